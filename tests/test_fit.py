"""Fitting (pwas_hdl.fit.regularized_lsq, pwas_hdl.fit.regressors, PWASVirtualSensor.fit / predict)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from pwas_hdl.io.csv_table import Table, select_signals
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.regressors import LagStructure
from pwas_hdl.fit.regularized_lsq import (
    DEFAULT_SIGMA_GRID,
    FIRST_ORDER_RIDGE,
    CVResult,
    cross_validate_sigma,
    fold_labels,
    solve_regularized,
    tikhonov_matrix,
)
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

SMALL_GRIDS = [[1], [4], [3, 4], [2, 1, 3], [2, 2, 2]]


# ------------------------------------------------------- recovery of weights
@pytest.mark.parametrize("order", [0, 1])
@pytest.mark.parametrize("p", [[3, 4], [2, 2, 2]], ids=["n2_p3x4", "n3_p2"])
def test_noise_free_fit_recovers_weights(p, order, make_grid, inside_points, rng):
    grid = make_grid(p)
    w_true = rng.normal(0.0, 1.0, (grid.n_vertices, 2))
    x = inside_points(grid, 150 * grid.n_vertices)
    h = grid.basis_matrix(x)
    z = grid.evaluate(w_true, x)
    w = solve_regularized(h, z, 1e-10, tikhonov_matrix(grid, order))
    assert w.shape == w_true.shape
    np.testing.assert_allclose(w, w_true, rtol=0, atol=1e-6)
    w1 = solve_regularized(h, z[:, 1], 1e-10, tikhonov_matrix(grid, order))
    assert w1.shape == (grid.n_vertices,)
    np.testing.assert_allclose(w1, w_true[:, 1], rtol=0, atol=1e-6)


def test_large_sigma_shrinks_weights(make_grid, inside_points, rng):
    """Sanity of the regulariser's direction: more sigma, smaller (order 0) weights."""
    grid = make_grid([3, 4])
    x = inside_points(grid, 2000)
    z = 5.0 + grid.evaluate(rng.normal(0.0, 1.0, grid.n_vertices), x)
    h, gam = grid.basis_matrix(x), tikhonov_matrix(grid, 0)
    norms = [np.linalg.norm(solve_regularized(h, z, s, gam)) for s in (1e-6, 1e1, 1e3, 1e6)]
    assert all(a > b for a, b in zip(norms, norms[1:]))
    assert norms[-1] < 0.05 * norms[0]


@pytest.mark.parametrize(
    "mu,my,p",
    [(0, 2, [3, 4]), (2, 1, [2, 3, 2])],
    ids=["y_lags_only", "u_and_y_lags"],
)
def test_sensor_recovers_pwas_function_of_lagged_signals(mu, my, p, rng):
    """z(t) = f(xi(t)) with f a PWAS function on the explicit domain: the sensor finds f's weights.

    The partitions differ per dimension and f has random weights, so a wrong regressor order
    (e.g. newest sample first) would not reproduce the weights.
    """
    t_len = 4000
    u = rng.uniform(-1.0, 2.0, t_len)
    # y: white, so that consecutive lags fill the whole box (every vertex is identifiable)
    y = rng.uniform(0.0, 1.0, t_len)
    n = mu + my
    lo = np.array([-1.0] * mu + [0.0] * my)
    hi = np.array([2.0] * mu + [1.0] * my)
    grid = Grid(lo, hi, p)
    w_true = rng.normal(0.0, 1.0, grid.n_vertices)
    m = max(mu, my)
    xi = np.column_stack(
        [u[m - 1 - lag : t_len - lag] for lag in range(mu - 1, -1, -1)]
        + [y[m - 1 - lag : t_len - lag] for lag in range(my - 1, -1, -1)]
    )
    assert xi.shape == (t_len - m + 1, n)
    z = np.zeros(t_len)
    z[m - 1 :] = grid.evaluate(w_true, xi)
    sensor = PWASVirtualSensor(mu=mu, my=my, partitions=p, sigma=1e-10, domain=(lo, hi))
    sensor.fit(u if mu else None, y, z)
    assert sensor.grid_ == grid
    assert sensor.weights_.shape == (grid.n_vertices, 1)
    np.testing.assert_allclose(sensor.weights_[:, 0], w_true, rtol=0, atol=1e-6)
    zhat = sensor.predict(u if mu else None, y)
    np.testing.assert_allclose(zhat[:, 0], z[m - 1 :], rtol=0, atol=1e-6)
    assert sensor.n_train_ == t_len - m + 1
    assert sensor.sigma_ == 1e-10 and sensor.cv_ is None


