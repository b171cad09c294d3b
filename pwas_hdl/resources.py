"""Files shipped inside the package: RTL templates, the cocotb testbench, JSON schemas.

In the repository they live at the top level (``rtl_templates/``, ``sim/``) or in
``pwas_hdl/schemas/``; the build maps them into the package (``pwas_hdl.rtl_templates``,
``pwas_hdl.sim``), so an editable install, a wheel and an sdist all find them the same way,
through :mod:`importlib.resources` -- never through paths relative to a source file.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["templates_dir", "sim_dir", "schemas_dir", "benchmarks_dir", "source_checkout"]


def _package_dir(package: str) -> Path:
    root = resources.files(package)
    path = Path(str(root))
    if not path.is_dir():  # pragma: no cover - zipped installs are not supported
        raise FileNotFoundError(f"package data {package} is not a folder on disk ({root}); install pwas-hdl unzipped")
    return path


def templates_dir() -> Path:
    """Folder of the ``*.tmpl`` files (Verilog instantiation, FuseSoC core, Yosys scripts, report)."""
    return _package_dir("pwas_hdl.rtl_templates")


def sim_dir() -> Path:
    """Folder of the cocotb testbench modules (``pwas_tb.py``, ``pwas_runner.py``, ...)."""
    return _package_dir("pwas_hdl.sim")


def schemas_dir() -> Path:
    """Folder of the JSON Schemas of the file formats (model file, manifest, bench results)."""
    return _package_dir("pwas_hdl.schemas")


def benchmarks_dir() -> Path:
    """Folder of the benchmark scripts (``benchmarks/`` of the repository); results go to its ``results/``."""
    return _package_dir("pwas_hdl.benchmarks")


def source_checkout() -> Path | None:
    """The repository root when pwas-hdl runs from a source checkout (an editable install: the
    mapped ``benchmarks/`` sits beside ``pyproject.toml`` and ``run.sh``); None for an installed wheel,
    where ``run.sh`` and ``constraints.txt`` do not exist, so messages must not send the user to them."""
    root = benchmarks_dir().parent
    return root if (root / "pyproject.toml").is_file() and (root / "run.sh").is_file() else None
