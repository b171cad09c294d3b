"""Bit-true fixed-point model of the PWAS circuit ("architecture B"): THE specification of the RTL.

Every integer the RTL computes is computed here, with the same widths, the same rounding, the
same saturation and the same tie rule, in plain ``numpy.int64``. A mismatch between RTL and this
model is an RTL bug (or a spec change); :meth:`FixedPointModel.trace` returns every pipeline
stage so that a testbench can name the first stage that differs.

Formats (all decided from the data by default, every one overridable)
---------------------------------------------------------------------
Inputs, per regressor dimension ``j`` (:class:`~pwas_hdl.fixedpoint.formats.InputFormat`)
    Signed ``B_in``-bit codes ``q`` (default ``B_in = 12``); one grid cell is exactly ``2**F_j``
    codes, ``F_j`` the largest with ``p_j 2**F_j <= min(input_fill 2**B_in, 2**B_in - 1)``
    (``input_fill = 0.9``), ``lo_code_j = -((p_j * 2**F_j + 1) // 2)``; physical ``x = offset_j + lsb_j * q`` with
    ``lsb_j = h_j / 2**F_j``, ``offset_j = lo_j - lo_code_j * lsb_j``. All lags of one signal
    share ``lo, hi, p`` and so the same format (:meth:`FixedPointModel.signal_input_formats`).
    ``F = max_j F_j`` is the common fraction width.
Weights
    Signed ``B_w``-bit codes, physical weight ``= code * 2**-Fw`` (offset 0), one format for all
    targets. Default ``Fw`` from a quantisation-noise budget (:func:`default_weight_frac`): the
    weight lsb is the largest power of two such that the RMS noise of weight rounding plus output
    rounding (uniform errors, output lsb = half the weight lsb) stays within
    ``NOISE_BUDGET = 5 %`` of ``ref``, i.e. ``lsb_w <= 0.05 * ref * sqrt(12 / 1.25)``; added in
    quadrature to an estimation error of size ``ref`` that costs about 0.1 % of RMSEE.
    ``B_w`` = the fewest bits that hold every weight code.
    Overflow policy ``"error"`` (default: :class:`ValueError` naming the weight, its vertex,
    value, the format range and the bits needed) or ``"saturate"`` (with a
    :func:`warnings.warn`, the error bound then includes the saturation error).
Output
    Signed ``B_out``-bit codes, physical output ``= code * 2**-Fo``, one format for all targets.
    Default ``Fo = Fw + 1`` (output lsb = half the weight lsb), with ``ref`` = the training RMSE
    (max over targets) or, when unknown, the weight range ``(max w - min w) / 2**10``; ``B_out`` = the fewest bits such that no output can saturate
    (``|f| <= max |w_q|`` because the ``mu`` are a convex combination).
Rounding
    ``rounding="half_up"`` (default) or ``"truncate"`` applies to the weight quantisation and to
    the output shift. Input quantisation (:meth:`FixedPointModel.quantize_inputs`, done before
    the circuit) is always half up with saturation.

Datapath (one row of the pipeline; names are the keys of :meth:`FixedPointModel.trace`)
---------------------------------------------------------------------------------------
1. ``t = q - lo_code`` (``B_in + 1`` bits signed); ``t_clamped = clip(t, 0, p_j * 2**F_j)``;
   ``out_of_range`` = some ``t`` was clamped.
2. ``cell_j = min(t_clamped >> F_j, p_j - 1)``; ``frac_raw_j = t_clamped - cell_j * 2**F_j`` in
   ``[0, 2**F_j]``; aligned ``frac_j = frac_raw_j << (F - F_j)`` in ``[0, 2**F]`` (``F + 1`` bits).
3. ``rank, perm = Grid.order(frac)`` (descending, ties: lower dimension first);
   ``vertices = Grid.simplex_vertices(cell, perm)``;
   ``mu = Grid.barycentric(frac, perm, one=2**F)``: ``mu_0 = 2**F - frac_perm[0]``,
   ``mu_k = frac_perm[k-1] - frac_perm[k]``, ``mu_n = frac_perm[n-1]``; each in ``[0, 2**F]``
   (``F + 1`` bits unsigned), ``sum mu = 2**F`` exactly.
4. Memory (:mod:`pwas_hdl.fixedpoint.memory_layout`, banked by default): vertex ``k`` is read from
   ``bank[k] = (sum(cell) + k) mod (n+1)`` at ``addr[k]``; ``w[k]`` is the word read back from
   the ROM image (so the layout is part of what is checked).
5. ``products_k = mu_k * w_k`` (exact, ``(F+1) + B_w + 1`` bits signed);
   ``acc = sum_k products_k`` (exact, ``product_bits + ceil(log2(n+1))`` bits), added in the
   order of the RTL's adder tree (:mod:`pwas_hdl.fixedpoint.reduction` over the products in
   memory-bank order).
6. ``sh = F + Fw - Fo >= 0``; ``acc_rounded = (acc + 2**(sh-1)) >> sh`` (half up) or
   ``acc >> sh`` (truncate), arithmetic shift, no rounding when ``sh = 0``;
   ``out = clip(acc_rounded, -2**(B_out-1), 2**(B_out-1) - 1)``.

Error bound
-----------
Against the float model with the *unquantised* weights evaluated at the physical input the code
represents (:meth:`FixedPointModel.reference`): ``mu`` is exact and sums to 1, so

    ``|out * 2**-Fo - f(x_q)| <= e_w + e_out``

with ``e_w = lsb_w / 2`` (half up) or ``lsb_w`` (truncate) -- or ``max |w - w_q|`` if weights were
saturated -- and ``e_out = lsb_out / 2`` (half up), ``(1 - 2**-sh) * lsb_out`` (truncate), 0 when
``sh = 0``. It holds for every input code (out-of-domain ones are clamped, and compared with the
float model at the clamped point) unless the output saturates, which the default ``B_out``
rules out. ``error_bound`` is in physical units, ``error_bound_lsb`` in output LSBs.
"""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
from numpy.typing import ArrayLike

