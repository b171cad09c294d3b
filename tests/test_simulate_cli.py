"""`pwas-hdl simulate`: replay a CSV through the generated RTL (cocotb), outputs and JSON summary."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from helpers.cli import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.io.csv_table import write_csv
from pwas_hdl.verify.simulation import load_design, sim_module

runner = CliRunner()
designs = sim_module("pwas_designs")
mutations = sim_module("pwas_mutations")


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """A sensor top (u0 with Mu = 1, y0 with My = 2) and the core of the same model, and data:
    two trajectories that wander over the domain and sometimes leave it, with a `z0_true` column."""
    root = tmp_path_factory.mktemp("cli")
    cfg = designs.DesignConfig("cli", "sensor", 1, 2, 1, 1, [3, 4, 4], 1, {}, seed=4)
    cfg.generate(root / "sensor")
    designs.DesignConfig("cli", "core", 1, 2, 1, 1, [3, 4, 4], 1, {}, seed=4).generate(root / "core")
    d = load_design(root / "sensor")
    g = d.sensor.grid_
    rng = np.random.default_rng(0)
    cols = {"run": [], "u0": [], "y0": [], "z0_true": []}
    for run, t_len in ((0, 150), (1, 90)):
        for dim, name in ((0, "u0"), (1, "y0")):
            lo, hi = g.lo[dim], g.hi[dim]
            x = np.clip(np.cumsum(rng.normal(0, 0.08 * (hi - lo), t_len)) + (lo + hi) / 2, lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo))
            cols[name] += x.tolist()
        cols["run"] += [run] * t_len
        cols["z0_true"] += rng.normal(0, 1, t_len).tolist()
    write_csv(root / "data.csv", {k: np.array(v) for k, v in cols.items()})
    single = {k: np.array(v[:150]) for k, v in cols.items() if k != "run"}
    write_csv(root / "one.csv", single)
    return root


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.rtl
@pytest.mark.parametrize("simulator, engine", [("icarus", "cocotb"), ("verilator", "cocotb"), ("verilator", "native")])
def test_simulate_sensor(simulator, engine, folders, sim_cache, tmp_path):
    out = tmp_path / "hw.csv"
    res = runner.invoke(app, ["simulate", str(folders / "sensor"), str(folders / "one.csv"), "--simulator", simulator,
                              "--engine", engine, "-o", str(out), "--build-dir", str(sim_cache)])
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "hw.json").read_text())
    assert s["mismatches"] == 0 and s["first_mismatch"] is None
    assert s["samples"] == 150 - 1  # M = max(Mu, My) = 2
    assert s["simulator"] == simulator and s["kind"] == "sensor" and s["engine"] == engine
    assert s["latency_cycles"]["measured_min"] == s["latency_cycles"]["measured_max"] == s["latency_cycles"]["manifest"]
    assert s["ii"]["measured"] == 1.0
    assert s["within_error_bound"] and s["max_error_vs_float_lsb"] <= s["error_bound_lsb"] + 1e-9
    assert s["out_of_range"] > 0  # the data leave the domain at times
    z = s["targets"]["z0"]
    assert z["reference_column"] == "z0_true" and z["rmsee_hw"] == pytest.approx(z["rmsee_bittrue"])
    assert s["samples_per_second"] > 0 and s["cycles"] > s["samples"]
    rows = _rows(out)
    assert [r["row"] for r in rows] == [str(i) for i in range(1, 150)]
    assert set(rows[0]) == {"row", "z0_hw", "z0_bittrue", "z0_float", "out_of_range", "mismatch"}
    # the hardware column equals the bit-true model evaluated independently of the testbench
    d = load_design(folders / "sensor")
    data = np.loadtxt(folders / "one.csv", delimiter=",", skiprows=1)
    xi = d.sensor.lags_.build(data[:, [0]], data[:, [1]])
    want, flags = d.model.predict(xi, return_flags=True)
    assert np.array_equal(np.array([float(r["z0_hw"]) for r in rows]), want[:, 0])
    assert np.array_equal(np.array([r["out_of_range"] == "1" for r in rows]), flags)


@pytest.mark.rtl
def test_simulate_waves_folder_is_part_of_the_outputs(folders, sim_cache, tmp_path):
    """--waves: the waveform folder (OUT_waves/) appears with the CSV and the summary, at its final
    path (no temporary left, a previous folder replaced), and the summary names the file there."""
    out = tmp_path / "hw.csv"
    (tmp_path / "hw_waves").mkdir()
    (tmp_path / "hw_waves" / "old.fst").write_text("previous run")
    res = runner.invoke(app, ["simulate", str(folders / "sensor"), str(folders / "one.csv"), "--simulator", "icarus",
                              "-o", str(out), "--build-dir", str(sim_cache), "--waves"])
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "hw.json").read_text())
    wave = tmp_path / "hw_waves" / s["waves"].split("hw_waves/", 1)[1]
    assert s["waves"] == str(wave) and wave.is_file() and wave.stat().st_size > 0
    assert not (tmp_path / "hw_waves" / "old.fst").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hw.csv", "hw.json", "hw_waves"]
    job = json.loads((tmp_path / "hw_waves" / "job.json").read_text())  # names no staging folder that is gone
    assert job["result"] == "result.json" and (tmp_path / "hw_waves" / job["result"]).is_file()


@pytest.mark.rtl
def test_simulate_waves_failure_keeps_the_log_and_leaves_nothing(folders, sim_cache, tmp_path, monkeypatch, capsys):
    """--waves on a sensor design: a failed simulator run named its log inside the private waveform
    folder, removed before the message was read; an error or an interrupt after the run left that
    folder in $TMPDIR (never cleaned: no process id in its name) and the staged CSV beside -o.
    Now the log is copied out as without --waves, and nothing is left but the previous outputs."""
    import tempfile

    from pwas_hdl.cli import main

    tmpd = tmp_path / "tmpdir"
    tmpd.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmpd))
    out = tmp_path / "run"
    out.mkdir()
    (out / "hw_waves").mkdir()
    (out / "hw_waves" / "old.fst").write_text("previous run")
    args = ["simulate", str(folders / "sensor"), str(folders / "one.csv"), "--simulator", "icarus", "-o", str(out / "hw.csv"),
            "--build-dir", str(sim_cache), "--waves"]
    sim = sim_module("pwas_runner")

    def failing(b, job, wd, **kw):
        (Path(wd) / "sim.log").write_text("the simulator's log\n")
        raise sim.SimulationError("the run failed", Path(wd) / "sim.log", "")

    with monkeypatch.context() as m:
        m.setattr(sim, "run_job", failing)
        capsys.readouterr()
        assert main(args) == 2
    named = capsys.readouterr().err.split("log: ", 1)[1].split()[0]
    logs = list(tmpd.iterdir())
    assert [str(p) for p in logs] == [named] and logs[0].read_text() == "the simulator's log\n"
    logs[0].unlink()
    for exc in (KeyboardInterrupt(), RuntimeError("late")):  # after the run, before the outputs are committed
        with monkeypatch.context() as m:
            m.setattr("pwas_hdl.verify.simulation._checks", mock.Mock(side_effect=exc))
            assert main(args) != 0
        assert list(tmpd.iterdir()) == []
        assert sorted(p.name for p in out.rglob("*")) == ["hw_waves", "old.fst"]


@pytest.mark.rtl
def test_simulate_core_trajectories_with_stalls(folders, sim_cache, tmp_path):
    out = tmp_path / "core.csv"
    summ = tmp_path / "s.json"
    res = runner.invoke(app, ["simulate", str(folders / "core"), str(folders / "data.csv"), "-o", str(out), "--json", str(summ),
                              "--traj-col", "run", "--stall", "0.3", "--seed", "2", "--build-dir", str(sim_cache)])
    assert res.exit_code == 0, res.output
    s = json.loads(summ.read_text())
    assert s["trajectories"] == 2 and s["samples"] == (150 - 1) + (90 - 1)
    assert s["mismatches"] == 0
    assert s["latency_cycles"]["measured_min"] >= s["latency_cycles"]["manifest"]
    assert s["ii"]["measured"] is None  # not measured with stalls
    rows = _rows(out)
    assert rows[149 - 1]["row"] == "149" and rows[149]["row"] == str(150 + 1)  # the second run starts at row 150 (+M-1)


@pytest.mark.rtl
def test_simulate_at_the_largest_stall_passes(folders, sim_cache, tmp_path):
    """--stall 0.95 (MAX_STALL): a correct design passes within the bench's cycle limit."""
    res = runner.invoke(app, ["simulate", str(folders / "sensor"), str(folders / "one.csv"), "-o", str(tmp_path / "o.csv"),
                              "--stall", "0.95", "--build-dir", str(sim_cache)])
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "o.json").read_text())
    assert s["samples"] == 149 and s["mismatches"] == 0 and s["stall"] == 0.95