@pytest.mark.parametrize("share", [True, False])
def test_domain_from_data_expanded_by_gamma(share, rng):
    y = rng.uniform(0.0, 1.0, 500)
    y[10], y[499] = -2.0, 3.0  # the extreme values appear in only one lag position each
    gamma = 1.5
    sensor = PWASVirtualSensor(my=2, partitions=2, sigma=1.0, gamma=gamma, share_lag_domain=share)
    sensor.fit(None, y, y**2)
    xi, _ = sensor.regressors(None, y)
    lo, hi = xi.min(axis=0), xi.max(axis=0)
    if share:
        lo, hi = np.full(2, lo.min()), np.full(2, hi.max())
        np.testing.assert_array_equal(sensor.grid_.lo[0], sensor.grid_.lo[1])
    else:
        assert sensor.grid_.lo[0] != sensor.grid_.lo[1] or sensor.grid_.hi[0] != sensor.grid_.hi[1]
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    np.testing.assert_allclose(sensor.grid_.lo, centre - gamma * half, rtol=1e-14)
    np.testing.assert_allclose(sensor.grid_.hi, centre + gamma * half, rtol=1e-14)


# ---------------------------------------------------------------- Tikhonov
@pytest.mark.parametrize("order", [0, 1])
@pytest.mark.parametrize("p", SMALL_GRIDS, ids=lambda p: "p" + "x".join(map(str, p)))
def test_tikhonov_matrix_is_symmetric_positive_definite(p, order, make_grid):
    grid = make_grid(p)
    gam = tikhonov_matrix(grid, order)
    assert sparse.issparse(gam) and gam.shape == (grid.n_vertices, grid.n_vertices)
    dense = gam.toarray()
    np.testing.assert_array_equal(dense, dense.T)
    ev = np.linalg.eigvalsh(dense)
    # clearly positive, not a rounding-level zero (a bare Laplacian has a null space)
    assert ev.min() > 1e-9 * ev.max(), (ev.min(), ev.max())
    if order == 0:
        np.testing.assert_array_equal(dense, np.eye(grid.n_vertices))


@pytest.mark.parametrize("p", [[4], [3, 4], [2, 1, 3]], ids=lambda p: "p" + "x".join(map(str, p)))
def test_first_order_penalty_prefers_smooth_functions(p, make_grid, rng):
    grid = make_grid(p)
    gam = tikhonov_matrix(grid, 1)
    lap_diag_mean = float(np.mean(gam.diagonal())) / (1 + FIRST_ORDER_RIDGE)
    eps = FIRST_ORDER_RIDGE * lap_diag_mean
    a = rng.normal(0.0, 1.0, grid.n)
    w_lin = grid.vertex_points() @ a + 0.3
    # a rough function of the same norm: checkerboard on the vertex grid
    w_rough = (-1.0) ** grid.vertex_coords().sum(axis=1)
    w_rough *= np.linalg.norm(w_lin) / np.linalg.norm(w_rough)
    pen_lin, pen_rough = float(w_lin @ (gam @ w_lin)), float(w_rough @ (gam @ w_rough))
    assert pen_lin < pen_rough
    # documented formula: sum_j sum_edges ((w_b - w_a)/h_j)^2 V_cell + eps ||w||^2; for a linear
    # function every edge along j contributes a_j^2 V_cell and there are p_j prod_{i!=j}(p_i+1) edges
    v_cell = float(np.prod(grid.step))
    edges = [int(grid.partitions[j] * np.prod(np.delete(grid.partitions + 1, j))) for j in range(grid.n)]
    expected = sum(a[j] ** 2 * v_cell * edges[j] for j in range(grid.n)) + eps * float(w_lin @ w_lin)
    np.testing.assert_allclose(pen_lin, expected, rtol=1e-9)
    # constants are penalised only by the tiny ridge
    w_const = np.full(grid.n_vertices, 2.0)
    np.testing.assert_allclose(float(w_const @ (gam @ w_const)), eps * float(w_const @ w_const), rtol=1e-6)


# ---------------------------------------------------------- cross-validation
def _cv_problem(rng, noise: float, make_grid, inside_points):
    grid = make_grid([8, 8])
    x = inside_points(grid, 300)
    z_true = grid.evaluate(grid.vertex_points() @ np.array([0.5, -0.3]), x)  # affine, small
    return grid, x, z_true + rng.normal(0.0, noise, z_true.shape)


CV_SIGMAS = [1e-6, 1e-3, 1e-1, 1.0, 10.0, 100.0]


