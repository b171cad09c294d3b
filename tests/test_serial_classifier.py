"""Classifiers on the serial architecture (``generate --architecture serial`` of a ``fit --classify`` model).

The argmax stage (:mod:`pwas_hdl.hdl.argmax`) after the serial core (:mod:`pwas_hdl.hdl.serial_core`)
or after the serial additive sum (:mod:`pwas_hdl.hdl.additive_top`), joined by the same
``inline_core_and_argmax`` as the parallel designs: the stage's registers advance with its own output
handshake, the core's output register feeds it, and a stalled stage stalls the core and its input
throttle as a stalled sink would. Once refused ("the argmax stage follows the parallel core only").

Configurations: ``sim/pwas_designs.CLASSIFIER_SERIAL_CONFIGS`` (a plain core with forced ties and two
argmax registers, an additive core with parts of 1 to 3 dimensions, an additive sensor top with a 1-
and a 3-dimensional part on the ``min`` pipeline) and the Lorenz classifier on a power-of-two partition
of ``tests/test_warped_design.py``. Checked: manifest (II, latency = the serial core's + the stage's,
architecture, classifier), header and report, byte-identical reruns, Verilator lint, cocotb on Icarus
and Verilator (full speed, stalls and backpressure, a reset mid-stream) bit-exact with the bit-true
model including the class index, sample for sample equal to the parallel design, a flipped weight
caught; and from the CLI: fit --classify -> generate --architecture serial -> simulate -> report ->
export-testbench (PASS; FAIL on a flipped weight and on a wrong expected class index).
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from helpers.cli import CliRunner
from helpers.design_cache import DesignCache, parallel_twin

from pwas_hdl.fixedpoint.argmax import argmax_index
from pwas_hdl.verify.simulation import Run, load_design, run_rtl, segment, sim_module, standard_runs
from test_warped_design import warped_classifier  # noqa: F401  (the Lorenz classifier on a power-of-two partition)

designs = sim_module("pwas_designs")
stimulus = sim_module("pwas_stimulus")
mutations = sim_module("pwas_mutations")
CFG = {c.name: c for c in designs.CLASSIFIER_SERIAL_CONFIGS}


def _parallel_twin(cfg):
    return parallel_twin(cfg, f"par-{cfg.name}")


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    return DesignCache(tmp_path_factory.mktemp("serial_classifier"))


def _codes(d, seed: int, m: int = 200) -> np.ndarray:
    return stimulus.design_codes(d, m, seed=seed)


def _expected_latency(man: dict, pipeline) -> int:
    """The serial core's latency (of the largest part + the sum register, additive) + the argmax stage's."""
    from pwas_hdl.hdl.argmax import argmax_latency
    from pwas_hdl.hdl.params import Pipeline
    from pwas_hdl.hdl.serial_core import serial_latency

    pl = Pipeline.cast(pipeline)
    stage = argmax_latency(man["classifier"]["n_classes"], pl)
    if "additive" in man:
        return serial_latency(pl, max(len(p["regressors"]) for p in man["additive"]["parts"])) + 1 + stage
    return serial_latency(pl, len(man["lags"]["regressors"])) + stage


@pytest.mark.parametrize("name", list(CFG))
def test_manifest_header_and_report_say_serial_and_classifier(name, folders):
    from pwas_hdl.design.manifest import manifest_errors

    cfg = CFG[name]
    folder = folders(cfg)
    man = json.loads((folder / "manifest.json").read_text())
    assert manifest_errors(man) == []
    c = man["classifier"]
    assert c["n_classes"] == cfg.nz and c["classes"] == [float(v) for v in cfg.classes]
    n_max = (max(len(p["regressors"]) for p in man["additive"]["parts"]) if cfg.additive else cfg.n)
    assert man["architecture"]["kind"] == "serial" and man["ii"] == n_max + 1 == man["architecture"]["ii"]
    assert man["latency_cycles"] == _expected_latency(man, cfg.options.get("pipeline"))
    assert man["generator"]["options"]["architecture"] == "serial" and man["memory"]["kind"] == "single"
    out = next(p for p in man["ports"] if p["role"] == "out.payload")
    assert out["fields"][-1]["name"] == "class_index" and c["lsb"] + c["width"] == out["width"]
    header = (folder / f"{man['top']}.v").read_text().split("\n/*")[0]
    what = "serial additive sum" if cfg.additive else "serial core"
    assert f"argmax stage after the {what} (one class index every {man['ii']} clocks)" in header
    assert f"II {man['ii']} (one sample every {man['ii']} clocks)" in header
    rep = (folder / "report.md").read_text()
    assert "## Classifier" in rep and f"stage after the {what}" in rep and "serial architecture" in rep


def test_rerun_is_byte_identical(tmp_path):
    cfg = CFG["acs-s-u2y2-1+3-cls3-ties-min"]
    assert cfg.generate(tmp_path / "a").files == cfg.generate(tmp_path / "b").files


@pytest.mark.rtl
@pytest.mark.parametrize("name", list(CFG))
def test_serial_classifier_rtl_is_lint_clean(name, folders, tmp_path):
    from pwas_hdl.flow.toolchain import lint_verilog

    for init in ("inline", "readmemh"):
        d = load_design(folders(CFG[name], init))
        path = tmp_path / init / f"{d.top}.v"
        path.parent.mkdir()
        path.write_text(d.verilog)
        r = lint_verilog(path)
        assert r.returncode == 0 and not r.stderr.strip(), r.stderr


def _class_checks(res, runs) -> set:
    """The class index was read, is the argmax of the RTL's scores and the bit-true class; the classes seen."""
    seen: set = set()
    for run, hw_run, cls_run in zip(runs, res.hw, res.hw_class):
        for seg, (z, _), cls in zip(run.segments, hw_run, cls_run):
            assert np.array_equal(cls, argmax_index(z)) and np.array_equal(cls, seg.cls[: len(cls)])
            seen |= set(cls.tolist())
    return seen


