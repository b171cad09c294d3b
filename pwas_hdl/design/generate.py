"""``pwas-hdl generate``: model file -> self-contained hardware folder.

The folder holds (``<top>`` is the module name):

``<top>.v``
    The design, one synthesizable Verilog-2005 file (weights inline as memory initialisers).
``<top>_rom_b<bank>.hex``
    The weight memories as ``$readmemh`` files, one per bank, one word per line holding all
    targets (target 0 in the least significant bits), exactly the words of the RTL memories
    (:func:`pwas_hdl.hdl.emit.memory_hex_files`); ``memory_init="readmemh"`` makes the Verilog
    load them instead of carrying the weights inline.
``manifest.json``
    Machine-readable description (:mod:`pwas_hdl.design.manifest`): ports, formats, latency, II, domain,
    lags, error bound, memory, and the options that rebuild the bit-true model.
``report.md``
    Short human-readable report.
``model.json``
    The model file the design was generated from (the float reference of the testbenches).
``<top>_inst.v``, ``<top>.core``
    Instantiation template and FuseSoC core description, filled from ``rtl_templates/``.

Same inputs give byte-identical files. The folder is written only when everything has been built
(in memory) without error; an existing folder is replaced only if it was made by ``generate``.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from string import Template
from typing import TYPE_CHECKING, Any, Callable


from pwas_hdl import __version__
from pwas_hdl.resources import templates_dir
from pwas_hdl.errors import InputError, InternalError, choice_text, option_text
from pwas_hdl.hdl.names import check_module_name, check_signal_names
from pwas_hdl.io.atomic import check_output_path, clean_stale_temps, make_temp_dir
from pwas_hdl.fixedpoint.bittrue import FixedPointModel
from pwas_hdl.fixedpoint.memory_layout import SINGLE_MEMORY, model_layout
from pwas_hdl.design.manifest import build_manifest, manifest_text
from pwas_hdl.fit.model_file import model_text
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

if TYPE_CHECKING:  # the hdl package (Amaranth) is imported when a design is built
    from pwas_hdl.hdl.params import Pipeline

__all__ = ["FORMAT_OPTIONS", "GeneratedDesign", "build_design", "generate", "fixed_point_model", "design_hash", "write_folder", "TEMPLATE_DIR",
           "design_summary"]

#: Keyword options of :class:`~pwas_hdl.fixedpoint.bittrue.FixedPointModel` that ``generate`` accepts.
FORMAT_OPTIONS = (
    "input_bits",
    "input_fill",
    "input_scale",
    "weight_bits",
    "weight_frac",
    "output_bits",
    "output_frac",
    "overflow",
    "rounding",
)

TEMPLATE_DIR = templates_dir()


@dataclass
class GeneratedDesign:
    """A design built in memory (and possibly written to a folder).

    Attributes
    ----------
    top : str
        Verilog module name.
    files : dict of str -> str
        File name (relative to the folder) -> text.
    manifest : dict
        The content of ``manifest.json``.
    model : FixedPointModel
        The bit-true model the RTL implements.
    component : amaranth Component
        The Amaranth design (core or sensor top).
    outdir : Path or None
        Where it was written.
    """

    top: str
    files: dict[str, str]
    manifest: dict[str, Any]
    model: FixedPointModel
    component: Any = field(repr=False)
    outdir: Path | None = None


def _load_sensor(model: PWASVirtualSensor | str | os.PathLike) -> PWASVirtualSensor:
    """The sensor itself (NotFittedError unless fitted), or the one a model file holds."""
    if isinstance(model, PWASVirtualSensor):
        model._check_fitted()
        return model
    return PWASVirtualSensor.load(model)


def fixed_point_model(sensor: PWASVirtualSensor, memory: str = "banked", **formats: Any) -> FixedPointModel:
    """The bit-true model of ``sensor`` with the given format options: the one :func:`generate` builds.

    Parameters
    ----------
    sensor : PWASVirtualSensor
        A fitted or loaded sensor.
    memory : {"banked", "replicated", "corner", "single"}
        Weight memory layout (:mod:`pwas_hdl.fixedpoint.memory_layout`); ``"single"``, the serial
        core's one memory (a serial design's ``generator.options.memory``), is the replicated
        layout's copy 0 and gives the model that layout
        (:func:`~pwas_hdl.fixedpoint.memory_layout.model_layout`).
    **formats
        Word formats, the names of :data:`FORMAT_OPTIONS` (``input_bits``, ``weight_frac``, ...);
        None means the default.

    Returns
    -------
    FixedPointModel
        An :class:`~pwas_hdl.fixedpoint.additive.AdditiveFixedPointModel` for an additive sensor, a
        :class:`~pwas_hdl.fixedpoint.warp.WarpedFixedPointModel` for one fitted with ``breakpoints``.

    Raises
    ------
    sklearn.exceptions.NotFittedError
        The sensor is not fitted.
    InputError
        An unknown or impossible format option; an observer-bank sensor (its bit-true model is
        :func:`pwas_hdl.fixedpoint.observer_bank.observer_bank_model`: the bank and its core).
    """
    _load_sensor(sensor)  # fitted?
    if getattr(sensor, "front_end_", None) is not None:  # the core's inputs are the bank's features
        raise InputError("an observer-bank sensor's bit-true model is the bank and its core: "
                         "pwas_hdl.fixedpoint.observer_bank.observer_bank_model(sensor), not fixed_point_model")
    unknown = set(formats) - set(FORMAT_OPTIONS)
    if unknown:
        raise InputError(f"unknown format option(s) {sorted(unknown)}; known: {', '.join(FORMAT_OPTIONS)}")
    given = {k: v for k, v in formats.items() if v is not None}
    memory = model_layout(memory)  # the serial core's single memory: the replicated layout's copy 0
    if _is_additive(sensor):  # the parts' cores summed before one rounding (pwas_hdl.fixedpoint.additive)
        from pwas_hdl.fixedpoint.additive import AdditiveFixedPointModel

        return AdditiveFixedPointModel.from_sensor(sensor, layout=memory, **given)
    if _is_warped(sensor):  # non-uniform partition: warp + the uniform core (pwas_hdl.fixedpoint.warp)
        from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel

        return WarpedFixedPointModel.from_sensor(sensor, layout=memory, **given)
    return FixedPointModel.from_sensor(sensor, layout=memory, **given)


def _is_warped(sensor: PWASVirtualSensor) -> bool:
    """True for a sensor fitted with ``breakpoints`` (a non-uniform grid: the warped designs;
    :func:`pwas_hdl.fixedpoint.warp.is_warped`)."""
    from pwas_hdl.fixedpoint.warp import is_warped

    return is_warped(sensor)


def _root_spacings(bank_model: Any, isqrt_every: int | None) -> list[int | None]:
    """The square-root register spacings a ``target_mhz`` search may try, in order: the given one
    alone, or for an observer bank with the 11b map (no ``isqrt_every`` given) the default (None),
    then every 2 and every digit step where the root has room for them; else ``[None]``."""
    from pwas_hdl.hdl.serial_observer_bank import DEFAULT_ISQRT_EVERY

    if isqrt_every is not None:
        return [isqrt_every]
    if bank_model is None or bank_model.bank.feature_map != "11b":
        return [None]
    steps = (bank_model.bank.formats.sum_bits + 1) // 2
    return [None, *(k for k in range(DEFAULT_ISQRT_EVERY - 1, 0, -1) if k <= steps - 1)]


def _core_inputs(sensor: PWASVirtualSensor) -> int:
    """Inputs of the widest PWAS core of the design (sets the adder-tree depth of the pipelines):
    the grid's dimension, or an additive sensor's largest part's."""
    subsets = getattr(sensor.grid_, "subsets", None)
    return max(len(sub) for sub in subsets) if subsets is not None else int(sensor.grid_.n)


