"""Small combinational building blocks whose Verilog (via Amaranth's RTLIL backend and Yosys'
``write_verilog``) passes ``verilator --lint-only -Wall`` without warnings.

Why this module exists. Amaranth's RTLIL backend *shortens* the operands of arithmetic and
comparison cells: constant-zero upper bits (unsigned) and repeated sign bits (signed) are dropped,
and constants are written with their minimal width. ``write_verilog`` then prints e.g.
``assign y = a + 8'h80;`` with a 10-bit ``a`` and an 11-bit ``y``, which Verilator flags
(WIDTHEXPAND). Likewise, bits of an intermediate result that are dropped by a slice are reported as
unused (UNUSEDSIGNAL), and a named signal that merely aliases a slice or an extension of another
value is never referenced by the generated code (UNUSEDSIGNAL).

The rules followed by the generator, and implemented here:

* additions / subtractions / comparisons only between operands of *equal* width whose top bit is a
  genuine net (a port, a register, a process output or the output of another cell), with the
  natural result width (one carry bit);
* constants enter arithmetic only with their top bit set at the operand width (``x + K`` and
  ``x - (2**w - K)`` are equal modulo ``2**w``: one of the two constants always has its top bit
  set), or through a multiplexer with explicit-width constant inputs, or as a case table;
* comparisons with a constant are split into a reduction of the upper bits and a comparison of the
  lower bits at the constant's exact width;
* bits deliberately dropped (carries of modular sums, bits shifted out by the output rounding) are
  collected in wires named ``unused_*``, which Verilator's default ``--unused-regexp`` (``*unused*``)
  exempts -- the usual lint idiom for intentionally unused bits;
* named :class:`~amaranth.hdl.Signal` objects are only created for registers, process (``If`` /
  ``Switch``) outputs and whole cell outputs, never for mere slices.
"""

from __future__ import annotations

from collections.abc import Sequence

from amaranth.hdl import Const, Module, Mux, Signal, Value, unsigned

from pwas_hdl.fixedpoint.reduction import tree_reduce

__all__ = ["bits_for", "rom", "sink_unused", "add_wrap", "add_const_wrap", "sum_wrap", "ge_const", "mux_const"]


def bits_for(v: int) -> int:
    """Unsigned width for the values ``0 .. v`` (at least 1).

    Parameters
    ----------
    v : int
        Largest value to represent (non-negative).

    Returns
    -------
    int
        ``max(1, v.bit_length())`` bits.
    """
    return max(1, int(v).bit_length())


def sink_unused(m: Module, value: Value, name: str) -> None:
    """Mark ``value`` (bits intentionally dropped) as used by a wire named ``unused_<name>``.

    Split in two pieces: an alias covering *all* the nets of a named signal could take over its
    name in the output, leaving the original name as an unused alias.

    Parameters
    ----------
    m : Module
        Module the wires are added to (``comb`` domain).
    value : Value
        The dropped bits, any width.
    name : str
        Wire name suffix: one wire ``unused_<name>`` for a 1-bit ``value``, else two,
        ``unused_<name>_lo`` (all bits but the top one) and ``unused_<name>_hi`` (the top bit).
    """
    if len(value) > 1:
        for part, sl in (("lo", value[:-1]), ("hi", value[-1:])):
            s = Signal(len(sl), name=f"unused_{name}_{part}")
            m.d.comb += s.eq(sl)
        return
    s = Signal(len(value), name=f"unused_{name}")
    m.d.comb += s.eq(value)


def rom(m: Module, sel: Value | int, values: Sequence[int], width: int, name: str) -> Value | int:
    """Case table ``values[sel]``: a combinational ``Switch`` on ``sel``.

    Parameters
    ----------
    m : Module
        Module the table is added to (``comb`` domain).
    sel : Value or int
        Unsigned selector; an int selects at elaboration time.
    values : sequence of int
        The table, entry 0 first, unsigned values of at most ``width`` bits; entries beyond
        ``2**len(sel)`` are never selected.
    width : int
        Width of the output signal, bits.
    name : str
        Name of the output signal.

    Returns
    -------
    Value or int
        A ``width``-bit signal holding ``values[sel]`` (0 for a ``sel`` beyond the table); an int
        when ``sel`` is an int (``values[sel]``, 0 beyond the table) or when every selectable entry
        is equal (that entry, also for a ``sel`` beyond the table: callers never select there).
    """
    if isinstance(sel, int):
        return values[sel] if sel < len(values) else 0
    vals = [int(v) for v in values[: 1 << len(sel)]]
    if all(v == vals[0] for v in vals):  # callers never select beyond the table
        return vals[0]
    out = Signal(unsigned(width), name=name)
    with m.Switch(sel):
        for i, v in enumerate(vals):
            if v:
                with m.Case(i):
                    m.d.comb += out.eq(v)
        with m.Default():
            m.d.comb += out.eq(0)
    return out


