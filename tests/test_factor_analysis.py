"""The symbolic analysis of a CHOLMOD factor (column counts read from CHOLMOD's struct) and the zero-order
``auto`` rule built on it (issue 18, fourteenth pass): where the size table picks CG, a factor that the
analysis shows to be cheap is used instead, and within the memory left."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from pwas_hdl.fit import regularized_lsq as rl
from pwas_hdl.fit import sparse_cholesky as sc
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.regularized_lsq import NormalEquationSolver, cross_validate_sigma, tikhonov_matrix

pytestmark = pytest.mark.skipif(not sc.cholmod_available(), reason="needs CHOLMOD (cvxopt)")


def _spd(n: int, density: float, seed: int) -> sparse.csc_array:
    a = sparse.random(n, n, density=density, random_state=seed)
    return sparse.csc_array(a + a.T + 10.0 * sparse.identity(n))


@pytest.mark.parametrize("n, density, supernodal", [(300, 0.02, True), (300, 0.02, False), (50, 0.3, True),
                                                     (400, 0.002, False)])
def test_counts_are_those_of_the_numeric_factor(n, density, supernodal):
    """lnz is the number of non-zeros of the factor CHOLMOD then computes, flops the sum of its squared
    column counts, and the values it allocates are at least lnz."""
    from cvxopt import cholmod

    a = _spd(n, density, n)
    chol = sc.PatternCholesky(a, supernodal=supernodal)
    counts = chol.counts()
    assert counts is not None and counts.n == n
    chol.factorize(chol.align(a))
    low = cholmod.getfactor(chol._factor)  # L as a sparse matrix (supernodal padding as explicit zeros)
    values = np.array(low.V).ravel()
    assert counts.lnz == int(np.count_nonzero(values))
    cols = np.bincount(np.array(low.J).ravel()[values != 0], minlength=n)
    assert counts.flops == pytest.approx(float(np.sum(cols.astype(float) ** 2)))
    assert counts.stored >= counts.lnz and counts.bytes == 8.0 * counts.stored


def test_counts_of_a_struct_that_does_not_fit_are_none():
    a = _spd(100, 0.05, 1)
    chol = sc.PatternCholesky(a)
    assert sc.factor_counts(chol._factor, 101, chol.nnz_lower) is None  # another order
    assert sc.factor_counts(chol._factor, 100, 10**6) is None  # fewer entries than the matrix has
    assert sc.factor_counts(object(), 100, 1) is None  # not a capsule


def _zero_order(n: int, p: int, t: int, seed: int = 3):
    rng = np.random.default_rng(seed)
    grid = Grid(np.full(n, -1.2), np.full(n, 1.2), p)
    x = rng.uniform(-1.0, 1.0, (t, n))
    z = np.sin(3 * x).sum(axis=1) + 0.1 * rng.standard_normal(t)
    h = sparse.csr_array(grid.basis_matrix(x))
    return h, z, tikhonov_matrix(grid, 0)


def test_zero_order_auto_factorises_where_the_analysis_finds_it_cheap(monkeypatch):
    h, z, gam = _zero_order(2, 40, 400)
    hth = sparse.csr_array(h.T @ h)
    monkeypatch.setitem(rl.DIRECT_MAX_UNKNOWNS_CHOLMOD, (0, 2), 10)  # the size table says CG
    solver = NormalEquationSolver(hth, gam, 2)
    assert solver.method == "direct" and solver.analysis is not None
    # a dearer factor than the rule allows, or no memory left for it: CG as the table says
    monkeypatch.setattr(rl, "DIRECT_FLOPS_PER_ENTRY", 1e-3)
    assert NormalEquationSolver(hth, gam, 2).method == "cg"
    monkeypatch.undo()
    monkeypatch.setitem(rl.DIRECT_MAX_UNKNOWNS_CHOLMOD, (0, 2), 10)
    assert NormalEquationSolver(hth, gam, 2, direct_headroom=0.0).method == "cg"
    assert NormalEquationSolver(hth, gam, 2, direct_headroom=1e12).method == "direct"
    # only zero order, only auto
    assert NormalEquationSolver(hth, gam, 2, method="cg").method == "cg"
    assert NormalEquationSolver(hth, gam, 2, method="cg").analysis is None
    # the CV by the analysed choice is the direct CV
    cv = cross_validate_sigma(h, z, gam, np.logspace(-5, 1, 4), folds=3)
    cd = cross_validate_sigma(h, z, gam, np.logspace(-5, 1, 4), folds=3, method="direct")
    assert cv.solver["method"] == "direct"
    np.testing.assert_array_equal(cv.fold_mse, cd.fold_mse)
    # the memory plan it reports charges the factor the size table did not
    plan = rl.plan_fit_memory(h.shape[0], h.shape[1], 2, 1, 0)
    analysed = NormalEquationSolver(hth, gam, 2).analysis
    assert cv.solver["memory_plan"]["estimate_mib"] * 2**20 == pytest.approx(plan["estimate"]["total"] + analysed.bytes)


def test_the_memory_left_is_shared_by_the_processes_that_may_hold_a_factor():
    assert rl.factor_holders(1) == 1 and rl.factor_holders(2) == 3  # two forked workers and the parent
    assert rl.direct_headroom(None, 5.0) is None
    assert rl.direct_headroom(100.0, 40.0, 3) == 15.0
    assert rl.direct_headroom(100.0, 40.0) == 60.0
    assert rl.direct_headroom(100.0, 140.0) == 0.0


def test_first_order_4d_uses_multigrid_where_the_data_block_is_cheap(monkeypatch):
    """n = 4, first order, ``auto`` above the direct limit: CG alone by the tables; with a data block
    that the analysis finds cheap, multigrid with the data-block cycle, whose CV errors are those of
    the direct CV within the solves' tolerance; with the threshold at zero, CG alone again."""
    rng = np.random.default_rng(2)
    grid = Grid(np.full(4, -1.2), np.full(4, 1.2), 5)  # 1296 vertices
    x = rng.uniform(-1.0, 1.0, (300, 4))
    z = np.sin(3 * x).sum(axis=1) + 0.1 * rng.standard_normal(300)
    h = sparse.csr_array(grid.basis_matrix(x))
    gam = tikhonov_matrix(grid, 1)
    hth = sparse.csr_array(h.T @ h)
    monkeypatch.setattr(rl, "MG_MIN_UNKNOWNS", 100)
    monkeypatch.setitem(rl.DIRECT_MAX_UNKNOWNS_CHOLMOD, (1, 4), 100)  # the table says CG
    from pwas_hdl.fit import multigrid as mg

    monkeypatch.setattr(mg, "COARSEST_MAX", 40)
    solver = NormalEquationSolver(hth, gam, 4)
    assert solver.mg_by_analysis and solver.block_mg and solver.method == "cg" and not solver.fallback
    sig = np.logspace(-5, 1, 4)
    cv = cross_validate_sigma(h, z, gam, sig, folds=3)
    cd = cross_validate_sigma(h, z, gam, sig, folds=3, method="direct")
    assert set(cv.solver["solves_by_method"]) <= {"mg", "mg-block"} and cv.solver["all_converged"]
    # within the stated weight bound: |rmse - rmse_direct| <= ||H_v||_2 * bound / sqrt(m), ||H_v||_2 <=
    # sqrt(max column sum) as every row of H sums to 1
    labels = rl.fold_labels(h.shape[0], 3)
    for f in range(3):
        hv = h[np.flatnonzero(labels == f)]
        limit = np.sqrt(float(np.asarray(hv.sum(axis=0)).max())) * cv.solver["weight_bound"][f] / np.sqrt(hv.shape[0])
        assert np.all(np.abs(np.sqrt(cv.fold_mse[f]) - np.sqrt(cd.fold_mse[f])) <= limit)
    np.testing.assert_allclose(cv.fold_mse, cd.fold_mse, rtol=1e-5)  # and in practice
    monkeypatch.setattr(rl, "DIRECT_FLOPS_PER_ENTRY", 0.0)
    other = NormalEquationSolver(hth, gam, 4)
    assert not other.mg_by_analysis and other._mg_shape is None
    assert not NormalEquationSolver(hth, gam, 4, analyse=False).mg_by_analysis


