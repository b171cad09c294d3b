"""RTL of the power-of-two warp (non-uniform partitions in hardware): the warped core and sensor top.

One combinational warp per dimension (the specification is :mod:`pwas_hdl.fixedpoint.warp`)
and one register on the warped codes become the first pipeline stage of the unchanged core
(:func:`attach_warp` sets :attr:`PWASCore.input_stage <pwas_hdl.hdl.core.PWASCore>`; the register
advances with the core's pipeline): ports, flow control and II are the core's, the latency is
the core's + 1; the input payload holds signed ``B_in``-bit codes ``q`` (not the core's ``W``-bit
``u``). The same stage serves the parallel and the serial core (``architecture="serial"``: the
warp register is one more front-end register of :class:`~pwas_hdl.hdl.serial_core.SerialPWASCore`)
and the virtual-sensor top (:class:`~pwas_hdl.hdl.sensor_top.PWASSensorTop` with ``warps``: lag
bank of ``B_in``-bit codes -> warp -> core), also the recurrent top
(:class:`~pwas_hdl.hdl.recurrent_top.PWASRecurrentTop` with ``warps``: its feedback registers hold
``B_in``-bit codes too). ``pwas-hdl generate`` builds all of them for a model
fitted with ``--breakpoints quantile-pow2`` (:func:`build_warped_design`); for a classifier model
(``fit --classify``) the builders' ``classifier`` adds the argmax stage of
:mod:`pwas_hdl.hdl.classifier_top` after the core (parallel or serial, as for a uniform grid):
warp register -> core -> argmax stage, the class index in the output payload's top bits.

Warp of one dimension (offset-binary ``qo = q + 2**(B_in-1)``, constants ``Bo_k = B_k + 2**(B_in-1)``)::

    below = qo < Bo_0;  above = qo > Bo_p;  top = qo >= Bo_p
    t = qo - Bo_0;  i = t >> f0 (the base step, 0 .. S-1);  low = t mod 2**f0
    U = all ones (below) | p 2**F + 1 (above) | p 2**F (top) | HI[i] | (low << SH[i])   (inside)
    u = U + L  (mod 2**W, offset binary, its MSB inverted: the signed core input)

with the case tables (``S`` entries) ``HI[i] = k 2**F + j 2**(F - e_k)`` and ``SH[i] = F - f0 - e_k``
for base step ``i`` = step ``j`` of cell ``k``: within a cell, ``(q - B_k) << (F - f0 - e_k)`` is
``j 2**(F - e_k) + (low << SH)``, whose two parts do not overlap (an OR). No multiplier, no
divider: three comparators, one constant subtraction, two small case tables, a shift multiplexer
over the distinct shifts, one constant addition.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from amaranth.hdl import Cat, Const, Module, Signal, Value, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from pwas_hdl.errors import InputError
from pwas_hdl.hdl._lintsafe import add_const_wrap, ge_const, rom
from pwas_hdl.hdl.classifier_top import argmax_extent
from pwas_hdl.hdl.core import PWASCore, core_output_layout
from pwas_hdl.hdl.params import CoreParams, Pipeline
from pwas_hdl.hdl.sensor_top import PWASSensorTop, sample_fields

if TYPE_CHECKING:
    from pwas_hdl.fit.regressors import LagStructure
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.fixedpoint.warp import Pow2Warp, WarpedFixedPointModel
    from pwas_hdl.hdl.argmax import ArgmaxStage

__all__ = ["WarpedPWASCore", "attach_warp", "build_warped_core", "build_warped_sensor", "build_warped_design",
           "warp_into", "write_warped_folder"]


def warp_into(m: Module, q: Value, warp: Pow2Warp, name: str) -> Value:
    """Add the warp of one dimension to ``m``: signed ``B_in``-bit ``q`` -> signed ``W``-bit ``u`` (a value).

    Parameters
    ----------
    m : Module
        Combinational logic is added to ``m.d.comb``.
    q : Value
        The input code, ``warp.input_bits`` bits (two's complement).
    warp : Pow2Warp
        The dimension's warp (breakpoint codes, case tables, output width ``W``).
    name : str
        Prefix of the signal names.

    Returns
    -------
    Value
        ``u``, ``warp.width`` bits (two's complement), not registered.
    """
    b, w, f = warp.input_bits, warp.width, warp.frac
    half = 1 << (b - 1)
    msb = Signal(name=f"{name}_msb_n")
    m.d.comb += msb.eq(~q[b - 1])
    qo = Cat(q[: b - 1], msb)
    bo = [c + half for c in warp.code_breaks]
    p, f0 = warp.p, warp.f0
    below = ge_const(qo, bo[0])
    below = (not below) if isinstance(below, bool) else ~below
    top = ge_const(qo, bo[p])
    above = ge_const(qo, bo[p] + 1)
    # inside: t = qo - Bo_0 in [0, S 2**f0): base step idx = t >> f0, offset in it low = t mod 2**f0
    s_total = (bo[p] - bo[0]) >> f0
    wt = max(1, (bo[p] - bo[0] - 1).bit_length())
    t = add_const_wrap(m, qo[:wt], -bo[0], f"{name}_t")
    low = t[:f0] if f0 else None
    idx = t[f0:wt] if wt > f0 else 0
    cell_of, sub_of = [], []
    for k, e in enumerate(warp.exps):
        cell_of += [k] * (1 << e)
        sub_of += list(range(1 << e))
    assert len(cell_of) == s_total
    shifts = warp.shifts()
    hi_vals = [(k << f) + (sub_of[i] << (f - warp.exps[k])) for i, k in enumerate(cell_of)]
    u_hi = rom(m, idx, hi_vals, w, f"{name}_hi")
    u_lo = 0
    if low is not None:
        kinds = sorted(set(shifts))
        code = rom(m, idx, [kinds.index(shifts[k]) for k in cell_of], max(1, (len(kinds) - 1).bit_length()), f"{name}_sc")
        if isinstance(code, int):  # one shift for every cell (e.g. equal cells): a value, not a named alias (lint)
            u_lo = Cat(Const(0, kinds[code]), low) if kinds[code] else low
        else:
            u_lo = Signal(unsigned(w), name=f"{name}_lo")
            with m.Switch(code):
                for c, sh in enumerate(kinds):
                    with (m.Case(c) if c < len(kinds) - 1 else m.Default()):
                        m.d.comb += u_lo.eq(Cat(Const(0, sh), low) if sh else low)
    big_u = Signal(unsigned(w), name=f"{name}_U")

    def inside():
        if isinstance(u_hi, int) and isinstance(u_lo, int):
            m.d.comb += big_u.eq(u_hi | u_lo)
        elif isinstance(u_lo, int):
            m.d.comb += big_u.eq(u_hi)
        elif isinstance(u_hi, int):
            m.d.comb += big_u.eq(u_lo | Const(u_hi, w) if u_hi else u_lo)
        else:
            m.d.comb += big_u.eq(u_hi | u_lo)  # the low bits of u_hi are 0: an OR, no adder

    def const(v):
        return lambda: m.d.comb.__iadd__(big_u.eq(v))

    # (condition, action) in priority order; constant conditions are folded
    chain = [(below, const((1 << w) - 1)), (above, const((p << f) + 1)), (top, const(p << f))]
    conds = [(c, a) for c, a in chain if c is not False]
    if not conds:
        inside()
    else:
        with m.If(conds[0][0]):
            conds[0][1]()
        for cond, act in conds[1:]:
            with m.Elif(cond):
                act()
        with m.Else():
            inside()
    qu = add_const_wrap(m, big_u, warp.lo_u + (1 << (w - 1)), f"{name}_u")  # offset-binary u
    return Cat(qu[: w - 1], ~qu[w - 1])  # a value, not a named alias (lint: see pwas_hdl.hdl._lintsafe)


def attach_warp(core: PWASCore, warps: Sequence[Pow2Warp]) -> int:
    """Put the warps (one per dimension) and their register in front of ``core`` (parallel or serial).

    Sets ``core.input_stage`` and adds the register to ``core.latency``.

    Parameters
    ----------
    core : PWASCore or SerialPWASCore
        Not elaborated yet; its ``params`` are the uniform core's (``in_width = W``).
    warps : sequence of Pow2Warp
        One per regressor dimension, all with the same ``input_bits`` and ``width == params.in_width``.

    Returns
    -------
    int
        ``B_in``: bits of one input code in front of the warp.

    Raises
    ------
    InputError
        Not one warp per dimension, mixed input widths, an output width other than the core's,
        or a core that already has an input stage.
    """
    warps = list(warps)
    p = core.params
    if len(warps) != p.n or {w.input_bits for w in warps} != {warps[0].input_bits} or any(w.width != p.in_width for w in warps):
        raise InputError(f"need {p.n} warps of one input width whose output width is the core's {p.in_width} bits")
    if core.input_stage is not None:
        raise InputError("the core has an input stage already (attach_warp was called on it before); build a new core")
    b = warps[0].input_bits

    def stage(m: Module, pipe, payload, valid):
        us = [warp_into(m, payload[j * b : (j + 1) * b], w, f"warp{j}") for j, w in enumerate(warps)]
        v, regs = pipe.stage("s_warp", True, valid, {"u": us})  # s_warp_u<j>, s_warp_valid
        return v, Cat(*regs["u"])

    core.input_stage = stage
    core.latency += 1
    core.warps = warps
    return b


def warp_hw_info(model: WarpedFixedPointModel, latency_cycles: int = 1) -> dict:
    """The manifest's ``warp`` entry: the model's :meth:`~pwas_hdl.fixedpoint.warp.WarpedFixedPointModel.warp_info`
    plus the hardware facts (cycles added, register names).

    Parameters
    ----------
    model : WarpedFixedPointModel
        The warped bit-true model.
    latency_cycles : int
        Cycles the warp adds (its one register).

    Returns
    -------
    dict
        ``warp_info()`` with ``latency_cycles``, ``register`` and ``meaning``.
    """
    return {**model.warp_info(), "latency_cycles": int(latency_cycles), "register": "s_warp_u<j> (one per dimension)",
            "meaning": "one warp per regressor dimension maps the input code q (s<B_in>.0, physical = offset + lsb * q) "
                       "to the code u of the uniform core (core_input_bits): three comparators, a constant subtraction, "
                       "two case tables over the base steps, a shift multiplexer, a constant addition; one register"}


class WarpedPWASCore(wiring.Component):
    """Warp stage (+ register) + PWAS core: ``n`` input codes ``q`` in, ``nz`` estimates out.

    Parameters
    ----------
    model : pwas_hdl.fixedpoint.warp.WarpedFixedPointModel
        Its ``warps`` (one per dimension) and ``core`` (the uniform core's bit-true model).
    memory, pipeline : as :class:`~pwas_hdl.hdl.core.PWASCore`
    architecture : {"parallel", "serial"}
        The core behind the warp (serial: II = n + 1, :mod:`pwas_hdl.hdl.serial_core`).
    argmax : ArgmaxStage, optional
        A classifier's decision stage after the core
        (:func:`~pwas_hdl.hdl.classifier_top.classifier_argmax`; :func:`build_warped_core` makes it
        from ``classifier``): the output payload then ends with the class index and the latency
        grows by ``argmax.latency``.

    Ports: as the core, but ``in.payload`` holds ``n`` signed ``B_in``-bit codes ``q``
    (``in_width`` bits each); with ``argmax`` ``out.payload`` adds the class index in its top bits.

    Attributes
    ----------
    core : PWASCore (inlined), ii, memory_plan, pipeline, params : the core's
    latency : int
        The core's + 1 (the warp register) + ``argmax.latency``.
    warps : list of Pow2Warp
    in_width : int
        ``B_in``: bits of one input code.
    argmax : ArgmaxStage or None

    Raises
    ------
    InputError
        An unknown ``architecture``, warps that do not fit the core
        (:func:`attach_warp`), parameters the core refuses, or an ``argmax`` whose ``index_lsb`` is
        not the core's output width.
    """

    kind = "core"

    def __init__(self, model: WarpedFixedPointModel, *, memory: str = "banked", pipeline: Pipeline | str | None = None,
                 architecture: str = "parallel", argmax: ArgmaxStage | None = None):
        from pwas_hdl.hdl.api import _make_core

        self._MustUse__silence = True
        self.warps = list(model.warps)
        params = CoreParams.from_model(model.core)
        out_bits = core_output_layout(params).size
        cycles, index_bits = argmax_extent(argmax, out_bits)
        self.core = _make_core(params, memory, pipeline, architecture)
        self.core._MustUse__silence = True
        self.in_width = attach_warp(self.core, self.warps)
        self.params = params
        self.argmax = argmax
        self.latency = self.core.latency + cycles
        self.ii = self.core.ii
        self.memory_plan, self.pipeline = self.core.memory_plan, self.core.pipeline
        self._model = model
        super().__init__({
            "in": In(stream.Signature(unsigned(params.n * self.in_width))),
            "out": Out(stream.Signature(unsigned(out_bits + index_bits))),
        })
        self._MustUse__silence = False

    @property
    def input_fields(self) -> list[dict]:
        """Input payload fields: one signed ``B_in``-bit code ``q`` per regressor."""
        return sample_fields(getattr(self.core, "input_names", [f"x{j}" for j in range(self.params.n)]), self.in_width)

    @property
    def extra_info(self) -> dict:
        """Manifest entries: ``warp`` (:func:`warp_hw_info`)."""
        return {"warp": warp_hw_info(self._model)}

    def elaborate(self, platform: Any) -> Module:
        """The warp stage, its register and the PWAS core (and the argmax stage, if any), connected.

        Parameters
        ----------
        platform : Any
            Amaranth build platform; the warp ignores it.

        Returns
        -------
        Module
            The core's :meth:`~pwas_hdl.hdl.core.PWASCore.build_into`, its input stage the warp,
            then the argmax stage (:func:`~pwas_hdl.hdl.classifier_top.inline_core_and_argmax`).
        """
        from pwas_hdl.hdl.classifier_top import inline_core_and_argmax

        m = Module()
        inp = getattr(self, "in")
        inline_core_and_argmax(m, self.core, self.argmax, inp.payload, inp.valid, inp.ready, self.out)
        return m


def build_warped_core(model: WarpedFixedPointModel, *, memory: str = "banked", pipeline: Pipeline | str | None = None,
                      name: str = "pwas_core", architecture: str = "parallel", classifier: dict | None = None) -> WarpedPWASCore:
    """The warped core of a :class:`~pwas_hdl.fixedpoint.warp.WarpedFixedPointModel` (named for emit).

    Parameters
    ----------
    model : WarpedFixedPointModel
        The warped bit-true model.
    memory, pipeline, name, architecture, classifier
        As :func:`pwas_hdl.hdl.api.build_core` (``name`` is not checked here; ``classifier``: the
        argmax stage after the core, :func:`pwas_hdl.hdl.api.classifier_stage`).

    Returns
    -------
    WarpedPWASCore
        Latency: the core's + 1 cycle (+ the argmax stage's); ``classifier`` as given (for the
        manifest's ``classifier`` entry, :func:`pwas_hdl.hdl.api.design_info`).

    Raises
    ------
    InputError
        As :class:`WarpedPWASCore`; a classifier whose class count differs from ``nz``
        (:func:`pwas_hdl.hdl.api.check_classifier`).
    """
    from pwas_hdl.hdl.api import classifier_stage

    argmax = classifier_stage(classifier, CoreParams.from_model(model.core), pipeline)
    comp = WarpedPWASCore(model, memory=memory, pipeline=pipeline, architecture=architecture, argmax=argmax)
    comp.module_name = name
    comp._MustUse__silence = True
    comp.core.input_names = list(model.regressor_names)
    comp.core.target_names = list(model.target_names)
    comp.classifier = dict(classifier) if classifier is not None else None
    return comp


def build_warped_sensor(model: WarpedFixedPointModel, lags: LagStructure | None, *, memory: str = "banked",
                        pipeline: Pipeline | str | None = None, name: str = "pwas_sensor",
                        architecture: str = "parallel", classifier: dict | None = None) -> PWASSensorTop:
    """The warped virtual-sensor top: lag bank of ``B_in``-bit codes -> warp (+ register) -> core.

    Parameters
    ----------
    model : pwas_hdl.fixedpoint.warp.WarpedFixedPointModel
        Its lags of one signal must share one input quantisation (:meth:`signal_input_formats`).
    lags : LagStructure or None
        The sensor's lag structure; None: derived from the model's ``regressor_signals``
        (:func:`~pwas_hdl.hdl.sensor_top.lag_plan`).
    memory, pipeline, name, architecture, classifier : as :func:`pwas_hdl.hdl.api.build_sensor`
        (``classifier``: the argmax stage after the core, inside the top)

    Returns
    -------
    PWASSensorTop
        With ``warps`` (and ``argmax`` for a classifier); ``extra_info`` adds the manifest's ``warp`` entry.

    Raises
    ------
    InputError
        The lags of a signal have different quantisations, or recurrent ``lags``; a classifier
        whose class count differs from ``nz``.
        As :func:`~pwas_hdl.hdl.sensor_top.lag_plan` or :class:`~pwas_hdl.hdl.sensor_top.PWASSensorTop`.
    """
    from pwas_hdl.hdl.api import classifier_stage
    from pwas_hdl.hdl.sensor_top import lag_plan

    model.signal_input_formats()  # InputError unless the lags of each signal can share one code
    params = CoreParams.from_model(model.core)
    signals, dims = lag_plan(model.core, lags)
    argmax = classifier_stage(classifier, params, pipeline)
    top = PWASSensorTop(params, signals, dims, memory=memory, pipeline=pipeline, architecture=architecture, warps=model.warps,
                        argmax=argmax)
    top.module_name = name
    top.classifier = dict(classifier) if classifier is not None else None
    top._MustUse__silence = True
    top.core.input_names = list(model.regressor_names)
    top.core.target_names = list(model.target_names)
    top.warp_entry = warp_hw_info(model)
    return top


def build_warped_design(model: WarpedFixedPointModel, design: str, lags: LagStructure | None, *, memory: str = "banked",
                        pipeline: Pipeline | str | None = None, name: str = "pwas_core",
                        architecture: str = "parallel", classifier: dict | None = None) -> WarpedPWASCore | PWASSensorTop:
    """The component ``generate`` builds for a warped model.

    Parameters
    ----------
    model : WarpedFixedPointModel
        The warped bit-true model.
    design : {"core", "sensor"}
        ``"core"``: :func:`build_warped_core`; any other value: :func:`build_warped_sensor`.
    lags : LagStructure or None
        For the sensor top.
    memory, pipeline, name, architecture, classifier
        As :func:`build_warped_core` (``classifier``: ``sensor.classifier_`` of a classifier model,
        the argmax stage after the core).

    Returns
    -------
    WarpedPWASCore or PWASSensorTop
        Named ``name``; latency the core's + 1 cycle (+ the argmax stage's).

    Raises
    ------
    InputError, ValueError
        As :func:`build_warped_core` or :func:`build_warped_sensor`.
    """
    if design == "core":
        return build_warped_core(model, memory=memory, pipeline=pipeline, name=name, architecture=architecture,
                                 classifier=classifier)
    return build_warped_sensor(model, lags, memory=memory, pipeline=pipeline, name=name, architecture=architecture,
                               classifier=classifier)


def write_warped_folder(sensor: PWASVirtualSensor, outdir: str | os.PathLike, *, input_bits: int = 12,
                        input_fill: float = 0.9, design: str = "core",
                        **options: Any) -> tuple[WarpedFixedPointModel, dict]:
    """Write the design folder of a sensor with power-of-two breakpoints: ``pwas-hdl generate``
    (:func:`pwas_hdl.design.generate.generate`) with these options, kept for the callers of the
    interim API.

    Parameters
    ----------
    sensor : PWASVirtualSensor
        Fitted with power-of-two breakpoints.
    outdir : path
        The design folder.
    input_bits : int
        ``B_in``, the width in bits of the input codes (default 12).
    input_fill : float
        Largest fraction of the input code range the domain takes (default 0.9).
    design, **options
        Passed to :func:`~pwas_hdl.design.generate.generate` (here ``design`` defaults to ``"core"``),
        as are ``input_bits`` and ``input_fill``.

    Returns
    -------
    (WarpedFixedPointModel, dict)
        The bit-true model the Verilog implements and the manifest written.
    """
    from pwas_hdl.design.generate import generate

    gd = generate(sensor, outdir, design=design, input_bits=input_bits, input_fill=input_fill, **options)
    return gd.model, gd.manifest
