"""The serial ("small") PWAS architecture (issue 15 item 2): ``generate --architecture serial``.

One multiplier per target, one memory of N words, n + 1 cycles per sample (II = n + 1), the same
bit-true model as the parallel design. Checked here: the manifest (II, latency, architecture,
memory), byte-identical reruns, Verilator lint, bad option values, and in cocotb on Icarus and
Verilator (full speed, random stalls and backpressure, a reset in the middle of a stream) that
every output equals the bit-true model -- and equals, sample for sample, the output of the
parallel design of the same model on the same stimulus.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import warnings

import numpy as np
import pytest
from helpers.cli import CliRunner
from helpers.design_cache import DesignCache, parallel_twin

from pwas_hdl.verify.simulation import load_design, run_rtl, segment, sim_module, standard_runs

designs = sim_module("pwas_designs")
stimulus = sim_module("pwas_stimulus")
SERIAL = {c.name: c for c in designs.SERIAL_CONFIGS}


def _parallel_twin(cfg):
    return parallel_twin(cfg, cfg.name.replace("serial-", "parallel-"), **designs.SERIAL_TWIN_OPTIONS.get(cfg.name, {}))


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    return DesignCache(tmp_path_factory.mktemp("serial"))


def _codes(d, seed: int, m: int = 150) -> np.ndarray:
    return stimulus.design_codes(d, m, seed=seed)


@pytest.mark.parametrize("name", list(SERIAL))
def test_manifest_states_ii_latency_architecture_memory(name, folders):
    from pwas_hdl.hdl.params import Pipeline
    from pwas_hdl.hdl.serial_core import serial_latency

    cfg = SERIAL[name]
    man = json.loads((folders(cfg) / "manifest.json").read_text())
    n = cfg.n
    assert man["ii"] == n + 1
    assert man["latency_cycles"] == serial_latency(Pipeline.cast(cfg.options.get("pipeline")), n)
    arch = man["architecture"]
    assert arch["kind"] == "serial" and arch["multipliers"] == cfg.nz and arch["cycles_per_sample"] == n + 1
    mem = man["memory"]
    assert (mem["kind"], mem["memories"], mem["depth"], mem["words"]) == ("single", 1, mem["n_vertices"], mem["n_vertices"])
    assert man["generator"]["options"]["architecture"] == "serial"
    par = json.loads((folders(_parallel_twin(cfg)) / "manifest.json").read_text())
    assert par["architecture"]["kind"] == "parallel" and par["ii"] == 1 and par["memory"]["memories"] == n + 1
    assert "architecture" not in par["generator"]["options"]  # parallel manifests keep their options


def test_serial_rerun_is_byte_identical_and_has_one_memory(tmp_path):
    cfg = designs.SERIAL_CONFIGS[0]
    a, b = cfg.generate(tmp_path / "a"), cfg.generate(tmp_path / "b")
    assert a.files == b.files
    v = a.files[f"{a.top}.v"]
    assert v.count("reg [") and "wmem0" in v and "wmem1" not in v
    assert "II 4 (one sample every 4 clocks)" in v


def test_serial_core_ports_equal_the_parallel_core():
    from pwas_hdl.hdl import build_core, design_info

    model = designs.SERIAL_CONFIGS[0].model()
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fxm = FixedPointModel.from_sensor(model)
    ser, par = design_info(build_core(fxm, architecture="serial")), design_info(build_core(fxm))
    assert ser["ports"] == par["ports"] and ser["payload"] == par["payload"]
    assert ser["ii"] == fxm.n + 1 and par["ii"] == 1
    with pytest.raises(ValueError, match=r"--architecture \(architecture\) must be one of parallel, serial"):
        build_core(fxm, architecture="tiny")


@pytest.mark.parametrize("args, msg", [
    (["--architecture", "tiny"], "--architecture (architecture) must be one of parallel, serial"),
    # (--clock-mhz with --architecture serial is searched now: tests/test_timing_closure_kinds.py)
    # --memory was ignored by the serial design (one memory of N words) while the manifest recorded it
    (["--architecture", "serial", "--memory", "replicated"], "--memory replicated does not apply to --architecture serial"),
    (["--architecture", "serial", "--memory", "corner"], "--memory corner does not apply to --architecture serial"),
    (["--architecture", "serial", "--memory", "banked"], "--memory banked does not apply to --architecture serial"),
])
def test_cli_bad_architecture_is_one_error_line_exit_2(args, msg, tmp_path):
    from pwas_hdl.cli import app

    cfg = designs.SERIAL_CONFIGS[0]
    model = tmp_path / "m.json"
    from pwas_hdl.fit.model_file import write_model

    write_model(cfg.model(), model)
    out = tmp_path / "out"
    r = CliRunner().invoke(app, ["generate", str(model), "-o", str(out), *args])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and msg in lines[0], r.output
    assert "Traceback" not in r.output and not out.exists()


@pytest.mark.rtl
@pytest.mark.parametrize("name", list(SERIAL))
def test_serial_rtl_is_lint_clean(name, folders, tmp_path):
    from pwas_hdl.flow.toolchain import tool_env

    d = load_design(folders(SERIAL[name]))
    path = tmp_path / f"{d.top}.v"
    path.write_text(d.verilog)
    env = tool_env()
    exe = shutil.which("verilator", path=env.get("PATH"))
    if exe is None:
        pytest.skip("verilator not found")
    r = subprocess.run([exe, "--lint-only", "-Wall", str(path)], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert r.returncode == 0, r.stderr


# both configurations on Icarus; on Verilator the sensor top (serial core + lag bank), to keep the
# suite's budget (one Verilator build of a serial design costs ~20 s here)
RTL_CASES = [(name, "icarus") for name in SERIAL] + [("serial-s-u3y3-p2-max", "verilator")]


@pytest.mark.rtl
@pytest.mark.parametrize("name, simulator", RTL_CASES)
def test_serial_rtl_bit_exact_with_parallel(name, simulator, folders, sim_cache, tmp_path):
    """Full speed (II = n + 1 from the handshake, latency = manifest), stalls, mid-stream reset: every
    output equals the bit-true model, and the parallel design's output on the same stimulus."""
    cfg = SERIAL[name]
    d = load_design(folders(cfg))
    dp = load_design(folders(_parallel_twin(cfg)))
    codes = _codes(d, seed=11)
    runs = standard_runs(d, codes, seed=11)
    res = run_rtl(d, runs, simulator, cache_dir=sim_cache, work_dir=tmp_path / "s")
    assert res.passed, res.report()
    assert set(res.latencies) == {d.latency}
    assert res.ii == float(cfg.n + 1) == d.manifest["ii"]
    per_stream = len(segment(d, codes).src)
    assert res.outputs >= 2 * per_stream + len(runs[2].segments[1].src)
    # the parallel design on the same runs: the same output codes and flags, sample for sample
    resp = run_rtl(dp, standard_runs(dp, codes, seed=11), simulator, cache_dir=sim_cache, work_dir=tmp_path / "p")
    assert resp.passed, resp.report()
    assert len(res.hw) == len(resp.hw)
    compared = 0
    for run, ra, rb in zip(runs, res.hw, resp.hw):
        for seg, (zs, os_), (zp, op) in zip(run.segments, ra, rb):
            if seg.drain:  # a drained segment gives every output; before a mid-stream reset, a prefix
                assert zs.shape == zp.shape
            k = min(len(zs), len(zp))
            np.testing.assert_array_equal(zs[:k], zp[:k])
            np.testing.assert_array_equal(os_[:k], op[:k])
            compared += k
    assert compared >= 2 * per_stream