@pytest.mark.rtl
# every configuration on Icarus (against the parallel design too); Verilator on the additive sensor
# (the CI budget; the random sweeps of benchmarks/rtl_random_configs.py run serial classifiers on both)
@pytest.mark.parametrize("name, simulator", [(n, "icarus") for n in CFG] + [("acs-s-u2y2-1+3-cls3-ties-min", "verilator")])
def test_serial_classifier_rtl_bit_exact_with_model_and_parallel(name, simulator, folders, sim_cache, tmp_path):
    """Full speed (II from the handshake), stalls and backpressure, a mid-stream reset: scores, flag and
    class index equal the bit-true model; on Icarus also the parallel design's, sample for sample."""
    cfg = CFG[name]
    d = load_design(folders(cfg))
    codes = _codes(d, seed=23)
    runs = standard_runs(d, codes, seed=23)
    res = run_rtl(d, runs, simulator, cache_dir=sim_cache, work_dir=tmp_path / "s", debug=False)
    assert res.passed and res.mismatches == 0, res.report()
    assert set(res.latencies) == {d.latency} == {int(d.manifest["latency_cycles"])}, res.report()
    assert res.ii == float(d.manifest["ii"]) > 1
    assert res.outputs >= 2 * len(segment(d, codes).src)
    # every class wins somewhere, except with forced ties class 1 (score 1 = score 0: the lowest index wins)
    assert _class_checks(res, runs) == set(range(cfg.nz)) - ({1} if cfg.ties else set())
    if simulator != "icarus":
        return
    dp = load_design(folders(_parallel_twin(cfg)))
    assert dp.manifest["ii"] == 1 and dp.manifest["classifier"] == d.manifest["classifier"]
    resp = run_rtl(dp, standard_runs(dp, codes, seed=23), simulator, cache_dir=sim_cache, work_dir=tmp_path / "p", debug=False)
    assert resp.passed, resp.report()
    compared = 0
    for run, ra, rb, ca, cb in zip(runs, res.hw, resp.hw, res.hw_class, resp.hw_class):
        for seg, (zs, os_), (zp, op), ks, kp in zip(run.segments, ra, rb, ca, cb):
            k = min(len(zs), len(zp))
            np.testing.assert_array_equal(zs[:k], zp[:k])
            np.testing.assert_array_equal(os_[:k], op[:k])
            np.testing.assert_array_equal(ks[:k], kp[:k])
            compared += k
    assert compared >= 2 * len(segment(d, codes).src)