@pytest.mark.rtl
def test_simulate_sensor_resets_between_trajectories(folders, sim_cache, tmp_path):
    res = runner.invoke(app, ["simulate", str(folders / "sensor"), str(folders / "data.csv"), "-o", str(tmp_path / "o.csv"),
                              "--traj-col", "run", "--build-dir", str(sim_cache)])
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "o.json").read_text())
    assert s["samples"] == 149 + 89 and s["mismatches"] == 0 and s["trajectories"] == 2


@pytest.mark.rtl
def test_simulate_native_reports_rtl_mismatch_and_resets_between_trajectories(folders, sim_cache, tmp_path):
    """The native engine on the two-trajectory data (a reset between them) and on a one-LSB fault."""
    out = tmp_path / "ok.csv"
    res = runner.invoke(app, ["simulate", str(folders / "sensor"), str(folders / "data.csv"), "--traj-col", "run", "--engine", "native",
                              "--stall", "0.3", "-o", str(out), "--build-dir", str(sim_cache)])
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "ok.json").read_text())
    assert s["samples"] == 149 + 89 and s["mismatches"] == 0 and s["trajectories"] == 2
    bad = tmp_path / "bad"
    shutil.copytree(folders / "sensor", bad)
    d = load_design(bad)
    d.verilog_path.write_text(mutations.round_constant_plus_one_lsb(d.verilog, d.model.shift)[0])
    res = runner.invoke(app, ["simulate", str(bad), str(folders / "one.csv"), "--engine", "native", "-o", str(tmp_path / "hw.csv"),
                              "--build-dir", str(sim_cache)])
    assert res.exit_code == 1, res.output
    s = json.loads((tmp_path / "hw.json").read_text())
    assert s["mismatches"] == s["samples"] == 149


