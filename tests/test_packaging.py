"""Packaging: every subpackage is listed, the wheel and sdist carry the package data, and an
installed wheel runs the whole flow with the checkout out of reach.
"""

from __future__ import annotations

import fnmatch
import importlib.metadata
import json
import os
import re
import shutil
import site
import subprocess
import sys
import tarfile
import tomllib
import zipfile
from pathlib import Path

import pytest

import pwas_hdl

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
SETUPTOOLS = PYPROJECT["tool"]["setuptools"]
#: The source files shipped for sure in every install; the rest of the package data follows
#: the package-data patterns of pyproject (checked generically below).
REQUIRED = {"pwas_hdl.rtl_templates": "*.tmpl", "pwas_hdl.sim": "*.py", "pwas_hdl.benchmarks": "*.py"}


def _source_dir(package: str) -> Path:
    """Folder of ``package`` in the checkout, following pyproject's package-dir mapping."""
    mapping = SETUPTOOLS.get("package-dir", {})
    parts = package.split(".")
    for i in range(len(parts), 0, -1):
        head = ".".join(parts[:i])
        if head in mapping:
            return ROOT / mapping[head] / Path(*parts[i:])
    return ROOT / Path(*parts)


def _discovered_packages() -> set[str]:
    """Every folder with an ``__init__.py`` under pwas_hdl/ and under each mapped folder."""
    found = set()
    roots = {"pwas_hdl": ROOT / "pwas_hdl", **{k: ROOT / v for k, v in SETUPTOOLS.get("package-dir", {}).items()}}
    for name, folder in roots.items():
        for init in folder.rglob("__init__.py"):
            rel = init.parent.relative_to(folder)
            if any(p.startswith(".") or p == "__pycache__" for p in rel.parts):
                continue
            found.add(".".join([name, *rel.parts]))
    return found


def _shipped_files(package: str) -> list[str]:
    """Relative names of the files of one package that the build must ship (modules + package data)."""
    folder = _source_dir(package)
    patterns = ["*.py", *SETUPTOOLS.get("package-data", {}).get(package, [])]
    return sorted(p.name for p in folder.iterdir() if p.is_file() and any(fnmatch.fnmatch(p.name, pat) for pat in patterns))


# ------------------------------------------------------------------------------------------------ fast


def test_every_subpackage_is_listed():
    listed = set(SETUPTOOLS["packages"])
    found = _discovered_packages()
    assert found - listed == set(), "add these to [tool.setuptools] packages in pyproject.toml"
    assert listed - found == set(), "listed in pyproject.toml but no such folder with an __init__.py"
    for mapped, folder in SETUPTOOLS.get("package-dir", {}).items():
        assert mapped in listed and (ROOT / folder / "__init__.py").is_file(), mapped


def test_package_data_patterns_name_listed_packages():
    listed = set(SETUPTOOLS["packages"])
    assert set(SETUPTOOLS.get("package-data", {})) <= listed
    for package, pattern in REQUIRED.items():
        assert any(fnmatch.fnmatch(f, pattern) for f in _shipped_files(package)), package


