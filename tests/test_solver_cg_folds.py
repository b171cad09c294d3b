"""The CV by CG alone (issue 18, ninth pass; ``auto`` from n = 4 up): the AMG preconditioner of a
sigma depends on that sigma alone, so the folds run on forked workers with the serial result; each
fold's sweep is cut into CG_SEGMENTS chains so that two workers share five folds evenly."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import sparse

from pwas_hdl.fit import fork_map as fm
from pwas_hdl.fit import regularized_lsq as rl
from pwas_hdl.fit.regularized_lsq import NormalEquationSolver, cross_validate_sigma
from pwas_hdl.flow.executor import Executor

from helpers.factor_sweep import random_problem

SIGMAS = np.asarray(rl.DEFAULT_SIGMA_GRID, dtype=float)


def _problem(t=900, seed=3):
    return random_problem(4, 4, t, seed)  # 625 vertices, first order


def _amg_sigmas(solver) -> list[float]:
    return [float(s) for s in SIGMAS if solver._pre.use_amg(float(s))]


@pytest.fixture(autouse=True)
def _amg_on_small_grids(monkeypatch):
    """The AMG tests below run on a 5^4 grid, far below AMG_MIN_SIDE: AMG is allowed here."""
    monkeypatch.setattr(rl, "AMG_MIN_SIDE", 2)


def test_amg_only_on_a_grid_with_a_long_axis(monkeypatch):
    """Below AMG_MIN_SIDE vertices on the longest axis the first-order CG is Jacobi at every sigma
    (measured cheaper than AMG there), from it AMG takes the penalty-dominated sigmas; the memory
    estimate charges the AMG hierarchy only where it may be built."""
    monkeypatch.undo()
    assert rl.AMG_MIN_SIDE == 128
    assert rl.amg_allowed(None) and rl.amg_allowed(128) and not rl.amg_allowed(127)
    h, z, gam = random_problem(4, 4, 900, 3)  # 5^4 vertices
    solver = NormalEquationSolver(sparse.csr_array(h.T @ h), gam, 4, method="cg")
    assert not solver._pre.amg and _amg_sigmas(solver) == []
    w, info = solver.solve(solver.restrict_matrix(sparse.csr_array(h.T @ h)), h.T @ z, float(SIGMAS[-1]))
    assert info.method == "cg" and info.converged and solver._pre.builds == 0
    h2, z2, gam2 = random_problem(2, 127, 3000, 4)  # 128 x 128 vertices
    solver2 = NormalEquationSolver(sparse.csr_array(h2.T @ h2), gam2, 2, method="cg")
    assert solver2._pre.amg and _amg_sigmas(solver2)
    on = rl.estimate_fit_memory(10**5, 32**4, 4, 1, 1, grid_side=None)
    off = rl.estimate_fit_memory(10**5, 32**4, 4, 1, 1, grid_side=32)
    assert off["factor"] == 8.0 * 32**4 and on["factor"] > 10 * off["factor"]
    assert on["total"] - off["total"] == on["factor"] - off["factor"]
    assert rl.estimate_fit_memory(10**5, 32**4, 4, 1, 1, grid_side=128)["factor"] == on["factor"]


def test_amg_hierarchy_of_a_sigma_is_that_of_its_band_whatever_was_solved_before():
    h, z, gam = _problem()
    hth = sparse.csr_array(h.T @ h)
    a_solver = NormalEquationSolver(hth, gam, 4, method="cg")
    amg = _amg_sigmas(a_solver)
    assert len(amg) >= 4  # several bands on the default grid
    ratio = rl.AMG_REUSE_RATIO
    for s in amg:  # the band's middle is within sqrt(ratio) of every sigma of the band
        s0 = a_solver._pre.anchor(s)
        assert 1 / math.sqrt(ratio) - 1e-12 <= s0 / s <= math.sqrt(ratio) + 1e-12
        assert a_solver._pre.use_amg(s0 / math.sqrt(ratio) * (1 + 1e-9))  # the band starts at an AMG sigma
    bands = {a_solver._pre.anchor(s) for s in amg}
    assert 2 <= len(bands) < len(amg)  # bands are shared by neighbouring sigmas
    # the preconditioner of the smallest AMG sigma after the whole sweep above it, and fresh
    v = np.random.default_rng(0).standard_normal(hth.shape[0])
    for s in sorted(amg, reverse=True):
        a = (hth + s * gam).tocsr()
        pre_after = a_solver._pre.get(a, s)
    assert a_solver._pre.builds == len(bands)  # one build per band, largest down
    fresh = NormalEquationSolver(hth, gam, 4, method="cg")
    np.random.seed(11)
    state = np.random.get_state()
    pre_fresh = fresh._pre.get(a, amg[0])
    after = np.random.get_state()
    assert after[0] == state[0] and np.array_equal(after[1], state[1]) and after[2:] == state[2:]  # restored
    assert fresh._pre.builds == 1
    np.testing.assert_array_equal(pre_after.matvec(v), pre_fresh.matvec(v))
    # a sigma of another band rebuilds; back in the first band, the first band's hierarchy again
    y0 = pre_fresh.matvec(v)
    top = (hth + amg[-1] * gam).tocsr()
    assert fresh._pre.anchor(amg[-1]) != fresh._pre.anchor(amg[0])
    fresh._pre.get(top, amg[-1])
    np.testing.assert_array_equal(fresh._pre.get(a, amg[0]).matvec(v), y0)
    assert fresh._pre.builds == 3


def test_cg_sweep_is_cut_into_consecutive_chains_costed_by_rho():
    h, z, gam = _problem()
    hth = sparse.csr_array(h.T @ h)
    solver = NormalEquationSolver(hth, gam, 4, method="cg")
    segs = solver.sweep_segments(hth, SIGMAS)
    assert len(segs) == rl.CG_SEGMENTS
    assert [i for s in segs for i in s] == solver.sweep_order(hth, SIGMAS)  # every sigma once, largest down
    assert max(map(len, segs)) - min(map(len, segs)) <= 1
    cost = [solver.segment_cost(hth, float(s)) for s in SIGMAS]
    assert all(0 < c <= 1 for c in cost) and cost == sorted(cost, reverse=True)  # smaller sigma, dearer
    assert cost[0] == 1.0  # the floor: at sigma = 1e-7 rho is below CG_COST_RHO_FLOOR here
    seg_cost = [sum(cost[i] for i in s) for s in segs]
    assert seg_cost == sorted(seg_cost)  # the chain of the smallest sigmas is handed out first
    assert NormalEquationSolver(hth, gam, 4, method="cg").sweep_segments(hth, SIGMAS[:2]) == [[1], [0]]


@pytest.mark.skipif(not fm.fork_available(), reason="needs fork")
@pytest.mark.parametrize("order", [0, 1])
def test_forked_cg_folds_give_the_serial_result(monkeypatch, order):
    from pwas_hdl.fit.geometry import Grid

    monkeypatch.setattr(rl, "FORK_MIN_UNKNOWNS", 100)
    h, z, gam = _problem()
    if order == 0:
        gam = rl.tikhonov_matrix(Grid(np.full(4, -1.2), np.full(4, 1.2), 4), 0)
    serial = cross_validate_sigma(h, z, gam, folds=5, method="cg", final_solve=True)
    with Executor(workers=2) as ex:
        forked = cross_validate_sigma(h, z, gam, folds=5, method="cg", final_solve=True, executor=ex)
        assert ex._client is None  # forked, not on a Dask cluster
    tasks = forked.solver["fork_tasks"]
    assert len(tasks) == 5 * rl.CG_SEGMENTS and len({t["pid"] for t in tasks}) <= 2
    assert serial.solver["fork_tasks"] == []
    np.testing.assert_array_equal(forked.fold_mse, serial.fold_mse)
    assert forked.best_sigma == serial.best_sigma
    assert forked.solver["iterations"] == serial.solver["iterations"]
    np.testing.assert_array_equal(forked.final_weights, serial.final_weights)
    if order == 1:  # the problem has AMG sigmas: the workers built their bands' hierarchies themselves
        assert _amg_sigmas(NormalEquationSolver(sparse.csr_array(h.T @ h), gam, 4, method="cg"))
