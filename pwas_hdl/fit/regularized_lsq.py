"""Tikhonov-regularised least squares for PWAS weights (paper eqs. 14-16) and sigma by CV.

The problem solved is ``min_w  sigma * w' Gamma w + ||z - H w||^2`` with ``sigma`` unnormalised
(the paper's sigma), whose solution is ``w = (H'H + sigma Gamma)^{-1} H'z``. Everything stays
sparse: ``H`` has ``n + 1`` non-zeros per row and ``H'H`` couples only vertices of a common simplex.
"""

from __future__ import annotations

import math
import os
import time
from contextlib import nullcontext
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Callable, Literal, Sequence

import numpy as np
from scipy import sparse
from scipy.sparse import linalg as splinalg

from pwas_hdl.errors import InputError, InternalError, ResourceLimit
from pwas_hdl.fit.blas_threads import single_blas_thread
from pwas_hdl.fit.fork_map import fork_available, fork_map
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.conjugate_gradients import pcg
from pwas_hdl.fit.multigrid import GridHierarchy, grid_shape_of
from pwas_hdl.fit.sparse_cholesky import (
    FactorCounts,
    NotPositiveDefinite,
    OutsidePattern,
    PatternCholesky,
    cholmod_available,
    grid_nested_dissection,
)
from pwas_hdl.limits import MAX_SIGMA_CANDIDATES, check_limit

if TYPE_CHECKING:
    from pwas_hdl.flow.executor import Executor

__all__ = [
    "tikhonov_matrix",
    "NormalEquationSolver",
    "SolveInfo",
    "choose_method",
    "estimate_fit_memory",
    "check_fit_memory",
    "plan_fit_memory",
    "memory_limit",
    "DIRECT_MAX_UNKNOWNS",
    "MG_DOMINANCE",
    "MG_MIN_UNKNOWNS",
    "MG_BLOCK_MIN_DIRECT",
    "block_cycle_used",
    "MG_DOMINANCE_CG",
    "MG_AUTO_DIMS",
    "CG_RTOL",
    "AMG_MIN_SIDE",
    "amg_allowed",
    "FACTOR_PCG_MAXITER",
    "GRID_FACTOR_BOUND",
    "grid_factor_bound",
    "FACTOR_PCG_SEGMENT",
    "FACTOR_DOMINANCE_CG",
    "FACTOR_PCG_MAXITER_CG",
    "FACTOR_CHAIN_DIMS",
    "FACTOR_CHAIN_FILL",
    "FORK_MIN_UNKNOWNS",
    "solve_regularized",
    "solve_report",
    "solve_warnings",
    "RESIDUAL_CHECK",
    "cross_validate_sigma",
    "CVResult",
    "DEFAULT_SIGMA_GRID",
]

#: Default candidate values of sigma for cross-validation (unnormalised, as in the paper).
DEFAULT_SIGMA_GRID: np.ndarray = np.logspace(-7, 3, 21)

#: Relative weight of the identity added to the first-order penalty so that Gamma is
#: positive definite (the gradient penalty alone vanishes on constant functions).
FIRST_ORDER_RIDGE = 1e-6


