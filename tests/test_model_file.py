"""Model file (JSON, format pwas-hdl-model v1): bit-exact save / load round trip."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pwas_hdl.fit.virtual_sensor import MODEL_FORMAT, MODEL_VERSION, PWASVirtualSensor, load_model


def _fitted(nz: int, rng: np.random.Generator) -> tuple[PWASVirtualSensor, np.ndarray, np.ndarray]:
    t_len = 700
    u = rng.uniform(-1.0, 1.0, t_len)
    y = np.cumsum(rng.normal(0.0, 0.1, t_len))
    z = np.column_stack([np.sin(y) + u * u, u * y - 0.1 * y**3])[:, :nz]
    if nz == 1:
        # CV-chosen sigma, domain from the data, first-order penalty
        sensor = PWASVirtualSensor(mu=1, my=2, partitions=[3, 5, 2], sigma=None, tikhonov_order=1,
                                   sigma_grid=[1e-4, 1e-2, 1.0], cv_folds=3, gamma=1.3)
        sensor.fit(u, y, z)
    else:
        # explicit sigma and domain, named signals
        lo, hi = [-1.0, y.min() - 0.5, y.min() - 0.5], [1.0, y.max() + 0.5, y.max() + 0.5]
        sensor = PWASVirtualSensor(mu=1, my=2, partitions=[4, 3, 3], sigma=1.0 / 3.0, domain=(lo, hi),
                                   input_names=["valve"], output_names=["level"], target_names=["flow", "temp"])
        sensor.fit(u, y, z)
    return sensor, u, y


def _new_data(rng):
    u = rng.uniform(-2.0, 2.0, 300)  # partly outside the training domain
    y = np.cumsum(rng.normal(0.0, 0.2, 300))
    return u, y


@pytest.mark.parametrize("nz", [1, 2])
def test_save_load_round_trip_is_bit_exact(nz, tmp_path, rng):
    sensor, _, _ = _fitted(nz, rng)
    path = tmp_path / "model.json"
    assert sensor.save(path) == path
    loaded = PWASVirtualSensor.load(path)
    assert loaded.weights_.shape == sensor.weights_.shape == (sensor.grid_.n_vertices, nz)
    np.testing.assert_array_equal(loaded.weights_, sensor.weights_)
    assert loaded.weights_.tobytes() == sensor.weights_.tobytes()
    assert loaded.grid_.lo.tobytes() == sensor.grid_.lo.tobytes()
    assert loaded.grid_.hi.tobytes() == sensor.grid_.hi.tobytes()
    np.testing.assert_array_equal(loaded.grid_.partitions, sensor.grid_.partitions)
    assert loaded.grid_ == sensor.grid_
    assert loaded.sigma_ == sensor.sigma_ and type(loaded.sigma_) is float
    assert loaded.lags_ == sensor.lags_
    assert loaded.signal_names() == sensor.signal_names()
    if nz == 1:
        assert loaded.cv_ is not None
        np.testing.assert_array_equal(loaded.cv_.sigmas, sensor.cv_.sigmas)
        np.testing.assert_array_equal(loaded.cv_.mse, sensor.cv_.mse)
        assert loaded.cv_.best_sigma == sensor.cv_.best_sigma == sensor.sigma_
    else:
        assert loaded.cv_ is None and loaded.sigma_ == 1.0 / 3.0
        assert loaded.signal_names() == (["valve"], ["level"], ["flow", "temp"])
    # identical predictions (with out-of-domain flags) on new data
    u, y = _new_data(rng)
    z1, f1 = sensor.predict(u, y, return_flags=True)
    z2, f2 = loaded.predict(u, y, return_flags=True)
    assert f1.any()
    assert np.array_equal(z1, z2) and np.array_equal(f1, f2)
    # the file content survives a second round trip unchanged, byte for byte
    assert loaded.to_dict() == sensor.to_dict()
    path2 = tmp_path / "again.json"
    loaded.save(path2)
    assert path2.read_bytes() == path.read_bytes()
    assert load_model(path2).weights_.tobytes() == sensor.weights_.tobytes()


def test_model_file_layout(tmp_path, rng):
    sensor, _, _ = _fitted(2, rng)
    path = sensor.save(tmp_path / "m.json")
    d = json.loads(path.read_text(encoding="utf-8"))
    assert d["format"] == MODEL_FORMAT and d["version"] == MODEL_VERSION
    assert d["lags"] == {"Mu": 1, "My": 2}
    assert d["regressors"] == ["valve[t]", "level[t-1]", "level[t]"]
    assert d["grid"]["partitions"] == [4, 3, 3]
    assert list(d["weights"]) == ["flow", "temp"]
    assert all(len(v) == sensor.grid_.n_vertices for v in d["weights"].values())
    assert d["fit"]["sigma"] == 1.0 / 3.0 and d["fit"]["cv"] is None
    assert d["fit"]["domain_from"] == "explicit"
    # the floats in the file are the exact doubles (shortest round-trip repr)
    assert np.array(d["weights"]["temp"]).tobytes() == sensor.weights_[:, 1].tobytes()


def test_save_is_deterministic(tmp_path):
    a, _, _ = _fitted(1, np.random.default_rng(5))
    b, _, _ = _fitted(1, np.random.default_rng(5))
    pa, pb = a.save(tmp_path / "a.json"), b.save(tmp_path / "b.json")
    assert pa.read_bytes() == pb.read_bytes()


def test_loaded_model_refits_like_the_original(tmp_path, rng):
    """Hyper-parameters survive the file: a loaded model refitted on the same data gives the same weights."""
    sensor, u, y = _fitted(2, rng)
    loaded = load_model(sensor.save(tmp_path / "m.json"))
    z = np.column_stack([np.sin(y) + u * u, u * y - 0.1 * y**3])
    sensor.fit(u, y, z)
    loaded.fit(u, y, z)
    assert loaded.grid_ == sensor.grid_
    np.testing.assert_array_equal(loaded.weights_, sensor.weights_)
