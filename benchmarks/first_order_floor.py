"""First-order solve floor (issue 18): what a first-order CV solve costs against the 2x budget.

The issue asks first-order Tikhonov within 2x of zero-order time. Both orders solve the same
number of systems (5 folds x 21 sigmas + the final one), so the 2x target allows a first-order
solve twice the CPU of a zero-order one. This script measures, for points of
``benchmarks/fit_scale.py`` (same problem, ``T`` samples):

- both orders' fit + 5-fold CV run serially by ``cross_validate_sigma`` as ``auto`` solves it:
  CPU seconds, solves, iterations (so CPU a solve, and the **budget** of a first-order solve,
  twice the zero-order CPU a solve);
- the kernels of one first-order multigrid-PCG iteration on CV fold 0's system (``n <= 4``, the
  dimensions where ``auto`` uses multigrid): one double-precision product ``A @ v`` on the fine
  grid (what CG does once an iteration), one single-precision Gauss-Seidel sweep there (pyamg's C++
  kernel; a V-cycle does two), one Gauss-Seidel V-cycle, and one data-block V-cycle at sigma = 1e-4
  (:meth:`pwas_hdl.fit.multigrid.FoldMultigrid.vcycle_block`);
- from those, how many multigrid-PCG iterations the budget pays for (``budget / (V-cycle +
  product)``, CG's own vector updates not counted) against the iterations the CV's solves took.

CPU seconds (``time.process_time``, one BLAS thread as the fit's solves run); nothing here asserts
on times.

Usage::

    python benchmarks/first_order_floor.py [--quick] [--points 2:999,4:31] [--outdir DIR] [--stem NAME]

writes ``first_order_floor.json`` and ``.md`` (``--quick``: ``T = 10^4``, n = 2, p = 127,
``first_order_floor_quick.*``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from pwas_hdl.bench_results import check_stem, default_outdir, write_json_and_markdown

#: (n, p) of the full run: the fit_scale points over 2x and the two named ones.
POINTS: list[tuple[int, int]] = [(2, 999), (2, 315), (3, 63), (4, 31)]
QUICK_POINTS: list[tuple[int, int]] = [(2, 127)]
#: the sigmas of the kernels: a penalty-dominated one (Gauss-Seidel cycle) and a data-dominated one
KERNEL_SIGMA, BLOCK_SIGMA = 1.0, 1e-4
#: the solve methods that iterate (SolveInfo.method)
ITERATIVE = ("cg", "mg", "mg-block")


def _cpu_ms(fn, repeats: int = 5) -> float:
    """Median CPU milliseconds of ``fn()`` over ``repeats`` calls (after one warm-up call)."""
    fn()
    times = []
    for _ in range(repeats):
        c0 = time.process_time()
        fn()
        times.append(time.process_time() - c0)
    return 1e3 * float(np.median(times))


def cv_cost(n: int, p: int, t: int, order: int) -> dict:
    """Serial fit + 5-fold CV of one order (``cross_validate_sigma``, ``auto``, final solve included)."""
    from pwas_hdl.benchmarks.fit_scale import _problem
    from pwas_hdl.fit.regularized_lsq import cross_validate_sigma, tikhonov_matrix

    grid, x, z = _problem(n, p, t)
    c0 = time.process_time()
    h = grid.basis_matrix(x)
    cv = cross_validate_sigma(h, z, tikhonov_matrix(grid, order), folds=5, final_solve=True)
    cpu = time.process_time() - c0
    solves = cv.solver["solves"] + 1
    iterative = sum(v for k, v in cv.solver["solves_by_method"].items() if k in ITERATIVE)
    iterative += cv.final_info.method in ITERATIVE
    its = cv.solver["iterations"] + cv.final_info.iterations
    return {"cpu_s": cpu, "solves": solves, "iterations": its, "iterative_solves": iterative,
            "by_method": cv.solver["solves_by_method"], "best_sigma": cv.best_sigma,
            "all_converged": cv.solver["all_converged"], "cpu_ms_per_solve": 1e3 * cpu / solves}


def kernels(n: int, p: int, t: int) -> dict:
    """CPU milliseconds of the first-order multigrid kernels on CV fold 0's system (see the module)."""
    from pyamg.relaxation.relaxation import gauss_seidel

    from pwas_hdl.benchmarks.cg_preconditioners import fold_system
    from pwas_hdl.fit.multigrid import GridHierarchy

    system = fold_system(n, p, t, 1)
    fold = GridHierarchy(system["shape"], system["gamma"]).for_matrix(system["m"])
    fold.set_sigma(KERNEL_SIGMA)
    a = fold.ops[0]
    a32 = a.astype(np.float32)
    rng = np.random.default_rng(0)
    b = rng.standard_normal(a.shape[0])
    b32, x32 = b.astype(np.float32), np.zeros(a.shape[0], dtype=np.float32)
    out = {
        "rows": int(a.shape[0]), "nnz_per_row": a.nnz / a.shape[0], "levels": len(fold.ops),
        "matvec_ms": _cpu_ms(lambda: a @ b),
        "gauss_seidel_ms": _cpu_ms(lambda: gauss_seidel(a32, x32, b32, iterations=1, sweep="forward")),
        # the cycles as PCG calls them, in the levels' vertex order (the public ones add two
        # permutations of the vector)
        "vcycle_ms": _cpu_ms(lambda: fold._vcycle_fine(b)),
    }
    fold.set_sigma(BLOCK_SIGMA)
    fold.set_block(BLOCK_SIGMA)
    out["vcycle_block_ms"] = _cpu_ms(lambda: fold._vcycle_block_fine(b))
    return out


