"""``cross_validate_sigma(..., final_solve=True)``: the full-data weights at the chosen sigma from the
CV's own solver are those of a separate :func:`solve_regularized` (same solver, same arithmetic),
for every solver path (direct zero / first order, multigrid, Jacobi-CG) and 1-D / 2-D targets."""

from __future__ import annotations

import numpy as np
import pytest

from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.regularized_lsq import cross_validate_sigma, solve_regularized, tikhonov_matrix


def _problem(shape, t, nz, seed=0):
    rng = np.random.default_rng(seed)
    grid = Grid(np.full(len(shape), -1.2), np.full(len(shape), 1.2), [s - 1 for s in shape])
    x = rng.uniform(-1.0, 1.0, (t, len(shape)))
    z = np.sin(3 * x).sum(axis=1, keepdims=True) + 0.1 * rng.standard_normal((t, nz))
    return grid, grid.basis_matrix(x), (z[:, 0] if nz == 1 else z)


@pytest.mark.parametrize("order,method,nz", [(0, "auto", 1), (1, "auto", 2), (1, "mg", 1), (1, "cg", 1), (0, "cg", 2)])
def test_final_weights_equal_a_separate_solve(order, method, nz):
    grid, h, z = _problem((17, 21), 400, nz)
    gam = tikhonov_matrix(grid, order)
    sig = np.logspace(-4, 2, 5)
    cv = cross_validate_sigma(h, z, gam, sig, folds=3, method=method, final_solve=True)
    w_ref, info_ref = solve_regularized(h, z, cv.best_sigma, gam, method=method, return_info=True)
    assert cv.final_weights.shape == w_ref.shape == ((grid.n_vertices,) if nz == 1 else (grid.n_vertices, nz))
    np.testing.assert_array_equal(cv.final_weights, w_ref)
    assert cv.final_info.method == info_ref.method and cv.final_info.iterations == info_ref.iterations


def test_without_final_solve_nothing_is_kept():
    grid, h, z = _problem((9, 9), 100, 1)
    cv = cross_validate_sigma(h, z, tikhonov_matrix(grid, 1), np.logspace(-3, 1, 3), folds=2)
    assert cv.final_weights is None and cv.final_info is None


def test_forked_cv_prepares_the_final_multigrid_while_the_workers_run(monkeypatch):
    """Forked folds (issue 18, fifth pass): the parent builds the final solve's multigrid levels
    while the workers run; the final weights stay those of a separate solve, bit for bit."""
    from pwas_hdl.fit import fork_map
    from pwas_hdl.fit import multigrid as mg
    from pwas_hdl.fit import regularized_lsq as rl
    from pwas_hdl.flow.executor import Executor

    if not fork_map.fork_available():
        pytest.skip("needs fork")
    monkeypatch.setattr(rl, "MG_MIN_UNKNOWNS", 100)
    monkeypatch.setattr(rl, "MG_BLOCK_MIN_DIRECT", 100)
    monkeypatch.setattr(rl, "FORK_MIN_UNKNOWNS", 100)
    monkeypatch.setattr(mg, "COARSEST_MAX", 40)
    grid, h, z = _problem((31, 31), 600, 1, seed=4)
    gam = tikhonov_matrix(grid, 1)
    sig = np.logspace(-1, 2, 4)  # all by multigrid (the Gauss-Seidel or the data-block cycle), and so the final solve
    built, for_matrix = [], mg.GridHierarchy.for_matrix

    def recording(self, m):  # in this process: was the map still running (its function set)?
        built.append(fork_map._TASK is not None)
        return for_matrix(self, m)

    monkeypatch.setattr(mg.GridHierarchy, "for_matrix", recording)
    with Executor(workers=2) as ex:
        cv = cross_validate_sigma(h, z, gam, sig, folds=3, executor=ex, final_solve=True)
    monkeypatch.setattr(mg.GridHierarchy, "for_matrix", for_matrix)
    assert cv.solver["fork_tasks"] and cv.solver["parent_overlap_cpu_s"] > 0
    assert built == [True]  # the final solve's levels, built during the map and not again after it
    assert cv.final_info.method in ("mg", "mg-block")  # both on the levels built during the map
    w_ref = solve_regularized(h, z, cv.best_sigma, gam)
    np.testing.assert_array_equal(cv.final_weights, w_ref)
