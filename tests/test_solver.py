"""The scalable solver of the regularised least squares (issue 18): CG against the direct solve,
the automatic choice, CV with warm starts, and the memory check."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from pwas_hdl import PWASVirtualSensor
from pwas_hdl.errors import InputError, ResourceLimit
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.sparse_cholesky import cholmod_available
from pwas_hdl.fit.regularized_lsq import (
    CG_RTOL,
    DEFAULT_SIGMA_GRID,
    MAX_MEMORY_ENV,
    NormalEquationSolver,
    check_fit_memory,
    choose_method,
    cross_validate_sigma,
    estimate_fit_memory,
    gamma_min_eigenvalue,
    memory_limit,
    parse_memory,
    solve_regularized,
    tikhonov_matrix,
)


def _problem(n: int, p: int, t: int, seed: int = 0, nz: int = 1):
    rng = np.random.default_rng(seed)
    grid = Grid(np.full(n, -1.2), np.full(n, 1.2), p)
    x = rng.uniform(-1.0, 1.0, (t, n))
    z = np.column_stack([np.sin(3 * x + k).sum(axis=1) for k in range(nz)]) + 0.1 * rng.standard_normal((t, nz))
    return grid, grid.basis_matrix(x), z


CASES = [(1, 300, 2000), (2, 40, 4000), (3, 9, 3000), (4, 4, 3000)]


@pytest.mark.parametrize("order", [0, 1])
@pytest.mark.parametrize("n,p,t", CASES)
def test_cg_matches_direct_within_stated_bound(n, p, t, order):
    """||w_cg - w_direct|| <= ||r|| / (sigma lambda_min(Gamma)), the bound reported by the solve,
    over the whole default sigma range; and the residual meets CG_RTOL."""
    grid, h, z = _problem(n, p, t, seed=n)
    gam = tikhonov_matrix(grid, order)
    for sigma in (1e-7, 1e-3, 1.0, 1e3):
        wd = solve_regularized(h, z, sigma, gam, method="direct")
        wc, info = solve_regularized(h, z, sigma, gam, method="cg", return_info=True)
        assert info.method == "cg" and info.converged and info.iterations > 0
        assert info.rel_residual <= CG_RTOL * 1.0001
        diff = float(np.max(np.linalg.norm(wc - wd, axis=0)))
        assert diff <= info.weight_bound, (sigma, diff, info)
        # what the bound means in practice: the predictions on the training data agree closely
        scale = float(np.abs(h @ wd).max())
        assert float(np.abs(h @ (wc - wd)).max()) <= 1e-4 * scale, (sigma, info)


def test_gamma_min_eigenvalue_is_exact():
    grid = Grid([0.0, -1.0], [2.0, 3.0], [4, 3])
    for order in (0, 1):
        gam = tikhonov_matrix(grid, order)
        lam = np.linalg.eigvalsh(gam.toarray()).min()
        np.testing.assert_allclose(gamma_min_eigenvalue(gam), lam, rtol=1e-6)


def test_zero_order_unsupported_vertices_are_exactly_zero():
    grid = Grid([0.0, 0.0], [1.0, 1.0], 20)
    rng = np.random.default_rng(3)
    x = rng.uniform(0.0, 0.3, (500, 2))  # data in one corner only
    h = grid.basis_matrix(x)
    z = x.sum(axis=1)
    for method in ("direct", "cg"):
        w = solve_regularized(h, z, 1e-3, tikhonov_matrix(grid, 0), method=method)
        untouched = np.asarray(abs(h).sum(axis=0)).reshape(-1) == 0
        assert untouched.sum() > 300
        assert np.all(w[untouched] == 0.0)


def test_auto_rule():
    assert choose_method(1000, 2, 1) == "direct"
    # first order in 2-D at N = 10^6: CHOLMOD factorises it in ~1.5 s, SuperLU does not
    assert choose_method(10**6, 2, 1) == ("direct" if cholmod_available() else "cg")
    assert choose_method(3 * 10**6, 2, 1) == "cg"
    assert choose_method(262_144, 3, 1) == "cg"  # 3-D first order: the factor is too dense
    assert choose_method(10**6, 2, 0) == "direct"  # zero order, 2-D: the factor stays sparse
    assert choose_method(10**5, 3, 0) == "direct"
    assert choose_method(10**6, 3, 0) == "cg"
    assert choose_method(10**5, 6, 1) == "cg"
    assert choose_method(4096, 6, 0) == "cg"  # H'H nearly dense in 6-D
    assert choose_method(4096, 4, 0) == "direct"  # the Lorenz baseline of the paper
    assert choose_method(10, 2, 1, "cg") == "cg"
    assert choose_method(10**7, 2, 1, "direct") == "direct"
    with pytest.raises(InputError, match="solver method"):
        choose_method(10, 2, 1, "lu")


@pytest.mark.parametrize("order", [0, 1])
def test_cv_with_cg_matches_direct(order):
    grid, h, z = _problem(2, 30, 3000, seed=7, nz=2)
    gam = tikhonov_matrix(grid, order)
    cd = cross_validate_sigma(h, z, gam, DEFAULT_SIGMA_GRID, folds=5, method="direct")
    cc = cross_validate_sigma(h, z, gam, DEFAULT_SIGMA_GRID, folds=5, method="cg")
    assert cd.solver["method"] == "direct" and cc.solver["method"] == "cg"
    assert cc.solver["all_converged"] and cc.solver["solves"] == 5 * DEFAULT_SIGMA_GRID.size
    assert cc.best_sigma == cd.best_sigma
    # stated bound on the fold errors: |rmse_cg - rmse_direct| <= ||H_v||_2 * weight_bound / sqrt(m),
    # ||H_v||_2 <= sqrt(max column sum) as every row of H sums to 1
    labels = np.arange(h.shape[0]) * 5 // h.shape[0]
    for f in range(5):
        hv = sparse.csr_array(h[np.flatnonzero(labels == f)])
        m = hv.shape[0] * z.shape[1]
        hv_norm = np.sqrt(float(np.asarray(hv.sum(axis=0)).max()))
        limit = hv_norm * cc.solver["weight_bound"][f] * np.sqrt(z.shape[1]) / np.sqrt(m)
        gap = np.abs(np.sqrt(cc.fold_mse[f]) - np.sqrt(cd.fold_mse[f]))
        assert np.all(gap <= limit), (f, gap, limit)
    # and in practice (measured, not a guarantee) the fold errors agree to 1e-4 relative
    np.testing.assert_allclose(cc.fold_mse, cd.fold_mse, rtol=1e-4)


def test_warm_start_saves_iterations():
    """From the previous candidate's weights (sigma one grid step larger) CG needs fewer iterations."""
    grid, h, z = _problem(2, 40, 4000, seed=2)
    gam = tikhonov_matrix(grid, 0)
    ht = h.T.tocsr()
    hth, b = ht @ h, ht @ z[:, 0]
    solver = NormalEquationSolver(hth, gam, 2, "cg")
    m = solver.restrict_matrix(hth)
    w0, _ = solver.solve(m, b, 10**-2.5)
    _, i_warm = solver.solve(m, b, 1e-3, x0=w0)
    _, i_cold = solver.solve(m, b, 1e-3)
    assert i_warm.iterations < i_cold.iterations


