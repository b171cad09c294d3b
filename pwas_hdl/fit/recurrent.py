"""Dynamical (recurrent) PWAS sensors: past estimates fed back as regressors (issue 13).

A sensor with ``Mz >= 1`` estimates

    z_hat(t) = f( u(t-Mu+1..t), y(t-My+1..t), z_hat(t-Mz..t-1) )

(regressor order: :class:`pwas_hdl.fit.regressors.LagStructure`, the ``nz*Mz`` fed-back dimensions
last, oldest first). This module holds the two things a recurrent sensor adds to a static one:

* :func:`run_recurrence` -- the closed loop, for any one-step evaluator (float weights here,
  the bit-true circuit in :mod:`pwas_hdl.fixedpoint.recurrence`): trajectories advance in
  lockstep, one vectorised evaluation per time step;
* :func:`refine_closed_loop` -- the fit. The weights are first solved in *series-parallel* form
  (the measured ``z`` in the fed-back dimensions, as MOBY-DIC does). With ``refine = K >= 1``
  the regressors are rebuilt from the *simulated* estimates of the current weights and the
  weights solved again (same sigma), at most ``K`` times; an iteration is kept only if it lowers
  the closed-loop RMSE (max over targets), and the loop stops at the first that does not.

Initial state (``initial_state`` of the model file's ``recurrence`` block)
    ``{"rule": "value", "values": {target: [z(t0-Mz) .. z(t0-1)]}}``: the first estimated sample
    ``t0 = M - 1`` (``M = max(Mu, My)``) sees these constants as its past estimates; the default
    of a fit is the training mean of each target for every lag; the hardware resets its feedback
    registers to their input codes. ``{"rule": "measured"}``: the measured ``z`` of the samples
    before ``t0 = max(M - 1, Mz)`` is the past (``predict`` then needs the target column; the
    hardware does not support it). During the closed-loop refinement the training trajectories
    always start from their measured ``z`` (the "measured" rule).

``lead`` (0 or 1): the estimate of row ``t`` is of ``z(t + lead)``. Fitted sensors have lead 0;
a PWAS approximation of an observer map ``z(t+1) = f(z(t), u(t), y(t))``
(:func:`pwas_hdl.fit.map_approximation.recurrent_sensor_from_map`) has lead 1.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np

from pwas_hdl.errors import InputError

if TYPE_CHECKING:
    from pwas_hdl.fit.geometry import Grid
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

__all__ = ["run_recurrence", "evaluate_weights", "refine_closed_loop", "initial_state_dict", "initial_block"]

Step = Callable[[np.ndarray, np.ndarray], np.ndarray]


def evaluate_weights(grid: "Grid", w: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """Float PWAS values at regressors ``xi`` for weights ``w``.

    Parameters
    ----------
    grid : Grid
        The simplicial grid (``n`` dimensions, ``N`` vertices).
    w : ndarray, shape (N, nz)
        Vertex weights, the targets' physical units.
    xi : ndarray, shape (m, n)
        Regressors, physical units.

    Returns
    -------
    ndarray, shape (m, nz)
        The PWAS values.
    """
    loc = grid.locate(xi)
    return np.einsum("mk,mkz->mz", loc.mu, w[loc.vertices])


def run_recurrence(step: Step, io_blocks: Sequence[np.ndarray], z_init: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Run the recurrence over several trajectories in lockstep.

    Parameters
    ----------
    step : callable(io, zpast) -> znew
        One step for ``k`` trajectories: ``io`` (k, n_io) the u/y part of the regressor, ``zpast``
        (k, Mz, nz) the past estimates, oldest first; returns (k, nz). Values may be floats or
        integer codes (the caller's convention; the bit-true step returns the fed-back codes).
    io_blocks : list of ndarray, each (R_i, n_io)
        The u/y part of the regressor of each row (row 0 = the first estimated sample).
    z_init : list of ndarray, each (Mz, nz)
        The past estimates of the first row of each trajectory, oldest first.

    Returns
    -------
    list of ndarray, each shape (R_i, nz)
        The estimates (what ``step`` returned), row by row.
    """
    n_traj = len(io_blocks)
    if len(z_init) != n_traj:
        raise InputError(f"{len(z_init)} initial states for {n_traj} trajectories; give one initial state per trajectory")
    if n_traj == 0:
        return []
    lens = np.array([b.shape[0] for b in io_blocks])
    state = np.stack([np.asarray(z) for z in z_init])  # (k, Mz, nz)
    nz = state.shape[2]
    outs = [np.empty((int(r), nz), dtype=state.dtype) for r in lens]
    for t in range(int(lens.max(initial=0))):
        act = np.flatnonzero(lens > t)
        io = np.stack([io_blocks[i][t] for i in act])
        znew = np.asarray(step(io, state[act]))
        if state.dtype.kind == "f" and znew.dtype.kind != "f":
            znew = znew.astype(state.dtype)
        for k, i in enumerate(act):
            outs[i][t] = znew[k]
        state[act] = np.concatenate([state[act, 1:], znew[:, None, :].astype(state.dtype)], axis=1)
    return outs


def float_step(grid, w: np.ndarray) -> Step:
    """The float one-step evaluator of weights ``w`` on ``grid`` (for :func:`run_recurrence`)."""

    def step(io: np.ndarray, zpast: np.ndarray) -> np.ndarray:
        return evaluate_weights(grid, w, np.hstack([io, zpast.reshape(zpast.shape[0], -1)]))

    return step


