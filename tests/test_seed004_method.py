"""Seed 004: plants, the observer-bank method step by step, learners' metrics, the EKF baseline."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from pwas_hdl.errors import InputError
from pwas_hdl.fit.observer_bank import (
    LPVARXModel, arx_regressors, bank_residuals, canonical_form, fit_lpv_arx, hat_basis, observer_gain,
    parse_observer, residual_features, select_models,
)
from pwas_hdl.systems.battery import BatteryEKF, BatteryModel, battery, make_battery_dataset
from pwas_hdl.systems.pv_benchmark import MODES, make_pv_dataset, pv_benchmark, switching4
from pwas_hdl.systems.pv_method import f1_per_mode, fit_ratio, min_distance_classify, nrmse


# ------------------------------------------------------------------------------------ plants
def test_pv_benchmark_is_seeded_and_rho_obeys_14c():
    a, b = pv_benchmark(3000, seed=4), pv_benchmark(3000, seed=4)
    assert np.array_equal(a.y, b.y) and np.array_equal(a.z, b.z)
    assert not np.array_equal(a.y, pv_benchmark(3000, seed=5).y)
    assert a.z[0, 0] == 0.0 and np.all(np.abs(a.z) <= 0.95)
    # the random walk moves slowly: |rho_{k+1} - 0.999 rho_k| is 0.03 |w| unless halved
    cos = pv_benchmark(3000, rho_law="cosine").z[:, 0]
    k = np.arange(2999)
    p = np.cos(k / 200.0)
    expect = np.where(np.abs(p) <= 0.95, p, p / 2)
    assert np.allclose(cos[1:], expect)


def test_pv_benchmark_output_equation():
    d = pv_benchmark(50, seed=1)
    # re-simulate eq. (14a) by hand for a few steps
    from pwas_hdl.systems.pv_benchmark import F, H

    x = np.zeros(5)
    for k in range(50):
        assert d.y[k, 0] == pytest.approx(-(1 + np.exp(d.z[k, 0])) * x[4], abs=1e-12)
        x = H @ x + 0.5 * np.arctan(x) + np.log(d.z[k, 0] + 1) * F @ d.u[k]


def test_switching4_modes_and_silent_first_mode():
    d = switching4(4000, seed=0)
    rho = d.z[:, 0]
    assert set(np.unique(rho)) == set(MODES)
    assert np.all(d.y[rho == 0.0] == 0.0)  # B = log(1) F = 0 and x0 = 0
    # rho_{k+1} = floor(4k/N)/2: rho_0 = 0 and k = 0..999 give 1001 samples of mode 1, k = 3000..3998 give 999 of mode 4
    assert np.count_nonzero(rho == 0.0) == 1001 and np.count_nonzero(rho == 1.5) == 999


def test_normalisation_uses_training_statistics_and_noise_after_it():
    tr, te, norm = make_pv_dataset("pv-benchmark", 4000, 1000, seed=3, noise=0.03)
    assert np.allclose(tr.z_true.mean(), 0.0, atol=1e-12) and np.allclose(tr.z_true.std(), 1.0)
    assert np.std(tr.z - tr.z_true) == pytest.approx(0.03, rel=0.1)
    raw = pv_benchmark(4000, seed=int(np.random.SeedSequence(3).spawn(3)[0].generate_state(1)[0]))
    assert np.allclose(norm.invert("z", tr.z_true), raw.z)
    _, te2, _ = make_pv_dataset("switching-4", 4000, 1000, seed=3)
    assert np.allclose(np.unique(te2.z), np.unique(te2.z_true))  # E2 labels are noise-free


def test_battery_matches_the_spec_reference_run():
    d = battery(2100, seed=0)  # seed_004.md C1: first reset at k = 2054
    soc = d.z[:, 0]
    assert np.flatnonzero(np.diff(soc) > 0.5)[0] == 2054
    assert 3.3 < d.y.min() < d.y.max() < 4.11
    assert np.all((d.u >= 0) & (d.u <= 0.8))


def test_battery_jacobians_are_exact():
    m = BatteryModel()
    rng = np.random.default_rng(0)
    for _ in range(5):
        x = np.array([rng.uniform(0.1, 1.0), rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05)])
        i = rng.uniform(0, 0.8)
        _, jac = m.rk4(x, i)
        _, grad = m.output(x, i)
        eps = 1e-6
        num = np.column_stack([(m.rk4(x + eps * e, i)[0] - m.rk4(x - eps * e, i)[0]) / (2 * eps) for e in np.eye(3)])
        ng = np.array([(m.output(x + eps * e, i)[0] - m.output(x - eps * e, i)[0]) / (2 * eps) for e in np.eye(3)])
        assert np.allclose(jac, num, rtol=1e-5, atol=1e-8)
        assert np.allclose(grad, ng, rtol=1e-5, atol=1e-7)


def test_battery_step_is_bitwise_rk4s_state():
    # the simulator's step (no Jacobians) does rk4's floating-point operations in rk4's order
    m = BatteryModel()
    rng = np.random.default_rng(1)
    for _ in range(200):
        x = np.array([rng.uniform(0.05, 1.0), rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1)])
        i, h = rng.uniform(-0.2, 0.8), rng.choice([5.0, 0.37])
        assert np.array_equal(m.step(x, i, h), m.rk4(x, i, h)[0])


def test_ekf_tracks_soc_from_noisy_voltage():
    tr, te, norm = make_battery_dataset(3000, 1500, seed=0)  # 1500 test samples: before the first reset
    cur = norm.invert("u", te.u)[:, 0]
    volt = norm.invert("y", te.y)[:, 0]
    soc = norm.invert("z", te.z_true)[:, 0]
    assert np.all(np.diff(soc) < 0)
    r = float((0.03 * norm.std["y"][0]) ** 2)
    est = BatteryEKF(q=(1e-8, 1e-6, 1e-6), r=r, x0=np.array([0.8, 0.0, 0.0])).run(cur, volt)[:, 0]
    rmse = np.sqrt(np.mean((est[200:] - soc[200:]) ** 2))
    assert rmse < 0.02
    assert np.sqrt(np.mean((soc[200:] - soc[200:].mean()) ** 2)) > 5 * rmse


# ----------------------------------------------------------------------------- local models
def _lpv_arx_data(gam_of_rho, order, t_len, rng):
    u = rng.normal(size=(t_len, 2))
    rho = np.clip(np.cumsum(rng.normal(0, 0.05, t_len)), -1, 1)
    y = np.zeros((t_len, 1))
    for k in range(order, t_len):
        phi = np.r_[-y[k - order : k, 0], u[k - order : k].reshape(-1), 1.0]
        y[k, 0] = phi @ gam_of_rho(rho[k])
    return u, y, rho


def test_arx_regressor_order_and_hat_basis():
    u = np.arange(20.0).reshape(10, 2)
    y = 100 + np.arange(10.0)[:, None]
    phi, tgt = arx_regressors(u, y, 2)
    assert np.array_equal(phi[0], [-100, -101, 0, 1, 2, 3, 1])  # [-y_{k-2}, -y_{k-1}, u_{k-2}, u_{k-1}, 1] at k = 2
    assert tgt[0] == 102
    b = hat_basis(np.array([-2.0, 0.0, 0.25, 1.0, 5.0]), np.array([0.0, 0.5, 1.0]))
    assert np.allclose(b.sum(axis=1), 1) and np.allclose(b[2], [0.5, 0.5, 0]) and np.allclose(b[4], [0, 0, 1])


def test_lad_recovers_a_pwl_in_rho_model_exactly():
    rng = np.random.default_rng(1)
    order, knots = 2, np.linspace(-1, 1, 3)
    coefs = rng.normal(0, 0.2, (3, 2 + 4 + 1))
    truth = LPVARXModel(knots, coefs, order, 2, 0.0)
    u, y, rho = _lpv_arx_data(lambda r: truth.gamma(np.array([r]))[0], order, 3000, rng)
    rho[:2] = [-1, 1]  # make the knot span exactly [-1, 1]
    m = fit_lpv_arx([u], [y], [rho], order, n_knots=3, max_rows=None)
    assert np.allclose(m.knots, knots)
    assert np.allclose(m.coefs, coefs, atol=1e-6)
    assert m.mae < 1e-6


def test_select_models_finds_clusters_of_rho():
    rho = np.repeat([-1.0, 0.0, 2.0], 100)
    gam = np.column_stack([rho * 3, -rho])
    models, leaf_rho = select_models(rho, gam, 3)
    assert np.allclose(leaf_rho, [-1, 0, 2]) and np.allclose(models, [[-3, 1], [0, 0], [6, -2]])
    assert select_models(rho, gam, 2)[0].shape == (2, 2)


# ----------------------------------------------------------------------------- observers
def test_canonical_form_realises_the_arx_and_deadbeat_residual_is_its_error():
    rng = np.random.default_rng(2)
    order = 3
    g = np.r_[0.1, -0.2, 0.3, rng.normal(size=2 * order), 0.05]
    u, y, _ = _lpv_arx_data(lambda r: g, order, 400, rng)
    res = bank_residuals(g[None], observer_gain(*canonical_form(g, order, 2)[::2], "deadbeat")[None], order, u, y)
    assert np.max(np.abs(res[order:])) < 1e-9  # exact after M steps
    a_mat, b_mat, c_mat, d = canonical_form(g, order, 2)
    assert np.allclose(np.poly(a_mat)[1:], g[:order][::-1])  # char. poly z^M + a1 z^{M-1} + ..
    y_other = y + 0.5 * np.sin(np.arange(400))[:, None]
    res2 = bank_residuals(g[None], np.zeros((1, order)), order, u, y_other)
    assert np.max(np.abs(res2[order:])) > 0.1


@pytest.mark.parametrize("obs", ["deadbeat", "poles:0.4", "poles:0.8", "kalman:1", "kalman:0.1"])
def test_observer_gains(obs):
    g = np.r_[0.1, -0.2, 0.3, -0.9, np.ones(8), 0.0]
    order = 4
    a_mat, _, c_mat, _ = canonical_form(g, order, 2)
    kind, par = parse_observer(obs)
    l_gain = observer_gain(a_mat, c_mat, kind, par)
    acl = a_mat - np.outer(l_gain, c_mat[0])
    eig = np.linalg.eigvals(acl)
    if kind == "deadbeat":
        assert np.allclose(np.linalg.matrix_power(acl, order), 0, atol=1e-12)
    elif kind == "poles":
        assert np.allclose(np.poly(acl), np.poly(np.full(order, par)), atol=1e-12)
    else:
        p = scipy.linalg.solve_discrete_are(a_mat.T, c_mat.T, np.eye(order), par * np.eye(1))
        assert np.allclose(l_gain, (a_mat @ p @ c_mat.T / (c_mat @ p @ c_mat.T + par)).ravel())
        assert np.max(np.abs(eig)) < 1


import scipy.linalg  # noqa: E402


@pytest.mark.parametrize("bad", ["poles", "poles:1", "kalman:0", "kalman:x", "luenberger", "deadbeat:1"])
def test_parse_observer_refuses(bad):
    with pytest.raises(InputError, match=r"--observer \(observer\) must be deadbeat, poles:R"):
        parse_observer(bad)


def test_feature_maps_11a_11b_match_their_definitions():
    rng = np.random.default_rng(3)
    res = rng.normal(size=(30, 2))
    l = 4
    f11b = residual_features(res, l, "11b")
    f11a = residual_features(res, l, "11a")
    assert f11b.shape == (26, 2) and f11a.shape == (26, 10)
    for i in (0, 7, 25):
        k = l + i
        for j in range(2):
            assert f11b[i, j] == pytest.approx(np.sqrt(np.sum(res[k - l : k + 1, j] ** 2) / l))
            assert np.array_equal(f11a[i, j * (l + 1) : (j + 1) * (l + 1)], res[k - l : k + 1, j][::-1])


# ----------------------------------------------------------------------------------- metrics
def test_metrics():
    t = np.sin(np.arange(100) / 5)
    assert fit_ratio(t, t) == 1 and nrmse(t, t) == 1
    assert fit_ratio(t, np.full_like(t, t.mean())) == pytest.approx(0)
    assert fit_ratio(t, -3 * t) == 0  # clipped at 0
    e = t + 0.1
    assert nrmse(t, e) == pytest.approx(1 - 0.1 / (t.max() - t.min()))
    idx = min_distance_classify(np.array([-0.1, 0.3, 0.26, 0.74, 9]), MODES)
    assert list(idx) == [0, 1, 1, 1, 3]
    f1 = f1_per_mode(np.array([0, 0, 1, 1]), np.array([0, 1, 1, 1]), 3)
    assert np.allclose(f1, [2 / 3, 0.8, 0.0])
    with pytest.raises(InputError):
        fit_ratio(t, t[:-1])