@pytest.mark.rtl
@pytest.mark.parametrize("name, simulator", [("cs-c-n2-nz4-ties-max", "verilator"), ("acs-s-u2y2-1+3-cls3-ties-min", "icarus")])
def test_flipped_weight_is_caught(name, simulator, folders, sim_cache, tmp_path):
    """A corrupted weight bit (target 0 of the first vertex, worth two output LSBs): the bench fails."""
    d = load_design(folders(CFG[name]))
    fx = d.model
    part = None
    if CFG[name].additive:
        dims = [len(s) for s in fx.subsets]
        part = dims.index(min(dims))
    bit = fx.weight_format.frac - fx.output_format.frac + 1
    text, desc = mutations.flip_weight_bit(d.verilog, 0, 0, bit, part=part)
    assert text != d.verilog
    path = tmp_path / f"{d.top}.v"
    path.write_text(text)
    dm = load_design(d.outdir, verilog=path)
    codes = _codes(d, seed=29, m=300)
    res = run_rtl(dm, [Run("full-speed", [segment(dm, codes)])], simulator, cache_dir=sim_cache, work_dir=tmp_path / "run",
                  debug=False)
    assert not res.passed and res.mismatches > 0, f"{desc}: the testbench did not notice\n{res.report()}"


@pytest.mark.rtl
@pytest.mark.parametrize("design", ["core", "sensor"])
def test_warped_serial_classifier_bit_exact_on_icarus(design, warped_classifier, sim_cache, tmp_path):  # noqa: F811
    """Warp register -> serial core -> argmax stage (pipeline max: 2 stage registers): bit-exact with the
    warped bit-true model including the class index, at full speed, with stalls and a mid-stream reset."""
    from pwas_hdl.design.generate import generate
    from pwas_hdl.flow.toolchain import lint_verilog

    m, _, _ = warped_classifier
    gd = generate(m, tmp_path / "d", design=design, input_bits=10, pipeline="max", architecture="serial")
    man = gd.manifest
    assert "warp" in man and "classifier" in man and man["architecture"]["kind"] == "serial" and man["ii"] == 3
    assert man["latency_cycles"] == _expected_latency(man, "max") + 1  # + the warp register
    r = lint_verilog(tmp_path / "d" / f"{gd.top}.v", gd.top)
    assert r.returncode == 0 and not r.stderr.strip(), r.stderr[-3000:]
    d = load_design(tmp_path / "d")
    codes = _codes(d, seed=31, m=120)
    runs = standard_runs(d, codes, seed=31)
    res = run_rtl(d, runs, "icarus", cache_dir=sim_cache, work_dir=tmp_path / "w", debug=False)
    assert res.passed and res.mismatches == 0, res.report()
    assert set(res.latencies) == {man["latency_cycles"]} and res.ii == 3.0
    assert _class_checks(res, runs) == {0, 1, 2}


def _fit(tmp_path: Path, kind: str) -> Path:
    """fit --classify of the switched plant's mode (3 classes): plain, additive (parts of 1 and 3
    dimensions) or on a power-of-two partition."""
    from pwas_hdl.cli import app

    run = CliRunner().invoke
    data = tmp_path / "train.csv"
    if not data.exists():
        r = run(app, ["make-data", "switched-linear", "-o", str(data), "--runs", "3", "--samples", "400", "--seed", "0"])
        assert r.exit_code == 0, r.output
        r = run(app, ["make-data", "switched-linear", "-o", str(tmp_path / "test.csv"), "--runs", "2", "--samples", "120",
                      "--seed", "7"])
        assert r.exit_code == 0, r.output
    extra = {"plain": ["--mu", "2", "--my", "2"], "additive": ["--mu", "2", "--my", "2", "--additive", "0;1,2,3"],
             "warped": ["--mu", "1", "--my", "2", "--breakpoints", "quantile-pow2"]}[kind]
    model = tmp_path / f"{kind}.json"
    r = run(app, ["fit", str(data), "-o", str(model), "-u", "u", "-y", "y", "-z", "mode", "--classify", "-p", "3",
                  "--traj-col", "run", *extra])
    assert r.exit_code == 0, r.output
    return model


