"""generate --goal (issue 14): latency / balanced / throughput name pipeline presets; one of --goal,
--pipeline, --clock-mhz chooses the pipeline, two of them are an error (exit 2, nothing written)."""

from __future__ import annotations

import json

import pytest

from pwas_hdl.cli import main
from pwas_hdl.design.generate import build_design
from pwas_hdl.hdl.params import GOALS, PIPELINE_PRESETS, Pipeline, goal_preset


def _run(capsys, *args):
    code = main([str(a) for a in args])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_goals_name_presets():
    assert set(GOALS) == {"latency", "balanced", "throughput"}
    assert all(v in PIPELINE_PRESETS for v in GOALS.values())
    n = 4
    lat = {g: Pipeline.cast(GOALS[g]).latency(n) for g in GOALS}
    assert lat["latency"] < lat["balanced"] < lat["throughput"]
    assert Pipeline.cast(GOALS["balanced"]) == Pipeline()  # the default
    mx = Pipeline.cast(GOALS["throughput"])
    assert all(mx.to_dict()[k] for k in ("split", "rank", "offset", "addr", "bank", "mem_out", "mul_in", "product")) and mx.tree_levels == 1
    assert Pipeline.cast(GOALS["latency"]) == Pipeline.cast("short")  # min + the multipliers' output register
    assert goal_preset("throughput", "ice40") == "max-lut" and goal_preset("throughput", "ecp5") == "max"
    assert all(goal_preset(g) == GOALS[g] for g in GOALS)
    with pytest.raises(ValueError, match="unknown goal 'fast'"):
        goal_preset("fast", "ice40")


def test_goal_builds_the_preset(lorenz_tiny):
    for goal, preset in GOALS.items():
        gd = build_design(lorenz_tiny.model, goal=goal)
        assert gd.manifest["pipeline"] == Pipeline.cast(preset).to_dict()
        assert gd.manifest["generator"]["options"]["pipeline"] == preset
        if goal == "throughput":  # the same design as the preset itself
            same = build_design(lorenz_tiny.model, pipeline=preset)
            assert gd.files[gd.manifest["files"]["verilog"]] == same.files[same.manifest["files"]["verilog"]]
    with pytest.raises(ValueError, match="unknown goal 'fast'"):
        build_design(lorenz_tiny.model, goal="fast")


def test_cli_goal_and_contradictions(capsys, tmp_path, lorenz_tiny):
    model = lorenz_tiny.model
    code, _, err = _run(capsys, "generate", model, "-o", tmp_path / "t", "--goal", "throughput")
    assert code == 0, err
    man = json.loads((tmp_path / "t" / "manifest.json").read_text())
    assert man["pipeline"] == Pipeline.cast("max").to_dict()
    assert man["latency_cycles"] == Pipeline.cast("max").latency(man["lags"]["My"])
    for extra, word in ((["--pipeline", "min"], "pipeline"), (["--clock-mhz", "50"], "--clock-mhz")):
        code, _, err = _run(capsys, "generate", model, "-o", tmp_path / "x", "--goal", "latency", *extra)
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert code == 2 and len(lines) == 1 and lines[0].startswith("error: "), err
        assert "not --goal with" in lines[0] and word in lines[0]
    code, _, err = _run(capsys, "generate", model, "-o", tmp_path / "x", "--goal", "fast")
    assert code == 2 and "unknown goal 'fast'" in err and "latency, balanced, throughput" in err
    assert not (tmp_path / "x").exists()


def test_cli_goal_follows_fpga(capsys, tmp_path, lorenz_tiny):
    """--goal throughput --fpga ice40 builds the split-multiplier preset (no DSP blocks on the HX8K)."""
    code, _, err = _run(capsys, "generate", lorenz_tiny.model, "-o", tmp_path / "i", "--goal", "throughput", "--fpga", "ice40")
    assert code == 0, err
    man = json.loads((tmp_path / "i" / "manifest.json").read_text())
    assert man["pipeline"] == Pipeline.cast("max-lut").to_dict() and man["pipeline"]["mul_halves"] is True
    assert man["latency_cycles"] == Pipeline.cast("max-lut").latency(man["lags"]["My"])
    code, _, err = _run(capsys, "generate", lorenz_tiny.model, "-o", tmp_path / "j", "--goal", "throughput", "--fpga", "vhdl")
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and "unknown FPGA family 'vhdl'" in lines[0], err
    assert not (tmp_path / "j").exists()