def _numeric_forbidden(monkeypatch):
    def refuse(self, values):
        raise AssertionError("a numeric factorisation was started")

    monkeypatch.setattr(sc.PatternCholesky, "factorize", refuse)


def test_direct_factor_over_the_limit_is_refused_before_the_numeric_factorisation(monkeypatch):
    """From n = 4 the estimate has only the fill rule (no grid bound): the direct method's factor is
    counted by the symbolic analysis before any numeric work, and a fit whose analysed factor does
    not fit the limit is refused with the factor's size (measured case: n = 6, N = 10^6, zero order,
    method "direct" passed the estimate and ran out of memory in CHOLMOD)."""
    h, z, gam = _zero_order(4, 5, 3000)
    monkeypatch.setattr(rl, "DIRECT_FILL_FACTOR", 1e-3)  # a fill rule that undercounts, as at N = 10^6
    est = rl.check_fit_memory(h.shape[0], h.shape[1], 4, 1, 0, "direct")
    hth = sparse.csr_array(h.T @ h)
    solver = NormalEquationSolver(hth, gam, 4, "direct")
    counts = sc.PatternCholesky(abs(solver.restrict_matrix(hth)) + abs(solver.gamma)).counts()
    assert counts.bytes > est["factor"]  # the premise: the analysis counts more than the rule charged
    limit = est["total"] + 0.5 * (counts.bytes - est["factor"])
    _numeric_forbidden(monkeypatch)
    with pytest.raises(rl.ResourceLimit, match=r"sparse Cholesky factor needs \d+ MiB \(CHOLMOD's symbolic analysis"):
        rl.solve_regularized(h, z, 1e-3, gam, method="direct", max_memory=int(limit))
    with pytest.raises(rl.ResourceLimit, match="over the limit"):
        cross_validate_sigma(h, z, gam, sigmas=[1e-3], method="direct", max_memory=int(limit))


