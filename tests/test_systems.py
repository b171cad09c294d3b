"""Benchmark plants of pwas_hdl.systems: the synthetic helicopter (and its make-data command)."""

from __future__ import annotations

import numpy as np
import pytest

from pwas_hdl.errors import InputError
from pwas_hdl.systems.helicopter import helicopter
from pwas_hdl.systems.lorenz import PlantData


def test_helicopter_is_plant_data_with_named_columns():
    d = helicopter(300, seed=0)
    assert isinstance(d, PlantData)
    assert d.u.shape == (300, 2) and d.y.shape == (300, 1) and d.z.shape == (300, 1) and d.z_true.shape == (300, 1)
    assert d.names == {"u": ["psi_d", "phi_d"], "y": ["phi"], "z": ["psi"]}
    assert list(d.columns()) == ["psi_d", "phi_d", "phi", "psi", "psi_true"]
    assert np.all(np.isfinite(d.u)) and np.all(np.isfinite(d.y)) and np.all(np.isfinite(d.z))


def test_helicopter_numbers_are_those_of_the_hardware_tables():
    """Samples 0, 199 and 399 of seed 0, as the former benchmarks/hw_tables.py helicopter_plant gave them
    (the data behind the Table VI row of benchmarks/results/hw_tables.json)."""
    d = helicopter(400, seed=0)
    rows = [0, 199, 399]
    np.testing.assert_allclose(d.u[rows].ravel(), [0.13016373820319643, 0.5507917463615961, 0.3479451575629992,
                                                    1.0131885150996156, 0.6829317001669919, 1.0436288492536638], rtol=1e-12)
    np.testing.assert_allclose(d.y[rows, 0], [0.5221792527727072, 0.9831640502791019, 1.0471553084501575], rtol=1e-12)
    np.testing.assert_allclose(d.z[rows, 0], [0.18314974549899013, 0.13064099408380145, 0.723985020200277], rtol=1e-12)
    np.testing.assert_allclose(d.z_true[rows, 0], [0.1826163079419228, 0.1349461137857273, 0.7197190656491753], rtol=1e-12)


def test_helicopter_seeded_closed_loop_and_noise():
    a, b, c = helicopter(800, seed=1), helicopter(800, seed=1), helicopter(300, seed=2)
    assert np.array_equal(a.z, b.z) and np.array_equal(a.u, b.u)
    assert not np.array_equal(a.u[:300], c.u)
    # measurement noise 0.01 rad on psi (z) as documented
    assert 0.008 < float(np.std(a.z - a.z_true)) < 0.012
    # the elevation loop tracks its reference: the tracking error is well below the reference's spread
    err = a.z_true[:, 0] - a.u[:, 0]
    assert np.sqrt(np.mean(err**2)) < 0.5 * np.std(a.u[:, 0])


@pytest.mark.parametrize("bad", [0, -5, 2.5, True])
def test_helicopter_refuses_bad_sizes(bad):
    with pytest.raises(InputError, match="n_samples"):
        helicopter(bad)


def test_make_data_helicopter_cli(tmp_path):
    from helpers.cli import CliRunner

    from pwas_hdl.cli import app
    from pwas_hdl.io.csv_table import read_csv

    out, test = tmp_path / "h.csv", tmp_path / "ht.csv"
    r = CliRunner().invoke(app, ["make-data", "helicopter", "-o", str(out), "--samples", "150",
                                 "--test-out", str(test), "--test-samples", "50", "--seed", "4"])
    assert r.exit_code == 0, r.output
    d = helicopter(200, seed=4)
    tab = read_csv(out)
    np.testing.assert_array_equal(tab.numeric(["psi"])[:, 0], d.z[:150, 0])
    np.testing.assert_array_equal(read_csv(test).numeric(["psi_d"])[:, 0], d.u[150:, 0])
    r = CliRunner().invoke(app, ["make-data", "helicopter", "-o", str(tmp_path / "x.csv"), "--samples", "0"])
    assert r.exit_code == 2 and "error:" in r.output and not (tmp_path / "x.csv").exists()