# ------------------------------------------------------------------------------- memory
def test_memory_estimate_grows_with_size():
    small = estimate_fit_memory(10**4, 10**4, 2, 1, 1, "cg")
    big = estimate_fit_memory(10**5, 10**6, 2, 1, 1, "cg")
    assert 0 < small["total"] < big["total"]
    assert big["total"] == pytest.approx(sum(big[k] for k in ("H", "HtH", "Gamma", "factor", "vectors", "shift", "model_file")))
    # the direct factor is charged its fill (at N = 10^4 with T = 10^5 samples the grid bound of a
    # 2-D factor, ~10 MB, is below CG's charge for its operators, so the comparison is made at 10^6)
    assert estimate_fit_memory(10**5, 10**6, 2, 1, 1, "direct")["factor"] > estimate_fit_memory(10**5, 10**6, 2, 1, 1, "cg")["factor"]
    assert estimate_fit_memory(10**5, 10**4, 4, 1, 1, "direct")["factor"] > estimate_fit_memory(10**5, 10**4, 4, 1, 1, "cg")["factor"]


@pytest.mark.skipif(not cholmod_available(), reason="the grid bound is CHOLMOD's (no cvxopt here)")
@pytest.mark.parametrize("n,p,t,order", [(2, 63, 2000, 0), (2, 63, 30000, 0), (2, 127, 5000, 1), (2, 63, 30000, 1),
                                         (3, 15, 3000, 0), (3, 15, 30000, 0), (3, 15, 5000, 1), (3, 11, 30000, 1)])