def tikhonov_matrix(grid: Grid, order: int = 0) -> sparse.csc_array:
    """Tikhonov regularisation matrix Gamma (N x N, sparse, symmetric positive definite).

    Parameters
    ----------
    grid : Grid
        The partition whose vertices carry the weights.
    order : {0, 1}
        ``0``: ``Gamma = I`` (zero-order Tikhonov).
        ``1``: gradient penalty. For every grid edge ``(a, a + e_j)`` parallel to axis ``j`` the
        difference quotient ``(w_{a+e_j} - w_a) / h_j`` is a partial derivative of the PWAS function
        on the simplices that contain the edge, so
        ``w' Gamma w = sum_j sum_edges ((w_{a+e_j} - w_a) / h_j)^2 * V_cell  +  eps * ||w||^2``
        with ``h_j`` the physical interval width and ``V_cell = prod(h_j)`` (the graph Laplacian
        of the vertex grid scaled per dimension, a Riemann sum of the squared gradient norm).
        ``eps = FIRST_ORDER_RIDGE * mean(diag(Laplacian))`` keeps Gamma positive definite.

    Returns
    -------
    scipy.sparse.csc_array, shape (N, N)
    """
    n_v = grid.n_vertices
    if order == 0:
        return sparse.identity(n_v, format="csc")
    if order != 1:
        raise InputError(f"Tikhonov order must be 0 or 1, got {order!r}")
    cell_volume = float(np.prod(grid.step))
    # built directly in CSC form (symmetric: column i = row i), one entry per (row, column) in
    # sorted row order i - s_0 < ... < i - s_{n-1} < i < i + s_{n-1} < ... < i + s_0 (C order: the
    # strides s_j decrease); the diagonal accumulates each vertex's edge weights axis by axis, as
    # the edge's end ``a`` then as its end ``b`` (adding 0.0 where it is not one), the order in
    # which summing the per-edge 2 x 2 blocks adds them. Measured at N = 10^6 (n = 2): 0.2 s
    # instead of 1.0-1.3 s through the 8 * N-entry COO form of those blocks, and ~1 s (fifth pass,
    # loaded machine) through a COO form with one entry per (row, column)
    n, idx = grid.n, np.arange(n_v, dtype=np.int64)
    strides = np.asarray(grid.strides, dtype=np.int64)
    shape = np.asarray(grid.partitions, dtype=np.int64) + 1
    rows = np.empty((n_v, 2 * n + 1), dtype=np.int64)
    vals = np.empty((n_v, 2 * n + 1))
    keep = np.ones((n_v, 2 * n + 1), dtype=bool)
    diag = np.zeros(n_v)
    for j in range(n):
        coord = (idx // strides[j]) % shape[j]
        wgt = cell_volume / grid.step[j] ** 2
        diag += np.where(coord < shape[j] - 1, wgt, 0.0)  # as the edge's end a (to a + e_j)
        diag += np.where(coord > 0, wgt, 0.0)  # as its end b (from a - e_j)
        rows[:, j], vals[:, j], keep[:, j] = idx - strides[j], -wgt, coord > 0
        k = 2 * n - j
        rows[:, k], vals[:, k], keep[:, k] = idx + strides[j], -wgt, coord < shape[j] - 1
    eps = FIRST_ORDER_RIDGE * float(diag.mean()) if diag.size and diag.mean() > 0 else FIRST_ORDER_RIDGE
    rows[:, n], vals[:, n] = idx, diag + eps
    indptr = np.concatenate([[0], np.cumsum(keep.sum(axis=1))]).astype(np.int64)
    return sparse.csc_array((vals[keep], rows[keep], indptr), shape=(n_v, n_v))


# ------------------------------------------------------------------ solver choice and bounds
#: ``method="auto"`` uses the sparse direct solve while the system has at most
#: ``DIRECT_MAX_UNKNOWNS[(order, min(n, 5))]`` unknowns (``n`` the regressor dimension; zero-order
#: problems are first reduced, exactly, to the data-supported vertices) and preconditioned
#: conjugate gradients above. The fill-in of the factor grows with ``n`` (separators of an
#: ``n``-dimensional grid) and with the first-order penalty, which couples every vertex to its grid
#: neighbours, while a zero-order ``H'H`` couples only vertices of simplices that hold data.
#: Measured on this project's shared 2-core machine (SuperLU, symmetric mode, T = 10^5, CPU s per
#: factorisation): n = 2 order 0, N = 10^6 (243 558 supported): 0.2 s; n = 2 order 1, N = 40 000:
#: 0.2 s, N = 10^6: ~25 s; n = 3, N = 32 768: 1.7 s (order 0), 4.3 s (order 1); n = 3 order 0,
#: N = 262 144: 5.3 s. In 4 to 6 dimensions ``H'H`` itself is nearly dense once T >> N (a vertex
#: shares simplices with up to 3^n - 1 others): n = 6, N = 4096, T = 10^5: fit with CV over 150 s
#: direct, 0.3 s CPU for 21 Jacobi-CG solves. The key is ``(order, min(n, 5))``.
DIRECT_MAX_UNKNOWNS: dict[tuple[int, int], int] = {
    (0, 1): 10_000_000,
    (0, 2): 2_000_000,
    (0, 3): 300_000,
    (0, 4): 5_000,
    (0, 5): 2_000,
    (1, 1): 1_000_000,
    (1, 2): 50_000,
    (1, 3): 20_000,
    (1, 4): 2_000,
    (1, 5): 2_000,
}

#: Zero order, ``auto``, CHOLMOD, where :data:`DIRECT_MAX_UNKNOWNS` picks CG: the full-data system
#: (``H'H`` on the touched vertices plus ``sigma I``; every fold's pattern is part of it) is analysed
#: first (CHOLMOD's symbolic analysis, :meth:`~pwas_hdl.fit.sparse_cholesky.PatternCholesky.counts`)
#: and factorised instead when its factor costs at most this many multiply-adds per non-zero of the
#: matrix's lower triangle (and fits the memory left, :class:`NormalEquationSolver` ``direct_headroom``):
#: about what 100 CG iterations cost. The fill of a zero-order factor depends on how the samples
#: connect the vertices, not only on their number: at N = 10^6 in 4-D (T / N = 0.1) the touched
#: vertices stay in loosely joined pieces, in 5-D and 6-D, or at T / N >= 1, they do not. Measured
#: (T = 10^5, CHOLMOD, one BLAS thread; flops / nnz, numeric CPU s, CG iterations of the same cost at
#: ~2.4 ns per non-zero of ``A``): n = 4, N = 1 048 576: a fold's 584, 0.087 s (~18), the full data's
#: 1.0e4 (~50), where CG stops at its cap of 2000 unconverged at the smallest sigmas; n = 4, N = 10 000:
#: 5.1e4, 0.11 s (~250; CG needs 293 on average there); n = 6, N = 15 625: 2.3e5, 1.2 s (~840); n = 4,
#: N = 104 976: 9.4e5, 6.9 s; n = 5, N = 1 048 576: 1.1e6, 18.5 s; n = 6, N = 10^6: 2.3e7 (lnz 1.4e9,
#: out of memory). In 2-D and 3-D, where the table picks the direct method anyway, 38 (n = 2,
#: N = 99 856) and 5.8e3 (n = 3, N = 262 144).
DIRECT_FLOPS_PER_ENTRY = 2e4

#: The ``auto`` limits where CHOLMOD is available (:mod:`pwas_hdl.fit.sparse_cholesky`; the table
#: above is SuperLU's). Only first order in 2-D moves: measured at n = 2, N = 10^6, T = 10^5 (one
#: BLAS thread, CPU s): 1.2-1.6 s per numeric factorisation and 0.15 s per solve, while
#: preconditioned CG at that size took over 150 s for the CV (Jacobi/AMG) and, with the factor of
#: the neighbouring sigma as preconditioner, 14-15 iterations = 2.2-2.4 s per sigma. In 3-D first
#: order the factor stays too dense (48 s per factorisation at N = 262 144, 12.7 s with a nested
#: dissection ordering; 45.8 s on the full-data pattern shared by the folds), so CG is kept there.
#: Solving the other sigmas from a neighbour's factor (PCG, multi-shift Lanczos) or reducing to the
#: touched vertices was measured and does not pay (``benchmarks/results/fit_scale_notes.md``).
DIRECT_MAX_UNKNOWNS_CHOLMOD: dict[tuple[int, int], int] = {**DIRECT_MAX_UNKNOWNS, (1, 2): 2_000_000}

#: First order, ``method="auto"``: a system ``(M + sigma Gamma) w = b`` whose penalty dominates its
#: data term, ``rho = sigma * mean(diag Gamma) / mean(rowsum M) >= MG_DOMINANCE`` (``mean(rowsum M)``
#: is the training samples per vertex, ``T_k / N``, as every row of ``H`` sums to 1), is solved by
#: conjugate gradients preconditioned by one geometric-multigrid V-cycle
#: (:mod:`pwas_hdl.fit.multigrid`) instead of a sparse factorisation; below it by the direct solve
#: (where :func:`choose_method` picks it), since there the V-cycle misses the smooth error that the
#: data term leaves nearly unpenalised (the iterations grow like ``rho ** -0.45``). Measured, one
#: fold, T = 10^5, rtol 1e-10, warm starts, CPU (``benchmarks/results/fit_scale_notes.md``): n = 2,
#: N = 10^6 (rho = 50 sigma): 8-10 iterations (0.5-0.65 s) for rho >= 5, 12 (0.71 s) at rho = 1.6,
#: 19 (1.13 s) at 0.5, 34 (2.1 s) at 0.16, 151 at 0.005, against 1.5-1.9 s per CHOLMOD
#: factorisation; n = 3, N = 262 144 (rho = 0.75 sigma): 9-10 iterations (0.2 s) for rho >= 7,
#: 12 at 0.75, 17 at 0.24, 28 at 0.075, 228 at 0.00075 (one CHOLMOD factorisation there: 46 s). The
#: cross-over in 2-D lies between rho = 0.16 and 0.5; 0.3 is taken. Where the direct solve is not
#: picked (too large) the base method is Jacobi-CG and the threshold :data:`MG_DOMINANCE_CG`.
MG_DOMINANCE = 0.3

#: The same cross-over against Jacobi-preconditioned CG, the base method where the direct solve is
#: not picked (n = 3, N = 262 144, T = 10^5, one fold, CPU: a multigrid-PCG iteration ~20 ms, a
#: Jacobi one ~3.6 ms): multigrid 12 / 28 / 47 / 228 iterations at rho = 0.75 / 0.075 / 0.024 /
#: 0.00075 against Jacobi's 166 / 190 / 203 / 663, i.e. 0.23 / 0.56 / 0.94 / 4.5 s against
#: 0.6 / 0.7 / 0.7 / 2.4 s: the cross-over lies between rho = 0.024 and 0.075.
MG_DOMINANCE_CG = 0.05

#: First order with multigrid (``auto`` or ``mg``, the data-block smoother on, the default; ``auto``
#: on a direct base method only from :data:`MG_BLOCK_MIN_DIRECT` unknowns): the sigmas of a fold with ``rho < MG_BLOCK_DOMINANCE[min(n, 3)]`` (``rho`` as in :data:`MG_DOMINANCE`,
#: ``n`` the regressor dimension) are solved by the V-cycle whose fine level is smoothed by the exact
#: data block ``M_TT + sigma diag(Gamma)_TT`` and Gauss-Seidel
#: (:class:`~pwas_hdl.fit.multigrid.DataBlockSmoother`, :meth:`~pwas_hdl.fit.multigrid.FoldMultigrid.vcycle_block`),
#: every other sigma by the Gauss-Seidel V-cycle alone; no sigma is factorised with ``Gamma``'s grid
#: edges (only a CG solve that stops at :data:`MG_BLOCK_MAXITER` is re-done so). Measured (fold 0,
#: T = 10^5, one BLAS thread, CPU s a sigma, warm-started from the next larger grid sigma, rtol
#: 1e-10), data-block against Gauss-Seidel cycle: n = 3, N = 262 144 at rho = 0.74 / 0.23 / 0.074 /
#: 0.023: 0.75 / 0.86 / 0.83 / 0.77 against 0.21 / 0.30 / 0.49 / 0.83 (11 iterations each against 12
#: / 17 / 28 / 47; the block cycle's iterations stay at 1-15 down to sigma = 1e-7, where Gauss-Seidel
#: needs > 4000); n = 2, N = 10^6 at rho = 5 / 1.6 / 0.5 / 0.16: 0.78 / 0.85 / 0.98 / 0.91 against
#: 0.66 / 0.79 / 1.16 / 1.97 (Gauss-Seidel 10 / 12 / 19 / 34 iterations, > 500 below rho ~ 0.005).
#: The cross-over lies near rho = 0.025 in 3-D and 1 in 2-D (a block solve is dearer against a
#: V-cycle in 3-D: its factor has more fill); 1-D takes the 2-D value, 4-D and up the 3-D one (not
#: measured).
MG_BLOCK_DOMINANCE: dict[int, float] = {1: 1.0, 2: 1.0, 3: 0.05, 4: 0.4}

#: First order, ``auto``, from this regressor dimension on (outside :data:`MG_AUTO_DIMS`, where CG alone
#: is the rule): multigrid with the data-block cycle is used where the data block of the full data
#: factorises cheaply, by the symbolic analysis and the threshold of :data:`DIRECT_FLOPS_PER_ENTRY`
#: (and fits the memory left); the block's fill, not the grid, is what decides. Measured (n = 4,
#: N = 1 048 576, T = 10^5, fold 0, one BLAS thread, CPU s a sigma, iterations; warm-started down):
#: Jacobi-CG 6.1 (311) / 2.6 (138) / 3.2 (162) / 19.6 (1011) / 40.6 (2000, unconverged) / 1.4 (65) at
#: sigma = 1e3 / 10 / 0.1 / 1e-3 / 1e-5 / 1e-7, multigrid 2.7 (11, with the levels' set-up) / 1.05 (12)
#: / 2.1 (12, block) / 1.7 (8) / 0.35 (1) / 0.36 (1); the block against the Gauss-Seidel cycle at rho =
#: 0.063 / 0.2 / 0.63 / 6.3: 2.1 / ~2.1 / 2.1 / 2.3 s against 5.0 / 2.8 / 1.7 / 1.05 s (the 4-D value of
#: :data:`MG_BLOCK_DOMINANCE`, 0.4). At n = 5, N = 1 048 576 the block costs 20-28 s a sigma (its
#: factor: 18.5 s), and the analysis keeps CG alone there and wherever T / N >= 1 from n = 4 up.
MG_BLOCK_ANALYSED_DIMS = (4,)

#: First order, ``auto``, where the base method is the direct one (CHOLMOD in 2-D, see
#: :data:`DIRECT_MAX_UNKNOWNS_CHOLMOD`): the data-block cycle of :data:`MG_BLOCK_DOMINANCE` is used
#: only from this many unknowns; below, the data-dominated sigmas are factorised (with factor-PCG,
#: :data:`FACTOR_PCG_MAXITER`), as with ``block_smoother=False``. A factorisation of the 2-D grid costs
#: about ``N^1.5`` (nested-dissection separators), a data-block solve about ``N`` times its ~10
#: iterations. Measured (``fit_scale.py --workers 2``, T = 10^5, the same hour, wall / CPU s of the
#: whole first-order fit, data block against factorisations): N = 99 856: 4.7 / 9.0 against
#: 4.1 / 7.8; N = 160 000: 6.4 / 12.2 against 6.4 / 12.3; N = 250 000: 9.5 / 17.8 against
#: 10.0 / 19.2; serially, one fold's data-dominated sigma at N = 99 856 0.1 s against 0.068 s.
MG_BLOCK_MIN_DIRECT = 150_000


def block_cycle_used(unknowns: int, method: str, chosen: str, use_mg: bool, block_smoother: bool = True) -> bool:
    """True when a first-order fit solves its data-dominated sigmas by the data-block cycle.

    Parameters
    ----------
    unknowns : int
        Weights solved for (the vertex count ``N``).
    method : {"auto", "direct", "cg", "mg"}
        The method asked for.
    chosen : str
        The base method :func:`choose_method` picks for this size.
    use_mg : bool
        Whether the fit uses multigrid at all (first order on a vertex grid of the sizes and
        dimensions of :data:`MG_MIN_UNKNOWNS` and :data:`MG_AUTO_DIMS`, or ``method="mg"``).
    block_smoother : bool
        The caller's switch (``False``: never).

    Returns
    -------
    bool
        ``use_mg`` and ``block_smoother`` with ``method`` ``auto`` or ``mg``, except ``auto`` on a
        direct base method below :data:`MG_BLOCK_MIN_DIRECT` unknowns.
    """
    if not (use_mg and block_smoother and method in ("auto", "mg")):
        return False
    return not (method == "auto" and chosen == "direct" and int(unknowns) < MG_BLOCK_MIN_DIRECT)


#: Iteration cap of a data-block multigrid-PCG solve (measured at most 15; a solve that hits the cap
#: is re-done by the direct method, see :data:`MG_BLOCK_DOMINANCE`).
MG_BLOCK_MAXITER = 200

#: Multigrid is used by ``auto`` from this many unknowns (below, a factorisation takes well under
#: a second: measured 0.8 s CPU for the whole first-order CV at n = 2, N = 10^4).
MG_MIN_UNKNOWNS = 50_000

#: Regressor dimensions in which ``auto`` uses multigrid: those measured. In 1-D the factor is
#: banded and cheaper than any V-cycle; from 4-D the prolongation has 2^n and the coarse levels up
#: to 3^n entries a row (not measured; ``method="mg"`` still works there).
MG_AUTO_DIMS = (2, 3)

#: First order, direct base method (CHOLMOD), ``auto``, at least :data:`FACTOR_PCG_MIN_UNKNOWNS` unknowns:
#: the data-dominated sigmas of a fold (those not solved by multigrid) are swept from the smallest
#: up; the smallest is factorised and each next one solved by CG preconditioned with the fold's
#: last factor (of a smaller sigma), warm-started from the previous sigma's weights, with at most
#: this many iterations (the stopping rule and weight bound of :data:`CG_RTOL` unchanged). The cap
#: is the measured cost of a factorisation plus its solve in PCG iterations (n = 2, N = 10^6,
#: T = 10^5, one fold, CPU: 1.6-2.5 s + 0.17 s against 0.17-0.21 s an iteration: ~10). The fold
#: refactorises, and makes no further attempt, as soon as an attempt hits the cap or the previous
#: one needed more than half of it (the count grows with every grid step away from the factor's
#: sigma: from the factor at 1e-7, warm started, 3 / 6 / 9 / 13 / 19 iterations at 10^-6.5 /
#: -6 / -5.5 / -5 / -4.5; one step above a factor at 1e-5 / 1e-4 / 1e-3: 10 / 12 / 14, above the
#: break-even). So it pays only where ``H'H``'s null space makes the preconditioned spectrum two
#: clusters (the smallest sigmas).
FACTOR_PCG_MAXITER = 10

#: Factor-PCG (:data:`FACTOR_PCG_MAXITER`) on a direct base method from this many unknowns. A
#: factorisation of the 2-D grid costs about ``N^1.5``, a PCG iteration with it about ``N log N``, so
#: the iterations a factorisation is worth shrink with ``N``: at N = 99 856 (T = 10^5, one fold, serial
#: CPU) a factorisation and its solve take 0.067 s and a PCG iteration 15 ms, while the attempt next to
#: the chain's first factor needs 10-11 iterations (0.15 s; then it stops at the cap and refactorises:
#: 0.74 s for the five folds' sigma = 10^-6.5 against 0.34 s by factorisation alone); at N = 250 000 the
#: chain's sigmas took 1.19 s against 1.09 s factorised; at N = 10^6 it pays (3 / 6 / 9 iterations at
#: 0.17-0.21 s against 1.6-2.5 s a factorisation). Below, every data-dominated sigma is factorised.
FACTOR_PCG_MIN_UNKNOWNS = 500_000

#: A fold's sweep by CG alone (method ``cg`` without the factor chain: ``auto`` from n = 4 up) is
#: cut into this many warm-started chains of consecutive sigmas (largest down, by count), so that
#: the forked workers of :func:`cross_validate_sigma` get ten or more tasks of unequal cost rather
#: than five equal ones (two workers then finish within a short chain of each other instead of one
#: fold). Measured at n = 4, N = 104 976, first order, fold 0 (CPU): the seven smallest sigmas
#: 26 s, the seven middle ones 4.7 s, the seven largest 3.5 s.
CG_SEGMENTS = 3

#: For the longest-first order of those chains: a Jacobi/AMG-CG sigma costs about
#: ``1 / sqrt(max(rho, CG_COST_RHO_FLOOR))`` (CG iterations grow like the square root of the
#: condition number, about ``1 / rho``; ``rho = sigma mean(diag Gamma) / mean(rowsum H'H)``), the
#: floor standing for :data:`CG_MAXITER` (measured at n = 4, N ~ 10^5: 2000 iterations from rho
#: ~ 1e-5 down, in both orders).
CG_COST_RHO_FLOOR = 1e-5

#: The factor-PCG chain of a fold (:data:`FACTOR_PCG_MAXITER`) covers only its this many smallest
#: data-dominated sigmas; every larger one is factorised in a segment of its own
#: (:meth:`NormalEquationSolver.sweep_segments`), a task that any worker process can take
#: (:func:`cross_validate_sigma`). Measured (n = 2, N = 10^6, T = 10^5, warm-started from the
#: factor at 1e-7): 3 / 6 / 9 / 13 iterations at 10^-6.5 / -6 / -5.5 / -5, so the chain's rule
#: (stop once an attempt needs more than half the cap) ends it by the third or fourth sigma anyway.
FACTOR_PCG_SEGMENT = 4

#: First order, base method Jacobi-CG (the direct solve not picked: n = 3, N = 262 144), ``auto``,
#: CHOLMOD, at least :data:`MG_MIN_UNKNOWNS` unknowns, n in :data:`FACTOR_CHAIN_DIMS`: the sigmas of
#: a fold with ``rho < FACTOR_DOMINANCE_CG`` (``rho`` as in :data:`MG_DOMINANCE`) are the *factor
#: chain*: swept from the smallest up, the smallest factorised by CHOLMOD with the geometric
#: nested-dissection ordering (:func:`~pwas_hdl.fit.sparse_cholesky.grid_nested_dissection`), each
#: next one by CG preconditioned with that factor and warm-started from the previous sigma (at most
#: :data:`FACTOR_PCG_MAXITER_CG` iterations; the rule of :data:`FACTOR_PCG_MAXITER` otherwise). There
#: Jacobi-CG needs the most iterations and stops at the cap (2000) unconverged. Measured (n = 3,
#: p = 63, T = 10^5, fold 0, one BLAS thread, CPU s): Jacobi-CG warm-started downwards 914 / 1492 /
#: 2418 / > 4000 iterations (3.4 / 6.1 / 8.3 / > 15 s) at sigma = 3.2e-4 / 1e-4 / 3.2e-5 / 1e-5;
#: the factor at 1e-7 14.3 s (symbolic 1.0 s, solve 0.26 s), then factor-PCG 3 / 4 / 5 / 9 / 14 / 21
#: / 36 / 63 iterations (~0.245 s each) at 10^-6.5 / -6 / -5.5 / -5 / -4.5 / -4 / -3.5 / -3. So
#: 1e-4 (rho ~ 7.5e-5: 5.2 s by PCG, 6.1 s by Jacobi) is in the chain, 3.2e-4 (rho ~ 2.4e-4: 8.7 s
#: against 3.4 s) is not: the threshold lies between, 1.5e-4 is taken.
FACTOR_DOMINANCE_CG = 1.5e-4

#: Iteration cap of a factor-PCG attempt in the factor chain of :data:`FACTOR_DOMINANCE_CG`: the
#: cost of one nested-dissection factorisation plus its solve in PCG iterations (n = 3, N = 262 144:
#: 14.3 + 0.26 s against ~0.245 s an iteration, ~60); the chain refactorises once an attempt hits
#: the cap or the previous one needed more than half of it (the 2-D rule, :data:`FACTOR_PCG_MAXITER`).
FACTOR_PCG_MAXITER_CG = 60

#: Regressor dimensions where the factor chain of :data:`FACTOR_DOMINANCE_CG` is used: those
#: measured (in 4-D and up the nested-dissection separators of a grid, and so the factor, grow faster).
FACTOR_CHAIN_DIMS = (3,)

#: Fill factor ``nnz(L) / nnz(A)`` of the factor chain's nested-dissection factor for
#: :func:`estimate_fit_memory` (``nnz(A)`` as estimated there): measured n = 3, N = 262 144,
#: T = 10^5: 1.8-1.95 GiB resident for the factor, ~48 x 12 bytes per estimated entry of ``A``.
FACTOR_CHAIN_FILL = 50.0

#: :func:`cross_validate_sigma` with an executor of ``workers >= 2`` local processes (no scheduler)
#: runs the folds' sigma sweeps on that many *forked* processes (:mod:`pwas_hdl.fit.fork_map`:
#: the data are inherited, not pickled) from this many unknowns; below, the existing path (Dask
#: tasks) is kept: there a fold costs well under a second and a worker's start-up more.
FORK_MIN_UNKNOWNS = 50_000

#: Relative residual at which conjugate gradients stop: ``||b - A w|| <= CG_RTOL * ||b||``.
#: Since ``A = H'H + sigma Gamma >= sigma * lambda_min(Gamma) I`` this guarantees
#: ``||w - w_direct||_2 <= CG_RTOL * ||b||_2 / (sigma * lambda_min(Gamma))`` (the *weight bound*,
#: reported per solve in :class:`SolveInfo`); ``lambda_min(Gamma) = 1`` for order 0 and
#: ``FIRST_ORDER_RIDGE * mean(diag(Laplacian))`` for order 1.
CG_RTOL = 1e-10

#: Iteration cap of one CG solve. A solve that hits it is re-done by the direct method when the
#: system has at most ``FALLBACK_FACTOR`` times the ``auto`` limit of unknowns or the factor chain of
#: :data:`FACTOR_DOMINANCE_CG` is used (then by its nested-dissection factorisation), and otherwise
#: reported as not converged (:attr:`SolveInfo.converged`, ``CVResult.solver["all_converged"]``).
CG_MAXITER = 2000

#: See :data:`CG_MAXITER`.
FALLBACK_FACTOR = 4

#: First-order problems use the AMG preconditioner when the penalty dominates the data term,
#: ``sigma * mean(diag Gamma) >= AMG_DOMINANCE * mean(diag H'H)`` (a scaled Laplacian, for which
#: AMG is made: measured 11 instead of 2290 Jacobi iterations at N = 10^6, n = 2, sigma = 100),
#: and Jacobi otherwise (an AMG V-cycle costs ~20 Jacobi iterations here, and at small sigma the
#: lumped surrogate is no better than the diagonal: measured at n = 3, N = 9261).
AMG_DOMINANCE = 10.0

#: ... and only on a vertex grid whose longest axis has at least this many vertices (or whose shape
#: :func:`~pwas_hdl.fit.multigrid.grid_shape_of` cannot tell, as before). Jacobi-CG needs about 4 to
#: 14 times the longest side in iterations on the penalty-dominated system, an AMG V-cycle costs
#: 18-26 Jacobi iterations and the solve takes 8-13 of them plus the hierarchy's build. Measured
#: (``benchmarks/cg_preconditioners.py --preconditioners jacobi,amg-lumped``, T = 10^5, CV fold 0,
#: sigma = 100 and 1000, cold, set-up + CG CPU, 2026-12-03): Jacobi cheaper at every point of n = 4
#: (sides 18, 32), 5 (10, 16), 6 (7, 10), n = 3 (sides 32 and 64; at 64 1.59 / 1.09 s against 2.04 /
#: 1.52 s) and n = 2 side 64; AMG cheaper from n = 2 side 128 (0.06 against 0.08 s) and 256 (0.29
#: against 0.69 s). Under ``auto`` only n >= 4 solves by CG alone, whose grids of at most 2 million vertices
#: have sides under 128; n = 2 and 3 solve their penalty-dominated sigmas by multigrid.
AMG_MIN_SIDE = 128


def amg_allowed(grid_side: int | None) -> bool:
    """True when the first-order CG preconditioner may be AMG (:data:`AMG_MIN_SIDE`).

    Parameters
    ----------
    grid_side : int or None
        Vertices on the longest axis of the vertex grid; None when unknown (then allowed).

    Returns
    -------
    bool
        ``grid_side is None or grid_side >= AMG_MIN_SIDE``.
    """
    return grid_side is None or int(grid_side) >= AMG_MIN_SIDE

#: The algebraic-multigrid hierarchy of the preconditioner serves a band of sigmas of this ratio
#: (built at the band's geometric middle: the preconditioned spectrum then lies within
#: ``[1 / sqrt(ratio), sqrt(ratio)]`` of the one it was built for, see :class:`_Preconditioner`).
AMG_REUSE_RATIO = 10.0

#: Seed of numpy's global generator while pyamg builds a hierarchy (see :class:`_Preconditioner`).
AMG_SEED = 0

#: Bytes of the AMG preconditioner of a first-order CG solve for :func:`estimate_fit_memory`, in
#: units of the estimated sparse ``A`` (``nnz(H'H) + nnz(Gamma)`` entries as estimated there): the
#: lumped surrogate, the hierarchy and pyamg's transient while it builds. Measured (the peak resident
#: set's growth over one build, T = 10^5, first order, 2026-12-03): 750 / 965 / 1144 MiB at n = 4 / 5 /
#: 6, N ~ 10^6 (the hierarchy alone 2.5-2.7 times the real ``A``), that is 5.2 / 5.3 / 5.4 estimated
#: ``A``; 1.9-2.2 at N ~ 10^5. The largest with a 20 % margin. (Charged before: 2, and the fits at
#: N ~ 10^6 measured 2786 / 3209 / 4075 MiB PSS with two workers against 1811 / 2217 / 2571 estimated.)
AMG_MEMORY_FACTOR = 6.5

#: The transient of forming a sigma's matrix ``M + sigma Gamma`` (the scaled copy of ``Gamma`` and the
#: sum's work arrays, while ``M`` and the sum are held), in units of the bytes of ``Gamma``, for
#: :func:`estimate_fit_memory`, each solving process. Measured (tracemalloc peak over the held
#: result, first order, T = 10^5, 2026-12-03): 1.35-1.36 at n = 4 (N ~ 10^5 and 10^6), 5 and 6
#: (N ~ 10^6); with a margin. (It was uncharged; the AMG charge hid it until AMG_MIN_SIDE: the
#: Jacobi-CG fits at N ~ 10^6 then measured 1370 MiB PSS at n = 4 against 1265 estimated.)
SHIFT_TRANSIENT_FACTOR = 1.5

#: Bytes each further forked CV worker holds beyond its solver state in :func:`estimate_fit_memory`
#: (pages copied on write, the allocator's arenas): measured ~110 MiB not in the estimate with the
#: factors held one at a time (n = 3, N = 262 144, first order, 2 workers: 2849 MiB PSS against
#: 2740 MiB estimated without this term, 2026-12-02); 128 MiB per worker.
FORK_WORKER_OVERHEAD = 128 * 2**20

#: Peak bytes a weight costs when the model file is written (its Python float, the JSON text and
#: its UTF-8 copy; measured 137 bytes a weight for 10^6 weights, numpy 2.4, CPython 3.11).
MODEL_TEXT_BYTES_PER_WEIGHT = 140

#: Environment variable with the memory limit in bytes (suffixes K, M, G accepted).
MAX_MEMORY_ENV = "PWAS_HDL_MAX_MEMORY"

#: Default memory limit: this fraction of ``MemAvailable`` in /proc/meminfo.
MEMORY_FRACTION = 0.8

#: Pessimistic fill factor of the direct factorisation (``nnz(L + U) / nnz(A)``; measured 17-25 on
#: the grids of this project) used by :func:`estimate_fit_memory`.
DIRECT_FILL_FACTOR = 40.0

#: Grid bound of the CHOLMOD factor for :func:`estimate_fit_memory` (regressor dimension ``n`` ->
#: ``(C, e, B, U0)``): ``nnz(L) <= C * U * log2(U)`` in 2-D and ``C * U**e`` above (the
#: nested-dissection fill of an ``n``-dimensional grid graph: ``U log U``, ``U**(4/3)``; ``U`` the
#: unknowns), held in ``B`` bytes an entry of ``L`` plus ``U0`` bytes an unknown (the symbolic
#: analysis: 190-330 measured). The estimate takes the smaller of this and the
#: ``DIRECT_FILL_FACTOR`` rule, which overstates the 2-D factors 3-20-fold. Measured (one CV fold,
#: uniform data on a grid 1.2 x wider, T = 10^5 and 3 x 10^5, orders 0 and 1, CHOLMOD's own
#: ordering or the nested dissection of the factor chain, symbolic and numeric resident set,
#: 2026-12-02): beyond ``U0 * U``, 18.5-42.3 bytes per ``U log2 U`` at n = 2 (U = 45 793 .. 10^6;
#: ``nnz(L) / (U log2 U)`` 0.13-3.37) and 104-156 bytes per ``U**(4/3)`` at n = 3 (U = 21 782 ..
#: 262 144; ``nnz(L) / U**(4/3)`` 0.8-13.3). ``C * B`` is the largest with a 20 % margin (51, 192);
#: dimensions not measured keep the fill rule alone.
GRID_FACTOR_BOUND: dict[int, tuple[float, float, float, float]] = {
    2: (4.25, 1.0, 12.0, 330.0),
    3: (16.0, 4.0 / 3.0, 12.0, 330.0),
}

Method = Literal["auto", "direct", "cg", "mg"]


@dataclass
class SolveInfo:
    """How one system ``(H'H + sigma Gamma) w = b`` was solved.

    Attributes
    ----------
    method : {"direct", "cg", "mg", "mg-block", "factor-pcg", "direct-fallback"}
        ``mg``: CG preconditioned by a geometric-multigrid V-cycle (:mod:`pwas_hdl.fit.multigrid`).
        ``mg-block``: the same with the data-block cycle (:data:`MG_BLOCK_DOMINANCE`).
        ``direct-fallback``: CG did not converge within :data:`CG_MAXITER`, the direct solve was used.
        ``factor-pcg``: CG preconditioned by the CHOLMOD factor of another sigma of the same fold
        (see :data:`FACTOR_PCG_MAXITER`).
    iterations : int
        CG iterations (summed over target columns); 0 for the direct solve.
    rel_residual : float
        Largest ``||b - A w|| / ||b||`` over the target columns (computed afresh, not CG's estimate).
    weight_bound : float
        Guaranteed bound on ``max_col ||w - w_exact||_2`` from the residual:
        ``||r|| / (sigma * lambda_min(Gamma))``.
    converged : bool
    """

    method: str
    iterations: int = 0
    rel_residual: float = 0.0
    weight_bound: float = 0.0
    converged: bool = True

    def to_dict(self) -> dict:
        """The attributes as plain JSON types.

        Returns
        -------
        dict
            ``method`` (str), ``iterations`` (int), ``rel_residual`` and ``weight_bound`` (float),
            ``converged`` (bool).
        """
        return {
            "method": self.method,
            "iterations": int(self.iterations),
            "rel_residual": float(self.rel_residual),
            "weight_bound": float(self.weight_bound),
            "converged": bool(self.converged),
        }


def gamma_min_eigenvalue(gamma: sparse.sparray) -> float:
    """Gershgorin lower bound on the smallest eigenvalue of a symmetric Gamma.

    ``min_i (Gamma_ii - sum_{j != i} |Gamma_ij|)``, clipped at 0. Rigorous for any symmetric
    matrix, and exact for the matrices of :func:`tikhonov_matrix`: 1 for order 0, the ridge
    ``eps`` for order 1 (the Laplacian part is diagonally dominant with zero row sums and has the
    constants in its null space, so ``lambda_min(L + eps I) = eps``).
    """
    g = sparse.csr_array(gamma)
    if g.shape[0] == 0:
        return 1.0
    diag = g.diagonal()
    off = np.asarray(abs(g).sum(axis=1)).reshape(-1) - np.abs(diag)
    return max(float((diag - off).min()), 0.0)


#: Smallest memory limit accepted: below it no fit can run (the interpreter and its libraries alone
#: take far more), so ``PWAS_HDL_MAX_MEMORY=1K`` is refused as a mistake instead of refusing every fit.
MIN_MEMORY_LIMIT = 2**20


def size_text(nbytes: float) -> str:
    """A memory size for a message: MiB from 1 MiB (one decimal below 10 MiB, unless whole), KiB or
    bytes below (never "0 MiB", nor "needs 1 MiB, over the limit of 1 MiB")."""
    if nbytes >= 10 * 2**20 or (nbytes >= 2**20 and nbytes % 2**20 == 0):
        return f"{nbytes / 2**20:.0f} MiB"
    if nbytes >= 2**20:
        return f"{nbytes / 2**20:.1f} MiB"
    if nbytes >= 2**10:
        return f"{nbytes / 2**10:.0f} KiB"
    return f"{nbytes:.0f} bytes"


#: How to raise the memory limit, in the refusals (the command line has only the environment variable).
RAISE_LIMIT_HINT = f"raise the limit with the environment variable {MAX_MEMORY_ENV} (e.g. {MAX_MEMORY_ENV}=8G; max_memory= in the Python API)"


def parse_memory(text: str | int | float, source: str = "memory limit", minimum: int = 1) -> int:
    """Bytes from ``"4G"``, ``"512M"``, ``"1e9"`` or a number (for ``$PWAS_HDL_MAX_MEMORY``), at least
    ``minimum`` (1 byte; :data:`MIN_MEMORY_LIMIT` for the environment variable); ``source`` names the
    setting in the messages."""
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        val = float(text)
    else:
        t = str(text).strip().upper().removesuffix("B")
        mult = {"K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}.get(t[-1:], 1)
        try:
            val = float(t[:-1] if mult != 1 else t) * mult
        except ValueError:
            raise InputError(f"{source} {text!r} is not a size; give bytes or a number with K, M or G (e.g. 4G)") from None
    if not (np.isfinite(val) and val >= 1):
        raise InputError(f"{source} {text!r} must be a positive size of at least 1 byte (e.g. 4G)")
    if val < minimum:
        raise InputError(f"{source} {text!r} is {size_text(val)}, below the {size_text(minimum)} any fit needs; "
                         f"give a size such as 512M or 4G")
    return int(val)


def available_memory() -> int | None:
    """``MemAvailable`` of /proc/meminfo in bytes (None where there is no /proc/meminfo)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def memory_limit(max_memory: int | str | None = None) -> tuple[int | None, str]:
    """The memory limit in bytes and where it comes from.

    Order: the explicit ``max_memory``; ``$PWAS_HDL_MAX_MEMORY``; ``MEMORY_FRACTION`` of the
    available RAM; ``(None, ...)`` (no limit) where none of these is known.

    Parameters
    ----------
    max_memory : int or str, optional
        An explicit limit: bytes, or text with a suffix K, M, G or T (:func:`parse_memory`).

    Returns
    -------
    limit : int or None
        The limit in bytes; None when no limit is known.
    source : str
        Where it comes from (``"max_memory"``, ``"$PWAS_HDL_MAX_MEMORY"``, ``"80% of the available
        RAM"`` or ``"unknown"``).

    Raises
    ------
    InputError
        ``max_memory`` or the environment variable cannot be parsed or is too small
        (:func:`parse_memory`).
    """
    if max_memory is not None:
        return parse_memory(max_memory, "max_memory"), "max_memory"
    env = os.environ.get(MAX_MEMORY_ENV)
    if env:
        return parse_memory(env, f"the environment variable {MAX_MEMORY_ENV}", MIN_MEMORY_LIMIT), f"${MAX_MEMORY_ENV}"
    avail = available_memory()
    if avail is None:
        return None, "unknown"
    return int(MEMORY_FRACTION * avail), f"{MEMORY_FRACTION:.0%} of the available RAM"


def _sparse_bytes(nnz: float, rows: int) -> float:
    idx = 4 if nnz < 2**31 and rows < 2**31 else 8
    return nnz * (8 + idx) + (rows + 1) * idx


def grid_factor_bound(n_unknowns: int, n_dims: int) -> tuple[float, float] | None:
    """``(nnz(L), bytes)``: the bound of :data:`GRID_FACTOR_BOUND` on the CHOLMOD factor of a grid system.

    Parameters
    ----------
    n_unknowns : int
        Unknowns ``U`` of the system (grid vertices solved for).
    n_dims : int
        Regressor dimension ``n``.

    Returns
    -------
    tuple of (float, float) or None
        The bound on the factor's entries ``nnz(L)`` (at most the dense triangle ``U (U + 1) / 2``)
        and on its bytes; None for a dimension not in :data:`GRID_FACTOR_BOUND`.
    """
    if int(n_dims) not in GRID_FACTOR_BOUND:
        return None
    c, e, per_entry, per_unknown = GRID_FACTOR_BOUND[int(n_dims)]
    u = max(float(n_unknowns), 2.0)
    nnz_l = c * u * np.log2(u) if int(n_dims) == 2 else c * u**e
    nnz_l = min(nnz_l, u * (u + 1) / 2)  # a dense triangle at most
    return nnz_l, per_entry * nnz_l + per_unknown * u


def choose_method(n_unknowns: int, n_dims: int, order: int = 1, method: Method = "auto") -> str:
    """``"direct"``, ``"cg"`` or ``"mg"``: the base method of a system of this size.

    ``auto`` picks direct up to ``DIRECT_MAX_UNKNOWNS[(order, min(n_dims, 5))]`` unknowns, CG above
    (:data:`DIRECT_MAX_UNKNOWNS_CHOLMOD` where CHOLMOD is available). First-order problems of at
    least :data:`MG_MIN_UNKNOWNS` unknowns then also use multigrid per sigma (see
    :data:`MG_DOMINANCE` and :class:`NormalEquationSolver`).

    Parameters
    ----------
    n_unknowns : int
        Unknowns of the system.
    n_dims : int
        Regressor dimension ``n`` (dimensions above 5 use the 5-D limit).
    order : int
        Tikhonov order (0, or first order for any non-zero value).
    method : {"auto", "direct", "cg", "mg"}
        The requested method; anything but ``auto`` is returned unchanged.

    Returns
    -------
    str
        ``"direct"``, ``"cg"`` or ``"mg"``.

    Raises
    ------
    InputError
        ``method`` is not one of the four.
    """
    if method not in ("auto", "direct", "cg", "mg"):
        raise InputError(f"solver method must be 'auto', 'direct', 'cg' or 'mg', got {method!r}")
    if method == "auto":
        limit = _direct_limits()[(1 if order else 0, min(max(int(n_dims), 1), 5))]
        return "direct" if n_unknowns <= limit else "cg"
    return method


def _direct_limits() -> dict[tuple[int, int], int]:
    """The ``auto`` table of the direct solver that is used (CHOLMOD where importable, else SuperLU)."""
    return DIRECT_MAX_UNKNOWNS_CHOLMOD if cholmod_available() else DIRECT_MAX_UNKNOWNS


def estimate_fit_memory(
    n_samples: int, n_vertices: int, n_dims: int, n_targets: int = 1, order: int = 0, method: Method = "auto",
    processes: int = 1, block_smoother: bool = True, grid_side: int | None = None,
) -> dict[str, float]:
    """Estimated peak bytes of a fit (with CV), before anything is allocated.

    Parameters
    ----------
    n_samples : int
        Rows ``T`` of ``H``.
    n_vertices : int
        Weights ``N`` per target.
    n_dims : int
        Regressor dimension ``n`` (``H`` has ``n + 1`` entries per row).
    n_targets : int
        Target columns ``nz``.
    order : {0, 1}
        Tikhonov order.
    method : {"auto", "direct", "cg", "mg"}
    processes : int
        Processes that solve folds at the same time (forked workers, see :func:`fork_workers`):
        each holds its own fold matrices, factor, multigrid levels and vectors (``H``, ``H'H`` and
        ``Gamma`` are inherited, shared).
    block_smoother : bool
        As in :class:`NormalEquationSolver`: with multigrid, the data-dominated sigmas by the
        data-block cycle, whose factor (of ``H'H`` on the touched vertices, without ``Gamma``'s grid
        edges) is charged as a zero-order one, instead of a first-order factor.
    grid_side : int, optional
        Vertices on the longest axis of the vertex grid (first order): below :data:`AMG_MIN_SIDE`
        CG is preconditioned by Jacobi alone and no AMG hierarchy is charged. Unknown (the
        default): charged.

    Returns
    -------
    dict
        ``H``, ``HtH`` (the normal matrix, counted three times: total, fold, shifted), ``Gamma``,
        ``factor`` (direct: ``DIRECT_FILL_FACTOR`` times ``nnz(A)``, or with CHOLMOD the smaller grid
        bound of :data:`GRID_FACTOR_BOUND`; first-order CG: the AMG preconditioner,
        :data:`AMG_MEMORY_FACTOR` times ``A`` (a diagonal below :data:`AMG_MIN_SIDE`); zero order: a
        diagonal; plus, where the factor chain of :data:`FACTOR_DOMINANCE_CG` is used, its nested-dissection factor, ``FACTOR_CHAIN_FILL`` times ``nnz(A)``), ``multigrid``
        (its levels, where first order uses it),
        ``vectors`` (weights, right-hand sides, CG work vectors), ``shift`` (forming ``M + sigma
        Gamma``, :data:`SHIFT_TRANSIENT_FACTOR`), ``model_file`` (writing the weights as JSON text,
        :data:`MODEL_TEXT_BYTES_PER_WEIGHT` a weight), ``workers`` (what each further
        process holds), ``fold_matrices`` (with forked workers: the parent's normal matrices of
        the other four folds, inherited by the workers) and ``total``, all in bytes; ``method`` the solver that ``auto`` would pick (as 1.0 = cg);
        ``worker_factor`` (not in ``total`` again): the factor bytes of each further process in
        ``workers`` (without the shared symbolic analysis of a first-order CHOLMOD factor).
    """
    t, nv, k = int(n_samples), int(n_vertices), int(n_dims) + 1
    nnz_h = t * k
    nnz_hth = min(float(nv) * nv, float(t) * k * k)
    nnz_gam = float(nv) if order == 0 else float(nv) * (2 * k - 1)
    nnz_a = nnz_hth + nnz_gam
    unknowns = min(nv, nnz_h) if order == 0 else nv
    chosen = choose_method(unknowns, n_dims, order, method)
    use_mg = order == 1 and (chosen == "mg" or (method == "auto" and nv >= MG_MIN_UNKNOWNS and int(n_dims) in MG_AUTO_DIMS))
    # Jacobi-CG base with the factor chain (FACTOR_DOMINANCE_CG): a nested-dissection factor too
    block = block_cycle_used(nv, method, chosen, use_mg, block_smoother)
    chain = (use_mg and chosen == "cg" and method == "auto" and int(n_dims) in FACTOR_CHAIN_DIMS
             and cholmod_available()) and not block
    chain_factor = _sparse_bytes(FACTOR_CHAIN_FILL * nnz_a, nv) if chain else 0.0
    if block:  # the data block: H'H on at most T (n + 1) touched vertices plus a diagonal
        touched = min(nv, nnz_h)
        direct_factor, analysis = _direct_factor_bytes(nnz_hth + touched, nv, touched, int(n_dims))
        chosen = "mg"
    else:
        direct_factor, analysis = _direct_factor_bytes(nnz_a, nv, unknowns, int(n_dims)) if chosen == "direct" else (0.0, 0.0)
    est = {
        "H": 2 * _sparse_bytes(nnz_h, t),  # H and its transpose
        "HtH": 3 * _sparse_bytes(nnz_a, nv),
        "Gamma": _sparse_bytes(nnz_gam, nv),
        "factor": (
            direct_factor
            if chosen == "direct" or block
            else (AMG_MEMORY_FACTOR * _sparse_bytes(nnz_a, nv) if order == 1 and chosen == "cg" and amg_allowed(grid_side)
                  else 8.0 * nv)
        ) + chain_factor,
        # the multigrid levels: the fine operator on the union pattern and its two value arrays
        # (3 x A), the prolongation and restriction (2^n entries a row), the coarse levels
        # (N / 2^n rows of at most 3^n entries, shrinking 2^n-fold per level) likewise tripled;
        # the single-precision strict upper triangles of every level for the residuals (16 bytes a
        # triangle entry with their values of m and Gamma: 8 a level entry, 2/3 of 12) and, with the
        # data-block cycle, both of the fine level in double precision (28 bytes an entry, 7/3 of 12)
        "multigrid": ((3.0 + 2.0 / 3.0 + (7.0 / 3.0 if block else 0.0)) * _sparse_bytes(nnz_a, nv)
                      + 2 * _sparse_bytes(float(nv) * 2 ** (k - 1), nv)
                      + (3.0 + 2.0 / 3.0) * _sparse_bytes(float(nv) * 3 ** (k - 1) / (2 ** (k - 1) - 1), nv))
        if use_mg else 0.0,
        "vectors": 8.0 * nv * (4 * int(n_targets) + 6) + 8.0 * t * 2 * int(n_targets),
        "shift": SHIFT_TRANSIENT_FACTOR * _sparse_bytes(nnz_gam, nv),
        # writing the model file (pwas_hdl.fit.model_file): every weight as a Python float and as text
        "model_file": float(MODEL_TEXT_BYTES_PER_WEIGHT) * nv * int(n_targets),
    }
    # first order with CHOLMOD: the symbolic analysis of the full-data pattern is made once, in the
    # parent before the fork (NormalEquationSolver.prepare_shared); the workers share its pages, so
    # each holds only its numeric factor
    shared = analysis if order == 1 and not block else 0.0
    per_process = (est["HtH"] * 2 / 3 + est["factor"] - shared + est["multigrid"] + est["vectors"] + est["shift"]
                   + FORK_WORKER_OVERHEAD)
    est["workers"] = per_process * (max(int(processes), 1) - 1)
    # what one factor at a time saves a worker (plan_fit_memory): its direct factor, or the factor
    # chain's (the Jacobi-CG / multigrid state of the chain's sweep it keeps)
    worker_factor = chain_factor if chain else (est["factor"] - shared if chosen == "direct" else 0.0)
    if block:  # a small factor: nothing to hold one at a time
        worker_factor = 0.0
    # forked workers: the parent holds every fold's normal matrix (5 folds; one is in "HtH")
    est["fold_matrices"] = 4 * _sparse_bytes(nnz_hth, nv) if int(processes) > 1 else 0.0
    est["total"] = float(sum(est.values()))
    est["method"] = 1.0 if chosen in ("cg", "mg") else 0.0
    est["worker_factor"] = worker_factor  # of "workers": each worker's own factor (not in the sum again)
    return est


def _direct_factor_bytes(nnz_a: float, n_vertices: int, unknowns: int, n_dims: int) -> tuple[float, float]:
    """``(bytes, analysis)``: the direct factor's bytes, the fill rule (``DIRECT_FILL_FACTOR`` x
    ``nnz(A)``) or with CHOLMOD the grid bound (:func:`grid_factor_bound`) where that is smaller, and
    of those the symbolic analysis's (the bound's per-unknown part; 0 under the fill rule)."""
    rule = _sparse_bytes(DIRECT_FILL_FACTOR * nnz_a, n_vertices)
    bound = grid_factor_bound(unknowns, n_dims) if cholmod_available() else None
    if bound is None or bound[1] > rule:
        return rule, 0.0
    return bound[1], GRID_FACTOR_BOUND[n_dims][3] * max(float(unknowns), 2.0)


def check_fit_memory(
    n_samples: int,
    n_vertices: int,
    n_dims: int,
    n_targets: int = 1,
    order: int = 0,
    method: Method = "auto",
    max_memory: int | str | None = None,
    processes: int = 1,
    block_smoother: bool = True,
    grid_side: int | None = None,
) -> dict[str, float]:
    """Refuse a fit whose estimated memory exceeds the limit, before allocating anything.

    Parameters
    ----------
    n_samples : int
        Rows ``T`` of ``H`` (samples).
    n_vertices : int
        Weights ``N`` per target.
    n_dims : int
        Regressor dimension ``n`` (``H`` has ``n + 1`` entries per row).
    n_targets : int
        Target columns ``nz``.
    order : {0, 1}
        Tikhonov order.
    method : {"auto", "direct", "cg", "mg"}
        The solver method, as in :func:`estimate_fit_memory`.
    max_memory : int or str, optional
        The limit in bytes, or text with a suffix K, M, G or T (``"4G"``, :func:`parse_memory`);
        overrides ``$PWAS_HDL_MAX_MEMORY`` and the default of ``MEMORY_FRACTION`` of the available
        RAM (:func:`memory_limit`).
    processes : int
        Processes that solve CV folds at the same time, as in :func:`estimate_fit_memory`.
    block_smoother : bool
        As in :func:`estimate_fit_memory`.
    grid_side : int, optional
        Vertices on the longest axis of the first-order vertex grid, as in :func:`estimate_fit_memory`.

    Returns
    -------
    dict
        The estimate (see :func:`estimate_fit_memory`).

    Raises
    ------
    ResourceLimit
        Naming the estimate, its largest parts and the limit.
    """
    est = estimate_fit_memory(n_samples, n_vertices, n_dims, n_targets, order, method, processes, block_smoother,
                              grid_side)
    limit, source = memory_limit(max_memory)
    if limit is not None and est["total"] > limit:
        parts = ", ".join(f"{k} {size_text(est[k])}" for k in ("H", "HtH", "Gamma", "factor", "multigrid", "vectors",
                                                                    "shift", "workers", "fold_matrices")
                          if k not in ("workers", "fold_matrices") or est[k] > 0)
        raise ResourceLimit(
            f"the fit needs an estimated {size_text(est['total'])} ({parts}) for T = {n_samples} samples and "
            f"N = {n_vertices} weights, over the limit of {size_text(limit)} ({source}); use fewer partitions "
            f"or samples, or {RAISE_LIMIT_HINT}"
        )
    return est


def _analysed_solver(hth: sparse.sparray, gamma: sparse.sparray, n_dims: int, n_samples: int, n_targets: int,
                     method: Method, rtol: float, block_smoother: bool, est: dict, limit: float | None,
                     processes: int) -> tuple["NormalEquationSolver", dict]:
    """The fit's solver, with the choices of a symbolic analysis (:data:`DIRECT_FLOPS_PER_ENTRY`,
    :data:`MG_BLOCK_ANALYSED_DIMS`) charged to the memory estimate ``est`` (the plan of
    :func:`plan_fit_memory` made before them): the analysed factor in every process that may hold
    one, or what method ``mg`` holds beyond the plan; where that goes over ``limit``, the solver of
    the size tables alone. Returns the solver and the estimate that holds for it."""
    solver = NormalEquationSolver(hth, gamma, n_dims, method, rtol, block_smoother=block_smoother,
                                  direct_headroom=direct_headroom(limit, est["total"], processes))
    if not (solver.direct_by_analysis or solver.mg_by_analysis):
        return solver, _checked_direct_factor(solver, hth, n_dims, est, limit, processes)
    if solver.direct_by_analysis:
        extra = factor_holders(processes) * solver.analysis.bytes
    else:
        extra = max(estimate_fit_memory(n_samples, hth.shape[0], n_dims, n_targets, 1, "mg", processes,
                                        block_smoother)["total"] - est["total"], 0.0)
    if limit is not None and est["total"] + extra > limit:
        return NormalEquationSolver(hth, gamma, n_dims, method, rtol, block_smoother=block_smoother,
                                    analyse=False), est
    return solver, dict(est, factor=est["factor"] + extra, total=est["total"] + extra)


def _checked_direct_factor(solver: "NormalEquationSolver", hth: sparse.sparray, n_dims: int, est: dict,
                           limit: float | None, processes: int) -> dict:
    """The estimate ``est`` with the direct method's factor as CHOLMOD's symbolic analysis counts it,
    where the estimate had only the fill rule (no :data:`GRID_FACTOR_BOUND` for this dimension).

    Run before any numeric factorisation, on the full-data pattern (each CV fold's pattern is part
    of it): from n = 4 the fill of ``DIRECT_FILL_FACTOR x nnz(A)`` can be far too small (measured:
    n = 6, N = 10^6, T = 10^5, zero order: ``method="direct"`` passed the estimate and then ran out
    of memory in CHOLMOD). The analysis's factor, in every process that may hold one, replaces the
    charged factor where larger; over ``limit`` the fit is refused.

    Raises
    ------
    ResourceLimit
        The analysed factor does not fit the limit.
    """
    if (solver.method != "direct" or solver.backend != "cholmod" or int(n_dims) in GRID_FACTOR_BOUND
            or solver.direct_by_analysis):
        return est
    if solver.analysis is None:
        solver.analyse_direct_factor(hth)
    if solver.analysis is None:  # the column counts could not be read: the fill rule stands
        return est
    extra = max(factor_holders(processes) * solver.analysis.bytes - est["factor"], 0.0)
    if limit is not None and est["total"] + extra > limit:
        raise ResourceLimit(
            f"the direct solve's sparse Cholesky factor needs {solver.analysis.bytes / 2**20:.0f} MiB "
            f"(CHOLMOD's symbolic analysis of N = {solver.analysis.n} unknowns, {solver.analysis.flops:.2g} "
            f"multiply-adds) and the fit {size_text(est['total'] + extra)} in all, over the limit of "
            f"{size_text(limit)}; use the iterative solver (method 'auto' or 'cg'), fewer partitions or "
            f"samples, or {RAISE_LIMIT_HINT}"
        )
    return dict(est, factor=est["factor"] + extra, total=est["total"] + extra)


def factor_holders(processes: int) -> int:
    """Processes that may hold a factor at the same time when a CV runs on ``processes``: each
    forked worker and the parent's final solve (one process: itself)."""
    return int(processes) + 1 if int(processes) > 1 else 1


