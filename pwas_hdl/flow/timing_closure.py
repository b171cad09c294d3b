"""Timing closure: pick the shallowest pipeline whose *measured* fmax reaches a target clock.

``generate(..., target_mhz=F, fpga_target="ecp5")`` (CLI: ``--clock-mhz F --fpga ecp5``) trades
pipeline depth for clock rate. :func:`pipeline_candidates` lists pipeline configurations from the
shallowest (2 cycles) to the deepest, one more register each, in the order that cuts the critical
path nextpnr reports (see the list's docstring); :func:`close_timing` places and routes them with
:func:`pwas_hdl.flow.synthesis.synthesize` (``--freq`` = the target, fixed placer seed) and returns the
first whose fmax reaches the target, with every measurement it made.

What is measured. nextpnr's fmax covers register-to-register paths only; a path from an input pin
to the first register (or from the last register to an output pin) is not constrained. A core whose
first register sits after the scale / rank / address logic would look fast while its input path
is long. So every candidate is placed inside a *timing harness*: a wrapper module that registers
every input and every output of the design (as the logic around an embedded core would), so that
the input and output paths are register-to-register paths and count in fmax. The harness adds
``harness_ffs`` flip-flops (the port bits) and nothing else; ``ffs_core`` subtracts them.

Search (deterministic for the same inputs, tools and seed): measure the shallowest candidate; while
the measured fmax is below the target, jump to the shallowest deeper candidate that could reach it
if its extra registers split the delay evenly (``fmax * L_next / L_measured >= target``; with
``prescreen=False`` simply the next one); when a candidate reaches the target after such a jump, the
skipped shallower candidates are measured downwards until one misses, so the answer is measured and
is the shallowest passing candidate above the last miss. When even the deepest misses, a
``TimingNotMet`` error (an :class:`~pwas_hdl.errors.InputError`: the target is the user's choice)
says the best fmax reached.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

from pwas_hdl.errors import InputError, InternalError
from pwas_hdl.hdl.params import Pipeline, PipelineRefused
from pwas_hdl.fixedpoint.memory_layout import WEIGHT_MEMORY_PATTERN
from pwas_hdl.io.atomic import make_temp_dir

if TYPE_CHECKING:
    from pwas_hdl.design.generate import GeneratedDesign

__all__ = [
    "FPGA_TARGETS",
    "TimingNotMet",
    "pipeline_candidates",
    "harness_verilog",
    "measure_design",
    "close_timing",
    "timing_report_text",
]

#: FPGA families the search places and routes on (``synthesis.synthesize`` targets).
FPGA_TARGETS = ("ecp5", "ice40")

Progress = Callable[[str], None]


class TimingNotMet(InputError):
    """Even the deepest pipeline misses the target clock (the message gives the best fmax and the
    largest target to ask for): bad input (``--clock-mhz``), exit 2, nothing written.

    Parameters
    ----------
    message : str
        The error message.
    record : dict
        The search's record so far (as :func:`close_timing` returns it), kept as :attr:`record`.
    """

    def __init__(self, message: str, record: dict[str, Any]):
        super().__init__(message)
        self.record = record


# ---------------------------------------------------------------------------------------------
# candidates
# ---------------------------------------------------------------------------------------------
def pipeline_candidates(n: int) -> list[Pipeline]:
    """Pipeline configurations of an ``n``-input core, shallowest first, latencies strictly increasing.

    Each one keeps the registers of the previous one and adds one where nextpnr put the critical
    path of the previous one (Lorenz core n = 4, N = 4096, default formats: 12-bit inputs, 11-bit
    weights; ECP5-45F inside the timing harness, ``--freq`` 150 MHz, seed 1; measured when the list
    was made)::

        cycles  adds          critical path of the previous candidate             fmax
        2       (min)         -                                                    47 MHz
        3       product       memory -> multipliers -> adder tree -> output        74
        4       rank          input -> scale / rank / addresses -> memory          78
        5       mem_out       memory clock-to-out -> multipliers                   99
        6       tree (1 reg)  products -> adder tree -> rounding -> output         111
        7       addr          rank -> addresses / mu / bank rotation -> memory     130
        8       tree (2 regs) products -> adder tree                               130
        9       split         (input -> scale / split -> rank)                     131
        10      tree (1/level)                                                     131
        11      mul_in        (added with issue 14)
        12      offset        (issue 14: rank -> offset tables | address adders)
        13      bank          (issue 14: bank rotation | memory address pins)

    That table was measured before the multiplier and block-RAM registers were packed into the
    hard blocks (:mod:`pwas_hdl.flow.hard_registers`, issue 14), when from 7 cycles on the 18x18
    multiplier was the critical path. Packed, candidate 7 (the ``balanced`` preset) reaches
    ~114 MHz (critical path: the products -> adder tree) and the 11-cycle one ~158 MHz (the vertex
    addresses); with the ``offset`` and ``bank`` registers (and the core's rank register holding the
    comparison bits) the last one, the ``max`` preset of 13 cycles, ~206 MHz (seed 1);
    ``benchmarks/hw_tables.py`` has the current figures. On iCE40 HX8K (multipliers in LUTs) the core goes from 42 MHz (2 cycles) to
    ~85-94 MHz, limited by the LUT multipliers.

    Parameters
    ----------
    n : int
        Inputs of the core (sets the adder-tree depth and so the tree registers of the candidates).

    Returns
    -------
    list of Pipeline
        The candidates; ``latency(n)`` (cycles) strictly increasing.
    """
    n = int(n)
    if n < 1:
        raise InputError("a PWAS core needs at least one input (n >= 1)")
    depth = Pipeline.tree_depth(n)
    tree = []  # tree_levels giving 1, 2, ... registers (distinct counts ceil(depth / t))
    for t in range(depth, 0, -1):
        if not tree or -(-depth // t) != -(-depth // tree[-1]):
            tree.append(t)
    steps = [("product", True), ("rank", True), ("mem_out", True), ("tree_levels", tree[0]), ("addr", True)]
    steps += [("tree_levels", t) for t in tree[1:2]] + [("split", True)] + [("tree_levels", t) for t in tree[2:]]
    steps += [("mul_in", True), ("offset", True), ("bank", True)]
    out = [Pipeline(split=False, rank=False, addr=False, mem_out=False, mul_in=False, product=False, tree_levels=0)]
    for key, val in steps:
        d = out[-1].to_dict()
        d[key] = val
        out.append(Pipeline.cast(d))
    lat = [p.latency(n) for p in out]
    assert all(a < b for a, b in zip(lat, lat[1:])), lat
    return out


def _label(p: Pipeline, registers: Sequence[str] | None = None) -> str:
    """A candidate's name in the record, the report and the messages: its preset's, else its registers
    (``rank+addr+mem_out+product+tree/3``).

    ``registers``: the registers the design builds with ``p``
    (:func:`pwas_hdl.hdl.api.pipeline_registers`; None: every one ``p`` has, as the parallel core).
    When the design ignores some of ``p``'s (the serial core: ``bank``, ``mul_in``, ``tree_levels``),
    the name lists the built ones only, and no preset name (a preset names registers not built).
    """
    on = [k for k in ("split", "rank", "offset", "addr", "bank", "mem_out", "mul_in", "product", "tree_levels") if getattr(p, k, False)]
    built = on if registers is None else [k for k in on if k in registers]
    if built == on:
        for name in ("min", "short", "balanced", "max"):
            if Pipeline.cast(name) == p:
                return name
    return "+".join(f"tree/{p.tree_levels}" if k == "tree_levels" else k for k in built) or "min"


# ---------------------------------------------------------------------------------------------
# timing harness
# ---------------------------------------------------------------------------------------------
def harness_verilog(manifest: dict[str, Any], name: str | None = None) -> tuple[str, str, int]:
    """A Verilog wrapper that registers every port of the manifest's top except the clock.

    Parameters
    ----------
    manifest : dict
        The design's manifest (``top``, ``clock``, ``ports``).
    name : str, optional
        The wrapper module's name (default ``<top>_timing_harness``).

    Returns
    -------
    module : str
        The wrapper module's name.
    verilog : str
        Its Verilog text.
    ffs : int
        Flip-flops the harness adds (one per port bit but the clock's).
    """
    top = manifest["top"]
    name = name or f"{top}_timing_harness"
    clk = manifest["clock"]["port"]
    ports = manifest["ports"]
    decl, regs, seq, conns = [], [], [], []
    nff = 0
    for p in ports:
        nm, w, d = p["name"], int(p["width"]), p["direction"]
        rng = f"[{w - 1}:0] " if w > 1 else ""
        if nm == clk:
            decl.append(f"    input wire {nm}")
            conns.append(f"        .{nm}({nm})")
            continue
        nff += w
        if d == "input":
            decl.append(f"    input wire {rng}{nm}")
            regs.append(f"    reg {rng}io_{nm};")
            seq.append(f"        io_{nm} <= {nm};")
            conns.append(f"        .{nm}(io_{nm})")
        elif d == "output":
            decl.append(f"    output reg {rng}{nm}")
            regs.append(f"    wire {rng}core_{nm};")
            seq.append(f"        {nm} <= core_{nm};")
            conns.append(f"        .{nm}(core_{nm})")
        else:
            raise InputError(f"port {nm} has direction {d!r}; the timing harness handles input and output ports")
    from pwas_hdl import __version__

    head = [
        f"{name}: timing harness of {top} generated by pwas-hdl {__version__} -- do not edit, regenerate",
        f"wraps {top} ({manifest.get('design', '?')} design, design_hash {manifest.get('design_hash', 'not recorded')}; "
        f"its model and formats: the header of {top}.v and manifest.json)",
        "every port but the clock registered, so that nextpnr's fmax covers the input and output paths of the",
        "design as they are when it is embedded in a larger one; the fields of the registered ports:",
    ]
    for p in ports:
        for f in p.get("fields", []):
            fmt = f.get("format")
            what = fmt["str"] if fmt and fmt.get("str") else (f.get("meaning") or "")
            head.append(f"  {p['name']}[{f['lsb'] + f['width'] - 1}:{f['lsb']}] {f['name']}: {what}".rstrip())
    text = (
        "".join(f"// {ln}\n" for ln in head)
        + f"module {name} (\n" + ",\n".join(decl) + "\n);\n"
        + "\n".join(regs) + "\n"
        f"    always @(posedge {clk}) begin\n" + "\n".join(seq) + "\n    end\n"
        f"    {top} core (\n" + ",\n".join(conns) + "\n    );\n"
        "endmodule\n"
    )
    return name, text, nff


_STAGE_RE = re.compile(r"^(s_(?:split|rank|voff|addr|bank|memout|mulin|mem|pp|prod|tree\d+))_")
#: The serial core's registers (:mod:`pwas_hdl.hdl.serial_core`) named by the parallel core's stage
#: of the same cycle: ``m_*`` beside the memory read (``s_mem``), ``mo_*`` the ``mem_out`` register
#: (``s_memout``), ``p_*`` the ``product`` register (``s_prod``).
_SERIAL_STAGE_RE = re.compile(r"^(m|mo|p)_(?:valid|first|last|mu|oor|data|prod[0-9]+)(?:$|_TRELLIS|_SB_|\$|\[)")
_SERIAL_STAGES = {"m": "s_mem", "mo": "s_memout", "p": "s_prod"}


def _stage_of_cell(cell: str) -> str:
    """Pipeline stage of a nextpnr cell, from the register names of :mod:`pwas_hdl.hdl.core` (the
    serial core's, :mod:`pwas_hdl.hdl.serial_core`, by the parallel core's stage of the same cycle
    where it has one: ``s_mem``, ``s_memout``, ``s_prod``; else ``serial ...``).

    After flattening, the harness registers are named after the nets they drive (``core.in__payload``
    ...) and the core's cells carry a ``core.`` prefix.
    """
    c = cell[5:] if cell.startswith("core.") else cell
    part = re.match(r"(part[0-9]+)_", c)  # an additive design's parts, flattened (pwas_hdl.hdl.additive_top)
    if part:  # the part's own names may repeat the prefix (part1_part1_acc): strip every copy of it
        rest = c[part.end():]
        while rest.startswith(part.group(0)):
            rest = rest[part.end():]
        return f"{part.group(1)} {_stage_of_cell(rest)}"
    if c.startswith(("io_", "in__payload", "in__valid", "rst", "out__ready", "s_axis_tdata", "s_axis_tvalid", "aresetn",
                     "m_axis_tready")):
        return "input register"
    if re.match(r"warmup[0-9]+", c):  # the warm-up shift register of a sensor / recurrent top (not the warm port)
        return "warm-up register"
    if c.startswith(("out__payload", "out__valid", "in__ready", "warm", "m_axis_tdata", "m_axis_tvalid", "s_axis_tready")):
        return "output register"
    if re.match(WEIGHT_MEMORY_PATTERN, c):
        return "memory"
    if c.startswith(("scores_payload", "scores_valid")):  # a classifier's core (or additive sum) output register,
        return "score register (argmax input)"  # which the argmax stage reads (classifier_top.inline_core_and_argmax)
    m = _STAGE_RE.match(c)
    if m:
        return m.group(1)
    if re.match(r"prod[0-9]+(_[0-9]+)?_MULT", c):  # a multiplier (its product register packed inside; serial: prod<z>)
        return "multiplier"
    if re.match(r"q_(addr|mu|valid)[0-9]+($|_TRELLIS|_SB_|\$)|q_oor", c):  # the serial core's vertex shift register
        return "serial vertex register"
    m = _SERIAL_STAGE_RE.match(c)
    if m:
        return _SERIAL_STAGES[m.group(1)]
    # the serial core's accumulator and the registers beside it (not part<i>_acc, a part's output)
    if re.match(r"acc([0-9]+|_done|_oor)($|_TRELLIS|_SB_|\$|\[)", c):
        return "serial accumulator"
    if re.match(r"gap($|_TRELLIS|_SB_|\$|\[)", c):  # the serial core's input throttle (serial_core.serial_throttle)
        return "serial input throttle"
    if re.match(r"fb[0-9]+_", c):  # a recurrent top's feedback path (recurrent_top: fb<c>_prod / _code / _z<k> / _in<k>)
        return "feedback register"
    for pattern, stage in _BANK_STAGES:  # an observer bank, parallel or serial: which part of it
        if re.match(pattern, c):
            return stage
    for prefix, stage in (("s_warp", "warp register"), ("am_", "argmax stage"), (("term", "psum", "sum_sat"), "additive sum"),
                          (("bank_", "feat", "obs"), "observer bank"),
                          ("lag_", "lag register")):  # a sensor top's lag bank (sensor_top)
        if c.startswith(prefix):
            return stage
    return re.split(r"_TRELLIS|_SB_|\$", c)[0][:40] or c[:40]


#: The parts of an observer bank by register / net name, first match wins: the parallel bank
#: (:mod:`pwas_hdl.hdl.observer_bank`, :mod:`pwas_hdl.hdl.residual_features`,
#: :mod:`pwas_hdl.hdl.observer_bank_top`; the taps of :mod:`pwas_hdl.hdl.observer_tap_sensor_top`) and
#: the serial bank's lanes (:mod:`pwas_hdl.hdl.serial_observer_bank`, ``lane<k>_*``).
_BANK_STAGES: tuple[tuple[str, str], ...] = (
    (r"s_in2?_|y_aligned|obs[0-9]+_(p(b[0-9]+|l)_|in[0-9]+)", "bank input stage"),
    (r"obs[0-9]+_|bank_update|state_saturated", "bank states"),
    (r"s_(res|sq)_|feat[0-9]+_sq", "bank residual square"),
    (r"s_sum|sum_update|feat[0-9]+_(sum|dl)", "bank window sum"),
    (r"s_isqrt|feat[0-9]+_isqrt", "bank square root"),
    (r"s_(root|code)_tap|tap[0-9]+_|tap_", "bank taps"),
    (r"s_root", "bank root register"),
    (r"s_code|feat[0-9]+_(capped|prod|affine|q)", "bank feature code"),
    (r"lane[0-9]+_(pa|pb[0-9]*|pl|px|a|b[0-9]*|l|kmul|mac_valid)(_|[0-9]|$|\$|\[)", "bank lane products"),
    (r"lane[0-9]+_(acc|x|new|shift|first|d($|_|\$|\[)|active|yhat)", "bank lane states"),
    (r"lane[0-9]+_(e|sq)(_|$|\$|\[)", "bank lane residual square"),
    (r"lane[0-9]+_(sum|dl|fs_)", "bank lane window sum"),
    (r"lane[0-9]+_(isqrt|root)", "bank lane square root"),
    (r"lane[0-9]+_(cap|f)", "bank lane feature code"),
    (r"lane[0-9]+_", "bank lane"),
    (r"bank_step|bank_", "bank schedule"),
)


def _critical_path(report: dict[str, Any]) -> dict[str, Any] | None:
    """The clock-to-clock critical path of a nextpnr report: start/end cell and stage, delays."""
    for cp in report.get("critical_paths", []):
        if cp.get("from", "").startswith("posedge") and cp.get("to", "").startswith("posedge"):
            path = cp.get("path") or []
            if not path:
                return None
            total = sum(float(s.get("delay", 0.0)) for s in path)
            routing = sum(float(s.get("delay", 0.0)) for s in path if s.get("type") == "routing")
            src, dst = path[0]["from"]["cell"], path[-1]["to"]["cell"]
            return {
                "from": _stage_of_cell(src),
                "to": _stage_of_cell(dst),
                "delay_ns": round(total, 3),
                "routing_ns": round(routing, 3),
            }
    return None


# ---------------------------------------------------------------------------------------------
# measuring one design
# ---------------------------------------------------------------------------------------------
def measure_design(
    gd: "GeneratedDesign",
    fpga: str,
    *,
    freq_mhz: float | None,
    seed: int = 1,
    device: str | None = None,
    workdir: str | os.PathLike,
    harness: bool = True,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Place and route a built design (:class:`~pwas_hdl.design.generate.GeneratedDesign`) on ``fpga``.

    The design's files are written to ``workdir`` and placed and routed by
    :func:`~pwas_hdl.flow.synthesis.synthesize` (with ``harness``: inside the timing harness, the
    same one ``pwas-hdl synth`` uses by default); returns its result with ``harness_ffs`` and
    ``ffs_core`` (the design's flip-flops) added and ``ffs`` counting the harness's too.

    Parameters
    ----------
    gd : GeneratedDesign
        The built design (its ``files`` and ``manifest``).
    fpga : str
        ``"ecp5"`` or ``"ice40"`` (as :func:`~pwas_hdl.flow.synthesis.synthesize`'s ``target``).
    freq_mhz : float, optional
        Target clock in MHz, nextpnr's ``--freq``.
    seed : int
        nextpnr placer seed.
    device : str, optional
        nextpnr device (default: the family's, see :func:`~pwas_hdl.flow.synthesis.synthesize`).
    workdir : str or os.PathLike
        Folder for the design's files and the run (emptied first if it exists).
    harness : bool
        Place and route inside the timing harness (:func:`harness_verilog`).
    progress : callable(str), optional
        Called with one line of text before each tool runs.

    Returns
    -------
    dict
        :func:`~pwas_hdl.flow.synthesis.synthesize`'s result (``fmax_mhz`` in MHz, resources in
        cells), ``ffs`` including the harness's flip-flops, plus ``harness_ffs`` and ``ffs_core``.
    """
    from pwas_hdl.flow.synthesis import synthesize

    work = Path(workdir)
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    for fname, text in gd.files.items():
        if fname.endswith((".v", ".hex", ".json")):
            (work / fname).write_text(text, encoding="utf-8")
    (work / "manifest.json").write_text(json.dumps(gd.manifest, indent=1) + "\n", encoding="utf-8")
    res = synthesize(work, fpga, device=device, freq_mhz=freq_mhz, seed=seed, workdir=work / "pnr", progress=progress,
                     harness=harness)
    nff = (res.get("harness") or {}).get("ffs", 0)
    res["harness_ffs"] = nff
    res["ffs_core"] = res["ffs"]
    if isinstance(res.get("ffs"), int):
        res["ffs"] = res["ffs"] + nff
    return res


# ---------------------------------------------------------------------------------------------
# the search
# ---------------------------------------------------------------------------------------------
def _entry(pipe: Pipeline, cycles: int, label: str, res: dict[str, Any] | None, target: float,
           note: str | None = None) -> dict[str, Any]:
    e: dict[str, Any] = {"latency_cycles": int(cycles), "label": label, "pipeline": pipe.to_dict()}
    if res is None:
        e.update({"measured": False, "note": note})
        return e
    fm = res.get("fmax_mhz")
    e.update({
        "measured": True,
        "fmax_mhz": fm,
        "latency_ns": res.get("latency_ns"),
        "meets_target": bool(fm is not None and fm >= target),
        "luts": res.get("luts"),
        "ffs": res.get("ffs"),
        "ffs_core": res.get("ffs_core"),
        "dsp": res.get("dsp"),
        "bram": res.get("bram"),
        "critical_path": res.get("critical_path"),
    })
    if note:
        e["note"] = note
    return e


def close_timing(
    build: Callable[[Pipeline], Any],
    n: int,
    target_mhz: float,
    *,
    fpga: str = "ecp5",
    device: str | None = None,
    seed: int = 1,
    prescreen: bool = True,
    candidates: Sequence[Pipeline] | None = None,
    workdir: str | os.PathLike | None = None,
    progress: Progress | None = None,
    executor: Any = None,
    latency: Callable[[Pipeline], int] | None = None,
    registers: Callable[[Pipeline], Sequence[str]] | None = None,
) -> tuple[Pipeline, dict[str, Any]]:
    """Find the shallowest candidate pipeline whose measured fmax reaches ``target_mhz``.

    Parameters
    ----------
    build
        ``pipeline -> GeneratedDesign`` (the design to measure, weights inline).
    n
        Number of core inputs (sets the adder-tree depth of the candidates).
    target_mhz
        Clock target in MHz; also nextpnr's ``--freq``.
    fpga, device
        ``"ecp5"`` (default device 45k) or ``"ice40"`` (hx8k).
    seed
        nextpnr placer seed (same inputs and seed: same result).
    prescreen
        Skip candidates that cannot reach the target even if their extra registers split the
        measured delay evenly; the skipped ones just below a passing candidate are measured
        afterwards (see the module notes).
    candidates
        Default :func:`pipeline_candidates` ``(n)``.
    latency : callable(Pipeline) -> int, optional
        The design's latency in cycles with a candidate pipeline (default: the core's,
        ``pipeline.latency(n)``). A design around the core (an additive sum register, a warp, an
        observer bank, an argmax stage) adds cycles; the record and the pre-screen use these. Of the
        default candidates, one whose ``latency`` raises :class:`~pwas_hdl.hdl.params.PipelineRefused`
        (a pipeline the design cannot take, though it takes others) or equals the previous kept
        one's (no register added: the same design) is dropped; any other error of ``latency`` (the
        design itself refused: e.g. a classifier on the serial core) is raised as it is. Given
        ``candidates`` must all be taken, latencies strictly increasing.
    registers : callable(Pipeline) -> sequence of str, optional
        The registers the design builds with a candidate pipeline
        (:func:`pwas_hdl.hdl.api.pipeline_registers`); the candidates' labels name those only (the
        serial core ignores ``bank``, ``mul_in`` and ``tree_levels``). Default: every register of
        the pipeline (the parallel core).
    workdir
        Where the place-and-route runs go (default: a temporary folder, removed afterwards).
    progress : callable(str), optional
        Called with one line of text before each tool runs.
    executor : pwas_hdl.flow.executor.Executor, optional
        With a distributed executor, the candidates the search may need next are placed and
        routed speculatively on the workers (as many as there are workers) while the search
        waits for the one it needs; the search itself, and so the record, is the serial one
        (speculative results that the search does not use are dropped).

    Returns
    -------
    (Pipeline, dict)
        The chosen pipeline and the JSON-ready record: ``target_mhz``, ``fpga``, ``device``,
        ``seed``, ``harness``, ``tools``, ``chosen`` (index into ``candidates``), ``candidates``
        (every candidate with ``measured``, and for the measured ones ``fmax_mhz``, ``latency_ns``,
        resources and the critical path), ``measurements`` (order of the runs).

    Raises
    ------
    TimingNotMet
        No candidate reaches the target (``record`` holds what was measured).
    InputError
        Bad target or FPGA family; a design that does not fit the device.
    """
    if fpga not in FPGA_TARGETS:
        raise InputError(f"--fpga (fpga_target) must be one of {', '.join(FPGA_TARGETS)}, got {fpga!r}")
    if isinstance(target_mhz, bool) or not isinstance(target_mhz, (int, float)) or not target_mhz > 0 or target_mhz == float("inf"):
        raise InputError(f"--clock-mhz (target_mhz) must be a positive number of MHz, got {target_mhz!r}")
    target = float(target_mhz)
    latency_of = latency if latency is not None else (lambda p: p.latency(n))
    if candidates is not None:
        cands = list(candidates)
        lat = [int(latency_of(p)) for p in cands]
    else:
        cands, lat = [], []
        for p in pipeline_candidates(n):
            try:
                cycles = int(latency_of(p))
            except PipelineRefused:  # e.g. an additive design's parts cannot be given equal latencies
                continue
            if not lat or cycles > lat[-1]:
                cands.append(p)
                lat.append(cycles)
        if not cands:
            raise InputError("none of the candidate pipelines can be built for this design; give --pipeline")
    if any(a >= b for a, b in zip(lat, lat[1:])):
        raise InputError(f"candidate latencies must increase strictly, got {lat}")
    labels = [_label(p, None if registers is None else registers(p)) for p in cands]

    results: dict[int, dict[str, Any]] = {}
    order: list[int] = []
    tmp = None
    if workdir is None:
        tmp = str(make_temp_dir(tempfile.gettempdir(), "pwas-timing"))
        base = Path(tmp)
    else:
        base = Path(workdir)
    tools = None
    try:
        speculate = executor is not None and getattr(executor, "distributed", False)
        futures: dict[int, Any] = {}
        width = executor.describe()["workers"] if speculate else 1

        def measure(i: int) -> dict[str, Any]:
            gd = build(cands[i])
            built = (getattr(gd, "manifest", None) or {}).get("latency_cycles")
            if built is not None and built != lat[i]:
                raise InternalError(f"candidate {labels[i]}: the design has latency {built}, "
                                    f"the search counted {lat[i]} cycles")
            return measure_design(gd, fpga, freq_mhz=target, seed=seed, device=device,
                                  workdir=base / f"c{i:02d}_L{lat[i]}")

        def submit(i: int) -> None:
            if 0 <= i < len(cands) and i not in futures and i not in results:
                futures[i] = executor._connect().submit(measure, i, retries=1, pure=False)

        def run(i: int) -> float:
            nonlocal tools
            if progress:
                progress(f"timing: candidate {i + 1}/{len(cands)} ({labels[i]}, {lat[i]} cycles) on {fpga} at {target:g} MHz")
            if speculate:
                # the one needed now; then, while workers are free, the one below (the downward
                # check) and the deeper ones in order
                submit(i)
                for k in [i - 1] + list(range(i + 1, len(cands))):
                    if sum(1 for f in futures.values() if not f.done()) >= width:
                        break
                    submit(k)
                res = futures.pop(i).result()
            else:
                res = measure(i)
            results[i] = res
            order.append(i)
            tools = tools or res.get("tools")
            fm = res.get("fmax_mhz") or 0.0
            if progress:
                progress(f"timing: {lat[i]} cycles -> fmax {fm:.1f} MHz ({'meets' if fm >= target else 'misses'} {target:g} MHz)")
            return fm

        chosen = None
        last_miss = -1
        i = 0
        while True:
            fm = run(i)
            if fm >= target:
                # measured downwards through skipped candidates until one misses
                j = i
                while j - 1 > last_miss:
                    if run(j - 1) >= target:
                        j -= 1
                    else:
                        break
                chosen = j
                break
            last_miss = i
            if i == len(cands) - 1:
                break
            nxt = i + 1
            if prescreen and fm > 0:
                nxt = next((k for k in range(i + 1, len(cands)) if fm * lat[k] / lat[i] >= target), len(cands) - 1)
            i = nxt
    finally:
        if speculate:
            for f in futures.values():
                f.cancel()
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)

    entries = []
    for k, p in enumerate(cands):
        note = None
        if k not in results:
            if chosen is not None and k > chosen:
                note = "not needed (a shallower candidate meets the target)"
            else:
                note = "skipped by the pre-screen (cannot reach the target if its extra registers split the measured delay evenly)"
        entries.append(_entry(p, lat[k], labels[k], results.get(k), target, note))
    best = max(order, key=lambda k: (results[k].get("fmax_mhz") or 0.0, -k))
    record: dict[str, Any] = {
        "target_mhz": target,
        "fpga": fpga,
        "device": results[order[0]].get("device"),
        "part": results[order[0]].get("part"),
        "seed": seed,
        "prescreen": bool(prescreen),
        "harness": "every port registered (fmax includes the input and output paths); "
                   "FF counts include the harness flip-flops (ffs_core excludes them)",
        "tools": tools,
        "measurements": [lat[k] for k in order],
        "chosen": chosen,
        "met": chosen is not None,
        "best_fmax_mhz": results[best].get("fmax_mhz"),
        "candidates": entries,
    }
    if chosen is None:
        fm = results[best].get("fmax_mhz")
        raise TimingNotMet(
            f"no pipeline reaches {target:g} MHz on {record['part']}: the best measured fmax is "
            f"{fm:.1f} MHz ({lat[best]} cycles, {labels[best]}){_limit_hint(results[best].get('critical_path'))}; "
            f"choose a target of at most {math.floor(fm)} MHz, another FPGA, or a fixed --pipeline",
            record,
        )
    return cands[chosen], record


