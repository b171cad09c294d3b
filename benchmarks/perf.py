"""Performance numbers of the float toolchain: fit with cross-validation, and evaluation throughput.

Usage::

    python benchmarks/perf.py [--repeats 5] [--outdir benchmarks/results]

1. Fit (``PWASVirtualSensor.fit`` with 5-fold cross-validation over the 21 default sigmas,
   zero-order Tikhonov, T = 6000 Lorenz samples) for N = 4096 (My = 4, p = 7) and N = 32768
   (My = 5, p = 7): median wall time over repeats, and peak memory. Each case runs in a fresh child
   process so that ``ru_maxrss`` (peak resident set size, whole process) belongs to that case alone;
   ``tracemalloc`` gives the peak of Python/numpy allocations during one fit (SuperLU's own C
   allocations are not traced, ``ru_maxrss`` includes them).
2. Evaluation throughput (points/s) for n = 4, p = 7 (N = 4096, the fitted baseline model):
   ``Grid.evaluate`` and ``PWASVirtualSensor.predict_regressors`` (Kuhn simplex, n + 1 = 5 vertices)
   against ``scipy.interpolate.RegularGridInterpolator(method="linear")`` (multilinear, 2^n = 16
   corners) on the same grid and the same random points; median over repeats after one warm-up.
   Also checks that both give the vertex weights at the vertices.

Prints the numbers and writes ``perf.json`` and ``perf.md`` into ``--outdir``. Nothing asserts on time.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

from pwas_hdl.bench_results import default_outdir

HERE = Path(__file__).resolve().parent
N_TRAIN = 6000
FIT_CASES = [(4, 7), (5, 7)]


def _maxrss_mib() -> float:
    # Linux reports kilobytes, macOS bytes.
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / (1024 * 1024) if sys.platform == "darwin" else rss / 1024


def child_fit(my: int, p: int, repeats: int) -> dict:
    """Time the fit of one case in this (fresh) process; returns a JSON-ready dict."""
    from pwas_hdl.systems.lorenz import lorenz
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    data = lorenz(N_TRAIN, seed=0)
    rss_before = _maxrss_mib()

    def make() -> PWASVirtualSensor:
        return PWASVirtualSensor(mu=0, my=my, partitions=p, gamma=1.2, sigma=None, tikhonov_order=0, cv_folds=5)

    times = []
    for _ in range(repeats):
        s = make()
        t0 = time.perf_counter()
        s.fit(None, data.y, data.z)
        times.append(time.perf_counter() - t0)
    rss_after = _maxrss_mib()
    tracemalloc.start()
    make().fit(None, data.y, data.z)
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {
        "My": my,
        "p": p,
        "N": (p + 1) ** my,
        "T": N_TRAIN,
        "rows_of_H": int(s.n_train_),
        "cv_folds": 5,
        "sigma_candidates": int(len(s.cv_.sigmas)),
        "factorisations": int(5 * len(s.cv_.sigmas) + 1),
        "sigma": float(s.sigma_),
        "repeats": repeats,
        "fit_times_s": times,
        "fit_time_s_median": statistics.median(times),
        "maxrss_before_fit_mib": rss_before,
        "maxrss_peak_mib": rss_after,
        "tracemalloc_peak_mib": traced_peak / 2**20,
    }


def run_fit_case(my: int, p: int, repeats: int) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child-fit", str(my), str(p), "--repeats", str(repeats)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _median_rate(fn, m: int, repeats: int) -> tuple[float, float]:
    fn()  # warm-up (first touch of the output buffers, caches)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    return m / med, med


def eval_benchmark(repeats: int, sizes: list[int]) -> dict:
    from scipy.interpolate import RegularGridInterpolator

    from pwas_hdl.systems.lorenz import lorenz
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    data = lorenz(N_TRAIN, seed=0)
    sensor = PWASVirtualSensor(mu=0, my=4, partitions=7, gamma=1.2, sigma=None).fit(None, data.y, data.z)
    grid = sensor.grid_
    w = sensor.weights_[:, 0].copy()
    axes = [grid.lo[j] + np.arange(grid.shape[j]) * grid.step[j] for j in range(grid.n)]
    rgi = RegularGridInterpolator(axes, w.reshape(grid.shape), method="linear", bounds_error=False, fill_value=None)

    # Vertex check: the vertex physical coordinates are exactly the RGI axes.
    xv = grid.vertex_points()
    pw_v = grid.evaluate(w, xv)
    rg_v = rgi(xv)
    coords = grid.vertex_coords().astype(float)
    cell, frac, rank, perm, verts, mu = grid.locate_grid_units(np.minimum(coords, grid.partitions))
    pw_units = np.einsum("mk,mk->m", mu, w[verts])
    scale = float(np.max(np.abs(w)))
    vertex_check = {
        "n_vertices": int(grid.n_vertices),
        "rgi_equal_weights": int(np.count_nonzero(rg_v == w)),
        "pwas_physical_equal_weights": int(np.count_nonzero(pw_v == w)),
        "pwas_physical_equal_rgi": int(np.count_nonzero(pw_v == rg_v)),
        "pwas_physical_max_abs_diff": float(np.max(np.abs(pw_v - w))),
        "pwas_physical_max_diff_in_eps_of_max_w": float(np.max(np.abs(pw_v - w)) / (np.finfo(float).eps * scale)),
        "pwas_grid_units_equal_weights": int(np.count_nonzero(pw_units == w)),
    }

    rng = np.random.default_rng(12345)
    lo = np.array([a[0] for a in axes])
    hi = np.array([a[-1] for a in axes])
    results = []
    for m in sizes:
        x = rng.uniform(lo, hi, (m, grid.n))
        r_pw, t_pw = _median_rate(lambda: grid.evaluate(w, x), m, repeats)
        r_vs, t_vs = _median_rate(lambda: sensor.predict_regressors(x), m, repeats)
        r_rg, t_rg = _median_rate(lambda: rgi(x), m, repeats)
        results.append({
            "points": m,
            "grid_evaluate_pts_per_s": r_pw,
            "predict_regressors_pts_per_s": r_vs,
            "rgi_linear_pts_per_s": r_rg,
            "grid_evaluate_s": t_pw,
            "predict_regressors_s": t_vs,
            "rgi_linear_s": t_rg,
            "pwas_over_rgi_speed": r_pw / r_rg,
        })
    # Independent cross-check off the vertices: for vertex values that are an affine function of the
    # position both interpolants reproduce that function, so they must agree up to rounding.
    a = rng.normal(size=grid.n)
    w_aff = grid.vertex_points() @ a + 1.0
    rgi_aff = RegularGridInterpolator(axes, w_aff.reshape(grid.shape), method="linear", bounds_error=False, fill_value=None)
    x = rng.uniform(lo, hi, (sizes[0], grid.n))
    exact = x @ a + 1.0
    vertex_check["affine_field_points"] = int(sizes[0])
    vertex_check["affine_field_max_abs_pwas_minus_exact"] = float(np.max(np.abs(grid.evaluate(w_aff, x) - exact)))
    vertex_check["affine_field_max_abs_rgi_minus_exact"] = float(np.max(np.abs(rgi_aff(x) - exact)))
    return {"n": grid.n, "p": 7, "N": int(grid.n_vertices), "repeats": repeats, "vertex_check": vertex_check, "throughput": results}


def _environment() -> dict:
    import scipy

    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
    }


def _markdown(res: dict) -> str:
    lines = ["# pwas-hdl performance", "", "Generated by `python benchmarks/perf.py`; numbers in `perf.json`.", ""]
    lines += ["## Fit with 5-fold cross-validation (Lorenz, T = 6000, 21 sigmas, zero-order Tikhonov)", ""]
    lines += ["| My | p | N | factorisations | fit time, median (s) | peak RSS (MiB) | RSS before fit (MiB) | tracemalloc peak (MiB) |",
              "|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for f in res["fit"]:
        lines.append(
            f"| {f['My']} | {f['p']} | {f['N']} | {f['factorisations']} | {f['fit_time_s_median']:.2f} "
            f"| {f['maxrss_peak_mib']:.0f} | {f['maxrss_before_fit_mib']:.0f} | {f['tracemalloc_peak_mib']:.1f} |"
        )
    ev = res["evaluate"]
    lines += ["", f"## Float evaluation, n = {ev['n']}, p = {ev['p']} (N = {ev['N']}), points/s (median of {ev['repeats']})", ""]
    lines += ["| points | Grid.evaluate | predict_regressors | RegularGridInterpolator linear | PWAS / RGI |",
              "|---:|---:|---:|---:|---:|"]
    for t in ev["throughput"]:
        lines.append(
            f"| {t['points']:.0e} | {t['grid_evaluate_pts_per_s']:.3g} | {t['predict_regressors_pts_per_s']:.3g} "
            f"| {t['rgi_linear_pts_per_s']:.3g} | {t['pwas_over_rgi_speed']:.2f} |"
        )
    vc = ev["vertex_check"]
    lines += [
        "",
        f"Vertex check ({vc['n_vertices']} vertices): RGI returns the weight exactly at {vc['rgi_equal_weights']}; "
        f"the PWAS model evaluated at physical vertex coordinates at {vc['pwas_physical_equal_weights']} "
        f"(max deviation {vc['pwas_physical_max_diff_in_eps_of_max_w']:.1f} eps x max|w|: the scaling "
        f"(x - lo) / step does not always land on an exact integer), and at grid-unit vertex coordinates at "
        f"{vc['pwas_grid_units_equal_weights']}.",
        "",
        "Off the vertices the two interpolants differ by construction (simplicial vs multilinear); for vertex "
        f"values of an affine function both reproduce it on {vc['affine_field_points']} random points "
        f"(max error PWAS {vc['affine_field_max_abs_pwas_minus_exact']:.2g}, RGI {vc['affine_field_max_abs_rgi_minus_exact']:.2g}).",
        "",
        f"Environment: Python {res['environment']['python']}, numpy {res['environment']['numpy']}, "
        f"scipy {res['environment']['scipy']}, {res['environment']['cpu_count']} CPUs.",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5, help="timed repeats per measurement (median; 1..1000, pwas_hdl.limits.MAX_BENCH_COUNT)")
    ap.add_argument("--outdir", type=Path, default=default_outdir())
    ap.add_argument("--child-fit", nargs=2, type=int, metavar=("MY", "P"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    from pwas_hdl.bench_results import check_count

    check_count("--repeats", args.repeats)
    if args.child_fit:
        print(json.dumps(child_fit(args.child_fit[0], args.child_fit[1], args.repeats)))
        return 0

    from pwas_hdl.io.atomic import atomic_write_text

    res: dict = {"format": "pwas-hdl-bench-perf", "version": 1, "environment": _environment(), "fit": []}
    for my, p in FIT_CASES:
        f = run_fit_case(my, p, args.repeats)
        res["fit"].append(f)
        print(
            f"fit My={my} p={p} N={f['N']}: median {f['fit_time_s_median']:.3f} s over {f['repeats']} "
            f"({', '.join(f'{t:.3f}' for t in f['fit_times_s'])}), peak RSS {f['maxrss_peak_mib']:.0f} MiB "
            f"(before fit {f['maxrss_before_fit_mib']:.0f}), tracemalloc peak {f['tracemalloc_peak_mib']:.1f} MiB",
            flush=True,
        )
    res["evaluate"] = eval_benchmark(args.repeats, [100_000, 1_000_000])
    vc = res["evaluate"]["vertex_check"]
    print(
        f"vertex check: {vc['n_vertices']} vertices; RGI == w at {vc['rgi_equal_weights']}, "
        f"PWAS(physical) == w at {vc['pwas_physical_equal_weights']} (max |diff| {vc['pwas_physical_max_abs_diff']:.3g}), "
        f"PWAS == RGI at {vc['pwas_physical_equal_rgi']}, PWAS(grid units) == w at {vc['pwas_grid_units_equal_weights']}; "
        f"affine field: max error PWAS {vc['affine_field_max_abs_pwas_minus_exact']:.2g}, RGI {vc['affine_field_max_abs_rgi_minus_exact']:.2g}"
    )
    for t in res["evaluate"]["throughput"]:
        print(
            f"evaluate n=4 p=7, {t['points']} points: Grid.evaluate {t['grid_evaluate_pts_per_s']:.3g} pts/s, "
            f"predict_regressors {t['predict_regressors_pts_per_s']:.3g} pts/s, "
            f"RegularGridInterpolator {t['rgi_linear_pts_per_s']:.3g} pts/s (PWAS/RGI {t['pwas_over_rgi_speed']:.2f}x)"
        )
    args.outdir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.outdir / "perf.json", json.dumps(res, indent=1, allow_nan=False) + "\n")
    atomic_write_text(args.outdir / "perf.md", _markdown(res))
    print(f"wrote {args.outdir / 'perf.json'} and {args.outdir / 'perf.md'}")
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
