"""The PWAS virtual sensor: fit / predict in the scikit-learn manner, and its model file.

A :class:`PWASVirtualSensor` estimates ``nz`` unmeasured quantities ``z(t)`` from the last ``Mu``
inputs and ``My`` outputs (paper eq. 2). All targets share one :class:`~pwas_hdl.fit.geometry.Grid`;
each has its own weight vector (componentwise fit).

The model file (save / load) is owned by :mod:`pwas_hdl.fit.model_file`.
A sensor with the observer-bank front end (seed 004, :mod:`pwas_hdl.fit.observer_bank`) adds the
optional ``front_end`` object to the model file; its regressors are the bank's features followed
by the lag taps. Lag models have no ``front_end`` key.
"""

from __future__ import annotations

import copy
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin

from pwas_hdl.fit import model_file
from pwas_hdl.errors import InputError, option_text
from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.limits import MAX_SIGMA_CANDIDATES, check_limit, check_values, check_weights
from pwas_hdl.fit.geometry import BREAKPOINT_RULES, Grid, pow2_breakpoints, quantile_breakpoints
from pwas_hdl.fit.model_file import MODEL_FORMAT, MODEL_VERSION
from pwas_hdl.fit.classifier import class_labels, class_target_names, decide, one_hot
from pwas_hdl.fit.regressors import LagStructure, as_trajectories
from pwas_hdl.fit.regularized_lsq import (
    CVResult,
    check_fit_memory,
    cross_validate_sigma,
    solve_regularized,
    solve_report,
    tikhonov_matrix,
)

if TYPE_CHECKING:
    from pwas_hdl.flow.executor import Executor

__all__ = ["PWASVirtualSensor", "MODEL_FORMAT", "MODEL_VERSION", "load_model"]

Trajectories = np.ndarray | Sequence[np.ndarray] | None


