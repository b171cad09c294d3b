"""The corner-bank memory read of :class:`~pwas_hdl.hdl.core.PWASCore` (``memory="corner"``).

Layout: :class:`pwas_hdl.fixedpoint.memory_layout.CornerLayout` -- ``2**n`` banks, bank ``s``
holds the cube corner ``c + s`` of every cell ``c`` at the address made of the cells' bit fields.
The memory address is therefore the cell coordinates themselves: no comparator, no rank table, no
rotation and no step table lies between the split and the block RAMs' address pins. The rank
comparisons run beside the address (their bits are registered with the memory read) and, in the
memory-read cycle, give

* ``mu`` in vertex order (the one-hot selection of the sorted fractions, then the subtractions of
  :meth:`PWASCore._mu_of_sorted`);
* for each vertex ``0 < k < n`` the index ``sel_k`` of its corner ``s_k = {j : rank_j < k}`` among
  the ``C(n, k)`` corners with ``k`` set bits (vertex 0 is corner 0, vertex ``n`` corner
  ``2**n - 1``).

After the read (and after the ``mem_out`` register, on ECP5 the DP16KD output register, when the
pipeline has it) :func:`select_corners` picks vertex ``k``'s word among its ``C(n, k)`` corners
(a multiplexer of registered selects); the multipliers and the adder tree then work in vertex
order, as the bit-true model sums for this layout
(:meth:`~pwas_hdl.fixedpoint.memory_layout.CornerLayout.product_slots`). The arithmetic is that of
the banked core: same ``mu``, same words, exact sum.

Registers before the memory (``split``, ``rank``, ``offset``, ``addr``, ``bank``) each hold the
address, the comparison bits, the fractions and the out-of-range flag; ``mu_late`` has no effect
(``mu`` is always computed in the memory-read cycle).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import combinations
from typing import TYPE_CHECKING, Any

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, unsigned

from pwas_hdl.hdl._lintsafe import bits_for, rom
from pwas_hdl.fixedpoint.memory_layout import weight_memory_name
from pwas_hdl.hdl.weight_rom import weight_rom

if TYPE_CHECKING:
    from pwas_hdl.hdl.core import PWASCore

__all__ = ["corner_read", "select_corners", "corner_patterns"]


def corner_patterns(n: int, k: int) -> list[int]:
    """The corners of vertex ``k`` (``k`` set bits among ``n``, bit ``j`` = dimension ``j``), in the
    order their index ``sel_k`` counts them (lexicographic combinations of the dimensions).

    Parameters
    ----------
    n : int
        Regressor dimension.
    k : int
        Vertex index ``0 .. n`` (the number of set bits).

    Returns
    -------
    list of int
        ``C(n, k)`` corner bit patterns (bank numbers ``0 .. 2**n - 1``).
    """
    return [sum(1 << j for j in c) for c in combinations(range(n), k)]


def _rank_bits(ge, n: int, j: int):
    """The ``n - 1`` comparison bits whose popcount is ``rank_j`` (ties to the lower index)."""
    return [ge[i, j] for i in range(j)] + [~ge[j, i] for i in range(j + 1, n)]


def corner_read(core: PWASCore, m: Module, pipe: Any, valid: Value, cs: list, ds: list,
                oor: Value | bool) -> tuple[Value, dict]:
    """Comparators, the registers before the memory, the ``2**n`` reads, ``mu`` and the selects.

    Parameters
    ----------
    core : PWASCore
        With ``memory_kind == "corner"``.
    m : Module
        Module the logic and the ROMs ``wmem<b>`` are added to.
    pipe : pwas_hdl.hdl.core._Pipe
        The core's pipeline-register collector (registers ``s_rank`` .. ``s_bank`` when the
        pipeline has them, and the memory-read stage ``s_mem``).
    valid : Value
        Valid bit of the sample after the split.
    cs, ds : list
        Cells (``width(p_j - 1)`` bits, or the int 0 when ``p_j = 1``) and aligned fractions
        (``F + 1`` bits) after the split (and its optional register).
    oor : Value or bool
        The out-of-range flag.

    Returns
    -------
    valid : Value
        Valid bit after the memory-read register.
    values : dict
        ``{"data": 2**n read words (word_bits each), "sel": [sel_1 .. sel_{n-1}] (Value or int),
        "mu": n + 1 coefficients (F + 1 bits) in vertex order, "oor": flag}`` after the memory
        register.
    """
    p, pl, plan = core.params, core.pipeline, core.memory_plan
    lay = plan.layout
    n, big_f = p.n, p.frac
    dw, aw = big_f + 1, plan.addr_width
    pairs = core._pairs(n)
    ge_bits = [core._name(m, ds[i] >= ds[j], f"ge_{i}_{j}") for i, j in pairs]  # ties go to i < j
    addr = []
    if aw:  # the cells' bit fields (CornerLayout.field_shifts), last dimension in the LSBs
        parts, pos = [], 0
        for j in sorted(range(n), key=lambda j: lay.field_shifts[j]):
            w = lay.cell_bits[j]
            if not w:
                continue
            assert lay.field_shifts[j] == pos, (j, lay.field_shifts, pos)
            parts.append(cs[j])
            pos += w
        addr = [Cat(*parts)]
    # the registers before the memory (every one on the same values: address, comparisons, fractions)
    for name, on in (("s_rank", pl.rank), ("s_voff", pl.offset), ("s_addr", pl.addr), ("s_bank", pl.bank)):
        valid, r = pipe.stage(name, on, valid, {"caddr": addr, "ge": ge_bits, "d": ds, "oor": oor})
        addr, ge_bits, ds, oor = r["caddr"], r["ge"], r["d"], r["oor"]

    mem_data = []
    for b in range(plan.n_banks):
        mem_data.append(weight_rom(m, weight_memory_name(b), plan.word_bits, plan.depth, plan.contents[b],
                                   addr[0] if aw else None, pipe.advance))
    valid, r = pipe.stage("s_mem", True, valid, {"ge": ge_bits, "d": ds, "oor": oor})
    ge = dict(zip(pairs, r["ge"]))
    ds = r["d"]

    # ------------------------------------------------ memory-read cycle: mu and the corner selects
    sels = []
    for k in range(1, n):
        pats = corner_patterns(n, k)
        table = []
        for v in range(1 << len(pairs)):
            g = {pr: (v >> i) & 1 for i, pr in enumerate(pairs)}
            ranks = [sum(g[i, j] for i in range(j)) + sum(1 - g[j, i] for i in range(j + 1, n)) for j in range(n)]
            s = sum(1 << j for j in range(n) if ranks[j] < k)
            table.append(pats.index(s) if s in pats else 0)  # inconsistent comparison bits: unreachable
        sels.append(rom(m, Cat(*[ge[pr] for pr in pairs]), table, bits_for(len(pats) - 1), f"csel{k}"))
    dsorted = []
    for k in range(1, n + 1):  # d_(k): the fraction of rank k - 1
        acc = None
        for j in range(n):
            if n == 1:
                term = ds[0]
            else:
                e = rom(m, Cat(*_rank_bits(ge, n, j)), [int(bin(v).count("1") == k - 1) for v in range(1 << (n - 1))], 1,
                        f"req{k}_{j}")
                term = ds[j] if isinstance(e, int) and e else (None if isinstance(e, int) else Mux(e, ds[j], Const(0, dw)))
            if term is not None:
                acc = term if acc is None else acc | term
        dsorted.append(acc if isinstance(acc, Signal) else core._name(m, acc, f"dsorted{k}", unsigned(dw)))
    mus = core._mu_of_sorted(m, dsorted)
    return valid, {"data": mem_data, "sel": sels, "mu": mus, "oor": r["oor"]}


def select_corners(m: Module, n: int, words: Sequence[Value], sels: Sequence[Value | int], width: int) -> list[Value]:
    """Vertex ``k``'s word: corner ``corner_patterns(n, k)[sel_k]`` of the ``2**n`` read words.

    Parameters
    ----------
    m : Module
        Module the multiplexers (``cword<k>``) are added to (``comb`` domain).
    n : int
        Regressor dimension (``n >= 1``).
    words : sequence of Value
        The ``2**n`` words read from the corner banks, bank order, ``width`` bits each.
    sels : sequence of Value or int
        ``sel_1 .. sel_{n-1}`` (:func:`corner_read`); an int selects at elaboration time.
    width : int
        Word width, bits.

    Returns
    -------
    list of Value
        ``n + 1`` words in vertex order: corner 0, the selected corners of vertices
        ``1 .. n-1``, corner ``2**n - 1``.
    """
    out = [words[0]]
    for k in range(1, n):
        pats = corner_patterns(n, k)
        sel = sels[k - 1]
        if isinstance(sel, int):
            out.append(words[pats[sel]])
            continue
        o = Signal(unsigned(width), name=f"cword{k}")
        with m.Switch(sel):
            for i, pat in enumerate(pats):
                with (m.Case(i) if i < len(pats) - 1 else m.Default()):
                    m.d.comb += o.eq(words[pat])
        out.append(o)
    if n >= 1:
        out.append(words[(1 << n) - 1])
    return out
