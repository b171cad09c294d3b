"""Bad input: a ValueError with a message that says what is wrong, and no file written."""

from __future__ import annotations

import copy
import json
import os
import re

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from pwas_hdl.errors import InputError
from pwas_hdl.io.csv_table import read_csv, write_csv
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.regressors import LagStructure
from pwas_hdl.fit.regularized_lsq import cross_validate_sigma, solve_regularized, tikhonov_matrix
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor


def _files(folder) -> list[str]:
    """Every entry in the folder, hidden temporary files included."""
    return sorted(os.listdir(folder))


def _write(path, text: str):
    path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture
def good_data(rng):
    t_len = 200
    u = rng.uniform(-1.0, 1.0, t_len)
    y = rng.uniform(0.0, 2.0, t_len)
    z = y * u + y
    return u, y, z


# ----------------------------------------------------------------------- CSV
def test_csv_unknown_column(tmp_path):
    table = read_csv(_write(tmp_path / "d.csv", "u,y,z\n1,2,3\n4,5,6\n"))
    with pytest.raises(ValueError, match=r"no column named 'zz'; the file has columns u, y, z"):
        table.numeric(["y", "zz"])
    with pytest.raises(ValueError, match="no column named 'traj'"):
        table.text("traj")


@pytest.mark.parametrize("cell", ["nan", "NaN", "inf", "-inf", "Infinity"])
def test_csv_nan_or_inf_cell(cell, tmp_path):
    table = read_csv(_write(tmp_path / "d.csv", f"u,y\n1,2\n3,{cell}\n5,6\n"))
    np.testing.assert_array_equal(table.numeric(["u"]), [[1.0], [3.0], [5.0]])  # the other column is fine
    with pytest.raises(ValueError, match=r"line 3, column 'y' is .*NaN/inf"):
        table.numeric(["u", "y"])


@pytest.mark.parametrize("cell", ["", "abc", "1,5"])
def test_csv_cell_not_a_number(cell, tmp_path):
    text = f'u,y\n1,2\n3,"{cell}"\n'
    table = read_csv(_write(tmp_path / "d.csv", text))
    want = r"line 3, column 'y' is empty \(a missing sample\)" if cell == "" else r"line 3, column 'y': .* is not a number"
    with pytest.raises(ValueError, match=want):
        table.numeric(["y"])


def test_csv_ragged_rows(tmp_path):
    with pytest.raises(ValueError, match="line 3 has 2 cells but the header has 3 columns"):
        read_csv(_write(tmp_path / "d.csv", "u,y,z\n1,2,3\n4,5\n"))
    with pytest.raises(ValueError, match="line 2 has 4 cells but the header has 3 columns"):
        read_csv(_write(tmp_path / "e.csv", "u,y,z\n1,2,3,4\n"))


def test_csv_empty_file_and_header_only(tmp_path):
    with pytest.raises(ValueError, match="the file is empty"):
        read_csv(_write(tmp_path / "empty.csv", ""))
    with pytest.raises(ValueError, match="header but no data rows"):
        read_csv(_write(tmp_path / "header.csv", "u,y,z\n"))
    with pytest.raises(ValueError, match="header but no data rows"):
        read_csv(_write(tmp_path / "blank.csv", "u,y,z\n\n , , \n"))


def test_csv_bad_header(tmp_path):
    with pytest.raises(ValueError, match="duplicate column name"):
        read_csv(_write(tmp_path / "dup.csv", "u,y,u\n1,2,3\n"))
    with pytest.raises(ValueError, match="empty column name"):
        read_csv(_write(tmp_path / "emptyname.csv", "u,,z\n1,2,3\n"))


def test_csv_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_csv(tmp_path / "nope.csv")


def test_write_csv_unequal_columns_writes_nothing(tmp_path):
    with pytest.raises(ValueError, match="columns have different lengths"):
        write_csv(tmp_path / "out.csv", {"a": np.arange(3.0), "b": np.arange(4.0)})
    assert _files(tmp_path) == []
    # an existing file is left as it was
    keep = _write(tmp_path / "out.csv", "old\n")
    with pytest.raises(ValueError, match="different lengths"):
        write_csv(keep, {"a": [1.0], "b": [1.0, 2.0]})
    assert keep.read_text(encoding="utf-8") == "old\n"
    assert _files(tmp_path) == ["out.csv"]


