"""The data-block multigrid cycle of the first-order CV (issue 18, eighth pass): the fine level
smoothed by Gauss-Seidel and the exact solve with ``M_TT + sigma diag(Gamma)_TT``, so that the
data-dominated sigmas converge in a few iterations without a factorisation of Gamma's grid edges;
the CV by it equals the direct CV, serially and on forked workers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from pwas_hdl.errors import InternalError
from pwas_hdl.fit import multigrid as mg
from pwas_hdl.fit import regularized_lsq as rl
from pwas_hdl.fit import sparse_cholesky as sc
from pwas_hdl.fit.regularized_lsq import NormalEquationSolver, cross_validate_sigma
from pwas_hdl.fit.sparse_cholesky import NotPositiveDefinite
from pwas_hdl.flow.executor import Executor

from helpers.factor_sweep import large_problem_rules, random_problem

SIGMAS = np.logspace(-7, 2, 10)


@pytest.fixture()
def large_rules(monkeypatch):
    """The size rules of a large problem (multigrid, forked workers) on a tiny one."""
    large_problem_rules(monkeypatch)


def _fold_matrix(h, z, folds=3, f=0):
    """Fold ``f``'s training normal matrix and right-hand side, as cross_validate_sigma forms them."""
    labels = rl.fold_labels(h.shape[0], folds)
    hth = sparse.csr_array(h.T @ h)
    hv = h[np.flatnonzero(labels == f)]
    m = (hth - sparse.csr_array(hv.T @ hv)).tocsr()
    return hth, m, h.T @ z - hv.T @ z[labels == f]


@pytest.mark.parametrize("cholmod", [True, False])
def test_data_block_solve_inverts_the_block_and_the_diagonal_elsewhere(monkeypatch, cholmod):
    if cholmod and not sc.cholmod_available():
        pytest.skip("needs CHOLMOD (cvxopt)")
    if not cholmod:
        monkeypatch.setattr(sc, "cholmod_available", lambda: False)
    h, z, gam = random_problem(2, 30, 200, 2)  # 961 vertices, most untouched
    _, m, _ = _fold_matrix(h, z)
    gd = gam.diagonal()
    blk = mg.DataBlockSmoother(m, gd)
    assert 0 < blk.touched.size < m.shape[0]
    assert np.all(m.diagonal()[np.setdiff1d(np.arange(m.shape[0]), blk.touched)] <= 0)
    sigma = 1e-4
    blk.factorize(sigma)
    t = blk.touched
    p = sparse.lil_matrix(sparse.diags(sigma * gd))
    p[np.ix_(t, t)] = (m[t][:, t] + sparse.diags(sigma * gd[t])).toarray()
    r = np.random.default_rng(0).standard_normal(m.shape[0])
    np.testing.assert_allclose(p.tocsr() @ blk.solve(r), r, rtol=1e-9, atol=1e-9)
    with pytest.raises(InternalError, match="positive diagonal"):  # our own Gamma: a bug, not bad input
        mg.DataBlockSmoother(m, np.zeros_like(gd))


def test_block_cycle_is_a_symmetric_positive_preconditioner():
    h, z, gam = random_problem(2, 30, 400, 3)
    _, m, _ = _fold_matrix(h, z)
    fold = mg.GridHierarchy((31, 31), gam, coarsest_max=40).for_matrix(m)
    fold.set_sigma(1e-5)
    fold.set_block(1e-5)
    rng = np.random.default_rng(1)
    x, y = rng.standard_normal((2, m.shape[0]))
    bx, by = fold.vcycle_block(x), fold.vcycle_block(y)
    # symmetric up to the single-precision coarse levels
    assert abs(y @ bx - x @ by) <= 1e-5 * np.sqrt((x @ bx) * (y @ by))
    assert x @ bx > 0 and y @ by > 0


@pytest.mark.parametrize("n, p, t", [(2, 30, 600), (3, 9, 800)])
def test_block_cycle_converges_where_gauss_seidel_alone_does_not(n, p, t):
    """At a data-dominated sigma the Gauss-Seidel V-cycle needs many times the data-block cycle's
    iterations; the data-block solve is within the stated weight bound of the direct solve."""
    h, z, gam = random_problem(n, p, t, 4)
    _, m, b = _fold_matrix(h, z)
    fold = mg.GridHierarchy((p + 1,) * n, gam, coarsest_max=40).for_matrix(m)
    a = (m + 1e-6 * gam).tocsc()
    wd = rl._solve_spd(a, b)
    lam = rl.gamma_min_eigenvalue(gam)
    wb, ib = fold.solve(b, 1e-6, rtol=rl.CG_RTOL, maxiter=500, block=True)
    _, ig = fold.solve(b, 1e-6, rtol=rl.CG_RTOL, maxiter=500, block=False)
    assert ib.converged and ib.iterations <= 30, ib
    assert ig.iterations >= 3 * ib.iterations, (ig, ib)
    assert float(np.linalg.norm(wb - wd)) <= ib.abs_residual / (1e-6 * lam)