def add_wrap(m: Module, a: Value, b: Value, name: str) -> Value:
    """``(a + b) mod 2**w`` for two unsigned ``w``-bit values (the caller knows it does not wrap).

    Parameters
    ----------
    m : Module
        Module the adder is added to (``comb`` domain).
    a, b : Value
        Unsigned addends of equal width ``w`` bits (asserted).
    name : str
        Name of the ``w + 1``-bit sum signal; its carry goes to ``unused_<name>_carry``.

    Returns
    -------
    Value
        The low ``w`` bits of the sum.
    """
    assert len(a) == len(b), (len(a), len(b))
    w = len(a)
    s = Signal(unsigned(w + 1), name=name)
    m.d.comb += s.eq(a + b)
    sink_unused(m, s[w], f"{name}_carry")
    return s[:w]


def add_const_wrap(m: Module, x: Value, k: int, name: str) -> Value:
    """``(x + k) mod 2**w`` for an unsigned ``w``-bit ``x`` (any integer ``k``).

    ``k mod 2**w`` with its top bit set is added; otherwise ``2**w - k`` is subtracted (same value
    modulo ``2**w``), so the constant always has its top bit set at width ``w``.

    Parameters
    ----------
    m : Module
        Module the adder is added to (``comb`` domain).
    x : Value
        Unsigned operand, ``w`` bits.
    k : int
        Constant, reduced modulo ``2**w``.
    name : str
        Name of the ``w + 1``-bit result signal; its top bit goes to ``unused_<name>_carry`` (or
        ``_borrow``).

    Returns
    -------
    Value
        ``w`` bits; ``x`` itself when ``k mod 2**w`` is 0.
    """
    w = len(x)
    k %= 1 << w
    if k == 0:
        return x
    if k >> (w - 1):
        s = Signal(unsigned(w + 1), name=name)
        m.d.comb += s.eq(x + Const(k, w))
        sink_unused(m, s[w], f"{name}_carry")
        return s[:w]
    # k has its top bit clear: subtract the complement instead (same value modulo 2**w)
    s = Signal(unsigned(w + 1), name=name)  # signed difference, only its low w bits are used
    m.d.comb += s.eq(x - Const((1 << w) - k, w))
    sink_unused(m, s[w], f"{name}_borrow")
    return s[:w]


def sum_wrap(m: Module, terms: Sequence[Value | int], width: int, name: str) -> Value | int:
    """Sum of unsigned ``width``-bit values and ints, modulo ``2**width`` (balanced tree).

    Parameters
    ----------
    m : Module
        Module the adders are added to (``comb`` domain).
    terms : sequence of Value or int
        Unsigned ``width``-bit values and integer constants; the constants are summed first and
        added once, after the tree.
    width : int
        Width of the values and of the result, bits.
    name : str
        Name prefix of the adders' signals (``<name>_s<level>_<i>``, ``<name>_k``).

    Returns
    -------
    Value or int
        ``width`` bits; an int (the constants' sum modulo ``2**width``) when ``terms`` holds no
        value.
    """
    const = sum(t for t in terms if isinstance(t, int))
    vals = [t for t in terms if not isinstance(t, int)]
    if not vals:
        return const % (1 << width)
    total = tree_reduce(vals, lambda a, b, lvl, i: add_wrap(m, a, b, f"{name}_s{lvl}_{i}"))
    return add_const_wrap(m, total, const, f"{name}_k")


def ge_const(x: Value, k: int) -> Value | bool:
    """``x >= k`` for an unsigned ``x`` and a constant ``k``.

    Parameters
    ----------
    x : Value
        Unsigned operand, ``w`` bits.
    k : int
        Constant.

    Returns
    -------
    Value or bool
        1-bit comparison (upper bits reduced, lower bits compared at ``k``'s width); ``True``
        when ``k <= 0``, ``False`` when ``k >= 2**w``.
    """
    w = len(x)
    if k <= 0:
        return True
    if k >= 1 << w:
        return False
    kb = int(k).bit_length()
    low = x[:kb] >= Const(k, kb)
    if kb == w:
        return low
    return x[kb:].any() | low


def mux_const(sel: Value | bool | int, k: int, width: int) -> Value | int:
    """``k`` if ``sel`` else 0, as a full-width ``width``-bit value (int when constant).

    Parameters
    ----------
    sel : Value or bool or int
        1-bit select; a bool or int selects at elaboration time.
    k : int
        Constant, unsigned, at most ``width`` bits.
    width : int
        Width of both multiplexer inputs, bits.

    Returns
    -------
    Value or int
        A ``width``-bit multiplexer; an int (``k`` or 0) when ``sel`` is a bool or int, 0 when
        ``k`` is 0.
    """
    if isinstance(sel, bool) or isinstance(sel, int):
        return k if sel else 0
    if k == 0:
        return 0
    return Mux(sel, Const(k, width), Const(0, width))