@pytest.mark.rtl
def test_simulate_reports_rtl_mismatch(folders, sim_cache, tmp_path):
    """A one-LSB fault in the RTL: every sample is flagged, exit status 1, the summary is written."""
    bad = tmp_path / "bad"
    shutil.copytree(folders / "sensor", bad)
    d = load_design(bad)
    text, _ = mutations.round_constant_plus_one_lsb(d.verilog, d.model.shift)
    d.verilog_path.write_text(text)
    out = tmp_path / "hw.csv"
    res = runner.invoke(app, ["simulate", str(bad), str(folders / "one.csv"), "-o", str(out), "--build-dir", str(sim_cache)])
    assert res.exit_code == 1, res.output
    assert "differ from the bit-true model" in res.output
    s = json.loads((tmp_path / "hw.json").read_text())
    assert s["mismatches"] == s["samples"] == 149
    assert s["first_mismatch"]["actual"][0] == s["first_mismatch"]["expected"][0] + 1
    assert all(r["mismatch"] == "1" for r in _rows(out))


@pytest.mark.parametrize(
    "args, msg",
    [
        (["--simulator", "modelsim"], "simulator must be one of"),
        (["--stall", "1.5"], "--stall must be in"),
        # beyond what the benches' cycle limit covers: refused before anything runs (it once ran and
        # reported a correct design as failing, "only 255 of 300 inputs were accepted", exit 1)
        (["--stall", "0.999"], "--stall must be in [0, 0.95]"),
        (["--stall", "0.96"], "--stall must be in [0, 0.95]"),
        (["--engine", "vcs"], "--engine must be one of"),
        (["--engine", "native", "--simulator", "icarus"], "runs on Verilator"),
        (["--engine", "native", "--waves"], "without waveforms"),
    ],
)
def test_simulate_bad_options(args, msg, folders, tmp_path):
    out = tmp_path / "o.csv"
    res = runner.invoke(app, ["simulate", str(folders / "sensor"), str(folders / "one.csv"), "-o", str(out), *args])
    assert res.exit_code == 2 and msg in res.output, res.output
    assert not out.exists() and not (tmp_path / "o.json").exists()


