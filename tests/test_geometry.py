"""Geometry of the Kuhn partition (pwas_hdl.fit.geometry): exactness, location, continuity, basis matrix.

The checks here are independent of the implementation where it matters: the located simplex is
verified by solving the dense barycentric system with numpy, the tie rule by brute force from its
written definition, and the number of simplices by counting distinct located vertex sets.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from pwas_hdl.fit.geometry import Grid

#: Partitions of the "any n, any p" tests: mixed (powers of two and not, with p_j = 1), powers of two.
MIXED_P = [1, 3, 7, 2, 5, 4]
POW2_P = [2, 4, 8, 1, 2, 4]
P_SETS = {"mixed": MIXED_P, "pow2": POW2_P, "ones": [1] * 6}
NS = [1, 2, 3, 4, 5, 6]


# ------------------------------------------------------------------ helpers
def face_points(grid: Grid, m: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points on inner Kuhn faces: in a random cell, two fractional parts (dims i != j) are equal.

    Returns the physical points and the tied dimension pair (i, j) of each point (i < j). Fractions
    are multiples of 1/1024 in [0.05, 0.95], so the ties are exact on a unit-step grid.
    Requires n >= 2.
    """
    n = grid.n
    cell = rng.integers(0, grid.partitions, size=(m, n))
    frac = rng.integers(51, 973, (m, n)) / 1024.0  # dyadic: exact ties on a unit-step grid
    pairs = np.array([rng.choice(n, 2, replace=False) for _ in range(m)])
    pairs.sort(axis=1)
    rows = np.arange(m)
    frac[rows, pairs[:, 1]] = frac[rows, pairs[:, 0]]
    x = grid.lo + (cell + frac) * grid.step
    return x, pairs[:, 0], pairs[:, 1]


def lipschitz_grid_units(grid: Grid, w: np.ndarray) -> float:
    """Bound of |f(s) - f(s')| / max_j |s_j - s'_j| (grid units): on a simplex df/ds_perm[k] is a
    difference of two weights, so the gradient 1-norm is at most 2 n max|w|."""
    return 2.0 * grid.n * float(np.max(np.abs(w)))


def reference_rank(frac: np.ndarray) -> np.ndarray:
    """rank_j = #{i : d_i > d_j or (d_i == d_j and i < j)} -- the documented rule, by brute force."""
    m, n = frac.shape
    rank = np.zeros((m, n), dtype=np.int64)
    for r in range(m):
        for j in range(n):
            rank[r, j] = sum(
                1 for i in range(n) if frac[r, i] > frac[r, j] or (frac[r, i] == frac[r, j] and i < j)
            )
    return rank


# -------------------------------------------------------------- exactness
@pytest.mark.parametrize("pname", sorted(P_SETS))
@pytest.mark.parametrize("n", NS)
def test_affine_function_reproduced_exactly(n, pname, make_grid, inside_points, rng):
    """Weights = affine function at the vertices -> the PWAS function IS that affine function."""
    grid = make_grid(P_SETS[pname][:n])
    a = rng.normal(0.0, 2.0, n)
    b = rng.normal(0.0, 2.0)
    w = grid.vertex_points() @ a + b
    x = inside_points(grid, 2000)
    if n >= 2:
        x = np.vstack([x, face_points(grid, 300, rng)[0]])
    # vertices too (all fractional parts tie at 0)
    x = np.vstack([x, grid.vertex_points(rng.integers(0, grid.n_vertices, 50))])
    exact = x @ a + b
    scale = abs(b) + float(np.abs(a) @ np.maximum(np.abs(grid.lo), np.abs(grid.hi)))
    err = np.max(np.abs(grid.evaluate(w, x) - exact))
    assert err <= 1e-9 * scale, f"max error {err:.3e} vs scale {scale:.3e}"