def test_direct_factor_within_the_limit_is_charged_as_analysed(monkeypatch):
    """Within the limit the analysed factor replaces the smaller fill-rule charge in the estimate the
    CV reports, and the solve is the factorisation's."""
    h, z, gam = _zero_order(4, 5, 3000)
    monkeypatch.setattr(rl, "DIRECT_FILL_FACTOR", 1e-3)
    hth = sparse.csr_array(h.T @ h)
    est = rl.check_fit_memory(h.shape[0], h.shape[1], 4, 1, 0, "direct")
    solver, checked = rl._analysed_solver(hth, gam, 4, h.shape[0], 1, "direct", rl.CG_RTOL, True, est, None, 1)
    assert solver.analysis is not None
    assert checked["factor"] == pytest.approx(solver.analysis.bytes)
    assert checked["total"] == pytest.approx(est["total"] - est["factor"] + solver.analysis.bytes)
    cv = cross_validate_sigma(h, z, gam, sigmas=[1e-3, 1e-1], method="direct")
    assert cv.solver["memory_plan"]["estimate_mib"] * 2**20 == pytest.approx(
        est["total"] - est["factor"] + solver.analysis.bytes, rel=1e-9)
    assert cv.solver["solves_by_method"] == {"direct": 10}


def test_grid_bounded_dimensions_are_not_analysed_again():
    """2-D and 3-D keep the measured grid bound (no extra analysis of the direct factor)."""
    rng = np.random.default_rng(0)
    grid = Grid(np.full(2, -1.2), np.full(2, 1.2), 15)
    h = sparse.csr_array(grid.basis_matrix(rng.uniform(-1, 1, (500, 2))))
    gam = tikhonov_matrix(grid, 1)
    hth = sparse.csr_array(h.T @ h)
    est = rl.check_fit_memory(500, h.shape[1], 2, 1, 1, "direct")
    solver, checked = rl._analysed_solver(hth, gam, 2, 500, 1, "direct", rl.CG_RTOL, True, est, None, 1)
    assert solver.analysis is None and checked is est


def test_cholmod_out_of_memory_is_a_resource_limit():
    """The last guard: CHOLMOD failing to allocate the numeric factor is a ResourceLimit (one `error:`
    line for fit), not a MemoryError traceback."""
    import types

    a = _spd(50, 0.1, 2)
    chol = sc.PatternCholesky(a)

    def numeric(matrix, factor):
        raise MemoryError

    chol._cholmod = types.SimpleNamespace(numeric=numeric)
    with pytest.raises(rl.ResourceLimit, match="factor of 50 unknowns did not fit in memory"):
        chol.factorize(chol.align(a))


def test_first_order_direct_factor_is_analysed_once(monkeypatch):
    """First order from n = 4 with the direct method: the memory check's analysis is the pattern the
    folds share, so the CV makes one symbolic analysis in all, not one for the check and one for the
    solves."""
    rng = np.random.default_rng(1)
    grid = Grid(np.full(4, -1.2), np.full(4, 1.2), 4)
    h = sparse.csr_array(grid.basis_matrix(rng.uniform(-1, 1, (2000, 4))))
    z = np.sin(3 * rng.uniform(-1, 1, 2000))
    analyses = []
    init = sc.PatternCholesky.__init__

    def counted(self, *args, **kwargs):
        analyses.append(1)
        init(self, *args, **kwargs)

    monkeypatch.setattr(sc.PatternCholesky, "__init__", counted)
    cv = cross_validate_sigma(h, z, tikhonov_matrix(grid, 1), sigmas=[1e-3, 1e-1], method="direct")
    assert cv.solver["solves_by_method"] == {"direct": 10}
    assert len(analyses) == 1
