"""The three-tank plant of seed 001 (Sergiyenko et al., *Symmetry* 2023, Section 5, eq. 26).

Equations (as reconstructed in ``seed-specs/seed_001.md`` §1; ``sq(d) = sign(d) sqrt(|d|)``,
assumption **A1**: the signed root, physical flow reversal)::

    x1(t+1) = a4 u1(t) - a1 sq(x1(t) - x2(t)) + x1(t) + rho(t)
    x2(t+1) = a5 u2(t) + a1 sq(x1(t) - x2(t)) - a2 sq(x2(t) - x3(t)) + x2(t)
    x3(t+1) = a2 sq(x2(t) - x3(t)) - a3 sq(x3(t)) + x3(t)
    y(t)    = x2(t) (+ optional Gaussian measurement noise)

with ``a1 = a2 = a3 = a4 = 0.1``, ``a5 = 0.2`` (§1.1), inputs ``u1 = u2 = 1 + sin(t + phase)``
(**A6**: t is the integer step index, radians) and the disturbance ``rho(t) ~ U[-0.15, 0.15]``
i.i.d. from a given step on, zero before (**A5**). The paper's run (**A7**: T = 1000 steps) starts
from ``x(0) = (8, 2, 1)`` with ``rho`` on from ``t = 100`` and phase 0; training runs (§4, an
assumption of the spec) start from random admissible levels ``x1 >= x2 >= x3 >= 0`` in [0, 25],
with a random input phase and ``rho`` on from ``t = 0``.

The estimation targets are ``x1`` and ``x3`` (the paper's ``nu = x1 x x3``); ``u`` holds both
inputs (they are equal in the paper's experiment, so an estimator should use only ``u1``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from pwas_hdl.errors import InputError
from pwas_hdl.systems.lorenz import PlantData, stack_runs

__all__ = ["THREE_TANK_PARAMS", "THREE_TANK_ASSUMPTIONS", "signed_sqrt", "three_tank_step", "simulate_three_tank",
           "three_tank_paper_run", "three_tank_training_runs"]

#: Coefficients and disturbance of Section 5 (seed_001.md §1.1).
THREE_TANK_PARAMS = {"a1": 0.1, "a2": 0.1, "a3": 0.1, "a4": 0.1, "a5": 0.2, "rho_max": 0.15}

#: The spec's assumptions used here (ids of seed-specs/seed_001.md §5 and §4).
THREE_TANK_ASSUMPTIONS = {
    "seed_001.A1": "signed square root sgn(d) sqrt(|d|) in the plant and in the paper's sensors",
    "seed_001.A2": "signs and roots of eqs. (26)-(28) as reconstructed in seed_001.md §1-2",
    "seed_001.A3": "B = [[a4, 0], [0, a5], [0, 0]] (the printed B is a typo)",
    "seed_001.A4": "sensor initial states z1(0) = 5 (x1 sensor, eq. 27), z2(0) = 2 (x3 sensor, eq. 28)",
    "seed_001.A5": "rho(t) i.i.d. U[-0.15, 0.15] for t >= 100 on the paper's run (t >= 0 on training runs), 0 before",
    "seed_001.A6": "t is the integer step index; u1 = u2 = 1 + sin(t) in radians",
    "seed_001.A7": "paper-replica run of T = 1000 steps from x(0) = (8, 2, 1)",
    "seed_001.A8": "metric: RMSE per estimated state over t >= 100 (and over t < 100)",
    "seed_001.4-training": "training: K runs of 1000 steps from random admissible x1 >= x2 >= x3 >= 0 in [0, 25], "
    "input phase uniform in [0, 2 pi), rho on from t = 0",
}


def signed_sqrt(d: ArrayLike) -> np.ndarray:
    """``sign(d) sqrt(|d|)`` (assumption A1), elementwise.

    Parameters
    ----------
    d : array_like, any shape (a scalar too)
        Level differences (or levels), in the plant's level unit (the paper gives none).

    Returns
    -------
    numpy.ndarray
        Float array of the shape of ``d`` (0-d for a scalar): the signed root.
    """
    d = np.asarray(d, dtype=float)
    return np.sign(d) * np.sqrt(np.abs(d))


def three_tank_step(x: np.ndarray, u1: float, u2: float, rho: float, prm: dict = THREE_TANK_PARAMS) -> np.ndarray:
    """One step of eq. (26): ``x(t) -> x(t+1)`` for levels ``x`` of shape (3,).

    Parameters
    ----------
    x : numpy.ndarray, shape (3,)
        Levels ``[x1, x2, x3]`` at step t (the paper gives no unit; the time unit is one step).
    u1, u2 : float
        Inflows into tanks 1 and 2 at step t (level units per step, scaled by ``a4`` and ``a5``).
    rho : float
        Disturbance added to ``x1(t+1)`` (level units).
    prm : dict
        Coefficients ``a1``..``a5`` (keys as in :data:`THREE_TANK_PARAMS`; ``rho_max`` unused here).

    Returns
    -------
    numpy.ndarray
        Shape (3,): the levels ``x(t+1)``.
    """
    a1, a2, a3, a4, a5 = (prm[k] for k in ("a1", "a2", "a3", "a4", "a5"))
    q12, q23, q3 = signed_sqrt(x[0] - x[1]), signed_sqrt(x[1] - x[2]), signed_sqrt(x[2])
    return np.array([
        a4 * u1 - a1 * q12 + x[0] + rho,
        a5 * u2 + a1 * q12 - a2 * q23 + x[1],
        a2 * q23 - a3 * q3 + x[2],
    ])


def simulate_three_tank(
    samples: int,
    x0: ArrayLike,
    rho_start: int,
    rng: np.random.Generator,
    phase: float = 0.0,
    noise: float = 0.0,
    prm: dict = THREE_TANK_PARAMS,
) -> PlantData:
    """One trajectory of eq. (26).

    Parameters
    ----------
    samples : int
        Steps T; sample ``t`` holds ``x(t)``, ``u(t)``, ``y(t)`` for t = 0..T-1.
    x0 : array_like, shape (3,)
        Initial levels.
    rho_start : int
        First step with the disturbance on.
    rng : numpy.random.Generator
        Source of ``rho`` (drawn first, T values) and of the seed of the y noise (drawn
        whatever ``noise`` is, so that the states do not depend on the noise level).
    phase : float
        Input phase (rad): ``u1 = u2 = 1 + sin(t + phase)``.
    noise : float
        Standard deviation of the Gaussian noise on ``y`` (the paper has none).
    prm : dict
        Coefficients ``a1``..``a5`` and the disturbance bound ``rho_max`` (``rho ~ U[-rho_max, rho_max]``),
        keys as in :data:`THREE_TANK_PARAMS`.

    Returns
    -------
    PlantData
        ``u`` (T, 2) ``[u1, u2]``; ``y`` (T, 1) ``x2`` + noise; ``z`` = ``z_true`` (T, 2) ``[x1, x3]``.
    """
    if samples < 1:
        raise InputError(f"samples must be >= 1, got {samples}")
    if noise < 0:
        raise InputError(f"the noise standard deviation must be >= 0, got {noise}")
    t = np.arange(samples)
    u = 1.0 + np.sin(t + phase)
    rho = rng.uniform(-prm["rho_max"], prm["rho_max"], samples)
    rho[t < rho_start] = 0.0
    noise_rng = np.random.default_rng(rng.integers(2**63))  # always drawn: the noise level does not change the states
    x = np.array(x0, dtype=float).reshape(3)
    traj = np.empty((samples, 3))
    for k in range(samples):
        traj[k] = x
        x = three_tank_step(x, u[k], u[k], rho[k], prm)
    y = traj[:, 1:2] + (noise_rng.normal(0.0, noise, (samples, 1)) if noise > 0 else 0.0)
    z = traj[:, [0, 2]]
    names = {"u": ["u1", "u2"], "y": ["y"], "z": ["x1", "x3"]}
    return PlantData(np.column_stack([u, u]), y, z.copy(), z.copy(), names)


def three_tank_paper_run(samples: int = 1000, seed: int = 0, noise: float = 0.0) -> PlantData:
    """The paper's run (Section 5, Fig. 2): ``x(0) = (8, 2, 1)``, ``rho`` from t = 100, phase 0.

    Parameters
    ----------
    samples : int
        Steps T (the spec's replica, A7, has 1000).
    seed : int
        Seed of the generator that draws the disturbance (and the seed of the y noise).
    noise : float
        Standard deviation of the Gaussian noise on ``y`` (the paper has none).

    Returns
    -------
    PlantData
        One trajectory as in :func:`simulate_three_tank` (``u`` (T, 2), ``y`` (T, 1), ``z`` (T, 2)
        ``[x1, x3]``), with ``run`` (T,) all 0.
    """
    d = simulate_three_tank(samples, (8.0, 2.0, 1.0), 100, np.random.default_rng(seed), 0.0, noise)
    d.run = np.zeros(samples, dtype=int)
    return d


def three_tank_training_runs(runs: int = 20, samples: int = 1000, seed: int = 0, noise: float = 0.0) -> PlantData:
    """``runs`` training trajectories (seed_001.md §4): random admissible levels and input phase.

    Levels: three values uniform in [0, 25], sorted so that ``x1 >= x2 >= x3``; phase uniform in
    [0, 2 pi); ``rho`` on from t = 0. The ``run`` column numbers the trajectories 0..runs-1.

    Parameters
    ----------
    runs : int
        Number of trajectories K (>= 1).
    samples : int
        Steps T per trajectory.
    seed : int
        Seed of the one generator that draws every run's levels, phase, disturbance and noise seed.
    noise : float
        Standard deviation of the Gaussian noise on ``y``.

    Returns
    -------
    PlantData
        The runs stacked: ``u`` (K T, 2), ``y`` (K T, 1), ``z`` (K T, 2) ``[x1, x3]``, ``run`` (K T,).
    """
    if runs < 1:
        raise InputError(f"runs must be >= 1, got {runs}")
    rng = np.random.default_rng(seed)
    parts = []
    for _ in range(runs):
        x0 = np.sort(rng.uniform(0.0, 25.0, 3))[::-1]
        phase = rng.uniform(0.0, 2 * np.pi)
        parts.append(simulate_three_tank(samples, x0, 0, rng, phase, noise))
    return stack_runs(parts)
