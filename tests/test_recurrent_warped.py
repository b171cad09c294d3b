"""Recurrent sensors (fit --mz) on a non-uniform partition (fit --breakpoints quantile-pow2): the
recurrent top with the warp in front of its core (generate refused them before).

The bit-true recurrence runs on the warped model (the fed-back estimate is requantised to the
warp's input code format of its dimension) and tracks the float recurrence; the RTL replays it bit
for bit on Icarus and Verilator (stalls, a reset mid-run); a flipped weight and a wrong feedback
rule are caught; generate / simulate / report / export-testbench work from the CLI.
"""

from __future__ import annotations

import json
import shutil
from functools import lru_cache

import numpy as np
import pytest

from pwas_hdl.cli import main
from pwas_hdl.design.manifest import load_manifest, validate_manifest
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.fixedpoint.recurrence import FeedbackRequant
from pwas_hdl.fixedpoint.warp import WarpInputFormat, WarpedFixedPointModel
from helpers.requant import check_requant_over_every_output_code

TOP = "pwas_recurrent_sensor"


def _system(rng, T):
    """z(t) = 0.7 z(t-1) + 0.4 tanh(2 y(t)) - 0.1 u(t)^2: nonlinear, stable."""
    u = rng.uniform(-1, 1, T)
    y = np.sin(np.arange(T) * 0.07) + 0.3 * rng.uniform(-1, 1, T)
    z = np.zeros(T)
    for t in range(1, T):
        z[t] = 0.7 * z[t - 1] + 0.4 * np.tanh(2 * y[t]) - 0.1 * u[t] ** 2
    return u, y, z


def _csv(path, cols: dict) -> None:
    names = list(cols)
    path.write_text(",".join(names) + "\n" + "".join(",".join(repr(float(v)) for v in r) + "\n" for r in zip(*cols.values())))


@pytest.fixture(scope="module")
def flow(tmp_path_factory):
    """A recurrent sensor (Mz = 1) fitted with quantile-pow2 breakpoints from the CLI, a run to
    replay and the generated folder."""
    root = tmp_path_factory.mktemp("recurrent_warped")
    u, y, z = _system(np.random.default_rng(1), 1500)
    _csv(root / "train.csv", {"u": u, "y": y, "z": z})
    u, y, z = _system(np.random.default_rng(7), 300)
    _csv(root / "run.csv", {"u": u, "y": y, "z": z})
    assert main(["fit", str(root / "train.csv"), "-o", str(root / "m.json"), "-u", "u", "-y", "y", "-z", "z", "--mu", "1",
                 "--my", "1", "--mz", "1", "--z0", "0", "-p", "4", "--breakpoints", "quantile-pow2", "--sigma", "1e-4"]) == 0
    assert main(["generate", str(root / "m.json"), "--design", "sensor", "--input-bits", "16", "-o", str(root / "hw")]) == 0
    return root


@lru_cache(maxsize=None)
def _design(path: str, architecture: str = "parallel"):
    from pwas_hdl.verify.recurrent_replay import build_recurrent_design

    return build_recurrent_design(PWASVirtualSensor.load(path), architecture=architecture)


def test_the_model_is_warped_and_its_past_estimate_is_a_signal_of_its_own(flow):
    d = _design(str(flow / "m.json"))
    fxm = d.rmodel.fxm
    assert isinstance(fxm, WarpedFixedPointModel)
    assert fxm.regressor_signals == [("u", 0), ("y", 0), ("z_hat", 1)] and fxm.regressor_names[-1] == "z_hat[t-1]"
    assert any(max(w.exps) > 0 for w in fxm.warps)  # really non-uniform somewhere
    assert isinstance(d.rmodel.z_formats[0], WarpInputFormat) and d.rmodel.signals == ["u", "y"]
    # the top: the warp register in front of the core, II = latency, B_in-bit payload and feedback registers
    assert d.latency == d.ii == d.top.core.latency and d.top.in_width == 16 and d.top.params.in_width == fxm.warps[0].width
    assert d.top.extra_info["warp"]["kind"] == "pow2"


