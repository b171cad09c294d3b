"""Geometric multigrid for the first-order CV (issue 18): the prolongation, the sigma-linear
Galerkin levels, the V-cycle's contraction, and the weights within the stated bound of the direct
solve when ``auto`` mixes multigrid and the factorisation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from pwas_hdl.errors import InputError
from pwas_hdl.fit import multigrid as mg
from pwas_hdl.fit import regularized_lsq as rl
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.regularized_lsq import (
    NormalEquationSolver,
    cross_validate_sigma,
    estimate_fit_memory,
    solve_regularized,
    tikhonov_matrix,
)


def _fold(shape=(23, 30), t=300, seed=0):
    """A first-order problem on a non-square grid (a swapped Kronecker order would show)."""
    rng = np.random.default_rng(seed)
    grid = Grid(np.full(len(shape), -1.2), np.full(len(shape), 1.2), [s - 1 for s in shape])
    x = rng.uniform(-1.0, 1.0, (t, len(shape)))
    z = np.sin(3 * x).sum(axis=1) + 0.1 * rng.standard_normal(t)
    h = grid.basis_matrix(x)
    return grid, h, z, tikhonov_matrix(grid, 1)


@pytest.mark.parametrize("m", [3, 4, 9, 10])
def test_interpolation_1d_is_exact_on_linear_functions(m):
    p = mg.interpolation_1d(m)
    assert p.shape == (m, m // 2 + 1)
    np.testing.assert_allclose(p.sum(axis=1), 1.0)
    coarse_pos = np.r_[np.arange(0, m, 2), [m - 1] if m % 2 == 0 else []]
    np.testing.assert_allclose(p @ (2.0 * coarse_pos + 1.0), 2.0 * np.arange(m) + 1.0)


def test_prolongation_reproduces_multilinear_functions_in_c_order():
    shape = (5, 8, 3)
    p, cshape = mg.prolongation(shape)
    assert cshape == (3, 5, 2)
    fine = np.stack(np.unravel_index(np.arange(int(np.prod(shape))), shape), axis=1).astype(float)
    coarse = np.stack(np.unravel_index(np.arange(int(np.prod(cshape))), cshape), axis=1).astype(float)
    # coarse coordinates in fine units: even indices, the last one kept for an even count
    for j, m in enumerate(shape):
        pos = np.r_[np.arange(0, m, 2), [m - 1] if m % 2 == 0 else []]
        coarse[:, j] = pos[coarse[:, j].astype(int)]

    def f(c):
        return 1.0 + 2.0 * c[:, 0] - c[:, 1] + 0.5 * c[:, 2] + 0.25 * c[:, 0] * c[:, 1]

    np.testing.assert_allclose(p @ f(coarse), f(fine), atol=1e-12)


def test_grid_shape_from_gamma():
    for shape in [(23, 30), (4, 5, 6), (2, 7)]:
        grid = Grid(np.zeros(len(shape)), np.ones(len(shape)), [s - 1 for s in shape])
        assert mg.grid_shape_of(tikhonov_matrix(grid, 1), len(shape)) == shape
        assert mg.grid_shape_of(tikhonov_matrix(grid, 0), len(shape)) is None
    # a Laplacian with an edge removed is not a full grid's
    g = sparse.lil_array(tikhonov_matrix(Grid([0, 0], [1, 1], [4, 4]), 1))
    g[3, 4] = g[4, 3] = 0.0
    assert mg.grid_shape_of(sparse.csr_array(g.tocsr()), 2) is None


@pytest.mark.parametrize("shared", [None, "fold", "reference"])
def test_levels_are_the_galerkin_operators_of_every_sigma(shared):
    """Each level's m_l + sigma Gamma_l (kept on the union pattern) equals Q_l' (M + sigma Gamma) Q_l:
    in double precision on the fine level and the coarsest (CG's products, the factor), in single
    between (only smoothed: formed in single from Gamma's and m's single values, so within a few
    roundings), and the fine level's single copy to one rounding. ``shared``: on the level
    patterns of the full data's matrix, for a fold's matrix (part of the data) or for that
    reference matrix itself (not coarsened again)."""
    grid, h, z, gam = _fold()
    m = sparse.csr_array(h.T @ h)
    hier = mg.GridHierarchy(grid.shape, gam, coarsest_max=30)
    assert hier.levels >= 3
    if shared:
        hier.share(m)
        if shared == "fold":
            m = sparse.csr_array(h[: h.shape[0] // 2].T @ h[: h.shape[0] // 2])
    fold = hier.for_matrix(m)
    assert (fold.shared is hier.shared) == bool(shared)
    assert hier.shared is None or hier.shared.is_reference(m) == (shared == "reference")
    eps32 = float(np.finfo(np.float32).eps)
    for sigma in (1e-4, 3.0):
        fold.set_sigma(sigma)
        a = sparse.csr_array(hier.internal(m + sigma * gam))  # the levels' vertex orders
        for level, op in enumerate(fold.ops):
            double = level in (0, hier.levels - 1)
            assert op.dtype == (np.float64 if double else np.float32)
            assert abs(sparse.csr_array(op) - a).max() <= (1e-12 if double else 4 * eps32) * abs(a).max()
            if level == 0:
                assert abs(sparse.csr_array(fold._ops32[0]) - a).max() <= eps32 * abs(a).max()
            if level < len(hier.p):
                a = sparse.csr_array(hier.p[level].T @ a @ hier.p[level])


def test_a_matrix_outside_the_shared_patterns_gets_its_own():
    """A matrix with an entry where the shared reference has none is not placed on its patterns."""
    grid, h, z, gam = _fold()
    hier = mg.GridHierarchy(grid.shape, gam, coarsest_max=30)
    half = h[: h.shape[0] // 2]
    hier.share(sparse.csr_array(half.T @ half))
    m = sparse.csr_array(h.T @ h)  # the other half's samples touch simplices the first half's do not
    fold = hier.for_matrix(m)
    assert fold.shared is not hier.shared
    fold.set_sigma(0.5)
    assert abs(sparse.csr_array(fold.ops[0]) - sparse.csr_array(hier.internal(m + 0.5 * gam))).max() <= 1e-12


def test_only_outside_pattern_falls_back_to_own_patterns(monkeypatch):
    """The fallback to a matrix's own patterns catches OutsidePattern and nothing else: another
    ValueError (a bug) propagates instead of silently taking the slower path."""
    grid, h, z, gam = _fold()
    hier = mg.GridHierarchy(grid.shape, gam, coarsest_max=30)
    hier.share(sparse.csr_array(h.T @ h))
    half = h[: h.shape[0] // 2]
    fold = sparse.csr_array(half.T @ half)  # within the full data's patterns
    assert hier.for_matrix(fold).shared is hier.shared

    def broken(self, ms):
        raise ValueError("a bug")

    monkeypatch.setattr(mg.LevelPatterns, "values_of", broken)
    with pytest.raises(ValueError, match="a bug"):
        hier.for_matrix(fold)


def test_vcycle_contracts_and_a_wrong_prolongation_does_not():
    """As a stationary iteration, x <- x + V(b - A x) reduces the error about 5x a cycle (at least 3x) at a
    penalty-dominated sigma; with the coarse columns of P shuffled, the coarse correction is useless
    and the rate is near the smoother's alone (1 - O(h^2))."""
    grid, h, z, gam = _fold(shape=(47, 62), t=800)
    m = sparse.csr_array(h.T @ h)
    sigma = 10.0
    a = sparse.csr_array(m + sigma * gam)
    rng = np.random.default_rng(1)
    x_true = rng.standard_normal(a.shape[0])
    b = a @ x_true

    def rate(fold):
        fold.set_sigma(sigma)
        x = np.zeros_like(b)
        errs = []
        for _ in range(6):
            x = x + fold.vcycle(b - a @ x)
            errs.append(np.linalg.norm(x - x_true))
        return (errs[-1] / errs[1]) ** (1 / 4)

    hier = mg.GridHierarchy(grid.shape, gam, coarsest_max=30)
    good = rate(hier.for_matrix(m))
    assert good < 0.35, good
    bad = mg.GridHierarchy(grid.shape, gam, coarsest_max=30)
    perm = rng.permutation(bad.p[0].shape[1])
    bad.p[0] = mg._csr(bad.p[0][:, perm])
    bad.r[0] = mg._csr(bad.p[0].T)
    bad.gammas = [bad.gammas[0]]
    for p, r in zip(bad.p, bad.r):
        bad.gammas.append(mg._csr(r @ bad.gammas[-1] @ p))
    worse = rate(bad.for_matrix(m))
    assert worse > 3 * good, (good, worse)


def test_mg_solve_within_the_stated_bound_of_the_direct_solve():
    grid, h, z, gam = _fold(shape=(31, 31), t=400, seed=3)
    for sigma in (1e-3, 1.0, 1e3):
        wd = solve_regularized(h, z, sigma, gam, method="direct")
        wm, info = solve_regularized(h, z, sigma, gam, method="mg", return_info=True)
        # the data-dominated sigma by the data-block cycle (MG_BLOCK_DOMINANCE), the others by Gauss-Seidel's
        assert info.method in ("mg", "mg-block") and info.converged and info.rel_residual <= rl.CG_RTOL
        assert float(np.linalg.norm(wm - wd)) <= info.weight_bound


def test_auto_mixes_multigrid_and_direct_by_dominance(monkeypatch):
    """Above MG_MIN_UNKNOWNS, first order, the earlier rule (no data-block smoother): the
    penalty-dominated sigmas by multigrid, the others by the factorisation; the fold errors those
    of the direct CV to the bound's precision."""
    monkeypatch.setattr(rl, "MG_MIN_UNKNOWNS", 100)
    monkeypatch.setattr(mg, "COARSEST_MAX", 40)
    grid, h, z, gam = _fold(shape=(31, 31), t=600, seed=4)
    sig = np.logspace(-4, 2, 5)
    ca = cross_validate_sigma(h, z, gam, sig, folds=3, block_smoother=False)
    cd = cross_validate_sigma(h, z, gam, sig, folds=3, method="direct")
    by = ca.solver["solves_by_method"]
    assert by.get("mg", 0) > 0 and by.get("direct", 0) > 0 and sum(by.values()) == 15
    assert ca.solver["all_converged"] and ca.solver["iterations"] > 0
    assert ca.best_sigma == cd.best_sigma
    np.testing.assert_allclose(ca.fold_mse, cd.fold_mse, rtol=1e-6)
    # the rule: rho = sigma mean(diag Gamma) / mean(rowsum M) against MG_DOMINANCE
    hth = sparse.csr_array(h.T @ h)
    solver = NormalEquationSolver(hth, gam, 2, block_smoother=False)
    rho = sig * gam.diagonal().mean() / (hth.sum() / hth.shape[0])
    assert [solver.uses_mg(hth, s) for s in sig] == list(rho >= rl.MG_DOMINANCE)


def test_mg_needs_a_first_order_grid_gamma():
    grid, h, z, gam = _fold()
    with pytest.raises(InputError, match="'mg'"):
        solve_regularized(h, z, 1.0, tikhonov_matrix(grid, 0), method="mg")
    with pytest.raises(InputError, match="'mg'"):
        solve_regularized(h, z, 1.0, sparse.identity(gam.shape[0], format="csr") * 2.0, method="mg")


def test_memory_estimate_counts_the_levels():
    est = estimate_fit_memory(10**5, 10**6, 2, 1, 1)
    assert est["multigrid"] > 0
    assert estimate_fit_memory(10**5, 10**6, 2, 1, 0)["multigrid"] == 0
    assert estimate_fit_memory(10**3, 10**3, 2, 1, 1)["multigrid"] == 0


def test_auto_uses_multigrid_only_in_the_measured_dimensions(monkeypatch):
    monkeypatch.setattr(rl, "MG_MIN_UNKNOWNS", 100)
    for shape, expect in [((400,), False), ((20, 20), True), ((8, 8, 8), True), ((5, 5, 5, 5), False)]:
        grid = Grid(np.zeros(len(shape)), np.ones(len(shape)), [s - 1 for s in shape])
        gam = tikhonov_matrix(grid, 1)
        hth = sparse.identity(gam.shape[0], format="csr") * 0.1
        assert NormalEquationSolver(hth, gam, len(shape)).uses_mg(hth, 1e3) is expect, shape


def test_explicit_zeros_of_the_fold_matrix_are_not_outside_the_pattern():
    grid, h, z, gam = _fold()
    m = sparse.csr_matrix(h.T @ h)
    m.data[: 7] = 0.0  # entries that cancelled exactly, kept as explicit zeros
    hier = mg.GridHierarchy(grid.shape, gam, coarsest_max=30)
    fold = hier.for_matrix(m)
    fold.set_sigma(1.0)
    m.eliminate_zeros()
    assert abs(sparse.csr_array(fold.ops[0]) - sparse.csr_array(hier.internal(m + gam))).max() <= 1e-12


def test_union_by_markers_equals_the_key_search():
    """The union pattern and both matrices' values on it, by one marker addition, are those of the
    key search, with explicit zeros of either matrix dropped."""
    rng = np.random.default_rng(7)
    for trial in range(12):
        n = int(rng.integers(1, 30))
        a = sparse.random(n, n, density=rng.uniform(0, 0.5), random_state=trial, format="csr")
        b = sparse.random(n, n, density=rng.uniform(0, 0.5), random_state=trial + 50, format="csr")
        a.data[::3] = 0.0
        pat, va, vb = mg._union_aligned(a, b)
        ref = mg._union_pattern(a, b)
        assert np.array_equal(pat.indptr, ref.indptr) and np.array_equal(pat.indices, ref.indices)
        assert np.array_equal(va, mg._aligned(ref, a)) and np.array_equal(vb, mg._aligned(ref, b))
        np.testing.assert_array_equal(pat.toarray() * 0 + sparse.csr_matrix((va, pat.indices, pat.indptr),
                                                                            shape=pat.shape).toarray(), a.toarray())


def test_permuted_equals_fancy_indexing():
    """Rows gathered and columns renumbered equal ``m[rows][:, cols]``, canonical, square and
    rectangular (the prolongations), from unsorted input with duplicates and from a sparse array."""
    rng = np.random.default_rng(3)
    for trial in range(10):
        n, k = int(rng.integers(1, 40)), int(rng.integers(1, 40))
        coo = sparse.random(n, k, density=rng.uniform(0, 0.4), random_state=trial, format="coo")
        dup = sparse.coo_matrix((np.concatenate([coo.data, coo.data[:3]]),
                                 (np.concatenate([coo.row, coo.row[:3]]), np.concatenate([coo.col, coo.col[:3]]))),
                                shape=coo.shape)
        m = dup.tocsr() if trial % 2 else sparse.csr_array(dup)
        rows, cols = rng.permutation(n), rng.permutation(k)
        got = mg._permuted(m, rows, cols)
        ref = sparse.csr_matrix(sparse.csr_matrix(m)[rows][:, cols])
        ref.sum_duplicates()
        ref.sort_indices()
        assert isinstance(got, sparse.csr_matrix) and got.has_canonical_format
        assert np.array_equal(got.indptr, ref.indptr) and np.array_equal(got.indices, ref.indices)
        np.testing.assert_array_equal(got.data, ref.data)


def _gamma_by_edge_blocks(grid):
    """Gamma as defined: the per-edge 2 x 2 blocks summed (COO), plus the ridge."""
    cell = float(np.prod(grid.step))
    rows, cols, vals = [], [], []
    for j in range(grid.n):
        a, b = grid.axis_edges(j)
        w = cell / grid.step[j] ** 2
        rows += [a, b, a, b]
        cols += [a, b, b, a]
        vals += [np.full(a.size, w), np.full(a.size, w), np.full(a.size, -w), np.full(a.size, -w)]
    n_v = grid.n_vertices
    lap = sparse.coo_array((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_v, n_v)).tocsc()
    eps = rl.FIRST_ORDER_RIDGE * float(lap.diagonal().mean())
    return (lap + eps * sparse.identity(n_v, format="csc")).tocsc()


@pytest.mark.parametrize("lo,hi,p", [([0, 0], [1, 3.7], [22, 29]), ([0, 0, 0], [1, 2.3, 0.7], [3, 4, 5]), ([0], [1.3], [17]),
                                     ([0, 0, 0, 0], [1, 2.1, 0.37, 5], [3, 2, 4, 3]), ([0] * 5, [1, 2.1, 0.37, 5, 0.9], [2, 3, 2, 2, 3])])
def test_first_order_gamma_is_the_sum_of_its_edge_blocks(lo, hi, p):
    """Built entry by entry, Gamma equals the summed per-edge blocks: bit for bit up to n = 4 (the
    order in which the blocks' duplicates are added), within an ulp beyond."""
    grid = Grid(np.asarray(lo, float), np.asarray(hi, float), p)
    got, ref = tikhonov_matrix(grid, 1), _gamma_by_edge_blocks(grid)
    assert got.has_canonical_format and np.array_equal(got.indptr, ref.indptr) and np.array_equal(got.indices, ref.indices)
    if grid.n <= 4:
        assert np.array_equal(got.data, ref.data)
    else:
        np.testing.assert_allclose(got.data, ref.data, rtol=4e-16, atol=0)


@pytest.mark.parametrize("n, k", [(0, 16), (1, 16), (7, 16), (16, 16), (100, 16), (1001, 16), (30, 4)])
def test_interleaved_order_is_a_permutation_of_interleaved_slabs(n, k):
    order = mg.interleaved_order(n, k)
    assert order.dtype == np.int64 and sorted(order.tolist()) == list(range(n))
    step = -(-n // k) if n else 0
    for pos, v in enumerate(order.tolist()[: 3 * k]):
        # consecutive positions run through the slabs: vertex j * step + i at some position i * k + j
        assert v % step * k + v // step >= pos if step else True
    if n >= k:
        first = [j * step for j in range(k) if j * step < n]  # position i = 0 of every slab
        assert order[: len(first)].tolist() == first


def test_levels_are_numbered_in_the_interleaved_order_and_solve_in_c_order():
    """The hierarchy's fine level is Gamma permuted by the interleaved order; solve and vcycle take
    and return C-order vectors (the weights equal the direct solve of the C-order system)."""
    grid, h, z, gam = _fold(shape=(47, 62), t=900)
    hier = mg.GridHierarchy(grid.shape, gam, coarsest_max=30)
    order = hier.orders[0]
    assert not np.array_equal(order, np.arange(order.size))
    assert abs(sparse.csr_array(hier.gammas[0]) - sparse.csr_array(gam)[order][:, order]).max() == 0.0
    m = sparse.csr_array(h.T @ h)
    b = h.T @ z
    fold = hier.for_matrix(m)
    w, info = fold.solve(b, 0.3, rtol=rl.CG_RTOL)
    wd = rl._solve_spd(sparse.csc_array(m + 0.3 * gam), b)
    assert info.converged
    assert float(np.linalg.norm(w - wd)) <= info.abs_residual / (0.3 * rl.gamma_min_eigenvalue(gam))
    v = np.random.default_rng(3).standard_normal(b.size)
    np.testing.assert_array_equal(hier.to_natural(hier.to_internal(v)), v)
    np.testing.assert_allclose(fold.vcycle(v), hier.to_natural(fold._vcycle_fine(hier.to_internal(v))))


def _reference_vcycle(fold, b, level):
    """The V-cycle with every residual a full product, as before the half-product residuals."""
    from pyamg.relaxation.relaxation import gauss_seidel

    if level == len(fold.ops) - 1:
        return fold._coarse.solve(b.astype(float)).astype(np.float32)
    a = fold._ops32[level]
    x = np.zeros_like(b)
    gauss_seidel(a, x, b, iterations=1, sweep="forward")
    r = b - a @ x
    x += fold._p32[level] @ _reference_vcycle(fold, fold._r32[level] @ r, level + 1)
    gauss_seidel(a, x, b, iterations=1, sweep="backward")
    return x


def _reference_block_cycle(fold, b):
    from pyamg.relaxation.relaxation import gauss_seidel

    a = fold.ops[0]
    x = fold.block.solve(b)
    gauss_seidel(a, x, b, iterations=1, sweep="forward")
    x += fold._p32[0] @ _reference_vcycle(fold, fold._r32[0] @ (b - a @ x).astype(np.float32), 1)
    gauss_seidel(a, x, b, iterations=1, sweep="backward")
    return x + fold.block.solve(b - a @ x)


@pytest.mark.parametrize("sigma", [1e-4, 0.5, 30.0])
def test_half_product_residuals_equal_the_full_products(sigma):
    """After a forward sweep from zero the residual is -U x, after a sweep from x0 it is -U (x - x0)
    (forward) or -L (x - x0) (backward): the cycles equal the ones with full products (a wrong
    triangle, or values of another sigma, would not)."""
    grid, h, z, gam = _fold(shape=(47, 62), t=900)
    fold = mg.GridHierarchy(grid.shape, gam, coarsest_max=30).for_matrix(sparse.csr_array(h.T @ h))
    fold.set_sigma(2 * sigma)
    fold.set_block(sigma)  # sets sigma itself, and the triangles' values with it
    # except the fine level's single-precision values, which the data-block cycle does not use:
    # the V-cycle from the fine level brings them to sigma first
    assert fold._fine32_sigma is None
    v = fold.vcycle(np.ones(gam.shape[0]))
    assert fold._fine32_sigma == sigma and fold._neg_upper32[0].sigma == sigma
    fold.sigma = None  # forget every value: set_sigma sets them all again, the same
    fold.set_sigma(sigma)
    np.testing.assert_array_equal(fold.vcycle(np.ones(gam.shape[0])), v)
    b = np.random.default_rng(4).standard_normal(gam.shape[0])
    b32 = b.astype(np.float32)
    # the same cycle up to rounding: single precision (a residual b - A x of nearly equal terms
    # rounds differently from -U x), double in the data-block cycle's fine level
    ref = _reference_vcycle(fold, b32, 0)
    assert np.linalg.norm(fold._vcycle(b32, 0) - ref) <= 1e-5 * np.linalg.norm(ref)
    ref = _reference_block_cycle(fold, b)
    assert np.linalg.norm(fold._vcycle_block_fine(b) - ref) <= 1e-6 * np.linalg.norm(ref)
    # a triangle of another sigma's values is not the same cycle
    fold._neg_upper32[0].set_sigma(3 * sigma)
    assert np.linalg.norm(fold._vcycle(b32, 0) - _reference_vcycle(fold, b32, 0)) > 1e-3 * np.linalg.norm(ref)


def test_set_sigma_after_set_block_refreshes_every_triangle_and_the_coarse_factor_falls_back():
    from pwas_hdl.fit.sparse_cholesky import NotPositiveDefinite, cholmod_available

    grid, h, z, gam = _fold(shape=(47, 62), t=900)
    fold = mg.GridHierarchy(grid.shape, gam, coarsest_max=30).for_matrix(sparse.csr_array(h.T @ h))
    fold.set_block(1e-3)
    fold.set_sigma(0.1)
    assert all(tri.sigma == 0.1 for tri in fold._neg_upper32 + fold._neg_tri64)
    if not cholmod_available():
        return

    def fail(values):
        raise NotPositiveDefinite("test")

    fold._coarse_chol.factorize = fail
    fold.set_sigma(2.0)  # SuperLU instead of the failing CHOLMOD factor
    assert fold.sigma == 2.0 and fold._coarse is not fold._coarse_chol
    b = np.random.default_rng(5).standard_normal(gam.shape[0])
    w, info = fold.solve(b, 2.0, rtol=rl.CG_RTOL)
    assert info.converged
