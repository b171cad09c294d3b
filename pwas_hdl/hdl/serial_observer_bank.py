"""The time-multiplexed ("serial") observer bank and feature unit of seed 004 (issue 12, item 2).

Bit for bit :class:`pwas_hdl.fixedpoint.observer_bank.FixedPointObserverBank`, as the parallel
bank (:mod:`pwas_hdl.hdl.observer_bank`), but with **one state-update unit per lane** shared over
the ``M`` states of the lane's observers, one state update per clock:

* the ``N_theta`` observers are split into ``lanes`` contiguous groups (``ceil(N / lanes)``
  observers in the first ones); a lane holds its states in one **rotating chain** of
  ``n_L * M`` registers in the order ``(j, 0), (j, 1), .., (j + 1, 0), ..``: in step ``s``
  the head is ``x_{j,i}`` and the next register ``x_{j,i+1}`` (0 for ``i = M - 1``), the new
  state goes to the tail and the chain shifts, so after ``n_L M`` steps (+ 1 flush, below) it is in order again
  and no wide read multiplexer is needed. ``x_{j,0}`` before the update is held for the
  observer's later steps;
* the update ``acc_i = A0_i x_0 + ((sum_c Bc_ic qu_c + Lc_i qy) << (F_s - F_in)) + Dc_i +
  2**(F_c-1) + (x_{i+1} << F_c)``, ``x_i' = sat((acc_i) >> F_c)`` with the coefficients from a
  table indexed by the step (``nu + 2`` variable multipliers per lane instead of
  ``N M (nu + 2)`` constant ones). The sum is an exact integer sum in the declared accumulator
  width, so its order does not matter and the rounding / saturation are the bit-true model's.
  The update is pipelined (:data:`MAC_STAGES` = 2): the products (and ``x_{i+1}``, ``Dc_i``)
  are registered in the step's cycle, the sum, rounding and saturation follow in the next cycle and enter the chain's tail;
  the chain shifts ``n_L M + 1`` times per sample (the extra *flush* shift drops the one stale
  tail entry of the first step and brings the last update in), so it is in order again;
* at step ``i = 0`` of observer ``j``: the residual ``e_j = x_{j,0} - (qy << (F_s - F_in))``,
  ``e_j**2`` (one squarer per lane), the running sum ``S_j`` (a rotating chain like the states)
  and the delay line of ``l + 1`` squares: one memory per lane (block / distributed RAM instead
  of ``N (l + 1)`` registers), word ``(j, slot)``, ``slot`` = sample number mod ``l + 1``; the
  oldest square is read one cycle before the window sum's update and counts as 0 until ``l + 1`` samples have
  been taken since reset (the bit-true delay line is 0 after reset); the new ``S_j`` enters a
  free-running feature pipeline: register, integer square root (11b; a register after every
  ``isqrt_every`` digit steps) or ``S`` itself (11b-sq), root register, the affine map to the
  core's input code with the constants from a table (one multiplier per lane; the capped root and
  the product registered: :data:`AFFINE_REGS` = 2), and the code register of feature ``j``.

Schedule (transfer of sample ``k`` in cycle ``t``; the inputs are latched): step ``s`` of every
lane in cycle ``t + 1 + s`` (``s < n_L M``); feature ``j`` (step ``s_j = (j - j_L) M`` in its
lane) is in its code register from cycle ``t + 1 + s_j + 3 + Q + R + A`` (``R``: the square root's
internal registers, ``A`` = :data:`AFFINE_REGS`); all codes from ``t + stages_before_core``,
``stages_before_core = 4 + Q + R + A + (n_max - 1) M`` (``Q`` = :data:`SQUARE_REGS`: the
residual, then its square registered before the window sum). ``cycles_per_sample = max(n_max M + 1, stages_before_core, core II)`` (``+ 1``:
the flush of the state-update pipeline):
``in.ready`` is high when the bank is idle or in its last cycle, and the previous sample's
feature codes have been taken by the core (or are taken in this cycle). II = cycles_per_sample.
With double-buffered codes (``plan_serial_bank(..., double_buffered=True)``, the observer sensor
top) the lanes write staging registers that are copied into the core's buffer (``buffer_load``),
and the II drops to ``max(n_max M + 1, ceil(stages_before_core / 2), (n_max - 1) M + 3, core II)``
(:func:`plan_serial_bank`; flow control in
:func:`pwas_hdl.hdl.observer_sensor_top.serial_sensor_path`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, signed, unsigned
from amaranth.lib.memory import Memory

from pwas_hdl.errors import InputError, InternalError
from pwas_hdl.hdl._lintsafe import add_const_wrap, add_wrap, bits_for, ge_const, rom, sink_unused
from pwas_hdl.hdl.observer_bank import _cbits, _sum, add_const_signed, const_product, saturate
from pwas_hdl.hdl.residual_features import cap_const

if TYPE_CHECKING:
    from pwas_hdl.fixedpoint.observer_bank import FixedPointObserverBank

__all__ = ["SerialBankPlan", "plan_serial_bank", "build_serial_front_end", "build_isqrt_pipelined", "isqrt_registers", "check_isqrt_every", "var_product",
           "table_mac", "lane_groups", "DEFAULT_ISQRT_EVERY"]

#: Digit steps of the integer square root between two pipeline registers (serial bank). 3: with the
#: state update, the square and the affine map pipelined, a register every 8 digits (the earlier
#: default) left the square root the critical path of the N3 11b design on the LFE5U-45F (8 digit
#: steps, 32.5 ns); every 3 steps it measured 76.1 MHz at II 26 (13.1 ns, still the square root),
#: the most samples/s of 2..4 by the estimate fmax / II (benchmarks/results/observer_bank_synth.md).
DEFAULT_ISQRT_EVERY = 3
#: Register stages of a lane's state update (products registered, then sum / round / saturate).
MAC_STAGES = 2
#: Registers inside the feature unit's affine map (the capped root; the product).
AFFINE_REGS = 2
#: Registers between a residual and the window sum (the residual; its square).
SQUARE_REGS = 2


@dataclass(frozen=True)
class SerialBankPlan:
    """Schedule of the time-multiplexed bank (all counts in clock cycles).

    Attributes
    ----------
    lanes : tuple of tuples of int
        The observers of each lane (contiguous, the first lanes the longest).
    order : int
        ``M``: the bank's observer order (state-update steps per observer and sample).
    steps : int
        ``n_max * M``: state-update steps (cycles) per sample of the longest lane.
    isqrt_every : int or None
        Digit steps of the square root between pipeline registers (None: no registers, or map
        11b-sq, which has no square root).
    isqrt_regs : int
        ``R``: registers inside the square root (0 for 11b-sq or ``isqrt_every`` None).
    stages_before_core : int
        Cycles from the input transfer to the core's input valid (``4 + SQUARE_REGS + R + AFFINE_REGS + (n_max - 1) M``).
    cycles_per_sample : int
        The II in cycles: ``max(steps + MAC_STAGES - 1, stages_before_core, core_ii)``; with double-buffered
        feature codes ``max(steps + MAC_STAGES - 1, ceil(stages_before_core / 2),
        (n_max - 1) M + SQUARE_REGS + 1, core_ii)``.
    double_buffered : bool
        The feature codes are double-buffered (:func:`build_serial_front_end` with ``buffer_load``):
        the next sample may enter while the previous one is still in the feature pipeline.
    """

    lanes: tuple
    order: int
    steps: int
    isqrt_every: int | None
    isqrt_regs: int
    stages_before_core: int
    cycles_per_sample: int
    double_buffered: bool = False

    def to_dict(self) -> dict:
        """JSON-ready schedule (the manifest's description of the serial bank).

        Returns
        -------
        dict
            ``lanes`` (count), ``observers_per_lane``, ``steps``, the register counts
            (``mac_stages``, ``affine_registers``, ``square_registers``, ``isqrt_registers``),
            ``isqrt_every``, ``stages_before_core``, ``cycles_per_sample`` (clock cycles) and
            ``double_buffered_codes``.
        """
        return {"lanes": len(self.lanes), "observers_per_lane": [len(ln) for ln in self.lanes], "steps": self.steps,
                "mac_stages": MAC_STAGES, "affine_registers": AFFINE_REGS, "square_registers": SQUARE_REGS,
                "isqrt_every": self.isqrt_every, "isqrt_registers": self.isqrt_regs,
                "stages_before_core": self.stages_before_core, "cycles_per_sample": self.cycles_per_sample,
                "double_buffered_codes": self.double_buffered}


def check_isqrt_every(isqrt_every: Any) -> None:
    """Refuse an ``isqrt_every`` that is not a positive integer or None.

    Parameters
    ----------
    isqrt_every : Any
        Digit steps of a square root between its registers, as given.

    Raises
    ------
    InputError
        Otherwise.
    """
    if isqrt_every is not None and (isinstance(isqrt_every, bool) or not isinstance(isqrt_every, int) or isqrt_every < 1):
        raise InputError(f"isqrt_every must be a positive integer or None, got {isqrt_every!r}")


def check_isqrt_every_option(isqrt_every: Any, has_bank: bool) -> None:
    """Refuse a user's ``--isqrt-every`` (``generate``, ``explore``) before anything is built: not a
    positive integer, or given for a model without an observer bank. The bank itself is checked by
    :func:`check_root_spacing`.

    Parameters
    ----------
    isqrt_every : Any
        The value as given; None: not given, nothing to check.
    has_bank : bool
        The model has an observer-bank front end.

    Raises
    ------
    InputError
        One of the two cases above.
    """
    if isqrt_every is None:
        return
    opt = "--isqrt-every (isqrt_every)"
    if isinstance(isqrt_every, bool) or not isinstance(isqrt_every, int) or isqrt_every < 1:
        raise InputError(f"{opt} must be a positive integer (digit steps of the square root between registers; "
                         f"default {DEFAULT_ISQRT_EVERY}), got {isqrt_every!r}")
    if not has_bank:
        raise InputError(f"{opt} applies to observer-bank sensors (fit --front-end observer-bank), whose features take "
                         "a square root; this model has no observer bank: leave it out")


def check_root_spacing(bank: FixedPointObserverBank, isqrt_every: int | None) -> None:
    """Refuse a root register spacing given by the user (``--isqrt-every``) that leaves no register
    inside the bank's square root, or a bank without one (map 11b-sq).

    Parameters
    ----------
    bank : FixedPointObserverBank
        The bit-true bank (feature map and window-sum width: the root's ``ceil(sum_bits / 2)`` digit steps).
    isqrt_every : int or None
        The spacing as given (a positive integer, :func:`check_isqrt_every`); None: nothing to check.

    Raises
    ------
    InputError
        The map has no square root, or ``isqrt_every`` is at least the root's digit steps.
    """
    if isqrt_every is None:
        return
    opt = "--isqrt-every (isqrt_every)"
    if bank.feature_map != "11b":
        raise InputError(f"{opt} applies to the 11b feature map (the square root of each window sum); this bank's map "
                         f"is {bank.feature_map}, which has no root: leave it out")
    steps = (bank.formats.sum_bits + 1) // 2
    if isqrt_every > steps - 1:
        raise InputError(f"{opt} = {isqrt_every} puts no register inside the square root: it has {steps} digit steps "
                         f"(window sums of {bank.formats.sum_bits} bits); give 1 .. {steps - 1}")


def isqrt_registers(bank: FixedPointObserverBank, every: int | None) -> int:
    """Registers :func:`build_isqrt_pipelined` puts into a feature's square root (the window sum of
    ``bank.formats.sum_bits`` bits, a register after every ``every`` digit steps); 0 for map 11b-sq
    (no root) or ``every`` None.

    Parameters
    ----------
    bank : FixedPointObserverBank
        The bit-true bank (feature map and sum width).
    every : int or None
        Digit steps between registers.

    Returns
    -------
    int
        The number of registers, the cycles the root takes.
    """
    if bank.feature_map != "11b" or not every:
        return 0
    pairs = (bank.formats.sum_bits + 1) // 2
    return len([i for i in range(1, pairs) if i % every == 0])


def lane_groups(n: int, lanes: int) -> tuple[tuple[int, ...], ...]:
    """``n`` units split into contiguous groups of ``ceil(n / lanes)`` (the first ones the longest; fewer
    groups than ``lanes`` where ``lanes`` does not divide evenly, e.g. 4 in 3 lanes: (0, 1), (2, 3)).

    Parameters
    ----------
    n : int
        Number of units (observers), ``n >= 1``.
    lanes : int
        Number of lanes asked for, ``1 .. n``.

    Returns
    -------
    tuple of tuple of int
        The unit indices of each group, ``0 .. n-1`` in order.
    """
    per = math.ceil(n / lanes)
    return tuple(tuple(range(s, min(n, s + per))) for s in range(0, n, per))


def plan_serial_bank(bank: FixedPointObserverBank, lanes: int = 1, isqrt_every: int | None = DEFAULT_ISQRT_EVERY,
                     core_ii: int = 1, double_buffered: bool = False) -> SerialBankPlan:
    """The schedule of a serial bank of ``lanes`` state-update units for ``bank`` (a FixedPointObserverBank).

    ``double_buffered``: the feature codes written by the lanes (staging) are copied into a second
    set of registers that the core reads, and at most two warm samples are between the input and
    the core's take (one in the core's buffer, one in the bank or held in staging): the II is then
    ``max(steps + 1, ceil(stages_before_core / 2), (n_max - 1) M + SQUARE_REGS + 1, core_ii)``
    instead of the feature pipeline's whole tail (a sample's staging writes span
    ``(n_max - 1) M + 1 <= steps`` cycles, so two samples' writes never meet; sample ``k + 2``
    enters no earlier than the cycle the core takes sample ``k``, ``stages_before_core`` cycles
    after sample ``k``'s transfer; the third term: a sample's delay-line slot is read up to its
    last observer's window sum).

    Parameters
    ----------
    bank : FixedPointObserverBank
        Gives ``N_theta`` (``n_models``), ``M`` (``order``), the feature map and the window-sum width.
    lanes : int
        State-update units, ``1 .. N_theta``.
    isqrt_every : int or None
        Digit steps of the square root between pipeline registers; None: no registers (map 11b
        only; ignored for 11b-sq).
    core_ii : int
        The core's initiation interval, cycles.
    double_buffered : bool
        Double-buffered feature codes (see above).

    Returns
    -------
    SerialBankPlan
        All counts in clock cycles.

    Raises
    ------
    InputError
        ``lanes`` not in ``1 .. N_theta`` or ``isqrt_every`` not a positive integer / None.
    """
    n, mo = bank.n_models, bank.order
    if isinstance(lanes, bool) or not isinstance(lanes, int) or not 1 <= lanes <= n:
        raise InputError(f"bank lanes (--bank-lanes) must be an integer in 1 .. {n} (the number of observers), got {lanes!r}")
    check_isqrt_every(isqrt_every)
    groups = lane_groups(n, lanes)
    n_max = len(groups[0])
    r = isqrt_registers(bank, isqrt_every)
    sbc = 4 + SQUARE_REGS + r + AFFINE_REGS + (n_max - 1) * mo
    # double-buffered: half the tail, and the sample's slot / oldest-square flag (updated at the next
    # transfer) are read up to its last observer's window sum, (n_max - 1) M + SQUARE_REGS + 1 cycles on
    tail = max(-(-sbc // 2), (n_max - 1) * mo + SQUARE_REGS + 1) if double_buffered else sbc
    cps = max(n_max * mo + MAC_STAGES - 1, tail, int(core_ii))  # + the flush of the state-update pipeline
    return SerialBankPlan(groups, mo, n_max * mo, isqrt_every if bank.feature_map == "11b" else None, r, sbc, cps,
                          bool(double_buffered))


def var_product(m: Module, coef: Value, x: Value, width: int, name: str) -> Signal:
    """``coef * x`` (two signed nets) as a named product net of exactly ``width`` bits.

    The multiplier cell's output is the named net; give ``coef`` ``width - len(x)`` bits (a table
    of that width, :func:`_table`) so that the cell's natural width is the product width (no
    extension in front of the adders: lint-clean, as ``const_product``).

    Parameters
    ----------
    m : Module
        Module the multiplier is added to (``comb`` domain).
    coef, x : Value
        The factors, read as signed.
    width : int
        Product width, bits (at least ``len(coef) + len(x)``).
    name : str
        Name of the product net.

    Returns
    -------
    Signal
        Signed ``width`` bits.

    Raises
    ------
    InternalError
        ``len(coef) + len(x) > width`` (the plan sizes every product: a bug, not bad input).
    """
    if len(coef) + len(x) > width:
        raise InternalError(f"a {len(coef)} x {len(x)}-bit product does not fit {width} bits (product {name})")
    p = Signal(signed(width), name=name)
    m.d.comb += p.eq(coef.as_signed() * x.as_signed())
    return p


def _table(m: Module, sel, values: list[int], name: str, width: int | None = None):
    """Signed table ``values[sel]`` as a signed net of the values' width or ``width`` (a Const when all equal)."""
    w = width or max(_cbits(int(v)) for v in values)
    if max(_cbits(int(v)) for v in values) > w:
        raise InternalError(f"a constant of table {name} does not fit {w} bits")
    t = rom(m, sel, [int(v) % (1 << w) for v in values], w, name)
    if isinstance(t, int):
        return Const(int(values[0]), signed(w))
    return t.as_signed()