def direct_headroom(limit: float | None, estimate: float, processes: int = 1) -> float | None:
    """Bytes each process that may hold a factor (:func:`factor_holders` of ``processes``) may add
    for a factor the estimate did not charge (see :data:`DIRECT_FLOPS_PER_ENTRY`): the limit less
    the estimate, shared; ``None`` without a limit."""
    if limit is None:
        return None
    return max(float(limit) - float(estimate), 0.0) / factor_holders(processes)


def plan_fit_memory(
    n_samples: int,
    n_vertices: int,
    n_dims: int,
    n_targets: int = 1,
    order: int = 0,
    method: Method = "auto",
    max_memory: int | str | None = None,
    processes: int = 1,
    block_smoother: bool = True,
    grid_side: int | None = None,
) -> dict:
    """How many processes a fit with CV can use within the memory limit, before allocating anything.

    The requested ``processes`` (forked CV workers, see :func:`fork_workers`) are tried first with
    every worker holding its own factor, then (``processes >= 2``) with the factorising segments of
    all folds run by one worker after another (``one_factor``: one factor resident at a time, see
    :func:`cross_validate_sigma`), then fewer processes, down to one.

    Parameters
    ----------
    n_samples : int
        Rows ``T`` of ``H`` (samples).
    n_vertices : int
        Weights ``N`` per target.
    n_dims : int
        Regressor dimension ``n`` (``H`` has ``n + 1`` entries per row).
    n_targets : int
        Target columns ``nz``.
    order : {0, 1}
        Tikhonov order.
    method : {"auto", "direct", "cg", "mg"}
        The solver method, as in :func:`estimate_fit_memory`.
    max_memory : int or str, optional
        The limit in bytes, or text with a suffix K, M, G or T (``"4G"``, :func:`parse_memory`);
        overrides ``$PWAS_HDL_MAX_MEMORY`` and the default of ``MEMORY_FRACTION`` of the available
        RAM (:func:`memory_limit`).
    processes : int
        The processes requested (forked CV workers); the plan may use fewer.
    block_smoother : bool
        As in :func:`estimate_fit_memory`.
    grid_side : int, optional
        Vertices on the longest axis of the first-order vertex grid, as in :func:`estimate_fit_memory`.

    Returns
    -------
    dict
        ``processes`` (to use, ``>= 1``), ``requested``, ``one_factor`` (bool), ``estimate`` (the
        :func:`estimate_fit_memory` dict of that plan, ``total`` in bytes), ``limit`` (bytes or None)
        and ``reason`` (None when the request fits as asked, else why the plan differs).

    Raises
    ------
    ResourceLimit
        Even one process does not fit (the message of :func:`check_fit_memory`).
    """
    requested = max(int(processes), 1)
    limit, source = memory_limit(max_memory)
    asked = None
    for procs in range(requested, 0, -1):
        est = estimate_fit_memory(n_samples, n_vertices, n_dims, n_targets, order, method, procs, block_smoother,
                                  grid_side)
        asked = asked or est
        candidates = [(False, est)]
        if procs > 1 and est["worker_factor"] > 0:
            one = dict(est)
            one["workers"] = est["workers"] - (procs - 1) * est["worker_factor"]
            one["total"] = est["total"] - (procs - 1) * est["worker_factor"]
            candidates.append((True, one))
        for one_factor, e in candidates:
            if limit is None or e["total"] <= limit:
                reason = None
                if procs < requested or one_factor:
                    how = (f"{procs} process{'es' if procs > 1 else ''}" + (", one factor at a time" if one_factor else ""))
                    reason = (f"{requested} processes need an estimated {asked['total'] / 2**20:.0f} MiB, over the limit of "
                              f"{limit / 2**20:.0f} MiB ({source}): the CV runs on {how} ({e['total'] / 2**20:.0f} MiB)")
                return {"processes": procs, "requested": requested, "one_factor": one_factor, "estimate": e,
                        "limit": limit, "reason": reason}
    # not even one process: the refusal names the one-process estimate
    check_fit_memory(n_samples, n_vertices, n_dims, n_targets, order, method, max_memory, 1, block_smoother, grid_side)
    raise InternalError("plan_fit_memory: one process over the limit was not refused")  # pragma: no cover


