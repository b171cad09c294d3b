"""Plants of seeds 001 (three-tank) and 003 (switched linear): equations, seeding, runs, CLI."""

import numpy as np
import pytest
from helpers.cli import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.errors import InputError
from pwas_hdl.io.csv_table import read_csv
from pwas_hdl.systems.switched_linear import SWITCHED_A, SWITCHED_B, simulate_switched, switched_paper_run, switched_training_runs
from pwas_hdl.systems.three_tank import THREE_TANK_PARAMS, signed_sqrt, three_tank_paper_run, three_tank_training_runs


def test_three_tank_follows_eq26_and_the_paper_setup():
    d = three_tank_paper_run(400, seed=3)
    x = np.column_stack([d.z[:, 0], d.y[:, 0], d.z[:, 1]])
    np.testing.assert_array_equal(x[0], [8.0, 2.0, 1.0])
    a = THREE_TANK_PARAMS
    u = d.u[:, 0]
    np.testing.assert_allclose(u, 1 + np.sin(np.arange(400)))
    # x3 and x2 equations hold exactly; x1 up to the disturbance, which is 0 before t = 100 and bounded after
    q12, q23 = signed_sqrt(x[:-1, 0] - x[:-1, 1]), signed_sqrt(x[:-1, 1] - x[:-1, 2])
    np.testing.assert_allclose(x[1:, 2], a["a2"] * q23 - a["a3"] * np.sqrt(x[:-1, 2]) + x[:-1, 2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(x[1:, 1], a["a5"] * u[:-1] + a["a1"] * q12 - a["a2"] * q23 + x[:-1, 1], atol=1e-12)
    rho = x[1:, 0] - (a["a4"] * u[:-1] - a["a1"] * q12 + x[:-1, 0])
    assert np.all(np.abs(rho[:100]) < 1e-12)
    assert 0.05 < np.abs(rho[100:]).max() <= 0.15 and np.std(rho[100:]) > 0.05
    assert np.all(x[:, 0] >= x[:, 1]) and np.all(x[:, 1] >= x[:, 2])  # the paper's admissible region


def test_three_tank_is_seeded_and_runs_are_indexed():
    a, b = three_tank_training_runs(3, 200, seed=1), three_tank_training_runs(3, 200, seed=1)
    np.testing.assert_array_equal(a.z, b.z)
    assert not np.array_equal(a.z, three_tank_training_runs(3, 200, seed=2).z)
    assert [len(r.y) for r in a.runs()] == [200] * 3 and list(np.unique(a.run)) == [0, 1, 2]
    noisy = three_tank_training_runs(3, 200, seed=1, noise=0.05)
    np.testing.assert_array_equal(noisy.z_true, a.z_true)
    assert 0.03 < np.std(noisy.y - a.y) < 0.07


def test_switched_plant_follows_eq11_and_records_the_mode():
    d = switched_training_runs(2, 500, seed=0)
    for r in d.runs():
        x, th, u = r.z_true, r.mode, r.u[:, 0]
        for k in range(len(th) - 1):
            np.testing.assert_allclose(x[k + 1], SWITCHED_A[th[k] - 1] @ x[k] + SWITCHED_B[th[k] - 1] * u[k], atol=1e-12)
        np.testing.assert_allclose(r.y[:, 0], x.sum(axis=1), atol=1e-12)
        dw = np.diff(np.flatnonzero(np.diff(th)))
        assert dw.min() >= 20 and dw.max() <= 50 and set(np.unique(th)) == {1, 2, 3}
    p = switched_paper_run()
    assert list(p.mode[[0, 33, 34, 67, 68, 99]]) == [1, 1, 2, 2, 3, 3]
    np.testing.assert_array_equal(p.z[0], [0.5, 0.5])


def test_output_driven_switching_uses_thresholds_at_dwell_boundaries():
    d = simulate_switched(2000, np.random.default_rng(4), switching="output", input_kind="prbs")
    th = d.mode
    dw = np.diff(np.flatnonzero(np.diff(th)))
    assert dw.min() >= 20 and set(np.unique(th)) == {1, 2, 3}
    with pytest.raises(InputError, match="switching"):
        simulate_switched(10, np.random.default_rng(0), switching="random")
    with pytest.raises(InputError, match="input"):
        simulate_switched(10, np.random.default_rng(0), input_kind="chirp")


def test_make_data_writes_named_columns_with_run(tmp_path):
    r = CliRunner().invoke(app, ["make-data", "three-tank", "-o", str(tmp_path / "t.csv"), "--runs", "2",
                                 "--samples", "50", "--test-out", str(tmp_path / "p.csv")])
    assert r.exit_code == 0, r.output
    t = read_csv(tmp_path / "t.csv")
    assert t.header == ["u1", "u2", "y", "x1", "x3", "x1_true", "x3_true", "run"] and len(t) == 100
    assert read_csv(tmp_path / "p.csv").numeric(["x1"])[0, 0] == 8.0
    r = CliRunner().invoke(app, ["make-data", "switched-linear", "-o", str(tmp_path / "s.csv"), "--runs", "2", "--samples", "60"])
    assert r.exit_code == 0, r.output
    assert read_csv(tmp_path / "s.csv").header == ["u", "y", "x1", "x2", "x1_true", "x2_true", "mode", "run"]
    for bad in (["--runs", "0"], ["--noise", "-1"], ["--switching", "nope"], ["--seed", "-1"], ["--input-signal", "chirp"]):
        out = tmp_path / "bad.csv"
        r = CliRunner().invoke(app, ["make-data", "switched-linear", "-o", str(out), *bad])
        assert r.exit_code == 2 and "error:" in r.output and not out.exists()