def test_write_csv_round_trip(tmp_path):
    """Counterpart of the failure above: equal columns are written and read back exactly."""
    a = np.array([0.1, 1.0 / 3.0, -2.5e-300])
    path = write_csv(tmp_path / "ok.csv", {"a": a, "n": np.array([1, 2, 3])})
    back = read_csv(path).numeric(["a", "n"])
    assert back[:, 0].tobytes() == a.tobytes()
    np.testing.assert_array_equal(back[:, 1], [1, 2, 3])


# ------------------------------------------------------------ arrays / fit
@pytest.mark.parametrize("which", ["u", "y", "z"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_or_inf_in_arrays(which, bad, good_data):
    u, y, z = (a.copy() for a in good_data)
    {"u": u, "y": y, "z": z}[which][17] = bad
    with pytest.raises(ValueError, match=rf"{which} trajectory 0 has a NaN or infinite value at sample 17"):
        PWASVirtualSensor(mu=1, my=1, partitions=2, sigma=1.0).fit(u, y, z)


def test_nan_points_in_evaluate():
    grid = Grid([0.0, 0.0], [1.0, 1.0], 2)
    with pytest.raises(ValueError, match="NaN or infinite"):
        grid.evaluate(np.zeros(grid.n_vertices), [[0.5, np.nan]])
    with pytest.raises(ValueError, match="points have 3 coordinates but the grid has n = 2"):
        grid.locate(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="weights have 5 rows but the grid has N = 9"):
        grid.evaluate(np.zeros(5), [[0.5, 0.5]])


def test_constant_signal_zero_width_domain(good_data):
    u, y, z = good_data
    with pytest.raises(ValueError, match=r"regressor\(s\) u0\[t\] are constant .*zero-width domain"):
        PWASVirtualSensor(mu=1, my=1, partitions=2, sigma=1.0).fit(np.full_like(u, 3.0), y, z)
    with pytest.raises(ValueError, match="domain dimension 1 has zero or negative width"):
        Grid([0.0, 1.0], [1.0, 1.0], 2)
    with pytest.raises(ValueError, match=r"--domain \(domain\): the interval of regressor u0\[t\] is 1\.0:0\.5, empty"):
        PWASVirtualSensor(mu=1, my=1, partitions=2, sigma=1.0, domain=([1.0, 0.0], [0.5, 2.0])).fit(u, y, z)


def test_fewer_samples_than_the_lags_need():
    y = np.array([0.1, 0.7])
    with pytest.raises(ValueError, match=r"2 samples but the lags need at least M = max\(Mu, My\) = 3"):
        PWASVirtualSensor(my=3, partitions=2, sigma=1.0).fit(None, y, y)
    # in a second trajectory too
    long = np.linspace(0.0, 1.0, 50)
    with pytest.raises(ValueError, match="lags need at least"):
        PWASVirtualSensor(my=3, partitions=2, sigma=1.0).fit(None, [long, y], [long, y])


def test_mismatched_lengths_and_trajectory_counts(good_data):
    u, y, z = good_data
    with pytest.raises(ValueError, match="different lengths"):
        PWASVirtualSensor(mu=1, my=1, sigma=1.0).fit(u[:-1], y, z)
    with pytest.raises(ValueError, match="target trajectory 0 has 150 samples but its inputs/outputs have 200"):
        PWASVirtualSensor(mu=1, my=1, sigma=1.0).fit(u, y, z[:150])
    with pytest.raises(ValueError, match="got 2 target trajectories for 1"):
        PWASVirtualSensor(mu=1, my=1, sigma=1.0).fit(u, y, [z, z])
    with pytest.raises(ValueError, match="got 2 input trajectories but 1 output trajectories"):
        PWASVirtualSensor(mu=1, my=1, sigma=1.0).fit([u, u], [y], [z, z])
    with pytest.raises(ValueError, match="no input data given"):
        PWASVirtualSensor(mu=1, my=1, sigma=1.0).fit(None, y, z)
    with pytest.raises(ValueError, match=r"--domain \(domain\) gives 1 lower and 1 upper bound\(s\) for 2 regressors"):
        PWASVirtualSensor(mu=1, my=1, sigma=1.0, domain=([0.0], [1.0])).fit(u, y, z)


@pytest.mark.parametrize("p", [0, -1, [2, 0]])
def test_partitions_below_one(p, good_data):
    u, y, z = good_data
    with pytest.raises(ValueError, match=r"needs p >= 1 intervals"):
        Grid([0.0, 0.0], [1.0, 1.0], p)
    with pytest.raises(ValueError, match=r"needs p >= 1 intervals"):
        PWASVirtualSensor(mu=1, my=1, partitions=p, sigma=1.0).fit(u, y, z)


@pytest.mark.parametrize("p", [2.5, [2, 1.5], np.array([3.0, 0.25])])
def test_partitions_not_integer(p, good_data):
    u, y, z = good_data
    with pytest.raises(ValueError, match="is not an integer"):
        Grid([0.0, 0.0], [1.0, 1.0], p)
    with pytest.raises(ValueError, match="is not an integer"):
        PWASVirtualSensor(mu=1, my=1, partitions=p, sigma=1.0).fit(u, y, z)


def test_partitions_wrong_count():
    with pytest.raises(ValueError, match="one integer or 2 integers"):
        Grid([0.0, 0.0], [1.0, 1.0], [2, 2, 2])


@pytest.mark.parametrize("gamma", [0.999, 0.0, -1.0, float("nan"), float("inf"), "2"])
def test_gamma_below_one(gamma, good_data):
    with pytest.raises(ValueError, match=r"--gamma \(gamma\) must be a number >= 1"):
        PWASVirtualSensor(mu=1, my=1, gamma=gamma, sigma=1.0).fit(*good_data)


@pytest.mark.parametrize("sigma", [0.0, -1e-3, float("nan"), float("inf")])
def test_sigma_not_positive(sigma, good_data):
    with pytest.raises(ValueError, match=r"--sigma \(sigma\) must be a positive"):
        PWASVirtualSensor(mu=1, my=1, sigma=sigma).fit(*good_data)
    grid = Grid([0.0], [1.0], 2)
    h = grid.basis_matrix(np.array([[0.1], [0.6]]))
    with pytest.raises(ValueError, match="sigma must be a positive finite number"):
        solve_regularized(h, np.zeros(2), sigma, tikhonov_matrix(grid))
    with pytest.raises(ValueError, match="sigma candidates must be positive finite"):
        cross_validate_sigma(h, np.zeros(2), tikhonov_matrix(grid), [1.0, sigma], folds=2)


def test_cv_folds(good_data):
    grid = Grid([0.0], [1.0], 2)
    h = grid.basis_matrix(np.linspace(0, 1, 3)[:, None])
    with pytest.raises(ValueError, match="at least 2 folds"):
        cross_validate_sigma(h, np.zeros(3), tikhonov_matrix(grid), [1.0], folds=1)
    with pytest.raises(ValueError, match=r"cannot split 3 samples into 4 folds \(--folds\); use --folds 3 or fewer"):
        cross_validate_sigma(h, np.zeros(3), tikhonov_matrix(grid), [1.0], folds=4)


@pytest.mark.parametrize("order", [2, -1, "1"])
def test_tikhonov_order_other_than_0_or_1(order, good_data):
    with pytest.raises(ValueError, match=r"--tikhonov \(tikhonov_order\) must be 0 \(Gamma = I\) or 1"):
        PWASVirtualSensor(mu=1, my=1, sigma=1.0, tikhonov_order=order).fit(*good_data)
    with pytest.raises(ValueError, match="Tikhonov order must be 0 or 1"):
        tikhonov_matrix(Grid([0.0], [1.0], 2), order)


def test_lag_structure_checks():
    with pytest.raises(ValueError, match="mu must be a non-negative integer"):
        LagStructure(-1, 1, 1, 1)
    with pytest.raises(ValueError, match="the regressor is empty"):
        LagStructure(0, 0, 1, 1)
    with pytest.raises(ValueError, match="the regressor is empty"):
        PWASVirtualSensor(mu=0, my=0, sigma=1.0).fit(np.zeros(10), np.zeros(10), np.zeros(10))


def test_failed_fit_leaves_earlier_fit_when_parameters_are_bad(good_data):
    """Parameter checks come before anything is changed."""
    s = PWASVirtualSensor(mu=1, my=1, partitions=2, sigma=1.0).fit(*good_data)
    w = s.weights_.copy()
    s.sigma = -1.0
    with pytest.raises(ValueError, match=r"--sigma \(sigma\) must be a positive"):
        s.fit(*good_data)
    np.testing.assert_array_equal(s.weights_, w)


# ---------------------------------------------------------- save: no files
def test_save_unfitted_writes_nothing(tmp_path):
    with pytest.raises(NotFittedError, match="not fitted yet"):
        PWASVirtualSensor().save(tmp_path / "m.json")
    assert _files(tmp_path) == []
    with pytest.raises(NotFittedError, match="not fitted yet"):
        PWASVirtualSensor().predict(None, np.zeros(5))


def test_failed_save_leaves_existing_file_untouched(tmp_path, good_data):
    s = PWASVirtualSensor(mu=1, my=1, partitions=2, sigma=1.0).fit(*good_data)
    path = s.save(tmp_path / "m.json")
    before = path.read_bytes()
    s.weights_[3, 0] = np.nan  # not representable in strict JSON
    with pytest.raises(ValueError):
        s.save(path)
    assert path.read_bytes() == before
    assert _files(tmp_path) == ["m.json"]  # no temporary file left behind


def test_save_into_missing_folder_writes_nothing(tmp_path, good_data):
    s = PWASVirtualSensor(mu=1, my=1, partitions=2, sigma=1.0).fit(*good_data)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        s.save(tmp_path / "missing" / "m.json")
    assert _files(tmp_path) == []


# -------------------------------------------------------- corrupt model file
@pytest.fixture
def model_dict(good_data) -> dict:
    """A model fitted with cross-validation (sigma not given, a cv record in the file)."""
    s = PWASVirtualSensor(mu=1, my=1, partitions=2, sigma=None, sigma_grid=[0.1, 1.0], cv_folds=2)
    return s.fit(*good_data).to_dict()


def _dump(tmp_path, d, name="m.json"):
    return _write(tmp_path / name, json.dumps(d))


def test_model_round_trip_baseline(tmp_path, model_dict):
    """The unmodified file loads (so the failures below come from the corruption)."""
    s = PWASVirtualSensor.load(_dump(tmp_path, model_dict))
    assert s.cv_ is not None and s.sigma_ == model_dict["fit"]["sigma"]


@pytest.mark.parametrize("keep", [0.5, 0.9, 0.99])
def test_model_truncated_json(keep, tmp_path, model_dict):
    text = json.dumps(model_dict, indent=1)
    path = _write(tmp_path / "m.json", text[: int(len(text) * keep)])
    with pytest.raises(ValueError, match="is not valid JSON .*corrupt or truncated"):
        PWASVirtualSensor.load(path)


def test_model_empty_or_binary(tmp_path):
    with pytest.raises(ValueError, match="is not valid JSON"):
        PWASVirtualSensor.load(_write(tmp_path / "empty.json", ""))
    (tmp_path / "bin.json").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ValueError, match="is not UTF-8"):
        PWASVirtualSensor.load(tmp_path / "bin.json")
    with pytest.raises(FileNotFoundError):
        PWASVirtualSensor.load(tmp_path / "none.json")


@pytest.mark.parametrize("fmt", ["pwas-hdl-modell", "", None, 1])
def test_model_wrong_format(fmt, tmp_path, model_dict):
    model_dict["format"] = fmt
    with pytest.raises(InputError, match='is not a pwas-hdl-model file .*"format": "pwas-hdl-model"'):
        PWASVirtualSensor.load(_dump(tmp_path, model_dict))
    del model_dict["format"]
    with pytest.raises(InputError, match="is not a pwas-hdl-model file"):
        PWASVirtualSensor.load(_dump(tmp_path, model_dict))
    with pytest.raises(InputError, match="is not a pwas-hdl-model file"):
        PWASVirtualSensor.load(_dump(tmp_path, [model_dict]))


@pytest.mark.parametrize("version", [0, 1, 3, "2", None])
def test_model_other_version(version, tmp_path, model_dict):
    model_dict["version"] = version
    with pytest.raises(InputError, match=rf"version {re.escape(repr(version))} is not supported \(this pwas-hdl reads "
                                         r"version 2\); re-run `pwas-hdl fit`"):
        PWASVirtualSensor.load(_dump(tmp_path, model_dict))


MISSING_KEYS = [
    ("signals",), ("lags",), ("grid",), ("weights",), ("fit",),
    ("signals", "inputs"), ("signals", "outputs"), ("signals", "targets"),
    ("lags", "Mu"), ("lags", "My"),
    ("grid", "lo"), ("grid", "hi"), ("grid", "partitions"),
    ("weights", "z0"),
    ("fit", "sigma"), ("fit", "gamma"), ("fit", "tikhonov_order"),
    ("fit", "cv", "mse"), ("fit", "cv", "best_sigma"),
]


@pytest.mark.parametrize("keys", MISSING_KEYS, ids=lambda k: ".".join(k))
def test_model_missing_key(keys, tmp_path, model_dict):
    d = copy.deepcopy(model_dict)
    node = d
    for k in keys[:-1]:
        node = node[k]
    del node[keys[-1]]
    if keys == ("weights", "z0"):  # the schema allows any target names: the consistency check names it
        want = r"weights has the keys \[\], signals.targets are \['z0'\]"
    else:
        want = rf"m.json: {re.escape('.'.join(keys))} is missing; re-run `pwas-hdl fit`"
    with pytest.raises(InputError, match=want):
        PWASVirtualSensor.load(_dump(tmp_path, d))


def test_model_inconsistent_content(tmp_path, model_dict):
    d = copy.deepcopy(model_dict)
    d["weights"]["z0"] = d["weights"]["z0"][:-1]
    with pytest.raises(InputError, match="weights.z0 has 8 values, the grid has N = 9 vertices"):
        PWASVirtualSensor.load(_dump(tmp_path, d, "short.json"))
    d = copy.deepcopy(model_dict)
    d["lags"]["My"] = 2
    with pytest.raises(InputError, match="grid.lo has 2 values, the lags give n = 3 regressors"):
        PWASVirtualSensor.load(_dump(tmp_path, d, "lags.json"))
    d = copy.deepcopy(model_dict)
    d["grid"]["partitions"] = [2, 0]
    with pytest.raises(InputError, match=r"grid.partitions\[1\] must be >= 1, got 0"):
        PWASVirtualSensor.load(_dump(tmp_path, d, "parts.json"))
    d = copy.deepcopy(model_dict)
    d["grid"]["hi"] = d["grid"]["lo"]
    with pytest.raises(InputError, match="width.json: grid: .*zero or negative width"):
        PWASVirtualSensor.load(_dump(tmp_path, d, "width.json"))
    d = copy.deepcopy(model_dict)
    d["fit"] = "oops"
    with pytest.raises(InputError, match='fit must be an object, got "oops"'):
        PWASVirtualSensor.load(_dump(tmp_path, d, "fit.json"))
    d = copy.deepcopy(model_dict)
    d["fit"]["train_rmse"] = [1.0]
    with pytest.raises(InputError, match=r"fit.train_rmse must be an object, got \[1.0\]"):
        PWASVirtualSensor.load(_dump(tmp_path, d, "rmse.json"))
    # json.loads accepts NaN; the loader must not
    text = json.dumps(model_dict).replace(repr(model_dict["weights"]["z0"][4]), "NaN", 1)
    with pytest.raises(InputError, match="nan.json is not valid JSON \\(NaN is not a JSON number\\)"):
        PWASVirtualSensor.load(_write(tmp_path / "nan.json", text))


def test_failed_refit_keeps_the_previous_fit(good_data):
    u, y, z = good_data
    m = PWASVirtualSensor(mu=1, my=1, sigma=1.0).fit(u, y, z)
    before = m.weights_.copy()
    with pytest.raises(ValueError, match="NaN"):
        m.fit(u, y, np.full_like(z, np.nan))
    assert np.array_equal(m.weights_, before)
    assert m.predict(u, y).shape[0] == u.shape[0]  # M = max(Mu, My) = 1


def test_z_longer_than_inputs_is_refused(good_data):
    u, y, z = good_data
    with pytest.raises(ValueError, match="sampled at the same instants"):
        PWASVirtualSensor(mu=1, my=1, sigma=1.0).fit(u, y, np.concatenate([z, z[:5]]))


@pytest.mark.parametrize("version", [True, 2.0])
def test_model_version_must_be_the_integer_2(tmp_path, good_data, version):
    import json

    u, y, z = good_data
    p = tmp_path / "m.json"
    PWASVirtualSensor(mu=1, my=1, sigma=1.0).fit(u, y, z).save(p)
    d = json.loads(p.read_text())
    d["version"] = version
    p.write_text(json.dumps(d))
    with pytest.raises(InputError, match=rf"version {version!r} is not supported"):
        PWASVirtualSensor.load(p)


def test_sigma_of_the_wrong_type_is_a_value_error(good_data):
    u, y, z = good_data
    with pytest.raises(ValueError, match=r"--sigma \(sigma\) must be a positive number"):
        PWASVirtualSensor(mu=1, my=1, sigma="1").fit(u, y, z)
