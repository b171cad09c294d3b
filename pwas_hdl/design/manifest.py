"""The hardware manifest: the one owner of ``manifest.json`` (constants, construction, schema, reading).

``pwas-hdl generate`` writes ``manifest.json`` next to the Verilog (built by :func:`build_manifest`,
written by :func:`manifest_text`); the cocotb testbenches, ``simulate``, ``synth``, ``report`` and
any FPGA flow read it with :func:`load_manifest` instead of hard-coding ports, widths, formats or
latency. Format ``pwas-hdl-manifest``, version 2, schema ``pwas_hdl/schemas/manifest-v2.schema.json``
(its ``$id`` is the file's ``$schema``)::

    {
      "$schema": "urn:pwas-hdl:schema:manifest-v2", "format": "pwas-hdl-manifest", "version": 2,
      "generator": {"pwas_hdl": "0.1.0", "options": {design, memory, pipeline, memory_init, input_bits, ...}},
      "design": "core" | "sensor" | "recurrent" | "estimator",  # PWAS core alone, lag bank + core, + feedback;
                                                 # or seed 003's estimator (pwas_hdl.design.estimator)
      "top": "pwas_core",                        # Verilog module name
      "files": {"verilog": "pwas_core.v", "model": "model.json", "manifest": "manifest.json",
                "report": "report.md", "instance_template": "pwas_core_inst.v", "fusesoc_core": "pwas_core.core",
                "hex": [{"file": "pwas_core_rom_b0.hex", "bank": 0, "depth": .., "width": ..,
                         "fields": [{"target": "z", "lsb": 0, "width": .., "signed": true}]}, ...]},
      "clock": {"port": "aclk", "edge": "rising"},       # ("clk" with generate --ports amaranth)
      "reset": {"port": "aresetn", "polarity": "low", "kind": "synchronous"},  # ("rst", "high")
      "latency_cycles": 7,                       # input transfer -> output valid, no stalls
      "ii": 1,                                   # initiation interval (one sample every ii clocks)
      "flow_control": {...},                     # the handshake rules in words
      "ports": [                                 # every port of the Verilog module, in module order:
                                                 # clock, reset, input stream, output stream, warm
        {"name": "aclk", "role": "clock", ...}, {"name": "aresetn", "role": "reset", ...},
        {"name": "s_axis_tvalid", "role": "in.valid", ...}, {"name": "s_axis_tready", "role": "in.ready", ...},
        {"name": "s_axis_tdata", "direction": "input", "width": 48, "signed": false, "role": "in.payload",
         "fields": [{"name": "y[t-3]", "lsb": 0, "width": 12, "signed": true, "regressor": "y[t-3]",
                     "signal": "y", "lag": 3, "format": {PortFormat.to_dict()}, "domain_codes": [lo, hi]}, ...]},
        {"name": "m_axis_tvalid", "role": "out.valid", ...}, ..., {"name": "m_axis_tdata", "role": "out.payload", ...}, ...
      ],
      "formats": {"inputs": [...], "signals": {...}, "weight": {...}, "output": {...}, "mu_frac": F,
                  "widths": {...}, "rounding": ..},
      "domain": {"lo": [...], "hi": [...], "partitions": [...], "lo_code": [...], "frac_bits": [...],
                 "n_vertices": N, "out_of_range": ".."},
      "lags": {"Mu": .., "My": .., "inputs": [...], "outputs": [...], "targets": [...], "regressors": [...],
               "warmup": {"samples_without_output": M - 1, "port": "warm", "meaning": ..}},   # sensor only
      "error_bound": {"lsb": .., "physical": .., "weight_term": .., "output_term": .., ...},
      "memory": {"kind": "banked" | "replicated" | "corner" | "single", "memories": n+1, "depth": .., "word_bits": ..,
                 "words": .., "bits": .., "n_vertices": N, "layout_spec": {...}},   # kind = generator.options.memory
      "pipeline": {...}, "arithmetic": {...},
      "architecture": {"kind": "parallel" | "serial", "multipliers": .., "multipliers_per_target": ..,
                       "cycles_per_sample": .., "ii": .., "meaning": ..,   # serial: memory.kind "single";
                       "pipeline_registers": ["rank", ..]},   # cycles_per_sample the core's, ii the design's
                                                 # (= the top-level ii); the registers of pipeline it builds
      "timing": {...},                           # only with generate --clock-mhz (timing closure)
      "classifier": {"target": "mode", "classes": [0, 1, 2], "n_classes": 3,   # only for a classifier model:
                     "port": "m_axis_tdata", "field": "class_index", "lsb": .., "width": 2,  # argmax stage after
                     "scores": ["mode=0", ..], "select": "max", "tie_rule": "lowest class index ..",  # the core
                     "stage_latency_cycles": 1, "meaning": .., "float_agreement": ..},
      "recurrence": {"Mz": 1, "lead": 1, "ii_cycles": L, "signals": ["y"],   # only for the recurrent design:
                     "initial_state": {"rule": "value", "values": [[2.0]]},  # the feedback path (issue 13)
                     "feedback": [{"target": "x3", "port": "m_axis_tdata", "output_field": "x3",
                                   "regressors": ["x3_hat[t-1]"], "regressor_indices": [1], "input_format": "s16..",
                                   "requant": {"rule": .., "mul": K, "add": C, "shift": S, "qmin": .., "qmax": ..,
                                               "product_bits": .., "error_bound": ..}, "initial_codes": [..]}],
                     "flow": "one sample in flight ..", "bit_true": "pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel"},
      "warp": {"kind": "pow2", "input_bits": B_in, "core_input_bits": W, "latency_cycles": 1,  # only for a
               "dimensions": [{"regressor", "breakpoints", "code_breaks", "exps", "f0", "F", "lo_u",  # non-uniform
                               "width", "shifts"}, ..], "rule": .., "register": .., "meaning": ..},   # partition
      "estimator": {...},                        # only for design "estimator" (seed 003's switched observer from an
                                                 # estimator file): kind, modes, states, window, signals, formats,
                                                 # coefficients, widths, bounds, detector; it has no formats, domain,
                                                 # lags, error_bound, memory, pipeline, arithmetic (no PWAS core)
      "front_end": {...}                         # only for observer-bank sensors: kind, cycles_per_sample,
                                                 # ii, stages_before_core, signals, formats, coefficients,
                                                 # feature_scale, widths, error_bound (FixedPointObserverBank.to_dict)
    }

Physical value of a field: ``physical = offset + scale * code * 2**-frac`` (its ``format``).
Reading checks strict JSON, ``format`` / ``version`` (another version: "re-run `pwas-hdl
generate`"), the schema (the message names the bad key, e.g. ``ports[2].width``) and what the
schema cannot state (ports named by ``clock`` / ``reset`` exist, one port per stream role, fields
inside their port, one domain entry per regressor; ``lags`` against the regressor names
(:meth:`~pwas_hdl.fit.regressors.LagStructure.names`), their formats, the input fields and the
warm-up; ``files.hex`` against ``memory``; field widths against their formats; ``latency_cycles``
against ``pipeline`` for a plain parallel core / sensor; ``ii`` against ``architecture`` /
``front_end``; the estimator's field widths and latency). :func:`load_manifest` also checks the
folder: the listed files stay inside it and every hex file has ``depth`` words of ``width`` bits.
Readers then index keys directly: there are no fallbacks for missing or renamed keys.

Version history: 1 (no ``$schema``, no validation), 2 (this one).
"""

