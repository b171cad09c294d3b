"""Run a generated design in a Verilog simulator (cocotb: Icarus or Verilator) against the bit-true model.

This is the library behind ``pwas-hdl simulate`` and the RTL tests. The testbench itself lives in
``sim/`` next to the package (``sim/pwas_tb.py``, drivers in ``sim/pwas_drivers.py``, build cache
in ``sim/pwas_runner.py``); it reads the design's ``manifest.json`` for ports, bit fields and
latency. This module prepares what the testbench replays and checks:

* :func:`load_design` reads a folder written by ``pwas-hdl generate`` and rebuilds the bit-true
  model from ``model.json`` and the generator options recorded in the manifest (the *expected*
  values come from there, never from the RTL).
* :func:`segment` turns input transfers (codes) into a :class:`Segment` with its expected outputs:
  for the core one output per transfer, for the sensor top one per transfer after the ``M - 1``
  warm-up transfers, computed through :class:`~pwas_hdl.fit.regressors.LagStructure` exactly as the
  software does.
* :func:`run_rtl` builds (cached) and runs the testbench and returns an :class:`RTLResult`:
  every mismatch (exact, 0 LSB), the error of the RTL against the float model and the stated bound,
  the measured latency and II, and -- with ``debug=True`` -- the first pipeline stage whose
  registers differ from :meth:`FixedPointModel.trace <pwas_hdl.fixedpoint.bittrue.FixedPointModel.trace>`
  for the first failing sample.
* :func:`simulate_data` replays a CSV file (``pwas-hdl simulate``).
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import re
import shutil
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from pwas_hdl.errors import CheckFailed, InputError, fault_text
from pwas_hdl.fixedpoint.memory_layout import WEIGHT_MEMORY_PATTERN
from pwas_hdl.resources import sim_dir
from pwas_hdl.fixedpoint.bitfields import pack, pack_fields
from pwas_hdl.fixedpoint.bittrue import FixedPointModel
from pwas_hdl.fixedpoint.reduction import tree_levels
from pwas_hdl.design.manifest import load_manifest
from pwas_hdl.io.atomic import logs_kept, make_temp_dir
from pwas_hdl.limits import check_seed, check_values

__all__ = [
    "SIM_DIR",
    "SIMULATORS",
    "ENGINES",
    "MAX_STALL",
    "Design",
    "Segment",
    "Run",
    "RTLResult",
    "load_design",
    "segment",
    "standard_runs",
    "run_rtl",
    "simulate_data",
    "simulate_arrays",
    "stage_probes",
    "locate_difference",
    "sim_module",
]

SIM_DIR = sim_dir()
SIMULATORS = ("icarus", "verilator")
#: Testbench engines of :func:`run_rtl` / ``pwas-hdl simulate --engine``.
ENGINES = ("cocotb", "native")
#: Largest ``--stall`` of ``pwas-hdl simulate``. The benches (``sim/pwas_tb.py``,
#: ``sim/pwas_recurrent_tb.py``, ``sim/pwas_native_tb.cpp``) give up after about 4 / (p_valid p_ready)
#: times the transfers' cycles with each probability taken >= 0.05, i.e. 4 times what a stalled
#: stream needs up to a stall of 0.95 (a transfer: about 1 / (1 - stall)^2 = 400 cycles); above it they
#: failed correct designs (and a transfer would take thousands of cycles: hours in cocotb).
MAX_STALL = 0.95


def sim_module(name: str) -> ModuleType:
    """Import a module of ``sim/`` (not an installed package) by path, e.g. ``"pwas_runner"``.

    Parameters
    ----------
    name : str
        The module's file name without ``.py``.

    Returns
    -------
    module
        The module (imported once, then taken from ``sys.modules``).

    Raises
    ------
    FileNotFoundError
        ``sim/<name>.py`` is missing (an incomplete installation).
    """
    if name in sys.modules:
        return sys.modules[name]
    path = SIM_DIR / f"{name}.py"
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing; the pwas-hdl installation is incomplete (reinstall pwas-hdl)")
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    try:
        spec.loader.exec_module(mod)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return mod


# ---------------------------------------------------------------------------------------------------- design


class ManifestView:
    """What a replay reads of a generated folder's manifest (``self.manifest``, ``self.outdir``):
    the top's name, the latency, the ports by role and the payload bit fields. Shared by
    :class:`Design` and :class:`~pwas_hdl.verify.estimator_simulation.EstimatorDesign`."""

    manifest: dict
    outdir: Path

    @property
    def top(self) -> str:
        """The top module's Verilog name (manifest ``top``)."""
        return self.manifest["top"]

    @property
    def latency(self) -> int:
        """Input-to-output latency, clock cycles (manifest ``latency_cycles``)."""
        return int(self.manifest["latency_cycles"])

    def port(self, role: str) -> dict:
        """The manifest's port record of one role.

        Parameters
        ----------
        role : str
            A port role of the manifest (``"in.payload"``, ``"out.payload"``, ``"clock"``, ...).

        Returns
        -------
        dict
            The port record (``name``, ``role``, ``width`` in bits, ``fields`` for a payload, ...).

        Raises
        ------
        KeyError
            The manifest has no port of that role.
        """
        for p in self.manifest["ports"]:
            if p["role"] == role:
                return p
        raise KeyError(f"the manifest of {self.outdir} has no port with role {role!r}")

    @property
    def in_fields(self) -> list[dict]:
        """The input payload's bit fields, payload order (manifest port ``in.payload``)."""
        return self.port("in.payload")["fields"]

    @property
    def out_fields(self) -> list[dict]:
        """The output payload's bit fields: the scores, ``out_of_range``[, ``class_index``]."""
        return self.port("out.payload")["fields"]


@dataclass
class Design(ManifestView):
    """A generated design folder and the bit-true model it must match (the manifest's facts: :class:`ManifestView`).

    Made by :func:`load_design`.

    Attributes
    ----------
    outdir : Path
        The design folder.
    manifest : dict
        Its ``manifest.json``, parsed.
    sensor : PWASVirtualSensor
        The sensor rebuilt from the folder's ``model.json``.
    model : FixedPointModel
        The bit-true model of the PWAS core (the formats the manifest lists).
    verilog_path : Path
        The Verilog file to simulate (the folder's, or the one given to :func:`load_design`).
    bank : ObserverBankSensorModel or None
        Observer-bank sensors (manifest ``front_end``): the bit-true bank + core
        (:class:`~pwas_hdl.fixedpoint.observer_bank.ObserverBankSensorModel`; ``model`` is its
        core); else None.
    """

    outdir: Path
    manifest: dict
    sensor: Any  # PWASVirtualSensor
    model: FixedPointModel
    verilog_path: Path
    bank: Any = None

    @property
    def kind(self) -> str:
        """The manifest's design kind: ``"core"``, ``"sensor"``, ``"recurrent"``, ..."""
        return self.manifest["design"]

    @property
    def warmup(self) -> int:
        """Input samples a sensor top takes before its first output (0 for a core)."""
        if self.kind not in ("sensor", "recurrent"):
            return 0
        return int(self.manifest["lags"]["warmup"]["samples_without_output"])  # the schema requires it for a sensor

    @property
    def verilog(self) -> str:
        """The text of :attr:`verilog_path`."""
        return self.verilog_path.read_text(encoding="utf-8")

    @property
    def runtime_files(self) -> dict[str, Path]:
        """Files the Verilog may read at simulation time (the ``$readmemh`` hex files), name -> path."""
        res = {}
        for h in self.manifest["files"]["hex"]:
            name = h["file"]
            if (self.outdir / name).is_file():
                res[name] = self.outdir / name
        return res


def load_design(outdir: str | os.PathLike, verilog: str | os.PathLike | None = None) -> Design:
    """Read a folder written by ``pwas-hdl generate``; rebuild its bit-true model.

    Parameters
    ----------
    outdir : str or os.PathLike
        The design folder (``manifest.json``, ``model.json``, the Verilog).
    verilog : str or os.PathLike, optional
        Simulate this file instead of the folder's (e.g. a deliberately mutated copy).

    Returns
    -------
    Design
        The manifest, the rebuilt sensor and bit-true model, and the paths the simulators need.

    Raises
    ------
    FileNotFoundError, ValueError
        No manifest / model, or the model rebuilt from ``model.json`` does not give the formats
        the manifest lists (the folder was edited by hand: regenerate it).
    """
    out = Path(outdir)
    try:
        design = _load_design(out, verilog)
        # what the replay reads later: a hand-edited manifest fails here, not in the middle of a run
        _ = (design.top, design.kind, design.latency, design.warmup, design.in_fields, design.out_fields,
             int(design.manifest["ii"]))
    except (KeyError, TypeError, AttributeError, IndexError) as exc:
        raise InputError(
            f"{out / 'manifest.json'} is incomplete or corrupt ({fault_text(exc)}); "
            "regenerate the folder with `pwas-hdl generate`"
        ) from exc
    return design