def test_grid_factor_bound_holds_for_the_real_factor(n, p, t, order):
    """The bound that the memory estimate charges a direct factor (GRID_FACTOR_BOUND) is above the
    entries of CHOLMOD's factor of a CV fold's system, sparse and dense data, both orders."""
    from cvxopt import cholmod

    from pwas_hdl.fit.regularized_lsq import grid_factor_bound
    from pwas_hdl.fit.sparse_cholesky import PatternCholesky

    grid, h, _z = _problem(n, p, t)
    hf = h[np.arange(t) % 5 != 0]  # a fold's training rows
    m = (hf.T @ hf).tocsc()
    gam = tikhonov_matrix(grid, order)
    if order == 0:  # zero order is solved on the data-supported vertices (as the solver reduces it)
        keep = np.flatnonzero(np.asarray(abs(h).sum(axis=0)).ravel() > 0)
        m, gam = m[keep][:, keep], gam[keep][:, keep]
    chol = PatternCholesky(abs(m) + abs(gam))
    chol.factorize(chol.align(m + 1e-7 * gam))
    nnz_l = len(cholmod.getfactor(chol._factor).V)
    bound, nbytes = grid_factor_bound(m.shape[0], n)
    assert nnz_l <= bound
    assert nbytes >= 12 * bound
    # and the estimate charges no more than the fill rule (the bound only tightens it)
    est = estimate_fit_memory(t, grid.n_vertices, n, 1, order, "direct")
    assert est["factor"] <= 40.0 * (8 + 4) * (min(grid.n_vertices**2, t * (n + 1) ** 2) + grid.n_vertices * (
        1 if order == 0 else 2 * n + 1)) + 4 * (grid.n_vertices + 1)


def test_grid_factor_bound_is_for_the_measured_dimensions_only():
    from pwas_hdl.fit.regularized_lsq import GRID_FACTOR_BOUND, grid_factor_bound

    assert set(GRID_FACTOR_BOUND) == {2, 3}
    assert grid_factor_bound(10**4, 4) is None and grid_factor_bound(10**4, 1) is None
    nnz_2, _ = grid_factor_bound(10**6, 2)
    assert nnz_2 == pytest.approx(4.25 * 10**6 * np.log2(10**6))
    assert grid_factor_bound(3, 3)[0] <= 6  # never more than a dense triangle


def test_memory_limit_refuses_before_solving(monkeypatch):
    grid, h, z = _problem(2, 40, 4000)
    gam = tikhonov_matrix(grid, 1)
    with pytest.raises(ResourceLimit, match=r"estimated [\d.]+ MiB .* over the limit of 1 MiB \(max_memory\)"):
        solve_regularized(h, z, 1.0, gam, max_memory="1M")
    with pytest.raises(ResourceLimit, match="max_memory"):
        cross_validate_sigma(h, z, gam, [1.0, 2.0], max_memory=2**20)
    monkeypatch.setenv(MAX_MEMORY_ENV, "1M")
    assert memory_limit() == (2**20, f"${MAX_MEMORY_ENV}")
    with pytest.raises(ResourceLimit, match=MAX_MEMORY_ENV):
        check_fit_memory(4000, grid.n_vertices, 2)
    sensor = PWASVirtualSensor(my=2, partitions=40, sigma=1.0)
    y = np.random.default_rng(0).uniform(-1, 1, 3000)
    with pytest.raises(ResourceLimit, match="N = 1681 weights"):
        sensor.fit(None, y, y**2)
    assert not hasattr(sensor, "weights_")
    monkeypatch.setenv(MAX_MEMORY_ENV, "1G")
    sensor.fit(None, y, y**2)
    assert sensor.weights_.shape == (1681, 1)


