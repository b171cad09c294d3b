"""Seed 004's learners and metrics: the predictors g_theta of eq. (8)-(9) and eq. (13).

The front end (local models, observer bank, feature maps) is the toolchain's
:mod:`pwas_hdl.fit.observer_bank`; this module holds what the paper puts on top of it
(Section 4.1, ``shared/design/seed-specs/seed_004.md`` 0.5-0.6):

* DTR, RFR: scikit-learn, ``max_depth = 15``, the forest with 10 trees;
* ANN: 2 x 30 ReLU + linear output, early stopping on a 5 % validation split. The paper uses Keras
  with AMSGrad; scikit-learn's ``MLPRegressor`` (Adam, no AMSGrad) is the substitute, with the
  features standardised first (A7: lr 1e-3, batch 64, patience 20);
* RFC (E2): ``RandomForestClassifier(n_estimators=10, max_depth=15)`` (B4);
* the minimum-distance classifier: mode ``i`` with the value nearest to the estimate;
* FIT (13a), NRMSE (13b) (both "higher is better"), per-mode F1.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pwas_hdl.errors import InputError

if TYPE_CHECKING:
    from sklearn.base import BaseEstimator

__all__ = ["make_predictor", "PREDICTORS", "fit_ratio", "nrmse", "min_distance_classify", "f1_per_mode"]

PREDICTORS = ("dtr", "rfr", "ann", "rfc")


def make_predictor(name: str, random_state: int = 0) -> BaseEstimator:
    """A fresh scikit-learn estimator with the paper's hyper-parameters.

    Parameters
    ----------
    name : {"dtr", "rfr", "ann", "rfc"}
        Decision-tree regressor, random-forest regressor, the 2 x 30 ReLU network, random-forest classifier.
    random_state : int
        Seed of the learner (bootstrap, weight initialisation, validation split).

    Returns
    -------
    sklearn.base.BaseEstimator
        Unfitted: ``DecisionTreeRegressor``, ``RandomForestRegressor``, ``RandomForestClassifier``, or
        for ``"ann"`` a ``Pipeline`` of ``StandardScaler`` and ``MLPRegressor``.
    """
    from sklearn.ensemble import RandomForestClassifier, RandomForestRegressor
    from sklearn.neural_network import MLPRegressor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.tree import DecisionTreeRegressor

    if name == "dtr":
        return DecisionTreeRegressor(max_depth=15, random_state=random_state)
    if name == "rfr":
        return RandomForestRegressor(n_estimators=10, max_depth=15, random_state=random_state, n_jobs=1)
    if name == "rfc":
        return RandomForestClassifier(n_estimators=10, max_depth=15, random_state=random_state, n_jobs=1)
    if name == "ann":
        return make_pipeline(
            StandardScaler(),
            MLPRegressor(hidden_layer_sizes=(30, 30), activation="relu", solver="adam", learning_rate_init=1e-3,
                         batch_size=64, early_stopping=True, validation_fraction=0.05, n_iter_no_change=20,
                         max_iter=500, random_state=random_state),
        )
    raise InputError(f"unknown predictor {name!r}; use one of {', '.join(PREDICTORS)}")


def _pair(true: np.ndarray, est: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(true, dtype=float).reshape(-1)
    e = np.asarray(est, dtype=float).reshape(-1)
    if t.shape != e.shape or t.size < 2:
        raise InputError(f"metric: true and estimated sequences must have the same length >= 2, got {t.size} and {e.size}")
    return t, e


def fit_ratio(true: np.ndarray, est: np.ndarray) -> float:
    """Eq. (13a): ``max{0, 1 - ||rho - rhohat|| / ||rho - mean(rho)||}`` (1 = perfect).

    Parameters
    ----------
    true, est : numpy.ndarray, shape (T,) (any shape, flattened; T >= 2, equal sizes)
        True and estimated sequences, same units.

    Returns
    -------
    float
        FIT in [0, 1] (dimensionless); NaN for a constant ``true``.
    """
    t, e = _pair(true, est)
    den = np.linalg.norm(t - t.mean())
    return float(max(0.0, 1.0 - np.linalg.norm(t - e) / den)) if den > 0 else float("nan")


def nrmse(true: np.ndarray, est: np.ndarray) -> float:
    """Eq. (13b): ``max{0, 1 - ||rho - rhohat|| / (sqrt(T) |max rho - min rho|)}`` (1 = perfect).

    Parameters
    ----------
    true, est : numpy.ndarray, shape (T,) (any shape, flattened; T >= 2, equal sizes)
        True and estimated sequences, same units.

    Returns
    -------
    float
        NRMSE score in [0, 1] (dimensionless); NaN for a constant ``true``.
    """
    t, e = _pair(true, est)
    den = np.sqrt(t.size) * abs(t.max() - t.min())
    return float(max(0.0, 1.0 - np.linalg.norm(t - e) / den)) if den > 0 else float("nan")


def min_distance_classify(est: np.ndarray, modes: np.ndarray) -> np.ndarray:
    """Index of the mode value nearest to each estimate (ties: the lower index), shape (T,).

    Parameters
    ----------
    est : numpy.ndarray, shape (T,) (any shape, flattened)
        Estimated scheduling parameter.
    modes : numpy.ndarray, shape (n_modes,)
        The mode values (e.g. :data:`~pwas_hdl.systems.pv_benchmark.MODES`), same units as ``est``.

    Returns
    -------
    numpy.ndarray of int, shape (T,)
        Index 0..n_modes-1 into ``modes`` per sample.
    """
    e = np.asarray(est, dtype=float).reshape(-1, 1)
    return np.argmin(np.abs(e - np.asarray(modes, dtype=float).reshape(1, -1)), axis=1)


def f1_per_mode(true_idx: np.ndarray, pred_idx: np.ndarray, n_modes: int) -> np.ndarray:
    """F1 score of each mode (``sklearn.metrics.f1_score(average=None)``), shape (n_modes,).

    Parameters
    ----------
    true_idx, pred_idx : numpy.ndarray of int, shape (T,) (any shape, flattened)
        True and predicted mode indices 0..n_modes-1.
    n_modes : int
        Number of modes; the labels scored are ``0 .. n_modes - 1``.

    Returns
    -------
    numpy.ndarray, shape (n_modes,)
        F1 per mode in [0, 1]; 0 for a mode absent from both sequences.
    """
    from sklearn.metrics import f1_score

    return f1_score(np.asarray(true_idx).reshape(-1), np.asarray(pred_idx).reshape(-1), labels=list(range(n_modes)),
                    average=None, zero_division=0.0)
