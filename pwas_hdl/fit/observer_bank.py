"""Observer-bank front end: residual features of a bank of learned local models (seed 004).

Masti, Bernardini, Bemporad, "A machine-learning approach to synthesize virtual sensors for
parameter-varying systems", EJC 2021, Sections 2-3 and 4.1; the steps below follow
``shared/design/seed-specs/seed_004.md`` section 0 (assumption ids A*, B*, C* refer to it).

1. **Local ARX models as a function of rho** (Problem 5): ``y_k = phi_k' gamma(rho_k)`` with
   ``phi_k = [-y_{k-M} .. -y_{k-1}, u_{k-M}' .. u_{k-1}', 1]`` and ``n_gamma = M ny + M nu + 1``.
   The paper learns ``gamma(rho)`` with an ANN and an MAE loss; here the substitute of A5:
   ``gamma(rho) = sum_j beta_j(rho) Gamma_j`` with 1-D hat (piecewise-linear) functions ``beta_j``
   on equally spaced knots, fitted by least absolute deviations (LAD, the same MAE loss) as a
   linear programme (:func:`scipy.optimize.linprog`, HiGHS) -- :func:`fit_lpv_arx`.
2. **N_theta representative models** (3.1.1): ``DecisionTreeRegressor(max_leaf_nodes=N_theta)``
   from ``rho_k`` to ``[gamma(rho_k); rho_k]``, raw targets (A6); the leaf means are the models
   -- :func:`select_models`.
3. **Observer canonical form** (6) of each model -- :func:`canonical_form`, and a Luenberger
   one-step predictor (7) ``xi_{k+1} = A xi_k + d + B u_k - L (C xi_k - y_k)`` with gain
   ``deadbeat`` (closed form ``L = -a``), ``poles`` (all poles at radius ``r``: ``L_i = c_i - a_i``)
   or ``kalman`` (stationary KF of eq. 15, ``w ~ N(0, I)``, ``v ~ N(0, lambda)``, DARE)
   -- :func:`observer_gain`; the bank is run by :func:`bank_residuals` (``xi_0 = 0``, A9).
4. **Feature maps** (10)-(11) on the residuals ``e^j_k = yhat^j_k - y_k`` with window ``l``:
   (11a) all residual lags ``e^j_k .. e^j_{k-l}`` (A8), (11b) ``v^j_k = sqrt(1/l sum_{r=k-l}^{k}
   (e^j_r)^2)`` (``l + 1`` terms divided by ``l``, as printed; ``m = 1``) -- :func:`residual_features`.
   The taps ``u(k-Mu+1..k)``, ``y(k-My+1..k)`` of the features (the paper: ``u_k, y_k``) are added by
   the sensor's lag structure (:class:`pwas_hdl.fit.virtual_sensor.PWASVirtualSensor`).

Features exist for samples ``k >= M + l`` of each trajectory (0-based): the first ``M`` residuals
carry the observers' start-up transient, and every residual in a window comes after it (a slightly
stricter start than A9's ``max(M+1, l+1)``).

:class:`ObserverBankFrontEnd` bundles the steps with ``fit``/``transform`` and ``to_dict``/``from_dict``
(the ``front_end`` block of the model file). Only one output channel (``ny = 1``, as in all of
the paper's examples) is supported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.sparse as sp
from sklearn.base import BaseEstimator

from pwas_hdl.errors import InputError, ResourceLimit

__all__ = [
    "arx_regressors", "hat_basis", "LPVARXModel", "fit_lpv_arx", "select_models", "canonical_form",
    "observer_gain", "parse_observer", "bank_residuals", "residual_features", "ObserverBankFrontEnd",
    "FEATURE_MAPS", "OBSERVER_KINDS", "FRONT_END_KIND",
]

FRONT_END_KIND = "observer-bank"
FEATURE_MAPS = ("11a", "11b", "11b-sq")
OBSERVER_KINDS = ("deadbeat", "poles", "kalman")
#: LAD rows above this are refused (the LP has 2 slack variables per row).
MAX_LAD_ROWS = 200_000


# ------------------------------------------------------------------------------------- step 1
def _mean_std(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column means and standard deviations of ``x`` (T, k).

    Where the plain sums overflow (signals beyond ~1e150), they are computed on ``x`` divided by the
    largest magnitude of its column, so that finite signals of any size have a finite spread.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        mean, std = x.mean(axis=0), x.std(axis=0)
    if np.all(np.isfinite(mean)) and np.all(np.isfinite(std)):
        return mean, std
    scale = np.max(np.abs(x), axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    xs = x / scale
    return xs.mean(axis=0) * scale, xs.std(axis=0) * scale


def arx_regressors(u: np.ndarray, y: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """ARX regressors of Problem (5) for one trajectory.

    Parameters
    ----------
    u : ndarray, shape (T, nu)
    y : ndarray, shape (T, 1)
    order : int
        ``M >= 1``: past samples of ``u`` and ``y``.

    Returns
    -------
    phi : ndarray, shape (T - M, n_gamma)
        Row ``i`` is ``[-y_{k-M} .. -y_{k-1}, u_{k-M}' .. u_{k-1}', 1]`` for ``k = M + i``
        (oldest first; ``n_gamma = M + M nu + 1``).
    target : ndarray, shape (T - M,)
        ``y_k``.
    """
    t_len = y.shape[0]
    if t_len <= order:
        raise InputError(f"a trajectory has {t_len} samples; the local models of order M = {order} need more than M; "
                         "give longer trajectories or a smaller --order")
    rows = t_len - order
    cols = [-y[order - i : order - i + rows, 0] for i in range(order, 0, -1)]
    for i in range(order, 0, -1):
        cols += [u[order - i : order - i + rows, c] for c in range(u.shape[1])]
    cols.append(np.ones(rows))
    return np.stack(cols, axis=1), y[order:, 0].copy()


def hat_basis(rho: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Piecewise-linear hat functions on sorted knots, clamped outside.

    Parameters
    ----------
    rho : ndarray, shape (T,)
    knots : ndarray, shape (K,), increasing, ``K >= 2``

    Returns
    -------
    ndarray, shape (T, K)
        Rows sum to 1; at most two non-zeros per row.
    """
    r = np.clip(np.asarray(rho, dtype=float).reshape(-1), knots[0], knots[-1])
    j = np.clip(np.searchsorted(knots, r, side="right") - 1, 0, knots.size - 2)
    t = (r - knots[j]) / (knots[j + 1] - knots[j])
    out = np.zeros((r.size, knots.size))
    idx = np.arange(r.size)
    out[idx, j] = 1.0 - t
    out[idx, j + 1] += t
    return out