def test_cv_noise_free_picks_smallest_sigma(make_grid, inside_points, rng):
    grid = make_grid([3, 4])
    x = inside_points(grid, 3000)
    z = grid.evaluate(rng.normal(0.0, 1.0, grid.n_vertices), x)
    cv = cross_validate_sigma(grid.basis_matrix(x), z, tikhonov_matrix(grid, 0), CV_SIGMAS, folds=5)
    assert cv.best_sigma == CV_SIGMAS[0]
    assert np.all(np.diff(cv.mse) > 0)


@pytest.mark.parametrize("order", [0, 1])
def test_cv_heavy_noise_does_not_pick_smallest_sigma(order, make_grid, inside_points):
    """81 weights, 300 samples, noise std 3 >> signal: over-fitting must lose. Checked on 5 seeds."""
    for seed in range(5):
        rng = np.random.default_rng(seed)
        grid, x, z = _cv_problem(rng, 3.0, make_grid, inside_points)
        cv = cross_validate_sigma(grid.basis_matrix(x), z, tikhonov_matrix(grid, order), CV_SIGMAS, folds=5)
        assert isinstance(cv, CVResult)
        np.testing.assert_array_equal(cv.sigmas, CV_SIGMAS)
        assert cv.mse.shape == (len(CV_SIGMAS),) and cv.fold_mse.shape == (5, len(CV_SIGMAS))
        assert cv.best_sigma in CV_SIGMAS
        assert cv.best_sigma == CV_SIGMAS[int(np.argmin(cv.mse))]
        assert cv.best_sigma != CV_SIGMAS[0], (seed, cv.mse)
        assert cv.mse[0] > 1.2 * cv.mse.min(), (seed, cv.mse)


def test_cv_fold_errors_match_direct_refits(make_grid, inside_points, rng):
    """The downdated normal equations give the same fold MSE as fitting each training set afresh."""
    grid, x, z = _cv_problem(rng, 1.0, make_grid, inside_points)
    h, gam = grid.basis_matrix(x), tikhonov_matrix(grid, 1)
    zz = np.column_stack([z, -2 * z + 1])
    folds = 4
    cv = cross_validate_sigma(h, zz, gam, CV_SIGMAS, folds=folds)
    labels = fold_labels(x.shape[0], folds)
    assert np.all(np.diff(labels) >= 0) and set(labels.tolist()) == set(range(folds))  # contiguous
    for f in range(folds):
        tr, va = labels != f, labels == f
        for i, s in enumerate(CV_SIGMAS):
            w = solve_regularized(h[np.flatnonzero(tr)], zz[tr], s, gam)
            mse = np.mean((zz[va] - h[np.flatnonzero(va)] @ w) ** 2)
            np.testing.assert_allclose(cv.fold_mse[f, i], mse, rtol=1e-7)
    np.testing.assert_allclose(cv.mse, cv.fold_mse.mean(axis=0), rtol=1e-15)


def test_sensor_without_sigma_runs_cv(rng):
    y = rng.uniform(-1.0, 1.0, 800)
    z = np.sin(3 * y) + rng.normal(0.0, 0.5, y.size)
    sensor = PWASVirtualSensor(my=1, partitions=12, sigma=None, cv_folds=4, sigma_grid=CV_SIGMAS)
    sensor.fit(None, y, z)
    assert isinstance(sensor.cv_, CVResult)
    assert sensor.cv_.folds == 4
    assert sensor.sigma_ == sensor.cv_.best_sigma
    assert sensor.sigma_ in CV_SIGMAS
    assert sensor.sigma_ == CV_SIGMAS[int(np.argmin(sensor.cv_.mse))]
    # the final weights are the full-data solve with the chosen sigma
    h = sensor.grid_.basis_matrix(y[:, None])
    w = solve_regularized(h, z, sensor.sigma_, tikhonov_matrix(sensor.grid_, 0))
    np.testing.assert_allclose(sensor.weights_[:, 0], w, rtol=0, atol=1e-12)
    # default candidate grid
    sensor2 = PWASVirtualSensor(my=1, partitions=5, sigma=None).fit(None, y, z)
    assert sensor2.sigma_ in DEFAULT_SIGMA_GRID
    np.testing.assert_array_equal(sensor2.cv_.sigmas, DEFAULT_SIGMA_GRID)
    # an explicit sigma skips the CV
    sensor3 = PWASVirtualSensor(my=1, partitions=5, sigma=0.25).fit(None, y, z)
    assert sensor3.sigma_ == 0.25 and sensor3.cv_ is None


