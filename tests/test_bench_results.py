"""The bench results format (pwas_hdl.bench_results) and its shipped schema."""

import json
from pathlib import Path

import pytest

from pwas_hdl import bench_results as br
from pwas_hdl.errors import InputError


def _doc():
    rows = [
        br.row_from_values("three-tank", "x1", "pwas", "float", "rmse", [0.1, 0.12, 0.11], config={"window": "t>=100"}),
        br.row("switched-linear", "y", "known-mode-observer", "float", "mse", 0.01, runs=1, paper=0.0069),
    ]
    return br.make_results("demo", rows, {"seed_001.A1": "signed square root"}, config={"runs": 3})


def test_row_statistics_and_roundtrip(tmp_path):
    doc = _doc()
    r = doc["rows"][0]
    assert r["value"] == pytest.approx(0.11)
    assert r["std"] == pytest.approx(0.01)  # ddof = 1
    assert r["runs"] == 3 and r["paper"] is None
    assert doc["rows"][1]["std"] is None
    p = br.write_results(tmp_path / "r.json", doc)
    assert br.load_results(p) == json.loads(json.dumps(doc))
    assert br.find_rows(doc, target="x1", config={"window": "t>=100"}) == [r]
    md = br.markdown_table(doc, config_keys=["window"])
    assert "0.11 ± 0.01" in md and "0.0069" in md


def test_nonfinite_values_become_null_and_are_counted():
    r = br.row_from_values("s", "x", "paper-27", "float", "rmse", [0.1, float("nan")])
    assert r["value"] is None and r["config"]["n_nonfinite"] == 1


@pytest.mark.parametrize(
    "mutate",
    [
        lambda d: d["rows"][0].update(stage="fpga"),
        lambda d: d["rows"][0].update(metric="mae"),
        lambda d: d["rows"][0].pop("paper"),
        lambda d: d["rows"][0].update(runs=0),
        lambda d: d.update(version=2),
        lambda d: d.pop("assumptions"),
    ],
)
def test_schema_refuses_malformed_documents(mutate, tmp_path):
    doc = _doc()
    mutate(doc)
    with pytest.raises(InputError, match="not a valid pwas-hdl-bench-results"):
        br.validate_results(doc)
    with pytest.raises(InputError):
        br.write_results(tmp_path / "bad.json", doc)
    assert not (tmp_path / "bad.json").exists()


def test_row_refuses_unknown_stage_and_metric():
    with pytest.raises(InputError, match="stage"):
        br.row("s", "x", "e", "asic", "rmse", 1.0)
    with pytest.raises(InputError, match="metric"):
        br.row("s", "x", "e", "float", "mae", 1.0)


def test_committed_bench_results_validate():
    """Every committed benchmarks/results/*.json that is a bench result satisfies the schema."""
    from pathlib import Path

    results = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
    checked = []
    for f in sorted(results.glob("*.json")):
        doc = json.loads(f.read_text())
        if isinstance(doc, dict) and doc.get("format") == br.RESULTS_FORMAT:
            br.load_results(f)  # raises InputError naming the first violation
            checked.append(f.stem)
    # the system benches and the Lorenz tables (bench lorenz writes this format directly now)
    assert {"lorenz_tables", "three_tank", "switched_linear", "lorenz_hlnn"} <= set(checked)


def test_default_outdir_is_the_checkout_results_or_the_cwd(tmp_path, monkeypatch):
    """Benchmark scripts write into benchmarks/results/ of a checkout, never into an installed
    package: from a wheel (no pyproject.toml beside the benchmarks folder) into ./benchmarks-results."""
    import pwas_hdl.resources as res

    checkout = Path(__file__).resolve().parents[1]
    if (checkout / "benchmarks" / "results").is_dir() and res.benchmarks_dir().parent == checkout:
        assert br.default_outdir() == res.benchmarks_dir() / "results"
    installed = tmp_path / "site-packages" / "pwas_hdl" / "benchmarks"
    (installed / "results").mkdir(parents=True)
    monkeypatch.setattr(res, "benchmarks_dir", lambda: installed)
    monkeypatch.chdir(tmp_path)
    assert br.default_outdir() == tmp_path / "benchmarks-results"