@pytest.mark.parametrize("n, p, t", [(2, 30, 600), (3, 9, 800)])
def test_cv_by_the_block_cycle_matches_the_direct_cv(large_rules, n, p, t):
    h, z, gam = random_problem(n, p, t, 5)
    ca = cross_validate_sigma(h, z, gam, SIGMAS, folds=3)
    cd = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, method="direct")
    by = ca.solver["solves_by_method"]
    # no factorisation: the penalty-dominated sigmas by the Gauss-Seidel cycle, the others by the block cycle
    assert set(by) == {"mg", "mg-block"} and sum(by.values()) == 3 * SIGMAS.size, by
    assert ca.solver["all_converged"] and ca.solver["block_failures"] == 0
    assert ca.best_sigma == cd.best_sigma
    # each fold error within what the solve's stated weight bound ||w - w_direct|| <= B allows:
    # |mse - mse_direct| <= (2 ||e_direct|| ||H_v||_F B + (||H_v||_F B)^2) / n_v
    labels = rl.fold_labels(h.shape[0], 3)
    bound = ca.solver["weight_bound"]
    for f in range(3):
        hv = h[np.flatnonzero(labels == f)]
        nv, hf = hv.shape[0], float(sparse.linalg.norm(hv))
        e = np.sqrt(cd.fold_mse[f] * nv)
        allowed = (2 * e * hf * bound[f] + (hf * bound[f]) ** 2) / nv
        assert np.all(np.abs(ca.fold_mse[f] - cd.fold_mse[f]) <= allowed), (f, ca.fold_mse[f] - cd.fold_mse[f], allowed)
    # where the bound is tight (the penalty-dominated half of the grid) the errors agree closely;
    # at the smallest sigmas the bound is loose (A's condition ~ 1 / sigma) and the errors agree
    # to what rtol allows there, so a tighter rtol must bring them to the direct CV's
    np.testing.assert_allclose(ca.fold_mse[:, 5:], cd.fold_mse[:, 5:], rtol=1e-8)
    tight = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, rtol=1e-13)
    # (a Gauss-Seidel-cycle solve may fall back to the factorisation there: its cycle is single precision)
    assert tight.solver["solves_by_method"]["mg-block"] == by["mg-block"]
    np.testing.assert_allclose(tight.fold_mse, cd.fold_mse, rtol=1e-8)
    # the rule: rho = sigma mean(diag Gamma) / mean(rowsum M_k) against MG_BLOCK_DOMINANCE of the dimension
    hth, m, _ = _fold_matrix(h, z)
    solver = NormalEquationSolver(hth, gam, n)
    rho = SIGMAS * gam.diagonal().mean() / (m.sum() / m.shape[0])
    assert solver.block_dominance == rl.MG_BLOCK_DOMINANCE[n]
    assert [solver.uses_block(m, float(s)) for s in SIGMAS] == list(rho < rl.MG_BLOCK_DOMINANCE[n])
    assert all(solver.uses_mg(m, float(s)) for s in SIGMAS) and not solver.factorises(m, 1e-7)


def test_block_segments_and_forked_workers_give_the_serial_result(large_rules):
    h, z, gam = random_problem(2, 30, 600, 6)
    hth, m, _ = _fold_matrix(h, z)
    solver = NormalEquationSolver(hth, gam, 2)
    segs = solver.sweep_segments(m, SIGMAS)
    block = [i for i in range(SIGMAS.size) if solver.uses_block(m, float(SIGMAS[i]))]
    assert 0 < len(block) < SIGMAS.size
    assert segs == [sorted(set(range(SIGMAS.size)) - set(block), key=lambda i: -SIGMAS[i]),
                    sorted(block, key=lambda i: -SIGMAS[i])]
    serial = cross_validate_sigma(h, z, gam, SIGMAS, folds=3)
    with Executor(workers=2) as ex:
        forked = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, executor=ex)
    assert forked.solver["fork_tasks"] and len(forked.solver["fork_tasks"]) == 6  # two segments a fold
    assert forked.best_sigma == serial.best_sigma
    np.testing.assert_allclose(forked.fold_mse, serial.fold_mse, rtol=0, atol=1e-12)
    assert forked.solver["solves_by_method"] == serial.solver["solves_by_method"]
    assert forked.solver["iterations"] == serial.solver["iterations"]


