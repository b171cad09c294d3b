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
  manifest's ``payload`` lists them (:func:`pack_fields`, :func:`unpack_fields`; for many rows at
  once, as arrays of 32-bit words the way Verilator stores a wide port, :func:`pack_fields_words`,
  :func:`unpack_fields_words`).

A value fits a ``w``-bit field when it lies in ``[-2**(w-1), 2**w - 1]`` (a signed or an unsigned
reading of the same bits); anything else is refused rather than silently wrapped. Words are Python
integers (a packed ROM word of several targets can be wider than 64 bits).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Iterable, Mapping, Sequence

import numpy as np

from pwas_hdl.errors import InputError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = [
    "to_unsigned",
    "to_signed",
    "pack",
    "unpack",
    "pack_fields",
    "unpack_fields",
    "pack_rows",
    "check_codes",
    "int64_codes",
    "pack_fields_words",
    "unpack_fields_words",
]


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
    """Two's complement reading of the low ``width`` bits of ``bits``.

    Parameters
    ----------
    bits : int
        A bit pattern (only its low ``width`` bits are read; not a width).
    width : int
        Field width in bits, ``>= 1``.

    Returns
    -------
    int
        In ``[-2**(width-1), 2**(width-1))``.
    """
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
    """Inverse of :func:`pack`: ``count`` fields of ``width`` bits, two's complement unless ``signed=False``.

    Parameters
    ----------
    word : int
        The packed word, field 0 in the least significant bits.
    width : int
        Bits per field.
    count : int
        Fields to read.
    signed : bool
        Read each field as two's complement (default) or unsigned.

    Returns
    -------
    list of int
        ``count`` codes.
    """
    word = int(word)
    mask = (1 << width) - 1
    if signed:
        return [to_signed(word >> (i * width), width) for i in range(count)]
    return [(word >> (i * width)) & mask for i in range(count)]


def pack_fields(values: Iterable[int], fields: Sequence[Mapping]) -> int:
    """Pack codes by explicit bit fields (``lsb``, ``width``; the manifest's ``payload`` entries).

    ``values[i]`` goes to ``fields[i]``; extra values or fields are ignored (``zip``).

    Parameters
    ----------
    values : iterable of int
        Codes, each fitting its field's ``width`` bits (signed or unsigned).
    fields : sequence of mapping
        ``lsb`` (bit position) and ``width`` (bits) of each field.

    Returns
    -------
    int
        The unsigned word.

    Raises
    ------
    InputError
        A value does not fit its field.
    """
    word = 0
    for v, f in zip(values, fields):
        word |= to_unsigned(v, int(f["width"])) << int(f["lsb"])
    return word


def unpack_fields(word: int, fields: Sequence[Mapping]) -> list[int]:
    """Inverse of :func:`pack_fields`; fields with a true ``signed`` are two's complement.

    Parameters
    ----------
    word : int
        The packed word.
    fields : sequence of mapping
        ``lsb`` (bit position), ``width`` (bits) and optionally ``signed`` of each field.

    Returns
    -------
    list of int
        One code per field.
    """
    word = int(word)
    out = []
    for f in fields:
        w = int(f["width"])
        v = (word >> int(f["lsb"])) & ((1 << w) - 1)
        out.append(to_signed(v, w) if f.get("signed") else v)
    return out


def pack_rows(codes: "ArrayLike", width: int) -> list[int]:
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
    a = np.asarray(codes)
    if a.dtype.kind == "u" and a.size and int(a.max()) > _INT64_MAX:  # int64 would wrap them: exact Python integers
        c = a.astype(object)
        return [pack(row, width) for row in (c if c.ndim > 1 else c[:, None]).tolist()]
    c = np.asarray(a, dtype=np.int64)
    if c.ndim == 1:
        c = c[:, None]
    if c.shape[1] * width > 63:  # wider than an int64: Python integers
        return [pack(row, width) for row in c.tolist()]
    check_codes(c, width)
    u = c & ((1 << width) - 1)
    word = np.zeros(len(c), dtype=np.int64)
    for i in range(c.shape[1]):
        word |= u[:, i] << (i * width)
    return word.tolist()


#: The largest int64: unsigned 64-bit codes above it would wrap to negatives in an int64 array.
_INT64_MAX = (1 << 63) - 1


def int64_codes(codes: "ArrayLike") -> np.ndarray | None:
    """``codes`` as an int64 array when that conversion is exact, else None (use Python integers).

    Exact for arrays and sequences of integers or booleans that an int64 holds. None for unsigned
    64-bit values of ``2**63`` and more (an int64 would wrap them to negatives, and a code that
    does not fit would be written as one that does), for floats (numpy turns NaN and values
    beyond int64 into ``-2**63`` where ``int()`` refuses them or keeps their value), objects,
    strings and ragged input.

    Parameters
    ----------
    codes : array_like
        Codes, any shape.

    Returns
    -------
    numpy.ndarray of int64, shape of ``codes``, or None
    """
    try:
        a = np.asarray(codes)
    except (OverflowError, TypeError, ValueError):
        return None
    if a.dtype.kind in "bi" or (a.dtype.kind == "u" and (not a.size or int(a.max()) <= _INT64_MAX)):
        return a.astype(np.int64)
    return None


