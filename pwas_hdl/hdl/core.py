"""The PWAS core ("architecture B", fully parallel, pipelined, II = 1) as an Amaranth component.

Data path (which registers exist is chosen by :class:`~pwas_hdl.hdl.params.Pipeline`)::

    in.payload (n codes) -> scale/clamp/split -> rank extractor (+ address precomputation)
        -> vertex addresses + mu -> n+1 synchronous memory reads -> n+1 multipliers per target
        -> adder tree -> rounding + saturation -> out.payload (nz codes + out_of_range)

Flow control (one global enable, no skid buffer)::

    advance  = ~out.valid | out.ready
    in.ready = advance

Every pipeline register, every memory read-port enable and the chain of valid bits advance
together; only the valid bits have a (synchronous) reset. A bubble is a slot with valid = 0.

Arithmetic (the bit-true specification, see :mod:`pwas_hdl.hdl.params`):

* the clamp flags and the cell / fraction split use the offset-binary input
  ``qu = q + 2**(B_in-1)`` and ``L = lo_code + 2**(B_in-1)``: ``under = qu < L``,
  ``top = qu >= L + p*2**F_j``, ``over = qu > L + p*2**F_j``; inside the domain the cell and the
  fraction are bit fields of ``(qu - L) mod 2**(F_j + width(c_j))``;
* rank: ``d_i >= d_j`` for ``i < j`` (ties to the lower index), ``n(n-1)/2`` comparators; a case
  table turns the ``n-1`` comparison bits of dimension ``j`` into the thermometer code
  ``lt_j[k-1] = (rank_j < k)`` (``k = 1..n-1``), which gives both the vertex steps and the one-hot
  selection of ``d_(k)``;
* banked addresses: bank ``b`` reads vertex ``k_b = (b - rot) mod (n+1)`` with
  ``rot = |c| mod (n+1)``; its step bits ``s_bj = [rank_j < k_b]`` are small tables of
  ``(rank_j, rot)`` and its address is computed from them directly (no rotation of finished
  addresses): ``addr_b = sum_{j<n-1} (c_j + s_bj) * S_j + (c_{n-1} + s_b,n-1) // (n+1)``
  (``S_j`` = ``BankedLayout.row_strides``, :mod:`pwas_hdl.fixedpoint.memory_layout`), the
  concatenation of the bit fields ``c_j + s_bj`` when the strides are aligned powers of two
  (:meth:`PWASCore._address_fields`), else ``base + table(s_b, wrap)`` with one adder per bank
  (``wrap = (c_{n-1} mod (n+1) == n)``). The ``mu_k`` are computed in vertex order and rotated
  (bank ``b`` multiplies its word by ``mu_{k_b}``), so the read data need no rotation back -- the
  exact sum of products does not depend on the order of its terms;
* widths: fractions and ``mu`` have ``F + 1`` bits (``mu_0 = 2**F`` is representable); products and
  partial sums are kept in ``F + B_w`` signed bits, the final sum in ``F + B_w + 1``: the ``mu_k``
  are non-negative and sum to ``2**F``, so every partial sum lies in
  ``[-2**(F+B_w-1), 2**F * (2**(B_w-1) - 1)]`` and nothing can overflow.

The Verilog of this description passes ``verilator --lint-only -Wall``; see
:mod:`pwas_hdl.hdl._lintsafe` for the rules that make it so.
"""

from __future__ import annotations

from typing import Any

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from pwas_hdl.errors import InputError
from pwas_hdl.hdl._lintsafe import add_const_wrap, add_wrap, bits_for, ge_const, rom, sink_unused, sum_wrap
from pwas_hdl.fixedpoint.reduction import tree_level, tree_reduce
from pwas_hdl.hdl.params import PIPELINE_REGISTERS, CoreParams, MemoryPlan, Pipeline
from pwas_hdl.fixedpoint.memory_layout import weight_memory_name
from pwas_hdl.hdl.weight_rom import weight_rom

__all__ = ["PWASCore", "core_input_layout", "core_output_layout"]


def core_input_layout(p: CoreParams) -> data.ArrayLayout:
    """Input payload fields: ``n`` signed ``B_in``-bit codes; element ``j`` at bits ``[j*B_in +: B_in]``.

    The port itself is a flat ``unsigned(n*B_in)`` (a layout-typed port makes Amaranth emit one
    alias wire per field, which Verilator reports as unused); use this layout to view it.

    Parameters
    ----------
    p : CoreParams
        Gives ``n`` and ``B_in = p.in_width``.

    Returns
    -------
    amaranth.lib.data.ArrayLayout
        ``n`` elements of ``signed(B_in)``, ``n * B_in`` bits.
    """
    return data.ArrayLayout(signed(p.in_width), p.n)


def core_output_layout(p: CoreParams) -> data.StructLayout:
    """Output payload fields: ``z`` (``nz`` signed ``B_out``-bit codes, target ``i`` at
    ``[i*B_out +: B_out]``) then ``out_of_range`` (bit ``nz*B_out``). The port is a flat unsigned.

    Parameters
    ----------
    p : CoreParams
        Gives ``nz`` and ``B_out = p.out_width``.

    Returns
    -------
    amaranth.lib.data.StructLayout
        ``nz * B_out + 1`` bits.
    """
    return data.StructLayout({"z": data.ArrayLayout(signed(p.out_width), p.nz), "out_of_range": 1})


class _Pipe:
    """Collects the pipeline registers (all enabled by ``advance``)."""

    def __init__(self, m: Module, advance):
        self.m = m
        self.advance = advance
        self.regs = []
        self.valids = []
        self.count = 0

    def stage(self, name: str, enabled: bool, valid, values: dict):
        """Register ``values`` (dict name -> value / int / list) when ``enabled``."""
        if not enabled:
            return valid, values
        out = {}
        for key, val in values.items():
            if isinstance(val, list):
                out[key] = [self._reg(f"{name}_{key}{i}", v) for i, v in enumerate(val)]
            else:
                out[key] = self._reg(f"{name}_{key}", val)
        v = Signal(name=f"{name}_valid")
        self.valids.append((v, valid))
        self.count += 1
        return v, out

    def _reg(self, name: str, val):
        if val is None or isinstance(val, (int, bool)):
            return val
        r = Signal(unsigned(len(val)), name=name, reset_less=True)
        self.regs.append((r, val))
        return r

    def finish(self):
        with self.m.If(self.advance):
            self.m.d.sync += [dst.eq(src) for dst, src in self.regs]
            self.m.d.sync += [dst.eq(src) for dst, src in self.valids]


def _bit(v):
    return Const(int(v), 1) if isinstance(v, (bool, int)) else v


def _or(a, b):
    if a is False:
        return b
    if b is False:
        return a
    if a is True or b is True:
        return True
    return a | b


def _not(a):
    return (not a) if isinstance(a, bool) else ~a