def test_memory_plan_tries_all_workers_then_one_factor_then_fewer(monkeypatch):
    """plan_fit_memory (issue 18): the requested forked workers when they fit, then the factors one at
    a time, then fewer processes; a refusal only when one process does not fit."""
    from pwas_hdl.fit.regularized_lsq import plan_fit_memory

    monkeypatch.delenv(MAX_MEMORY_ENV, raising=False)
    args = (10**5, 10**6, 2, 1, 1, "auto")
    full = estimate_fit_memory(*args, processes=2, block_smoother=False)  # the rule with first-order factors
    single = estimate_fit_memory(*args, processes=1, block_smoother=False)["total"]
    one_factor = full["total"] - full["worker_factor"]
    assert single < one_factor < full["total"]
    as_asked = plan_fit_memory(*args, max_memory=int(full["total"]) + 1, processes=2, block_smoother=False)
    assert (as_asked["processes"], as_asked["one_factor"], as_asked["reason"]) == (2, False, None)
    assert as_asked["estimate"]["total"] == full["total"]
    mid = plan_fit_memory(*args, max_memory=int(one_factor) + 1, processes=2, block_smoother=False)
    assert mid["processes"] == 2 and mid["one_factor"] and mid["estimate"]["total"] == pytest.approx(one_factor)
    assert "2 processes need an estimated" in mid["reason"] and "one factor at a time" in mid["reason"]
    low = plan_fit_memory(*args, max_memory=int(single) + 1, processes=2, block_smoother=False)
    assert (low["processes"], low["one_factor"]) == (1, False) and "runs on 1 process" in low["reason"]
    with pytest.raises(ResourceLimit, match=r"over the limit of \d+ MiB \(max_memory\)"):
        plan_fit_memory(*args, max_memory=int(single) - 1, processes=2, block_smoother=False)
    serial = plan_fit_memory(*args, max_memory=int(single) + 1, processes=1, block_smoother=False)
    assert (serial["processes"], serial["reason"]) == (1, None)


def test_fit_says_when_the_memory_limit_changed_the_workers(monkeypatch, tmp_path):
    """``fit`` prints the plan's reason as a note (the CV records it in ``solver["memory_plan"]``)."""
    from helpers.cli import CliRunner

    from pwas_hdl.cli import app
    from pwas_hdl.fit import regularized_lsq as rl

    real = rl.plan_fit_memory

    def plan(*a, **k):
        out = real(*a, **k)
        return {**out, "reason": "2 processes need an estimated 9 MiB, over the limit of 8 MiB (max_memory): the CV runs on 1 process (5 MiB)"}

    monkeypatch.setattr(rl, "plan_fit_memory", plan)
    rng = np.random.default_rng(1)
    y = rng.uniform(-1, 1, 400)
    (tmp_path / "d.csv").write_text("y,z\n" + "".join(f"{float(a)!r},{float(a * a)!r}\n" for a in y))
    r = CliRunner().invoke(app, ["fit", str(tmp_path / "d.csv"), "-o", str(tmp_path / "m.json"), "-y", "y", "-z", "z",
                                 "--my", "1", "-p", "8"])
    assert r.exit_code == 0, r.output
    assert "note: 2 processes need an estimated 9 MiB" in r.output


def test_default_limit_is_a_fraction_of_available_ram(monkeypatch):
    monkeypatch.delenv(MAX_MEMORY_ENV, raising=False)
    limit, source = memory_limit()
    if limit is None:
        pytest.skip("no /proc/meminfo here")
    assert "available RAM" in source and limit > 0


@pytest.mark.parametrize("text,value", [("4G", 4 * 2**30), ("512M", 512 * 2**20), ("1e9", 10**9), (2048, 2048), ("3kb", 3072)])
def test_parse_memory(text, value):
    assert parse_memory(text) == value


@pytest.mark.parametrize("text", ["lots", "-1G", "0", "nanG"])
def test_parse_memory_rejects(text):
    with pytest.raises(InputError, match="memory limit"):
        parse_memory(text)


