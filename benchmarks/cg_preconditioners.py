"""CG preconditioners from n = 4 up (issue 18): iterations and CPU of one CV fold's solves.

From regressor dimension 4 up ``method="auto"`` solves every CV system ``(H_k'H_k + sigma Gamma) w
= H_k'z`` by conjugate gradients with the Jacobi preconditioner (the penalty-dominated first-order
sigmas with algebraic multigrid, see :data:`pwas_hdl.fit.regularized_lsq.AMG_DOMINANCE`). This
script measures the alternatives on the systems of CV fold 0 (training = the other four of five
contiguous blocks, as :func:`~pwas_hdl.fit.regularized_lsq.cross_validate_sigma` cuts them) of the
problem of ``benchmarks/fit_scale.py``, each solved cold (from zero) to the solver's relative
residual :data:`~pwas_hdl.fit.regularized_lsq.CG_RTOL`:

- ``jacobi``: ``diag(A)^{-1}`` (what ``auto`` uses);
- ``sgs``: one symmetric Gauss-Seidel sweep from zero (pyamg's C++ kernel; symmetric positive
  definite for SPD ``A``);
- ``amg``: one smoothed-aggregation V-cycle (pyamg) built on ``A`` itself (first order);
- ``amg-lumped``: the same on the lumped surrogate ``diag(rowsum H_k'H_k) + sigma Gamma`` of
  :class:`~pwas_hdl.fit.regularized_lsq._Preconditioner`, built at this sigma (the solver builds
  it from the full-data ``H'H`` and for a band of sigmas; first order);
- ``two-level`` / ``two-level-2``: Jacobi plus an exact coarse correction,
  ``D^{-1} + Q (Q'AQ)^{-1} Q'`` (additive, SPD), ``Q`` the multilinear prolongation
  (:func:`pwas_hdl.fit.multigrid.prolongation`) from the next coarser grid or the one below it,
  the coarse matrix factorised by SuperLU (first order: ``Gamma`` of a full grid).

Zero-order systems are first restricted to the touched vertices, as the solver does. For every
system the row count, entries a row and the CPU time of one ``A @ v`` (mean of repeats) are
recorded too; the Markdown splits a CG iteration's CPU into that product and the rest (the
preconditioner and CG's vector updates and dot products on vectors of ``rows`` entries). CPU seconds (``time.process_time``, one BLAS thread advised) of the set-up and of CG;
nothing here asserts on times.

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/cg_preconditioners.py [--quick] [--points 4:17,5:9]
        [--sigmas 1e-2,1e-4] [--preconditioners jacobi,sgs] [--maxiter 3000] [--outdir DIR] [--stem NAME]

writes ``cg_preconditioners.json`` and ``.md`` (``--quick``: ``T = 10^4``, n = 4, p = 5, 300
iterations at most, ``cg_preconditioners_quick.*``). ``--preconditioners`` runs a subset (each order
runs those of the subset that :data:`PRECONDITIONERS` lists for it), e.g. ``jacobi`` alone at
``--points 4:31`` (N ~ 10^6, where the multigrid set-ups take minutes).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from pwas_hdl.bench_results import check_stem, default_outdir, write_json_and_markdown

#: (n, p) of the full run: the n = 4 point of the fit_scale table at N ~ 10^5.
POINTS: list[tuple[int, int]] = [(4, 17)]
QUICK_POINTS: list[tuple[int, int]] = [(4, 5)]
#: a middle sigma and a small one that Jacobi-CG still solves within the cap (n = 4, N ~ 10^5: 1919
#: iterations at 1e-4; at 1e-6 Jacobi, SGS and both two-level forms stop at 3000, scratch runs of
#: 2026-12-03, which is why the default leaves it out)
SIGMAS: tuple[float, ...] = (1e-2, 1e-4)
QUICK_SIGMAS: tuple[float, ...] = (1e-2, 1e-4)
#: largest grid a point may have (refused before the basis matrix is built)
MAX_VERTICES = 2_000_000
#: the preconditioners of each Tikhonov order (those that need a full first-order grid: order 1 only)
PRECONDITIONERS: dict[int, tuple[str, ...]] = {
    0: ("jacobi", "sgs"),
    1: ("jacobi", "sgs", "amg", "amg-lumped", "two-level", "two-level-2"),
}


def fold_system(n: int, p: int, t: int, order: int) -> dict:
    """The normal matrix, right-hand side and ``Gamma`` of CV fold 0 of the fit_scale problem.

    Returns a dict with ``m`` (``H_k'H_k``, CSR), ``b`` (``H_k'z``), ``gamma`` (CSR), ``shape``
    (the vertex grid, None where restricted) and ``lumped`` (row sums of ``m``); zero order
    restricted to the touched vertices.
    """
    from scipy import sparse

    from pwas_hdl.benchmarks.fit_scale import _problem
    from pwas_hdl.fit.regularized_lsq import fold_labels, tikhonov_matrix

    grid, x, z = _problem(n, p, t)
    h = sparse.csr_array(grid.basis_matrix(x))
    train = fold_labels(t, 5) != 0
    ht = h[train]
    m = sparse.csr_array(ht.T @ ht)
    b = ht.T @ z[train]
    gamma = sparse.csr_array(tikhonov_matrix(grid, order))
    shape = tuple(int(k) + 1 for k in grid.partitions)
    if order == 0:
        keep = np.flatnonzero(m.diagonal() > 0)
        m, gamma, b, shape = m[keep][:, keep], gamma[keep][:, keep], b[keep], None
    return {"m": m, "b": b, "gamma": gamma, "shape": shape, "lumped": np.asarray(m.sum(axis=1)).ravel()}


def preconditioner(name: str, a, system: dict, sigma: float):
    """The preconditioner ``name`` of ``a = m + sigma Gamma`` as a scipy LinearOperator."""
    from scipy import sparse
    from scipy.sparse import linalg as splinalg

    shape = a.shape
    d = a.diagonal()
    if name == "jacobi":
        return splinalg.LinearOperator(shape, matvec=lambda v: v / d, dtype=float)
    if name == "sgs":
        from pyamg.relaxation.relaxation import gauss_seidel

        ac = sparse.csr_matrix(a)
        ac.sort_indices()

        def sgs(v):
            v = np.asarray(v, dtype=float).ravel()
            out = np.zeros_like(v)
            gauss_seidel(ac, out, v, iterations=1, sweep="symmetric")
            return out

        return splinalg.LinearOperator(shape, matvec=sgs, dtype=float)
    if name in ("amg", "amg-lumped"):
        import pyamg

        target = a if name == "amg" else sparse.diags_array(system["lumped"]) + sigma * system["gamma"]
        state = np.random.get_state()
        try:
            np.random.seed(0)  # pyamg's spectral-radius estimates start from the global generator
            ml = pyamg.smoothed_aggregation_solver(sparse.csr_matrix(target), symmetry="symmetric")
        finally:
            np.random.set_state(state)
        return ml.aspreconditioner(cycle="V")
    if name in ("two-level", "two-level-2"):
        from pwas_hdl.fit.multigrid import prolongation

        q, coarse = prolongation(system["shape"])
        if name == "two-level-2":
            q2, _ = prolongation(coarse)
            q = sparse.csr_array(q @ q2)
        qt = sparse.csr_array(q.T)
        lu = splinalg.splu(sparse.csc_matrix(qt @ a @ q))
        return splinalg.LinearOperator(shape, matvec=lambda v: v / d + q @ lu.solve(qt @ v), dtype=float)
    raise ValueError(f"unknown preconditioner {name!r}")


def _matvec_cpu(a, repeats: int = 50) -> float:
    v = np.random.default_rng(0).random(a.shape[0])
    c = time.process_time()
    for _ in range(repeats):
        a @ v
    return (time.process_time() - c) / repeats


def run(points, sigmas, t: int, maxiter: int, progress=print, names: tuple[str, ...] | None = None) -> dict:
    """Every (point, order, sigma, preconditioner) of fold 0; see the module docstring.

    ``names``: the preconditioners to run (default all; each order runs those of them that
    :data:`PRECONDITIONERS` lists for it).
    """
    from scipy import sparse
    from scipy.sparse import linalg as splinalg

    from pwas_hdl.fit.regularized_lsq import CG_RTOL

    rows = []
    for n, p in points:
        for order in (0, 1):
            system = fold_system(n, p, t, order)
            for sigma in sigmas:
                a = sparse.csr_array(system["m"] + sigma * system["gamma"])
                base = {"n": n, "p": p, "N": (p + 1) ** n, "order": order, "sigma": sigma, "rows": a.shape[0],
                        "nnz_per_row": a.nnz / a.shape[0], "matvec_cpu_ms": 1e3 * _matvec_cpu(a)}
                for name in (n_ for n_ in PRECONDITIONERS[order] if names is None or n_ in names):
                    c = time.process_time()
                    pre = preconditioner(name, a, system, sigma)
                    setup = time.process_time() - c
                    count = [0]

                    def _cb(_xk, count=count):
                        count[0] += 1

                    c = time.process_time()
                    w, info = splinalg.cg(a, system["b"], rtol=CG_RTOL, atol=0.0, maxiter=maxiter, M=pre, callback=_cb)
                    cg_cpu = time.process_time() - c
                    rel = float(np.linalg.norm(system["b"] - a @ w) / np.linalg.norm(system["b"]))
                    row = {**base, "preconditioner": name, "setup_cpu_s": setup, "iterations": count[0],
                           "cg_cpu_s": cg_cpu, "converged": info == 0, "rel_residual": rel}
                    rows.append(row)
                    progress(f"n={n} p={p} order {order} sigma {sigma:.0e} {name}: {count[0]} iterations"
                             f"{'' if info == 0 else ' (cap)'}, set-up {setup:.2f} s, CG {cg_cpu:.2f} s CPU")
    return {"T": t, "folds": 5, "fold": 0, "rtol": CG_RTOL, "maxiter": maxiter, "rows": rows}


def markdown(res: dict) -> str:
    out = [
        "# CG preconditioners from n = 4 up (issue 18)", "",
        f"CV fold 0 of 5 (T = {res['T']}, the problem of benchmarks/fit_scale.py), each system solved from zero "
        f"to a relative residual of {res['rtol']:g}, at most {res['maxiter']} iterations; CPU seconds.", "",
        "An iteration's CPU is split into the product `A @ v` (timed on its own) and the rest: the preconditioner "
        "and CG's vector updates and dot products.", "",
        "| n | p | order | sigma | rows | entries a row | A @ v (ms) | preconditioner | set-up (s) | iterations | CG (s) "
        "| an iteration (ms) | of it not A @ v (ms) |",
        "|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in res["rows"]:
        its = f"{r['iterations']}" + ("" if r["converged"] else " (cap)")
        per = 1e3 * r["cg_cpu_s"] / r["iterations"] if r["iterations"] else float("nan")
        out.append(f"| {r['n']} | {r['p']} | {r['order']} | {r['sigma']:.0e} | {r['rows']} | {r['nnz_per_row']:.1f} | "
                   f"{r['matvec_cpu_ms']:.2f} | {r['preconditioner']} | {r['setup_cpu_s']:.2f} | {its} | "
                   f"{r['cg_cpu_s']:.2f} | {per:.2f} | {per - r['matvec_cpu_ms']:.2f} |")
    return "\n".join(out) + "\n"


def parse_points(text: str | None, default: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """The ``--points`` option: ``n:p`` pairs, comma-separated, ``n, p >= 2``, at most
    :data:`MAX_VERTICES` vertices a point (``default`` when ``text`` is None).

    Raises
    ------
    pwas_hdl.errors.InputError
        A malformed pair, or a grid over the vertex limit.
    """
    from pwas_hdl.errors import InputError

    if text is None:
        return default
    try:
        points = [tuple(int(v) for v in item.split(":")) for item in text.split(",")]
    except ValueError:
        points = []
    if not points or any(len(pt) != 2 or pt[0] < 2 or pt[1] < 2 for pt in points):
        raise InputError(f"--points takes n:p pairs with n, p >= 2, e.g. 4:17,5:9; got {text!r}")
    if any((p + 1) ** n > MAX_VERTICES for n, p in points):
        raise InputError(f"--points: at most {MAX_VERTICES} vertices ((p + 1)^n) a point; got {text!r}")
    return points


def _parse(args) -> tuple[list[tuple[int, int]], tuple[float, ...], int, int, str, tuple[str, ...] | None]:
    """Points, sigmas, T, iteration cap, file stem and preconditioners from the options; bad values
    raise InputError."""
    from pwas_hdl.errors import InputError

    points, sigmas, t, maxiter, stem = ((QUICK_POINTS, QUICK_SIGMAS, 10_000, 300, "cg_preconditioners_quick")
                                        if args.quick else (POINTS, SIGMAS, 100_000, 3000, "cg_preconditioners"))
    points = parse_points(args.points, points)
    if args.sigmas is not None:
        try:
            sigmas = tuple(float(v) for v in args.sigmas.split(","))
        except ValueError:
            sigmas = ()
        if not sigmas or any(not np.isfinite(v) or v <= 0 for v in sigmas):
            raise InputError(f"--sigmas takes positive numbers, comma-separated, e.g. 1e-2,1e-4; got {args.sigmas!r}")
    if args.maxiter is not None:
        try:
            maxiter = int(args.maxiter)
        except ValueError:
            maxiter = 0
        if not 1 <= maxiter <= 100_000:
            raise InputError(f"--maxiter must be a count from 1 to 100000; got {args.maxiter!r}")
    names = None
    if args.preconditioners is not None:
        known = tuple(dict.fromkeys(PRECONDITIONERS[0] + PRECONDITIONERS[1]))
        names = tuple(v.strip() for v in args.preconditioners.split(","))
        if not names or any(v not in known for v in names):
            raise InputError(f"--preconditioners takes names from {', '.join(known)}, comma-separated; "
                             f"got {args.preconditioners!r}")
    return points, sigmas, t, maxiter, check_stem(args.stem or stem), names


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="T = 10^4, n = 4, p = 5, at most 300 iterations (CI smoke)")
    ap.add_argument("--points", default=None, help="n:p points, comma-separated, n, p >= 2 (default 4:17)")
    ap.add_argument("--sigmas", default=None, help="sigmas, comma-separated (default 1e-2,1e-4)")
    ap.add_argument("--preconditioners", default=None,
                    help="a subset, comma-separated, of " + ", ".join(dict.fromkeys(PRECONDITIONERS[0] + PRECONDITIONERS[1]))
                    + " (default all)")
    ap.add_argument("--maxiter", default=None, help="CG iteration cap (default 3000; --quick 300)")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="output folder")
    ap.add_argument("--stem", default=None, help="output file stem (default cg_preconditioners[_quick])")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    points, sigmas, t, maxiter, stem, names = _parse(args)
    args.outdir.mkdir(parents=True, exist_ok=True)
    res = run(points, sigmas, t, maxiter, progress=lambda m: print(m, flush=True), names=names)
    write_json_and_markdown(args.outdir, stem, res, markdown(res))
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
