"""The recurrent sensor through the CLI flow (issue 13): generate -> simulate (Icarus, Verilator)
-> synth, the manifest's recurrence block, and bad input (exit 2, nothing written)."""

from __future__ import annotations

import copy
import json
import shutil

import numpy as np
import pytest

from pwas_hdl.cli import main
from pwas_hdl.design.manifest import load_manifest, validate_manifest
from pwas_hdl.errors import InputError


def _map(y, z):
    return 0.9 * z + 0.1 * np.sqrt(y)


def _csv(path, cols: dict) -> None:
    names = list(cols)
    rows = zip(*(cols[n] for n in names))
    path.write_text(",".join(names) + "\n" + "".join(",".join(repr(float(v)) for v in r) + "\n" for r in rows))


@pytest.fixture(scope="module")
def flow(tmp_path_factory):
    """A recurrent map sensor (fit-map --state, p = 4), a dynamical sensor (fit --mz 1), their data and folders."""
    root = tmp_path_factory.mktemp("recurrent_cli")
    rng = np.random.default_rng(0)
    y, z = rng.uniform(0, 4, 600), rng.uniform(0, 4, 600)
    _csv(root / "samples.csv", {"y": y, "z": z, "znext": _map(y, z)})
    # two trajectories of the recurrence z(t+1) = f(y(t), z(t)) from z(0) = 1 (the sensor's --z0)
    runs, ys, zs = [], [], []
    for r, T in enumerate((120, 80)):
        yr = 2.0 + 1.5 * np.sin(np.arange(T) / (9.0 + 4 * r))
        zr = np.empty(T)
        zr[0] = 1.0
        for t in range(1, T):
            zr[t] = _map(yr[t - 1], zr[t - 1])
        runs.append(np.full(T, r)), ys.append(yr), zs.append(zr)
    _csv(root / "run.csv", {"run": np.concatenate(runs), "y": np.concatenate(ys), "z": np.concatenate(zs)})
    u, yd = rng.uniform(-1, 1, 200), rng.uniform(-1, 1, 200)
    zd = np.zeros(200)
    for t in range(1, 200):
        zd[t] = 0.8 * zd[t - 1] + 0.3 * yd[t] - 0.1 * u[t]
    _csv(root / "dyn.csv", {"u": u, "y": yd, "z": zd})
    assert main(["fit-map", str(root / "samples.csv"), "-o", str(root / "map.json"), "-y", "y", "--state", "z", "-z", "znext",
                 "-p", "4", "--z0", "1"]) == 0
    assert main(["fit", str(root / "dyn.csv"), "-o", str(root / "dyn.json"), "-u", "u", "-y", "y", "-z", "z", "--mu", "1",
                 "--my", "1", "-p", "2", "--sigma", "1e-9", "--mz", "1", "--z0", "0"]) == 0
    for m in ("map", "dyn"):
        assert main(["generate", str(root / f"{m}.json"), "--design", "sensor", "--input-bits", "16", "-o", str(root / m)]) == 0
    return root


def test_generate_writes_the_recurrent_top_and_its_manifest(flow):
    for m, regs, mz in (("map", ["y[t]", "z_hat[t-1]"], 1), ("dyn", ["u[t]", "y[t]", "z_hat[t-1]"], 1)):
        man = load_manifest(flow / m)
        assert man["design"] == man["generator"]["options"]["design"] == "recurrent"
        assert man["top"] == "pwas_recurrent_sensor" and man["lags"]["regressors"] == regs
        r = man["recurrence"]
        assert r["Mz"] == mz and r["ii_cycles"] == man["ii"] == man["latency_cycles"] >= 1
        assert r["lead"] == (1 if m == "map" else 0)
        fb = r["feedback"][0]
        assert fb["output_field"] == "z" and fb["regressors"] == ["z_hat[t-1]"] and fb["regressor_indices"] == [len(regs) - 1]
        # the reset code is the input code of the initial state in the fed-back dimension's format
        inp = man["formats"]["inputs"][len(regs) - 1]
        z0 = r["initial_state"]["values"][0][0]
        assert z0 == (1.0 if m == "map" else 0.0)
        assert abs(inp["offset"] + inp["lsb"] * fb["initial_codes"][0] - z0) <= inp["lsb"] / 2 + 1e-12
        q = fb["requant"]
        assert q["qmin"] == -(2**15) and q["qmax"] == 2**15 - 1 and q["shift"] >= 1
        assert [p["name"] for p in man["ports"] if p["role"] == "in.payload"][0] == "s_axis_tdata"
        assert [f["name"] for f in man["ports"][4]["fields"]] == r["signals"]
        v = (flow / m / "pwas_recurrent_sensor.v").read_text()
        assert "PWAS recurrent virtual-sensor top" in v and "// recurrence: Mz = 1" in v and f"II {man['ii']} (one sample every" in v
        assert str(flow) not in v  # no absolute paths
        rep = (flow / m / "report.md").read_text()
        assert "## Recurrence" in rep and f"K = {q['mul']}, C = {q['add']}, S = {q['shift']}" in rep


