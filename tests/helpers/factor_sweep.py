"""A warm-started sigma sweep checked solve by solve against the direct solve (the factor-PCG rules' tests)."""

from __future__ import annotations

import numpy as np

from pwas_hdl.fit import regularized_lsq as rl


def sweep_against_direct(solver, hth, b, gam, sigmas, order, cap: int) -> list[str]:
    """Solve ``hth + sigma gam`` for ``sigmas[order]`` in that order, each warm-started from the
    previous solution; a factor-PCG solve must converge within ``cap`` iterations and the stated
    weight bound of the direct solve, any other must equal it. Returns the methods used."""
    w, methods = None, []
    for i in order:
        w, info = solver.solve(hth, b, float(sigmas[i]), x0=w)
        methods.append(info.method)
        wd = rl._solve_spd((hth + sigmas[i] * gam).tocsc(), b)
        if info.method == "factor-pcg":
            assert info.converged and info.rel_residual <= rl.CG_RTOL
            assert 0 < info.iterations <= cap
            assert float(np.linalg.norm(w - wd)) <= info.weight_bound
        else:
            np.testing.assert_allclose(w, wd, rtol=1e-8, atol=1e-10)
    return methods


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
    monkeypatch.setattr(rl, "FORK_MIN_UNKNOWNS", 100)
    monkeypatch.setattr(mg, "COARSEST_MAX", 40)