def check_codes(codes: np.ndarray, width: int) -> None:
    """:func:`to_unsigned`'s check on an integer array: every code fits ``width`` bits, signed or
    unsigned (``-2**(width-1) <= code < 2**width``).

    Parameters
    ----------
    codes : numpy.ndarray of int64, any shape
    width : int
        Bits, 1..63.

    Raises
    ------
    InputError
        A code does not fit (the message names the first one, as :func:`to_unsigned` does).
    """
    bad = (codes < -(1 << (width - 1))) | (codes >= (1 << width))
    if bad.any():
        raise InputError(f"code {int(codes[bad].flat[0])} does not fit {width} bits")


def _array_field(f: Mapping, k: int) -> tuple[int, int, str]:
    """``(width, lsb, name)`` of field ``k`` for the array forms (int64 codes: up to 62 bits)."""
    w, lsb, name = int(f["width"]), int(f["lsb"]), f.get("name", k)
    if w > 62:
        raise InputError(f"field {name!r} is {w} bits wide; arrays of codes hold fields of up to 62 bits")
    return w, lsb, name


def _chunks(lsb: int, width: int, word_bits: int):
    """``(word index, offset in the word, offset in the field, bits)`` of the pieces of a field."""
    done = 0
    while done < width:
        wi, off = divmod(lsb + done, word_bits)
        take = min(word_bits - off, width - done)
        yield wi, off, done, take
        done += take


def pack_fields_words(values: "ArrayLike", fields: Sequence[Mapping], n_words: int, word_bits: int = 32) -> np.ndarray:
    """:func:`pack_fields` of many rows at once, as ``word_bits``-bit words (word 0 = the low bits).

    Parameters
    ----------
    values : array_like of int, shape (m, len(fields))
        Codes that fit their fields (fields of up to 62 bits).
    fields : sequence of dict
        ``lsb``, ``width`` of each field.
    n_words : int
        Words per row (``ceil(payload width / word_bits)``).
    word_bits : int
        Bits per word: 8, 16 or 32 (default 32: Verilator's ``VlWide`` words).

    Returns
    -------
    ndarray, shape (m, n_words), unsigned of ``word_bits`` bits

    Raises
    ------
    InputError
        Bad ``word_bits`` or shape, a code that does not fit its field, a field wider than 62 bits
        or ending past ``n_words`` words.
    """
    if word_bits not in (8, 16, 32):
        raise InputError(f"word_bits must be 8, 16 or 32, got {word_bits!r}")
    v = np.asarray(values, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != len(fields):
        raise InputError(f"values must have shape (m, {len(fields)}), got {v.shape}")
    out = np.zeros((v.shape[0], int(n_words)), dtype=np.uint64)
    for k, f in enumerate(fields):
        w, lsb, name = _array_field(f, k)
        col = v[:, k]
        bad = (col < -(1 << (w - 1))) | (col >= (1 << w))
        if bad.any():
            raise InputError(f"code {int(col[bad][0])} does not fit {w} bits (field {name!r})")
        col = (col & ((1 << w) - 1)).astype(np.uint64)
        for wi, off, done, take in _chunks(lsb, w, word_bits):
            if wi >= n_words:
                raise InputError(f"field {name!r} ends past the {n_words} words of {word_bits} bits")
            out[:, wi] |= ((col >> np.uint64(done)) & np.uint64((1 << take) - 1)) << np.uint64(off)
    return out.astype({8: np.uint8, 16: np.uint16, 32: np.uint32}[word_bits])


def unpack_fields_words(words: "ArrayLike", fields: Sequence[Mapping], word_bits: int = 32) -> np.ndarray:
    """Inverse of :func:`pack_fields_words`: ``(m, n_words)`` -> ``(m, len(fields))`` int64.

    Fields with a true ``signed`` are two's complement; fields of up to 62 bits.

    Parameters
    ----------
    words : array_like of unsigned int, shape (m, n_words)
        ``word_bits``-bit words of each row, word 0 the low bits.
    fields : sequence of mapping
        ``lsb`` (bit position), ``width`` (bits) and optionally ``signed`` of each field.
    word_bits : int
        Bits per word, as in :func:`pack_fields_words`.

    Returns
    -------
    ndarray of int64, shape (m, len(fields))
        The codes.

    Raises
    ------
    InputError
        ``words`` is not 2-D, or a field is wider than 62 bits.
    """
    wv = np.asarray(words).astype(np.uint64)
    if wv.ndim != 2:
        raise InputError(f"words must have shape (m, n_words), got {wv.shape}")
    out = np.zeros((wv.shape[0], len(fields)), dtype=np.int64)
    for k, f in enumerate(fields):
        w, lsb, _ = _array_field(f, k)
        acc = np.zeros(wv.shape[0], dtype=np.uint64)
        for wi, off, done, take in _chunks(lsb, w, word_bits):
            acc |= ((wv[:, wi] >> np.uint64(off)) & np.uint64((1 << take) - 1)) << np.uint64(done)
        val = acc.astype(np.int64)
        if f.get("signed"):
            val = np.where(val >= (1 << (w - 1)), val - (1 << w), val)
        out[:, k] = val
    return out