from __future__ import annotations

import functools
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pwas_hdl.errors import InputError, InternalError
from pwas_hdl.fixedpoint.memory_layout import SINGLE_MEMORY
from pwas_hdl.io.json_contract import check_header, json_text, read_json, schema_errors, validate
from pwas_hdl.limits import MAX_LATENCY_CYCLES, MAX_PORT_BITS

if TYPE_CHECKING:
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel

__all__ = [
    "MANIFEST_FORMAT", "MANIFEST_VERSION", "MANIFEST_SCHEMA", "MANIFEST_SCHEMA_ID", "MANIFEST_FILE", "STREAM_ROLES",
    "build_manifest", "build_estimator_manifest", "manifest_text", "manifest_errors", "validate_manifest", "load_manifest", "port", "field",
    "folder_inputs", "built_pipeline_registers",
]

MANIFEST_FORMAT = "pwas-hdl-manifest"
MANIFEST_VERSION = 2
#: File name of the schema in ``pwas_hdl/schemas/``.
MANIFEST_SCHEMA = "manifest-v2.schema.json"
#: The schema's ``$id``, written as ``$schema`` in every manifest.
MANIFEST_SCHEMA_ID = "urn:pwas-hdl:schema:manifest-v2"
#: Name of the manifest in a generated folder.
MANIFEST_FILE = "manifest.json"
#: Roles of the stream ports every design has (one port each).
STREAM_ROLES = ("in.payload", "in.valid", "in.ready", "out.payload", "out.valid", "out.ready")

_HINT = "re-run `pwas-hdl generate` to write the design folder again"
#: Roles of the single-bit ports (clock, reset, handshakes, the sensor top's ``warm``).
_ONE_BIT_ROLES = ("clock", "reset", "in.valid", "in.ready", "out.valid", "out.ready", "warm")


# ------------------------------------------------------------------------------ construction
def _fields(design: str, fxm: "FixedPointModel", info: dict, port_name: str, is_input: bool) -> list[dict]:
    """Payload bit fields with their fixed-point formats and physical scaling."""
    fields = [dict(f) for f in info["payload"].get(port_name, [])]
    if is_input:
        if design == "core":
            for j, f in enumerate(fields):
                inp = fxm.inputs[j]
                f.update({"regressor": fxm.regressor_names[j], "signal": fxm.regressor_signals[j][0],
                          "lag": fxm.regressor_signals[j][1], "format": inp.port.to_dict(),
                          "domain_codes": [int(inp.lo_code), int(inp.hi_code)]})
        elif "front_end" in info:  # observer-bank sensor: one normalised code per u / y signal
            sig = {d["name"]: d for d in info["front_end"]["signals"]}
            for f in fields:
                d = sig[f["name"]]
                f.update({"signal": f["name"], "format": {k: v for k, v in d.items() if k != "name"}})
        else:
            sig = fxm.signal_input_formats()
            for f in fields:
                inp = sig[f["name"]]
                f.update({"signal": f["name"], "format": inp.port.to_dict(),
                          "domain_codes": [int(inp.lo_code), int(inp.hi_code)]})
    else:
        for f in fields:
            if f["name"] in fxm.target_names:
                f.update({"target": f["name"], "format": fxm.output_port.to_dict()})
            elif f["name"] == "out_of_range":
                f["meaning"] = "1: some regressor was outside the domain and was clamped to it"
            elif "classifier" in info and f["name"] == info["classifier"]["field"]:
                f.update({"meaning": info["classifier"]["meaning"] + "; " + info["classifier"]["tie_rule"],
                          "classes": info["classifier"]["classes"]})
    return fields


def build_manifest(design: str, top: str, fxm: "FixedPointModel", info: dict[str, Any], sensor: "PWASVirtualSensor",
                   files: dict[str, Any], options: dict[str, Any], timing: dict[str, Any] | None = None,
                   recurrence: Any = None) -> dict[str, Any]:
    """The manifest of a built design, validated against the schema.

    Parameters
    ----------
    design : {"core", "sensor", "recurrent"}
    top : str
        Verilog module name.
    fxm : FixedPointModel
        The bit-true model the RTL implements.
    info : dict
        :func:`pwas_hdl.hdl.design_info` of the Amaranth component.
    sensor : PWASVirtualSensor
        The fitted model.
    files : dict
        The ``files`` entry (names relative to the folder).
    options : dict
        The generate options that rebuild the bit-true model (``generator.options``).
    timing : dict, optional
        The timing-closure record (:func:`pwas_hdl.flow.timing_closure.close_timing`).
    recurrence : RecurrentFixedPointModel, optional
        The recurrent design (``design == "recurrent"``): its feedback path becomes the
        ``recurrence`` block (:func:`_recurrence_entry`).

    Returns
    -------
    dict
        The JSON-ready manifest (:func:`manifest_text` gives its file text).

    Raises
    ------
    InternalError
        The manifest does not satisfy its own schema (a bug in the generator).
    """
    from pwas_hdl import __version__

    fx = fxm.to_dict()
    ports = []
    for prt in info["ports"]:
        entry = dict(prt)  # name, role, direction, width, signed (pwas_hdl.hdl.emit.port_list)
        if prt["name"] in info["payload"]:
            entry["fields"] = _fields(design, fxm, info, prt["name"], prt["role"] == "in.payload")
        ports.append(entry)
    ins, outs, tgts = sensor.signal_names()
    lags = sensor.lags_
    man: dict[str, Any] = {
        "$schema": MANIFEST_SCHEMA_ID,
        "format": MANIFEST_FORMAT,
        "version": MANIFEST_VERSION,
        "generator": {"pwas_hdl": __version__, "options": options},
        "design": design,
        "top": top,
        "files": files,
        "clock": info["clock"],
        "reset": info["reset"],
        "latency_cycles": int(info["latency"]),
        "ii": int(info["ii"]),
        "flow_control": info["flow_control"],
        "ports": ports,
        "formats": {
            "inputs": fx["inputs"],
            "signals": fx["signals"],
            "weight": fx["weights"],
            "output": fx["output"],
            "mu_frac": int(fx["F"]),
            "widths": fx["widths"],
            "rounding": fx["rounding"],
        },
        "domain": {
            "lo": [float(v) for v in sensor.grid_.lo],
            "hi": [float(v) for v in sensor.grid_.hi],
            "partitions": [int(v) for v in sensor.grid_.partitions],
            "lo_code": [int(v) for v in fxm.lo_codes],
            "frac_bits": [int(v) for v in fxm.frac_bits],
            "n_vertices": int(sensor.grid_.n_vertices),
            "out_of_range": "inputs outside the domain are clamped to it and raise out_of_range",
        },
        "lags": {
            "Mu": int(lags.mu) if lags is not None else 0,
            "My": int(lags.my) if lags is not None else 0,
            "inputs": ins if lags is not None and lags.nu else [],
            "outputs": outs if lags is not None and lags.ny else [],
            "targets": tgts,
            "regressors": list(fxm.regressor_names),
            **({"warmup": info["warmup"]} if "warmup" in info else {}),
        },
        "error_bound": fx["error_bound"],
        "memory": {**info["memory"], "n_vertices": int(sensor.grid_.n_vertices), "layout_spec": fx["layout"]},
        "pipeline": info["pipeline"],
        "arithmetic": info["arithmetic"],
    }
    if "additive" in fx:  # additive sensor (issue 15): the parts, bit-true (formats) and hardware (memories)
        hw = info["additive"]
        man["additive"] = {
            "parts": [{**a, **{k: h[k] for k in ("module_suffix", "latency", "pipeline", "memory")}}
                      for a, h in zip(fx["additive"]["parts"], hw["parts"])],
            "sum_bits": hw["sum_bits"],
            "sum": fx["additive"]["sum"],
        }
    if "warp" in info:  # non-uniform partition (issue 15): the warp in front of the core (pwas_hdl.hdl.warp)
        man["warp"] = info["warp"]
    if "architecture" in info:  # parallel or serial (pwas_hdl.hdl.serial_core.architecture_info)
        man["architecture"] = info["architecture"]
    if timing is not None:
        man["timing"] = timing
    if "classifier" in info:  # a classifier model: argmax stage after the core
        man["classifier"] = info["classifier"]
    if recurrence is not None:  # the recurrent top (issue 13): the feedback path
        man["recurrence"] = _recurrence_entry(recurrence, info, sensor, ports)
    if "front_end" in info:  # observer-bank sensor (issue 12): bank formats, constants, bounds, cycles per sample
        man["front_end"] = info["front_end"]
    errs = manifest_errors(man)
    if errs:
        raise InternalError(f"the generated manifest of {top} breaks its schema: {errs[0]}")
    return man


