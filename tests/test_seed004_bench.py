"""CI smoke of the seed-004 benches (--quick) and their bad input."""

from __future__ import annotations

import pytest
from helpers.cli import CliRunner

from pwas_hdl import bench_results as br
from pwas_hdl.cli import app

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.mark.slow
@pytest.mark.parametrize("bench,estimators", [
    ("pv-benchmark", {"dtr", "rfr", "pwas-feat", "pwas-raw"}),
    ("switching-4", {"rfr", "rfc", "pwas-feat", "pwas-raw"}),
    ("battery", {"rfr", "pwas-feat", "pwas-raw", "ekf-1", "ekf-2", "ekf-3", "ekf-4"}),
])
def test_quick_bench_writes_valid_results(tmp_path, bench, estimators):
    js, md, png = tmp_path / "r.json", tmp_path / "r.md", tmp_path / "r.png"
    extra = ["--plot", png] if bench == "battery" else []
    res = invoke("bench", bench, "--quick", "-o", js, "--md", md, *extra)
    assert res.exit_code == 0, res.output
    doc = br.load_results(js)
    assert doc["quick"] is True and doc["bench"] == bench
    assert {r["estimator"] for r in doc["rows"]} == estimators
    fits = [r for r in doc["rows"] if r["metric"] == "fit"]
    assert fits and all(r["value"] is not None and 0 <= r["value"] <= 1 for r in fits)
    # the bank sensors beat the raw-lag PWAS on the parameter-varying systems (issue 11's point)
    if bench != "battery":
        feat = br.find_rows(doc, estimator="pwas-feat", metric="fit")[0]["value"]
        raw = br.find_rows(doc, estimator="pwas-raw", metric="fit")[0]["value"]
        assert feat > raw + 0.2
    assert "train_s" in fits[0]["config"] and "peak_mib" in fits[0]["config"]
    assert md.read_text().startswith("# Seed 004")
    if bench == "battery":
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("args,needle", [
    (["pv-benchmark", "--runs", "0"], "--runs must be >= 1"),
    (["pv-benchmark", "--predictors", "svm"], "--predictors: unknown svm"),
    (["pv-benchmark", "--cases", "nope"], "unknown case(s) nope"),
    (["switching-4", "--runs", "0"], "--runs must be >= 1"),
    (["battery", "--runs", "-1"], "--runs must be >= 1"),
])
def test_bench_bad_input(tmp_path, args, needle):
    js = tmp_path / "r.json"
    res = invoke("bench", *args, "-o", js)
    assert res.exit_code == 2 and "error:" in res.output and needle in res.output, res.output
    assert not js.exists()
