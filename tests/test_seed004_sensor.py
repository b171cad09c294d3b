"""The observer-bank front end inside the PWAS virtual sensor: Python, model file, CLI."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from helpers.cli import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.errors import InputError
from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.systems.pv_benchmark import make_pv_dataset
from pwas_hdl.systems.pv_method import fit_ratio

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def pv_data():
    return make_pv_dataset("pv-benchmark", 4000, 1500, seed=2)


@pytest.fixture(scope="module")
def pv_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("pv")
    res = invoke("make-data", "pv-benchmark", "-o", d / "train.csv", "--samples", 4000, "--test-out", d / "test.csv",
                 "--test-samples", 1500, "--seed", 2)
    assert res.exit_code == 0, res.output
    return d


@pytest.mark.slow
@pytest.mark.parametrize("taps,feat", [((0, 0), "11b"), ((1, 1), "11b"), ((0, 2), "11a")])
def test_fit_predict_save_load_bit_exact(pv_data, tmp_path, taps, feat):
    tr, te, _ = pv_data
    # 11a: 2 observers x (l + 1) = 4 features + 2 taps, p = 2 -> 3^6 vertices
    fe = ObserverBankFrontEnd(n_models=2 if feat == "11a" else 3, window=1 if feat == "11a" else 7, features=feat)
    m = PWASVirtualSensor(mu=taps[0], my=taps[1], partitions=2 if feat == "11a" else 3, gamma=1.0, sigma=0.01,
                          front_end=fe, input_names=["u1", "u2"], output_names=["y"], target_names=["rho"])
    m.fit(tr.u, tr.y, tr.z)
    assert not hasattr(fe, "models_")  # the given front end is a template; the fitted copy is front_end_
    zhat = m.predict(te.u, te.y)
    assert zhat.shape == (te.y.shape[0] - m.memory + 1, 1)
    names = m.to_dict()["regressors"]
    assert len(names) == m.grid_.n
    m.save(tmp_path / "m.json")
    m2 = PWASVirtualSensor.load(tmp_path / "m.json")
    assert np.array_equal(m2.predict(te.u, te.y), zhat)
    assert m2.to_dict() == m.to_dict()
    m2.save(tmp_path / "m2.json")
    assert (tmp_path / "m.json").read_bytes() == (tmp_path / "m2.json").read_bytes()


@pytest.mark.slow
def test_bank_features_carry_rho(pv_data):
    """On E1 the bank's features explain rho where a short raw window does not (issue 11)."""
    tr, te, _ = pv_data
    bank = PWASVirtualSensor(mu=0, my=0, partitions=4, gamma=1.0, front_end=ObserverBankFrontEnd()).fit(tr.u, tr.y, tr.z)
    raw = PWASVirtualSensor(mu=2, my=3, partitions=3).fit(tr.u, tr.y, tr.z)
    fit_bank = fit_ratio(te.z_true[bank.memory - 1:], bank.predict(te.u, te.y))
    fit_raw = fit_ratio(te.z_true[raw.memory - 1:], raw.predict(te.u, te.y))
    assert fit_bank > 0.4 and fit_bank > fit_raw + 0.2, (fit_bank, fit_raw)


def test_lag_model_file_has_no_front_end_block(pv_data):
    tr, _, _ = pv_data
    d = PWASVirtualSensor(mu=1, my=2, partitions=2, sigma=0.1).fit(tr.u, tr.y, tr.z).to_dict()
    assert "front_end" not in d


def test_corrupt_front_end_block_is_refused(pv_data, tmp_path):
    tr, _, _ = pv_data
    m = PWASVirtualSensor(mu=0, my=0, partitions=2, sigma=0.1, front_end=ObserverBankFrontEnd(n_models=2)).fit(tr.u, tr.y, tr.z)
    d = m.to_dict()
    for mutate in (lambda b: b.pop("gains"), lambda b: b.update(kind="kalman-bank"), lambda b: b.update(models=[[1.0]]),
                   lambda b: b.update(window=0)):
        bad = json.loads(json.dumps(d))
        mutate(bad["front_end"])
        with pytest.raises(InputError, match="front_end"):
            PWASVirtualSensor.from_dict(bad)

    # edits that loaded and then failed inside predict / generate with IndexError (a bare number or a
    # short list for a statistic), divided by a zero standard deviation, or carried NaN (null) in
    # leaf_rho / lpv into generate's manifest (ValueError: not JSON compliant)
    def set_norm(key, value):
        return lambda b: b["normalization"].update({key: value})

    for mutate, words in [
        (set_norm("y_mean", -1.0), "front_end.normalization.y_mean must be a list of 1 number(s)"),
        (set_norm("y_std", []), "front_end.normalization.y_std must be a list of 1 number(s)"),
        (set_norm("y_std", [[]]), "front_end.normalization.y_std must be a list of 1 number(s)"),
        (set_norm("u_std", [1.0]), "front_end.normalization.u_std must be a list of 2 number(s)"),
        (set_norm("y_std", [True]), "front_end.normalization.y_std must be a list of 1 number(s)"),
        (set_norm("u_mean", [0.5, False]), "front_end.normalization.u_mean must be a list of 2 number(s)"),
        (set_norm("y_std", [0.0]), "front_end.normalization.y_std must hold positive standard deviations"),
        (set_norm("u_std", [1.0, -2.0]), "front_end.normalization.u_std must hold positive standard deviations"),
        (lambda b: b["leaf_rho"].__setitem__(0, None), "non-finite values in the observer-bank block"),
        (lambda b: b["lpv"]["knots"].__setitem__(0, None), "non-finite values in the observer-bank block"),
    ]:
        bad = json.loads(json.dumps(d))
        mutate(bad["front_end"])
        with pytest.raises(InputError, match="front_end") as ei:
            PWASVirtualSensor.from_dict(bad)
        assert words in str(ei.value), (words, str(ei.value))


