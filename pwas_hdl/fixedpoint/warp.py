"""Bit-true model of the power-of-two warp: non-uniform (``--breakpoints quantile-pow2``) PWAS in hardware.

A non-uniform partition whose cells are power-of-two multiples of one base step per dimension
(:func:`pwas_hdl.fit.geometry.pow2_breakpoints`) needs no divider: a small *warp* stage maps the
input code to the code of a uniform grid, and the unchanged uniform core
(:class:`pwas_hdl.fixedpoint.bittrue.FixedPointModel`, :class:`pwas_hdl.hdl.core.PWASCore`) does
the rest. This module is the specification of that stage, bit for bit
(:mod:`pwas_hdl.hdl.warp` is its RTL).

Per dimension ``j`` (index ``j`` dropped), cells ``k = 0 .. p-1`` of ``2**e_k`` base steps ``h0``:

* input codes: signed ``B_in`` bits, ``x = offset + lsb * q`` with ``lsb = h0 / 2**f0``, ``f0`` the
  largest with ``S * 2**f0 <= min(input_fill * 2**B_in, 2**B_in - 1)`` (``S = sum_k 2**e_k`` base
  steps across the domain); the domain is ``[B_0, B_p]`` in codes, ``B_0 = -((S 2**f0 + 1) // 2)``,
  ``B_(k+1) = B_k + 2**(f0 + e_k)`` (every breakpoint is a code);
* the uniform core sees ``u`` (signed ``W`` bits, its own input format: ``lo_code = L``, one cell
  ``= 2**F`` codes, ``F >= f0 + max e_k``), where the warp is::

      q <  B_0             -> u = L - 1                  (below: the core clamps and flags it)
      q >  B_p             -> u = L + p 2**F + 1         (above: idem)
      q == B_p             -> u = L + p 2**F             (the top face)
      B_k <= q < B_(k+1)   -> u = L + k 2**F + ((q - B_k) << (F - f0 - e_k))

  exact: within cell ``k`` the grid coordinate of the core, ``(u - L) / 2**F``, is
  ``k + (q - B_k) / 2**(f0 + e_k)``, the float model's warp (:meth:`pwas_hdl.fit.geometry.Grid.to_grid_units`)
  at the physical value of ``q``; so the error bound of the core applies unchanged.

:class:`WarpedFixedPointModel` = the warps + a :class:`FixedPointModel` of the same weights on
the unit grid (cells of one grid unit) with ``input_bits = W``.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
from numpy.typing import ArrayLike

from pwas_hdl.errors import InputError
from pwas_hdl.fit.geometry import Grid, pow2_exponents

if TYPE_CHECKING:
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.fixedpoint.formats import FixedFormat, PortFormat

__all__ = ["Pow2Warp", "WarpInputFormat", "WarpedFixedPointModel", "is_warped"]


def is_warped(sensor: Any) -> bool:
    """True for a sensor fitted with ``breakpoints`` on one grid (a non-uniform partition): its
    bit-true model is :class:`WarpedFixedPointModel`, its designs have the warp in front of the core.

    The one test of "warped" for every design kind (``generate``, the observer-bank and recurrent
    models, the replay); an additive sensor's grid (``subsets``) is not warped.

    Parameters
    ----------
    sensor : PWASVirtualSensor
        Fitted.

    Returns
    -------
    bool
    """
    grid = sensor.grid_
    return getattr(grid, "breakpoints", None) is not None and getattr(grid, "subsets", None) is None


@dataclass(frozen=True)
class Pow2Warp:
    """The warp of one dimension (all integers; see the module notes).

    Attributes
    ----------
    input_bits : int
        ``B_in``, the width in bits of the input code ``q``.
    code_breaks : tuple of int
        ``B_0 .. B_p`` (input codes).
    exps : tuple of int
        ``e_k``: cell ``k`` is ``2**(f0 + e_k)`` input codes.
    f0 : int
    frac : int
        ``F`` of the core's dimension (one core cell = ``2**F`` codes of ``u``).
    lo_u : int
        ``L``, the core's ``lo_code``.
    width : int
        ``W``, bits of the signed ``u``.
    """

    input_bits: int
    code_breaks: tuple[int, ...]
    exps: tuple[int, ...]
    f0: int
    frac: int
    lo_u: int
    width: int

    @property
    def p(self) -> int:
        """Number of cells ``p`` of the dimension."""
        return len(self.exps)

    def shifts(self) -> tuple[int, ...]:
        """Left shift of cell ``k``: ``F - f0 - e_k``.

        Returns
        -------
        tuple of int
            ``p`` shifts, one per cell.
        """
        return tuple(self.frac - self.f0 - e for e in self.exps)

    def apply(self, q: np.ndarray) -> np.ndarray:
        """``u`` codes (int64, same shape) for input codes ``q``.

        Parameters
        ----------
        q : ndarray of int
            Input codes of this dimension (``B_in``-bit; any shape).

        Returns
        -------
        ndarray of int64, shape of ``q``
            The core's codes ``u`` by the rule of the module notes: ``lo_u - 1`` below ``B_0``,
            ``lo_u + p 2**F + 1`` above ``B_p``.
        """
        q = np.asarray(q, dtype=np.int64)
        b = np.asarray(self.code_breaks, dtype=np.int64)
        k = np.clip(np.searchsorted(b, q, side="right") - 1, 0, self.p - 1)
        sh = np.asarray(self.shifts(), dtype=np.int64)[k]
        u = self.lo_u + (k << self.frac) + ((q - b[k]) << sh)
        u = np.where(q < b[0], self.lo_u - 1, u)
        u = np.where(q > b[-1], self.lo_u + (self.p << self.frac) + 1, u)
        return u

    def apply_one(self, q: int) -> int:
        """:meth:`apply` of one code, in Python integers (the recurrence's step).

        Parameters
        ----------
        q : int
            An input code of this dimension.

        Returns
        -------
        int
            ``u``, as :meth:`apply` gives it (``bisect_right`` is ``searchsorted(side="right")``).
        """
        b = self.code_breaks
        if q < b[0]:
            return self.lo_u - 1
        if q > b[-1]:
            return self.lo_u + (self.p << self.frac) + 1
        k = min(max(bisect_right(b, q) - 1, 0), self.p - 1)
        return self.lo_u + (k << self.frac) + ((q - b[k]) << (self.frac - self.f0 - self.exps[k]))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (the manifest's ``warp.dimensions`` entries).

        Returns
        -------
        dict
            The attributes (``frac`` as ``F``) and the per-cell ``shifts``.
        """
        return {"input_bits": self.input_bits, "code_breaks": list(self.code_breaks), "exps": list(self.exps), "f0": self.f0,
                "F": self.frac, "lo_u": self.lo_u, "width": self.width, "shifts": list(self.shifts())}


@dataclass(frozen=True)
class WarpInputFormat:
    """Input code format of one dimension of a warped (power-of-two non-uniform) design.

    Signed ``bits``-bit codes ``q`` with ``x = offset + lsb * q`` (as a port format ``s<bits>.0``
    with ``scale = lsb``); the domain ``[lo, hi]`` is ``[lo_code, hi_code] = [B_0, B_p]`` in codes.
    Two dimensions with equal formats (``==`` compares the quantisation only, not the cut points
    inside the domain) can share one input code: the lags of one signal in the sensor top.

    Attributes
    ----------
    bits : int
        ``B_in``, the width in bits of the input codes.
    lo, hi : float
        Domain, physical units.
    partitions : int
        Cells ``p`` of the dimension.
    lsb, offset : float
        Physical units per code and of code 0.
    lo_code, hi_code : int
        ``B_0`` and ``B_p``.
    breakpoints : tuple of float
        The cut points (physical), ``p + 1`` (not compared).
    code_breaks : tuple of int
        ``B_0 .. B_p`` (not compared).
    """

    bits: int
    lo: float
    hi: float
    partitions: int
    lsb: float
    offset: float
    lo_code: int
    hi_code: int
    breakpoints: tuple[float, ...] = field(default=(), compare=False)
    code_breaks: tuple[int, ...] = field(default=(), compare=False)

    @property
    def frac(self) -> int:
        """0: the codes are integers (the cells are ``2**(f0 + e_k)`` codes, not one power of two)."""
        return 0

    @property
    def format(self) -> FixedFormat:
        """:class:`~pwas_hdl.fixedpoint.formats.FixedFormat` ``s<bits>.0``, rounding half up, saturating."""
        from pwas_hdl.fixedpoint.formats import FixedFormat

        return FixedFormat(self.bits, 0, True, "half_up", "saturate")

    @property
    def port(self) -> PortFormat:
        """:class:`~pwas_hdl.fixedpoint.formats.PortFormat` ``s<bits>.0``, ``scale = lsb``, :attr:`offset`."""
        from pwas_hdl.fixedpoint.formats import PortFormat, SignalScaling

        return PortFormat(self.format, SignalScaling(self.lsb, self.offset))

    def quantize(self, x: ArrayLike, return_saturated: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Input codes of physical values: ``floor(lo_code + (x - lo) / lsb + 1/2)``, saturated to
        ``bits`` (as :meth:`pwas_hdl.fixedpoint.formats.InputFormat.quantize`: ``x = lo`` gives
        ``lo_code`` exactly).

        Parameters
        ----------
        x : array_like of float
            Physical values, any shape.
        return_saturated : bool
            Also return the mask of the values that saturated the ``bits``-bit range.

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
        from pwas_hdl.fixedpoint.formats import quantize_input

        return quantize_input(self, x, return_saturated)

    def to_physical(self, q: ArrayLike) -> np.ndarray:
        """``lo + lsb * (q - lo_code)``.

        Parameters
        ----------
        q : array_like of int
            Input codes (LSB), any shape.

        Returns
        -------
        ndarray of float64, shape of ``q``
            Physical units.
        """
        from pwas_hdl.fixedpoint.formats import input_to_physical

        return input_to_physical(self, q)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description, with the keys of :meth:`InputFormat.to_dict` where they apply.

        Returns
        -------
        dict
            ``format``, ``bits``, ``F`` (0), ``partitions``, ``lo``, ``hi``, ``lo_code``, ``hi_code``,
            ``input_scale`` (``"warp"``), ``min_code``, ``max_code``, ``lsb``, ``offset``, ``scale``
            (= ``lsb``), ``breakpoints``, ``code_breaks`` and the rule ``physical``.
        """
        fmt = self.format
        return {"format": str(fmt), "bits": self.bits, "signed": True, "F": 0, "partitions": self.partitions,
                "lo": self.lo, "hi": self.hi, "lo_code": self.lo_code, "hi_code": self.hi_code,
                "input_scale": "warp", "min_code": fmt.min_code, "max_code": fmt.max_code, "lsb": self.lsb,
                "offset": self.offset, "scale": self.lsb, "breakpoints": list(self.breakpoints),
                "code_breaks": list(self.code_breaks),
                "physical": "offset + lsb * code; the warp maps the code to the uniform core's (manifest warp)"}


class WarpedFixedPointModel:
    """Bit-true model of a power-of-two non-uniform PWAS: input quantisation, warp, uniform core.

    Parameters
    ----------
    grid : Grid
        With breakpoints whose cells are power-of-two multiples of one base step in every
        dimension (a uniform dimension counts: all ``e_k = 0``).
    weights : ndarray, shape (N,) or (N, nz)
    input_bits : int
        ``B_in``, the width in bits of the inputs ``q`` (default 12).
    input_fill : float
        Largest fraction of the input code range the domain takes (default 0.9); also the fill of
        the core's ``u`` codes.
    **core_options
        Weight / output formats, rounding, names, ``reference_error``: as
        :class:`~pwas_hdl.fixedpoint.bittrue.FixedPointModel` (``input_scale`` must stay ``pow2``).

    Attributes
    ----------
    warps : list of Pow2Warp
    core : FixedPointModel
        The uniform core on the unit grid, ``input_bits = W``.
    lsb, offset : ndarray, shape (n,)
        ``x = offset + lsb * q`` (physical units).
    inputs : list of WarpInputFormat
        The input code format of every dimension.
    error_bound : float
        The core's (the warp is exact).

    The model has the interface of a :class:`~pwas_hdl.fixedpoint.bittrue.FixedPointModel` that
    ``generate``, the manifest and ``simulate`` use (``evaluate``, ``reference``, ``trace``,
    ``quantize_inputs``, ``signal_input_formats``, ``to_dict``, ``lo_codes`` = ``B_0``, and the
    core's formats, memory and bound: ``output_format``, ``weight_format``, ``widths``, ...).
    """

    def __init__(self, grid: Grid, weights: np.ndarray, *, input_bits: int = 12, input_fill: float = 0.9, **core_options: Any):
        from pwas_hdl.fixedpoint.bittrue import FixedPointModel

        if core_options.get("input_scale", "pow2") not in ("pow2", None):
            raise InputError("the power-of-two warp feeds a pow2 core: --input-scale must be 'pow2'")
        core_options.pop("input_scale", None)
        if not (isinstance(input_bits, (int, np.integer)) and 2 <= input_bits <= 32):
            raise InputError(f"--input-bits must be an integer in 2..32, got {input_bits!r}")
        if not (0 < input_fill <= 1):
            raise InputError(f"--input-fill must be in (0, 1], got {input_fill!r}")
        self.grid = grid
        self.n = grid.n
        self.input_bits = int(input_bits)
        self.input_fill = float(input_fill)
        limit = min(input_fill * 2.0**input_bits, 2**input_bits - 1)
        cells, lsb, offset, cuts = [], [], [], []
        for j in range(grid.n):
            b = grid.breakpoints[j] if grid.breakpoints is not None and grid.breakpoints[j] is not None else \
                np.linspace(grid.lo[j], grid.hi[j], int(grid.partitions[j]) + 1)
            got = pow2_exponents(b)
            if got is None:
                raise InputError(f"the cells of dimension {j} are not power-of-two multiples of one base step; "
                                 "the warp needs --breakpoints quantile-pow2 (or a file with such cells)")
            e, h0 = got
            e = e - e.min()
            s = int(np.sum(1 << e))
            f0 = math.floor(math.log2(limit / s)) if limit >= s else -1
            while f0 >= 0 and s << f0 > limit:
                f0 -= 1
            if f0 < 0:
                raise InputError(f"dimension {j} spans {s} base steps: {input_bits}-bit inputs cannot give each one a code; "
                                 f"use --input-bits {int(s).bit_length() + 1} or more (input_bits)")
            lo_in = -((s << f0) + 1) // 2
            breaks = [lo_in] + [lo_in + (int(c) << f0) for c in np.cumsum(1 << e)]
            cells.append((tuple(int(v) for v in breaks), tuple(int(v) for v in e), f0))
            lsb.append((b[-1] - b[0]) / (s << f0))
            offset.append(b[0] - lo_in * lsb[-1])
            cuts.append(tuple(float(v) for v in b))
        self.lsb, self.offset = np.array(lsb), np.array(offset)
        self.inputs = [WarpInputFormat(self.input_bits, float(grid.lo[j]), float(grid.hi[j]), int(grid.partitions[j]),
                                       float(lsb[j]), float(offset[j]), br[0], br[-1], cuts[j], br)
                       for j, (br, _e, _f0) in enumerate(cells)]
        parts = grid.partitions
        unit = Grid(np.zeros(grid.n), parts.astype(float), parts)
        need = [f0 + max(e) for _, e, f0 in cells]
        width = max(int((int(p) << f) + 1).bit_length() + 1 for p, f in zip(parts, need))
        while True:
            core = FixedPointModel(unit, weights, input_bits=width, input_fill=input_fill, **core_options)
            if all(fj >= nd for fj, nd in zip(core.frac_bits, need)):
                break
            width += 1
        self.core = core
        self.warps = [Pow2Warp(self.input_bits, br, e, f0, int(core.frac_bits[j]), int(core.lo_codes[j]), width)
                      for j, (br, e, f0) in enumerate(cells)]
        for w in self.warps:  # the below / above codes are representable (input_fill < 1 leaves room)
            hi_code = w.lo_u + (w.p << w.frac) + 1
            if w.lo_u - 1 < -(1 << (width - 1)) or hi_code > (1 << (width - 1)) - 1:
                raise InputError("input_fill must leave room for the out-of-range codes of the warp: use input_fill < 1")
        self.error_bound = core.error_bound
        self.nz = core.nz
        self.target_names = core.target_names
        self.regressor_names = core.regressor_names
        self.regressor_signals = core.regressor_signals

    # ------------------------------------------------------------------ the core's formats (a FixedPointModel's interface)
    #: attributes of the uniform core that are the warped model's own (formats, memory, bound)
    _CORE_ATTRIBUTES = ("output_format", "output_port", "weight_format", "weight_codes", "n_weights_saturated",
                        "weight_error_max", "error_bound_lsb", "error_bound_weight", "error_bound_output",
                        "output_may_saturate", "widths", "F", "shift", "rounding", "overflow", "layout", "rom",
                        "weights", "reference_error", "reference_error_source")

    def __getattr__(self, name: str):
        core = self.__dict__.get("core")
        if core is not None and name in WarpedFixedPointModel._CORE_ATTRIBUTES:
            return getattr(core, name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def lo_codes(self) -> tuple[int, ...]:
        """``B_0`` per dimension: the input code of the domain's lower bound."""
        return tuple(f.lo_code for f in self.inputs)

    @property
    def frac_bits(self) -> tuple[int, ...]:
        """``F_j`` of the uniform core behind the warp (one core cell = ``2**F_j`` codes of ``u``)."""
        return tuple(self.core.frac_bits)

    def to_physical_output(self, out_codes: ArrayLike) -> np.ndarray:
        """Physical output values (the core's output format).

        Parameters
        ----------
        out_codes : array_like of int, shape (m, nz)
            Output codes, as :meth:`evaluate` returns them.

        Returns
        -------
        ndarray of float, shape (m, nz)
            Physical target units.
        """
        return self.core.to_physical_output(out_codes)

    def reference(self, q: ArrayLike) -> np.ndarray:
        """Float model (unquantised weights) at the physical inputs the codes ``q`` represent, shape (m, nz).

        The warp is exact, so this is the uniform core's reference at the warped codes: the
        non-uniform PWAS of the fit at ``represented_inputs(q)`` (clamped to the domain).

        Parameters
        ----------
        q : array_like of int, shape (m, n) or (n,)
            Input codes inside the ``B_in``-bit range.

        Returns
        -------
        ndarray of float, shape (m, nz)
            Physical target units.

        Raises
        ------
        InputError
            ``q`` has not ``n`` columns or a code outside the ``B_in``-bit range.
        """
        return self.core.reference(self.warp(q))

    def trace(self, q: ArrayLike) -> dict[str, np.ndarray]:
        """The core's trace (:meth:`FixedPointModel.trace`) at the warped codes, with ``q`` the
        input codes and ``u`` (m, n) the warped ones.

        Parameters
        ----------
        q : array_like of int, shape (m, n) or (n,)
            Input codes inside the ``B_in``-bit range.

        Returns
        -------
        dict of str to ndarray
            The stages of :meth:`FixedPointModel.trace` (its ``t``, ``cell``, ... are those of
            ``u``), with ``q`` the input codes (m, n) and ``u`` the warped codes (m, n).
        """
        qa = np.atleast_2d(np.asarray(q, dtype=np.int64))
        u = self.warp(qa)
        tr = self.core.trace(u)
        tr["u"], tr["q"] = u, qa
        return tr

    def signal_input_formats(self) -> dict[str, WarpInputFormat]:
        """The input format of each signal (the sensor top feeds one code to all its lags).

        Returns
        -------
        dict of str to WarpInputFormat
            Signal name -> the format of its lags, in the order of first appearance.

        Raises
        ------
        InputError
            Two lags of one signal are quantised differently (other domains or another number of
            base steps): the lag bank cannot feed them one code.
        """
        res: dict[str, WarpInputFormat] = {}
        for j, (sig, _lag) in enumerate(self.regressor_signals):
            f = self.inputs[j]
            if sig in res and res[sig] != f:
                raise InputError(
                    f"the lags of signal {sig!r} need different input codes (dimension {j}: lsb {f.lsb!r} on [{f.lo}, {f.hi}], "
                    f"{f.bits}-bit codes {f.lo_code}..{f.hi_code}); the sensor top feeds one code per signal to all its lags, "
                    "so their breakpoints need the same domain and the same number of base steps (generate --design core "
                    "takes one code per regressor)"
                )
            res.setdefault(sig, f)
        return res

    def warp_info(self) -> dict[str, Any]:
        """The manifest's ``warp`` entry without the hardware keys (bit-true facts of every dimension).

        Returns
        -------
        dict
            ``kind`` (``"pow2"``), ``input_bits``, ``core_input_bits`` (``W``), ``dimensions``
            (regressor name, breakpoints and :meth:`Pow2Warp.to_dict` of each), the ``rule`` as
            text and ``bit_true`` (this class).
        """
        return {
            "kind": "pow2",
            "input_bits": self.input_bits,
            "core_input_bits": int(self.warps[0].width),
            "dimensions": [{"regressor": nm, "breakpoints": list(f.breakpoints), **w.to_dict()}
                           for nm, f, w in zip(self.regressor_names, self.inputs, self.warps)],
            "rule": "B_k <= q < B_(k+1): u = lo_u + k 2**F + ((q - B_k) << shifts[k]); q == B_p: lo_u + p 2**F; "
                    "q < B_0: lo_u - 1; q > B_p: lo_u + p 2**F + 1 (the core clamps and flags both)",
            "bit_true": "pwas_hdl.fixedpoint.warp.WarpedFixedPointModel",
        }

    def to_dict(self) -> dict[str, Any]:
        """Everything the manifest needs (as :meth:`FixedPointModel.to_dict`): the core's formats
        with the warped inputs, plus ``warp``.

        Returns
        -------
        dict
            The core's :meth:`FixedPointModel.to_dict` with ``inputs`` (one
            :meth:`WarpInputFormat.to_dict` per regressor, with ``name``, ``signal``, ``lag``),
            ``signals`` (per signal, or None when the lags of a signal differ) and ``warp``
            (:meth:`warp_info`).
        """
        d = self.core.to_dict()
        try:
            signals = {k: v.to_dict() for k, v in self.signal_input_formats().items()}
        except InputError:
            signals = None
        d["inputs"] = [{"name": nm, "signal": sig, "lag": lag, **f.to_dict()}
                       for nm, (sig, lag), f in zip(self.regressor_names, self.regressor_signals, self.inputs)]
        d["signals"] = signals
        d["warp"] = self.warp_info()
        return d

    @classmethod
    def from_sensor(cls, sensor: PWASVirtualSensor, **options: Any) -> "WarpedFixedPointModel":
        """The warped bit-true model of a fitted sensor with power-of-two breakpoints.

        Parameters
        ----------
        sensor : PWASVirtualSensor
            Fitted, with a grid whose cells are power-of-two multiples of one base step
            (``breakpoints="quantile-pow2"``).
        **options
            The keyword options of the constructor; regressor and target names default to the
            sensor's, ``reference_error`` to the largest finite positive training RMSE.

        Returns
        -------
        WarpedFixedPointModel

        Raises
        ------
        InputError
            The cells are not power-of-two multiples, or the formats are impossible.
        """
        from pwas_hdl.fixedpoint.model_setup import sensor_names

        names, signals, tgts = sensor_names(sensor)  # past estimates (fit --mz): the signals <target>_hat
        options.setdefault("regressor_names", names)
        options.setdefault("regressor_signals", signals)
        options.setdefault("target_names", tgts)
        from_rmse = "reference_error" not in options
        if from_rmse:
            rmse = np.asarray(getattr(sensor, "train_rmse_", []), dtype=float).reshape(-1)
            rmse = rmse[np.isfinite(rmse) & (rmse > 0)]
            options["reference_error"] = float(rmse.max()) if rmse.size else None
        model = cls(sensor.grid_, sensor.weights_, **options)
        if from_rmse and options["reference_error"] is not None:
            model.core.reference_error_source = "train_rmse"
        return model

    # ------------------------------------------------------------------ integer path
    @property
    def code_range(self) -> tuple[int, int]:
        """Smallest and largest signed ``B_in``-bit input code."""
        return -(1 << (self.input_bits - 1)), (1 << (self.input_bits - 1)) - 1

    def quantize_inputs(self, x: ArrayLike, return_saturated: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Input codes of physical points (half up, saturated to ``B_in`` bits), shape (m, n).

        Parameters
        ----------
        x : array_like of float, shape (m, n) or (n,)
            Physical regressor values.
        return_saturated : bool
            Also return a bool (m,) mask of the rows where some value saturated the code range (as
            :meth:`FixedPointModel.quantize_inputs`).

        Returns
        -------
        q : ndarray of int64, shape (m, n)
            Input codes.
        saturated : ndarray of bool, shape (m,)
            Only with ``return_saturated``.

        Raises
        ------
        InputError
            ``x`` has not ``n`` columns, or contains NaN.
        """
        xa = np.atleast_2d(np.asarray(x, dtype=float))
        if xa.shape[1] != self.n:
            raise InputError(f"inputs have {xa.shape[1]} columns, the model has n = {self.n}")
        q = np.empty(xa.shape, dtype=np.int64)
        sat = np.zeros(xa.shape, dtype=bool)
        for j, f in enumerate(self.inputs):
            q[:, j], sat[:, j] = f.quantize(xa[:, j], return_saturated=True)
        return (q, sat.any(axis=1)) if return_saturated else q

    def represented_inputs(self, q: ArrayLike) -> np.ndarray:
        """Physical values of input codes, shape (m, n).

        Parameters
        ----------
        q : array_like of int, shape (m, n) or (n,)
            Input codes (not checked).

        Returns
        -------
        ndarray of float, shape (m, n)
            ``offset + lsb * q``, physical units (not clamped to the domain).
        """
        return self.offset + self.lsb * np.atleast_2d(np.asarray(q, dtype=np.int64))

    def warp(self, q: ArrayLike) -> np.ndarray:
        """``u`` codes of the core, shape (m, n).

        Parameters
        ----------
        q : array_like of int, shape (m, n) or (n,)
            Input codes inside the ``B_in``-bit range.

        Returns
        -------
        ndarray of int64, shape (m, n)
            The warped codes (:meth:`Pow2Warp.apply` per dimension).

        Raises
        ------
        InputError
            ``q`` has not ``n`` columns or a code outside the ``B_in``-bit range.
        """
        qa = np.atleast_2d(np.asarray(q, dtype=np.int64))
        lo, hi = self.code_range
        if qa.shape[1] != self.n or qa.min(initial=lo) < lo or qa.max(initial=hi) > hi:
            raise InputError(f"input codes must have {self.n} columns within the signed {self.input_bits}-bit range")
        return np.stack([w.apply(qa[:, j]) for j, w in enumerate(self.warps)], axis=1)

    def evaluate(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Output codes (m, nz) and out-of-range flags (m,) for input codes ``q`` (m, n).

        Parameters
        ----------
        q : array_like of int, shape (m, n) or (n,)
            Input codes inside the ``B_in``-bit range.

        Returns
        -------
        out : ndarray of int64, shape (m, nz)
            Output codes (the core's output format).
        out_of_range : ndarray of bool, shape (m,)
            True where some input was outside the domain.

        Raises
        ------
        InputError
            ``q`` has not ``n`` columns or a code outside the ``B_in``-bit range.
        """
        return self.core.evaluate(self.warp(q))

    def evaluate_one(self, q: Sequence[int]) -> tuple[tuple[int, ...], bool]:
        """:meth:`evaluate` of one row of input codes, in Python integers (the recurrence's step):
        the warps (:meth:`Pow2Warp.apply_one`), then the core's
        :meth:`~pwas_hdl.fixedpoint.bittrue.FixedPointModel.evaluate_one`.

        Parameters
        ----------
        q : sequence of int, length n
            Input codes inside the ``B_in``-bit range (not checked).

        Returns
        -------
        out : tuple of int, length nz
        out_of_range : bool
        """
        return self.core.evaluate_one([w.apply_one(v) for w, v in zip(self.warps, q)])

    def check_codes(self, q: ArrayLike) -> None:
        """Refuse input codes outside the ``B_in``-bit range (as :meth:`evaluate` does).

        Parameters
        ----------
        q : array_like of int, shape (m, n)

        Raises
        ------
        InputError
        """
        self.warp(q)

    def predict(self, x: ArrayLike, return_flags: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Physical outputs for physical inputs (quantised first), shape (m, nz).

        Parameters
        ----------
        x : array_like of float, shape (m, n) or (n,)
            Physical regressor values.
        return_flags : bool
            Also return the flags below (as :meth:`FixedPointModel.predict`).

        Returns
        -------
        zhat : ndarray of float, shape (m, nz)
            Physical target units.
        flags : ndarray of bool, shape (m,)
            Only with ``return_flags``: out of the domain or input saturation.
        """
        q, sat = self.quantize_inputs(x, return_saturated=True)
        out, oor = self.evaluate(q)
        z = self.core.to_physical_output(out)
        return (z, oor | sat) if return_flags else z

    def input_port_format(self, j: int) -> dict[str, Any]:
        """The manifest ``format`` of input field ``j``: ``s<B_in>.0`` with ``physical = offset_j + lsb_j * code``.

        Parameters
        ----------
        j : int
            Regressor dimension, ``0 <= j < n``.

        Returns
        -------
        dict
            :meth:`~pwas_hdl.fixedpoint.formats.PortFormat.to_dict` of that format.
        """
        from pwas_hdl.fixedpoint.formats import FixedFormat, PortFormat, SignalScaling

        return PortFormat(FixedFormat(self.input_bits, 0, True, "half_up", "saturate"),
                          SignalScaling(float(self.lsb[j]), float(self.offset[j]))).to_dict()

    def summary(self) -> dict[str, Any]:
        """A short JSON-ready description of the input side.

        Returns
        -------
        dict
            ``input_bits``, ``input_fill``, ``lsb`` and ``offset`` (lists of ``n``, physical
            units per code and of code 0), ``warps`` (:meth:`Pow2Warp.to_dict` of each) and
            ``core_input_bits`` (``W``).
        """
        return {"input_bits": self.input_bits, "input_fill": self.input_fill, "lsb": self.lsb.tolist(),
                "offset": self.offset.tolist(), "warps": [w.to_dict() for w in self.warps], "core_input_bits": self.warps[0].width}
