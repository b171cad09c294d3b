"""Argmax stage: the class index of ``C`` signed scores, as an Amaranth stream component.

Placed after the PWAS core of a classifier (``C = nz`` one-hot score targets sharing one locator),
or after any block that outputs ``C`` codes side by side (e.g. the residuals of an observer bank,
with ``select="min"``). Its bit-true specification is :mod:`pwas_hdl.fixedpoint.argmax`:

* pairwise compare tree in the order of :mod:`pwas_hdl.fixedpoint.reduction`; a node keeps the
  upper block's winner ``b`` only if ``v_b > v_a`` (``select="min"``: ``v_b < v_a``), so ties go to
  the **lowest class index** (``numpy.argmax``);
* ``ceil(log2 C)`` compare levels; pipeline registers as the core's adder tree
  (:class:`~pwas_hdl.hdl.params.Pipeline` ``tree_levels``): with ``tree_levels = t > 0`` a register
  after every ``t`` levels and after the last one (``ceil(levels / t)`` cycles), with
  ``tree_levels = 0`` (preset ``min``) none: the index is combinational from the input payload
  (the core's output register) and the stage adds no latency;
* flow control as the core's (one global enable): ``advance = ~out.valid | out.ready``,
  ``in.ready = advance``; only the valid bits are reset. Without registers ``out.valid = in.valid``
  and ``in.ready = out.ready``.

Payloads (flat unsigned vectors, LSB first)::

    in.payload  = scores (C signed `width`-bit codes, score i at [i*width +: width]) | extra bits
    out.payload = in.payload (unchanged, delayed with the index) | index (index_width bits)

``extra_bits`` are carried through untouched (the core's ``out_of_range`` flag), so the output
holds the scores, the flags and, in its top ``index_width`` bits, the class index.
"""

from __future__ import annotations

from typing import Any

from types import SimpleNamespace

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from pwas_hdl.errors import InputError
from pwas_hdl.fixedpoint.argmax import SELECT, compare_levels, index_width
from pwas_hdl.fixedpoint.reduction import tree_level
from pwas_hdl.hdl.params import Pipeline

__all__ = ["ArgmaxStage", "argmax_latency", "inner_stream"]


