"""Non-uniform partitions through ``generate`` / ``simulate`` (issue 15 item 3, hardware).

A model fitted with ``--breakpoints quantile-pow2`` gets the warped designs: ``--design core``
(``n`` input codes -> warp + register -> core) and ``--design sensor`` (one code per signal -> lag
bank -> warp + register -> core), parallel or serial. Checked here: the manifest's ``warp`` entry
and latency, byte-identical reruns, ``load_design`` rebuilding the same bit-true model, the clear
refusals, lint (``verilator -Wall``) and the cocotb bench on Icarus and Verilator (full speed,
stalls and backpressure, a reset mid-stream, input codes outside the domain) bit-exact with the
bit-true model, and ``simulate`` writing the hardware, bit-true and float columns.

A classifier on a power-of-two partition (``fit --classify --breakpoints quantile-pow2``, once refused)
gets the warp, the core and the argmax stage: its manifest (``warp`` and ``classifier``), latency
(``--clock-mhz`` too), the serial core behind a classifier, lint, the cocotb bench with the class
index, ``simulate``, ``report`` and the exported testbench.
"""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest
from typer.testing import CliRunner


@pytest.fixture(scope="module")
def warped_sensor():
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.lorenz import lorenz

    d = lorenz(1200, seed=5)
    m = PWASVirtualSensor(my=2, partitions=5, breakpoints="quantile-pow2", sigma=1e-3, output_names=["y"], target_names=["z"])
    m.fit(None, d.y, d.z)
    return m, d


def test_warped_sensor_manifest(warped_sensor, tmp_path):
    from pwas_hdl.design.generate import generate
    from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel
    from pwas_hdl.verify.simulation import load_design

    m, _ = warped_sensor
    np.testing.assert_array_equal(m.grid_.breakpoints[0], m.grid_.breakpoints[1])  # one set of cuts per signal
    gd = generate(m, tmp_path / "s", design="sensor", input_bits=10)
    man = gd.manifest
    w = man["warp"]
    assert isinstance(gd.model, WarpedFixedPointModel) and any(len(set(d["exps"])) > 1 for d in w["dimensions"])
    assert w["input_bits"] == 10 and w["latency_cycles"] == 1 and w["core_input_bits"] == gd.model.warps[0].width
    assert man["latency_cycles"] == gd.component.core.pipeline.latency(2) + 1
    for dim, b in zip(w["dimensions"], m.grid_.breakpoints):
        np.testing.assert_allclose(dim["breakpoints"], b, rtol=0, atol=0)
    port = next(p for p in man["ports"] if p["role"] == "in.payload")
    assert port["width"] == 10 and [f["signal"] for f in port["fields"]] == ["y"]  # one signal, one 10-bit code
    f = port["fields"][0]
    assert f["domain_codes"] == [gd.model.warps[0].code_breaks[0], gd.model.warps[0].code_breaks[-1]]
    assert f["format"]["offset"] + f["format"]["scale"] * f["domain_codes"][0] == pytest.approx(m.grid_.lo[0])
    assert "warp" in man["formats"]["inputs"][0]["input_scale"]
    d = load_design(tmp_path / "s")  # simulate's bit-true model is the warped one, the same
    assert isinstance(d.model, WarpedFixedPointModel)
    assert [x.to_dict() for x in d.model.warps] == [x.to_dict() for x in gd.model.warps]


def test_warped_lags_of_one_signal_need_one_input_code(warped_sensor):
    from pwas_hdl.errors import InputError
    from pwas_hdl.fit.geometry import Grid
    from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel

    m, _ = warped_sensor
    g = m.grid_
    b1 = np.asarray(g.breakpoints[1])  # the same cells over another (narrower) domain
    g2 = Grid([g.lo[0], b1[0] / 2], [g.hi[0], b1[-1] / 2], g.partitions, breakpoints=[g.breakpoints[0], b1 / 2])
    wm = WarpedFixedPointModel(g2, m.weights_, input_bits=10, regressor_signals=[("y", 1), ("y", 0)])
    with pytest.raises(InputError, match="one code per signal"):
        wm.signal_input_formats()
    assert wm.to_dict()["signals"] is None  # the core design still has one code per regressor