@pytest.mark.parametrize("bits,frac", [(18, 12), (14, 9), (21, 16)])
def test_feedback_requant_to_a_warp_input_format_over_every_output_code(flow, bits, frac):
    """FeedbackRequant.between derived for the warp's input code format: q is the warp input code of
    the output's value (half up), within its error bound, saturating; checked for every output code."""
    check_requant_over_every_output_code(_design(str(flow / "m.json")).rmodel.z_formats[0], bits, frac)


def test_bittrue_warped_recurrence_tracks_the_float_one(flow):
    """The measured deviation of the bit-true (warped) recurrence from the float one over 4000
    steps: max 0.0026 = 1.75 x the per-step bound (circuit + requantisation, 0.0015) with 16-bit
    inputs, the same in both halves (no drift)."""
    s = PWASVirtualSensor.load(flow / "m.json")
    d = _design(str(flow / "m.json"))
    u, y, z = _system(np.random.default_rng(7), 4000)
    zf = s.predict(u[:, None], y[:, None])[:, 0]
    res = d.rmodel.run(d.rmodel.quantize_signals(u[:, None], y[:, None]))
    zb = d.rmodel.fxm.to_physical_output(res["out"])[:, 0]
    dev = np.abs(zb - zf)
    per_step = d.rmodel.fxm.error_bound + d.rmodel.feedback[0].error_bound
    assert dev.max() < 5 * per_step
    half = dev.shape[0] // 2
    assert dev[half:].max() <= 1.5 * dev[:half].max()
    rms = float(np.sqrt(np.mean((zb - z) ** 2)))
    assert rms <= 1.01 * float(np.sqrt(np.mean((zf - z) ** 2)))  # as accurate as the float recurrence
    # the fed-back code is the warp input code of the estimate (up to ties), the reset code the initial state's
    fmt = d.rmodel.z_formats[0]
    assert np.mean(res["fed_back"][:, 0] == fmt.quantize(zb)) > 0.999
    assert res["regressor"][0, -1] == d.rmodel.initial_codes[0, 0] == fmt.quantize(np.array([0.0]))[0]
    np.testing.assert_array_equal(res["regressor"][1:, -1], res["fed_back"][:-1, 0])


def test_generate_writes_the_warped_recurrent_top(flow, tmp_path):
    man = load_manifest(flow / "hw")
    validate_manifest(man)
    assert man["design"] == "recurrent" and man["architecture"]["kind"] == "parallel"
    assert man["ii"] == man["latency_cycles"] == man["recurrence"]["ii_cycles"]
    assert man["warp"]["latency_cycles"] == 1 and [d["regressor"] for d in man["warp"]["dimensions"]] == ["u[t]", "y[t]", "z_hat[t-1]"]
    fb = man["recurrence"]["feedback"][0]
    assert fb["input_format"] == "s16.0" and fb["regressors"] == ["z_hat[t-1]"]
    inp = man["formats"]["inputs"][2]
    assert inp["input_scale"] == "warp" and abs(inp["offset"] + inp["lsb"] * fb["initial_codes"][0]) <= inp["lsb"] / 2
    v = (flow / "hw" / f"{TOP}.v").read_text()
    assert "PWAS recurrent virtual-sensor top" in v and "non-uniform partition (power-of-two cells)" in v
    assert "one sample in flight through the warp and the parallel core" in v
    rep = (flow / "hw" / "report.md").read_text()
    assert "## Recurrence" in rep and "## Non-uniform partition" in rep and "serial architecture" not in rep
    # deterministic
    assert main(["generate", str(flow / "m.json"), "--design", "sensor", "--input-bits", "16", "-o", str(tmp_path / "again")]) == 0
    names = sorted(p.name for p in (flow / "hw").iterdir() if p.is_file())
    assert names == sorted(p.name for p in (tmp_path / "again").iterdir())
    for n in names:
        assert (flow / "hw" / n).read_bytes() == (tmp_path / "again" / n).read_bytes(), n