def argmax_latency(n_classes: int, pipeline: Pipeline | str | None = None) -> int:
    """Cycles the argmax stage adds: ``ceil(ceil(log2 C) / tree_levels)``, 0 when ``tree_levels = 0``.

    Parameters
    ----------
    n_classes : int
        Number of scores ``C`` (0 when ``C = 1``: no compare level).
    pipeline : Pipeline, preset name or None
        Its ``tree_levels`` counts; default balanced.

    Returns
    -------
    int
        Latency in clock cycles.
    """
    pl = Pipeline.cast(pipeline)
    levels = compare_levels(n_classes)
    if pl.tree_levels == 0 or levels == 0:
        return 0
    return -(-levels // pl.tree_levels)


def inner_stream(width: int, prefix: str) -> SimpleNamespace:
    """``payload`` / ``valid`` / ``ready`` signals joining two inlined stages (names ``<prefix>_*``).

    Parameters
    ----------
    width : int
        Payload bits.
    prefix : str
        Signal name prefix.

    Returns
    -------
    types.SimpleNamespace
        ``payload`` (unsigned ``width``, reset-less), ``valid``, ``ready`` (1 bit).
    """
    return SimpleNamespace(payload=Signal(unsigned(width), name=f"{prefix}_payload", reset_less=True),
                           valid=Signal(name=f"{prefix}_valid"), ready=Signal(name=f"{prefix}_ready"))


class ArgmaxStage(wiring.Component):
    """Index of the best of ``n_inputs`` signed scores, pipelined, II = 1.

    Parameters
    ----------
    n_inputs : int
        Number of scores ``C >= 1`` (classes).
    width : int
        Bits of each score code (the core's ``B_out``).
    signed : bool
        Scores are two's complement (default) or unsigned.
    extra_bits : int
        Payload bits above the scores carried through unchanged (e.g. ``out_of_range``).
    pipeline : Pipeline, preset name or None
        Its ``tree_levels`` places the registers (see the module docstring); default balanced.
    select : {"max", "min"}
        Largest (default) or smallest score wins; ties to the lowest index either way.

    Ports: ``in`` (stream of ``C*width + extra_bits`` bits), ``out`` (stream of
    ``C*width + extra_bits + index_width`` bits: the input payload, then the index).

    Attributes
    ----------
    latency : int
        Cycles from an input transfer to its output (no stalls), :func:`argmax_latency`.
    ii : int
        1.
    index_width : int
        ``max(1, ceil(log2 C))``.
    index_lsb : int
        Bit of the output payload where the index starts (``C*width + extra_bits``).

    Raises
    ------
    InputError
        ``n_inputs < 1``, ``width < 1``, ``extra_bits < 0``, an unknown ``select``, or an invalid
        ``pipeline`` (:meth:`Pipeline.cast`).
    TypeError
        ``pipeline`` of another type (:meth:`Pipeline.cast`).
    """

    #: The option of ``pipeline`` whose registers the stage builds (when it has a compare level)
    pipeline_registers = ("tree_levels",)

    def __init__(self, n_inputs: int, width: int, *, signed: bool = True, extra_bits: int = 0,
                 pipeline: Pipeline | str | None = None, select: str = "max"):
        self._MustUse__silence = True  # no "never used" warning for an object whose __init__ raised
        if int(n_inputs) < 1:
            raise InputError(f"an argmax stage needs at least one input, got {n_inputs}")
        if int(width) < 1 or int(extra_bits) < 0:
            raise InputError(f"width must be >= 1 and extra_bits >= 0, got {width}, {extra_bits}")
        if select not in SELECT:
            raise InputError(f"select must be one of {', '.join(SELECT)}, got {select!r}")
        self.n_inputs = int(n_inputs)
        self.width = int(width)
        self.signed = bool(signed)
        self.extra_bits = int(extra_bits)
        self.select = select
        self.pipeline = Pipeline.cast(pipeline)
        self.index_width = index_width(self.n_inputs)
        self.index_lsb = self.n_inputs * self.width + self.extra_bits
        self.latency = argmax_latency(self.n_inputs, self.pipeline)
        self.ii = 1
        super().__init__({
            "in": In(stream.Signature(unsigned(self.index_lsb))),
            "out": Out(stream.Signature(unsigned(self.index_lsb + self.index_width))),
        })
        self._MustUse__silence = False

    def scores_stream(self, out: Any, prefix: str = "scores") -> SimpleNamespace:
        """The stream that the block before an inlined stage drives, for :meth:`build_into`.

        Parameters
        ----------
        out : stream interface
            The stage's own output stream (its ``valid`` / ``ready`` are reused at latency 0).
        prefix : str
            Name prefix of the new signals.

        Returns
        -------
        types.SimpleNamespace
            With registers: new ``<prefix>_payload`` / ``_valid`` / ``_ready`` signals
            (:func:`inner_stream`). Without (latency 0): a new payload signal but ``out``'s own
            valid and ready, so that no signal merely aliases another (Verilator's UNUSEDSIGNAL).
        """
        if self.latency:
            return inner_stream(self.index_lsb, prefix)
        return SimpleNamespace(payload=Signal(unsigned(self.index_lsb), name=f"{prefix}_payload", reset_less=True),
                               valid=out.valid, ready=out.ready)

    def elaborate(self, platform: Any) -> Module:
        """The pipelined argmax logic (ties to the lowest index).

        Parameters
        ----------
        platform : Any
            Amaranth build platform; unused here.

        Returns
        -------
        Module
            :meth:`build_into` on the stage's own ports.
        """
        m = Module()
        inp = getattr(self, "in")
        self.build_into(m, inp.payload, inp.valid, inp.ready, self.out)
        return m

    def build_into(self, m: Module, payload: Value, valid: Value, advance: Signal, out: Any) -> None:
        """Add the stage's logic to ``m`` (its own :meth:`elaborate`, or inlined after a core).

        Parameters
        ----------
        m : Module
            Module the compare tree and its registers are added to.
        payload : Value
            The scores and extra bits (``index_lsb`` bits).
        valid : Value
            Valid bit of ``payload``.
        advance : Signal
            1 bit, driven here (the input is taken when ``valid & advance``).
        out : stream interface
            Output stream: ``payload`` and ``valid`` driven here, ``ready`` read.
        """
        w, iw, levels = self.width, self.index_width, compare_levels(self.n_inputs)
        tl = self.pipeline.tree_levels
        regs: list = []
        valids: list = []

        def score(i):
            s = payload[i * w : (i + 1) * w]
            return s.as_signed() if self.signed else s

        def as_index(v):
            return Const(v, iw) if isinstance(v, int) else v

        def node(a, b, lvl, i):
            (ia, va), (ib, vb) = a, b
            gt = Signal(name=f"am_better{lvl}_{i}")
            m.d.comb += gt.eq(vb > va if self.select == "max" else vb < va)
            idx = Signal(unsigned(iw), name=f"am_index{lvl}_{i}")
            m.d.comb += idx.eq(Mux(gt, as_index(ib), as_index(ia)))
            if lvl == levels - 1:  # the root: only its index is used
                return idx, None
            val = Signal(va.shape(), name=f"am_value{lvl}_{i}")
            m.d.comb += val.eq(Mux(gt, vb, va))
            return idx, val

        items = [(i, score(i)) for i in range(self.n_inputs)]
        data = payload
        for lvl in range(levels):
            items = tree_level(items, node, lvl)
            last = lvl == levels - 1
            if tl and (lvl + 1) % tl == 0 and not last:
                # an intermediate register: the remaining (index, value) pairs and the payload
                new = []
                for k, (ix, vx) in enumerate(items):
                    if not isinstance(ix, int):
                        r = Signal(unsigned(iw), name=f"am_s{lvl}_index{k}", reset_less=True)
                        regs.append((r, ix))
                        ix = r
                    rv = Signal(vx.shape(), name=f"am_s{lvl}_value{k}", reset_less=True)
                    regs.append((rv, vx))
                    new.append((ix, rv))
                items = new
                rd = Signal(unsigned(len(data)), name=f"am_s{lvl}_payload", reset_less=True)
                regs.append((rd, data))
                data = rd
                v = Signal(name=f"am_s{lvl}_valid")
                valids.append((v, valid))
                valid = v
        index = as_index(items[0][0])
        result = Cat(data, index)
        if self.latency == 0:
            m.d.comb += out.payload.eq(result)
            if valid is not out.valid:  # (a scores_stream() shares them: nothing to connect)
                m.d.comb += out.valid.eq(valid)
            if advance is not out.ready:
                m.d.comb += advance.eq(out.ready)
            return
        m.d.comb += advance.eq(~out.valid | out.ready)
        regs.append((out.payload, result))
        valids.append((out.valid, valid))
        with m.If(advance):
            m.d.sync += [dst.eq(src) for dst, src in regs]
            m.d.sync += [dst.eq(src) for dst, src in valids]
