"""Bad option values and output paths found by a sweep of every command (qa2): each is refused with
one error: line, exit 2 and nothing written, before any tool runs."""

from __future__ import annotations

import shutil

import pytest

import pwas_hdl.cli
from pwas_hdl.design.generate import build_design, write_folder
from pwas_hdl.verify.simulation import sim_module
from tests.helpers.cli import CliRunner
from tests.helpers.folders import tree


@pytest.fixture(scope="module")
def design(tmp_path_factory):
    m = sim_module("pwas_designs").synthetic_model(0, 1, 0, 1, 1, seed=2)
    root = tmp_path_factory.mktemp("qa2cli")
    model = root / "m.json"
    m.save(model)
    return write_folder(build_design(m, design="core").files, root / "hw"), model


def _refused(tmp_path, args, message):
    before = tree(tmp_path)
    res = CliRunner().invoke(pwas_hdl.cli.app, args)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], (res.exit_code, lines)
    assert tree(tmp_path) == before


@pytest.mark.parametrize("args, message", [
    (["report", "{hw}", "--json", "{hw}/model.json"], "is also the input the design's model file"),
    (["report", "{hw}", "-o", "{hw}/pwas_core.v"], "is also the input the design's verilog file"),
    (["report", "{hw}", "--sim", ""], "--sim is empty"),
    (["synth", "{hw}", "--fpga", "generic", "--json", "{hw}/pwas_core_rom_b0.hex"], "is also the input a weight memory"),
    (["synth", "{hw}", "--fpga", ""], "unknown synthesis target ''"),
    (["synth", "{hw}", "--device", " "], "--device (device) is empty"),
    (["synth", "{hw}", "--package", ""], "--package (package) is empty"),
    (["synth", "{hw}", "--seed", str(2**63)], "--seed (seed) must be an integer in 0..9223372036854775807"),
    (["simulate", "{hw}", "{data}", "-o", "{hw}/pwas_core.v"], "is also the input the design's verilog file"),
    (["simulate", "{hw}", "{data}", "-o", ""], "-o: the output path is empty"),
    (["simulate", "{hw}", "{data}", "-o", "{tmp}/s.csv", "--seed", "-1"], "--seed (seed) must be an integer >= 0, got -1"),
    (["generate", "{model}", "-o", "{tmp}/g", "--workers", "-1"], "--workers must be a non-negative integer"),
    (["generate", "{model}", "-o", "{tmp}/g", "--scheduler", ""], "--scheduler must be an address"),
    (["make-data", "lorenz", "-o", "{tmp}/l.csv", "--test-samples", "0"], "--samples and --test-samples must be >= 1"),
    (["make-data", "pv-benchmark", "-o", "{tmp}/p.csv", "--test-samples", "1000000000"], "--test-samples = 1000000000 exceeds"),
])
def test_bad_value_or_path_is_refused_before_the_work(design, tmp_path, args, message):
    hw, model = design
    local = tmp_path / "hw"
    shutil.copytree(hw, local)
    (tmp_path / "d.csv").write_text("y0,z0\n0.1,0.2\n0.3,0.4\n")
    fill = {"hw": str(local), "model": str(model), "data": str(tmp_path / "d.csv"), "tmp": str(tmp_path)}
    _refused(tmp_path, [a.format(**fill) for a in args], message)
