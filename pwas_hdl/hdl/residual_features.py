"""The residual feature unit (seed 004, map 11b / 11b-sq) as Amaranth logic.

Bit for bit :class:`pwas_hdl.fixedpoint.observer_bank.FixedPointObserverBank`: per observer
``sq = e * e``, a delay line of ``l + 1`` squares and the running window sum
``S <= S + sq - sq_{k-l-1}`` (registers, updated on each input transfer, 0 after reset), then
(one pipeline register later) the integer square root ``r = isqrt(S)`` (map 11b; digit by digit,
``ceil(B_S / 2)`` compare-subtract steps) or ``r = S`` (11b-sq), and the constant affine map to the
PWAS core's input code ``q = sat((min(r >> t, cap) * K + C) >> R)``.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed, unsigned

from pwas_hdl.hdl._lintsafe import ge_const, sink_unused
from pwas_hdl.hdl.observer_bank import const_net, ext_signed, saturate

__all__ = ["build_window_sums", "build_isqrt", "build_feature_codes"]


def build_window_sums(m: Module, bank, residuals: list, transfer) -> list:
    """Squares, delay lines and running sums; returns the ``S_j`` registers (unsigned ``window_sum`` bits)."""
    fmt = bank.formats
    rb, sqb, sumb = fmt.residual_bits, fmt.square_bits, fmt.sum_bits
    lw = bank.window
    sums = []
    for j, e in enumerate(residuals):
        p = Signal(signed(2 * rb), name=f"feat{j}_sq_full")
        m.d.comb += p.eq(e * e)
        sink_unused(m, p[sqb:], f"feat{j}_sq_top")  # e*e >= 0 and < 2**(2 rb - 2)
        sq = p[:sqb]
        dl = [Signal(unsigned(sqb), name=f"feat{j}_dl{i}") for i in range(lw + 1)]
        s = Signal(unsigned(sumb), name=f"feat{j}_sum")
        sq_w = Signal(signed(sumb + 2), name=f"feat{j}_sq_in")
        old_w = Signal(signed(sumb + 2), name=f"feat{j}_sq_out")
        s_w = Signal(signed(sumb + 2), name=f"feat{j}_sum_ext")
        m.d.comb += [sq_w.eq(sq), old_w.eq(dl[lw]), s_w.eq(s)]
        t1 = Signal(signed(sumb + 3), name=f"feat{j}_sum_add")
        m.d.comb += t1.eq(s_w + sq_w)
        sink_unused(m, t1[sumb + 2], f"feat{j}_sum_add_top")
        t2 = Signal(signed(sumb + 3), name=f"feat{j}_sum_next")
        m.d.comb += t2.eq(t1[: sumb + 2].as_signed() - old_w)
        sink_unused(m, t2[sumb:], f"feat{j}_sum_next_top")  # the window sum is in [0, 2**sumb)
        with m.If(transfer):
            m.d.sync += [dl[0].eq(sq), s.eq(t2[:sumb])] + [dl[i].eq(dl[i - 1]) for i in range(1, lw + 1)]
        sums.append(s)
    return sums


def build_isqrt(m: Module, value, name: str):
    """``floor(sqrt(value))`` of an unsigned value, combinational digit-by-digit (restoring) square root.

    Returns an unsigned ``ceil(len(value) / 2)``-bit net.
    """
    w = len(value)
    pairs = (w + 1) // 2
    v = Cat(value, Const(0, 2 * pairs - w)) if 2 * pairs > w else value
    rw = pairs + 2  # remainder / trial width
    rem = Const(0, rw)
    root = None  # bits so far, MSB first
    for i in range(pairs):
        hi = 2 * (pairs - 1 - i)
        two = v[hi : hi + 2]
        cur = Signal(unsigned(rw), name=f"{name}_r{i}")
        m.d.comb += cur.eq(Cat(two, rem[: rw - 2]))
        # trial = (root << 2) | 1
        trial = Signal(unsigned(rw), name=f"{name}_t{i}")
        m.d.comb += trial.eq(Cat(Const(1, 2), root) if root is not None else 1)
        diff = Signal(unsigned(rw + 1), name=f"{name}_d{i}")
        m.d.comb += diff.eq(cur - trial)
        bit = Signal(name=f"{name}_b{i}")
        m.d.comb += bit.eq(~diff[rw])
        nrem = Signal(unsigned(rw), name=f"{name}_m{i}")
        m.d.comb += nrem.eq(Mux(bit, diff[:rw], cur))
        rem = nrem
        root = Cat(bit, root) if root is not None else bit
        if len(root) > rw - 2:
            root = root[: rw - 2]
    sink_unused(m, rem, f"{name}_rem")
    out = Signal(unsigned(pairs), name=name)
    m.d.comb += out.eq(root)
    return out


def build_feature_codes(m: Module, bank, roots: list) -> list:
    """Affine map of ``r`` to the core's input code per feature: ``sat((min(r >> t, cap) * K + C) >> R)``."""
    t, sh = bank.root_shift, bank.scale_shift
    bcore = bank.input_bits_core
    codes = []
    for j, r in enumerate(roots):
        rs = r[t:] if t else r
        cap = int(bank.root_cap[j])
        capw = max(1, cap.bit_length())
        if cap < (1 << len(rs)) - 1:
            over = ge_const(rs, cap + 1)
            if isinstance(over, bool):
                capped_v = Const(cap, capw) if over else rs[:capw]
            else:
                capped_v = Mux(over, Const(cap, capw), rs[:capw])
        else:
            capped_v = rs
        capped = Signal(unsigned(capw), name=f"feat{j}_capped")
        m.d.comb += capped.eq(capped_v)
        if len(rs) > capw and not (cap < (1 << len(rs)) - 1):
            sink_unused(m, rs[capw:], f"feat{j}_root_top")
        k = int(bank.scale_mul[j])
        kw = k.bit_length() + 1
        kn = const_net(m, k, kw, f"feat{j}_k")
        pw = capw + 1 + kw
        prod = Signal(signed(pw), name=f"feat{j}_prod")
        m.d.comb += prod.eq(Cat(capped, Const(0, 1)).as_signed() * kn)
        sw = bank.widths["scale_product"]
        c = int(bank.scale_add[j])
        cn = const_net(m, c, sw, f"feat{j}_c")
        pe = ext_signed(m, prod, sw, f"feat{j}_prod_ext")
        tot = Signal(signed(sw + 1), name=f"feat{j}_affine")
        m.d.comb += tot.eq(pe + cn)
        sink_unused(m, tot[sw], f"feat{j}_affine_top")
        sink_unused(m, tot[:sh], f"feat{j}_affine_frac")
        rv = tot[sh:sw].as_signed()
        q, _ = saturate(m, rv, bcore, f"feat{j}_q")
        codes.append(q)
    return codes
