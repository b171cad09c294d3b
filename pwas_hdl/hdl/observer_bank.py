"""The observer bank of seed 004 as Amaranth logic: ``N_theta`` Luenberger predictors, one sample per clock.

Bit for bit :class:`pwas_hdl.fixedpoint.observer_bank.FixedPointObserverBank` (see its module for
the arithmetic). Architecture: **parallel constant multipliers**, one state update of every
observer per input transfer (1 cycle per sample, II = 1). The time-multiplexed alternative
(``--architecture serial``) is :mod:`pwas_hdl.hdl.serial_observer_bank`: ``nu + 2`` multipliers
per lane instead of up to ``N M (nu + 2)``, at ``~N M / lanes`` cycles per sample; the multipliers are by constants (the
coefficient codes), which synthesis turns into shift-add trees or DSP blocks, and zero
coefficients (``a0`` of a deadbeat gain) cost nothing. Per observer and state: ``nu + 1``
constant multiplications by the input codes and one by the first state (when ``a0 != 0``).

All arithmetic is written so that the Verilog passes ``verilator --lint-only -Wall``: every
operand of an addition is a whole product net of the accumulator width (:func:`const_product`:
the input alignment and the ``<< F_c`` of the next state are folded into constant factors),
constants are added modulo the width (:func:`add_const_signed`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from amaranth.hdl import Cat, Const, Module, Signal, Value, signed, unsigned

from pwas_hdl.errors import InternalError
from pwas_hdl.hdl._lintsafe import sink_unused

if TYPE_CHECKING:
    from pwas_hdl.fixedpoint.observer_bank import FixedPointObserverBank

__all__ = ["build_observer_bank", "const_product", "add_const_signed", "saturate", "advance_registers", "INPUT_STAGES"]

#: Registers between the input transfer and the state update (``s_in``: the input products; ``s_in2``:
#: their sum and the rounding constant).
INPUT_STAGES = 2


def saturate(m: Module, rv: Value, width: int, name: str, flag: bool = True) -> tuple[Signal, Signal | None]:
    """Saturate a signed value (wider than ``width``) to ``width`` bits.

    Parameters
    ----------
    m : Module
        Module the logic is added to (``comb`` domain).
    rv : Value
        Signed value, more than ``width`` bits (asserted).
    width : int
        Output width, bits.
    name : str
        Name of the output net; the flag is ``<name>_sat``.
    flag : bool
        Also return a flag net.

    Returns
    -------
    net : Signal
        ``rv`` clipped to ``[-2**(width-1), 2**(width-1) - 1]``, signed ``width`` bits.
    saturated : Signal or None
        1 bit, high when ``rv`` was clipped; ``None`` when ``flag`` is false.
    """
    assert len(rv) > width, (len(rv), width)
    sign = rv[-1]
    upper = rv[width - 1 : len(rv) - 1]
    o = Signal(signed(width), name=name)
    f = Signal(name=f"{name}_sat") if flag else None
    with m.If(~sign & upper.any()):
        m.d.comb += [o.eq((1 << (width - 1)) - 1)] + ([f.eq(1)] if flag else [])
    with m.Elif(sign & ~upper.all()):
        m.d.comb += [o.eq(-(1 << (width - 1)))] + ([f.eq(1)] if flag else [])
    with m.Else():
        m.d.comb += o.eq(rv[:width])
    return o, f


def _sum(m: Module, terms: list, width: int, name: str):
    """Balanced sum of signed ``width``-bit nets, result kept at ``width`` bits (no overflow by construction).

    No terms (every coefficient of the row quantised to 0) is the constant 0.
    """
    if not terms:
        return Const(0, signed(width))
    level = 0
    while len(terms) > 1:
        nxt = []
        for i in range(0, len(terms) - 1, 2):
            s = Signal(signed(width + 1), name=f"{name}_s{level}_{i // 2}")
            m.d.comb += s.eq(terms[i] + terms[i + 1])
            sink_unused(m, s[width], f"{name}_s{level}_{i // 2}_top")
            nxt.append(s[:width].as_signed())
        if len(terms) % 2:
            nxt.append(terms[-1])
        terms = nxt
        level += 1
    return terms[0]


def _cbits(v: int) -> int:
    """Signed width of the constant ``v`` (at least 2)."""
    return max(2, (v.bit_length() if v >= 0 else (-v - 1).bit_length()) + 1)


def const_product(m: Module, k: int, x: Value, width: int, name: str) -> Signal:
    """``k * x`` (signed constant times signed ``x``) as a named product net of exactly ``width`` bits.

    The constant net gets ``width - len(x)`` bits, so the multiplier's natural width is the
    accumulator width (a whole cell output: no extension in front of the adders).

    Parameters
    ----------
    m : Module
        Module the multiplier is added to (``comb`` domain).
    k : int
        Signed constant factor.
    x : Value
        Operand, read as signed.
    width : int
        Product width, bits.
    name : str
        Name of the product net.

    Returns
    -------
    Signal
        Signed ``width`` bits.

    Raises
    ------
    InternalError
        ``k`` does not fit ``width - len(x)`` signed bits (the formats' plan sized ``width`` for
        every constant: a bug, not bad input).
    """
    kw = width - len(x)
    if kw < _cbits(k):
        raise InternalError(f"constant {k} does not fit {kw} bits (product {name})")
    p = Signal(signed(width), name=name)
    m.d.comb += p.eq(Const(k, signed(kw)) * x.as_signed())
    return p


def add_const_signed(m: Module, x: Value, k: int, name: str) -> Value:
    """``x + k`` for a signed named net ``x`` whose true sum fits its width (modular add).

    Parameters
    ----------
    m : Module
        Module the adder is added to (``comb`` domain).
    x : Value
        Signed operand, ``w`` bits.
    k : int
        Signed constant (added modulo ``2**w``).
    name : str
        Name of the adder's result net (:func:`~pwas_hdl.hdl._lintsafe.add_const_wrap`).

    Returns
    -------
    Value
        Signed ``w`` bits.
    """
    from pwas_hdl.hdl._lintsafe import add_const_wrap

    w = len(x)
    return add_const_wrap(m, x.as_unsigned(), k % (1 << w), name).as_signed()


def build_observer_bank(m: Module, bank: FixedPointObserverBank, qu: Sequence[Value], qy: Value,
                        transfer: Value, advance: Value) -> tuple[list[Value], Signal, list[list[Signal]], Signal]:
    """Add the bank to ``m``: two input stages (:data:`INPUT_STAGES`), then the state update.

    Stage ``s_in`` (registers loading when ``advance`` is high) holds the input products, stage
    ``s_in2`` per observer and state their sum and the rounding constant (the part of the next
    state that does not depend on the states); both carry the aligned output code and the valid
    bit. The states update two enabled cycles after the transfer, from ``s_in2`` and the state
    terms only: the multipliers and the input adder tree are out of the bank's recurrence. The
    sums are modular in the accumulator width and the whole sum fits it, so the next states are
    those of the one-cycle form bit for bit.

    Parameters
    ----------
    m : Module
        Module the observers are added to (state registers in ``sync``, without reset).
    bank : FixedPointObserverBank
        The bit-true bank: coefficient codes and formats.
    qu : sequence of Value
        Signed ``B_in``-bit input codes, one per input channel (``nu``).
    qy : Value
        Signed ``B_in``-bit code of the measured output.
    transfer : Value
        1 bit, the input transfer: the sample enters stage ``s_in``.
    advance : Value
        1 bit, the pipeline's enable: the input stages load when it is high.

    Returns
    -------
    residuals : list of Value
        ``N`` signed ``residual_bits`` nets, ``e_j = x_j0 - (qy << (F_s - F_in))`` of the sample
        in stage ``s_in2`` (from the states before its update).
    saturated : Signal
        1 bit, some state saturates in this update.
    states : list of list of Signal
        ``N`` lists of ``M`` state registers, signed ``state_bits`` each.
    update : Signal
        1 bit, ``s_in2_valid & advance``: the states update (the sample in ``s_in2`` leaves it);
        the residuals belong to that sample.

    Raises
    ------
    InternalError
        A coefficient does not fit its product's constant width (:func:`const_product`; the
        formats were planned for every coefficient).
    """
    fmt = bank.formats
    n, mo, nu = bank.n_models, bank.order, bank.nu
    fc, fs, fin = fmt.coef_frac, fmt.state_frac, fmt.input_frac
    bs, accw, rb = fmt.state_bits, fmt.acc_bits, fmt.residual_bits
    sh_in = fs - fin
    states = [[Signal(signed(bs), name=f"obs{j}_x{i}") for i in range(mo)] for j in range(n)]
    # stages s_in (the products) and s_in2 (their sum): the transfer's valid bit and the aligned output code
    in_valid = advance_registers(m, advance_registers(m, transfer, 1, advance, "s_in_valid"), 1, advance, "s_in2_valid")
    update = Signal(name="bank_update")
    m.d.comb += update.eq(in_valid & advance)
    qy_al = advance_registers(m, advance_registers(m, const_product(m, 1 << sh_in, qy, rb, "y_aligned"), 1, advance,
                                                   "s_in_y"), 1, advance, "s_in2_y")
    residuals = []
    sat_flags = []
    for j in range(n):
        x0 = const_product(m, 1, states[j][0], rb, f"obs{j}_yhat")
        e = Signal(signed(rb + 1), name=f"obs{j}_e_full")
        m.d.comb += e.eq(x0 - qy_al)
        sink_unused(m, e[rb], f"obs{j}_e_top")
        residuals.append(e[:rb].as_signed())
        for i in range(mo):
            d = int(bank.d_codes[j, i]) + (1 << (fc - 1))  # the rounding term folded into the constant
            inputs = []
            coefs = [(int(bank.b_codes[j, i, c]), qu[c], f"b{c}") for c in range(nu)] + [(int(bank.l_codes[j, i]), qy, "l")]
            for cv, sig, nm in coefs:
                if cv:  # the input alignment << (F_s - F_in) is folded into the constant; stage s_in
                    inputs.append(advance_registers(m, const_product(m, cv << sh_in, sig, accw, f"obs{j}_p{nm}_{i}"),
                                                     1, advance, f"s_in_obs{j}_p{nm}_{i}"))
            terms = []
            if inputs:  # the products' sum and the constant: stage s_in2 (modular in accw bits)
                part = add_const_signed(m, _sum(m, inputs, accw, f"obs{j}_in{i}"), d, f"obs{j}_in{i}_d")
                terms.append(advance_registers(m, part, 1, advance, f"s_in2_obs{j}_{i}"))
            a0 = int(bank.a0_codes[j, i])
            if a0:
                terms.append(const_product(m, a0, states[j][0], accw, f"obs{j}_pa_{i}"))
            if i + 1 < mo:
                terms.append(const_product(m, 1 << fc, states[j][i + 1], accw, f"obs{j}_px_{i}"))
            if terms:
                acc = _sum(m, terms, accw, f"obs{j}_acc{i}")
                if not inputs:
                    acc = add_const_signed(m, acc, d, f"obs{j}_acc{i}_d")
                rv = acc[fc:].as_signed()
                sink_unused(m, acc[:fc], f"obs{j}_acc{i}_frac")
                nxt, flag = saturate(m, rv, bs, f"obs{j}_next{i}")
                sat_flags.append(flag)
            else:  # a constant state (all its coefficients are 0)
                v = d >> fc
                lim = 1 << (bs - 1)
                nxt = Const(min(max(v, -lim), lim - 1), signed(bs))
                if not -lim <= v < lim:
                    sat_flags.append(update)
            with m.If(update):
                m.d.sync += states[j][i].eq(nxt)
    saturated = Signal(name="state_saturated")
    m.d.comb += saturated.eq(Cat(*sat_flags).any() if sat_flags else 0)
    return residuals, saturated, states, update


def advance_registers(m: Module, value: Value, n: int, advance: Value, name: str) -> Value:
    """``value`` through ``n`` registers that load when ``advance`` is high (a stalling pipeline's
    stages; reset-less, except a 1-bit value, a valid bit, which resets to 0).

    Parameters
    ----------
    m : Module
        Module the registers are added to.
    value : Value
        The value to delay.
    n : int
        Registers, ``>= 0`` (0: ``value`` itself).
    advance : Value
        1 bit, the pipeline's enable.
    name : str
        Name of the last register (the others ``<name>_d<k>``).

    Returns
    -------
    Value
        ``value`` as it was ``n`` enabled cycles before, of its shape.
    """
    for k in range(n):
        reg = Signal(value.shape(), name=name if k == n - 1 else f"{name}_d{k}", reset_less=len(value) > 1)
        with m.If(advance):
            m.d.sync += reg.eq(value)
        value = reg
    return value
