"""The serial ("small") PWAS core: one multiplier per target, ``n + 1`` cycles per sample.

The MOBY-DIC serial architecture (issue 15, item 2) for small devices such as an iCE40 UP5K. It
computes exactly what the parallel core (:class:`pwas_hdl.hdl.core.PWASCore`) computes -- the same
bit-true model (:class:`pwas_hdl.fixedpoint.bittrue.FixedPointModel`), bit for bit -- with one
multiply-accumulate unit per target and one weight memory of ``N`` words instead of ``n + 1``
banks and an adder tree.

Data path::

    in.payload (n codes) -> scale/clamp/split -> rank -> n+1 vertex addresses + mu   (PWASCore._vertices)
        -> load register (n+1 addresses, n+1 mu) -> one vertex per cycle, k = 0 .. n
        -> one synchronous memory read (N words, all targets in one word)
        -> [mem_out register] -> one multiplier per target -> [product register]
        -> accumulator (k = 0 loads, k > 0 adds) -> rounding + saturation -> out.payload

The front end is the parallel core's own (:meth:`PWASCore._vertices` with the replicated
addressing: the address of a vertex is its linear index in the vertex order of
:mod:`pwas_hdl.fit.geometry`), with the same optional ``split`` / ``rank`` / ``addr`` registers;
the rounding is the parallel core's own (:meth:`PWASCore._round`). The sum of the ``n + 1``
products is accumulated in vertex order instead of the adder tree's order: integer sums are
exact (every partial sum fits ``F + B_w`` signed bits, see :mod:`pwas_hdl.hdl.core`), so the
accumulator equals the tree's sum and the one rounding step gives identical output codes.

Flow control (one global enable, as the parallel core, plus an input throttle)::

    advance  = ~out.valid | out.ready          (every register and the memory read port)
    in.ready = advance & (gap == 0)            (gap: n .. 0, counts advancing cycles after a transfer)

so the input accepts at most one sample every ``n + 1`` advancing cycles (II = n + 1 at full
speed); a stalled sink stops everything, including the throttle. A valid sample reaches the
load register exactly ``n + 1`` or more advancing cycles after the previous one, when the
previous sample's last vertex is being read: the load never overwrites a vertex still to be read.

Latency (input transfer to ``out.valid``, no stalls): ``split + rank + offset + addr + 1 (load) + n
(vertices 1..n) + 1 (memory) + mem_out + product + 1 (accumulator) + 1 (output)``
(:func:`serial_latency`); the
``tree_levels`` and ``mul_in`` options do not apply (no adder tree; the multiplier operands come
straight from the memory register or ``mem_out``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from amaranth.hdl import Const, Module, Signal, Value, signed, unsigned

from pwas_hdl.errors import InputError, InternalError
from pwas_hdl.hdl._lintsafe import add_const_wrap, add_wrap, bits_for, sink_unused
from pwas_hdl.hdl.core import PWASCore, _Pipe
from pwas_hdl.hdl.params import CoreParams, MemoryPlan, Pipeline
from pwas_hdl.fixedpoint.memory_layout import SINGLE_MEMORY, weight_memory_name
from pwas_hdl.hdl.weight_rom import weight_rom

__all__ = ["SerialPWASCore", "SingleMemoryPlan", "ARCHITECTURES", "SERIAL_REGISTERS", "serial_latency", "serial_throttle"]

#: The values of ``generate --architecture``.
ARCHITECTURES = ("parallel", "serial")

#: The registers of a :class:`~pwas_hdl.hdl.params.Pipeline` the serial core builds (front end, memory
#: data, product); ``bank``, ``mul_in``, ``mul_halves`` and ``tree_levels`` do not apply (no banks,
#: the multiplier operands straight from the memory register, no adder tree).
SERIAL_REGISTERS = ("split", "rank", "offset", "addr", "mem_out", "product")


def serial_latency(pipeline: Pipeline, n: int) -> int:
    """Cycles from an input transfer to its output in the serial core (no stalls).

    Parameters
    ----------
    pipeline : Pipeline
        Its :data:`SERIAL_REGISTERS` apply (``split``, ``rank``, ``offset``, ``addr``, ``mem_out``,
        ``product``); ``tree_levels``, ``mul_in``, ``mul_halves`` and ``bank`` do not.
    n : int
        Regressor dimension.

    Returns
    -------
    int
        Latency in clock cycles (the ``n + 1`` multiply-accumulate steps included).
    """
    # the registers of SERIAL_REGISTERS + load + vertices 1..n + memory + accumulator + output
    return sum(int(getattr(pipeline, k)) for k in SERIAL_REGISTERS) + 1 + n + 1 + 1 + 1


class SingleMemoryPlan(MemoryPlan):
    """One weight memory of ``N`` words, address = linear vertex index (C order, last dimension
    fastest), each word packing all ``nz`` targets (target 0 in the LSBs).

    The ``layout`` is the replicated layout of the grid (whose copy 0 is exactly this memory);
    only one copy exists.

    Attributes
    ----------
    layout : ReplicatedLayout
        The grid's replicated layout (depth ``N``, address = linear vertex index; built by :meth:`build`).
    word_bits : int
        Bits of one packed word, ``nz * B_w``.
    contents : tuple of tuple of int
        One entry (the one memory) of ``N`` packed words.
    """

    @property
    def kind(self) -> str:
        """Always ``"single"`` (:data:`~pwas_hdl.fixedpoint.memory_layout.SINGLE_MEMORY`)."""
        return SINGLE_MEMORY

    @property
    def n_banks(self) -> int:
        """Always 1."""
        return 1

    @property
    def words(self) -> int:
        """``N``: one word per vertex."""
        return self.depth

    @classmethod
    def build(cls, p: CoreParams, kind: str = "single") -> "SingleMemoryPlan":
        """The single memory of ``p``'s grid and weight codes.

        Parameters
        ----------
        p : CoreParams
            Grid, weight codes ``(N, nz)`` and weight width ``B_w``.
        kind : str
            Not used (always the single memory; the argument keeps the signature of
            :meth:`MemoryPlan.build`).

        Returns
        -------
        SingleMemoryPlan
            ``N`` words of ``nz * B_w`` bits.
        """
        from pwas_hdl.fixedpoint.bitfields import pack_rows
        from pwas_hdl.fixedpoint.memory_layout import make_layout

        layout = make_layout(p.grid, "replicated")  # depth N, address = linear vertex index
        words = tuple(pack_rows(np.asarray(p.weights, dtype=np.int64), p.weight_width))
        return cls(layout, p.nz * p.weight_width, (words,))

    def layout_spec(self) -> dict:
        """The manifest's ``memory.layout_spec`` of the serial design.

        Returns
        -------
        dict
            ``kind``, ``memories`` (1), ``depth`` (words), ``address`` (a sentence: how a vertex's
            address is formed).
        """
        return {"kind": SINGLE_MEMORY, "memories": 1, "depth": int(self.depth),
                "address": "linear vertex index (C order, last dimension fastest)"}


class SerialPWASCore(PWASCore):
    """Serial PWAS evaluator: one regressor every ``n + 1`` clocks, ``nz`` estimates out.

    Parameters
    ----------
    params : CoreParams
        The core's parameters (those of the parallel core).
    pipeline : Pipeline, preset name ("min", "balanced", "max") or None (balanced)
        ``split``, ``rank``, ``offset``, ``addr`` (front end), ``mem_out`` and ``product``
        registers apply (:func:`serial_latency`).
    memory : str
        Must be ``"single"`` (the one memory of ``N`` words); accepted for the signature of
        :class:`~pwas_hdl.hdl.core.PWASCore`.
    round_output : bool
        ``False``: no rounding or saturation; the output register holds the exact accumulator,
        ``acc_width + 1`` signed bits per target (``out_field_width``), as the parallel core's
        (the parts of a serial additive design, :mod:`pwas_hdl.hdl.additive_top`).

    Ports: as :class:`~pwas_hdl.hdl.core.PWASCore` (``in.ready`` is low while a sample is in the
    multiply-accumulate loop).

    Raises
    ------
    InputError
        ``memory`` other than ``"single"``, or as :class:`~pwas_hdl.hdl.core.PWASCore`.

    Attributes
    ----------
    latency : int
        :func:`serial_latency`.
    ii : int
        ``n + 1``.
    memory_plan : SingleMemoryPlan
    """

    architecture = "serial"

    #: The options of ``pipeline`` whose registers this core builds (the others are ignored)
    pipeline_registers = SERIAL_REGISTERS

    #: the vertex shift register takes mu (PWASCore._vertex_fields)
    _replicated_mu_late = False

    def __init__(self, params: CoreParams, *, pipeline: Pipeline | str | None = None, memory: str = "single",
                 round_output: bool = True):
        self._MustUse__silence = True
        if memory != SINGLE_MEMORY:
            raise InputError(f"the serial core has one weight memory (memory='single'), got {memory!r}")
        super().__init__(params, memory="replicated", pipeline=pipeline, round_output=round_output)
        self._MustUse__silence = True
        # the front end's addresses are the replicated layout's (linear vertex index)
        self.memory_plan = SingleMemoryPlan.build(params)
        self.memory_kind = "replicated"
        self.latency = serial_latency(self.pipeline, params.n)
        self.ii = params.n + 1
        self._MustUse__silence = False

    @property
    def extra_info(self) -> dict:
        """Manifest entries of the serial architecture (merged by :func:`pwas_hdl.hdl.api.design_info`)."""
        return {"architecture": architecture_info(self)}

    def flow_control(self, names: dict) -> dict:
        """The handshake rules of the input throttle, in words.

        Parameters
        ----------
        names : dict of str to str
            Port names by role (:func:`~pwas_hdl.hdl.emit.port_names`).

        Returns
        -------
        dict of str to str
            ``advance`` and the ``in.ready`` port's rule (merged into the manifest's
            ``flow_control``).
        """
        ov, orr, ir = names["out.valid"], names["out.ready"], names["in.ready"]
        return {
            "advance": f"~{ov} | {orr}",
            ir: f"advance & (gap == 0): one transfer every {self.ii} advancing cycles at most (II = n + 1); "
            f"gap counts the advancing cycles since the last transfer",
        }

    def build_into(self, m: Module, payload: Value, valid: Value, advance: Signal, out: Any) -> None:
        """Add the serial core's logic to ``m`` (arguments as :meth:`PWASCore.build_into`).

        ``advance`` is driven with ``(~out.valid | out.ready) & (gap == 0)``: the input is taken
        when ``valid & advance``, at most once every ``n + 1`` advancing cycles
        (:func:`serial_throttle`, then :meth:`build_datapath`).

        Parameters
        ----------
        m : Module
            Module the logic is added to.
        payload, valid : Value
            Input sample (``n*B_in`` bits) and its valid bit.
        advance : Signal
            Input enable, driven here.
        out : stream interface
            Output stream (``ready`` read, the rest driven).
        """
        adv = Signal(name="mac_advance")
        m.d.comb += adv.eq(~out.valid | out.ready)
        take = serial_throttle(m, self.params.n, adv, valid, advance)
        self.build_datapath(m, payload, take, adv, out)

    def build_datapath(self, m: Module, payload: Value, take: Value, adv: Value, out: Any) -> None:
        """Add everything after the input throttle: front end, vertex shift register, memory,
        multiply-accumulate and output register.

        The caller owns the throttle: ``take`` must be high at most once every ``n + 1`` cycles in
        which ``adv`` is high (the load never overwrites a vertex still to be read). A serial
        additive design (:mod:`pwas_hdl.hdl.additive_top`) drives several cores with one throttle
        and one ``adv``.

        Parameters
        ----------
        m : Module
            Module the logic is added to.
        payload : Value
            Input sample (``n*B_in`` bits), read when ``take`` is high.
        take : Value
            1 bit: a sample enters in this cycle (when ``adv`` is high too).
        adv : Value
            1 bit: every register and the memory read port advance (``~out.valid | out.ready`` of
            the core's sink).
        out : stream interface
            ``payload`` (``nz * out_field_width + 1`` bits) and ``valid`` are driven here, as
            registers enabled by ``adv``; ``ready`` is not read (``adv`` carries it).
        """
        p = self.params
        n, nb, nz = p.n, p.n + 1, p.nz
        dw, bw, accw = p.frac + 1, p.weight_width, p.acc_width
        plan = self.memory_plan
        aw = plan.addr_width
        pl = self.pipeline

        # ---------------------------------------------------------- front end (the parallel core's)
        pipe = _Pipe(m, adv)
        fvalid, addr, mus, _rot, oor = self._vertices(m, pipe, payload, take)
        pipe.finish()
        front_regs = pipe.count

        # ---------------------------------------------------------- load / shift register of the vertices
        q_addr = [Signal(unsigned(aw), name=f"q_addr{k}", reset_less=True) for k in range(nb)] if aw else []
        q_mu = [Signal(unsigned(dw), name=f"q_mu{k}", reset_less=True) for k in range(nb)]
        q_v = [Signal(name=f"q_valid{k}") for k in range(nb)]
        oor_v = oor if not isinstance(oor, bool) else None
        q_oor = Signal(name="q_oor", reset_less=True) if oor_v is not None else Const(int(oor), 1)
        with m.If(adv):
            with m.If(fvalid):
                m.d.sync += [q_addr[k].eq(addr[k]) for k in range(nb) if aw]
                m.d.sync += [q_mu[k].eq(mus[k]) for k in range(nb)]
                m.d.sync += [q_v[k].eq(1) for k in range(nb)]
                if oor_v is not None:
                    m.d.sync += q_oor.eq(oor_v)
            with m.Else():
                m.d.sync += [q_addr[k].eq(q_addr[k + 1]) for k in range(n) if aw]
                m.d.sync += [q_mu[k].eq(q_mu[k + 1]) for k in range(n)]
                m.d.sync += [q_v[k].eq(q_v[k + 1]) for k in range(n)] + [q_v[n].eq(0)]
        # position 0 holds vertex k: it is the first when all n+1 positions are full, the last when
        # position 1 is empty (the next sample arrives only after position 0 held vertex n)
        first = q_v[n]
        last = ~q_v[1]

        # ---------------------------------------------------------- memory read (the register)
        rdata = weight_rom(m, weight_memory_name(0), plan.word_bits, plan.depth, plan.contents[0], q_addr[0] if aw else None, adv)

        regs = []  # (dst, src) pairs enabled by adv
        valids = []

        def reg(name, val, shape, reset_less=True):
            r = Signal(shape, name=name, reset_less=reset_less)
            (regs if reset_less else valids).append((r, val))
            return r

        m_v = reg("m_valid", q_v[0], 1, reset_less=False)
        m_first = reg("m_first", first, 1)
        m_last = reg("m_last", last, 1)
        m_mu = reg("m_mu", q_mu[0], unsigned(dw))
        m_oor = reg("m_oor", q_oor, 1)
        data = rdata
        if pl.mem_out:
            data = reg("mo_data", data, unsigned(plan.word_bits))
            m_v = reg("mo_valid", m_v, 1, reset_less=False)
            m_first, m_last = reg("mo_first", m_first, 1), reg("mo_last", m_last, 1)
            m_mu, m_oor = reg("mo_mu", m_mu, unsigned(dw)), reg("mo_oor", m_oor, 1)

        # ---------------------------------------------------------- one multiplier per target
        prods = []
        for z in range(nz):
            w = data[z * bw : (z + 1) * bw].as_signed()
            pr = Signal(signed(dw + bw), name=f"prod{z}")  # accw + 1 bits (exact)
            m.d.comb += pr.eq(m_mu * w)
            prods.append(pr)
        if pl.product:
            prods = [reg(f"p_prod{z}", prods[z], signed(dw + bw)) for z in range(nz)]
            m_v = reg("p_valid", m_v, 1, reset_less=False)
            m_first, m_last = reg("p_first", m_first, 1), reg("p_last", m_last, 1)
            m_oor = reg("p_oor", m_oor, 1)

        # ---------------------------------------------------------- accumulate (vertex order)
        accs = []
        for z in range(nz):
            acc = Signal(signed(accw + 1), name=f"acc{z}", reset_less=True)
            nxt = add_wrap(m, acc.as_unsigned(), prods[z].as_unsigned(), f"acc_next{z}")
            with m.If(adv & m_v):
                with m.If(m_first):
                    m.d.sync += acc.eq(prods[z])
                with m.Else():
                    m.d.sync += acc.eq(nxt)
            accs.append(acc)
        a_done = reg("acc_done", m_v & m_last, 1, reset_less=False)
        a_oor = reg("acc_oor", m_oor, 1)

        # ---------------------------------------------------------- round, saturate, output register
        zs = self._round(m, accs) if self.round_output else accs  # unrounded: the exact sums (additive parts)
        outw = self.out_field_width
        for z, o in enumerate(zs):
            regs.append((out.payload[z * outw : (z + 1) * outw], o))
        regs.append((out.payload[-1], a_oor))
        valids.append((out.valid, a_done))
        with m.If(adv):
            m.d.sync += [d.eq(s) for d, s in regs] + [d.eq(s) for d, s in valids]
        got = front_regs + 1 + n + 1 + int(pl.mem_out) + int(pl.product) + 1 + 1
        assert got == self.latency, (got, self.latency)


def serial_throttle(m: Module, n: int, adv: Value, valid: Value, advance: Signal) -> Value:
    """The serial core's input throttle: at most one transfer every ``n + 1`` advancing cycles.

    ``gap`` (``n`` .. 0) counts the advancing cycles since the last transfer; ``advance = adv &
    (gap == 0)`` is the input's ready.

    Parameters
    ----------
    m : Module
        Module the counter is added to (signals ``gap``, ``gap_free``, ``gap_dec``).
    n : int
        Cycles to wait after a transfer: the II is ``n + 1`` (``n``: the regressor dimension of the
        core, or the largest part's of a serial additive design).
    adv : Value
        1 bit: the design advances in this cycle.
    valid : Value
        1 bit: the input offers a sample.
    advance : Signal
        1 bit, driven here: the input's ready (a transfer when ``valid & advance``).

    Returns
    -------
    Value
        ``take = valid & (gap == 0)``: a sample enters (in the cycles where ``adv`` is high).
    """
    gap = Signal(unsigned(bits_for(n)), name="gap")
    free = Signal(name="gap_free")
    m.d.comb += free.eq(~gap.any())
    m.d.comb += advance.eq(adv & free)
    take = valid & free
    gap_dec = add_const_wrap(m, gap, -1, "gap_dec")
    with m.If(adv):
        with m.If(take):
            m.d.sync += gap.eq(n)
        with m.Elif(~free):
            m.d.sync += gap.eq(gap_dec)
    return take


def architecture_info(core: PWASCore, ii: int | None = None, why: str | None = None) -> dict:
    """The manifest's ``architecture`` entry of a core (parallel or serial).

    Parameters
    ----------
    core : PWASCore or SerialPWASCore or AdditiveCore
        Serial when its ``architecture`` attribute is ``"serial"``; an additive core (one with
        ``parts``, :mod:`pwas_hdl.hdl.additive_top`) is described by its parts' entries.
    ii : int, optional
        The design's II in cycles, when a top around the core takes samples more slowly than the
        core could (the recurrent top: II = latency; the serial observer bank: its cycles per
        sample). None: the core's own.
    why : str, optional
        Why the design's II is ``ii`` (a phrase, e.g. the top's ``ii_meaning``), for ``meaning``.

    Returns
    -------
    dict
        ``kind``, ``multipliers``, ``multipliers_per_target``, ``cycles_per_sample`` (the core's),
        ``ii`` (the design's; clock cycles) and ``meaning`` (it states that II); an additive core's
        multipliers are its parts' (summed), its cycles per sample and II the largest part's.

    Raises
    ------
    InternalError
        ``ii`` differs from the core's without ``why``.
    """
    parts = getattr(core, "parts", None)
    if parts:  # an additive design: its part cores, summed before one rounding
        infos = [architecture_info(c) for c in parts]
        own = max(a["ii"] for a in infos)
        base = {"kind": infos[0]["kind"], "multipliers": sum(a["multipliers"] for a in infos),
                "multipliers_per_target": sum(a["multipliers_per_target"] for a in infos),
                "cycles_per_sample": max(a["cycles_per_sample"] for a in infos),
                "meaning": f"{len(infos)} additive part cores, each (n = its own dimension): {infos[0]['meaning']}; "
                "the parts take each sample together" + (", one every n + 1 cycles of the largest part"
                                                         if infos[0]["kind"] == "serial" else "")}
    else:
        p = core.params
        if getattr(core, "architecture", "parallel") == "serial":
            own = p.n + 1
            base = {"kind": "serial", "multipliers": p.nz, "multipliers_per_target": 1, "cycles_per_sample": p.n + 1,
                    "meaning": "one multiply-accumulate unit per target, one vertex weight x barycentric "
                    "coordinate per cycle, n + 1 cycles per sample, one weight memory of N words"}
        else:
            own = 1
            base = {"kind": "parallel", "multipliers": (p.n + 1) * p.nz, "multipliers_per_target": p.n + 1,
                    "cycles_per_sample": 1,
                    "meaning": "n + 1 memories read and n + 1 multipliers per target in every cycle, adder tree, II = 1"}
    ii = own if ii is None else int(ii)
    if ii != own:  # the top's II, not the core's: the text says the field's value and why
        if why is None:
            raise InternalError(f"the design's II {ii} differs from its core's {own} and nothing says why")
        base["meaning"] += f" (the core's); the design's II = {ii}: {why}"
    return {k: base[k] for k in ("kind", "multipliers", "multipliers_per_target", "cycles_per_sample")} | {
        "ii": ii, "meaning": base["meaning"]}
