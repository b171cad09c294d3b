"""Bit-true u/y taps of an observer-bank sensor (issue 12): the lag taps beside the residual features.

A bank sensor fitted with ``--mu/--my`` (seed 004's ``u_k, y_k`` for the battery: ``--mu 1 --my 1``)
has the regressor ``[v_1 .. v_Ntheta, u(t-Mu+1) .. u(t), y(t-My+1) .. y(t)]``
(:meth:`pwas_hdl.fit.virtual_sensor.PWASVirtualSensor.regressors`). In hardware the taps come from
a lag bank of the same input codes the observer bank takes (the *normalised* signals
``s<B_in>.<F_in>``, :class:`~pwas_hdl.fixedpoint.observer_bank.FixedPointObserverBank`), and each tap
is mapped to the PWAS core's input code of its dimension by a constant affine map -- the same
rule as the feature codes::

    q_j = sat_{B_core}((qn * K_j + C_j) >> R)          R = B_in + 4
    K_j = round(2**R std_s 2**-F_in / lsb_j)           (std_s, mean_s: the signal's normalisation)
    C_j = round(2**R (mean_s - offset_j) / lsb_j) + 2**(R-1)   (the half-up rounding folded in)

with ``lsb_j``, ``offset_j`` the core input format of dimension ``j`` (physical = offset + lsb q).
The tap of lag ``d`` at sample ``k`` is the code of sample ``k - d`` (0 before sample 0: the lag
bank's reset value; the sensor has no output for those samples).

Error bound of a tap against the represented signal (the float sensor's regressor):
``|offset_j + lsb_j q_j - x| <= (1/2 + (2**(B_in-1) + 1) 2**-(R+1)) lsb_j`` (the final rounding,
``K_j`` rounded to ``2**-R`` over ``|qn| <= 2**(B_in-1)``, and ``C_j``), unless ``q_j`` saturates --
which happens only outside the code range of the core, beyond its domain, where both the hardware
and the float model clamp. The estimate's bound adds ``G_j`` times this per tap
(:class:`TappedObserverBankSensorModel`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.fixedpoint.bittrue import FixedPointModel
from pwas_hdl.fixedpoint.observer_bank import FixedPointObserverBank, ObserverBankSensorModel, _edge_lipschitz

if TYPE_CHECKING:
    from pwas_hdl.fit.regressors import LagStructure
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

__all__ = ["BankTaps", "TappedObserverBankSensorModel"]


class BankTaps:
    """The lag taps of an observer-bank sensor as a bit-true map from the bank's input codes.

    Parameters
    ----------
    bank : FixedPointObserverBank
    lags : LagStructure
        The sensor's taps (``nu`` inputs with ``Mu`` lags, the output with ``My`` lags).
    tap_inputs : list of InputFormat
        The core's input formats of the tap dimensions, in regressor order.

    Attributes
    ----------
    dims : list of (signal index, lag)
        Signal index into the bank's codes (``u0 .. u{nu-1}``, then ``y0`` at ``nu``).
    mul, add : list of int;  shift : int
        ``K_j``, ``C_j``, ``R``.
    error_bound : list of float
        Per tap, physical units.
    """

    def __init__(self, bank: FixedPointObserverBank, lags: "LagStructure", tap_inputs: list):
        self.bank = bank
        self.lags = lags
        sod = lags.signal_of_dimension()
        if any(kind == "z" for kind, _, _ in sod):
            raise InputError("an observer-bank sensor with fed-back estimates (--mz) has no hardware")
        if lags.ny > 1:
            raise InputError("the observer bank takes one output signal; taps of several outputs are not available")
        self.dims = [(ch if kind == "u" else bank.nu, int(lag)) for kind, ch, lag in sod]
        if len(tap_inputs) != len(self.dims):
            raise InputError(f"{len(tap_inputs)} tap input formats for {len(self.dims)} taps")
        self.tap_inputs = list(tap_inputs)
        self.memory = int(lags.memory)
        self.shift = int(bank.input_bits) + 4
        r, fin = self.shift, bank.input_frac
        self.mul, self.add = [], []
        for (s, _lag), f in zip(self.dims, self.tap_inputs):
            port = bank.signal_ports[s]
            std, mean = float(port.scaling.scale), float(port.scaling.offset)
            k = int(math.floor(2.0**r * std * 2.0**-fin / f.lsb + 0.5))
            c = int(math.floor(2.0**r * (mean - f.offset) / f.lsb + 0.5)) + (1 << (r - 1))
            if k <= 0:
                raise InputError("a tap's scale rounds to 0 (the core's input LSB is far larger than the signal's)")
            self.mul.append(k)
            self.add.append(c)
        self.core_bits = int(self.tap_inputs[0].bits)
        qn = 1 << (bank.input_bits - 1)
        self.product_bits = max(int(max(self.mul)).bit_length() + bank.input_bits + 2,
                                max(abs(int(c)) for c in self.add).bit_length() + 2) + 1
        self.error_bound = [(0.5 + (qn + 1) * 2.0 ** -(r + 1)) * f.lsb for f in self.tap_inputs]

    def codes(self, codes: np.ndarray) -> np.ndarray:
        """Tap codes of one trajectory from reset.

        Parameters
        ----------
        codes : ndarray of int, shape (T, nu + 1)
            The bank's input codes (columns ``u0 .. u{nu-1}, y0``).

        Returns
        -------
        ndarray of int64, shape (T, n_taps)
            The core's input codes of the tap dimensions (a lag before the first sample reads the
            bank input code 0).
        """
        c = np.asarray(codes, dtype=np.int64)
        t_len = c.shape[0]
        out = np.empty((t_len, len(self.dims)), dtype=np.int64)
        lo, hi = -(1 << (self.core_bits - 1)), (1 << (self.core_bits - 1)) - 1
        for j, ((s, lag), k, a) in enumerate(zip(self.dims, self.mul, self.add)):
            col = np.zeros(t_len, dtype=np.int64)
            col[lag:] = c[: t_len - lag, s] if lag else c[:, s]
            out[:, j] = np.clip((col * k + a) >> self.shift, lo, hi)
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description of the taps (the manifest's ``taps`` block).

        Returns
        -------
        dict
            ``taps`` (signal name and lag of each), ``mul``, ``add``, ``shift``, ``product_bits``,
            ``lag_bank_samples``, the ``rule`` as text and ``error_bound`` (per tap, physical
            units).
        """
        names = self.bank.signal_names
        return {"taps": [{"signal": names[s], "lag": lag} for s, lag in self.dims], "mul": list(self.mul), "add": list(self.add),
                "shift": self.shift, "product_bits": self.product_bits, "lag_bank_samples": self.memory,
                "rule": "q_j = sat((qn[k - lag_j] * mul_j + add_j) >> shift), qn the bank's input code of the tap's signal",
                "error_bound": list(self.error_bound)}


