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
from sklearn.base import BaseEstimator

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


class HLNNSensor(BaseEstimator):
    """HLNN virtual sensor on the PWAS regressor (a scikit-learn estimator).

    The hyper-parameters below are the ``__init__`` arguments, stored unchanged (``get_params`` /
    ``set_params``, ``sklearn.base.clone``) and checked by :meth:`fit`; fitted attributes end in ``_``.

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
    lags_ : LagStructure
    hidden_ : int
        The chosen hidden-layer size.
    val_rmse_ : dict
        Hidden size -> validation RMSE (target units, averaged over the targets).
    model_ : sklearn estimator
        The fitted network (standardised inputs and targets).
    nz_ : int
        Number of targets.
    """

    def __init__(self, mu: int = 0, my: int = 1, hidden_sizes: Sequence[int] = DEFAULT_HIDDEN_SIZES,
                 val_fraction: float = 0.2, restarts: int = 3, max_iter: int = 1000, alpha: float = 1e-4, seed: int = 0):
        self.mu = mu
        self.my = my
        self.hidden_sizes = hidden_sizes
        self.val_fraction = val_fraction
        self.restarts = restarts
        self.max_iter = max_iter
        self.alpha = alpha
        self.seed = seed

    def _check_params(self) -> tuple[int, ...]:
        """The hidden sizes as ints; :class:`InputError` for an impossible setting (before any work)."""
        for nm in ("mu", "my", "restarts", "max_iter", "seed"):
            v = getattr(self, nm)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < (1 if nm in ("restarts", "max_iter") else 0):
                raise InputError(f"{nm} must be an integer >= {1 if nm in ('restarts', 'max_iter') else 0}, got {v!r}")
        sizes = tuple(self.hidden_sizes) if self.hidden_sizes is not None else ()
        if not sizes or not all(isinstance(h, (int, np.integer)) and not isinstance(h, bool) and h >= 1 for h in sizes):
            raise InputError(f"hidden_sizes must be positive integers, got {self.hidden_sizes!r}")
        if not (isinstance(self.val_fraction, (int, float)) and 0 < self.val_fraction < 1):
            raise InputError(f"val_fraction must be in (0, 1), got {self.val_fraction!r}")
        return tuple(int(h) for h in sizes)

    def _xi(self, u, y, lags: LagStructure | None = None):
        us = as_trajectories(u, "u") if self.mu else []
        ys = as_trajectories(y, "y") if self.my else []
        if lags is None:
            lags = LagStructure(int(self.mu), int(self.my), us[0].shape[1] if us else 0, ys[0].shape[1] if ys else 0)
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

    def fit(self, u: np.ndarray | Sequence[np.ndarray] | None, y: np.ndarray | Sequence[np.ndarray] | None,
            z: np.ndarray | Sequence[np.ndarray]) -> "HLNNSensor":
        """Fit on trajectories (as :meth:`PWASVirtualSensor.fit <pwas_hdl.fit.virtual_sensor.PWASVirtualSensor.fit>`).

        Parameters
        ----------
        u : ndarray (T, nu), list of such, or None when ``mu == 0``
        y : ndarray (T, ny), list of such, or None when ``my == 0``
        z : ndarray (T,) or (T, nz), or list of such
            Targets, same sample times.

        Returns
        -------
        self
        """
        hidden_sizes = self._check_params()
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
        self.val_rmse_ = {h: self._best(h, xtr, ztr, xva, zva)[1] for h in hidden_sizes}
        self.hidden_ = min(self.val_rmse_, key=self.val_rmse_.get)
        # refit the chosen size on all the training data (restarts scored by their training error)
        self.model_, _ = self._best(self.hidden_, xi, target, xi, zt)
        self.lags_, self.nz_ = lags, nz
        return self

    def predict(self, u: np.ndarray | Sequence[np.ndarray] | None, y: np.ndarray | Sequence[np.ndarray] | None) -> np.ndarray:
        """Estimates ``(sum_i (T_i - M + 1), nz)``, rows ``t = M-1 .. T_i-1`` of each trajectory (target units).

        Parameters
        ----------
        u : ndarray (T, nu), list of such, or None when ``mu == 0``
            Inputs, as in :meth:`fit`.
        y : ndarray (T, ny), list of such, or None when ``my == 0``
            Measured outputs, as in :meth:`fit`.

        Returns
        -------
        numpy.ndarray
            Shape ``(sum_i (T_i - M + 1), nz)`` with ``M`` the regressor's lag depth: one row per
            complete regressor, trajectories in order, in the units of the fitted target.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            Before :meth:`fit`.
        """
        if not hasattr(self, "model_"):
            from sklearn.exceptions import NotFittedError

            raise NotFittedError("this HLNNSensor is not fitted yet; call fit() first")
        _, xi, _ = self._xi(u, y, self.lags_)
        return self.model_.predict(xi).reshape(xi.shape[0], self.nz_)
