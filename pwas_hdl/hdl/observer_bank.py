"""The observer bank of seed 004 as Amaranth logic: ``N_theta`` Luenberger predictors, one sample per clock.

Bit for bit :class:`pwas_hdl.fixedpoint.observer_bank.FixedPointObserverBank` (see its module for
the arithmetic). Architecture: **parallel constant multipliers**, one state update of every
observer per input transfer (1 cycle per sample, II = 1). Time-multiplexing over ``M`` cycles
would save multipliers but cut the sample rate by ``M``; the multipliers are by constants (the
coefficient codes), which synthesis turns into shift-add trees or DSP blocks, and zero
coefficients (``a0`` of a deadbeat gain) cost nothing. Per observer and state: ``nu + 1``
constant multiplications by the input codes and one by the first state (when ``a0 != 0``).

All arithmetic is written so that the Verilog passes ``verilator --lint-only -Wall``: every
operand of an addition is a named net of the accumulator width (:func:`_ext`), constants enter
through named constant nets.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Signal, signed, unsigned

from pwas_hdl.hdl._lintsafe import sink_unused

__all__ = ["build_observer_bank", "const_net", "ext_signed", "saturate"]


def const_net(m: Module, value: int, width: int, name: str, is_signed: bool = True):
    """A named net holding a constant (so that arithmetic sees a full-width operand)."""
    s = Signal(signed(width) if is_signed else unsigned(width), name=name)
    m.d.comb += s.eq(value)
    return s


def ext_signed(m: Module, value, width: int, name: str):
    """``value`` (signed) sign-extended to a named ``width``-bit signed net."""
    s = Signal(signed(width), name=name)
    m.d.comb += s.eq(value)
    return s


def saturate(m: Module, rv, width: int, name: str):
    """Saturate a signed value to ``width`` bits; returns (net, saturated flag)."""
    if len(rv) <= width:
        return ext_signed(m, rv, width, name), Const(0, 1)
    sign = rv[-1]
    upper = rv[width - 1 : len(rv) - 1]
    o = Signal(signed(width), name=name)
    flag = Signal(name=f"{name}_sat")
    with m.If(~sign & upper.any()):
        m.d.comb += [o.eq((1 << (width - 1)) - 1), flag.eq(1)]
    with m.Elif(sign & ~upper.all()):
        m.d.comb += [o.eq(-(1 << (width - 1))), flag.eq(1)]
    with m.Else():
        m.d.comb += o.eq(rv[:width])
    return o, flag


def _sum(m: Module, terms: list, width: int, name: str):
    """Balanced sum of signed ``width``-bit nets, result kept at ``width`` bits (no overflow by construction)."""
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


def build_observer_bank(m: Module, bank, qu: list, qy, transfer):
    """Add the bank to ``m``.

    Parameters
    ----------
    bank : FixedPointObserverBank
    qu : list of signed ``B_in`` values (one per input channel);  qy : signed ``B_in`` value
    transfer : 1-bit value; the states update when it is high

    Returns
    -------
    residuals : list of signed ``residual_bits`` nets, ``e_j = x_j0 - (qy << (F_s - F_in))``
        (from the states before the update: the residual of the sample being transferred)
    saturated : 1-bit net, some state saturates in this update
    states : list (N) of lists (M) of state registers
    """
    fmt = bank.formats
    n, mo, nu = bank.n_models, bank.order, bank.nu
    fc, fs, fin = fmt.coef_frac, fmt.state_frac, fmt.input_frac
    bs, accw, rb = fmt.state_bits, fmt.acc_bits, fmt.residual_bits
    sh_in = fs - fin
    bin_ = fmt.input_bits
    states = [[Signal(signed(bs), name=f"obs{j}_x{i}") for i in range(mo)] for j in range(n)]
    qy_al = ext_signed(m, Cat(Const(0, sh_in), qy).as_signed() if sh_in else qy, rb, "y_aligned")
    residuals = []
    sat_flags = []
    for j in range(n):
        x0 = ext_signed(m, states[j][0], rb, f"obs{j}_yhat")
        e = Signal(signed(rb + 1), name=f"obs{j}_e_full")
        m.d.comb += e.eq(x0 - qy_al)
        sink_unused(m, e[rb], f"obs{j}_e_top")
        residuals.append(e[:rb].as_signed())
        for i in range(mo):
            terms = []
            a0 = int(bank.a0_codes[j, i])
            if a0:
                cw = max(2, a0.bit_length() + 1) if a0 >= 0 else max(2, (-a0 - 1).bit_length() + 1)
                k = const_net(m, a0, cw, f"obs{j}_a0_{i}")
                p = Signal(signed(cw + bs), name=f"obs{j}_pa_{i}")
                m.d.comb += p.eq(k * states[j][0])
                terms.append(ext_signed(m, p, accw, f"obs{j}_ta_{i}"))
            inj = []
            coefs = [(int(bank.b_codes[j, i, c]), qu[c], f"b{c}") for c in range(nu)] + [(int(bank.l_codes[j, i]), qy, "l")]
            for cv, sig, nm in coefs:
                if not cv:
                    continue
                cw = max(2, cv.bit_length() + 1) if cv >= 0 else max(2, (-cv - 1).bit_length() + 1)
                k = const_net(m, cv, cw, f"obs{j}_{nm}_{i}")
                p = Signal(signed(cw + bin_), name=f"obs{j}_p{nm}_{i}")
                m.d.comb += p.eq(k * sig)
                if sh_in:
                    p = Cat(Const(0, sh_in), p).as_signed()
                terms.append(ext_signed(m, p, accw, f"obs{j}_t{nm}_{i}"))
            d = int(bank.d_codes[j, i]) + (1 << (fc - 1))  # the rounding term folded into the constant
            terms.append(const_net(m, d, accw, f"obs{j}_d_{i}"))
            if i + 1 < mo:
                terms.append(ext_signed(m, Cat(Const(0, fc), states[j][i + 1]).as_signed(), accw, f"obs{j}_tx_{i}"))
            acc = _sum(m, terms, accw, f"obs{j}_acc{i}")
            rv = acc[fc:].as_signed()
            sink_unused(m, acc[:fc], f"obs{j}_acc{i}_frac")
            nxt, flag = saturate(m, rv, bs, f"obs{j}_next{i}")
            if not isinstance(flag, Const):
                sat_flags.append(flag)
            with m.If(transfer):
                m.d.sync += states[j][i].eq(nxt)
    saturated = Signal(name="state_saturated")
    m.d.comb += saturated.eq(Cat(*sat_flags).any() if sat_flags else 0)
    return residuals, saturated, states
