"""The first-order CV at scale in 3-D (issue 18, fifth pass): where the base method is Jacobi-CG,
the smallest sigmas of a fold are the *factor chain* (a nested-dissection CHOLMOD factorisation of
the smallest, factor-PCG upwards), and a Jacobi- or multigrid-CG solve that stops unconverged is
re-done by the factorisation, so every CV solve converges (the stopping rule unchanged)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from pwas_hdl.errors import InternalError
from pwas_hdl.fit import regularized_lsq as rl
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.regularized_lsq import NormalEquationSolver, cross_validate_sigma, tikhonov_matrix
from pwas_hdl.fit.sparse_cholesky import PatternCholesky, cholmod_available, grid_nested_dissection
from pwas_hdl.flow.executor import Executor

from helpers.factor_sweep import large_problem_rules, random_problem, sweep_against_direct

pytestmark = pytest.mark.skipif(not cholmod_available(), reason="needs CHOLMOD (cvxopt)")

SIGMAS = np.logspace(-7, 2, 10)


@pytest.fixture()
def rules_3d(monkeypatch):
    """The size rules of n = 3, p = 63 (Jacobi-CG base, multigrid, the factor chain) on 10^3 vertices."""
    large_problem_rules(monkeypatch)
    monkeypatch.setitem(rl.DIRECT_MAX_UNKNOWNS_CHOLMOD, (1, 3), 100)


def _problem(t=800, seed=5):
    return random_problem(3, 9, t, seed)


def test_grid_nested_dissection_is_a_permutation_that_factorises():
    perm = grid_nested_dissection((7, 5, 6), leaf=8)
    assert sorted(perm.tolist()) == list(range(7 * 5 * 6))
    # the last eliminated vertices are the first separator: the mid-plane of the longest axis
    last = np.unravel_index(perm[-5 * 6:], (7, 5, 6))[0]
    assert np.all(last == 3)
    grid = Grid(np.full(3, -1.0), np.full(3, 1.0), 6)
    gam = tikhonov_matrix(grid, 1)
    a = (gam + sparse.identity(gam.shape[0])).tocsc()
    chol = PatternCholesky(a, grid_nested_dissection(grid.shape))
    chol.factorize(chol.align(a))
    b = np.arange(a.shape[0], dtype=float)
    np.testing.assert_allclose(a @ chol.solve(b), b, rtol=1e-10, atol=1e-9)
    with pytest.raises(InternalError, match="permutation"):  # our own ordering: a bug, not bad input
        PatternCholesky(a, np.zeros(a.shape[0], dtype=int))


def test_factor_chain_by_the_rule_within_the_bound_of_the_direct_solve(rules_3d):
    h, z, gam = _problem()
    hth = sparse.csr_array(h.T @ h)
    b = h.T @ z
    solver = NormalEquationSolver(hth, gam, 3, block_smoother=False)
    assert solver.method == "cg" and solver.factor_chain and solver.fallback
    chain = [i for i in range(SIGMAS.size) if solver.uses_factor_chain(hth, float(SIGMAS[i]))]
    rho = SIGMAS * float(gam.diagonal().mean()) / (float(hth.sum()) / hth.shape[0])
    assert chain == [i for i in range(SIGMAS.size) if rho[i] < rl.FACTOR_DOMINANCE_CG] and len(chain) >= 3
    segs = solver.sweep_segments(hth, SIGMAS)
    mg_idx = [i for i in range(SIGMAS.size) if solver.uses_mg(hth, float(SIGMAS[i]))]
    jacobi = [i for i in range(SIGMAS.size) if i not in chain and i not in mg_idx]
    assert mg_idx and jacobi
    # multigrid, then Jacobi-CG, from the largest sigma down, then the chain from the smallest up
    assert segs == [sorted(mg_idx, key=lambda i: -SIGMAS[i]), sorted(jacobi, key=lambda i: -SIGMAS[i]), chain]
    assert [solver.segment_cost(hth, float(SIGMAS[i])) for i in chain] == [rl._CHAIN_COST] * len(chain)
    solver.start_segment()
    methods = sweep_against_direct(solver, hth, b, gam, SIGMAS, chain, rl.FACTOR_PCG_MAXITER_CG)
    assert methods[0] == "direct" and methods[1] == "factor-pcg"


def test_unconverged_cg_is_redone_by_the_factorisation(rules_3d):
    h, z, gam = _problem()
    hth = sparse.csr_array(h.T @ h)
    b = h.T @ z
    solver = NormalEquationSolver(hth, gam, 3, maxiter=3, block_smoother=False)  # no Jacobi-CG converges in 3 iterations
    jacobi = solver.sweep_segments(hth, SIGMAS)[1]
    assert not any(solver.uses_mg(hth, float(SIGMAS[i])) for i in jacobi)
    assert jacobi
    w, info = solver.solve(hth, b, float(SIGMAS[jacobi[0]]))
    assert info.method == "direct-fallback" and info.converged
    np.testing.assert_allclose(w, rl._solve_spd((hth + SIGMAS[jacobi[0]] * gam).tocsc(), b), rtol=1e-8, atol=1e-10)


def test_cv_3d_all_converged_and_forked_gives_the_serial_result(rules_3d):
    h, z, gam = _problem()
    serial = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, block_smoother=False)
    by = serial.solver["solves_by_method"]
    assert serial.solver["all_converged"] and serial.solver["max_rel_residual"] <= rl.CG_RTOL
    assert by.get("factor-pcg", 0) > 0 and by.get("direct", 0) == 3 and by.get("mg", 0) > 0 and by.get("cg", 0) > 0
    direct = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, method="direct", block_smoother=False)
    assert direct.best_sigma == serial.best_sigma
    np.testing.assert_allclose(serial.fold_mse, direct.fold_mse, rtol=1e-6)
    with Executor(workers=2) as ex:
        forked = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, executor=ex, block_smoother=False)
    assert forked.best_sigma == serial.best_sigma
    np.testing.assert_allclose(forked.fold_mse, serial.fold_mse, rtol=0, atol=1e-12)
    assert forked.solver["solves_by_method"] == by and forked.solver["iterations"] == serial.solver["iterations"]
    assert len(forked.solver["fork_tasks"]) == 3 * 3  # three segments a fold


def test_memory_estimate_counts_the_chain_factor(monkeypatch):
    with_chain = rl.estimate_fit_memory(10**5, 64**3, 3, 1, 1, block_smoother=False)
    monkeypatch.setattr(rl, "FACTOR_CHAIN_DIMS", ())
    without = rl.estimate_fit_memory(10**5, 64**3, 3, 1, 1, block_smoother=False)
    nnz_a = 10**5 * 16.0 + 64**3 * 7.0
    assert with_chain["factor"] - without["factor"] == pytest.approx(rl._sparse_bytes(rl.FACTOR_CHAIN_FILL * nnz_a, 64**3))


def _limit_between(low: float, high: float) -> int:
    assert low < high
    return int((low + high) / 2)


def test_memory_limit_holds_the_factors_one_at_a_time_with_the_serial_result(rules_3d):
    """Under a memory limit that two factors exceed but one does not, ``--workers 2`` keeps both
    workers: every fold's factor chain runs in one task, one factor resident at a time (issue 18),
    and the CV is the serial one."""
    h, z, gam = _problem()
    side = 10  # the 10^3 grid's longest axis, as cross_validate_sigma passes it (AMG_MIN_SIDE)
    full = rl.estimate_fit_memory(h.shape[0], h.shape[1], 3, 1, 1, processes=2, block_smoother=False, grid_side=side)
    one = full["total"] - full["worker_factor"]
    limit = _limit_between(one, full["total"])
    plan = rl.plan_fit_memory(h.shape[0], h.shape[1], 3, 1, 1, max_memory=limit, processes=2, block_smoother=False,
                              grid_side=side)
    assert plan["processes"] == 2 and plan["one_factor"] and "one factor at a time" in plan["reason"]
    serial = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, block_smoother=False)
    with Executor(workers=2) as ex:
        forked = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, executor=ex, max_memory=limit, block_smoother=False)
    mp = forked.solver["memory_plan"]
    assert mp["processes"] == 2 and mp["requested"] == 2 and mp["one_factor"] and mp["reason"] == plan["reason"]
    np.testing.assert_allclose(forked.fold_mse, serial.fold_mse, rtol=0, atol=1e-12)
    assert forked.best_sigma == serial.best_sigma
    assert forked.solver["solves_by_method"] == serial.solver["solves_by_method"]
    # three segments a fold (multigrid, Jacobi-CG, the chain): the three chains are one task
    assert len(forked.solver["fork_tasks"]) == 3 * 3 - 2
    # without the limit, the plan is the request and each chain is a task of its own
    with Executor(workers=2) as ex:
        free = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, executor=ex, block_smoother=False)
    assert free.solver["memory_plan"] == {**free.solver["memory_plan"], "processes": 2, "one_factor": False, "reason": None}
    assert len(free.solver["fork_tasks"]) == 3 * 3


def test_memory_limit_below_one_factor_falls_back_to_one_process(rules_3d):
    h, z, gam = _problem()
    side = 10  # as above
    one_proc = rl.estimate_fit_memory(h.shape[0], h.shape[1], 3, 1, 1, processes=1, block_smoother=False,
                                      grid_side=side)["total"]
    full = rl.estimate_fit_memory(h.shape[0], h.shape[1], 3, 1, 1, processes=2, block_smoother=False, grid_side=side)
    limit = _limit_between(one_proc, full["total"] - full["worker_factor"])
    with Executor(workers=2) as ex:
        cv = cross_validate_sigma(h, z, gam, SIGMAS[::3], folds=2, executor=ex, max_memory=limit, block_smoother=False)
        assert ex._client is None  # nor on Dask workers: in this process
    mp = cv.solver["memory_plan"]
    assert mp["processes"] == 1 and not mp["one_factor"] and "the CV runs on 1 process" in mp["reason"]
    assert cv.solver["fork_tasks"] == []  # serial, in this process
    with pytest.raises(rl.ResourceLimit, match="over the limit"):
        cross_validate_sigma(h, z, gam, SIGMAS[::3], folds=2, max_memory=int(one_proc * 0.9), block_smoother=False)


def test_a_fallback_under_the_factor_lock_frees_its_factor(rules_3d):
    """One factor at a time: the direct solve after an unconverged CG holds the lock and does not keep
    its factor (the chain's worker may hold one meanwhile)."""
    import threading

    h, z, gam = _problem()
    hth = sparse.csr_array(h.T @ h)
    b = h.T @ z
    solver = NormalEquationSolver(hth, gam, 3, block_smoother=False)
    solver.maxiter = 1  # every CG solve stops at its cap: the fallback
    solver.factor_lock = threading.RLock()
    sigma = float(SIGMAS[-1])
    w, info = solver.solve(hth, b, sigma)
    assert info.method == "direct-fallback" and info.converged
    assert solver._m_cache is None
    assert solver.factor_lock.acquire(blocking=False)  # released
    np.testing.assert_allclose(w, rl._solve_spd((hth + sigma * gam).tocsc(), b), rtol=1e-8, atol=1e-10)