def _order_of(gamma: sparse.sparray) -> int:
    """0 when Gamma is the identity (zero order), else 1."""
    g = sparse.csr_array(gamma)
    return 0 if g.nnz == g.shape[0] and np.all(g.diagonal() == 1.0) else 1


def _grid_side(gamma: sparse.sparray, n_dims: int) -> int | None:
    """Vertices on the longest axis of a first-order ``Gamma``'s grid (None: zero order, or not a grid)."""
    if _order_of(gamma) != 1:
        return None
    shape = grid_shape_of(gamma, n_dims)
    return max(shape) if shape else None


def _dims_of(h: sparse.sparray) -> int:
    """Regressor dimension ``n`` from the non-zeros per row of ``H`` (``n + 1``)."""
    return max(int(np.ceil(h.nnz / max(h.shape[0], 1))) - 1, 1)


# ------------------------------------------------------------------------------- solvers
def _solve_spd(a: sparse.csc_array, b: np.ndarray) -> np.ndarray:
    """Solve the sparse SPD system ``a x = b`` (``b`` shape (N,) or (N, k)) by sparse LU.

    The matrix is symmetric positive definite, so no pivoting is needed: SuperLU runs in symmetric
    mode on the minimum-degree ordering of ``A + A'`` with the diagonal as pivots (threshold 0).
    Partial pivoting would only destroy the fill-reducing ordering (measured: 50 s instead of
    under 1 s at N = 40 000, first order).
    """
    lu = splinalg.splu(
        sparse.csc_matrix(a), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )
    return lu.solve(np.asarray(b, dtype=float))


class _Preconditioner:
    """Preconditioner of ``A = M_data + sigma Gamma`` for conjugate gradients.

    Jacobi (``diag(A)^{-1}``) by default. First-order problems on a grid with a long enough axis
    (``amg``, see :data:`AMG_MIN_SIDE`) whose penalty dominates (see :data:`AMG_DOMINANCE`) get one
    V-cycle of smoothed-aggregation algebraic multigrid (pyamg) on the *lumped* surrogate
    ``diag(rowsum(H'H)) + sigma0 Gamma``, an M-matrix (a scaled grid Laplacian plus a positive
    diagonal); since ``H'H <= diag(rowsum(H'H))`` (each row of ``H`` is a
    probability vector) the surrogate bounds ``A`` from above. The hierarchy is built on the
    full-data normal matrix and reused for every fold, and for every sigma of its band: the AMG
    sigmas are cut into bands of ratio ``AMG_REUSE_RATIO`` from the first one up (see
    :meth:`anchor`), each with its hierarchy built at the band's geometric middle ``sigma0``
    (surrogates of two sigmas are spectrally equivalent within their ratio, here at most
    ``sqrt(AMG_REUSE_RATIO)`` either way). The preconditioner of a sigma is so a function of that
    sigma alone, not of the solves before it: a fold gives the same weights in any process and
    after any other fold (:func:`cross_validate_sigma` forks the folds of CG sweeps). One
    hierarchy is held at a time (the last band's).
    """

    def __init__(self, lumped: np.ndarray, gamma: sparse.csr_array, order: int, amg: bool = True):
        self.lumped = lumped
        self.gamma = gamma
        self.order = order
        #: AMG allowed at all (:func:`amg_allowed` of the grid's longest side)
        self.amg = bool(amg)
        self._sigma0: float | None = None
        self._ml = None
        self.builds = 0
        self._data_diag = float(lumped.mean()) if lumped.size else 0.0
        self._gamma_diag = float(gamma.diagonal().mean()) if gamma.shape[0] else 0.0

    def use_amg(self, sigma: float) -> bool:
        return (self.amg and self.order == 1 and self._gamma_diag > 0
                and sigma * self._gamma_diag >= AMG_DOMINANCE * self._data_diag)

    def anchor(self, sigma: float) -> float:
        """The sigma at which the hierarchy used for ``sigma`` (an AMG sigma) is built.

        The band ``[s1 R^k, s1 R^(k+1))`` that holds ``sigma`` (``s1`` the smallest AMG sigma,
        ``AMG_DOMINANCE mean(diag H'H) / mean(diag Gamma)``; ``R = AMG_REUSE_RATIO``), at its
        geometric middle ``s1 R^(k + 1/2)``.
        """
        s1 = AMG_DOMINANCE * self._data_diag / self._gamma_diag
        k = math.floor(math.log(sigma / s1) / math.log(AMG_REUSE_RATIO))
        return s1 * AMG_REUSE_RATIO ** (k + 0.5)

    def get(self, a: sparse.csr_array, sigma: float):
        if not self.use_amg(sigma):
            d = a.diagonal()
            return splinalg.LinearOperator(a.shape, matvec=lambda v: v / d if v.ndim == 1 else v / d[:, None], dtype=float)
        sigma0 = self.anchor(sigma)
        if self._ml is None or sigma0 != self._sigma0:
            import pyamg

            m = (sparse.diags_array(self.lumped) + sigma0 * self.gamma).tocsr()
            self._ml = None  # the previous band's hierarchy is freed before the next one is built
            # pyamg starts its spectral-radius estimates (the prolongation smoother's omega) from
            # numpy's global random generator: seeded here and restored, so that the hierarchy is a
            # function of the matrix alone (the same in every process and after any other build)
            state = np.random.get_state()
            try:
                np.random.seed(AMG_SEED)
                self._ml = pyamg.smoothed_aggregation_solver(sparse.csr_matrix(m), symmetry="symmetric")
            finally:
                np.random.set_state(state)
            self._sigma0 = sigma0
            self.builds += 1
        return self._ml.aspreconditioner(cycle="V")


