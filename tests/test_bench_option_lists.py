"""bench: every list and count option is checked before the run, --quick or not.

``bench pv-benchmark --ann-cases foo`` and ``--tables ""`` started the full benchmark;
``bench battery|switching-4|pv-benchmark --quick --runs 0`` ran (exit 0) where ``three-tank`` refused it.
The executor is replaced by a stub that stops the command, so a check that is missing fails fast
instead of running the benchmark.
"""

from __future__ import annotations

import pytest
from helpers.cli import CliRunner
from helpers.folders import tree

import pwas_hdl.cli as cli
from pwas_hdl.errors import InputError

RUNNER = CliRunner()
STOP = "stub executor: the bench would start here"


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    def stop(*_a, **_k):
        raise InputError(STOP)

    monkeypatch.setattr(cli, "_executor", stop)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _one_error(args, root) -> str:
    before = tree(root)
    res = RUNNER.invoke(cli.app, ["bench", *args, "-o", "b.json"])
    lines = res.output.strip().splitlines()
    assert res.exit_code == 2, res.output
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    assert tree(root) == before
    return lines[0]


@pytest.mark.parametrize("args, words", [
    (["pv-benchmark", "--ann-cases", "foo"], ["--ann-cases", "unknown case(s) foo", "base"]),
    (["pv-benchmark", "--ann-cases", ""], ["--ann-cases is empty"]),
    (["pv-benchmark", "--tables", ""], ["--tables is empty", "T1"]),
    (["pv-benchmark", "--tables", ","], ["--tables is empty"]),
    (["pv-benchmark", "--tables", "T"], ["--tables: unknown T", "T7"]),
    (["pv-benchmark", "--tables", "T1,T9"], ["--tables: unknown T9"]),
    (["pv-benchmark", "--cases", ""], ["--cases is empty"]),
    (["pv-benchmark", "--predictors", ""], ["--predictors is empty", "dtr"]),
    (["pv-benchmark", "--quick", "--cases", "foo"], ["--cases", "unknown case(s) foo"]),
    (["pv-benchmark", "--quick", "--ann-cases", "foo"], ["--ann-cases", "foo"]),
])
def test_pv_benchmark_refuses_unknown_and_empty_lists(in_tmp, args, words):
    line = _one_error(args, in_tmp)
    assert STOP not in line, line
    for w in words:
        assert w in line, (w, line)


@pytest.mark.parametrize("bench", ["pv-benchmark", "switching-4", "battery", "three-tank", "switched-linear", "lorenz-hlnn"])
@pytest.mark.parametrize("runs", ["0", "-1", "1001"])
def test_runs_is_checked_with_quick_too(in_tmp, bench, runs):
    line = _one_error([bench, "--quick", "--runs", runs], in_tmp)
    assert "--runs" in line and STOP not in line, line


def test_lorenz_seeds_is_checked_with_quick_too(in_tmp):
    line = _one_error(["lorenz", "--quick", "--seeds", "0"], in_tmp)
    assert "--seeds" in line and STOP not in line, line


@pytest.mark.parametrize("args", [["pv-benchmark", "--tables", "T4", "--ann-cases", "base,cosine"],
                                  ["pv-benchmark", "--quick", "--predictors", "rfr,pwas-feat"],
                                  ["pv-benchmark", "--cases", "base, kf1"],
                                  ["battery", "--quick", "--runs", "1000"]])
def test_good_lists_reach_the_run(in_tmp, args):
    assert STOP in _one_error(args, in_tmp)
