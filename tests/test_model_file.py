"""Model file (JSON, format pwas-hdl-model v2, pwas_hdl.fit.model_file): bit-exact round trip, schema, clear errors."""

from __future__ import annotations

import copy
import json

import jsonschema
import numpy as np
import pytest

from pwas_hdl.errors import InputError
from pwas_hdl.fit import model_file
from pwas_hdl.fit.model_file import MODEL_FORMAT, MODEL_SCHEMA_ID, MODEL_VERSION, model_errors, validate_model
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor, load_model
from pwas_hdl.io.json_contract import load_schema
from pwas_hdl.resources import schemas_dir


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


def test_loaded_model_keeps_the_cv_and_domain_settings(tmp_path, rng):
    """The settings the file records (shuffled CV folds, per-lag domains, the sigma grid) come back as
    the loaded estimator's parameters, so a refit of the loaded model cross-validates and boxes the
    data as the original did (the other round-trip tests use an explicit sigma and domain)."""
    t_len = 400
    u = rng.uniform(-1.0, 1.0, t_len)
    y = np.cumsum(rng.normal(0.0, 0.1, t_len))
    z = np.sin(y) + u * u + rng.normal(0.0, 0.05, t_len)
    sensor = PWASVirtualSensor(mu=1, my=2, partitions=[3, 3, 3], sigma=None, sigma_grid=[1e-3, 1e-1, 10.0], cv_folds=4,
                               cv_shuffle=True, share_lag_domain=False, gamma=1.1)
    sensor.fit(u, y, z)
    loaded = load_model(sensor.save(tmp_path / "m.json"))
    keys = ("mu", "my", "partitions", "gamma", "sigma", "tikhonov_order", "share_lag_domain", "cv_folds", "cv_shuffle",
            "sigma_grid")
    params, back = sensor.get_params(), loaded.get_params()
    assert {k: back[k] for k in keys} == {k: params[k] for k in keys}
    sensor.fit(u, y, z)
    loaded.fit(u, y, z)
    assert loaded.grid_ == sensor.grid_
    np.testing.assert_array_equal(loaded.cv_.mse, sensor.cv_.mse)
    np.testing.assert_array_equal(loaded.weights_, sensor.weights_)


# ------------------------------------------------------------------------ schema
@pytest.fixture
def good(rng) -> dict:
    return _fitted(2, rng)[0].to_dict()


def test_shipped_schema_is_draft_2020_12_and_the_written_file_validates(good, tmp_path):
    schema = json.loads((schemas_dir() / "model-v2.schema.json").read_text(encoding="utf-8"))
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["$id"] == MODEL_SCHEMA_ID == good["$schema"]
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.Draft202012Validator(schema).validate(good)  # the library itself, not only our wrapper
    assert good["format"] == MODEL_FORMAT and good["version"] == MODEL_VERSION == 2
    assert model_errors(good) == []
    assert load_schema("model-v2.schema.json") == schema


def _set(d: dict, path: tuple, value) -> dict:
    d = copy.deepcopy(d)
    node = d
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return d


@pytest.mark.parametrize(
    "path, value, message",
    [
        (("lags", "My"), 2.7, "lags.My must be an integer, got 2.7"),
        (("lags", "My"), "2", 'lags.My must be an integer, got "2"'),
        (("lags", "Mu"), -1, "lags.Mu must be >= 0, got -1"),
        (("lags", "Mu"), True, "lags.Mu must be an integer, got true"),
        (("grid", "partitions"), [4, 3, 2.5], r"grid.partitions[2] must be an integer, got 2.5"),
        (("grid", "lo"), [0.0, "a", 1.0], 'grid.lo[1] must be a number, got "a"'),
        (("fit", "tikhonov_order"), 2, "fit.tikhonov_order must be one of 0, 1, got 2"),
        (("fit", "gamma"), 0.5, "fit.gamma must be >= 1, got 0.5"),
        (("fit", "sigma"), 0, "fit.sigma must be > 0, got 0"),
        (("fit", "domain_from"), "file", 'fit.domain_from must be one of "data", "explicit", got "file"'),
        (("fit", "cv"), [], "fit.cv must be an object or null, got []"),
        (("signals", "targets"), [], "signals.targets must have at least 1 item, got 0"),
        (("signals", "inputs"), ["valve", "valve"], "signals.inputs has repeated items"),
        (("weights", "flow"), [1.0, None], "weights.flow[1] must be a number, got null"),
        (("weights", "flow"), [1.0, 2, True], "weights.flow[2] must be a number, got true"),
        (("weights", "flow"), [], "weights.flow must have at least 1 item, got 0"),
        (("weights", "flow"), 1.0, "weights.flow must be a list, got 1.0"),
        (("fit", "colour"), "red", "fit has the unknown key 'colour'"),
        (("extra",), 1, "the top level has the unknown key 'extra'"),
        (("$schema",), "urn:pwas-hdl:schema:model-v1", '$schema must be "urn:pwas-hdl:schema:model-v2"'),
    ],
)
def test_broken_file_one_message_naming_the_key(good, tmp_path, path, value, message):
    bad = _set(good, path, value)
    f = tmp_path / "model.json"
    f.write_text(json.dumps(bad))
    with pytest.raises(InputError) as ei:
        PWASVirtualSensor.load(f)
    msg = str(ei.value)
    assert msg.startswith(f"{f}: {message}"), msg
    assert "re-run `pwas-hdl fit`" in msg and "\n" not in msg
    assert not list(tmp_path.glob(".*"))  # reading leaves nothing behind
    with pytest.raises(InputError, match="in memory"):
        validate_model(bad, source="in memory")