def test_warped_model_flags_as_the_uniform_model(warped_sensor):
    """``predict(return_flags=True)`` and ``quantize_inputs(return_saturated=True)``: the interface of
    FixedPointModel (out of the domain or saturated -> flagged; inside -> not)."""
    from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel

    m, d = warped_sensor
    wm = WarpedFixedPointModel.from_sensor(m, input_bits=10)
    lo, hi = m.grid_.lo, m.grid_.hi
    mid = (lo + hi) / 2
    far = hi + 1e6 * (hi - lo)  # saturates the code range
    past = hi + 0.03 * (hi - lo)  # a code beyond the domain, inside the range (fill 0.9)
    x = np.vstack([mid, far, past])
    q, sat = wm.quantize_inputs(x, return_saturated=True)
    np.testing.assert_array_equal(q, wm.quantize_inputs(x))
    assert sat.tolist() == [False, True, False]
    z, flags = wm.predict(x, return_flags=True)
    np.testing.assert_array_equal(z, wm.predict(x))
    assert flags.tolist() == [False, True, True]


@pytest.mark.parametrize("extra, msg", [(["--design", "recurrent"], "recurrent"),
                                        (["--input-scale", "exact"], "--input-scale must be 'pow2'")])
def test_generate_warped_refusals_are_one_error_line(extra, msg, warped_sensor, tmp_path):
    from pwas_hdl.cli import app

    m, _ = warped_sensor
    m.save(tmp_path / "m.json")
    r = CliRunner().invoke(app, ["generate", str(tmp_path / "m.json"), "-o", str(tmp_path / "g"), *extra])
    assert r.exit_code == 2, r.output
    assert [ln for ln in r.output.splitlines() if ln.startswith("error:")] and msg in r.output, r.output
    assert "Traceback" not in r.output and not (tmp_path / "g").exists()


def _lint_and_codes(gd, folder, simulator: str, t: int):
    """The written design ``folder`` of ``gd`` (lint-clean under Verilator, whichever simulator runs it:
    a lint costs ~1 s, a Verilator build ~20 s) and ``t`` input transfers of codes: every breakpoint
    +- 1 and the whole code range in each column, the columns shuffled independently."""
    from pwas_hdl.flow.toolchain import tool_env
    from pwas_hdl.verify.simulation import load_design

    env = tool_env()
    exe = shutil.which("verilator", path=env.get("PATH"))
    r = subprocess.run([exe, "--lint-only", "-Wall", f"{gd.top}.v"], capture_output=True, text=True, env=env, cwd=folder)
    assert r.returncode == 0, r.stderr
    wm = gd.model
    rng = np.random.default_rng(11)
    lo, hi = wm.code_range
    breaks = np.array(wm.warps[0].code_breaks)
    d = load_design(folder)
    ncol = len(d.in_fields)
    codes = np.stack([_codes(rng, lo, hi, breaks, t) for _ in range(ncol)], axis=1)
    for j in range(1, ncol):
        codes[:, j] = rng.permutation(codes[:, j])
    return d, codes


def _codes(rng, lo, hi, breaks, t):
    """Random input codes over the whole code range (outside the domain too) and every breakpoint +- 1."""
    near = np.concatenate([breaks - 1, breaks, breaks + 1])
    near = np.repeat(np.clip(near, lo, hi), 3)
    return np.concatenate([rng.integers(lo, hi + 1, t), near, [lo, hi, lo, hi]]).astype(np.int64)


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.parametrize("opts", [
    dict(design="core", pipeline="min", memory="corner", ports="amaranth"),
    dict(design="sensor", pipeline="short", memory="replicated", memory_init="readmemh"),
    dict(design="sensor", pipeline="max-lut", input_bits=7, weight_bits=12, output_bits=11, overflow="saturate"),
], ids=["core-min-corner-amaranth", "sensor-short-replicated-readmemh", "sensor-maxlut-odd-widths"])
def test_warped_option_sets_lint_clean_and_byte_identical(warped_sensor, tmp_path, opts):
    """The warp in front of other pipelines, memories, ports and word lengths than the cocotb tests below
    build (their lint covers the max core and the balanced sensor, parallel and serial; the 11-bit output
    saturates, so its warning is expected): clean under
    verilator -Wall, every warning fatal, and byte-identical when built again."""
    from pwas_hdl.design.generate import build_design, generate
    from pwas_hdl.flow.toolchain import lint_verilog

    m, _ = warped_sensor
    gd = generate(m, tmp_path / "d", **opts)
    assert "warp" in gd.manifest and build_design(m, **opts).files == gd.files
    r = lint_verilog(tmp_path / "d" / f"{gd.top}.v", gd.top)
    assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[-3000:]