@pytest.mark.parametrize("pname", sorted(P_SETS))
@pytest.mark.parametrize("n", NS)
def test_value_at_every_vertex_is_its_weight(n, pname, make_grid, rng):
    grid = make_grid(P_SETS[pname][:n])
    w = rng.normal(0.0, 1.0, (grid.n_vertices, 2))
    got = grid.evaluate(w, grid.vertex_points())
    np.testing.assert_allclose(got, w, rtol=0, atol=1e-9 * np.max(np.abs(w)))
    # one-column weights give the same values as column 0 of the two-column case
    np.testing.assert_allclose(grid.evaluate(w[:, 0], grid.vertex_points()), got[:, 0], rtol=0, atol=1e-15)


def test_vertex_numbering_is_row_major(make_grid):
    grid = make_grid([3, 1, 4])
    coords = grid.vertex_coords()
    assert coords.shape == (grid.n_vertices, 3)
    np.testing.assert_array_equal(np.ravel_multi_index(tuple(coords.T), grid.shape), np.arange(grid.n_vertices))
    np.testing.assert_array_equal(grid.vertex_index(coords), np.arange(grid.n_vertices))
    assert grid.n_vertices == 4 * 2 * 5
    assert grid.n_simplices == math.factorial(3) * 3 * 1 * 4


# -------------------------------------------------------------- barycentric
@pytest.mark.parametrize("pname", ["mixed", "pow2"])
@pytest.mark.parametrize("n", NS)
def test_mu_nonnegative_and_sums_to_one(n, pname, make_grid, inside_points, rng):
    grid = make_grid(P_SETS[pname][:n])
    parts = [
        inside_points(grid, 500),
        grid.vertex_points(),  # all fractional parts tie (0, or 1 on the upper boundary)
        grid.lo + rng.uniform(-0.5, 1.5, (200, n)) * (grid.hi - grid.lo),  # some outside (clamped)
    ]
    if n >= 2:
        parts.append(face_points(grid, 300, rng)[0])
    loc = grid.locate(np.vstack(parts))
    assert loc.mu.shape[1] == n + 1
    assert np.all(loc.mu >= 0.0), loc.mu.min()
    assert np.all(np.abs(loc.mu.sum(axis=1) - 1.0) <= 4 * (n + 1) * np.finfo(float).eps)
    assert np.all((loc.frac >= 0) & (loc.frac <= 1))
    assert np.all((loc.cell >= 0) & (loc.cell <= grid.partitions - 1))
    assert np.all((loc.s >= 0) & (loc.s <= grid.partitions))


# -------------------------------------------------------------- continuity
@pytest.mark.parametrize("n", [2, 3, 4, 6])
def test_continuous_across_inner_kuhn_faces(n, make_grid, rng):
    """Across a face d_i = d_j the located simplex changes but the value does not jump."""
    grid = make_grid(MIXED_P[:n])
    w = rng.normal(0.0, 1.0, grid.n_vertices)
    m = 400
    x, i, j = face_points(grid, m, rng)
    eps = 1e-7  # grid units
    d = np.zeros((m, n))
    d[np.arange(m), i] = eps
    d[np.arange(m), j] = -eps
    xp, xm = x + d * grid.step, x - d * grid.step
    lp, lm = grid.locate(xp), grid.locate(xm)
    # meaningful: the two sides really are in different simplices (same cell, other order)
    np.testing.assert_array_equal(lp.cell, lm.cell)
    rows = np.arange(m)
    assert np.all(lp.rank[rows, i] < lp.rank[rows, j])
    assert np.all(lm.rank[rows, i] > lm.rank[rows, j])
    assert np.all(np.any(lp.vertices != lm.vertices, axis=1))
    bound = lipschitz_grid_units(grid, w) * 2 * eps * 1.01 + 1e-12
    jump = np.abs(grid.evaluate(w, xp) - grid.evaluate(w, xm))
    assert np.max(jump) <= bound, (np.max(jump), bound)
    on_face = grid.evaluate(w, x)
    assert np.max(np.abs(on_face - grid.evaluate(w, xp))) <= bound