@pytest.mark.rtl
@pytest.mark.parametrize("kind, design, simulator", [("plain", "sensor", "icarus"), ("additive", "core", "icarus"),
                                                     ("warped", "sensor", "icarus")])
def test_cli_fit_generate_simulate_report_export(kind, design, simulator, sim_cache, tmp_path):
    """From the CLI: fit --classify -> generate --architecture serial -> simulate (stalls, one reset per
    trajectory): 0 mismatches and 0 class mismatches; report's classifier table; the exported testbench
    passes, and fails on a flipped weight and on a wrong expected class index."""
    from pwas_hdl.cli import app
    from pwas_hdl.io.csv_table import read_csv

    run = CliRunner().invoke
    model = _fit(tmp_path, kind)
    g = tmp_path / "g"
    r = run(app, ["generate", str(model), "-o", str(g), "--design", design, "--architecture", "serial"])
    assert r.exit_code == 0, r.output
    man = json.loads((g / "manifest.json").read_text())
    assert man["architecture"]["kind"] == "serial" and "classifier" in man and man["ii"] > 1
    r = run(app, ["simulate", str(g), str(tmp_path / "test.csv"), "-o", str(tmp_path / "hw.csv"), "--simulator", simulator,
                  "--traj-col", "run", "--stall", "0.3", "--seed", "2", "--build-dir", str(sim_cache)])
    assert r.exit_code == 0, r.output
    s = json.loads((tmp_path / "hw.json").read_text())
    assert s["mismatches"] == 0 and s["checks"]["passed"] and s["trajectories"] == 2
    assert s["classifier"]["class_mismatches"] == 0
    assert s["latency_cycles"]["measured_min"] == man["latency_cycles"]
    t = read_csv(tmp_path / "hw.csv")
    hw, bt = (t.numeric([col])[:, 0] for col in ("mode_hat_hw", "mode_hat_bittrue"))
    np.testing.assert_array_equal(hw, bt)
    assert len(set(hw.tolist())) > 1
    r = run(app, ["report", str(g), "--sim", str(tmp_path / "hw.json")])
    assert r.exit_code == 0, r.output
    assert "## Classifier (class index of the RTL" in r.output
    assert f"II {man['ii']} (serial architecture; classifier of mode (3 classes): argmax stage" in r.output
    if shutil.which("iverilog") is None:
        pytest.skip("iverilog not installed")
    tb = tmp_path / "tb"
    r = run(app, ["export-testbench", str(g), "-o", str(tb), "--samples", "200"])
    assert r.exit_code == 0, r.output

    def icarus(folder: Path) -> subprocess.CompletedProcess:
        files = (folder / "files.f").read_text().split()
        subprocess.run(["iverilog", "-g2005", "-o", str(folder / "t.vvp"), *[str(folder / f) for f in files]], check=True,
                       capture_output=True)
        return subprocess.run(["vvp", "-n", str(folder / "t.vvp")], cwd=folder, capture_output=True, text=True, timeout=600)

    res = icarus(tb)
    assert res.returncode == 0 and "PASS" in res.stdout and f"II {man['ii']}" in res.stdout, res.stdout[-2000:]
    top = man["top"]
    bad = tmp_path / "bad-weight"
    shutil.copytree(tb, bad)
    v = (bad / f"{top}.v").read_text()
    mem = "part0_wmem0" if kind == "additive" else "wmem0"
    text, _ = mutations.flip_weight_bit(v, 0, 0, man["formats"]["weight"]["bits"] - 2, part=0 if kind == "additive" else None)
    (bad / f"{top}.v").write_text(text)
    assert mem in text
    res = icarus(bad)
    assert res.returncode != 0 and "FAIL" in res.stdout, res.stdout[-2000:]
    # the class index is compared: a wrong expected class (the other index bit values) fails
    bad = tmp_path / "bad-class"
    shutil.copytree(tb, bad)
    exp = bad / f"{top}_tb_expected.hex"
    lines = exp.read_text().splitlines()
    c = man["classifier"]
    k = next(i for i, ln in enumerate(lines) if ln.strip() and int(ln, 16) >> c["lsb"] == 0)
    lines[k] = f"{int(lines[k], 16) ^ (1 << c['lsb']):0{len(lines[k])}x}"
    exp.write_text("\n".join(lines) + "\n")
    res = icarus(bad)
    assert res.returncode != 0 and "FAIL" in res.stdout, res.stdout[-2000:]