@dataclass
class LPVARXModel:
    """``gamma(rho) = sum_j beta_j(rho) Gamma_j`` (the PWL-in-rho substitute of A5).

    Attributes
    ----------
    knots : ndarray, shape (K,)
        Knots of the hat functions (units of rho).
    coefs : ndarray, shape (K, n_gamma)
        ``Gamma_j``, ordered ``[a_M .. a_1, b_M' .. b_1', c]``.
    order, nu : int
    mae : float
        Mean absolute one-step error of the fit on its training rows (units of y).
    """

    knots: np.ndarray
    coefs: np.ndarray
    order: int
    nu: int
    mae: float

    def gamma(self, rho: np.ndarray) -> np.ndarray:
        """ARX parameters at each ``rho``, shape (T, n_gamma).

        Parameters
        ----------
        rho : ndarray, shape (T,)
            Scheduling parameter values (the measured rho, its physical units).

        Returns
        -------
        ndarray, shape (T, n_gamma)
            The hat-basis interpolation of the local ARX parameters at each ``rho``.
        """
        return hat_basis(rho, self.knots) @ self.coefs


def fit_lpv_arx(
    us: Sequence[np.ndarray],
    ys: Sequence[np.ndarray],
    rhos: Sequence[np.ndarray],
    order: int,
    n_knots: int = 6,
    max_rows: int | None = 10000,
) -> LPVARXModel:
    """Problem (5) with the PWL substitute of A5, solved by LAD (a linear programme).

    ``min sum_k |y_k - phi_k' sum_j beta_j(rho_k) Gamma_j|`` over ``Gamma`` (K x n_gamma), written
    solved as the dual linear programme ``max y'd s.t. X'd = 0, |d| <= 1`` (HiGHS interior point
    with crossover), whose equality multipliers are ``-Gamma``: ``n_gamma K`` constraints instead of
    one per sample.

    Parameters
    ----------
    us, ys, rhos : lists of ndarray, shapes (T_i, nu), (T_i, 1), (T_i,) or (T_i, 1)
        One entry per trajectory. ``rho_k`` is the measured parameter at the instant of ``y_k``.
    order : int
        ``M``.
    n_knots : int
        ``K >= 2`` equally spaced knots from the smallest to the largest training rho.
    max_rows : int or None
        Use at most this many regression rows, evenly strided over the data (the LP's size; None:
        all of them).

    Returns
    -------
    LPVARXModel
    """
    if n_knots < 2:
        raise InputError(f"the local-model basis needs at least 2 knots, got {n_knots}")
    phis, tgts, rs = [], [], []
    for u, y, r in zip(us, ys, rhos):
        phi, tgt = arx_regressors(u, y, order)
        phis.append(phi)
        tgts.append(tgt)
        rs.append(np.asarray(r, dtype=float).reshape(-1)[order:])
    phi = np.concatenate(phis)
    tgt = np.concatenate(tgts)
    rho = np.concatenate(rs)
    if max_rows is not None and phi.shape[0] > max_rows:
        keep = np.linspace(0, phi.shape[0] - 1, max_rows).round().astype(int)
        phi, tgt, rho = phi[keep], tgt[keep], rho[keep]
    if phi.shape[0] > MAX_LAD_ROWS:
        raise ResourceLimit(f"the LAD fit of the local models would have {phi.shape[0]} rows; the limit is {MAX_LAD_ROWS} (lower max_rows)")
    lo, hi = float(rho.min()), float(rho.max())
    if not hi > lo:
        raise InputError(f"the target (rho, the -z/--targets column) is constant in the training data (always {lo:g}); the "
                         "observer bank needs it to vary: give data in which it varies")
    knots = np.linspace(lo, hi, n_knots)
    beta = hat_basis(rho, knots)
    t_rows, n_g = phi.shape
    # design row k: kron(beta_k, phi_k) against vec(Gamma) in row-major (knot, parameter) order;
    # beta has two non-zeros a row, so the design is sparse
    design = sp.csr_matrix((beta[:, :, None] * phi[:, None, :]).reshape(t_rows, n_knots * n_g))
    # LAD through its dual LP (n_theta equality rows instead of t_rows):
    #   max_d y'd  s.t.  X'd = 0, -1 <= d <= 1;  theta = minus the multipliers of X'd = 0
    res = scipy.optimize.linprog(-tgt, A_eq=design.T.tocsr(), b_eq=np.zeros(design.shape[1]), bounds=(-1.0, 1.0),
                                 method="highs-ipm")
    if res.status != 0:
        raise InputError(f"the LAD fit of the local models failed ({res.message}); check the data or lower the order")
    theta = -np.asarray(res.eqlin.marginals, dtype=float)
    coefs = theta.reshape(n_knots, n_g)
    mae = float(np.mean(np.abs(tgt - design @ theta)))
    return LPVARXModel(knots, coefs, order, (n_g - 1 - order) // order, mae)


# ------------------------------------------------------------------------------------- step 2
def select_models(rho: np.ndarray, gammas: np.ndarray, n_models: int, random_state: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """N_theta representative local models: the leaves of a DTR ``rho -> [gamma; rho]`` (3.1.1).

    Parameters
    ----------
    rho : ndarray, shape (T,)
    gammas : ndarray, shape (T, n_gamma)
        ``gamma(rho_k)`` on the training set.
    n_models : int
        ``max_leaf_nodes`` of the tree.
    random_state : int
        Seed of the tree (ties between equal splits).

    Returns
    -------
    models : ndarray, shape (n_leaves, n_gamma)
        Leaf means of gamma, sorted by the leaves' mean rho (``n_leaves <= n_models``).
    leaf_rho : ndarray, shape (n_leaves,)
        Mean rho of each leaf.
    """
    from sklearn.tree import DecisionTreeRegressor

    if n_models < 1:
        raise InputError(f"the number of local models must be >= 1, got {n_models}")
    r = np.asarray(rho, dtype=float).reshape(-1, 1)
    if n_models == 1:
        return gammas.mean(axis=0, keepdims=True), np.array([r.mean()])
    tree = DecisionTreeRegressor(max_leaf_nodes=n_models, random_state=random_state)
    tree.fit(r, np.column_stack([gammas, r]))
    leaves = tree.apply(r)
    ids = np.unique(leaves)
    models = np.array([gammas[leaves == i].mean(axis=0) for i in ids])
    leaf_rho = np.array([r[leaves == i, 0].mean() for i in ids])
    order = np.argsort(leaf_rho, kind="stable")
    return models[order], leaf_rho[order]


# ------------------------------------------------------------------------------------- step 3
def canonical_form(gamma: np.ndarray, order: int, nu: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Observer canonical form (6) of one ARX model.

    Parameters
    ----------
    gamma : ndarray, shape (n_gamma,)
        ``[a_M .. a_1, b_M' .. b_1', c]`` (``b_i`` in R^nu).
    order, nu : int

    Returns
    -------
    A : (M, M)  first column ``-a_1 .. -a_M``, ones on the superdiagonal
    B : (M, nu) rows ``b_1 .. b_M``
    C : (1, M)  ``[1, 0, .., 0]``
    d : (M,)    ``[c, 0, .., 0]``
    """
    g = np.asarray(gamma, dtype=float)
    a = g[:order][::-1]  # a_1 .. a_M
    b = g[order : order + order * nu].reshape(order, nu)[::-1]  # b_1 .. b_M
    c = g[-1]
    amat = np.zeros((order, order))
    amat[:, 0] = -a
    amat[np.arange(order - 1), np.arange(1, order)] = 1.0
    cmat = np.zeros((1, order))
    cmat[0, 0] = 1.0
    d = np.zeros(order)
    d[0] = c
    return amat, b.copy(), cmat, d


def parse_observer(text: str) -> tuple[str, float | None]:
    """``"deadbeat"``, ``"poles:R"`` or ``"kalman:LAMBDA"`` -> (kind, parameter).

    Parameters
    ----------
    text : str
        The observer option (case and surrounding blanks ignored).

    Returns
    -------
    kind : {"deadbeat", "poles", "kalman"}
    parameter : float or None
        The radius ``R`` (poles), ``LAMBDA`` (kalman) or None (deadbeat).

    Raises
    ------
    InputError
        Any other text, a radius outside [0, 1) or a lambda <= 0.
    """
    t = text.strip().lower()
    kind, _, par = t.partition(":")
    if kind == "deadbeat" and not par:
        return "deadbeat", None
    if kind in ("poles", "kalman") and par:
        try:
            v = float(par)
        except ValueError:
            v = math.nan
        if kind == "poles" and 0 <= v < 1:
            return kind, v
        if kind == "kalman" and v > 0 and math.isfinite(v):
            return kind, v
    raise InputError(
        f"--observer (observer) must be deadbeat, poles:R (all poles at radius 0 <= R < 1) or kalman:LAMBDA "
        f"(measurement-noise variance LAMBDA > 0), got {text!r}; e.g. --observer poles:0.5 or --observer kalman:0.1"
    )


def observer_gain(a_mat: np.ndarray, c_mat: np.ndarray, kind: str, param: float | None = None) -> np.ndarray:
    """Gain ``L`` (M,) of the one-step predictor ``xi+ = A xi + .. - L (C xi - y)``.

    Parameters
    ----------
    a_mat : ndarray, shape (M, M)
        ``A`` of the canonical form (:func:`canonical_form`): first column ``-a_1 .. -a_M``.
    c_mat : ndarray, shape (1, M)
        ``C`` of the canonical form, ``[1, 0, .., 0]``.
    kind : {"deadbeat", "poles", "kalman"}
        deadbeat: ``L = -a`` so ``A - L C`` is the nilpotent shift (all poles at 0);
        poles: ``L_i = c_i - a_i`` with ``(z - r)^M = z^M + c_1 z^{M-1} + .. + c_M``;
        kalman: stationary Kalman predictor of (15) with ``Q = I``, ``R = lambda``:
        ``P = dare(A', C', I, lambda)``, ``L = A P C' (C P C' + lambda)^-1``.
    param : float, optional
        The radius ``r`` (poles) or ``lambda`` (kalman); unused by deadbeat.

    Returns
    -------
    ndarray, shape (M,)
        The gain ``L``.
    """
    a = -a_mat[:, 0]
    m = a.size
    if kind == "deadbeat":
        return -a.copy()
    if kind == "poles":
        c = np.poly(np.full(m, float(param)))[1:]
        return c - a
    if kind == "kalman":
        lam = float(param)
        p = scipy.linalg.solve_discrete_are(a_mat.T, c_mat.T, np.eye(m), lam * np.eye(1))
        return (a_mat @ p @ c_mat.T / (c_mat @ p @ c_mat.T + lam)).reshape(-1)
    raise InputError(f"unknown observer kind {kind!r}; use one of {', '.join(OBSERVER_KINDS)}")


def bank_residuals(models: np.ndarray, gains: np.ndarray, order: int, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Run the observer bank (7) on one trajectory from ``xi_0 = 0`` and return the residuals.

    Each observer is the LTI system ``xi_{k+1} = (A - L C) xi_k + B u_k + L y_k + d``,
    ``yhat_k = C xi_k``; it is evaluated per input channel as a transfer function with
    :func:`scipy.signal.lfilter` (zero initial state, the constant ``d`` as an input of ones).

    Parameters
    ----------
    models : ndarray, shape (N_theta, n_gamma)
    gains : ndarray, shape (N_theta, M)
    order : int
    u : ndarray, shape (T, nu)
    y : ndarray, shape (T, 1)

    Returns
    -------
    ndarray, shape (T, N_theta)
        ``e^j_k = yhat^j_k - y_k``.
    """
    import scipy.signal  # here, not at module level: ~0.5 s to import, only the float bank uses it

    nu = u.shape[1]
    t_len = y.shape[0]
    inputs = np.column_stack([u, y[:, 0], np.ones(t_len)])
    res = np.empty((t_len, models.shape[0]))
    for j, (g, l) in enumerate(zip(models, gains)):
        a_mat, b_mat, c_mat, d = canonical_form(g, order, nu)
        acl = a_mat - np.outer(l, c_mat[0])
        bin_ = np.column_stack([b_mat, l, d])
        yhat = np.zeros(t_len)
        for col in range(bin_.shape[1]):
            num, den = scipy.signal.ss2tf(acl, bin_[:, col : col + 1], c_mat, np.zeros((1, 1)))
            yhat += scipy.signal.lfilter(num[0], den, inputs[:, col])
        res[:, j] = yhat - y[:, 0]
    return res


def residual_features(res: np.ndarray, window: int, feature_map: str) -> np.ndarray:
    """Feature maps (11a) / (11b) of the residuals of one trajectory (without the u, y taps).

    Parameters
    ----------
    res : ndarray, shape (T, N_theta)
    window : int
        ``l >= 1``.
    feature_map : {"11a", "11b", "11b-sq"}

    Returns
    -------
    ndarray, shape (T - l, n_feat)
        Row ``i`` belongs to sample ``k = l + i``. (11a): ``[e^1_k .. e^1_{k-l}, .., e^N_k .. e^N_{k-l}]``
        (``n_feat = N_theta (l + 1)``); (11b): ``[v^1_k .. v^N_k]`` (``n_feat = N_theta``);
        (11b-sq): ``[s^1_k .. s^N_k]``, ``s = v**2`` (the squared feature, an equivalent monotone map that
        needs no square root in hardware, :mod:`pwas_hdl.fixedpoint.observer_bank`).
    """
    t_len, n_th = res.shape
    rows = t_len - window
    if feature_map == "11a":
        cols = [res[window - lag : window - lag + rows, j] for j in range(n_th) for lag in range(window + 1)]
        return np.stack(cols, axis=1)
    if feature_map in ("11b", "11b-sq"):
        # the running sum of squares must stay finite: T * max|e|**2 below the float range (checked, not
        # left to numpy's overflow warning and a later "NaN or infinite" error that blames the data)
        big = float(np.max(np.abs(res))) if res.size else 0.0
        if not big <= math.sqrt(1e300 / max(t_len, 1)):
            raise InputError(f"the observer-bank residuals reach {big:.3g}, too large for the windowed RMS features "
                             f"({feature_map}) to be computed: the input / output columns hold values far too large "
                             f"for the bank's models; rescale or clean the data")
        c = np.concatenate([np.zeros((1, n_th)), np.cumsum(res**2, axis=0)])
        sums = c[window + 1 :] - c[: rows]
        ms = np.maximum(sums, 0.0) / window
        return np.sqrt(ms) if feature_map == "11b" else ms
    raise InputError(f"feature map must be one of {', '.join(FEATURE_MAPS)}, got {feature_map!r}")


# ---------------------------------------------------------------------------------- front end
class ObserverBankFrontEnd(BaseEstimator):
    """Seed 004's front end: learned local models, an observer bank and residual features.

    A scikit-learn estimator (``get_params`` / ``set_params``, ``sklearn.base.clone``): nested in a
    :class:`~pwas_hdl.fit.virtual_sensor.PWASVirtualSensor` its parameters are
    ``front_end__n_models`` etc. of the sensor's ``get_params(deep=True)`` / ``set_params``.

    Parameters
    ----------
    n_models : int
        ``N_theta``: observers in the bank (paper default 5).
    observer : str
        ``"deadbeat"`` (default), ``"poles:R"`` or ``"kalman:LAMBDA"`` (:func:`parse_observer`).
    window : int
        ``l`` of the feature map (paper 7).
    features : {"11b", "11a", "11b-sq"}
        Feature map.
    order : int
        ``M`` of the local ARX models (paper 5).
    n_knots : int
        Hat functions of the PWL-in-rho local-model substitute (A5).
    lad_rows : int or None
        Rows used by the LAD fit (evenly strided; None: all).
    normalize : bool
        Standardise u and y with their training mean / std before the bank (stored in the model;
        the paper's data are normalised already, so this is nearly the identity there).

    Attributes (after ``fit``)
    --------------------------
    models_ : ndarray (N, n_gamma)   the selected gamma's, ordered by their leaf's mean rho
    leaf_rho_ : ndarray (N,)
    gains_ : ndarray (N, M)
    u_mean_, u_std_ : ndarray (nu,);  y_mean_, y_std_ : ndarray (1,)
    lpv_mae_ : float                 MAE of the local-model fit (normalised units)
    nu_ : int
    """

    kind = FRONT_END_KIND

    def __init__(self, n_models: int = 5, observer: str = "deadbeat", window: int = 7, features: str = "11b",
                 order: int = 5, n_knots: int = 6, lad_rows: int | None = 10000, normalize: bool = True):
        self.n_models = n_models
        self.observer = observer
        self.window = window
        self.features = features
        self.order = order
        self.n_knots = n_knots
        self.lad_rows = lad_rows
        self.normalize = normalize

    def check_params(self) -> None:
        """Raise :class:`InputError` for an impossible setting (before any work)."""
        for nm, opt, lo in (("n_models", "--models", 1), ("window", "--window", 1), ("order", "--order", 1),
                            ("n_knots", None, 2)):
            v = getattr(self, nm)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < lo:
                what = f"{opt} ({nm})" if opt else nm
                raise InputError(f"observer bank: {what} must be an integer >= {lo}, got {v!r}")
        if self.features not in FEATURE_MAPS:
            raise InputError(f"observer bank: --features (features) must be 11a or 11b (or 11b-sq, the squared 11b), "
                             f"got {self.features!r}")
        parse_observer(self.observer)

    @property
    def memory(self) -> int:
        """Samples of history a feature row needs: the first row is sample ``M + l`` (0-based)."""
        return self.order + self.window + 1

    @property
    def n_features(self) -> int:
        """Bank features per row (without the u, y taps)."""
        return self.n_models_ * (self.window + 1) if self.features == "11a" else self.n_models_

    @property
    def n_models_(self) -> int:
        """Number of models ``N_theta`` in the fitted bank (rows of ``models_``)."""
        return int(self.models_.shape[0])

    def feature_names(self) -> list[str]:
        """``v1[t] ..`` (11b), ``s1[t] ..`` (11b-sq) or ``e1[t] .. e1[t-l] ..`` (11a).

        Returns
        -------
        list of str
            ``N_theta`` names (11b, 11b-sq) or ``N_theta (l + 1)`` names (11a), in feature order.
        """
        if self.features in ("11b", "11b-sq"):
            return [f"{'v' if self.features == '11b' else 's'}{j + 1}[t]" for j in range(self.n_models_)]
        return [f"e{j + 1}[t]" if lag == 0 else f"e{j + 1}[t-{lag}]" for j in range(self.n_models_) for lag in range(self.window + 1)]

    def _scale(self, us: list[np.ndarray], ys: list[np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray]]:
        return [(u - self.u_mean_) / self.u_std_ for u in us], [(y - self.y_mean_) / self.y_std_ for y in ys]

    def _check_signals(self, us: list[np.ndarray], ys: list[np.ndarray]) -> None:
        if not ys:
            raise InputError("the observer-bank front end needs the measured output y")
        if ys[0].shape[1] != 1:
            raise InputError(f"the observer-bank front end supports one output column, got {ys[0].shape[1]}")
        if us and len(us) != len(ys):
            raise InputError(f"got {len(us)} input trajectories but {len(ys)} output trajectories")
        for i, y in enumerate(ys):
            if y.shape[0] < self.memory:
                raise InputError(
                    f"trajectory {i} has {y.shape[0]} samples; the observer bank needs at least M + l + 1 = {self.memory}; "
                    "give longer trajectories, or a smaller --order (M) or --window (l)"
                )

    def fit(self, us: list[np.ndarray], ys: list[np.ndarray], zs: list[np.ndarray], random_state: int = 0,
            lpv: LPVARXModel | None = None) -> "ObserverBankFrontEnd":
        """Learn the local models, select ``N_theta`` of them and design their observers.

        Parameters
        ----------
        us : list of ndarray (T_i, nu) (empty list: no inputs)
        ys : list of ndarray (T_i, 1)
        zs : list of ndarray (T_i, 1)
            The measured parameter rho (one target column).
        random_state : int
            Seed of the selection tree.
        lpv : LPVARXModel, optional
            Local models already learned on the same data with the same ``order`` (``lpv_`` of another
            front end): step 1 is skipped. Benches use it to vary N_theta, observer or features
            without solving the same LAD problem again.

        Returns
        -------
        ObserverBankFrontEnd
            ``self``, fitted.

        Raises
        ------
        InputError
            Bad parameters or signals, a constant signal column, or an observer design that fails.
        """
        self.check_params()
        self._check_signals(us, ys)
        if zs[0].shape[1] != 1:
            raise InputError(f"the observer-bank front end learns its local models from one target (rho), got {zs[0].shape[1]} target columns")
        nu = us[0].shape[1] if us else 0
        if not us:
            us = [np.zeros((y.shape[0], 0)) for y in ys]
        if self.normalize:
            ucat, ycat = np.concatenate(us), np.concatenate(ys)
            (self.u_mean_, self.u_std_), (self.y_mean_, self.y_std_) = _mean_std(ucat), _mean_std(ycat)
            for nm, s in (("input", self.u_std_), ("output", self.y_std_)):
                if np.any(s <= 0):
                    opt = "-u/--inputs" if nm == "input" else "-y/--outputs"
                    k = int(np.flatnonzero(s <= 0)[0]) + 1
                    raise InputError(f"{nm} column {k} of {opt} is constant in the training data; remove it from {opt} "
                                     "or use data that excites it")
        else:
            self.u_mean_, self.u_std_ = np.zeros(nu), np.ones(nu)
            self.y_mean_, self.y_std_ = np.zeros(1), np.ones(1)
        self.nu_ = nu
        usn, ysn = self._scale(us, ys)
        if lpv is None:
            lpv = fit_lpv_arx(usn, ysn, zs, self.order, self.n_knots, self.lad_rows)
        elif lpv.order != self.order or lpv.nu != nu:
            raise InputError(f"the given local models have order {lpv.order} and {lpv.nu} inputs, expected {self.order} and {nu}")
        rho = np.concatenate([z[:, 0] for z in zs])
        models, leaf_rho = select_models(rho, lpv.gamma(rho), self.n_models, random_state)
        kind, par = parse_observer(self.observer)
        gains = []
        for g in models:
            a_mat, _, c_mat, _ = canonical_form(g, self.order, nu)
            try:
                gains.append(observer_gain(a_mat, c_mat, kind, par))
            except (np.linalg.LinAlgError, ValueError) as exc:
                raise InputError(f"observer design ({self.observer}) failed for a local model: {exc}") from exc
        self.models_ = models
        self.leaf_rho_ = leaf_rho
        self.gains_ = np.array(gains)
        self.lpv_mae_ = lpv.mae
        self.lpv_ = lpv
        return self

    def transform(self, us: list[np.ndarray], ys: list[np.ndarray]) -> tuple[np.ndarray, list[slice]]:
        """Bank features of every trajectory, stacked.

        Parameters
        ----------
        us : list of ndarray (T_i, nu)
            Inputs of each trajectory, physical units (empty list: no inputs).
        ys : list of ndarray (T_i, 1)
            Output of each trajectory, physical units; ``T_i >= M + l + 1``.

        Returns
        -------
        feats : ndarray, shape (sum_i (T_i - M - l), n_features)
        valid : list of slice
            Samples of trajectory ``i`` that have a feature row: ``slice(M + l, T_i)``.
        """
        if not hasattr(self, "models_"):
            raise InputError("the observer-bank front end is not fitted; call fit() first (or use the fitted front_end_ of a sensor)")
        self._check_signals(us, ys)
        if not us:
            us = [np.zeros((y.shape[0], 0)) for y in ys]
        if us[0].shape[1] != self.nu_:
            raise InputError(f"the observer bank was fitted with {self.nu_} input channel(s), got {us[0].shape[1]}")
        usn, ysn = self._scale(us, ys)
        blocks, valid = [], []
        for u, y in zip(usn, ysn):
            res = bank_residuals(self.models_, self.gains_, self.order, u, y)
            f = residual_features(res, self.window, self.features)[self.order :]
            blocks.append(f)
            valid.append(slice(self.memory - 1, y.shape[0]))
        return np.concatenate(blocks), valid

    # ------------------------------------------------------------------ model file block
    def to_dict(self) -> dict:
        """The ``front_end`` block of the model file (floats round-trip exactly through JSON).

        Returns
        -------
        dict
            Hyper-parameters, ``nu``, the ``normalization`` statistics, the selected ``models``,
            ``leaf_rho``, the observer ``gains``, ``lpv_mae`` and the ``lpv`` knots and
            coefficients (lists of floats).
        """
        fl = lambda a: [float(v) for v in np.asarray(a).reshape(-1)]  # noqa: E731
        return {
            "kind": FRONT_END_KIND,
            "n_models": int(self.n_models),
            "observer": self.observer,
            "window": int(self.window),
            "features": self.features,
            "order": int(self.order),
            "n_knots": int(self.n_knots),
            "lad_rows": None if self.lad_rows is None else int(self.lad_rows),
            "normalize": bool(self.normalize),
            "nu": int(self.nu_),
            "normalization": {"u_mean": fl(self.u_mean_), "u_std": fl(self.u_std_), "y_mean": fl(self.y_mean_), "y_std": fl(self.y_std_)},
            "models": [fl(g) for g in self.models_],
            "leaf_rho": fl(self.leaf_rho_),
            "gains": [fl(g) for g in self.gains_],
            "lpv_mae": float(self.lpv_mae_),
            "lpv": {"knots": fl(self.lpv_.knots), "coefs": [fl(c) for c in self.lpv_.coefs]},
        }

    @classmethod
    def from_dict(cls, d: dict) -> "ObserverBankFrontEnd":
        """Rebuild a fitted front end from :meth:`to_dict`'s block (``KeyError``/``ValueError`` if corrupt).

        Parameters
        ----------
        d : dict
            The model file's ``front_end`` block.

        Returns
        -------
        ObserverBankFrontEnd
            Fitted (``models_``, ``gains_``, normalisation, ``lpv_`` restored).

        Raises
        ------
        KeyError, ValueError
            A missing key, another ``kind``, non-finite values or inconsistent sizes.
        """
        if d.get("kind") != FRONT_END_KIND:
            raise InputError(f"front_end kind {d.get('kind')!r} is not {FRONT_END_KIND!r}")
        obj = cls(int(d["n_models"]), str(d["observer"]), int(d["window"]), str(d["features"]), int(d["order"]),
                  int(d["n_knots"]), None if d["lad_rows"] is None else int(d["lad_rows"]), bool(d["normalize"]))
        obj.check_params()
        nu = int(d["nu"])
        nrm = d["normalization"]
        obj.nu_ = nu
        obj.u_mean_, obj.u_std_ = np.array(nrm["u_mean"], dtype=float), np.array(nrm["u_std"], dtype=float)
        obj.y_mean_, obj.y_std_ = np.array(nrm["y_mean"], dtype=float), np.array(nrm["y_std"], dtype=float)
        n_g = obj.order * (1 + nu) + 1
        obj.models_ = np.array(d["models"], dtype=float).reshape(-1, n_g)
        obj.gains_ = np.array(d["gains"], dtype=float).reshape(obj.models_.shape[0], obj.order)
        obj.leaf_rho_ = np.array(d["leaf_rho"], dtype=float).reshape(obj.models_.shape[0])
        obj.lpv_mae_ = float(d["lpv_mae"])
        lpv = d["lpv"]
        obj.lpv_ = LPVARXModel(np.array(lpv["knots"], dtype=float), np.array(lpv["coefs"], dtype=float).reshape(-1, n_g), obj.order, nu, obj.lpv_mae_)
        for arr in (obj.u_mean_, obj.u_std_, obj.y_mean_, obj.y_std_, obj.models_, obj.gains_, obj.leaf_rho_,
                    obj.lpv_.knots, obj.lpv_.coefs):
            if not np.all(np.isfinite(arr)):
                raise InputError("non-finite values in the observer-bank block; the model file is corrupt or was edited: fit the model again")
        # each statistic a list of one number per signal (a bare number, a nested list or a missing
        # y_std entry failed later with IndexError), every standard deviation positive
        for key, arr, size in (("u_mean", obj.u_mean_, nu), ("u_std", obj.u_std_, nu), ("y_mean", obj.y_mean_, 1),
                               ("y_std", obj.y_std_, 1)):
            if arr.shape != (size,) or any(isinstance(v, bool) for v in nrm[key]):  # true would read as 1.0
                raise InputError(f"front_end.normalization.{key} must be a list of {size} number(s) ({nu} inputs, 1 output), "
                                 f"got {nrm[key]!r}; the model file is corrupt or was edited: fit the model again")
            if key.endswith("std") and not np.all(arr > 0):
                raise InputError(f"front_end.normalization.{key} must hold positive standard deviations, got {nrm[key]!r}; "
                                 "the model file is corrupt or was edited: fit the model again")
        return obj