def _is_additive(sensor: PWASVirtualSensor) -> bool:
    """True for a sensor fitted with ``additive`` (its grid is an AdditiveGrid)."""
    return getattr(sensor.grid_, "subsets", None) is not None


def _template(name: str) -> Template:
    path = TEMPLATE_DIR / name
    if not path.is_file():
        raise FileNotFoundError(f"template {path} is missing; the pwas-hdl installation is incomplete")
    return Template(path.read_text(encoding="utf-8"))


def _md_table(header: list[str], rows: list[list[Any]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def _report(man: dict, sensor: PWASVirtualSensor, fxm: FixedPointModel) -> str:
    ports = _md_table(
        ["port", "dir", "width", "fields (LSB first)"],
        [
            [f"`{p['name']}`", p["direction"], p["width"],
             ", ".join(f"{f['name']} [{f['lsb'] + f['width'] - 1}:{f['lsb']}]" for f in p.get("fields", [])) or "-"]
            for p in man["ports"]
        ],
    )
    fmts = man["formats"]
    rows = []
    seen = set()
    for inp in fmts["inputs"]:
        key = inp["signal"] if man["design"] != "core" else inp["name"]
        if key in seen:
            continue
        seen.add(key)
        rows.append([f"input {key}", inp["format"], f"{inp['lsb']:.6g}", f"[{inp['lo']:.6g}, {inp['hi']:.6g}], p = {inp['partitions']}"])
    w, o = fmts["weight"], fmts["output"]
    rows.append(["weights", f"s{w['bits']}.{w['frac']}", f"{2.0 ** -w['frac']:.6g}", f"{fxm.weight_codes.size} codes, {w['n_saturated']} saturated"])
    rows.append(["output", f"s{o['bits']}.{o['frac']}", f"{o['physical_lsb']:.6g}", f"shift {o['shift']}, may saturate: {o['may_saturate']}"])
    fmt_table = _md_table(["quantity", "format", "physical LSB", "notes"], rows)
    dom = man["domain"]
    dom_table = _md_table(
        ["regressor", "lo", "hi", "p", "codes lo..hi", "F_j"],
        [[r, f"{lo:.6g}", f"{hi:.6g}", p, f"{inp['lo_code']} .. {inp['hi_code']}", fb]
         for r, lo, hi, p, fb, inp in zip(man["lags"]["regressors"], dom["lo"], dom["hi"], dom["partitions"],
                                          dom["frac_bits"], fmts["inputs"])],
    )
    mem = man["memory"]
    mem_text = (
        f"Layout **{mem['kind']}**: {_memory_shape(man)} = {mem['words']} words, {mem['bits']} bits for "
        f"N = {mem['n_vertices']} weights ({mem['words'] / mem['n_vertices']:.3f} N)."
    )
    init = mem.get("init", {})
    hexes = [h["file"] for h in man["files"].get("hex", [])]
    if init.get("kind") == "readmemh":
        par = init["parameter"]
        init_text = (
            f"\n\nThe weights are **not** in the Verilog: it loads them with `$readmemh` at time zero from "
            f"{', '.join(f'`{h}`' for h in hexes)}, each name prefixed with the parameter `{par}` (default "
            f"`\"{init['default']}\"`: the simulator's or synthesis tool's working directory). Copy the files with the "
            f"Verilog and set `{par}` where the module is instantiated, to their folder with the trailing `/`, "
            f"relative to the tool's working directory or absolute: `{man['top']} #(.{par}(\"path/to/hex/\")) u_{man['top']} (...)` "
            f"(the instance template `{man['files'].get('instance_template', man['top'] + '_inst.v')}` has the line). "
            f"A missing file leaves the memory undefined (Icarus prints an error and runs on with `x`)."
        )
    else:
        init_text = (
            "\n\nThe weights are inline in the Verilog (`--memory-init inline`): the `.hex` files are a copy for "
            "inspection, not read by the design."
        ) if hexes else ""
    warm = man["lags"].get("warmup")
    warm_text = (
        f"\n- After every reset the first {warm['samples_without_output']} transfer"
        f"{'s only fill the lag bank and produce' if warm['samples_without_output'] != 1 else ' only fills the lag bank and produces'} no output; every "
        f"later transfer produces one estimate (output `{warm['port']}` is high from the transfer that yields the first)."
    ) if warm else ""
    code_rows = []
    seen_codes = set()
    for inp in fmts["inputs"]:
        key = inp["signal"] if man["design"] != "core" else inp["name"]
        if key in seen_codes or "offset" not in inp:
            continue
        seen_codes.add(key)
        code_rows.append(f"- `{key}`: physical = {inp['offset']!r} + {inp['lsb']!r} * code; "
                         f"code = round((physical - {inp['offset']!r}) / {inp['lsb']!r}), half up, "
                         f"saturated to {inp['bits']} bits")
    code_text = ("\n\nInput codes (the bit-true model's quantisation, `pwas_hdl.FixedPointModel.quantize_inputs`):\n\n"
                 + "\n".join(code_rows)) if code_rows else ""
    eb = man["error_bound"]
    terms = f"(weight rounding {eb['weight_term']:.4g} + output rounding {eb['output_term']:.4g}, physical units)"
    files = "\n".join(f"- `{f}`" for f in sorted(_file_names(man["files"])))
    return _template("report.md.tmpl").substitute(
        top=man["top"], design=("virtual-sensor top (observer bank + residual features + core)"
                                if "front_end" in man and man["design"] == "sensor" else
                                {"core": "core", "sensor": "virtual-sensor top (lag bank + core)",
                                 "recurrent": "recurrent virtual-sensor top (lag bank + core + feedback of the estimates)"}[man["design"]]),
        version=__version__,
        model_summary=(f"n = {sensor.grid_.n} ({', '.join(man['lags']['regressors'])}), N = {sensor.grid_.n_vertices}, "
                       f"targets {', '.join(man['lags']['targets'])}, sigma = {sensor.sigma_:.3g}"),
        clock=man["clock"]["port"], reset=_reset_text(man, "`"), latency=man["latency_cycles"], ii=man["ii"],
        rate=_rate_text(man),
        port_table=ports, format_table=fmt_table, bound_lsb=f"{eb['lsb']:.4g}", bound_phys=f"{eb['physical']:.4g}",
        bound_terms=terms, domain_table=dom_table, memory_text=mem_text + init_text, file_list=files,
        warmup_text=warm_text, input_code_text=code_text,
    )


def _memory_shape(man: dict) -> str:
    """The weight memories as memories x depth, for the header and the report: ``5 x 1024 words of 22
    bits``; an additive design's part by part, each part's memories of its own depth (``one set per
    additive part: 2 x 3 + 3 x 4 + 4 x 15 words of 22 bits``; ``memory.depth`` is the largest part's)."""
    mems = [p["memory"] for p in man["additive"]["parts"]] if "additive" in man else [man["memory"]]
    widths = {m["word_bits"] for m in mems}
    shape = (" + ".join(f"{m['memories']} x {m['depth']}" for m in mems) + f" words of {widths.pop()} bits"
             if len(widths) == 1 else " + ".join(f"{m['memories']} x {m['depth']} words of {m['word_bits']} bits" for m in mems))
    return ("one set per additive part: " if "additive" in man else "") + shape


def _rate_text(man: dict) -> str:
    """The report's throughput phrase: one sample per clock, or every II clocks and why (the serial
    core's n + 1 cycles, or a recurrent top's one sample in flight, II = latency, whatever its core)."""
    if man["ii"] == 1:
        return "one sample per clock"
    if "recurrence" in man:
        from pwas_hdl.design.recurrent import loop_text

        return f"one sample every {man['ii']} clocks: one sample in flight through {loop_text(man)}, II = latency"
    return f"one sample every {man['ii']} clocks: serial architecture"


def _file_names(files: dict) -> list[str]:
    out = []
    for v in files.values():
        if isinstance(v, str):
            out.append(v)
        elif isinstance(v, list):
            out += [h["file"] for h in v]
        elif isinstance(v, dict):
            out += [x for x in v.values() if isinstance(x, str)]
    return out


def _reset_text(man: dict, quote: str = "") -> str:
    r = man["reset"]
    return f"{quote}{r['port']}{quote} ({r['kind']}, active {r['polarity']})"


def _physical_text(fmt: dict) -> str:
    """A manifest field format and its physical value, as the header and the instance template say it
    (``s12.-1, physical = code * 2**1``; offset and scale where they are not 0 and 1)."""
    lsb = f"2**-{fmt['frac']}" if fmt["frac"] > 0 else f"2**{-fmt['frac']}"
    name = fmt.get("str") or f"{'s' if fmt['signed'] else 'u'}{fmt['bits']}.{fmt['frac']}"
    if fmt.get("offset") or fmt.get("scale", 1.0) != 1.0:
        return f"{name}, physical = {fmt['offset']!r} + {fmt['scale']!r} * code * {lsb}"
    return f"{name}, physical = code * {lsb}"


def _instance(man: dict, source: str) -> str:
    """The instantiation template ``<top>_inst.v``; ``source`` names what the design was generated from
    (``model.json SHA-256 ...``, as line 2 of the Verilog header), so the template says which model it is for."""
    comments = []
    for p in man["ports"]:
        for f in p.get("fields", []):
            fmt = f.get("format")
            desc = ""
            if fmt:
                desc = f" {_physical_text(fmt)}"
            comments.append(f"//   {p['name']}[{f['lsb'] + f['width'] - 1}:{f['lsb']}] {f['name']}{desc}")
    conns = ",\n".join(
        f"    .{p['name']}({p['name']})" for p in man["ports"]
    )
    init = man["memory"].get("init", {})
    params = f'#(.{init["parameter"]}("{init["default"]}")) ' if init.get("parameter") else ""
    mem_dir = (f"// {init['parameter']}: folder of the .hex weight files (with the trailing /), relative to the\n"
               "// simulator's working directory or absolute.\n") if params else ""
    return _template("instance.v.tmpl").substitute(
        top=man["top"], version=__version__, source=source, design_hash=man["design_hash"],
        clock=man["clock"]["port"], reset=_reset_text(man), latency=man["latency_cycles"],
        latency_plural="" if man["latency_cycles"] == 1 else "s", ii=man["ii"], parameters=params, mem_dir_comment=mem_dir,
        field_comments="\n".join(comments), connections=conns,
    )


def _fusesoc(man: dict, memory_init: str) -> str:
    """The FuseSoC CAPI2 core of the folder (Edalize flow API: targets ``lint`` and ``sim``).

    The ``.hex`` files are part of the core only when the Verilog reads them
    (``memory_init="readmemh"``); each is copied (``copyto``) into the work folder where the
    simulator runs, since ``$readmemh`` resolves its file name there.
    """
    filesets = "rtl"
    rom = ""
    if memory_init == "readmemh":
        filesets += ", rom"
        rom = "  rom:\n    files:\n" + "".join(
            f"      - {h['file']}: {{copyto: {h['file']}}}\n" for h in man["files"]["hex"]
        ) + "    file_type: user\n"
    return _template("fusesoc.core.tmpl").substitute(
        version=__version__, vlnv=f"pwas-hdl:generated:{man['top']}:0.1.0",
        description=f"PWAS {man['design']} {man['top']} (latency {man['latency_cycles']} cycles, II {man['ii']})",
        verilog=man["files"]["verilog"], rom_fileset=rom, filesets=filesets, top=man["top"],
    )


def build_design(
    model: PWASVirtualSensor | str | os.PathLike,
    *,
    design: str = "core",
    name: str | None = None,
    memory: str | None = None,
    pipeline: str | Pipeline | dict | None = None,
    memory_init: str = "inline",
    ports: str = "axis",
    goal: str | None = None,
    target_mhz: float | None = None,
    fpga_target: str = "ecp5",
    timing_seed: int = 1,
    prescreen: bool = True,
    progress: Callable[[str], None] | None = None,
    executor: Any = None,
    architecture: str = "parallel",
    bank_lanes: int | None = None,
    isqrt_every: int | None = None,
    **formats: Any,
) -> GeneratedDesign:
    """Build the RTL and all artifacts in memory.

    Parameters
    ----------
    model : PWASVirtualSensor or path of a model file
        An estimator file (``pwas-hdl-estimator``, :mod:`pwas_hdl.fit.estimator_file`) or a
        :class:`~pwas_hdl.fit.estimator_file.SwitchedEstimatorConfig` builds seed 003's estimator
        instead (:func:`pwas_hdl.design.estimator.build_estimator_design`: options ``name``, ``ports``
        and its formats ``input_bits``, ``input_headroom``, ``state_bits``, ``state_frac``, ``coef_frac``).
    design : {"core", "sensor", "recurrent"}
        The PWAS core alone (input = regressor codes) or the virtual-sensor top (input = one
        (u, y) sample per transfer, lag bank inside). For a recurrent model (``Mz >= 1``: fit
        ``--mz``, fit-map ``--state``) "sensor" builds the recurrent top
        (:mod:`pwas_hdl.design.recurrent`: feedback of the estimates, II = latency) and the
        manifest's design is "recurrent" (also accepted here).
        A model fitted with ``additive`` (:mod:`pwas_hdl.fit.additive`) gets the additive designs of
        :mod:`pwas_hdl.hdl.additive_top` (one core per part, parallel or serial, the exact sum, one
        rounding; a classifier's argmax stage after the sum, parallel or serial).
        A model fitted with power-of-two ``breakpoints`` gets the warped designs of
        :mod:`pwas_hdl.hdl.warp` (the warp and its register in front of the core), a classifier's
        too (warp -> core -> argmax stage; parallel or serial, as every classifier), an observer-bank
        sensor's (bank -> features [+ u/y taps] -> warp -> core, parallel or serial), a
        recurrent model's (the recurrent top with the warp in front of its core; the fed-back
        estimate is requantised to the warp's input code format).
    name : str, optional
        Verilog module name (default ``pwas_core`` / ``pwas_sensor``).
    memory : {"banked", "replicated", "corner"}, optional
        Weight memory: ``n + 1`` banks holding about N words, or ``n + 1`` copies of the N words, or
        ``2**n`` corner banks addressed by the cell alone (:mod:`pwas_hdl.hdl.corner`). None (default):
        the goal's memory (:func:`pwas_hdl.design.goal_memory.goal_memory`): replicated for
        ``goal="latency"`` on ECP5 where its bit-field addresses and block RAMs fit, else banked.
    pipeline : str, Pipeline or dict, optional
        Pipeline preset of :mod:`pwas_hdl.hdl.params` (``min``, ``short``, ``balanced``, ``max``), or the
        registers themselves (a :class:`~pwas_hdl.hdl.params.Pipeline` or its ``to_dict()``).
    goal : {"latency", "balanced", "throughput"}, optional
        Pick the pipeline by what matters (:data:`pwas_hdl.hdl.params.GOALS`): ``latency`` (fewest
        nanoseconds from input to output), ``throughput`` (highest clock, II = 1) or ``balanced``
        (the default pipeline). Each names a pipeline preset measured on ECP5 (see the README's
        hardware tables); recorded in the manifest as that preset. Not with ``pipeline`` or
        ``target_mhz``: one of the three chooses the pipeline.
    target_mhz : float, optional
        Choose the pipeline by timing closure instead (:mod:`pwas_hdl.flow.timing_closure`): the
        shallowest candidate whose fmax, measured by place and route on ``fpga_target``, reaches
        ``target_mhz``; recorded in the manifest (``timing``) and the report. Not with ``pipeline``.
        Every design kind (additive, warped, classifier, recurrent, observer-bank and serial
        designs too); the record's latencies are the whole design's.
        Raises :class:`~pwas_hdl.flow.timing_closure.TimingNotMet` (an ``InputError``) when even the
        deepest pipeline misses the target. Takes one place-and-route run per candidate tried.
    fpga_target : {"ecp5", "ice40"}
        FPGA family of the timing closure (devices: ECP5 LFE5U-45F, iCE40 HX8K) and of ``goal``
        (:func:`pwas_hdl.hdl.params.goal_preset`: ``throughput`` on ``ice40`` is ``max-lut``).
    timing_seed : int
        nextpnr placer seed of the timing closure (same inputs and seed: same choice).
    prescreen : bool
        Let the timing closure skip candidates that cannot reach the target (see its notes).
    progress : callable, optional
        Called with one line of text before each place-and-route run of the timing closure.
    executor : pwas_hdl.flow.executor.Executor, optional
        Runs the timing closure's place-and-route candidates on Dask workers (speculatively;
        the choice and the record are those of the serial search).
    ports : {"axis", "amaranth"}
        Port names (:func:`pwas_hdl.hdl.emit.emit_verilog`): AXI4-Stream style ``aclk``, ``aresetn``
        (synchronous, active low), ``s_axis_tvalid/tready/tdata``, ``m_axis_tvalid/tready/tdata``
        (default), or Amaranth's ``clk``, ``rst`` (active high), ``in__*``, ``out__*``. The
        manifest lists them with their roles; ``warm`` (sensor top) keeps its name.
    memory_init : {"inline", "readmemh"}
        Weights as initialisers inside the Verilog (self-contained), or ``$readmemh`` of the
        ``.hex`` files of the folder (relative names: run tools from the folder).
    architecture : {"parallel", "serial"}
        ``parallel`` (default): ``n + 1`` memories and multipliers per target, II = 1.
        ``serial``: one multiplier per target, one memory of N words, ``n + 1`` cycles per
        sample (II = n + 1), bit-exact with the parallel design (:mod:`pwas_hdl.hdl.serial_core`);
        inside the recurrent top II = latency (one sample in flight).
        Not with ``memory`` (refused: the serial memory is the only one). With ``target_mhz`` the
        search runs over the registers the serial core takes (``split``, ``rank``, ``offset``,
        ``addr``, ``mem_out``, ``product``).
        For an additive model, ``serial`` puts every part on the serial core (one throttle at the
        largest part's II, :mod:`pwas_hdl.hdl.additive_top`). A classifier (plain, additive or
        warped) gets its argmax stage after the serial core or sum (:mod:`pwas_hdl.hdl.classifier_top`;
        the stage's ``tree_levels`` registers count in the latency and in the ``target_mhz`` search).
        For an observer-bank sensor, ``serial`` also time-multiplexes the bank
        (:mod:`pwas_hdl.hdl.serial_observer_bank`: ``bank_lanes`` state-update units, the II is
        the manifest's ``front_end.cycles_per_sample``).
    bank_lanes : int, optional
        Observer-bank sensors with ``architecture="serial"``: state-update units sharing the
        ``N_theta x M`` updates (1 .. N_theta, default 1: ``N_theta M`` cycles per sample or a few more).
    isqrt_every : int, optional
        Observer-bank sensors with the ``11b`` feature map: digit steps of each feature's integer
        square root between pipeline registers (1 .. its digit steps - 1, ``ceil(sum_bits / 2) - 1``; default
        :data:`~pwas_hdl.hdl.serial_observer_bank.DEFAULT_ISQRT_EVERY` = 3). Smaller: a shorter
        path inside the root (a higher clock), more registers and cycles of latency (parallel
        bank; the serial bank's II may grow with its feature pipeline). Manifest
        ``front_end.isqrt_every`` / ``isqrt_registers``.
    **formats
        Fixed-point options (:data:`FORMAT_OPTIONS`); ``None`` means the data-driven default.

    Returns
    -------
    GeneratedDesign
    """
    from pwas_hdl.design.estimator import build_estimator_design, is_estimator

    from pwas_hdl.design.goal_memory import DEFAULT_MEMORY, goal_memory
    from pwas_hdl.flow.timing_closure import FPGA_TARGETS

    if fpga_target not in FPGA_TARGETS:  # checked whether or not --clock-mhz / --goal use it: never silently ignored
        raise InputError(f"--fpga (fpga_target) must be one of {', '.join(FPGA_TARGETS)}, got {fpga_target!r}")
    if is_estimator(model):  # an estimator file (seed 003's switched observer): pwas_hdl.design.estimator
        if isqrt_every is not None:
            raise InputError("--isqrt-every applies to observer-bank sensors with the 11b feature map (the square root "
                             "of each window sum); an estimator file has no square root: leave it out")
        return build_estimator_design(model, design=design, name=name, memory=memory or DEFAULT_MEMORY, pipeline=pipeline, memory_init=memory_init,
                                      ports=ports, goal=goal, target_mhz=target_mhz, architecture=architecture, bank_lanes=bank_lanes,
                                      **formats)
    from pwas_hdl.hdl import Pipeline, build_core, build_sensor, design_info, emit_verilog
    from pwas_hdl.fixedpoint.memory_layout import hex_file_name
    from pwas_hdl.hdl.emit import MEM_DIR_DEFAULT, MEM_DIR_PARAMETER, memory_hex_files

    if design not in ("core", "sensor", "recurrent"):
        raise InputError(f"{option_text('design')} must be core or sensor (or, of a recurrent model, recurrent), got {design!r}")
    if memory is not None and memory not in ("banked", "replicated", "corner"):
        raise InputError(choice_text(option_text("memory"), ("banked", "replicated", "corner"), memory))
    from pwas_hdl.hdl.serial_core import ARCHITECTURES

    if architecture not in ARCHITECTURES:
        raise InputError(choice_text(option_text("architecture"), ARCHITECTURES, architecture))
    if architecture == "serial" and memory is not None:  # it was ignored, and the manifest recorded it as built
        raise InputError(f"--memory {memory} does not apply to --architecture serial (one weight memory of N words, "
                         "one vertex read per cycle); leave --memory out")
    if architecture == "serial":  # the serial core's one memory of N words: what the manifest records (was "banked")
        memory = SINGLE_MEMORY
    if name is not None:
        check_module_name(name)
    sensor = _load_sensor(model)
    design = _design_kind(design, sensor)  # "sensor" of a recurrent model: the recurrent top (issue 13)
    top = name or {"core": "pwas_core", "sensor": "pwas_sensor", "recurrent": "pwas_recurrent_sensor"}[design]
    for kind, names in zip(("input", "output", "target"), sensor.signal_names()):
        check_signal_names(names, f"{kind} signal")
    if goal is not None:
        from pwas_hdl.hdl.params import goal_preset

        preset = goal_preset(goal, fpga_target)  # ValueError for an unknown goal
        given = [k for k, v in (("--pipeline", pipeline), ("--clock-mhz", target_mhz)) if v is not None]
        if given:
            raise InputError(f"give one of --goal, --pipeline or --clock-mhz, not --goal with {given[0]}: "
                             "each chooses the pipeline")
        pipeline = preset
    additive = _is_additive(sensor)
    warped = _is_warped(sensor)  # non-uniform partition (issue 15): pwas_hdl.hdl.warp
    bank_model = None  # observer-bank front end (issue 12): pwas_hdl.fixedpoint.observer_bank
    if bank_lanes is not None and (getattr(sensor, "front_end_", None) is None or architecture != "serial" or design != "sensor"):
        raise InputError("--bank-lanes applies to observer-bank sensors with --design sensor --architecture serial only")
    from pwas_hdl.hdl.serial_observer_bank import check_isqrt_every_option

    check_isqrt_every_option(isqrt_every, getattr(sensor, "front_end_", None) is not None)
    if getattr(sensor, "front_end_", None) is not None:
        from pwas_hdl.fixedpoint.observer_bank import observer_bank_model

        if design == "recurrent":
            raise InputError("hardware for a recurrent observer-bank sensor is not available")
        if design == "core":  # its inputs would be the bank's features, which a manifest's lags do not describe
            raise InputError("--design core of an observer-bank sensor is not available: the core's inputs are the "
                             "bank's residual features, not lagged u / y samples; give --design sensor (the bank, "
                             "the features and the core)")
        bank_model = observer_bank_model(sensor, memory=memory or DEFAULT_MEMORY, **formats)
        from pwas_hdl.hdl.serial_observer_bank import check_root_spacing

        check_root_spacing(bank_model.bank, isqrt_every)  # at least one register inside the root
        fxm = bank_model.core
        memory = memory or DEFAULT_MEMORY
    else:
        from pwas_hdl.fixedpoint.observer_bank import BANK_FORMAT_OPTIONS

        for k in BANK_FORMAT_OPTIONS:
            if formats.get(k) is not None:
                raise InputError(f"{option_text(k)} sets a format of the observer bank: it applies to observer-bank "
                                 "sensors (fit --front-end observer-bank) and estimator files only")
        fxm = fixed_point_model(sensor, memory=memory or DEFAULT_MEMORY, **formats)
        if memory is None:  # the goal's memory (pwas_hdl.design.goal_memory)
            plain = (not additive and not warped and design in ("core", "sensor") and architecture == "parallel"
                     and getattr(sensor, "classifier_", None) is None)
            memory = goal_memory(goal, fpga_target, fxm, plain=plain)
            if memory != DEFAULT_MEMORY:
                fxm = fixed_point_model(sensor, memory=memory, **formats)
    classifier = getattr(sensor, "classifier_", None)  # a classifier model: argmax stage after the core
    if additive:
        if design == "recurrent":
            raise InputError("hardware for a recurrent additive sensor is not available")

    root_spacing = {} if isqrt_every is None else {"isqrt_every": isqrt_every}  # an observer bank's square root

    def component(pipe: Pipeline | None) -> tuple[Any, Any]:
        """The design's Amaranth component with pipeline ``pipe`` (and a recurrent top's recurrence)."""
        recurrence = None
        if additive:  # the parts' cores (parallel or serial), summed before one rounding (pwas_hdl.hdl.additive_top)
            from pwas_hdl.hdl.additive_top import build_additive_core, build_additive_sensor

            comp = (build_additive_core(fxm, memory=memory, pipeline=pipe, name=top, classifier=classifier,
                                        architecture=architecture) if design == "core"
                    else build_additive_sensor(fxm, sensor.lags_, memory=memory, pipeline=pipe, name=top, classifier=classifier,
                                               architecture=architecture))
        elif design == "recurrent":
            from pwas_hdl.design.recurrent import build_recurrent_component

            comp, recurrence = build_recurrent_component(sensor, fxm, memory=memory, name=top, classifier=classifier,
                                                         pipeline=pipe, architecture=architecture)
        elif warped and bank_model is None:  # lag bank (sensor) -> warp + register -> the uniform core [-> argmax stage]
            from pwas_hdl.hdl.warp import build_warped_design

            comp = build_warped_design(fxm, design, sensor.lags_, memory=memory, pipeline=pipe, name=top, architecture=architecture,
                                       classifier=classifier)
        elif design == "core":
            comp = build_core(fxm, memory=memory, pipeline=pipe, name=top, classifier=classifier, architecture=architecture)
        elif bank_model is not None:  # observer bank -> features [-> warp + register] -> core
            from pwas_hdl.hdl.observer_sensor_top import build_observer_sensor

            if hasattr(bank_model, "taps"):  # u/y taps beside the features (pwas_hdl.hdl.observer_tap_sensor_top)
                from pwas_hdl.hdl.observer_tap_sensor_top import build_tapped_observer_sensor

                comp = build_tapped_observer_sensor(bank_model, memory=memory, pipeline=pipe, name=top, architecture=architecture,
                                                    lanes=1 if bank_lanes is None else bank_lanes, **root_spacing)
            else:
                # --architecture serial: the time-multiplexed bank and the serial core (pwas_hdl.hdl.serial_observer_bank)
                comp = build_observer_sensor(bank_model, memory=memory, pipeline=pipe, name=top, architecture=architecture,
                                             lanes=1 if bank_lanes is None else bank_lanes, **root_spacing)
        else:
            comp = build_sensor(fxm, sensor.lags_, memory=memory, pipeline=pipe, name=top, classifier=classifier,
                                architecture=architecture)
        return comp, recurrence

    timing = None
    if target_mhz is not None:
        from pwas_hdl.flow.timing_closure import close_timing

        if pipeline is not None:
            raise InputError("give either a pipeline or a target clock (target_mhz / --clock-mhz), not both")
        if memory_init not in ("inline", "readmemh"):
            raise InputError(choice_text(option_text("memory_init"), ("inline", "readmemh"), memory_init))

        def candidate(pipe: Pipeline) -> GeneratedDesign:
            return build_design(sensor, design=design, name=name, memory=None if architecture == "serial" else memory,
                                pipeline=pipe, memory_init="inline", ports=ports, architecture=architecture,
                                bank_lanes=bank_lanes, **root_spacing, **formats)

        # each candidate's latency is the built component's (an additive sum, a warp, an observer
        # bank or an argmax stage adds cycles to the core's; the serial core takes only some of the
        # registers: candidates that add none of them are the same design, dropped); a candidate the
        # design cannot take is dropped
        from pwas_hdl.flow.timing_closure import TimingNotMet, best_critical_path, in_square_root
        from pwas_hdl.hdl.api import pipeline_registers
        from pwas_hdl.hdl.serial_observer_bank import DEFAULT_ISQRT_EVERY

        built: dict[Pipeline, Any] = {}

        def built_component(pipe: Pipeline) -> Any:  # each candidate's component, built once for both questions
            if pipe not in built:
                built[pipe] = component(pipe)[0]
            return built[pipe]

        # an observer bank's square root is not cut by the core's registers: when the best candidate
        # misses inside it, the search runs again with a denser root (unless --isqrt-every was given)
        spacings = _root_spacings(bank_model, isqrt_every)
        tried: list[int] = []
        for k, spacing in enumerate(spacings):
            root_spacing = {} if spacing is None else {"isqrt_every": spacing}
            built.clear()
            try:
                # the record's labels name the registers each candidate's design builds (the serial core ignores some)
                chosen, timing = close_timing(candidate, _core_inputs(sensor), target_mhz, fpga=fpga_target,
                                              seed=timing_seed, prescreen=prescreen, progress=progress, executor=executor,
                                              latency=lambda pipe: int(built_component(pipe).latency),
                                              registers=lambda pipe: pipeline_registers(built_component(pipe)))
            except TimingNotMet as exc:
                tried.append(spacing or DEFAULT_ISQRT_EVERY)
                if k + 1 < len(spacings) and in_square_root(best_critical_path(exc.record)):
                    if progress is not None:
                        progress(f"the best pipeline misses {target_mhz:g} MHz inside the observer bank's square root: "
                                 f"searching again with a register every {spacings[k + 1]} digit steps (--isqrt-every)")
                    continue
                if len(tried) > 1:
                    raise TimingNotMet(f"{exc} (searched with the square root's register every "
                                       f"{', '.join(map(str, tried))} digit steps)", exc.record) from None
                raise
            if tried:
                timing["isqrt_every_searched"] = [*tried, spacing]  # the root spacings searched, the last one chosen
                isqrt_every = spacing  # recorded in the options: the design is built with it
            break
    else:
        chosen = pipeline
    comp, recurrence = component(Pipeline.cast(chosen) if chosen is not None else None)
    info = design_info(comp, ports)

    prefix = f"{top}_rom"
    bw = fxm.weight_format.bits
    fields = [{"target": t, "lsb": i * bw, "width": bw, "signed": True} for i, t in enumerate(fxm.target_names)]
    if additive:
        from pwas_hdl.hdl.additive_top import emit_additive_verilog

        verilog = emit_additive_verilog(comp, top, memory_init=memory_init, hex_prefix=prefix, ports=ports)
        hexes = memory_hex_files(comp, prefix)
        part_plans = [(i, b, c.memory_plan) for i, c in enumerate(comp.core.parts if design == "sensor" else comp.parts)
                      for b in range(c.memory_plan.n_banks)]
        hex_entries = [{"file": hex_file_name(prefix, b, i), "part": i, "bank": b, "depth": int(pl.depth), "width": int(pl.word_bits),
                        "fields": fields} for i, b, pl in part_plans]
        if [h["file"] for h in hex_entries] != list(hexes):
            raise InternalError("the manifest's hex entries of the additive parts are not the files written")
    else:
        verilog = emit_verilog(comp, top, memory_init=memory_init, hex_prefix=prefix, ports=ports)
        hexes = memory_hex_files(comp, prefix)
        plan = info["memory"]
        hex_entries = [
            {"file": fname, "bank": b, "depth": int(plan["depth"]), "width": int(plan["word_bits"]), "fields": fields}
            for b, fname in enumerate(hexes)
        ]
    files = {
        "verilog": f"{top}.v",
        "model": "model.json",
        "manifest": "manifest.json",
        "report": "report.md",
        "instance_template": f"{top}_inst.v",
        "fusesoc_core": f"{top}.core",
        "hex": hex_entries,
    }
    if pipeline is not None and not isinstance(pipeline, str):
        pipeline = Pipeline.cast(pipeline).to_dict()
    options = {"design": design, "memory": memory, "pipeline": pipeline, "memory_init": memory_init, "ports": ports,
               **{k: formats.get(k) for k in FORMAT_OPTIONS}}
    if architecture != "parallel":
        options["architecture"] = architecture
    if bank_lanes is not None:
        options["bank_lanes"] = bank_lanes
    if isqrt_every is not None:
        options["isqrt_every"] = isqrt_every
    if bank_model is not None:
        from pwas_hdl.fixedpoint.observer_bank import BANK_FORMAT_OPTIONS

        options.update({k: formats.get(k) for k in BANK_FORMAT_OPTIONS})
    if timing is not None:
        options.update(target_mhz=float(target_mhz), fpga_target=fpga_target)
    # how the weights get into the memories (the manifest's memory.init; MEM_DIR: pwas_hdl.hdl.emit)
    info["memory"]["init"] = ({"kind": "readmemh", "parameter": MEM_DIR_PARAMETER, "default": MEM_DIR_DEFAULT,
                               "meaning": "folder of the hex files with its trailing /, prefixed to their names"}
                              if memory_init == "readmemh" else {"kind": "inline"})
    man = build_manifest(design, top, fxm, info, sensor, files, options, timing, recurrence=recurrence)
    if architecture == "serial":  # one memory of N words (pwas_hdl.hdl.serial_core.SingleMemoryPlan)
        man["memory"]["layout_spec"] = comp_core(comp).memory_plan.layout_spec()
    model = model_text(sensor)
    model_sha256 = hashlib.sha256(model.encode("utf-8")).hexdigest()
    verilog = _verilog_header(man, model_sha256) + verilog
    man["design_hash"] = design_hash({files["verilog"]: verilog, "model.json": model, **hexes})
    texts: dict[str, str] = {
        files["verilog"]: verilog,
        "model.json": model,
        "manifest.json": manifest_text(man),
        "report.md": _report(man, sensor, fxm) + (_timing_section(timing) if timing is not None else "")
        + (_additive_section(man) if "additive" in man else "")
        + (_classifier_section(man) if "classifier" in man else "")
        + (_recurrence_section(man) if "recurrence" in man else "")
        + (_warp_section(man) if "warp" in man else ""),
        files["instance_template"]: _instance(man, f"model.json SHA-256 {model_sha256}"),
        files["fusesoc_core"]: _fusesoc(man, memory_init),
        **hexes,
    }
    return GeneratedDesign(top, texts, man, fxm, comp)


#: What each port does (by its manifest role), for the Verilog header; ``{in.valid}`` etc. are
#: replaced by the design's own port names (AXI-Stream or Amaranth naming), ``{polarity}`` by the
#: reset polarity of the manifest.
_PORT_MEANING = {
    "clock": "clock, rising edge",
    "reset": "synchronous reset, active {polarity}",
    "in.valid": "the source offers {in.payload}",
    "in.ready": "the design accepts: a transfer on a rising edge with {in.valid} & {in.ready}",
    "in.payload": "input sample (signed codes, field 0 in the low bits):",
    "out.valid": "{out.payload} holds an estimate (held while {out.ready} is low)",
    "out.ready": "the sink takes {out.payload} (low = backpressure; the whole pipeline waits)",
    "out.payload": "estimate (signed codes, target 0 in the low bits) and flags:",
    "warm": "1 once the lag bank holds a full regressor (the next transfer yields an estimate)",
    "warm.observer-bank": "1 once M + l samples have been taken since reset (the next transfer yields an estimate)",
}


_HEADER_KIND = {"core": "PWAS core", "sensor": "PWAS virtual-sensor top", "recurrent": "PWAS recurrent virtual-sensor top"}


def design_summary(man: dict) -> str:
    """What a PWAS design is, in a few words, for ``generate``'s console line: the architecture and the
    design (``serial core``, ``parallel sensor top``), then what the model adds (``additive, 3 parts``,
    ``non-uniform partition``, ``observer bank``, ``classifier, 3 classes``).

    Parameters
    ----------
    man : dict
        The manifest of a PWAS design (not the estimator's).

    Returns
    -------
    str
    """
    what = {"core": "core", "sensor": "sensor top", "recurrent": "recurrent sensor top"}[man["design"]]
    words = [f"{man['architecture']['kind']} {what}"]
    if "additive" in man:
        words.append(f"additive, {len(man['additive']['parts'])} parts")
    if "warp" in man:
        words.append("non-uniform partition")
    if "front_end" in man:
        words.append(f"observer bank ({man['front_end']['n_models']} observers)")
    if "classifier" in man:
        words.append(f"classifier, {man['classifier']['n_classes']} classes")
    return ", ".join(words)


def _port_meaning(man: dict, role: str) -> str:
    names = {p["role"]: p["name"] for p in man["ports"]}
    if role == "warm" and "front_end" in man:
        role = f"warm.{man['front_end']['kind']}"
    text = _PORT_MEANING.get(role, role)
    for r, name in names.items():
        text = text.replace("{" + r + "}", name)
    return text.replace("{polarity}", man["reset"]["polarity"])


def _cycles(n: int) -> str:
    """``1 cycle``, ``11 cycles``."""
    return f"{n} cycle" + ("" if n == 1 else "s")


def _verilog_header(man: dict, model_sha256: str) -> str:
    """Comment block at the top of the generated Verilog: generator, model, formats, ports, timing.

    Deterministic (no dates, no paths): the same inputs give the same text.
    """
    fm = man["formats"]
    eb = man["error_bound"]
    lines = [
        f"{man['top']}: {_HEADER_KIND[man['design']]} generated by "
        f"pwas-hdl {__version__} -- do not edit, regenerate",
        f"model.json SHA-256 {model_sha256}",
        f"regressor (n = {len(man['lags']['regressors'])}): {', '.join(man['lags']['regressors'])}; "
        f"{man['domain']['n_vertices']} vertices; targets: {', '.join(man['lags']['targets'])}",
        *([f"additive sensor: {len(man['additive']['parts'])} parts (" + "; ".join(
            ", ".join(man['lags']['regressors'][j] for j in pt['regressors']) for pt in man['additive']['parts'])
            + "), each a " + ("serial PWAS core (one multiplier per target, n_i + 1 cycles per sample, all parts taking "
                              "each sample together)" if man["architecture"]["kind"] == "serial" else "PWAS core")
            + " without rounding; their sums added exactly, then rounded once"] if "additive" in man else []),
        f"latency {man['latency_cycles']} cycles (input transfer to {_port_meaning(man, '{out.valid}')}), II {man['ii']} "
        + ("(one sample per clock)" if man["ii"] == 1 else f"(one sample every {man['ii']} clocks)"),
        f"weights {fm['weight']['str']} ({man['memory']['kind']} memor{'ies' if 'additive' in man else 'y'}, {_memory_shape(man)}"
        + (f" = {man['memory']['words']} words" if "additive" in man else "") + f"); output {fm['output']['str']} "
        f"(LSB {fm['output']['lsb']!r}); |hw - float| <= {eb['lsb']!r} LSB = {eb['physical']!r}",
    ]
    if "classifier" in man:
        c = man["classifier"]
        labels = ", ".join(f"{v:g}" for v in c["classes"])
        lines.append(f"classifier of {c['target']} ({c['n_classes']} classes {labels}): argmax stage after the {_stage_source(man)}, "
                     f"class index in "
                     f"{c['port']}[{c['lsb'] + c['width'] - 1}:{c['lsb']}] {c['field']}, ties to the lowest class index, "
                     f"{_cycles(c['stage_latency_cycles'])} of the latency")
    if "warp" in man:  # non-uniform partition (issue 15): pwas_hdl.hdl.warp
        w = man["warp"]
        lines.append(f"non-uniform partition (power-of-two cells): a warp maps each s{w['input_bits']}.0 input code to the uniform "
                     f"core's {w['core_input_bits']}-bit code, {w['latency_cycles']} register (in the latency); breakpoints:")
        lines += [f"  {d['regressor']}: {', '.join(f'{v:.6g}' for v in d['breakpoints'])} (codes {', '.join(map(str, d['code_breaks']))})"
                  for d in w["dimensions"]]
    if "recurrence" in man:
        from pwas_hdl.design.recurrent import recurrence_header_lines

        lines += recurrence_header_lines(man)
    if "front_end" in man:  # observer-bank sensor: the bank in front of the core
        fe = man["front_end"]
        ff = fe["formats"]
        lines.append(f"observer bank: {fe['n_models']} observers of order {fe['order']} ({fe['observer']}), window l = {fe['window']}, "
                     f"feature map {fe['feature_map']}; states s{ff['state_bits']}.{ff['state_frac']} (saturating), coefficients "
                     f"{ff['coef_frac']} fraction bits; {_cycles(fe['cycles_per_sample'])} per sample; first estimate at sample "
                     f"{fe['first_output_sample']} after reset; |estimate - float sensor| <= "
                     f"{', '.join(repr(v) for v in fe['error_bound']['estimate']['physical'])} unless a state saturates")
    lines += [
        "ports:",
    ]
    for prt in man["ports"]:
        d = "in " if prt["direction"] == "input" else "out"
        lines.append(f"  {prt['name']:<14} {d} {prt['width']:>4}  {_port_meaning(man, prt['role'])}")
        for f in prt.get("fields", []):
            bits = f"[{f['lsb'] + f['width'] - 1}:{f['lsb']}]"
            what = f.get("meaning")
            if what is None:
                what = _physical_text(f["format"])
            lines.append(f"      {bits:<9} {f['name']}: {what}")
    return "".join(f"// {ln}".rstrip() + "\n" for ln in lines) + "\n"


def comp_core(comp: Any) -> Any:
    """The core of a built design (the component itself, or the sensor top's core).

    Parameters
    ----------
    comp : Component
        A core or a top of :mod:`pwas_hdl.hdl`.

    Returns
    -------
    Component
        ``comp.core`` if it has one, else ``comp``.
    """
    return getattr(comp, "core", comp)


def design_hash(files: dict[str, str]) -> str:
    """SHA-256 of the files that make the design (Verilog, weight memories, model), by name.

    Stored in the manifest (``design_hash``) and in every simulation and synthesis result, so that
    a result made for an earlier design is recognised as stale.

    Parameters
    ----------
    files : dict of str to str
        File name -> text (UTF-8 encoded for hashing); hashed in name order, each with its name
        and length.

    Returns
    -------
    str
        64 lowercase hex digits.
    """
    h = hashlib.sha256()
    for name in sorted(files):
        data = files[name].encode("utf-8")
        h.update(f"{name}\0{len(data)}\0".encode("utf-8"))
        h.update(data)
    return h.hexdigest()


def _stage_source(man: dict) -> str:
    """What the argmax stage follows, for the header and the report: ``core`` (parallel), or the
    ``serial core`` / ``serial additive sum`` and its rate (one class index every II clocks)."""
    if man.get("architecture", {}).get("kind") != "serial":
        return "core"
    return f"serial {'additive sum' if 'additive' in man else 'core'} (one class index every {man['ii']} clocks)"


def _classifier_section(man: dict) -> str:
    """Report section of a classifier design (the argmax stage and its class-index field)."""
    c = man["classifier"]
    labels = ", ".join(f"{v:g}" for v in c["classes"])
    return (f"\n## Classifier\n\nTarget `{c['target']}`, {c['n_classes']} classes ({labels}, in index order). An argmax "
            f"stage after the {_stage_source(man)} ({_cycles(c['stage_latency_cycles'])}, included in the latency) writes the class index "
            f"to `{c['port']}[{c['lsb'] + c['width'] - 1}:{c['lsb']}]` (`{c['field']}`); ties go to the lowest class index. "
            f"{c['float_agreement'][0].upper()}{c['float_agreement'][1:]}.\n")


def _design_kind(design: str, sensor: PWASVirtualSensor) -> str:
    """``design`` after the recurrent dispatch: a recurrent model's sensor top is the recurrent top."""
    recurrent = sensor.lags_ is not None and sensor.lags_.recurrent
    if design == "recurrent" and not recurrent:
        raise InputError("--design recurrent needs a recurrent model (fit --mz or fit-map --state), and this model has no "
                         "fed-back estimates; use --design sensor or core")
    return "recurrent" if design == "sensor" and recurrent else design


def _additive_section(man: dict) -> str:
    """Report section of an additive design: its parts (regressors, latency, accumulator, alignment,
    memories) and, for the serial architecture, how the parts of different latencies are aligned."""
    add, arch = man["additive"], man["architecture"]
    regs = man["lags"]["regressors"]
    rows = [[i, ", ".join(f"`{regs[j]}`" for j in pt["regressors"]), pt["latency"], pt["align_shift"],
             f"{pt['memory']['memories']} x {pt['memory']['depth']} words ({pt['memory']['kind']})"]
            for i, pt in enumerate(add["parts"])]
    serial = arch["kind"] == "serial"
    text = (f"\n## Additive parts\n\n{len(rows)} parts, each a {'serial' if serial else 'parallel'} PWAS core without "
            f"rounding ({arch['multipliers']} multipliers in all); their accumulators, shifted left by the alignment shift, "
            f"are added exactly in {add['sum_bits']} bits and rounded once, in one more register.")
    if serial:
        text += (f" The parts take each sample together, one every {man['ii']} clocks (the largest part's n + 1); a "
                 "shorter part's sum waits in its own output register (the next sample overwrites it no earlier) until "
                 f"the largest part's is ready: latency = the largest part's {max(pt['latency'] for pt in add['parts'])} "
                 "cycles + 1.")
    return text + "\n\n" + _md_table(["part", "regressors", "latency (cycles)", "alignment shift (bits)", "memories"],
                                      rows) + "\n"


def _warp_section(man: dict) -> str:
    """Report section of a non-uniform (power-of-two) partition: the warp in front of the core."""
    w = man["warp"]
    rows = [[f"`{d['regressor']}`", ", ".join(f"{v:.6g}" for v in d["breakpoints"]), ", ".join(map(str, d["code_breaks"])),
             ", ".join(str(1 << e) for e in d["exps"]), d["F"]] for d in w["dimensions"]]
    return (f"\n## Non-uniform partition\n\nEach input code (s{w['input_bits']}.0) is warped to the code of the uniform core "
            f"({w['core_input_bits']} bits, `2**F` codes per cell) in {w['latency_cycles']} register, included in the latency: "
            "comparators, a subtraction, two case tables, a shift (no multiplier, no divider).\n\n"
            + _md_table(["regressor", "breakpoints", "input codes", "base steps per cell", "core F"], rows) + "\n")


def _recurrence_section(man: dict) -> str:
    from pwas_hdl.design.recurrent import recurrence_report_text

    return recurrence_report_text(man)


def _timing_section(timing: dict) -> str:
    from pwas_hdl.flow.timing_closure import timing_report_text

    return "\n" + timing_report_text(timing)


def _generated_names(manifest_path: Path) -> set[str]:
    """The files a previous ``generate`` wrote (from its manifest's ``files``); empty if unreadable."""
    try:
        files = json.loads(manifest_path.read_text(encoding="utf-8"))["files"]
        names = {v for k, v in files.items() if k != "hex" and isinstance(v, str)}
        names |= {h["file"] for h in files.get("hex", [])}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {"manifest.json"}
    return {n for n in names if n and "/" not in n and "\\" not in n and not n.startswith(".")}


def check_outdir(outdir: str | os.PathLike, what: str = "-o") -> Path:
    """Refuse an output folder that ``generate`` may not write or replace (before any work).

    Stale pwas-hdl temporaries in an existing folder are removed first.

    Parameters
    ----------
    outdir : path
        The output folder (need not exist).
    what : str
        The option that named it, for messages.

    Returns
    -------
    Path
        The checked folder path.

    Raises
    ------
    InputError
        A bad path (:func:`~pwas_hdl.io.atomic.check_output_path`), or an existing folder that is
        neither empty nor made by ``generate`` (it holds no pwas-hdl ``manifest.json``).
    """
    out = check_output_path(outdir, what, kind="folder")
    if out.is_dir():
        try:
            clean_stale_temps(out)  # what a killed earlier run left
            entries = list(out.iterdir())
            man = out / "manifest.json"
            ours = man.is_file() and '"pwas-hdl-manifest"' in man.read_text(encoding="utf-8", errors="replace")[:200]
        except OSError as exc:
            raise InputError(f"{what} {str(out)!r}: cannot read the folder ({exc.strerror or exc})") from None
        if entries and not ours:
            raise InputError(f"{out} is not empty and was not made by pwas-hdl generate; choose a new or empty folder")
        if not os.access(out, os.W_OK | os.X_OK):
            raise InputError(f"{what} {str(out)!r} is not writable; choose another folder")
    return out


def write_folder(files: dict[str, str], outdir: str | os.PathLike) -> Path:
    """Write the generated ``files`` into ``outdir``; results and user files there are kept.

    ``outdir`` may be new, empty, or a folder made by ``generate`` (it holds a pwas-hdl
    ``manifest.json``); anything else is refused so that no user file is lost
    (:func:`check_outdir`). Re-generating replaces only the files the previous ``generate`` wrote
    (the names its manifest lists; those the new design does not have are removed). Everything
    else stays: ``sim/`` and ``synth/`` results, user files. The results record the
    ``design_hash`` they were made for, and ``pwas-hdl report`` marks those whose hash differs
    from the new manifest's as stale (:func:`pwas_hdl.design.report.stale_results`).

    A new folder is staged beside ``outdir`` and renamed into place whole. In an existing folder
    each file is written to a temporary folder inside it and renamed into place, the manifest
    last, so a reader sees either the old or the new version of every file. Temporaries are named
    with this process's pid, so the next run removes those of a killed one.

    Parameters
    ----------
    files : dict of str to str
        File name (inside ``outdir``) -> UTF-8 text; ``manifest.json`` among them.
    outdir : path

    Returns
    -------
    Path
        The folder written.

    Raises
    ------
    InputError
        As :func:`check_outdir`.
    """
    out = check_outdir(outdir)
    if not out.exists():
        # a new folder: staged beside it and renamed into place whole (a killed run leaves only a
        # pid-named temporary, which the next run removes)
        parent = out.parent if str(out.parent) else Path(".")
        parent.mkdir(parents=True, exist_ok=True)
        tmp = make_temp_dir(parent, out.name)
        try:
            for fname, text in files.items():
                (tmp / fname).write_text(text, encoding="utf-8")
                os.chmod(tmp / fname, 0o644)
            os.chmod(tmp, 0o755)
            os.replace(tmp, out)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        return out
    man = out / "manifest.json"
    previous = _generated_names(man) if man.is_file() else set()
    tmp = make_temp_dir(out, "generate")
    try:
        for fname, text in files.items():
            (tmp / fname).write_text(text, encoding="utf-8")
            os.chmod(tmp / fname, 0o644)
        for fname in sorted(files, key=lambda f: f == "manifest.json"):  # the manifest last
            os.replace(tmp / fname, out / fname)
        for fname in sorted(previous - set(files)):
            (out / fname).unlink(missing_ok=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out


def generate(model: PWASVirtualSensor | str | os.PathLike, outdir: str | os.PathLike, **options: Any) -> GeneratedDesign:
    """Build the design (see :func:`build_design` for the options) and write its folder.

    The folder is checked (:func:`check_outdir`) before the design is built. Re-generating into
    a folder keeps its ``sim/``, ``synth/`` and user files; results made for another design are
    then stale (:func:`write_folder`, :func:`pwas_hdl.design.report.stale_results`).

    Parameters
    ----------
    model : PWASVirtualSensor or path of a model (or estimator) file
    outdir : str or os.PathLike
        The design folder (created; Verilog, ``manifest.json``, ``report.md``, ...).
    **options
        The keyword options of :func:`build_design` (``design``, ``memory``, ``pipeline``, formats).

    Returns
    -------
    GeneratedDesign
        The design, with ``outdir`` set.
    """
    check_outdir(outdir)
    gd = build_design(model, **options)
    gd.outdir = write_folder(gd.files, outdir)
    return gd
