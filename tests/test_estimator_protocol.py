"""The scikit-learn estimator protocol of the estimators beyond PWASVirtualSensor's own basics
(tests/test_fit.py): the nested observer-bank front end, refits, parameter validation in fit."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.base import clone

from pwas_hdl.errors import InputError
from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor


def test_observer_bank_front_end_is_a_nested_estimator():
    """get_params(deep=True) lists the front end's parameters, set_params reaches them, clone works on
    the front end alone and gives the sensor a fresh unfitted one, the repr shows its parameters
    (it was a plain object: no front_end__* parameters, set_params(front_end__n_models=..) failed,
    clone(front_end) raised TypeError and the repr was '<... object at 0x..>')."""
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    fe = ObserverBankFrontEnd(n_models=3, window=3)
    m = PWASVirtualSensor(my=0, partitions=2, sigma=0.1, front_end=fe)
    deep = m.get_params(deep=True)
    assert deep["front_end"] is fe and deep["front_end__n_models"] == 3 and deep["front_end__window"] == 3
    assert {k for k in deep if k.startswith("front_end__")} == {f"front_end__{k}" for k in fe.get_params()}
    assert "ObserverBankFrontEnd(n_models=3, window=3)" in repr(m)
    assert m.set_params(front_end__n_models=2) is m and fe.n_models == 2
    c = clone(fe)
    assert type(c) is ObserverBankFrontEnd and c is not fe and c.get_params() == fe.get_params()

    tr, _, _ = make_pv_dataset("pv-benchmark", 1200, 10, seed=2)
    m.fit(tr.u, tr.y, tr.z)
    assert m.front_end_.n_models_ == 2 and not hasattr(fe, "models_")  # fitted on a copy
    c = clone(m)
    assert c.front_end is not m.front_end and not hasattr(c.front_end, "models_")
    assert c.get_params(deep=True) == {**m.get_params(deep=True), "front_end": c.front_end}
    np.testing.assert_array_equal(c.fit(tr.u, tr.y, tr.z).weights_, m.weights_)


def test_refit_forgets_the_fitted_attributes_of_the_previous_model(tmp_path):
    """A refit replaces the whole fitted state: attributes a previous fit or a loaded file set and this
    fit does not (a recurrent sensor's recurrence_fit_ / initial_state_rule_ / initial_values_, a
    classifier's classifier_) are removed, so the model file of the refit describes the refit (they
    stayed: a classifier refitted on one regression target wrote a classifier block with its old
    classes, a file that load() refused)."""
    rng = np.random.default_rng(5)
    u = rng.normal(size=(400, 1))
    y = np.cumsum(0.1 * u, axis=0)
    z = np.sin(y) + 0.1 * u
    m = PWASVirtualSensor(mu=1, my=1, mz=1, partitions=3, sigma=1e-3).fit(u, y, z)
    assert hasattr(m, "recurrence_fit_")
    fresh = PWASVirtualSensor(mu=1, my=1, partitions=3, sigma=1e-3).fit(u, y, z)
    m.set_params(mz=0).fit(u, y, z)
    assert sorted(k for k in vars(m) if k.endswith("_")) == sorted(k for k in vars(fresh) if k.endswith("_"))
    np.testing.assert_array_equal(m.weights_, fresh.weights_)

    labels = (z[:, 0] > 0).astype(float)
    clf = PWASVirtualSensor(mu=1, my=1, partitions=3, sigma=1e-3, target_names=["c"], classify=True).fit(u, y, labels)
    loaded = PWASVirtualSensor.load(clf.save(tmp_path / "clf.json"))
    assert loaded.classifier_["classes"] == [0.0, 1.0] and loaded.classify
    loaded.set_params(classify=False, target_names=["z"]).fit(u, y, z)
    assert not hasattr(loaded, "classifier_") and "classifier" not in loaded.to_dict()
    np.testing.assert_array_equal(PWASVirtualSensor.load(loaded.save(tmp_path / "z.json")).weights_, fresh.weights_)


@pytest.mark.parametrize("params, data, match", [
    (dict(my=1.5), None, "my must be a non-negative integer"),        # was truncated to 1 silently
    (dict(mu=True, my=1), None, "mu must be a non-negative integer"),
    (dict(gamma=0.5), None, r"--gamma \(gamma\) must be a number >= 1"),
    (dict(tikhonov_order=2), None, r"--tikhonov \(tikhonov_order\) must be 0"),
    (dict(share_lag_domain="no"), None, "share_lag_domain must be True or False, got 'no'"),  # "no" read as True
    (dict(cv_shuffle=1), None, "cv_shuffle must be True or False, got 1"),
    (dict(), dict(z=None), r"z \(the measured targets"),             # was 'got 0 target trajectories for 1 ...'
    (dict(), dict(y="complex"), "is complex"),                       # the imaginary part was dropped with a warning
    (dict(), dict(y="sparse"), "sparse matrix"),                     # was 'setting an array element with a sequence'
    (dict(), dict(y="text"), "not an array of numbers"),
    (dict(output_names=["a", "b"]), None, r"2 output names \['a', 'b'\] for 1 output column"),
    (dict(mu=1, input_names=["a"]), dict(u=np.zeros((200, 2))), "1 input names"),
])
def test_fit_refuses_bad_parameters_and_signals_with_input_error(params, data, match):
    """Each is an InputError (a ValueError) that names the problem; the wrong number of signal names was
    accepted and written to a model file that load() refused ('grid.lo has 1 values, the lags give n = 2')."""
    import scipy.sparse

    from pwas_hdl.errors import InputError

    rng = np.random.default_rng(1)
    y = rng.normal(size=(200, 1))
    sig = dict(u=None, y=y, z=y**2)
    for key, val in (data or {}).items():
        sig[key] = {"complex": y + 1j, "sparse": scipy.sparse.csr_matrix(y), "text": np.full((200, 1), "a")}.get(val, val) \
            if isinstance(val, str) else val
    m = PWASVirtualSensor(**{"partitions": 2, "sigma": 1e-3, **params})
    with pytest.raises(InputError, match=match):
        m.fit(sig["u"], sig["y"], sig["z"])
    assert not hasattr(m, "weights_")


def test_design_functions_refuse_an_unfitted_sensor_with_not_fitted_error(tmp_path):
    """fixed_point_model / build_design / generate of an unfitted sensor raised AttributeError
    ('no attribute grid_' / 'lags_'); now sklearn's NotFittedError, as predict does, and nothing is written."""
    from sklearn.exceptions import NotFittedError

    from pwas_hdl import build_design, fixed_point_model, generate

    for call in (lambda: fixed_point_model(PWASVirtualSensor()), lambda: build_design(PWASVirtualSensor()),
                 lambda: build_design(PWASVirtualSensor(), design="sensor"),
                 lambda: generate(PWASVirtualSensor(), tmp_path / "hw")):
        with pytest.raises(NotFittedError, match="not fitted"):
            call()
    assert not (tmp_path / "hw").exists()