def best_critical_path(record: dict[str, Any]) -> dict[str, Any] | None:
    """The critical path of the fastest measured candidate of a search's record (the shallowest of
    equal fmax), or None.

    Parameters
    ----------
    record : dict
        As :func:`close_timing` returns it (or :attr:`TimingNotMet.record`).

    Returns
    -------
    dict or None
        ``{"from", "to", "delay_ns", "routing_ns"}`` (stage names, ns), None when not measured.
    """
    measured = [c for c in record.get("candidates", []) if c.get("measured") and c.get("fmax_mhz") is not None]
    if not measured:
        return None
    return max(measured, key=lambda c: (c["fmax_mhz"], -c["latency_cycles"])).get("critical_path")


def in_square_root(path: dict[str, Any] | None) -> bool:
    """True when a critical path (:func:`best_critical_path`) starts or ends inside an observer bank's
    square root (parallel or serial: stage names ``bank square root`` / ``bank lane square root``)."""
    return bool(path) and any("square root" in str(path.get(k) or "") for k in ("from", "to"))


def _limit_hint(path: dict[str, Any] | None) -> str:
    """What the best candidate's critical path says about the search's limit, for the
    :class:`TimingNotMet` message: a path inside an observer bank is not cut by the core's registers
    (those the search varies), and one inside its square root is shortened by ``--isqrt-every``."""
    ends = [str(path.get(k) or "") for k in ("from", "to")] if path else []
    if in_square_root(path):
        return (f"; its critical path ({' -> '.join(ends)}) is inside the observer bank's square root: a smaller "
                "--isqrt-every (default 3) shortens it")
    if any(e.startswith("bank ") for e in ends):
        return (f"; its critical path ({' -> '.join(ends)}) is in the observer bank, which the core's pipeline "
                "registers do not cut")
    return ""


