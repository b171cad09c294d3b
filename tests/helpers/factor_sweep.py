"""A warm-started sigma sweep checked solve by solve against the direct solve (the factor-PCG rules' tests)."""

from __future__ import annotations

import numpy as np

from pwas_hdl.fit import regularized_lsq as rl


def sweep_against_direct(solver, hth, b, gam, sigmas, order, cap: int) -> list[str]:
    """Solve ``hth + sigma gam`` for ``sigmas[order]`` in that order, each warm-started from the
    previous solution; a factor-PCG solve must converge within ``cap`` iterations and the stated
    weight bound of the direct solve, any other must be a direct solve as exact as SuperLU's.
    Returns the methods used.

    "As exact": a relative residual at the rounding level, ``DIRECT_RESIDUAL``, as SuperLU's own. No
    CG solve stopped at ``CG_RTOL`` reaches it, and the exact solution of the next sigma of the grid
    (a stale factor) measured 1.3e-6 to 0.76 on these problems; any distance bound from SuperLU's weights
    would follow from the two residuals, so none is added. Element-wise equality of two direct
    solvers is not a property of the solver: at sigma = 1e-7 the 3-D chain's system has condition
    number 1.6e8, and CHOLMOD (nested dissection) and SuperLU (MMD) differ by 2.7e-8 relative on
    one weight on one CPU and by less on another, both with residuals ~3e-16."""
    w, methods = None, []
    for i in order:
        w, info = solver.solve(hth, b, float(sigmas[i]), x0=w)
        methods.append(info.method)
        a = (hth + sigmas[i] * gam).tocsc()
        wd = rl._solve_spd(a, b)
        if info.method == "factor-pcg":
            assert info.converged and info.rel_residual <= rl.CG_RTOL
            assert 0 < info.iterations <= cap
            assert float(np.linalg.norm(w - wd)) <= info.weight_bound
        else:
            nb = float(np.linalg.norm(b))
            r, rd = float(np.linalg.norm(b - a @ w)), float(np.linalg.norm(b - a @ wd))
            assert r <= DIRECT_RESIDUAL * nb and rd <= DIRECT_RESIDUAL * nb
    return methods


#: Relative residual ``||b - A w|| / ||b||`` a direct solve must reach in :func:`sweep_against_direct`
#: (measured 2-3e-16 for CHOLMOD and SuperLU on its problems; a CG solve stops at ``CG_RTOL`` = 1e-10).
DIRECT_RESIDUAL = 1e-13


def random_problem(n: int, p: int, t: int, seed: int):
    """``(H, z, Gamma)``: ``t`` uniform samples of ``sum_j sin(3 x_j)`` + noise on an ``n``-D grid
    of ``p`` partitions per axis over [-1.2, 1.2]^n, first-order Tikhonov."""
    from scipy import sparse

    from pwas_hdl.fit.geometry import Grid

    rng = np.random.default_rng(seed)
    grid = Grid(np.full(n, -1.2), np.full(n, 1.2), p)
    x = rng.uniform(-1.0, 1.0, (t, n))
    z = np.sin(3 * x).sum(axis=1) + 0.1 * rng.standard_normal(t)
    return sparse.csr_array(grid.basis_matrix(x)), z, rl.tikhonov_matrix(grid, 1)


def large_problem_rules(monkeypatch) -> None:
    """The size rules of a large problem (multigrid, forked workers) on a tiny one."""
    from pwas_hdl.fit import multigrid as mg

    monkeypatch.setattr(rl, "MG_MIN_UNKNOWNS", 100)
    monkeypatch.setattr(rl, "MG_BLOCK_MIN_DIRECT", 100)
    monkeypatch.setattr(rl, "FACTOR_PCG_MIN_UNKNOWNS", 100)
    monkeypatch.setattr(rl, "FORK_MIN_UNKNOWNS", 100)
    monkeypatch.setattr(mg, "COARSEST_MAX", 40)