@pytest.mark.rtl
@pytest.mark.parametrize("args", [[], ["--pipeline", "min", "--memory", "replicated", "--input-bits", "14"],
                                  ["--pipeline", "max", "--memory", "corner", "--memory-init", "readmemh"]],
                         ids=["default", "min-replicated-14bit", "max-corner-readmemh"])
def test_warped_recurrent_top_lint_clean(flow, tmp_path, args):
    from pwas_hdl.flow.toolchain import lint_verilog, which

    if which("verilator") is None:
        pytest.skip("verilator not installed")
    out = flow / "hw" if not args else tmp_path / "hw"
    if args:
        assert main(["generate", str(flow / "m.json"), "--design", "sensor", *args, "-o", str(out)]) == 0
    r = lint_verilog(out / f"{TOP}.v", TOP)
    assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[-2000:]


@pytest.mark.rtl
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_simulate_warped_recurrent_design(flow, tmp_path, simulator, sim_cache):
    out = tmp_path / "hw.csv"
    assert main(["simulate", str(flow / "hw"), str(flow / "run.csv"), "-o", str(out), "--simulator", simulator,
                 "--build-dir", str(sim_cache)]) == 0
    s = json.loads(out.with_suffix(".json").read_text())
    assert s["kind"] == "recurrent" and s["mismatches"] == 0 and s["checks"]["passed"] and s["samples"] == 300
    man = load_manifest(flow / "hw")
    assert s["latency_cycles"]["measured_min"] == s["latency_cycles"]["measured_max"] == man["latency_cycles"]
    assert s["ii"]["measured"] == man["ii"] == man["latency_cycles"]
    # measured: max 0.0019 from the float recurrence (16-bit state codes; output LSB 0.00098), RMSEE 0.2 % below the float one
    assert s["max_error_vs_float"] < 0.005
    t = s["targets"]["z"]
    assert t["rmsee_hw"] <= 1.01 * t["rmsee_float"]


@pytest.mark.rtl
@pytest.mark.parametrize("architecture", ["parallel", "serial"])
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_warped_recurrent_replay_stalls_and_reset_bit_exact(flow, tmp_path, simulator, architecture, sim_cache):
    from pwas_hdl.verify.recurrent_replay import replay, standard_recurrent_runs

    d = _design(str(flow / "m.json"), architecture)
    u, y, _z = _system(np.random.default_rng(3), 400)
    codes = d.rmodel.quantize_signals(u[:, None], y[:, None])
    r = replay(d, codes, simulator, runs=standard_recurrent_runs(codes.shape[0], seed=2), cache_dir=sim_cache, work_dir=tmp_path)
    assert r["passed"], r["failures"][:3]
    full = r["runs"][0]["segments"][0]
    assert full["outputs"] == codes.shape[0] and full["latencies"] == [d.latency] and full["spacings"] == [d.ii]
    assert r["runs"][1]["segments"][0]["outputs"] < codes.shape[0]  # the stall run: a reset mid-run


@pytest.mark.rtl
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_warped_recurrent_top_on_the_serial_core(flow, tmp_path, simulator, sim_cache):
    """generate --architecture serial of the warped recurrent model: the warp in front of the serial
    core, latency = II = the serial core's + 1; lint-clean, simulate bit-exact."""
    from pwas_hdl.flow.toolchain import lint_verilog, which
    from pwas_hdl.hdl import Pipeline
    from pwas_hdl.hdl.serial_core import serial_latency

    hw = tmp_path / "hw"
    assert main(["generate", str(flow / "m.json"), "--design", "sensor", "--architecture", "serial", "--input-bits", "16",
                 "-o", str(hw)]) == 0
    man = load_manifest(hw)
    assert man["architecture"]["kind"] == "serial" and "warp" in man and man["design"] == "recurrent"
    assert man["latency_cycles"] == man["ii"] == serial_latency(Pipeline.cast(None), 3) + 1
    assert "one sample in flight through the warp and the serial core" in (hw / f"{TOP}.v").read_text()
    if simulator == "verilator" and which("verilator") is not None:
        r = lint_verilog(hw / f"{TOP}.v", TOP)
        assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[-2000:]
    out = tmp_path / "hw.csv"
    assert main(["simulate", str(hw), str(flow / "run.csv"), "-o", str(out), "--simulator", simulator,
                 "--build-dir", str(sim_cache)]) == 0
    s = json.loads(out.with_suffix(".json").read_text())
    assert s["mismatches"] == 0 and s["checks"]["passed"] and s["samples"] == 300
    assert s["latency_cycles"]["measured_max"] == man["latency_cycles"] and s["ii"]["measured"] == man["ii"]