def test_cg_that_does_not_converge_falls_back_to_direct(monkeypatch):
    import pwas_hdl.fit.regularized_lsq as rl

    grid, h, z = _problem(2, 40, 4000, seed=5)  # 1681 unknowns
    gam = tikhonov_matrix(grid, 1)
    monkeypatch.setitem(rl._direct_limits(), (1, 2), 1000)  # auto -> cg, fallback allowed up to 4000
    ht = h.T.tocsr()
    hth, b = ht @ h, ht @ z[:, 0]
    solver = NormalEquationSolver(hth, gam, 2, "auto", maxiter=2)
    assert solver.method == "cg"
    w, info = solver.solve(solver.restrict_matrix(hth), b, 1e-5)
    assert info.method == "direct-fallback" and info.iterations == 2
    np.testing.assert_array_equal(w, solve_regularized(h, z[:, 0], 1e-5, gam, method="direct"))
    # explicit cg: no fallback, the iterate is reported as not converged
    solver = NormalEquationSolver(hth, gam, 2, "cg", maxiter=2)
    _, info = solver.solve(solver.restrict_matrix(hth), b, 1e-5)
    assert info.method == "cg" and not info.converged


# ------------------------------------------------------------------ direct backends (CHOLMOD)
needs_cholmod = pytest.mark.skipif(not cholmod_available(), reason="cvxopt (CHOLMOD) not importable")


@needs_cholmod
@pytest.mark.parametrize("order", [0, 1])
def test_cholmod_matches_superlu(order):
    """Both direct backends solve the same system: the difference is rounding, bounded by the
    condition number times machine precision; checked through the residual of each."""
    grid, h, z = _problem(2, 30, 3000, seed=11, nz=2)
    gam = tikhonov_matrix(grid, order)
    ht = h.T.tocsr()
    hth, b = (ht @ h).tocsr(), ht @ z
    for sigma in (1e-6, 1e-2, 10.0):
        out = {}
        for backend in ("cholmod", "superlu"):
            solver = NormalEquationSolver(hth, gam, 2, "direct", direct_backend=backend)
            assert solver.backend == backend
            w, info = solver.solve(solver.restrict_matrix(hth), b, sigma)
            a = (hth + sigma * gam).tocsr()
            assert np.linalg.norm(b - a @ w) <= 1e-9 * np.linalg.norm(b), (backend, sigma)
            out[backend] = w
        scale = float(np.abs(out["superlu"]).max())
        np.testing.assert_allclose(out["cholmod"], out["superlu"], atol=1e-6 * scale)


@needs_cholmod
@pytest.mark.parametrize("order", [0, 1])
def test_cholmod_analyses_each_fold_once(order):
    """The CV reuses symbolic analyses: zero order one per fold (5 analyses), first order one on
    the full-data pattern for all folds; one numeric factorisation per (fold, sigma) either way;
    and the CV agrees with the SuperLU one."""
    import pwas_hdl.fit.sparse_cholesky as sc

    grid, h, z = _problem(2, 20, 2000, seed=4)
    gam = tikhonov_matrix(grid, order)
    made = []
    orig = sc.PatternCholesky.__init__

    def counting_init(self, pattern):
        made.append(self)
        orig(self, pattern)

    sigmas = [1e-4, 1e-2, 1.0]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sc.PatternCholesky, "__init__", counting_init)
        cv = cross_validate_sigma(h, z, gam, sigmas, folds=5, method="direct")
    if order == 0:
        assert len(made) == 5 and [c.factorizations for c in made] == [3] * 5
    else:
        assert len(made) == 1 and made[0].factorizations == 15
    assert cv.solver["method"] == "direct" and cv.solver["solves"] == 15
    # against SuperLU solves of every fold's own system (441 unknowns)
    from scipy.sparse.linalg import spsolve

    labels = np.arange(h.shape[0]) * 5 // h.shape[0]
    hs = sparse.csr_array(h)
    for f in range(5):
        tr, va = labels != f, labels == f
        ht_tr = hs[np.flatnonzero(tr)].T.tocsr()
        gram, rhs = (ht_tr @ ht_tr.T).tocsc(), ht_tr @ z[tr, 0]
        hv = hs[np.flatnonzero(va)]
        for i, s in enumerate(sigmas):
            w = spsolve((gram + s * gam).tocsc(), rhs)
            assert cv.fold_mse[f, i] == pytest.approx(float(np.mean((z[va, 0] - hv @ w) ** 2)), rel=1e-8)