def _load_design(out: Path, verilog: str | os.PathLike | None) -> Design:
    from pwas_hdl.design.generate import FORMAT_OPTIONS, fixed_point_model
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    man = load_manifest(out)
    files = man["files"]
    model_file = out / files["model"]
    if not model_file.is_file():
        raise FileNotFoundError(f"{model_file} is missing; regenerate the folder with `pwas-hdl generate`")
    sensor = PWASVirtualSensor.load(model_file)
    opts = man["generator"]["options"]
    fmts = {k: opts[k] for k in FORMAT_OPTIONS if opts[k] is not None}
    bank = None
    with warnings.catch_warnings():  # saturation warnings were given by `generate`; the manifest records them
        warnings.simplefilter("ignore", UserWarning)
        if "front_end" in man:  # observer-bank sensor (issue 12)
            from pwas_hdl.fixedpoint.observer_bank import BANK_FORMAT_OPTIONS, observer_bank_model

            bank = observer_bank_model(sensor, memory=opts["memory"], **fmts, **{k: opts.get(k) for k in BANK_FORMAT_OPTIONS})
            fxm = bank.core
        else:
            fxm = fixed_point_model(sensor, memory=opts["memory"], **fmts)
    fx = fxm.to_dict()
    want = man["formats"]
    for key, mine in (("output", fx["output"]), ("weight", fx["weights"]), ("widths", fx["widths"]), ("mu_frac", fx["F"])):
        theirs = want[key]
        if key in ("output", "weight"):
            mine = {k: mine[k] for k in ("bits", "frac")}
            theirs = {k: theirs[k] for k in ("bits", "frac")}
        if json.dumps(mine, sort_keys=True) != json.dumps(theirs, sort_keys=True):
            raise InputError(
                f"{out}: the bit-true model rebuilt from model.json has {key} {mine}, the manifest says {theirs}; "
                "the folder was modified after `pwas-hdl generate`: regenerate it"
            )
    if [int(v) for v in man["domain"]["lo_code"]] != [int(v) for v in fxm.lo_codes]:
        raise InputError(f"{out}: manifest lo_code {man['domain']['lo_code']} differs from the model's {list(fxm.lo_codes)}; regenerate")
    design_v = files["verilog"] if isinstance(files["verilog"], str) else files["verilog"][0]  # [0]: the design
    vpath = Path(verilog) if verilog is not None else out / design_v
    if not vpath.is_file():
        raise FileNotFoundError(f"{vpath} is missing; regenerate the folder with `pwas-hdl generate`")
    return Design(out, man, sensor, fxm, vpath, bank)


# ---------------------------------------------------------------------------------------------------- stimulus


@dataclass
class Segment:
    """Input transfers between two resets and the outputs they must give.

    Attributes
    ----------
    codes : ndarray of int, shape (T, fields)
        One row per input transfer (the core: regressor codes ``q``; the sensor top: one code per
        signal, payload order).
    q : ndarray of int, shape (m, n)
        The regressor codes of each expected output.
    expected : ndarray of int64, shape (m, nz)
        Output codes from the bit-true model.
    oor : ndarray of bool, shape (m,)
        Out-of-range flags from the bit-true model.
    src : ndarray of int, shape (m,)
        The transfer (row of ``codes``) that completes each output's regressor.
    drain : bool
        Wait for every output before the next reset; otherwise reset ``hold`` cycles after the
        last transfer (in the middle of the stream).
    hold : int
        Clock cycles from the last transfer to the reset when not ``drain``.
    cls : ndarray of int, shape (m,), or None
        A classifier design's class index (:func:`pwas_hdl.fixedpoint.argmax.argmax_index` of
        ``expected``), else None.
    """

    codes: np.ndarray
    q: np.ndarray
    expected: np.ndarray
    oor: np.ndarray
    src: np.ndarray
    drain: bool = True
    hold: int = 0
    cls: np.ndarray | None = None

    def rows(self) -> np.ndarray:
        """Expected output payload fields, in the manifest's order: scores, ``out_of_range``[, ``class_index``].

        Returns
        -------
        ndarray of int64, shape (m, nz + 1) or (m, nz + 2)
            Output codes, the flag (0 / 1) and, for a classifier, the class index.
        """
        cols = [self.expected, self.oor[:, None].astype(np.int64)]
        if self.cls is not None:
            cols.append(np.asarray(self.cls, dtype=np.int64)[:, None])
        return np.concatenate(cols, axis=1).astype(np.int64)

    def to_job(self) -> dict:
        """The segment as the testbench's JSON job reads it.

        Returns
        -------
        dict
            ``codes`` (T lists of ints), ``expected`` (:meth:`rows` as lists), ``src``, ``drain``,
            ``hold``.
        """
        exp = self.rows()
        return {"codes": self.codes.astype(np.int64).tolist(), "expected": exp.astype(np.int64).tolist(),
                "src": self.src.astype(np.int64).tolist(), "drain": bool(self.drain), "hold": int(self.hold)}


@dataclass
class Run:
    """Segments replayed with one stall pattern.

    Attributes
    ----------
    name : str
        The run's name in the results (``"full"``, ``"stall"``, ...).
    segments : list of Segment
        Replayed in order, a reset before each.
    p_valid, p_ready : float
        Probability in ``[0, 1]`` that the source offers / the sink accepts in a clock cycle (1.0:
        never stalls).
    seed : int
        Seed of the stall pattern.
    """

    name: str
    segments: list[Segment]
    p_valid: float = 1.0
    p_ready: float = 1.0
    seed: int = 0

    def to_job(self) -> dict:
        """The run as the testbench's JSON job reads it.

        Returns
        -------
        dict
            ``name``, ``p_valid``, ``p_ready``, ``seed`` and ``segments`` (:meth:`Segment.to_job`
            of each).
        """
        return {"name": self.name, "p_valid": self.p_valid, "p_ready": self.p_ready, "seed": self.seed,
                "segments": [s.to_job() for s in self.segments]}