def build_estimator_manifest(top: str, info: dict[str, Any], files: dict[str, Any], options: dict[str, Any],
                             estimator: dict[str, Any]) -> dict[str, Any]:
    """The manifest of the estimator design (seed 003's switched observer, :mod:`pwas_hdl.design.estimator`).

    No PWAS core: the keys of the PWAS designs (``formats``, ``domain``, ``lags``, ``error_bound``,
    ``memory``, ``pipeline``, ``arithmetic``) are absent; ``estimator`` holds the formats,
    coefficient codes, widths, bounds and detector; the payload fields carry their formats.

    Parameters
    ----------
    top : str
        Verilog module name.
    info : dict
        The top's description (``clock``, ``reset``, ``latency`` and ``ii`` in cycles,
        ``flow_control``, ``ports`` with their fields).
    files, options : dict
        The ``files`` entry and the generate options, as for :func:`build_manifest`.
    estimator : dict
        The ``estimator`` block.

    Returns
    -------
    dict
        The JSON-ready manifest with ``design = "estimator"``.

    Raises
    ------
    InternalError
        The manifest does not satisfy its own schema (a bug in the generator).
    """
    from pwas_hdl import __version__

    man: dict[str, Any] = {
        "$schema": MANIFEST_SCHEMA_ID, "format": MANIFEST_FORMAT, "version": MANIFEST_VERSION,
        "generator": {"pwas_hdl": __version__, "options": options},
        "design": "estimator", "top": top, "files": files,
        "clock": info["clock"], "reset": info["reset"],
        "latency_cycles": int(info["latency"]), "ii": int(info["ii"]), "flow_control": info["flow_control"],
        "ports": info["ports"], "estimator": estimator,
    }
    errs = manifest_errors(man)
    if errs:
        raise InternalError(f"the generated manifest of {top} breaks its schema: {errs[0]}")
    return man


def _estimator_errors(m: dict[str, Any]) -> list[str]:
    """The estimator design: its block and its payload fields agree (``m`` is schema-valid)."""
    e = m["estimator"]
    errs = []
    if len(e["signals"]["states"]) != e["states"]:
        errs.append(f"estimator.signals.states names {len(e['signals']['states'])} states for estimator.states = {e['states']}")
    if not (e["ii"] == m["ii"] and e["cycles_per_sample"] <= m["ii"]):
        errs.append(f"estimator.ii {e['ii']} differs from ii {m['ii']}")
    if e.get("architecture") == "serial" and (e.get("schedule") or {}).get("cycles_per_sample") != m["ii"]:
        errs.append(f"the serial estimator's schedule gives {(e.get('schedule') or {}).get('cycles_per_sample')} cycles per sample, ii is {m['ii']}")
    ins = [f["name"] for p in m["ports"] if p["role"] == "in.payload" for f in p.get("fields", [])]
    if ins != [e["signals"]["input"], e["signals"]["output"]]:
        errs.append(f"the input payload fields {ins} are not the estimator's signals {[e['signals']['input'], e['signals']['output']]}")
    outs = [f["name"] for p in m["ports"] if p["role"] == "out.payload" for f in p.get("fields", [])]
    want = [f"{s}_hat" for s in e["signals"]["states"]] + [f"{e['signals']['output']}_hat", "mode_index", "state_saturated"]
    if outs != want:
        errs.append(f"the output payload fields {outs} are not {want}")
        return errs
    # widths: the fields against their formats and the estimator's formats; latency against the architecture
    f = e["formats"]
    width = {nm: f["input_bits"] for nm in ins} | {f"{s}_hat": f["state_bits"] for s in e["signals"]["states"]}
    for p in m["ports"]:
        for fl in p.get("fields", []):
            fmt = fl.get("format")
            if fmt is not None and (fl["width"] != fmt["bits"] or fl["signed"] != fmt["signed"]):
                errs.append(f"the field {fl['name']} of {p['name']} is {fl['width']} bits, its format {fmt.get('str')} {fmt['bits']}")
            elif fl["name"] in width and fl["width"] != width[fl["name"]]:
                errs.append(f"the field {fl['name']} of {p['name']} is {fl['width']} bits, estimator.formats gives {width[fl['name']]}")
    lat = 1 if e.get("architecture", "parallel") == "parallel" else m["ii"] + 1
    if m["latency_cycles"] != lat:
        errs.append(f"latency_cycles is {m['latency_cycles']}, the {e.get('architecture', 'parallel')} estimator's is {lat}")
    return errs