@needs_cholmod
def test_pattern_cholesky_refuses_entries_outside_its_pattern_and_indefinite():
    from pwas_hdl.fit.sparse_cholesky import NotPositiveDefinite, OutsidePattern, PatternCholesky

    pc = PatternCholesky(sparse.identity(4, format="csr"))
    with pytest.raises(OutsidePattern, match="outside"):
        pc.align(sparse.csr_array(np.ones((4, 4))))
    with pytest.raises(NotPositiveDefinite):
        pc.factorize(np.array([1.0, -1.0, 1.0, 1.0]))
    pc.factorize(pc.align(2.0 * sparse.identity(4, format="csr")))
    np.testing.assert_allclose(pc.solve(np.ones(4)), 0.5)


@needs_cholmod
def test_indefinite_fold_matrix_falls_back_to_superlu(monkeypatch):
    """A non-positive CHOLMOD pivot (rounding in H'H - H_v'H_v at tiny sigma) is solved by SuperLU."""
    import pwas_hdl.fit.sparse_cholesky as sc

    grid, h, z = _problem(2, 20, 2000, seed=6)
    gam = tikhonov_matrix(grid, 0)
    ht = h.T.tocsr()
    hth, b = (ht @ h).tocsr(), ht @ z[:, 0]

    def refuse(self, values):
        raise sc.NotPositiveDefinite("test")

    monkeypatch.setattr(sc.PatternCholesky, "factorize", refuse)
    solver = NormalEquationSolver(hth, gam, 2, "direct")
    w, info = solver.solve(solver.restrict_matrix(hth), b, 1e-3)
    ref = NormalEquationSolver(hth, gam, 2, "direct", direct_backend="superlu")
    np.testing.assert_array_equal(w, ref.solve(ref.restrict_matrix(hth), b, 1e-3)[0])
    assert solver.superlu_fallbacks == 1 and ref.superlu_fallbacks == 0


def test_direct_backend_is_checked():
    grid, h, _ = _problem(2, 5, 100)
    with pytest.raises(InputError, match="direct backend"):
        NormalEquationSolver(h.T @ h, tikhonov_matrix(grid, 0), 2, "direct", direct_backend="mkl")


@needs_cholmod
def test_solver_pickles_without_its_factors():
    """A solver shipped to a Dask worker (pickled) leaves its CHOLMOD factors behind (they cannot be
    pickled) and analyses again there, with the same weights."""
    import pickle

    grid, h, z = _problem(2, 10, 500, seed=8)
    gam = tikhonov_matrix(grid, 1)
    ht = h.T.tocsr()
    hth, b = (ht @ h).tocsr(), ht @ z[:, 0]
    solver = NormalEquationSolver(hth, gam, 2, "direct")
    w1, _ = solver.solve(solver.restrict_matrix(hth), b, 1e-2)
    assert solver._shared_chol is not None
    copy = pickle.loads(pickle.dumps(solver))
    assert copy._shared_chol is None and copy._m_cache is None
    w2, _ = copy.solve(copy.restrict_matrix(hth), b, 1e-2)
    np.testing.assert_allclose(w2, w1, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("n, p, side, pss_mib", [
    (4, 31, None, 2786), (5, 15, None, 3209), (6, 9, None, 4075),  # with AMG (fit_scale_pass10_big.json)
    (4, 31, 32, 1370), (5, 15, 16, 1524), (6, 9, 10, 1714),  # Jacobi alone (fit_scale_pass11_big.json)
    (4, 17, 18, 355), (5, 9, 10, 417), (6, 6, 7, 543),  # Jacobi alone, N ~ 10^5 (fit_scale_pass11_mid.json)
])
def test_memory_estimate_covers_the_measured_first_order_cg_fits(n, p, side, pss_mib):
    """The first-order CG fits at N ~ 10^6 (T = 10^5, two forked workers) measured more peak PSS
    than the estimate charged before AMG_MEMORY_FACTOR (with AMG) and SHIFT_TRANSIENT_FACTOR
    (Jacobi alone, below AMG_MIN_SIDE): the estimate the memory check refuses by must cover them."""
    est = estimate_fit_memory(10**5, (p + 1) ** n, n, 1, 1, processes=2, grid_side=side)
    assert est["method"] == 1.0 and est["total"] >= pss_mib * 2**20