@pytest.mark.parametrize("n", [2, 3, 5])
def test_both_simplices_of_a_face_give_the_same_value_on_it(n, make_grid, rng):
    """The tie rule only picks one of the simplices sharing the face; the other gives the same value."""
    grid = make_grid(MIXED_P[:n], unit=True)  # grid units = physical units: ties are exact
    w = rng.normal(0.0, 1.0, grid.n_vertices)
    x, i, j = face_points(grid, 300, rng)
    loc = grid.locate(x)
    rows = np.arange(x.shape[0])
    assert np.all(loc.frac[rows, i] == loc.frac[rows, j])
    # keep the points on exactly one face (no third dimension with the same fraction)
    keep = np.sum(loc.frac == loc.frac[rows, i][:, None], axis=1) == 2
    assert keep.mean() > 0.5
    x, i, j = x[keep], i[keep], j[keep]
    loc = grid.locate(x)
    rows = np.arange(x.shape[0])
    # the tied dimensions are adjacent in the order; swap them to get the neighbouring simplex
    ri, rj = loc.rank[rows, i], loc.rank[rows, j]
    assert np.all(rj == ri + 1)
    other = loc.perm.copy()
    other[rows, ri], other[rows, rj] = loc.perm[rows, rj], loc.perm[rows, ri]
    v2 = grid.simplex_vertices(loc.cell, other)
    mu2 = grid.barycentric(loc.frac, other)
    assert np.all(np.any(v2 != loc.vertices, axis=1))
    np.testing.assert_allclose(np.sum(mu2 * w[v2], axis=1), np.sum(loc.mu * w[loc.vertices], axis=1), rtol=0, atol=1e-12)


@pytest.mark.parametrize("n", [1, 2, 4])
def test_continuous_across_cell_boundaries(n, make_grid, rng):
    grid = make_grid([3, 5, 2, 4][:n])
    w = rng.normal(0.0, 1.0, grid.n_vertices)
    m = 300
    s = rng.uniform(0.0, 1.0, (m, n)) * grid.partitions
    j = rng.integers(0, n, m)
    rows = np.arange(m)
    s[rows, j] = rng.integers(1, grid.partitions[j])  # an inner cell boundary (all p_j >= 2 here)
    x = grid.lo + s * grid.step
    eps = 1e-7
    d = np.zeros((m, n))
    d[rows, j] = eps
    lp, lm = grid.locate(x + d * grid.step), grid.locate(x - d * grid.step)
    np.testing.assert_array_equal(lp.cell[rows, j], lm.cell[rows, j] + 1)
    bound = lipschitz_grid_units(grid, w) * 2 * eps * 1.01 + 1e-12
    jump = np.abs(grid.evaluate(w, x + d * grid.step) - grid.evaluate(w, x - d * grid.step))
    assert np.max(jump) <= bound, (np.max(jump), bound)


