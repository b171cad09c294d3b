"""make-data --noise is bounded (0..MAX_NOISE): ``--noise 1e308`` wrote CSVs of inf / NaN (exit 0)."""

from __future__ import annotations

import pytest
from helpers.cli import CliRunner
from helpers.folders import tree

import pwas_hdl.cli as cli

RUNNER = CliRunner()

SMALL = {"three-tank": ["--runs", "1", "--samples", "20"], "switched-linear": ["--runs", "1", "--samples", "20"],
         "pv-benchmark": ["--samples", "50"], "switching-4": ["--samples", "50"], "battery": ["--samples", "50"]}


@pytest.mark.parametrize("system", sorted(SMALL))
@pytest.mark.parametrize("noise", ["1e308", "1e30", "1001"])
def test_a_noise_above_the_bound_is_refused_and_nothing_written(tmp_path, monkeypatch, system, noise):
    monkeypatch.chdir(tmp_path)
    before = tree(tmp_path)
    res = RUNNER.invoke(cli.app, ["make-data", system, "-o", "d.csv", "--test-out", "t.csv", *SMALL[system], "--noise", noise])
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert res.exit_code == 2, res.output
    assert len(errors) == 1 and len(res.output.strip().splitlines()) == 1, res.output
    assert "--noise" in errors[0] and "at most 1000" in errors[0], errors[0]
    assert tree(tmp_path) == before


@pytest.mark.parametrize("system", ["three-tank", "pv-benchmark"])
def test_the_bound_itself_is_accepted_and_gives_finite_data(tmp_path, system):
    import numpy as np

    from pwas_hdl.io.csv_table import read_csv

    out = tmp_path / "d.csv"
    res = RUNNER.invoke(cli.app, ["make-data", system, "-o", str(out), *SMALL[system], "--noise", "1000"])
    assert res.exit_code == 0, res.output
    t = read_csv(out)
    assert np.all(np.isfinite(t.numeric(t.header)))


def test_the_bound_is_stated_in_the_help():
    for system in SMALL:
        res = RUNNER.invoke(cli.app, ["make-data", system, "--help"])
        assert res.exit_code == 0 and "0..1000" in res.output, res.output