def test_schema_sees_one_weight_of_an_all_number_list(good):
    """The weight lists are checked for numbers in one pass; the schema validator gets their first
    items only (its cost no longer grows with N), and whole lists when one holds a non-number."""
    from pwas_hdl.fit.model_file import _schema_view

    view = _schema_view(good)
    assert {k: v for k, v in view.items() if k != "weights"} == {k: v for k, v in good.items() if k != "weights"}
    assert view["weights"] == {k: v[:1] for k, v in good["weights"].items()}
    bad = _set(good, ("weights", "flow"), [*good["weights"]["flow"][:-1], "x"])
    assert _schema_view(bad) is bad


def test_missing_schema_key_is_named(good, tmp_path):
    del good["$schema"]
    with pytest.raises(InputError, match=r"^m: \$schema is missing"):
        validate_model(good, "m")


def test_consistency_beyond_the_schema(good):
    cases = [
        (_set(good, ("regressors",), ["a", "b", "c"]), "regressors ['a', 'b', 'c'] do not match the lags"),
        (_set(good, ("grid", "hi"), good["grid"]["hi"][:2]), "grid.hi has 2 values, the lags give n = 3 regressors"),
        (_set(good, ("fit", "train_rmse"), {"flow": 1.0}), "fit.train_rmse has the keys ['flow'], signals.targets are ['flow', 'temp']"),
        (_set(good, ("lags", "Mu"), 0) | {"signals": {**good["signals"], "inputs": []}}, "grid.lo has 3 values, the lags give n = 2"),
        (_set(good, ("signals", "outputs"), []), "lags.My is 2 but signals.outputs is empty"),
    ]
    for d, message in cases:
        with pytest.raises(InputError) as ei:
            validate_model(d, "m.json")
        assert message in str(ei.value), (message, str(ei.value))


def test_version_1_file_is_refused_with_the_fix(good, tmp_path):
    old = {k: v for k, v in good.items() if k != "$schema"} | {"version": 1}
    f = tmp_path / "old.json"
    f.write_text(json.dumps(old))
    with pytest.raises(InputError, match=r"pwas-hdl-model version 1 is not supported \(this pwas-hdl reads version 2\); "
                                         r"re-run `pwas-hdl fit`"):
        PWASVirtualSensor.load(f)


def test_cli_names_the_bad_key(good, tmp_path, capsys):
    from pwas_hdl.cli import main

    f = tmp_path / "model.json"
    f.write_text(json.dumps(_set(good, ("lags", "My"), 2.7)))
    assert main(["info", str(f)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {f}: lags.My must be an integer, got 2.7; re-run `pwas-hdl fit` to write the model file again"]


def test_model_file_module_is_the_only_writer(tmp_path, rng):
    """save() and model_file.write_model() write the same bytes; the sensor keeps no format code of its own."""
    sensor = _fitted(1, rng)[0]
    a = sensor.save(tmp_path / "a.json")
    b = model_file.write_model(sensor, tmp_path / "b.json")
    assert a.read_bytes() == b.read_bytes() == model_file.model_text(sensor).encode()
    import inspect

    from pwas_hdl.fit import virtual_sensor

    src = inspect.getsource(virtual_sensor)
    assert '"pwas-hdl-model"' not in src and "json.dumps" not in src
