"""What every fixed-point PWAS model's constructor does first, written once.

Used by :class:`pwas_hdl.fixedpoint.bittrue.FixedPointModel` (one grid) and
:class:`pwas_hdl.fixedpoint.additive.AdditiveFixedPointModel` (a sum of parts on one box):

* :func:`weight_matrix`: the weights as an (N, nz) float array, checked;
* :func:`model_names`: regressor names, regressor signals ``(signal, lag)`` and target names, with
  their defaults (``x0..``, ``(name, 0)``, ``z0..``), checked against ``n`` and ``nz``;
* :func:`sensor_names`: those names of a fitted sensor (also used by
  :class:`pwas_hdl.fixedpoint.warp.WarpedFixedPointModel`), past estimates as ``<target>_hat``;
* :func:`input_code_arrays`: the per-regressor constants of the input formats as int64 arrays;
* :func:`output_reference`: the reference error that sets the output LSB, and where it came from.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence

import numpy as np

from pwas_hdl.errors import InputError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    from pwas_hdl.fixedpoint.formats import InputFormat

__all__ = ["weight_matrix", "model_names", "sensor_names", "input_code_arrays", "output_reference"]


def weight_matrix(weights: "ArrayLike", n_vertices: int) -> np.ndarray:
    """The weights as a float array of shape (N, nz) (a 1-D array is one target).

    Parameters
    ----------
    weights : array_like of float, shape (N, nz) or (N,)
        Vertex weights, the targets' physical units.
    n_vertices : int
        ``N``, the grid's vertices.

    Returns
    -------
    ndarray of float64, shape (N, nz)
        The weights (a copy only where the conversion needs one).

    Raises
    ------
    InputError
        Not N rows (``n_vertices``), no column, or NaN / infinite values.
    """
    w = np.asarray(weights, dtype=float)
    if w.ndim == 1:
        w = w[:, None]
    if w.ndim != 2 or w.shape[0] != n_vertices or w.shape[1] < 1:
        raise InputError(f"weights must have shape (N, nz) with N = {n_vertices}, got {np.shape(weights)}")
    if not np.all(np.isfinite(w)):
        raise InputError("weights contain NaN or infinite values; fit the model again or pass finite weights")
    return w


def sensor_names(sensor: "PWASVirtualSensor") -> tuple[list[str], list[tuple[str, int]], list[str]]:
    """``(regressor names, regressor signals, target names)`` of a fitted sensor.

    The fed-back estimates of a recurrent sensor (``Mz >= 1``) are the signal ``<target>_hat``
    (its dimensions named ``<target>_hat[t-k]``), so that their input format is their own, not an
    output's.

    Parameters
    ----------
    sensor : PWASVirtualSensor
        Fitted (``lags_`` and the signal names).

    Returns
    -------
    names : list of str
        ``n`` regressor names (:meth:`LagStructure.names <pwas_hdl.fit.regressors.LagStructure.names>`).
    signals : list of (str, int)
        ``n`` pairs ``(signal, lag)``, lag in samples.
    targets : list of str
        ``nz`` target names.
    """
    ins, outs, tgts = sensor.signal_names()
    lags = sensor.lags_
    by_kind = {"u": ins, "y": outs, "z": [f"{t}_hat" for t in tgts]}  # "z": fed-back estimates (issue 13)
    signals = [(by_kind[kind][ch], lag) for kind, ch, lag in lags.signal_of_dimension()]
    return lags.names(ins, outs, tgts), signals, list(tgts)


def model_names(n: int, nz: int, regressor_names: Sequence[str] | None, regressor_signals: Sequence[tuple[str, int]] | None,
                target_names: Sequence[str] | None) -> tuple[list[str], list[tuple[str, int]], list[str]]:
    """``(regressor names, regressor signals, target names)`` of a model with ``n`` regressors and ``nz`` targets.

    Defaults: ``x0 .. x{n-1}``; each regressor its own signal at lag 0; ``z0 .. z{nz-1}``.

    Parameters
    ----------
    n : int
        Regressors (grid dimensions).
    nz : int
        Targets.
    regressor_names : sequence of str, length n, optional
        Name of each regressor.
    regressor_signals : sequence of (str, int), length n, optional
        ``(signal, lag)`` of each regressor (lag in samples).
    target_names : sequence of str, length nz, optional
        Name of each target.

    Returns
    -------
    names : list of str
        ``n`` regressor names.
    signals : list of (str, int)
        ``n`` regressor signals ``(signal, lag)``.
    targets : list of str
        ``nz`` target names.

    Raises
    ------
    InputError
        A list of the wrong length.
    """
    names = list(regressor_names) if regressor_names is not None else [f"x{j}" for j in range(n)]
    signals = [(str(s), int(lag)) for s, lag in regressor_signals] if regressor_signals is not None else [(nm, 0) for nm in names]
    targets = list(target_names) if target_names is not None else [f"z{i}" for i in range(nz)]
    if len(names) != n or len(signals) != n:
        raise InputError(f"need {n} regressor names/signals, got {len(names)}/{len(signals)}")
    if len(targets) != nz:
        raise InputError(f"need {nz} target names, got {len(targets)}")
    return names, signals, targets


def input_code_arrays(inputs: "Sequence[InputFormat]") -> tuple[np.ndarray, ...]:
    """The constants of the input formats (:class:`~pwas_hdl.fixedpoint.formats.InputFormat`, one per
    regressor) as int64 arrays (n,): ``(lo_code, frac, input_span, scale_mul, scale_shift, min_code, max_code)``.

    Parameters
    ----------
    inputs : sequence of InputFormat, length n
        One input format per regressor.

    Returns
    -------
    tuple of 7 ndarray of int64, each shape (n,)
        ``lo_code`` (LSB), ``frac`` (bits), ``input_span`` (codes), ``scale_mul``, ``scale_shift``
        (bits), ``min_code``, ``max_code`` (LSB).
    """
    def col(get) -> np.ndarray:
        return np.array([get(f) for f in inputs], dtype=np.int64)

    return (col(lambda f: f.lo_code), col(lambda f: f.frac), col(lambda f: f.input_span), col(lambda f: f.scale_mul),
            col(lambda f: f.scale_shift), col(lambda f: f.format.min_code), col(lambda f: f.format.max_code))


def output_reference(reference_error: float | None, w: np.ndarray) -> tuple[float, str]:
    """The reference error of the output LSB and its source: ``reference_error`` when a positive
    finite number ("given"), else the weight range / 2**10 ("weight_range"), or 1.0 for constant
    weights ("constant_weights").

    Parameters
    ----------
    reference_error : float, optional
        The requested reference error (the targets' physical units).
    w : ndarray, shape (N, nz)
        The float weights (physical units).

    Returns
    -------
    reference : float
        The reference error, physical units.
    source : str
        ``"given"``, ``"weight_range"`` or ``"constant_weights"``.
    """
    if reference_error is not None and math.isfinite(reference_error) and reference_error > 0:
        return float(reference_error), "given"
    rng = float(w.max() - w.min())
    return (rng / 2**10, "weight_range") if rng > 0 else (1.0, "constant_weights")
