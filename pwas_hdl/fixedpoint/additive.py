"""Bit-true model of an additive PWAS sensor (issue 15): the parts' cores, summed before one rounding.

An additive sensor is ``f(x) = sum_i f_i(x_{S_i})`` (:mod:`pwas_hdl.fit.additive`). Its circuit is
one PWAS core per part (:class:`~pwas_hdl.fixedpoint.bittrue.FixedPointModel`, architecture B, on
the part's grid) with the output rounding left out, and one adder + rounding behind them:

1. Inputs: one format per regressor dimension, from the shared domain box (as the full model:
   ``grid_input_formats`` of ``lo, hi, p``), so a regressor has the same code in every part; part
   ``i`` reads the codes of its dimensions ``q[:, S_i]``. ``F = max_j F_j`` over all dimensions,
   ``F_i`` over ``S_i``.
2. Part ``i``: ``acc_i`` exactly as :meth:`FixedPointModel.trace` (Kuhn location, banked memory,
   ``mu``-weighted sum of its ``|S_i| + 1`` vertex weights), in units of ``2**-(F_i + Fw)``. All parts
   share one weight format ``s<B_w>.<Fw>`` (``B_w`` the widest part's need).
3. ``acc = sum_i acc_i << (F - F_i)`` (exact: no bit is dropped before the single rounding), then
   ``sh = F + Fw - Fo``, ``acc_rounded = (acc + 2**(sh-1)) >> sh`` (half up) or ``acc >> sh``
   (truncate), ``out = clip(acc_rounded, -2**(B_out-1), 2**(B_out-1) - 1)``. ``out_of_range`` is the OR
   of the parts' flags (a regressor in no part does not affect the estimate or the flag).

Default formats: ``Fw`` from the noise budget of :mod:`pwas_hdl.fixedpoint.bittrue` with ``k`` weight
roundings in the sum: the largest power-of-two ``lsb_w`` with
``sqrt((k + 1/4) lsb_w**2 / 12) <= NOISE_BUDGET * ref`` (``k = 1`` is the full model's rule);
``Fo = Fw + 1``; ``B_out`` the fewest bits such that no output saturates
(``|f| <= sum_i max |w_q,i|``).

Error bound (against the float additive model with unquantised weights at the represented input,
:meth:`AdditiveFixedPointModel.reference`): every part's ``mu`` are exact and sum to 1, so part
``i`` errs by at most its weight-rounding bound ``e_w,i`` (``lsb_w / 2`` half up, ``lsb_w``
truncate, or ``max |w - w_q|`` of the part if weights saturated), and the sum is rounded once::

    |out * 2**-Fo - f(x_q)| <= sum_i e_w,i + e_out

(``e_out`` as in the full model). The bound is attained up to the output rounding when every
part's weight errors have one sign at the vertices a point uses.
"""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
from numpy.typing import ArrayLike

from pwas_hdl.errors import InputError, option_text
from pwas_hdl.fixedpoint.bittrue import MAX_DATAPATH_BITS, NOISE_BUDGET, FixedPointModel, _py_shift_round, default_output_frac
from pwas_hdl.fixedpoint.formats import FixedFormat, PortFormat, SignalScaling, grid_input_formats, shift_round, signed_bits_needed
from pwas_hdl.fixedpoint.model_setup import input_code_arrays, model_names, output_reference, weight_matrix

if TYPE_CHECKING:
    from pwas_hdl.fit.additive import AdditiveGrid
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

__all__ = ["AdditiveFixedPointModel", "additive_weight_frac"]


def additive_weight_frac(ref: float, n_parts: int, budget: float = NOISE_BUDGET) -> int:
    """Default ``Fw`` of an additive model with ``n_parts`` weight roundings in its sum.

    The largest power-of-two ``lsb_w`` with ``sqrt((n_parts + 1/4) lsb_w**2 / 12) <= budget * ref``
    (uniform, independent rounding errors; output lsb = half the weight lsb); ``n_parts = 1`` gives
    :func:`pwas_hdl.fixedpoint.bittrue.default_weight_frac`.

    Parameters
    ----------
    ref : float
        The reference error, physical target units (> 0; the sensor's training RMSE).
    n_parts : int
        Number of parts ``k`` (weight roundings summed).
    budget : float
        Fraction of ``ref`` the quantisation noise may take (default :data:`NOISE_BUDGET`).

    Returns
    -------
    int
        ``Fw``, weight fraction bits (weight LSB ``2**-Fw`` physical units; may be negative).

    Raises
    ------
    InputError
        ``ref`` is not a positive finite number.
    """
    if not (math.isfinite(ref) and ref > 0):
        raise InputError(f"reference error must be a positive number, got {ref!r}")
    limit = budget * ref * math.sqrt(12.0 / (n_parts + 0.25))
    return -(math.frexp(limit)[1] - 1)