def table_mac(m: Module, sel: Value, columns: Sequence[Sequence[int]], operands: Sequence[Value], width: int, name: str,
              registered: bool = False, product_enable: Value | None = None,
              shifts: Sequence[int] | None = None) -> Value | None:
    """``sum_k columns[k][sel] * operands[k]``: one variable multiplier per operand with its
    coefficient from a table indexed by ``sel`` (the step of a time-multiplexed unit), summed exactly
    in ``width`` bits (the caller's bound; the order of an exact sum does not matter).

    Parameters
    ----------
    m : Module
        Module the tables, multipliers and adders are added to.
    sel : Value
        Unsigned table index (entries beyond a column's length are 0, except in a column whose
        entries are all equal: a constant, :func:`~pwas_hdl.hdl._lintsafe.rom`).
    columns : sequence of sequence of int
        One signed coefficient column per operand; an all-zero column adds no multiplier.
    operands : sequence of Value
        Signed nets, one per column.
    width : int
        The accumulator width, bits (every product is a ``width``-bit net, :func:`var_product`).
    name : str
        Name prefix of the tables (``<name>_c<k>``), products (``<name>_p<k>``) and sum
        (``<name>_acc``).
    registered : bool
        The coefficients from (reset-less) registers loaded with ``columns[k][sel]`` in every
        cycle: give the *next* cycle's index as ``sel`` (the table decode leaves the datapath).
    product_enable : 1-bit net, optional
        Register every product (loaded when the net is high): the sum is then one cycle behind the
        operands (a pipelined MAC).
    shifts : list of int, optional
        Per operand: the product is ``(columns[k][sel] * operands[k]) << shifts[k]`` (a narrower
        multiplier for coefficients with ``shifts[k]`` trailing zero bits: give the columns unshifted).

    Returns
    -------
    Value or None
        The signed ``width``-bit sum, or None when every column is 0.

    Raises
    ------
    InputError
        A coefficient does not fit its table width (``width - shifts[k] - len(operands[k])``
        signed bits).
    """
    terms = []
    shifts = list(shifts) if shifts is not None else [0] * len(operands)
    for k, (col, x) in enumerate(zip(columns, operands)):
        if any(int(v) for v in col):
            pw = width - shifts[k]  # the product's width before the shift
            c = _table(m, sel, [int(v) for v in col], f"{name}_c{k}", width=pw - len(x))
            if registered and not isinstance(c, Const):
                r = Signal(signed(len(c)), name=f"{name}_c{k}_reg", reset_less=True)
                m.d.sync += r.eq(c)
                c = r
            p = var_product(m, c, x, pw, f"{name}_p{k}")
            if product_enable is not None:
                pr = Signal(signed(pw), name=f"{name}_p{k}_reg", reset_less=True)
                with m.If(product_enable):
                    m.d.sync += pr.eq(p)
                p = pr
            terms.append(Cat(Const(0, shifts[k]), p).as_signed() if shifts[k] else p)
    return _sum(m, terms, width, f"{name}_acc") if terms else None


