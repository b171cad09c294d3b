"""The one-hidden-layer neural network (HLNN) baseline of seed 000 (Poggi et al. 2012, [5]).

The paper compares its PWAS sensor with "HLNNs analogous to [5]" (Milanese et al. 2006) and
quotes the best one (Lorenz, Table II: RMSEE 24; helicopter, Table VI: six hidden neurons, 2.62)
without regressor, activation or training details. Assumption **A7** of ``seed_000.md``: the same
regressor as the PWAS (``pwas_hdl.fit.regressors.LagStructure``: ``Mu`` input and ``My`` output
lags, oldest first), one hidden layer of ``tanh`` units, a linear output, least-squares training
(scikit-learn ``MLPRegressor``, L-BFGS), inputs and target standardised, best of a few restarts.
The hidden size is chosen by validation: the last ``val_fraction`` of the training regressors
(a contiguous block: the samples are a time series) is held out, every size in
``hidden_sizes`` is trained on the rest, and the size with the lowest validation RMSE is refitted
on all the training data.
"""

from __future__ import annotations

import warnings
from typing import Sequence

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.fit.regressors import LagStructure, as_trajectories

__all__ = ["HLNNSensor", "DEFAULT_HIDDEN_SIZES"]

DEFAULT_HIDDEN_SIZES = (2, 4, 6, 8, 12, 16)


def _net(hidden: int, seed: int, max_iter: int, alpha: float):
    from sklearn.compose import TransformedTargetRegressor
    from sklearn.neural_network import MLPRegressor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    mlp = MLPRegressor(hidden_layer_sizes=(hidden,), activation="tanh", solver="lbfgs", alpha=alpha,
                       max_iter=max_iter, random_state=seed)
    return TransformedTargetRegressor(regressor=make_pipeline(StandardScaler(), mlp), transformer=StandardScaler())


class HLNNSensor:
    """HLNN virtual sensor on the PWAS regressor (scikit-learn style).

    Parameters
    ----------
    mu, my : int
        Input and output lags (as :class:`~pwas_hdl.fit.virtual_sensor.PWASVirtualSensor`).
    hidden_sizes : sequence of int
        Candidate hidden-layer sizes (validation picks one).
    val_fraction : float
        Share of the training regressors held out (the last contiguous block) to pick the size.
    restarts : int
        Random initialisations per size; the best on the validation block is kept.
    max_iter : int
        L-BFGS iterations.
    alpha : float
        L2 penalty of ``MLPRegressor``.
    seed : int
        Seed of the first restart (restart ``r`` uses ``seed + r``).

    Attributes
    ----------
    lags_ : LagStructure; hidden_ : int, the chosen size; val_rmse_ : dict size -> validation RMSE
    (target units, per target averaged); model_ : the fitted scikit-learn estimator.
    """

    def __init__(self, mu: int = 0, my: int = 1, hidden_sizes: Sequence[int] = DEFAULT_HIDDEN_SIZES,
                 val_fraction: float = 0.2, restarts: int = 3, max_iter: int = 1000, alpha: float = 1e-4, seed: int = 0):
        self.mu, self.my = int(mu), int(my)
        self.hidden_sizes = tuple(int(h) for h in hidden_sizes)
        self.val_fraction, self.restarts, self.max_iter, self.alpha, self.seed = val_fraction, restarts, max_iter, alpha, seed
        if not self.hidden_sizes or min(self.hidden_sizes) < 1:
            raise InputError(f"hidden_sizes must be positive integers, got {hidden_sizes!r}")
        if not 0 < val_fraction < 1:
            raise InputError(f"val_fraction must be in (0, 1), got {val_fraction}")
        if restarts < 1:
            raise InputError(f"restarts must be >= 1, got {restarts}")

    def _xi(self, u, y, lags: LagStructure | None = None):
        us = as_trajectories(u, "u") if self.mu else []
        ys = as_trajectories(y, "y") if self.my else []
        if lags is None:
            lags = LagStructure(self.mu, self.my, us[0].shape[1] if us else 0, ys[0].shape[1] if ys else 0)
        return lags, *lags.build_many(us, ys, max(len(us), len(ys)))

    def _best(self, hidden: int, xtr, ztr, xva, zva):
        best, best_rmse = None, np.inf
        for r in range(self.restarts):
            net = _net(hidden, self.seed + r, self.max_iter, self.alpha)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # L-BFGS iteration-limit warnings: the validation error decides
                net.fit(xtr, ztr)
            rmse = float(np.sqrt(np.mean((net.predict(xva).reshape(zva.shape) - zva) ** 2)))
            if rmse < best_rmse:
                best, best_rmse = net, rmse
        return best, best_rmse

    def fit(self, u, y, z) -> "HLNNSensor":
        """Fit on trajectories ``u`` (T, nu), ``y`` (T, ny), ``z`` (T, nz) (or lists of them)."""
        lags, xi, valid = self._xi(u, y)
        zs = as_trajectories(z, "z")
        zt = np.concatenate([zi[sl] for zi, sl in zip(zs, valid)], axis=0)
        nz = zt.shape[1]
        m = xi.shape[0]
        n_val = int(round(self.val_fraction * m))
        if n_val < 1 or m - n_val < 2:
            raise InputError(f"{m} training regressors are too few to hold out {self.val_fraction:.0%} for validation")
        target = zt[:, 0] if nz == 1 else zt
        xtr, xva, ztr, zva = xi[:-n_val], xi[-n_val:], target[:-n_val], zt[-n_val:]
        self.val_rmse_ = {h: self._best(h, xtr, ztr, xva, zva)[1] for h in self.hidden_sizes}
        self.hidden_ = min(self.val_rmse_, key=self.val_rmse_.get)
        # refit the chosen size on all the training data (restarts scored by their training error)
        self.model_, _ = self._best(self.hidden_, xi, target, xi, zt)
        self.lags_, self.nz_ = lags, nz
        return self

    def predict(self, u, y) -> np.ndarray:
        """Estimates ``(sum_i (T_i - M + 1), nz)``, rows ``t = M-1 .. T_i-1`` of each trajectory."""
        if not hasattr(self, "model_"):
            raise RuntimeError("this HLNNSensor is not fitted yet; call fit() first")
        _, xi, _ = self._xi(u, y, self.lags_)
        return self.model_.predict(xi).reshape(xi.shape[0], self.nz_)
