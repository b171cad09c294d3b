"""Seed 003's estimator as a generated design (issue 12): the estimator file, generate, manifest, lint.

The fast tests check the file format and the refusals (no design is built); the ``rtl`` tests
build the folder once (module fixture), lint it and check byte-identical reruns.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pwas_hdl.errors import InputError
from pwas_hdl.fit.estimator_file import SwitchedEstimatorConfig, estimator_text, read_estimator, write_estimator
from pwas_hdl.systems.switched_observer import estimator_config


def test_estimator_file_round_trip_is_exact(tmp_path):
    cfg = estimator_config()
    p = write_estimator(cfg, tmp_path / "est.json")
    back = read_estimator(p)
    for a, b in zip(cfg.A + cfg.B + cfg.C + cfg.K, back.A + back.B + back.C + back.K):
        assert np.array_equal(a, b)
    assert estimator_text(back) == p.read_text()
    assert back.signal_names() == (["u"], ["y"], ["x1", "x2"]) and back.window == 1 and back.n_modes == 3


@pytest.mark.parametrize("edit, words", [
    (lambda d: d.update(extra=1), "extra"),
    (lambda d: d["modes"][1].update(B=[1.0]), "modes[1].B has 1 values"),
    (lambda d: d["modes"][0]["A"][0].append(0.5), "modes[0].A[0] has 3 values"),
    (lambda d: d.update(window=0), "window"),
    (lambda d: d.update(version=2), "version 2 is not supported"),
    (lambda d: d["signals"].update(states=["x1", "u"]), "distinct"),
])
def test_estimator_file_refuses_bad_content(tmp_path, edit, words):
    d = json.loads(estimator_text(estimator_config()))
    edit(d)
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(d))
    with pytest.raises(InputError, match="bad.json") as ei:
        read_estimator(p)
    assert words in str(ei.value)


def test_estimator_file_refuses_an_infinite_number(tmp_path):
    d = json.loads(estimator_text(estimator_config()))
    d["modes"][0]["K"][0] = 12345.5
    p = tmp_path / "inf.json"
    p.write_text(json.dumps(d).replace("12345.5", "1e999"))  # valid JSON that parses to inf
    with pytest.raises(InputError, match=r"modes\[0\]\.K holds a value that is not a finite number"):
        read_estimator(p)


@pytest.mark.parametrize("damage", ["truncated", "nan"])
def test_generate_names_the_estimator_hint_for_a_broken_estimator_file(tmp_path, capsys, damage):
    """A truncated / NaN estimator file through `generate`: one error line with the estimator's hint
    (not the model file's `pwas-hdl fit`), exit 2, nothing written."""
    from pwas_hdl.cli import main

    text = estimator_text(estimator_config())
    bad = text[: len(text) // 2] if damage == "truncated" else text.replace("]", ", NaN]", 1)
    (tmp_path / "est.json").write_text(bad)
    assert main(["generate", str(tmp_path / "est.json"), "-o", str(tmp_path / "g")]) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "--estimator-out" in lines[0], lines
    assert "pwas-hdl fit" not in lines[0] and not (tmp_path / "g").exists()


def test_generate_refuses_pwas_options_and_unstable_gains(tmp_path):
    from pwas_hdl.design.generate import build_design

    cfg = estimator_config()
    with pytest.raises(InputError, match="--memory 'replicated' belongs to the PWAS designs") as exc:
        build_design(cfg, memory="replicated")
    # the options it lists are the ones generate takes for an estimator file (it said the bank formats
    # were API-only after generate got --state-bits, --state-frac, --coef-frac and --input-headroom)
    assert "API" not in str(exc.value)
    for opt in ("--architecture", "--bank-lanes", "--input-bits", "--input-headroom", "--state-bits", "--state-frac",
                "--coef-frac"):
        assert opt in str(exc.value)
    with pytest.raises(InputError, match="design recurrent does not apply"):
        build_design(cfg, design="recurrent")
    with pytest.raises(InputError, match=r"--state-bits \(state_bits\) must be an integer in 2\.\.48"):
        build_design(cfg, state_bits=1)
    bad = SwitchedEstimatorConfig(cfg.A, cfg.B, cfg.C, [np.full(2, 50.0)] * 3)  # poles of A - K C far outside
    with pytest.raises(InputError, match="not stable"):
        build_design(bad)


def test_cli_make_data_writes_the_estimator_and_refuses_a_bad_path(tmp_path):
    from pwas_hdl.cli import app
    from helpers.cli import CliRunner

    r = CliRunner().invoke(app, ["make-data", "switched-linear", "-o", str(tmp_path / "d.csv"), "--runs", "1", "--samples", "50",
                                 "--estimator-out", str(tmp_path / "est.json")])
    assert r.exit_code == 0, r.output
    assert read_estimator(tmp_path / "est.json").source["poles"] == [0.3, 0.4]
    r = CliRunner().invoke(app, ["make-data", "switched-linear", "-o", str(tmp_path / "e.csv"), "--runs", "1", "--samples", "50",
                                 "--estimator-out", str(tmp_path / "nofolder" / "est.json")])
    assert r.exit_code == 2 and "error:" in r.output and not (tmp_path / "e.csv").exists()


# ------------------------------------------------------------------------------------------ rtl: the built folder
@pytest.fixture(scope="module")
def est_folder(tmp_path_factory):
    from pwas_hdl.design.generate import generate

    out = tmp_path_factory.mktemp("est") / "hw"
    path = write_estimator(estimator_config(), out.parent / "est.json")
    return path, generate(path, out)


@pytest.mark.rtl
def test_generate_estimator_folder_manifest_lint_reruns(est_folder, tmp_path):
    from pwas_hdl.design.generate import generate
    from pwas_hdl.design.manifest import load_manifest
    from pwas_hdl.flow.toolchain import lint_verilog

    path, gd = est_folder
    man = load_manifest(gd.outdir)
    assert man["design"] == "estimator" and man["latency_cycles"] == 1 == man["ii"] and man["files"]["hex"] == []
    e = man["estimator"]
    assert (e["modes"], e["states"], e["window"]) == (3, 2, 1) and e["formats"]["state_bits"] == gd.model.state_bits
    outs = [f["name"] for p in man["ports"] if p["role"] == "out.payload" for f in p["fields"]]
    assert outs == ["x1_hat", "x2_hat", "y_hat", "mode_index", "state_saturated"]
    mode = next(f for p in man["ports"] for f in p.get("fields", []) if f["name"] == "mode_index")
    assert mode["format"]["offset"] == 1.0 and not mode["signed"]
    again = generate(path, tmp_path / "hw2")
    assert again.files == gd.files  # byte-identical reruns
    text = gd.files["pwas_estimator.v"]
    assert "/tmp" not in text and "seed 003 switched-observer estimator generated by pwas-hdl" in text
    r = lint_verilog(gd.outdir / "pwas_estimator.v", "pwas_estimator")
    assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[:2000]
    # a hand edit of a field width or of the latency is refused (pwas_hdl.design.manifest._estimator_errors)
    from pwas_hdl.design.manifest import manifest_errors

    i = next(k for k, p in enumerate(man["ports"]) if p["role"] == "out.payload")
    wide = json.loads(json.dumps(man))
    wide["ports"][i]["fields"][0]["width"] += 1
    wide["ports"][i]["fields"][0]["format"]["bits"] += 1
    assert any("estimator.formats gives" in e for e in manifest_errors(wide)), manifest_errors(wide)
    late = json.loads(json.dumps(man)) | {"latency_cycles": 3}
    assert any("the parallel estimator's is 1" in e for e in manifest_errors(late)), manifest_errors(late)


def _stimulus(est, n=150, seed=7, noise=0.02):
    """Codes of a noisy switched-linear run followed by out-of-range inputs (saturated to the extreme codes)."""
    from pwas_hdl.systems.switched_linear import switched_training_runs

    d = switched_training_runs(1, n, seed=seed, switching="time", noise=noise)
    rng = np.random.default_rng(seed)
    wild = rng.choice([-1.0, 1.0], size=(40, 2)) * np.array([30.0, 50.0])  # beyond the +-8 head room
    u = np.concatenate([d.u[:, 0], wild[:, 0]])
    y = np.concatenate([d.y[:, 0], wild[:, 1]])
    return est.quantize_signals(u, y)


@pytest.mark.rtl
@pytest.mark.parametrize("simulator, state_bits", [("icarus", None), ("icarus", 12)])  # Verilator: the simulate test below
def test_estimator_rtl_bit_exact_stalls_reset_out_of_range_saturation(simulator, state_bits, est_folder, tmp_path, sim_cache):
    """cocotb on both simulators, driven by the manifest: full speed (latency and II measured), random
    bubbles and backpressure with a reset mid-stream, out-of-range inputs; 12-bit states saturate."""
    from pwas_hdl.design.generate import generate
    from pwas_hdl.verify.estimator_simulation import load_estimator_design, replay_estimator

    path, gd = est_folder
    out = gd.outdir if state_bits is None else generate(path, tmp_path / "sat", state_bits=state_bits, ports="amaranth").outdir
    design = load_estimator_design(out)
    codes = _stimulus(design.est)
    assert np.abs(codes).max() == 2048  # the out-of-range samples reach the extreme codes
    tr = design.est.trace(codes)
    assert bool(tr["state_saturated"].any()) == (state_bits is not None)
    res = replay_estimator(design, codes, simulator, cache_dir=sim_cache)
    assert res["passed"], res.get("failures")
    assert res["mismatches"] == 0 and res["outputs_compared"] > 2 * len(codes)  # full run, the cut prefix, the run after the reset
    assert res["latency"] == [1] and res["ii"] == [1]
    hw = res["rtl"]["full-speed"][0]
    assert np.array_equal(hw["theta"], tr["theta"]) and np.array_equal(hw["x_hat"], tr["x_hat"])
    assert np.array_equal(hw["state_saturated"], tr["state_saturated"])


@pytest.mark.rtl
def test_simulate_estimator_folder_writes_hw_beside_bittrue_and_float(est_folder, tmp_path, sim_cache):
    from pwas_hdl.io.csv_table import write_csv
    from pwas_hdl.systems.switched_linear import switched_training_runs
    from pwas_hdl.verify.simulation import simulate_data

    _, gd = est_folder
    d = switched_training_runs(2, 60, seed=3, switching="time", noise=0.02)
    write_csv(tmp_path / "data.csv", d.columns())
    (tmp_path / "hw_waves").mkdir()
    (tmp_path / "hw_waves" / "old.vcd").write_text("previous run")
    res = simulate_data(gd.outdir, tmp_path / "data.csv", tmp_path / "hw.csv", simulator="verilator", traj_col="run",
                        cache_dir=sim_cache, waves=True)
    s = res["summary"]
    # the waveform folder replaces the previous one with the CSV (the bench wrote into it, old files stayed)
    assert s["waves"] == str(tmp_path / "hw_waves" / "dump.vcd") and Path(s["waves"]).stat().st_size > 0
    assert not (tmp_path / "hw_waves" / "old.vcd").exists()
    assert s["checks"]["passed"] and s["mismatches"] == 0 and s["samples"] == 120 and s["trajectories"] == 2
    assert s["latency_cycles"]["measured_max"] == 1 and s["ii"]["measured"] == 1
    assert s["modes"]["differ_beyond_bound"] == 0
    hw = np.genfromtxt(tmp_path / "hw.csv", delimiter=",", names=True)
    assert {"mode_hat_hw", "mode_hat_bittrue", "mode_hat_float", "x1_hat_hw", "x2_hat_float", "y_hat_hw"} <= set(hw.dtype.names)
    assert np.array_equal(hw["mode_hat_hw"], hw["mode_hat_bittrue"])
    assert "mode_accuracy_hw" in s["metrics"] and "x1_rmse_float" in s["metrics"]
    from pwas_hdl.design.report import collect_report, report_markdown

    rep = collect_report(gd.outdir, [res["summary_path"]])
    text = report_markdown(rep)
    assert rep["design"]["kind"] == "estimator" and rep["fit"] is None
    assert "| verilator | 120 | 0 | 1..1 | 1 |" in text and "mode accuracy hw / float" in text
    assert "Latency 1 cycle, II 1." in text


@pytest.mark.parametrize("ports, reset, polarity", [("axis", "aresetn", "low"), ("amaranth", "rst", "high")])
def test_estimator_header_says_what_each_port_does(tmp_path, ports, reset, polarity):
    """The estimator's Verilog header described its ports by their manifest roles ('aresetn ... reset',
    's_axis_tvalid ... in.valid'): no reset polarity, no handshake rule. It now says what the PWAS designs' header says."""
    from pwas_hdl.design.generate import build_design

    path = write_estimator(estimator_config(), tmp_path / "est.json")
    gd = build_design(path, ports=ports)
    head = gd.files["pwas_estimator.v"].split("\n\n")[0]
    lines = {ln.split()[1]: ln for ln in head.splitlines() if ln.startswith("//   ") and not ln.startswith("//     ")}
    assert f"synchronous reset, active {polarity}" in lines[reset], head
    assert "clock, rising edge" in lines[gd.manifest["clock"]["port"]]
    roles = {p["role"]: p["name"] for p in gd.manifest["ports"]}
    assert f"a transfer on a rising edge with {roles['in.valid']} & {roles['in.ready']}" in lines[roles["in.ready"]]
    assert all(not ln.rstrip().endswith((" reset", " in.valid", " out.payload")) for ln in lines.values()), head