def _signal_columns(design: Design, codes: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Split sensor-top transfer codes (payload order) into the u and y code matrices of LagStructure."""
    lags = design.sensor.lags_
    ins, outs, _ = design.sensor.signal_names()
    names = [f["signal"] for f in design.in_fields]
    col = {nm: i for i, nm in enumerate(names)}
    try:
        cu = codes[:, [col[nm] for nm in ins]] if lags.nu and lags.mu else None
        cy = codes[:, [col[nm] for nm in outs]] if lags.ny and lags.my else None
    except KeyError as exc:
        raise InputError(f"the sensor top has no input field for signal {exc}; regenerate the design") from None
    return cu, cy


def segment(design: Design, codes: ArrayLike, *, drain: bool = True, hold: int = 0) -> Segment:
    """The expected outputs of the input transfers ``codes`` right after a reset.

    Parameters
    ----------
    design : Design
        The generated design (:func:`load_design`).
    codes : array_like of int, shape (T, fields)
        One row per input transfer: the regressor codes ``q`` (core) or one code per signal in
        payload order (sensor top).
    drain : bool
        Wait for every output before the next reset.
    hold : int
        Without ``drain``: cycles after the last transfer before the reset.

    Returns
    -------
    Segment
        With the bit-true expected outputs; a sensor top has none for the first
        :attr:`Design.warmup` transfers.

    Raises
    ------
    InputError
        ``codes`` is not 2-D with one column per input field.
    """
    c = np.asarray(codes, dtype=np.int64)
    if c.ndim != 2 or c.shape[1] != len(design.in_fields):
        raise InputError(f"codes must have shape (T, {len(design.in_fields)}), got {c.shape}")
    if design.kind == "core":
        q = c
        src = np.arange(len(c))
    else:
        w = design.warmup
        if len(c) <= w:
            q = np.empty((0, design.model.n), dtype=np.int64)
        elif design.bank is not None:  # observer bank: q = the feature codes the bank gives the core
            tr = design.bank.bank.trace(c)
            q = tr["feature_codes"]
            if hasattr(design.bank, "taps"):  # u/y taps beside the features (pwas_hdl.fixedpoint.bank_taps)
                q = np.hstack([q, design.bank.taps.codes(c)])
            q = q[w:]
        else:
            cu, cy = _signal_columns(design, c)
            q = design.sensor.lags_.build(cu, cy).astype(np.int64)
        src = np.arange(w, w + len(q))
    if len(q):
        out, oor = design.model.evaluate(q)
    else:
        out, oor = np.empty((0, design.model.nz), dtype=np.int64), np.empty(0, dtype=bool)
    cls = None
    clf = design.manifest.get("classifier")  # optional: present exactly for a classifier design
    if clf is not None:
        from pwas_hdl.fixedpoint.argmax import argmax_index

        cls = argmax_index(out, clf["select"]) if len(out) else np.empty(0, dtype=np.int64)
    return Segment(c, q, out, oor, src, drain, hold, cls)


def standard_runs(design: Design, codes: ArrayLike, *, seed: int = 0, stalls: tuple[float, float] = (0.7, 0.6)) -> list[Run]:
    """The three replays of the RTL tests: full speed (latency, II = 1), random bubbles and
    backpressure, and a reset in the middle of a stream (with stalls) followed by a fresh stream.

    Parameters
    ----------
    design : Design
    codes : array_like of int, shape (T, fields)
        Input transfers (as :func:`segment`).
    seed : int
        Seed of the reset's hold time and of the runs' stall patterns.
    stalls : (float, float)
        ``p_valid`` and ``p_ready`` of the ``"stalls"`` run.

    Returns
    -------
    list of Run
        ``"full-speed"``, ``"stalls"`` and ``"reset-mid-stream"`` (cut at ``max(warmup + 2, T // 3)``,
        ``p_valid = p_ready = 0.8``).
    """
    c = np.asarray(codes, dtype=np.int64)
    rng = np.random.default_rng(seed)
    cut = max(design.warmup + 2, len(c) // 3)
    hold = int(rng.integers(0, max(1, design.latency)))
    return [
        Run("full-speed", [segment(design, c)]),
        Run("stalls", [segment(design, c)], stalls[0], stalls[1], seed + 1),
        Run("reset-mid-stream", [segment(design, c[:cut], drain=False, hold=hold), segment(design, c[cut:])], 0.8, 0.8, seed + 2),
    ]


# ---------------------------------------------------------------------------------------------------- probes

_PROBE_RE = re.compile(
    r"^\s*reg\s+(?:signed\s+)?(?:\[(\d+):(\d+)\]\s+)?"
    r"(s_(?:split|rank|voff|addr|bank|memout|mulin|mem|pp|prod|tree\d+)_[a-z]+\d*|vdata\d+|out__payload|m_axis_tdata)\s*;",
    re.M,
)
#: The output payload register under the two port namings (``generate --ports amaranth|axis``).
_OUT_REGS = ("out__payload", "m_axis_tdata")
_STAGE_ORDER = ("s_split", "s_rank", "s_voff", "s_addr", "s_bank", "s_mem", "s_memout", "s_mulin", "s_pp", "s_prod")


def stage_probes(verilog: str) -> dict[str, int]:
    """Pipeline registers of a generated design that the debug run records: name -> width.

    They keep the Amaranth names (``s_<stage>_<value><index>``, ``vdata<k>`` = weight words of
    vertex ``k`` after the memory, ``out__payload``); the ``_valid`` bits are left out.

    Parameters
    ----------
    verilog : str
        The design's Verilog text.

    Returns
    -------
    dict of str to int
        Register name -> width in bits, in source order.
    """
    res = {}
    for mo in _PROBE_RE.finditer(verilog):
        hi, lo, name = mo.group(1), mo.group(2), mo.group(3)
        if name.endswith("_valid"):
            continue
        res[name] = (int(hi) - int(lo) + 1) if hi is not None else 1
    return res


_MEM_RE = re.compile(r"^\s*reg\s+\[(\d+):(\d+)\]\s+(" + WEIGHT_MEMORY_PATTERN + r")\s*\[(\d+):(\d+)\]\s*;", re.M)


def weight_memories(verilog: str) -> dict[str, int]:
    """Weight memories of a generated design (arrays ``wmem<b>``, ``part<i>_wmem<b>`` of an additive
    design: :func:`~pwas_hdl.fixedpoint.memory_layout.weight_memory_name`): name -> depth."""
    return {mo.group(3): abs(int(mo.group(4)) - int(mo.group(5))) + 1 for mo in _MEM_RE.finditer(verilog)}


def _memory_diffs(design: Design, read: dict) -> list[dict]:
    """Words of the simulated weight memories that differ from the bit-true model's ROM image."""
    rom = design.model.rom  # (banks, depth, nz)
    bw = design.model.weight_format.bits
    diffs = []
    for name, words in read.items():
        b = int(name[4:])
        if not isinstance(words, list) or b >= rom.shape[0]:
            continue
        for a, got in enumerate(words[: rom.shape[1]]):
            exp = pack(rom[b, a], bw)
            if got is None or got != exp:
                diffs.append({"memory": name, "addr": a, "expected": exp, "actual": got,
                              "expected_codes": [int(v) for v in rom[b, a]]})
    return diffs


def _stage_of(name: str) -> str:
    if name.startswith("vdata"):
        return "vdata"
    if name in _OUT_REGS:
        return "out"
    mo = re.match(r"(s_(?:split|rank|voff|addr|bank|memout|mulin|mem|pp|prod|tree\d+))_", name)
    return mo.group(1) if mo else name


def _stage_offsets(names: Sequence[str], latency: int) -> dict[str, int] | None:
    """Cycle offset (after the input transfer) at which each stage register holds the sample."""
    stages = {_stage_of(n) for n in names} - {"vdata", "out"}
    order = [s for s in _STAGE_ORDER if s in stages]
    order += sorted((s for s in stages if s.startswith("s_tree")), key=lambda s: int(s[6:]))
    order.append("out")
    if len(order) != latency:
        return None
    off = {s: i + 1 for i, s in enumerate(order)}
    off["vdata"] = off.get("s_memout", off.get("s_mem", 0))
    return off


def _tree_levels(products: np.ndarray) -> list[list[list[int]]]:
    """The adder tree of the core: per level, per target, the partial sums (pwas_hdl.fixedpoint.reduction)."""
    per_target = [tree_levels([int(v) for v in products[:, z]], lambda a, b, _lvl, _i: a + b) for z in range(products.shape[1])]
    return [[t[lvl] for t in per_target] for lvl in range(len(per_target[0]))]


def _bank_order(tr: dict, values: np.ndarray) -> np.ndarray:
    """Rows of ``values`` (indexed by simplex vertex k) re-ordered by the memory that reads vertex k."""
    out = np.empty_like(values)
    out[np.asarray(tr["bank"], dtype=np.int64)] = values
    return out


def _expected_probe(name: str, tr: dict, model: FixedPointModel, out_fields: list[dict], bank_order: bool) -> int | None:
    """Value the bit-true trace (one sample) gives for a pipeline register; None if not modelled.

    ``bank_order``: after the memory read the generator keeps ``mu``, products and partial sums in
    memory (bank) order -- memory ``b`` multiplies its word by the ``mu`` of the vertex it read --
    rather than in simplex-vertex order (older generators, recognised by their ``vdata`` nets).
    """
    if name in _OUT_REGS:
        vals = [int(v) for v in tr["out"]] + [int(tr["out_of_range"])]
        if len(out_fields) > len(vals):  # a classifier: the class index in the top field
            from pwas_hdl.fixedpoint.argmax import argmax_index

            vals.append(int(argmax_index(np.asarray(tr["out"], dtype=np.int64)[None, :])[0]))
        return pack_fields(vals, out_fields)
    bw = model.weight_format.bits
    mo = re.match(r"vdata(\d+)$", name)
    if mo:
        return pack(tr["w"][int(mo.group(1))], bw)
    mo = re.match(r"s_(split|rank|voff|addr|bank|memout|mulin|mem|pp|prod|tree(\d+))_([a-z]+)(\d*)$", name)
    if not mo:
        return None
    stage, lvl, what, idx = mo.group(1), mo.group(2), mo.group(3), mo.group(4)
    i = int(idx) if idx else None
    n = model.n
    nb = n + 1
    if stage == "addr":  # the register before the memories holds vertex order (rotated after it)
        bank_order = False
    mu = _bank_order(tr, tr["mu"]) if bank_order else tr["mu"]
    products = _bank_order(tr, tr["products"]) if bank_order else tr["products"]
    if what == "c":
        return int(tr["cell"][i])
    if what == "d":
        return int(tr["frac"][i])
    if what == "oor":  # s_split keeps one flag per dimension (oor<j>), joined after it
        return int(tr["out_of_range"]) if i is None else None
    if what == "rot":  # s_rank keeps the first level of the rotation sum (rot<i>): not modelled
        return int(tr["rot"]) if i is None else None
    if what == "ge":  # the rank register: comparison bits d_a >= d_b of the pairs a < b in order
        pairs = [(a, b) for a in range(n) for b in range(a + 1, n)]
        a, b = pairs[i]
        return int(int(tr["frac"][a]) >= int(tr["frac"][b]))
    if what == "ds":  # the offset register: d_(k+1), the fraction of rank k
        return int(tr["frac"][int(np.flatnonzero(np.asarray(tr["rank"]) == i)[0])])
    if what == "mu":
        return int(mu[i])
    if what == "lt":
        r = int(tr["rank"][i])
        return sum(1 << (k - 1) for k in range(1, n) if r < k)
    if what == "data":
        return pack(tr["w_by_bank"][i], bw)
    if what == "addr":  # vertex i's address (register before the memories) or memory i's
        return int(tr["addr_by_bank"][i] if bank_order else tr["addr"][i])
    if what == "baddr":  # memory i's address (banked core without the address rotation, issue 14)
        return int(tr["addr_by_bank"][i])
    if what == "p":
        return int(products[i % nb, i // nb])
    if what == "t" and lvl is not None:
        levels = _tree_levels(products)
        flat = [v for row in levels[int(lvl)] for v in row]
        return flat[i] if i < len(flat) else None
    return None  # base, wrap: address intermediates the model does not name


@dataclass
class StageDiff:
    stage: str
    offset: int
    register: str
    expected: int
    actual: int | None


def locate_difference(design: Design, probe: dict, q_row: Sequence[int]) -> dict:
    """Compare the recorded pipeline registers of one sample with the bit-true trace.

    Returns ``{"first_stage": name or None, "diffs": [StageDiff...], "checked": k,
    "trace": {stage: value}, "offsets": ..., "memory_diffs": ...}`` (``first_stage`` None: every
    register the model names agreed, e.g. a corrupted constant that only shows in the output, or no
    offsets could be assigned).

    Parameters
    ----------
    design : Design
    probe : dict
        What the debug run recorded: ``values`` (register name -> value per cycle after the
        transfer) and optionally ``memories`` (the weight memories' words).
    q_row : sequence of int, length n
        The regressor codes of the sample.

    Returns
    -------
    dict
        ``first_stage``, ``diffs`` (sorted by cycle offset, then register), ``checked`` (registers
        compared), ``trace`` (the bit-true trace of the sample as JSON types), ``offsets`` (stage ->
        cycle offset, or None) and ``memory_diffs`` (list, or None when no memory was recorded).
    """
    model = design.model
    tr_all = model.trace(np.asarray(q_row, dtype=np.int64)[None, :])
    tr = {k: v[0] for k, v in tr_all.items()}
    widths = stage_probes(design.verilog)
    values = probe.get("values", {})
    offsets = _stage_offsets(list(values), design.latency)
    bank_order = re.search(r"\bvdata\d+\b", design.verilog) is None
    diffs, checked = [], 0
    if offsets is not None:
        for name, rec in values.items():
            st = _stage_of(name)
            off = offsets.get(st)
            if off is None or off >= len(rec):
                continue
            exp = _expected_probe(name, tr, model, design.out_fields, bank_order)
            if exp is None:
                continue
            w = widths.get(name, 64)
            got = rec[off]
            checked += 1
            if got is None or (exp - got) % (1 << w) != 0:
                diffs.append(StageDiff(st, off, name, exp % (1 << w), got))
    diffs.sort(key=lambda d: (d.offset, d.register))
    first = diffs[0].stage if diffs else None
    mem = _memory_diffs(design, probe["memories"]) if isinstance(probe.get("memories"), dict) else None
    trace = {k: (v.tolist() if isinstance(v, np.ndarray) else (v.item() if hasattr(v, "item") else v)) for k, v in tr.items()}
    return {"first_stage": first, "diffs": diffs, "checked": checked, "trace": trace, "offsets": offsets,
            "memory_diffs": mem}


# ---------------------------------------------------------------------------------------------------- results


@dataclass
class RTLResult:
    """Outcome of :func:`run_rtl` (one simulator, one design, several runs).

    Attributes
    ----------
    simulator : str
        ``"icarus"`` or ``"verilator"``.
    design : Design
        The simulated design.
    runs : list of Run
        The replays.
    raw : dict
        The testbench's JSON result as written.
    failures : list of str
        Testbench failures (missing outputs, protocol errors, ...), one line each.
    mismatches : int
        Outputs whose codes differ from the bit-true model.
    outputs : int
        Outputs received, all runs.
    latencies : list of int
        Input-to-output latency of each output of the runs without backpressure, clock cycles.
    ii : float or None
        Measured initiation interval, clock cycles per sample (the largest of the stall-free
        draining segments); None when no segment measures it.
    float_error_max : float
        ``max |RTL output - float model|`` at the input codes, physical target units (saturated
        outputs left out).
    float_error_max_lsb : float
        The same in output LSBs.
    error_bound, error_bound_lsb : float
        The bit-true model's error bound, physical units and output LSBs.
    cycles : int
        Clock cycles simulated, all runs.
    sim_seconds : float
        Seconds inside the simulator (testbench runs).
    wall_seconds : float
        Seconds of the simulator process(es), start-up included.
    build_seconds : float
        Seconds of the simulator build (0 when reused).
    build_reused : bool
        The cached build was reused.
    located : dict or None
        With ``debug``: :func:`locate_difference`'s record of the first differing sample.
    hw : list
        Per run, per segment: ``(codes, oor)``, the RTL's output codes ``(m, nz)`` and
        out-of-range flags ``(m,)``.
    hw_class : list
        Classifier designs: per run, per segment, the RTL's class index ``(m,)``; else empty lists.
    latencies_all : list of int
        Latencies of all runs, backpressure included (waiting counts), clock cycles.
    saturated : int
        Outputs at the saturation limits (left out of the float comparison).
    """

    simulator: str
    design: Design
    runs: list[Run]
    raw: dict
    failures: list[str]
    mismatches: int
    outputs: int
    latencies: list[int]
    ii: float | None
    float_error_max: float
    float_error_max_lsb: float
    error_bound: float
    error_bound_lsb: float
    cycles: int
    sim_seconds: float
    wall_seconds: float
    build_seconds: float
    build_reused: bool
    located: dict | None = None
    hw: list = field(default_factory=list, repr=False)
    hw_class: list = field(default_factory=list, repr=False)
    latencies_all: list = field(default_factory=list, repr=False)
    saturated: int = 0

    @property
    def passed(self) -> bool:
        """No testbench failure, no mismatch, and the testbench reported success."""
        return not self.failures and self.mismatches == 0 and bool(self.raw.get("passed"))

    @property
    def within_bound(self) -> bool:
        """:attr:`float_error_max` is within :attr:`error_bound` (relative slack 1e-9)."""
        return self.float_error_max <= self.error_bound * (1 + 1e-9) + 1e-12

    def first_mismatch(self) -> dict | None:
        """The testbench's record of the first output that differed (run order, then segment order).

        Returns
        -------
        dict or None
            ``run``, ``segment``, ``output``, ``input``, ``input_codes``, ``expected``, ``actual``
            (as the testbench wrote them); None when every output matched.
        """
        for r in self.raw.get("runs", []):
            for s in r.get("segments", []):
                if s.get("first_mismatches"):
                    return s["first_mismatches"][0]
        return None

    def report(self) -> str:
        """Human-readable account: failures, the first mismatch, its bit-true trace and the first
        pipeline stage that differs (when the debug run recorded the registers).

        Returns
        -------
        str
            Several lines (no trailing newline).
        """
        lines = [f"{self.simulator} {self.design.top} ({self.design.kind}, {self.design.outdir.name}): "
                 f"{self.outputs} outputs, {self.mismatches} mismatches, latency {sorted(set(self.latencies))} "
                 f"(manifest {self.design.latency}), II {self.ii}"]
        lines += [f"  FAIL {f}" for f in self.failures]
        m = self.first_mismatch()
        if m is not None:
            fields = [f["name"] for f in self.design.out_fields]
            lines.append(f"  first mismatch: run {m['run']!r} segment {m['segment']} output {m['output']} "
                         f"(input transfer {m['input']}, codes {m['input_codes']}): expected {dict(zip(fields, m['expected']))}, "
                         f"RTL {dict(zip(fields, m['actual']))}")
        if self.located is not None:
            loc = self.located
            if loc["first_stage"]:
                lines.append(f"  first differing pipeline stage: {loc['first_stage']} (cycle +{loc['diffs'][0].offset} after the transfer)")
                for d in loc["diffs"][:8]:
                    lines.append(f"    {d.register}: expected {d.expected}, RTL {d.actual} (stage {d.stage})")
            elif self.mismatches:
                lines.append(f"  debug run: all {loc['checked']} modelled pipeline registers agree with the bit-true trace "
                             "(the difference is in logic the model does not name, e.g. an address)")
            else:
                lines.append(f"  debug self-check: all {loc['checked']} modelled pipeline registers agree with the bit-true trace")
            md = loc.get("memory_diffs")
            if md:
                lines.append(f"  weight memory differs from the model's ROM image in {len(md)} word(s):")
                for d in md[:4]:
                    lines.append(f"    {d['memory']}[{d['addr']}]: expected {d['expected']:#x} (codes {d['expected_codes']}), RTL {d['actual']!r}")
            elif md is not None:
                lines.append("  weight memories: every word equals the model's ROM image")
            tr = loc["trace"]
            keys = ("q", "t_clamped", "out_of_range", "cell", "frac", "rank", "vertices", "bank", "addr", "mu", "w", "acc", "acc_rounded", "out")
            lines.append("  bit-true trace of the sample: " + "; ".join(f"{k}={tr[k]}" for k in keys if k in tr))
        if not self.within_bound:
            lines.append(f"  float error {self.float_error_max:.6g} > bound {self.error_bound:.6g}")
        return "\n".join(lines)


def _summarise(design: Design, runs: list[Run], raw: dict, simulator: str, build: dict, wall: float) -> RTLResult:
    model = design.model
    fo = model.output_format
    lsb = 2.0 ** -fo.frac
    failures = list(raw.get("failures", []))
    mismatches = outputs = cycles = 0
    lat: list[int] = []
    lat_all: list[int] = []
    n_sat = 0
    ii = None
    err = 0.0
    hw = []
    hw_class = []
    sim_s = 0.0
    n_fields = len(design.out_fields)  # scores, out_of_range[, class_index]
    for run, rr in zip(runs, raw.get("runs", [])):
        cycles += int(rr.get("cycles", 0))
        sim_s += float(rr.get("wall_s", 0.0))
        hw_run = []
        cls_run = []
        for seg, sr in zip(run.segments, rr.get("segments", [])):
            got = np.array(sr.get("got", []), dtype=np.int64).reshape(-1, n_fields)
            hw_run.append((got[:, :model.nz], got[:, model.nz].astype(bool)))
            if n_fields > model.nz + 1:
                cls_run.append(got[:, model.nz + 1])
            mismatches += int(sr.get("mismatches", 0))
            outputs += len(got)
            lat_all += [int(v) for v in sr.get("latencies", [])]
            if run.p_ready >= 1.0:
                lat += [int(v) for v in sr.get("latencies", [])]
            acc = sr.get("accepted_at", [])
            if int(design.manifest["ii"]) > 1:  # serial: the warm-up transfers are not throttled
                acc = acc[design.warmup:]
            if run.p_ready >= 1.0 and run.p_valid >= 1.0 and len(acc) > 1 and seg.drain:
                seg_ii = (acc[-1] - acc[0]) / (len(acc) - 1)
                ii = seg_ii if ii is None else max(ii, seg_ii)
            k = min(len(got), len(seg.q))
            if k:
                # the bound holds unless the output saturates (only possible with a narrow output_bits)
                sat = np.any((seg.expected[:k] <= fo.min_code) | (seg.expected[:k] >= fo.max_code), axis=1) \
                    if model.output_may_saturate else np.zeros(k, dtype=bool)
                n_sat += int(sat.sum())
                if (~sat).any():
                    ref = model.reference(seg.q[:k][~sat])
                    err = max(err, float(np.max(np.abs(got[:k, :model.nz][~sat] * lsb - ref))))
        hw.append(hw_run)
        hw_class.append(cls_run)
    return RTLResult(
        simulator, design, runs, raw, failures, mismatches, outputs, lat, ii, err, err / lsb,
        float(model.error_bound), float(model.error_bound_lsb), cycles, sim_s, wall,
        float(build.get("build_seconds", 0.0)), bool(build.get("reused", False)), None, hw, hw_class, lat_all, n_sat,
    )


def run_rtl(
    design: Design,
    runs: Sequence[Run],
    simulator: str = "icarus",
    *,
    cache_dir: str | os.PathLike | None = None,
    work_dir: str | os.PathLike | None = None,
    waves: bool = False,
    debug: bool = False,
    strict: bool = True,
    clock_ns: float = 10.0,
    probe_output: int | None = None,
    verilator_args: Sequence[str] = (),
    engine: str = "cocotb",
) -> RTLResult:
    """Build (or reuse) ``design`` for ``simulator`` and replay ``runs`` through the testbench.

    ``engine``: ``"cocotb"`` (default; the manifest-driven cocotb bench ``sim/pwas_tb.py`` on
    Icarus or Verilator, with the debug trace) or ``"native"`` (the generated Verilator C++ bench
    ``sim/pwas_native_tb.cpp``: the same runs, stalls and resets, checks and result layout, about
    100 times faster; Verilator only, no ``debug`` / ``waves``).

    ``debug``: when an output differs, re-run that sample alone and record the pipeline registers
    (:func:`stage_probes`), then name the first stage that differs from the bit-true trace
    (:attr:`RTLResult.located`). ``waves``: record FST (Icarus) / VCD (Verilator) in ``work_dir``
    (a separate cached build). ``probe_output``: with ``debug``, also record the registers of this
    output of the first run when everything matches (a self-check of the probe mapping: then
    :attr:`RTLResult.located` must find no difference). ``strict``: the cocotb test itself fails on a mismatch (the result
    is returned either way). ``work_dir`` (default: a temporary folder, removed afterwards unless
    ``waves``) holds the job, the result, the log and the waveform.

    Parameters
    ----------
    design : Design
        The generated design (:func:`load_design`).
    runs : sequence of Run
        The replays (e.g. :func:`standard_runs`).
    simulator : {"icarus", "verilator"}
    cache_dir : str or os.PathLike, optional
        Where simulator builds are cached (default: the runner's cache).
    work_dir : str or os.PathLike, optional
        As above.
    waves, debug, strict : bool
        As above (``strict`` and ``probe_output`` apply to the cocotb engine).
    clock_ns : float
        Clock period of the cocotb bench, ns.
    probe_output : int, optional
        As above.
    verilator_args : sequence of str
        Extra Verilator arguments of the cocotb build.
    engine : {"cocotb", "native"}

    Returns
    -------
    RTLResult
        Mismatches, failures, latencies, II and the error against the float model; a
        difference does not raise.

    Raises
    ------
    InputError
        An unknown ``simulator`` or ``engine``, or ``native`` with Icarus, ``debug`` or ``waves``.
    ToolMissing, ToolFailed
        The simulator is not installed, or its build or run failed.
    """
    if simulator not in SIMULATORS:
        raise InputError(f"simulator must be one of {', '.join(SIMULATORS)}, got {simulator!r}")
    if engine not in ENGINES:
        raise InputError(f"--engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    runner = sim_module("pwas_runner")
    if engine == "native":
        ignored = [nm for nm, given in (("probe_output", probe_output is not None), ("verilator_args", bool(verilator_args)),
                                        ("clock_ns", clock_ns != 10.0)) if given]
        if ignored:  # the C++ bench has no probes, builds with its own options and counts cycles, not ns
            raise InputError(f"{', '.join(ignored)} apply to the cocotb engine only (engine='cocotb'); leave "
                             f"{'it' if len(ignored) == 1 else 'them'} out with engine='native'")
        return _run_native(design, runs, simulator, cache_dir=cache_dir, work_dir=work_dir, waves=waves, debug=debug)
    b = runner.build(design.verilog_path, design.top, simulator, cache_dir=cache_dir, waves=waves, verilator_args=verilator_args)
    tmp = None
    if work_dir is None:
        tmp = make_temp_dir(tempfile.gettempdir(), f"pwas-sim-{simulator}")  # pid-named: removed by a later run if killed
        wd = tmp
    else:
        wd = Path(work_dir)
    job = {
        "manifest": str((design.outdir / "manifest.json").resolve()),
        "strict": bool(strict),
        "debug": bool(debug),
        "probes": sorted(stage_probes(design.verilog)) if debug else [],
        "memories": weight_memories(design.verilog) if debug else {},
        "probe_output": probe_output if debug else None,
        "clock_ns": clock_ns,
        "reset_cycles": 2,
        "runs": [r.to_job() for r in runs],
    }
    try:
        with logs_kept(None if waves else tmp, f"pwas-sim-{simulator}"):
            raw = runner.run_job(b, job, wd, files=design.runtime_files)
    finally:
        if tmp is not None and not waves:
            shutil.rmtree(tmp, ignore_errors=True)
    res = _summarise(design, list(runs), raw, simulator, raw.get("build", {}), float(raw.get("wall_s", 0.0)))
    if debug:
        for ri, rr in enumerate(raw.get("runs", [])):
            pr = rr.get("probe")
            if pr:
                seg = runs[ri].segments[pr["segment"]]
                row = int(np.flatnonzero(seg.src == pr["input"])[0])
                res.located = locate_difference(design, pr, seg.q[row])
                break
    return res


def _run_native(design: Design, runs: Sequence[Run], simulator: str, *, cache_dir, work_dir, waves: bool, debug: bool) -> RTLResult:
    if simulator != "verilator":
        raise InputError(f"--engine native runs on Verilator only (got --simulator {simulator}); use --simulator verilator "
                         "or --engine cocotb")
    if debug or waves:
        raise InputError("the debug trace and waveforms need the cocotb engine (--engine cocotb)")
    native = sim_module("pwas_native")
    b = native.build(design.verilog_path, design.manifest, cache_dir=cache_dir)
    tmp = Path(tempfile.mkdtemp(prefix="pwas-native-")) if work_dir is None else None
    try:
        with logs_kept(tmp, "pwas-native"):
            raw = native.run(b, design.manifest, list(runs), tmp or work_dir, files=design.runtime_files)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return _summarise(design, list(runs), raw, "verilator", raw["build"], float(raw["wall_s"]))


# ---------------------------------------------------------------------------------------------------- CSV replay


def _check_references(table: "Table", targets: Sequence[str]) -> None:
    """The reference columns of the RMSEE (``<t>_true`` or ``<t>``) hold no value above
    :data:`~pwas_hdl.limits.MAX_VALUE`: refused before the simulator runs, not as an overflow after it."""
    for t in targets:
        ref = table.reference_column(t)
        if ref is not None:
            check_values(f"{table.path}: column {ref!r}", table.numeric([ref])[:, 0],
                         "fix the data (no RMSEE can be measured against it)")


def _rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2))) if len(a) else float("nan")


def simulate_data(
    outdir: str | os.PathLike,
    data: "str | os.PathLike | Table",
    output: str | os.PathLike,
    *,
    simulator: str | None = None,
    engine: str = "cocotb",
    summary_path: str | os.PathLike | None = None,
    traj_col: str | None = None,
    stall: float = 0.0,
    seed: int = 0,
    cache_dir: str | os.PathLike | None = None,
    waves: bool = False,
    progress: Callable[[str], None] | None = None,
    blank_rows: str = "error",
) -> dict:
    """Replay the rows of a CSV file through the generated RTL (``pwas-hdl simulate``).

    The sensor top gets one (u, y) sample per transfer (reset between trajectories); the core gets
    the regressors built in software. Inputs are quantised as the bit-true model does (half up,
    saturated). Writes ``output`` (CSV: ``row``, ``<t>_hw``, ``<t>_bittrue``, ``<t>_float``,
    ``out_of_range``, ``mismatch``; one row per hardware output, in data order; a classifier design
    adds ``<c>_hat_hw``, ``<c>_hat_bittrue``, ``<c>_hat_float``, the class labels of the RTL's
    ``class_index``, of the bit-true argmax and of the float argmax, and its ``mismatch`` includes
    the class) and the JSON summary (``summary_path``, default ``output`` with the suffix ``.json``;
    a classifier adds ``classifier``: class mismatches, agreement with the float classifier,
    accuracy / F1 when the data has the true class in column ``<c>_true`` or ``<c>``, as ``predict``
    finds it; a value there that is none of the classes is refused before the simulator runs; its
    ``targets``, the scores, have no RMSEE: a score has no reference column).

    ``engine``: ``"cocotb"`` (default) or ``"native"`` (the Verilator C++ bench, see
    :func:`run_rtl`; ``simulator`` then defaults to and must be ``"verilator"``). Both write the
    same summary and CSV.

    ``data`` is a CSV path or a :class:`~pwas_hdl.io.csv_table.Table` (see :func:`simulate_arrays`); a Table
    read from a file (its ``path`` a file) keeps that file among the inputs no output may replace.

    Returns ``{"summary": dict, "summary_path": str, "output": str, "result": RTLResult,
    "rows": ndarray (m,), "estimates": ndarray (m, nz)}``: the data row of each hardware output and
    the hardware estimates in physical units; a classifier design adds ``"class_index"`` (m,). Differences do not raise: mismatches against the
    bit-true model, testbench failures, a measured latency or II other than the manifest's and
    errors beyond the bound are listed in ``summary["checks"]`` (``passed`` false: the CLI exits
    with status 1). Both files are written or neither; every path is checked before the
    simulation starts.

    Parameters
    ----------
    outdir : str or os.PathLike
        The design folder (``pwas-hdl generate``).
    data : str, os.PathLike or Table
        The CSV data (signals in physical units).
    output : str or os.PathLike
        The CSV file to write.
    simulator : {"icarus", "verilator"}, optional
        Default ``"icarus"`` (``"verilator"`` with the native engine).
    engine : {"cocotb", "native"}
    summary_path : str or os.PathLike, optional
        The JSON summary (default: ``output`` with the suffix ``.json``).
    traj_col : str, optional
        Column that numbers the trajectories (a reset between them); None: one trajectory.
    stall : float
        Probability of a bubble on the input and of backpressure on the output per cycle,
        ``0 <= stall <=`` :data:`MAX_STALL`.
    seed : int
        Seed of the stall pattern.
    cache_dir : str or os.PathLike, optional
        Where simulator builds are cached.
    waves : bool
        Record a waveform.
    progress : callable, optional
        Called with one line of text per step.
    blank_rows : str
        What :func:`~pwas_hdl.io.csv_table.read_csv` does with blank rows (default ``"error"``); unused when
        ``data`` is a Table (read already, its blank rows handled then).

    Returns
    -------
    dict
        As described above.

    Raises
    ------
    InputError
        Bad data, options or paths, an unknown ``simulator`` or a ``stall`` out of range (before
        anything runs).
    CheckFailed
        The RTL did not produce every output (nothing is written).
    """
    from pwas_hdl.io.atomic import OutputSet, check_output_path
    from pwas_hdl.io.csv_table import Table, check_trajectory_column, format_csv, read_csv, split_trajectories

    say = progress or (lambda msg: None)
    simulator = resolve_simulator(simulator, engine)
    if not 0.0 <= stall <= MAX_STALL:
        raise InputError(f"--stall must be in [0, {MAX_STALL}] (the probability of a bubble / of backpressure per cycle; "
                         f"the benches' cycle limit covers stalls up to {MAX_STALL}), got {stall}")
    check_seed(seed)  # numpy's generators take no negative seed
    check_output_path(output, "-o")  # before its .json sibling is made from it
    spath = Path(summary_path) if summary_path is not None else Path(output).with_suffix(".json")
    # no output may replace DATA, also when it comes as a Table read from a file (the CLI reads it once, for its
    # warnings and this replay: read_csv records the file lines of its rows); a Table built in memory
    # (simulate_arrays: path "arrays", no lines) names no file, even when one of that name exists here
    src = (data.path if data.lines and Path(data.path).is_file() else None) if isinstance(data, Table) else data
    sources = [(src, "DATA")] if src is not None else []
    if _is_estimator_folder(outdir):  # seed 003's estimator (issue 12): pwas_hdl.verify.estimator_simulation
        return _simulate_estimator(outdir, data, output, spath, sources, simulator=simulator, engine=engine, traj_col=traj_col,
                                   stall=stall, seed=seed, cache_dir=cache_dir, waves=waves, say=say, blank_rows=blank_rows)
    from pwas_hdl.design.manifest import folder_inputs

    # every file of the design (manifest, Verilog, model, hex files): no output replaces one
    outset = OutputSet(inputs=sources + folder_inputs(outdir))
    outset.add(output, "-o")
    outset.add(spath, "--json" if summary_path is not None else "the summary (-o with .json)")
    waves_dir = waves_folder(output)
    if waves:  # the waveform folder is an output too: replaced with the CSV and the summary, or not at all
        outset.add(waves_dir, "the --waves folder", kind="folder")
    if cache_dir is not None:
        check_output_path(cache_dir, "--build-dir", kind="folder")
    elif os.environ.get("PWAS_HDL_SIM_CACHE"):  # the default cache from the environment: checked like the option
        check_output_path(os.environ["PWAS_HDL_SIM_CACHE"], "$PWAS_HDL_SIM_CACHE (the simulator build cache; set it to "
                          "a folder or unset it)", kind="folder")
    design = load_design(outdir)
    if design.kind == "recurrent":  # issue 13: the recurrent bench (pwas_hdl.verify.recurrent_simulation)
        from pwas_hdl.verify.recurrent_simulation import simulate_recurrent

        table = data if isinstance(data, Table) else read_csv(data, blank_rows=blank_rows)
        _check_references(table, design.sensor.signal_names()[2])
        with outset:  # a failure removes the staged waveform folder
            return simulate_recurrent(design, table, output, spath, outset, simulator=simulator, engine=engine,
                                      traj_col=traj_col, stall=stall, seed=seed, cache_dir=cache_dir, waves=waves, say=say)
    sensor, model = design.sensor, design.model
    ins, outs, tgts = sensor.signal_names()
    lags = sensor.lags_
    if design.kind == "core" and lags is not None and lags.recurrent:
        # the core's last nz*Mz inputs are the fed-back estimates, which no column of DATA holds
        fed = lags.names(ins, outs, tgts)[lags.io_dimension:]
        raise InputError(f"{outdir}: the core of a recurrent model takes its own past estimates as regressors "
                         f"({', '.join(fed)}), which simulate cannot form from DATA; "
                         "generate --design sensor (the recurrent top, which feeds them back) to replay DATA, or "
                         "check this core with `pwas-hdl export-testbench`")
    table = data if isinstance(data, Table) else read_csv(data, blank_rows=blank_rows)
    if getattr(sensor, "classifier_", None) is None:  # a classifier's scores have no reference column (none read below);
        _check_references(table, tgts)  # its label column is checked by classifier.true_labels
    data = table.path
    clf = getattr(sensor, "classifier_", None)
    check_trajectory_column(table, traj_col, [*ins, *outs], [clf["target"]] if clf is not None else tgts)
    slices = split_trajectories(table, traj_col)
    segs, rows, xs = [], [], []
    if design.bank is not None:  # observer-bank sensor: every u and the y feed the bank
        u_all, y_all = (table.numeric(ins) if ins else None), table.numeric(outs)
        m_hist = design.warmup + 1
        zfs = []
    else:
        u_all = table.numeric(ins) if lags.nu and lags.mu else None
        y_all = table.numeric(outs) if lags.ny and lags.my else None
        m_hist = lags.memory
    for sl in slices:
        if design.bank is not None:
            if sl.stop - sl.start < m_hist:
                raise table.short_trajectory(sl, m_hist, "the observer bank needs", traj_col)
            u = u_all[sl] if u_all is not None else None
            codes, _ = design.bank.quantize_signals(u, y_all[sl])
            segs.append(segment(design, codes))
            rows.append(np.arange(sl.start + m_hist - 1, sl.stop))
            zfs.append(sensor.predict(u if u is not None else None, y_all[sl]))
            continue
        t_len = sl.stop - sl.start
        if t_len < m_hist:
            raise table.short_trajectory(sl, m_hist, "the lags need", traj_col)
        u = u_all[sl] if u_all is not None else None
        y = y_all[sl] if y_all is not None else None
        xi = lags.build(u, y)  # physical regressors (float model input)
        if design.kind == "core":
            codes = model.quantize_inputs(xi)
        else:
            fmts = model.signal_input_formats()
            cols = []
            for f in design.in_fields:
                nm = f["signal"]
                src = u if nm in ins and u is not None and lags.mu else y
                names = ins if src is u else outs
                cols.append(fmts[nm].quantize(src[:, names.index(nm)]))
            codes = np.stack(cols, axis=1).astype(np.int64)
        segs.append(segment(design, codes))
        rows.append(np.arange(sl.start + m_hist - 1, sl.stop))
        xs.append(xi)
    truth = None  # a classifier's true class (column, labels of the output rows): LABEL_true or LABEL, as predict reads it
    if clf is not None:
        from pwas_hdl.fit.classifier import true_labels

        truth = true_labels(table, clf["target"], clf["classes"], np.concatenate(rows) if rows else np.empty(0, dtype=np.int64))
    p = 1.0 - stall
    run = Run("replay", segs, p, p, seed)
    if engine == "native" and (simulator != "verilator" or waves):
        raise InputError("--engine native runs on Verilator without waveforms: use --simulator verilator and no --waves "
                         "(or --engine cocotb)")
    say(f"simulating {sum(len(s.src) for s in segs)} samples of {data} through {design.top} on {simulator} ({engine}) ...")
    t0 = time.perf_counter()
    # the simulator writes its folder in a private temporary one, staged into the output set at the end and
    # removed however the command ends; on an error the staged outputs go too (a failed run's log is copied out)
    work = Path(tempfile.mkdtemp(prefix="pwas-hdl-waves-")) if waves else None
    try:
        with outset:
            with logs_kept(work, f"pwas-sim-{simulator}"):
                res = run_rtl(design, [run], simulator, cache_dir=cache_dir, waves=waves, strict=False, engine=engine,
                              work_dir=work)
            if work is not None and res.raw.get("waves"):  # where the waveform will be once committed
                res.raw["waves"] = waves_path(res.raw["waves"], work, output)
            wall = time.perf_counter() - t0
            lsb = 2.0 ** -model.output_format.frac
            hw_codes = [h[0] for h in res.hw[0]]
            hw_oor = [h[1] for h in res.hw[0]]
            complete = all(len(hc) == len(s.expected) for hc, s in zip(hw_codes, segs))
            if not complete:
                raise CheckFailed("the RTL did not produce every output: " + "; ".join(res.failures[:3]))
            hw = np.concatenate(hw_codes) if hw_codes else np.empty((0, model.nz), dtype=np.int64)
            oor = np.concatenate(hw_oor)
            bt = np.concatenate([s.expected for s in segs])
            bt_oor = np.concatenate([s.oor for s in segs])
            q = np.concatenate([s.q for s in segs])
            row = np.concatenate(rows)
            mism = np.any(hw != bt, axis=1) | (oor != bt_oor)
            clf = design.manifest.get("classifier")  # a classifier design: the class index is checked too
            if clf is not None:
                hw_cls = np.concatenate(res.hw_class[0]) if res.hw_class and res.hw_class[0] else np.empty(0, dtype=np.int64)
                bt_cls = np.concatenate([s.cls for s in segs])
                mism = mism | (hw_cls != bt_cls)
            # float model at the real inputs
            zf = np.concatenate(zfs) if design.bank is not None else sensor.predict_regressors(np.concatenate(xs))
            zref = model.reference(q)  # float model at the inputs the codes represent
            zhw = hw * lsb
            cols: dict[str, Any] = {"row": row}
            if clf is not None:  # the class scores under the names predict gives them (<c>_score_<k>)
                from pwas_hdl.fit.classifier import score_column

                tgts = [score_column(clf["target"], c) for c in clf["classes"]]
            for i, t in enumerate(tgts):
                cols[f"{t}_hw"] = zhw[:, i]
                cols[f"{t}_bittrue"] = bt[:, i] * lsb
                cols[f"{t}_float"] = zf[:, i]
            clf_summary = None
            if clf is not None:
                clf_summary, clf_cols = _class_columns(clf, hw_cls, bt_cls, bt, zf, zref, model.error_bound, truth)
                cols.update(clf_cols)
            cols["out_of_range"] = oor
            cols["mismatch"] = mism
            csv_text = format_csv(cols)
            e_ref = np.abs(zhw - zref)
            e_float = np.abs(zhw - zf)
            targets = {}
            for i, t in enumerate(tgts):
                entry: dict[str, Any] = {
                    "max_error_vs_float_at_codes": float(e_ref[:, i].max()) if len(e_ref) else 0.0,
                    "max_error_vs_float_at_codes_lsb": float(e_ref[:, i].max() / lsb) if len(e_ref) else 0.0,
                    "max_error_vs_float_model": float(e_float[:, i].max()) if len(e_float) else 0.0,
                    "max_error_vs_float_model_lsb": float(e_float[:, i].max() / lsb) if len(e_float) else 0.0,
                }
                # a classifier's scores have no reference (a column of predict's scores is no truth): its
                # decision is scored against the label column (classifier.true_labels, _class_columns)
                ref = table.reference_column(t) if clf is None else None
                if ref is not None:
                    ztrue = table.numeric([ref])[row, 0]
                    entry.update(reference_column=ref, rmsee_hw=_rmse(zhw[:, i], ztrue), rmsee_bittrue=_rmse(bt[:, i] * lsb, ztrue),
                                 rmsee_float=_rmse(zf[:, i], ztrue), rmsee_float_at_codes=_rmse(zref[:, i], ztrue))
                    entry["rmsee_increase_hw_vs_float_percent"] = 100.0 * (entry["rmsee_hw"] / entry["rmsee_float"] - 1.0)
                targets[t] = entry
            first = None
            if mism.any():
                k = int(np.flatnonzero(mism)[0])
                first = {"row": int(row[k]), "regressor_codes": q[k].tolist(), "expected": bt[k].tolist() + [int(bt_oor[k])],
                         "actual": hw[k].tolist() + [int(oor[k])]}
                if clf is not None:
                    first["expected"].append(int(bt_cls[k]))
                    first["actual"].append(int(hw_cls[k]))
            lat = sorted(set(res.latencies if stall == 0 else res.latencies_all))
            n = int(len(row))
            summary = {
                "design": design.top,
                "design_hash": design.manifest.get("design_hash"),  # the design this result is for (report: stale?)
                "kind": design.kind,
                "outdir": str(design.outdir),
                "data": str(data),
                "simulator": simulator,
                "engine": engine,
                "simulator_version": sim_module("pwas_runner").tool_versions(simulator),
                "samples": n,
                "input_transfers": int(sum(len(s.codes) for s in segs)),
                "trajectories": len(segs),
                "mismatches": int(mism.sum()),
                "first_mismatch": first,
                "out_of_range": int(oor.sum()),
                "output_lsb": lsb,
                "error_bound": res.error_bound,
                "error_bound_lsb": res.error_bound_lsb,
                "within_error_bound": bool(float(e_ref.max(initial=0.0)) <= res.error_bound * (1 + 1e-9) + 1e-12),
                "max_error_vs_float_lsb": float(e_ref.max(initial=0.0) / lsb),
                "max_error_vs_float": float(e_ref.max(initial=0.0)),
                "targets": targets,
                "latency_cycles": {"manifest": design.latency, "measured_min": lat[0] if lat else None,
                                   "measured_max": lat[-1] if lat else None,
                                   "note": "from the input transfer that completes a regressor to out.valid"
                                   + ("" if stall == 0 else "; with stalls, cycles waiting on out.ready are included")},
                "ii": {"manifest": int(design.manifest["ii"]), "measured": res.ii,
                       "note": "cycles per accepted input at full speed" if stall == 0 else "not measured with stalls (--stall > 0)"},
                "stall": stall,
                "cycles": res.cycles,
                "clock_ns": 10.0,
                "simulation_seconds": res.sim_seconds,
                "samples_per_second": n / res.sim_seconds if res.sim_seconds > 0 else None,
                "cycles_per_second": res.cycles / res.sim_seconds if res.sim_seconds > 0 else None,
                "simulator_process_seconds": res.wall_seconds,
                "build_seconds": res.build_seconds,
                "build_reused": res.build_reused,
                "total_seconds": wall,
                "testbench_failures": res.failures,
                "waves": res.raw.get("waves"),
            }
            if clf_summary is not None:
                summary["classifier"] = clf_summary
            summary["checks"] = _checks(summary, stall)
            outset.write_text(output, csv_text)
            outset.write_text(spath, json.dumps(summary, indent=2, allow_nan=False, default=_json_default) + "\n")
            if work is not None:
                staged = outset.temp_dir(waves_dir)
                for item in work.iterdir():
                    shutil.move(str(item), str(staged / item.name))
            outset.commit()
            ret = {"summary": summary, "summary_path": str(spath), "output": str(output), "result": res, "rows": row, "estimates": zhw}
            if clf is not None:
                ret["class_index"] = hw_cls  # the RTL's class index of each output (classifier designs)
            return ret
    finally:
        if work is not None:
            shutil.rmtree(work, ignore_errors=True)


def _class_columns(clf: dict, hw_cls: np.ndarray, bt_cls: np.ndarray, bt_codes: np.ndarray, zf: np.ndarray,
                   zref: np.ndarray, bound: float, truth: tuple[str, np.ndarray] | None) -> tuple[dict, dict]:
    """CSV columns and summary of a classifier design's class output.

    Columns ``<target>_hat_hw`` (the label of the RTL's class index), ``<target>_hat_bittrue``
    (argmax of the bit-true codes) and ``<target>_hat_float`` (argmax of the float scores at the
    real inputs, :func:`pwas_hdl.fit.classifier.decide`). The summary has the class mismatches
    (RTL vs bit-true), the agreement with the float classifier at the represented inputs (where the
    bound applies) and at the real inputs (:func:`pwas_hdl.fixedpoint.argmax.agreement`) and, when
    the data has the true class (``truth``: its column and the labels of the output rows, from
    :func:`pwas_hdl.fit.classifier.true_labels`), accuracy and per-class F1 of the three.
    """
    from pwas_hdl.fit import classifier as fc
    from pwas_hdl.fixedpoint.argmax import agreement

    classes = np.asarray(clf["classes"], dtype=float)
    t = clf["target"]
    hw_lab = classes[hw_cls] if len(hw_cls) else np.empty(0)
    bt_lab = classes[bt_cls] if len(bt_cls) else np.empty(0)
    fl_lab = fc.decide(zf, classes) if len(zf) else np.empty(0)
    cols = {f"{t}_hat_{k}": fc.label_column(lab, classes) for k, lab in (("hw", hw_lab), ("bittrue", bt_lab), ("float", fl_lab))}
    summary: dict[str, Any] = {
        "target": t, "classes": classes.tolist(), "class_mismatches": int(np.sum(hw_cls != bt_cls)),
        "tie_rule": clf["tie_rule"],
        # where the bound applies: the float scores at the inputs the codes represent
        "agreement_float_at_codes": agreement(zref, bt_codes, bound),
        "agreement_float": agreement(zf, bt_codes, bound),  # at the real inputs (input rounding too)
    }
    if truth is not None:
        ref, labels = truth
        for name, lab in (("hw", hw_lab), ("bittrue", bt_lab), ("float", fl_lab)):
            summary[f"scores_{name}"] = fc.class_scores(labels, lab, classes)
        summary["reference_column"] = ref
    return summary, cols


def _is_estimator_folder(outdir: str | os.PathLike) -> bool:
    """True when ``outdir`` holds a valid manifest of the estimator design (others: the usual path and its errors)."""
    try:
        return load_manifest(outdir)["design"] == "estimator"
    except (OSError, ValueError, KeyError, TypeError):
        return False


def resolve_simulator(simulator: str | None, engine: str = "cocotb") -> str:
    """The simulator ``simulate`` runs: ``simulator``, or by default ``icarus`` (``verilator`` with
    ``engine="native"``).

    Parameters
    ----------
    simulator : str, optional
        ``icarus`` or ``verilator``; None for the default.
    engine : str
        ``cocotb`` or ``native``.

    Returns
    -------
    str
        The simulator's name.

    Raises
    ------
    InputError
        An unknown ``engine`` or ``simulator``.
    """
    if engine not in ENGINES:
        raise InputError(f"--engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    if simulator is None:
        simulator = "verilator" if engine == "native" else "icarus"
    if simulator not in SIMULATORS:
        raise InputError(f"--simulator must be one of {', '.join(SIMULATORS)}, got {simulator!r}")
    return simulator


def waves_folder(output: str | os.PathLike) -> Path:
    """The folder ``simulate --waves`` writes: ``<output stem>_waves`` beside the CSV ``output``,
    spelt as ``output`` is (relative stays relative, as the summary's ``data`` and ``outdir``)."""
    out = Path(output)
    return out.parent / f"{out.stem}_waves"


def waves_path(recorded: str | os.PathLike, work: str | os.PathLike, output: str | os.PathLike) -> str:
    """Where the waveform file ``recorded``, written in the simulator's folder ``work``, is once
    that folder has become :func:`waves_folder` of ``output`` (the summary's ``waves``)."""
    return str(waves_folder(output) / Path(recorded).resolve().relative_to(Path(work).resolve()))


def _simulate_estimator(outdir, data, output, spath, sources, *, blank_rows: str, waves: bool, cache_dir, **kw) -> dict:
    from pwas_hdl.io.atomic import OutputSet, check_output_path
    from pwas_hdl.io.csv_table import Table, read_csv
    from pwas_hdl.verify.estimator_simulation import simulate_estimator_data

    from pwas_hdl.design.manifest import folder_inputs

    outset = OutputSet(inputs=sources + folder_inputs(outdir))  # the manifest, the estimator file, the Verilog
    outset.add(output, "-o")
    outset.add(spath, "the summary (-o with .json)")
    if waves:
        outset.add(waves_folder(output), "the --waves folder", kind="folder")
    if cache_dir is not None:
        check_output_path(cache_dir, "--build-dir", kind="folder")
    table = data if isinstance(data, Table) else read_csv(data, blank_rows=blank_rows)
    with outset:  # a failure removes the staged waveform folder
        return simulate_estimator_data(outdir, table, output, spath, outset, waves=waves, cache_dir=cache_dir, **kw)


def simulate_arrays(
    outdir: str | os.PathLike,
    output: str | os.PathLike,
    *,
    u: np.ndarray | Sequence[np.ndarray] | None = None,
    y: np.ndarray | Sequence[np.ndarray] | None = None,
    z_true: np.ndarray | Sequence[np.ndarray] | None = None,
    **options: Any,
) -> dict:
    """Replay signals given as arrays through the generated RTL (as :func:`simulate_data` does a CSV file).

    Parameters
    ----------
    outdir : path
        Folder written by :func:`pwas_hdl.design.generate.generate`.
    output : path
        CSV of the hardware estimates to write (as :func:`simulate_data`); the JSON summary goes
        next to it unless ``summary_path`` is given.
    u, y : ndarray, shape (T, nu) / (T, ny), or a list of such (one per trajectory), optional
        Inputs and outputs in physical units, the columns in the order of the model's signals
        (``sensor.signal_names()``); ``None`` when the model does not use them.
    z_true : ndarray, shape (T, nz) or (T,), or a list of such, optional
        Reference values of the targets: the summary then holds the RMSEE of hardware, bit-true and
        float estimates against them. Of a classifier design, its true class labels (T,) or (T, 1)
        (values of its classes): the summary's ``classifier`` then holds accuracy and F1.
    **options
        ``simulator``, ``stall``, ``seed``, ``cache_dir``, ``waves``, ``summary_path``,
        ``progress`` of :func:`simulate_data`.

    Returns
    -------
    dict
        As :func:`simulate_data`: ``summary``, ``estimates`` (m, nz), ``rows`` (m,) (sample index
        counted over the concatenated trajectories), ``result``.
    """
    from pwas_hdl.fit.regressors import as_trajectories
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.io.csv_table import Table, reference_column_names

    if "traj_col" in options or "data" in options:
        raise TypeError("simulate_arrays takes trajectories as lists of arrays, not traj_col/data")
    sensor = PWASVirtualSensor.load(Path(outdir) / "model.json")
    ins, outs, tgts = sensor.signal_names()
    lags = sensor.lags_
    clf = getattr(sensor, "classifier_", None)
    refs = [clf["target"]] if clf is not None else tgts  # a classifier's reference: its class label, not its scores
    columns: dict[str, list] = {}
    n_traj = None
    for names, arr, what, used in ((ins, u, "u", lags.nu and lags.mu), (outs, y, "y", lags.ny and lags.my),
                                   ([reference_column_names(t)[0] for t in refs], z_true, "z_true", z_true is not None)):
        if not used:
            continue
        if arr is None:
            raise InputError(f"the model uses {what} ({', '.join(names)}); pass {what}=")
        trajs = as_trajectories(arr, what)
        if n_traj is not None and len(trajs) != len(n_traj):
            raise InputError(f"{what} has {len(trajs)} trajectories, the other signals {len(n_traj)}")
        if n_traj is not None and [len(t) for t in trajs] != n_traj:
            raise InputError(f"{what} has trajectories of {[len(t) for t in trajs]} samples, the other signals {n_traj}")
        n_traj = [len(t) for t in trajs]
        stacked = np.concatenate(trajs, axis=0)
        if stacked.shape[1] != len(names):
            raise InputError(f"{what} has {stacked.shape[1]} columns, the model's signals are {', '.join(names)}")
        for j, nm in enumerate(names):
            columns[nm] = stacked[:, j].tolist()
    if n_traj is None:
        raise InputError("no signal given: pass u= and/or y=")
    columns["_trajectory"] = [i for i, t in enumerate(n_traj) for _ in range(t)]
    header = list(columns)
    rows = [[repr(columns[h][r]) for h in header] for r in range(sum(n_traj))]
    table = Table("arrays", header, rows)
    return simulate_data(outdir, table, output, traj_col="_trajectory", **options)


def _checks(summary: dict, stall: float) -> dict:
    """Every way a replay can fail, from its summary: ``{"passed": bool, "failures": [str, ...]}``."""
    fails: list[str] = []
    if summary["mismatches"]:
        fails.append(f"{summary['mismatches']} hardware output(s) differ from the bit-true model "
                     f"(first: {json.dumps(summary['first_mismatch'], default=_json_default)})")
    fails += [f"testbench: {f}" for f in summary["testbench_failures"]]
    lat = summary["latency_cycles"]
    if stall == 0 and summary["samples"] and (lat["measured_min"], lat["measured_max"]) != (lat["manifest"], lat["manifest"]):
        fails.append(f"measured latency {lat['measured_min']}..{lat['measured_max']} cycles, the manifest says {lat['manifest']}")
    ii = summary["ii"]
    if stall == 0 and ii["measured"] is not None and ii["measured"] != ii["manifest"]:
        fails.append(f"measured II {ii['measured']:g}, the manifest says {ii['manifest']}")
    if not summary["within_error_bound"]:
        fails.append(f"error against the float model {summary['max_error_vs_float_lsb']:.4g} LSB exceeds the bound "
                     f"{summary['error_bound_lsb']:.4g} LSB")
    return {"passed": not fails, "failures": fails}


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o) if math.isfinite(float(o)) else None
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