def build_isqrt_pipelined(m: Module, value: Value, name: str, every: int | None,
                          enable: Value | None = None) -> tuple[Value, int]:
    """``floor(sqrt(value))`` digit by digit as :func:`pwas_hdl.hdl.residual_features.build_isqrt`,
    with a reset-less register after every ``every`` digit steps (free-running, or loading when
    ``enable`` is high).

    Parameters
    ----------
    m : Module
        Module the logic is added to (registers in ``sync``).
    value : Value
        Unsigned radicand.
    name : str
        Name prefix of the step nets and registers.
    every : int or None
        Digit steps between registers; None or 0: no registers (combinational).
    enable : Value or None
        1 bit: the registers load when it is high (a stalling pipeline: the parallel bank's
        ``advance``); None: every clock (the serial bank's token pipeline).

    Returns
    -------
    root : Value
        Unsigned ``ceil(len(value) / 2)`` bits.
    registers : int
        Number of registers inserted: ``root`` is valid that many (enabled) cycles after ``value``.
    """
    w = len(value)
    pairs = (w + 1) // 2
    v = Cat(value, Const(0, 2 * pairs - w)) if 2 * pairs > w else value
    two0 = v[2 * pairs - 2 : 2 * pairs]
    b0 = Signal(name=f"{name}_b0")
    m.d.comb += b0.eq(two0.any())
    rem = rom(m, two0, [0, 0, 1, 2], 2, f"{name}_m0")  # two - (two != 0)
    if isinstance(rem, int):
        rem = Const(rem, 2)
    bits = [b0]
    regs = 0
    for i in range(1, pairs):
        if every and i % every == 0:  # pipeline register: the input bits still to come, the remainder, the root so far
            lo_need = 2 * (pairs - i)
            vr = Signal(unsigned(lo_need), name=f"{name}_r{regs}_v", reset_less=True)
            rr = Signal(unsigned(len(rem)), name=f"{name}_r{regs}_m", reset_less=True)
            br = Signal(unsigned(len(bits)), name=f"{name}_r{regs}_b", reset_less=True)
            loads = [vr.eq(v[:lo_need]), rr.eq(rem), br.eq(Cat(*bits))]
            if enable is None:
                m.d.sync += loads
            else:
                with m.If(enable):
                    m.d.sync += loads
            v, rem, bits = vr, rr, [br[k] for k in range(len(bits))]
            regs += 1
        lo = 2 * (pairs - 1 - i)
        two = v[lo : lo + 2]
        root = Cat(*reversed(bits))
        trial = Cat(Const(1, 2), root)
        cur_lo = Cat(two, rem[:i])
        diff = Signal(unsigned(i + 3), name=f"{name}_d{i}")
        m.d.comb += diff.eq(cur_lo - trial)
        bit = Signal(name=f"{name}_b{i}")
        m.d.comb += bit.eq(rem[i] | ~diff[i + 2])
        nrem = Signal(unsigned(i + 2), name=f"{name}_m{i}")
        m.d.comb += nrem.eq(Mux(bit, diff[: i + 2], cur_lo))
        rem = nrem
        bits.append(bit)
    sink_unused(m, rem, f"{name}_rem")
    return Cat(*reversed(bits)), regs