from pwas_hdl.errors import InputError, choice_text, option_text
from pwas_hdl.fixedpoint.formats import _MAX_ABS_FRAC
from pwas_hdl.fixedpoint.formats import (
    FixedFormat,
    InputFormat,
    PortFormat,
    SignalScaling,
    grid_input_formats,
    signed_bits_needed,
    shift_round,
)
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fixedpoint.memory_layout import make_layout
from pwas_hdl.fixedpoint.model_setup import input_code_arrays, model_names, output_reference, sensor_names, weight_matrix
from pwas_hdl.fixedpoint.reduction import tree_reduce

if TYPE_CHECKING:
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

__all__ = ["FixedPointModel", "MAX_DATAPATH_BITS", "TRACE_STAGES", "NOISE_BUDGET", "default_weight_frac"]

#: Widest intermediate the int64 model (and the generator) accepts.
MAX_DATAPATH_BITS = 62

#: Keys of :meth:`FixedPointModel.trace`, in pipeline order.
TRACE_STAGES = (
    "q",
    "t",
    "t_clamped",
    "out_of_range",
    "cell",
    "frac_raw",
    "frac",
    "rank",
    "perm",
    "vertices",
    "rot",
    "bank",
    "addr",
    "addr_by_bank",
    "mu",
    "w_by_bank",
    "w",
    "products",
    "acc",
    "acc_rounded",
    "out_saturated",
    "out",
)


#: RMS quantisation noise (weight + output rounding) allowed by the default formats, as a
#: fraction of the reference error (the training RMSE).
NOISE_BUDGET = 0.05