class AdditiveFixedPointModel(FixedPointModel):
    """Bit-true model of an additive sensor: one :class:`FixedPointModel` per part, summed exactly.

    It has no one-sample path (``evaluate_one`` is None: the plain model's would read one grid);
    :class:`~pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel` then runs :meth:`evaluate`.

    The input side (formats, :meth:`quantize_inputs`, :meth:`represented_inputs`,
    :meth:`signal_input_formats`, :meth:`predict`) is that of :class:`FixedPointModel` on all ``n``
    regressors; :meth:`evaluate`, :meth:`trace` and :meth:`reference` are the additive circuit.

    Parameters
    ----------
    grid : pwas_hdl.fit.additive.AdditiveGrid
        The parts' grids on the shared domain box (``PWASVirtualSensor.grid_`` of an additive sensor).
    weights : ndarray, shape (sum_i N_i,) or (sum_i N_i, nz)
        Stacked float weights (``PWASVirtualSensor.weights_`` of an additive sensor).
    input_bits, input_fill, input_scale, weight_bits, weight_frac, output_bits, output_frac
        As :class:`FixedPointModel` (widths ``*_bits`` and fraction bits ``*_frac`` in bits); the
        weight format is common to all parts and the output format is that of the sum.
    overflow, rounding, reference_error, layout, regressor_names, regressor_signals, target_names
        As :class:`FixedPointModel`.

    Attributes
    ----------
    parts : list of FixedPointModel
        Part ``i`` on ``grid.parts[i]`` (its own output format is exact, ``Fo_i = Fw + F_i``: only its
        ``acc`` is used).
    subsets : tuple of tuple of int
    align : list of int
        ``F - F_i``: left shift of part ``i``'s accumulator before the sum.
    weight_codes : ndarray (sum_i N_i, nz), int64
        Stacked weight codes.
    """

    #: no one-sample path (the plain model's evaluate_one reads one grid's strides)
    evaluate_one = None

    def __init__(
        self,
        grid: "AdditiveGrid",
        weights: np.ndarray,
        *,
        input_bits: int = 12,
        input_fill: float = 0.9,
        input_scale: str = "pow2",
        weight_bits: int | None = None,
        weight_frac: int | None = None,
        output_bits: int | None = None,
        output_frac: int | None = None,
        overflow: str = "error",
        rounding: str = "half_up",
        reference_error: float | None = None,
        layout: str = "banked",
        regressor_names: Sequence[str] | None = None,
        regressor_signals: Sequence[tuple[str, int]] | None = None,
        target_names: Sequence[str] | None = None,
    ):
        from pwas_hdl.fit.additive import AdditiveGrid

        if not isinstance(grid, AdditiveGrid):
            raise TypeError(f"grid must be a pwas_hdl.fit.additive.AdditiveGrid, got {type(grid).__name__}")
        w = weight_matrix(weights, grid.n_vertices)
        for nm, v in (("weight_bits", weight_bits), ("weight_frac", weight_frac), ("output_bits", output_bits), ("output_frac", output_frac)):
            if v is not None and (not isinstance(v, (int, np.integer)) or isinstance(v, bool)):
                raise InputError(f"{nm} must be an integer or None, got {v!r}")
        self.grid = grid
        self.subsets = grid.subsets
        self.n = grid.n
        self.nz = int(w.shape[1])
        self.weights = w
        self.rounding = rounding
        self.overflow = overflow
        self.regressor_names, self.regressor_signals, self.target_names = model_names(
            self.n, self.nz, regressor_names, regressor_signals, target_names)

        # ---- inputs: one format per regressor of the shared box (what the parts see too)
        self.inputs = grid_input_formats(grid.lo, grid.hi, grid.partitions, input_bits, input_fill, input_scale)
        self.input_bits, self.input_fill, self.input_scale = int(input_bits), float(input_fill), str(input_scale)
        self.F = max(f.frac for f in self.inputs)
        self._lo_code, self._fj, self._span, self._kmul, self._rsh, self._qmin, self._qmax = input_code_arrays(self.inputs)

        # ---- the output lsb from the reference error, with k weight roundings in the sum
        k = grid.n_parts
        ref, ref_src = output_reference(reference_error, w)
        self.reference_error, self.reference_error_source = ref, ref_src
        fw = int(weight_frac) if weight_frac is not None else additive_weight_frac(ref, k)
        fo = int(output_frac) if output_frac is not None else default_output_frac(fw, self.F)
        sh = self.F + fw - fo
        if sh < 0:
            raise InputError(
                f"{option_text('output_frac')} = {fo} is finer than the exact sum (F + weight_frac = {self.F} + {fw} = "
                f"{self.F + fw}); use --output-frac <= {self.F + fw}"
            )
        self.shift = sh

        # ---- the parts: one weight format for all (the widest need unless weight_bits is given)
        blocks = grid.split_weights(w)

        def part_models(bits: int | None) -> list[FixedPointModel]:
            out = []
            for s, g, wb in zip(self.subsets, grid.parts, blocks):
                f_i = max(self.inputs[j].frac for j in s)
                out.append(FixedPointModel(
                    g, wb, input_bits=input_bits, input_fill=input_fill, input_scale=input_scale, weight_bits=bits,
                    weight_frac=fw, output_frac=fw + f_i, overflow=overflow, rounding=rounding, reference_error=ref,
                    layout=layout, regressor_names=[self.regressor_names[j] for j in s],
                    regressor_signals=[self.regressor_signals[j] for j in s], target_names=self.target_names))
            return out

        with warnings.catch_warnings():
            if weight_bits is None:
                warnings.simplefilter("ignore", UserWarning)  # the exact outputs of the parts are never used
            parts = part_models(weight_bits)
        need = max(p.weight_format.bits for p in parts)
        if weight_bits is None and any(p.weight_format.bits != need for p in parts):
            parts = part_models(need)
        self.parts = parts
        self.align = [self.F - p.F for p in parts]
        self.weight_format = FixedFormat(parts[0].weight_format.bits, fw, True, rounding, overflow)
        self.weight_codes = np.concatenate([p.weight_codes for p in parts], axis=0)
        self.n_weights_saturated = int(sum(p.n_weights_saturated for p in parts))
        self.weight_error_max = float(max(p.weight_error_max for p in parts))

        # ---- output format of the sum
        lo_sum = sum(int(p.weight_codes.min()) << self.F for p in parts)
        hi_sum = sum(int(p.weight_codes.max()) << self.F for p in parts)
        self._out_reach = (_py_shift_round(lo_sum, sh, rounding), _py_shift_round(hi_sum, sh, rounding))
        if self._out_reach == (0, 0) and np.any(self.weight_codes):
            raise InputError(f"{option_text('output_frac')} = {fo} (LSB 2^{-fo}) rounds every output of the additive sensor to 0 "
                             f"(weights at --weight-frac {fw}); use a larger --output-frac (at most {self.F + fw}, the exact sum)")
        b_out = int(output_bits) if output_bits is not None else signed_bits_needed(list(self._out_reach))
        self.output_format = FixedFormat(b_out, fo, True, rounding, "saturate")
        self.output_port = PortFormat(self.output_format, SignalScaling(1.0, 0.0))
        self.output_may_saturate = not bool(np.all(self.output_format.fits(np.array(self._out_reach))))
        if self.output_may_saturate:
            warnings.warn(f"output format {self.output_format} cannot hold every reachable output of the sum (codes "
                          f"{self._out_reach[0]}..{self._out_reach[1]}); the error bound does not hold for saturated outputs", stacklevel=2)

        # ---- widths: the parts' accumulators (F_i + B_w + 1 bits), aligned and summed
        bw = self.weight_format.bits
        acc_bits = [p.widths["acc"] for p in parts]
        self.sum_bits = self.F + bw + 1 + max(0, (k - 1).bit_length())
        self.widths = {
            "q": self.input_bits,
            "t": self.input_bits + 1,
            "weight": bw,
            "part_acc": acc_bits,
            "sum": self.sum_bits,
            "out": self.output_format.bits,
        }
        if self.sum_bits > MAX_DATAPATH_BITS:
            raise InputError(f"the sum of the parts would need {self.sum_bits} bits (> {MAX_DATAPATH_BITS}); use fewer input or weight bits")
        self.layout = parts[0].layout

        # ---- error bound: every part's weight rounding, one output rounding
        lsb_o = self.output_format.lsb
        e_w = float(sum(p.error_bound_weight for p in parts))
        e_o = 0.0 if sh == 0 else (0.5 * lsb_o if rounding == "half_up" else (1.0 - 2.0**-sh) * lsb_o)
        self.error_bound_weight, self.error_bound_output = e_w, e_o
        self.error_bound = e_w + e_o
        self.error_bound_lsb = self.error_bound / lsb_o

    # ------------------------------------------------------------- construction
    @classmethod
    def from_sensor(cls, sensor: "PWASVirtualSensor", **overrides: Any) -> "AdditiveFixedPointModel":
        """Bit-true model of a fitted additive :class:`~pwas_hdl.fit.virtual_sensor.PWASVirtualSensor`
        (names and the reference error as :meth:`FixedPointModel.from_sensor`).

        Parameters
        ----------
        sensor : PWASVirtualSensor
            A fitted sensor with ``additive`` (``grid_`` an ``AdditiveGrid``, ``weights_`` stacked).
        **overrides
            Keyword arguments of :class:`AdditiveFixedPointModel` (``input_bits``, ``weight_frac``, ...).

        Returns
        -------
        AdditiveFixedPointModel
        """
        return super().from_sensor(sensor, **overrides)

    # ------------------------------------------------------------- datapath
    def _run(self, q, full: bool) -> dict:
        qa = self._check_codes(q)
        traces = [p.trace(qa[:, list(s)]) for p, s in zip(self.parts, self.subsets)]
        acc = sum(tr["acc"] << a for tr, a in zip(traces, self.align))
        oor = np.zeros(qa.shape[0], dtype=bool)
        for tr in traces:
            oor |= tr["out_of_range"]
        acc_r = shift_round(acc, self.shift, self.rounding)
        fo = self.output_format
        out = np.clip(acc_r, fo.min_code, fo.max_code)
        assert np.all(np.abs(acc) < (1 << (self.sum_bits - 1))), "the sum exceeds its declared width"
        res = {"out": out, "out_of_range": oor}
        if full:
            res.update(q=qa, parts=traces, part_acc=[tr["acc"] for tr in traces], acc=acc, acc_rounded=acc_r,
                       out_saturated=np.any(acc_r != out, axis=1))
        return res

    def trace(self, q: ArrayLike) -> dict:
        """Every stage of the additive datapath for input codes ``q``.

        Parameters
        ----------
        q : array_like of int, shape (m, n) or (n,)
            Signed input codes of all ``n`` regressors.

        Returns
        -------
        dict
            ``q`` (m, n); ``parts`` (one :meth:`FixedPointModel.trace` each, on ``q[:, S_i]``);
            ``part_acc`` (list of (m, nz)); the aligned sum ``acc``, ``acc_rounded`` and ``out``
            (m, nz); ``out_saturated`` and ``out_of_range`` (m,), bool.
        """
        return self._run(q, full=True)

    def reference(self, q: ArrayLike) -> np.ndarray:
        """Float additive model (unquantised weights) at the physical inputs the codes represent:
        the sum of the parts' :meth:`FixedPointModel.reference`.

        Parameters
        ----------
        q : array_like of int, shape (m, n) or (n,)
            Signed input codes inside the ``B_in``-bit range.

        Returns
        -------
        ndarray, shape (m, nz), float
            Physical target units.
        """
        qa = self._check_codes(q)
        return sum(p.reference(qa[:, list(s)]) for p, s in zip(self.parts, self.subsets))

    # ------------------------------------------------------------- reporting
    def to_dict(self) -> dict:
        """As :meth:`FixedPointModel.to_dict`, plus ``additive`` (the parts) and ``layout`` per part."""
        d = super().to_dict()
        d["layout"] = {"kind": self.layout.kind, "parts": [p.layout.to_dict() for p in self.parts]}
        bound = d.pop("error_bound")
        ref = d.pop("reference_error")
        d["additive"] = {
            "parts": [
                {"regressors": [int(j) for j in s], "names": [self.regressor_names[j] for j in s],
                 "n_vertices": int(p.grid.n_vertices), "F": int(p.F), "align_shift": int(a),
                 "acc_bits": int(p.widths["acc"]), "weight_term": float(p.error_bound_weight)}
                for s, p, a in zip(self.subsets, self.parts, self.align)
            ],
            "sum": "acc = sum_i acc_i << align_shift_i (exact), then one rounding by shift and saturation to the output format",
        }
        d["error_bound"] = {**bound, "against": "float additive model (sum of the parts), unquantised weights, at the physical "
                                                 "input the code represents"}
        d["reference_error"] = ref
        return d

    def __repr__(self) -> str:
        return (f"AdditiveFixedPointModel(n={self.n}, parts={len(self.parts)}, nz={self.nz}, F={self.F}, "
                f"weights={self.weight_format}, output={self.output_format}, shift={self.shift}, "
                f"bound={self.error_bound_lsb:.3g} lsb)")