def _cg(
    a: sparse.csr_array,
    b: np.ndarray,
    precond,
    x0: np.ndarray | None,
    sigma: float,
    lam_gamma: float,
    rtol: float,
    maxiter: int,
) -> tuple[np.ndarray, SolveInfo]:
    """Preconditioned CG column by column; the stopping test is ``||b - A w|| <= rtol ||b||``."""
    b2 = np.asarray(b, dtype=float).reshape(a.shape[0], -1)
    w = np.zeros_like(b2) if x0 is None else np.array(x0, dtype=float).reshape(b2.shape)
    its, worst_rel, worst_abs, ok = 0, 0.0, 0.0, True
    for j in range(b2.shape[1]):
        nb = float(np.linalg.norm(b2[:, j]))
        if nb == 0.0:
            w[:, j] = 0.0
            continue
        wj, its_j, done = pcg(a, b2[:, j], precond, w[:, j], rtol, maxiter)
        w[:, j] = wj
        its += its_j
        r = float(np.linalg.norm(b2[:, j] - a @ wj))
        worst_rel = max(worst_rel, r / nb)
        worst_abs = max(worst_abs, r)
        ok = ok and done
    bound = worst_abs / (sigma * lam_gamma) if lam_gamma > 0 else float("inf")
    return w.reshape(np.shape(b)), SolveInfo("cg", its, worst_rel, bound, ok)


