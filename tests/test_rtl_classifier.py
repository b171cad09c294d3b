"""The PWAS mode classifier generated as RTL and bit-exact against its bit-true model in the cocotb bench.

Two classifier configurations (issue 10):

* ``switched-3modes``: the seed-003 switched linear system, a PWAS classifier of its 3 modes
  (one-hot scores on one grid, lags Mu = My = 2, p = 4) fitted on simulated runs, generated as the
  virtual-sensor top (lag bank + core + argmax stage);
* ``ties-nz4``: a synthetic core with nz = 4 scores where score 1 always equals score 0 and score 3
  equals score 2 on every other vertex (ties forced), pipeline ``max`` (2 argmax registers).

Each is replayed on Icarus and Verilator at full speed, with random stalls and with a reset in the
middle of a stream; the class index (``class_index`` field of the output payload) must equal the
argmax of the bit-true scores, ties to the lowest index, like every score and flag.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from pwas_hdl.design.manifest import load_manifest, manifest_errors
from pwas_hdl.fixedpoint.argmax import argmax_index
from pwas_hdl.verify.simulation import Run, load_design, run_rtl, segment, sim_module, simulate_arrays, standard_runs

designs = sim_module("pwas_designs")
stimulus = sim_module("pwas_stimulus")

MODES = (1, 2, 3)
SIMULATORS = ("icarus", "verilator")
TIES = designs.DesignConfig("ties-nz4", "core", 0, 2, 0, 1, [4, 3], 4, {"pipeline": "max"}, seed=5,
                            classes=(1, 2, 3, 4), ties=True)


def switched_classifier():
    """The 3-mode PWAS classifier of the switched linear system (seed 003), fitted quickly."""
    from pwas_hdl.benchmarks.bench_common import QUICK_SIGMA_GRID, PWASConfig, fit_pwas
    from pwas_hdl.fit import classifier as clf
    from pwas_hdl.systems.switched_linear import switched_training_runs

    train = switched_training_runs(4, 600, seed=1000, switching="time").runs()
    names = {"u": ["u"], "y": ["y"], "z": clf.class_target_names("mode", MODES)}
    m = fit_pwas(PWASConfig(2, 2, 4), [d.u for d in train], [d.y for d in train], [clf.one_hot(d.mode, MODES) for d in train],
                 names, QUICK_SIGMA_GRID)
    m.classifier_ = {"target": "mode", "classes": [float(c) for c in MODES]}
    return m


@pytest.fixture(scope="module")
def switched_model():
    return switched_classifier()


@pytest.fixture(scope="module")
def folders(switched_model, tmp_path_factory):
    from pwas_hdl.design.generate import generate

    root = tmp_path_factory.mktemp("classifiers")
    generate(switched_model, root / "switched-3modes", design="sensor")
    TIES.generate(root / "ties-nz4")
    return {"switched-3modes": root / "switched-3modes", "ties-nz4": root / "ties-nz4"}


def _codes(d, seed: int, m: int = 200) -> np.ndarray:
    return stimulus.design_codes(d, m, seed=seed)


def test_classifier_manifest_and_header(folders):
    """The class port is described (field, width, labels in order, tie rule); the header names it."""
    for name, folder in folders.items():
        man = load_manifest(folder)
        c = man["classifier"]
        out = next(p for p in man["ports"] if p["role"] == "out.payload")
        f = out["fields"][-1]
        assert (f["name"], f["lsb"], f["width"], f["signed"]) == ("class_index", c["lsb"], c["width"], False)
        assert c["port"] == out["name"] and c["lsb"] + c["width"] == out["width"]
        assert c["scores"] == [g["name"] for g in out["fields"][: c["n_classes"]]]
        assert f["classes"] == c["classes"] and c["tie_rule"].startswith("lowest class index")
        assert (1 << c["width"]) >= c["n_classes"] > (1 << (c["width"] - 1)) or c["n_classes"] <= 2
        text = (folder / man["files"]["verilog"]).read_text()
        assert f"classifier of mode ({c['n_classes']} classes" in text.split("\n/*")[0]
        assert "class_index" in text.split("\n/*")[0]
    assert load_manifest(folders["switched-3modes"])["classifier"]["classes"] == [1.0, 2.0, 3.0]
    assert load_manifest(folders["ties-nz4"])["classifier"]["stage_latency_cycles"] == 2  # pipeline max, 2 levels


def test_classifier_manifest_inconsistencies_are_caught(folders):
    man = json.loads((folders["ties-nz4"] / "manifest.json").read_text())
    assert manifest_errors(man) == []
    for edit, words in ((lambda m: m["classifier"].update(lsb=m["classifier"]["lsb"] - 1), "differ from its field"),
                        (lambda m: m["classifier"].update(classes=[1.0, 2.0]), "differ from its field"),
                        (lambda m: m.pop("classifier"), "has no classifier entry"),
                        (lambda m: m["classifier"].update(scores=["mode=1", "x", "y", "z"]), "are not fields")):
        bad = json.loads(json.dumps(man))
        edit(bad)
        errs = manifest_errors(bad)
        assert errs and words in errs[0], errs


def test_generation_is_deterministic(folders, tmp_path):
    TIES.generate(tmp_path / "again")
    for f in (folders["ties-nz4"]).iterdir():
        if f.is_file():
            assert (tmp_path / "again" / f.name).read_text() == f.read_text(), f.name


@pytest.mark.rtl  # runs Verilator's linter
def test_classifier_designs_lint_clean(folders, tmp_path):
    from test_hdl_verilog import VERILATOR, lint

    if VERILATOR is None:
        pytest.skip("verilator not installed")
    for name, folder in folders.items():
        man = load_manifest(folder)
        assert lint((folder / man["files"]["verilog"]).read_text(), man["top"], tmp_path) == [], name


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.parametrize("opts", [
    {"design": "sensor", "pipeline": "min", "ports": "amaranth"},  # the argmax combinational from the output register
    {"design": "core", "pipeline": "short", "input_scale": "exact", "memory": "corner"},
    {"design": "sensor", "pipeline": "max-lut", "input_bits": 7, "memory": "replicated", "memory_init": "readmemh"},
], ids=["sensor-min-amaranth", "core-short-exact-corner", "sensor-maxlut-7bit-replicated-readmemh"])
def test_classifier_option_sets_lint_clean_and_deterministic(switched_model, opts, tmp_path):
    """The argmax stage behind other pipelines, memories, input scales and widths than the folders above
    (its lint test covered the default sensor and the max core only): clean under verilator -Wall and
    byte-identical when built again."""
    from test_hdl_verilog import VERILATOR, lint

    from pwas_hdl.design.generate import build_design

    if VERILATOR is None:
        pytest.skip("verilator not installed")
    gd = build_design(switched_model, **opts)
    assert "classifier" in gd.manifest
    assert build_design(switched_model, **opts).files == gd.files
    assert lint(gd.files[f"{gd.top}.v"], gd.top, tmp_path) == []


@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize("name", ["switched-3modes", "ties-nz4"])
@pytest.mark.rtl
def test_classifier_rtl_bit_exact(name, simulator, folders, sim_cache, tmp_path):
    """Scores, flag and class index equal the bit-true model on both simulators, with stalls and resets."""
    d = load_design(folders[name])
    codes = _codes(d, seed=3)
    runs = standard_runs(d, codes, seed=3)
    res = run_rtl(d, runs, simulator, cache_dir=sim_cache, work_dir=tmp_path)
    assert res.passed, res.report()
    assert set(res.latencies) == {d.latency} and res.ii == 1.0
    per_stream = len(segment(d, codes).src)
    assert res.outputs >= 2 * per_stream + len(runs[2].segments[1].src)
    # the class index really was read and is the bit-true argmax (ties to the lowest index)
    for run, hw_run, cls_run in zip(runs, res.hw, res.hw_class):
        for seg, (z, _), cls in zip(run.segments, hw_run, cls_run):
            k = len(cls)
            assert k and np.array_equal(cls, argmax_index(z)) and np.array_equal(cls, seg.cls[:k])
    cls_all = np.concatenate([c for r in res.hw_class for c in r])
    if name == "ties-nz4":
        z_all = np.concatenate([z for r in res.hw for z, _ in r])
        tied = (z_all == z_all.max(axis=1, keepdims=True)).sum(axis=1) > 1
        assert tied.sum() > 50  # ties were exercised, and the lowest index won them
        assert not np.any(cls_all == 1)  # score 1 equals score 0 everywhere: class 1 can never win
        assert len(set(cls_all.tolist())) >= 3
    else:
        assert set(cls_all.tolist()) == {0, 1, 2}


@pytest.mark.rtl
def test_wrong_class_expectation_fails(folders, sim_cache, tmp_path):
    """The bench compares the class field: a wrong expected class is reported as a mismatch."""
    d = load_design(folders["ties-nz4"])
    seg = segment(d, _codes(d, seed=4, m=60))
    seg.cls = (seg.cls + 1) % 4
    res = run_rtl(d, [Run("full-speed", [seg])], "icarus", cache_dir=sim_cache, work_dir=tmp_path, strict=False)
    assert not res.passed and res.mismatches == len(seg.cls)


@pytest.mark.rtl
def test_simulate_writes_the_class_column(folders, sim_cache, tmp_path):
    """`simulate` on a switched-linear test run: class labels of RTL, bit-true and float, all compared."""
    from pwas_hdl.systems.switched_linear import switched_training_runs

    d = switched_training_runs(1, 400, seed=5000, switching="time").runs()[0]
    out = tmp_path / "hw.csv"
    r = simulate_arrays(folders["switched-3modes"], out, u=d.u, y=d.y, cache_dir=sim_cache)
    s = r["summary"]
    assert s["checks"]["passed"], s["checks"]
    header = out.read_text().splitlines()[0].split(",")
    assert {"mode_hat_hw", "mode_hat_bittrue", "mode_hat_float"} <= set(header)
    # the scores under predict's names (mode_score_<k>), not the model's one-hot targets (mode=<k>)
    scores = [f"mode_score_{k}{sfx}" for k in MODES for sfx in ("_hw", "_bittrue", "_float")]
    assert set(scores) <= set(header) and not any("=" in h for h in header), header
    assert sorted(s["targets"]) == sorted(f"mode_score_{k}" for k in MODES)
    c = s["classifier"]
    assert c["class_mismatches"] == 0
    # where the bound applies (float scores at the represented inputs) a difference needs a near tie
    assert c["agreement_float_at_codes"]["differ_outside_margin"] == 0
    assert c["agreement_float"]["agreement"] > 0.95
    rows = [line.split(",") for line in out.read_text().splitlines()[1:]]
    i_hw, i_bt = header.index("mode_hat_hw"), header.index("mode_hat_bittrue")
    assert all(row[i_hw] == row[i_bt] for row in rows)
    # integer classes are written as predict writes them: 2, not 2.0
    assert all(row[header.index(c)].lstrip("-").isdigit() for row in rows for c in ("mode_hat_hw", "mode_hat_bittrue", "mode_hat_float"))
    truth = d.mode[r["rows"]]
    hw = np.array([float(row[i_hw]) for row in rows])
    assert np.mean(hw == truth) > 0.6  # a working mode classifier, not a constant


@pytest.mark.rtl
def test_switched_linear_bench_rtl_rows():
    """`bench switched-linear` rtl rows: the classifier's RTL replay gives the bit-true accuracy / F1 exactly."""
    from pwas_hdl import bench_results as br
    from pwas_hdl.benchmarks.switched_linear import markdown, run_switched_linear

    doc, _ = run_switched_linear(quick=True, rtl="icarus")
    br.validate_results(doc)
    assert doc["config"]["rtl"]["replays"] == 1 and doc["config"]["rtl"]["class_mismatches_vs_bittrue"] == 0
    for tgt in ["mode"] + [f"mode={c}" for c in MODES]:
        (hw,) = br.find_rows(doc, target=tgt, estimator="pwas-classifier", stage="rtl")
        (bt,) = br.find_rows(doc, target=tgt, estimator="pwas-classifier", stage="bittrue")
        assert hw["metric"] == ("accuracy" if tgt == "mode" else "f1")
        assert hw["value"] == bt["value"] and 0.5 < hw["value"] <= 1.0
    assert "| pwas-classifier | rtl |" in markdown(doc)


@pytest.mark.rtl
def test_exported_testbench_checks_the_class(folders, tmp_path):
    """export-testbench of a classifier design: its expected words include the class index (Icarus passes)."""
    import shutil
    import subprocess

    from pwas_hdl.verify.testbench import export_testbench

    if shutil.which("iverilog") is None:
        pytest.skip("iverilog not installed")
    tb = tmp_path / "tb"
    export_testbench(folders["ties-nz4"], tb, samples=200)
    files = (tb / "files.f").read_text().split()
    subprocess.run(["iverilog", "-g2005", "-o", str(tb / "t.vvp"), *[str(tb / f) for f in files]], check=True, capture_output=True)
    run = subprocess.run(["vvp", "-n", str(tb / "t.vvp")], cwd=tb, capture_output=True, text=True, timeout=600)
    assert "PASS" in run.stdout, run.stdout[-2000:]