def timing_report_text(rec: dict[str, Any]) -> str:
    """The Markdown section of ``report.md`` about a timing-closure search.

    Parameters
    ----------
    rec : dict
        The record of :func:`close_timing`.

    Returns
    -------
    str
        Markdown (clocks in MHz, latencies in cycles and ns).
    """
    lines = [
        "## Timing closure",
        "",
        f"Target **{rec['target_mhz']:g} MHz** on {rec['part']} (nextpnr, seed {rec['seed']}, `--freq` = target; "
        f"design inside a harness that registers every port, so fmax covers the input and output paths). "
        f"Candidates from the shallowest; measured in the order {', '.join(str(v) for v in rec['measurements'])} (cycles).",
        "",
        "| cycles | pipeline | fmax (MHz) | latency (ns) | LUT4 | FF (core) | DSP | BRAM | critical path | result |",
        "|---:|---|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    skipped: dict[str, list[str]] = {}
    for k, c in enumerate(rec["candidates"]):
        if c["measured"]:
            cp = c.get("critical_path") or {}
            cpt = f"{cp.get('from')} -> {cp.get('to')} ({cp.get('delay_ns')} ns)" if cp else "-"
            mark = "**chosen**" if rec.get("chosen") == k else ("meets" if c["meets_target"] else "misses")
            lines.append(f"| {c['latency_cycles']} | {c['label']} | {c['fmax_mhz']} | {c['latency_ns']} | {c['luts']} | "
                         f"{c['ffs_core']} | {c['dsp']} | {c['bram']} | {cpt} | {mark} |")
        else:
            skipped.setdefault(c["note"], []).append(f"{c['latency_cycles']} ({c['label']})")
    for note, cands in skipped.items():
        lines += ["", f"Not measured, {note}: {', '.join(cands)}."]
    return "\n".join(lines) + "\n"