@pytest.mark.rtl
def test_a_wrong_feedback_rule_and_a_flipped_weight_are_caught(flow, tmp_path, sim_cache, capsys):
    from copy import copy

    from pwas_hdl.verify.recurrent_replay import replay, standard_recurrent_runs

    d = _design(str(flow / "m.json"))
    u, y, _z = _system(np.random.default_rng(3), 120)
    codes = d.rmodel.quantize_signals(u[:, None], y[:, None])
    # the bit-true recurrence with a feedback one input code off: the RTL must disagree
    wrong, rm = copy(d), copy(d.rmodel)
    fb = rm.feedback[0]
    rm.feedback = [FeedbackRequant(fb.mul, fb.add + (1 << fb.shift), fb.shift, fb.qmin, fb.qmax, fb.out_bits, fb.in_bits,
                                   fb.error_bound)]
    wrong.rmodel = rm
    bad = replay(wrong, codes, "icarus", runs=standard_recurrent_runs(codes.shape[0]), cache_dir=sim_cache,
                 work_dir=tmp_path / "fb")
    assert not bad["passed"] and bad["mismatches"] > 0
    # the LSB of every word of one weight memory flipped after generate: simulate exits 1
    hw = tmp_path / "flipped"
    assert main(["generate", str(flow / "m.json"), "--design", "sensor", "--input-bits", "16", "--memory-init", "readmemh",
                 "-o", str(hw)]) == 0
    man = load_manifest(hw)
    hexf = hw / man["files"]["hex"][0]["file"]
    words = hexf.read_text().split()
    hexf.write_text("".join(format(int(w, 16) ^ 1, f"0{len(w)}x") + "\n" for w in words))
    out = tmp_path / "f.csv"
    assert main(["simulate", str(hw), str(flow / "run.csv"), "-o", str(out), "--build-dir", str(sim_cache)]) == 1
    s = json.loads(out.with_suffix(".json").read_text())
    assert s["mismatches"] > 0 and not s["checks"]["passed"]
    capsys.readouterr()


@pytest.mark.rtl
def test_report_and_export_testbench_of_the_warped_recurrent_top(flow, tmp_path, sim_cache, capsys):
    from pwas_hdl.flow.toolchain import which

    hw = tmp_path / "hw"
    shutil.copytree(flow / "hw", hw)
    (hw / "sim").mkdir()
    assert main(["simulate", str(hw), str(flow / "run.csv"), "-o", str(hw / "sim" / "icarus.csv"), "--build-dir",
                 str(sim_cache)]) == 0
    capsys.readouterr()
    assert main(["report", str(hw), "--json", str(tmp_path / "r.json")]) == 0
    text = capsys.readouterr().out
    assert f"# {TOP} (recurrent)" in text and "| icarus | 300 | 0 |" in text
    tb = tmp_path / "tb"
    assert main(["export-testbench", str(hw), "-o", str(tb), "--samples", "40"]) == 0
    assert (tb / f"tb_{TOP}.v").is_file()
    if which("iverilog") is None:
        pytest.skip("iverilog not installed")
    import subprocess

    from pwas_hdl.flow.toolchain import tool_env

    r = subprocess.run(["bash", str(tb / "run_icarus.sh")], capture_output=True, text=True, cwd=tb, env=tool_env())
    assert r.returncode == 0 and "PASS" in r.stdout, r.stdout[-2000:] + r.stderr[-2000:]