@pytest.mark.rtl
@pytest.mark.parametrize("design, arch, simulator", [
    ("core", "parallel", "icarus"), ("core", "parallel", "verilator"), ("core", "serial", "icarus"),
    ("sensor", "parallel", "verilator"),  # sensor-parallel on Icarus: the simulate test below
    ("sensor", "serial", "icarus"), ("sensor", "serial", "verilator"),
])
def test_warped_design_in_cocotb_bit_exact(design, arch, simulator, warped_sensor, sim_cache, tmp_path):
    from pwas_hdl.design.generate import build_design, generate
    from pwas_hdl.verify.simulation import run_rtl, standard_runs

    m, _ = warped_sensor
    pipe = "max" if arch == "parallel" and design == "core" else None
    gd = generate(m, tmp_path / "d", design=design, architecture=arch, input_bits=10, pipeline=pipe)
    if simulator == "verilator":  # byte-identical when built again
        assert build_design(m, design=design, architecture=arch, input_bits=10, pipeline=pipe).files == gd.files
    d, codes = _lint_and_codes(gd, tmp_path / "d", simulator, 120)
    runs = standard_runs(d, codes, seed=3)
    oor = np.concatenate([s.oor for r in runs for s in r.segments])
    assert oor.any() and not oor.all()  # inputs outside the domain, flagged
    res = run_rtl(d, runs, simulator, cache_dir=sim_cache, strict=False)
    assert res.passed, res.report()
    # every output but those a reset mid-stream drops in flight
    assert res.mismatches == 0 and res.outputs >= sum(len(s.expected) for r in runs for s in r.segments if s.drain)
    assert set(res.latencies) == {gd.manifest["latency_cycles"]} and res.ii == gd.manifest["ii"]
    assert res.within_bound


