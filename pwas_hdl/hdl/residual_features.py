"""The residual feature unit (seed 004, map 11b / 11b-sq) as Amaranth logic.

Bit for bit :class:`pwas_hdl.fixedpoint.observer_bank.FixedPointObserverBank`: per observer
``sq = e * e``, a delay line of ``l + 1`` squares and the running window sum
``S <= S + sq - sq_{k-l-1}`` (registers, updated once per sample -- in the parallel bank from the
registered residual and square, stages ``s_res`` / ``s_sq`` -- 0 after reset; modulo
``2**B_S``, exact because the window sum lies in ``[0, 2**B_S)``), then (one pipeline register
later) the integer square root ``r = isqrt(S)`` (map 11b; digit by digit, ``B_S / 2``
compare-subtract steps, combinational) or ``r = S`` (11b-sq), and the constant affine map to the
PWAS core's input code ``q = sat((min(r >> t, cap) * K + C) >> R)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from amaranth.hdl import Cat, Const, Module, Signal, Value, signed, unsigned

from pwas_hdl.hdl._lintsafe import add_wrap, ge_const, sink_unused
from pwas_hdl.hdl.observer_bank import add_const_signed, advance_registers, const_product, saturate

if TYPE_CHECKING:
    from pwas_hdl.fixedpoint.observer_bank import FixedPointObserverBank

__all__ = ["build_window_sums", "build_isqrt", "build_feature_codes", "sub_wrap"]



def cap_const(m: Module, rs: Value, cap: int, capped: Signal) -> None:
    """``capped = min(rs, cap)`` for a constant ``cap`` (``capped`` holds ``cap``): one constant compare.

    Parameters
    ----------
    m : Module
        Module the compare is added to (``comb`` domain).
    rs : Value
        Unsigned value to cap.
    cap : int
        Non-negative constant.
    capped : Signal
        Unsigned output, driven here; wide enough for ``cap`` (``rs`` is truncated to its width
        below the cap).
    """
    capw = len(capped)
    over = ge_const(rs, cap + 1)
    if isinstance(over, bool):
        m.d.comb += capped.eq(cap if over else rs[:capw])
    else:
        with m.If(over):
            m.d.comb += capped.eq(cap)
        with m.Else():
            m.d.comb += capped.eq(rs[:capw])

def sub_wrap(m: Module, a: Value, b: Value, name: str) -> Value:
    """``(a - b) mod 2**w`` for two unsigned ``w``-bit nets.

    Parameters
    ----------
    m : Module
        Module the subtractor is added to (``comb`` domain).
    a, b : Value
        Unsigned, equal width ``w`` bits (asserted).
    name : str
        Name of the ``w + 1``-bit difference net; its borrow goes to ``unused_<name>_borrow``.

    Returns
    -------
    Value
        The low ``w`` bits of the difference.
    """
    assert len(a) == len(b), (len(a), len(b))
    w = len(a)
    s = Signal(unsigned(w + 1), name=name)
    m.d.comb += s.eq(a - b)
    sink_unused(m, s[w], f"{name}_borrow")
    return s[:w]


def build_window_sums(m: Module, bank: FixedPointObserverBank, residuals: Sequence[Value], transfer: Value,
                      stage_enable: Value | None = None) -> list[Signal]:
    """Squares, delay lines and running sums of the residuals.

    Parameters
    ----------
    m : Module
        Module the logic is added to (delay lines and sums in ``sync``, reset to 0).
    bank : FixedPointObserverBank
        Gives the formats (``residual_bits``, ``sum_bits = 2 * residual_bits``) and the window
        ``l`` (``l + 1`` delay registers per residual).
    residuals : sequence of Value
        ``N`` signed ``residual_bits`` residuals (:func:`~pwas_hdl.hdl.observer_bank.build_observer_bank`).
    transfer : Value
        1 bit; the delay lines and sums update when it is high (with ``stage_enable``: from the
        registered squares, i.e. the sample whose residuals were there two enabled cycles before).
    stage_enable : Value, optional
        1 bit: the residuals (stage ``s_res``, ``s_res_<j>``) and their squares (stage ``s_sq``,
        ``s_sq_<j>``) are registered, loading when it is high, between the residuals and the sums;
        None: the sums add the squares of ``residuals`` directly.

    Returns
    -------
    list of Signal
        The ``N`` window-sum registers ``S_j``, unsigned ``window_sum`` (``sum_bits``) bits.
    """
    fmt = bank.formats
    rb, sumb = fmt.residual_bits, fmt.sum_bits
    assert fmt.square_bits == sumb == 2 * rb
    lw = bank.window
    sums = []
    for j, e in enumerate(residuals):
        if stage_enable is not None:
            e = advance_registers(m, e, 1, stage_enable, f"s_res_{j}")
        p = Signal(signed(2 * rb), name=f"feat{j}_sq")
        m.d.comb += p.eq(e * e)
        sq = p.as_unsigned()
        if stage_enable is not None:
            sq = advance_registers(m, sq, 1, stage_enable, f"s_sq_{j}")
        dl = [Signal(unsigned(sumb), name=f"feat{j}_dl{i}") for i in range(lw + 1)]
        s = Signal(unsigned(sumb), name=f"feat{j}_sum")
        added = add_wrap(m, s, sq, f"feat{j}_sum_add")
        nxt = sub_wrap(m, added, dl[lw], f"feat{j}_sum_next")
        with m.If(transfer):
            m.d.sync += [dl[0].eq(sq), s.eq(nxt)] + [dl[i].eq(dl[i - 1]) for i in range(1, lw + 1)]
        sums.append(s)
    return sums


def build_isqrt(m: Module, value: Value, name: str) -> Value:
    """``floor(sqrt(value))`` of an unsigned value: combinational digit-by-digit (restoring) square root.

    Step ``i`` (``i = 0 ..``, two input bits each, MSB first) holds the remainder in ``i + 2`` bits
    and the root in ``i + 1`` bits: ``cur = rem << 2 | two`` (``i + 3`` bits), ``trial = root << 2 | 1``
    (``i + 2`` bits); ``bit = cur >= trial`` = ``cur[i+2] | no borrow of cur[:i+2] - trial``;
    ``rem = bit ? cur - trial : cur`` (both ``< 2**(i+2)``).

    Parameters
    ----------
    m : Module
        Module the logic is added to (``comb`` domain only: no registers).
    value : Value
        Unsigned radicand.
    name : str
        Name prefix of the step nets.

    Returns
    -------
    Value
        The root, unsigned ``ceil(len(value) / 2)`` bits
        (:func:`~pwas_hdl.hdl.serial_observer_bank.build_isqrt_pipelined` without registers).
    """
    from pwas_hdl.hdl.serial_observer_bank import build_isqrt_pipelined  # the one digit-by-digit root (no registers here)

    root, _ = build_isqrt_pipelined(m, value, name, None)
    return root


def build_feature_codes(m: Module, bank: FixedPointObserverBank, roots: Sequence[Value],
                        stage_enable: Value | None = None) -> list[Signal]:
    """Affine map of ``r`` to the core's input code per feature: ``sat((min(r >> t, cap) * K + C) >> R)``.

    Parameters
    ----------
    m : Module
        Module the logic is added to (``comb`` domain).
    bank : FixedPointObserverBank
        Gives ``t = root_shift``, ``cap = root_cap[j]``, ``K = scale_mul[j]``, ``C = scale_add[j]``,
        ``R = scale_shift`` and the code width ``input_bits_core``.
    roots : sequence of Value
        ``N`` unsigned roots ``r_j`` (or the window sums, map 11b-sq).
    stage_enable : Value, optional
        1 bit: the capped root (``s_code_cap<j>``) and the product (``s_code_prod<j>``) are
        registered, loading when it is high (the map in
        :data:`~pwas_hdl.hdl.serial_observer_bank.AFFINE_REGS` + 1 cycles with the caller's code
        register); None: combinational.

    Returns
    -------
    list of Signal
        ``N`` feature codes, signed ``input_bits_core`` (the core's ``B_in``) bits, saturated.

    Raises
    ------
    InputError
        A ``scale_mul`` constant does not fit the ``scale_product`` width
        (:func:`~pwas_hdl.hdl.observer_bank.const_product`).
    """
    t, sh = bank.root_shift, bank.scale_shift
    bcore = bank.input_bits_core
    sw = bank.widths["scale_product"]
    codes = []
    for j, r in enumerate(roots):
        if t:
            sink_unused(m, r[:t], f"feat{j}_root_low")
        rs = r[t:] if t else r
        cap = int(bank.root_cap[j])
        capw = max(1, cap.bit_length())
        capped = Signal(unsigned(capw), name=f"feat{j}_capped")
        if cap < (1 << len(rs)) - 1:
            cap_const(m, rs, cap, capped)
        else:
            m.d.comb += capped.eq(rs)
        if stage_enable is not None:
            capped = advance_registers(m, capped, 1, stage_enable, f"s_code_cap{j}")
        prod = const_product(m, int(bank.scale_mul[j]), Cat(capped, Const(0, 1)), sw, f"feat{j}_prod")
        if stage_enable is not None:
            prod = advance_registers(m, prod, 1, stage_enable, f"s_code_prod{j}")
        tot = add_const_signed(m, prod, int(bank.scale_add[j]), f"feat{j}_affine")
        sink_unused(m, tot[:sh], f"feat{j}_affine_frac")
        q, _ = saturate(m, tot[sh:].as_signed(), bcore, f"feat{j}_q", flag=False)
        codes.append(q)
    return codes
