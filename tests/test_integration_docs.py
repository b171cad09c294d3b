"""What an integrator needs from a generated folder's report.md (the datasheet) when the design is
wired by hand into another project: how the `$readmemh` weights are found, how many transfers the
sensor top's lag bank swallows after reset, and how a physical input becomes a code."""

from __future__ import annotations

import json

import pytest

from pwas_hdl.verify.simulation import sim_module

designs = sim_module("pwas_designs")
DesignConfig = designs.DesignConfig

SENSOR_READMEMH = DesignConfig("s-u1y2-p3-readmemh", "sensor", 1, 2, 1, 1, 3, 1, {"memory_init": "readmemh"})
SENSOR_INLINE = DesignConfig("s-u1y2-p3", "sensor", 1, 2, 1, 1, 3, 1, {})


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    root = tmp_path_factory.mktemp("integ-docs")
    for cfg in (SENSOR_READMEMH, SENSOR_INLINE):
        cfg.generate(root / cfg.name)
    return root


def test_report_of_a_readmemh_design_says_how_the_hex_files_are_found(folders):
    out = folders / SENSOR_READMEMH.name
    man = json.loads((out / "manifest.json").read_text())
    report = (out / "report.md").read_text()
    param = man["memory"]["init"]["parameter"]
    assert "$readmemh" in report and f"`{param}`" in report, report
    assert f'#(.{param}("' in report  # how to set it where the module is instantiated
    for f in man["files"]["hex"]:
        assert f["file"] in report


def test_report_of_an_inline_design_says_the_hex_files_are_not_needed(folders):
    report = (folders / SENSOR_INLINE.name / "report.md").read_text()
    assert "MEM_DIR" not in report
    assert "inline" in report and "not read by the design" in report, report


def test_report_states_the_warm_up_and_the_input_code_of_a_physical_value(folders):
    out = folders / SENSOR_INLINE.name
    man = json.loads((out / "manifest.json").read_text())
    report = (out / "report.md").read_text()
    k = man["lags"]["warmup"]["samples_without_output"]
    assert k >= 1
    assert f"the first {k} transfer" in report and "`warm`" in report, report
    for inp in man["formats"]["inputs"]:
        # the exact offset and LSB of the code, not only the 6-digit domain ends
        assert repr(inp["offset"]) in report and repr(inp["lsb"]) in report, (inp, report)
    assert "half up" in report