class PWASCore(wiring.Component):
    """Pipelined PWAS evaluator: one regressor in, ``nz`` estimates out, every clock.

    Parameters
    ----------
    params : CoreParams
        Integer description of the datapath (grid, formats, weight codes).
    memory : {"banked", "replicated", "corner"}
        Weight memory layout (:mod:`pwas_hdl.fixedpoint.memory_layout`); ``corner``:
        :mod:`pwas_hdl.hdl.corner` (``2**n`` banks addressed by the cells alone).
    pipeline : Pipeline, preset name ("min", "short", "balanced", "max") or None (balanced)
        Which optional registers exist (:class:`~pwas_hdl.hdl.params.Pipeline`).
    round_output : bool
        ``False``: no rounding or saturation; the output register holds the exact accumulator,
        ``acc_width + 1`` signed bits per target (``out_field_width``), for a design that adds
        several cores before one rounding (the additive sensor, :mod:`pwas_hdl.hdl.additive_top`).

    Ports (flattened Verilog names): ``clk``, ``rst`` (synchronous, active high), ``in__valid``,
    ``in__ready``, ``in__payload`` (``n*B_in`` bits), ``out__valid``, ``out__ready``,
    ``out__payload`` (``nz*B_out + 1`` bits; ``nz*out_field_width + 1`` with ``round_output=False``);
    see :func:`core_input_layout` and :func:`core_output_layout` for the payload bit fields.

    Attributes
    ----------
    latency : int
        Cycles from an input transfer to the corresponding output: when ``in.valid & in.ready`` is
        high in cycle ``t`` (sampled at the clock edge ending it) and the sink never stalls,
        ``out.valid`` is high with the result in cycle ``t + latency``.
    ii : int
        Initiation interval (1).
    memory_plan : MemoryPlan
        Number, depth and width of the weight memories and their contents.

    Raises
    ------
    InputError
        A ``lo_code`` outside the signed ``B_in``-bit input range, an unknown ``memory`` layout or
        an invalid ``pipeline`` (:meth:`Pipeline.cast`).
    TypeError
        ``pipeline`` of another type (:meth:`Pipeline.cast`).
    """

    #: The options of ``pipeline`` whose registers this core builds: all (each counts in ``latency``)
    pipeline_registers = PIPELINE_REGISTERS

    def __init__(self, params: CoreParams, *, memory: str = "banked", pipeline: Pipeline | str | None = None,
                 round_output: bool = True):
        self._MustUse__silence = True  # no "never used" warning for an object whose __init__ raised
        lo, hi = -(1 << (params.in_width - 1)), (1 << (params.in_width - 1)) - 1
        for j, v in enumerate(params.lo_code):
            if not lo <= v <= hi:
                raise InputError(
                    f"lo_code[{j}] = {v} is outside the signed {params.in_width}-bit input range; "
                    "the domain's lower bound must be a representable input code"
                )
        self.params = params
        self.pipeline = Pipeline.cast(pipeline)
        self.memory_kind = memory
        self.memory_plan = MemoryPlan.build(params, memory)
        self.latency = self.pipeline.latency(params.n)
        self.ii = 1
        self.round_output = bool(round_output)
        #: optional first pipeline stage in front of the scale stage: ``f(m, pipe, payload, valid) ->
        #: (valid, payload)``, e.g. the warp of a non-uniform partition (:func:`pwas_hdl.hdl.warp.attach_warp`,
        #: which also adds its register to ``latency``)
        self.input_stage = None
        #: bits per target in the output payload: B_out, or acc_width + 1 without the rounding
        self.out_field_width = params.out_width if self.round_output else params.acc_width + 1
        super().__init__(
            {
                "in": In(stream.Signature(unsigned(core_input_layout(params).size))),
                "out": Out(stream.Signature(unsigned(core_output_layout(params).size if self.round_output
                                                     else self.out_field_width * params.nz + 1))),
            }
        )
        self._MustUse__silence = False

    def elaborate(self, platform: Any) -> Module:
        """The pipelined PWAS evaluator's logic (stages, weight memories, adder tree).

        Parameters
        ----------
        platform : Any
            Amaranth build platform; the core does not use it.

        Returns
        -------
        Module
            The core's logic, :meth:`build_into` on its own ports.
        """
        m = Module()
        inp = getattr(self, "in")
        # advance = in.ready (one net; a separately named copy would be an unused alias wire)
        self.build_into(m, inp.payload, inp.valid, inp.ready, self.out)
        return m

    def build_into(self, m: Module, payload: Value, valid: Value, advance: Signal, out: Any) -> None:
        """Add the core's logic to ``m`` (used by :meth:`elaborate` and by the sensor top).

        Parameters
        ----------
        m : Module
            Module the logic is added to.
        payload, valid : Value
            The input sample (``n*B_in`` bits, :func:`core_input_layout`) and its valid bit.
        advance : Signal
            1 bit, driven here with ``~out.valid | out.ready``: the input is taken when
            ``valid & advance``.
        out : stream interface
            Output stream (``payload`` and ``valid`` driven here, ``ready`` read).
        """
        m.d.comb += advance.eq(~out.valid | out.ready)
        pipe = _Pipe(m, advance)
        valid, vals = self._front(m, pipe, payload, valid)
        zs, oor, valid = self._back(m, pipe, valid, vals, advance)
        outw = self.out_field_width
        for z, o in enumerate(zs):
            pipe.regs.append((out.payload[z * outw : (z + 1) * outw], o))
        pipe.regs.append((out.payload[-1], _bit(oor)))
        pipe.valids.append((out.valid, valid))
        pipe.count += 1
        pipe.finish()
        assert pipe.count == self.latency, (pipe.count, self.latency)

    # ------------------------------------------------------------------ front end
    def _front(self, m: Module, pipe: _Pipe, payload, valid):
        """Scale/clamp/split, rank, addresses and mu (up to the memory address)."""
        valid, addr, mus, rot, oor = self._vertices(m, pipe, payload, valid)
        if self.memory_kind == "corner":  # addr / mus: the cells / fractions (pwas_hdl.hdl.corner)
            from pwas_hdl.hdl.corner import corner_read

            return corner_read(self, m, pipe, valid, addr, mus, oor)
        p, plan = self.params, self.memory_plan
        nb, dw, aw = p.n + 1, p.frac + 1, plan.addr_width
        return self._banks(m, pipe, valid, addr, mus, rot, oor, nb, dw, aw, plan)

    def _vertices(self, m: Module, pipe: _Pipe, payload, valid):
        """Scale/clamp/split, rank, the n+1 addresses and mu.

        Returns ``(valid, addr, mu, rot, oor)`` after the optional ``addr`` register. Replicated
        layout: ``addr[k]`` is vertex ``k``'s address (``[]`` when the memories have one word),
        ``rot = 0``. Banked: ``addr[b]`` is bank ``b``'s address (:meth:`_bank_direct`), ``mu`` in
        vertex order and ``rot`` the bank rotation. Shared with
        :class:`pwas_hdl.hdl.serial_core.SerialPWASCore` (replicated).
        """
        p, pl = self.params, self.pipeline
        n, big_f, bin_ = p.n, p.frac, p.in_width
        nb = n + 1
        dw = big_f + 1
        cw = [bits_for(pj - 1) for pj in p.partitions]
        if self.input_stage is not None:  # e.g. the warp (pwas_hdl.hdl.warp): n codes of in_width bits after it
            valid, payload = self.input_stage(m, pipe, payload, valid)

        # ---------------------------------------------------------- A: scale / clamp / split
        cs, ds, oor_j = [], [], []
        raw = []  # raw_compare: (top, under, fraction bit field of the input) per dimension, or None
        for j in range(n):
            pj, fj = p.partitions[j], p.frac_bits[j]
            q = payload[j * bin_ : (j + 1) * bin_]
            big_l = p.lo_code[j] + (1 << (bin_ - 1))
            sc = p.scaling[j]  # input_scale "exact": (S, K, R), t' = (t * K) >> R
            tmax = sc[0] if sc else pj << fj  # input codes across the domain
            w = min(fj + cw[j], bin_) if not sc else bits_for(tmax - 1)
            # offset binary qu = q + 2**(B-1) (order preserving); its inverted sign bit is a named
            # net, created only when something reads it
            full = 1 << bin_
            need_msb = w == bin_ or any(0 < k < full for k in (big_l, big_l + tmax, big_l + tmax + 1))
            if need_msb:
                msb = Signal(name=f"q{j}_msb_n")
                m.d.comb += msb.eq(~q[bin_ - 1])
                qu = Cat(q[: bin_ - 1], msb)
            else:
                qu = q
            under = _not(ge_const(qu, big_l))
            top = ge_const(qu, big_l + tmax)
            over = ge_const(qu, big_l + tmax + 1)
            if not isinstance(under, bool):
                under = self._name(m, under, f"under{j}")
            if not isinstance(top, bool):
                top = self._name(m, top, f"top{j}")
            if not isinstance(over, bool):
                over = self._name(m, over, f"over{j}")
            oor_j.append(_or(under, over))
            if pl.raw_compare and not pl.split and n > 1 and self.memory_kind != "corner":  # (corner: its own comparators)
                raw.append(self._raw_fraction(m, qu, big_l, fj, sc, top, under, j))
            # inside: (qu - L) mod 2**W holds the cell (upper bits) and the fraction (lower bits)
            t = add_const_wrap(m, qu[:w], -big_l, f"t{j}")
            if sc:  # exact scale: t in [0, S) -> t' = (t * K) >> R in [0, p * 2**F_j), cell and fraction
                k_mul, r_sh = sc[1], sc[2]
                prod = Signal(unsigned(w + k_mul.bit_length()), name=f"tscale{j}")
                m.d.comb += prod.eq(t * k_mul)
                sink_unused(m, prod[:r_sh], f"tscale{j}_low")  # the bits the shift drops
                w = min(fj + cw[j], len(prod) - r_sh)
                if len(prod) > r_sh + w:  # always 0: t' < p * 2**F_j
                    sink_unused(m, prod[r_sh + w:], f"tscale{j}_top")
                t = prod[r_sh : r_sh + w]
            c = 0 if pj == 1 else Signal(unsigned(cw[j]), name=f"c{j}")
            d = Signal(unsigned(dw), name=f"d{j}")

            def inside(c=c, d=d, t=t, fj=fj, w=w):
                if not isinstance(c, int) and w > fj:
                    m.d.comb += c.eq(t[fj:w])
                if fj > 0:
                    m.d.comb += d.eq(Cat(Const(0, big_f - fj), t[: min(fj, w)]))

            if top is not False:
                with m.If(top):
                    if not isinstance(c, int):
                        m.d.comb += c.eq(pj - 1)
                    m.d.comb += d.eq(1 << big_f)
                if under is not False:
                    with m.Elif(~under):
                        inside()
                else:
                    with m.Else():
                        inside()
            elif under is not False:
                with m.If(~under):
                    inside()
            else:  # the domain covers every input code: no clamping, still a process for full widths
                with m.If(valid):
                    inside()
            cs.append(c)
            ds.append(d)
            if isinstance(c, int) and w > fj:  # p_j = 1: the cell is always 0
                sink_unused(m, t[fj:w], f"t{j}_cell")

        # the out-of-range flags of the dimensions are registered one by one and joined after the
        # split register (the flag is only needed at the output)
        valid, r = pipe.stage("s_split", pl.split, valid, {"c": cs, "d": ds, "oor": oor_j})
        cs, ds = r["c"], r["d"]
        oor = False
        for f in r["oor"]:
            oor = _or(oor, f)
        if self.memory_kind == "corner":  # the cells address the corner banks directly (_front)
            return valid, cs, ds, 0, oor

        # ---------------------------------------------------------- B: rank + address precompute
        # the n(n-1)/2 comparison bits are what the rank register holds; the case tables that turn
        # them into thermometer codes come after it (one carry chain per stage)
        pairs = self._pairs(n)
        if raw and all(x is not None for x in raw):  # raw_compare: the comparators on the input bits
            zeros: dict = {}
            ge_bits = [self._raw_ge(m, raw[i], raw[j], big_f, f"ge_{i}_{j}", zeros) for i, j in pairs]
        else:
            ge_bits = [self._name(m, ds[i] >= ds[j], f"ge_{i}_{j}") for i, j in pairs]  # ties go to i < j

        # the base address and the bank rotation are sums over the dimensions: their first tree level
        # is computed here, the rest after the rank register (so that the rank stage holds one carry
        # chain, as the comparators; the sums are the same in any order)
        plan = self.memory_plan
        aw = plan.addr_width
        base_part, wrap, rot_part = [], 0, []
        rbits = bits_for(n)
        # banked: the bank addresses as bit fields c_j + step (no adder) where the layout allows it
        fields = self._address_fields() if self.memory_kind == "banked" else None
        # replicated: the vertex addresses as bit fields c_j + [rank_j < k] where the grid allows it
        vfields = self._vertex_fields() if self.memory_kind == "replicated" else None
        if self.memory_kind == "banked":
            rst = plan.layout.row_strides  # address weight of c_j, j < n-1
            p_last = p.partitions[n - 1]
            if aw and fields is None:
                terms = [rom(m, cs[j], [i * rst[j] for i in range(p.partitions[j])], aw, f"a{j}") for j in range(n - 1)]
                terms.append(rom(m, cs[n - 1], [i // nb for i in range(p_last)], aw, f"a{n - 1}"))
                base_part = self._first_level(terms, lambda a, b, i: add_wrap(m, a, b, f"base0_{i}"), 1 << aw)
                wrap = rom(m, cs[n - 1], [int(i % nb == n) for i in range(p_last)], 1, "wrap")
            if pl.split and pl.rank:
                # behind a split register (the throughput build) the split -> rank stage keeps the
                # comparators and the first level of the residue tables, the rest follows the rank
                # register (measured: the whole rotation there made it the critical stage)
                res = [rom(m, cs[j], [i % nb for i in range(p.partitions[j])], rbits, f"cres{j}") for j in range(n)]
                table = [((x & ((1 << rbits) - 1)) + (x >> rbits)) % nb for x in range(1 << (2 * rbits))]
                rot_part = self._first_level(res, lambda a, b, i: rom(m, Cat(a, b), table, rbits, f"rot0_{i}"), nb)
            else:
                # the whole rotation before the rank register: the per-bank step tables after it are
                # then functions of registered bits only
                rot_part = [self._rotation(m, cs, nb, rbits, tables=pl.raw_compare and not pl.split)]
        else:
            st = [int(v) for v in plan.layout.grid.strides]  # replicated: address = linear vertex index
            if vfields is None:
                terms = [rom(m, cs[j], [i * st[j] for i in range(p.partitions[j])], aw, f"a{j}") for j in range(n)]
                base_part = self._first_level(terms, lambda a, b, i: add_wrap(m, a, b, f"base0_{i}"), 1 << aw)

        valid, r = pipe.stage(
            "s_rank", pl.rank, valid, {"ge": ge_bits, "d": ds, "oor": oor, "base": base_part, "wrap": wrap, "rot": rot_part,
                                       "c": cs if fields is not None or vfields is not None else []}
        )
        ds, oor, wrap = r["d"], r["oor"], r["wrap"]
        ge = dict(zip(pairs, r["ge"]))
        if self.memory_kind == "banked":
            base = sum_wrap(m, r["base"], aw, "base") if aw and fields is None else 0
            rot = self._modsum(m, r["rot"], nb, rbits, "rot")
            return self._bank_direct(m, pipe, valid, ge, ds, oor, r["c"] if fields is not None else cs, base, wrap, rot,
                                     fields)
        if vfields is not None:
            return self._vertex_direct(m, pipe, valid, ge, ds, oor, r["c"], vfields)
        lt = []
        if n > 1:
            therm = []
            for v in range(1 << (n - 1)):
                rank = bin(v).count("1")
                therm.append(sum(1 << (k - 1) for k in range(1, n) if rank < k))
            for j in range(n):
                bits = [ge[i, j] for i in range(j)] + [~ge[j, i] for i in range(j + 1, n)]
                lt.append(rom(m, Cat(*bits), therm, n - 1, f"lt{j}"))
        base = sum_wrap(m, r["base"], aw, "base") if aw else 0
        rot = 0

        # ---------------------------------------------------------- C: vertices, addresses, mu
        def step(k, j):
            if k == 0:
                return False
            if k == n:
                return True
            return lt[j][k - 1]

        # (replicated layout from here on; banked memories returned above)
        # vertex k's address offset from the base is a function of the n step bits of vertex k
        # alone (sum_j step_kj * S_j): one case table of at most 2**n words and one adder per vertex
        # instead of an adder tree of n + 1 terms
        addr, offs = [], []
        if aw:
            full = 1 << aw
            for k in range(nb):
                pairs = [(step(k, j), st[j]) for j in range(n)]
                const = sum(w for b, w in pairs if b is True)
                var = [(b, w) for b, w in pairs if not isinstance(b, bool)]
                if var:
                    table = [(const + sum(w for i, (_, w) in enumerate(var) if v >> i & 1)) % full for v in range(1 << len(var))]
                    off = rom(m, Cat(*[b for b, _ in var]), table, aw, f"voff{k}")
                else:
                    off = const % full
                offs.append(off)

        # d_(k): the fraction of rank k-1 (one-hot selection from the thermometer codes)
        def sel(k, j):
            if n == 1:
                return True
            if k == 1:
                return lt[j][0]
            if k == n:
                return ("not", lt[j][n - 2])
            return lt[j][k - 1] & ~lt[j][k - 2]

        dsorted = []
        for k in range(1, n + 1):
            if n == 1:
                dsorted.append(ds[0])
                continue
            acc = None
            for j in range(n):
                sj = sel(k, j)
                if isinstance(sj, tuple):  # Mux(~s, a, b) would leave the inverter unused
                    term = Mux(sj[1], Const(0, dw), ds[j])
                else:
                    term = Mux(sj, ds[j], Const(0, dw))
                acc = term if acc is None else acc | term
            dsorted.append(acc if isinstance(acc, Signal) else self._name(m, acc, f"dsorted{k}", unsigned(dw)))
        # optional register on the offsets and the selected fractions, before the address adders and
        # the mu subtractions (it splits stage C in two: tables / one-hot selection, then carry chains)
        valid, r = pipe.stage("s_voff", pl.offset, valid,
                              {"off": offs, "base": base, "ds": dsorted, "rot": rot, "oor": oor})
        offs, base, dsorted, rot, oor = r["off"], r["base"], r["ds"], r["rot"], r["oor"]
        addr = [sum_wrap(m, [base, off], aw, f"vaddr{k}") for k, off in enumerate(offs)]
        mus = self._mu_of_sorted(m, dsorted)

        # optional register on the vertex addresses and mu, before the bank rotation
        valid, r = pipe.stage("s_addr", pl.addr, valid, {"addr": addr, "mu": mus, "rot": rot, "oor": oor})
        addr, mus, rot, oor = r["addr"], r["mu"], r["rot"], r["oor"]
        return valid, addr, mus, rot, oor

    def _raw_fraction(self, m: Module, qu, big_l: int, fj: int, sc, top, under, j: int):
        """``raw_compare``: ``(top, under, r, j)`` with ``r`` the fraction ``(qu - L) mod 2**F_j`` as a
        bit field of ``qu`` (bit ``F_j - 1`` inverted when ``L mod 2**F_j = 2**(F_j-1)``); None when
        the fraction is not such a bit field (exact scale, other ``L``)."""
        low = big_l % (1 << fj) if fj else 0
        if sc or fj == 0 or low not in (0, 1 << (fj - 1)):
            return None
        if low:  # the inverted top bit is a named net (a cell output); the rest is wiring
            inv = Signal(name=f"rfrac{j}_msb_n")
            m.d.comb += inv.eq(~qu[fj - 1])
            r = Cat(qu[: fj - 1], inv)
        else:
            r = qu[:fj]
        return top, under, r, j

    def _raw_zero(self, m: Module, x, cache: dict):
        """``r == 0`` of a raw fraction (one named net per dimension, made when first needed)."""
        _top, _under, r, j = x
        if j not in cache:
            cache[j] = self._name(m, ~r.any(), f"rzero{j}")
        return cache[j]

    def _raw_ge(self, m: Module, a, b, big_f: int, name: str, zeros: dict):
        """``d_a >= d_b`` from the raw fractions and the clamp flags (see Pipeline ``raw_compare``)."""
        ta, ua, ra, _ja = a
        tb, ub, rb, _jb = b
        wa, wb = len(ra), len(rb)
        if wa == wb:
            cmp = ra >= rb
        else:  # aligned to F bits (fractions of F_j < F bits are shifted up)
            cmp = Cat(Const(0, big_f - wa), ra) >= Cat(Const(0, big_f - wb), rb)
        rawge = self._name(m, cmp, f"{name}_raw")
        inner = rawge if ua is False else Mux(ua, self._raw_zero(m, b, zeros), rawge)
        inner = _or(ub, inner)
        if tb is not False:
            inner = ~tb & inner
        return self._name(m, _or(ta, inner), name)

    #: whether the replicated front may hand the sorted fractions (not ``mu``) to the memory register
    #: (``mu_late``; the serial core's vertex shift register takes ``mu``)
    _replicated_mu_late = True

    def _vertex_fields(self):
        """Bit fields of the replicated layout's vertex address, or None (then base + offset adders).

        Only with ``mu_late`` (and no ``offset`` register, n > 1: the latency-first front), for
        :class:`PWASCore`, where the layout's address is a concatenation of fields
        (:meth:`pwas_hdl.fixedpoint.memory_layout.ReplicatedLayout.address_fields`). Returns
        ``[(e, width, j), ...]``.
        """
        p, pl, plan = self.params, self.pipeline, self.memory_plan
        if not (self._replicated_mu_late and pl.mu_late and not pl.offset and p.n > 1 and plan.addr_width):
            return None
        return plan.layout.address_fields()

    def _vertex_direct(self, m: Module, pipe: _Pipe, valid, ge, ds, oor, cs, fields):
        """Replicated memories with bit-field vertex addresses (:meth:`_vertex_fields`).

        Vertex ``k``'s coordinate in dimension ``j`` is ``c_j + [rank_j < k]``, ``rank_j`` the count
        of dimension ``j``'s ``n - 1`` comparison bits: each field one case table of ``(c_j``, those
        bits``)`` (vertex 0: ``c_j``; vertex ``n``: ``c_j + 1``), the address their concatenation
        (no adder). The sorted fractions go on to the memory register (``mu_late``: ``mu`` follows
        the read, :meth:`_banks`). Returns what :meth:`_vertices` returns (copy ``k`` = vertex ``k``,
        ``rot = 0``).
        """
        p, pl, plan = self.params, self.pipeline, self.memory_plan
        n, nb, aw = p.n, p.n + 1, plan.addr_width
        mask = (1 << (n - 1)) - 1
        addr = []
        for k in range(nb):
            parts, pos = [], 0
            for e, w, j in sorted(fields):
                c = cs[j]
                g = [ge[i, j] for i in range(j)] + [ge[j, i] for i in range(j + 1, n)]
                low = (1 << j) - 1  # d_i >= d_j (i < j) counts when set, d_j >= d_i (i > j) when clear

                def value(cv, v=0, k=k, low=low):
                    rank = bin(v & low).count("1") + bin(~v & mask & ~low).count("1")
                    return cv + int(rank < k)

                if k == 0:
                    f = c
                else:  # vertex n: c_j + 1 whatever the comparison bits
                    ins = [(c, bits_for(p.partitions[j] - 1))] + ([(Cat(*g), n - 1)] if k < n else [])
                    f = self._table(m, ins, value, w, f"vf{k}_{j}")
                if e > pos:  # bits no field covers
                    parts.append(Const(0, e - pos))
                if isinstance(f, int):
                    parts.append(Const(f, w))
                elif len(f) < w:
                    parts.append(Cat(f, Const(0, w - len(f))))
                else:
                    parts.append(f)
                pos = e + w
            if pos < aw:
                parts.append(Const(0, aw - pos))
            addr.append(Cat(*parts))  # wiring only
        gs = self._sorted_fractions(m, ge, ds)
        valid, r = pipe.stage("s_addr", pl.addr, valid, {"addr": addr, "ds": gs, "oor": oor})
        return valid, r["addr"], r["ds"], 0, r["oor"]

    def _address_fields(self):
        """Bit fields of the banked address, or None when the layout's address needs adders.

        ``addr(v) = sum_{j<n-1} v_j * row_strides[j] + v_{n-1} // (n+1)``: when every
        ``row_strides[j]`` is a power of two ``2**e_j`` and the fields ``[e_j, e_j + width(p_j))``
        and ``[0, width(p_{n-1} // (n+1)))`` are disjoint inside the address, the sum is their
        concatenation (e.g. ``p_j + 1`` a power of two for ``0 < j < n-1``, as p = 7). Returns
        ``[(e, width, j), ...]`` (``j = n-1``: the last dimension's ``// (n+1)`` field).
        """
        p, plan = self.params, self.memory_plan
        aw, n, nb = plan.addr_width, p.n, p.n + 1
        if not aw:
            return None
        spans = []
        for j, s in enumerate(plan.layout.row_strides):
            if s < 1 or s & (s - 1):
                return None
            spans.append((s.bit_length() - 1, bits_for(p.partitions[j]), j))
        if p.partitions[n - 1] // nb:
            spans.append((0, bits_for(p.partitions[n - 1] // nb), n - 1))
        used = 0
        for e, w, _j in spans:
            mask = ((1 << w) - 1) << e
            if used & mask or e + w > aw:
                return None
            used |= mask
        return spans

    @staticmethod
    def _table(m: Module, inputs, f, width: int, name: str):
        """``f(*values)`` as a case table over the non-constant ``inputs`` (``[(value or int, width)]``);
        an int when it is constant (unreachable input codes give whatever ``f`` returns, or 0)."""
        var = [(v, w) for v, w in inputs if not isinstance(v, (int, bool))]
        table = []
        for x in range(1 << sum(w for _v, w in var)):
            args, pos = [], 0
            for v, w in inputs:
                if isinstance(v, (int, bool)):
                    args.append(int(v))
                else:
                    args.append((x >> pos) & ((1 << w) - 1))
                    pos += w
            table.append(int(f(*args)) % (1 << width))
        if not var:
            return table[0]
        return rom(m, Cat(*[v for v, _w in var]), table, width, name)

    def _bank_direct(self, m: Module, pipe: _Pipe, valid, ge, ds, oor, cs, base, wrap, rot, fields):
        """Banked memories without an address rotation: bank ``b``'s step bits and address, ``mu``.

        Bank ``b`` reads vertex ``k_b = (b - rot) mod (n+1)``. Its step bits
        ``s_bj = [rank_j < k_b]`` are small tables of ``(rank_j, rot)``; its address is built from
        them (bit fields ``c_j + s_bj`` when :meth:`_address_fields` allows, else the shared base plus
        a table of the step bits, one adder per bank). ``mu`` is computed in vertex order from the
        sorted fractions (one-hot selection by the comparison bits) and rotated after the ``addr``
        register (:meth:`_banks`; with ``mu_late`` after the memory register). Returns what
        :meth:`_vertices` returns, the addresses in bank order, ``mu`` (or, ``mu_late``, the sorted
        fractions) in vertex order.
        """
        p, pl, plan = self.params, self.pipeline, self.memory_plan
        n, big_f = p.n, p.frac
        nb, dw, aw = n + 1, big_f + 1, plan.addr_width
        rbits, kw = bits_for(n), bits_for(n - 1)
        cw = [bits_for(pj - 1) for pj in p.partitions]
        rot_in = (rot, rbits)
        # the step bits the address uses: with bit fields only the dimensions that have one (the last
        # dimension has none when p_{n-1} < n + 1: its vertex coordinate // (n+1) is always 0)
        used_dims = set(range(n)) if fields is None else {j for _e, _w, j in fields}
        # late_select: the address fields are chosen by the comparison bits among values precomputed
        # from the cells and the rotation (:meth:`_late_field`): no rank or step tables
        late = bool(pl.late_select and fields is not None and aw and not pl.offset and n > 1)
        ranks = []
        for j in range(n):
            if n == 1 or j not in used_dims or late:
                ranks.append(0)
                continue
            bits = [ge[i, j] for i in range(j)] + [~ge[j, i] for i in range(j + 1, n)]
            ranks.append(rom(m, Cat(*bits), [bin(v).count("1") for v in range(1 << (n - 1))], kw, f"rank{j}"))

        def kb(b, t):
            return (b - t) % nb

        step = [[self._table(m, [(ranks[j], kw), rot_in], lambda r, t, b=b: t < nb and r < kb(b, t), 1, f"step{b}_{j}")
                 if j in used_dims and not late else 0 for j in range(n)] for b in range(nb)]
        if pl.sort_late and pl.mu_late and n > 1:
            # sort_late: the fractions in dimension order and the comparison bits travel to the memory
            # register; the sort is made in the memory-read cycle (_banks)
            gs = list(ds) + [Cat(*[_bit(ge[ij]) for ij in self._pairs(n)])]
        else:
            gs = self._sorted_fractions(m, ge, ds)  # in vertex order: mu is rotated after the addr register (_banks)

        # address pieces: bit fields (no carry chain) or a per-bank offset table
        def address_pieces(step, cs):
            pieces = []
            for b in range(nb if aw else 0):
                if late:
                    pieces.append([self._late_field(m, ge, cs, rot_in, b, w, j) for _e, w, j in fields])
                elif fields is not None:
                    fb = []
                    for e, w, j in fields:
                        if j < n - 1:
                            f = self._table(m, [(cs[j], cw[j]), (step[b][j], 1)], lambda c, s: c + s, w, f"af{b}_{j}")
                        else:
                            f = self._table(m, [(cs[j], cw[j]), (step[b][j], 1)], lambda c, s: (c + s) // nb, w, f"af{b}_{j}")
                        fb.append(f)
                    pieces.append(fb)
                else:
                    rst = plan.layout.row_strides
                    ins = [(step[b][j], 1) for j in range(n - 1)] + [(step[b][n - 1], 1), (wrap, 1)]
                    wts = list(rst)
                    pieces.append([self._table(m, ins, lambda *v, wts=wts: sum(x * w for x, w in zip(v, wts)) + (v[-1] & v[-2]),
                                               aw, f"boff{b}")])
            return pieces

        # optional register before the mu subtractions: on the address pieces and the base (a layout
        # without bit fields: its adders come after it) or, bit fields, on the step bits and the cells
        # (the fields' tables come after it, beside the mu subtractions), and on the sorted fractions
        late_fields = fields is not None and pl.offset and aw
        pieces = [] if late_fields else address_pieces(step, cs)
        valid, r = pipe.stage("s_voff", pl.offset, valid,
                              {"f": [x for pc in pieces for x in pc], "base": base, "ds": gs, "rot": rot, "oor": oor,
                               "st": [x for row in step for x in row] if late_fields else [],
                               "c": list(cs) if late_fields else []})
        flat, base, gs, rot, oor = r["f"], r["base"], r["ds"], r["rot"], r["oor"]
        if late_fields:
            step = [r["st"][b * n : (b + 1) * n] for b in range(nb)]
            pieces = address_pieces(step, r["c"])
            flat = [x for pc in pieces for x in pc]
        addr = []
        if aw:
            per = len(pieces[0])
            for b in range(nb):
                pb = flat[b * per : (b + 1) * per]
                if fields is not None:
                    parts, pos = [], 0
                    for (e, w, _j), f in sorted(zip(fields, pb), key=lambda t: t[0][0]):
                        if e > pos:  # bits no field covers
                            parts.append(Const(0, e - pos))
                        parts.append(Const(f, w) if isinstance(f, int) else f)
                        pos = e + w
                    if pos < aw:
                        parts.append(Const(0, aw - pos))
                    addr.append(Cat(*parts))  # wiring only (a named copy would be an unused alias)
                else:
                    off = pb[0]
                    addr.append(sum_wrap(m, [base, off], aw, f"baddr{b}"))
        # mu_late: the sorted fractions travel to the memory register; mu and its rotation are
        # computed in the memory-read cycle (_banks)
        # (register names: "baddr" = the addresses in bank order, "ds" = the sorted fractions d_(k+1))
        mkey = "ds" if pl.mu_late else "mu"
        mus = gs if pl.mu_late else self._mu_of_sorted(m, gs)
        valid, r = pipe.stage("s_addr", pl.addr, valid, {"baddr": addr, mkey: mus, "rot": rot, "oor": oor})
        return valid, r["baddr"], r[mkey], r["rot"], r["oor"]

    def _late_field(self, m: Module, ge, cs, rot_in, b: int, w: int, j: int):
        """``late_select``: bank ``b``'s address field of dimension ``j`` (``w`` bits) as a late select.

        The field is ``c_j + s_bj`` (``j < n-1``; ``(c_j + s_bj) // (n+1)`` for the last dimension)
        with ``s_bj = [rank_j < k_b(rot)]`` and ``rank_j`` the count of the ``n-1`` comparison
        bits of dimension ``j`` (``d_i >= d_j``, i < j; ``d_j > d_i``, i > j). For each rank ``r``
        the field's value depends on ``c_j`` and ``rot`` only, which are known before the
        comparators' carry chains end: the ``n`` candidates are case tables of ``(c_j, rot)``, and
        each field bit is a case table of the comparison bits that selects among them (a Shannon
        expansion on the late inputs) instead of rank table -> step table -> field table.
        """
        p = self.params
        n, nb = p.n, p.n + 1
        cw = bits_for(p.partitions[j] - 1)
        g = [ge[i, j] for i in range(j)] + [ge[j, i] for i in range(j + 1, n)]
        low = (1 << j) - 1  # the bits that count when set (d_i >= d_j, i < j); the others when clear

        def rank(v: int) -> int:
            return bin(v & low).count("1") + bin(~v & ((1 << (n - 1)) - 1) & ~low).count("1")

        def value(c: int, t: int, r: int) -> int:
            s = int(t < nb and r < (b - t) % nb)
            return c + s if j < n - 1 else (c + s) // nb

        bits = []
        for i in range(w):
            cand = [self._table(m, [(cs[j], cw), rot_in], lambda c, t, r=r, i=i: (value(c, t, r) >> i) & 1, 1,
                                f"lsv{b}_{j}_{i}_{r}") for r in range(n)]
            if all(isinstance(x, int) for x in cand) and len(set(cand)) == 1:
                bits.append(Const(cand[0], 1))
                continue
            out = Signal(name=f"ls{b}_{j}_{i}")
            with m.Switch(Cat(*g)):
                for v in range(1 << (n - 1)):
                    with m.Case(v):
                        x = cand[rank(v)]
                        m.d.comb += out.eq(Const(x, 1) if isinstance(x, int) else x)
            bits.append(out)
        return Cat(*bits)

    @staticmethod
    def _pairs(n: int) -> list[tuple[int, int]]:
        """The comparison pairs ``(i, j)``, ``i < j``, in the order of the comparison bits."""
        return [(i, j) for i in range(n) for j in range(i + 1, n)]

    def _sorted_fractions(self, m: Module, ge, ds):
        """``d_(k)``, k = 1..n: the fraction of rank ``k - 1`` (one-hot selection by case tables of
        the comparison bits ``ge[i, j] = d_i >= d_j``; ``ds`` in dimension order, ``F + 1`` bits each)."""
        n, dw = len(ds), self.params.frac + 1
        dsorted = []
        for k in range(1, n + 1):
            acc = None
            for j in range(n):
                if n == 1:
                    e = 1
                else:
                    bits = [ge[i, j] for i in range(j)] + [~ge[j, i] for i in range(j + 1, n)]
                    e = rom(m, Cat(*bits), [int(bin(v).count("1") == k - 1) for v in range(1 << (n - 1))], 1, f"req{k}_{j}")
                term = ds[j] if isinstance(e, int) and e else (None if isinstance(e, int) else Mux(e, ds[j], Const(0, dw)))
                if term is not None:
                    acc = term if acc is None else acc | term
            dsorted.append(acc if isinstance(acc, Signal) else self._name(m, acc, f"dsorted{k}", unsigned(dw)))
        return dsorted

    def _mu_of_sorted(self, m: Module, ds_sorted):
        """``mu_0 = 2**F - d_(1)``, ``mu_k = d_(k) - d_(k+1)``, ``mu_n = d_(n)`` (vertex order)."""
        big_f = self.params.frac
        n, dw = len(ds_sorted), big_f + 1
        mus = []
        for k in range(n + 1):
            if k == n:
                mus.append(ds_sorted[n - 1])
                continue
            hi = Const(1 << big_f, dw) if k == 0 else ds_sorted[k - 1]
            diff = Signal(signed(dw + 1), name=f"mu{k}")
            m.d.comb += diff.eq(hi - ds_sorted[k])
            sink_unused(m, diff[dw], f"mu{k}_sign")
            mus.append(diff[:dw])
        return mus

    @staticmethod
    def _rotate(m: Module, values, rot, width: int, name: str):
        """``out[b] = values[(b - rot) mod len(values)]`` (a case table of ``rot``)."""
        nb = len(values)
        if isinstance(rot, int):
            return [values[(b - rot) % nb] for b in range(nb)]
        out = [Signal(unsigned(width), name=f"{name}{b}") for b in range(nb)]
        with m.Switch(rot):
            for s in range(nb):
                with (m.Case(s) if s < nb - 1 else m.Default()):
                    m.d.comb += [out[b].eq(values[(b - s) % nb]) for b in range(nb)]
        return out

    def _banks(self, m: Module, pipe: _Pipe, valid, addr, mus, rot, oor, nb, dw, aw, plan):
        """Bank rotation and the memory read (the memory register)."""
        n = nb - 1
        # Bank b reads vertex (b - rot) mod (n+1): rotate the addresses, and rotate the mu's the
        # same way instead of the read data back (the sum of products does not depend on the
        # order; mu is narrower than nz weights and needs no rot downstream).
        late = self.pipeline.mu_late and (self.memory_kind == "banked" or self._vertex_fields() is not None)
        if self.memory_kind == "banked":  # _bank_direct: the addresses are in bank order, mu in vertex order
            bank_addr = addr
            bank_mu = mus if late else self._rotate(m, mus, rot, dw, "bank_mu")
        elif late:  # _vertex_direct: copy k = vertex k, the sorted fractions (mu after the read)
            bank_addr, bank_mu = addr, mus
        elif not isinstance(rot, int):
            bank_addr = [Signal(unsigned(aw), name=f"bank_addr{b}") for b in range(nb)] if aw else []
            bank_mu = [Signal(unsigned(dw), name=f"bank_mu{b}") for b in range(nb)]
            with m.Switch(rot):
                for s in range(nb):
                    with (m.Case(s) if s < n else m.Default()):
                        m.d.comb += [bank_addr[b].eq(addr[(b - s) % nb]) for b in range(nb) if aw]
                        m.d.comb += [bank_mu[b].eq(mus[(b - s) % nb]) for b in range(nb)]
        else:
            bank_addr = [addr[(b - rot) % nb] for b in range(nb)] if aw else []
            bank_addr = [Const(a, aw) if isinstance(a, int) else a for a in bank_addr]
            bank_mu = [mus[(b - rot) % nb] for b in range(nb)]

        # optional register on the rotated addresses and mu: the memories' address pins are then
        # driven by flip-flops (no logic between them and the block RAMs)
        mkey = "ds" if late else "mu"  # late: the sorted fractions (vertex order), not mu yet
        valid, r = pipe.stage("s_bank", self.pipeline.bank, valid,
                              {"addr": bank_addr, mkey: bank_mu, "oor": oor, "rot": rot if late else 0})
        bank_addr, bank_mu, oor, rot = r["addr"], r[mkey], r["oor"], r["rot"]

        # ---------------------------------------------------------- D: memory read (the register)
        mem_data = []
        for b in range(nb):
            mem_data.append(weight_rom(m, weight_memory_name(b), plan.word_bits, plan.depth, plan.contents[b],
                                       bank_addr[b] if aw else None, pipe.advance))
        valid, r = pipe.stage("s_mem", True, valid, {mkey: bank_mu, "oor": oor, "rot": rot if late else 0})
        bank_mu = r[mkey]
        if late:  # mu and its rotation in the memory-read cycle (beside the block RAM's clock-to-output)
            if self.pipeline.sort_late and n > 1 and self.memory_kind == "banked":  # and the sort: d_j in dimension order + the comparison bits
                gebits = bank_mu[n]
                ge = {ij: gebits[i] for i, ij in enumerate(self._pairs(n))}
                bank_mu = self._sorted_fractions(m, ge, bank_mu[:n])
            bank_mu = self._rotate(m, self._mu_of_sorted(m, bank_mu), r["rot"], dw, "bank_mu")
        return valid, {"data": mem_data, "mu": bank_mu, "oor": r["oor"]}

    # ------------------------------------------------------------------ back end
    def _back(self, m: Module, pipe: _Pipe, valid, vals, advance):
        p, pl = self.params, self.pipeline
        n, nz = p.n, p.nz
        nb = n + 1
        dw = p.frac + 1
        bw, accw = p.weight_width, p.acc_width

        valid, r = pipe.stage("s_memout", pl.mem_out, valid, vals)
        if "sel" in r:  # corner banks: vertex k's word among its corners (pwas_hdl.hdl.corner)
            from pwas_hdl.hdl.corner import select_corners

            r = {k: v for k, v in r.items() if k != "sel"} | {"data": select_corners(m, n, r["data"], r["sel"],
                                                                                    self.memory_plan.word_bits)}
        valid, r = pipe.stage("s_mulin", pl.mul_in, valid, r)
        vdata, mus, oor = r["data"], r["mu"], r["oor"]

        # ---------------------------------------------------------- E: multiply (in bank order)
        prods = []
        if pl.mul_halves:
            # two half-width partial products per weight (low half unsigned, high half signed),
            # registered, then one addition: mu * w = (mu * w_hi) * 2**kl + mu * w_lo, exactly
            kl = bw // 2
            parts = []
            for z in range(nz):
                for k in range(nb):
                    word = vdata[k][z * bw : (z + 1) * bw]
                    lo = 0  # a 1-bit weight has no low half
                    if kl:
                        lo = Signal(unsigned(dw + kl), name=f"pplo{z}_{k}")
                        m.d.comb += lo.eq(mus[k] * word[:kl])
                    prod_hi = mus[k] * word[kl:].as_signed()
                    hi = Signal(prod_hi.shape(), name=f"pphi{z}_{k}")  # the cell's own width
                    m.d.comb += hi.eq(prod_hi)
                    parts += [lo, hi]
            valid, r = pipe.stage("s_pp", True, valid, {"pp": parts, "oor": oor})
            oor = r["oor"]
            for i in range(nz * nb):
                z, k = divmod(i, nb)
                lo, hi = r["pp"][2 * i], r["pp"][2 * i + 1]
                if not kl:
                    prods.append(hi[:accw])
                    sink_unused(m, hi[accw:], f"prod{z}_{k}_top")
                    continue
                # hi * 2**kl + lo without operands of unequal widths (see _lintsafe): the low kl
                # bits are lo's; lo's upper dw bits are added to hi's lower dw bits (carry c); hi's
                # upper bits are taken + c (a constant addition and a multiplexer)
                lo_up, hi_lo, hi_up = lo[kl:], hi[:dw], hi[dw:]
                mid = Signal(unsigned(dw + 1), name=f"ppmid{z}_{k}")
                m.d.comb += mid.eq(hi_lo + lo_up)
                inc = add_const_wrap(m, hi_up, 1, f"ppinc{z}_{k}")
                up = Signal(unsigned(len(hi_up)), name=f"ppup{z}_{k}")
                with m.If(mid[dw]):
                    m.d.comb += up.eq(inc)
                with m.Else():
                    m.d.comb += up.eq(hi_up)
                pr = Cat(lo[:kl], mid[:dw], up)  # the exact product, at least accw + 1 bits
                sink_unused(m, pr[accw:], f"prod{z}_{k}_top")
                prods.append(pr[:accw])
        else:
            for z in range(nz):
                for k in range(nb):
                    w = vdata[k][z * bw : (z + 1) * bw].as_signed()
                    pr = Signal(signed(dw + bw), name=f"prod{z}_{k}")
                    m.d.comb += pr.eq(mus[k] * w)
                    sink_unused(m, pr[accw], f"prod{z}_{k}_top")
                    prods.append(pr[:accw])
        valid, r = pipe.stage("s_prod", pl.product, valid, {"p": prods, "oor": oor})
        prods, oor = r["p"], r["oor"]
        terms = [prods[z * nb : (z + 1) * nb] for z in range(nz)]

        if pl.flat_sum:  # one multi-operand sum per target (rounding constant included)
            accs, k = zip(*(self._flat_sum(m, row, z) for z, row in enumerate(terms)))
            if not self.round_output:
                return list(accs), oor, valid
            return self._round(m, list(accs), rounded=bool(k[0])), oor, valid

        # ---------------------------------------------------------- F: adder tree
        # the order of pwas_hdl.fixedpoint.reduction (as the bit-true model and the debug probes)
        levels = Pipeline.tree_depth(n)

        def add(a, b, lvl, i, z):
            s = Signal(signed(accw + 1), name=f"sum{lvl}_{z}_{i}")
            m.d.comb += s.eq(a.as_signed() + b.as_signed())
            if lvl == levels - 1:
                return s
            sink_unused(m, s[accw], f"sum{lvl}_{z}_{i}_top")
            return s[:accw]

        for lvl in range(levels):
            last = lvl == levels - 1
            terms = [tree_level(terms[z], lambda a, b, lv, i, z=z: add(a, b, lv, i, z), lvl) for z in range(nz)]
            if pl.tree_levels and ((lvl + 1) % pl.tree_levels == 0 or last):
                flat = [t for row in terms for t in row]
                valid, r = pipe.stage(f"s_tree{lvl}", True, valid, {"t": flat, "oor": oor})
                pos, new = 0, []
                for row in terms:
                    new.append(r["t"][pos : pos + len(row)])
                    pos += len(row)
                terms, oor = new, r["oor"]
        accs = [row[0] for row in terms]  # accw + 1 bits
        if not self.round_output:  # the exact sums go to the output register (additive sensor)
            return accs, oor, valid
        return self._round(m, accs), oor, valid

    def _flat_sum(self, m: Module, prods, z: int):
        """``sum(prods) (+ 2**(sh-1))`` as one modular sum of ``accw + 1``-bit operands (``flat_sum``).

        Every product (``accw`` signed bits) is sign-extended to ``W = accw + 1`` bits and every
        addition is done at ``W`` bits with its carry dropped (:func:`~pwas_hdl.hdl._lintsafe.sum_wrap`,
        the tree order of :mod:`pwas_hdl.fixedpoint.reduction`): no intermediate result is truncated
        or re-extended, so Yosys' ``alumacc`` merges the additions into one ``$macc`` (a carry-save
        tree of full adders and a single carry chain). Exact: the sum lies in the ``W``-bit signed
        range with the half-up constant added (see :meth:`_round`), and a sum modulo ``2**W`` does
        not depend on the order of its terms, so the result equals the tree sum plus the constant.

        Returns ``(acc, k)``: the ``W``-bit sum (unsigned view) and the constant included (0 when
        rounding is not half-up or ``sh`` is outside ``1 .. accw``; :meth:`_round` adds nothing more).
        """
        p = self.params
        accw, sh = p.acc_width, p.shift
        k = (1 << (sh - 1)) if p.rounding == "half_up" and 0 < sh <= accw and self.round_output else 0
        ext = [Cat(t, t[accw - 1]) for t in prods]
        if self.pipeline.counter_sum and 3 < len(ext) <= 6:
            return self._counter_sum(m, ext, k, accw + 1, f"fsum{z}"), k
        return sum_wrap(m, ext + [k], accw + 1, f"fsum{z}"), k

    @staticmethod
    def _counter_sum(m: Module, ops, k: int, width: int, name: str):
        """``(sum(ops) + k) mod 2**width`` through one level of column counters (``counter_sum``).

        Column ``c``'s bits of the ``len(ops) <= 6`` operands and bit ``c`` of the constant ``k`` are
        counted by a case table (a 4- to 6-input function per count bit: one wide LUT on ECP5); the
        count bits of weight ``2**i`` form the ``i``-th of ``ceil(log2(len(ops) + 2))`` words (shifted
        by ``i``), which one multi-operand sum adds (:func:`~pwas_hdl.hdl._lintsafe.sum_wrap`: a
        carry-save level and one carry chain). Exact modulo ``2**width``: column by column, the
        words add up to the operands plus ``k``.
        """
        nv = len(ops)
        cb = bits_for(nv + 1)
        words = [[] for _ in range(cb)]
        for c in range(width):
            kb = (k >> c) & 1
            cnt = rom(m, Cat(*[o[c] for o in ops]), [bin(v).count("1") + kb for v in range(1 << nv)], cb, f"{name}_n{c}")
            for i in range(cb):
                words[i].append(cnt[i])
        terms = []
        for i in range(cb):
            if width - i < len(words[i]):  # the count bits shifted out of the sum
                sink_unused(m, Cat(*words[i][width - i:]), f"{name}_w{i}_top")
            bits = words[i][: width - i]
            terms.append(Cat(Const(0, i), *bits) if i else Cat(*bits))
        return sum_wrap(m, terms, width, name)

    def _round(self, m: Module, accs, rounded: bool = False):
        """Rounding and saturation of the ``accw + 1``-bit sums to the output codes (one per target).

        ``rounded``: the half-up constant is already in the sums (:meth:`_flat_sum`).
        Shared with :class:`pwas_hdl.hdl.serial_core.SerialPWASCore`."""
        p = self.params
        nz, accw = p.nz, p.acc_width

        # ---------------------------------------------------------- G: round, saturate
        outw, sh = p.out_width, p.shift
        zs = []
        for z in range(nz):
            a = accs[z]
            if sh > accw:
                # |acc| <= 2**(accw-1) <= 2**(sh-1): the result is 0 (half up) or the sign (truncate)
                if p.rounding == "half_up":
                    sink_unused(m, a, f"acc{z}")
                    zs.append(Const(0, signed(outw)))
                    continue
                sink_unused(m, a[:-1], f"acc{z}")
                rv = a[-1:].as_signed()
            elif sh > 0:
                # exact in accw + 1 bits: acc + 2**(sh-1) <= 2**(accw-1) - 2**F + 2**(accw-1)
                rs = a.as_unsigned()
                if p.rounding == "half_up" and not rounded:
                    rs = add_const_wrap(m, rs, 1 << (sh - 1), f"rnd{z}")
                sink_unused(m, rs[:sh], f"rnd{z}_frac")
                rv = rs[sh:].as_signed()
            elif sh == 0:
                rv = a.as_signed()
            else:
                rv = Cat(Const(0, -sh), a).as_signed()
            if len(rv) <= outw:
                zs.append(rv)
                continue
            if getattr(self.pipeline, "prune_sat", False) and self._sat_unreachable(z):
                sink_unused(m, rv[outw:], f"sat{z}_top")  # copies of the sign bit: never saturates
                zs.append(rv[:outw].as_signed())
                continue
            sign = rv[-1]
            upper = rv[outw - 1 : len(rv) - 1]
            o = Signal(signed(outw), name=f"sat{z}")
            with m.If(~sign & upper.any()):
                m.d.comb += o.eq((1 << (outw - 1)) - 1)
            with m.Elif(sign & ~upper.all()):
                m.d.comb += o.eq(-(1 << (outw - 1)))
            with m.Else():
                m.d.comb += o.eq(rv[:outw])
            zs.append(o)
        return zs

    def _sat_unreachable(self, z: int) -> bool:
        """True when no input can make target ``z``'s rounded sum leave the ``B_out``-bit range.

        ``mu_k >= 0`` and ``sum_k mu_k = 2**F`` (every input, clamped or not), so the exact sum lies
        in ``[min_v w_vz, max_v w_vz] * 2**F`` over the weights in the memories; the rounding
        (``(acc + 2**(sh-1)) >> sh``, ``acc >> sh`` or ``acc << -sh``) is monotonic. When both ends
        map inside ``[-2**(B_out-1), 2**(B_out-1) - 1]`` the saturation never acts and
        ``prune_sat`` leaves it out (the bit-true model's saturation is then the identity).
        """
        p = self.params
        sh, outw, big_f = p.shift, p.out_width, p.frac
        w = p.weights[:, z]

        def out(acc: int) -> int:
            if sh > 0:
                return (acc + ((1 << (sh - 1)) if p.rounding == "half_up" else 0)) >> sh
            return acc << -sh

        lo, hi = out(int(w.min()) << big_f), out(int(w.max()) << big_f)
        return -(1 << (outw - 1)) <= lo and hi <= (1 << (outw - 1)) - 1

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _name(m: Module, value, name: str, shape=None):
        s = Signal(shape if shape is not None else unsigned(len(value)), name=name)
        m.d.comb += s.eq(value)
        return s

    @staticmethod
    def _first_level(values, combine, modulus: int) -> list:
        """The first level of a pairwise reduction of ``values`` (ints folded into one constant
        ``mod modulus``, kept last when non-zero): ``combine(a, b, i)`` joins two nets."""
        const = sum(v for v in values if isinstance(v, int)) % modulus
        nets = [v for v in values if not isinstance(v, int)]
        out = tree_level(nets, lambda a, b, _lvl, i: combine(a, b, i), 0) if len(nets) > 2 else nets
        return out + ([const] if const else [])

    def _rotation(self, m: Module, cs, nb: int, rbits: int, tables: bool = False):
        """``rot = |c| mod nb``: the cells' sum (an adder tree of equal-width operands) and one table,
        when that sum has at most 6 bits and not ``tables``; else the residues' tables
        (:meth:`_modsum`: no carry chain)."""
        p = self.params
        const = sum(c for c in cs if isinstance(c, int))
        nets = [c for c in cs if not isinstance(c, int)]
        total = const + sum(pj - 1 for pj, c in zip(p.partitions, cs) if not isinstance(c, int))

        def width(a, b, _lvl, _i):  # the tree's operand widths (None: unequal somewhere)
            return a + 1 if a is not None and a == b else None

        def add(a, b, lvl, i):
            s = Signal(unsigned(len(a) + 1), name=f"csum{lvl}_{i}")
            m.d.comb += s.eq(a + b)
            return s

        if len(nets) >= 2 and bits_for(total) <= 6 and not tables:
            w = tree_reduce([len(c) for c in nets], width)
            if w is not None and w <= 6:
                sm = tree_reduce(nets, add)
                return rom(m, sm, [(v + const) % nb for v in range(1 << len(sm))], rbits, "rot")
        res = [rom(m, c, [i % nb for i in range(pj)], rbits, f"cres{j}") for j, (c, pj) in enumerate(zip(cs, p.partitions))]
        return self._modsum(m, res, nb, rbits, "rot")

    @staticmethod
    def _modsum(m: Module, res, nb: int, rbits: int, name: str):
        """``sum(res) mod nb`` for residues in ``0 .. nb-1`` (case tables, no arithmetic)."""
        consts = sum(r for r in res if isinstance(r, int)) % nb
        vals = [r for r in res if not isinstance(r, int)]
        if not vals:
            return consts
        table = [((x & ((1 << rbits) - 1)) + (x >> rbits)) % nb for x in range(1 << (2 * rbits))]
        v = tree_reduce(vals, lambda a, b, lvl, i: rom(m, Cat(a, b), table, rbits, f"{name}_{lvl}_{i}"))
        if consts:
            v = rom(m, v, [(x + consts) % nb for x in range(nb)], rbits, f"{name}_k")
        return v
