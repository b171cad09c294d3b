"""Recurrent sensors on the serial core: `generate --design sensor --architecture serial` of a
recurrent model (generate refused it: "the recurrent top feeds back a parallel core only").

The recurrent top already has one sample in flight (II = latency), so the serial core (one
multiplier per target, n + 1 cycles per sample, the same bit-true model) slots in: latency = the
serial core's, II = latency. Uses the recurrent map and dynamical sensors of
tests/test_recurrent_cli.py (its ``flow`` fixture).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from pwas_hdl.cli import main
from pwas_hdl.design.manifest import load_manifest, validate_manifest
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.fixedpoint.recurrence import FeedbackRequant
from pwas_hdl.hdl import Pipeline
from pwas_hdl.hdl.serial_core import serial_latency
from test_recurrent_cli import flow  # noqa: F401 (the fixture: map.json, dyn.json, run.csv, dyn.csv)

TOP = "pwas_recurrent_sensor"


def _gen(flow, model, out, *args):  # noqa: F811
    assert main(["generate", str(flow / f"{model}.json"), "--design", "sensor", "--architecture", "serial", "--input-bits",
                 "16", *args, "-o", str(out)]) == 0
    return load_manifest(out)


@pytest.fixture(scope="module")
def serial(flow, tmp_path_factory):  # noqa: F811
    """The serial recurrent tops of the map (n = 2) and the dynamical sensor (n = 3)."""
    root = tmp_path_factory.mktemp("recurrent_serial")
    for m in ("map", "dyn"):
        _gen(flow, m, root / m)
    return root


@pytest.mark.parametrize("model, n", [("map", 2), ("dyn", 3)])
def test_generate_writes_the_serial_recurrent_top(flow, serial, tmp_path, model, n):  # noqa: F811
    man = load_manifest(serial / model)
    validate_manifest(man)
    lat = serial_latency(Pipeline.cast(None), n)
    assert man["design"] == "recurrent" and man["architecture"]["kind"] == "serial" and man["memory"]["kind"] == "single"
    assert man["latency_cycles"] == man["ii"] == man["recurrence"]["ii_cycles"] == man["architecture"]["ii"] == lat
    assert man["architecture"]["cycles_per_sample"] == n + 1 < lat  # the throttle never bites: one sample in flight
    assert "& advance" in man["flow_control"]["in.ready"]
    parallel = load_manifest(flow / model)
    assert man["recurrence"]["feedback"] == parallel["recurrence"]["feedback"]  # the same bit-true recurrence
    v = (serial / model / f"{TOP}.v").read_text()
    assert "one sample in flight through the serial core" in v and "single memory" in v
    rep = (serial / model / "report.md").read_text()
    assert "through the serial core, II = latency" in rep
    _gen(flow, model, tmp_path / "again")
    names = sorted(p.name for p in (serial / model).iterdir() if p.is_file())
    assert names == sorted(p.name for p in (tmp_path / "again").iterdir())
    for nm in names:
        assert (serial / model / nm).read_bytes() == (tmp_path / "again" / nm).read_bytes(), nm


def test_serial_recurrent_refusals(flow, tmp_path, capsys):  # noqa: F811
    """What stays refused: --memory (the serial core's one memory is the only layout); one error line,
    exit 2, nothing written."""
    out = tmp_path / "o"
    assert main(["generate", str(flow / "map.json"), "--design", "sensor", "--architecture", "serial", "--memory", "banked",
                 "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.strip().startswith("error:") and err.count("error:") == 1 and "--memory banked does not apply" in err
    assert not out.exists()


@pytest.mark.rtl
@pytest.mark.parametrize("args", [[], ["--pipeline", "max", "--ports", "amaranth", "--memory-init", "readmemh"],
                                  ["--pipeline", "min", "--rounding", "truncate", "--input-bits", "11"]],
                         ids=["default", "max-amaranth-readmemh", "min-truncate-11bit"])
@pytest.mark.parametrize("model", ["map", "dyn"])
def test_serial_recurrent_top_lint_clean(flow, serial, tmp_path, model, args):  # noqa: F811
    from pwas_hdl.flow.toolchain import lint_verilog, which

    if which("verilator") is None:
        pytest.skip("verilator not installed")
    out = serial / model
    if args:
        out = tmp_path / "hw"
        _gen(flow, model, out, *args)
    r = lint_verilog(out / f"{TOP}.v", TOP)
    assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[-2000:]


@pytest.mark.rtl
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_simulate_serial_recurrent_design(flow, serial, tmp_path, simulator, sim_cache):  # noqa: F811
    out = tmp_path / "hw.csv"
    assert main(["simulate", str(serial / "map"), str(flow / "run.csv"), "-o", str(out), "--traj-col", "run", "--simulator",
                 simulator, "--build-dir", str(sim_cache)]) == 0
    s = json.loads(out.with_suffix(".json").read_text())
    man = load_manifest(serial / "map")
    assert s["kind"] == "recurrent" and s["mismatches"] == 0 and s["checks"]["passed"] and s["samples"] == 200
    assert s["latency_cycles"]["measured_min"] == s["latency_cycles"]["measured_max"] == man["latency_cycles"]
    assert s["ii"]["measured"] == man["ii"] == man["latency_cycles"]
    # the written CSV says the same as the summary: every hardware estimate equals the bit-true one (the
    # serial top's equality with the parallel top is test_serial_recurrent_replay_stalls_and_reset_bit_exact's)
    tab = np.loadtxt(out, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(tab[:, 2], tab[:, 3])  # hw == bit-true


@pytest.mark.rtl
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_serial_recurrent_replay_stalls_and_reset_bit_exact(flow, tmp_path, simulator, sim_cache):  # noqa: F811
    from pwas_hdl.verify.recurrent_replay import build_recurrent_design, replay, standard_recurrent_runs

    s = PWASVirtualSensor.load(flow / "dyn.json")
    d = build_recurrent_design(s, architecture="serial")
    par = build_recurrent_design(s)
    assert d.latency == d.ii == serial_latency(Pipeline.cast(None), 3) and par.latency < d.latency
    rng = np.random.default_rng(11)
    u, y = rng.uniform(-1, 1, (300, 1)), rng.uniform(-1, 1, (300, 1))
    codes = d.rmodel.quantize_signals(u, y)
    np.testing.assert_array_equal(codes, par.rmodel.quantize_signals(u, y))
    r = replay(d, codes, simulator, runs=standard_recurrent_runs(codes.shape[0], seed=5), cache_dir=sim_cache, work_dir=tmp_path)
    assert r["passed"], r["failures"][:3]
    full = r["runs"][0]["segments"][0]
    assert full["outputs"] == codes.shape[0] and full["latencies"] == [d.latency] and full["spacings"] == [d.ii]
    assert r["runs"][1]["segments"][0]["outputs"] < codes.shape[0]  # the stall run: a reset mid-run
    np.testing.assert_array_equal(r["bittrue_out"], par.rmodel.run(codes)["out"][: len(r["bittrue_out"])])


@pytest.mark.rtl
def test_serial_recurrent_wrong_feedback_and_flipped_weight_are_caught(flow, tmp_path, sim_cache, capsys):  # noqa: F811
    from copy import copy

    from pwas_hdl.verify.recurrent_replay import build_recurrent_design, replay, standard_recurrent_runs

    d = build_recurrent_design(PWASVirtualSensor.load(flow / "map.json"), architecture="serial")
    data = np.loadtxt(flow / "run.csv", delimiter=",", skiprows=1)
    codes = d.rmodel.quantize_signals(None, data[:120, 1:2])
    wrong, rm = copy(d), copy(d.rmodel)
    fb = rm.feedback[0]
    rm.feedback = [FeedbackRequant(fb.mul, fb.add - (1 << fb.shift), fb.shift, fb.qmin, fb.qmax, fb.out_bits, fb.in_bits,
                                   fb.error_bound)]  # one input code lower
    wrong.rmodel = rm
    bad = replay(wrong, codes, "icarus", runs=standard_recurrent_runs(codes.shape[0]), cache_dir=sim_cache, work_dir=tmp_path / "fb")
    assert not bad["passed"] and bad["mismatches"] > 0
    hw = tmp_path / "flipped"
    man = _gen(flow, "map", hw, "--memory-init", "readmemh")
    (hexf,) = [hw / h["file"] for h in man["files"]["hex"]]  # the serial core's one memory
    words = hexf.read_text().split()
    hexf.write_text("".join(format(int(w, 16) ^ 1, f"0{len(w)}x") + "\n" for w in words))
    out = tmp_path / "f.csv"
    assert main(["simulate", str(hw), str(flow / "run.csv"), "-o", str(out), "--traj-col", "run", "--build-dir",
                 str(sim_cache)]) == 1
    s = json.loads(out.with_suffix(".json").read_text())
    assert s["mismatches"] > 0 and not s["checks"]["passed"]
    capsys.readouterr()


@pytest.mark.rtl
def test_report_and_export_testbench_of_the_serial_recurrent_top(flow, serial, tmp_path, sim_cache, capsys):  # noqa: F811
    import shutil
    import subprocess

    from pwas_hdl.flow.toolchain import tool_env, which

    hw = tmp_path / "hw"
    shutil.copytree(serial / "dyn", hw)
    (hw / "sim").mkdir()
    assert main(["simulate", str(hw), str(flow / "dyn.csv"), "-o", str(hw / "sim" / "icarus.csv"), "--build-dir",
                 str(sim_cache)]) == 0
    capsys.readouterr()
    assert main(["report", str(hw)]) == 0
    text = capsys.readouterr().out
    man = load_manifest(hw)
    assert f"# {TOP} (recurrent)" in text and "| icarus | 200 | 0 |" in text and f"II {man['ii']}" in text
    tb = tmp_path / "tb"
    assert main(["export-testbench", str(hw), "-o", str(tb), "--samples", "40"]) == 0
    if which("iverilog") is None:
        pytest.skip("iverilog not installed")
    r = subprocess.run(["bash", str(tb / "run_icarus.sh")], capture_output=True, text=True, cwd=tb, env=tool_env())
    assert r.returncode == 0 and f"latency {man['latency_cycles']}, II {man['ii']}" in r.stdout, r.stdout[-2000:] + r.stderr[-2000:]
