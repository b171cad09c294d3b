"""The generated FuseSoC ``.core``: accepted by FuseSoC itself, flow API, hex files only when read.

FuseSoC (the PyPI ``fusesoc``, dev extra) runs as a subprocess with an empty configuration file and
its cache and build folders under ``tmp_path``, so the user's FuseSoC setup plays no part.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from pwas_hdl.design.generate import generate
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.flow.toolchain import tool_env
from pwas_hdl.systems.lorenz import lorenz

CASES = [("core", "inline"), ("core", "readmemh"), ("sensor", "inline"), ("sensor", "readmemh")]
IDS = [f"{d}-{m}" for d, m in CASES]


@pytest.fixture(scope="module")
def small_model(tmp_path_factory) -> Path:
    """A small Lorenz sensor (My = 3, p = 3: N = 64 weights), fixed sigma: fitted in well under a second."""
    d = lorenz(1500, seed=0)
    m = PWASVirtualSensor(my=3, partitions=3, gamma=1.2, sigma=1e-3, output_names=["y"], target_names=["z"])
    m.fit(None, d.y, d.z)
    path = tmp_path_factory.mktemp("model") / "small.json"
    m.save(path)
    return path


@pytest.fixture(scope="module")
def designs(small_model, tmp_path_factory) -> dict[tuple[str, str], Path]:
    root = tmp_path_factory.mktemp("fusesoc_designs")
    out = {}
    for design, init in CASES:
        folder = root / f"{design}_{init}"
        generate(small_model, folder, design=design, memory_init=init, name=f"pwas_{design}_{init}")
        out[(design, init)] = folder
    return out


def _core(folder: Path) -> tuple[Path, dict]:
    (core,) = folder.glob("*.core")
    return core, yaml.safe_load(core.read_text(encoding="utf-8"))


def _fusesoc(tmp_path: Path, folder: Path | list[Path], *args: str) -> subprocess.CompletedProcess:
    """``fusesoc --config <empty> --cores-root <folder>... ARGS`` with the tools of :func:`tool_env` on PATH."""
    env = tool_env()
    env.update(XDG_CACHE_HOME=str(tmp_path / "cache"), XDG_DATA_HOME=str(tmp_path / "data"),
               XDG_CONFIG_HOME=str(tmp_path / "config"))
    exe = shutil.which("fusesoc", path=env["PATH"])
    assert exe is not None, "fusesoc is not installed: pip install -e '.[dev]' (FuseSoC is in the dev extra)"
    conf = tmp_path / "fusesoc.conf"
    conf.touch()
    roots = [a for f in (folder if isinstance(folder, list) else [folder]) for a in ("--cores-root", str(f))]
    return subprocess.run([exe, "--monochrome", "--config", str(conf), *roots, *args],
                          cwd=tmp_path, env=env, capture_output=True, text=True, check=False, timeout=300)


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_core_uses_flow_api_and_lists_hex_only_when_read(designs, case):
    folder = designs[case]
    _, core = _core(folder)
    verilog = (folder / core["filesets"]["rtl"]["files"][0]).read_text(encoding="utf-8")
    hexes = sorted(p.name for p in folder.glob("*.hex"))
    assert hexes, "generate writes the .hex files in both modes"
    assert {"default", "lint", "sim"} <= set(core["targets"])
    for name, target in core["targets"].items():
        assert "default_tool" not in target and "tools" not in target, name
    assert core["targets"]["lint"]["flow"] == "lint"
    assert core["targets"]["lint"]["flow_options"]["tool"] == "verilator"
    assert core["targets"]["sim"]["flow"] == "sim"
    for fs in core["filesets"].values():
        assert "copyto" not in fs  # FuseSoC 2.4.7 rejects a fileset-level copyto
    reads = "$readmemh" in verilog
    assert reads == (case[1] == "readmemh")
    if reads:
        rom = core["filesets"]["rom"]["files"]
        listed = {name: attrs for entry in rom for name, attrs in entry.items()}
        assert sorted(listed) == hexes
        assert all(attrs["copyto"] == name for name, attrs in listed.items())
        assert all(f'"{h}"' in verilog for h in hexes)
        assert all("rom" in t["filesets"] for t in core["targets"].values())
    else:
        assert "rom" not in core["filesets"]
        assert all(t["filesets"] == ["rtl"] for t in core["targets"].values())


def test_fusesoc_accepts_the_cores(designs, tmp_path):
    """One FuseSoC run parses the four cores (a core it rejects is left out of the list with a warning)."""
    res = _fusesoc(tmp_path, list(designs.values()), "list-cores")
    log = res.stdout + res.stderr
    assert res.returncode == 0, log
    assert "Parse error" not in log and "failed to parse" not in log, log
    for folder in designs.values():
        assert _core(folder)[1]["name"] in log, log
    name = _core(designs[("sensor", "readmemh")])[1]["name"]
    res = _fusesoc(tmp_path, designs[("sensor", "readmemh")], "core", "show", name)
    assert res.returncode == 0 and "pwas_sensor_readmemh" in res.stdout, res.stdout + res.stderr


def test_fusesoc_rejects_a_broken_core(designs, tmp_path):
    """Control: the validation above does notice a core FuseSoC refuses (the old fileset-level copyto)."""
    broken = tmp_path / "broken"
    shutil.copytree(designs[("sensor", "readmemh")], broken)
    core_path, core = _core(broken)
    core_path.write_text(core_path.read_text(encoding="utf-8").replace("    file_type: user\n",
                                                                       "    file_type: user\n    copyto: .\n"),
                         encoding="utf-8")
    res = _fusesoc(tmp_path, broken, "core", "show", core["name"])
    assert res.returncode != 0
    assert "copyto" in res.stdout + res.stderr


@pytest.mark.rtl
@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_fusesoc_lint_target_passes(designs, case, tmp_path):
    _, core = _core(designs[case])
    res = _fusesoc(tmp_path, designs[case], "run", "--work-root", str(tmp_path / "work"), "--target", "lint",
                   core["name"])
    log = res.stdout + res.stderr
    assert res.returncode == 0, log
    assert "WARNING" not in log and "%Warning" not in log, log  # FuseSoC deprecations, Verilator -Wall
    assert "--lint-only" in (tmp_path / "work" / f"{core['name'].replace(':', '_')}.vc").read_text()


@pytest.mark.rtl
def test_fusesoc_lint_target_fails_on_a_lint_warning(designs, tmp_path):
    """Control: the lint target does fail when Verilator -Wall warns (a width mismatch added)."""
    broken = tmp_path / "broken"
    shutil.copytree(designs[("core", "inline")], broken)
    core_path, core = _core(broken)
    v = broken / core["filesets"]["rtl"]["files"][0]
    text = v.read_text(encoding="utf-8")
    v.write_text(text.replace("endmodule", "  wire [3:0] pwas_test_narrow = 8'hff;\nendmodule", 1), encoding="utf-8")
    res = _fusesoc(tmp_path, broken, "run", "--work-root", str(tmp_path / "work"), "--target", "lint", core["name"])
    assert res.returncode != 0
    assert "WIDTH" in res.stdout + res.stderr


@pytest.mark.rtl
@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_fusesoc_sim_target_loads_the_memories(designs, case, tmp_path):
    """Icarus elaborates and runs the core; with $readmemh every .hex is found in the work folder."""
    _, core = _core(designs[case])
    work = tmp_path / "work"
    res = _fusesoc(tmp_path, designs[case], "run", "--work-root", str(work), "--target", "sim", core["name"])
    log = res.stdout + res.stderr
    assert res.returncode == 0, log
    assert "Unable to open" not in log, log
    if case[1] == "readmemh":
        for h in designs[case].glob("*.hex"):
            assert (work / h.name).read_bytes() == h.read_bytes()


@pytest.mark.rtl
def test_fusesoc_sim_target_notices_a_missing_memory(designs, tmp_path):
    """Control: without the copyto, $readmemh does not find the files (so the check above means something)."""
    broken = tmp_path / "broken"
    shutil.copytree(designs[("sensor", "readmemh")], broken)
    core_path, core = _core(broken)
    text = core_path.read_text(encoding="utf-8")
    for h in broken.glob("*.hex"):
        text = text.replace(f"{h.name}: {{copyto: {h.name}}}", h.name)
    core_path.write_text(text, encoding="utf-8")
    res = _fusesoc(tmp_path, broken, "run", "--work-root", str(tmp_path / "work"), "--target", "sim", core["name"])
    assert "Unable to open" in res.stdout + res.stderr