def eq_const(x: Value, k: int) -> Value:
    """``x == k`` for an unsigned net and a constant (lint-clean: the constant at ``k``'s own width,
    the bits above it reduced).

    Parameters
    ----------
    x : Value
        Unsigned net.
    k : int
        Non-negative constant.

    Returns
    -------
    Value
        1 bit; ``Const(0, 1)`` when ``k >= 2**len(x)``.
    """
    if k == 0:
        return ~x.any()
    if k >= 1 << len(x):
        return Const(0, 1)
    kb = int(k).bit_length()
    low = x[:kb] == Const(k, kb)  # at the constant's own width (as ge_const)
    return low if kb == len(x) else low & ~x[kb:].any()


def _delay(m: Module, sig, n: int, name: str, reset_less: bool):
    for d in range(n):
        r = Signal(len(sig), name=f"{name}_d{d}", reset_less=reset_less)
        m.d.sync += r.eq(sig)
        sig = r
    return sig


def _coef_reg(m: Module, sel, values: list[int], name: str, width: int):
    """``values[sel]`` registered (free-running, reset-less) as a signed ``width``-bit net; a
    Const when the table is constant (nothing to register)."""
    t = _table(m, sel, values, f"{name}_tab", width=width)
    if isinstance(t, Const):
        return t
    r = Signal(signed(width), name=name, reset_less=True)
    m.d.sync += r.eq(t)
    return r


