"""Bit-true model of a recurrent PWAS sensor (issue 13): the fed-back estimate in fixed point.

THE specification of :class:`pwas_hdl.hdl.recurrent_top.PWASRecurrentTop`. One sample of the
measured signals per transfer (codes of their input formats, as the lag sensor top); the
regressor of sample ``t`` is the u/y lag taps followed by the past estimates
``z_hat(t-Mz) .. z_hat(t-1)`` of every target, each already in the *input* code format of its
regressor dimension (all lags of one target share it: ``share_lag_domain``).

Feedback requantisation (output code ``o``, ``s<B_out>.<Fo>``, to the input code ``q`` of the
fed-back dimension, format ``lo_code, lsb``)::

    q = clip( (o * K + C) >> S,  -2**(B_in-1), 2**(B_in-1) - 1 )          (arithmetic shift)

with ``r = 2**-Fo / lsb`` (input codes per output code), ``S`` such that ``K = round(r 2**S)``
has :data:`FEEDBACK_PRECISION` bits, and ``C = floor((lo_code - lo / lsb) 2**S) + 2**(S-1)``:
``(o K + C) >> S`` is ``o r + (lo_code - lo/lsb)`` -- the input code of the physical value
``o 2**-Fo`` -- rounded half up (the rule of :meth:`InputFormat.quantize
<pwas_hdl.fixedpoint.formats.InputFormat.quantize>`), up to the constants' rounding, and
saturated to the ``B_in``-bit range. Error of the fed-back value against the output it comes from
(unless it saturates): ``|q lsb + offset - o 2**-Fo| <= lsb (1/2 + eps)`` with
``eps = 2**(B_out-1) |K 2**-S - r| + |C 2**-S - c0 - 1/2|`` (:attr:`FeedbackRequant.error_bound`).
Inside the grid domain the stage is the same rounding a sample of a measured signal goes through.

Initial state: the reset values of the feedback registers are the input codes of the model's
initial values (``InputFormat.quantize``, half up, saturating). The warm-up of the u/y lags
(``M - 1`` transfers) is as in the lag sensor top; the first estimate (transfer ``M - 1``) sees
the initial codes as its past.

How quantisation errors propagate: each step adds the bit-true error of the circuit
(:attr:`FixedPointModel.error_bound`) and the requantisation error above to the state; the
closed loop filters them with the (local) gain of the recurrence. No closed-form bound is given
for a general PWAS map; the benches and tests *measure* the deviation of the bit-true recurrence
from the float one over long runs (:func:`recurrence_deviation`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence
from fractions import Fraction

import numpy as np
from numpy.typing import ArrayLike

from pwas_hdl.errors import InputError
from pwas_hdl.fit.regressors import LagStructure
from pwas_hdl.fixedpoint.bittrue import FixedPointModel
from pwas_hdl.fixedpoint.formats import FixedFormat, InputFormat

if TYPE_CHECKING:
    from pwas_hdl.fixedpoint.warp import WarpInputFormat, WarpedFixedPointModel

__all__ = ["FEEDBACK_PRECISION", "LOCKSTEP_MIN", "FeedbackRequant", "RecurrentFixedPointModel"]

#: Significant bits of the requantisation multiplier ``K``.
FEEDBACK_PRECISION = 24

#: Trajectories from which :meth:`RecurrentFixedPointModel.run_many` runs them in lockstep (one
#: array evaluation a time step) rather than one by one on the one-sample path: about where the two
#: cost the same (``benchmarks/recurrence_speed.py``).
LOCKSTEP_MIN = 48


@dataclass(frozen=True)
class FeedbackRequant:
    """``q = clip((o * mul + add) >> shift, qmin, qmax)``: an output code to an input code.

    Made by :meth:`between` (see the module docstring for the constants).

    Attributes
    ----------
    mul, add : int
        ``K`` and ``C`` of the module docstring (integers scaled by ``2**shift``).
    shift : int
        ``S``, bits of the arithmetic right shift.
    qmin, qmax : int
        The input code range (``-2**(B_in-1)``, ``2**(B_in-1) - 1``).
    out_bits : int
        ``B_out``, bits of the output code ``o``.
    in_bits : int
        ``B_in``, bits of the input code ``q``.
    error_bound : float
        ``lsb (1/2 + eps)``: bound on the error of the fed-back value against the output it comes
        from (unless it saturates), physical units of the fed-back dimension.
    """

    mul: int
    add: int
    shift: int
    qmin: int
    qmax: int
    out_bits: int
    in_bits: int
    error_bound: float

    @classmethod
    def between(cls, out_format: FixedFormat, inp: InputFormat | WarpInputFormat,
                precision: int = FEEDBACK_PRECISION) -> "FeedbackRequant":
        """The requantisation from ``out_format`` codes to ``inp`` codes.

        Derivation (any ``inp`` whose codes are ``x = lo + lsb (q - lo_code)`` and whose
        quantisation is ``floor(lo_code + (x - lo) / lsb + 1/2)`` saturated to ``inp.format``, the
        one rule of :func:`~pwas_hdl.fixedpoint.formats.quantize_input`): the output code ``o``
        stands for ``x = o 2**-Fo``, so the input code of ``x`` is ``floor(o r + c0 + 1/2)`` with
        ``r = 2**-Fo / lsb`` and ``c0 = lo_code - lo / lsb``; ``K``, ``C``, ``S`` approximate
        ``r`` and ``c0 + 1/2`` in ``S`` fraction bits. This holds for an :class:`InputFormat`
        (uniform grid) and for a :class:`~pwas_hdl.fixedpoint.warp.WarpInputFormat` (non-uniform
        power-of-two partition: its codes ``q`` are the warp's inputs, ``lo_code = B_0``, and the
        warp that follows is exact), so the same rule feeds back into a warped core.

        Parameters
        ----------
        out_format : FixedFormat
            The output format ``s<B_out>.<Fo>`` of the estimate fed back.
        inp : InputFormat or WarpInputFormat
            The input format of the fed-back regressor dimension (``lo``, ``lsb`` in physical
            units, ``lo_code``, ``bits`` and a saturating ``format``).
        precision : int
            Bits of ``mul`` (``K``), default :data:`FEEDBACK_PRECISION`.

        Returns
        -------
        FeedbackRequant
        """
        lsb = Fraction(inp.lsb)
        r = Fraction(1, 1) / (lsb * (Fraction(2) ** out_format.frac))
        c0 = Fraction(inp.lo_code) - Fraction(inp.lo) / lsb
        e = math.floor(math.log2(r.numerator) - math.log2(r.denominator))
        shift = max(1, precision - 1 - e)
        mul = round(r * 2**shift)
        add = math.floor(c0 * 2**shift) + (1 << (shift - 1))
        eps = (2 ** (out_format.bits - 1)) * abs(Fraction(mul, 2**shift) - r) + abs(Fraction(add, 2**shift) - c0 - Fraction(1, 2))
        fmt = inp.format
        return cls(int(mul), int(add), int(shift), int(fmt.min_code), int(fmt.max_code), int(out_format.bits), int(inp.bits),
                   float(lsb * (Fraction(1, 2) + eps)))

    @property
    def product_bits(self) -> int:
        """Signed width that holds ``o * mul + add`` for every ``B_out``-bit ``o``."""
        hi = max(abs(-(1 << (self.out_bits - 1)) * self.mul + self.add), abs(((1 << (self.out_bits - 1)) - 1) * self.mul + self.add))
        return hi.bit_length() + 1

    def check_top_product(self, target: int) -> None:
        """Refuse a requantisation the recurrent top cannot compute.

        The top (:meth:`pwas_hdl.hdl.recurrent_top.PWASRecurrentTop._requant`) forms the unsigned
        product ``(o + 2**(B_out-1)) * mul`` in ``B_out + bits(mul)`` bits and takes ``q`` from its
        low ``B_in + S`` bits, so it needs ``B_out + bits(mul) >= B_in + S``. Checked wherever a
        recurrent design is made (:func:`pwas_hdl.design.recurrent.recurrent_model`: generate,
        explore) and by the top itself.

        Parameters
        ----------
        target : int
            Index of the target (for the message).

        Raises
        ------
        InputError
            The product is narrower than ``B_in + S``.
        """
        pw = self.out_bits + self.mul.bit_length()
        if pw < self.in_bits + self.shift:
            raise InputError(f"feedback requantisation of target {target}: the product has {pw} bits, fewer than "
                             f"B_in + S = {self.in_bits + self.shift}; use more output bits or fewer input bits")

    def apply(self, o: ArrayLike) -> np.ndarray:
        """Input codes of output codes ``o``.

        Parameters
        ----------
        o : array_like of int, any shape
            Output codes (``B_out``-bit).

        Returns
        -------
        ndarray of int64, the shape of ``o``
            Input codes, saturated to ``[qmin, qmax]``.
        """
        oa = np.asarray(o, dtype=np.int64)
        if self.product_bits > 62:  # exact with Python integers
            v = np.array([(int(x) * self.mul + self.add) >> self.shift for x in oa.reshape(-1)], dtype=object).reshape(oa.shape)
            return np.clip(v, self.qmin, self.qmax).astype(np.int64)
        return np.clip((oa * self.mul + self.add) >> self.shift, self.qmin, self.qmax)

    def apply_one(self, o: int) -> int:
        """:meth:`apply` of one output code, in Python integers (exact at any width; the
        recurrence's step).

        Parameters
        ----------
        o : int
            An output code.

        Returns
        -------
        int
            The input code, saturated to ``[qmin, qmax]``.
        """
        q = (o * self.mul + self.add) >> self.shift
        return self.qmin if q < self.qmin else self.qmax if q > self.qmax else q

    def to_dict(self) -> dict:
        """JSON-ready description (a manifest's ``requant`` entry).

        Returns
        -------
        dict
            The ``rule`` as text, ``mul``, ``add``, ``shift``, ``qmin``, ``qmax``,
            ``product_bits`` and ``error_bound`` (physical units).
        """
        return {"rule": "q = clip((o * mul + add) >> shift, qmin, qmax): round half up, saturate",
                "mul": self.mul, "add": self.add, "shift": self.shift, "qmin": self.qmin, "qmax": self.qmax,
                "product_bits": self.product_bits, "error_bound": self.error_bound}


class RecurrentFixedPointModel:
    """The recurrence in fixed point: a :class:`FixedPointModel` plus the feedback path.

    Parameters
    ----------
    fxm : FixedPointModel or WarpedFixedPointModel
        Of the recurrent sensor (``FixedPointModel.from_sensor``, or
        ``WarpedFixedPointModel.from_sensor`` for a non-uniform power-of-two partition: the codes
        are then the warp's inputs and the fed-back estimate is requantised to the
        :class:`~pwas_hdl.fixedpoint.warp.WarpInputFormat` of its dimension); its regressor ends
        with the fed-back dimensions.
    lags : LagStructure
        With ``Mz >= 1`` (``sensor.lags_``).
    initial_values : array_like (Mz, nz)
        Physical initial past estimates (oldest first; ``sensor.initial_values_``).

    Attributes
    ----------
    signals : list of str
        The measured signals of the input payload, in order (one ``B_in``-bit code each).
    signal_formats : list of InputFormat or WarpInputFormat
    z_formats : list of InputFormat or WarpInputFormat
        The input format of each target's fed-back dimensions.
    feedback : list of FeedbackRequant, one per target
    initial_codes : ndarray (Mz, nz), int64
        Reset values of the feedback registers.
    """

    def __init__(self, fxm: FixedPointModel | WarpedFixedPointModel, lags: LagStructure, initial_values: ArrayLike):
        if not lags.recurrent:
            raise InputError("the lag structure has no fed-back estimates (Mz = 0): use FixedPointModel")
        if lags.dimension != fxm.n:
            raise InputError(f"the lag structure has n = {lags.dimension}, the fixed-point model {fxm.n}")
        self.fxm, self.lags = fxm, lags
        formats = fxm.signal_input_formats()  # raises unless the lags of each signal share a format
        sod = lags.signal_of_dimension()
        self.signals: list[str] = []
        for j, (kind, _ch, _lag) in enumerate(sod):
            sig = fxm.regressor_signals[j][0]
            if kind != "z" and sig not in self.signals:
                self.signals.append(sig)
        self.signal_formats = [formats[s] for s in self.signals]
        zdims = {c: [j for j, (k, ch, _) in enumerate(sod) if k == "z" and ch == c] for c in range(lags.nz)}
        self.z_formats = [fxm.inputs[zdims[c][0]] for c in range(lags.nz)]
        self.feedback = [FeedbackRequant.between(fxm.output_format, f) for f in self.z_formats]
        iv = np.asarray(initial_values, dtype=float)
        if iv.size != lags.mz * lags.nz or not np.all(np.isfinite(iv)):
            raise InputError(f"initial_values must be Mz x nz = {lags.mz} x {lags.nz} finite physical values (oldest first), "
                             f"got shape {iv.shape}{'' if np.all(np.isfinite(iv)) else ' with NaN or infinite values'}")
        iv = iv.reshape(lags.mz, lags.nz)
        self.initial_values = iv
        self.initial_codes = np.stack([f.quantize(iv[:, c]) for c, f in enumerate(self.z_formats)], axis=1).astype(np.int64)

    # ------------------------------------------------------------------ inputs
    def quantize_signals(self, u: np.ndarray | None, y: np.ndarray | None) -> np.ndarray:
        """Payload codes of one trajectory: each measured signal in its input format.

        Parameters
        ----------
        u : ndarray, shape (T, nu), or None
            Measured inputs, physical units (None when the model has no input lags).
        y : ndarray, shape (T, ny), or None
            Measured outputs, physical units (None when the model has no output lags).

        Returns
        -------
        ndarray of int64, shape (T, S)
            One ``B_in``-bit code per signal of :attr:`signals`, in that order.
        """
        cols = []
        for s, f in zip(self.signals, self.signal_formats):
            kind, ch = self._signal_kind(s)
            src = u if kind == "u" else y
            cols.append(f.quantize(np.asarray(src, dtype=float)[:, ch]))
        return np.stack(cols, axis=1).astype(np.int64)

    def _signal_kind(self, name: str) -> tuple[str, int]:
        for j, (kind, ch, _lag) in enumerate(self.lags.signal_of_dimension()):
            if self.fxm.regressor_signals[j][0] == name and kind != "z":
                return kind, ch
        raise KeyError(name)

    def _io_codes(self, codes: np.ndarray) -> np.ndarray:
        """The u/y part of the regressor codes from the payload codes (rows t = M-1 ..)."""
        lags = self.lags
        kinds = [self._signal_kind(s) for s in self.signals]
        u = np.zeros((codes.shape[0], lags.nu)) if lags.nu else None
        y = np.zeros((codes.shape[0], lags.ny)) if lags.ny else None
        for i, (kind, ch) in enumerate(kinds):
            (u if kind == "u" else y)[:, ch] = codes[:, i]
        io_lags = LagStructure(lags.mu, lags.my, lags.nu, lags.ny)
        return io_lags.build(u, y).astype(np.int64)

    # ------------------------------------------------------------------ run
    def run(self, codes: ArrayLike) -> dict:
        """The recurrence on the payload codes of one trajectory (the circuit after a reset).

        Each sample is one :meth:`FixedPointModel.evaluate_one
        <pwas_hdl.fixedpoint.bittrue.FixedPointModel.evaluate_one>` (Python integers: the next
        regressor needs this output, so the samples cannot be one array) and one
        :meth:`FeedbackRequant.apply_one` per target; the u/y codes are checked once, before the
        loop (the fed-back codes are in range by construction). The result equals a loop of
        :meth:`FixedPointModel.evaluate <pwas_hdl.fixedpoint.bittrue.FixedPointModel.evaluate>` on
        one-row arrays (:meth:`_run_reference`) bit for bit, about 30 times faster.

        Parameters
        ----------
        codes : array_like of int, shape (T, S)
            One row per input transfer.

        Returns
        -------
        dict
            ``out`` (R, nz) output codes, ``out_of_range`` (R,), ``fed_back`` (R, nz) the input
            codes stored into the feedback registers, ``regressor`` (R, n) the regressor codes,
            with ``R = T - M + 1`` rows for the transfers ``M-1 .. T-1``.
        """
        return self._run_io(self._io_codes(self._payload(codes)))

    def _run_io(self, io: np.ndarray) -> dict:
        """:meth:`run` from the u/y regressor codes (rows t = M-1 ..)."""
        step = getattr(self.fxm, "evaluate_one", None)
        if step is None:  # a model without the one-sample path: the array loop
            return self._loop(io)
        nz, R = self.lags.nz, io.shape[0]
        if R:  # the checks of evaluate on the u/y codes, once (with the reset codes in the fed-back columns)
            self.fxm.check_codes(np.concatenate([io, np.broadcast_to(self.initial_codes.reshape(1, -1), (R, self.initial_codes.size))], axis=1))
        feedback = [fb.apply_one for fb in self.feedback]
        past = [int(v) for v in self.initial_codes.reshape(-1)]  # (Mz, nz) oldest first, row by row
        regs, outs, flags, feds = [], [], [], []
        for row in io.tolist():
            reg = row + past
            o, fl = step(reg)
            fed = [f(v) for f, v in zip(feedback, o)]
            past = past[nz:] + fed
            regs.append(reg)
            outs.append(o)
            flags.append(fl)
            feds.append(fed)
        return {"out": np.array(outs, dtype=np.int64).reshape(R, nz), "out_of_range": np.array(flags, dtype=bool).reshape(R),
                "fed_back": np.array(feds, dtype=np.int64).reshape(R, nz),
                "regressor": np.array(regs, dtype=np.int64).reshape(R, self.fxm.n)}

    def run_many(self, codes: Sequence[ArrayLike], lockstep: bool | None = None) -> list[dict]:
        """:meth:`run` of several trajectories (each from reset), the same results.

        With many trajectories they run in lockstep: one :meth:`FixedPointModel.evaluate
        <pwas_hdl.fixedpoint.bittrue.FixedPointModel.evaluate>` and one
        :meth:`FeedbackRequant.apply` per target and time step, over every trajectory still running
        (the array path's cost is per call, so a step of ``k`` trajectories costs about one sample
        of :meth:`_run_reference`). With few, each runs on :meth:`run`'s one-sample path, which is
        faster up to about :data:`LOCKSTEP_MIN` trajectories.

        Parameters
        ----------
        codes : sequence of array_like of int, each shape (T_i, S)
            The payload codes of each trajectory.
        lockstep : bool, optional
            Force (True) or avoid (False) the lockstep; default: lockstep from
            :data:`LOCKSTEP_MIN` trajectories on.

        Returns
        -------
        list of dict
            :meth:`run`'s result for each trajectory, in order.
        """
        ios = [self._io_codes(self._payload(c)) for c in codes]
        if lockstep is None:
            lockstep = len(ios) >= LOCKSTEP_MIN
        if not lockstep:
            return [self._run_io(io) for io in ios]
        nz, n = self.lags.nz, self.fxm.n
        k_io = n - self.initial_codes.size
        order = sorted(range(len(ios)), key=lambda i: -ios[i].shape[0])  # longest first: the running ones are a prefix
        lengths = np.array([ios[i].shape[0] for i in order], dtype=np.int64)
        R = int(lengths[0]) if len(order) else 0
        reg = np.zeros((len(order), R, n), dtype=np.int64)
        for r, i in enumerate(order):
            reg[r, :lengths[r], :k_io] = ios[i]
        out = np.zeros((len(order), R, nz), dtype=np.int64)
        fed = np.zeros((len(order), R, nz), dtype=np.int64)
        oor = np.zeros((len(order), R), dtype=bool)
        past = np.broadcast_to(self.initial_codes.reshape(1, -1), (len(order), self.initial_codes.size)).copy()
        for t in range(R):
            k = int(np.count_nonzero(lengths > t))
            reg[:k, t, k_io:] = past[:k]
            o, fl = self.fxm.evaluate(reg[:k, t])
            out[:k, t], oor[:k, t] = o, fl
            f = np.stack([fb.apply(o[:, c]) for c, fb in enumerate(self.feedback)], axis=1)
            fed[:k, t] = f
            past[:k] = np.concatenate([past[:k, nz:], f], axis=1)
        res: list[dict] = [{}] * len(ios)
        for r, i in enumerate(order):
            m = int(lengths[r])
            res[i] = {"out": out[r, :m].copy(), "out_of_range": oor[r, :m].copy(), "fed_back": fed[r, :m].copy(),
                      "regressor": reg[r, :m].copy()}
        return res

    def _payload(self, codes: ArrayLike) -> np.ndarray:
        ca = np.asarray(codes, dtype=np.int64)
        if ca.ndim != 2 or ca.shape[1] != len(self.signals):
            raise InputError(f"codes must have shape (T, {len(self.signals)}), got {ca.shape}")
        return ca

    def _run_reference(self, codes: ArrayLike) -> dict:
        """:meth:`run` as a loop of :meth:`FixedPointModel.evaluate
        <pwas_hdl.fixedpoint.bittrue.FixedPointModel.evaluate>` on one-row arrays and
        :meth:`FeedbackRequant.apply`: the straightforward definition the tests and
        ``benchmarks/recurrence_speed.py`` compare :meth:`run` with (slow: ~0.3 ms a sample)."""
        return self._loop(self._io_codes(self._payload(codes)))

    def _loop(self, io: np.ndarray) -> dict:
        mz, nz = self.lags.mz, self.lags.nz
        past = self.initial_codes.copy()  # (Mz, nz) oldest first
        R = io.shape[0]
        out = np.empty((R, nz), dtype=np.int64)
        fed = np.empty((R, nz), dtype=np.int64)
        oor = np.empty(R, dtype=bool)
        reg = np.empty((R, self.fxm.n), dtype=np.int64)
        for t in range(R):
            reg[t] = np.concatenate([io[t], past.reshape(-1)])
            o, fl = self.fxm.evaluate(reg[t][None, :])
            out[t], oor[t] = o[0], fl[0]
            fed[t] = [fb.apply(o[0, c]) for c, fb in enumerate(self.feedback)]
            past = np.vstack([past[1:], fed[t][None, :]]) if mz > 1 else fed[t][None, :].copy()
        return {"out": out, "out_of_range": oor, "fed_back": fed, "regressor": reg}

    def predict(self, u: np.ndarray | None, y: np.ndarray | None) -> np.ndarray:
        """Physical estimates of one trajectory through the bit-true recurrence.

        Parameters
        ----------
        u : ndarray, shape (T, nu), or None
            Measured inputs, physical units (None when the model has no input lags).
        y : ndarray, shape (T, ny), or None
            Measured outputs, physical units (None when the model has no output lags).

        Returns
        -------
        ndarray, shape (R, nz), float
            Estimates in physical target units, ``R = T - M + 1`` rows for ``t = M-1 .. T-1``
            (:meth:`run`).
        """
        return self.fxm.to_physical_output(self.run(self.quantize_signals(u, y))["out"])

    def to_dict(self) -> dict:
        """The feedback path for a manifest / report (JSON-ready)."""
        return {
            "Mz": self.lags.mz,
            "signals": list(self.signals),
            "fed_back": [{"target": t, "input_format": f.to_dict(), "requant": fb.to_dict(),
                          "initial_codes": [int(v) for v in self.initial_codes[:, c]]}
                         for c, (t, f, fb) in enumerate(zip(self.fxm.target_names, self.z_formats, self.feedback))],
        }