class NormalEquationSolver:
    """Solves ``(M + sigma Gamma) w = b`` for many ``M`` (folds) and sigmas, reusing work.

    Zero-order problems are first reduced, exactly, to the vertices that some sample touches
    (elsewhere the row of ``H'H`` is zero and so is ``b``: ``w = 0``).

    Parameters
    ----------
    hth : sparse array, shape (N, N)
        Full-data normal matrix ``H'H`` (the preconditioner is built from it).
    gamma : sparse array, shape (N, N)
    n_dims : int
        Regressor dimension ``n`` (for the ``auto`` rule).
    method : {"auto", "direct", "cg", "mg"}
        See :func:`choose_method`. First order, ``auto``: from :data:`MG_MIN_UNKNOWNS` unknowns on
        a vertex grid in 2-D or 3-D, every sigma by multigrid-preconditioned CG, the data-dominated
        ones (:data:`MG_BLOCK_DOMINANCE`) with the data-block cycle, and a solve that stops
        unconverged again by the factorisation (on a direct base method below
        :data:`MG_BLOCK_MIN_DIRECT` unknowns, the earlier rule below instead: :func:`block_cycle_used`); ``mg``: the same in any dimension. With
        ``block_smoother=False`` the earlier rule: multigrid where the penalty dominates
        (:data:`MG_DOMINANCE`), otherwise the factorisation and factor-PCG (2-D) or, where the
        base method is Jacobi-CG (3-D), the factor chain (:data:`FACTOR_DOMINANCE_CG`).
    rtol : float
        CG relative-residual tolerance (default :data:`CG_RTOL`).
    maxiter : int, optional
        CG iteration cap (default :data:`CG_MAXITER`, read when the solver is made).
    direct_backend : {"auto", "cholmod", "superlu"}
        The direct solve: CHOLMOD (:class:`~pwas_hdl.fit.sparse_cholesky.PatternCholesky`, one
        symbolic analysis per fold matrix, a numeric factorisation per sigma) where cvxopt is
        importable (``auto``), else SuperLU (:func:`_solve_spd`, a full factorisation per system).
    block_smoother : bool
        First order with multigrid (``auto``, ``mg``): solve the data-dominated sigmas by the
        data-block multigrid cycle (:data:`MG_BLOCK_DOMINANCE`; the default). ``False`` keeps the
        earlier rule (factorisations, factor-PCG and the factor chain at those sigmas), for
        comparison.
    direct_headroom : float, optional
        Bytes a factor chosen by a symbolic analysis may take (:data:`DIRECT_FLOPS_PER_ENTRY`,
        :data:`MG_BLOCK_ANALYSED_DIMS`; the memory limit less the fit's estimate, per process that
        may hold one, :func:`direct_headroom`); ``None``: not limited.
    analyse : bool
        ``auto`` with CHOLMOD: make those analyses (the default); ``False``: the size tables alone.

    Attributes
    ----------
    analysis : FactorCounts or None
        The symbolic analysis behind the choice of :data:`DIRECT_FLOPS_PER_ENTRY` (zero order,
        ``auto``, where the size table picked CG), else None.
    """

    def __init__(
        self,
        hth: sparse.sparray,
        gamma: sparse.sparray,
        n_dims: int,
        method: Method = "auto",
        rtol: float = CG_RTOL,
        maxiter: int | None = None,
        direct_backend: Literal["auto", "cholmod", "superlu"] = "auto",
        block_smoother: bool = True,
        direct_headroom: float | None = None,
        analyse: bool = True,
    ):
        hth = sparse.csr_array(hth)
        gamma = sparse.csr_array(gamma)
        self.n = hth.shape[0]
        self.lam_gamma = gamma_min_eigenvalue(gamma)
        self.order = _order_of(gamma)
        if self.order == 0:
            self.keep = np.flatnonzero(hth.diagonal() > 0)
            if self.keep.size == self.n:
                self.keep = None
        else:
            self.keep = None
        self.gamma = self._restrict(gamma)
        unknowns = self.n if self.keep is None else self.keep.size
        self.method = choose_method(unknowns, n_dims, self.order, method)
        self.fallback = method == "auto" and unknowns <= FALLBACK_FACTOR * _direct_limits()[
            (self.order, min(max(int(n_dims), 1), 5))
        ]
        self.rtol = float(rtol)
        self.maxiter = CG_MAXITER if maxiter is None else int(maxiter)
        if direct_backend not in ("auto", "cholmod", "superlu"):
            raise InputError(f"direct backend must be 'auto', 'cholmod' or 'superlu', got {direct_backend!r}")
        if direct_backend == "cholmod" and not cholmod_available():
            raise InputError("direct backend 'cholmod' needs cvxopt (pip install cvxopt)")
        self.backend = "superlu" if direct_backend == "superlu" or not cholmod_available() else "cholmod"
        self.analysis: FactorCounts | None = None
        #: the direct method (zero order) or multigrid with the data-block cycle (first order, n >= 4)
        #: chosen by a symbolic analysis (:data:`DIRECT_FLOPS_PER_ENTRY`, :data:`MG_BLOCK_ANALYSED_DIMS`)
        self.direct_by_analysis = False
        self.mg_by_analysis = False
        analyse = bool(analyse) and method == "auto" and self.backend == "cholmod"
        if analyse and self.method == "cg" and self.order == 0:
            self._direct_by_analysis(self._restrict(hth), direct_headroom)
        #: the vertex-grid shape for multigrid (first order on a full grid), None where not used
        self._mg_shape = None
        if self.order == 1 and self.keep is None and (method == "mg" or (
                method == "auto" and self.n >= MG_MIN_UNKNOWNS and int(n_dims) in MG_AUTO_DIMS)):
            self._mg_shape = grid_shape_of(gamma, n_dims)
        elif (analyse and self.order == 1 and self.method == "cg" and self.n >= MG_MIN_UNKNOWNS
              and int(n_dims) in MG_BLOCK_ANALYSED_DIMS and bool(block_smoother)):
            shape = grid_shape_of(gamma, n_dims)
            if shape is not None and self._cheap_data_block(hth, direct_headroom):
                self._mg_shape, self.mg_by_analysis = shape, True
        if self._mg_shape is None and method == "mg":
            raise InputError("solver method 'mg' needs the first-order Gamma of a full vertex grid (tikhonov_matrix)")
        self._full_mean_row = float(hth.sum()) / max(self.n, 1)
        self._mg_hier: GridHierarchy | None = None
        self._mg_cache: tuple | None = None
        self._gamma_diag: float | None = None
        if self.method == "cg":
            lumped = np.asarray(self._restrict(hth).sum(axis=1)).reshape(-1)
            self._pre = _Preconditioner(lumped, self.gamma, self.order, amg_allowed(_grid_side(gamma, n_dims)))
        #: the data-dominated sigmas of a fold by PCG with the factor of a smaller sigma
        #: (see :data:`FACTOR_PCG_MAXITER`): first order, ``auto``, CHOLMOD, full grid, large
        self.factor_pcg = (method == "auto" and self.method == "direct" and self.order == 1 and self.keep is None
                           and self.backend == "cholmod" and self.n >= FACTOR_PCG_MIN_UNKNOWNS)
        #: base method Jacobi-CG: the smallest sigmas by the factor chain (:data:`FACTOR_DOMINANCE_CG`);
        #: a Jacobi- or multigrid-CG solve that stops unconverged is re-done by the factorisation
        self.factor_chain = (method == "auto" and self.method == "cg" and self._mg_shape is not None
                             and self.backend == "cholmod" and int(n_dims) in FACTOR_CHAIN_DIMS)
        if self.factor_chain:
            self.factor_pcg = True
            self.fallback = True
        #: first order with multigrid: the data-dominated sigmas by the data-block cycle
        #: (:data:`MG_BLOCK_DOMINANCE`) instead of factorisations
        self.block_mg = block_cycle_used(self.n, method, self.method, self._mg_shape is not None, bool(block_smoother))
        #: the nested-dissection ordering for a first-order factorisation (3-D, see FACTOR_DOMINANCE_CG)
        self._nd_order = self._mg_shape is not None and int(n_dims) in FACTOR_CHAIN_DIMS
        #: the threshold of :meth:`uses_block` for this dimension (:data:`MG_BLOCK_DOMINANCE`)
        self.block_dominance = MG_BLOCK_DOMINANCE.get(max(int(n_dims), 1), MG_BLOCK_DOMINANCE[3])
        if self.block_mg:
            self.factor_pcg = self.factor_chain = False
            # a data-block solve that stops at its cap is re-done by the factorisation
            self.fallback = self.fallback or (method == "auto" and self.backend == "cholmod")
        if self.mg_by_analysis:  # a first-order factorisation is out of reach there: unconverged is reported
            self.fallback = False
        self._factor_pcg_cap = FACTOR_PCG_MAXITER_CG if self.factor_chain else FACTOR_PCG_MAXITER
        #: the fold's factor reuse: ``{"m": m, "last": iterations of the last PCG, "stopped": bool}``
        self._reuse: dict | None = None
        self._m_cache: tuple | None = None
        #: first order: the full-data pattern ``H'H + Gamma`` holds every fold's ``H_k'H_k + Gamma``
        #: (``H_k'H_k = H'H - H_v'H_v``), so one symbolic analysis serves every fold and the
        #: final solve (see :meth:`_cholmod_solve`); built lazily, in the process that solves
        self._shared_hth = hth if self.order == 1 and self.keep is None else None
        self._shared_chol: tuple | None = None
        #: CHOLMOD factorisations that met a non-positive pivot and were solved by SuperLU instead
        self.superlu_fallbacks = 0
        #: factor-PCG attempts that hit :data:`FACTOR_PCG_MAXITER` (then refactorised)
        self.factor_pcg_failures = 0
        #: data blocks (:data:`MG_BLOCK_DOMINANCE`) not positive definite (solved by Gauss-Seidel alone)
        self.block_failures = 0
        self.infos: list[SolveInfo] = []
        #: one factor at a time (cross_validate_sigma under a memory limit, see plan_fit_memory): a
        #: lock shared by the forked workers; a fallback factorisation holds it and frees its factor
        self.factor_lock = None

    def _analyse(self, pattern: sparse.sparray) -> PatternCholesky:
        """CHOLMOD's symbolic analysis of ``pattern``; its counts kept in :attr:`analysis`."""
        chol = PatternCholesky(pattern)
        self.analysis = chol.counts()
        return chol

    def analyse_direct_factor(self, hth: sparse.sparray) -> FactorCounts | None:
        """The counts of the factor the direct method makes, from the full-data system ``hth + Gamma``.

        Every fold's pattern is part of it; the counts are kept in :attr:`analysis`. First order
        analyses the pattern the folds share (:meth:`_shared_pattern`), so the solves do not
        analyse it again.

        Parameters
        ----------
        hth : sparse array, shape (N, N)
            The full-data normal matrix ``H'H``.

        Returns
        -------
        FactorCounts or None
            The factor's counts; None where CHOLMOD's struct could not be read.
        """
        if self._shared_hth is not None:
            self.analysis = self._shared_pattern()[0].counts()
        else:
            self._analyse(abs(self._restrict(hth)) + abs(self.gamma))
        return self.analysis

    def _cheap_factor(self, pattern: sparse.sparray, headroom: float | None) -> bool:
        """Whether CHOLMOD's symbolic analysis of ``pattern`` (kept in :attr:`analysis`) finds its
        factor cheap (:data:`DIRECT_FLOPS_PER_ENTRY`) and within ``headroom`` bytes."""
        chol = self._analyse(pattern)
        if self.analysis is None:
            return False
        cheap = self.analysis.flops <= DIRECT_FLOPS_PER_ENTRY * chol.nnz_lower
        return bool(cheap and (headroom is None or self.analysis.bytes <= headroom))

    def _direct_by_analysis(self, m: sparse.csr_array, headroom: float | None) -> None:
        """Zero order: the direct method instead of CG where the factor of the full-data system is
        cheap (:meth:`_cheap_factor`)."""
        if self._cheap_factor(abs(m) + abs(self.gamma), headroom):
            self.method = "direct"
            self.direct_by_analysis = True

    def _cheap_data_block(self, hth: sparse.csr_array, headroom: float | None) -> bool:
        """First order from n = 4 (:data:`MG_BLOCK_ANALYSED_DIMS`): whether the data block of the
        full data, ``H'H`` on the touched vertices plus a diagonal (every fold's block is part of
        it), factorises cheaply (:meth:`_cheap_factor`)."""
        touched = np.flatnonzero(hth.diagonal() > 0)
        if touched.size == 0:
            return False
        block = sparse.csr_array(hth[touched][:, touched])
        return self._cheap_factor(abs(block) + sparse.identity(touched.size, format="csr"), headroom)

    def __getstate__(self) -> dict:
        """Pickled (e.g. shipped to a Dask worker) without the CHOLMOD factors, which cannot be."""
        state = dict(self.__dict__)
        state["_m_cache"] = state["_shared_chol"] = state["_mg_cache"] = state["_reuse"] = None
        state["factor_lock"] = None
        return state

    def factorises(self, m: sparse.csr_array, sigma: float) -> bool:
        """True when the solve at ``sigma`` factorises ``m + sigma Gamma``.

        The direct method or the factor chain; a fallback of an unconverged CG solve aside.

        Parameters
        ----------
        m : sparse array, shape (U, U)
            A fold's normal matrix (on the unknowns solved for).
        sigma : float
            The regularisation weight.

        Returns
        -------
        bool
        """
        if self.uses_mg(m, sigma):
            return False
        return self.method == "direct" or self.uses_factor_chain(m, sigma)

    def drop_factor(self) -> None:
        """Free the factor this process keeps for the next solve of the same matrix (and its
        factor-PCG state): one factor at a time, the worker of the factorising segments lets go
        of its last one before another worker may factorise."""
        self._m_cache = None
        self._reuse = None

    def _fallback_direct(self, m: sparse.csr_array, bk: np.ndarray, sigma: float) -> np.ndarray:
        """The direct solve after CG stopped at its cap; with :attr:`factor_lock` under the lock, the
        factor freed before it is released."""
        if self.factor_lock is None:
            return self._direct(m, bk, sigma)
        with self.factor_lock:
            try:
                return self._direct(m, bk, sigma)
            finally:
                self.drop_factor()

    def uses_mg(self, m: sparse.csr_array, sigma: float) -> bool:
        """True when ``(m + sigma Gamma) w = b`` is solved by multigrid-preconditioned CG.

        ``mg`` as the method: always. With multigrid available (``auto``, first order, at least
        :data:`MG_MIN_UNKNOWNS` unknowns) when the penalty dominates,
        ``rho = sigma * mean(diag Gamma) / mean(rowsum m)`` at least :data:`MG_DOMINANCE` (base
        method direct) or :data:`MG_DOMINANCE_CG` (base method Jacobi-preconditioned CG).

        Parameters
        ----------
        m : sparse array, shape (U, U)
            A fold's normal matrix (on the unknowns solved for).
        sigma : float
            The regularisation weight.

        Returns
        -------
        bool
        """
        if self._mg_shape is None:
            return False
        if self.method == "mg" or self.block_mg:
            return True
        limit = MG_DOMINANCE if self.method == "direct" else MG_DOMINANCE_CG
        return sigma * self._gamma_diag_mean() >= limit * self._mg_fold(m)[1]

    def uses_block(self, m: sparse.csr_array, sigma: float) -> bool:
        """True when this sigma is solved by the data-block multigrid cycle.

        That is with :attr:`block_mg` and ``rho <`` :attr:`block_dominance` (see
        :data:`MG_BLOCK_DOMINANCE`).

        Parameters
        ----------
        m : sparse array, shape (U, U)
            A fold's normal matrix (on the unknowns solved for).
        sigma : float
            The regularisation weight.

        Returns
        -------
        bool
        """
        if not self.block_mg:
            return False
        return sigma * self._gamma_diag_mean() < self.block_dominance * self._mg_fold(m)[1]

    def uses_factor_chain(self, m: sparse.csr_array, sigma: float) -> bool:
        """True when the base method is Jacobi-CG and this sigma is in the fold's factor chain.

        That is ``rho < FACTOR_DOMINANCE_CG`` (see :data:`FACTOR_DOMINANCE_CG`).

        Parameters
        ----------
        m : sparse array, shape (U, U)
            A fold's normal matrix (on the unknowns solved for).
        sigma : float
            The regularisation weight.

        Returns
        -------
        bool
        """
        if not self.factor_chain:
            return False
        return sigma * self._gamma_diag_mean() < FACTOR_DOMINANCE_CG * self._mg_fold(m)[1]

    def segment_cost(self, m: sparse.csr_array, sigma: float) -> float:
        """Relative cost of this sigma in a segment, for the order of the forked tasks (:func:`_fork_segments`).

        :data:`_MG_COST` by multigrid, :data:`_CHAIN_COST` in the factor chain,
        :data:`_MG_BLOCK_COST` by the data-block cycle, a sigma of a sweep by CG alone
        ``sqrt(CG_COST_RHO_FLOOR / max(rho, CG_COST_RHO_FLOOR))``, else 1.

        Parameters
        ----------
        m : sparse array, shape (U, U)
            A fold's normal matrix (on the unknowns solved for).
        sigma : float
            The regularisation weight.

        Returns
        -------
        float
            A relative cost (1 for a solve of none of these kinds); only the order of the costs
            matters.
        """
        if self.uses_block(m, sigma):
            return _MG_BLOCK_COST
        if self.uses_mg(m, sigma):
            return _MG_COST
        if self.method == "cg" and not self.factor_chain:  # CG alone: see CG_COST_RHO_FLOOR (at most 1)
            rho = sigma * self._gamma_diag_mean() / max(self._full_mean_row, np.finfo(float).tiny)
            return math.sqrt(CG_COST_RHO_FLOOR / max(rho, CG_COST_RHO_FLOOR))
        return _CHAIN_COST if self.uses_factor_chain(m, sigma) else 1.0

    def full_data_uses_mg(self, sigma: float) -> bool:
        """:meth:`uses_mg` for the full-data normal matrix (a lower bound of every fold's rho).

        Parameters
        ----------
        sigma : float
            The regularisation weight.

        Returns
        -------
        bool
        """
        return self._mg_shape is not None and (
            self.method == "mg" or self.block_mg
            or sigma * self._gamma_diag_mean() >= (MG_DOMINANCE if self.method == "direct" else MG_DOMINANCE_CG)
            * self._full_mean_row)

    def _gamma_diag_mean(self) -> float:
        if self._gamma_diag is None:  # one pass over Gamma, not one per (fold, sigma) query
            self._gamma_diag = float(self.gamma.diagonal().mean())
        return self._gamma_diag

    def _mg_fold(self, m: sparse.csr_array) -> tuple:
        """``(m, mean(rowsum m), FoldMultigrid or None)`` for this ``m``, kept until the next ``m``."""
        if self._mg_cache is None or self._mg_cache[0] is not m:
            self._mg_cache = (m, float(m.sum()) / max(m.shape[0], 1), None)
        return self._mg_cache

    def _mg_solve(self, m: sparse.csr_array, bk: np.ndarray, sigma: float, x0k) -> tuple[np.ndarray, SolveInfo]:
        """Multigrid-preconditioned CG, column by column, to :attr:`rtol` (see :func:`_cg`)."""
        self.prepare_multigrid(m)  # the levels of m (built once, freeing the previous fold's first)
        fold = self._mg_cache[2]
        block = self.uses_block(m, sigma)
        if block:
            try:
                fold.set_block(float(sigma))
            except NotPositiveDefinite:  # rounding in H'H - H_v'H_v at a tiny sigma: Gauss-Seidel alone
                self.block_failures += 1
                block = False
        maxiter = min(self.maxiter, MG_BLOCK_MAXITER) if block else self.maxiter
        b2 = np.asarray(bk, dtype=float).reshape(self.n, -1)
        x2 = None if x0k is None else np.asarray(x0k, dtype=float).reshape(b2.shape)
        w = np.zeros_like(b2)
        its, worst_rel, worst_abs, ok = 0, 0.0, 0.0, True
        for j in range(b2.shape[1]):
            w[:, j], mi = fold.solve(b2[:, j], sigma, None if x2 is None else x2[:, j], self.rtol, maxiter, block)
            its += mi.iterations
            worst_rel, worst_abs = max(worst_rel, mi.rel_residual), max(worst_abs, mi.abs_residual)
            ok = ok and mi.converged
        bound = worst_abs / (sigma * self.lam_gamma) if self.lam_gamma > 0 else float("inf")
        return w.reshape(np.shape(bk)), SolveInfo("mg-block" if block else "mg", its, worst_rel, bound, ok)

    def sweep_order(self, m: sparse.csr_array, sigmas: np.ndarray) -> list[int]:
        """Order in which a fold (normal matrix ``m``) solves its ``sigmas`` (indices).

        From the largest sigma down (each iterative solve warm-started from the previous one);
        with :attr:`factor_pcg` the sigmas solved by multigrid first (largest down), then the
        data-dominated ones from the smallest up (see :data:`FACTOR_PCG_MAXITER`).

        Parameters
        ----------
        m : sparse array, shape (U, U)
            The fold's normal matrix.
        sigmas : ndarray, shape (S,)
            The candidate sigmas.

        Returns
        -------
        list of int
            A permutation of ``range(S)``.
        """
        descending = [int(i) for i in np.argsort(-np.asarray(sigmas, dtype=float), kind="stable")]
        if not self.factor_pcg:
            return descending
        if self.factor_chain:  # multigrid and Jacobi-CG down, then the factor chain up
            iterative = [i for i in descending if not self.uses_factor_chain(m, float(sigmas[i]))]
            return iterative + [i for i in reversed(descending) if i not in set(iterative)]
        iterative = [i for i in descending if self.uses_mg(m, float(sigmas[i]))]
        return iterative + [i for i in reversed(descending) if i not in set(iterative)]

    def sweep_segments(self, m: sparse.csr_matrix, sigmas: np.ndarray) -> list[list[int]]:
        """:meth:`sweep_order` cut into independent segments (indices into ``sigmas``).

        Each segment starts afresh (no warm start, no factor of another segment; see
        :meth:`start_segment`), so the segments of all folds can run in any order and on any
        process with the results of the serial sweep. Where the base method is the direct one and
        multigrid is used: the multigrid sigmas (one warm-started chain), then with
        :attr:`factor_pcg` the :data:`FACTOR_PCG_SEGMENT` smallest data-dominated sigmas (the
        factor-PCG chain), then every other data-dominated sigma alone (a factorisation each).
        With :attr:`block_mg`: the sigmas of the Gauss-Seidel cycle, then those of the data-block
        cycle (:data:`MG_BLOCK_DOMINANCE`; each a warm-started chain from the largest down).
        With :attr:`factor_chain` (base method Jacobi-CG): the multigrid sigmas, the Jacobi-CG ones
        (each a warm-started chain from the largest down; three tasks a fold balance the forked
        workers better than two), then the factor chain (from the smallest up).
        With CG alone (base method ``cg`` without the factor chain): :data:`CG_SEGMENTS` chains of
        consecutive sigmas (each warm-started largest down). Otherwise the whole sweep is one
        segment.

        Parameters
        ----------
        m : sparse array, shape (U, U)
            The fold's normal matrix.
        sigmas : ndarray, shape (S,)
            The candidate sigmas.

        Returns
        -------
        list of list of int
            Non-empty segments whose concatenation is a permutation of ``range(S)``.
        """
        order = self.sweep_order(m, sigmas)
        if self.block_mg:  # the Gauss-Seidel cycle's sigmas, the data-block cycle's (each largest down)
            block = [i for i in order if self.uses_block(m, float(sigmas[i]))]
            return [seg for seg in ([i for i in order if i not in set(block)], block) if seg]
        if self.factor_chain:  # multigrid, Jacobi-CG (each a warm-started chain), the factor chain
            chain = [i for i in order if self.uses_factor_chain(m, float(sigmas[i]))]
            mg = [i for i in order if self.uses_mg(m, float(sigmas[i]))]
            jacobi = [i for i in order if i not in set(chain) | set(mg)]
            return [seg for seg in (mg, jacobi, chain) if seg]
        if self.method == "cg":  # CG alone: CG_SEGMENTS chains of consecutive sigmas, each largest down
            cuts = np.linspace(0, len(order), min(CG_SEGMENTS, len(order)) + 1).round().astype(int)
            return [order[a:b] for a, b in zip(cuts[:-1], cuts[1:]) if b > a]
        if not (self.method == "direct" and self._mg_shape is not None):
            return [order]
        mg = [i for i in order if self.uses_mg(m, float(sigmas[i]))]
        rest = [i for i in order if i not in set(mg)]
        segments = [mg] if mg else []
        head = FACTOR_PCG_SEGMENT if self.factor_pcg else 1
        if rest:
            segments.append(rest[:head])
        return segments + [[i] for i in rest[head:]]

    def prepare_multigrid(self, m: sparse.csr_array) -> None:
        """Build now the multigrid levels of ``m`` (kept for the next solve with this ``m``; see
        :meth:`_mg_solve`): :func:`cross_validate_sigma` does so for the final solve while its
        forked workers run (measured ~1 s CPU at n = 2, N = 10^6 off the critical path). Nothing
        happens where multigrid is not used.

        Parameters
        ----------
        m : sparse array, shape (U, U)
            The normal matrix of the next solves.
        """
        if self._mg_shape is None:
            return
        _, mean_row, fold = self._mg_fold(m)
        if fold is None:
            self._shared_levels()
            self._mg_cache = None
            self._mg_cache = (m, mean_row, self._mg_hier.for_matrix(m))

    def start_segment(self) -> None:
        """Forget the factor-PCG state of the previous segment (see :meth:`sweep_segments`)."""
        self._reuse = None

    def prepare_shared(self) -> None:
        """Build now the work that every fold and sigma shares, so that forked workers inherit it.

        The multigrid prolongations and coarse ``Gamma`` levels (:class:`GridHierarchy`) with the
        full data's level patterns (:class:`~pwas_hdl.fit.multigrid.LevelPatterns`), and for
        first order with CHOLMOD the symbolic analysis of the full-data pattern (see
        :meth:`_cholmod_solve`); otherwise each worker process would build its own (measured
        2-4 s CPU each at n = 2, N = 10^6). Serial solves build them lazily.
        """
        if self._mg_shape is not None:
            self._shared_levels()
        if (self.method == "direct" or self.factor_chain) and self.backend == "cholmod" and not self.block_mg:
            self._shared_pattern()

    def _shared_levels(self) -> GridHierarchy:
        """The multigrid hierarchy, with the full data's level patterns that every fold's levels fit
        (:meth:`~pwas_hdl.fit.multigrid.GridHierarchy.share`), built once."""
        if self._mg_hier is None:
            self._mg_hier = GridHierarchy(self._mg_shape, self.gamma)
        if self._mg_hier.shared is None and self._shared_hth is not None:
            self._mg_hier.share(self._shared_hth)
        return self._mg_hier

    def _shared_pattern(self) -> tuple | None:
        """``(PatternCholesky, Gamma's values)`` of the full-data pattern (first order), built once."""
        if self._shared_hth is not None and self._shared_chol is None:
            pattern = abs(self._shared_hth) + abs(self.gamma)
            chol = (PatternCholesky(pattern, grid_nested_dissection(self._mg_shape)) if self._nd_order
                    and (self.factor_chain or self.block_mg) else PatternCholesky(pattern))
            self._shared_chol = (chol, chol.align(self.gamma))
        return self._shared_chol

    def _direct_or_factor_pcg(self, m: sparse.csr_array, bk: np.ndarray, sigma: float,
                              x0k: np.ndarray | None) -> tuple[np.ndarray, SolveInfo]:
        """The direct solve, or PCG with the fold's factor of another sigma (:data:`FACTOR_PCG_MAXITER`)."""
        st = self._reuse if self._reuse is not None and self._reuse["m"] is m else None
        if (self.factor_pcg and st is not None and not st["stopped"] and x0k is not None
                and self._m_cache is not None and self._m_cache[0] is m):
            chol = self._m_cache[1]
            a = (m + sigma * self.gamma).tocsr()
            pre = splinalg.LinearOperator(a.shape, matvec=chol.solve, dtype=float)
            wk, info = _cg(a, bk, pre, x0k, sigma, self.lam_gamma, self.rtol, self._factor_pcg_cap)
            # converged on the residual computed afresh (whatever CG's own recurrence said: it can
            # stop at the cap a hair above the tolerance while the true residual is below), else
            # refactorise (the iterate is dropped)
            if info.rel_residual <= self.rtol:
                st["last"] = info.iterations
                st["stopped"] = info.iterations > self._factor_pcg_cap // 2
                return wk, SolveInfo("factor-pcg", info.iterations, info.rel_residual, info.weight_bound, True)
            st["stopped"] = True
            self.factor_pcg_failures += 1
        fallbacks = self.superlu_fallbacks
        wk = self._direct(m, bk, sigma)
        if self.factor_pcg:
            # a SuperLU fallback leaves no usable CHOLMOD factor of this sigma
            usable = self.backend == "cholmod" and self.superlu_fallbacks == fallbacks
            self._reuse = {"m": m, "last": 0, "stopped": (st["stopped"] if st is not None else False) or not usable}
        return wk, SolveInfo("direct")

    def _restrict(self, m: sparse.sparray) -> sparse.csr_array:
        m = sparse.csr_array(m)
        return m if self.keep is None else sparse.csr_array(m[self.keep][:, self.keep])

    def restrict_matrix(self, m: sparse.sparray) -> sparse.csr_array:
        """``m`` on the unknowns that are solved for (identity map unless order 0 with empty vertices).

        Parameters
        ----------
        m : sparse array, shape (N, N)

        Returns
        -------
        scipy.sparse.csr_array, shape (U, U)
            The rows and columns of the kept vertices (``U = N`` when none is dropped).
        """
        return self._restrict(m)

    def _direct(self, m: sparse.csr_array, bk: np.ndarray, sigma: float) -> np.ndarray:
        """The direct solve of ``(m + sigma Gamma) w = bk`` with the chosen backend."""
        if self.backend == "cholmod":
            return self._cholmod_solve(m, bk, sigma)
        return _solve_spd((m + sigma * self.gamma).tocsc(), bk)

    def _cholmod_solve(self, m: sparse.csr_array, bk: np.ndarray, sigma: float) -> np.ndarray:
        """CHOLMOD factorisation of ``m + sigma Gamma``, then solve.

        The symbolic analysis is done once per ``m`` (per fold in the CV) on the pattern of
        ``m + Gamma`` and kept, with ``m``'s values on it, for the next call with the same ``m``;
        each sigma is then one numeric factorisation. First order analyses once, on the full-data
        pattern ``H'H + Gamma``, for all folds: there the grid edges of Gamma dominate the pattern
        and the fold's numeric factorisation was measured no dearer on it (n = 2, N = 10^6,
        T = 10^5: 1.66 / 1.38 s instead of 1.93 / 1.48 s at sigma = 1e-3 / 10), while each
        analysis costs 1.8-1.9 s CPU. For zero order, analysing each fold's own pattern rather
        than one pattern of the full ``H'H`` for all folds was measured 3x cheaper per numeric
        factorisation (n = 3, N = 262 144, zero order: 0.17-0.21 s instead of 0.53-0.61 s; the
        validation samples' entries cancel in ``H'H - H_v'H_v``). A non-positive pivot (``m`` is a
        difference of normal matrices, so at tiny sigma rounding can make it indefinite) falls
        back to SuperLU.
        """
        if self._m_cache is None or self._m_cache[0] is not m:
            self._m_cache = None  # free the previous factor first
            if self._shared_hth is not None:
                chol, g_vals = self._shared_pattern()
                try:
                    self._m_cache = (m, chol, chol.align(m), g_vals)
                except OutsidePattern:  # not a fold of the full-data matrix: its own analysis
                    self._m_cache = None
            if self._m_cache is None:
                chol = PatternCholesky(abs(m) + abs(self.gamma))
                self._m_cache = (m, chol, chol.align(m), chol.align(self.gamma))
        _, chol, m_vals, g_vals = self._m_cache
        try:
            chol.factorize(m_vals + sigma * g_vals)
        except NotPositiveDefinite:
            self.superlu_fallbacks += 1
            return _solve_spd((m + sigma * self.gamma).tocsc(), bk)
        return chol.solve(bk)

    def solve(
        self, m: sparse.csr_array, b: np.ndarray, sigma: float, x0: np.ndarray | None = None
    ) -> tuple[np.ndarray, SolveInfo]:
        """Weights for ``(m + sigma Gamma) w = b``.

        Parameters
        ----------
        m : sparse array, shape (U, U)
            A normal matrix already passed through :meth:`restrict_matrix` (``U`` kept unknowns).
        b : ndarray, shape (N,) or (N, nz)
            Full-size right-hand side.
        sigma : float
            The regularisation weight of ``Gamma``.
        x0 : ndarray, shape as ``b``, optional
            Full-size warm start (CG only).

        Returns
        -------
        w : ndarray, same shape as ``b``
        info : SolveInfo
        """
        b = np.asarray(b, dtype=float)
        bk = b if self.keep is None else b[self.keep]
        if self.uses_mg(m, sigma):
            x0k = None if x0 is None else (x0 if self.keep is None else np.asarray(x0)[self.keep])
            wk, info = self._mg_solve(m, bk, sigma, x0k)
            if not info.converged and self.fallback:
                wk = self._fallback_direct(m, bk, sigma)
                info = SolveInfo("direct-fallback", info.iterations)
        elif self.method == "direct" or self.uses_factor_chain(m, sigma):
            x0k = None if x0 is None else (x0 if self.keep is None else np.asarray(x0)[self.keep])
            wk, info = self._direct_or_factor_pcg(m, bk, sigma, x0k)
        else:
            a = (m + sigma * self.gamma).tocsr()
            x0k = None if x0 is None else (x0 if self.keep is None else np.asarray(x0)[self.keep])
            wk, info = _cg(a, bk, self._pre.get(a, sigma), x0k, sigma, self.lam_gamma, self.rtol, self.maxiter)
            if not info.converged and self.fallback:
                wk = self._fallback_direct(m, bk, sigma)
                info = SolveInfo("direct-fallback", info.iterations)
        self.infos.append(info)
        if self.keep is None:
            return wk, info
        w = np.zeros_like(b)
        w[self.keep] = wk
        return w, info


