"""HLNN baseline (seed 000, A7): one tanh hidden layer on the PWAS regressor, size by validation."""

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
    with pytest.raises(InputError):
        HLNNSensor(hidden_sizes=())
    with pytest.raises(InputError):
        HLNNSensor(val_fraction=1.5)
    with pytest.raises(RuntimeError, match="not fitted"):
        HLNNSensor(my=1).predict(None, np.zeros((5, 1)))
    with pytest.raises(InputError, match="too few"):
        HLNNSensor(my=1).fit(None, np.zeros((2, 1)), np.zeros((2, 1)))
