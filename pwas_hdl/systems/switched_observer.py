"""The virtual estimator of seed 003 (Morales-Morales et al. 2013) for switched linear systems.

* :func:`switched_observability_matrix` -- eq. (6): for a mode path ``theta_k .. theta_{k+N-1}``
  (dwell ``N_i`` in mode ``i``, concatenated without separation), the rows
  ``C(theta_{k+j}) A(theta_{k+j-1}) ... A(theta_k)``, ``j = 0..N-1``; the system is observable
  along the path when its rank is ``n`` (eq. 12 for the example of eq. 11: rank 2).
* :func:`observer_gains` -- the Luenberger gains of each mode by pole placement
  (``scipy.signal.place_poles`` on the dual pair; assumption **A4**: poles {0.3, 0.4}).
* :func:`run_switched_observer` -- the estimator of Fig. 2: the bank of per-mode models (8),
  the residual mode detector (9) read as ``theta_hat_k = argmin_i sum_{window} |y - C_i xhat^i|^2``
  (assumption **A3**; window 1 = the printed single-sample residual), and the switched Luenberger
  observer (10) driven by the detected mode. ``bank="literal"`` runs (8) as printed (open-loop
  models), ``bank="practical"`` (default) gives each model the output injection ``K_i`` (A3).
  ``known_mode=...`` gives the baseline of [18] (the same observer with the true mode).

Outputs are aligned with the plant samples: row ``k`` holds the estimate available at ``k``
(``xhat_k``, ``yhat_k = C(theta_hat_k) xhat_k`` and ``theta_hat_k``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.signal import place_poles

from pwas_hdl.errors import InputError
from pwas_hdl.systems.switched_linear import SWITCHED_A, SWITCHED_B, SWITCHED_C

__all__ = [
    "DEFAULT_POLES",
    "switched_observability_matrix",
    "observer_gains",
    "ObserverRun",
    "run_switched_observer",
    "mode_scores",
]

#: Observer poles of assumption A4 (seed_003.md §5).
DEFAULT_POLES = (0.3, 0.4)


def switched_observability_matrix(modes: Sequence[int], dwells: Sequence[int], A: Sequence[np.ndarray] = SWITCHED_A,
                                   C: Sequence[np.ndarray] = SWITCHED_C) -> np.ndarray:
    """The switched observability matrix ``O(theta^s_{N_s})`` of eq. (6).

    Parameters
    ----------
    modes : sequence of int (labels 1..s)
        Modes visited in order.
    dwells : sequence of int, same length
        Samples ``N_i`` spent in each (>= 1).
    A, C : sequence of numpy.ndarray
        Per-mode matrices, shapes (n, n) and (p, n) (a (n,) row for p = 1), index ``label - 1``
        (default: eq. (11)).

    Returns
    -------
    O : ndarray, shape (p * sum(dwells), n)
        The rows ``C(theta_{k+j}) A(theta_{k+j-1}) ... A(theta_k)`` along the path.
    """
    if len(modes) != len(dwells) or not modes:
        raise InputError("modes and dwells must be non-empty and of equal length")
    path = []
    for m, d in zip(modes, dwells):
        if not 1 <= int(m) <= len(A):
            raise InputError(f"mode {m} is not in 1..{len(A)}")
        if int(d) < 1:
            raise InputError(f"dwell must be >= 1, got {d}")
        path += [int(m)] * int(d)
    n = A[0].shape[0]
    prod = np.eye(n)
    rows = []
    for j, m in enumerate(path):
        rows.append(np.atleast_2d(C[m - 1]) @ prod)
        prod = A[m - 1] @ prod
    return np.vstack(rows)


def observer_gains(poles: Sequence[float] = DEFAULT_POLES, A: Sequence[np.ndarray] = SWITCHED_A,
                   C: Sequence[np.ndarray] = SWITCHED_C) -> tuple[np.ndarray, ...]:
    """Gains ``K_i`` (n,) with ``eig(A_i - K_i C_i) = poles`` for every mode (A4).

    Parameters
    ----------
    poles : sequence of float, length n
        Desired discrete-time closed-loop poles of every mode's error dynamics (dimensionless,
        inside the unit circle for a convergent observer).
    A, C : sequence of numpy.ndarray
        Per-mode matrices, shapes (n, n) and (1, n) or (n,) (one output), index ``label - 1``
        (default: eq. (11)).

    Returns
    -------
    tuple of numpy.ndarray
        One gain of shape (n,) per mode, in the order of ``A``.

    Raises
    ------
    InputError
        When ``scipy.signal.place_poles`` rejects the poles.
    """
    out = []
    for Ai, Ci in zip(A, C):
        Ci = np.atleast_2d(Ci)
        try:
            res = place_poles(Ai.T, Ci.T, np.asarray(poles, dtype=float))
        except ValueError as exc:
            raise InputError(f"pole placement failed for poles {list(poles)}: {exc}") from None
        out.append(res.gain_matrix.T.reshape(-1))
    return tuple(out)


@dataclass
class ObserverRun:
    """Result of :func:`run_switched_observer` (T samples).

    Attributes
    ----------
    x_hat : numpy.ndarray, shape (T, n)
        State estimates; row ``k`` is ``xhat_k``, available at sample k.
    y_hat : numpy.ndarray, shape (T,)
        Output estimates ``C(theta_hat_k) xhat_k``.
    theta_hat : numpy.ndarray of int, shape (T,)
        Detected (or given) mode labels 1..s.
    residuals : numpy.ndarray, shape (T, s)
        Detector residuals: per mode, the sum of ``|y - C_i xhat^i|^2`` over the window.
    """

    x_hat: np.ndarray
    y_hat: np.ndarray
    theta_hat: np.ndarray
    residuals: np.ndarray


def run_switched_observer(
    u: np.ndarray,
    y: np.ndarray,
    K: Sequence[np.ndarray] | None = None,
    known_mode: np.ndarray | None = None,
    bank: str = "practical",
    window: int = 1,
    x0_hat: ArrayLike | None = None,
    A: Sequence[np.ndarray] = SWITCHED_A,
    B: Sequence[np.ndarray] = SWITCHED_B,
    C: Sequence[np.ndarray] = SWITCHED_C,
) -> ObserverRun:
    """The virtual estimator of Fig. 2 (eqs. 8-10), or the known-mode baseline of [18].

    Parameters
    ----------
    u : numpy.ndarray, shape (T,) or (T, 1)
        Input, one value per sample.
    y : numpy.ndarray, shape (T,) or (T, 1)
        Measured output.
    K : sequence of numpy.ndarray, optional
        Per-mode gains, each shape (n,) (default :func:`observer_gains` with :data:`DEFAULT_POLES`).
    known_mode : numpy.ndarray of int, shape (T,), optional
        Mode labels 1..s to use instead of the detector (baseline [18]).
    bank : {"practical", "literal"}
        Per-mode observers with output injection, or the open-loop models of (8).
    window : int
        Samples in the detector's residual sum (A3; 1 = eq. 9 as printed).
    x0_hat : array_like, shape (n,), optional
        Initial estimate for the observer and the bank (default 0, A6).
    A, B, C : sequence of numpy.ndarray
        Per-mode matrices, shapes (n, n), (n,) and (n,) (one input, one output), index ``label - 1``
        (default: eq. (11)).

    Returns
    -------
    ObserverRun
        ``x_hat`` (T, n), ``y_hat`` (T,), ``theta_hat`` (T,), ``residuals`` (T, s), row k aligned
        with plant sample k.
    """
    u = np.asarray(u, dtype=float).reshape(-1)
    y = np.asarray(y, dtype=float).reshape(-1)
    if u.size != y.size:
        raise InputError(f"u has {u.size} samples and y {y.size}")
    if bank not in ("practical", "literal"):
        raise InputError(f"bank must be 'practical' or 'literal', got {bank!r}")
    if window < 1:
        raise InputError(f"window must be >= 1, got {window}")
    K = observer_gains(A=A, C=C) if K is None else K
    s, n, T = len(A), A[0].shape[0], y.size
    if known_mode is not None:
        known_mode = np.asarray(known_mode, dtype=int).reshape(-1)
        if known_mode.size != T or known_mode.min() < 1 or known_mode.max() > s:
            raise InputError(f"known_mode must have {T} labels in 1..{s}")
    x0 = np.zeros(n) if x0_hat is None else np.asarray(x0_hat, dtype=float).reshape(n)
    xh, bk = x0.copy(), np.tile(x0, (s, 1))
    Cs = [np.asarray(c, dtype=float).reshape(-1) for c in C]
    out_x, out_y, out_th, res = np.empty((T, n)), np.empty(T), np.empty(T, dtype=int), np.empty((T, s))
    sq = np.zeros((window, s))
    for k in range(T):
        r = np.array([y[k] - Cs[i] @ bk[i] for i in range(s)])
        sq[k % window] = r**2
        res[k] = sq.sum(axis=0) if k + 1 >= window else sq[: k + 1].sum(axis=0)
        th = int(known_mode[k]) if known_mode is not None else int(np.argmin(res[k])) + 1
        i = th - 1
        out_x[k], out_y[k], out_th[k] = xh, Cs[i] @ xh, th
        e = y[k] - Cs[i] @ xh
        xh = A[i] @ xh + B[i] * u[k] + K[i] * e  # (10)
        for j in range(s):  # (8)
            inj = K[j] * r[j] if bank == "practical" else 0.0
            bk[j] = A[j] @ bk[j] + B[j] * u[k] + inj
    return ObserverRun(out_x, out_y, out_th, res)


def mode_scores(true: np.ndarray, pred: np.ndarray, labels: Sequence[int] = (1, 2, 3)) -> dict:
    """Accuracy and per-mode F1 of mode labels: ``{"accuracy": a, "f1": {label: f1}}``.

    Parameters
    ----------
    true, pred : numpy.ndarray of int, shape (T,)
        True and detected mode labels.
    labels : sequence of int
        The labels scored (default the three modes of eq. (11)).

    Returns
    -------
    dict
        ``"accuracy"``: fraction of samples with ``pred == true`` (0..1); ``"f1"``: label -> F1 score (0..1).
    """
    from pwas_hdl.fit.classifier import class_scores

    sc = class_scores(true, pred, labels)
    return {"accuracy": sc["accuracy"], "f1": {int(c): v for c, v in zip(labels, sc["f1"])}}


def estimator_config(poles: Sequence[float] = DEFAULT_POLES, window: int = 1):
    """The estimator file content of this plant (:class:`pwas_hdl.fit.estimator_file.SwitchedEstimatorConfig`):
    eq. (11)'s ``A_i, B_i, C_i`` and the gains :func:`observer_gains` ``(poles)``, detector window ``window``."""
    from pwas_hdl.fit.estimator_file import SwitchedEstimatorConfig

    return SwitchedEstimatorConfig(list(SWITCHED_A), list(SWITCHED_B), list(SWITCHED_C), list(observer_gains(poles)), window=window,
                                   input_name="u", output_name="y", state_names=["x1", "x2"],
                                   source={"system": "switched-linear", "equation": "seed 003 eq. (11)",
                                           "poles": [float(p) for p in poles], "gains": "scipy.signal.place_poles (A4)"})
