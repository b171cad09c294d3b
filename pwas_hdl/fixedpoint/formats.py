"""Fixed-point number formats: two's complement codes, rounding, overflow, physical scaling.

Everything the bit-true model (:mod:`pwas_hdl.fixedpoint.bittrue`) and the RTL generator need to agree on a
number format lives here.

Conventions
-----------
Code and value
    A :class:`FixedFormat` ``sB.F`` (signed) or ``uB.F`` (unsigned) holds integer *codes* ``c`` of
    ``B`` bits; the code stands for the *format value* ``c * 2**-F`` (``F`` may be negative or
    larger than ``B``). Signed codes are two's complement: ``-2**(B-1) <= c <= 2**(B-1) - 1``;
    unsigned ``0 <= c <= 2**B - 1``. Codes are ``numpy.int64``, so ``B <= 64`` (signed) and
    ``B <= 63`` (unsigned).
Rounding (value -> code)
    ``"half_up"``: ``c = floor(v * 2**F + 0.5)`` (ties go towards +infinity, also for negative
    values: -0.5 -> 0, -1.5 -> -1). ``"truncate"``: ``c = floor(v * 2**F)`` (towards -infinity,
    what dropping low bits of a two's complement number does). Both are computed exactly in
    float64 (``v * 2**F`` is an exact scaling; the half-up test uses ``x - floor(x) >= 0.5``, which
    is exact, not ``floor(x + 0.5)``, which is not for ``x`` just below a tie).
Overflow (code outside the range)
    ``"saturate"``: clamp to the nearest end; ``"error"``: raise :class:`ValueError` naming the
    worst value and the bits it needs; ``"wrap"``: keep the low ``B`` bits (two's complement
    wrap-around; exact while ``|v * 2**F| < 2**53``).
Physical meaning
    A port carries a :class:`PortFormat` = format + :class:`SignalScaling`::

        physical = offset + scale * (code * 2**-F)

    The manifest prints format, scale and offset of every port.
Grid inputs
    :class:`InputFormat` is the format of one regressor dimension of a PWAS grid: signed
    ``B_in``-bit codes placed so that **one grid cell is exactly** ``2**F_j`` **codes** (see the
    class). The hardware then needs no multiplier to go from the input code to the cell index
    and the fraction.

RTL rounding of a right shift
    :func:`shift_round` is the integer operation the RTL performs to drop ``sh`` low bits:
    ``(a + 2**(sh-1)) >> sh`` (half up) or ``a >> sh`` (truncate), arithmetic shifts.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Sequence

import numpy as np
from numpy.typing import ArrayLike

from pwas_hdl.errors import InputError, fault_text

if TYPE_CHECKING:
    from pwas_hdl.fixedpoint.warp import WarpInputFormat

__all__ = [
    "ROUNDING_MODES",
    "OVERFLOW_MODES",
    "FixedFormat",
    "SignalScaling",
    "PortFormat",
    "InputFormat",
    "grid_input_formats",
    "quantize_input",
    "input_to_physical",
    "signed_bits_needed",
    "unsigned_bits_needed",
    "shift_round",
    "frac_for_bits",
]

ROUNDING_MODES = ("half_up", "truncate")
OVERFLOW_MODES = ("saturate", "error", "wrap")

_MAX_ABS_FRAC = 1000  # keeps 2**-frac a normal float64


def _is_int(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def signed_bits_needed(codes: ArrayLike) -> int:
    """Fewest two's complement bits that hold every integer in ``codes`` (at least 1).

    ``c >= 0`` needs ``c.bit_length() + 1`` bits, ``c < 0`` needs ``(-c - 1).bit_length() + 1``.

    Parameters
    ----------
    codes : int or array_like of int
        Integers, any shape (empty: 1 bit).

    Returns
    -------
    int
        Bits (a two's complement width).
    """
    a = np.asarray(codes)
    if a.size == 0:
        return 1
    hi = int(a.max())
    lo = int(a.min())
    return max(1, hi.bit_length() + 1 if hi >= 0 else 1, (-lo - 1).bit_length() + 1 if lo < 0 else 1)


def unsigned_bits_needed(codes: ArrayLike) -> int:
    """Fewest unsigned bits that hold every integer in ``codes`` (at least 1).

    Parameters
    ----------
    codes : int or array_like of int
        Non-negative integers, any shape (empty: 1 bit).

    Returns
    -------
    int
        Bits, ``max(1, max(codes).bit_length())``.

    Raises
    ------
    InputError
        A code is negative.
    """
    a = np.asarray(codes)
    if a.size == 0:
        return 1
    if int(a.min()) < 0:
        raise InputError(f"negative code {int(a.min())} cannot be unsigned")
    return max(1, int(a.max()).bit_length())


def shift_round(a: ArrayLike, sh: int, rounding: str = "half_up") -> np.ndarray:
    """Drop ``sh`` low bits of integers as the RTL does.

    Parameters
    ----------
    a : array_like of int
        Two's complement integers (``numpy.int64``), any shape.
    sh : int
        Bits to drop, ``>= 0``; ``sh = 0`` returns ``a`` unchanged (no rounding).
    rounding : {"half_up", "truncate"}
        ``"half_up"``: ``(a + 2**(sh-1)) >> sh`` = ``floor(a / 2**sh + 1/2)``;
        ``"truncate"``: ``a >> sh`` = ``floor(a / 2**sh)``. ``>>`` is an arithmetic shift.

    Returns
    -------
    ndarray of int64, shape of ``a``
        The shifted integers (units of ``2**sh`` of ``a``'s LSB).

    Raises
    ------
    InputError
        ``sh`` is not an integer ``>= 0``, or an unknown ``rounding``.
    """
    if not _is_int(sh) or sh < 0:
        raise InputError(f"shift must be an integer >= 0, got {sh!r}")
    if rounding not in ROUNDING_MODES:
        raise InputError(f"rounding must be one of {ROUNDING_MODES}, got {rounding!r}")
    x = np.asarray(a, dtype=np.int64)
    if sh == 0:
        return x.copy()
    if rounding == "half_up":
        x = x + np.int64(1 << (sh - 1))
    return x >> np.int64(sh)


def _round_scaled(scaled: np.ndarray, rounding: str) -> np.ndarray:
    """Integer-valued float array: ``floor(scaled)`` or ``floor(scaled + 1/2)``, exactly."""
    fl = np.floor(scaled)
    if rounding == "truncate":
        return fl
    # scaled - floor(scaled) is exact in float64, floor(scaled + 0.5) is not (0.49999999999999994).
    with np.errstate(invalid="ignore"):  # +-inf - +-inf: left infinite, saturated later
        return np.where(np.isfinite(scaled), fl + ((scaled - fl) >= 0.5), scaled)


@dataclass(frozen=True)
class FixedFormat:
    """A binary fixed-point format: ``bits`` total, ``frac`` fraction bits, two's complement.

    Parameters
    ----------
    bits : int
        Total width, ``1 <= bits <= 64`` (signed) or ``<= 63`` (unsigned; codes are int64).
    frac : int
        Fraction bits: the code ``c`` stands for ``c * 2**-frac``. May be negative (lsb > 1) or
        larger than ``bits`` (all values smaller than 1). ``|frac| <= 1000``.
    signed : bool
        Two's complement signed (default) or unsigned.
    rounding : {"half_up", "truncate"}
        Rounding of :meth:`quantize` (see the module docstring).
    overflow : {"saturate", "error", "wrap"}
        What :meth:`quantize` does with values outside the range.

    Examples
    --------
    >>> f = FixedFormat(8, 4)
    >>> str(f), f.lsb, f.min_value, f.max_value
    ('s8.4', 0.0625, -8.0, 7.9375)
    >>> f.quantize([0.03125, -0.03125, 100.0]).tolist()
    [1, 0, 127]
    """

    bits: int
    frac: int
    signed: bool = True
    rounding: str = "half_up"
    overflow: str = "saturate"

    def __post_init__(self) -> None:
        if not _is_int(self.bits):
            raise InputError(f"bits must be an integer, got {self.bits!r}")
        if not _is_int(self.frac):
            raise InputError(f"frac (fraction bits) must be an integer, got {self.frac!r}")
        if not isinstance(self.signed, (bool, np.bool_)):
            raise InputError(f"signed must be True or False, got {self.signed!r}")
        if self.bits < 1:
            raise InputError(f"bits = {self.bits}: a fixed-point format needs at least 1 bit")
        limit = 64 if self.signed else 63
        if self.bits > limit:
            raise InputError(
                f"bits = {self.bits} exceeds {limit}, the widest {'signed' if self.signed else 'unsigned'} "
                "format whose codes fit numpy.int64"
            )
        if abs(self.frac) > _MAX_ABS_FRAC:
            raise InputError(f"frac = {self.frac} is out of the supported range [-{_MAX_ABS_FRAC}, {_MAX_ABS_FRAC}]")
        if self.rounding not in ROUNDING_MODES:
            raise InputError(f"rounding must be one of {ROUNDING_MODES}, got {self.rounding!r}")
        if self.overflow not in OVERFLOW_MODES:
            raise InputError(f"overflow must be one of {OVERFLOW_MODES}, got {self.overflow!r}")
        # normalise numpy scalars to Python ints so that the dataclass hashes/compares simply
        object.__setattr__(self, "bits", int(self.bits))
        object.__setattr__(self, "frac", int(self.frac))
        object.__setattr__(self, "signed", bool(self.signed))

    # ------------------------------------------------------------ range
    @property
    def lsb(self) -> float:
        """Value of one code step, ``2**-frac``."""
        return math.ldexp(1.0, -self.frac)

    @property
    def min_code(self) -> int:
        """Smallest code: ``-2**(bits-1)`` (signed) or 0."""
        return -(1 << (self.bits - 1)) if self.signed else 0

    @property
    def max_code(self) -> int:
        """Largest code: ``2**(bits-1) - 1`` (signed) or ``2**bits - 1``."""
        return (1 << (self.bits - 1)) - 1 if self.signed else (1 << self.bits) - 1

    @property
    def min_value(self) -> float:
        """``min_code * lsb``."""
        return math.ldexp(float(self.min_code), -self.frac)

    @property
    def max_value(self) -> float:
        """``max_code * lsb`` (rounded to float64 for ``bits > 53``)."""
        return math.ldexp(float(self.max_code), -self.frac)

    def __str__(self) -> str:
        return f"{'s' if self.signed else 'u'}{self.bits}.{self.frac}"

    @classmethod
    def from_string(cls, text: str, rounding: str = "half_up", overflow: str = "saturate") -> "FixedFormat":
        """Parse ``"s16.4"``, ``"u12.9"`` or ``"s8.-2"`` (the :meth:`__str__` form).

        Parameters
        ----------
        text : str
            ``s`` (signed) or ``u`` (unsigned), the total bits, ``.``, the fraction bits.
        rounding : {"half_up", "truncate"}
        overflow : {"saturate", "error", "wrap"}

        Returns
        -------
        FixedFormat

        Raises
        ------
        InputError
            ``text`` does not parse, or the format is invalid.
        """
        m = re.fullmatch(r"\s*([su])(\d+)\.(-?\d+)\s*", str(text))
        if not m:
            raise InputError(f"cannot parse fixed-point format {text!r}; expected e.g. 's16.4' or 'u12.9'")
        return cls(int(m.group(2)), int(m.group(3)), m.group(1) == "s", rounding, overflow)

    # ------------------------------------------------------- conversion
    def fits(self, codes: ArrayLike) -> np.ndarray:
        """Elementwise: is the integer code inside ``[min_code, max_code]``?

        Parameters
        ----------
        codes : array_like of int or float
            Codes, any shape; a float that is not a whole number does not fit.

        Returns
        -------
        ndarray of bool, shape of ``codes`` (use ``.all()`` for one answer)
        """
        c = np.asarray(codes)
        if c.dtype.kind in "iu":
            return (c >= self.min_code) & (c <= self.max_code)
        return (c >= self.min_code) & (c <= self.max_code) & (c == np.floor(c))

    def to_float(self, codes: ArrayLike) -> np.ndarray:
        """Format values ``codes * 2**-frac`` (float64; exact for ``|code| < 2**53``).

        Parameters
        ----------
        codes : array_like of int
            Codes (converted to int64), any shape.

        Returns
        -------
        ndarray of float64, shape of ``codes``
            Format values (not physical units; see :meth:`PortFormat.to_physical`).
        """
        return np.ldexp(np.asarray(codes, dtype=np.int64).astype(float), -self.frac)

    def quantize(self, values: ArrayLike, return_saturated: bool = False,
                 what: str = "value") -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Round values to codes and apply the overflow rule.

        Parameters
        ----------
        values : array_like of float
            Format values (``code * 2**-frac`` units, i.e. *not* physical units; see
            :meth:`PortFormat.quantize` for physical values), any shape. NaN is refused; +-inf
            saturates (or raises with ``overflow="error"``).
        return_saturated : bool
            Also return the boolean mask of the values that were outside the range before the
            overflow rule (saturated, wrapped; with ``"error"`` it is all False). ``mask.sum()``
            is the number of saturated values.
        what : str
            Noun used in error messages (e.g. ``"weight"``).

        Returns
        -------
        codes : ndarray of int64, shape of ``values``
        saturated : ndarray of bool, shape of ``values`` (only with ``return_saturated``)

        Raises
        ------
        InputError
            NaN input, or ``overflow="error"`` and a value does not fit. The message names the
            worst value (the one furthest outside the range), the range of the format and the
            number of bits (at this ``frac``) that would hold every value.
        """
        v = np.asarray(values, dtype=float)
        if np.isnan(v).any():
            idx = np.unravel_index(int(np.flatnonzero(np.isnan(v.reshape(-1)))[0]), v.shape)
            raise InputError(f"{what} at index {tuple(int(i) for i in idx)} is NaN; cannot quantize to {self}")
        return self._apply(_round_scaled(np.ldexp(v, self.frac), self.rounding), v, return_saturated, what)

    def _apply(self, r: np.ndarray, v: np.ndarray, return_saturated: bool, what: str):
        """Overflow rule on integer-valued float codes ``r`` (``v``: original values, for messages)."""
        lo_f = float(self.min_code)  # exact: a power of two or 0
        hi_f = float(self.max_code)
        if int(hi_f) > self.max_code:  # bits > 53: largest float64 <= max_code
            hi_f = float(np.nextafter(hi_f, -np.inf))
        below = r < lo_f
        above = r > hi_f
        bad = below | above
        if self.overflow == "error" and bad.any():
            excess = np.where(below, lo_f - r, np.where(above, r - hi_f, 0.0))
            flat = int(np.argmax(excess.reshape(-1)))
            idx = tuple(int(i) for i in np.unravel_index(flat, r.shape))
            worst = float(v.reshape(-1)[flat])
            where = f" at index {idx}" if r.ndim else ""
            if not np.isfinite(r).all():
                need = "no finite number of bits holds an infinite value"
            elif not self.signed and r.min() < 0:
                need = "negative values need a signed format"
            else:
                rr = [int(r.min()), int(r.max())]
                nb = signed_bits_needed(rr) if self.signed else unsigned_bits_needed(rr)
                need = f"{nb} bits are needed at {self.frac} fraction bits"
            raise InputError(
                f"{what}{where} = {worst!r} does not fit the fixed-point format {self} "
                f"(range [{self.min_value!r}, {self.max_value!r}], lsb {self.lsb!r}); "
                f"{int(bad.sum())} value(s) overflow and {need}. "
                "Use more bits, fewer fraction bits, or overflow='saturate'"
            )
        if self.overflow == "wrap":
            span = 2.0 ** self.bits
            r = np.where(bad, np.mod(r - lo_f, span) + lo_f, r)
            codes = r.astype(np.int64)
        else:
            codes = np.clip(r, lo_f, hi_f).astype(np.int64)
            codes = np.where(above, np.int64(self.max_code), codes)
            codes = np.where(below, np.int64(self.min_code), codes)
        codes = np.asarray(codes, dtype=np.int64)
        return (codes, bad) if return_saturated else codes

    # ---------------------------------------------------------- files
    def to_dict(self) -> dict:
        """JSON-ready description (``from_dict`` reads ``bits``, ``frac``, ``signed``,
        ``rounding``, ``overflow``; the rest is for people and the manifest).

        Returns
        -------
        dict
            ``str``, ``bits``, ``frac``, ``signed``, ``rounding``, ``overflow``, ``lsb``,
            ``min_code``, ``max_code``, ``min_value``, ``max_value``.
        """
        return {
            "str": str(self),
            "bits": self.bits,
            "frac": self.frac,
            "signed": self.signed,
            "rounding": self.rounding,
            "overflow": self.overflow,
            "lsb": self.lsb,
            "min_code": self.min_code,
            "max_code": self.max_code,
            "min_value": self.min_value,
            "max_value": self.max_value,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "FixedFormat":
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        d : dict
            ``bits`` and ``frac`` (required), ``signed``, ``rounding``, ``overflow`` (optional:
            True, ``"half_up"``, ``"saturate"``); other keys are ignored.

        Returns
        -------
        FixedFormat

        Raises
        ------
        InputError
            A required key is missing, or the values do not make a valid format.
        """
        try:
            return cls(int(d["bits"]), int(d["frac"]), bool(d.get("signed", True)), d.get("rounding", "half_up"), d.get("overflow", "saturate"))
        except (KeyError, TypeError) as exc:
            raise InputError(f"not a fixed-point format description ({fault_text(exc)}): {d!r}") from exc


def frac_for_bits(values: ArrayLike, bits: int, signed: bool = True, rounding: str = "half_up") -> int:
    """Largest number of fraction bits with which every value fits in ``bits`` bits.

    Useful for precision sweeps ("given B_w bits, the finest lsb that holds all weights").

    Parameters
    ----------
    values : array_like of float
        Format values, any shape (flattened); must be finite; at least one must be non-zero.
    bits : int
        Total width in bits of the format.
    signed : bool
        Two's complement signed, or unsigned.
    rounding : {"half_up", "truncate"}
        Rounding of the quantization (see :class:`FixedFormat`).

    Returns
    -------
    int
        Fraction bits ``frac`` such that ``FixedFormat(bits, frac, signed, rounding, "error").quantize(values)``
        succeeds and ``frac + 1`` would not.

    Raises
    ------
    InputError
        No value, a non-finite value, all values zero, an invalid ``bits``, or no ``frac`` in
        ``[-1000, 1000]`` that holds the values.
    """
    v = np.asarray(values, dtype=float).reshape(-1)
    if v.size == 0 or not np.all(np.isfinite(v)) or not np.any(v != 0):
        raise InputError("frac_for_bits needs finite values, at least one of them non-zero")
    FixedFormat(bits, 0, signed)  # validates bits
    big = float(np.max(np.abs(v)))
    frac = (bits - 1 if signed else bits) - (math.frexp(big)[1])  # a first guess, refined below
    frac = max(-_MAX_ABS_FRAC, min(_MAX_ABS_FRAC, frac))

    def ok(f: int) -> bool:
        fmt = FixedFormat(bits, f, signed, rounding, "saturate")
        _, sat = fmt.quantize(v, return_saturated=True)
        return not sat.any()

    while not ok(frac):
        frac -= 1
        if frac < -_MAX_ABS_FRAC:
            raise InputError(f"no fraction-bit count lets the values fit {bits} bits")
    while frac < _MAX_ABS_FRAC and ok(frac + 1):
        frac += 1
    return frac


@dataclass(frozen=True)
class SignalScaling:
    """Physical meaning of a format value: ``physical = offset + scale * value``.

    Parameters
    ----------
    scale : float
        Positive, finite.
    offset : float
        Finite.
    """

    scale: float = 1.0
    offset: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise InputError(f"scale must be a positive finite number, got {self.scale!r}")
        if not math.isfinite(self.offset):
            raise InputError(f"offset must be finite, got {self.offset!r}")
        object.__setattr__(self, "scale", float(self.scale))
        object.__setattr__(self, "offset", float(self.offset))

    def to_physical(self, value: ArrayLike) -> np.ndarray:
        """``offset + scale * value``.

        Parameters
        ----------
        value : array_like of float
            Format values (``code * 2**-frac``), any shape.

        Returns
        -------
        ndarray of float64, shape of ``value``
            Physical values.
        """
        return self.offset + self.scale * np.asarray(value, dtype=float)

    def from_physical(self, x: ArrayLike) -> np.ndarray:
        """``(x - offset) / scale``.

        Parameters
        ----------
        x : array_like of float
            Physical values, any shape.

        Returns
        -------
        ndarray of float64, shape of ``x``
            Format values (not yet rounded).
        """
        return (np.asarray(x, dtype=float) - self.offset) / self.scale

    def to_dict(self) -> dict:
        """JSON-ready description.

        Returns
        -------
        dict
            ``{"scale": float, "offset": float}``.
        """
        return {"scale": self.scale, "offset": self.offset}


@dataclass(frozen=True)
class PortFormat:
    """Format of a port: codes of ``format`` with the physical meaning ``scaling``.

    ``physical = scaling.offset + scaling.scale * (code * 2**-format.frac)``.

    Parameters
    ----------
    format : FixedFormat
        The codes' format.
    scaling : SignalScaling
        Default: the identity (physical value = format value).
    """

    format: FixedFormat
    scaling: SignalScaling = SignalScaling()

    @property
    def physical_lsb(self) -> float:
        """Physical value of one code step, ``scale * 2**-frac``."""
        return self.scaling.scale * self.format.lsb

    def to_physical(self, codes: ArrayLike) -> np.ndarray:
        """Physical values of codes.

        Parameters
        ----------
        codes : array_like of int
            Codes of :attr:`format`, any shape.

        Returns
        -------
        ndarray of float64, shape of ``codes``
            ``offset + scale * code * 2**-frac``, physical units.
        """
        return self.scaling.to_physical(self.format.to_float(codes))

    def quantize(self, x: ArrayLike, return_saturated: bool = False,
                 what: str = "value") -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Codes of physical values (rounding and overflow of ``format``).

        Parameters
        ----------
        x : array_like of float
            Physical values, any shape.
        return_saturated : bool
            Also return the mask of the values outside the range (see :meth:`FixedFormat.quantize`).
        what : str
            Noun used in error messages.

        Returns
        -------
        codes : ndarray of int64, shape of ``x``
        saturated : ndarray of bool, shape of ``x`` (only with ``return_saturated``)

        Raises
        ------
        InputError
            NaN input, or ``overflow="error"`` and a value does not fit.
        """
        return self.format.quantize(self.scaling.from_physical(x), return_saturated, what)

    def to_dict(self) -> dict:
        """Format, scale and offset (JSON-ready) with the conversion rule spelled out.

        Returns
        -------
        dict
            :meth:`FixedFormat.to_dict` plus ``scale``, ``offset``, ``physical_lsb`` and the rule
            ``physical``.
        """
        return {
            **self.format.to_dict(),
            "scale": self.scaling.scale,
            "offset": self.scaling.offset,
            "physical_lsb": self.physical_lsb,
            "physical": "offset + scale * code * 2**-frac",
        }

    @classmethod
    def from_dict(cls, d: dict) -> "PortFormat":
        """Inverse of :meth:`to_dict`.

        Parameters
        ----------
        d : dict
            The keys of :meth:`FixedFormat.from_dict`, and ``scale`` and ``offset`` (default 1
            and 0).

        Returns
        -------
        PortFormat

        Raises
        ------
        InputError
            Not a valid format, or a scale that is not positive and finite.
        """
        return cls(FixedFormat.from_dict(d), SignalScaling(float(d.get("scale", 1.0)), float(d.get("offset", 0.0))))


def _cell_frac_bits(p: int, bits: int, fill: float) -> int:
    """Largest ``F`` with ``p * 2**F <= min(fill * 2**bits, 2**bits - 1)``, exactly.

    ``2**bits - 1`` is the widest span a ``bits``-bit code range holds (``2**bits`` codes, so
    ``2**bits - 1`` steps from the lowest to the highest); without it ``fill = 1`` with a power-of-two
    ``p`` would put ``hi_code`` one above the largest code. Below ``fill = 1 - 2**-bits`` this is
    ``floor(log2(fill * 2**bits / p))``."""
    rhs = min(Fraction(fill) * (1 << bits), Fraction((1 << bits) - 1))
    f = bits  # p >= 1 and fill <= 1, so F <= bits
    while f >= 0 and Fraction(p) * Fraction(2) ** f > rhs:
        f -= 1
    return f


@dataclass(frozen=True)
class InputFormat:
    """Input code format of one regressor dimension ``j`` of a PWAS grid.

    Build it with :meth:`for_interval`. The domain ``[lo, hi]`` with ``p`` intervals of width
    ``h = (hi - lo) / p`` is mapped to signed ``bits``-bit codes ``q`` so that **one grid cell is
    exactly** ``2**F`` **codes**:

    * ``F`` = the largest integer with ``p * 2**F <= min(fill * 2**bits, 2**bits - 1)``
      (``= floor(log2(fill * 2**bits / p))`` for ``fill < 1``), required ``>= 0``;
    * ``lo_code = -((p * 2**F + 1) // 2)``, ``hi_code = lo_code + p * 2**F`` (the domain is centred
      in the code range; ``q = lo_code`` is ``x = lo``, ``q = hi_code`` is ``x = hi``; both are codes:
      ``min_code <= lo_code`` and ``hi_code <= max_code`` for every ``fill``);
    * ``lsb = h / 2**F`` (physical units per code), ``offset = lo - lo_code * lsb``, so
      ``x = offset + lsb * q``.

    As a :class:`PortFormat` this is ``s<bits>.<F>`` with ``scale = h`` and ``offset``: the format
    value ``q * 2**-F`` counts grid cells.

    ``fill = 1`` uses as much of the code range as a power-of-two cell allows: for ``p`` a power
    of two that is half of it (``p * 2**F = 2**(bits-1)``: ``2**bits`` steps do not fit in
    ``2**bits`` codes), for other ``p`` more than half. ``fill < 1`` leaves head room on both sides
    so that out-of-domain inputs are seen and flagged.

    Hardware (scale stage, no multiplier): ``t = q - lo_code`` (``bits + 1`` signed bits),
    clamp ``t`` to ``[0, p * 2**F]`` (flag ``out_of_range`` if it clamped), cell
    ``c = min(t >> F, p - 1)``, fraction ``d = t - c * 2**F`` in ``[0, 2**F]`` (``F + 1`` bits;
    ``2**F`` only on the top face).

    Attributes
    ----------
    lo, hi : float
        Domain bounds, physical units.
    partitions : int
        ``p >= 1``.
    bits : int
        ``B_in``, the width of the input codes in bits.
    fill : float
        ``input_fill`` in ``(0, 1]``.
    frac : int
        ``F_j``: fraction bits, one grid cell is ``2**F_j`` grid sub-steps.
    lo_code : int
        The input code of ``lo`` (LSB).
    span : int
        Input codes across the domain, ``S``; 0 for the "pow2" scale (then ``p * 2**F``).
    scale_mul : int
        ``K`` of the "exact" front-end scale ``t' = (t * K) >> R`` (1 for "pow2").
    scale_shift : int
        ``R``, in bits, of that scale (0 for "pow2").
    """

    lo: float
    hi: float
    partitions: int
    bits: int
    fill: float
    frac: int
    lo_code: int
    span: int = 0  # input codes across the domain; 0: p * 2**F (scale "pow2")
    scale_mul: int = 1  # K of the exact front-end scale t' = (t * K) >> R ("exact")
    scale_shift: int = 0  # R

    @property
    def scale(self) -> str:
        """``"pow2"`` (one cell = ``2**F`` input codes) or ``"exact"`` (a constant scale in front)."""
        return "pow2" if self.span == 0 else "exact"

    @property
    def input_span(self) -> int:
        """Input codes from ``lo`` to ``hi``: ``p * 2**F`` (pow2) or ``S`` (exact)."""
        return self.span or self.span_codes

    def scaled(self, t: ArrayLike) -> np.ndarray:
        """Grid sub-steps (``2**F`` per cell) of input offsets ``t = q - lo_code``.

        Parameters
        ----------
        t : array_like of int
            Input code offsets ``q - lo_code`` (LSB, converted to int64), any shape.

        Returns
        -------
        ndarray of int64, shape of ``t``
            ``t`` (pow2) or ``(t * K) >> R`` (exact; ``0 -> 0``, ``S -> p * 2**F``,
            non-decreasing). Not clamped.
        """
        ta = np.asarray(t, dtype=np.int64)
        return ta if self.span == 0 else (ta * self.scale_mul) >> self.scale_shift

    @classmethod
    def for_interval(cls, lo: float, hi: float, partitions: int, bits: int = 12, fill: float = 0.9, dim: int | None = None,
                     scale: str = "pow2") -> "InputFormat":
        """The input format of the interval ``[lo, hi]`` cut into ``partitions`` cells.

        Parameters
        ----------
        lo, hi : float
            ``hi > lo``, finite.
        partitions : int
            ``p >= 1``.
        bits : int
            ``B_in``, ``2 <= bits <= 40``.
        fill : float
            Fraction of the code range the domain may use, ``0 < fill <= 1``.
        dim : int, optional
            Dimension index, for error messages.
        scale : {"pow2", "exact"}
            ``"pow2"``: one cell is ``2**F`` codes (no arithmetic in front; a power-of-two ``p``
            uses at most half the code range). ``"exact"``: the domain takes
            ``S = min(floor(fill * 2**bits), 2**bits - 1)`` codes for any ``p`` and the front end
            scales the offset ``t = q - lo_code`` by a constant, ``t' = (t * K) >> R`` with
            ``F`` the smallest such that ``p * 2**F >= S``, ``R = bits + 1`` and
            ``K = ceil(p * 2**(F + R) / S)``: exact at both ends (``t' = p * 2**F`` at ``t = S``)
            and monotone; the point the hardware evaluates is ``lo + h * t' / 2**F``.

        Returns
        -------
        InputFormat

        Raises
        ------
        InputError
            Bad arguments, or ``F < 0`` ("B_in too small for p_j intervals").
        """
        tag = f"_{dim}" if dim is not None else ""
        lo, hi = float(lo), float(hi)
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise InputError(f"input domain{tag} [{lo}, {hi}] must be finite with hi > lo")
        if not _is_int(partitions) or partitions < 1:
            raise InputError(f"p{tag} = {partitions!r}: need an integer number of intervals >= 1")
        if not _is_int(bits) or not 2 <= bits <= 40:
            raise InputError(f"--input-bits (input_bits) = {bits!r}: need an integer in [2, 40]")
        if not (isinstance(fill, (int, float, np.floating)) and 0 < float(fill) <= 1):
            raise InputError(f"--input-fill (input_fill) = {fill!r}: need a number in (0, 1]")
        fill = float(fill)
        p = int(partitions)
        if scale not in ("pow2", "exact"):
            raise InputError(f"--input-scale (input_scale) must be 'pow2' or 'exact', got {scale!r}")
        if scale == "exact":
            smax = int(min(Fraction(fill) * (1 << int(bits)), Fraction((1 << int(bits)) - 1)))
            if smax < p:
                raise InputError(f"B_in too small for p{tag} = {p} intervals: input_bits = {bits} at input_fill = {fill} gives "
                                 f"{smax} codes, fewer than one per grid cell")
            f = 0
            while (p << f) < smax:
                f += 1
            if (p << f) == smax:  # the cell is a power of two codes already: no scale needed
                return cls(lo, hi, p, int(bits), fill, int(f), int(-((smax + 1) // 2)))
            r = int(bits) + 1
            k = -(-(p << (f + r)) // smax)
            return cls(lo, hi, p, int(bits), fill, int(f), int(-((smax + 1) // 2)), int(smax), int(k), int(r))
        f = _cell_frac_bits(p, int(bits), fill)
        if f < 0:
            need = int(bits)
            while _cell_frac_bits(p, need, fill) < 0:
                need += 1
            raise InputError(
                f"B_in too small for p{tag} = {p} intervals: input_bits = {bits} at input_fill = {fill} gives "
                f"fewer than one code per grid cell; use input_bits >= {need} (or fewer intervals)"
            )
        lo_code = -(((p << f) + 1) // 2)
        return cls(lo, hi, p, int(bits), fill, int(f), int(lo_code))

    # ------------------------------------------------------------ derived
    @property
    def cell_codes(self) -> int:
        """Codes per grid cell, ``2**F``."""
        return 1 << self.frac

    @property
    def span_codes(self) -> int:
        """Codes across the domain, ``p * 2**F``."""
        return self.partitions << self.frac

    @property
    def hi_code(self) -> int:
        """``lo_code + input_span`` (the code of ``hi``; ``<= max_code``)."""
        return self.lo_code + self.input_span

    @property
    def step(self) -> float:
        """Physical cell width ``h = (hi - lo) / p`` (as :attr:`pwas_hdl.fit.geometry.Grid.step`)."""
        return (self.hi - self.lo) / self.partitions

    @property
    def lsb(self) -> float:
        """Physical value of one input code, ``h / 2**F`` (pow2) or ``(hi - lo) / S`` (exact)."""
        return math.ldexp(self.step, -self.frac) if self.span == 0 else (self.hi - self.lo) / self.span

    @property
    def offset(self) -> float:
        """``lo - lo_code * lsb``: the physical value of code 0."""
        return self.lo - self.lo_code * self.lsb

    @property
    def format(self) -> FixedFormat:
        """``s<bits>.<F>`` (pow2) or ``s<bits>.0`` (exact), rounding half up, saturating."""
        return FixedFormat(self.bits, self.frac if self.span == 0 else 0, True, "half_up", "saturate")

    @property
    def port(self) -> PortFormat:
        """:class:`PortFormat` with ``scale = h`` (pow2) or ``lsb`` (exact) and :attr:`offset`."""
        return PortFormat(self.format, SignalScaling(self.step if self.span == 0 else self.lsb, self.offset))

    # --------------------------------------------------------- conversion
    def quantize(self, x: ArrayLike, return_saturated: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Input codes of physical values.

        ``q = floor(lo_code + (x - lo) / lsb + 1/2)`` evaluated in float64 (round half up to the
        nearest code; measured from ``lo`` so that ``x = lo`` gives ``lo_code`` exactly), then
        saturated to ``[-2**(bits-1), 2**(bits-1) - 1]``.

        Parameters
        ----------
        x : array_like of float, physical units
            Values to quantize, any shape.
        return_saturated : bool
            Also return the mask of values that saturated the ``bits``-bit range.

        Returns
        -------
        q : ndarray of int64, shape of ``x``
            Input codes (LSB).
        saturated : ndarray of bool, shape of ``x`` (only with ``return_saturated``)

        Raises
        ------
        InputError
            ``x`` contains NaN.
        """
        return quantize_input(self, x, return_saturated)

    def to_physical(self, q: ArrayLike) -> np.ndarray:
        """Physical value a code represents: ``lo + lsb * (q - lo_code)`` (= ``offset + lsb*q``).

        Parameters
        ----------
        q : array_like of int
            Input codes (LSB), any shape.

        Returns
        -------
        ndarray of float64, shape of ``q``
            Physical units.
        """
        return input_to_physical(self, q)

    def grid_units(self, q: ArrayLike) -> np.ndarray:
        """Unclamped grid coordinate the hardware computes for codes, ``scaled(q - lo_code) / 2**F``
        (exact float; ``(q - lo_code) / 2**F`` for pow2).

        Parameters
        ----------
        q : array_like of int
            Input codes (LSB), any shape.

        Returns
        -------
        ndarray of float64, shape of ``q``
            Grid units (cells from ``lo``); outside ``[0, p]`` for codes outside the domain.
        """
        return np.ldexp(self.scaled(np.asarray(q, dtype=np.int64) - self.lo_code).astype(float), -self.frac)

    def to_dict(self) -> dict:
        """JSON-ready: domain, ``F``, codes, physical scaling.

        Returns
        -------
        dict
            ``format``, ``bits``, ``F``, ``partitions``, ``lo``, ``hi``, ``fill``, ``lo_code``,
            ``hi_code``, ``input_scale`` (and ``input_span``, ``scale_mul``, ``scale_shift`` for
            the exact scale, ``cell_codes`` for pow2), ``min_code``, ``max_code``, ``lsb``,
            ``offset``, ``scale`` (the cell width ``h``) and the rule ``physical``.
        """
        return {
            "format": str(self.format),
            "bits": self.bits,
            "signed": True,
            "F": self.frac,
            "partitions": self.partitions,
            "lo": self.lo,
            "hi": self.hi,
            "fill": self.fill,
            "lo_code": self.lo_code,
            "hi_code": self.hi_code,
            "input_scale": self.scale,
            **({"input_span": self.span, "scale_mul": self.scale_mul, "scale_shift": self.scale_shift,
                "scaled": "t' = ((q - lo_code) * scale_mul) >> scale_shift grid sub-steps, 2**F per cell"}
               if self.span else {"cell_codes": self.cell_codes}),
            "min_code": self.format.min_code,
            "max_code": self.format.max_code,
            "lsb": self.lsb,
            "offset": self.offset,
            "scale": self.step,
            "physical": "offset + lsb * code = offset + scale * code * 2**-F",
        }


def quantize_input(f: InputFormat | WarpInputFormat, x: ArrayLike,
                   return_saturated: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """The input codes of physical values ``x`` for an input format ``f``.

    ``floor(lo_code + (x - lo) / lsb + 1/2)`` in float64, saturated to ``f.format`` (see
    :meth:`InputFormat.quantize`).

    Parameters
    ----------
    f : InputFormat or WarpInputFormat
        Anything with ``lo``, ``lo_code``, ``lsb`` and a saturating ``format``.
    x : array_like of float
        Physical values, any shape.
    return_saturated : bool
        Also return the mask of the values that saturated ``f.format``.

    Returns
    -------
    q : ndarray of int64, shape of ``x``
        Input codes (LSB).
    saturated : ndarray of bool, shape of ``x`` (only with ``return_saturated``)

    Raises
    ------
    InputError
        ``x`` contains NaN.
    """
    v = np.asarray(x, dtype=float)
    if np.isnan(v).any():
        raise InputError("input values contain NaN; cannot quantize")
    with np.errstate(over="ignore"):  # a value far outside a tiny lsb: +-inf, saturated like any outside value
        scaled = f.lo_code + (v - f.lo) / f.lsb
    return f.format._apply(_round_scaled(scaled, "half_up"), v, return_saturated, "input")


def input_to_physical(f: InputFormat | WarpInputFormat, q: ArrayLike) -> np.ndarray:
    """The physical values input codes ``q`` represent for an input format ``f``.

    Parameters
    ----------
    f : InputFormat or WarpInputFormat
        As in :func:`quantize_input`.
    q : array_like of int
        Input codes (LSB), any shape.

    Returns
    -------
    ndarray of float64, shape of ``q``
        ``lo + lsb * (q - lo_code)``, physical units.
    """
    return f.lo + f.lsb * (np.asarray(q, dtype=np.int64) - f.lo_code).astype(float)


def grid_input_formats(lo: Sequence[float], hi: Sequence[float], partitions: Sequence[int], bits: int = 12, fill: float = 0.9,
                       scale: str = "pow2") -> list[InputFormat]:
    """One :class:`InputFormat` per dimension (e.g. of a :class:`~pwas_hdl.fit.geometry.Grid`:
    ``grid_input_formats(g.lo, g.hi, g.partitions)``).

    Parameters
    ----------
    lo, hi : sequence of float, length n
        Domain bounds per dimension, physical units.
    partitions : sequence of int, length n
        Intervals ``p_j`` per dimension.
    bits : int
        ``B_in``, the input code width in bits, as in :meth:`InputFormat.for_interval`.
    fill, scale
        As in :meth:`InputFormat.for_interval` (the same for every dimension).

    Returns
    -------
    list of InputFormat
        ``n`` formats (as many as the shortest of ``lo``, ``hi``, ``partitions``).

    Raises
    ------
    InputError
        A dimension's arguments are invalid (the message names the dimension).
    """
    return [InputFormat.for_interval(float(a), float(b), int(p), bits, fill, dim=j, scale=scale)
            for j, (a, b, p) in enumerate(zip(lo, hi, partitions))]