@single_blas_thread()
def solve_regularized(
    h: sparse.sparray,
    z: np.ndarray,
    sigma: float,
    gamma: sparse.sparray,
    method: Method = "auto",
    x0: np.ndarray | None = None,
    rtol: float = CG_RTOL,
    max_memory: int | str | None = None,
    return_info: bool = False,
) -> "np.ndarray | tuple[np.ndarray, SolveInfo]":
    """Weights ``w = (H'H + sigma Gamma)^{-1} H'z`` (eq. 16).

    Parameters
    ----------
    h : sparse array, shape (T, N)
        Alpha-basis matrix.
    z : ndarray, shape (T,) or (T, nz)
        Targets.
    sigma : float
        Tikhonov weight (``> 0``; unnormalised as in eq. 14).
    gamma : sparse array, shape (N, N)
        Regularisation matrix (symmetric positive definite, from :func:`tikhonov_matrix`).
    method : {"auto", "direct", "cg", "mg"}
        Sparse Cholesky / LU, or conjugate gradients to relative residual ``rtol`` (Jacobi- or, ``mg``,
        multigrid-preconditioned); ``auto`` by size and, first order, by the dominance of the
        penalty (see :data:`DIRECT_MAX_UNKNOWNS` and :data:`MG_DOMINANCE` for the rule,
        :data:`CG_RTOL` for the weight bound).
    x0 : ndarray, shape like the result, optional
        Warm start for CG.
    rtol : float
        CG tolerance.
    max_memory : int or str, optional
        Memory limit: bytes, or text with a binary suffix K, M, G or T (``"4G"`` = 4 GiB,
        :func:`parse_memory`); default ``$PWAS_HDL_MAX_MEMORY`` or a fraction of the available RAM
        (:func:`memory_limit`, checked by :func:`check_fit_memory`).
    return_info : bool
        Also return the :class:`SolveInfo`.

    Returns
    -------
    ndarray, shape (N,) or (N, nz)  (and SolveInfo with ``return_info``)

    Raises
    ------
    InputError
        ``sigma`` not a positive finite number.
    ResourceLimit
        Estimated memory over the limit.
    """
    if not (np.isfinite(sigma) and sigma > 0):
        raise InputError(f"sigma must be a positive finite number, got {sigma!r}")
    z = np.asarray(z, dtype=float)
    nz = 1 if z.ndim == 1 else z.shape[1]
    h = sparse.csr_array(h)
    est = check_fit_memory(h.shape[0], h.shape[1], _dims_of(h), nz, _order_of(gamma), method, max_memory,
                           grid_side=_grid_side(gamma, _dims_of(h)))
    ht = h.T.tocsr()
    hth = ht @ h
    solver, _ = _analysed_solver(hth, gamma, _dims_of(h), h.shape[0], nz, method, rtol, True, est,
                                 memory_limit(max_memory)[0], 1)
    w, info = solver.solve(solver.restrict_matrix(hth), ht @ z, float(sigma), x0)
    return (w, info) if return_info else w


#: :func:`solve_report` calls weights converged only where their relative residual, computed afresh,
#: is at most this: :data:`CG_RTOL` with room for the rounding of another order of the products
#: (a direct solve measures ~1e-15).
RESIDUAL_CHECK = 10 * CG_RTOL


def solve_report(
    h: sparse.sparray,
    z: np.ndarray,
    w: np.ndarray,
    sigma: float,
    gamma: sparse.sparray,
    info: SolveInfo | None = None,
    cv: "CVResult | None" = None,
) -> dict:
    """How well the weights ``w`` solve ``(H'H + sigma Gamma) w = H'z``, checked afresh.

    The residual ``r = H'z - (H'H + sigma Gamma) w`` is computed from ``h``, ``z`` and ``w``
    themselves (not taken from the solver), so the report holds for whatever produced ``w``: a
    factorisation, CG stopped at its tolerance, or CG stopped at its iteration cap. Since
    ``H'H + sigma Gamma >= sigma lambda_min(Gamma) I``, ``||w - w_exact||_2 <= ||r||_2 /
    (sigma lambda_min(Gamma))`` (:func:`gamma_min_eigenvalue`, a Gershgorin bound).

    Parameters
    ----------
    h : sparse array, shape (T, N)
    z : ndarray, shape (T,) or (T, nz)
    w : ndarray, shape (N,) or (N, nz)
    sigma : float
    gamma : sparse array, shape (N, N)
    info : SolveInfo, optional
        The solver's own account of the solve (method, iterations, whether it met its stopping rule).
    cv : CVResult, optional
        The cross-validation that chose sigma: its count of solves and of those that stopped unconverged.

    Returns
    -------
    dict
        ``rel_residual`` (largest ``||r_j|| / ||H'z_j||`` over the target columns ``j``, 0 where
        ``H'z_j = 0``; inf where a weight is not finite), ``weight_bound`` (largest
        ``||r_j|| / (sigma lambda_min(Gamma))``; None where Gershgorin gives no positive bound on
        ``lambda_min(Gamma)``, inf where a weight is not finite), ``converged`` (the solver's
        stopping rule met, where ``info`` tells, and ``rel_residual <= RESIDUAL_CHECK``),
        ``method`` and ``iterations`` (from ``info``, else None), ``cv_solves`` and
        ``cv_unconverged`` (from ``cv``, else None).
    """
    h = sparse.csr_array(h)
    z2 = np.asarray(z, dtype=float).reshape(h.shape[0], -1)
    w2 = np.asarray(w, dtype=float).reshape(h.shape[1], -1)
    htz = h.T @ z2
    r = htz - h.T @ (h @ w2) - float(sigma) * (gamma @ w2)
    rn, bn = np.linalg.norm(r, axis=0), np.linalg.norm(htz, axis=0)
    if not np.all(np.isfinite(rn)):  # a NaN or inf weight: no residual, no bound
        rel, worst = math.inf, math.inf
    else:
        rel = float(np.max(np.where(bn > 0, rn / np.where(bn > 0, bn, 1.0), 0.0), initial=0.0))
        worst = float(rn.max(initial=0.0))
    lam = float(sigma) * gamma_min_eigenvalue(gamma)
    bound = worst / lam if lam > 0 else None
    out = {
        "method": None if info is None else str(info.method),
        "iterations": None if info is None else int(info.iterations),
        # the solver's stopping rule met (where known) and the residual, computed afresh, at the
        # tolerance (RESIDUAL_CHECK: rounding between the solver's and this product's order aside)
        "converged": (info is None or bool(info.converged)) and rel <= RESIDUAL_CHECK,
        "rel_residual": rel,
        "weight_bound": bound,
        "cv_solves": None,
        "cv_unconverged": None,
    }
    if cv is not None and "solves" in cv.solver:
        out["cv_solves"] = int(cv.solver["solves"])
        out["cv_unconverged"] = int(cv.solver.get("unconverged", 0))
    return out


def solve_warnings(report: dict | None, sigma: float) -> list[str]:
    """The ``warning:`` lines a :func:`solve_report` calls for (none when every solve converged).

    One line when the weights' own solve stopped unconverged (its residual and weight bound, and
    what makes the system better conditioned), one when some of the CV's solves did (the CV errors
    of those sigmas are then approximate, and so may be the choice of sigma).

    Parameters
    ----------
    report : dict or None
        What :func:`solve_report` returns (None or empty: no warning).
    sigma : float
        The sigma of the weights' solve (named in the message).

    Returns
    -------
    list of str
        Zero, one or two lines, each starting with ``warning:``.
    """
    if not report:
        return []
    out = []
    if not report.get("converged", True):
        its = report.get("iterations")
        how = f"stopped after {its} iterations" if its else "stopped"
        bound, rel = report.get("weight_bound"), report.get("rel_residual")
        finite = bound is not None and math.isfinite(bound)
        off = (f"the weights are within {bound:.3g} (2-norm) of the exact solution" if finite
               else "no bound on the weights' error is available")
        at = f"at relative residual {rel:.3g}" if rel is not None and math.isfinite(rel) else "with no finite residual"
        out.append(f"warning: the weights did not converge: the solve at sigma = {sigma:.3g} {how} {at} "
                   f"(target {CG_RTOL:g}); {off}. A larger --sigma, fewer partitions (-p) or more samples per "
                   "weight make the system better conditioned")
    bad, total = report.get("cv_unconverged"), report.get("cv_solves")
    if bad:
        out.append(f"warning: {bad} of {total} cross-validation solves stopped unconverged: the CV errors at "
                   "those sigmas, and so the choice of sigma, are approximate")
    return out


@dataclass
class CVResult:
    """Outcome of the cross-validation of sigma.

    Attributes
    ----------
    sigmas : ndarray, shape (S,)
        Candidate values tried.
    mse : ndarray, shape (S,)
        Mean validation mean-squared error (over folds and targets) for each candidate.
    best_sigma : float
        The candidate with the lowest validation MSE.
    folds : int
        Number of folds.
    fold_mse : ndarray, shape (folds, S)
        Validation MSE of each fold and candidate.
    solver : dict
        How the systems were solved: ``method``, ``solves``, CG ``iterations`` in total,
        ``max_rel_residual``, ``all_converged``, ``unconverged`` (the count of solves that stopped
        unconverged), ``direct_fallbacks``, ``solves_by_method`` (count per
        :attr:`SolveInfo.method`: ``auto`` mixes multigrid and the direct solve in first order),
        ``superlu_fallbacks`` (CHOLMOD pivots that were not positive), ``weight_bound`` (folds, S), the bound of each
        solve on ``max_col ||w - w_exact||_2`` (zero for the direct solve), and ``fork_tasks`` (the CPU
        seconds and worker pid of each task on forked workers, else empty) and
        ``parent_overlap_cpu_s`` (this process's CPU seconds while they ran: the final solve's
        multigrid levels); not written to the model file.
    final_weights : ndarray, shape (N,) or (N, nz), or None
        With ``final_solve=True`` (:func:`cross_validate_sigma`): the full-data weights at
        ``best_sigma``, as :func:`solve_regularized` returns them; else None.
        :meth:`PWASVirtualSensor.fit <pwas_hdl.fit.virtual_sensor.PWASVirtualSensor.fit>` takes
        them and leaves None in ``cv_``. Not written to the model file.
    final_info : SolveInfo or None
        How ``final_weights`` were solved (with ``final_solve=True``; else None).
    shuffle : bool
        The folds were shuffled samples (``fit --cv-shuffle``), not contiguous blocks; written to
        the model file as ``shuffle: true`` only when set.
    """

    sigmas: np.ndarray
    mse: np.ndarray
    best_sigma: float
    folds: int
    fold_mse: np.ndarray = field(repr=False, default_factory=lambda: np.empty(0))
    solver: dict = field(repr=False, default_factory=dict)
    final_weights: np.ndarray | None = field(repr=False, default=None, compare=False)
    final_info: "SolveInfo | None" = field(repr=False, default=None, compare=False)
    shuffle: bool = False

    def to_dict(self) -> dict:
        """The ``fit.cv`` block of the model file.

        Returns
        -------
        dict
            ``sigmas`` and ``mse`` (lists of ``S`` floats), ``best_sigma`` (float), ``folds`` (int)
            and, for shuffled folds only, ``shuffle: true`` (JSON types).
        """
        d = {
            "sigmas": [float(s) for s in self.sigmas],
            "mse": [float(v) for v in self.mse],
            "best_sigma": float(self.best_sigma),
            "folds": int(self.folds),
        }
        if self.shuffle:
            d["shuffle"] = True
        return d


def fold_labels(n_rows: int, folds: int, shuffle: bool = False, seed: int = 0) -> np.ndarray:
    """Fold number of every row: contiguous blocks (default, honest for time series) or shuffled."""
    if folds < 2:
        raise InputError(f"cross-validation needs at least 2 folds, got {folds}")
    if n_rows < folds:
        raise InputError(f"cannot split {n_rows} samples into {folds} folds (--folds); use --folds {n_rows} or fewer, or more data")
    labels = (np.arange(n_rows) * folds) // n_rows
    if shuffle:
        labels = np.random.default_rng(seed).permutation(labels)
    return labels


def fork_workers(executor, n_unknowns: int) -> int:
    """Forked processes for the CV folds: the executor's local ``workers`` (``>= 2``, no scheduler)
    from :data:`FORK_MIN_UNKNOWNS` unknowns where the system can fork, else 0 (see
    :func:`_fork_segments`)."""
    if executor is None or getattr(executor, "scheduler", None) is not None:
        return 0
    workers = getattr(executor, "workers", None) or 0
    if workers < 2 or n_unknowns < FORK_MIN_UNKNOWNS or not fork_available():
        return 0
    return int(workers)


def _map_folds(fn: Callable, folds: int, executor, n_sigmas: int,
               progress: Callable[[int, int], None] | None) -> list:
    """``[fn(f) for f in range(folds)]``: the map hook of :func:`cross_validate_sigma`.

    On ``executor`` (a distributed :class:`pwas_hdl.flow.executor.Executor`) one task per fold
    (``fn(f, progress=None)``: what is shipped holds no callback, which need not pickle, and the
    progress is counted per fold here); otherwise in this process, in fold order, with the per-solve
    ``fn(f, progress=progress)``. Either way the results are those of the serial loop. (Forked local
    workers take the folds' segments instead, see :func:`_fork_segments`.)
    """
    if executor is None or not getattr(executor, "distributed", False) or folds < 2:
        return [fn(f, progress=progress) for f in range(folds)]
    report = None if progress is None else (lambda done, total: progress(done * n_sigmas, total * n_sigmas))
    return executor.map(partial(fn, progress=None), range(folds), labels=[f"cv fold {f}" for f in range(folds)],
                        progress=report)


#: Relative cost of a multigrid-solved sigma against a factorised one, for the longest-first order
#: of the forked segments (:func:`_fork_segments`; measured at n = 2, N = 10^6: 0.5-1.1 s per
#: multigrid solve against 1.5-1.9 s per factorisation and solve).
_MG_COST = 0.4

#: The same for a sigma of the factor chain (:data:`FACTOR_DOMINANCE_CG`) against a Jacobi-CG one:
#: measured at n = 3, N = 262 144, fold 0: the chain of 7 sigmas ~29 s (its factorisation 14-17 s),
#: the 5 Jacobi-CG sigmas 8.4 s, the 9 multigrid ones 2.6 s.
_CHAIN_COST = 2.5

#: The same for a sigma of the data-block multigrid cycle (:data:`MG_BLOCK_DOMINANCE`): measured
#: 0.5-1.1 s at n = 2 and 3 (fold 0), about twice a Gauss-Seidel-cycle sigma.
_MG_BLOCK_COST = 0.8


#: What a worker spends on a fold before its first multigrid sigma, in the units of
#: :data:`_MG_COST`: the fold's multigrid levels (:meth:`~pwas_hdl.fit.multigrid.GridHierarchy.for_matrix`)
#: and, for the data-block cycle, the block's symbolic analysis. Measured at n = 2, N = 10^6
#: (T = 10^5, a fold, CPU): 1.0 s for the levels on an idle core, 2.5 s beside two busy workers,
#: against 0.5-1.1 s a multigrid sigma.
_MG_SETUP_COST = 0.6


def _makespan(task_costs: list[float], procs: int) -> float:
    """The finish time of tasks handed out longest first to whichever of ``procs`` workers is free."""
    loads = [0.0] * max(int(procs), 1)
    for c in sorted(task_costs, reverse=True):
        i = loads.index(min(loads))
        loads[i] += c
    return max(loads)


