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
    assert code == 2 and len(lines) == 1 and "--fpga (fpga_target) must be one of ecp5, ice40, got 'vhdl'" in lines[0], err
    assert not (tmp_path / "j").exists()


# ------------------------------------------------------------------ the goal's memory (issue 14)
def test_goal_latency_takes_the_replicated_memory(lorenz_tiny):
    """--goal latency without --memory on ECP5 builds exactly --memory replicated --goal latency; every
    other goal, --fpga ice40 and an explicit --memory keep their memory (banked by default)."""
    gd = build_design(lorenz_tiny.model, goal="latency")
    assert gd.manifest["generator"]["options"]["memory"] == "replicated"
    grid = lorenz_tiny.sensor.grid_
    assert gd.manifest["memory"]["memories"] == grid.n + 1 and gd.manifest["memory"]["depth"] == grid.n_vertices
    same = build_design(lorenz_tiny.model, goal="latency", memory="replicated")
    assert gd.files == same.files
    for kw, mem in (({"goal": "latency", "memory": "banked"}, "banked"), ({"goal": "latency", "fpga_target": "ice40"}, "banked"),
                    ({"goal": "balanced"}, "banked"), ({"goal": "throughput"}, "banked"), ({}, "banked"),
                    ({"goal": "latency", "architecture": "serial"}, "single")):  # the serial core's one memory
        assert build_design(lorenz_tiny.model, **kw).manifest["generator"]["options"]["memory"] == mem, kw


def _fxm(partitions, nz=1):
    import numpy as np

    from pwas_hdl.fit.geometry import Grid
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel

    n = len(partitions)
    grid = Grid([0.0] * n, [1.0] * n, partitions)
    w = np.random.default_rng(0).normal(size=(grid.n_vertices, nz))
    return FixedPointModel(grid, w)


@pytest.mark.parametrize("partitions, nz, plain, goal, fpga, expected", [
    ((7, 7, 7, 7), 1, True, "latency", "ecp5", "replicated"),   # the Lorenz core: 5 x 3 DP16KD, 5 MULT
    ((3, 3), 1, True, "latency", None, "replicated"),
    ((7, 7, 7, 7), 1, False, "latency", "ecp5", "banked"),      # not a plain parallel core / sensor
    ((7, 7, 7, 7), 1, True, "latency", "ice40", "banked"),
    ((7, 7, 7, 7), 1, True, "throughput", "ecp5", "banked"),
    ((7, 7, 7, 7), 1, True, None, "ecp5", "banked"),
    ((7, 5, 7), 1, True, "latency", "ecp5", "banked"),          # stride 48: the address needs adders
    ((5, 7, 7), 1, True, "latency", "ecp5", "replicated"),      # strides 64, 8, 1 (p_0 is free)
    ((7,), 1, True, "latency", "ecp5", "banked"),               # n = 1: no fields form
    ((15, 15, 15, 15), 1, True, "latency", "ecp5", "banked"),   # 5 copies of 65 536 words: > 36 DP16KD
    ((7, 7, 7, 7), 8, True, "latency", "ecp5", "banked"),       # 40 multipliers: > 36 MULT18X18D
])
def test_goal_memory_rule(partitions, nz, plain, goal, fpga, expected):
    from pwas_hdl.design.goal_memory import goal_memory

    assert goal_memory(goal, fpga, _fxm(partitions, nz), plain=plain) == expected


def test_goal_memory_counts_the_rows():
    """The rule's block counts are the floorplan row's: a model just under and just over the 36 DP16KD."""
    from pwas_hdl.design.goal_memory import goal_memory
    from pwas_hdl.fixedpoint.memory_layout import make_layout
    from pwas_hdl.flow.explore import bram18k_blocks
    from pwas_hdl.flow.floorplan import SITE_TABLES

    rows = len(SITE_TABLES["45k"].sites["DP16KD"])
    for nz in range(1, 8):
        fxm = _fxm((7, 7, 7, 7), nz)
        lay = make_layout(fxm.grid, "replicated")
        brams = lay.n_banks * bram18k_blocks(lay.depth, nz * fxm.weight_format.bits)
        mem = goal_memory("latency", "ecp5", fxm, plain=True)
        assert (mem == "replicated") == (brams <= rows and lay.n_banks * nz <= 36), (nz, brams, mem)


def test_cli_goal_latency_memory(capsys, tmp_path, lorenz_tiny):
    code, _, err = _run(capsys, "generate", lorenz_tiny.model, "-o", tmp_path / "r", "--goal", "latency")
    assert code == 0, err
    man = json.loads((tmp_path / "r" / "manifest.json").read_text())
    assert man["generator"]["options"]["memory"] == "replicated"
    code, _, err = _run(capsys, "generate", lorenz_tiny.model, "-o", tmp_path / "b", "--goal", "latency", "--memory", "banked")
    assert code == 0, err
    assert json.loads((tmp_path / "b" / "manifest.json").read_text())["generator"]["options"]["memory"] == "banked"
    code, _, err = _run(capsys, "generate", lorenz_tiny.model, "-o", tmp_path / "x", "--goal", "latency", "--memory", "fastest")
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and "--memory (memory) must be one of" in lines[0], err
    assert not (tmp_path / "x").exists()
