"""The README's Python API section runs: its ```python blocks, in order, in a temporary folder.

Blocks whose first line says ``# needs Icarus`` run the simulator (marker ``rtl``), ``# needs
Yosys`` the synthesis tools (marker ``synth``; its report reads the simulation's summary, so that
test is ``rtl`` too); the rest is the fast part. Each test runs every
block up to the last one it covers, so no test depends on another having run.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def _blocks() -> list[str]:
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Python API\n") :]
    section = section[: section.index("\n## ", 1)]
    return re.findall(r"```python\n(.*?)```", section, re.S)


def _needs(block: str) -> str | None:
    first = block.lstrip().splitlines()[0]
    mo = re.match(r"# needs (Icarus|Yosys)", first)
    return {"Icarus": "rtl", "Yosys": "synth"}[mo.group(1)] if mo else None


def _run(upto: str | None, tmp_path: Path, monkeypatch) -> None:
    """Run the fast blocks and, when ``upto`` is a marker, the blocks up to the last with that marker."""
    blocks = _blocks()
    last = max((i for i, b in enumerate(blocks) if _needs(b) == upto), default=-1) if upto else len(blocks) - 1
    monkeypatch.chdir(tmp_path)
    ns: dict = {"__name__": "readme"}
    for i, block in enumerate(blocks[: last + 1]):
        if upto is None and _needs(block) is not None:
            continue
        exec(compile(block, f"README.md python block {i + 1}", "exec"), ns)


def test_readme_has_the_api_blocks():
    blocks = _blocks()
    assert len(blocks) >= 5
    assert {_needs(b) for b in blocks} == {None, "rtl", "synth"}
    assert any("clone(" in b for b in blocks) and any("simulate_arrays(" in b for b in blocks)


def test_readme_python_api_fast_part(tmp_path, monkeypatch):
    _run(None, tmp_path, monkeypatch)
    assert (tmp_path / "hw" / "manifest.json").is_file() and (tmp_path / "model.json").is_file()


@pytest.mark.rtl
@pytest.mark.slow
def test_readme_python_api_simulation(tmp_path, monkeypatch, sim_cache):
    monkeypatch.setenv("PWAS_HDL_SIM_CACHE", str(sim_cache))
    _run("rtl", tmp_path, monkeypatch)
    assert (tmp_path / "hw_icarus.json").is_file()


@pytest.mark.synth
@pytest.mark.rtl
@pytest.mark.slow
def test_readme_python_api_synthesis(tmp_path, monkeypatch, sim_cache):
    monkeypatch.setenv("PWAS_HDL_SIM_CACHE", str(sim_cache))
    _run("synth", tmp_path, monkeypatch)
    assert (tmp_path / "hw" / "synth" / "generic" / "synth.json").is_file()