def _product_reg(m: Module, coef, x, width: int, name: str):
    """``coef * x`` (:func:`var_product`) in a free-running register (MAC stage 1 -> stage 2)."""
    p = var_product(m, coef, x, width, name)
    r = Signal(signed(width), name=f"{name}_r", reset_less=True)
    m.d.sync += r.eq(p)
    return r


def build_serial_front_end(m: Module, bank: FixedPointObserverBank, plan: SerialBankPlan, cur: Sequence[Value],
                           transfer: Value, sample_warm: Value,
                           buffer_load: Signal | None = None) -> tuple[list[Signal], Signal, Signal]:
    """Add the time-multiplexed bank and feature unit to ``m``.

    Parameters
    ----------
    m : Module
        Module the bank, the feature unit and their registers are added to.
    bank : FixedPointObserverBank
        The bit-true bank: coefficient codes, formats, window, feature map.
    plan : SerialBankPlan
        Its schedule (:func:`plan_serial_bank`).
    cur : sequence of Value
        Signed ``B_in``-bit codes ``u0 .. y0`` (the input payload; latched on ``transfer``).
    transfer : Value
        1 bit, the input transfer.
    sample_warm : Value
        1-bit register: the sample being processed yields an output (set by the caller at the transfer).
    buffer_load : Signal, optional
        1-bit net, driven by the caller.
        Double-buffered codes (``plan.double_buffered``): the returned ``codes`` are a second set of
        registers loaded when the net is high with the staging codes (``feat{j}_code``), the one
        being written in that cycle taken from its write (so a load in ``done``'s cycle holds the
        sample's complete codes).

    Returns
    -------
    codes : list of Signal
        ``N`` registers of signed ``input_bits_core`` bits, the core's input codes (the buffer
        when ``buffer_load`` is given).
    done : Signal
        1 bit, high in the cycle the last feature code of a warm sample is written.
    free : Signal
        1 bit, the bank is idle or in its last cycle (a transfer may start the next sample).

    Raises
    ------
    InternalError
        ``buffer_load`` given for a single-buffered plan or missing for a double-buffered one,
        or an observer constant wider than the accumulator (the plan sized it: a bug).
    """
    fmt = bank.formats
    mo, nu = bank.order, bank.nu
    fc, fs, fin = fmt.coef_frac, fmt.state_frac, fmt.input_frac
    bs, accw, rb, sumb = fmt.state_bits, fmt.acc_bits, fmt.residual_bits, fmt.sum_bits
    sh_in = fs - fin
    lw = bank.window
    t_cps = plan.cycles_per_sample

    # ---- inputs latched at the transfer
    lat = [Signal(signed(bank.input_bits), name=f"bank_in{c}", reset_less=True) for c in range(len(cur))]
    with m.If(transfer):
        m.d.sync += [r.eq(c) for r, c in zip(lat, cur)]
    qu, qy = lat[:nu], lat[nu]

    # ---- step counter: busy for cycles t+1 .. t+cps
    stw = bits_for(t_cps - 1)
    st = Signal(unsigned(stw), name="bank_step")
    busy = Signal(name="bank_busy")
    last = Signal(name="bank_last")
    m.d.comb += last.eq(busy & eq_const(st, t_cps - 1))
    sw_i = bits_for(mo - 1)
    si = Signal(unsigned(sw_i), name="bank_state_index")  # i of the step
    ow = bits_for(max(len(g) for g in plan.lanes) - 1)
    oj = Signal(unsigned(ow), name="bank_observer_index")  # observer within the lane
    with m.If(transfer):
        m.d.sync += [st.eq(0), busy.eq(1), si.eq(0), oj.eq(0)]
    with m.Elif(busy):
        with m.If(last):
            m.d.sync += busy.eq(0)
        with m.Else():
            m.d.sync += st.eq(add_const_wrap(m, st, 1, "bank_step_inc"))
        if mo > 1:
            with m.If(eq_const(si, mo - 1)):
                m.d.sync += [si.eq(0), oj.eq(add_const_wrap(m, oj, 1, "bank_obs_inc"))]
            with m.Else():
                m.d.sync += si.eq(add_const_wrap(m, si, 1, "bank_si_inc"))
        else:
            m.d.sync += oj.eq(add_const_wrap(m, oj, 1, "bank_obs_inc"))
    free = Signal(name="bank_free")
    m.d.comb += free.eq(~busy | last)
    first_state = Signal(name="bank_first_state")
    m.d.comb += first_state.eq(eq_const(si, 0)) if mo > 1 else first_state.eq(1)
    last_state = Signal(name="bank_last_state")
    m.d.comb += last_state.eq(eq_const(si, mo - 1)) if mo > 1 else last_state.eq(1)

    # ---- delay-line slot of the sample (circular, l + 1 slots) and whether it was written since reset
    slw = bits_for(lw)
    wptr = Signal(unsigned(slw), name="bank_dl_next_slot")
    slot = Signal(unsigned(slw), name="bank_dl_slot")
    cnt = Signal(unsigned(bits_for(lw + 1)), name="bank_dl_count")
    old_valid = Signal(name="bank_dl_old_valid")
    with m.If(transfer):
        wrap = eq_const(wptr, lw)
        m.d.sync += [slot.eq(wptr), wptr.eq(Mux(wrap, 0, add_const_wrap(m, wptr, 1, "bank_dl_slot_inc"))),
                     old_valid.eq(ge_const(cnt, lw + 1))]
        with m.If(~ge_const(cnt, lw + 1)):
            m.d.sync += cnt.eq(add_const_wrap(m, cnt, 1, "bank_dl_count_inc"))

    qy_al = const_product(m, 1 << sh_in, qy, rb, "bank_y_aligned")
    codes = [Signal(signed(bank.input_bits_core), name=f"feat{j}_code", reset_less=True) for j in range(bank.n_models)]
    done = Signal(name="bank_features_done")
    if (buffer_load is not None) != plan.double_buffered:
        raise InternalError("buffer_load is given exactly for a double-buffered plan")
    buf = ([Signal(signed(bank.input_bits_core), name=f"feat{j}_code_buf", reset_less=True) for j in range(bank.n_models)]
           if buffer_load is not None else None)
    sat_flags = []
    for ln, group in enumerate(plan.lanes):
        nl = len(group)
        steps = nl * mo
        pre = f"lane{ln}"
        active = Signal(name=f"{pre}_active")
        m.d.comb += active.eq(busy & ~ge_const(st, steps) if steps < (1 << stw) else busy)
        # ---- state chain
        chain = [Signal(signed(bs), name=f"{pre}_x{k}") for k in range(steps)]
        head = chain[0]
        nxt = Signal(signed(bs), name=f"{pre}_x_next")
        if steps > 1:
            m.d.comb += nxt.eq(Mux(last_state, 0, chain[1]))
        else:
            m.d.comb += nxt.eq(0)
        # coefficients of step (j, i) in lane order (tables indexed by the step); the products are
        # registered (MAC stage 1, the step's cycle), the sum, rounding and saturation follow in the
        # next cycle (stage 2) and go to the chain's tail
        order = [(j, i) for j in group for i in range(mo)]
        a0 = [int(bank.a0_codes[j, i]) for j, i in order]
        terms = []
        if any(a0):  # x_{j,0} before the update: the head in step i = 0, held for the later steps
            x0_hold = Signal(signed(bs), name=f"{pre}_first_hold", reset_less=True)
            x0 = Signal(signed(bs), name=f"{pre}_first")
            m.d.comb += x0.eq(Mux(first_state, head, x0_hold))
            with m.If(active & first_state):
                m.d.sync += x0_hold.eq(head)
            terms.append(_product_reg(m, _table(m, st, a0, f"{pre}_a0", width=accw - bs), x0, accw, f"{pre}_pa"))
        inj = []  # the input alignment << (F_s - F_in) folded into the tabled coefficients (as the parallel bank)
        for c in range(nu):
            bv = [int(bank.b_codes[j, i, c]) << sh_in for j, i in order]
            if any(bv):
                inj.append(_product_reg(m, _table(m, st, bv, f"{pre}_b{c}", width=accw - len(qu[c])), qu[c], accw,
                                        f"{pre}_pb{c}"))
        lv = [int(bank.l_codes[j, i]) << sh_in for j, i in order]
        if any(lv):
            inj.append(_product_reg(m, _table(m, st, lv, f"{pre}_l", width=accw - len(qy)), qy, accw, f"{pre}_pl"))
        terms += inj
        nxt_r = Signal(signed(bs), name=f"{pre}_x_next_r", reset_less=True)
        m.d.sync += nxt_r.eq(nxt)
        terms.append(const_product(m, 1 << fc, nxt_r, accw, f"{pre}_px"))
        dh = [int(bank.d_codes[j, i]) + (1 << (fc - 1)) for j, i in order]  # the rounding term folded in
        if all(v == dh[0] for v in dh):
            acc = add_const_signed(m, _sum(m, terms, accw, f"{pre}_acc"), dh[0], f"{pre}_acc_d")
        else:
            w = max(_cbits(v) for v in dh)
            if w > accw:
                raise InternalError("observer constant wider than the accumulator")
            dnet = _coef_reg(m, st, dh, f"{pre}_d", accw)  # registered at the step: stage 2's term
            acc = _sum(m, terms + [dnet], accw, f"{pre}_acc")
        sink_unused(m, acc[:fc], f"{pre}_acc_frac")
        new, flag = saturate(m, acc[fc:].as_signed(), bs, f"{pre}_new")
        stage2 = Signal(name=f"{pre}_mac_valid")  # stage 2 holds a state update of this sample
        m.d.sync += stage2.eq(active)
        sat_flags.append(flag & stage2)
        shift = busy  # the steps and one flush cycle (the last update enters the tail); busy when that is the whole II
        if steps + 1 < (1 << stw):
            shift = Signal(name=f"{pre}_shift")
            m.d.comb += shift.eq(busy & ~ge_const(st, steps + 1))
        with m.If(shift):
            m.d.sync += [chain[k].eq(chain[k + 1]) for k in range(steps - 1)] + [chain[-1].eq(new)]

        # ---- residual, square, window record (rotates once per observer)
        sums = [Signal(unsigned(sumb), name=f"{pre}_sum{o}") for o in range(nl)]
        # the delay lines: one memory per lane, word (observer o, slot) = Cat(o, slot); the square of
        # sample k - l - 1 is read one cycle before the window sum's update (0 while not written since reset)
        mem = Memory(shape=unsigned(sumb), depth=(1 << ow) * (lw + 1), init=[])
        m.submodules[f"{pre}_dlmem"] = mem
        rp = mem.read_port(domain="sync")
        wp = mem.write_port()
        xh = const_product(m, 1, head, rb, f"{pre}_yhat")
        e = Signal(signed(rb + 1), name=f"{pre}_e_full")
        m.d.comb += e.eq(xh - qy_al)
        sink_unused(m, e[rb], f"{pre}_e_top")
        rot = active & first_state
        # SQUARE_REGS = 2: the residual registered, then its square, with the step's valid bit and
        # the observer index alongside; the window sum, its memory write and the feature pipeline
        # follow 2 cycles after the step. The oldest square of observer o is read in the cycle
        # before (word (o, slot), synchronous read: no register of its own) and written over in
        # the sum's cycle (read first; window >= 1: l + 1 >= 2 slots, so no other sample's access
        # meets the word)
        e_r = Signal(signed(rb), name=f"{pre}_e_r", reset_less=True)
        rot_1 = Signal(name=f"{pre}_e_valid")
        oj_1 = Signal(unsigned(ow), name=f"{pre}_e_obs", reset_less=True)
        m.d.sync += [e_r.eq(e[:rb].as_signed()), rot_1.eq(rot), oj_1.eq(oj)]
        rp.addr = Cat(oj_1, slot)
        p = Signal(signed(2 * rb), name=f"{pre}_sq")
        m.d.comb += p.eq(e_r * e_r)
        sq_r = Signal(unsigned(2 * rb), name=f"{pre}_sq_r", reset_less=True)
        rot_d = Signal(name=f"{pre}_sq_valid")
        oj_d = Signal(unsigned(ow), name=f"{pre}_sq_obs", reset_less=True)
        m.d.sync += [sq_r.eq(p.as_unsigned()), rot_d.eq(rot_1), oj_d.eq(oj_1)]
        old_r = Signal(unsigned(sumb), name=f"{pre}_dl_oldest")
        m.d.comb += old_r.eq(Mux(old_valid, rp.data, 0))
        wp.addr = Cat(oj_d, slot)
        wp.data = sq_r
        wp.en = rot_d
        added = add_wrap(m, sums[0], sq_r, f"{pre}_sum_add")
        s_new = _sub_wrap(m, added, old_r, f"{pre}_sum_next")
        with m.If(rot_d):
            m.d.sync += [sums[o].eq(sums[o + 1]) for o in range(nl - 1)] + [sums[-1].eq(s_new)]

        # ---- feature pipeline: S register -> isqrt (R registers) -> root register -> code register
        s_reg = Signal(unsigned(sumb), name=f"{pre}_fs_sum", reset_less=True)
        tok = Signal(name=f"{pre}_fs_tok")
        idx = Signal(unsigned(ow), name=f"{pre}_fs_idx", reset_less=True)
        m.d.sync += [s_reg.eq(s_new), tok.eq(rot_d), idx.eq(oj_d)]
        if bank.feature_map == "11b":
            r, nreg = build_isqrt_pipelined(m, s_reg, f"{pre}_isqrt", plan.isqrt_every)
            assert nreg == plan.isqrt_regs, (nreg, plan.isqrt_regs)
        else:
            r, nreg = s_reg, 0
        tok_r = _delay(m, tok, nreg, f"{pre}_tok", reset_less=False)
        idx_r = _delay(m, idx, nreg, f"{pre}_idx", reset_less=True)
        root = Signal(unsigned(len(r)), name=f"{pre}_root", reset_less=True)
        tok2 = Signal(name=f"{pre}_root_tok")
        idx2 = Signal(unsigned(ow), name=f"{pre}_root_idx", reset_less=True)
        m.d.sync += [root.eq(r), tok2.eq(tok_r), idx2.eq(idx_r)]
        q, tok_q, idx_q = _affine(m, bank, group, root, idx2, tok2, pre)
        for o, j in enumerate(group):
            wr = Signal(name=f"feat{j}_code_write")
            m.d.comb += wr.eq(tok_q & eq_const(idx_q, o))
            with m.If(wr):
                m.d.sync += codes[j].eq(q)
            if buf is not None:
                with m.If(buffer_load):
                    m.d.sync += buf[j].eq(Mux(wr, q, codes[j]))
        if ln == 0:
            last_tok = Signal(name="bank_last_token")  # the last feature token of a sample (warm or not)
            m.d.comb += last_tok.eq(tok_q & eq_const(idx_q, nl - 1))
            w = sample_warm
            if buf is not None:
                # double-buffered: the next sample's transfer may come before this one's last token, and
                # then sample_warm is the newer sample's. Samples between transfer and last token: 0 .. 2
                # (II >= ceil(stages_before_core / 2)); with 2 the token is the older one's: its warm bit
                # is the one sample_warm held before the latest transfer
                in_pipe = Signal(unsigned(2), name="bank_samples_in_pipe")
                warm_prev = Signal(name="bank_sample_warm_prev")
                with m.If(transfer):
                    m.d.sync += warm_prev.eq(sample_warm)
                with m.If(transfer & ~last_tok):
                    m.d.sync += in_pipe.eq(add_const_wrap(m, in_pipe, 1, "bank_in_pipe_inc"))
                with m.Elif(last_tok & ~transfer):
                    m.d.sync += in_pipe.eq(add_const_wrap(m, in_pipe, -1, "bank_in_pipe_dec"))
                w = Signal(name="bank_token_warm")
                m.d.comb += w.eq(Mux(in_pipe[1], warm_prev, sample_warm))
            m.d.comb += done.eq(last_tok & w)
    sat = Signal(name="state_saturated")
    m.d.comb += sat.eq(Cat(*sat_flags).any())
    sink_unused(m, sat, "state_saturated_flag")
    return (buf if buf is not None else codes), done, free


