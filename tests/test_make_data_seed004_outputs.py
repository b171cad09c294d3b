"""make-data pv-benchmark / switching-4 / battery check both output paths before the work and write
both files or none: a bad --test-out used to leave the -o/--out file written (exit 2), and
``--test-out`` naming the -o file silently overwrote the training set with the test set (exit 0)."""

from __future__ import annotations

import pytest
from helpers.cli import CliRunner
from helpers.folders import tree

import pwas_hdl.cli as cli

RUNNER = CliRunner()


@pytest.mark.parametrize("system", ["pv-benchmark", "switching-4", "battery"])
@pytest.mark.parametrize("test_out, words", [("missing/t.csv", ("--test-out", "does not exist")),
                                             ("d.csv", ("-o/--out", "--test-out", "own path"))])
def test_a_bad_test_out_writes_nothing(tmp_path, monkeypatch, system, test_out, words):
    monkeypatch.chdir(tmp_path)
    before = tree(tmp_path)
    res = RUNNER.invoke(cli.app, ["make-data", system, "-o", "d.csv", "--samples", "50", "--test-out", test_out,
                                  "--test-samples", "20"])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert tree(tmp_path) == before