def _recurrence_entry(rm: Any, info: dict[str, Any], sensor: "PWASVirtualSensor", ports: list[dict]) -> dict[str, Any]:
    """The ``recurrence`` block: which output field feeds which regressors, the requantisation
    rule, the reset codes, II and the flow control (:mod:`pwas_hdl.design.recurrent`)."""
    names = list(rm.fxm.regressor_names)
    sod = rm.lags.signal_of_dimension()
    out = next(p for p in ports if p["role"] == "out.payload")
    iv = rm.initial_values
    feedback = []
    for c, (t, f, fb) in enumerate(zip(rm.fxm.target_names, rm.z_formats, rm.feedback)):
        dims = [j for j, (k, ch, _lag) in enumerate(sod) if k == "z" and ch == c]  # oldest lag first
        feedback.append({
            "target": t, "port": out["name"], "output_field": t,
            "regressors": [names[j] for j in dims], "regressor_indices": dims,
            "input_format": str(f.format),
            "requant": fb.to_dict(), "initial_codes": [int(v) for v in rm.initial_codes[:, c]],
        })
    rec = info["recurrence"]
    return {
        "Mz": int(rm.lags.mz), "lead": int(getattr(sensor, "lead_", 0)), "ii_cycles": int(rec["ii_cycles"]),
        "signals": list(rm.signals),
        "initial_state": {"rule": str(sensor.initial_state_rule_), "values": [[float(v) for v in row] for row in iv]},
        "feedback": feedback, "flow": rec["flow"],
        "bit_true": "pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel",
    }


def manifest_text(manifest: dict[str, Any]) -> str:
    """The text of ``manifest.json`` (strict JSON, indented, newline at the end).

    Parameters
    ----------
    manifest : dict
        A manifest (:func:`build_manifest`).

    Returns
    -------
    str

    Raises
    ------
    InputError
        A NaN or infinite number in the manifest.
    """
    return json_text(manifest)


# ------------------------------------------------------------------------------ validation
def _consistency_errors(m: dict[str, Any]) -> list[str]:
    """What the schema cannot say (``m`` is schema-valid)."""
    errs = []
    if m["latency_cycles"] > MAX_LATENCY_CYCLES:  # a hand edit: simulate would wait that many cycles for an output
        errs.append(f"latency_cycles {m['latency_cycles']} exceeds the limit of {MAX_LATENCY_CYCLES} cycles")
    names = [p["name"] for p in m["ports"]]
    estimator = m["design"] == "estimator"  # no PWAS core (pwas_hdl.design.estimator)
    if len(set(names)) != len(names):
        errs.append(f"ports has repeated names {sorted({n for n in names if names.count(n) > 1})}")
    for key in ("clock", "reset"):
        if m[key]["port"] not in names:
            errs.append(f"{key}.port {m[key]['port']!r} is not one of the ports {names}")
    roles = [p["role"] for p in m["ports"]]
    for role in STREAM_ROLES:
        if roles.count(role) != 1:
            errs.append(f"ports must have exactly one port with role {role!r}, found {roles.count(role)}")
    for i, p in enumerate(m["ports"]):
        if p["role"] in _ONE_BIT_ROLES and p["width"] != 1:
            errs.append(f"ports[{i}] ({p['name']}, role {p['role']}) must be 1 bit wide, got {p['width']}")
        if p["width"] > MAX_PORT_BITS:
            errs.append(f"ports[{i}] ({p['name']}) is {p['width']} bits wide, more than the limit of {MAX_PORT_BITS}")
            continue
        fields = p.get("fields", [])
        if fields and p["width"] > max(f["lsb"] + f["width"] for f in fields):
            # the fields are packed from bit 0 with no spare bits; a wider port is a hand edit
            # (export-testbench would size its vectors by it: 10^8 bits took 14 GB)
            errs.append(f"ports[{i}] ({p['name']}) is {p['width']} bits wide but its fields end at bit "
                        f"{max(f['lsb'] + f['width'] for f in fields) - 1}")
            continue
        used = 0
        for j, f in enumerate(fields):
            if f["lsb"] + f["width"] > p["width"]:
                errs.append(f"ports[{i}].fields[{j}] ({f['name']}) reaches bit {f['lsb'] + f['width'] - 1} "
                            f"of the {p['width']}-bit port {p['name']}")
                continue
            mask = ((1 << f["width"]) - 1) << f["lsb"]
            if used & mask:
                errs.append(f"ports[{i}].fields[{j}] ({f['name']}) overlaps another field of {p['name']}")
            used |= mask
    for i, p in enumerate(m["ports"]):
        need = {"in.payload": ("signal", "format"), "out.payload": ("target", "format")}.get(p["role"], ())
        for j, f in enumerate(p.get("fields", [])):
            if p["role"] == "out.payload" and (f["name"] == "out_of_range" or "classes" in f):
                continue
            if estimator and p["role"] == "out.payload" and "meaning" in f and "format" not in f:
                continue  # a flag (state_saturated), described in words
            for key in need:
                if key not in f:
                    errs.append(f"ports[{i}].fields[{j}].{key} is missing (every field of {p['role']} has one)")
    if estimator:
        return errs + _estimator_errors(m)
    if "estimator" in m:
        errs.append(f"estimator is given for a {m['design']} design (only the estimator design has one)")
    n = len(m["lags"]["regressors"])
    for key in ("lo", "hi", "partitions", "lo_code", "frac_bits"):
        if len(m["domain"][key]) != n:
            errs.append(f"domain.{key} has {len(m['domain'][key])} values for {n} lags.regressors")
    if len(m["formats"]["inputs"]) != n:
        errs.append(f"formats.inputs has {len(m['formats']['inputs'])} entries for {n} lags.regressors")
    if m["generator"]["options"]["design"] != m["design"]:
        errs.append(f"generator.options.design is {m['generator']['options']['design']!r} but design is {m['design']!r}")
    recorded = (m["generator"]["options"]["memory"], m["memory"]["kind"])
    # the serial core's memory is "single"; generate recorded the option as "banked" before 2026-12-07, so
    # serial folders generated then stay readable
    if recorded[0] != recorded[1] and recorded != ("banked", SINGLE_MEMORY):
        errs.append(f"generator.options.memory is {m['generator']['options']['memory']!r} but memory.kind is {m['memory']['kind']!r}")
    if m["memory"]["n_vertices"] != m["domain"]["n_vertices"]:
        errs.append(f"memory.n_vertices {m['memory']['n_vertices']} differs from domain.n_vertices {m['domain']['n_vertices']}")
    warm = m["lags"].get("warmup")  # optional by the schema: present exactly for the sensor designs
    if (warm is not None) != (m["design"] in ("sensor", "recurrent")):
        errs.append("lags.warmup is missing (the sensor design has one)" if warm is None
                    else "lags.warmup is given for a core design (only the sensor design has a lag bank)")
    elif warm is not None and warm["port"] not in names:
        errs.append(f"lags.warmup.port {warm['port']!r} is not one of the ports {names}")
    errs += _classifier_errors(m)
    errs += _recurrence_errors(m)
    if errs:
        return errs
    return _lag_errors(m) + _memory_errors(m) + _width_errors(m) + _latency_errors(m) + _rate_errors(m) + _register_errors(m)