def test_recurrent_generate_is_byte_identical(flow, tmp_path):
    assert main(["generate", str(flow / "map.json"), "--design", "sensor", "--input-bits", "16", "-o", str(tmp_path / "again")]) == 0
    names = sorted(p.name for p in (flow / "map").iterdir() if p.is_file())
    assert names == sorted(p.name for p in (tmp_path / "again").iterdir())
    for n in names:
        assert (flow / "map" / n).read_bytes() == (tmp_path / "again" / n).read_bytes(), n


def test_validate_manifest_checks_the_recurrence_block(flow):
    man = load_manifest(flow / "map")
    validate_manifest(man)

    def bad(edit, match):
        m = copy.deepcopy(man)
        edit(m)
        with pytest.raises(InputError, match=match):
            validate_manifest(m)

    bad(lambda m: m.pop("recurrence"), "recurrence is missing")
    bad(lambda m: m["recurrence"].update(ii_cycles=1), "II = latency")
    bad(lambda m: m["recurrence"]["feedback"][0].update(output_field="nope"), "output_field")
    bad(lambda m: m["recurrence"]["feedback"][0].update(regressor_indices=[0]), "regressors")
    bad(lambda m: m["recurrence"]["feedback"][0].update(initial_codes=[2**20]), "outside")
    bad(lambda m: m["recurrence"]["feedback"][0]["requant"].pop("mul"), "mul")
    bad(lambda m: m.update(design="sensor") or m["generator"]["options"].update(design="sensor"), "only the recurrent design")


