"""Tikhonov-regularised least squares for PWAS weights (paper eqs. 14-16) and sigma by CV.

The problem solved is ``min_w  sigma * w' Gamma w + ||z - H w||^2`` with ``sigma`` unnormalised
(the paper's sigma), whose solution is ``w = (H'H + sigma Gamma)^{-1} H'z``. Everything stays
sparse: ``H`` has ``n + 1`` non-zeros per row and ``H'H`` couples only vertices of a common simplex.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Literal, Sequence

import numpy as np
from scipy import sparse
from scipy.sparse import linalg as splinalg

from pwas_hdl.fit.geometry import Grid
from pwas_hdl.limits import MAX_SIGMA_CANDIDATES, check_limit

__all__ = [
    "tikhonov_matrix",
    "solve_regularized",
    "cross_validate_sigma",
    "CVResult",
    "DEFAULT_SIGMA_GRID",
]

#: Default candidate values of sigma for cross-validation (unnormalised, as in the paper).
DEFAULT_SIGMA_GRID: np.ndarray = np.logspace(-7, 3, 21)

#: Relative weight of the identity added to the first-order penalty so that Gamma is
#: positive definite (the gradient penalty alone vanishes on constant functions).
FIRST_ORDER_RIDGE = 1e-6


def tikhonov_matrix(grid: Grid, order: int = 0) -> sparse.csc_array:
    """Tikhonov regularisation matrix Gamma (N x N, sparse, symmetric positive definite).

    Parameters
    ----------
    grid : Grid
        The partition whose vertices carry the weights.
    order : {0, 1}
        ``0``: ``Gamma = I`` (zero-order Tikhonov).
        ``1``: gradient penalty. For every grid edge ``(a, a + e_j)`` parallel to axis ``j`` the
        difference quotient ``(w_{a+e_j} - w_a) / h_j`` is a partial derivative of the PWAS function
        on the simplices that contain the edge, so
        ``w' Gamma w = sum_j sum_edges ((w_{a+e_j} - w_a) / h_j)^2 * V_cell  +  eps * ||w||^2``
        with ``h_j`` the physical interval width and ``V_cell = prod(h_j)`` (the graph Laplacian
        of the vertex grid scaled per dimension, a Riemann sum of the squared gradient norm).
        ``eps = FIRST_ORDER_RIDGE * mean(diag(Laplacian))`` keeps Gamma positive definite.

    Returns
    -------
    scipy.sparse.csc_array, shape (N, N)
    """
    n_v = grid.n_vertices
    if order == 0:
        return sparse.identity(n_v, format="csc")
    if order != 1:
        raise ValueError(f"Tikhonov order must be 0 or 1, got {order!r}")
    cell_volume = float(np.prod(grid.step))
    rows, cols, vals = [], [], []
    for j in range(grid.n):
        a, b = grid.axis_edges(j)
        wgt = cell_volume / grid.step[j] ** 2
        # (w_b - w_a)^2 * wgt -> [[wgt, -wgt], [-wgt, wgt]] on (a, b)
        rows += [a, b, a, b]
        cols += [a, b, b, a]
        vals += [np.full(a.size, wgt), np.full(a.size, wgt), np.full(a.size, -wgt), np.full(a.size, -wgt)]
    lap = sparse.coo_array(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_v, n_v)
    ).tocsc()
    diag = lap.diagonal()
    eps = FIRST_ORDER_RIDGE * float(diag.mean()) if diag.size and diag.mean() > 0 else FIRST_ORDER_RIDGE
    return (lap + eps * sparse.identity(n_v, format="csc")).tocsc()


def _solve_spd(a: sparse.csc_array, b: np.ndarray) -> np.ndarray:
    """Solve the sparse SPD system ``a x = b`` (``b`` shape (N,) or (N, k)) by sparse LU."""
    lu = splinalg.splu(sparse.csc_matrix(a), permc_spec="MMD_AT_PLUS_A")
    return lu.solve(np.asarray(b, dtype=float))


def solve_regularized(h: sparse.sparray, z: np.ndarray, sigma: float, gamma: sparse.sparray) -> np.ndarray:
    """Weights ``w = (H'H + sigma Gamma)^{-1} H'z`` (eq. 16).

    Parameters
    ----------
    h : sparse array, shape (T, N)
        Alpha-basis matrix.
    z : ndarray, shape (T,) or (T, nz)
        Targets.
    sigma : float
        Tikhonov weight (``> 0``; unnormalised as in eq. 14).
    gamma : sparse array, shape (N, N)
        Regularisation matrix (symmetric positive definite).

    Returns
    -------
    ndarray, shape (N,) or (N, nz)
    """
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma must be a positive finite number, got {sigma!r}")
    ht = h.T.tocsr()
    a = (ht @ h + sigma * gamma).tocsc()
    return _solve_spd(a, ht @ z)


@dataclass
class CVResult:
    """Outcome of the cross-validation of sigma.

    Attributes
    ----------
    sigmas : ndarray, shape (S,)
        Candidate values tried.
    mse : ndarray, shape (S,)
        Mean validation mean-squared error (over folds and targets) for each candidate.
    best_sigma : float
        The candidate with the lowest validation MSE.
    folds : int
        Number of folds.
    """

    sigmas: np.ndarray
    mse: np.ndarray
    best_sigma: float
    folds: int
    fold_mse: np.ndarray = field(repr=False, default_factory=lambda: np.empty(0))

    def to_dict(self) -> dict:
        return {
            "sigmas": [float(s) for s in self.sigmas],
            "mse": [float(v) for v in self.mse],
            "best_sigma": float(self.best_sigma),
            "folds": int(self.folds),
        }


def fold_labels(n_rows: int, folds: int, shuffle: bool = False, seed: int = 0) -> np.ndarray:
    """Fold number of every row: contiguous blocks (default, honest for time series) or shuffled."""
    if folds < 2:
        raise ValueError(f"cross-validation needs at least 2 folds, got {folds}")
    if n_rows < folds:
        raise ValueError(f"cannot split {n_rows} samples into {folds} folds; use fewer folds or more data")
    labels = (np.arange(n_rows) * folds) // n_rows
    if shuffle:
        labels = np.random.default_rng(seed).permutation(labels)
    return labels


def cross_validate_sigma(
    h: sparse.sparray,
    z: np.ndarray,
    gamma: sparse.sparray,
    sigmas: Sequence[float] | None = None,
    folds: int = 5,
    shuffle: bool = False,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
) -> CVResult:
    """Choose sigma by k-fold cross-validation over a grid of candidates.

    For each fold the normal equations of the other folds are formed once
    (``H_k'H_k = H'H - H_v'H_v``), and one sparse factorisation per candidate sigma is made.

    Parameters
    ----------
    h : sparse array, shape (T, N)
    z : ndarray, shape (T,) or (T, nz)
    gamma : sparse array, shape (N, N)
    sigmas : sequence of float, optional
        Candidates (default :data:`DEFAULT_SIGMA_GRID`).
    folds : int
        Number of folds (``>= 2``).
    shuffle : bool
        Shuffle rows before splitting (default: contiguous blocks, which keeps validation samples
        away from the correlated neighbours of training samples).
    seed : int
        Seed of the shuffle.
    progress : callable(done, total), optional
        Called after each solve.

    Returns
    -------
    CVResult
    """
    if sigmas is not None and hasattr(sigmas, "__len__"):
        check_limit("the number of sigma candidates", len(sigmas), MAX_SIGMA_CANDIDATES, "give fewer candidates")
    sig = np.asarray(DEFAULT_SIGMA_GRID if sigmas is None else sigmas, dtype=float).reshape(-1)
    check_limit("the number of sigma candidates", sig.size, MAX_SIGMA_CANDIDATES, "give fewer candidates")
    if sig.size == 0 or not np.all(np.isfinite(sig)) or np.any(sig <= 0):
        raise ValueError("sigma candidates must be positive finite numbers")
    h = sparse.csr_array(h)
    z2 = np.asarray(z, dtype=float).reshape(h.shape[0], -1)
    labels = fold_labels(h.shape[0], folds, shuffle, seed)
    ht = h.T.tocsr()
    hth = (ht @ h).tocsc()
    htz = ht @ z2
    fold_mse = np.zeros((folds, sig.size))
    total, done = folds * sig.size, 0
    for f in range(folds):
        val = labels == f
        hv = h[np.flatnonzero(val)]
        hvt = hv.T.tocsr()
        a_tr = (hth - hvt @ hv).tocsc()
        b_tr = htz - hvt @ z2[val]
        for i, s in enumerate(sig):
            w = _solve_spd((a_tr + s * gamma).tocsc(), b_tr)
            resid = z2[val] - hv @ w
            fold_mse[f, i] = float(np.mean(resid**2))
            done += 1
            if progress is not None:
                progress(done, total)
    mse = fold_mse.mean(axis=0)
    best = float(sig[int(np.argmin(mse))])
    return CVResult(sig, mse, best, folds, fold_mse)