def default_weight_frac(ref: float, budget: float = NOISE_BUDGET) -> int:
    """Default weight fraction bits ``Fw`` for a reference error ``ref`` (physical units).

    With uniform rounding errors the weight term contributes at most ``lsb_w**2 / 12`` of variance
    (the ``mu`` are a convex combination) and the output rounding ``lsb_o**2 / 12`` with
    ``lsb_o = lsb_w / 2``; the largest power-of-two ``lsb_w`` with
    ``sqrt(1.25 * lsb_w**2 / 12) <= budget * ref`` is chosen, ``Fw = -log2(lsb_w)``.

    Parameters
    ----------
    ref : float
        The reference error, physical target units (> 0; the sensor's training RMSE).
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
    limit = budget * ref * math.sqrt(12.0 / 1.25)
    return -(math.frexp(limit)[1] - 1)


def default_output_frac(weight_frac: int, input_frac: int) -> int:
    """Default output fraction bits ``Fo`` for weight fraction ``Fw`` and input fraction ``F``.

    One bit finer than the weights (``lsb_o = lsb_w / 2``, as :func:`default_weight_frac` budgets),
    but never finer than the exact product ``F + Fw``: with ``F = 0`` (the fewest input bits) the
    output is then the exact product, with no rounding at all.
    """
    return min(int(weight_frac) + 1, int(input_frac) + int(weight_frac))


def _py_shift_round(a: int, sh: int, rounding: str) -> int:
    if sh == 0:
        return a
    return (a + (1 << (sh - 1))) >> sh if rounding == "half_up" else a >> sh


class FixedPointModel:
    """Bit-true model of the PWAS circuit for one grid and weight set.

    Parameters
    ----------
    grid : Grid
    weights : ndarray, shape (N,) or (N, nz)
        Float weights in vertex order (``PWASVirtualSensor.weights_``).
    input_bits : int
        Input code width ``B_in``, bits, sign included (default 12).
    input_fill : float
        Fraction of the input code range used by the domain, ``(0, 1]`` (default 0.9).
    input_scale : {"pow2", "exact"}
        ``"pow2"`` (default): one cell = ``2**F_j`` input codes, no arithmetic in front (a
        power-of-two ``p`` uses at most half the code range); ``"exact"``: the domain takes the
        whole ``input_fill`` of the code range for any ``p`` and the front end scales by a constant
        (:meth:`InputFormat.for_interval <pwas_hdl.fixedpoint.formats.InputFormat.for_interval>`).
    weight_bits : int, optional
        Weight code width ``B_w``, bits, sign included; default: the fewest bits that hold every
        weight code.
    weight_frac : int, optional
        Weight fraction bits ``Fw`` (weight LSB ``2**-Fw`` physical units; may be negative);
        default :func:`default_weight_frac` of ``reference_error`` (noise budget).
    output_bits : int, optional
        Output code width ``B_out``, bits, sign included; default: the fewest bits such that no
        output saturates.
    output_frac : int, optional
        Output fraction bits ``Fo`` (output LSB ``2**-Fo`` physical target units); default ``Fw + 1``.
    overflow : {"error", "saturate"}
        What to do with weights that do not fit ``weight_bits`` (default "error").
    rounding : {"half_up", "truncate"}
        Rounding of the weight quantisation and of the output shift.
    reference_error : float, optional
        The accuracy the output lsb is chosen against (``from_sensor`` passes the training
        RMSE). Default/invalid: ``(max w - min w) / 2**10`` (or 1.0 if all weights are equal).
    layout : {"banked", "replicated", "corner"}
        Weight memory layout (:mod:`pwas_hdl.fixedpoint.memory_layout`).
    regressor_names : sequence of str, optional
        Names of the ``n`` dimensions (default ``x0 ..``).
    regressor_signals : sequence of (str, int), optional
        ``(signal name, lag)`` per dimension (default: each dimension its own signal, lag 0).
    target_names : sequence of str, optional
        Names of the ``nz`` outputs (default ``z0 ..``).

    Attributes
    ----------
    grid : Grid
    n, nz : int
    weights : ndarray (N, nz), float -- the unquantised weights
    inputs : list of InputFormat, one per dimension
    F : int
        ``max_j F_j``.
    weight_format : FixedFormat
        ``s<B_w>.<Fw>``.
    output_format : FixedFormat
        ``s<B_out>.<Fo>``, saturating.
    output_port : PortFormat
        Output format with identity scaling.
    shift : int
        ``sh = F + Fw - Fo``.
    weight_codes : ndarray (N, nz), int64
    n_weights_saturated : int
    weight_error_max : float
        ``max |w - w_q|`` over all weights (physical).
    layout : BankedLayout or ReplicatedLayout
    rom : ndarray (n_banks, depth, nz), int64 -- the memory image
    widths : dict
        Bit widths of every datapath signal (see :attr:`widths`).
    output_may_saturate : bool
        True when a user-given ``output_bits`` is too narrow for some reachable output.
    error_bound : float
        Physical units.
    error_bound_lsb : float
        Output LSBs.
    """

    def __init__(
        self,
        grid: Grid,
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
        if not isinstance(grid, Grid):
            raise TypeError(f"grid must be a pwas_hdl.fit.geometry.Grid, got {type(grid).__name__}")
        if getattr(grid, "breakpoints", None) is not None:  # the input formats below assume equal cells
            raise InputError("FixedPointModel needs a uniform grid; of a model fitted with --breakpoints (non-uniform "
                             "partition) build pwas_hdl.fixedpoint.warp.WarpedFixedPointModel, as generate and simulate do")
        w = weight_matrix(weights, grid.n_vertices)
        if overflow not in ("error", "saturate"):
            raise InputError(choice_text(option_text("overflow"), ("error", "saturate"), overflow))
        if rounding not in ("half_up", "truncate"):
            raise InputError(choice_text(option_text("rounding"), ("half_up", "truncate"), rounding))
        for nm, v in (("weight_bits", weight_bits), ("weight_frac", weight_frac), ("output_bits", output_bits), ("output_frac", output_frac)):
            if v is not None and (not isinstance(v, (int, np.integer)) or isinstance(v, bool)):
                raise InputError(f"{option_text(nm)} must be an integer or None, got {v!r}")
            if nm.endswith("_bits") and v is not None and not 1 <= v <= 64:  # before any format is built with it
                raise InputError(f"{option_text(nm)} = {v}: need an integer in [1, 64] (codes are held in numpy.int64)")
        self.grid = grid
        self.n = grid.n
        self.nz = int(w.shape[1])
        self.weights = w
        self.rounding = rounding
        self.overflow = overflow

        # ---- names
        self.regressor_names, self.regressor_signals, self.target_names = model_names(
            self.n, self.nz, regressor_names, regressor_signals, target_names)

        # ---- inputs
        self.inputs: list[InputFormat] = grid_input_formats(grid.lo, grid.hi, grid.partitions, input_bits, input_fill, input_scale)
        self.input_bits = int(input_bits)
        self.input_fill = float(input_fill)
        self.input_scale = str(input_scale)
        self.F = max(f.frac for f in self.inputs)
        # _span: the clamp range, input codes
        self._lo_code, self._fj, self._span, self._kmul, self._rsh, self._qmin, self._qmax = input_code_arrays(self.inputs)

        # ---- output lsb from the reference error
        ref, ref_src = output_reference(reference_error, w)
        self.reference_error = ref
        self.reference_error_source = ref_src
        fw = int(weight_frac) if weight_frac is not None else default_weight_frac(ref)
        fo = int(output_frac) if output_frac is not None else default_output_frac(fw, self.F)
        for nm, v in (("weight_frac", fw), ("output_frac", fo)):
            if abs(v) > _MAX_ABS_FRAC:  # before the shifts below (1 << 10**20 never ends)
                if nm == "output_frac" and output_frac is None:  # the default, from the weight fraction bits
                    raise InputError(
                        f"{option_text('weight_frac')} = {fw} gives the default {option_text('output_frac')} = {v}, out of "
                        f"the supported range [-{_MAX_ABS_FRAC}, {_MAX_ABS_FRAC}]; use a smaller --weight-frac or give "
                        "--output-frac")
                if nm == "weight_frac" and weight_frac is None:  # the default, from the reference error
                    raise InputError(
                        f"the default {option_text('weight_frac')} = {v}, from the reference error {ref:.3g} "
                        f"({'the weight range / 2^10' if ref_src == 'weight_range' else 'the training RMSE or as given'}), is out of the "
                        f"supported range [-{_MAX_ABS_FRAC}, {_MAX_ABS_FRAC}]: the target's values are too "
                        f"{'small' if v > 0 else 'large'} for fixed point; rescale the target column (a unit of "
                        "sensible size) and fit again, or give --weight-frac")
                raise InputError(f"{option_text(nm)} = {v} is out of the supported range [-{_MAX_ABS_FRAC}, {_MAX_ABS_FRAC}]")
        sh = self.F + fw - fo
        if sh < 0:
            raise InputError(
                f"{option_text('output_frac')} = {fo} is finer than the exact product (F + weight_frac = {self.F} + {fw} = "
                f"{self.F + fw}); the output would need padding bits: use --output-frac <= {self.F + fw}"
            )
        self.shift = sh

        # ---- weights
        self.weight_codes, self.weight_format, self.n_weights_saturated = self._quantize_weights(w, weight_bits, fw)
        self.weight_error_max = float(np.max(np.abs(w - self.weight_format.to_float(self.weight_codes))))

        # ---- output format
        wmin, wmax = int(self.weight_codes.min()), int(self.weight_codes.max())
        self._out_reach = (_py_shift_round(wmin << self.F, sh, rounding), _py_shift_round(wmax << self.F, sh, rounding))
        if self._out_reach == (0, 0) and np.any(self.weight_codes):
            raise InputError(
                f"{option_text('output_frac')} = {fo} (LSB 2^{-fo}) rounds every output to 0 (weights reach {wmin}..{wmax} "
                f"codes at --weight-frac {fw}); use a larger --output-frac (e.g. {fw - max(abs(wmin), abs(wmax)).bit_length() + 1})"
            )
        b_out = int(output_bits) if output_bits is not None else signed_bits_needed(list(self._out_reach))
        if b_out > 64:  # the default width (a given --output-bits is checked against [1, 64] above)
            raise InputError(
                f"the outputs would need {b_out} bits at {option_text('output_frac')} = {fo}{'' if output_frac is not None else ' (the default)'}, "
                f"more than the 64 of a code; use a smaller --output-frac (at most {fo - (b_out - 64)}) or --weight-frac"
            )
        self.output_format = FixedFormat(b_out, fo, True, rounding, "saturate")
        self.output_port = PortFormat(self.output_format, SignalScaling(1.0, 0.0))
        self.output_may_saturate = not bool(np.all(self.output_format.fits(np.array(self._out_reach))))
        if self.output_may_saturate:
            warnings.warn(
                f"output format {self.output_format} cannot hold every reachable output (codes {self._out_reach[0]}"
                f"..{self._out_reach[1]}, {signed_bits_needed(list(self._out_reach))} bits needed): outputs may saturate "
                "and the error bound does not hold for saturated outputs",
                stacklevel=2,
            )

        # ---- widths
        pb = (self.F + 1) + self.weight_format.bits + 1
        self.widths = {
            "q": self.input_bits,
            "t": self.input_bits + 1,
            "cell": [max(1, int(p - 1).bit_length()) for p in grid.partitions],
            "frac_raw": [int(f) + 1 for f in self._fj],
            "frac": self.F + 1,
            "rank": max(1, (self.n - 1).bit_length()),
            "mu": self.F + 1,
            "weight": self.weight_format.bits,
            "product": pb,
            "acc": pb + self.n.bit_length(),  # + ceil(log2(n + 1))
            "out": self.output_format.bits,
        }
        if self.widths["acc"] > MAX_DATAPATH_BITS:
            raise InputError(
                f"the accumulator would need {self.widths['acc']} bits (> {MAX_DATAPATH_BITS}): "
                f"F = {self.F}, B_w = {self.weight_format.bits}; use fewer input bits (--input-bits) or weight bits "
                "(a smaller --weight-frac or --weight-bits)"
            )

        # ---- memory
        self.layout = make_layout(grid, layout)
        self.rom = self.layout.contents(self.weight_codes)

        # ---- error bound
        lsb_w, lsb_o = self.weight_format.lsb, self.output_format.lsb
        e_w = 0.5 * lsb_w if rounding == "half_up" else lsb_w
        if self.n_weights_saturated:
            e_w = max(e_w, self.weight_error_max)
        if sh == 0:
            e_o = 0.0
        else:
            e_o = 0.5 * lsb_o if rounding == "half_up" else (1.0 - 2.0**-sh) * lsb_o
        self.error_bound_weight = e_w
        self.error_bound_output = e_o
        self.error_bound = e_w + e_o
        self.error_bound_lsb = self.error_bound / lsb_o

    # ------------------------------------------------------------- per-dimension views
    @property
    def lo_codes(self) -> tuple[int, ...]:
        """``lo_code_j`` per dimension."""
        return tuple(f.lo_code for f in self.inputs)

    @property
    def frac_bits(self) -> tuple[int, ...]:
        """``F_j`` per dimension (one grid cell = ``2**F_j`` input codes)."""
        return tuple(f.frac for f in self.inputs)

    @property
    def input_lsb(self) -> np.ndarray:
        """Physical ``lsb_j`` per dimension."""
        return np.array([f.lsb for f in self.inputs])

    @property
    def input_offset(self) -> np.ndarray:
        """Physical ``offset_j`` per dimension (``x = offset_j + lsb_j * q``)."""
        return np.array([f.offset for f in self.inputs])

    # ------------------------------------------------------------- construction
    def _quantize_weights(self, w: np.ndarray, weight_bits: int | None, fw: int) -> tuple[np.ndarray, FixedFormat, int]:
        free = FixedFormat(64, fw, True, self.rounding, "saturate")
        codes_free, sat_free = free.quantize(w, return_saturated=True)
        if sat_free.any() or signed_bits_needed(codes_free) > 64:
            wtop = float(np.max(np.abs(w)))
            most = 62 - math.floor(math.log2(wtop)) if wtop > 0 and math.isfinite(wtop) else fw - 1  # wtop 2^most < 2^63
            raise InputError(f"{option_text('weight_frac')} = {fw} makes the weights too large for 64-bit codes (the largest "
                             f"|weight| is {wtop:.6g}); use fewer fraction bits (--weight-frac {min(most, fw - 1)} at most)")
        wmax = float(np.max(np.abs(w))) if w.size else 0.0
        if wmax > 0 and not np.any(codes_free):
            # a format whose LSB is above every weight: the design would compute 0 for every input
            least = math.ceil(-math.log2(wmax)) if math.isfinite(math.log2(wmax)) else fw
            raise InputError(
                f"{option_text('weight_frac')} = {fw} (LSB 2^{-fw}) rounds every weight to 0 (the largest |weight| is "
                f"{wmax:.6g}); use a larger --weight-frac (--weight-frac {least} keeps the largest weight)"
            )
        need = signed_bits_needed(codes_free)
        if weight_bits is None:
            return codes_free, FixedFormat(need, fw, True, self.rounding, self.overflow), 0
        fmt = FixedFormat(int(weight_bits), fw, True, self.rounding, self.overflow)
        codes, sat = FixedFormat(fmt.bits, fw, True, self.rounding, "saturate").quantize(w, return_saturated=True)
        if not sat.any():
            return codes, fmt, 0
        err = np.abs(w - fmt.to_float(codes))
        i, t = np.unravel_index(int(np.argmax(np.where(sat, err, -1.0))), w.shape)
        coords = tuple(int(c) for c in self.grid.vertex_coords(int(i)))
        what = f"weight {int(i)} (vertex {coords}) of target {self.target_names[t]!r} = {float(w[i, t])!r}"
        if self.overflow == "error":
            raise InputError(
                f"{what} does not fit the weight format {fmt} (range [{fmt.min_value!r}, {fmt.max_value!r}], "
                f"lsb {fmt.lsb!r}); {int(sat.sum())} weight(s) overflow, {need} bits are needed at {fw} fraction bits. "
                "Use --weight-bits (weight_bits) >= %d, fewer --weight-frac bits, or --overflow saturate" % need
            )
        warnings.warn(
            f"{int(sat.sum())} weight(s) saturated to the format {fmt} (range [{fmt.min_value!r}, {fmt.max_value!r}]); "
            f"the worst is {what}, error {float(err[i, t])!r}; {need} bits would avoid it. "
            "The error bound includes the saturation error",
            stacklevel=3,
        )
        return codes, fmt, int(sat.sum())

    @classmethod
    def from_sensor(cls, sensor: "PWASVirtualSensor", **overrides: Any) -> "FixedPointModel":
        """Bit-true model of a fitted :class:`~pwas_hdl.fit.virtual_sensor.PWASVirtualSensor`.

        The reference error for the default output lsb is the sensor's training RMSE (max over
        targets) unless ``reference_error`` is given. Names of regressors, signals and targets
        come from the sensor.

        Parameters
        ----------
        sensor : PWASVirtualSensor
            A fitted (or loaded) sensor with a uniform grid: its ``grid_`` and ``weights_`` (N, nz).
        **overrides
            Keyword arguments of :class:`FixedPointModel` (``input_bits``, ``weight_frac``, ...).

        Returns
        -------
        FixedPointModel

        Raises
        ------
        sklearn.exceptions.NotFittedError
            The sensor is not fitted.
        InputError
            A format option is impossible, or the grid is non-uniform (``breakpoints``).
        """
        if not hasattr(sensor, "weights_"):
            from sklearn.exceptions import NotFittedError  # a ValueError; imported here: sklearn is slow to import

            raise NotFittedError("the sensor is not fitted yet; call fit() or load a model first")
        names, signals, tgts = sensor_names(sensor)  # past estimates: the signals <target>_hat (issue 13)
        given = set(overrides)
        if "reference_error" not in overrides:
            rmse = np.asarray(getattr(sensor, "train_rmse_", []), dtype=float).reshape(-1)
            rmse = rmse[np.isfinite(rmse) & (rmse > 0)]
            overrides["reference_error"] = float(rmse.max()) if rmse.size else None
        overrides.setdefault("regressor_names", names)
        overrides.setdefault("regressor_signals", signals)
        overrides.setdefault("target_names", tgts)
        from_rmse = overrides["reference_error"] is not None and "reference_error" not in given
        model = cls(sensor.grid_, sensor.weights_, **overrides)
        if from_rmse:
            model.reference_error_source = "train_rmse"
        return model

    # ------------------------------------------------------------- inputs
    def quantize_inputs(self, x: ArrayLike, return_saturated: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Input codes of physical regressors (half up, saturated to ``B_in`` bits).

        Parameters
        ----------
        x : array_like, shape (m, n) or (n,)
            Physical regressor values (the units of the signals).
        return_saturated : bool
            Also return a bool (m,) mask of rows where some value saturated the code range.

        Returns
        -------
        q : ndarray of int64, shape (m, n)
        saturated : ndarray of bool, shape (m,) (only with ``return_saturated``)
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
        """Physical points the circuit evaluates for input codes.

        ``lo_j + lsb_j * (q - lo_code_j)``; with ``input_scale="exact"``, inside the domain
        ``lo_j + h_j t'_j / 2**F_j`` (the scaled offset, :meth:`InputFormat.scaled`).

        Parameters
        ----------
        q : array_like of int, shape (m, n) or (n,)
            Signed input codes inside the ``B_in``-bit range.

        Returns
        -------
        ndarray of float, shape (m, n)
            Physical regressor values.
        """
        qa = self._check_codes(q)
        x = np.stack([f.to_physical(qa[:, j]) for j, f in enumerate(self.inputs)], axis=1)
        for j, f in enumerate(self.inputs):
            if f.scale == "exact":
                t = qa[:, j] - f.lo_code
                inside = (t >= 0) & (t <= f.input_span)
                x[inside, j] = f.lo + f.step * np.ldexp(f.scaled(t[inside]).astype(float), -f.frac)
        return x

    def _check_codes(self, q) -> np.ndarray:
        qa = np.atleast_2d(np.asarray(q))
        if qa.dtype.kind not in "iu":
            if qa.dtype.kind != "f" or not np.all(qa == np.floor(qa)):
                raise InputError("input codes must be integers; use quantize_inputs() for physical values")
        qa = qa.astype(np.int64)
        if qa.ndim != 2 or qa.shape[1] != self.n:
            raise InputError(f"input codes must have shape (m, {self.n}), got {np.shape(q)}")
        bad = (qa < self._qmin) | (qa > self._qmax)
        if bad.any():
            r, j = np.argwhere(bad)[0]
            raise InputError(
                f"input code {int(qa[r, j])} (row {int(r)}, dimension {int(j)}) is outside the "
                f"{self.input_bits}-bit range [{int(self._qmin[j])}, {int(self._qmax[j])}]"
            )
        return qa

    # ------------------------------------------------------------- datapath
    def _run(self, q, full: bool) -> dict:
        qa = self._check_codes(q)
        m = qa.shape[0]
        t = qa - self._lo_code
        tc = np.clip(t, 0, self._span)
        oor = np.any(tc != t, axis=1)
        ts = (tc * self._kmul) >> self._rsh  # input_scale "exact": constant scale to 2**F_j sub-steps per cell
        cell = np.minimum(ts >> self._fj, self.grid.partitions - 1)
        frac_raw = ts - (cell << self._fj)
        frac = frac_raw << (self.F - self._fj)
        rank, perm = Grid.order(frac)
        vertices = self.grid.simplex_vertices(cell, perm)
        mu = Grid.barycentric(frac, perm, one=1 << self.F)
        bank, addr = self.layout.simplex_bank_addr(vertices)
        w = self.rom[bank, addr, :]  # (m, n+1, nz)
        products = mu[:, :, None] * w
        # summed as the RTL sums: memory b multiplies the word it read, the adder tree of
        # pwas_hdl.fixedpoint.reduction pairs the memories (0, 1), (2, 3), ... (exact either way)
        rows = np.arange(m)[:, None]
        slot = self.layout.product_slots(bank)  # the products' order in the adder tree (bank, or vertex for "corner")
        by_bank = np.empty_like(products)
        by_bank[rows, slot] = products
        acc = tree_reduce([by_bank[:, b, :] for b in range(by_bank.shape[1])], lambda a, b, _lvl, _i: a + b)
        acc_r = shift_round(acc, self.shift, self.rounding)
        fo = self.output_format
        out = np.clip(acc_r, fo.min_code, fo.max_code)
        lim = 1 << (self.widths["acc"] - 1)
        assert np.all(np.abs(acc) < lim), "accumulator exceeds its declared width"  # cannot happen: sum mu = 2**F
        res = {"out": out, "out_of_range": oor}
        if full:
            addr_by_bank = np.zeros_like(addr)
            addr_by_bank[rows, slot] = addr
            w_by_bank = np.zeros_like(w)
            w_by_bank[rows, slot, :] = w
            res.update(
                q=qa,
                t=t,
                t_clamped=tc,
                cell=cell,
                frac_raw=frac_raw,
                frac=frac,
                rank=rank,
                perm=perm,
                vertices=vertices,
                rot=cell.sum(axis=1) % (self.n + 1),
                bank=bank,
                addr=addr,
                addr_by_bank=addr_by_bank,
                mu=mu,
                w_by_bank=w_by_bank,
                w=w,
                products=products,
                acc=acc,
                acc_rounded=acc_r,
                out_saturated=np.any(acc_r != out, axis=1),
            )
        return res

    def evaluate(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Run the circuit on input codes.

        Parameters
        ----------
        q : array_like of int, shape (m, n) or (n,)
            Input codes inside the ``B_in``-bit range.

        Returns
        -------
        out : ndarray of int64, shape (m, nz)
            Output codes (``s<B_out>.<Fo>``).
        out_of_range : ndarray of bool, shape (m,)
            True where some input was outside the domain and has been clamped.
        """
        r = self._run(q, full=False)
        return r["out"], r["out_of_range"]

    def evaluate_one(self, q: Sequence[int]) -> tuple[tuple[int, ...], bool]:
        """The circuit on one row of input codes, in plain Python integers (the recurrence's step).

        The arithmetic of :meth:`evaluate` (module notes, steps 1-6) for one sample without numpy:
        one call costs a few microseconds instead of the ~30 array operations ``evaluate`` spends on
        a row. :class:`~pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel` calls it once per
        sample, where every row depends on the previous output. Two parts of the datapath are the
        circuit's structure, not its arithmetic, and are not repeated: the memory read (every layout
        stores the code of vertex ``v`` wherever it is read, :meth:`layout.contents
        <pwas_hdl.fixedpoint.memory_layout.BankedLayout.contents>`, so the word is
        ``weight_codes[v]``) and the adder tree's order (the products are summed exactly, so the
        order does not change the sum). ``tests/test_recurrence_speed.py`` checks it equals
        :meth:`evaluate` bit for bit on random codes (out of the domain, ties of the fractions,
        saturated outputs, every layout, both roundings and input scales).

        Parameters
        ----------
        q : sequence of int, length n
            Input codes inside the ``B_in``-bit range (not checked: check a batch with
            :meth:`evaluate` or before, as :meth:`RecurrentFixedPointModel.run
            <pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel.run>` does).

        Returns
        -------
        out : tuple of int, length nz
            Output codes, as a row of :meth:`evaluate`'s ``out``.
        out_of_range : bool
            As :meth:`evaluate`'s flag of the row.
        """
        c = self.__dict__.get("_one_constants")
        if c is None:
            c = self._one_constants = self._step_constants()
        dims, one, strides, words, nz, sh, half, omin, omax = c
        oor = False
        base = 0
        frac = []
        for qj, (lo, span, kmul, rsh, fj, cmax, align), st in zip(q, dims, strides):
            t = qj - lo
            if t < 0:
                t, oor = 0, True
            elif t > span:
                t, oor = span, True
            ts = (t * kmul) >> rsh
            cell = ts >> fj
            if cell > cmax:
                cell = cmax
            frac.append((ts - (cell << fj)) << align)
            base += cell * st
        perm = sorted(range(len(frac)), key=frac.__getitem__, reverse=True)  # stable: ties keep the lower dimension first
        v, upper = base, one
        wv = words[v]
        acc = [0] * nz
        for j in perm:  # vertex k: mu_k = frac_perm[k-1] - frac_perm[k] (mu_0 = 2**F - frac_perm[0])
            d = frac[j]
            mu = upper - d
            for z in range(nz):
                acc[z] += mu * wv[z]
            upper = d
            v += strides[j]
            wv = words[v]
        out = []
        for z in range(nz):  # mu_n = frac_perm[n-1]
            a = acc[z] + upper * wv[z]
            if sh:
                a = (a + half) >> sh
            out.append(omin if a < omin else omax if a > omax else a)
        return tuple(out), oor

    def check_codes(self, q: ArrayLike) -> None:
        """Refuse input codes that :meth:`evaluate` refuses (not integers, not ``n`` columns, outside
        the ``B_in``-bit range), with its message; what :meth:`evaluate_one` leaves to its caller.

        Parameters
        ----------
        q : array_like of int, shape (m, n)

        Raises
        ------
        InputError
        """
        self._check_codes(q)

    def _step_constants(self) -> tuple:
        """The constants :meth:`evaluate_one` needs, as Python integers (made once)."""
        def ints(a) -> list[int]:
            return [int(v) for v in a]

        align = [self.F - f for f in ints(self._fj)]
        dims = tuple(zip(ints(self._lo_code), ints(self._span), ints(self._kmul), ints(self._rsh), ints(self._fj),
                         [int(p) - 1 for p in self.grid.partitions], align))
        sh = int(self.shift)
        half = (1 << (sh - 1)) if sh and self.rounding == "half_up" else 0
        fo = self.output_format
        return (dims, 1 << self.F, tuple(ints(self.grid.strides)), self.weight_codes.tolist(), self.nz, sh, half,
                int(fo.min_code), int(fo.max_code))

    def trace(self, q: ArrayLike) -> dict[str, np.ndarray]:
        """Every pipeline stage for input codes ``q``.

        Parameters
        ----------
        q : array_like of int, shape (m, n) or (n,)
            Signed input codes.

        Returns
        -------
        dict of str to ndarray
            Integer (or bool) arrays, one per stage. Keys (:data:`TRACE_STAGES`) and shapes:
            ``q, t, t_clamped, cell, frac_raw, frac, rank, perm`` (m, n); ``out_of_range,
            out_saturated`` (m,); ``vertices, bank, addr, mu`` (m, n+1) indexed by simplex vertex
            ``k``; ``rot`` (m,) = ``sum(cell) mod (n+1)``; ``addr_by_bank`` (m, n_banks) address
            presented to each bank; ``w`` (m, n+1, nz) weight code of vertex ``k``; ``w_by_bank``
            (m, n_banks, nz) word read from each bank; ``products`` (m, n+1, nz); ``acc,
            acc_rounded, out`` (m, nz). See the module docstring for the definitions and
            :attr:`widths` for the widths.
        """
        return self._run(q, full=True)

    def reference(self, q: ArrayLike) -> np.ndarray:
        """Float model (unquantised weights) at the physical inputs the codes represent.

        Equal to ``grid.evaluate(weights, represented_inputs(q))`` up to float rounding; it is
        computed from the exact grid coordinates ``(clip(q - lo_code) ) / 2**F_j`` with
        :meth:`Grid.locate_grid_units`, so no physical round trip moves a point across a face.

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
        tc = np.clip(qa - self._lo_code, 0, self._span)
        s = np.ldexp(((tc * self._kmul) >> self._rsh).astype(float), -self._fj)
        _, _, _, _, vertices, mu = self.grid.locate_grid_units(s)
        return np.einsum("mk,mkz->mz", mu, self.weights[vertices])

    def to_physical_output(self, out_codes: ArrayLike) -> np.ndarray:
        """Physical output values ``code * 2**-Fo``.

        Parameters
        ----------
        out_codes : array_like of int, shape (m, nz)
            Output codes (``s<B_out>.<Fo>``), as :meth:`evaluate` returns them.

        Returns
        -------
        ndarray of float, shape (m, nz)
            Physical target units.
        """
        return self.output_port.to_physical(out_codes)

    def predict(self, x: ArrayLike, return_flags: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Physical regressors -> physical outputs through the bit-true circuit.

        Parameters
        ----------
        x : array_like, shape (m, n) or (n,)
            Physical regressor values (quantised by :meth:`quantize_inputs`).
        return_flags : bool
            Also return the flags below.

        Returns
        -------
        zhat : ndarray (m, nz), float
        flags : ndarray (m,), bool -- out_of_range or input saturation (only with ``return_flags``)
        """
        q, sat = self.quantize_inputs(x, return_saturated=True)
        out, oor = self.evaluate(q)
        z = self.to_physical_output(out)
        return (z, oor | sat) if return_flags else z

    # ------------------------------------------------------------- reporting
    def signal_input_formats(self) -> dict[str, InputFormat]:
        """The input format of each signal (all its lags share it).

        Returns
        -------
        dict of str to InputFormat
            Signal name -> the format of its lags, in first-appearance order.

        Raises
        ------
        InputError
            Two lags of one signal have different formats (the lag bank of the sensor top
            scales once per signal, so it needs ``share_lag_domain=True`` in the fit).
        """
        res: dict[str, InputFormat] = {}
        for j, (sig, _lag) in enumerate(self.regressor_signals):
            f = self.inputs[j]
            if sig in res and res[sig] != f:
                raise InputError(
                    f"the lags of signal {sig!r} have different input formats (dimension {j}: {f.to_dict()['format']} "
                    f"on [{f.lo}, {f.hi}]); the sensor top scales each signal once, so its lags need one interval "
                    "and the same number of intervals: fit without --separate-lag-domains (share_lag_domain=True) and with "
                    "one -p value for all lags of the signal, or generate --design core"
                )
            res.setdefault(sig, f)
        return res

    def to_dict(self) -> dict:
        """Everything the manifest needs (JSON-ready): formats, codes, scaling, widths, layout, bound.

        Returns
        -------
        dict
            ``n``, ``nz``, ``F``, ``rounding``, ``weight_overflow``, ``inputs`` (one per regressor
            dimension), ``signals`` (``None`` when the lags of a signal have different formats),
            ``weights``, ``output``, ``widths`` (bits), ``layout``, ``error_bound`` (physical units
            and output LSB) and ``reference_error``.
        """
        try:
            signals = {k: v.to_dict() for k, v in self.signal_input_formats().items()}
        except InputError:  # lags of one signal with different formats
            signals = None
        return {
            "n": self.n,
            "nz": self.nz,
            "F": self.F,
            "rounding": self.rounding,
            "weight_overflow": self.overflow,
            "inputs": [
                {"name": nm, "signal": sig, "lag": lag, **f.to_dict()}
                for nm, (sig, lag), f in zip(self.regressor_names, self.regressor_signals, self.inputs)
            ],
            "signals": signals,
            "weights": {
                **self.weight_format.to_dict(),
                "scale": 1.0,
                "offset": 0.0,
                "n_saturated": self.n_weights_saturated,
                "max_abs_error": self.weight_error_max,
            },
            "output": {
                **self.output_port.to_dict(),
                "targets": list(self.target_names),
                "shift": self.shift,
                "reachable_codes": [int(self._out_reach[0]), int(self._out_reach[1])],
                "may_saturate": self.output_may_saturate,
            },
            "widths": dict(self.widths),
            "layout": self.layout.to_dict(),
            "error_bound": {
                "physical": self.error_bound,
                "lsb": self.error_bound_lsb,
                "weight_term": self.error_bound_weight,
                "output_term": self.error_bound_output,
                "includes_weight_saturation": bool(self.n_weights_saturated),
                "holds_unless_output_saturates": True,
                "against": "float model, unquantised weights, at the physical input the code represents",
            },
            "reference_error": {"value": self.reference_error, "source": self.reference_error_source},
        }

    def __repr__(self) -> str:
        fin = ", ".join(f"{f.format}" for f in self.inputs)
        return (
            f"FixedPointModel(n={self.n}, nz={self.nz}, inputs=[{fin}], F={self.F}, weights={self.weight_format}, "
            f"output={self.output_format}, shift={self.shift}, bound={self.error_bound_lsb:.3g} lsb)"
        )
