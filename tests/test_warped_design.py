"""Non-uniform partitions through ``generate`` / ``simulate`` (issue 15 item 3, hardware).

A model fitted with ``--breakpoints quantile-pow2`` gets the warped designs: ``--design core``
(``n`` input codes -> warp + register -> core) and ``--design sensor`` (one code per signal -> lag
bank -> warp + register -> core), parallel or serial. Checked here: the manifest's ``warp`` entry
and latency, byte-identical reruns, ``load_design`` rebuilding the same bit-true model, the clear
refusals, lint (``verilator -Wall``) and the cocotb bench on Icarus and Verilator (full speed,
stalls and backpressure, a reset mid-stream, input codes outside the domain) bit-exact with the
bit-true model, and ``simulate`` writing the hardware, bit-true and float columns.
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
    from pwas_hdl.flow.toolchain import tool_env
    from pwas_hdl.verify.simulation import load_design, run_rtl, standard_runs

    m, _ = warped_sensor
    pipe = "max" if arch == "parallel" and design == "core" else None
    gd = generate(m, tmp_path / "d", design=design, architecture=arch, input_bits=10, pipeline=pipe)
    if simulator == "verilator":  # lint-clean, and byte-identical when built again
        assert build_design(m, design=design, architecture=arch, input_bits=10, pipeline=pipe).files == gd.files
        env = tool_env()
        exe = shutil.which("verilator", path=env.get("PATH"))
        r = subprocess.run([exe, "--lint-only", "-Wall", f"{gd.top}.v"], capture_output=True, text=True, env=env,
                           cwd=tmp_path / "d")
        assert r.returncode == 0, r.stderr
    wm = gd.model
    rng = np.random.default_rng(11)
    lo, hi = wm.code_range
    breaks = np.array(wm.warps[0].code_breaks)
    d = load_design(tmp_path / "d")
    ncol = len(d.in_fields)
    codes = np.stack([_codes(rng, lo, hi, breaks, 120) for _ in range(ncol)], axis=1)
    if ncol > 1:  # the core: shuffle the columns independently
        for j in range(1, ncol):
            codes[:, j] = rng.permutation(codes[:, j])
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
