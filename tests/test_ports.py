"""Port names and order of the generated Verilog (`generate --ports axis|amaranth`), the manifest's
roles, the instantiation template, and the MEM_DIR parameter of `$readmemh` designs."""

from __future__ import annotations

import json
import re
import subprocess

import pytest
from typer.testing import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.design.generate import build_design
from pwas_hdl.flow.toolchain import tool_env, which
from pwas_hdl.verify.simulation import sim_module

designs = sim_module("pwas_designs")

AXIS = ["aclk", "aresetn", "s_axis_tvalid", "s_axis_tready", "s_axis_tdata", "m_axis_tvalid", "m_axis_tready", "m_axis_tdata"]
AMARANTH = ["clk", "rst", "in__valid", "in__ready", "in__payload", "out__valid", "out__ready", "out__payload"]
ROLES = ["clock", "reset", "in.valid", "in.ready", "in.payload", "out.valid", "out.ready", "out.payload"]


def _header(verilog: str, top: str) -> list[str]:
    mo = re.search(r"^module " + top + r"\(([^)]*)\);", verilog, re.M)
    assert mo, "no module header"
    return [p.strip() for p in mo.group(1).split(",")]


@pytest.fixture(scope="module")
def sensor_model():
    return designs.synthetic_model(1, 2, 1, 1, 3, 1, seed=2)


@pytest.mark.parametrize("ports, names, polarity", [("axis", AXIS, "low"), ("amaranth", AMARANTH, "high")])
def test_port_names_order_and_roles(ports, names, polarity, sensor_model):
    gd = build_design(sensor_model, design="sensor", ports=ports)
    man = gd.manifest
    # issue 8: clock, reset, input stream, output stream (then warm); the module header in that order
    assert [p["name"] for p in man["ports"]] == names + ["warm"]
    assert [p["role"] for p in man["ports"]] == ROLES + ["warm"]
    assert _header(gd.files["pwas_sensor.v"], "pwas_sensor") == names + ["warm"]
    assert man["clock"]["port"] == names[0] and man["reset"] == {"port": names[1], "polarity": polarity, "kind": "synchronous"}
    assert man["generator"]["options"]["ports"] == ports
    inst = gd.files["pwas_sensor_inst.v"]
    assert [m.group(1) for m in re.finditer(r"^\s+\.(\w+)\(", inst, re.M)] == names + ["warm"]
    assert f"active {polarity}" in inst and f"active {polarity}" in gd.files["report.md"]
    other = AMARANTH if ports == "axis" else AXIS
    for name in other[2:]:  # the other scheme's names appear nowhere in the Verilog
        assert not re.search(r"(?<![\w$\\])" + name + r"(?![\w$])", gd.files["pwas_sensor.v"]), name
    if ports == "axis":
        assert "assign rst = ~aresetn;" in gd.files["pwas_sensor.v"]


def test_axis_and_amaranth_designs_are_the_same_logic(sensor_model):
    """Renaming is all that differs: the texts agree once the names are mapped back."""
    a = build_design(sensor_model, design="sensor").files["pwas_sensor.v"]
    b = build_design(sensor_model, design="sensor", ports="amaranth").files["pwas_sensor.v"]
    back = a.replace("  input aresetn;\n  wire aresetn;\n", "  input rst;\n").replace("  assign rst = ~aresetn;\n", "")
    for x, y in zip(AXIS, AMARANTH):
        back = re.sub(r"(?<![\w$\\])" + x + r"(?![\w$])", y, back)
    assert back == b


@pytest.mark.skipif(which("verilator") is None, reason="verilator not installed")
@pytest.mark.parametrize("ports, init", [("axis", "inline"), ("amaranth", "inline"), ("axis", "readmemh")])
def test_lint_clean(ports, init, sensor_model, tmp_path):
    gd = build_design(sensor_model, design="sensor", ports=ports, memory_init=init)
    v = tmp_path / "pwas_sensor.v"
    v.write_text(gd.files["pwas_sensor.v"])
    r = subprocess.run([which("verilator"), "--lint-only", "-Wall", str(v)], capture_output=True, text=True, env=tool_env())
    assert r.returncode == 0, r.stderr


def test_readmemh_mem_dir_parameter(sensor_model):
    gd = build_design(sensor_model, design="core", memory_init="readmemh")
    v = gd.files["pwas_core.v"]
    assert 'parameter MEM_DIR = "./";' in v
    loads = re.findall(r'\$readmemh\(\{MEM_DIR, "(pwas_core_rom_b\d+\.hex)"\}, wmem\d+\);', v)
    assert sorted(loads) == sorted(h["file"] for h in gd.manifest["files"]["hex"])
    assert gd.manifest["memory"]["init"]["parameter"] == "MEM_DIR"
    assert 'pwas_core #(.MEM_DIR("./")) u_pwas_core (' in gd.files["pwas_core_inst.v"]
    inline = build_design(sensor_model, design="core")
    assert "MEM_DIR" not in inline.files["pwas_core.v"] and "MEM_DIR" not in inline.files["pwas_core_inst.v"]
    assert inline.manifest["memory"]["init"] == {"kind": "inline"}


def test_bad_ports_option(sensor_model, tmp_path):
    model = tmp_path / "m.json"
    sensor_model.save(model)
    r = CliRunner().invoke(app, ["generate", str(model), "-o", str(tmp_path / "out"), "--ports", "wishbone"])
    assert r.exit_code == 2 and "error:" in r.output and "--ports" in r.output and "Traceback" not in r.output, r.output
    assert not (tmp_path / "out").exists()
    r = CliRunner().invoke(app, ["generate", str(model), "-o", str(tmp_path / "out"), "--ports", "amaranth"])
    assert r.exit_code == 0, r.output
    assert json.loads((tmp_path / "out" / "manifest.json").read_text())["clock"]["port"] == "clk"