def _register_errors(m: dict[str, Any]) -> list[str]:
    """``architecture.pipeline_registers`` names only registers that ``pipeline`` has (an additive
    design's parts have pipelines of their own: not checked)."""
    regs = (m.get("architecture") or {}).get("pipeline_registers")
    if regs is None or "additive" in m:
        return []
    off = [k for k in regs if not m["pipeline"].get(k)]
    return [f"architecture.pipeline_registers names {off}, which pipeline does not have"] if off else []


def built_pipeline_registers(m: dict[str, Any]) -> list[str]:
    """The registers of a manifest's ``pipeline`` that its design builds, in stage order.

    ``architecture.pipeline_registers`` (:func:`pwas_hdl.hdl.api.pipeline_registers` records it;
    the serial core ignores ``bank``, ``mul_in``, ``mul_halves`` and ``tree_levels``). A manifest
    without it (written before it was recorded) gets the registers ``pipeline`` has on that its
    architecture builds (the parallel core all of them, the serial core those of
    :data:`~pwas_hdl.hdl.serial_core.SERIAL_REGISTERS`); a design without a pipeline (the estimator)
    none. Ask this, not
    ``pipeline``, whenever what matters is a register in the hardware (hard-register packing, the
    floorplan).

    Parameters
    ----------
    m : dict
        A manifest (:func:`load_manifest`, :func:`build_manifest`).

    Returns
    -------
    list of str
        Names of :data:`~pwas_hdl.hdl.params.PIPELINE_REGISTERS` (``tree_levels``: some adder-tree
        or compare-tree register).
    """
    regs = (m.get("architecture") or {}).get("pipeline_registers")
    if regs is not None:
        return list(regs)
    from pwas_hdl.hdl.params import PIPELINE_REGISTERS

    pl = m.get("pipeline") or {}
    regs = [k for k in PIPELINE_REGISTERS if pl.get(k)]
    if (m.get("architecture") or {}).get("kind") == "serial":
        from pwas_hdl.hdl.serial_core import SERIAL_REGISTERS

        # the serial core's registers; a classifier's argmax stage builds its tree_levels registers on it too
        regs = [k for k in regs if k in SERIAL_REGISTERS or (k == "tree_levels" and "classifier" in m)]
    return regs


def _rate_errors(m: dict[str, Any]) -> list[str]:
    """``ii`` agrees with the block that sets it: ``front_end.ii`` of an observer-bank sensor, else
    ``architecture.ii`` and its ``cycles_per_sample`` (a recurrent design: II = latency, checked above)."""
    if "front_end" in m:
        fe = m["front_end"]
        return [] if fe.get("ii", m["ii"]) == m["ii"] else [f"ii is {m['ii']}, front_end.ii is {fe['ii']}"]
    a = m.get("architecture")
    if a is None or "recurrence" in m:
        return []
    if not (a["ii"] == a["cycles_per_sample"] == m["ii"]):
        return [f"ii is {m['ii']}, architecture ({a['kind']}) gives ii {a['ii']} and {a['cycles_per_sample']} cycles per sample"]
    return []


_Z_NAME = re.compile(r".+_hat\[t-[1-9][0-9]*\]$")


def _lag_errors(m: dict[str, Any]) -> list[str]:
    """``lags`` agrees with the regressors it names, their formats, the input fields and the warm-up.

    The regressor names are rebuilt from ``Mu``, ``My``, the signals and (recurrent designs) the fed-back
    estimates by :meth:`pwas_hdl.fit.regressors.LagStructure.names`, the one rule that names them; an
    observer-bank sensor's feature regressors come first (``front_end``).
    """
    from pwas_hdl.fit.regressors import LagStructure

    lg, regs = m["lags"], m["lags"]["regressors"]
    ins, outs, tgts = lg["inputs"], lg["outputs"], lg["targets"]
    if m.get("recurrence") is not None:
        mz = m["recurrence"]["Mz"]
    else:  # a core of a recurrent model: its past estimates end the regressor
        n_z = len(regs) - next((k for k in range(len(regs), 0, -1) if not _Z_NAME.match(regs[k - 1])), 0)
        mz = n_z // len(tgts) if n_z % len(tgts) == 0 else -1
        if mz < 0:
            return [f"lags.regressors ends with {n_z} past estimates, not a multiple of the {len(tgts)} lags.targets"]
    io_dim = len(ins) * lg["Mu"] + len(outs) * lg["My"]
    if io_dim + len(tgts) * mz > len(regs):  # also bounds Mu, My before any list of that size is made
        return [f"lags Mu = {lg['Mu']}, My = {lg['My']} with {len(ins)} inputs and {len(outs)} outputs need "
                f"{io_dim + len(tgts) * mz} regressors, lags.regressors has {len(regs)}"]
    want: list[str] = []
    if io_dim + len(tgts) * mz:
        try:
            want = LagStructure(lg["Mu"], lg["My"], len(ins), len(outs), mz, len(tgts) if mz else 0).names(ins, outs, tgts)
        except ValueError as exc:
            return [f"lags: {exc}"]
    front = len(regs) - len(want)  # the observer bank's features
    errs = []
    if front and "front_end" not in m:
        errs.append(f"lags.regressors has {len(regs)} names, lags Mu = {lg['Mu']}, My = {lg['My']} give {len(want)}: {want}")
    elif regs[front:] != want:
        errs.append(f"lags.regressors {regs[front:]} are not the regressors {want} of lags Mu = {lg['Mu']}, My = {lg['My']}"
                    f" (inputs {ins}, outputs {outs})")
    for j, (r, f) in enumerate(zip(regs, m["formats"]["inputs"])):
        if f.get("name", r) != r:
            errs.append(f"formats.inputs[{j}].name {f['name']!r} differs from lags.regressors[{j}] {r!r}")
    warm = lg.get("warmup")
    memory = max(lg["Mu"] if ins else 0, lg["My"] if outs else 0)
    if warm is not None and "front_end" not in m and warm["samples_without_output"] != max(memory - 1, 0):
        errs.append(f"lags.warmup.samples_without_output is {warm['samples_without_output']}, the lag bank of "
                    f"Mu = {lg['Mu']}, My = {lg['My']} fills after {max(memory - 1, 0)} samples")
    inp = port(m, "in.payload")
    fields = inp.get("fields", [])
    if not fields:  # a payload described without fields (the schema allows it): nothing to compare
        pass
    elif m["design"] == "core" and "warp" not in m:
        got = [f.get("regressor") for f in fields]
        if got != regs:
            errs.append(f"the input payload fields carry the regressors {got}, lags.regressors is {regs}")
    elif m["design"] in ("sensor", "recurrent") and "front_end" not in m:
        got = [f.get("signal") for f in fields]
        used = [s for s in ins if lg["Mu"]] + [s for s in outs if lg["My"]]
        if got != used:
            errs.append(f"the input payload fields carry the signals {got}, the lag bank of lags Mu = {lg['Mu']}, "
                        f"My = {lg['My']} takes {used}")
    return errs


