"""`pwas-hdl report`: collects generate / simulate / synth results of a folder into one table."""

from __future__ import annotations

import json

import numpy as np
from helpers.cli import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.design.generate import generate
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

runner = CliRunner()


def _folder(tmp_path):
    rng = np.random.default_rng(0)
    y = rng.uniform(-1, 1, (300, 1))
    m = PWASVirtualSensor(my=2, partitions=3, sigma=1e-3, output_names=["y"], target_names=["z"]).fit(None, y, y**2)
    out = tmp_path / "hw"
    generate(m, out)
    return out


def test_report_collects_sim_and_synth(tmp_path):
    out = _folder(tmp_path)
    (out / "sim").mkdir()
    (out / "sim" / "icarus.json").write_text(json.dumps({
        "simulator": "icarus", "samples": 10, "mismatches": 0, "latency_cycles": {"measured_min": 7, "measured_max": 7},
        "ii": {"measured": 1.0}, "max_error_vs_float_lsb": 0.25, "within_error_bound": True, "samples_per_second": 1e3,
        "targets": {"z": {"reference_column": "z", "rmsee_float": 0.5, "rmsee_hw": 0.51,
                          "rmsee_increase_hw_vs_float_percent": 2.0}}}))
    (out / "synth" / "ecp5").mkdir(parents=True)
    (out / "synth" / "ecp5" / "synth.json").write_text(json.dumps({
        "target": "ecp5", "part": "LFE5U-45F", "luts": 123, "ffs": 45, "carry": 6, "dsp": 3, "bram": 3,
        "bram_bits": 55296, "fmax_mhz": 99.5, "latency_ns": 70.35, "throughput_msps": 99.5, "timing_met": True,
        "floorplan": {"mode": "auto", "applied": True, "rows": {"DP16KD": "Y34", "MULT18X18D": "Y46"}, "cells": {}, "reason": None}}))
    res = runner.invoke(app, ["report", str(out), "--json", str(tmp_path / "r.json")])
    assert res.exit_code == 0, res.output
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["design"]["N"] == 16 and rep["design"]["ii"] == 1
    assert rep["simulation"][0]["targets"]["z"]["rmsee_hw"] == 0.51
    assert rep["synthesis"][0]["luts"] == 123
    assert "| icarus | 10 | 0 | 7..7 |" in res.output
    assert "| ecp5 | LFE5U-45F | 123 | 45 |" in res.output
    assert rep["synthesis"][0]["floorplan"] == {"applied": True, "rows": {"DP16KD": "Y34", "MULT18X18D": "Y46"}, "reason": None}
    assert "Floorplan (ecp5): block RAMs and multipliers on fixed sites (DP16KD in row Y34, MULT18X18D in row Y46" in res.output


def test_report_refuses_a_foreign_summary(tmp_path):
    out = _folder(tmp_path)
    bad = tmp_path / "x.json"
    bad.write_text('{"hello": 1}')
    res = runner.invoke(app, ["report", str(out), "--sim", str(bad)])
    assert res.exit_code == 2 and "not a `pwas-hdl simulate` summary" in res.output
    res = runner.invoke(app, ["report", str(tmp_path / "nowhere")])
    assert res.exit_code == 2 and "run `pwas-hdl generate" in res.output


SIM_OK = {"simulator": "icarus", "samples": 10, "mismatches": 0, "latency_cycles": {"measured_min": 7, "measured_max": 7},
          "ii": {"measured": 1.0}, "max_error_vs_float_lsb": 0.25, "targets": {"z": {"rmsee_float": 0.5, "rmsee_hw": 0.51}}}
SYNTH_OK = {"target": "ecp5", "top": "pwas_core", "part": "LFE5U-45F", "luts": 123, "ffs": 45, "fmax_mhz": 99.5,
            "latency_ns": 70.35, "throughput_msps": 99.5}