class PWASVirtualSensor(RegressorMixin, BaseEstimator):
    """Piecewise-affine simplicial virtual sensor.

    A scikit-learn estimator: the hyper-parameters below are the ``__init__`` arguments, stored
    unchanged (``get_params`` / ``set_params``; ``sklearn.base.clone`` gives an unfitted copy);
    fitted attributes end in ``_``; :meth:`score` is the coefficient of determination R^2. Unlike
    a plain regressor it takes the signals ``(u, y)`` rather than a feature matrix: the regressors
    are built from their lags (use :meth:`predict_regressors` for ready-made regressors).

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
    front_end : "lags" or ObserverBankFrontEnd
        What the PWAS function is evaluated on. ``"lags"`` (default): the lag regressor above.
        An :class:`~pwas_hdl.fit.observer_bank.ObserverBankFrontEnd` (seed 004): its residual
        features followed by the lag taps ``u(t-Mu+1..t)``, ``y(t-My+1..t)`` (``Mu = My = 0``
        allowed: features only). The inputs feed the bank whatever ``mu`` is. The front end is
        fitted on a copy during :meth:`fit` (``front_end_``) and stored in the model file.
    mz : int
        Past estimates ``Mz >= 0`` fed back as regressors (issue 13, :mod:`pwas_hdl.fit.recurrent`):
        ``z_hat(t-Mz..t-1)`` of every target follow the lag taps. Fitted in series-parallel form
        (the measured ``z`` in those dimensions); :meth:`predict` runs the recurrence. Lag front
        end only.
    refine : int
        Closed-loop refinements ``K >= 0`` after the series-parallel fit (``Mz >= 1``): refit on
        regressors built from the simulated estimates while the closed-loop error improves.
    initial_state : "mean", "measured" or array_like
        The past estimates the recurrence starts from: ``"mean"`` (default) the training mean of
        each target, ``"measured"`` the measured ``z`` before the first estimate (``predict``
        then needs ``z``), or ``nz`` values (or (Mz, nz), oldest first).
    additive : str or sequence of sequences of int, optional
        Reduced-complexity additive sensor (:mod:`pwas_hdl.fit.additive`): ``f(x) = sum_i
        f_i(x_{S_i})``, one PWAS part per subset ``S_i`` of the regressor dimensions: ``"time"``
        (one part per time instant), ``"pairs"`` / ``"triples"`` (sliding windows of 2 / 3 lags),
        ``"0,1;1,2"`` or a list of index lists. The parts share the domain box and partitions;
        ``grid_`` is then an :class:`~pwas_hdl.fit.additive.AdditiveGrid` and ``weights_`` the
        stacked part weights. ``None`` (default): one PWAS function on all regressors. Lag
        regressors only (not with the observer-bank front end).
    breakpoints : None, "quantile", "quantile-pow2" or sequence of array_like
        Non-uniform partition (:mod:`pwas_hdl.fit.geometry`). None (default): equal intervals.
        ``"quantile"``: cuts at the ``k / p_j`` quantiles of the training regressors inside the
        domain (:func:`~pwas_hdl.fit.geometry.quantile_breakpoints`); ``"quantile-pow2"``: the
        same rounded to cells that are power-of-two multiples of a base step
        (:func:`~pwas_hdl.fit.geometry.pow2_breakpoints`). A sequence: one array of ``p_j + 1``
        strictly increasing cut points per regressor dimension, physical units; it fixes the
        domain (first and last cut) and the partitions (``domain`` and ``partitions`` are then
        not used). Same number of weights ``N`` as the uniform grid with the same partitions.
    classify : bool
        A PWAS classifier (:mod:`pwas_hdl.fit.classifier`): ``z`` is one column of class labels
        (numbers; at least 2 and at most 64 distinct values), fitted as one one-hot score per class on
        one shared grid (targets ``<label>=<k>``, ``<label>`` the one ``target_names`` entry or
        ``"z"``). :meth:`predict` returns the scores ``(T, C)``, :meth:`predict_class` the labels
        (argmax, ties to the lowest class); ``classifier_`` holds the label name and the classes.
        Lag front end, no feedback (``mz = 0``).

    Attributes (after ``fit``)
    --------------------------
    grid_ : Grid
    weights_ : ndarray, shape (N, nz)
    sigma_ : float
    cv_ : CVResult or None
    solve_ : dict or None
        How well ``weights_`` solve the regularised normal equations at ``sigma_``, checked afresh
        (:func:`~pwas_hdl.fit.regularized_lsq.solve_report`: relative residual, weight bound,
        converged, and the CV's unconverged solves); None for a dynamical sensor (``mz``), whose
        weights are refined in closed loop.
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
        front_end: str | ObserverBankFrontEnd = "lags",
        mz: int = 0,
        refine: int = 0,
        initial_state: str | Sequence[float] = "mean",
        additive: str | Sequence[Sequence[int]] | None = None,
        breakpoints: str | Sequence[Sequence[float]] | None = None,
        classify: bool = False,
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
        self.front_end = front_end
        self.mz = mz
        self.refine = refine
        self.initial_state = initial_state
        self.additive = additive
        self.breakpoints = breakpoints
        self.classify = classify

    # ------------------------------------------------------------ validation
    def _check_params(self) -> None:
        """Raise :class:`~pwas_hdl.errors.InputError` for an impossible hyper-parameter (before any work)."""
        for nm in ("mu", "my"):
            v = getattr(self, nm)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 0:
                raise InputError(f"{nm} must be a non-negative integer (number of past samples), got {v!r}")
        if not (isinstance(self.gamma, (int, float)) and math.isfinite(self.gamma) and self.gamma >= 1):
            raise InputError(f"{option_text('gamma')} must be a number >= 1 (domain expansion factor), got {self.gamma!r}")
        if self.sigma is not None and not (
            isinstance(self.sigma, (int, float, np.floating)) and math.isfinite(self.sigma) and self.sigma > 0
        ):
            raise InputError(f"{option_text('sigma')} must be a positive number, or None to choose it by cross-validation "
                             f"(leave --sigma out), got {self.sigma!r}")
        if self.tikhonov_order not in (0, 1):
            raise InputError(f"--tikhonov (tikhonov_order) must be 0 (Gamma = I) or 1 (gradient), got {self.tikhonov_order!r}")
        for nm in ("share_lag_domain", "cv_shuffle", "classify"):  # a string such as "no" would read as True
            if not isinstance(getattr(self, nm), (bool, np.bool_)):
                raise InputError(f"{nm} must be True or False, got {getattr(self, nm)!r}")
        if not isinstance(self.cv_folds, (int, np.integer)) or isinstance(self.cv_folds, bool) or self.cv_folds < 2:
            raise InputError(f"--folds (cv_folds) must be an integer >= 2, got {self.cv_folds!r}; give --folds 2 or more")
        if isinstance(self.front_end, ObserverBankFrontEnd):
            self.front_end.check_params()
        elif self.front_end != "lags":
            raise InputError(f"front_end must be 'lags' or an ObserverBankFrontEnd, got {self.front_end!r}")
        for nm in ("mz", "refine"):
            v = getattr(self, nm)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 0:
                raise InputError(f"{nm} must be a non-negative integer, got {v!r}")
        if self.mz and self._bank:
            raise InputError("mz >= 1 (past estimates as regressors) needs the lag front end, not the observer bank")
        if isinstance(self.initial_state, str) and self.initial_state not in ("mean", "measured"):
            raise InputError(f"initial_state must be 'mean', 'measured' or numbers, got {self.initial_state!r}")
        if self.additive is not None and self._bank:
            raise InputError("an additive sensor (--additive) needs the lag front end (--front-end lags)")
        if self.additive is not None and self.mz:
            raise InputError("an additive sensor (--additive) with past estimates (--mz) is not available yet; use one of them")
        if isinstance(self.breakpoints, str) and self.breakpoints not in BREAKPOINT_RULES:
            raise InputError(f"breakpoints must be None, {', '.join(BREAKPOINT_RULES)} or one list of cut points per "
                             f"regressor, got {self.breakpoints!r}")
        if self.breakpoints is not None and self.additive is not None:
            raise InputError("breakpoints (non-uniform partition) with an additive sensor is not available yet; use one of them")
        if self.classify and (self._bank or self.mz):
            raise InputError("classify (--classify) needs the lag front end and no past estimates (not "
                             "--front-end observer-bank, not --mz)")
        if self.classify and self.target_names is not None and len(self.target_names) != 1:
            raise InputError(f"a classifier has one label column: give one target name (the label's), got "
                             f"{list(self.target_names)}")
        if self.sigma_grid is not None and hasattr(self.sigma_grid, "__len__"):
            check_limit("the number of sigma candidates", len(self.sigma_grid), MAX_SIGMA_CANDIDATES,
                        "give fewer candidates (--sigma-grid)")

    def _make_grid(self, xi: np.ndarray, lo: np.ndarray, hi: np.ndarray, groups=None) -> Grid:
        """The partition of the fit: uniform, at data quantiles, or at the given breakpoints.

        ``groups``: dimensions whose quantile cuts are taken from their pooled samples (the lags of
        one signal with ``share_lag_domain``: one set of cuts per signal, so that the sensor top
        feeds one input code to all of them, :mod:`pwas_hdl.hdl.warp`)."""
        bp = self.breakpoints
        if bp is None:
            return Grid(lo, hi, self.partitions)
        if isinstance(bp, str):
            parts = Grid(lo, hi, self.partitions).partitions  # validated partitions
            rule = quantile_breakpoints if bp == "quantile" else pow2_breakpoints
            return Grid(lo, hi, parts, breakpoints=rule(xi, lo, hi, parts, groups=groups))
        rows = [np.asarray(b, dtype=float).reshape(-1) for b in bp]
        if len(rows) != xi.shape[1]:
            raise InputError(f"{len(rows)} breakpoint lists for n = {xi.shape[1]} regressors (one list per regressor)")
        for j, b in enumerate(rows):
            if b.size < 2:
                raise InputError(f"breakpoints of regressor {j} have {b.size} value(s); a dimension needs at least 2 (one interval)")
        try:
            return Grid([b[0] for b in rows], [b[-1] for b in rows], [b.size - 1 for b in rows], breakpoints=rows)
        except ValueError as exc:
            raise InputError(str(exc)) from exc

    @property
    def _bank(self) -> bool:
        """True when the regressor comes from an observer-bank front end."""
        return isinstance(self.front_end, ObserverBankFrontEnd)

    @property
    def memory(self) -> int:
        """Samples of history one estimate needs: estimates exist for ``t = memory - 1 .. T - 1``."""
        self._check_fitted()
        m = self.lags_.memory if self.lags_ is not None else 1
        return max(m, self.front_end_.memory) if getattr(self, "front_end_", None) is not None else m

    # ------------------------------------------------------------------ fit
    def regressors(self, u: Trajectories, y: Trajectories) -> tuple[np.ndarray, list[slice]]:
        """Stacked regressors of the trajectories (see :mod:`pwas_hdl.fit.regressors`).

        Uses the fitted lag structure when the sensor is fitted, else the one implied by the data.

        Parameters
        ----------
        u, y : as in :meth:`fit`

        Returns
        -------
        xi : ndarray, shape (sum_i (T_i - M + 1), n)
            Physical regressors, row blocks per trajectory (observer bank: its features, then the
            lag taps).
        valid : list of slice
            Per trajectory, the samples ``t`` that have a row: ``slice(M - 1, T_i)``.

        Raises
        ------
        InputError
            A recurrent sensor (``mz >= 1``): its regressors need its own estimates (use :meth:`predict`).
        """
        if self._bank:
            self._check_fitted()
            return self._bank_regressors(self.front_end_, self.lags_, u, y)
        lags = self.lags_ if hasattr(self, "lags_") else self._infer_lags(u, y)
        if lags is not None and lags.recurrent:
            raise InputError(
                f"this sensor is recurrent (Mz = {lags.mz}): its regressor holds its own past estimates, which only the "
                "recurrence produces; use predict() (or LagStructure.build_series_parallel with the measured z)"
            )
        return self._build_regressors(lags, u, y)

    def _bank_regressors(self, fe: ObserverBankFrontEnd, lags: LagStructure | None, u: Trajectories, y: Trajectories) -> tuple[np.ndarray, list[slice]]:
        """Observer-bank features, then the lag taps, aligned on the later start of the two."""
        us = as_trajectories(u, "u", fe.nu_ if hasattr(fe, "nu_") else None)
        ys = as_trajectories(y, "y", 1)
        feats, fvalid = fe.transform(us, ys)
        if lags is None:
            return feats, fvalid
        taps, tvalid = self._build_regressors(lags, u, y)
        start = max(fe.memory, lags.memory) - 1
        blocks, valid, fo, to = [], [], 0, 0
        for fv, tv in zip(fvalid, tvalid):
            fn, tn = fv.stop - fv.start, tv.stop - tv.start
            fb = feats[fo + start - fv.start : fo + fn]
            tb = taps[to + start - tv.start : to + tn]
            blocks.append(np.hstack([fb, tb]))
            valid.append(slice(start, fv.stop))
            fo, to = fo + fn, to + tn
        return np.concatenate(blocks), valid

    @staticmethod
    def _build_regressors(lags: LagStructure, u: Trajectories, y: Trajectories) -> tuple[np.ndarray, list[slice]]:
        us = as_trajectories(u, "u", lags.nu) if lags.nu else []
        ys = as_trajectories(y, "y", lags.ny) if lags.ny else []
        if us and ys and len(us) != len(ys):
            raise InputError(f"got {len(us)} input trajectories but {len(ys)} output trajectories")
        return lags.build_many(us, ys, max(len(us), len(ys)))

    def _infer_lags(self, u: Trajectories, y: Trajectories) -> LagStructure | None:
        us = as_trajectories(u, "u")
        ys = as_trajectories(y, "y")
        if self._bank:  # taps only; the bank itself takes every input channel
            nu = us[0].shape[1] if us else 0
            ny = ys[0].shape[1] if ys else 0
            if self.mu * nu + self.my * ny == 0:
                return None
            return LagStructure(int(self.mu), int(self.my), nu if self.mu else 0, ny if self.my else 0)
        if self.mu and not us:
            raise InputError(f"Mu = {self.mu} input lags requested but no input data given; pass u or set mu=0")
        if self.my and not ys:
            raise InputError(f"My = {self.my} output lags requested but no output data given; pass y or set my=0")
        nu = us[0].shape[1] if us and self.mu else 0
        ny = ys[0].shape[1] if ys and self.my else 0
        return LagStructure(int(self.mu), int(self.my), nu, ny)

    def _data_domain(self, xi: np.ndarray, lags: LagStructure | None, fe: ObserverBankFrontEnd | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The gamma-expanded data box; the bank's features (first columns) each get their own range."""
        n_feat = fe.n_features if fe is not None else 0
        lo = xi.min(axis=0)
        hi = xi.max(axis=0)
        if self.share_lag_domain and lags is not None:
            dims = lags.signal_of_dimension()
            for signal in sorted({(kind, ch) for kind, ch, _ in dims}):
                idx = [n_feat + j for j, (kind, ch, _) in enumerate(dims) if (kind, ch) == signal]
                lo[idx] = lo[idx].min()
                hi[idx] = hi[idx].max()
        const = np.flatnonzero(hi <= lo)
        if const.size:
            names = [self._regressor_names(lags, fe)[j] for j in const]
            raise InputError(
                f"regressor(s) {', '.join(names)} are constant in the training data (zero-width domain); "
                "remove the constant signal, add excitation, or pass an explicit domain"
            )
        # halves first (exact, so the same box as 0.5 * (lo + hi) +- 0.5 * (hi - lo) * gamma) and the
        # overflow of a huge gamma or a data range near the float limit checked here, not warned by numpy
        with np.errstate(over="ignore", invalid="ignore"):
            centre = 0.5 * lo + 0.5 * hi
            half = (0.5 * hi - 0.5 * lo) * self.gamma
            box_lo, box_hi = centre - half, centre + half
        wide = np.flatnonzero(~(np.isfinite(box_lo) & np.isfinite(box_hi)))
        if wide.size:
            name = self._regressor_names(lags, fe)[int(wide[0])]
            raise InputError(
                f"the domain of regressor {name} (the data range [{lo[wide[0]]:.6g}, {hi[wide[0]]:.6g}] expanded by "
                f"gamma = {self.gamma:g}) is wider than a float can hold; give a smaller gamma (--gamma), an explicit "
                "domain (--domain), or rescale the signal"
            )
        return box_lo, box_hi

    def _regressor_names(self, lags: LagStructure | None, fe: ObserverBankFrontEnd | None = None) -> list[str]:
        fe = fe if fe is not None else getattr(self, "front_end_", None)
        head = fe.feature_names() if fe is not None else []
        if lags is None:
            return head
        ins = list(self.input_names) if self.input_names else [f"u{i}" for i in range(lags.nu)]
        outs = list(self.output_names) if self.output_names else [f"y{i}" for i in range(lags.ny)]
        tgts = list(self.target_names) if self.target_names else [f"z{i}" for i in range(lags.nz)]
        return head + lags.names(ins, outs, tgts)

    def fit(
        self,
        u: Trajectories,
        y: Trajectories,
        z: Trajectories,
        progress: Callable[[int, int], None] | None = None,
        executor: "Executor | None" = None,
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
        executor : pwas_hdl.flow.executor.Executor, optional
            Runs the cross-validation folds on Dask workers when distributed (same result).

        Returns
        -------
        self
        """
        self._check_params()
        # Everything is computed into locals first: a fit that fails leaves a previous fit intact.
        lags = self._infer_lags(u, y)
        if z is None:
            raise InputError("z (the measured targets, (T, nz) or a list of such) is needed to fit; got None")
        zs = as_trajectories(z, "z")
        classifier = None
        if self.classify:  # one label column -> one one-hot score per class (pwas_hdl.fit.classifier)
            if any(zi.shape[1] != 1 for zi in zs):
                raise InputError(f"a classifier fits one label column; z has {zs[0].shape[1]} columns")
            classes = class_labels(np.concatenate([zi[:, 0] for zi in zs]))
            zs = [one_hot(zi[:, 0], classes) for zi in zs]
            classifier = {"target": self.target_names[0] if self.target_names else "z", "classes": classes}
        fe = None
        if self._bank:
            fe = copy.deepcopy(self.front_end)
            us, ys = as_trajectories(u, "u"), as_trajectories(y, "y")
            if len(zs) != len(ys):
                raise InputError(f"got {len(zs)} target trajectories for {len(ys)} output trajectories")
            fe.fit(us, ys, zs)
            xi, valid = self._bank_regressors(fe, lags, u, y)
        elif self.mz:
            lags, xi, valid, rec = self._series_parallel(lags, u, y, zs)
        else:
            xi, valid = self._build_regressors(lags, u, y)
        if len(zs) != len(valid):
            raise InputError(f"got {len(zs)} target trajectories for {len(valid)} input/output trajectories")
        for i, (zi, sl) in enumerate(zip(zs, valid)):
            if zi.shape[0] != sl.stop:
                raise InputError(
                    f"target trajectory {i} has {zi.shape[0]} samples but its inputs/outputs have {sl.stop}; "
                    "u, y and z must be sampled at the same instants"
                )
        zt = np.concatenate([zi[sl] for zi, sl in zip(zs, valid)], axis=0)
        nz = zt.shape[1]
        if self.target_names is not None and len(self.target_names) != nz and classifier is None:
            raise InputError(f"{len(self.target_names)} target names for {nz} target columns")
        for i in range(nz if classifier is None else 0):  # before the solve: its squared errors would overflow
            name = self.target_names[i] if self.target_names is not None else f"z{i}"
            check_values(f"the target {name!r}", zt[:, i], "rescale it (divide it by a power of ten)")
        # names the model file holds must match its signals, or load() refuses the file
        n_in = fe.nu_ if fe is not None else (lags.nu if lags is not None and lags.mu else None)
        n_out = 1 if fe is not None else (lags.ny if lags is not None and lags.my else None)
        for what, names, count in (("input", self.input_names, n_in), ("output", self.output_names, n_out)):
            if names and count is not None and len(names) != count:
                raise InputError(f"{len(names)} {what} names {list(names)} for {count} {what} column(s); give one name per "
                                 f"column of {'u' if what == 'input' else 'y'} (or None for the defaults)")
        if self.domain is not None:
            lo, hi = (np.asarray(b, dtype=float).reshape(-1) for b in self.domain)
            names = self._regressor_names(lags, fe)
            if lo.size != xi.shape[1] or hi.size != xi.shape[1]:
                raise InputError(f"{option_text('domain')} gives {lo.size} lower and {hi.size} upper bound(s) for "
                                 f"{xi.shape[1]} regressors ({', '.join(names)}); give one lo:hi per regressor, in that order")
            bad = np.flatnonzero(np.isfinite(lo) & np.isfinite(hi) & ~(hi > lo))  # non-finite: the Grid's message
            if bad.size:
                j = int(bad[0])
                raise InputError(f"{option_text('domain')}: the interval of regressor {names[j]} is {float(lo[j])!r}:{float(hi[j])!r}, "
                                 "empty or reversed; give lo < hi")
        else:
            lo, hi = self._data_domain(xi, lags, fe)
        if self.additive is not None:  # sum of PWAS parts on regressor subsets (pwas_hdl.fit.additive)
            from pwas_hdl.fit.additive import AdditiveGrid, additive_tikhonov_matrix, parse_additive

            grid = AdditiveGrid(lo, hi, self.partitions, parse_additive(self.additive, lags.signal_of_dimension()))
            basis_dims = grid.basis_dims
        else:
            groups = None  # one set of quantile cuts per signal when its lags share the domain
            if self.share_lag_domain and lags is not None and fe is None:
                sod = lags.signal_of_dimension()
                groups = [[j for j, d in enumerate(sod) if d[:2] == key] for key in dict.fromkeys(d[:2] for d in sod)]
            grid = self._make_grid(xi, lo, hi, groups)
            basis_dims = grid.n
        # refuse (ResourceLimit) before H, H'H or a factor is allocated; limit: $PWAS_HDL_MAX_MEMORY
        # or a fraction of the available RAM (see pwas_hdl.fit.regularized_lsq.check_fit_memory)
        check_weights(grid.n_vertices, nz)
        check_fit_memory(xi.shape[0], grid.n_vertices, basis_dims, nz, int(self.tikhonov_order),
                         grid_side=max(grid.shape) if self.additive is None else None)
        h = grid.basis_matrix(xi)
        gam = (additive_tikhonov_matrix(grid, self.tikhonov_order) if self.additive is not None
               else tikhonov_matrix(grid, self.tikhonov_order))
        method = "auto"
        if self.additive is not None:  # first order: the factorisation (CG does not converge, see the module)
            from pwas_hdl.fit.additive import additive_solver_method

            method = additive_solver_method(grid, self.tikhonov_order)
        if self.sigma is None:
            cv = cross_validate_sigma(h, zt, gam, self.sigma_grid, self.cv_folds, self.cv_shuffle, progress=progress,
                                      executor=executor, method=method, final_solve=True)
            sigma = cv.best_sigma
            # the full-data solve by the CV's own solver (= solve_regularized, without a second H'H / analysis)
            info = cv.final_info
            w, cv.final_weights, cv.final_info = cv.final_weights.reshape(grid.n_vertices, nz), None, None
        else:
            cv, sigma = None, float(self.sigma)
            w, info = solve_regularized(h, zt, sigma, gam, method=method, return_info=True)
            w = w.reshape(grid.n_vertices, nz)
        # the solve checked afresh from the weights (residual, weight bound); a dynamical sensor's
        # weights are then refined in closed loop and solve another system: no report there
        solve = None if self.mz else solve_report(h, zt, w, sigma, gam, info, cv)
        rec_info = None
        if self.mz:
            from pwas_hdl.fit.recurrent import refine_closed_loop

            sp_rmse = np.sqrt(np.mean((zt - h @ w) ** 2, axis=0))
            w, rec_info = refine_closed_loop(
                grid, grid.basis_matrix, lambda hh: solve_regularized(hh, zt, sigma, gam).reshape(grid.n_vertices, nz),
                w, rec["io"], rec["z"], rec["z_init"], lags.mz, int(self.refine))
            rec_info["series_parallel_rmse"] = sp_rmse
            rec_info["initial"] = self._initial_values(zs, lags)
        resid = zt - h @ w
        # forget every fitted attribute of a previous fit or load (recurrence_, classifier_, map_fit_, ...):
        # this fit sets its own, and a stale one would describe another model (and be written to its file)
        for key in [k for k in vars(self) if k.endswith("_") and not k.startswith("_")]:
            delattr(self, key)
        self.lags_ = lags
        self.front_end_ = fe
        self.nu_ = fe.nu_ if fe is not None else lags.nu
        self.ny_ = 1 if fe is not None else lags.ny
        self.grid_ = grid
        self.weights_ = w
        self.sigma_ = sigma
        self.cv_ = cv
        self.solve_ = solve
        self.n_train_ = int(xi.shape[0])
        self.train_rmse_ = np.sqrt(np.mean(resid**2, axis=0))
        self.n_trajectories_ = len(valid)
        self.lead_ = 0
        if classifier is not None:
            self.classifier_ = classifier
        if rec_info is not None:
            self.initial_state_rule_, self.initial_values_ = rec_info.pop("initial")
            self.recurrence_fit_ = {"mode": "series-parallel", "refine": int(self.refine), **rec_info}
        return self

    def _series_parallel(self, lags: LagStructure, u: Trajectories, y: Trajectories, zs: list[np.ndarray]):
        """Regressors with the measured z in the fed-back dimensions, and the closed-loop pieces."""
        from dataclasses import replace

        nz = zs[0].shape[1] if zs else 0
        lags = replace(lags, mz=int(self.mz), nz=nz)
        us = as_trajectories(u, "u", lags.nu) if lags.nu else []
        ys = as_trajectories(y, "y", lags.ny) if lags.ny else []
        n_traj = max(len(us), len(ys))
        if len(zs) != n_traj:
            raise InputError(f"got {len(zs)} target trajectories for {n_traj} input/output trajectories")
        blocks, valid, io, zb, z0 = [], [], [], [], []
        s = lags.start
        for i in range(n_traj):
            zi = zs[i]
            xi = lags.build_series_parallel(us[i] if lags.nu else None, ys[i] if lags.ny else None, zi)
            blocks.append(xi)
            valid.append(slice(s, zi.shape[0]))
            io.append(xi[:, : lags.io_dimension])
            zb.append(zi[s:])
            z0.append(zi[s - lags.mz: s])
        return lags, np.concatenate(blocks), valid, {"io": io, "z": zb, "z_init": z0}

    def _initial_values(self, zs: list[np.ndarray], lags: LagStructure):
        """(rule, values (Mz, nz) or None) from the ``initial_state`` parameter."""
        if isinstance(self.initial_state, str):
            if self.initial_state == "measured":
                return "measured", None
            mean = np.concatenate(zs).mean(axis=0)
            return "value", np.tile(mean, (lags.mz, 1))
        v = np.asarray(self.initial_state, dtype=float)
        if v.size == lags.nz:
            v = np.tile(v.reshape(1, lags.nz), (lags.mz, 1))
        if v.shape != (lags.mz, lags.nz) or not np.all(np.isfinite(v)):
            raise InputError(f"initial_state must be {lags.nz} (or {lags.mz}x{lags.nz}) finite numbers, got {v.reshape(-1).tolist()}")
        return "value", v

    # -------------------------------------------------------------- predict
    def _check_fitted(self) -> None:
        if not hasattr(self, "weights_"):
            from sklearn.exceptions import NotFittedError  # a ValueError; imported here: sklearn is slow to import

            raise NotFittedError("this PWASVirtualSensor is not fitted yet; call fit() or load a model first")

    def predict_regressors(self, xi: np.ndarray, return_flags: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Evaluate the PWAS function at regressor vectors.

        Parameters
        ----------
        xi : ndarray, shape (m, n)
            Physical regressors (as :meth:`regressors` builds them).
        return_flags : bool
            Also return the out-of-domain flag of each row (True where a coordinate was clamped).

        Returns
        -------
        zhat : ndarray, shape (m, nz)
            Estimates, physical target units.
        flags : ndarray, shape (m,), bool  (only with ``return_flags``)
        """
        self._check_fitted()
        if not isinstance(self.grid_, Grid):  # additive: the sum of the parts (pwas_hdl.fit.additive)
            zhat = self.grid_.evaluate(self.weights_, xi)
            return (zhat, self.grid_.to_grid_units(xi)[1]) if return_flags else zhat
        loc = self.grid_.locate(xi)
        zhat = np.einsum("mk,mkz->mz", loc.mu, self.weights_[loc.vertices])
        return (zhat, loc.out_of_domain) if return_flags else zhat

    def predict(self, u: Trajectories, y: Trajectories, return_flags: bool = False,
                z: Trajectories = None) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Estimate ``z`` for every sample that has a full regressor.

        Parameters
        ----------
        u, y : as in :meth:`fit`
        return_flags : bool
            Also return the out-of-domain flags.
        z : as in :meth:`fit`, optional
            Only for a recurrent sensor whose initial state rule is "measured": the measured z
            before the first estimate (rows then start at ``t = max(M-1, Mz)``).

        Returns
        -------
        zhat : ndarray, shape (sum_i (T_i - M + 1), nz)
            Row blocks per trajectory, sample ``t = M-1 .. T_i-1``. A recurrent sensor (``Mz >= 1``)
            runs the recurrence: row ``t`` is ``z_hat(t + lead)`` from the past estimates.
        flags : ndarray, shape (sum_i (T_i - M + 1),), bool  (only with ``return_flags``)
            True where a regressor coordinate was clamped to the domain (out-of-domain row).
        """
        self._check_fitted()
        if self.lags_ is not None and self.lags_.recurrent:
            return self._predict_recurrent(u, y, z, return_flags)
        xi, _ = self.regressors(u, y)
        return self.predict_regressors(xi, return_flags)

    def predict_class(self, u: Trajectories, y: Trajectories) -> np.ndarray:
        """The class labels of a classifier (``classify=True`` or a loaded classifier file).

        Parameters
        ----------
        u, y : as in :meth:`fit`

        Returns
        -------
        labels : ndarray, shape (sum_i (T_i - M + 1),)
            The class of the largest score (:meth:`predict`), ties to the lowest class
            (:func:`pwas_hdl.fit.classifier.decide`: what the generated argmax stage outputs).

        Raises
        ------
        InputError
            The model is not a classifier.
        """
        self._check_fitted()
        clf = getattr(self, "classifier_", None)
        if clf is None:
            raise InputError("predict_class needs a classifier (fit with classify=True, or fit --classify)")
        return decide(self.predict(u, y), clf["classes"])

    def _predict_recurrent(self, u: Trajectories, y: Trajectories, z: Trajectories, return_flags: bool):
        """Run the recurrence (:func:`pwas_hdl.fit.recurrent.run_recurrence`) on every trajectory."""
        from pwas_hdl.fit.recurrent import initial_block, run_recurrence

        lags = self.lags_
        io, valid = self._build_regressors(lags, u, y)
        zs = as_trajectories(z, "z", lags.nz) if z is not None else [None] * len(valid)
        if len(zs) != len(valid):
            raise InputError(f"got {len(zs)} target trajectories for {len(valid)} input/output trajectories")
        skip = lags.start - (lags.memory - 1) if self.initial_state_rule_ == "measured" else 0
        blocks, inits, off = [], [], 0
        for sl, zi in zip(valid, zs):
            rows = sl.stop - sl.start
            if rows - skip < 1:
                raise InputError(f"a trajectory has {sl.stop} samples; the recurrence needs more than {sl.start + skip}")
            blocks.append(io[off + skip: off + rows])
            inits.append(initial_block(self, zi, sl.start + skip))
            off += rows
        def step(io_rows, zpast):
            return self.predict_regressors(np.hstack([io_rows, zpast.reshape(zpast.shape[0], -1)]))

        out = run_recurrence(step, blocks, inits)
        zhat = np.concatenate(out)
        if not return_flags:
            return zhat
        # flags were produced step by step for the active trajectories: recompute per row instead
        past = [np.concatenate([i0, o]) for i0, o in zip(inits, out)]
        xi = np.concatenate([np.hstack([b] + [p[lags.mz - lag: lags.mz - lag + b.shape[0]] for lag in range(lags.mz, 0, -1)])
                             for b, p in zip(blocks, past)])
        return zhat, self.grid_.locate(xi).out_of_domain

    def score(self, u: Trajectories, y: Trajectories, z: Trajectories, sample_weight: np.ndarray | Sequence[float] | None = None) -> float:
        """Coefficient of determination R^2 of the estimates of ``z`` (as scikit-learn regressors).

        Parameters
        ----------
        u, y, z : as in :meth:`fit`
            ``z`` is compared at the samples that have a full regressor (``t = M-1 .. T_i-1`` of
            each trajectory), the rows :meth:`predict` returns.
        sample_weight : array_like, shape (rows,), optional

        Returns
        -------
        float
            ``sklearn.metrics.r2_score``, averaged uniformly over the targets (1 is perfect).
        """
        from sklearn.metrics import r2_score

        zhat = self.predict(u, y)
        if self.lags_ is not None and self.lags_.recurrent:  # the rows of the recurrence ("value" rule)
            _, valid = self._build_regressors(self.lags_, u, y)
        else:
            _, valid = self.regressors(u, y)
        zs = as_trajectories(z, "z")
        if len(zs) != len(valid):
            raise InputError(f"got {len(zs)} target trajectories for {len(valid)} input/output trajectories")
        zt = np.concatenate([zi[sl] for zi, sl in zip(zs, valid)], axis=0)
        if zt.shape != zhat.shape:
            raise InputError(f"z has {zt.shape[0]} usable rows and {zt.shape[1]} columns, the estimates {zhat.shape}")
        return float(r2_score(zt, zhat, sample_weight=sample_weight))

    # ----------------------------------------------------------- properties
    @property
    def n_inputs(self) -> int:
        """Number of measured input signals ``nu`` (raises ``NotFittedError`` before fitting)."""
        self._check_fitted()
        return getattr(self, "nu_", self.lags_.nu if self.lags_ is not None else 0)

    @property
    def n_outputs(self) -> int:
        """Number of measured output signals ``ny`` (1 with a front end; ``NotFittedError`` before fitting)."""
        self._check_fitted()
        return getattr(self, "ny_", self.lags_.ny if self.lags_ is not None else 0)

    @property
    def n_targets(self) -> int:
        """Number of estimated targets ``nz`` (columns of ``weights_``; ``NotFittedError`` before fitting)."""
        self._check_fitted()
        return int(self.weights_.shape[1])

    def signal_names(self) -> tuple[list[str], list[str], list[str]]:
        """Names of the signals.

        Returns
        -------
        inputs, outputs, targets : list of str
            ``nu``, ``ny`` and ``nz`` names (defaults ``u0..``, ``y0..``, ``z0..``).
        """
        self._check_fitted()
        ins = list(self.input_names) if self.input_names else [f"u{i}" for i in range(self.n_inputs)]
        outs = list(self.output_names) if self.output_names else [f"y{i}" for i in range(self.n_outputs)]
        clf = getattr(self, "classifier_", None)
        if clf is not None:  # the one-hot scores: <label>=<k>
            tgts = class_target_names(clf["target"], clf["classes"])
        else:
            tgts = list(self.target_names) if self.target_names else [f"z{i}" for i in range(self.n_targets)]
        return ins, outs, tgts

    # ------------------------------------------------------------ save/load
    def to_dict(self) -> dict:
        """The model-file content as a JSON-ready dict (:func:`pwas_hdl.fit.model_file.model_to_dict`).

        Returns
        -------
        dict
            What :meth:`from_dict` reads back.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            The sensor is not fitted.
        """
        return model_file.model_to_dict(self)

    def to_json(self) -> str:
        """The model file's text (what :meth:`save` writes; :func:`pwas_hdl.fit.model_file.model_text`).

        Returns
        -------
        str
            Strict JSON with a newline at the end.

        Raises
        ------
        InputError
            A weight or statistic is not finite.
        sklearn.exceptions.NotFittedError
            The sensor is not fitted.
        """
        return model_file.model_text(self)

    def save(self, path: str | os.PathLike) -> Path:
        """Write the model file atomically (:func:`pwas_hdl.fit.model_file.write_model`).

        Parameters
        ----------
        path : str or os.PathLike
            The JSON file to write (replaced whole, or left as it was on error).

        Returns
        -------
        Path
            ``path``.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            The sensor is not fitted.
        """
        return model_file.write_model(self, path)

    @classmethod
    def from_dict(cls, d: dict, source: str = "model") -> "PWASVirtualSensor":
        """Rebuild a fitted sensor from a model-file dict (validated: :func:`pwas_hdl.fit.model_file.model_from_dict`).

        Parameters
        ----------
        d : dict
            The parsed model file (:meth:`to_dict`).
        source : str
            What ``d`` came from, for error messages.

        Returns
        -------
        PWASVirtualSensor
            Fitted: ``predict`` gives what the saved sensor gave.

        Raises
        ------
        InputError
            ``d`` is not a valid model (the message names the key).
        """
        return model_file.model_from_dict(d, source)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "PWASVirtualSensor":
        """Read and validate a model file (:func:`pwas_hdl.fit.model_file.read_model`).

        Parameters
        ----------
        path : str or os.PathLike
            A model file written by :meth:`save` or ``pwas-hdl fit``.

        Returns
        -------
        PWASVirtualSensor
            The fitted sensor.

        Raises
        ------
        FileNotFoundError
            The file does not exist.
        InputError
            The file is not strict JSON, not a pwas-hdl model, of another version, or a key is
            missing, of the wrong type or inconsistent (the message names it).
        """
        return model_file.read_model(path)


def load_model(path: str | os.PathLike) -> PWASVirtualSensor:
    """Shorthand for :meth:`PWASVirtualSensor.load`.

    Parameters
    ----------
    path : str or os.PathLike
        A model file written by :meth:`PWASVirtualSensor.save` or ``pwas-hdl fit``.

    Returns
    -------
    PWASVirtualSensor
        The fitted sensor.
    """
    return PWASVirtualSensor.load(path)