@pytest.mark.rtl
def test_simulate_writes_hw_beside_bittrue_and_float(warped_sensor, sim_cache, tmp_path):
    from pwas_hdl.cli import app
    from pwas_hdl.io.csv_table import read_csv

    m, d = warped_sensor
    m.save(tmp_path / "m.json")
    (tmp_path / "data.csv").write_text("y,z_true\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(d.y[:300, 0], d.z_true[:300, 0])))
    run = CliRunner().invoke
    r = run(app, ["generate", str(tmp_path / "m.json"), "--design", "sensor", "-o", str(tmp_path / "g")])
    assert r.exit_code == 0, r.output
    r = run(app, ["simulate", str(tmp_path / "g"), str(tmp_path / "data.csv"), "-o", str(tmp_path / "hw.csv"),
                  "--simulator", "icarus", "--build-dir", str(sim_cache)])
    assert r.exit_code == 0, r.output
    s = json.loads((tmp_path / "hw.json").read_text())
    assert s["mismatches"] == 0 and s["samples"] == 299 and s["within_error_bound"] and s["checks"]["passed"]
    t = read_csv(tmp_path / "hw.csv")
    hw, bt, fl = (t.numeric([c])[:, 0] for c in ("z_hw", "z_bittrue", "z_float"))
    np.testing.assert_array_equal(hw, bt)
    np.testing.assert_allclose(fl, m.predict(None, d.y[:300])[:, 0], rtol=1e-12)
    assert np.max(np.abs(hw - fl)) < 0.05 * np.std(fl)  # quantised, close to the float sensor


@pytest.mark.synth
def test_warped_sensor_synth_and_report(warped_sensor, tmp_path):
    """``synth`` (Yosys, generic target) and ``report`` read the warped folder."""
    from pwas_hdl import collect_report, report_markdown, synthesize
    from pwas_hdl.design.generate import generate

    m, _ = warped_sensor
    generate(m, tmp_path / "g", design="sensor", input_bits=10)
    r = synthesize(tmp_path / "g", "generic")
    assert r["luts"] > 0 and r["dsp"] >= 0 and r["latency_cycles"] == 8
    md = report_markdown(collect_report(tmp_path / "g", []))
    assert "generic" in md and "inputs s10.0" in md
    assert "## Non-uniform partition" in (tmp_path / "g" / "report.md").read_text()


# --- a classifier (fit --classify) on a non-uniform partition: warp register -> core -> argmax stage ---

CLASSES = (0.0, 1.0, 2.0)


@pytest.fixture(scope="module")
def warped_classifier():
    """Three classes of the Lorenz z (its tertiles) from y, My = 2, p = 5 quantile-pow2 cells: the warp,
    the uniform core's 3 one-hot scores and the argmax stage."""
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.lorenz import lorenz

    d = lorenz(1200, seed=5)
    z = d.z[:, 0]
    labels = np.digitize(z, np.quantile(z, [1 / 3, 2 / 3])).astype(float)
    m = PWASVirtualSensor(my=2, partitions=5, breakpoints="quantile-pow2", sigma=1e-3, classify=True, output_names=["y"],
                          target_names=["c"]).fit(None, d.y, labels)
    assert m.classifier_ == {"target": "c", "classes": list(CLASSES)}
    return m, d, labels


@pytest.mark.parametrize("design", ["core", "sensor"])
def test_warped_classifier_manifest_header_report_and_reruns(design, warped_classifier, tmp_path):
    """Both entries (warp, classifier), schema-valid and consistent; the latency is the core's + the warp
    register + the argmax stage; the class index is the output payload's top field; byte-identical reruns;
    simulate's bit-true model is the warped one and its expected rows end with the class index."""
    from pwas_hdl.design.generate import build_design, generate
    from pwas_hdl.design.manifest import manifest_errors
    from pwas_hdl.fixedpoint.argmax import argmax_index
    from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel
    from pwas_hdl.hdl.argmax import argmax_latency
    from pwas_hdl.verify.simulation import load_design, segment

    m, _, _ = warped_classifier
    gd = generate(m, tmp_path / "d", design=design, input_bits=10, pipeline="max")
    man = gd.manifest
    assert manifest_errors(json.loads((tmp_path / "d" / "manifest.json").read_text())) == []
    w, c = man["warp"], man["classifier"]
    assert isinstance(gd.model, WarpedFixedPointModel) and any(len(set(dim["exps"])) > 1 for dim in w["dimensions"])
    assert w["input_bits"] == 10 and w["latency_cycles"] == 1
    assert c["classes"] == list(CLASSES) and c["n_classes"] == 3 and c["target"] == "c"
    assert c["stage_latency_cycles"] == argmax_latency(3, "max") == 2
    assert man["latency_cycles"] == gd.component.core.pipeline.latency(2) + 1 + 2 == gd.component.latency
    inp = next(p for p in man["ports"] if p["role"] == "in.payload")
    assert [f["width"] for f in inp["fields"]] == [10] * (2 if design == "core" else 1)  # B_in-bit codes in front of the warp
    out = next(p for p in man["ports"] if p["role"] == "out.payload")
    f = out["fields"][-1]
    assert (f["name"], f["lsb"], f["width"]) == ("class_index", c["lsb"], c["width"]) and c["lsb"] + c["width"] == out["width"]
    assert [g["name"] for g in out["fields"][:3]] == c["scores"] == ["c=0", "c=1", "c=2"]
    header = gd.files[f"{gd.top}.v"].split("\n/*")[0]
    assert "classifier of c (3 classes" in header and "non-uniform partition" in header
    report = gd.files["report.md"]
    assert "## Classifier" in report and "## Non-uniform partition" in report
    assert build_design(m, design=design, input_bits=10, pipeline="max").files == gd.files
    d = load_design(tmp_path / "d")
    assert isinstance(d.model, WarpedFixedPointModel) and d.latency == man["latency_cycles"]
    lo, hi = d.model.code_range
    codes = np.random.default_rng(2).integers(lo, hi + 1, (40, len(d.in_fields)))
    seg = segment(d, codes)
    assert seg.rows().shape[1] == 3 + 1 + 1 and np.array_equal(seg.rows()[:, -1], argmax_index(seg.expected))
    assert len(set(seg.cls.tolist())) > 1


@pytest.mark.parametrize("design", ["core", "sensor"])
def test_warped_classifier_on_the_serial_core(design, warped_classifier):
    """``--architecture serial`` (was refused, as for a uniform classifier): warp register -> serial core ->
    argmax stage, II = n + 1, latency = the serial core's + 1 + the stage's; the uniform classifier gets
    the same stage after its serial core. (Bit-exact RTL: tests/test_serial_classifier.py.)"""
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.hdl.argmax import argmax_latency
    from pwas_hdl.hdl.params import Pipeline
    from pwas_hdl.hdl.serial_core import serial_latency

    m, d, labels = warped_classifier
    uniform = PWASVirtualSensor(my=2, partitions=3, sigma=1e-3, classify=True, output_names=["y"],
                                target_names=["c"]).fit(None, d.y, labels)
    for model, warp in ((uniform, 0), (m, 1)):
        man = build_design(model, design=design, architecture="serial", pipeline="max").manifest
        assert man["architecture"]["kind"] == "serial" and man["ii"] == 3 and ("warp" in man) == bool(warp)
        assert man["classifier"]["stage_latency_cycles"] == argmax_latency(3, "max") == 2
        assert man["latency_cycles"] == serial_latency(Pipeline.cast("max"), 2) + warp + 2


def test_warped_classifier_clock_mhz_counts_warp_and_argmax(warped_classifier, monkeypatch):
    """``--clock-mhz``: every candidate's latency is the built design's (core + warp register + argmax stage,
    whose registers follow the candidate's pipeline); the chosen one is the shallowest that meets the target."""
    from helpers.timing import FakePlaceAndRoute

    import pwas_hdl.flow.timing_closure as tc
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.hdl import Pipeline
    from pwas_hdl.hdl.argmax import argmax_latency

    m, _, _ = warped_classifier
    fake = FakePlaceAndRoute(mhz_per_cycle=11.0)
    monkeypatch.setattr(tc, "measure_design", fake)
    gd = build_design(m, design="sensor", target_mhz=100.0)
    man, tm = gd.manifest, gd.manifest["timing"]
    assert "warp" in man and "classifier" in man and tm["met"]
    cands = tm["candidates"]
    for cand in cands:
        assert cand["latency_cycles"] == Pipeline.cast(cand["pipeline"]).latency(2) + 1 + argmax_latency(3, cand["pipeline"])
    chosen = cands[tm["chosen"]]
    assert man["latency_cycles"] == chosen["latency_cycles"] == min(c["latency_cycles"] for c in cands if c["latency_cycles"] * 11.0 >= 100)
    assert fake.built and all(lat == c["latency_cycles"] for (p, lat), c in zip(sorted(fake.built, key=lambda b: b[1]),
                                                                             [c for c in cands if c["measured"]]))


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.parametrize("opts", [
    dict(design="sensor", pipeline="min", ports="amaranth"),  # the argmax stage combinational from the output register
    dict(design="core", pipeline="short", memory="corner", memory_init="readmemh"),
], ids=["sensor-min-amaranth", "core-short-corner-readmemh"])
def test_warped_classifier_option_sets_lint_clean(warped_classifier, tmp_path, opts):
    """Other pipelines, memories and ports than the cocotb tests below: clean under verilator -Wall."""
    from pwas_hdl.design.generate import generate
    from pwas_hdl.flow.toolchain import lint_verilog

    m, _, _ = warped_classifier
    gd = generate(m, tmp_path / "d", input_bits=10, **opts)
    assert "warp" in gd.manifest and "classifier" in gd.manifest
    r = lint_verilog(tmp_path / "d" / f"{gd.top}.v", gd.top)
    assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[-3000:]


@pytest.mark.rtl
@pytest.mark.parametrize("design, pipe, simulator", [
    ("core", "max", "icarus"), ("sensor", None, "icarus"), ("sensor", None, "verilator"),  # Verilator: the sensor (core inside)
])
def test_warped_classifier_in_cocotb_bit_exact(design, pipe, simulator, warped_classifier, sim_cache, tmp_path):
    """Scores, flag and class index equal the bit-true model (warp, core, argmax) at full speed, with stalls
    and backpressure and with a reset mid-stream; latency and II as the manifest says; lint-clean."""
    from pwas_hdl.design.generate import generate
    from pwas_hdl.fixedpoint.argmax import argmax_index
    from pwas_hdl.verify.simulation import run_rtl, standard_runs

    m, _, _ = warped_classifier
    gd = generate(m, tmp_path / "d", design=design, input_bits=10, pipeline=pipe)
    d, codes = _lint_and_codes(gd, tmp_path / "d", simulator, 100)
    runs = standard_runs(d, codes, seed=3)
    res = run_rtl(d, runs, simulator, cache_dir=sim_cache, work_dir=tmp_path / "w", strict=False)
    assert res.passed, res.report()
    assert res.mismatches == 0 and res.outputs >= sum(len(s.expected) for r in runs for s in r.segments if s.drain)
    assert set(res.latencies) == {gd.manifest["latency_cycles"]} and res.ii == 1.0
    for run, hw_run, cls_run in zip(runs, res.hw, res.hw_class):  # the class index was read and is the bit-true argmax
        for seg, (z, _), cls in zip(run.segments, hw_run, cls_run):
            assert len(cls) and np.array_equal(cls, argmax_index(z)) and np.array_equal(cls, seg.cls[: len(cls)])
    assert set(np.concatenate([c for r in res.hw_class for c in r]).tolist()) == {0, 1, 2}


@pytest.mark.rtl
def test_warped_classifier_simulate_report_and_exported_testbench(warped_classifier, sim_cache, tmp_path):
    """`simulate` on CSV data (0 mismatches, the class columns of RTL and bit-true equal), `report` shows the
    classifier table, and the exported testbench (expected words with the class index) passes on Icarus."""
    from pwas_hdl.cli import app
    from pwas_hdl.io.csv_table import read_csv
    from pwas_hdl.verify.testbench import export_testbench

    m, d, labels = warped_classifier
    m.save(tmp_path / "m.json")
    (tmp_path / "data.csv").write_text("y,c\n" + "".join(f"{float(a)!r},{int(b)}\n" for a, b in zip(d.y[:300, 0], labels[:300])))
    run = CliRunner().invoke
    r = run(app, ["generate", str(tmp_path / "m.json"), "--design", "sensor", "--input-bits", "10", "-o", str(tmp_path / "g")])
    assert r.exit_code == 0, r.output
    r = run(app, ["simulate", str(tmp_path / "g"), str(tmp_path / "data.csv"), "-o", str(tmp_path / "hw.csv"),
                  "--simulator", "icarus", "--build-dir", str(sim_cache)])
    assert r.exit_code == 0, r.output
    s = json.loads((tmp_path / "hw.json").read_text())
    assert s["mismatches"] == 0 and s["samples"] == 299 and s["checks"]["passed"]
    c = s["classifier"]
    assert c["class_mismatches"] == 0 and c["agreement_float_at_codes"]["differ_outside_margin"] == 0
    t = read_csv(tmp_path / "hw.csv")
    hw, bt = (t.numeric([col])[:, 0] for col in ("c_hat_hw", "c_hat_bittrue"))
    np.testing.assert_array_equal(hw, bt)
    assert set(hw.tolist()) <= set(CLASSES) and len(set(hw.tolist())) > 1
    r = run(app, ["report", str(tmp_path / "g"), "--sim", str(tmp_path / "hw.json")])
    assert r.exit_code == 0, r.output
    assert "## Classifier (class index of the RTL" in r.output and "| icarus | 299 | 0 |" in r.output
    if shutil.which("iverilog") is None:
        pytest.skip("iverilog not installed")
    tb = tmp_path / "tb"
    export_testbench(tmp_path / "g", tb, samples=200)
    files = (tb / "files.f").read_text().split()
    subprocess.run(["iverilog", "-g2005", "-o", str(tb / "t.vvp"), *[str(tb / f) for f in files]], check=True, capture_output=True)
    res = subprocess.run(["vvp", "-n", str(tb / "t.vvp")], cwd=tb, capture_output=True, text=True, timeout=600)
    assert "PASS" in res.stdout, res.stdout[-2000:]
