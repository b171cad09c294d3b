"""$PWAS_HDL_MAX_MEMORY: an unusable value is refused naming the variable, sizes below 1 MiB are shown
in KiB / bytes (not "0 MiB"), and the refusal tells a command-line user to raise the variable (D17)."""

from __future__ import annotations

import pytest
from helpers.cli import CliRunner
from helpers.folders import tree

import pwas_hdl.cli as cli

RUNNER = CliRunner()


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("mem")
    assert RUNNER.invoke(cli.app, ["make-data", "lorenz", "-o", str(d / "d.csv"), "--samples", "400"]).exit_code == 0
    return d


def _fit_refused(root, monkeypatch, value, partitions="3") -> str:
    monkeypatch.setenv("PWAS_HDL_MAX_MEMORY", value)
    before = tree(root)
    res = RUNNER.invoke(cli.app, ["fit", str(root / "d.csv"), "-o", str(root / "m.json"), "-y", "y", "-z", "z",
                                  "--my", "2", "-p", partitions, "--sigma", "1e-3"])
    lines = res.output.strip().splitlines()
    assert res.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error:"), res.output
    assert tree(root) == before
    return lines[0]


@pytest.mark.parametrize("value, words", [("1K", ["1 KiB", "below the 1 MiB"]), ("1e-9", ["at least 1 byte"]),
                                          ("0.5", ["at least 1 byte"]), ("lots", ["not a size"])])
def test_an_unusable_limit_is_refused_naming_the_variable(data, monkeypatch, value, words):
    line = _fit_refused(data, monkeypatch, value)
    assert "PWAS_HDL_MAX_MEMORY" in line and repr(value) in line, line
    for w in words:
        assert w in line, (w, line)


def test_the_refusal_shows_small_sizes_and_names_the_variable_to_raise(data, monkeypatch):
    line = _fit_refused(data, monkeypatch, "1M", partitions="30")
    assert " 0 MiB" not in line and "KiB" in line, line
    assert "over the limit of 1 MiB ($PWAS_HDL_MAX_MEMORY)" in line, line
    assert "estimated 1 MiB" not in line, line  # not the same figure as the limit it is over
    assert "raise the limit with the environment variable PWAS_HDL_MAX_MEMORY" in line, line


@pytest.mark.parametrize("nbytes, text", [(0, "0 bytes"), (1000, "1000 bytes"), (2048, "2 KiB"), (2**20, "1 MiB"),
                                          (1.25 * 2**20, "1.2 MiB"), (12 * 2**20, "12 MiB"), (2**33, "8192 MiB")])
def test_size_text(nbytes, text):
    from pwas_hdl.fit.regularized_lsq import size_text

    assert size_text(nbytes) == text