# ----------------------------------------------------------------- location
@pytest.mark.parametrize("pname", ["mixed", "pow2"])
@pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
def test_located_simplex_contains_point_independent_solve(n, pname, make_grid, inside_points, rng):
    """Solve the dense (n+1)x(n+1) barycentric system of the located vertices with numpy."""
    grid = make_grid(P_SETS[pname][:n])
    x = inside_points(grid, 200)
    if n >= 2:
        x = np.vstack([x, face_points(grid, 50, rng)[0]])
    loc = grid.locate(x)
    assert not loc.out_of_domain.any()
    pts = grid.vertex_points(loc.vertices)  # (m, n+1, n)
    m = x.shape[0]
    a = np.concatenate([np.swapaxes(pts, 1, 2), np.ones((m, 1, n + 1))], axis=1)  # (m, n+1, n+1)
    rhs = np.concatenate([x, np.ones((m, 1))], axis=1)[:, :, None]
    lam = np.linalg.solve(a, rhs)[:, :, 0]
    assert lam.min() >= -1e-12, lam.min()
    np.testing.assert_allclose(lam, loc.mu, rtol=0, atol=1e-10)
    # the located vertices are n+1 distinct vertices of the cell c
    assert np.all(np.sort(loc.vertices, axis=1)[:, 1:] != np.sort(loc.vertices, axis=1)[:, :-1])
    np.testing.assert_array_equal(grid.vertex_coords(loc.vertices[:, 0]), loc.cell)


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_rank_and_perm_are_inverse_permutations(n, make_grid, inside_points):
    grid = make_grid(MIXED_P[:n])
    loc = grid.locate(inside_points(grid, 300))
    rows = np.arange(loc.rank.shape[0])[:, None]
    ks = np.arange(n)[None, :]
    np.testing.assert_array_equal(np.sort(loc.perm, axis=1), np.broadcast_to(ks, loc.perm.shape))
    np.testing.assert_array_equal(loc.rank[rows, loc.perm], np.broadcast_to(ks, loc.perm.shape))
    np.testing.assert_array_equal(loc.perm[rows, loc.rank], np.broadcast_to(ks, loc.perm.shape))
    # perm orders the fractional parts descending
    d_sorted = np.take_along_axis(loc.frac, loc.perm, axis=1)
    assert np.all(np.diff(d_sorted, axis=1) <= 0)


@pytest.mark.parametrize("n", [2, 3, 4, 6])
def test_tie_rule_lower_index_gets_lower_rank(n, make_grid, rng):
    """Constructed ties: fractional parts from {0, 1/4, 1/2, 3/4} are exact in binary."""
    grid = make_grid([4] * n, unit=True)
    m = 500
    cell = rng.integers(0, 4, (m, n))
    frac = rng.integers(0, 4, (m, n)) / 4.0
    x = cell + frac
    loc = grid.locate(x)
    np.testing.assert_array_equal(loc.frac, frac)
    assert any(len(set(r)) < n for r in frac.tolist())  # there are ties
    ref = reference_rank(frac)
    np.testing.assert_array_equal(loc.rank, ref)
    # on every tie the lower dimension index has the lower rank
    for r in range(m):
        for i, j in itertools.combinations(range(n), 2):
            if frac[r, i] == frac[r, j]:
                assert loc.rank[r, i] < loc.rank[r, j]
    # the integer form (fixed-point model) uses the same rule
    irank, iperm = Grid.order((frac * 4).astype(np.int64))
    np.testing.assert_array_equal(irank, ref)
    np.testing.assert_array_equal(iperm, loc.perm)


def test_tie_rule_hand_examples():
    rank, perm = Grid.order(np.array([[0.5, 0.5, 0.5], [0.25, 0.5, 0.5], [0.5, 0.25, 0.5], [0.5, 0.5, 0.75]]))
    np.testing.assert_array_equal(perm, [[0, 1, 2], [1, 2, 0], [0, 2, 1], [2, 0, 1]])
    np.testing.assert_array_equal(rank, [[0, 1, 2], [2, 0, 1], [0, 2, 1], [1, 2, 0]])


@pytest.mark.parametrize("n", [2, 3, 5])
def test_hardware_form_stepped_iff_rank_below_k(n, make_grid, inside_points, rng):
    """Dimension j has stepped at vertex k exactly when rank_j < k (the sorter-free form)."""
    grid = make_grid(MIXED_P[:n])
    x = np.vstack([inside_points(grid, 200), face_points(grid, 100, rng)[0]])
    loc = grid.locate(x)
    for k in range(n + 1):
        offset = grid.vertex_coords(loc.vertices[:, k]) - loc.cell
        np.testing.assert_array_equal(offset, (loc.rank < k).astype(np.int64))


@pytest.mark.parametrize("p", [[3, 4], [2, 2, 2], [1, 2, 1]])
def test_number_of_distinct_simplices(p, make_grid, inside_points):
    grid = make_grid(p)
    loc = grid.locate(inside_points(grid, 30000))
    simplices = {tuple(sorted(v)) for v in loc.vertices.tolist()}
    assert len(simplices) == grid.n_simplices == math.factorial(len(p)) * int(np.prod(p))