# ------------------------------------------------------------- trajectories
def test_regressors_never_straddle_trajectories():
    my = 3
    y1 = np.arange(1.0, 6.0)  # T1 = 5
    y2 = 100.0 + np.arange(1.0, 8.0)  # T2 = 7
    sensor = PWASVirtualSensor(my=my)
    xi, valid = sensor.regressors(None, [y1, y2])
    assert xi.shape == ((5 - my + 1) + (7 - my + 1), my)
    expected = np.array(
        [[1, 2, 3], [2, 3, 4], [3, 4, 5], [101, 102, 103], [102, 103, 104], [103, 104, 105], [104, 105, 106], [105, 106, 107]],
        dtype=float,
    )
    np.testing.assert_array_equal(xi, expected)
    assert valid == [slice(2, 5), slice(2, 7)]
    # the concatenation would have created the (different) straddling rows [4, 5, 101], [5, 101, 102]
    xi_cat, _ = sensor.regressors(None, np.concatenate([y1, y2]))
    assert xi_cat.shape[0] == xi.shape[0] + my - 1
    assert all(np.all(r < 100) or np.all(r > 100) for r in xi)
    assert any(np.any(r < 100) and np.any(r > 100) for r in xi_cat)


def test_fit_and_predict_with_several_trajectories(rng):
    """Targets are aligned per trajectory; the same data as a CSV with a trajectory column agrees."""
    my, lens = 2, [60, 45, 80]
    ys = [rng.uniform(0.0, 1.0, t) for t in lens]
    zs = [np.concatenate([[0.0], y[1:] - 0.5 * y[:-1]]) for y in ys]  # affine in (y[t-1], y[t])
    sensor = PWASVirtualSensor(my=my, partitions=[2, 3], sigma=1e-9, domain=([0, 0], [1, 1]))
    sensor.fit(None, ys, zs)
    assert sensor.n_train_ == sum(t - my + 1 for t in lens)
    assert sensor.n_trajectories_ == 3
    zhat = sensor.predict(None, ys)
    assert zhat.shape == (sum(t - my + 1 for t in lens), 1)
    np.testing.assert_allclose(zhat[:, 0], np.concatenate([z[my - 1 :] for z in zs]), atol=1e-7)
    # the same data through a CSV table with a trajectory column
    rows = [[f"run{i}", repr(float(yv)), repr(float(zv))] for i, (y, z) in enumerate(zip(ys, zs)) for yv, zv in zip(y, z)]
    table = Table("mem.csv", ["traj", "y", "z"], rows)
    ys_csv = select_signals(table, ["y"], "traj")
    zs_csv = select_signals(table, ["z"], "traj")
    assert [a.shape[0] for a in ys_csv] == lens
    sensor_csv = PWASVirtualSensor(my=my, partitions=[2, 3], sigma=1e-9, domain=([0, 0], [1, 1])).fit(None, ys_csv, zs_csv)
    np.testing.assert_array_equal(sensor_csv.weights_, sensor.weights_)


# ---------------------------------------------------- lag structure, targets
def test_mu_zero_allowed_and_inputs_ignored(rng):
    u = rng.uniform(0.0, 1.0, (300, 2))
    y = rng.uniform(0.0, 1.0, 300)
    z = y**2
    a = PWASVirtualSensor(mu=0, my=2, partitions=3, sigma=1e-3).fit(u, y, z)
    b = PWASVirtualSensor(mu=0, my=2, partitions=3, sigma=1e-3).fit(None, y, z)
    assert a.n_inputs == 0 and a.lags_.dimension == 2 and a.grid_.n == 2
    np.testing.assert_array_equal(a.weights_, b.weights_)
    np.testing.assert_array_equal(a.predict(u, y), b.predict(None, y))


def test_regressor_order_two_inputs_two_lags():
    """nu = 2, Mu = 2, ny = 1, My = 2 -> n = 6: [u0(t-1), u1(t-1), u0(t), u1(t), y(t-1), y(t)]."""
    t = np.arange(10.0)
    u = np.column_stack([1000 + t, 2000 + t])
    y = 3000 + t
    sensor = PWASVirtualSensor(mu=2, my=2)
    xi, valid = sensor.regressors(u, y)
    assert xi.shape == (9, 6)
    assert valid == [slice(1, 10)]
    tt = np.arange(1, 10.0)
    expected = np.column_stack([1000 + tt - 1, 2000 + tt - 1, 1000 + tt, 2000 + tt, 3000 + tt - 1, 3000 + tt])
    np.testing.assert_array_equal(xi, expected)
    lags = LagStructure(2, 2, 2, 1)
    assert lags.dimension == 6 and lags.memory == 2
    assert lags.names(["a", "b"], ["y"]) == ["a[t-1]", "b[t-1]", "a[t]", "b[t]", "y[t-1]", "y[t]"]
    # fitted: the model reports the same order
    rng = np.random.default_rng(1)
    u = rng.uniform(0.0, 1.0, (200, 2))
    y = rng.uniform(0.0, 1.0, 200)
    s = PWASVirtualSensor(mu=2, my=2, partitions=1, sigma=1e-6).fit(u, y, y + u[:, 0])
    assert s.grid_.n == 6 and s.weights_.shape == (2**6, 1)
    assert s.to_dict()["regressors"] == ["u0[t-1]", "u1[t-1]", "u0[t]", "u1[t]", "y0[t-1]", "y0[t]"]


