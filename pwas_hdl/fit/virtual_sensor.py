"""The PWAS virtual sensor: fit / predict in the scikit-learn manner, and its model file.

A :class:`PWASVirtualSensor` estimates ``nz`` unmeasured quantities ``z(t)`` from the last ``Mu``
inputs and ``My`` outputs (paper eq. 2). All targets share one :class:`~pwas_hdl.fit.geometry.Grid`;
each has its own weight vector (componentwise fit).

Model file (``.json``, format ``pwas-hdl-model``, version 1) -- see ``docs`` in the README::

    {
      "format": "pwas-hdl-model", "version": 1,
      "signals": {"inputs": [...], "outputs": [...], "targets": [...]},
      "lags": {"Mu": int, "My": int},
      "regressors": ["y[t-3]", ...],                 # order of the regressor dimensions
      "grid": {"lo": [...], "hi": [...], "partitions": [...]},
      "weights": {"<target>": [w_0, ..., w_{N-1}], ...},   # vertex order of pwas_hdl.fit.geometry
      "fit": {"sigma": ..., "tikhonov_order": ..., "gamma": ..., "cv": {...} | null, ...}
    }

Floats are written with Python's shortest round-trip representation, so save/load is bit-exact.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from pwas_hdl.io.atomic import atomic_write_text
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.regressors import LagStructure, as_trajectories
from pwas_hdl.fit.regularized_lsq import CVResult, cross_validate_sigma, solve_regularized, tikhonov_matrix

__all__ = ["PWASVirtualSensor", "MODEL_FORMAT", "MODEL_VERSION", "load_model"]

MODEL_FORMAT = "pwas-hdl-model"
MODEL_VERSION = 1

Trajectories = np.ndarray | Sequence[np.ndarray] | None


class PWASVirtualSensor:
    """Piecewise-affine simplicial virtual sensor.

    Parameters
    ----------
    mu : int
        Number of past input samples ``Mu >= 0`` in the regressor (0: inputs unused).
    my : int
        Number of past output samples ``My >= 0``.
    partitions : int or sequence of int
        Intervals ``p_j >= 1`` per regressor dimension (one int for all).
    gamma : float
        Domain expansion factor ``>= 1`` about the centre of the data box (Section V-B).
        Ignored when ``domain`` is given.
    sigma : float or None
        Tikhonov weight of eq. (14), unnormalised. ``None``: choose by k-fold cross-validation.
    tikhonov_order : {0, 1}
        Zero-order (``Gamma = I``) or first-order (gradient) regularisation.
    cv_folds : int
        Folds of the cross-validation.
    sigma_grid : sequence of float, optional
        Candidates for the cross-validation.
    cv_shuffle : bool
        Shuffle samples across folds (default: contiguous blocks).
    domain : (lo, hi), optional
        Explicit domain bounds, each of shape (n,), physical units.
    share_lag_domain : bool
        When the domain comes from data, give every lag of one signal the same interval (the
        union of their ranges) so that the hardware scales each signal once. With ``False`` each
        regressor dimension gets its own data range.
    input_names, output_names, target_names : sequence of str, optional
        Signal names (stored in the model file; used by the CLI and the generator).

    Attributes (after ``fit``)
    --------------------------
    grid_ : Grid
    weights_ : ndarray, shape (N, nz)
    sigma_ : float
    cv_ : CVResult or None
    lags_ : LagStructure
    n_train_ : int  (number of regressor rows used)
    """

    def __init__(
        self,
        mu: int = 0,
        my: int = 1,
        partitions: int | Sequence[int] = 7,
        gamma: float = 1.2,
        sigma: float | None = None,
        tikhonov_order: int = 0,
        cv_folds: int = 5,
        sigma_grid: Sequence[float] | None = None,
        cv_shuffle: bool = False,
        domain: tuple[Sequence[float], Sequence[float]] | None = None,
        share_lag_domain: bool = True,
        input_names: Sequence[str] | None = None,
        output_names: Sequence[str] | None = None,
        target_names: Sequence[str] | None = None,
    ):
        self.mu = mu
        self.my = my
        self.partitions = partitions
        self.gamma = gamma
        self.sigma = sigma
        self.tikhonov_order = tikhonov_order
        self.cv_folds = cv_folds
        self.sigma_grid = sigma_grid
        self.cv_shuffle = cv_shuffle
        self.domain = domain
        self.share_lag_domain = share_lag_domain
        self.input_names = input_names
        self.output_names = output_names
        self.target_names = target_names

    # ------------------------------------------------------------ validation
    def _check_params(self) -> None:
        if not (isinstance(self.gamma, (int, float)) and math.isfinite(self.gamma) and self.gamma >= 1):
            raise ValueError(f"gamma must be a number >= 1 (domain expansion factor), got {self.gamma!r}")
        if self.sigma is not None and not (
            isinstance(self.sigma, (int, float, np.floating)) and math.isfinite(self.sigma) and self.sigma > 0
        ):
            raise ValueError(f"sigma must be a positive number or None (cross-validation), got {self.sigma!r}")
        if self.tikhonov_order not in (0, 1):
            raise ValueError(f"tikhonov_order must be 0 or 1, got {self.tikhonov_order!r}")

    # ------------------------------------------------------------------ fit
    def regressors(self, u: Trajectories, y: Trajectories) -> tuple[np.ndarray, list[slice]]:
        """Stacked regressors of the trajectories (see :mod:`pwas_hdl.fit.regressors`).

        Uses the fitted lag structure when the sensor is fitted, else the one implied by the data.
        """
        lags = self.lags_ if hasattr(self, "lags_") else self._infer_lags(u, y)
        return self._build_regressors(lags, u, y)

    @staticmethod
    def _build_regressors(lags: LagStructure, u: Trajectories, y: Trajectories) -> tuple[np.ndarray, list[slice]]:
        us = as_trajectories(u, "u", lags.nu) if lags.nu else []
        ys = as_trajectories(y, "y", lags.ny) if lags.ny else []
        if us and ys and len(us) != len(ys):
            raise ValueError(f"got {len(us)} input trajectories but {len(ys)} output trajectories")
        return lags.build_many(us, ys, max(len(us), len(ys)))

    def _infer_lags(self, u: Trajectories, y: Trajectories) -> LagStructure:
        us = as_trajectories(u, "u")
        ys = as_trajectories(y, "y")
        if self.mu and not us:
            raise ValueError(f"Mu = {self.mu} input lags requested but no input data given; pass u or set mu=0")
        if self.my and not ys:
            raise ValueError(f"My = {self.my} output lags requested but no output data given; pass y or set my=0")
        nu = us[0].shape[1] if us and self.mu else 0
        ny = ys[0].shape[1] if ys and self.my else 0
        return LagStructure(int(self.mu), int(self.my), nu, ny)

    def _data_domain(self, xi: np.ndarray, lags: LagStructure) -> tuple[np.ndarray, np.ndarray]:
        lo = xi.min(axis=0)
        hi = xi.max(axis=0)
        if self.share_lag_domain:
            dims = lags.signal_of_dimension()
            for signal in sorted({(kind, ch) for kind, ch, _ in dims}):
                idx = [j for j, (kind, ch, _) in enumerate(dims) if (kind, ch) == signal]
                lo[idx] = lo[idx].min()
                hi[idx] = hi[idx].max()
        const = np.flatnonzero(hi <= lo)
        if const.size:
            names = [self._regressor_names(lags)[j] for j in const]
            raise ValueError(
                f"regressor(s) {', '.join(names)} are constant in the training data (zero-width domain); "
                "remove the constant signal, add excitation, or pass an explicit domain"
            )
        centre = 0.5 * (lo + hi)
        half = 0.5 * (hi - lo) * self.gamma
        return centre - half, centre + half

    def _regressor_names(self, lags: LagStructure) -> list[str]:
        ins = list(self.input_names) if self.input_names else [f"u{i}" for i in range(lags.nu)]
        outs = list(self.output_names) if self.output_names else [f"y{i}" for i in range(lags.ny)]
        return lags.names(ins, outs)

    def fit(
        self,
        u: Trajectories,
        y: Trajectories,
        z: Trajectories,
        progress: Callable[[int, int], None] | None = None,
    ) -> "PWASVirtualSensor":
        """Fit the weights by regularised least squares (eqs. 14-16).

        Parameters
        ----------
        u : ndarray (T, nu), list of such (one per trajectory), or None when ``mu == 0``
            Measured inputs.
        y : ndarray (T, ny), list of such, or None when ``my == 0``
            Measured outputs.
        z : ndarray (T,) or (T, nz), or list of such
            The quantity to estimate, measured during the experiment (same sample times).
        progress : callable(done, total), optional
            Called during cross-validation.

        Returns
        -------
        self
        """
        self._check_params()
        # Everything is computed into locals first: a fit that fails leaves a previous fit intact.
        lags = self._infer_lags(u, y)
        xi, valid = self._build_regressors(lags, u, y)
        zs = as_trajectories(z, "z")
        if len(zs) != len(valid):
            raise ValueError(f"got {len(zs)} target trajectories for {len(valid)} input/output trajectories")
        for i, (zi, sl) in enumerate(zip(zs, valid)):
            if zi.shape[0] != sl.stop:
                raise ValueError(
                    f"target trajectory {i} has {zi.shape[0]} samples but its inputs/outputs have {sl.stop}; "
                    "u, y and z must be sampled at the same instants"
                )
        zt = np.concatenate([zi[sl] for zi, sl in zip(zs, valid)], axis=0)
        nz = zt.shape[1]
        if self.target_names is not None and len(self.target_names) != nz:
            raise ValueError(f"{len(self.target_names)} target names for {nz} target columns")
        if self.domain is not None:
            lo, hi = (np.asarray(b, dtype=float).reshape(-1) for b in self.domain)
            if lo.size != lags.dimension or hi.size != lags.dimension:
                raise ValueError(f"explicit domain must have {lags.dimension} bounds per side, got {lo.size} and {hi.size}")
        else:
            lo, hi = self._data_domain(xi, lags)
        grid = Grid(lo, hi, self.partitions)
        h = grid.basis_matrix(xi)
        gam = tikhonov_matrix(grid, self.tikhonov_order)
        if self.sigma is None:
            cv = cross_validate_sigma(h, zt, gam, self.sigma_grid, self.cv_folds, self.cv_shuffle, progress=progress)
            sigma = cv.best_sigma
        else:
            cv, sigma = None, float(self.sigma)
        w = solve_regularized(h, zt, sigma, gam).reshape(grid.n_vertices, nz)
        resid = zt - h @ w
        self.lags_ = lags
        self.grid_ = grid
        self.weights_ = w
        self.sigma_ = sigma
        self.cv_ = cv
        self.n_train_ = int(xi.shape[0])
        self.train_rmse_ = np.sqrt(np.mean(resid**2, axis=0))
        self.n_trajectories_ = len(valid)
        return self

    # -------------------------------------------------------------- predict
    def _check_fitted(self) -> None:
        if not hasattr(self, "weights_"):
            from sklearn.exceptions import NotFittedError  # a ValueError; imported here: sklearn is slow to import

            raise NotFittedError("this PWASVirtualSensor is not fitted yet; call fit() or load a model first")

    def predict_regressors(self, xi: np.ndarray, return_flags: bool = False):
        """Evaluate the PWAS function at regressor vectors.

        Parameters
        ----------
        xi : ndarray, shape (m, n)
        return_flags : bool
            Also return the out-of-domain flag of each row (True where a coordinate was clamped).

        Returns
        -------
        zhat : ndarray, shape (m, nz)
        flags : ndarray, shape (m,), bool  (only with ``return_flags``)
        """
        self._check_fitted()
        loc = self.grid_.locate(xi)
        zhat = np.einsum("mk,mkz->mz", loc.mu, self.weights_[loc.vertices])
        return (zhat, loc.out_of_domain) if return_flags else zhat

    def predict(self, u: Trajectories, y: Trajectories, return_flags: bool = False):
        """Estimate ``z`` for every sample that has a full regressor.

        Parameters
        ----------
        u, y : as in :meth:`fit`
        return_flags : bool
            Also return the out-of-domain flags.

        Returns
        -------
        zhat : ndarray, shape (sum_i (T_i - M + 1), nz)
            Row blocks per trajectory, sample ``t = M-1 .. T_i-1``.
        flags : ndarray of bool (only with ``return_flags``)
        """
        self._check_fitted()
        xi, _ = self.regressors(u, y)
        return self.predict_regressors(xi, return_flags)

    # ----------------------------------------------------------- properties
    @property
    def n_inputs(self) -> int:
        self._check_fitted()
        return self.lags_.nu

    @property
    def n_outputs(self) -> int:
        self._check_fitted()
        return self.lags_.ny

    @property
    def n_targets(self) -> int:
        self._check_fitted()
        return int(self.weights_.shape[1])

    def signal_names(self) -> tuple[list[str], list[str], list[str]]:
        """Names of (inputs, outputs, targets), defaults ``u0.., y0.., z0..``."""
        self._check_fitted()
        ins = list(self.input_names) if self.input_names else [f"u{i}" for i in range(self.lags_.nu)]
        outs = list(self.output_names) if self.output_names else [f"y{i}" for i in range(self.lags_.ny)]
        tgts = list(self.target_names) if self.target_names else [f"z{i}" for i in range(self.n_targets)]
        return ins, outs, tgts

    # ------------------------------------------------------------ save/load
    def to_dict(self) -> dict:
        """The model-file content as a JSON-ready dict."""
        self._check_fitted()
        ins, outs, tgts = self.signal_names()
        return {
            "format": MODEL_FORMAT,
            "version": MODEL_VERSION,
            "signals": {"inputs": ins, "outputs": outs, "targets": tgts},
            "lags": {"Mu": int(self.lags_.mu), "My": int(self.lags_.my)},
            "regressors": self._regressor_names(self.lags_),
            "grid": {
                "lo": [float(v) for v in self.grid_.lo],
                "hi": [float(v) for v in self.grid_.hi],
                "partitions": [int(v) for v in self.grid_.partitions],
            },
            "weights": {t: [float(v) for v in self.weights_[:, i]] for i, t in enumerate(tgts)},
            "fit": {
                "sigma": float(self.sigma_),
                "sigma_given": self.sigma is not None,
                "tikhonov_order": int(self.tikhonov_order),
                "gamma": float(self.gamma),
                "domain_from": "explicit" if self.domain is not None else "data",
                "share_lag_domain": bool(self.share_lag_domain),
                "n_train": int(self.n_train_),
                "n_trajectories": int(self.n_trajectories_),
                "train_rmse": {t: float(v) for t, v in zip(tgts, self.train_rmse_)},
                "cv": self.cv_.to_dict() if self.cv_ is not None else None,
            },
        }

    def save(self, path: str | os.PathLike) -> Path:
        """Write the model file atomically (nothing is left half-written on error)."""
        text = json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n"
        return atomic_write_text(path, text)

    @classmethod
    def from_dict(cls, d: dict, source: str = "model") -> "PWASVirtualSensor":
        """Rebuild a fitted sensor from the dict written by :meth:`to_dict`."""
        if not isinstance(d, dict) or d.get("format") != MODEL_FORMAT:
            raise ValueError(f"{source} is not a pwas-hdl model (missing \"format\": \"{MODEL_FORMAT}\")")
        if type(d.get("version")) is not int or d.get("version") != MODEL_VERSION:
            raise ValueError(
                f"{source} has model version {d.get('version')!r}, this pwas-hdl reads version {MODEL_VERSION}; "
                "re-run `pwas-hdl fit` to regenerate it"
            )
        try:
            sig, lags, g, fit = d["signals"], d["lags"], d["grid"], d["fit"]
            ins, outs, tgts = list(sig["inputs"]), list(sig["outputs"]), list(sig["targets"])
            grid = Grid(g["lo"], g["hi"], g["partitions"])
            w = np.array([d["weights"][t] for t in tgts], dtype=float).T.reshape(grid.n_vertices, len(tgts))
            obj = cls(
                mu=int(lags["Mu"]),
                my=int(lags["My"]),
                partitions=[int(p) for p in g["partitions"]],
                gamma=float(fit["gamma"]),
                sigma=float(fit["sigma"]) if fit.get("sigma_given") else None,
                tikhonov_order=int(fit["tikhonov_order"]),
                domain=(grid.lo, grid.hi) if fit.get("domain_from") == "explicit" else None,
                share_lag_domain=bool(fit.get("share_lag_domain", True)),
                input_names=ins,
                output_names=outs,
                target_names=tgts,
            )
            obj.lags_ = LagStructure(obj.mu, obj.my, len(ins) if obj.mu else 0, len(outs) if obj.my else 0)
            if obj.lags_.dimension != grid.n:
                raise ValueError(f"lags give n = {obj.lags_.dimension} but the grid has {grid.n} dimensions")
            if d["regressors"] != obj._regressor_names(obj.lags_):
                raise ValueError(f"regressors {d['regressors']} do not match the lags and signal names")
            sigma = float(fit["sigma"])
            cv = fit.get("cv")
            cv_res = (
                CVResult(np.array(cv["sigmas"]), np.array(cv["mse"]), float(cv["best_sigma"]), int(cv["folds"]))
                if cv
                else None
            )
            n_train = int(fit.get("n_train", 0))
            n_traj = int(fit.get("n_trajectories", 1))
            train_rmse = np.array([fit.get("train_rmse", {}).get(t, float("nan")) for t in tgts])
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise ValueError(f"{source} is corrupt or incomplete ({type(exc).__name__}: {exc}); re-run `pwas-hdl fit`") from exc
        if not np.all(np.isfinite(w)):
            raise ValueError(f"{source} has non-finite weights; re-run `pwas-hdl fit`")
        obj.grid_ = grid
        obj.weights_ = w
        obj.sigma_ = sigma
        obj.cv_ = cv_res
        obj.n_train_ = n_train
        obj.n_trajectories_ = n_traj
        obj.train_rmse_ = train_rmse
        return obj

    @classmethod
    def load(cls, path: str | os.PathLike) -> "PWASVirtualSensor":
        """Read a model file written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            The file does not exist.
        ValueError
            The file is not valid JSON, not a pwas-hdl model, of another version, or incomplete.
        """
        p = Path(path)
        try:
            text = p.read_text(encoding="utf-8")
        except UnicodeDecodeError as exc:
            raise ValueError(f"model file {p} is not UTF-8 text (corrupt?); re-run `pwas-hdl fit`") from exc
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"model file {p} is not valid JSON ({exc.msg} at line {exc.lineno}); it is corrupt or truncated, re-run `pwas-hdl fit`") from exc
        return cls.from_dict(d, source=f"model file {p}")


def load_model(path: str | os.PathLike) -> PWASVirtualSensor:
    """Shorthand for :meth:`PWASVirtualSensor.load`."""
    return PWASVirtualSensor.load(path)
