"""HLNN baseline (seed 000, A7): one tanh hidden layer on the PWAS regressor, size by validation."""

import warnings

import numpy as np
import pytest

from pwas_hdl.errors import InputError
from pwas_hdl.fit.regressors import LagStructure
from pwas_hdl.systems.hlnn import HLNNSensor


def _data(rng, T=1500):
    u = rng.uniform(-1, 1, (T, 1))
    y = np.zeros((T, 1))
    for t in range(1, T):
        y[t] = 0.6 * y[t - 1] + np.tanh(2 * u[t - 1])
    z = np.sin(2 * y) + 0.5 * u  # a smooth function of the current regressor
    return u, y, z


@pytest.mark.slow
def test_hlnn_fits_a_smooth_map_and_picks_a_size(rng):
    u, y, z = _data(rng)
    h = HLNNSensor(mu=1, my=1, hidden_sizes=(1, 8), restarts=1, max_iter=300, seed=0).fit(u[:1000], y[:1000], z[:1000])
    assert set(h.val_rmse_) == {1, 8} and h.hidden_ == min(h.val_rmse_, key=h.val_rmse_.get)
    assert h.val_rmse_[8] < h.val_rmse_[1]          # one tanh unit cannot bend sin(2y) enough
    zh = h.predict(u[1000:], y[1000:])
    assert zh.shape == (500, 1)                     # M = 1: every sample has a regressor
    assert np.sqrt(np.mean((zh - z[1000:]) ** 2)) < 0.1 * np.std(z)
    assert h.lags_ == LagStructure(1, 1, 1, 1)


def test_hlnn_refuses_bad_parameters_and_unfitted_use(rng):
    from sklearn.exceptions import NotFittedError

    y = rng.normal(size=(50, 1))
    for bad in (dict(hidden_sizes=()), dict(val_fraction=1.5), dict(restarts=0), dict(my=1.5), dict(hidden_sizes=(2, 0))):
        m = HLNNSensor(**bad)  # stored unchanged; refused by fit (the scikit-learn convention)
        assert all(m.get_params()[k] == v for k, v in bad.items())
        with pytest.raises(InputError):
            m.fit(None, y, y)
        assert not hasattr(m, "model_")
    with pytest.raises(NotFittedError, match="not fitted"):
        HLNNSensor(my=1).predict(None, np.zeros((5, 1)))
    with pytest.raises(InputError, match="too few"):
        HLNNSensor(my=1).fit(None, np.zeros((2, 1)), np.zeros((2, 1)))


def test_hlnn_is_a_scikit_learn_estimator(rng):
    """get_params / set_params / clone, parameters stored unchanged, the same fit twice (it had no
    get_params, so clone raised TypeError, and __init__ converted and validated its arguments)."""
    from sklearn.base import clone

    u, y, z = _data(rng, T=300)
    h = HLNNSensor(mu=1, my=1, hidden_sizes=[1, 2], restarts=1, max_iter=50, seed=3)
    assert h.get_params()["hidden_sizes"] == [1, 2] and h.get_params()["seed"] == 3
    assert repr(h) == "HLNNSensor(hidden_sizes=[1, 2], max_iter=50, mu=1, restarts=1, seed=3)"
    c = clone(h).set_params(seed=3)
    assert c is not h and c.get_params() == h.get_params()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        h.fit(u, y, z)
        c.fit(u, y, z)
    assert c.hidden_ == h.hidden_ and c.val_rmse_ == h.val_rmse_
    np.testing.assert_array_equal(c.predict(u, y), h.predict(u, y))
    assert not hasattr(clone(h), "model_")
