"""Helpers shared by the system benches (three-tank, switched-linear, lorenz-hlnn).

* :func:`select_pwas` -- lags and partitions of a PWAS sensor chosen by validation on the training
  trajectories (the last ``holdout`` trajectories held out), then refitted on all of them;
* :func:`pwas_estimates` -- float and bit-true (default formats, 12-bit inputs) estimates of a
  fitted sensor on test trajectories, aligned to the samples ``t = M-1 .. T-1``;
* :func:`rmse` -- root mean square error over a boolean window.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.fixedpoint.bittrue import FixedPointModel

__all__ = ["PWASConfig", "QUICK_SIGMA_GRID", "select_pwas", "pwas_estimates", "rmse", "fit_pwas"]


@dataclass(frozen=True)
class PWASConfig:
    """One candidate: lags, partitions per dimension, domain expansion, Tikhonov order."""

    mu: int
    my: int
    p: int
    gamma: float = 1.1
    tikhonov: int = 0

    def label(self) -> str:
        return f"Mu={self.mu} My={self.my} p={self.p}"


#: Sigma candidates of the ``--quick`` smoke runs (the full runs use the default 21-value grid).
QUICK_SIGMA_GRID = tuple(float(v) for v in np.logspace(-6, 2, 5))


def fit_pwas(cfg: PWASConfig, us: Sequence[np.ndarray] | None, ys: Sequence[np.ndarray], zs: Sequence[np.ndarray],
             names: dict | None = None, sigma_grid: Sequence[float] | None = None, sigma: float | None = None) -> PWASVirtualSensor:
    """Fit one PWAS sensor on trajectories: sigma by 5-fold CV on contiguous blocks over ``sigma_grid``, or ``sigma``."""
    names = names or {}
    extra: dict = {"sigma_grid": list(sigma_grid)} if sigma_grid is not None else {}
    if sigma is not None:
        extra["sigma"] = float(sigma)
    m = PWASVirtualSensor(mu=cfg.mu, my=cfg.my, partitions=cfg.p, gamma=cfg.gamma, tikhonov_order=cfg.tikhonov,
                          input_names=names.get("u"), output_names=names.get("y"), target_names=names.get("z"), **extra)
    return m.fit(list(us) if (us is not None and cfg.mu) else None, list(ys), list(zs))


def rmse(err: np.ndarray, window: np.ndarray | None = None) -> float:
    """``sqrt(mean(err[window]**2))`` over all columns."""
    e = np.asarray(err, dtype=float)
    if window is not None:
        e = e[np.asarray(window, dtype=bool)]
    return float(np.sqrt(np.mean(e**2)))


def select_pwas(
    candidates: Sequence[PWASConfig],
    us: Sequence[np.ndarray],
    ys: Sequence[np.ndarray],
    zs: Sequence[np.ndarray],
    holdout: int,
    names: dict | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[PWASConfig, dict[str, float]]:
    """The candidate with the lowest RMSE on the last ``holdout`` trajectories (fit on the others).

    Returns the chosen configuration and the validation RMSE of every candidate (by label).
    """
    if holdout < 1 or holdout >= len(ys):
        raise ValueError(f"holdout must be in 1..{len(ys) - 1}, got {holdout}")
    scores: dict[str, float] = {}
    for cfg in candidates:
        tr = slice(None, -holdout)
        va = slice(-holdout, None)
        m = fit_pwas(cfg, us[tr] if us is not None else None, ys[tr], zs[tr], names)
        zh = m.predict(list(us[va]) if cfg.mu else None, list(ys[va]))
        lag = m.lags_.memory - 1
        truth = np.concatenate([z[lag:] for z in zs[va]], axis=0)
        scores[cfg.label()] = rmse(zh - truth)
        if progress:
            progress(f"  validation {cfg.label()}: RMSE {scores[cfg.label()]:.4g}")
    best = min(candidates, key=lambda c: scores[c.label()])
    return best, scores


def pwas_estimates(model: PWASVirtualSensor, u: np.ndarray | None, y: np.ndarray, **fixed) -> dict[str, np.ndarray]:
    """Float and bit-true estimates of one test trajectory, NaN-padded to its T samples.

    ``fixed`` are :class:`~pwas_hdl.fixedpoint.bittrue.FixedPointModel` options (default formats,
    12-bit inputs). Returns ``float`` and ``bittrue`` (T, nz) and ``out_of_domain`` (T,) (float
    model clamp flag or bit-true input saturation / out of range).
    """
    xi, _ = model.regressors(u if model.lags_.nu else None, y)
    zf, flag_f = model.predict_regressors(xi, return_flags=True)
    fp = FixedPointModel.from_sensor(model, **fixed)
    zb, flag_b = fp.predict(xi, return_flags=True)
    T, lag, nz = len(y), model.lags_.memory - 1, zf.shape[1]
    out = {"float": np.full((T, nz), np.nan), "bittrue": np.full((T, nz), np.nan), "out_of_domain": np.zeros(T, dtype=bool)}
    out["float"][lag:] = zf
    out["bittrue"][lag:] = zb
    out["out_of_domain"][lag:] = flag_f | flag_b
    out["fixed_point"] = fp
    return out
