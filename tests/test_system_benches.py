"""CI smoke of the system benches (`pwas-hdl bench three-tank|switched-linear|lorenz-hlnn --quick`).

Each writes a valid pwas-hdl-bench-results document, the Markdown tables and the figure. The
assertions are properties the quick runs must show whatever the machine's speed (no timing).
"""

import copy

import pytest
from helpers.cli import CliRunner

from pwas_hdl import bench_results as br
from pwas_hdl.cli import app

#: (doc, traces) of the real ``run_lorenz_hlnn(quick=True)`` of this module, once: the all-or-nothing
#: test needs a bench that computes and then fails writing, not a second computation of the same run.
_HLNN_QUICK: list = []


@pytest.fixture
def hlnn_quick_once(monkeypatch):
    """``lorenz_hlnn.run_lorenz_hlnn`` that computes the quick run once per module (the real function,
    called with the CLI's arguments) and hands out copies of its result afterwards."""
    from pwas_hdl.benchmarks import lorenz_hlnn

    real = lorenz_hlnn.run_lorenz_hlnn

    def once(**kw):
        assert kw["quick"] and kw["runs"] == 5 and kw["executor"].kind == "serial"  # the CLI's quick call
        if not _HLNN_QUICK:
            _HLNN_QUICK.append(real(**kw))
        return copy.deepcopy(_HLNN_QUICK[0])

    monkeypatch.setattr(lorenz_hlnn, "run_lorenz_hlnn", once)


def _bench(tmp_path, name):
    files = {k: tmp_path / f"{name}.{k}" for k in ("json", "md", "png")}
    r = CliRunner().invoke(app, ["bench", name, "--quick", "-o", str(files["json"]), "--md", str(files["md"]),
                                 "--plot", str(files["png"])])
    assert r.exit_code == 0, r.output
    doc = br.load_results(files["json"])
    assert doc["quick"] and doc["bench"] == name and doc["assumptions"]
    assert files["png"].stat().st_size > 10_000 and "|" in files["md"].read_text()
    return doc


def _value(doc, **kw):
    rows = br.find_rows(doc, **kw)
    assert len(rows) == 1, (kw, rows)
    return rows[0]["value"]


@pytest.mark.slow
@pytest.mark.rtl  # its --quick run replays the recurrent map-28 sensor on Icarus
def test_bench_three_tank_quick(tmp_path):
    doc = _bench(tmp_path, "three-tank")
    w = {"window": "t>=100", "noise_y": 0.0}
    # sensor (28) is decoupled from the disturbance: essentially exact; (27) is not
    assert _value(doc, target="x3", estimator="paper-28", config=w) < 2e-3
    assert _value(doc, target="x1", estimator="paper-27", config=w) > 0.1
    for tgt in ("x1", "x3"):
        f, b = _value(doc, target=tgt, estimator="pwas", stage="float", config=w), _value(doc, target=tgt, estimator="pwas", stage="bittrue", config=w)
        assert f > 0 and abs(b - f) < 0.1 * f + 1e-3  # 12-bit default formats stay close to the float model
    # issue 13: the recurrent PWAS of map (28) in hardware (RTL replay, its own output codes) on the paper's run
    rtl = br.find_rows(doc, target="x3", estimator="pwas-map-28", stage="rtl", config=w)[0]
    assert rtl["config"]["rtl_mismatches"] == 0 and rtl["config"]["ii"] == rtl["config"]["latency"]
    assert rtl["value"] == _value(doc, target="x3", estimator="pwas-map-28", stage="bittrue", config=w) <= 0.01
    assert br.find_rows(doc, target="x1", estimator="pwas-map-27", stage="rtl", config=w)[0]["config"]["rtl_mismatches"] == 0
    assert {r["config"]["Mz"] for r in br.find_rows(doc, system="lorenz")} >= {0, 1}


@pytest.mark.slow
def test_bench_switched_linear_quick(tmp_path):
    doc = _bench(tmp_path, "switched-linear")
    c = {"test": "replica", "switching": "time", "noise_y": 0.0}
    known = br.find_rows(doc, target="y", estimator="known-mode-observer", metric="mse", config=c)[0]
    assert known["paper"] == 0.0069 and 0 < known["value"] < 0.05
    assert br.find_rows(doc, target="y", estimator="switched-observer", metric="mse", config=c)[0]["paper"] == 0.0966
    acc = _value(doc, target="mode", estimator="switched-observer", metric="accuracy", config={"test": "long"})
    assert 1 / 3 < acc <= 1
    for est in ("pwas-round", "pwas-classifier"):
        for stage in ("float", "bittrue"):
            assert 1 / 3 < _value(doc, target="mode", estimator=est, stage=stage, metric="accuracy") <= 1


@pytest.mark.slow
def test_bench_lorenz_hlnn_quick(tmp_path, hlnn_quick_once):
    doc = _bench(tmp_path, "lorenz-hlnn")
    for system, paper in (("lorenz", 24.0), ("helicopter-surrogate", 2.62)):
        rows = br.find_rows(doc, system=system, estimator="hlnn")
        assert rows[0]["paper"] == paper and rows[0]["value"] > 0
        pw = br.find_rows(doc, system=system, estimator="pwas", stage="float")[0]
        assert pw["value"] > 0 and pw["config"]["N"] == 4096


def test_bench_refuses_bad_runs_and_missing_folder(tmp_path):
    r = CliRunner().invoke(app, ["bench", "three-tank", "-o", str(tmp_path / "x.json"), "--runs", "0"])
    assert r.exit_code == 2 and "error:" in r.output
    r = CliRunner().invoke(app, ["bench", "switched-linear", "--quick", "-o", str(tmp_path / "no" / "x.json")])
    assert r.exit_code == 2 and "does not exist" in r.output
    assert not (tmp_path / "x.json").exists()


def test_bench_outputs_are_all_or_nothing(tmp_path, monkeypatch, hlnn_quick_once):
    """A bench whose figure fails leaves neither the JSON nor the Markdown (one OutputSet)."""
    from pwas_hdl.benchmarks import lorenz_hlnn  # the cheapest system bench (no simulator run)

    def broken_plot(traces, path):
        raise OSError(f"cannot write {path}: disk full")

    monkeypatch.setattr(lorenz_hlnn, "plot", broken_plot)
    files = [tmp_path / "b.json", tmp_path / "b.md", tmp_path / "b.png"]
    r = CliRunner().invoke(app, ["bench", "lorenz-hlnn", "--quick", "-o", str(files[0]), "--md", str(files[1]),
                                 "--plot", str(files[2])])
    assert r.exit_code == 2 and "disk full" in r.output, r.output
    assert sorted(p.name for p in tmp_path.iterdir()) == []