def _fold_tasks(segments: list[list[list[int]]], cost_of: Callable[[int, int], float], procs: int,
                setup_of: Callable[[int, int], float]) -> list[tuple]:
    """Tasks of :func:`_fork_segments` where segment ``k`` of fold ``f`` needs ``setup_of(f, k)``
    of set-up in every task it runs in (the largest of a task's segments counted once).

    A fold whose segments run as one task is set up once, a fold split into one task per segment
    once per segment (its tasks may run in different workers), but whole folds balance the
    workers worse (five folds on two workers). The cheapest folds are split, as few as give the
    shortest estimated finish (:func:`_makespan`, the set-up included); on a tie, more folds are
    split.
    """
    plain = [((f, k),) for f, segs in enumerate(segments) for k in range(len(segs))]
    setups = [[float(setup_of(f, k)) for k in range(len(segs))] for f, segs in enumerate(segments)]
    if not any(c > 0 for row in setups for c in row):
        return plain  # nothing to save: one task per segment, as without set-up costs
    fold_cost = [sum(cost_of(f, i) for seg in segs for i in seg) for f, segs in enumerate(segments)]
    by_cost = sorted(range(len(segments)), key=lambda f: (fold_cost[f], f))
    best, best_split = float("inf"), len(segments)
    for n_split in range(len(segments) + 1):
        split = set(by_cost[:n_split])
        costs = []
        for f, segs in enumerate(segments):
            if f in split:
                costs += [sum(cost_of(f, i) for i in seg) + setups[f][k] for k, seg in enumerate(segs)]
            else:
                costs.append(fold_cost[f] + max(setups[f], default=0.0))
        span = _makespan(costs, procs)
        if span <= best * (1 + 1e-9):
            best, best_split = min(best, span), n_split
    split = set(by_cost[:best_split])
    return [t for f, segs in enumerate(segments)
            for t in ([((f, k),) for k in range(len(segs))] if f in split else [tuple((f, k) for k in range(len(segs)))])
            if t]


def _fork_segments(run: Callable, segments: list[list[list[int]]], cost_of: Callable[[int, int], float],
                   procs: int, n_sigmas: int, progress, stats: list | None,
                   parent_work: Callable[[], object] | None = None,
                   heavy: Callable[[int, int], bool] | None = None, factor_lock=None,
                   after_group: Callable[[], object] | None = None,
                   setup_of: Callable[[int, int], float] | None = None) -> list[list]:
    """Every fold's sweep segments (:meth:`NormalEquationSolver.sweep_segments`) on ``procs`` forked
    workers (:func:`pwas_hdl.fit.fork_map.fork_map`: the data are inherited, not pickled).

    The segments are independent tasks handed out longest first (estimated cost
    ``cost_of(f, i)`` per sigma ``i`` of fold ``f``: a factorised or Jacobi-CG sigma 1, a multigrid
    one :data:`_MG_COST`, one of the factor chain :data:`_CHAIN_COST`), so that the workers finish
    within about one factorisation of each other. ``parent_work`` runs in the parent meanwhile (see
    :func:`~pwas_hdl.fit.fork_map.fork_map`). ``run(f, segment)`` returns that segment's results; the
    return value is ``[[result of each segment of fold f, in segment order] for f]``. With ``heavy(f, k)``
    (segment ``k`` of fold ``f`` factorises) the factorising segments of all folds form one task that
    holds ``factor_lock`` (one factor resident at a time, see :func:`plan_fit_memory`) and calls
    ``after_group()`` before it releases it. Otherwise, with ``setup_of(f, k)`` (what a worker
    spends on fold ``f`` before segment ``k`` can start, in the units of ``cost_of``, once per
    task; see :data:`_MG_SETUP_COST`) the segments of some folds run as one task (:func:`_fold_tasks`).
    """
    # a task is a tuple of (fold, segment) pairs run one after another; one segment each, except
    # that with ``heavy`` (one factor at a time) every factorising segment is in one task, which
    # holds ``factor_lock`` while it runs, and that with ``setup_of`` whole folds may be one task
    # each (_fold_tasks)
    tasks = [((f, k),) for f, segs in enumerate(segments) for k in range(len(segs))]
    group: tuple = ()
    if heavy is not None:
        group = tuple(t[0] for t in tasks if heavy(*t[0]))
        if group:
            tasks = [group] + [t for t in tasks if t[0] not in set(group)]
    elif setup_of is not None:
        tasks = _fold_tasks(segments, cost_of, procs, setup_of)
    cost = {t: sum(cost_of(f, i) for f, k in t for i in segments[f][k]) for t in tasks}
    tasks.sort(key=lambda t: -cost[t])  # stable: equal costs stay in fold order

    def run_task(t: tuple) -> list:
        if group and t == group:
            with factor_lock if factor_lock is not None else nullcontext():
                out = [run(f, segments[f][k]) for f, k in t]
                if after_group is not None:
                    after_group()  # e.g. free the last factor before the lock is released
                return out
        return [run(f, segments[f][k]) for f, k in t]

    total = len(segments) * n_sigmas
    report = None if progress is None else (lambda done, n: progress(done * total // n, total))
    out = fork_map(run_task, tasks, procs, report, stats, parent_work)
    by_seg = {pair: r for t, res in zip(tasks, out) for pair, r in zip(t, res)}
    if stats is not None:  # fork_map gives them in the order of ``tasks``: back to (fold, segment)
        info = dict(zip(tasks, stats[-len(tasks):]))
        del stats[-len(tasks):]
        stats.extend(info[t] for t in sorted(tasks))
    return [[by_seg[(f, k)] for k in range(len(segs))] for f, segs in enumerate(segments)]


@single_blas_thread()
def cross_validate_sigma(
    h: sparse.sparray,
    z: np.ndarray,
    gamma: sparse.sparray,
    sigmas: Sequence[float] | None = None,
    folds: int = 5,
    shuffle: bool = False,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    method: Method = "auto",
    rtol: float = CG_RTOL,
    max_memory: int | str | None = None,
    executor: "Executor | None" = None,
    final_solve: bool = False,
    block_smoother: bool = True,
) -> CVResult:
    """Choose sigma by k-fold cross-validation over a grid of candidates.

    Work is reused across folds and sigmas: ``H'H`` and ``H'z`` are formed once and each fold's
    normal equations are the total minus the fold's part (``H_k'H_k = H'H - H_v'H_v``). With the
    direct method there is one sparse factorisation per (fold, sigma); with multigrid (first order,
    see :data:`MG_DOMINANCE`) the levels of a fold are built once and each sigma is an axpy per
    level, a small coarsest factorisation and the V-cycle PCG. The sigmas of a fold are solved
    from the largest down, each iterative solve warm-started from the previous sigma's weights;
    the Jacobi/AMG preconditioner of CG is built from the full-data ``H'H`` and shared by all
    folds (see :class:`NormalEquationSolver`).

    Parameters
    ----------
    h : sparse array, shape (T, N)
    z : ndarray, shape (T,) or (T, nz)
    gamma : sparse array, shape (N, N)
    sigmas : sequence of float, optional
        Candidates (default :data:`DEFAULT_SIGMA_GRID`).
    folds : int
        Number of folds (``>= 2``).
    shuffle : bool
        Shuffle rows before splitting (default: contiguous blocks, which keeps validation samples
        away from the correlated neighbours of training samples).
    seed : int
        Seed of the shuffle.
    progress : callable(done, total), optional
        Called after each solve.
    method : {"auto", "direct", "cg", "mg"}
        Solver (see :func:`choose_method` and :class:`NormalEquationSolver`).
    rtol : float
        CG relative-residual tolerance.
    max_memory : int or str, optional
        Memory limit: bytes, or text with a binary suffix K, M, G or T (``"4G"`` = 4 GiB,
        :func:`parse_memory`); default ``$PWAS_HDL_MAX_MEMORY`` or a fraction of the available RAM
        (:func:`memory_limit`, checked by :func:`check_fit_memory`).
    executor : pwas_hdl.flow.executor.Executor, optional
        Runs the folds (one task per fold: its sigma sweep) on Dask workers when it is
        distributed, or, with local ``workers >= 2`` and at least
        :data:`FORK_MIN_UNKNOWNS` unknowns, on that many forked processes that inherit the data
        (one task per segment of a fold's sweep, or per whole fold where its multigrid set-up
        outweighs the balance, see :func:`_fork_segments`); the result is the serial one.
    final_solve : bool
        Also solve the full-data system at the chosen sigma with this CV's solver
        (:attr:`CVResult.final_weights`): the same weights as ``solve_regularized(h, z, best_sigma,
        gamma, method, rtol=rtol)`` (same solver, same arithmetic) without forming ``H'H`` again or
        rebuilding the shared analysis / multigrid hierarchy (measured ~1-2 s CPU at n = 2, N = 10^6,
        first order).
    block_smoother : bool
        First order with multigrid: the data-dominated sigmas by the data-block cycle (the default;
        see :data:`MG_BLOCK_DOMINANCE` and :class:`NormalEquationSolver`).

    Returns
    -------
    CVResult
    """
    if sigmas is not None and hasattr(sigmas, "__len__"):
        check_limit("the number of sigma candidates", len(sigmas), MAX_SIGMA_CANDIDATES, "give fewer candidates")
    sig = np.asarray(DEFAULT_SIGMA_GRID if sigmas is None else sigmas, dtype=float).reshape(-1)
    check_limit("the number of sigma candidates", sig.size, MAX_SIGMA_CANDIDATES, "give fewer candidates")
    if sig.size == 0 or not np.all(np.isfinite(sig)) or np.any(sig <= 0):
        bad = sig[~(np.isfinite(sig) & (sig > 0))]
        raise InputError("sigma candidates must be positive finite numbers (--sigma-grid), got "
                         + (f"{float(bad[0])!r}" if bad.size else "none") + "; give e.g. 1e-4,1e-3 or logspace:-6:1:8")
    h = sparse.csr_array(h)
    z2 = np.asarray(z, dtype=float).reshape(h.shape[0], -1)
    labels = fold_labels(h.shape[0], folds, shuffle, seed)
    mem_plan = plan_fit_memory(h.shape[0], h.shape[1], _dims_of(h), z2.shape[1], _order_of(gamma), method, max_memory,
                               processes=max(fork_workers(executor, h.shape[1]), 1), block_smoother=block_smoother,
                               grid_side=_grid_side(gamma, _dims_of(h)))
    ht = h.T.tocsr()
    hth = (ht @ h).tocsr()
    htz = ht @ z2
    solver, est = _analysed_solver(hth, gamma, _dims_of(h), h.shape[0], z2.shape[1], method, rtol, block_smoother,
                                   mem_plan["estimate"], mem_plan["limit"], mem_plan["processes"])
    mem_plan = dict(mem_plan, estimate=est)
    hth_r = solver.restrict_matrix(hth)
    fold_mse = np.zeros((folds, sig.size))
    weight_bound = np.zeros((folds, sig.size))
    total, done = folds * sig.size, 0

    def fold_data(f: int) -> tuple:
        """The fold's validation rows, their basis rows, and its training normal equations."""
        val = labels == f
        hv = h[np.flatnonzero(val)]
        hvt = hv.T.tocsr()
        a_tr = (hth_r - solver.restrict_matrix(hvt @ hv)).tocsr()
        return val, hv, a_tr, htz - hvt @ z2[val]

    def run_segment(data: tuple, segment: list[int], progress=None) -> tuple:
        """Solve one segment of a fold's sweep (it starts afresh: see ``sweep_segments``)."""
        nonlocal done
        val, hv, a_tr, b_tr = data
        first, fallbacks, block_fails = len(solver.infos), solver.superlu_fallbacks, solver.block_failures
        solver.start_segment()
        w, mse_s, bound_s = None, [], []
        for i in segment:
            w, info = solver.solve(a_tr, b_tr, float(sig[i]), x0=w)
            bound_s.append(info.weight_bound)
            mse_s.append(float(np.mean((z2[val] - hv @ w) ** 2)))
            done += 1
            if progress is not None:
                progress(done, total)
        return (segment, mse_s, bound_s, solver.infos[first:], solver.superlu_fallbacks - fallbacks,
                solver.block_failures - block_fails)

    def merge(results: list) -> tuple[np.ndarray, np.ndarray, list, int, int]:
        mse_f, bound_f, infos_f, fb, bf = np.zeros(sig.size), np.zeros(sig.size), [], 0, 0
        for segment, mse_s, bound_s, infos_s, fb_s, bf_s in results:
            mse_f[segment], bound_f[segment] = mse_s, bound_s
            infos_f += infos_s
            fb += fb_s
            bf += bf_s
        return mse_f, bound_f, infos_f, fb, bf

    def one_fold(f: int, progress=None) -> tuple[np.ndarray, np.ndarray, list, int, int]:
        with single_blas_thread():  # also on a Dask worker (a remote one need not limit its BLAS)
            data = fold_data(f)
            return merge([run_segment(data, seg, progress) for seg in solver.sweep_segments(data[2], sig)])

    # one fold = one task (serial, Dask) or one segment or fold = one task (forked workers); the counts a
    # task leaves in the solver come back with its results
    task_stats: list = []
    overlap = [0.0]  # CPU seconds of this process spent while forked workers ran
    # every fold is independent of the others (each solver state a fold's sweep uses is a function
    # of that fold and sigma: see sweep_segments and _Preconditioner), so the folds may run anywhere
    procs = fork_workers(executor, solver.n if solver.keep is None else solver.keep.size) if folds >= 2 else 0
    procs = min(procs, mem_plan["processes"]) if procs else 0  # the memory limit's plan (plan_fit_memory)
    one_factor = bool(procs > 1 and mem_plan["one_factor"])
    if procs == 1:
        procs = 0  # one process: this one, serially
    if procs:
        import multiprocessing

        # one factor at a time: the factorising segments run in one task, holding this lock; a
        # fallback factorisation elsewhere waits for it (NormalEquationSolver.factor_lock)
        solver.factor_lock = multiprocessing.get_context("fork").RLock() if one_factor else None
        # the forked workers inherit every fold's matrices and the shared analysis (built here once)
        datas = [fold_data(f) for f in range(folds)]
        segments = [solver.sweep_segments(d[2], sig) for d in datas]
        solver.prepare_shared()

        def prepare_final() -> None:
            """While the workers run: the final solve's multigrid levels (its sigma is not known yet)."""
            c0 = time.process_time()
            if final_solve and any(solver.full_data_uses_mg(float(s)) for s in sig):
                solver.prepare_multigrid(hth_r)
            overlap[0] = time.process_time() - c0

        heavy = (lambda f, k: any(solver.factorises(datas[f][2], float(sig[i])) for i in segments[f][k])) if one_factor else None
        per_fold = _fork_segments(lambda f, seg: run_segment(datas[f], seg), segments,
                                  lambda f, i: solver.segment_cost(datas[f][2], float(sig[i])), procs, sig.size,
                                  progress, task_stats, prepare_final, heavy=heavy, factor_lock=solver.factor_lock,
                                  after_group=solver.drop_factor,
                                  setup_of=lambda f, k: _MG_SETUP_COST if any(
                                      solver.uses_mg(datas[f][2], float(sig[i])) for i in segments[f][k]) else 0.0)
        solver.factor_lock = None
        del datas
        parts = [merge(r) for r in per_fold]
    else:
        # the memory limit allows one process (plan_fit_memory): the folds run here, not on Dask workers
        serial_only = mem_plan["processes"] == 1 and mem_plan["requested"] > 1
        parts = _map_folds(one_fold, folds, None if serial_only else executor, sig.size, progress)
    for f, (mse_f, bound_f, *_) in enumerate(parts):
        fold_mse[f], weight_bound[f] = mse_f, bound_f
    solver.infos = [i for part in parts for i in part[2]]
    solver.superlu_fallbacks = sum(part[3] for part in parts)
    mse = fold_mse.mean(axis=0)
    best = float(sig[int(np.argmin(mse))])
    infos = solver.infos
    summary = {
        "method": solver.method,
        "solves": len(infos),
        "iterations": int(sum(i.iterations for i in infos)),
        "max_rel_residual": float(max((i.rel_residual for i in infos), default=0.0)),
        "all_converged": bool(all(i.converged for i in infos)),
        "unconverged": int(sum(not i.converged for i in infos)),
        "direct_fallbacks": int(sum(i.method == "direct-fallback" for i in infos)),
        "solves_by_method": {k: int(sum(i.method == k for i in infos)) for k in sorted({i.method for i in infos})},
        "superlu_fallbacks": int(solver.superlu_fallbacks),
        # data blocks that were not positive definite (those sigmas by the Gauss-Seidel cycle)
        "block_failures": int(sum(part[4] for part in parts)),
        "weight_bound": weight_bound,
        # forked workers (see _fork_segments): per task (a segment or a whole fold), in (fold, segment) order, its CPU
        # seconds and the worker's pid
        "fork_tasks": [{"cpu_s": float(c), "pid": int(p)} for c, p in task_stats],
        # CPU seconds this process spent while the forked workers ran (off the critical path)
        "parent_overlap_cpu_s": float(overlap[0]),
        # the memory limit's plan (plan_fit_memory): the forked processes used, whether the factors
        # were held one at a time, and why the plan differs from the request (None: as asked)
        "memory_plan": {"processes": max(procs, 1), "requested": mem_plan["requested"], "one_factor": one_factor,
                        "estimate_mib": mem_plan["estimate"]["total"] / 2**20, "reason": mem_plan["reason"]},
    }
    final_w = final_info = None
    if final_solve:
        solver.start_segment()
        final_w, final_info = solver.solve(hth_r, htz[:, 0] if np.ndim(z) == 1 else htz, best)
    return CVResult(sig, mse, best, folds, fold_mse, summary, final_w, final_info, shuffle=bool(shuffle))