def test_recurrent_generate_bad_input(flow, tmp_path, capsys):
    static = tmp_path / "static.json"
    assert main(["fit-map", str(flow / "samples.csv"), "-o", str(static), "-y", "y,z", "-z", "znext", "-p", "3"]) == 0
    measured = tmp_path / "measured.json"
    assert main(["fit", str(flow / "dyn.csv"), "-o", str(measured), "-u", "u", "-y", "y", "-z", "z", "--mu", "1", "--my", "1",
                 "-p", "2", "--sigma", "1e-9", "--mz", "1", "--z0", "measured"]) == 0
    capsys.readouterr()
    for model, design, what in ((static, "recurrent", "needs a recurrent model"), (measured, "sensor", "measured")):
        out = tmp_path / f"out_{design}"
        assert main(["generate", str(model), "--design", design, "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.strip().startswith("error:") and err.count("error:") == 1 and what in err and "Traceback" not in err
        assert not out.exists()


def test_simulate_refuses_the_core_of_a_recurrent_model(flow, tmp_path, capsys):
    """`generate --design core` of a recurrent model is the bare core (its last inputs are the fed-back
    estimates); simulate cannot form those from DATA: one error line naming the way out, exit 2, nothing written
    (it said 'inputs have 2 columns, the model has n = 3')."""
    core = tmp_path / "core"
    assert main(["generate", str(flow / "dyn.json"), "--design", "core", "-o", str(core)]) == 0
    capsys.readouterr()
    out = tmp_path / "hw.csv"
    assert main(["simulate", str(core), str(flow / "dyn.csv"), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.strip().startswith("error:") and err.count("error:") == 1 and "Traceback" not in err
    assert "z_hat[t-1]" in err and "--design sensor" in err and "export-testbench" in err
    assert not out.exists() and not out.with_suffix(".json").exists()


@pytest.mark.rtl
def test_recurrent_top_lint_clean(flow):
    from pwas_hdl.flow.toolchain import lint_verilog, which

    if which("verilator") is None:
        pytest.skip("verilator not installed")
    for m in ("map", "dyn"):
        r = lint_verilog(flow / m / "pwas_recurrent_sensor.v", "pwas_recurrent_sensor")
        assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[-2000:]


@pytest.mark.rtl
@pytest.mark.parametrize("model, args", [
    ("map", ["--pipeline", "min", "--ports", "amaranth"]),
    ("dyn", ["--pipeline", "short", "--memory", "corner", "--memory-init", "readmemh", "--rounding", "truncate"]),
    ("map", ["--pipeline", "max-lut", "--memory", "replicated", "--input-scale", "exact", "--input-bits", "11"]),
], ids=["map-min-amaranth", "dyn-short-corner-readmemh", "map-maxlut-replicated-exact-11bit"])
def test_recurrent_top_option_sets_lint_clean_and_byte_identical(flow, tmp_path, model, args):
    """The recurrent top (its feedback requantisation and II = latency counter) behind the other pipelines,
    memories, input scale, ports and widths: lint-clean and byte-identical when generated again (the test
    above covers the default build only)."""
    from pwas_hdl.flow.toolchain import lint_verilog, which

    if which("verilator") is None:
        pytest.skip("verilator not installed")
    for d in ("a", "b"):
        assert main(["generate", str(flow / f"{model}.json"), "--design", "sensor", *args, "-o", str(tmp_path / d)]) == 0
    names = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert names == sorted(p.name for p in (tmp_path / "b").iterdir())
    for n in names:
        assert (tmp_path / "a" / n).read_bytes() == (tmp_path / "b" / n).read_bytes(), n
    r = lint_verilog(tmp_path / "a" / "pwas_recurrent_sensor.v", "pwas_recurrent_sensor")
    assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[-2000:]


@pytest.mark.rtl
@pytest.mark.parametrize("simulator", ["icarus", "verilator"])
def test_simulate_recurrent_design(flow, tmp_path, simulator, sim_cache, capsys):
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    out = tmp_path / "hw.csv"
    args = ["simulate", str(flow / "map"), str(flow / "run.csv"), "-o", str(out), "--traj-col", "run", "--simulator", simulator,
            "--build-dir", str(sim_cache)]
    assert main(args) == 0
    s = json.loads(out.with_suffix(".json").read_text())
    assert s["kind"] == "recurrent" and s["mismatches"] == 0 and s["checks"]["passed"] and s["trajectories"] == 2
    assert s["samples"] == 200 and s["latency_cycles"]["measured_min"] == s["latency_cycles"]["measured_max"] == s["ii"]["manifest"]
    assert s["ii"]["measured"] == s["ii"]["manifest"]
    lines = out.read_text().splitlines()
    assert lines[0] == "row,estimate_of_row,z_hw,z_bittrue,z_float,out_of_range,mismatch" and len(lines) == 201
    tab = np.array([[float(c) for c in ln.split(",")] for ln in lines[1:]])
    np.testing.assert_array_equal(tab[:, 2], tab[:, 3])  # hw == bit-true
    np.testing.assert_array_equal(tab[:, 1], tab[:, 0] + 1)  # lead 1
    # the float column is the model's own recurrence, restarted per trajectory
    sensor = PWASVirtualSensor.load(flow / "map.json")
    data = np.loadtxt(flow / "run.csv", delimiter=",", skiprows=1)
    zf = np.concatenate([sensor.predict(None, data[data[:, 0] == r][:, 1:2])[:, 0] for r in (0, 1)])
    np.testing.assert_allclose(tab[:, 4], zf, rtol=0, atol=1e-12)
    # measured deviation of the 16-bit recurrence from the float one: a few output LSBs, and it tracks the true z
    assert s["max_error_vs_float_lsb"] < 64
    t = s["targets"]["z"]
    assert t["reference_column"] == "z" and t["reference_rows"] == 198 and t["rmsee_hw"] < 0.05
    if simulator != "icarus":
        return
    capsys.readouterr()
    # bad input: one error line, exit 2, nothing written
    for extra, what in ((["--engine", "native"], "feed-forward designs only"), (["--traj-col", "nope"], "nope")):
        o = tmp_path / f"bad{len(what)}.csv"
        assert main(["simulate", str(flow / "map"), str(flow / "run.csv"), "-o", str(o), "--simulator", "verilator"
                     if extra[0] == "--engine" else "icarus", "--build-dir", str(sim_cache), *extra]) == 2
        err = capsys.readouterr().err
        assert err.strip().startswith("error:") and err.count("error:") == 1 and what in err and "Traceback" not in err
        assert not o.exists() and not o.with_suffix(".json").exists()
    # the recurrent top's testbench (its vectors from the bit-true recurrence; run in tests/test_export_testbench.py)
    assert main(["export-testbench", str(flow / "map"), "-o", str(tmp_path / "tb"), "--samples", "50"]) == 0
    assert (tmp_path / "tb" / "tb_pwas_recurrent_sensor.v").is_file()
    capsys.readouterr()
    (tmp_path / "noy.csv").write_text("x,z\n1,2\n3,4\n")
    assert main(["simulate", str(flow / "map"), str(tmp_path / "noy.csv"), "-o", str(tmp_path / "noy_hw.csv")]) == 2
    assert not (tmp_path / "noy_hw.csv").exists()
    # an RTL that differs from its bit-true model (the model's initial state edited after generate): exit 1
    bad = tmp_path / "edited"
    shutil.copytree(flow / "map", bad)
    d = json.loads((bad / "model.json").read_text())
    d["recurrence"]["initial_state"]["values"] = {"z": [1.5]}
    (bad / "model.json").write_text(json.dumps(d))
    assert main(["simulate", str(bad), str(flow / "run.csv"), "-o", str(tmp_path / "e.csv"), "--traj-col", "run",
                 "--build-dir", str(sim_cache)]) == 1
    se = json.loads((tmp_path / "e.json").read_text())
    assert se["mismatches"] > 0 and not se["checks"]["passed"]


@pytest.mark.rtl
def test_simulate_recurrent_waves_folder_is_replaced_and_named_as_given(flow, tmp_path, sim_cache, monkeypatch):
    """--waves on the segment bench: the bench wrote straight into OUT_waves/ (a previous run's files
    stayed in it, a failed run left a partial folder) and the summary named it by its absolute path.
    Now the folder is staged and replaces the old one with the CSV, and ``waves`` is spelt as -o is."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "hw_waves").mkdir()
    (tmp_path / "hw_waves" / "old.fst").write_text("previous run")
    assert main(["simulate", str(flow / "map"), str(flow / "run.csv"), "-o", "hw.csv", "--traj-col", "run", "--waves",
                 "--build-dir", str(sim_cache)]) == 0
    s = json.loads((tmp_path / "hw.json").read_text())
    assert s["waves"] == "hw_waves/pwas_recurrent_sensor.fst" and (tmp_path / s["waves"]).stat().st_size > 0
    assert not (tmp_path / "hw_waves" / "old.fst").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hw.csv", "hw.json", "hw_waves"]
    job = json.loads((tmp_path / "hw_waves" / "job.json").read_text())  # names no staging folder that is gone
    assert job["result"] == "result.json" and (tmp_path / "hw_waves" / job["result"]).is_file()


@pytest.mark.synth
def test_synth_generic_recurrent(flow, tmp_path):
    out = tmp_path / "synth"
    assert main(["synth", str(flow / "map"), "--fpga", "generic", "-o", str(out)]) == 0
    r = json.loads((out / "synth.json").read_text())
    man = load_manifest(flow / "map")
    assert r["latency_cycles"] == r["ii"] == man["ii"] and r["design_hash"] == man["design_hash"]
    assert r["luts"] > 0 and r["ffs"] > 0 and r["multipliers_rtl"] >= 1