def test_version_has_one_source():
    assert "version" not in PYPROJECT["project"] and "version" in PYPROJECT["project"]["dynamic"]
    assert PYPROJECT["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "pwas_hdl.__version__"}
    assert importlib.metadata.version("pwas-hdl") == pwas_hdl.__version__


def test_resources_point_into_the_installed_package():
    from pwas_hdl.resources import schemas_dir, sim_dir, templates_dir

    assert (templates_dir() / "fusesoc.core.tmpl").is_file()
    assert (sim_dir() / "pwas_tb.py").is_file()
    assert schemas_dir().is_dir()


def test_no_source_file_finds_files_relative_to_itself():
    """Package code locates its data through pwas_hdl.resources, never ``__file__`` (benchmark scripts,
    which write their results next to themselves in the checkout, are not package code)."""
    own_file = re.compile(r"(?<![\w.])__file__")
    offenders = []
    for package in SETUPTOOLS["packages"]:
        if package == "pwas_hdl.benchmarks":
            continue
        for py in _source_dir(package).glob("*.py"):
            for i, line in enumerate(py.read_text(encoding="utf-8").splitlines(), 1):
                if own_file.search(line):
                    offenders.append(f"{py.relative_to(ROOT)}:{i}: {line.strip()}")
    assert offenders == []


# ------------------------------------------------------------------------------------------------ slow


#: Files of the sdist besides the package (MANIFEST.in adds the last three, tests/ and benchmarks/results/).
SDIST_EXTRA_FILES = ("pyproject.toml", "README.md", "LICENSE", "MANIFEST.in", "run.sh", "constraints.txt", ".ci/run")


def _copy_source(dst: Path) -> Path:
    """The files a build reads: the top-level files, the package, its mapped folders and the tests."""
    src = dst / "src"
    src.mkdir()
    for name in SDIST_EXTRA_FILES:
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, src / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")
    for folder in {"pwas_hdl", "tests", *SETUPTOOLS.get("package-dir", {}).values()}:
        shutil.copytree(ROOT / folder, src / folder, ignore=ignore)
    return src


def _run(cmd: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    res = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, check=False, timeout=900)
    assert res.returncode == 0, f"{' '.join(cmd)} -> exit {res.returncode}\n{res.stdout}\n{res.stderr}"
    return res


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> dict[str, Path]:
    """sdist, then the wheel built from that sdist (``python -m build`` without isolation: offline).

    A probe schema is added to the copied source only, so the ``pwas_hdl.schemas`` package-data rule
    is checked whether or not the real schemas have landed yet.
    """
    tmp = tmp_path_factory.mktemp("build")
    src = _copy_source(tmp)
    (src / "pwas_hdl" / "schemas" / "zz_packaging_probe.json").write_text("{}\n", encoding="utf-8")
    dist = tmp / "dist"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    _run([sys.executable, "-m", "build", "--no-isolation", "--outdir", str(dist), str(src)], tmp, env)
    (wheel,) = dist.glob("*.whl")
    (sdist,) = dist.glob("*.tar.gz")
    return {"wheel": wheel, "sdist": sdist, "src": src}


@pytest.mark.slow
def test_wheel_and_sdist_carry_the_package_data(built):
    with zipfile.ZipFile(built["wheel"]) as z:
        in_wheel = set(z.namelist())
        (meta,) = [n for n in in_wheel if n.endswith(".dist-info/METADATA")]
        metadata = z.read(meta).decode("utf-8")
    with tarfile.open(built["sdist"]) as t:
        top = t.getnames()[0].split("/")[0]
        in_sdist = {n.split("/", 1)[1] for n in t.getnames() if "/" in n}
    assert top == f"pwas_hdl-{pwas_hdl.__version__}"
    assert built["wheel"].name.startswith(f"pwas_hdl-{pwas_hdl.__version__}-")
    # SPDX license expression and the license file.
    assert f"License-Expression: {PYPROJECT['project']['license']}" in metadata.splitlines()
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in in_wheel)
    assert "LICENSE" in in_sdist
    mapping = SETUPTOOLS.get("package-dir", {})
    for package in SETUPTOOLS["packages"]:
        files = _shipped_files(package)
        if package in REQUIRED:
            assert any(fnmatch.fnmatch(f, REQUIRED[package]) for f in files), package
        src_rel = mapping.get(package, package.replace(".", "/"))
        for f in files:
            assert f"{package.replace('.', '/')}/{f}" in in_wheel, (package, f)
            assert f"{src_rel}/{f}" in in_sdist, (package, f)
    assert "pwas_hdl/schemas/zz_packaging_probe.json" in in_wheel
    assert "pwas_hdl/schemas/zz_packaging_probe.json" in in_sdist
    # The sdist runs the test suite and reproduces CI: every file of tests/, run.sh, the pins.
    for name in SDIST_EXTRA_FILES:
        assert name in in_sdist, name
    for f in (ROOT / "tests").glob("*.py"):
        assert f"tests/{f.name}" in in_sdist, f.name
    # ... and the committed results its tests read
    results = sorted(p.name for p in (ROOT / "benchmarks" / "results").iterdir() if p.is_file())
    assert results and all(f"benchmarks/results/{name}" in in_sdist for name in results)
    assert not any("__pycache__" in n for n in in_sdist | in_wheel)
    assert not any(n.startswith("tests/") for n in in_wheel)
    # The benchmark results are data of the repository, not of the package.
    assert not any("/results/" in n for n in in_wheel)


