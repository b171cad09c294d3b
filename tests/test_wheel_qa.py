"""The wheel carries every file the package reads through :mod:`pwas_hdl.resources` (fast: no build).

tests/test_packaging.py checks, after a build, that the files matching pyproject's package-data
patterns are in the wheel; this checks the other direction without building: no file of a resource
folder falls outside those patterns (a new ``sim/foo.h`` or ``rtl_templates/x.v`` would be read
from the checkout by an editable install and be missing from every wheel).
"""

from __future__ import annotations

import fnmatch
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SETUPTOOLS = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
#: The packages that pwas_hdl.resources hands out as folders, and their folder in the checkout.
RESOURCE_PACKAGES = {"pwas_hdl.rtl_templates": ROOT / "rtl_templates", "pwas_hdl.sim": ROOT / "sim",
                     "pwas_hdl.schemas": ROOT / "pwas_hdl" / "schemas"}


@pytest.mark.parametrize("package", sorted(RESOURCE_PACKAGES))
def test_every_file_of_a_resource_folder_is_package_data(package):
    folder = RESOURCE_PACKAGES[package]
    patterns = ["*.py", *SETUPTOOLS.get("package-data", {}).get(package, [])]
    files = [p for p in folder.rglob("*") if p.is_file() and "__pycache__" not in p.parts and not p.name.startswith(".")]
    assert files, folder
    left_out = [str(p.relative_to(ROOT)) for p in files
                if p.parent != folder or not any(fnmatch.fnmatch(p.name, pat) for pat in patterns)]
    assert left_out == [], f"not shipped in the wheel: add a package-data pattern in pyproject.toml ({left_out})"


def test_resources_name_only_listed_packages():
    """The packages resources.py resolves are all listed for the build (else the wheel has no such folder)."""
    import re

    text = (ROOT / "pwas_hdl" / "resources.py").read_text(encoding="utf-8")
    asked = set(re.findall(r'_package_dir\("([\w.]+)"\)', text))
    assert asked >= set(RESOURCE_PACKAGES)
    assert asked <= set(SETUPTOOLS["packages"]), asked - set(SETUPTOOLS["packages"])