@pytest.mark.slow
def test_cli_fit_predict_roundtrip_and_generate_refuses(pv_files, tmp_path):
    model = tmp_path / "bank.json"
    res = invoke("fit", pv_files / "train.csv", "-o", model, "-u", "u1,u2", "-y", "y", "-z", "rho",
                 "--front-end", "observer-bank", "--models", 5, "--observer", "kalman:0.1", "--window", 7, "--features", "11b",
                 "--mu", 1, "--my", 1, "-p", 2, "--gamma", 1.0)
    assert res.exit_code == 0, res.output
    d = json.loads(model.read_text())
    assert d["front_end"]["kind"] == "observer-bank" and d["front_end"]["observer"] == "kalman:0.1"
    assert d["regressors"][-3:] == ["u1[t]", "u2[t]", "y[t]"]
    pred = tmp_path / "pred.csv"
    res = invoke("predict", model, pv_files / "test.csv", "-o", pred)
    assert res.exit_code == 0, res.output
    assert "RMSE of rho_hat against column rho_true" in res.output
    rows = list(csv.DictReader(pred.open()))
    m = PWASVirtualSensor.load(model)
    assert int(rows[0]["row"]) == m.memory - 1 == 5 + 7 and len(rows) == 1500 - m.memory + 1
    # the CLI estimate equals the Python one from the same file
    from pwas_hdl.io.csv_table import read_csv

    t = read_csv(pv_files / "test.csv")
    zhat = m.predict(t.numeric(["u1", "u2"]), t.numeric(["y"]))[:, 0]
    assert np.array_equal(np.array([float(r["rho_hat"]) for r in rows]), zhat)
    out = tmp_path / "gen"
    res = invoke("generate", model, "--design", "core", "-o", out)
    # hardware for bank sensors with taps exists (issue 12; tests/test_bank_taps_hw.py), of the whole sensor only
    assert res.exit_code == 2 and "--design core of an observer-bank sensor is not available" in res.output
    assert not out.exists()


@pytest.mark.parametrize(
    "extra,needle",
    [
        (["--observer", "poles:2"], "--observer (observer) must be"),
        (["--features", "11c"], "--features (features) must be 11a or 11b"),
        (["--front-end", "bank"], "--front-end must be"),
        (["--models", "0"], "--models (n_models) must be an integer >= 1"),
        (["--window", "0"], "--window (window) must be"),
        (["-y", "y,u1"], "exactly one measured output"),
    ],
)
def test_cli_bad_bank_options(pv_files, tmp_path, extra, needle):
    model = tmp_path / "m.json"
    args = ["fit", pv_files / "train.csv", "-o", model, "-u", "u1,u2", "-y", "y", "-z", "rho",
            "--front-end", "observer-bank", "--mu", 0, "--my", 0]
    # a later --output/--front-end replaces the earlier one for single-valued options only; rebuild the list instead
    if extra[0] == "-y":
        args[args.index("-y") + 1] = extra[1]
    elif extra[0] == "--front-end":
        args[args.index("--front-end") + 1] = extra[1]
    else:
        args += extra
    res = invoke(*args)
    assert res.exit_code == 2, res.output
    assert "error:" in res.output and needle in res.output and "Traceback" not in res.output
    assert not model.exists()


def test_bank_needs_varying_target(pv_data):
    tr, _, _ = pv_data
    with pytest.raises(InputError, match="constant"):
        PWASVirtualSensor(mu=0, my=0, front_end=ObserverBankFrontEnd()).fit(tr.u, tr.y, np.zeros_like(tr.z))


def test_make_data_seed004_commands(tmp_path):
    for system, cols in (("pv-benchmark", ["u1", "u2", "y", "rho", "rho_true"]), ("switching-4", ["u1", "u2", "y", "rho", "rho_true"]),
                         ("battery", ["i", "v", "soc", "soc_true"])):
        out = tmp_path / f"{system}.csv"
        res = invoke("make-data", system, "-o", out, "--samples", 200, "--seed", 1, "--noise", 0.01)
        assert res.exit_code == 0, res.output
        assert out.read_text().splitlines()[0].split(",") == cols
        again = tmp_path / "again.csv"
        invoke("make-data", system, "-o", again, "--samples", 200, "--seed", 1, "--noise", 0.01)
        assert again.read_bytes() == out.read_bytes()
    res = invoke("make-data", "pv-benchmark", "-o", tmp_path / "x.csv", "--rho-law", "sine")
    assert res.exit_code == 2 and "--rho-law (rho_law) must be one of random-walk, cosine" in res.output and not (tmp_path / "x.csv").exists()
