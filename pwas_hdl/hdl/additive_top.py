"""Hardware of the additive PWAS sensor (issue 15): the parts' cores in parallel, summed before one rounding.

Datapath (the bit-true specification is :class:`pwas_hdl.fixedpoint.additive.AdditiveFixedPointModel`)::

    regressor codes (n x B_in) --+--> q[S_1] -> PWASCore part 1 (no rounding) -> acc_1 --+
                                 +--> q[S_2] -> PWASCore part 2 (no rounding) -> acc_2 --+--> sum (exact,
                                 ...                                                     |    acc_i << F - F_i)
                                 +--> q[S_k] -> PWASCore part k (no rounding) -> acc_k --+--> round, saturate
                                                                                              -> out register

* Every part is a :class:`~pwas_hdl.hdl.core.PWASCore` with ``round_output=False`` (its output
  register holds the exact accumulator), elaborated into its own Verilog module
  ``<top>_part<i>`` with its own weight memories. The parts read the same input codes: one scaling
  per regressor (and, in the sensor top, one lag bank, :class:`~pwas_hdl.hdl.sensor_top.PWASSensorTop`).
* The parts get pipelines of equal latency (the given one, with the ``addr`` / ``mem_out`` /
  ``split`` / ``rank`` / ``product`` registers or more adder-tree registers added to the parts with
  fewer adder-tree levels), so their valid bits are equal; latency = part latency + 1 (the sum register).
* Flow control: ``advance = ~out.valid | out.ready`` for the sum register; each part's output
  register is read when ``advance`` is high (``part.out.ready = advance``), so a part advances when
  its output is empty or taken: all parts move together, ``in.ready`` is the parts' ``advance``.
* Widths: ``acc_i`` has ``F_i + B_w + 1`` bits; the aligned terms and partial sums ``W = F + B_w + 1
  + ceil(log2 k)`` bits (``|acc_i << (F - F_i)| <= 2**(F + B_w - 1)``: no sum can overflow); the
  rounding adds ``2**(sh-1)`` modulo ``2**W`` and drops ``sh`` bits, then saturates to ``B_out``.

Serial architecture (``architecture="serial"``): every part is a
:class:`~pwas_hdl.hdl.serial_core.SerialPWASCore` with ``round_output=False`` (one multiplier per
target, ``n_i + 1`` cycles per sample, one weight memory of ``N_i`` words), all driven by one input
throttle (:func:`~pwas_hdl.hdl.serial_core.serial_throttle` with ``n_max``, the largest part's
dimension: II = ``n_max + 1``) and one ``advance``; then the same exact sum and rounding.

* Alignment: the parts take each sample in the same cycle, so part ``i``'s sum is ready
  ``n_max - n_i`` cycles before the largest part's. It waits in the part's own output register, at
  no cost: that register holds the part's accumulator, which the next sample overwrites (its first
  vertex) no earlier than ``n_max + 1`` advancing cycles after this sample's first vertex, i.e. in
  the cycle after the largest part's sum reaches its output register. The sum register reads every
  part's output register when the largest part's ``valid`` is high. (Starting the shorter parts
  later would need ``n_max - n_i`` registers of their ``n_i * B_in`` input bits; delaying their
  results in a shift register ``n_max - n_i`` registers of ``nz * acc_bits_i + 1`` bits: both are
  avoided.) Latency = the largest part's serial latency + 1 (the sum register).
* The pipeline asked for is every part's own (no equalising: the serial latency depends on
  ``n_i`` only through the ``n_i`` multiply-accumulate steps).
* The shorter parts' ``valid`` registers are not read (the largest part's is the sum's).

The Verilog (:func:`emit_additive_verilog`) is one module, the parts flattened into it (their names
prefixed ``part<i>_``); its weight memories ``part<i>_wmem<b>`` are initialised inline or, with
``memory_init="readmemh"``, loaded from the files of :func:`pwas_hdl.hdl.emit.memory_hex_files` (``<prefix>_p<i>_b<b>.hex``)
under the ``MEM_DIR`` parameter, as :func:`pwas_hdl.hdl.emit.emit_verilog` does for one core.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import re
from dataclasses import dataclass, replace
from types import SimpleNamespace

from amaranth.hdl import Cat, Const, Module, Signal, Value, signed, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from pwas_hdl.errors import InputError, InternalError, choice_text, option_text
from pwas_hdl.fixedpoint.reduction import tree_reduce
from pwas_hdl.fixedpoint.memory_layout import SINGLE_MEMORY
from pwas_hdl.hdl._lintsafe import add_const_wrap, sink_unused
from pwas_hdl.hdl.classifier_top import argmax_extent
from pwas_hdl.hdl.core import PWASCore
from pwas_hdl.hdl.names import check_module_name
from pwas_hdl.hdl.params import CoreParams, Pipeline, PipelineRefused
from pwas_hdl.hdl.sensor_top import PWASSensorTop, lag_plan
from pwas_hdl.hdl.serial_core import ARCHITECTURES, SerialPWASCore, serial_throttle

if TYPE_CHECKING:
    from pwas_hdl.fit.regressors import LagStructure
    from pwas_hdl.fixedpoint.additive import AdditiveFixedPointModel

__all__ = ["AdditiveCore", "AdditiveSensorTop", "build_additive_core", "build_additive_sensor", "emit_additive_verilog",
           "equal_latency_pipelines"]


def equal_latency_pipelines(base: Pipeline, dims: list[int]) -> list[Pipeline]:
    """One pipeline per part (``dims``: the parts' dimensions) with the latency of the slowest part.

    Parts with fewer adder-tree levels get the optional registers of ``base`` they lack (``addr``,
    ``mem_out``, ``mul_in``, ``split``, ``rank``, ``product``, in this order), then more adder-tree
    registers. When ``base`` has every register already (the ``max`` preset), the deeper parts go
    without ``mul_in`` so that the shallower ones can take it.

    Parameters
    ----------
    base : Pipeline
        The pipeline asked for.
    dims : list of int
        Regressor dimension of each part.

    Returns
    -------
    list of Pipeline
        One per part, in ``dims`` order, all with the same :meth:`Pipeline.latency`.

    Raises
    ------
    PipelineRefused
        No such pipeline exists for some part (e.g. every register is already used): an
        :class:`~pwas_hdl.errors.InputError` the timing closure takes as "not a candidate".
    """
    try:
        return _equal_latency(base, dims)
    except PipelineRefused:
        if not base.mul_in:
            raise
        return _equal_latency(replace(base, mul_in=False), dims)


def _equal_latency(base: Pipeline, dims: list[int]) -> list[Pipeline]:
    target = max(base.latency(n) for n in dims)
    out = []
    for n in dims:
        p = base
        for fld in ("addr", "mem_out", "mul_in", "split", "rank", "product"):
            if p.latency(n) >= target:
                break
            if not getattr(p, fld):
                p = replace(p, **{fld: True})
        lv = p.tree_levels
        while p.latency(n) < target and lv != 1:
            lv = max(Pipeline.tree_depth(n), 1) if lv == 0 else lv - 1
            p = replace(p, tree_levels=lv)
        if p.latency(n) != target:
            raise PipelineRefused(f"the additive parts cannot be given equal latencies with pipeline {base.to_dict()} "
                             f"(parts of dimensions {sorted(set(dims))}); use another --pipeline or parts of equal size")
        out.append(p)
    return out


@dataclass(frozen=True)
class AdditiveParams:
    """Integer description of the additive datapath as a whole (what ``design_info`` reports).

    ``partitions``, ``lo_code``, ``frac_bits`` per regressor of the whole sensor; ``acc_width + 1``
    is the width ``W`` of the sum; ``shift = F + Fw - Fo``.
    """

    partitions: tuple[int, ...]
    in_width: int
    lo_code: tuple[int, ...]
    frac_bits: tuple[int, ...]
    weight_width: int
    weight_frac: int
    out_width: int
    out_frac: int
    nz: int
    rounding: str
    sum_width: int

    @property
    def n(self) -> int:
        """Regressors of the whole sensor."""
        return len(self.partitions)

    @property
    def frac(self) -> int:
        """``F = max F_j``."""
        return max(self.frac_bits)

    @property
    def shift(self) -> int:
        """Right shift of the sum before rounding, ``F + Fw - Fo`` bits."""
        return self.frac + self.weight_frac - self.out_frac

    @property
    def acc_width(self) -> int:
        """``sum_width - 1`` (so that ``acc_width + 1`` is the sum's width, as for a single core)."""
        return self.sum_width - 1


@dataclass(frozen=True)
class AdditiveMemoryPlan:
    """The weight memories of all parts (each part's :class:`~pwas_hdl.hdl.params.MemoryPlan`)."""

    parts: tuple

    @property
    def kind(self) -> str:
        """Layout name of the parts' memories (that of part 0)."""
        return self.parts[0].kind

    def layout_spec(self) -> dict:
        """The manifest's ``memory.layout_spec`` of a serial additive design (parts of
        :class:`~pwas_hdl.hdl.serial_core.SingleMemoryPlan`).

        Returns
        -------
        dict
            ``kind`` (``"single"``), ``memories`` (one per part), ``depth`` (words of the largest),
            ``address`` (a sentence).
        """
        spec = self.parts[0].layout_spec()
        return {**spec, "memories": len(self.parts), "depth": int(max(p.depth for p in self.parts)),
                "address": f"{spec['address']} of the part's own grid; one memory of N_i words per part"}

    def to_dict(self) -> dict:
        """JSON-ready summary over all parts.

        Returns
        -------
        dict
            Keys as :meth:`MemoryPlan.to_dict`: memories, words and bits summed, ``depth`` the
            largest, ``word_bits`` of part 0.
        """
        return {
            "kind": self.kind,
            "memories": int(sum(p.n_banks for p in self.parts)),
            "depth": int(max(p.depth for p in self.parts)),
            "word_bits": int(self.parts[0].word_bits),
            "words": int(sum(p.words for p in self.parts)),
            "bits": int(sum(p.bits for p in self.parts)),
        }


class _Out:
    """The output side a part core drives (``payload``, ``valid``) and reads (``ready``)."""

    def __init__(self, name: str, width: int, ready):
        self.payload = Signal(width, name=f"{name}_acc", reset_less=True)
        self.valid = Signal(name=f"{name}_valid")
        self.ready = ready


class AdditiveCore(wiring.Component):
    """The additive datapath: the parts' cores in parallel, the exact sum, one rounding.

    Parameters
    ----------
    model : AdditiveFixedPointModel
        The bit-true additive model: its parts, subsets, alignment shifts and formats.
    memory : {"banked", "replicated", "corner"}
        Each part's weight memory (as :class:`~pwas_hdl.hdl.core.PWASCore`); ignored with
        ``architecture="serial"`` (one memory of ``N_i`` words per part).
    pipeline : Pipeline, preset name or None
        The parts' pipeline (parallel: made equal in latency, :func:`equal_latency_pipelines`;
        serial: every part's own, :func:`~pwas_hdl.hdl.serial_core.serial_latency`).
    architecture : {"parallel", "serial"}
        The parts' cores: :class:`~pwas_hdl.hdl.core.PWASCore` (II = 1) or
        :class:`~pwas_hdl.hdl.serial_core.SerialPWASCore` (one multiplier per target and part, II =
        ``n_max + 1``; see the module notes for the alignment of the parts).
    argmax : ArgmaxStage, optional
        A classifier's stage after the sum (:func:`~pwas_hdl.hdl.api.classifier_stage`): inlined
        by :meth:`elaborate` (not by :meth:`build_into`, the sum alone); the output payload then
        ends with the class index and the latency grows by ``argmax.latency``.

    Ports: as :class:`~pwas_hdl.hdl.core.PWASCore` (``in.payload``: ``n`` codes of ``B_in`` bits;
    ``out.payload``: ``nz`` codes of ``B_out`` bits, then ``out_of_range``).

    Attributes
    ----------
    parts : list of PWASCore or SerialPWASCore
        The part cores (``round_output=False``).
    architecture : str
        ``"parallel"`` or ``"serial"``.
    lead : int
        Index of the part whose ``valid`` the sum register takes (the first of largest latency).
    subsets : tuple of tuple of int
        Regressor indices of each part.
    latency, ii : int
        Cycles: the (largest) part latency + 1 (the sum register), plus the argmax stage's; II = 1
        (parallel) or ``n_max + 1`` (serial).
    params : AdditiveParams
    memory_plan : AdditiveMemoryPlan
    pipeline : Pipeline
        The pipeline asked for (the parts' own are ``parts[i].pipeline``).

    Raises
    ------
    InputError
        No equal-latency pipelines exist for the parts (parallel), an unknown ``architecture``,
        or the output shift ``F + Fw - Fo`` is not smaller than the sum's width ``W``.
    InternalError
        An aligned part accumulator is wider than the sum.
    """

    def __init__(self, model: AdditiveFixedPointModel, *, memory: str = "banked", pipeline: Pipeline | str | None = None,
                 argmax: Any = None, architecture: str = "parallel"):
        self._MustUse__silence = True
        if architecture not in ARCHITECTURES:
            raise InputError(choice_text(option_text("architecture"), ARCHITECTURES, architecture))
        base = Pipeline.cast(pipeline)
        self.subsets = tuple(model.subsets)
        self.align = list(model.align)
        self.architecture = architecture
        part_params = [CoreParams.from_model(p) for p in model.parts]
        if architecture == "serial":  # every part on the serial core, one throttle (build_into)
            self.parts = [SerialPWASCore(pp, pipeline=base, round_output=False) for pp in part_params]
        else:
            pipes = equal_latency_pipelines(base, [pp.n for pp in part_params])
            self.parts = [PWASCore(pp, memory=memory, pipeline=pl, round_output=False) for pp, pl in zip(part_params, pipes)]
        for c in self.parts:
            c._MustUse__silence = True  # built into the part modules by build_into, never elaborated alone
        self.pipeline = base
        self.memory_kind = SINGLE_MEMORY if architecture == "serial" else memory
        self.memory_plan = AdditiveMemoryPlan(tuple(c.memory_plan for c in self.parts))
        self.argmax = argmax  # a classifier's stage after the sum (elaborate only; build_into is the sum alone)
        cycles, index_bits = argmax_extent(argmax, int(model.nz) * int(model.output_format.bits) + 1)
        part_latency = max(c.latency for c in self.parts)
        self.lead = next(i for i, c in enumerate(self.parts) if c.latency == part_latency)
        self.latency = part_latency + 1 + cycles
        self.ii = max(c.ii for c in self.parts)
        self.params = AdditiveParams(
            partitions=tuple(int(v) for v in model.grid.partitions), in_width=int(model.input_bits),
            lo_code=tuple(int(v) for v in model.lo_codes), frac_bits=tuple(int(v) for v in model.frac_bits),
            weight_width=int(model.weight_format.bits), weight_frac=int(model.weight_format.frac),
            out_width=int(model.output_format.bits), out_frac=int(model.output_format.frac), nz=int(model.nz),
            rounding=str(model.rounding), sum_width=int(model.sum_bits))
        if self.params.shift >= self.params.sum_width:
            raise InputError(f"the output shift {self.params.shift} drops every bit of the {self.params.sum_width}-bit sum; "
                             "use a larger output_frac")
        for c, a in zip(self.parts, self.align):
            if c.out_field_width + a > self.params.sum_width:
                raise InternalError("an aligned part accumulator is wider than the sum")
        super().__init__({
            "in": In(stream.Signature(unsigned(self.params.n * self.params.in_width))),
            "out": Out(stream.Signature(unsigned(self.params.nz * self.params.out_width + 1 + index_bits))),
        })
        self._MustUse__silence = False

    def elaborate(self, platform: Any) -> Module:
        """The additive datapath's logic: the parts' cores in parallel, their exact sum and one rounding
        (then a classifier's argmax stage, if any).

        Parameters
        ----------
        platform : Any
            Amaranth build platform (the datapath does not depend on it).

        Returns
        -------
        Module
        """
        from pwas_hdl.hdl.classifier_top import inline_core_and_argmax

        m = Module()
        inp = getattr(self, "in")
        inline_core_and_argmax(m, self, self.argmax, inp.payload, inp.valid, inp.ready, self.out)
        return m

    def build_into(self, m: Module, payload: Value, valid: Value, advance: Signal, out: Any) -> None:
        """Add the parts (as submodules ``part<i>``), the sum and the rounding to ``m``.

        Parallel: each part's :meth:`PWASCore.build_into` (equal latencies, ``advance`` = part 0's
        input enable). Serial: one :func:`~pwas_hdl.hdl.serial_core.serial_throttle` (``advance =
        sum_advance & (gap == 0)``, one transfer every :attr:`ii` cycles) and each part's
        :meth:`SerialPWASCore.build_datapath` on the same ``take`` and ``sum_advance``. Then, for
        both, the sum register reads the parts' output registers when the part :attr:`lead`'s
        ``valid`` is high.

        Parameters
        ----------
        m : Module
            Module the parts (submodules ``part<i>``), sum and rounding are added to.
        payload, valid, advance, out
            The interface of :meth:`PWASCore.build_into`: ``payload`` (``n*B_in`` bits) and
            ``valid`` the input sample, ``advance`` a 1-bit signal driven here (the input is
            taken when ``valid & advance``), ``out`` the output stream (payload and valid driven
            here).
        """
        p = self.params
        b = p.in_width
        nz, big_w, outw, sh = p.nz, p.sum_width, p.out_width, p.shift
        serial = self.architecture == "serial"
        adv = Signal(name="sum_advance")
        m.d.comb += adv.eq(~out.valid | out.ready)
        # serial: one throttle for all parts (the largest part's II); they take each sample together
        take = serial_throttle(m, self.ii - 1, adv, valid, advance) if serial else None
        # one net per regressor code, read by the parts that use it (a process output, so that each
        # part's ports are exactly the codes it reads; its value while valid = 0 is never used)
        xs = []
        for j in range(p.n):
            x = Signal(b, name=f"x{j}")
            with m.If(valid):
                m.d.comb += x.eq(payload[j * b : (j + 1) * b])
            xs.append(x)
        used = sorted({j for sub in self.subsets for j in sub})
        for j in sorted(set(range(p.n)) - set(used)):  # a regressor in no part: read by no one
            sink_unused(m, xs[j], f"x{j}")
        outs = []
        for i, (core, sub) in enumerate(zip(self.parts, self.subsets)):
            mi = Module()
            m.submodules[f"part{i}"] = mi
            o = _Out(f"part{i}", core.out_field_width * nz + 1, adv)
            q = Cat(*[xs[j] for j in sub])
            if serial:  # the shared throttle's take and advance (a shorter part's sum waits in its output register)
                core.build_datapath(mi, q, take, adv, o)
            else:
                part_adv = advance if i == 0 else Signal(name=f"part{i}_advance")  # all equal: equal latency and inputs
                core.build_into(mi, q, valid, part_adv, o)
            outs.append(o)
        lead = outs[self.lead]  # its valid is the sum's (parallel: every part's valid is the same)

        zs = []
        for z in range(nz):
            terms = []
            for i, (core, o) in enumerate(zip(self.parts, outs)):
                fw = core.out_field_width
                acc = o.payload[z * fw : (z + 1) * fw].as_signed()
                a = self.align[i]
                t = Signal(signed(big_w), name=f"term{z}_{i}")
                with m.If(lead.valid):  # a process output: a genuine W-bit net (see _lintsafe)
                    m.d.comb += t.eq(Cat(Const(0, a), acc).as_signed() if a else acc)
                terms.append(t)

            def add(x, y, lvl, k, z=z):
                s = Signal(signed(big_w + 1), name=f"psum{lvl}_{z}_{k}")
                m.d.comb += s.eq(x.as_signed() + y.as_signed())
                sink_unused(m, s[big_w], f"psum{lvl}_{z}_{k}_top")
                return s[:big_w]

            total = tree_reduce(terms, add)
            zs.append(self._round(m, total, z))
        oor = outs[0].payload[-1]
        for o in outs[1:]:
            oor = oor | o.payload[-1]
        with m.If(adv):
            m.d.sync += out.payload.eq(Cat(*zs, oor))
            m.d.sync += out.valid.eq(lead.valid)

    def _round(self, m: Module, acc, z: int):
        """``clip((acc + 2**(sh-1)) >> sh)`` (half up) or ``clip(acc >> sh)`` (truncate) to ``B_out`` bits."""
        p = self.params
        sh, outw = p.shift, p.out_width
        if sh > 0:
            rs = acc.as_unsigned()
            if p.rounding == "half_up":
                rs = add_const_wrap(m, rs, 1 << (sh - 1), f"sum_rnd{z}")  # no wrap: |acc| < 2**(W-2)
            sink_unused(m, rs[:sh], f"sum_rnd{z}_frac")
            rv = rs[sh:].as_signed()
        else:
            rv = acc.as_signed()
        if len(rv) <= outw:
            return rv.as_signed()
        sign = rv[-1]
        upper = rv[outw - 1 : len(rv) - 1]
        o = Signal(signed(outw), name=f"sum_sat{z}")
        with m.If(~sign & upper.any()):
            m.d.comb += o.eq((1 << (outw - 1)) - 1)
        with m.Elif(sign & ~upper.all()):
            m.d.comb += o.eq(-(1 << (outw - 1)))
        with m.Else():
            m.d.comb += o.eq(rv[:outw])
        return o

    @property
    def extra_info(self) -> dict:
        """Manifest entries of the core: ``additive`` (:meth:`additive_info`)."""
        return {"additive": self.additive_info()}

    def additive_info(self) -> dict:
        """The parts of the hardware: subsets, pipelines, latencies and memories (for the manifest).

        Returns
        -------
        dict
            ``parts`` (per part: module suffix, regressor indices, latency in cycles, pipeline,
            accumulator bits, alignment shift in bits, memory), ``sum_bits``, ``latency`` (a
            sentence: part latency + 1).
        """
        latency = ("part latency + 1 (the sum, rounding and saturation register)" if self.architecture != "serial" else
                   f"the largest part's latency + 1 (the sum, rounding and saturation register); the parts take each "
                   f"sample together, one every {self.ii} cycles, and a shorter part's sum waits in its output register")
        return {
            "parts": [
                {"module_suffix": f"_part{i}", "regressors": [int(j) for j in sub], "latency": int(c.latency),
                 "pipeline": c.pipeline.to_dict(), "acc_bits": int(c.out_field_width), "align_shift": int(a),
                 "memory": c.memory_plan.to_dict()}
                for i, (c, sub, a) in enumerate(zip(self.parts, self.subsets, self.align))
            ],
            "sum_bits": int(self.params.sum_width),
            "latency": latency,
        }

    def flow_control(self, names: dict) -> dict:
        """The serial design's input throttle, in words (nothing for the parallel one).

        Parameters
        ----------
        names : dict of str to str
            Port names by role (:func:`~pwas_hdl.hdl.emit.port_names`).

        Returns
        -------
        dict of str to str
            Merged into the manifest's ``flow_control`` (:func:`~pwas_hdl.hdl.api.design_info`).
        """
        if self.architecture != "serial":
            return {}
        return {**self.parts[self.lead].flow_control(names), names["in.ready"]:
                f"advance & (gap == 0): one transfer every {self.ii} advancing cycles at most (II = n + 1 of the "
                "largest part); gap counts the advancing cycles since the last transfer"}


class AdditiveSensorTop(PWASSensorTop):
    """Lag bank (:class:`~pwas_hdl.hdl.sensor_top.PWASSensorTop`: its elaborate, ports, warm-up and
    flow control) + :class:`AdditiveCore` (``core``) in place of the single core.

    Parameters
    ----------
    model : AdditiveFixedPointModel
        The bit-true additive model (as :class:`AdditiveCore`).
    signals : sequence of (name, n_lags)
        The lag bank's signals in payload order (:func:`~pwas_hdl.hdl.sensor_top.lag_plan`).
    dims : sequence of (signal index, lag)
        One per regressor dimension of the whole sensor, lag in samples (0: the current sample).
    memory, pipeline, architecture
        As :class:`AdditiveCore`.
    argmax : ArgmaxStage, optional
        A classifier's stage after the sum, inlined by the sensor top's elaborate
        (:class:`~pwas_hdl.hdl.sensor_top.PWASSensorTop`).

    Raises
    ------
    InputError
        ``dims`` does not have one entry per regressor (``n``).
    InputError, InternalError
        As :class:`AdditiveCore`.
    """

    kind = "sensor"

    def __init__(self, model: AdditiveFixedPointModel, signals: Sequence[tuple[str, int]], dims: Sequence[tuple[int, int]], *,
                 memory: str = "banked", pipeline: Pipeline | str | None = None, argmax: Any = None,
                 architecture: str = "parallel"):
        self._MustUse__silence = True
        # the sum alone: the top inlines the stage
        self.core = AdditiveCore(model, memory=memory, pipeline=pipeline, architecture=architecture)
        self.core._MustUse__silence = True
        self.argmax = argmax  # a classifier's stage after the sum (PWASSensorTop.elaborate inlines it)
        self.params = self.core.params
        self.signals = [(str(nm), int(k)) for nm, k in signals]
        self.dims = [(int(s), int(lag)) for s, lag in dims]
        if len(self.dims) != self.params.n:
            raise InputError(f"{len(self.dims)} lag-bank dimensions for a sensor with n = {self.params.n}")
        cycles, index_bits = argmax_extent(argmax, self.params.nz * self.params.out_width + 1)
        self.latency = self.core.latency + cycles
        self.ii = self.core.ii
        self.memory_plan = self.core.memory_plan
        self.pipeline = self.core.pipeline
        self.warmup = max(k for _, k in self.signals) - 1
        wiring.Component.__init__(self, {  # the sensor top's signature; its __init__ builds a single core
            "in": In(stream.Signature(unsigned(len(self.signals) * self.params.in_width))),
            "out": Out(stream.Signature(unsigned(self.params.nz * self.params.out_width + 1 + index_bits))),
            "warm": Out(1),
        })
        self._MustUse__silence = False

    @property
    def extra_info(self) -> dict:
        """The sensor top's manifest entries (lags, warm-up) plus ``additive``."""
        return {**super().extra_info, "additive": self.core.additive_info()}


def build_additive_core(model: AdditiveFixedPointModel, *, memory: str = "banked", pipeline: Pipeline | str | None = None,
                        name: str = "pwas_core", classifier: dict | None = None,
                        architecture: str = "parallel") -> AdditiveCore:
    """The additive core of an :class:`~pwas_hdl.fixedpoint.additive.AdditiveFixedPointModel` (input: regressor codes).

    Parameters
    ----------
    model : AdditiveFixedPointModel
        The bit-true additive model.
    memory, pipeline, architecture
        As :class:`AdditiveCore`.
    name : str
        Verilog module name (not checked here; :func:`emit_additive_verilog` checks it).
    classifier : dict, optional
        ``{"target": name, "classes": [labels]}`` of a classifier model (``sensor.classifier_``):
        the argmax stage after the sum (:func:`~pwas_hdl.hdl.api.classifier_stage`); the output
        payload then ends with the class index (parallel or serial: the stage's registers advance
        with its own output's handshake, the sum register feeds it).

    Returns
    -------
    AdditiveCore
        With ``module_name``, ``input_names``, ``target_names`` and ``classifier`` set.

    Raises
    ------
    InputError
        No equal-latency pipelines exist, the output shift drops the whole sum, or not one class
        per score target.
    """
    core = AdditiveCore(model, memory=memory, pipeline=pipeline, argmax=_argmax(classifier, model, pipeline),
                        architecture=architecture)
    core.classifier = dict(classifier) if classifier is not None else None
    core.module_name = name
    core._MustUse__silence = True
    core.input_names = list(model.regressor_names)
    core.target_names = list(model.target_names)
    return core


def _argmax(classifier: dict | None, model: AdditiveFixedPointModel, pipeline: Pipeline | str | None) -> Any:
    """A classifier's argmax stage after the additive sum (None without a classifier), of either
    architecture (:func:`~pwas_hdl.hdl.api.classifier_stage`)."""
    if classifier is None:
        return None
    from pwas_hdl.hdl.api import classifier_stage

    params = SimpleNamespace(nz=int(model.nz), out_width=int(model.output_format.bits))  # what the stage reads
    return classifier_stage(classifier, params, Pipeline.cast(pipeline))


def build_additive_sensor(model: AdditiveFixedPointModel, lags: LagStructure | None = None, *, memory: str = "banked",
                          pipeline: Pipeline | str | None = None, name: str = "pwas_sensor",
                          classifier: dict | None = None, architecture: str = "parallel") -> AdditiveSensorTop:
    """The additive virtual-sensor top (one lag bank, the parts' cores, the sum) of an additive bit-true model.

    Parameters
    ----------
    model : AdditiveFixedPointModel
        The bit-true additive model.
    lags : LagStructure, optional
        As :func:`~pwas_hdl.hdl.sensor_top.lag_plan` (default: from ``model.regressor_signals``).
    memory, pipeline, architecture
        As :class:`AdditiveCore`.
    name : str
        Verilog module name.
    classifier : dict, optional
        As :func:`build_additive_core`.

    Returns
    -------
    AdditiveSensorTop

    Raises
    ------
    InputError
        The lags of a signal have different input formats
        (``model.signal_input_formats``), recurrent ``lags``, or as :func:`build_additive_core`.
        As :func:`~pwas_hdl.hdl.sensor_top.lag_plan` (``lags`` that do not match the model).
    """

    model.signal_input_formats()  # raises unless all lags of each signal share one format
    signals, dims = lag_plan(model, lags)
    top = AdditiveSensorTop(model, signals, dims, memory=memory, pipeline=pipeline,
                            argmax=_argmax(classifier, model, pipeline), architecture=architecture)
    top.classifier = dict(classifier) if classifier is not None else None
    top.module_name = name
    top._MustUse__silence = True
    top.core.input_names = list(model.regressor_names)
    top.core.target_names = list(model.target_names)
    return top


#: A name inside a flattened part: ``\\part<i>.<name> `` (Yosys' escaped hierarchical identifier).
_FLAT_NAME = re.compile(r"\\(?P<flat>\$flatten\\)?part(?P<i>[0-9]+)\.(?P<name>[A-Za-z0-9_$]+) ")


def _flat_name(mo: re.Match) -> str:
    """``\\part3.c0 `` -> ``part3_c0``; Yosys' internal ``\\$flatten\\part3.$7 `` -> ``\\$part3_$7 `` (escaped, as
    the other internal ``\\$<k> `` names of the output)."""
    base = f"part{mo.group('i')}_{mo.group('name')}"
    if mo.group("flat") or not re.match(r"[A-Za-z_]", mo.group("name")):
        return f"\\${base} "
    return base


def _flat_verilog(component, name: str):
    """Amaranth's Verilog conversion (:mod:`pwas_hdl.hdl.yosys_convert`: RTLIL, then Yosys'
    ``proc -nomux -norom; memory_collect; write_verilog -norename``) with the part modules flattened
    into the top (Yosys ``flatten`` after ``proc``): one module, as every other design of pwas-hdl.
    Returns the text with the weight ROMs as black boxes and their registry
    (:func:`~pwas_hdl.hdl.yosys_convert.component_verilog_roms`)."""
    from pwas_hdl.hdl.yosys_convert import CONVERT_PASSES, component_verilog_roms

    return component_verilog_roms(component, name, (CONVERT_PASSES[0], "flatten", *CONVERT_PASSES[1:]))


def emit_additive_verilog(component: AdditiveCore | AdditiveSensorTop, name: str, *, memory_init: str = "inline",
                          hex_prefix: str = "w", ports: str = "axis") -> str:
    """Verilog of an additive design: one module ``name`` (the parts flattened into it).

    As :func:`pwas_hdl.hdl.emit.emit_verilog` (same normalisation, port order, ``ports`` naming and
    ``memory_init``); the parts' names ``\\part<i>.<name>`` become plain identifiers
    ``part<i>_<name>``, so the weight memories are ``part<i>_wmem<b>``. Deterministic.

    Parameters
    ----------
    component : AdditiveCore or AdditiveSensorTop
        The additive design.
    name : str
        Module name.
    memory_init : {"inline", "readmemh"}
        ``"inline"``: every ``part<i>_wmem<b>`` is initialised by assignments in an ``initial``
        block. ``"readmemh"``: ``initial $readmemh({MEM_DIR, "<hex_prefix>_p<i>_b<b>.hex"},
        part<i>_wmem<b>, ...);`` -- the files of :func:`pwas_hdl.hdl.emit.memory_hex_files` -- with the module
        parameter ``MEM_DIR`` (default ``"./"``) as in :func:`~pwas_hdl.hdl.emit.emit_verilog`.
    hex_prefix : str
        File-name prefix of the ``.hex`` files (``memory_init="readmemh"`` only).
    ports : {"axis", "amaranth"}
        Port naming (:func:`~pwas_hdl.hdl.emit.port_names`).

    Returns
    -------
    str
        The Verilog text (first line: the Yosys version).

    Raises
    ------
    InputError
        ``name`` is not a plain Verilog identifier, an unknown ``memory_init`` or ``ports``, or a
        ``hex_prefix`` that is not a plain file-name prefix.
    InternalError
        Flattening leaves a name clash, a hierarchical name or more than one module; a weight
        memory is not one of a part's memory plan or does not hold its words (``readmemh``).
    """
    from pwas_hdl.hdl.emit import _check_memory_init, _check_naming, _name_ports, _splice_weights, _token, normalise_verilog

    check_module_name(name, "module name")
    _check_memory_init(memory_init, hex_prefix)
    _check_naming(ports)
    text, roms = _flat_verilog(component, name)  # the ROMs' words are written last (splice_roms)
    renamed = {_flat_name(mo) for mo in _FLAT_NAME.finditer(text)}
    clash = sorted(nm for nm in renamed if not nm.startswith("\\") and _token(nm).search(text))
    if clash:
        raise InternalError(f"flattening the additive parts would reuse the name(s) {clash[:3]}")
    text = _FLAT_NAME.sub(_flat_name, text)
    if re.search(r"\\\S*\\", text):
        raise InternalError("a hierarchical name is left in the flattened additive design")
    if re.search(r"^module ", text, re.M) is None or len(re.findall(r"^module ", text, re.M)) != 1:
        raise InternalError("the flattened additive design is not one module")
    return _splice_weights(_name_ports(normalise_verilog(text), name, component, ports), roms, component, memory_init, hex_prefix)
