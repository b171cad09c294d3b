"""RTL of the power-of-two warp (non-uniform partitions in hardware) and the warped core.

:class:`WarpedPWASCore` = one combinational warp per dimension (the specification is
:mod:`pwas_hdl.fixedpoint.warp`) in front of the unchanged :class:`~pwas_hdl.hdl.core.PWASCore`,
which is inlined (``build_into``), behind one register on the warped codes (enabled with the
core's pipeline): ports, flow control and II are the core's, the latency is the core's + 1; the
input payload holds ``n`` signed ``B_in``-bit codes ``q`` (not the core's ``W``-bit ``u``).

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

from amaranth.hdl import Cat, Const, Module, Signal, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from pwas_hdl.hdl._lintsafe import add_const_wrap, ge_const, rom
from pwas_hdl.hdl.core import PWASCore, core_output_layout
from pwas_hdl.hdl.params import CoreParams, Pipeline
from pwas_hdl.hdl.sensor_top import sample_fields

__all__ = ["WarpedPWASCore", "build_warped_core", "warp_into", "write_warped_folder"]


def warp_into(m: Module, q, warp, name: str):
    """Add the warp of one dimension to ``m``: signed ``B_in``-bit ``q`` -> signed ``W``-bit ``u`` (a value)."""
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
        u_lo = Signal(unsigned(w), name=f"{name}_lo")
        if isinstance(code, int):
            m.d.comb += u_lo.eq(Cat(Const(0, kinds[code]), low))
        else:
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


class WarpedPWASCore(wiring.Component):
    """Warp stage (+ register) + PWAS core: ``n`` input codes ``q`` in, ``nz`` estimates out, every clock.

    Parameters
    ----------
    model : pwas_hdl.fixedpoint.warp.WarpedFixedPointModel
    memory, pipeline : as :class:`~pwas_hdl.hdl.core.PWASCore`

    Attributes
    ----------
    core : PWASCore (inlined), latency, ii, memory_plan, pipeline, params : the core's
    warps : list of Pow2Warp
    """

    kind = "core"

    def __init__(self, model, *, memory: str = "banked", pipeline: Pipeline | str | None = None):
        self._MustUse__silence = True
        self.warps = list(model.warps)
        self.in_width = int(model.input_bits)
        params = CoreParams.from_model(model.core)
        self.core = PWASCore(params, memory=memory, pipeline=pipeline)
        self.core._MustUse__silence = True
        self.params = params
        self.latency, self.ii = self.core.latency + 1, self.core.ii  # + the warp register
        self.memory_plan, self.pipeline = self.core.memory_plan, self.core.pipeline
        super().__init__({
            "in": In(stream.Signature(unsigned(params.n * self.in_width))),
            "out": Out(stream.Signature(unsigned(core_output_layout(params).size))),
        })
        self._MustUse__silence = False

    @property
    def input_fields(self) -> list[dict]:
        return sample_fields(getattr(self.core, "input_names", [f"x{j}" for j in range(self.params.n)]), self.in_width)

    @property
    def extra_info(self) -> dict:
        return {"warp": [w.to_dict() for w in self.warps]}

    def elaborate(self, platform):
        m = Module()
        inp = getattr(self, "in")
        b = self.in_width
        us = [warp_into(m, inp.payload[j * b : (j + 1) * b], w, f"warp{j}") for j, w in enumerate(self.warps)]
        # the warp register: one more pipeline stage, enabled by the core's advance (= in.ready)
        regs = [Signal(w.width, name=f"s_warp_u{j}", reset_less=True) for j, w in enumerate(self.warps)]
        valid = Signal(name="s_warp_valid")
        with m.If(inp.ready):
            m.d.sync += [r.eq(u) for r, u in zip(regs, us)] + [valid.eq(inp.valid)]
        self.core.build_into(m, Cat(*regs), valid, inp.ready, self.out)
        return m


def build_warped_core(model, *, memory: str = "banked", pipeline: Pipeline | str | None = None,
                      name: str = "pwas_core") -> WarpedPWASCore:
    """The warped core of a :class:`~pwas_hdl.fixedpoint.warp.WarpedFixedPointModel` (named for emit)."""
    comp = WarpedPWASCore(model, memory=memory, pipeline=pipeline)
    comp.module_name = name
    comp._MustUse__silence = True
    comp.core.input_names = list(model.regressor_names)
    comp.core.target_names = list(model.target_names)
    return comp


def write_warped_folder(sensor, outdir, *, input_bits: int = 12, input_fill: float = 0.9, **formats):
    """Write a design folder of the warped core of a sensor with power-of-two breakpoints.

    The interim path until ``generate`` builds warped designs itself: the folder holds the Verilog
    of :class:`WarpedPWASCore` and a valid ``manifest.json`` -- the manifest of the uniform core
    of the same weights on the unit grid (built by :func:`pwas_hdl.design.generate.build_design`,
    ``input_bits`` = the warp's ``W``), whose input port is replaced by the warped core's
    (``n`` fields of ``input_bits`` bits, physical ``offset_j + lsb_j * code``, the domain in
    codes ``[B_0, B_p]``) and whose latency is the warped core's. ``synth`` and the manifest-driven
    testbench read it; ``simulate`` does not (it rebuilds a uniform bit-true model). ``model.json``
    is that unit-grid model (the one the manifest describes), not the non-uniform one.

    Returns
    -------
    (WarpedFixedPointModel, dict)
        The bit-true model the Verilog implements and the manifest written.
    """
    import copy
    from pathlib import Path

    import numpy as np

    from pwas_hdl.design.generate import build_design
    from pwas_hdl.design.manifest import manifest_errors, manifest_text
    from pwas_hdl.errors import InternalError
    from pwas_hdl.fit.geometry import Grid
    from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel
    from pwas_hdl.hdl.emit import emit_verilog

    wm = WarpedFixedPointModel.from_sensor(sensor, input_bits=input_bits, input_fill=input_fill, **formats)
    eq = copy.deepcopy(sensor)
    p = sensor.grid_.partitions
    eq.grid_, eq.breakpoints = Grid(np.zeros(sensor.grid_.n), p.astype(float), p), None
    gd = build_design(eq, design="core", input_bits=wm.warps[0].width, input_fill=input_fill, **formats)
    fm = gd.model
    if (fm.frac_bits != wm.core.frac_bits or fm.lo_codes != wm.core.lo_codes or fm.output_format != wm.core.output_format
            or not np.array_equal(fm.weight_codes, wm.core.weight_codes)):
        raise InternalError("the uniform core of the warped design differs from the warp's bit-true core")
    comp = build_warped_core(wm, name=gd.top)
    verilog = emit_verilog(comp, gd.top)
    man = copy.deepcopy(gd.manifest)
    port = next(pt for pt in man["ports"] if pt["role"] == "in.payload")
    b = wm.input_bits
    port["width"] = b * sensor.grid_.n
    for j, f in enumerate(port["fields"]):
        f.update(lsb=j * b, width=b, format=wm.input_port_format(j),
                 domain_codes=[wm.warps[j].code_breaks[0], wm.warps[j].code_breaks[-1]])
    man["latency_cycles"] = comp.latency
    errs = manifest_errors(man)
    if errs:
        raise InternalError(f"the warped design's manifest breaks its schema: {errs[0]}")
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "manifest.json").write_text(manifest_text(man), encoding="utf-8")
    (out / man["files"]["verilog"]).write_text(verilog, encoding="utf-8")
    (out / "model.json").write_text(gd.files["model.json"], encoding="utf-8")
    return wm, man