def _closed_loop(grid, w, io_blocks, z_init) -> list[np.ndarray]:
    return run_recurrence(float_step(grid, w), io_blocks, z_init)


def _rmse(parts: list[np.ndarray], targets: list[np.ndarray]) -> np.ndarray:
    e = np.concatenate([p - t for p, t in zip(parts, targets)])
    return np.sqrt(np.mean(e**2, axis=0))


def refine_closed_loop(grid: "Grid", basis: Callable[[np.ndarray], object], solve: Callable[[object], np.ndarray],
                       w0: np.ndarray, io_blocks: list[np.ndarray], z_blocks: list[np.ndarray],
                       z_init: list[np.ndarray], mz: int, iterations: int) -> tuple[np.ndarray, dict]:
    """Series-parallel weights ``w0`` refined on the closed-loop error (see the module docstring).

    Parameters
    ----------
    grid : Grid
        The simplicial grid of the weights (``N`` vertices).
    basis : callable(xi) -> H
        The basis matrix of regressors ``xi`` (m, n).
    solve : callable(H) -> w (N, nz)
        The regularised least-squares solve against the stacked targets (fixed sigma).
    w0 : ndarray (N, nz)
        Series-parallel solution.
    io_blocks, z_blocks : list of ndarray (R_i, n_io) / (R_i, nz)
        The u/y regressor part and the measured targets of each training row.
    z_init : list of ndarray (Mz, nz)
        The measured z before the first row of each trajectory.
    mz : int
        Fed-back lags ``Mz`` of each target.
    iterations : int
        Upper bound ``K`` on the refinements (0: none).

    Returns
    -------
    w : ndarray (N, nz)
        The weights with the lowest closed-loop RMSE (max over targets) seen.
    info : dict
        ``closed_loop_rmse`` (per target, of ``w``), ``series_parallel_closed_loop_rmse`` (of ``w0``),
        ``history`` (max closed-loop RMSE per iteration, iteration 0 = series-parallel),
        ``iterations_used`` (refinements kept).
    """
    sim = _closed_loop(grid, w0, io_blocks, z_init)
    err0 = _rmse(sim, z_blocks)
    best_w, best_err, best_max = w0, err0, float(err0.max())
    history = [best_max]
    used = 0
    for _ in range(int(iterations)):
        xi = []
        for io, zi, s, z0 in zip(io_blocks, z_blocks, sim, z_init):
            past = np.concatenate([z0, s])  # estimates z(t0-Mz) ..
            cols = [past[mz - lag: mz - lag + io.shape[0]] for lag in range(mz, 0, -1)]
            xi.append(np.hstack([io] + cols))
        w = solve(basis(np.concatenate(xi)))
        sim_new = _closed_loop(grid, w, io_blocks, z_init)
        err = _rmse(sim_new, z_blocks)
        history.append(float(err.max()))
        if not float(err.max()) < best_max:
            break
        best_w, best_err, best_max, sim = w, err, float(err.max()), sim_new
        used += 1
    return best_w, {"closed_loop_rmse": best_err, "series_parallel_closed_loop_rmse": err0, "history": history,
                    "iterations_used": used}


def initial_state_dict(rule: str, values: np.ndarray | None, targets: Sequence[str]) -> dict:
    """The model file's ``initial_state`` block.

    Parameters
    ----------
    rule : {"value", "measured"}
        The initial-state rule (see the module docstring).
    values : ndarray, shape (Mz, nz), or None
        For the "value" rule: the constant past estimates ``z(t0-Mz) .. z(t0-1)``, oldest first, the
        targets' physical units; ignored by "measured".
    targets : sequence of str
        The ``nz`` target names (the keys of ``values`` in the block).

    Returns
    -------
    dict
        ``{"rule": "measured"}`` or ``{"rule": "value", "values": {target: [Mz floats]}}``.
    """
    if rule == "measured":
        return {"rule": "measured"}
    v = np.asarray(values, dtype=float)
    return {"rule": "value", "values": {t: [float(x) for x in v[:, i]] for i, t in enumerate(targets)}}


def initial_block(sensor: "PWASVirtualSensor", z: np.ndarray | None, n_rows_before: int) -> np.ndarray:
    """The past of a trajectory's first estimated row: the stored constants, or the
    measured ``z`` of the ``Mz`` samples before row ``n_rows_before`` ("measured" rule).

    Parameters
    ----------
    sensor : PWASVirtualSensor
        A fitted recurrent sensor (``lags_``, ``initial_state_rule_``, ``initial_values_``).
    z : ndarray, shape (T, nz), or None
        The trajectory's measured targets (needed by the "measured" rule only).
    n_rows_before : int
        Samples of the trajectory before its first estimated row (at least ``Mz`` for "measured").

    Returns
    -------
    ndarray, shape (Mz, nz)
        The past estimates, oldest first, physical units.

    Raises
    ------
    InputError
        The rule is "measured" and ``z`` is None.
    """
    lags = sensor.lags_
    if sensor.initial_state_rule_ == "measured":
        if z is None:
            raise InputError("this recurrent sensor starts from the measured z (initial state rule 'measured'): pass z")
        return np.asarray(z, dtype=float)[n_rows_before - lags.mz: n_rows_before]
    return np.array(sensor.initial_values_, dtype=float).reshape(lags.mz, lags.nz)
