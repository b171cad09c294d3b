"""The command-line interface: happy paths end to end and clean failures (exit 2, nothing written)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

runner = CliRunner()


def invoke(*args: str):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def lorenz_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("lorenz")
    res = invoke("make-data", "lorenz", "-o", d / "train.csv", "--samples", 3000, "--test-output", d / "test.csv",
                 "--test-samples", 503, "--seed", 3)
    assert res.exit_code == 0, res.output
    return d


def test_every_command_has_help():
    for cmd in (["--help"], ["fit", "--help"], ["generate", "--help"], ["simulate", "--help"], ["synth", "--help"], ["report", "--help"], ["explore", "--help"], ["predict", "--help"], ["info", "--help"], ["bench", "lorenz", "--help"],
                ["make-data", "lorenz", "--help"]):
        res = invoke(*cmd)
        assert res.exit_code == 0, (cmd, res.output)
        assert "Usage" in res.output


def test_fit_predict_roundtrip(lorenz_files, tmp_path):
    model = tmp_path / "m.json"
    res = invoke("fit", lorenz_files / "train.csv", "--output", "y", "--target", "z", "--my", 3, "-p", 4, "-o", model)
    assert res.exit_code == 0, res.output
    m = PWASVirtualSensor.load(model)
    assert m.grid_.n == 3 and m.grid_.n_vertices == 125
    assert m.cv_ is not None and m.sigma_ == m.cv_.best_sigma

    pred = tmp_path / "pred.csv"
    res = invoke("predict", model, lorenz_files / "test.csv", "-o", pred)
    assert res.exit_code == 0, res.output
    assert "RMSE of z_hat against column z_true" in res.output
    rows = list(csv.DictReader(pred.open()))
    assert len(rows) == 503 - 2
    assert rows[0]["row"] == "2"
    # The CLI's estimates are exactly the API's.
    test = np.loadtxt(lorenz_files / "test.csv", delimiter=",", skiprows=1)
    api = m.predict(None, test[:, [0]])[:, 0]
    assert np.array_equal(np.array([float(r["z_hat"]) for r in rows]), api)

    res = invoke("info", model)
    assert res.exit_code == 0
    info = json.loads(res.output)
    assert info["N"] == 125 and info["regressors"] == ["y[t-2]", "y[t-1]", "y[t]"]


def test_fit_with_fixed_sigma_first_order_and_trajectories(tmp_path):
    rng = np.random.default_rng(0)
    path = tmp_path / "d.csv"
    with path.open("w") as fh:
        fh.write("run,u,y,z\n")
        for run in ("a", "b"):
            u = rng.uniform(-1, 1, 200)
            y = np.cumsum(u) * 0.1
            for i in range(200):
                fh.write(f"{run},{u[i]},{y[i]},{u[i] * y[i]}\n")
    model = tmp_path / "m.json"
    res = invoke("fit", path, "--input", "u", "--output", "y", "--target", "z", "--mu", 2, "--my", 1, "-p", "3,3,2",
                 "--sigma", "1e-3", "--tikhonov", 1, "--traj-col", "run", "-o", model)
    assert res.exit_code == 0, res.output
    m = PWASVirtualSensor.load(model)
    assert m.sigma_ == 1e-3 and m.cv_ is None and m.n_train_ == 2 * 199
    assert m.grid_.partitions.tolist() == [3, 3, 2]


@pytest.mark.parametrize(
    "args, message",
    [
        (["--output", "nope", "--target", "z"], "no column named 'nope'"),
        (["--output", "y"], "--target"),
        (["--output", "y", "--target", "z", "-p", "0"], "p >= 1"),
        (["--output", "y", "--target", "z", "--gamma", "0.5"], "gamma"),
        (["--output", "y", "--target", "z", "--sigma", "-1"], "sigma"),
        (["--output", "y", "--target", "z", "--tikhonov", "2"], "order"),
        (["--output", "y", "--target", "z", "-p", "x"], "--partitions"),
        (["--output", "y", "--target", "z", "--my", "5000"], "lags need at least"),
    ],
)
def test_fit_bad_input_exits_2_and_writes_nothing(lorenz_files, tmp_path, args, message):
    model = tmp_path / "m.json"
    res = invoke("fit", lorenz_files / "train.csv", *args, "-o", model)
    assert res.exit_code == 2, res.output
    assert message in res.output
    assert not model.exists()


def test_predict_corrupt_model_exits_2(lorenz_files, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "pwas-hdl-model", "version": 1, "signals"')
    pred = tmp_path / "p.csv"
    res = invoke("predict", bad, lorenz_files / "test.csv", "-o", pred)
    assert res.exit_code == 2
    assert "corrupt" in res.output
    assert not pred.exists()


def test_bench_lorenz_quick(tmp_path):
    out = tmp_path / "b.json"
    md = tmp_path / "b.md"
    res = invoke("bench", "lorenz", "--quick", "--seeds", 1, "--json", out, "--md", md)
    assert res.exit_code == 0, res.output
    data = json.loads(out.read_text())
    assert md.read_text().strip()
    assert json.dumps(data)  # plain JSON, no NaN