@pytest.mark.rtl
@pytest.mark.parametrize("name, simulator", [("acs-c-n4-cls2-max", "icarus"), ("cs-c-n2-nz4-ties-max", "verilator")])
def test_readmemh_serial_classifier_equals_bittrue_model(name, simulator, folders, sim_cache, tmp_path):
    """``--memory-init readmemh``: the weights from the hex files, the class index as with inline init."""
    d = load_design(folders(CFG[name], "readmemh"))
    assert d.manifest["memory"]["init"]["kind"] == "readmemh" and "classifier" in d.manifest
    assert '$readmemh({MEM_DIR, "' in d.verilog and "wmem0[0] =" not in d.verilog
    codes = _codes(d, seed=37, m=150)
    runs = standard_runs(d, codes, seed=37)
    res = run_rtl(d, runs, simulator, cache_dir=sim_cache, work_dir=tmp_path, debug=False)
    assert res.passed and res.mismatches == 0, res.report()
    assert set(res.latencies) == {d.latency} and res.ii == float(d.manifest["ii"])
    assert len(_class_checks(res, runs)) > 1


@pytest.mark.parametrize("kind, design", [("additive", "sensor"), ("warped", "core")])
def test_clock_mhz_search_counts_the_stage_on_the_serial_core(kind, design, warped_classifier, monkeypatch):  # noqa: F811
    """``--clock-mhz`` (fake place and route): every candidate's latency is the serial design's (the
    serial core, + the sum register or the warp register) + the argmax stage's registers, as built."""
    import pwas_hdl.flow.timing_closure as tc
    from helpers.timing import FakePlaceAndRoute
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.hdl.argmax import argmax_latency

    additive = CFG["acs-c-n4-cls2-max" if design == "core" else "acs-s-u2y2-1+3-cls3-ties-min"]
    model = additive.model() if kind == "additive" else warped_classifier[0]
    fake = FakePlaceAndRoute(mhz_per_cycle=9.0)
    monkeypatch.setattr(tc, "measure_design", fake)
    gd = build_design(model, design=design, target_mhz=100.0, architecture="serial")
    man, tm = gd.manifest, gd.manifest["timing"]
    assert tm["met"] and man["architecture"]["kind"] == "serial" and "classifier" in man
    cands = tm["candidates"]
    extra = 1 if kind == "warped" else 0  # the warp register (the additive sum register is in _expected_latency)
    for c in cands:
        assert c["latency_cycles"] == _expected_latency(man, c["pipeline"]) + extra
        assert c["latency_cycles"] == build_design(model, design=design, pipeline=c["pipeline"],
                                                   architecture="serial").manifest["latency_cycles"]
    assert any(argmax_latency(man["classifier"]["n_classes"], c["pipeline"]) for c in cands)
    chosen = cands[tm["chosen"]]
    assert man["latency_cycles"] == chosen["latency_cycles"] == min(c["latency_cycles"] for c in cands
                                                                    if c["latency_cycles"] * 9.0 >= 100)