def test_report_refuses_values_out_of_range(tmp_path):
    """Negative counts, zero samples, an infinite fmax, another top were printed as if measured."""
    out = _folder(tmp_path)
    man = json.loads((out / "manifest.json").read_text())
    cases = [
        ("sim", {"mismatches": -5}, "mismatches = -5 is out of range"),
        ("sim", {"samples": 0, "mismatches": 0}, "samples = 0 is out of range"),
        ("sim", {"mismatches": 11}, "more than samples"),
        ("sim", {"latency_cycles": {"measured_min": -1, "measured_max": 7}}, "latency_cycles.measured_min = -1"),
        ("sim", {"max_error_vs_float_lsb": float("nan")}, "not a finite number"),
        ("sim", {"targets": {"z": {"rmsee_hw": -0.5}}}, "targets.z.rmsee_hw = -0.5"),
        ("sim", {"design": "other_top", "design_hash": man["design_hash"]}, "result for the top \"other_top\""),
        ("synth", {"luts": -1}, "luts = -1 is out of range"),
        ("synth", {"fmax_mhz": float("inf")}, "fmax_mhz = inf is not a finite number"),
        ("synth", {"fmax_mhz": 0}, "fmax_mhz = 0 is out of range (must be > 0)"),
        ("synth", {"target": "xilinx"}, "target = \"xilinx\" is not one of"),
        ("synth", {"top": "other_top", "design_hash": man["design_hash"]}, "result for the top \"other_top\""),
    ]
    for kind, change, msg in cases:
        for p in (out / "sim" / "s.json", out / "synth" / "ecp5" / "synth.json"):
            p.unlink(missing_ok=True)
        path = out / "sim" / "s.json" if kind == "sim" else out / "synth" / "ecp5" / "synth.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({**(SIM_OK if kind == "sim" else SYNTH_OK), **change}))  # Infinity / NaN as JSON writes them
        res = runner.invoke(app, ["report", str(out), "--json", str(tmp_path / "r.json"), "-o", str(tmp_path / "r.md")])
        assert res.exit_code == 2, (change, res.output)
        assert res.output.count("error:") == 1 and msg in res.output and "Traceback" not in res.output, (change, res.output)
        assert not (tmp_path / "r.json").exists() and not (tmp_path / "r.md").exists()
    # the same files within range are shown; another top marked stale (an earlier design) is kept, not refused
    (out / "sim" / "s.json").write_text(json.dumps({**SIM_OK, "design": "other_top", "design_hash": "0" * 64}))
    (out / "synth" / "ecp5" / "synth.json").write_text(json.dumps({**SYNTH_OK, "top": man["top"], "design_hash": man["design_hash"]}))
    res = runner.invoke(app, ["report", str(out)])
    assert res.exit_code == 0 and "| ecp5 | LFE5U-45F | 123 | 45 |" in res.output and "stale" in res.output, res.output


def test_report_shows_the_class_results_of_a_classifier(tmp_path):
    """A classifier design's simulation summary has the class mismatches, the accuracy against the label
    and the agreement with the float argmax; report showed only the score rows (no reference, RMSEE '-')."""
    from pwas_hdl.io.csv_table import write_csv
    from pwas_hdl.systems.switched_linear import switched_training_runs

    write_csv(tmp_path / "train.csv", switched_training_runs(2, 300, seed=0).columns())
    assert runner.invoke(app, ["fit", str(tmp_path / "train.csv"), "-o", str(tmp_path / "m.json"), "-u", "u", "-y", "y",
                               "-z", "mode", "--classify", "--mu", "1", "--my", "1", "-p", "2", "--sigma", "1e-3",
                               "--traj-col", "run"]).exit_code == 0
    out = tmp_path / "hw"
    assert runner.invoke(app, ["generate", str(tmp_path / "m.json"), "--design", "sensor", "-o", str(out)]).exit_code == 0
    (out / "sim").mkdir()
    clf = {"target": "mode", "classes": [1.0, 2.0, 3.0], "class_mismatches": 0, "reference_column": "mode",
           "agreement_float": {"samples": 10, "agreement": 0.9}, "scores_hw": {"accuracy": 0.8125},
           "scores_float": {"accuracy": 0.75}}
    (out / "sim" / "icarus.json").write_text(json.dumps({**SIM_OK, "targets": {}, "classifier": clf}))
    (out / "sim" / "verilator.json").write_text(json.dumps({**SIM_OK, "simulator": "verilator", "targets": {},
                                                            "classifier": {**clf, "scores_hw": {"accuracy": "high"}}}))
    res = runner.invoke(app, ["report", str(out), "--json", str(tmp_path / "r.json")])
    assert res.exit_code == 0, res.output
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["simulation"][0]["classifier"] == {"class_mismatches": 0, "accuracy_hw": 0.8125, "accuracy_float": 0.75,
                                                  "reference_column": "mode", "agreement_float": 0.9}
    assert rep["simulation"][1]["classifier"]["accuracy_hw"] is None  # a value of another type is not carried
    assert "## Classifier" in res.output and "| icarus | 10 | 0 | 0.8125 | 0.75 | mode | 0.9 |" in res.output
    assert "| verilator | 10 | 0 | - | 0.75 | mode | 0.9 |" in res.output