def _sub_wrap(m: Module, a, b, name: str):
    from pwas_hdl.hdl.residual_features import sub_wrap

    return sub_wrap(m, a, b, name)


def _stage(m: Module, tok, idx, pre: str, k: int):
    """The feature pipeline's token and observer index one register later (stage ``k`` of the affine map)."""
    t = Signal(name=f"{pre}_fa{k}_tok")
    i = Signal(unsigned(len(idx)), name=f"{pre}_fa{k}_idx", reset_less=True)
    m.d.sync += [t.eq(tok), i.eq(idx)]
    return t, i


def _affine(m: Module, bank, group, root, idx, tok, pre: str):
    """``sat((min(r >> t, cap_j) * K_j + C_j) >> R)`` with the constants of the lane's observer ``idx``,
    in :data:`AFFINE_REGS` register stages (the capped root, then the product). Returns
    ``(code, tok, idx)``: the code net and the token / index of its cycle."""
    t, sh = bank.root_shift, bank.scale_shift
    bcore = bank.input_bits_core
    swd = bank.widths["scale_product"]
    if t:
        sink_unused(m, root[:t], f"{pre}_root_low")
    rs = root[t:] if t else root
    caps = [int(bank.root_cap[j]) for j in group]
    capw = max(1, max(c.bit_length() for c in caps))
    rw = len(rs)
    assert capw <= rw, (capw, rw)  # cap_j <= the largest r >> t
    cap = rom(m, idx, caps, rw, f"{pre}_cap")  # at the root's width: one comparator
    capped = Signal(unsigned(capw), name=f"{pre}_capped")
    if isinstance(cap, int):  # one observer in the lane (or equal caps): a constant compare, as the parallel unit
        cap_const(m, rs, cap, capped)
    else:
        with m.If(rs > cap):
            m.d.comb += capped.eq(cap[:capw])
        with m.Else():
            m.d.comb += capped.eq(rs[:capw])
    capped_r = Signal(unsigned(capw), name=f"{pre}_capped_r", reset_less=True)  # stage 1: the capped root
    m.d.sync += capped_r.eq(capped)
    tok, idx = _stage(m, tok, idx, pre, 1)
    return _affine_tail(m, bank, group, capped_r, capw, idx, tok, pre)