def _memory_errors(m: dict[str, Any]) -> list[str]:
    """``files.hex`` agrees with ``memory`` (one file per memory, its depth and word width) and its
    fields with the weight format."""
    mem, hexes = m["memory"], m["files"]["hex"]
    errs = []
    parts = [p["memory"] for p in m["additive"]["parts"] if "memory" in p] if "additive" in m else [mem]
    for k, pm in enumerate(parts):  # an additive design: every part has its own memories of its own depth
        if pm["words"] != pm["memories"] * pm["depth"]:
            where = f"additive.parts[{k}].memory" if "additive" in m else "memory"
            errs.append(f"{where}.words {pm['words']} is not memories x depth = {pm['memories']} x {pm['depth']}")
    if "additive" in m and parts and (mem["words"], mem["memories"], mem["depth"]) != (
            sum(pm["words"] for pm in parts), sum(pm["memories"] for pm in parts), max(pm["depth"] for pm in parts)):
        errs.append(f"memory (words {mem['words']}, memories {mem['memories']}, depth {mem['depth']}) is not the sum of "
                    "the additive parts' words and memories and their largest depth")
    if mem["words"] < mem["n_vertices"]:
        errs.append(f"memory.words {mem['words']} holds fewer than n_vertices = {mem['n_vertices']} words")
    wbits = m["formats"]["weight"]["bits"]
    for i, h in enumerate(hexes):
        used = 0
        for j, f in enumerate(h["fields"]):
            mask = ((1 << f["width"]) - 1) << f["lsb"] if f["lsb"] + f["width"] <= h["width"] else -1
            if mask < 0 or used & mask:
                errs.append(f"files.hex[{i}].fields[{j}] ({f['target']}) is outside its {h['width']}-bit word or overlaps another field")
                break
            used |= mask
            if f["target"] not in m["lags"]["targets"]:
                errs.append(f"files.hex[{i}].fields[{j}].target {f['target']!r} is not one of lags.targets")
            elif "additive" not in m and f["width"] != wbits:
                errs.append(f"files.hex[{i}].fields[{j}] ({f['target']}) is {f['width']} bits wide, formats.weight.bits is {wbits}")
    if "additive" in m:  # every part has its own memories (additive.parts[].memory)
        return errs
    if hexes and len(hexes) != mem["memories"]:
        errs.append(f"files.hex lists {len(hexes)} files for memory.memories = {mem['memories']}")
    for i, h in enumerate(hexes):
        if (h["depth"], h["width"]) != (mem["depth"], mem["word_bits"]):
            errs.append(f"files.hex[{i}] ({h['file']}) has depth {h['depth']} and width {h['width']}, memory has depth "
                        f"{mem['depth']} and word_bits {mem['word_bits']}")
        elif h["bank"] != i:
            errs.append(f"files.hex[{i}] ({h['file']}) is bank {h['bank']}, not {i}")
    return errs


def _width_errors(m: dict[str, Any]) -> list[str]:
    """Every payload field is as wide as its format, in the signedness of its format, and the output
    fields are the output format of ``formats``."""
    errs = []
    out_fmt = m["formats"]["output"]
    for i, p in enumerate(m["ports"]):
        for j, f in enumerate(p.get("fields", [])):
            fmt = f.get("format")
            if fmt is None:
                continue
            if f["width"] != fmt["bits"] or f["signed"] != fmt["signed"]:
                errs.append(f"ports[{i}].fields[{j}] ({f['name']}) is {f['width']} bits "
                            f"{'signed' if f['signed'] else 'unsigned'}, its format {fmt.get('str')} is {fmt['bits']} bits "
                            f"{'signed' if fmt['signed'] else 'unsigned'}")
            elif "domain_codes" in f and not _code_range(fmt)[0] <= f["domain_codes"][0] <= f["domain_codes"][1] <= _code_range(fmt)[1]:
                errs.append(f"ports[{i}].fields[{j}].domain_codes {f['domain_codes']} are outside the codes "
                            f"{list(_code_range(fmt))} of {fmt.get('str')}")
            elif p["role"] == "out.payload" and "target" in f and "additive" not in m and (fmt["bits"], fmt["frac"]) != (out_fmt["bits"], out_fmt["frac"]):
                errs.append(f"ports[{i}].fields[{j}] ({f['name']}) has the format {fmt.get('str')}, formats.output is "
                            f"s{out_fmt['bits']}.{out_fmt['frac']}")
    return errs


def _code_range(fmt: dict[str, Any]) -> tuple[int, int]:
    """Smallest and largest code of a fixed-point format (from ``bits`` and ``signed``)."""
    b = fmt["bits"]
    return (-(1 << (b - 1)), (1 << (b - 1)) - 1) if fmt["signed"] else (0, (1 << b) - 1)


def _latency_errors(m: dict[str, Any]) -> list[str]:
    """``latency_cycles`` of a plain parallel core or lag-bank sensor is the latency of its ``pipeline``
    (:meth:`pwas_hdl.hdl.params.Pipeline.latency`, plus the classifier's argmax stage)."""
    from pwas_hdl.hdl.params import Pipeline

    if (m["design"] not in ("core", "sensor") or m.get("architecture", {}).get("kind", "parallel") != "parallel"
            or any(k in m for k in ("warp", "additive", "front_end", "recurrence"))):
        return []  # these add stages of their own (the designs' manifests state them)
    try:
        want = Pipeline.cast(m["pipeline"]).latency(len(m["lags"]["regressors"]))
    except (TypeError, ValueError) as exc:
        return [f"pipeline: {exc}"]
    want += m["classifier"]["stage_latency_cycles"] if "classifier" in m else 0
    if m["latency_cycles"] != want:
        return [f"latency_cycles is {m['latency_cycles']}, the pipeline {m['pipeline']} gives {want} cycles"]
    return []