@pytest.mark.parametrize("order", [0, 1])
def test_two_targets_equal_two_single_target_fits(order, rng):
    u = rng.uniform(-1.0, 1.0, 600)
    y = np.cumsum(rng.normal(0.0, 0.1, 600))
    z = np.column_stack([np.sin(y) + u, u * y])
    kw = dict(mu=1, my=2, partitions=[3, 2, 4], sigma=0.05, tikhonov_order=order)
    both = PWASVirtualSensor(**kw).fit(u, y, z)
    one = PWASVirtualSensor(**kw).fit(u, y, z[:, 0])
    two = PWASVirtualSensor(**kw).fit(u, y, z[:, 1])
    assert both.n_targets == 2 and both.weights_.shape == (both.grid_.n_vertices, 2)
    assert both.grid_ == one.grid_ == two.grid_
    np.testing.assert_allclose(both.weights_[:, 0], one.weights_[:, 0], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(both.weights_[:, 1], two.weights_[:, 0], rtol=1e-10, atol=1e-12)
    zhat = both.predict(u, y)
    np.testing.assert_allclose(zhat[:, 0], one.predict(u, y)[:, 0], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(zhat[:, 1], two.predict(u, y)[:, 0], rtol=1e-10, atol=1e-12)


def test_refit_replaces_previous_model(rng):
    y = rng.uniform(0.0, 1.0, 300)
    s = PWASVirtualSensor(my=1, partitions=3, sigma=1e-6).fit(None, y, y)
    s.my = 2
    s.fit(None, y, 2 * y)
    assert s.grid_.n == 2 and s.lags_.my == 2
    np.testing.assert_allclose(s.predict(None, y)[:, 0], 2 * y[1:], atol=1e-4)


# ------------------------------------------------------------------ scikit-learn estimator protocol
def test_sklearn_protocol_params_clone_score_repr(rng):
    from sklearn.base import clone

    t = np.arange(400)
    y = np.sin(0.05 * t)[:, None] + 0.01 * rng.normal(size=(400, 1))
    z = (y[:, 0] ** 2)[:, None]
    m = PWASVirtualSensor(my=2, partitions=4, sigma=1e-6, target_names=["z"])
    params = m.get_params()
    assert params["my"] == 2 and params["partitions"] == 4 and params["sigma"] == 1e-6 and params["mu"] == 0
    assert set(params) == {"mu", "my", "partitions", "gamma", "sigma", "tikhonov_order", "cv_folds", "sigma_grid",
                           "cv_shuffle", "domain", "share_lag_domain", "input_names", "output_names", "target_names",
                           "front_end", "mz", "refine", "initial_state", "additive", "breakpoints", "classify"}
    m.fit(None, y, z)
    c = clone(m)
    assert c is not m and not hasattr(c, "weights_") and not hasattr(c, "grid_")
    assert c.get_params() == m.get_params()
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError, match="not fitted"):
        c.predict(None, y)
    # set_params changes a hyper-parameter (and only that); the refit uses it
    assert c.set_params(partitions=2) is c and c.partitions == 2 and c.my == 2
    assert c.fit(None, y, z).grid_.n_vertices == 9 and m.grid_.n_vertices == 25
    # score is R^2 of the rows predict returns (as sklearn.metrics.r2_score)
    zhat = m.predict(None, y)
    zt = z[1:]
    r2 = 1 - np.sum((zt - zhat) ** 2) / np.sum((zt - zt.mean()) ** 2)
    assert m.score(None, y, z) == pytest.approx(r2, rel=1e-12)
    assert 0.9 < m.score(None, y, z) <= 1.0 and c.score(None, y, z) < m.score(None, y, z)
    assert m.score(None, y, -z) < 0
    # a readable repr: the class and the parameters that differ from their defaults
    assert repr(m) == "PWASVirtualSensor(my=2, partitions=4, sigma=1e-06, target_names=['z'])"
    with pytest.raises(ValueError, match="Invalid parameter"):
        m.set_params(nonsense=1)
