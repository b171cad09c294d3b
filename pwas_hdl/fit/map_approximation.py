"""PWAS approximation of a given map ``f: box in R^n -> R^k`` (issue 13, step 2).

:func:`fit_map` samples a callable ``f`` over a box (the grid vertices plus uniform random
points), :func:`fit_map_samples` takes ready-made samples (``pwas-hdl fit-map`` reads them from
CSV); both solve the same regularised least squares as a virtual sensor
(:func:`pwas_hdl.fit.regularized_lsq.solve_regularized`, zero-order Tikhonov, a small fixed
``sigma``) and report the approximation error, max and RMS per output, on a separate test set:
dense uniform random points of the box for a callable, held-out samples for given samples.

The approximation becomes a model file the rest of the toolchain reads:

* :func:`static_sensor_from_map` -- a static map model (every argument a current input sample,
  ``Mu = 1`` and/or ``My = 1``), which ``generate`` / ``simulate`` take as any lag model;
* :func:`recurrent_sensor_from_map` -- an observer ``z(t+1) = f(u(t), y(t), z(t))`` as a
  recurrent PWAS sensor (``Mz = 1``, ``lead = 1``: the estimate of row ``t`` is ``z(t+1)``,
  :mod:`pwas_hdl.fit.recurrent`); the hardware form is :mod:`pwas_hdl.hdl.recurrent_top`.

Argument order of ``f`` for both: the inputs ``u``, then the outputs ``y``, then (recurrent only)
the states ``z`` -- the order of the lag regressor (:class:`~pwas_hdl.fit.regressors.LagStructure`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np

from pwas_hdl.errors import InputError, option_text
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.limits import check_seed, check_values

if TYPE_CHECKING:
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

__all__ = ["MapApproximation", "fit_map", "fit_map_samples", "map_errors", "static_sensor_from_map",
           "recurrent_sensor_from_map"]

#: Default Tikhonov weight (unnormalised): negligible against H'H for a few samples per vertex.
MAP_SIGMA = 1e-8


@dataclass
class MapApproximation:
    """A fitted PWAS approximation of a map.

    Attributes
    ----------
    grid : Grid
    weights : ndarray, shape (N, k)
    sigma : float
    errors : dict
        ``max``, ``rms`` (lists, one per output), ``n_test`` and ``test`` (how the test set was made).
    n_train : int
    """

    grid: Grid
    weights: np.ndarray
    sigma: float
    errors: dict = field(default_factory=dict)
    n_train: int = 0

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """PWAS values at points ``x`` (m, n): shape (m, k)."""
        loc = self.grid.locate(np.atleast_2d(np.asarray(x, dtype=float)))
        return np.einsum("mk,mkz->mz", loc.mu, self.weights[loc.vertices])


def _as_2d(v: np.ndarray, m: int, what: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[0] != m:
        raise InputError(f"{what} must have {m} rows (one per point), got shape {np.shape(v)}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{what} has NaN or infinite values")
    return a


def map_errors(approx: MapApproximation, x: np.ndarray, fx: np.ndarray, test: str) -> dict:
    """Max and RMS of ``approx(x) - fx`` per output.

    Parameters
    ----------
    approx : MapApproximation
        The approximation, ``k`` outputs.
    x : ndarray, shape (m, n)
        Test points, physical units.
    fx : ndarray, shape (m,) or (m, k)
        The map's values at ``x`` (the units of its outputs).
    test : str
        How the test set was made (kept as ``errors["test"]``).

    Returns
    -------
    dict
        ``max``, ``rms`` (lists of ``k`` floats, the units of ``fx``), ``n_test`` (``m``) and ``test``.

    Raises
    ------
    InputError
        ``fx`` has not ``m`` rows, or NaN or infinite values.
    """
    e = approx(x) - _as_2d(fx, x.shape[0], "f(x)")
    return {"max": [float(v) for v in np.max(np.abs(e), axis=0)], "rms": [float(v) for v in np.sqrt(np.mean(e**2, axis=0))],
            "n_test": int(x.shape[0]), "test": test}


def _solve(grid: Grid, x: np.ndarray, fx: np.ndarray, sigma: float) -> np.ndarray:
    from pwas_hdl.fit.regularized_lsq import check_fit_memory, solve_regularized, tikhonov_matrix

    if not (np.isfinite(sigma) and sigma > 0):
        raise InputError(f"{option_text('sigma')} must be a positive number, got {sigma!r}; e.g. --sigma 1e-8")
    check_fit_memory(x.shape[0], grid.n_vertices, grid.n, fx.shape[1], 0)
    h = grid.basis_matrix(x)
    return solve_regularized(h, fx, sigma, tikhonov_matrix(grid, 0)).reshape(grid.n_vertices, fx.shape[1])


def _box(box) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = (np.asarray(b, dtype=float).reshape(-1) for b in box)
    if lo.size != hi.size or lo.size == 0 or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(hi <= lo):
        raise InputError(f"the box (--domain) must have finite bounds with lo < hi in every dimension, got lo = {lo.tolist()}, "
                         f"hi = {hi.tolist()}; give one lo:hi with lo < hi per argument")
    return lo, hi


def fit_map(f: Callable[[np.ndarray], np.ndarray], box: tuple[np.ndarray | Sequence[float], np.ndarray | Sequence[float]],
            partitions: int | Sequence[int], *, samples_per_vertex: float = 3.0,
            sigma: float = MAP_SIGMA, n_test: int = 20000, seed: int = 0) -> MapApproximation:
    """PWAS approximation of a callable over a box.

    Parameters
    ----------
    f : callable(x) -> fx
        ``x`` (m, n) points, physical units; returns (m,) or (m, k).
    box : (lo, hi), each of shape (n,)
        The domain (the PWAS grid's domain).
    partitions : int or sequence of int
        Intervals ``p_j`` per dimension.
    samples_per_vertex : float
        Uniform random samples per grid vertex, besides the vertices themselves.
    sigma : float
        Tikhonov weight (zero order, unnormalised).
    n_test : int
        Uniform random test points (a dense test set, drawn independently of the samples).
    seed : int
        Seed of the training samples (the test points use ``seed + 1``).

    Returns
    -------
    MapApproximation
        ``errors`` on the ``n_test`` test points.
    """
    lo, hi = _box(box)
    grid = Grid(lo, hi, partitions)
    rng = np.random.default_rng(seed)
    verts = np.atleast_2d(grid.vertex_points())
    m = int(round(samples_per_vertex * grid.n_vertices))
    x = np.vstack([verts, lo + (hi - lo) * rng.random((m, lo.size))])
    fx = _as_2d(f(x), x.shape[0], "f(x)")
    approx = MapApproximation(grid, _solve(grid, x, fx, sigma), float(sigma), n_train=int(x.shape[0]))
    xt = lo + (hi - lo) * np.random.default_rng(seed + 1).random((int(n_test), lo.size))
    approx.errors = map_errors(approx, xt, f(xt), f"{int(n_test)} uniform random points of the box (seed {seed + 1})")
    return approx


def fit_map_samples(x: np.ndarray, fx: np.ndarray, partitions: int | Sequence[int], *,
                    box: tuple[np.ndarray | Sequence[float], np.ndarray | Sequence[float]] | None = None, sigma: float = MAP_SIGMA,
                    test_fraction: float = 0.2, seed: int = 0) -> MapApproximation:
    """PWAS approximation of a map from samples ``(x, f(x))``.

    Parameters
    ----------
    x : ndarray, shape (m, n)
        Sample points, physical units.
    fx : ndarray, shape (m,) or (m, k)
        The map's values at ``x``.
    partitions : int or sequence of int
        Intervals ``p_j`` per dimension.
    box : (lo, hi), each of shape (n,), optional
        The domain; default the bounding box of ``x`` (exactly: a sample on the border is inside).
    sigma : float
        Tikhonov weight (zero order, unnormalised).
    test_fraction : float
        Share of the samples held out (at random, ``seed``) to measure the error, in [0, 0.9];
        0: the error is measured on the fitting samples (then said in ``errors["test"]``).
    seed : int
        Seed of the random hold-out.

    Returns
    -------
    MapApproximation
    """
    x = np.atleast_2d(np.asarray(x, dtype=float))
    fx = _as_2d(fx, x.shape[0], "f(x)")
    check_values("f(x)", fx, "rescale the values (divide them by a power of ten)")
    if not np.all(np.isfinite(x)):
        raise InputError("the sample points have NaN or infinite values")
    if not (0.0 <= test_fraction <= 0.9):
        raise InputError(f"test_fraction must be in [0, 0.9], got {test_fraction!r}")
    check_seed(seed)
    lo, hi = _box(box if box is not None else (x.min(axis=0), x.max(axis=0)))
    grid = Grid(lo, hi, partitions)
    idx = np.random.default_rng(seed).permutation(x.shape[0])
    n_test = int(round(test_fraction * x.shape[0]))
    test, train = idx[:n_test], idx[n_test:]
    if train.size < 1:
        raise InputError("no samples left to fit after the hold-out; give more samples or a smaller test fraction")
    approx = MapApproximation(grid, _solve(grid, x[train], fx[train], sigma), float(sigma), n_train=int(train.size))
    if n_test:
        approx.errors = map_errors(approx, x[test], fx[test], f"{n_test} held-out samples ({test_fraction:g} of the samples, seed {seed})")
    else:
        approx.errors = map_errors(approx, x, fx, "the fitting samples (no hold-out)")
    return approx


def _sensor(approx: MapApproximation, n_u: int, n_y: int, inputs, outputs, targets):
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    k = approx.weights.shape[1]
    if len(targets) != k:
        raise InputError(f"{len(targets)} target names for a map with {k} outputs")
    s = PWASVirtualSensor(mu=1 if n_u else 0, my=1 if n_y else 0, partitions=[int(p) for p in approx.grid.partitions],
                          gamma=1.0, sigma=approx.sigma, domain=(approx.grid.lo, approx.grid.hi), share_lag_domain=True,
                          input_names=list(inputs), output_names=list(outputs), target_names=list(targets))
    s.front_end_ = None
    s.grid_ = approx.grid
    s.weights_ = np.asarray(approx.weights, dtype=float)
    s.sigma_ = float(approx.sigma)
    s.cv_ = None
    s.n_train_ = int(approx.n_train)
    s.n_trajectories_ = 1
    rms = approx.errors.get("rms")
    s.train_rmse_ = np.asarray(rms if rms is not None else np.zeros(k), dtype=float)
    s.lead_ = 0
    s.map_fit_ = dict(approx.errors)
    return s


def static_sensor_from_map(approx: MapApproximation, inputs: Sequence[str] = (), outputs: Sequence[str] = (),
                           targets: Sequence[str] = ("f",)) -> "PWASVirtualSensor":
    """A static model file of the map: the arguments are the current samples of ``inputs`` then ``outputs``.

    Parameters
    ----------
    approx : MapApproximation
        Of ``f`` with ``n = len(inputs) + len(outputs)`` arguments and ``len(targets)`` outputs.
    inputs, outputs : sequence of str
        Names of the arguments, in order: the inputs ``u``, then the outputs ``y``.
    targets : sequence of str
        Names of the map's outputs (the sensor's targets).

    Returns
    -------
    PWASVirtualSensor
        Fitted, ``Mu = 1`` (if inputs), ``My = 1`` (if outputs); ``train_rmse`` = the test RMS error.
    """
    from pwas_hdl.fit.regressors import LagStructure

    n = approx.grid.n
    if len(inputs) + len(outputs) != n:
        raise InputError(f"{len(inputs)} input and {len(outputs)} output names for a map of {n} arguments")
    s = _sensor(approx, len(inputs), len(outputs), inputs, outputs, targets)
    s.lags_ = LagStructure(1 if inputs else 0, 1 if outputs else 0, len(inputs), len(outputs))
    s.nu_, s.ny_ = s.lags_.nu, s.lags_.ny
    return s


def recurrent_sensor_from_map(approx: MapApproximation, inputs: Sequence[str], outputs: Sequence[str], targets: Sequence[str],
                              z0: Sequence[float]) -> "PWASVirtualSensor":
    """The observer ``z(t+1) = f(u(t), y(t), z(t))`` as a recurrent PWAS sensor.

    Parameters
    ----------
    approx : MapApproximation
        Of ``f`` with the arguments ``u`` (``len(inputs)``), ``y`` (``len(outputs)``), then the
        ``nz = len(targets)`` states, and ``nz`` outputs (the next states, in the same order).
    inputs, outputs, targets : sequence of str
        Signal names; ``targets`` are the states.
    z0 : sequence of float
        The initial state ``z(0)`` (fed back for the first sample, the "value" rule).

    Returns
    -------
    PWASVirtualSensor
        ``Mu = 1`` (if inputs), ``My = 1`` (if outputs), ``Mz = 1``, ``lead = 1``: row ``t`` of
        ``predict`` is the estimate of ``z(t+1)``, computed from ``u(t), y(t)`` and the previous row.
    """
    from pwas_hdl.fit.regressors import LagStructure

    nz = len(targets)
    if len(inputs) + len(outputs) + nz != approx.grid.n or approx.weights.shape[1] != nz:
        raise InputError(f"a map of {approx.grid.n} arguments and {approx.weights.shape[1]} outputs cannot be the observer of "
                         f"{len(inputs)} input(s), {len(outputs)} output(s) and {nz} state(s) (arguments u, y, z; outputs z(t+1))")
    z0a = np.asarray(z0, dtype=float).reshape(-1)
    if z0a.size != nz or not np.all(np.isfinite(z0a)):
        raise InputError(f"z0 must give {nz} finite value(s), got {z0a.tolist()}")
    s = _sensor(approx, len(inputs), len(outputs), inputs, outputs, targets)
    s.lags_ = LagStructure(1 if inputs else 0, 1 if outputs else 0, len(inputs), len(outputs), 1, nz)
    s.nu_, s.ny_ = s.lags_.nu, s.lags_.ny
    s.mz = 1
    s.initial_state = z0a.copy()
    s.initial_state_rule_ = "value"
    s.initial_values_ = z0a.reshape(1, nz)
    s.lead_ = 1
    s.recurrence_fit_ = {"mode": "map"}
    return s