def run(points, t: int, progress=print) -> dict:
    from pwas_hdl.bench_results import environment
    from pwas_hdl.fit.blas_threads import single_blas_thread

    rows = []
    t0 = time.perf_counter()
    for n, p in points:
        with single_blas_thread():
            zero, first = cv_cost(n, p, t, 0), cv_cost(n, p, t, 1)
            k = kernels(n, p, t) if n <= 4 else None
        budget = 2.0 * zero["cpu_ms_per_solve"]
        row = {"n": n, "p": p, "N": (p + 1) ** n, "T": t, "zero": zero, "first": first, "kernels": k,
               "budget_ms_per_solve": budget, "ratio_cpu": first["cpu_s"] / zero["cpu_s"]}
        if k is not None:
            it_ms = k["vcycle_ms"] + k["matvec_ms"]
            row["iterations_in_budget"] = budget / it_ms
            row["mean_iterations"] = first["iterations"] / max(first["iterative_solves"], 1)
        rows.append(row)
        progress(f"n={n} p={p}: zero {zero['cpu_ms_per_solve']:.0f} ms a solve, first {first['cpu_ms_per_solve']:.0f} "
                 f"ms ({row['ratio_cpu']:.2f}x CPU)"
                 + (f", V-cycle {k['vcycle_ms']:.1f} ms + product {k['matvec_ms']:.1f} ms: "
                    f"{row['iterations_in_budget']:.1f} iterations in the budget, {row['mean_iterations']:.1f} taken"
                    if k else ""))
    return {"benchmark": "first_order_floor", "T": t, "rows": rows,
            "environment": environment(time.perf_counter() - t0)}


def markdown(res: dict) -> str:
    out = ["# First-order solve floor (issue 18)", "",
           f"T = {res['T']}; serial fit + 5-fold CV over the 21 default sigmas + the final solve, `auto`, one BLAS "
           "thread; CPU. *Budget*: twice the zero-order CPU a solve (the 2x target with equal solve counts). "
           "*Iterations in budget*: budget / (Gauss-Seidel V-cycle + fine product), CG's vector work not counted.", "",
           "| n | p | N | zero order CPU s (ms a solve) | first order CPU s (ms a solve) | ratio | first-order methods "
           "| fine rows, nnz/row | product ms | GS sweep ms | V-cycle ms | block V-cycle ms | iterations in budget "
           "| iterations a solve taken |",
           "|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in res["rows"]:
        z, f, k = r["zero"], r["first"], r["kernels"]
        methods = ", ".join(f"{m} {c}" for m, c in f["by_method"].items())
        cells = [f"{r['n']}", f"{r['p']}", f"{r['N']}", f"{z['cpu_s']:.1f} ({z['cpu_ms_per_solve']:.0f})",
                 f"{f['cpu_s']:.1f} ({f['cpu_ms_per_solve']:.0f})", f"{r['ratio_cpu']:.2f}x", methods]
        if k is None:
            cells += ["-"] * 7
        else:
            cells += [f"{k['rows']}, {k['nnz_per_row']:.1f}", f"{k['matvec_ms']:.2f}", f"{k['gauss_seidel_ms']:.2f}",
                      f"{k['vcycle_ms']:.1f}", f"{k['vcycle_block_ms']:.1f}", f"{r['iterations_in_budget']:.1f}",
                      f"{r['mean_iterations']:.1f}"]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="T = 10^4, n = 2, p = 127 (CI smoke)")
    ap.add_argument("--points", default=None, help="n:p points, comma-separated, n, p >= 2 (default 2:999,2:315,3:63,4:31)")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="output folder")
    ap.add_argument("--stem", default=None, help="output file stem (default first_order_floor[_quick])")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    from pwas_hdl.benchmarks.cg_preconditioners import parse_points

    points = parse_points(args.points, QUICK_POINTS if args.quick else POINTS)
    t = 10_000 if args.quick else 100_000
    stem = check_stem(args.stem or ("first_order_floor_quick" if args.quick else "first_order_floor"))
    args.outdir.mkdir(parents=True, exist_ok=True)
    res = run(points, t, progress=lambda m: print(m, flush=True))
    write_json_and_markdown(args.outdir, stem, res, markdown(res))
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