def test_a_block_not_positive_definite_is_solved_by_gauss_seidel(large_rules, monkeypatch):
    h, z, gam = random_problem(2, 30, 600, 7)
    hth, m, b = _fold_matrix(h, z)

    def indefinite(self, sigma):
        raise NotPositiveDefinite("test")

    monkeypatch.setattr(mg.DataBlockSmoother, "factorize", indefinite)
    solver = NormalEquationSolver(hth, gam, 2)
    sigma = float(SIGMAS[0])
    assert solver.uses_block(m, sigma)
    w, info = solver.solve(m, b, sigma)
    assert solver.block_failures == 1 and info.method == "mg" and info.converged
    assert float(np.linalg.norm(w - rl._solve_spd((m + sigma * gam).tocsc(), b))) <= info.weight_bound


def test_an_unconverged_block_solve_is_redone_by_the_factorisation(large_rules, monkeypatch):
    if not sc.cholmod_available():
        pytest.skip("the fallback needs CHOLMOD here")
    monkeypatch.setattr(rl, "MG_BLOCK_MAXITER", 1)
    h, z, gam = random_problem(2, 30, 600, 8)
    hth, m, b = _fold_matrix(h, z)
    solver = NormalEquationSolver(hth, gam, 2)
    assert solver.fallback
    w, info = solver.solve(m, b, 1e-7)
    assert info.method == "direct-fallback"
    np.testing.assert_allclose(w, rl._solve_spd((m + 1e-7 * gam).tocsc(), b), rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("n, nv", [(2, 10**6), (3, 64**3)])
def test_memory_estimate_charges_the_block_not_a_first_order_factor(n, nv):
    if not sc.cholmod_available():
        pytest.skip("the first-order factors are charged with CHOLMOD")
    new = rl.estimate_fit_memory(10**5, nv, n, 1, 1, processes=2)
    old = rl.estimate_fit_memory(10**5, nv, n, 1, 1, processes=2, block_smoother=False)
    assert new["worker_factor"] == 0.0 and old["worker_factor"] > 0  # nothing to hold one at a time
    assert new["factor"] < old["factor"] and new["total"] < old["total"]
    # the block's factor is charged as the zero-order fit's (H'H on at most T (n + 1) vertices)
    zero = rl.estimate_fit_memory(10**5, nv, n, 1, 0, "direct")
    assert new["factor"] == pytest.approx(zero["factor"], rel=0.05)


def test_block_cycle_only_from_its_size_on_a_direct_base(monkeypatch):
    """``auto`` on a direct base method (2-D with CHOLMOD) factorises the data-dominated sigmas below
    MG_BLOCK_MIN_DIRECT unknowns (with factor-PCG from FACTOR_PCG_MIN_UNKNOWNS) and uses the
    data-block cycle from it; ``mg`` and a Jacobi-CG base (3-D) use the cycle at any size; the
    memory estimate follows the same rule."""
    if not sc.cholmod_available():
        pytest.skip("the direct base method of 2-D multigrid is CHOLMOD's")
    monkeypatch.setattr(rl, "MG_MIN_UNKNOWNS", 100)
    h, z, gam = random_problem(2, 30, 600, 5)  # 961 unknowns
    hth = sparse.csr_array(h.T @ h)
    h3, _, gam3 = random_problem(3, 9, 600, 5)  # 1000 unknowns, Jacobi-CG base
    hth3 = sparse.csr_array(h3.T @ h3)
    for limit, block in [(962, False), (961, True)]:
        monkeypatch.setattr(rl, "MG_BLOCK_MIN_DIRECT", limit)
        solver = NormalEquationSolver(hth, gam, 2)
        assert solver.method == "direct" and solver.block_mg is block
        assert not solver.factor_pcg  # 961 < FACTOR_PCG_MIN_UNKNOWNS: the sigmas factorised
        monkeypatch.setattr(rl, "FACTOR_PCG_MIN_UNKNOWNS", 961)  # the earlier rule's factor-PCG below
        assert NormalEquationSolver(hth, gam, 2).factor_pcg is not block
        monkeypatch.setattr(rl, "FACTOR_PCG_MIN_UNKNOWNS", 962)
        assert NormalEquationSolver(hth, gam, 2, method="mg").block_mg
        assert NormalEquationSolver(hth3, gam3, 3).block_mg
        est = rl.estimate_fit_memory(600, 961, 2, 1, 1, processes=2)
        old = rl.estimate_fit_memory(600, 961, 2, 1, 1, processes=2, block_smoother=False)
        assert (est == old) is not block
    monkeypatch.setattr(rl, "MG_BLOCK_MIN_DIRECT", 962)
    cv = cross_validate_sigma(h, z, gam, np.logspace(-6, 2, 5), folds=3)
    by = cv.solver["solves_by_method"]
    assert "mg-block" not in by and by.get("direct", 0) > 0 and by.get("mg", 0) > 0