@pytest.mark.parametrize("initial", [[1.0, 2.0, 3.0], [np.nan]])
def test_recurrent_fixed_point_model_refuses_bad_initial_values(initial):
    """The wrong number of initial values said 'cannot reshape array of size 3 into shape (1,1)', a NaN
    'input values contain NaN; cannot quantize'; now an InputError naming Mz x nz."""
    from pwas_hdl.errors import InputError
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel
    from pwas_hdl.fixedpoint.recurrence import RecurrentFixedPointModel

    rng = np.random.default_rng(0)
    u = rng.normal(size=(400, 1))
    y = np.cumsum(0.1 * u, axis=0)
    rec = PWASVirtualSensor(mu=1, my=1, mz=1, partitions=3, sigma=1e-3).fit(u, y, np.sin(y))
    fxm = FixedPointModel.from_sensor(rec)
    assert RecurrentFixedPointModel(fxm, rec.lags_, rec.initial_values_).initial_codes.shape == (1, 1)
    with pytest.raises(InputError, match="Mz x nz = 1 x 1"):
        RecurrentFixedPointModel(fxm, rec.lags_, initial)


def test_loaded_model_keeps_the_cross_validation_settings(tmp_path):
    """load() restores cv_folds, sigma_grid and cv_shuffle from the model file's fit.cv block (they came back as the
    defaults 5 and None, so clone(loaded).fit(...) cross-validated differently from the original fit)."""
    rng = np.random.default_rng(2)
    u = rng.normal(size=(400, 1))
    y = np.cumsum(0.1 * u, axis=0)
    z = np.sin(3 * y) + 0.05 * rng.normal(size=(400, 1))
    for kw in (dict(cv_folds=3, sigma_grid=[1e-4, 1e-2, 1.0]), dict(), dict(cv_shuffle=True, cv_folds=4)):
        m = PWASVirtualSensor(mu=1, my=1, partitions=4, **kw).fit(u, y, z)
        loaded = PWASVirtualSensor.load(m.save(tmp_path / "m.json"))
        assert loaded.cv_folds == m.cv_folds and loaded.sigma_grid == m.sigma_grid
        assert loaded.cv_shuffle == m.cv_shuffle and loaded.cv_.shuffle == m.cv_shuffle
        assert ("shuffle" in m.to_dict()["fit"]["cv"]) == m.cv_shuffle  # written only for shuffled folds
        refit = clone(loaded).fit(u, y, z)
        assert refit.cv_.folds == m.cv_.folds and np.array_equal(refit.cv_.sigmas, m.cv_.sigmas)
        np.testing.assert_array_equal(refit.weights_, m.weights_)


def test_a_list_of_lists_is_refused_as_ambiguous():
    """(T, 2).tolist() was read as T trajectories of two samples and one channel, and the fit succeeded
    with nz = ny = 1; a list of lists is now refused (arrays say which is meant)."""
    rng = np.random.default_rng(0)
    y2, z2 = rng.normal(size=(300, 2)), rng.normal(size=(300, 2))
    with pytest.raises(InputError, match="y is a list of lists"):
        PWASVirtualSensor(my=1, partitions=3, sigma=1e-3).fit(None, y2.tolist(), z2)
    m = PWASVirtualSensor(my=1, partitions=3, sigma=1e-3).fit(None, y2, z2)  # the array: one trajectory, 2 channels
    assert m.to_dict()["signals"]["targets"] == ["z0", "z1"] and m.ny_ == 2
    two = PWASVirtualSensor(my=1, partitions=3, sigma=1e-3).fit(None, [y2[:150], y2[150:]], [z2[:150], z2[150:]])
    assert two.n_trajectories_ == 2
    one = PWASVirtualSensor(my=1, partitions=3, sigma=1e-3).fit(None, list(y2[:, 0]), z2[:, :1])  # a list of numbers
    assert one.n_trajectories_ == 1
