"""Fits at scale (issue 18): fit + 5-fold CV time and peak memory from N = 10^3 to 10^6 weights.

Each point is a regressor dimension ``n`` and partition ``p`` (``N = (p + 1)^n``), a Tikhonov order
(0 or 1) and ``T`` random regressors uniform in ``[-1, 1]^n`` (the domain is that box expanded by
``gamma = 1.2``); the target is ``z = sum_j sin(3 x_j) + 0.1 e``, ``e`` standard normal. The timed
job is what ``PWASVirtualSensor.fit`` does with ``sigma=None``: the basis matrix ``H``, ``Gamma``,
5-fold cross-validation (contiguous blocks) over the default grid of 21 sigmas and the final solve
at the chosen sigma, with the solver that ``method="auto"`` picks
(:func:`pwas_hdl.fit.regularized_lsq.choose_method`; first order: multigrid-PCG for the
penalty-dominated sigmas, see :data:`pwas_hdl.fit.regularized_lsq.MG_DOMINANCE`).

Every point runs in its own subprocess (so that ``ru_maxrss`` is the peak resident memory of that
fit alone) with a wall-time limit; wall and CPU seconds are both recorded, because the machine is
shared with other jobs and wall time then overstates the cost. Where the final solve is iterative
(CG or multigrid-PCG), a second
subprocess solves the final system again with the direct sparse solve (under its own time limit)
and the largest weight difference ``max |w_cg - w_direct|`` is recorded beside the bound the CG
solve guarantees (``||r|| / (sigma lambda_min(Gamma))``).

Usage::

    python benchmarks/fit_scale.py [--quick] [--outdir benchmarks/results] [--limit 300] [--budget S] [--workers N]
                                   [--points n:p,...] [--no-block-smoother] [--stem NAME]

writes ``fit_scale.json`` and ``fit_scale.md`` (``--quick``: ``T = 10^4``, small sizes only,
``fit_scale_quick.*``). Nothing here asserts on times.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pwas_hdl.bench_results import check_stem, default_outdir, write_json_and_markdown

HERE = Path(__file__).resolve().parent

#: (n, p) of the full table: N = (p + 1)^n from about 10^3 to 10^6 for n = 2..6; the two points the
#: issue names first (n = 2, p = 999 and n = 3, p = 63).
FULL_POINTS: list[tuple[int, int]] = [
    (2, 999), (3, 63),
    (2, 31), (3, 9), (4, 5), (5, 3), (6, 3),
    (2, 99), (3, 20), (4, 9), (5, 5), (6, 4),
    (2, 315), (3, 45), (4, 17), (5, 9), (6, 6),
    (4, 31), (5, 15), (6, 9),
]
QUICK_POINTS: list[tuple[int, int]] = [(2, 31), (3, 9), (4, 5), (2, 99), (3, 20)]


def _problem(n: int, p: int, t: int, seed: int = 0):
    from pwas_hdl.fit.geometry import Grid

    rng = np.random.default_rng(seed)
    x = rng.uniform(-1.0, 1.0, (t, n))
    z = np.sin(3.0 * x).sum(axis=1) + 0.1 * rng.standard_normal(t)
    grid = Grid(np.full(n, -1.2), np.full(n, 1.2), p)
    return grid, x, z


class _PssPeak:
    """Peak proportional set size (PSS) of this process and its children, sampled every ``period`` s.

    The sum of PSS counts pages shared copy-on-write with forked workers once (``ru_maxrss`` of
    each counts them in every process): the machine's memory actually used. ``None`` without
    psutil or ``/proc/<pid>/smaps_rollup``. Sampling runs in a thread of this process; reading the
    large processes' page maps is not free (measured ~10 s CPU over a 160 s first-order run at
    2 samples a second), so the thread's own CPU seconds (:attr:`cpu`) are subtracted from the
    fit's CPU time by the caller.
    """

    def __init__(self, period: float = 1.0):
        import threading

        self.period, self.peak, self.cpu, self._stop = period, None, 0.0, threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def _sample(self):
        import psutil

        me = psutil.Process()
        total = 0
        for proc in [me, *me.children(recursive=True)]:
            try:
                total += proc.memory_full_info().pss
            except (psutil.Error, AttributeError):
                pass
        return total

    def _loop(self):
        try:
            while not self._stop.is_set():
                v = self._sample()
                self.peak = v if self.peak is None else max(self.peak, v)
                self.cpu = time.thread_time()
                self._stop.wait(self.period)
        except Exception:  # no psutil / no smaps: no figure
            self.peak = None
        self.cpu = time.thread_time()

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()


def worker_fit(n: int, p: int, order: int, t: int, weights_out: str, workers: int = 0,
               block_smoother: bool = True) -> dict:
    """The timed fit (runs in a subprocess); saves the weights for the direct comparison.

    ``workers >= 2``: the CV folds run as ``fit --workers N`` runs them
    (:class:`pwas_hdl.flow.executor.Executor`; from ``FORK_MIN_UNKNOWNS`` unknowns on that many
    forked processes, below on a local Dask cluster; start-up timed too). CPU time is then this
    process's plus the workers' (``RUSAGE_CHILDREN`` after they are shut down); the peak memory is
    this process's plus that of the largest worker, times the worker count (an upper bound of the
    sum: ``ru_maxrss`` of the children is their maximum, not their sum, and counts the pages they
    share with the parent copy-on-write). ``critical_cpu_s``: this process's CPU plus that of
    the busiest forked worker (sum of its tasks' CPU), the wall time the run would take on two
    otherwise idle cores (derived from CPU times, not a wall measurement); the CPU this process
    spends while the workers run (``parent_overlap_cpu_s``, the final solve's set-up) is not added.
    """
    from pwas_hdl.fit.regularized_lsq import cross_validate_sigma, fork_workers, plan_fit_memory, tikhonov_matrix
    from pwas_hdl.fit.sparse_cholesky import cholmod_available
    from pwas_hdl.flow.executor import Executor

    grid, x, z = _problem(n, p, t)
    c0, w0 = time.process_time(), time.perf_counter()
    with _PssPeak() as pss, Executor(workers=workers if workers >= 2 else None) as ex:
        # the estimate of the plan fit makes for this run under the memory limit (cross_validate_sigma
        # makes the same plan again): with forked workers, each worker's own solver state counted
        # too, or one factor at a time, or fewer processes (plan_fit_memory; a refusal fails the point)
        est = plan_fit_memory(t, grid.n_vertices, n, 1, order, processes=max(fork_workers(ex, grid.n_vertices), 1),
                              block_smoother=block_smoother, grid_side=max(grid.shape))["estimate"]
        h = grid.basis_matrix(x)
        gam = tikhonov_matrix(grid, order)
        cv = cross_validate_sigma(h, z, gam, folds=5, executor=ex, final_solve=True, block_smoother=block_smoother)
        w, info = cv.final_weights, cv.final_info  # as fit does: the CV's solver solves the full data
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0 - pss.cpu  # without the sampler's CPU
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    own_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    np.save(weights_out, w)
    overlap = float(cv.solver.get("parent_overlap_cpu_s", 0.0))
    per_worker: dict[int, float] = {}
    for task in cv.solver.get("fork_tasks", []):
        per_worker[task["pid"]] = per_worker.get(task["pid"], 0.0) + task["cpu_s"]
    return {
        "peak_pss_mib": None if pss.peak is None else pss.peak / 2**20,
        "fork_worker_cpu_s": sorted(per_worker.values()),
        # this process's CPU outside the workers' run plus the busiest worker's (or this process's
        # own work during the run, if longer: cross_validate_sigma's parent_overlap_cpu_s)
        "critical_cpu_s": (cpu - overlap + max(max(per_worker.values()), overlap)) if per_worker else None,
        "parent_overlap_cpu_s": overlap,
        "wall_s": wall,
        "cpu_s": cpu + (kids.ru_utime + kids.ru_stime if workers >= 2 else 0.0),
        "workers": workers if workers >= 2 else 1,
        "peak_rss_mib": own_peak + (workers * kids.ru_maxrss / 1024.0 if workers >= 2 else 0.0),
        # the plan's estimate as the CV reports it: with a factor that the analysis of
        # DIRECT_FLOPS_PER_ENTRY chose after the plan, charged to every process that may hold one
        "estimated_mib": cv.solver.get("memory_plan", {}).get("estimate_mib", est["total"] / 2**20),
        "method": cv.solver["method"],
        "direct_backend": "cholmod" if cholmod_available() else "superlu",
        "cv_solves": cv.solver["solves"],
        "cv_cg_iterations": cv.solver["iterations"],
        "cv_max_rel_residual": cv.solver["max_rel_residual"],
        "cv_all_converged": cv.solver["all_converged"],
        "cv_direct_fallbacks": cv.solver["direct_fallbacks"],
        "block_smoother": block_smoother,
        "cv_block_failures": cv.solver.get("block_failures", 0),
        "cv_solves_by_method": cv.solver.get("solves_by_method", {}),
        "memory_plan": cv.solver.get("memory_plan"),
        "best_sigma": cv.best_sigma,
        "best_cv_mse": float(cv.mse.min()),
        "final": info.to_dict(),
    }


def worker_direct(n: int, p: int, order: int, t: int, sigma: float, weights_in: str) -> dict:
    """The direct solve of the final system, compared with the saved weights."""
    from pwas_hdl.fit.regularized_lsq import solve_regularized, tikhonov_matrix

    grid, x, z = _problem(n, p, t)
    h = grid.basis_matrix(x)
    gam = tikhonov_matrix(grid, order)
    c0, w0 = time.process_time(), time.perf_counter()
    wd = solve_regularized(h, z, sigma, gam, method="direct")
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    w = np.load(weights_in)
    return {
        "direct_wall_s": wall,
        "direct_cpu_s": cpu,
        "max_abs_weight_diff": float(np.max(np.abs(w - wd))),
        "rel_weight_diff": float(np.linalg.norm(w - wd) / max(np.linalg.norm(wd), 1e-300)),
    }


def _run_child(args: list[str], limit: float) -> dict:
    """Run one point in a subprocess of its own session; on timeout kill the whole session (the
    fit's forked CV workers too: killing the fit process alone left them running as orphans)."""
    import signal

    cmd = [sys.executable, str(Path(__file__).resolve()), *args]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        stdout, stderr = proc.communicate(timeout=limit)
    except subprocess.TimeoutExpired:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:  # pragma: no cover - already gone
            pass
        proc.communicate()
        return {"status": "timeout", "limit_s": limit}
    if proc.returncode != 0:
        tail = (stderr or "").strip().splitlines()[-1:] or ["?"]
        return {"status": "failed", "error": tail[0]}
    res = json.loads(stdout.strip().splitlines()[-1])
    res["status"] = "ok"
    return res


def run(points, t: int, limit: float, direct_limit: float, budget: float = float("inf"), progress=print,
        workers: int = 0, block_smoother: bool = True) -> dict:
    rows = []
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="pwas-fit-scale-") as tmp:
        for n, p in points:
            for order in (0, 1):
                wfile = os.path.join(tmp, f"w_{n}_{p}_{order}.npy")
                row = {"n": n, "p": p, "N": (p + 1) ** n, "order": order, "T": t}
                if time.perf_counter() - t_start > budget:
                    row.update({"status": "not run (time budget of the benchmark spent)"})
                    rows.append(row)
                    continue
                row.update(_run_child(["--worker", "fit", json.dumps([n, p, order, t, wfile, workers, block_smoother])], limit))
                if row["status"] == "ok" and (row["method"] == "cg" or row["final"]["method"] in ("cg", "mg", "mg-block")):
                    d = _run_child(
                        ["--worker", "direct", json.dumps([n, p, order, t, row["best_sigma"], wfile])], direct_limit
                    )
                    row["direct"] = d
                elif row["status"] == "ok":
                    row["direct"] = {"status": "is the direct solve"}
                rows.append(row)
                progress(_line(row))
    return {
        "format": "pwas-hdl-bench-fit-scale",
        "version": 1,
        "setup": {
            "T": t,
            "folds": 5,
            "sigma_grid": "logspace(-7, 3, 21) (DEFAULT_SIGMA_GRID)",
            "data": "x uniform in [-1, 1]^n, z = sum_j sin(3 x_j) + 0.1 N(0, 1), domain [-1.2, 1.2]^n",
            "timed": "plan_fit_memory + H + Gamma + 5-fold CV over 21 sigmas + final solve, method auto",
            "limit_s": limit,
            "direct_limit_s": direct_limit,
            "budget_s": budget if budget != float("inf") else None,
            "workers": workers if workers >= 2 else 1,
            # first order with multigrid: the data-dominated sigmas by the data-block cycle (the default)
            "block_smoother": block_smoother,
            # shared: other jobs ran (1-minute load average >= IDLE_LOAD at the start, or unknown)
            "shared_machine": _load() is None or _load() >= IDLE_LOAD,
            "load_average_at_start": _load(),
            "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
            # the memory limit the fits planned for (plan_fit_memory): bytes and where it came from
            "memory_limit": _memory_limit(),
        },
        "environment": _environment(),
        "rows": rows,
        "total_time_s": time.perf_counter() - t_start,
    }


#: a 1-minute load average below this at the start counts as an idle 2-core machine (the README's "idle")
IDLE_LOAD = 2.0


def _load() -> float | None:
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else None


def _environment() -> dict:
    import scipy

    try:
        import pyamg

        amg = pyamg.__version__
    except ImportError:  # pragma: no cover
        amg = None
    try:
        import cvxopt

        cvx = cvxopt.__version__
    except ImportError:  # pragma: no cover
        cvx = None
    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "pyamg": amg,
        "cvxopt": cvx,
        "cpu_count": os.cpu_count(),
    }


def _line(r: dict) -> str:
    head = f"n={r['n']} p={r['p']} N={r['N']} order {r['order']}: "
    if r["status"] != "ok":
        return head + r["status"] + (f" after {r['limit_s']:.0f} s" if r["status"] == "timeout" else f" ({r.get('error')})")
    d = r.get("direct", {})
    diff = f"{d['max_abs_weight_diff']:.1e}" if "max_abs_weight_diff" in d else d.get("status", "-")
    return (
        head + f"{r['method']} wall {r['wall_s']:.1f} s cpu {r['cpu_s']:.1f} s, peak {r['peak_rss_mib']:.0f} MiB, "
        f"sigma {r['best_sigma']:.2g}, max|w - w_direct| {diff}"
    )


def _memory_limit() -> dict:
    from pwas_hdl.fit.regularized_lsq import memory_limit

    limit, source = memory_limit()
    return {"bytes": limit, "source": source}


def markdown(res: dict) -> str:
    s = res["setup"]
    ml = s.get("memory_limit") or {}
    out = [
        "# Fits at scale: fit + 5-fold CV (issue 18)",
        "",
        f"T = {s['T']} random regressors, 5-fold CV over 21 sigmas (1e-7 .. 1e3) + final solve, solver chosen "
        f"by `method=\"auto\"`. Each point in its own process; limit {s['limit_s']:.0f} s wall per fit and "
        f"{s['direct_limit_s']:.0f} s per direct reference solve. "
        + ("First order: the earlier rule (`--no-block-smoother`: factorisations at the data-dominated sigmas). "
           if s.get("block_smoother") is False else "")
        + (f"Memory limit {ml['bytes'] / 2**20:.0f} MiB ({ml['source']}). " if ml.get("bytes") else "")
        + ("**The 2-core machine was shared with other engineers' jobs** (load average "
           f"{s['load_average_at_start'] or float('nan'):.1f} at the start): wall times are inflated, CPU times are "
           "the fairer measure." if s.get("shared_machine", True) else
           f"The 2-core machine was otherwise idle (load average {s['load_average_at_start']:.1f} at the start): "
           "wall times are the cost.")
        + (f" The CV folds ran as `fit --workers {s['workers']}` runs them (from 50 000 unknowns on "
           f"{s['workers']} forked processes, below on a local Dask cluster): CPU includes the workers', peak RSS "
           "is this process's plus workers x the largest worker's (an upper bound: shared pages counted in each); "
           "`critical CPU` = this process's CPU + the busiest forked worker's (without what this process did "
           "while the workers ran), the wall time on idle cores (derived from CPU times)."
           if s.get("workers", 1) > 1 else "")
        + (" `peak PSS`: the largest sum of the proportional set sizes of the fit's process and its "
           "workers, sampled every second (shared pages counted once: the memory actually used; the sampler's "
           "CPU is not in the CPU columns)."
           if s.get("workers", 1) > 1 else ""),
        "",
        "| n | p | N | order | solver | wall (s) | CPU (s) | peak RSS (MiB) | estimate (MiB) | CV CG/MG iterations | sigma | max abs w - w_direct | CG bound | direct CPU (s) | order1/order0 CPU | critical CPU (s) | peak PSS (MiB) |",
        "|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    by_key = {(r["n"], r["p"], r["order"]): r for r in res["rows"]}
    for r in res["rows"]:
        pre = f"| {r['n']} | {r['p']} | {r['N']} | {r['order']} "
        if r["status"] != "ok":
            what = f"timeout (> {r['limit_s']:.0f} s)" if r["status"] == "timeout" else r["status"]
            out.append(pre + f"| {what} |" + " |" * 12)
            continue
        d = r.get("direct", {})
        if "max_abs_weight_diff" in d:
            diff, dcpu = f"{d['max_abs_weight_diff']:.1e}", f"{d['direct_cpu_s']:.1f}"
        elif d.get("status") == "is the direct solve":
            diff, dcpu = "0 (direct)", "-"
        else:
            diff, dcpu = f"direct {d.get('status', '-')}", "-"
        ratio = "-"
        r0 = by_key.get((r["n"], r["p"], 0))
        if r["order"] == 1 and r0 is not None and r0["status"] == "ok":
            ratio = f"{r['cpu_s'] / r0['cpu_s']:.2f}"
        iterative = r["method"] == "cg" or r["final"]["method"] in ("cg", "mg")
        bound = f"{r['final']['weight_bound']:.1e}" if iterative else "-"
        by = r.get("cv_solves_by_method") or {}
        if len(by) > 1:  # auto mixed the methods over the sigmas (first order: multigrid + another)
            solver = " + ".join(f"{k} {v}" for k, v in sorted(by.items()))
        else:
            solver = r["method"]
        if "direct_backend" in r and ("direct" in by or r["method"] == "direct"):
            solver += f" ({r['direct_backend']})"
        if r.get("cv_direct_fallbacks"):
            solver += f" ({r['cv_direct_fallbacks']} direct fallbacks)"
        if not r["cv_all_converged"] or not r["final"]["converged"]:
            solver += " NOT all converged"
        mp = r.get("memory_plan") or {}
        if mp.get("reason"):  # the memory limit changed the plan (plan_fit_memory)
            solver += (f" [memory limit: {mp['processes']} process{'es' if mp['processes'] > 1 else ''}"
                       f"{', one factor at a time' if mp.get('one_factor') else ''}]")
        out.append(
            pre + f"| {solver} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | {r['peak_rss_mib']:.0f} | "
            f"{r['estimated_mib']:.0f} | {r['cv_cg_iterations']} | {r['best_sigma']:.2g} | {diff} | {bound} | {dcpu} | {ratio} | "
            + (f"{r['critical_cpu_s']:.1f} |" if r.get("critical_cpu_s") is not None else "- |")
            + (f" {r['peak_pss_mib']:.0f} |" if r.get("peak_pss_mib") is not None else " - |")
        )
    env = res["environment"]
    out += [
        "",
        f"Environment: Python {env['python']}, numpy {env['numpy']}, scipy {env['scipy']}, pyamg {env['pyamg']}, "
        f"cvxopt {env.get('cvxopt')} (CHOLMOD), OPENBLAS_NUM_THREADS={s.get('OPENBLAS_NUM_THREADS')}, "
        f"{env['cpu_count']} CPUs. Total run time {res['total_time_s']:.0f} s.",
        "",
    ]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--worker"]:
        kind, params = argv[1], json.loads(argv[2])
        res = worker_fit(*params) if kind == "fit" else worker_direct(*params)
        print(json.dumps(res))
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="T = 10^4 and small sizes only (CI smoke)")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="output folder")
    ap.add_argument("--limit", type=float, default=300.0, help="wall-time limit per fit, s (default 300)")
    ap.add_argument("--direct-limit", type=float, default=120.0, help="wall-time limit per direct solve, s")
    ap.add_argument("--budget", type=float, default=float("inf"), help="start no new point after this many s")
    ap.add_argument("--points", default=None, help="only these n:p points, comma-separated (e.g. 6:3,2:999)")
    ap.add_argument("--workers", type=int, default=0,
                    help="run the CV folds on a local Dask cluster of this many processes (default: serial)")
    ap.add_argument("--no-block-smoother", action="store_true",
                    help="first order: the earlier rule (factorisations at the data-dominated sigmas) instead of "
                         "the data-block multigrid cycle, for comparison")
    ap.add_argument("--stem", default=None, help="output file stem (default fit_scale / fit_scale_quick)")
    args = ap.parse_args(argv)
    points, t, stem = (QUICK_POINTS, 10_000, "fit_scale_quick") if args.quick else (FULL_POINTS, 100_000, "fit_scale")
    if args.points:
        try:
            points = [tuple(int(v) for v in item.split(":")) for item in args.points.split(",")]
        except ValueError:
            ap.error("--points takes n:p pairs, e.g. 6:3,2:999")
        if any(len(pt) != 2 or pt[0] < 1 or pt[1] < 1 for pt in points):
            ap.error("--points takes n:p pairs with n, p >= 1, e.g. 6:3,2:999")
    stem = check_stem(args.stem or stem)
    args.outdir.mkdir(parents=True, exist_ok=True)
    if args.workers < 0:
        ap.error("--workers must be 0 (serial) or a positive count")
    res = run(points, t, args.limit, args.direct_limit, args.budget, progress=lambda m: print(m, flush=True),
              workers=args.workers, block_smoother=not args.no_block_smoother)
    write_json_and_markdown(args.outdir, stem, res, markdown(res))
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