@pytest.mark.slow
@pytest.mark.rtl
@pytest.mark.synth
def test_installed_wheel_runs_the_flow_outside_the_checkout(built, tmp_path):
    """make-data -> fit -> generate --design sensor -> simulate (Icarus) -> synth generic, from the wheel.

    The new venv gets the wheel without dependencies; the dependencies already installed in this
    interpreter's site-packages are made visible with a ``.pth`` file. Paths in a ``.pth`` are
    appended to sys.path without processing the ``.pth`` files found there, so this environment's
    editable finder of the checkout stays inactive -- checked through ``pwas_hdl.__file__``.
    """
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp_path, dict(os.environ))
    vpy = venv / "bin" / "python"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep)
                                  if p and Path(p).resolve() != Path(sys.executable).parent.resolve())
    env["PWAS_HDL_SIM_CACHE"] = str(tmp_path / "sim-cache")
    _run([sys.executable, "-m", "pip", "--python", str(vpy), "install", "--no-deps", "--no-index", "-q",
          str(built["wheel"])], tmp_path, env)
    vsite = Path(_run([str(vpy), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                      tmp_path, env).stdout.strip())
    deps = [p for p in [*site.getsitepackages(), site.getusersitepackages()] if Path(p).is_dir()]
    (vsite / "_pwas_hdl_test_deps.pth").write_text("\n".join(deps) + "\n", encoding="utf-8")

    work = tmp_path / "work"
    work.mkdir()
    where = json.loads(_run([str(vpy), "-c",
                             "import json, pwas_hdl, pwas_hdl.resources as r; print(json.dumps("
                             "[pwas_hdl.__file__, str(r.templates_dir()), str(r.sim_dir()), str(r.schemas_dir())]))"],
                            work, env).stdout)
    for path in where:
        assert Path(path).resolve().is_relative_to(vsite.resolve()), where
        assert not Path(path).resolve().is_relative_to(ROOT), where

    cli = str(venv / "bin" / "pwas-hdl")
    _run([cli, "make-data", "lorenz", "-o", "train.csv", "--samples", "1500", "--test-output", "test.csv",
          "--test-samples", "300", "--seed", "0"], work, env)
    _run([cli, "fit", "train.csv", "--output", "y", "--target", "z", "--my", "3", "-p", "3", "--gamma", "1.2",
          "--sigma", "1e-3", "-o", "model.json"], work, env)
    _run([cli, "generate", "model.json", "--design", "sensor", "-o", "hw"], work, env)
    for name in ("pwas_sensor.v", "manifest.json", "report.md", "model.json", "pwas_sensor.core", "pwas_sensor_inst.v"):
        assert (work / "hw" / name).is_file(), name
    _run([cli, "simulate", "hw", "test.csv", "--simulator", "icarus", "-o", "icarus.csv"], work, env)
    summary = json.loads((work / "icarus.json").read_text(encoding="utf-8"))
    assert summary["samples"] == 300 - 3 + 1
    assert summary["mismatches"] == 0
    assert summary["testbench_failures"] == []
    rows = (work / "icarus.csv").read_text(encoding="utf-8").splitlines()
    assert len(rows) == 1 + summary["samples"]
    _run([cli, "synth", "hw", "--fpga", "generic"], work, env)
    synth = json.loads((work / "hw" / "synth" / "generic" / "synth.json").read_text(encoding="utf-8"))
    assert synth["top"] == "pwas_sensor" and synth["luts"] > 0 and synth["ffs"] > 0
