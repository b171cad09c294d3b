"""Signed bit fields in one unsigned word: the single packing / unpacking of payloads and ROM words.

Every place that puts several two's complement codes into one integer uses this module: the stream
payloads of the generated designs (``in__payload``, ``out__payload``), the packed weight words of
the memories (target 0 in the least significant bits), the Amaranth-simulator helpers
(:mod:`pwas_hdl.hdl.simulate`), the RTL replay and its debug probes
(:mod:`pwas_hdl.verify.simulation`) and the cocotb drivers in ``sim/``.

Two ways to name the fields:

* equal widths, field ``i`` at bits ``[i*width +: width]`` (:func:`pack`, :func:`unpack`,
  :func:`pack_rows`);
* explicit fields, a sequence of dicts with ``lsb``, ``width`` and optionally ``signed``, as the
  manifest's ``payload`` lists them (:func:`pack_fields`, :func:`unpack_fields`).

A value fits a ``w``-bit field when it lies in ``[-2**(w-1), 2**w - 1]`` (a signed or an unsigned
reading of the same bits); anything else is refused rather than silently wrapped. Words are Python
integers (a packed ROM word of several targets can be wider than 64 bits).
"""

from __future__ import annotations

from typing import Iterable, Mapping, Sequence

import numpy as np

from pwas_hdl.errors import InputError

__all__ = ["to_unsigned", "to_signed", "pack", "unpack", "pack_fields", "unpack_fields", "pack_rows"]


def to_unsigned(value: int, width: int) -> int:
    """The ``width``-bit two's complement pattern of ``value``.

    Parameters
    ----------
    value : int
        In ``[-2**(width-1), 2**width - 1]``.
    width : int
        Field width in bits, ``>= 1``.

    Returns
    -------
    int
        In ``[0, 2**width)``.

    Raises
    ------
    InputError
        ``value`` does not fit ``width`` bits.
    """
    v = int(value)
    if not -(1 << (width - 1)) <= v < (1 << width):
        raise InputError(f"code {v} does not fit {width} bits")
    return v & ((1 << width) - 1)


def to_signed(bits: int, width: int) -> int:
    """Two's complement reading of the low ``width`` bits of ``bits``."""
    v = int(bits) & ((1 << width) - 1)
    return v - (1 << width) if v >> (width - 1) else v


def pack(values: Iterable[int], width: int) -> int:
    """Pack codes of equal width into one word, element 0 in the least significant bits.

    Parameters
    ----------
    values : iterable of int
        Signed or unsigned codes that fit ``width`` bits.
    width : int
        Bits per field.

    Returns
    -------
    int
        Unsigned, ``len(values) * width`` bits.
    """
    word = 0
    for i, v in enumerate(values):
        word |= to_unsigned(v, width) << (i * width)
    return word


def unpack(word: int, width: int, count: int, signed: bool = True) -> list[int]:
    """Inverse of :func:`pack`: ``count`` fields of ``width`` bits, two's complement unless ``signed=False``."""
    word = int(word)
    mask = (1 << width) - 1
    if signed:
        return [to_signed(word >> (i * width), width) for i in range(count)]
    return [(word >> (i * width)) & mask for i in range(count)]


def pack_fields(values: Iterable[int], fields: Sequence[Mapping]) -> int:
    """Pack codes by explicit bit fields (``lsb``, ``width``; the manifest's ``payload`` entries).

    ``values[i]`` goes to ``fields[i]``; extra values or fields are ignored (``zip``).
    """
    word = 0
    for v, f in zip(values, fields):
        word |= to_unsigned(v, int(f["width"])) << int(f["lsb"])
    return word


def unpack_fields(word: int, fields: Sequence[Mapping]) -> list[int]:
    """Inverse of :func:`pack_fields`; fields with a true ``signed`` are two's complement."""
    word = int(word)
    out = []
    for f in fields:
        w = int(f["width"])
        v = (word >> int(f["lsb"])) & ((1 << w) - 1)
        out.append(to_signed(v, w) if f.get("signed") else v)
    return out


def pack_rows(codes, width: int) -> list[int]:
    """One packed word per row of ``codes`` (:func:`pack` of each row).

    Parameters
    ----------
    codes : array_like of int, shape (rows, fields) or (rows,)
        E.g. the ROM image of one bank, ``(depth, nz)``: target 0 in the least significant bits.
    width : int
        Bits per field.

    Returns
    -------
    list of int
        ``rows`` unsigned words of ``fields * width`` bits.
    """
    c = np.asarray(codes, dtype=np.int64)
    if c.ndim == 1:
        c = c[:, None]
    return [pack(row, width) for row in c.tolist()]