def test_points_outside_are_clamped_and_flagged(make_grid, rng):
    grid = make_grid([3, 2, 5])
    w = rng.normal(0.0, 1.0, grid.n_vertices)
    x = grid.lo + rng.uniform(-1.0, 2.0, (500, 3)) * (grid.hi - grid.lo)
    loc = grid.locate(x)
    outside = np.any((x < grid.lo) | (x > grid.hi), axis=1)
    assert outside.any() and (~outside).any()
    np.testing.assert_array_equal(loc.out_of_domain, outside)
    np.testing.assert_array_equal(grid.evaluate(w, x), grid.evaluate(w, np.clip(x, grid.lo, grid.hi)))


def test_points_on_the_domain_boundary_are_not_flagged(make_grid, rng):
    """The domain is the closed box [lo, hi]: a coordinate exactly at lo or hi (the data's own min /
    max with gamma = 1, a sensor at its rail) is inside and must not be reported as out of domain."""
    grid = make_grid([3, 2, 5])
    x = grid.lo + rng.uniform(0.0, 1.0, (200, 3)) * (grid.hi - grid.lo)
    cols = rng.integers(0, 3, 200)
    rows = np.arange(200)
    x[rows[:100], cols[:100]] = grid.lo[cols[:100]]
    x[rows[100:], cols[100:]] = grid.hi[cols[100:]]
    x = np.vstack([x, grid.lo, grid.hi, grid.vertex_points()])
    loc = grid.locate(x)
    assert not loc.out_of_domain.any()
    # one ulp outside is outside
    above = np.nextafter(grid.hi, np.inf)
    below = np.nextafter(grid.lo, -np.inf)
    assert grid.locate(np.vstack([above, below])).out_of_domain.all()
    # many boxes: (hi - lo) / step rounds above p for about 1 box in 20, which must not flag x = hi
    for _ in range(500):
        lo = rng.uniform(-100.0, 100.0, 2)
        g = Grid(lo, lo + 10.0 ** rng.uniform(-3, 3, 2), rng.integers(1, 50, 2))
        corners = np.array([[a, b] for a in (g.lo[0], g.hi[0]) for b in (g.lo[1], g.hi[1])])
        assert not g.locate(corners).out_of_domain.any(), g


# -------------------------------------------------------------- basis matrix
@pytest.mark.parametrize("pname", ["mixed", "pow2", "ones"])
@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_basis_matrix_rows_and_product(n, pname, make_grid, inside_points, rng):
    grid = make_grid(P_SETS[pname][:n])
    x = np.vstack([inside_points(grid, 400), grid.vertex_points()])  # vertices: explicit zero entries
    h = grid.basis_matrix(x)
    m = x.shape[0]
    assert h.shape == (m, grid.n_vertices)
    assert h.nnz == m * (n + 1)
    np.testing.assert_array_equal(np.diff(h.indptr), np.full(m, n + 1))
    for r in range(0, m, 37):
        cols = h.indices[h.indptr[r] : h.indptr[r + 1]]
        assert len(set(cols.tolist())) == n + 1
    assert h.data.min() >= 0
    np.testing.assert_allclose(h.sum(axis=1), 1.0, rtol=0, atol=1e-14)
    w = rng.normal(0.0, 1.0, (grid.n_vertices, 2))
    np.testing.assert_allclose(h @ w, grid.evaluate(w, x), rtol=0, atol=1e-12)
    np.testing.assert_allclose(h @ w[:, 1], grid.evaluate(w[:, 1], x), rtol=0, atol=1e-12)
    # the same entries as the located simplex: H[t, v_k] = mu_k
    loc = grid.locate(x)
    dense = h.toarray()
    np.testing.assert_array_equal(dense[np.arange(m)[:, None], loc.vertices], loc.mu)