@functools.lru_cache(maxsize=None)
def _hex_words(width: int) -> re.Pattern:
    """Lines of hex words of at most ``width`` bits, each ended by a newline: ``ceil(width / 4)``
    digits whose first one holds the top ``width - 4 (digits - 1)`` bits, or fewer digits."""
    digits = -(-width // 4)
    top = "".join(c for c in "0123456789abcdefABCDEF" if int(c, 16) < 1 << (width - 4 * (digits - 1)))
    word = f"[{top}][0-9a-fA-F]{{{digits - 1}}}" + (f"|[0-9a-fA-F]{{1,{digits - 1}}}" if digits > 1 else "")
    return re.compile(f"(?:(?:{word})\n)*")


def _folder_errors(m: dict[str, Any], folder: Path) -> list[str]:
    """The files on disk agree with the manifest: listed files stay inside the folder; every hex file
    there has ``depth`` lines of one word of ``width`` bits; a ``$readmemh`` design has its hex files."""
    errs = []
    root = folder.resolve()
    f = m["files"]
    names = [v for k, v in f.items() if isinstance(v, str)] + [n for n in (f["verilog"] if isinstance(f["verilog"], list) else [])]
    names += [h["file"] for h in f["hex"]]
    for nm in names:
        p = folder / nm
        try:
            if p.exists() and root not in p.resolve().parents:
                errs.append(f"files: {nm} leads outside the folder (to {p.resolve()})")
        except (OSError, RuntimeError) as exc:  # a symlink loop, a path that cannot be resolved
            errs.append(f"files: {nm} cannot be resolved ({exc})")
    if errs:
        return errs
    readmemh = (m.get("memory", {}).get("init") or {}).get("kind") == "readmemh"
    for i, h in enumerate(f["hex"]):
        p = folder / h["file"]
        if not p.is_file():
            if readmemh:
                errs.append(f"files.hex[{i}]: {h['file']} is missing (the Verilog reads it with $readmemh)")
            continue
        digits = -(-h["width"] // 4)
        if p.stat().st_size > h["depth"] * (digits + 2) + 4096:  # read nothing bigger than depth words could be
            errs.append(f"files.hex[{i}]: {h['file']} has {p.stat().st_size} bytes, more than {h['depth']} words of "
                        f"{h['width']} bits take")
            continue
        raw = p.read_text(encoding="ascii", errors="replace").splitlines()
        lines = [ln.strip() for ln in raw if ln.strip()]
        if len(lines) == h["depth"] and _hex_words(h["width"]).fullmatch("\n".join(lines) + "\n" if lines else ""):
            continue  # every line a word of `width` bits (one regular expression over the file, not a loop a line)
        numbered = ((k + 1, ln.strip()) for k, ln in enumerate(raw) if ln.strip())  # line numbers as an editor shows them
        bad = next(((k, ln) for k, ln in numbered if len(ln) > digits or not all(c in "0123456789abcdefABCDEF" for c in ln)
                    or int(ln, 16) >> h["width"]), None)
        if bad is not None:  # a line that is not a word (a comment, a header) before the count: it explains a wrong count
            errs.append(f"files.hex[{i}]: line {bad[0]} of {h['file']} ({bad[1][:20]!r}) is not a {h['width']}-bit hex word; "
                        f"the file holds one word a line and nothing else (regenerate the design with `pwas-hdl generate`)")
        elif len(lines) != h["depth"]:
            errs.append(f"files.hex[{i}]: {h['file']} has {len(lines)} words, files.hex[{i}].depth is {h['depth']}")
    return errs or _port_name_errors(m, folder)


#: How much of the Verilog :func:`_port_name_errors` reads to find the top module's header (it is
#: near the start: the generated files put the header comment and then the top module first).
_HEADER_BYTES = 2**20


def _port_name_errors(m: dict[str, Any], folder: Path) -> list[str]:
    """The ports the manifest names are the ports of module ``top`` in the design's Verilog (the
    testbenches drive and read them by name: a renamed one failed inside the simulator)."""
    f = m["files"]
    vpath = folder / (f["verilog"] if isinstance(f["verilog"], str) else f["verilog"][0])
    try:
        with open(vpath, encoding="utf-8", errors="replace") as fh:
            head = fh.read(_HEADER_BYTES)
    except OSError:  # a missing Verilog is reported by its readers
        return []
    head = re.sub(r"//[^\n]*|/\*.*?\*/|\(\*.*?\*\)", " ", head, flags=re.S)  # comments, attributes
    mo = re.search(r"^\s*module\s+" + re.escape(m["top"]) + r"\s*\(([^)]*)\)\s*;", head, re.M)
    if mo is None:  # not a header this reader knows: left to the tools
        return []
    # a name list (Yosys: `a, b`) or ANSI declarations (`input wire [7:0] a, ...`): the last identifier of each item
    have = [ids[-1] for item in mo.group(1).split(",") if (ids := re.findall(r"[A-Za-z_][A-Za-z0-9_$]*", item))]
    # only ports the manifest names and the module lacks: a module may have more (a hand-made core's
    # debug output, synthesised bare), which the benches leave unconnected
    extra = [p["name"] for p in m["ports"] if p["name"] not in have]
    if extra:
        return [f"ports names {', '.join(extra)}, which module {m['top']} in {vpath.name} does not have (its ports: {', '.join(have)})"]
    return []


def _recurrence_errors(m: dict[str, Any]) -> list[str]:
    """The recurrence block: present exactly for the recurrent design, its fields and regressors exist, II = latency."""
    r = m.get("recurrence")
    if (r is not None) != (m["design"] == "recurrent"):
        return ["recurrence is missing (the recurrent design has one)" if r is None
                else f"recurrence is given for a {m['design']} design (only the recurrent design has a feedback path)"]
    if r is None:
        return []
    errs = []
    if not (r["ii_cycles"] == m["ii"] == max(1, m["latency_cycles"])):
        errs.append(f"recurrence.ii_cycles {r['ii_cycles']}, ii {m['ii']} and latency_cycles {m['latency_cycles']} must agree "
                    "(one sample in flight: II = latency)")
    regs = m["lags"]["regressors"]
    outs = {p["name"]: {f["name"] for f in p.get("fields", [])} for p in m["ports"] if p["role"] == "out.payload"}
    for i, fb in enumerate(r["feedback"]):
        if fb["target"] not in m["lags"]["targets"]:
            errs.append(f"recurrence.feedback[{i}].target {fb['target']!r} is not one of lags.targets")
        if fb["output_field"] not in outs.get(fb["port"], set()):
            errs.append(f"recurrence.feedback[{i}].output_field {fb['output_field']!r} is not a field of the output port {fb['port']!r}")
        if len(fb["regressors"]) != r["Mz"] or len(fb["regressor_indices"]) != r["Mz"] or len(fb["initial_codes"]) != r["Mz"]:
            errs.append(f"recurrence.feedback[{i}] must name Mz = {r['Mz']} regressors, indices and initial codes")
        elif any(j >= len(regs) or regs[j] != nm for j, nm in zip(fb["regressor_indices"], fb["regressors"])):
            errs.append(f"recurrence.feedback[{i}].regressors {fb['regressors']} are not lags.regressors at {fb['regressor_indices']}")
        q = fb["requant"]
        if not all(q["qmin"] <= c <= q["qmax"] for c in fb["initial_codes"]):
            errs.append(f"recurrence.feedback[{i}].initial_codes {fb['initial_codes']} are outside [{q['qmin']}, {q['qmax']}]")
    if len(r["feedback"]) != len(m["lags"]["targets"]):
        errs.append(f"recurrence.feedback has {len(r['feedback'])} entries for {len(m['lags']['targets'])} targets")
    return errs


def _classifier_errors(m: dict[str, Any]) -> list[str]:
    """The classifier entry agrees with its class-index field and the score targets."""
    c = m.get("classifier")
    outs = [p for p in m["ports"] if p["role"] == "out.payload"]
    marked = [f["name"] for p in outs for f in p.get("fields", []) if "classes" in f]
    if c is None:
        return [f"output field {marked[0]!r} has classes but the manifest has no classifier entry"] if marked else []
    errs = []
    out = outs[0] if len(outs) == 1 else None
    fields = {f["name"]: f for f in out.get("fields", [])} if out else {}
    f = fields.get(c["field"])
    if out is None or c["port"] != out["name"] or f is None:
        errs.append(f"classifier.field {c['field']!r} is not a field of the output payload port {c['port']!r}")
    elif (f["lsb"], f["width"], f.get("classes")) != (c["lsb"], c["width"], c["classes"]):
        errs.append(f"classifier lsb/width/classes {c['lsb']}/{c['width']}/{c['classes']} differ from its field "
                    f"{f['lsb']}/{f['width']}/{f.get('classes')}")
    if not (len(c["classes"]) == len(c["scores"]) == c["n_classes"]):
        errs.append(f"classifier has {len(c['classes'])} classes, {len(c['scores'])} scores and n_classes {c['n_classes']}")
    missing = [s for s in c["scores"] if s not in fields]
    if missing:
        errs.append(f"classifier.scores {missing} are not fields of the output payload")
    if (1 << c["width"]) < c["n_classes"]:
        errs.append(f"classifier.width {c['width']} bits cannot index {c['n_classes']} classes")
    return errs


def manifest_errors(d: Any) -> list[str]:
    """Every problem of a manifest dict, one sentence each (empty: a valid manifest).

    Parameters
    ----------
    d : Any
        The parsed manifest.

    Returns
    -------
    list of str
        A wrong format or version gives that one problem alone; else the schema violations or,
        when there are none, the consistency problems the schema cannot express.
    """
    if not isinstance(d, dict) or d.get("format") != MANIFEST_FORMAT:
        return [f'not a {MANIFEST_FORMAT} file (missing "format": "{MANIFEST_FORMAT}")']
    if type(d.get("version")) is not int or d.get("version") != MANIFEST_VERSION:
        return [f"version {d.get('version')!r} is not supported (this pwas-hdl reads version {MANIFEST_VERSION})"]
    return schema_errors(d, MANIFEST_SCHEMA) or _consistency_errors(d)


def validate_manifest(d: Any, source: str = "manifest") -> None:
    """Check a manifest dict against the format (header, schema, consistency).

    Parameters
    ----------
    d : Any
        The parsed manifest.
    source : str
        Name of the file, for the message.

    Raises
    ------
    InputError
        One message that names ``source``, the bad key by its path and what was expected.
    """
    check_header(d, MANIFEST_FORMAT, MANIFEST_VERSION, source, _HINT)
    validate(d, MANIFEST_SCHEMA, source, _HINT)
    errs = _consistency_errors(d)
    if errs:
        raise InputError(f"{source}: {errs[0]}; {_HINT}")


def load_manifest(outdir_or_file: str | os.PathLike) -> dict[str, Any]:
    """Read and validate a manifest (a generated folder or the ``manifest.json`` itself).

    Parameters
    ----------
    outdir_or_file : path
        A folder written by ``pwas-hdl generate`` or a ``.json`` file; the files that a folder's
        manifest lists are checked too (against the manifest's folder).

    Returns
    -------
    dict
        The validated manifest.

    Raises
    ------
    FileNotFoundError
        No manifest there (run ``pwas-hdl generate`` first).
    ResourceLimit
        A manifest larger than :data:`~pwas_hdl.limits.MAX_JSON_BYTES`.
    InputError
        A file that is neither a folder nor ``.json``, not strict JSON, not a pwas-hdl manifest, another version, or a key missing, of the wrong
        type or inconsistent (the message names it).
    """
    p = Path(outdir_or_file)
    if p.is_dir():
        p = p / MANIFEST_FILE
    if not p.exists():
        raise FileNotFoundError(f"{p} does not exist; run `pwas-hdl generate MODEL -o DIR` first")
    if p.name != MANIFEST_FILE and p.suffix.lower() != ".json":  # e.g. a data CSV given where the folder goes
        raise InputError(f"{p} is a file, not a folder written by `pwas-hdl generate` (nor its {MANIFEST_FILE}); "
                         "give the design folder")
    d = read_json(p, _HINT)
    validate_manifest(d, str(p))
    errs = _folder_errors(d, p.parent)
    if errs:
        raise InputError(f"{p}: {errs[0]}; {_HINT}")
    return d


def folder_inputs(outdir: str | os.PathLike) -> list[tuple[Path, str]]:
    """Every file of a generated folder that its readers read: the manifest and the files it lists.

    For the ``inputs`` of an :class:`~pwas_hdl.io.atomic.OutputSet`, so that no command writes an
    output over the Verilog, the model or a hex file of the design it reads.

    Parameters
    ----------
    outdir : path
        The design folder.

    Returns
    -------
    list of (Path, str)
        ``(path, "the manifest")``, ``(path, "the design's model file")``, ...

    Without a manifest only its path is listed (the reader reports the missing folder itself).

    Raises
    ------
    InputError
        As :func:`load_manifest` for a manifest that is there.
    """
    folder = Path(outdir)
    if not (folder / MANIFEST_FILE).exists():
        return [(folder / MANIFEST_FILE, "the manifest")]
    m = load_manifest(folder)
    f = m["files"]
    res = [(folder / MANIFEST_FILE, "the manifest")]
    for key, v in f.items():
        if key == "hex":
            res += [(folder / h["file"], "a weight memory of the design") for h in v]
        elif key != "manifest":
            what = "the estimator file" if key == "model" and m["design"] == "estimator" else f"the design's {key.replace('_', ' ')} file"
            res += [(folder / n, what) for n in ([v] if isinstance(v, str) else v)]
    return res


# ------------------------------------------------------------------------------ access
def port(manifest: dict[str, Any], role: str) -> dict[str, Any]:
    """The port whose ``role`` is ``role`` (e.g. ``"in.payload"``, ``"out.valid"``).

    Parameters
    ----------
    manifest : dict
        A loaded manifest.
    role : str

    Returns
    -------
    dict
        The first matching entry of ``manifest["ports"]`` (``name``, ``role``, ``direction``,
        ``width`` in bits, ``signed``, payload ports also ``fields``).

    Raises
    ------
    KeyError
        No port has that role.
    """
    for prt in manifest["ports"]:
        if prt["role"] == role:
            return prt
    raise KeyError(f"the manifest has no port with role {role!r}")


def field(port_entry: dict[str, Any], name: str) -> dict[str, Any]:
    """A named bit field of a port.

    Parameters
    ----------
    port_entry : dict
        An entry of the manifest's ``ports`` (:func:`port`).
    name : str
        Field name (a signal, target, ``out_of_range``, ...).

    Returns
    -------
    dict
        The field: ``name``, ``lsb`` and ``width`` in bits, ``signed`` and, where known, its format.

    Raises
    ------
    KeyError
        The port has no field of that name (or no fields).
    """
    for f in port_entry.get("fields", []):  # "fields" is optional: only payload ports have it
        if f["name"] == name:
            return f
    raise KeyError(f"port {port_entry['name']} has no field {name!r}")