class TappedObserverBankSensorModel(ObserverBankSensorModel):
    """Bit-true observer-bank sensor with u/y taps: bank features and requantised taps -> PWAS core.

    Build with :meth:`from_sensor`. The first estimate is at sample ``max(M + l, memory - 1)``
    after reset (``memory = max(Mu, My)``), as the float sensor's regressors.

    Parameters
    ----------
    bank : FixedPointObserverBank
        The bit-true bank (features).
    core : FixedPointModel
        The bit-true PWAS core on the features followed by the taps.
    taps : BankTaps
        The requantised u/y lag taps.
    sensor : PWASVirtualSensor, optional
        The float sensor they were built from (needed by :meth:`reference`).
    """

    def __init__(self, bank: FixedPointObserverBank, core: FixedPointModel, taps: BankTaps, sensor: Any = None):
        self.bank, self.core, self.taps, self.sensor = bank, core, taps, sensor
        self.lipschitz = _edge_lipschitz(core.grid, core.weights)
        fb = np.array(list(bank.feature_error_bound) + list(taps.error_bound))
        self.error_bound = [float(core.error_bound + self.lipschitz[z] @ fb) for z in range(core.nz)]

    @property
    def first_output(self) -> int:
        """Sample index (0-based since reset) of the first estimate: ``max(M + l, memory - 1)``."""
        return max(self.bank.first_output, self.taps.memory - 1)

    @classmethod
    def from_sensor(cls, sensor: "PWASVirtualSensor", *, input_bits: int = 12, input_headroom: float | None = 8.0,
                    coef_frac: int | None = None, state_frac: int | None = None, state_bits: int | None = None,
                    **core_formats: Any) -> "TappedObserverBankSensorModel":
        """From a fitted bank sensor with taps (``sensor.lags_`` not None).

        Parameters
        ----------
        sensor : PWASVirtualSensor
            Fitted, with an observer-bank front end and u/y lag taps.
        input_bits, input_headroom, coef_frac, state_frac, state_bits, **core_formats
            As :meth:`ObserverBankSensorModel.from_sensor` (``input_bits``: ``B_in``, bits of the
            u / y codes and of the core's input codes).

        Returns
        -------
        TappedObserverBankSensorModel

        Raises
        ------
        InputError
            No observer-bank front end or no taps, fed-back estimates, several outputs, or
            impossible formats.
        """
        fe = getattr(sensor, "front_end_", None)
        lags = getattr(sensor, "lags_", None)
        if fe is None or lags is None:
            raise InputError("the model is not an observer-bank sensor with u/y taps")
        from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel, is_warped

        ins, outs, tgts = sensor.signal_names()
        fnames = fe.feature_names()
        tnames = lags.names(ins, outs, tgts)
        given = {k: v for k, v in core_formats.items() if v is not None}
        rmse = np.asarray(getattr(sensor, "train_rmse_", []), float).reshape(-1)
        rmse = rmse[np.isfinite(rmse) & (rmse > 0)]
        given.setdefault("reference_error", float(rmse.max()) if rmse.size else None)
        by_kind = {"u": ins, "y": outs}
        signals = [(nm, 0) for nm in fnames] + [(by_kind[k][ch], lag) for k, ch, lag in lags.signal_of_dimension()]
        # a non-uniform partition: the warp, then the uniform core; the features and the taps are
        # requantised to the warp's input codes (WarpInputFormat: the same lsb / offset rule)
        core_cls: Any = WarpedFixedPointModel if is_warped(sensor) else FixedPointModel
        core = core_cls(sensor.grid_, sensor.weights_, input_bits=input_bits, regressor_names=fnames + tnames,
                        regressor_signals=signals, target_names=tgts, **given)
        nf = len(fnames)
        bank = FixedPointObserverBank(fe, core.inputs[:nf], input_bits=input_bits,
                                      input_headroom=8.0 if input_headroom is None else input_headroom,
                                      coef_frac=coef_frac, state_frac=state_frac, state_bits=state_bits)
        taps = BankTaps(bank, lags, core.inputs[nf:])
        return cls(bank, core, taps, sensor)

    def trace(self, codes: np.ndarray) -> dict[str, np.ndarray]:
        """Bank trace, ``tap_codes`` (T, n_taps), and the core's ``out`` / ``out_of_range`` for rows ``k >= first_output``.

        Parameters
        ----------
        codes : ndarray of int, shape (T, nu + 1)
            Input codes of one trajectory from reset.

        Returns
        -------
        dict of str to ndarray
            :meth:`FixedPointObserverBank.trace` with ``tap_codes`` (T, n_taps), ``out``
            (T - first_output, nz) output codes and ``out_of_range`` (T - first_output,).
        """
        tr = self.bank.trace(codes)
        tr["tap_codes"] = self.taps.codes(codes)
        q = np.hstack([tr["feature_codes"], tr["tap_codes"]])[self.first_output :]
        out, oor = self.core.evaluate(q) if q.shape[0] else (np.zeros((0, self.core.nz), np.int64), np.zeros(0, bool))
        tr["out"], tr["out_of_range"] = out, oor
        return tr

    def reference(self, codes: np.ndarray) -> np.ndarray:
        """The float sensor (front end + taps + PWAS) at the physical signals the codes represent.

        Parameters
        ----------
        codes : ndarray of int, shape (T, nu + 1)
            Input codes of one trajectory from reset.

        Returns
        -------
        ndarray of float, shape (T - first_output, nz)
            Physical target units (needs the ``sensor`` the model was built from).
        """
        u, y = self.bank.represented_signals(codes)
        xi, _ = self.sensor.regressors([u] if self.bank.nu else None, [y])
        return self.sensor.predict_regressors(xi)

    def to_dict(self) -> dict:
        d = super().to_dict()
        d["taps"] = self.taps.to_dict()
        d["error_bound"]["taps"] = list(self.taps.error_bound)
        d["error_bound"]["rule"] = "core bound + sum_j G_j * (feature or tap) bound_j"
        d["first_output_sample"] = self.first_output
        return d