def _affine_tail(m: Module, bank, group, capped, capw: int, idx, tok, pre: str):
    sh = bank.scale_shift
    bcore = bank.input_bits_core
    swd = bank.widths["scale_product"]
    kmul = _table(m, idx, [int(bank.scale_mul[j]) for j in group], f"{pre}_kmul", width=swd - capw - 1)
    prod = var_product(m, kmul, Cat(capped, Const(0, 1)), swd, f"{pre}_fprod")
    prod_r = Signal(signed(swd), name=f"{pre}_fprod_r", reset_less=True)  # stage 2: the product
    m.d.sync += prod_r.eq(prod)
    tok, idx = _stage(m, tok, idx, pre, 2)
    adds = [int(bank.scale_add[j]) for j in group]
    if all(a == adds[0] for a in adds):
        tot = add_const_signed(m, prod_r, adds[0], f"{pre}_faffine")
    else:
        cn = _table(m, idx, adds, f"{pre}_fadd", width=swd)
        tot = _sum(m, [prod_r, cn], swd, f"{pre}_faffine")
    sink_unused(m, tot[:sh], f"{pre}_faffine_frac")
    qv, _ = saturate(m, tot[sh:].as_signed(), bcore, f"{pre}_fq", flag=False)
    return qv, tok, idx