def test_simulate_bad_inputs(folders, tmp_path):
    out = tmp_path / "o.csv"
    res = runner.invoke(app, ["simulate", str(tmp_path / "nowhere"), str(folders / "one.csv"), "-o", str(out)])
    assert res.exit_code == 2 and "pwas-hdl generate" in res.output
    wrong = tmp_path / "wrong.csv"
    write_csv(wrong, {"a": np.arange(5.0), "y0": np.arange(5.0)})
    res = runner.invoke(app, ["simulate", str(folders / "sensor"), str(wrong), "-o", str(out)])
    assert res.exit_code == 2 and "no column named 'u0'" in res.output, res.output
    assert not out.exists()


def test_simulate_help():
    res = runner.invoke(app, ["simulate", "--help"])
    assert res.exit_code == 0
    for opt in ("--simulator", "--engine", "--json", "--traj-col", "--stall", "--build-dir", "--waves"):
        assert opt in res.output
    # the CSV columns the help lists are the ones simulate writes (mismatch was missing)
    text = " ".join(res.output.split())
    assert "row, TARGET_hw, TARGET_bittrue, TARGET_float, out_of_range, mismatch" in text


def test_simulate_failure_names_a_log_that_still_exists(folders, tmp_path, monkeypatch):
    # the testbench runs in a temporary folder removed afterwards: the `error:` line named the sim.log
    # inside it, which was gone by the time the user read it; it is copied out first
    import re
    from types import SimpleNamespace
    from unittest import mock

    from pwas_hdl.errors import ToolFailed

    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr("tempfile.tempdir", None)  # TMPDIR read afresh

    def run_job(b, job, wd, **kw):
        (wd / "sim.log").write_text("the simulator's own words\n")
        raise ToolFailed("the testbench wrote no result (icarus, top)", wd / "sim.log", "the simulator's own words")

    fake = SimpleNamespace(build=lambda *a, **kw: None, run_job=run_job)
    out = tmp_path / "o.csv"
    with mock.patch("pwas_hdl.verify.simulation.sim_module", return_value=fake):
        res = runner.invoke(app, ["simulate", str(folders / "sensor"), str(folders / "one.csv"), "-o", str(out)])
    lines = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert res.exit_code == 2 and len(lines) == 1 and "wrote no result" in lines[0], res.output
    log = re.search(r"log: (\S+)$", lines[0]).group(1)
    assert (tmp_path / "tmp") in Path(log).parents and Path(log).read_text() == "the simulator's own words\n", lines[0]
    assert not out.exists() and not [p for p in (tmp_path / "tmp").iterdir() if p.is_dir()]  # the work folder is gone


@pytest.mark.rtl
def test_simulate_writes_into_the_design_folder_by_default(folders, sim_cache, tmp_path):
    """Without -o the results go to OUTDIR/sim/SIMULATOR.csv / .json, where `report` reads them (-o was
    required, and OUTDIR/sim had to be made by hand); a refused run leaves no empty sim/ behind."""
    import shutil

    hw = tmp_path / "sensor"
    shutil.copytree(folders / "sensor", hw)
    assert not (hw / "sim").exists()
    wrong = tmp_path / "wrong.csv"
    write_csv(wrong, {"a": np.arange(5.0), "y0": np.arange(5.0)})
    res = runner.invoke(app, ["simulate", str(hw), str(wrong), "--build-dir", str(sim_cache)])
    assert res.exit_code == 2 and "no column named 'u0'" in res.output, res.output
    assert not (hw / "sim").exists()
    res = runner.invoke(app, ["simulate", str(hw), str(folders / "one.csv"), "--build-dir", str(sim_cache)])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in (hw / "sim").iterdir()) == ["icarus.csv", "icarus.json"]
    res = runner.invoke(app, ["report", str(hw), "--json", str(tmp_path / "r.json")])
    assert res.exit_code == 0, res.output
    sims = json.loads((tmp_path / "r.json").read_text())["simulation"]
    assert [s["simulator"] for s in sims] == ["icarus"] and sims[0]["mismatches"] == 0
