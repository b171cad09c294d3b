"""`fit` checks every option value, also those the chosen front end or a given --sigma leaves unused.

Before, `--folds 0` with `--sigma`, or `--models 0` / `--window 0` / `--order 0` with the lag front end,
were accepted silently (a typo went unnoticed); now each is one `error:` line, exit 2, nothing written.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers.cli import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.errors import InputError
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor


@pytest.fixture(scope="module")
def data_csv(tmp_path_factory):
    rng = np.random.default_rng(0)
    y = rng.uniform(-1, 1, 60)
    path = tmp_path_factory.mktemp("fitopts") / "d.csv"
    path.write_text("y,z\n" + "".join(f"{a:.6f},{np.sin(a):.6f}\n" for a in y))
    return path


@pytest.mark.parametrize(
    "extra,needle",
    [
        (["--sigma", "0.1", "--folds", "0"], "--folds (cv_folds) must be an integer >= 2"),
        (["--folds", "1"], "--folds (cv_folds) must be an integer >= 2"),
        (["--models", "0"], "--models (n_models) must be an integer >= 1"),
        (["--window", "0"], "--window (window) must be an integer >= 1"),
        (["--order", "-1"], "--order (order) must be an integer >= 1"),
        (["--observer", "poles:2"], "--observer (observer) must be"),
        (["--features", "11c"], "--features (features) must be"),
    ],
)
def test_unused_option_values_are_checked(data_csv, tmp_path, extra, needle):
    out = tmp_path / "m.json"
    res = CliRunner().invoke(app, ["fit", str(data_csv), "-o", str(out), "-y", "y", "-z", "z", "-p", "3", *extra])
    assert res.exit_code == 2, res.output
    assert res.output.count("error:") == 1 and needle in res.output and "Traceback" not in res.output
    assert not out.exists()


def test_api_checks_cv_folds_with_a_given_sigma():
    y = np.linspace(-1, 1, 40)[:, None]
    with pytest.raises(InputError, match="cv_folds"):
        PWASVirtualSensor(my=1, partitions=3, sigma=0.1, cv_folds=1, output_names=["y"], target_names=["z"]).fit(
            None, y, np.sin(y))


def test_good_options_still_fit(data_csv, tmp_path):
    out = tmp_path / "m.json"
    res = CliRunner().invoke(app, ["fit", str(data_csv), "-o", str(out), "-y", "y", "-z", "z", "-p", "3", "--sigma", "0.1"])
    assert res.exit_code == 0, res.output
    assert out.exists()
