"""The switched (piecewise) linear plant of seed 003 (Morales-Morales et al., *Sensors* 2013, eq. 11).

``x_{k+1} = A(theta_k) x_k + B(theta_k) u_k``, ``y_k = C(theta_k) x_k`` (+ optional Gaussian
output noise, assumption **A7**), three modes (``theta in {1, 2, 3}``), ``n = 2``, ``m = p = 1``::

    A1 = [[0.6, 0.10], [-0.195, 0.79]]    B1 = [0.20, 0.20]
    A2 = [[0.45, 0.16], [-0.36, 0.545]]   B2 = [0.5, 0.5]
    A3 = [[0.59, 0.10], [-0.195, 0.79]]   B3 = [0.6, 0.7]     C1 = C2 = C3 = (1 1)

The paper gives no switching law, input, sample time or initial state; the spec's assumptions
(``seed-specs/seed_003.md`` §5) are used and recorded in :data:`SWITCHED_ASSUMPTIONS`:

* **A1** T_s = 1: the paper's "100 seconds" are 100 samples; longer runs for training.
* **A2** switching: ``time`` -- cyclic 1 -> 2 -> 3 -> 1 with dwell ``D`` samples (fixed, or random
  in [20, 50]); ``output`` -- at dwell boundaries only (minimum dwell 20), ``theta`` from output
  thresholds (1 if ``y < c1``, 2 if ``c1 <= y < c2``, else 3) with ``c1, c2`` the terciles of
  ``y`` of a time-switched pilot run with the same input.
* **A5** inputs: ``step`` (u = 1), ``prbs`` (levels {0, 2} redrawn every 5 samples), ``sine``
  (``1 + 0.5 sin(0.1 k)``).
* **A6** ``x_0 = (0.5, 0.5)`` on the paper-replica run; training runs draw ``x_0`` uniformly in [0, 2]^2.

The true mode is recorded (``PlantData.mode``, labels 1..3); the targets are the states x1, x2.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from pwas_hdl.errors import InputError, choice_text
from pwas_hdl.systems.lorenz import PlantData, stack_runs

__all__ = ["SWITCHED_A", "SWITCHED_B", "SWITCHED_C", "SWITCHED_ASSUMPTIONS", "SWITCHING_LAWS", "INPUT_KINDS",
           "switched_input", "simulate_switched", "switched_paper_run", "switched_training_runs"]

#: Mode matrices of eq. (11), index 0..2 for modes 1..3.
SWITCHED_A = (
    np.array([[0.6, 0.10], [-0.195, 0.79]]),
    np.array([[0.45, 0.16], [-0.36, 0.545]]),
    np.array([[0.59, 0.10], [-0.195, 0.79]]),
)
SWITCHED_B = (np.array([0.20, 0.20]), np.array([0.5, 0.5]), np.array([0.6, 0.7]))
SWITCHED_C = (np.array([1.0, 1.0]),) * 3

SWITCHING_LAWS = ("time", "output")
INPUT_KINDS = ("step", "prbs", "sine")

SWITCHED_ASSUMPTIONS = {
    "seed_003.A1": "T_s = 1 sample; the paper's 100 s run = 100 samples; training runs are longer",
    "seed_003.A2": "switching 'time': cyclic 1->2->3->1, dwell D (34 on the paper replica, random in [20, 50] otherwise); "
    "'output': at dwell boundaries (min dwell 20) theta from terciles of y of a time-switched pilot run",
    "seed_003.A5": "input 'step' u = 1, 'prbs' levels {0, 2} redrawn every 5 samples, 'sine' 1 + 0.5 sin(0.1 k)",
    "seed_003.A6": "x0 = (0.5, 0.5) on the paper replica, U[0, 2]^2 on training runs; observers start at 0",
    "seed_003.A7": "optional Gaussian output noise (std 0.01-0.05 in the noise study); none on the replica",
    "seed_003.A9": "PWAS trained on long random runs (random dwell, PRBS input, random x0), tested on independent runs",
}


def switched_input(kind: str, samples: int, rng: np.random.Generator) -> np.ndarray:
    """Input sequence of assumption A5, shape (samples,).

    Parameters
    ----------
    kind : {"step", "prbs", "sine"}
        ``step``: u = 1; ``prbs``: levels {0, 2} redrawn every 5 samples; ``sine``: ``1 + 0.5 sin(0.1 k)``
        (k the sample index, radians).
    samples : int
        Length T of the sequence (samples; T_s = 1, assumption A1).
    rng : numpy.random.Generator
        Draws the PRBS levels (``ceil(T / 5)`` of them); unused by ``step`` and ``sine``.

    Returns
    -------
    numpy.ndarray
        Shape (samples,): the input ``u_k``.
    """
    k = np.arange(samples)
    if kind == "step":
        return np.ones(samples)
    if kind == "sine":
        return 1.0 + 0.5 * np.sin(0.1 * k)
    if kind == "prbs":
        levels = rng.choice([0.0, 2.0], size=-(-samples // 5))
        return np.repeat(levels, 5)[:samples]
    raise InputError(choice_text("--input-signal (input_kind)", INPUT_KINDS, kind))


def _dwells(samples: int, dwell, rng: np.random.Generator) -> list[int]:
    out, total = [], 0
    while total < samples:
        d = int(dwell) if np.isscalar(dwell) else int(rng.integers(dwell[0], dwell[1] + 1))
        if d < 1:
            raise InputError(f"dwell must be >= 1, got {d}")
        out.append(d)
        total += d
    return out


def _run(u: np.ndarray, x0: np.ndarray, modes_for) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Simulate with ``modes_for(k, y_k, theta_prev) -> theta_k`` (labels 1..3)."""
    T = u.size
    x = np.array(x0, dtype=float).reshape(2)
    xs, ys, th = np.empty((T, 2)), np.empty(T), np.empty(T, dtype=int)
    theta = 1
    for k in range(T):
        yk_pre = float(SWITCHED_C[theta - 1] @ x)  # C is the same for every mode
        theta = modes_for(k, yk_pre, theta)
        xs[k], ys[k], th[k] = x, SWITCHED_C[theta - 1] @ x, theta
        x = SWITCHED_A[theta - 1] @ x + SWITCHED_B[theta - 1] * u[k]
    return xs, ys, th


def simulate_switched(
    samples: int,
    rng: np.random.Generator,
    switching: str = "time",
    input_kind: str = "prbs",
    dwell: int | tuple[int, int] = (20, 50),
    x0: ArrayLike = (0.5, 0.5),
    noise: float = 0.0,
) -> PlantData:
    """One trajectory of eq. (11).

    Parameters
    ----------
    samples : int
        Samples T (k = 0..T-1); sample ``k`` holds ``x_k``, ``u_k``, ``y_k`` and ``theta_k``.
    rng : numpy.random.Generator
        Draws, in order: the input, the dwell times, the seed of the output noise.
    switching : {"time", "output"}
        Switching law of assumption A2.
    input_kind : {"step", "prbs", "sine"}
        Input of assumption A5.
    dwell : int or (int, int)
        Fixed dwell or the inclusive range of the random dwell (samples). For ``output`` the
        lower bound is at least 20 (the minimum dwell of A2).
    x0 : array_like, shape (2,)
        Initial state ``x_0``.
    noise : float
        Standard deviation of the Gaussian noise on ``y``.

    Returns
    -------
    PlantData
        ``u`` (T, 1), ``y`` (T, 1), ``z`` = ``z_true`` (T, 2) = ``[x1, x2]``, ``mode`` (T,) in 1..3.
    """
    if samples < 1:
        raise InputError(f"samples must be >= 1, got {samples}")
    if noise < 0:
        raise InputError(f"the noise standard deviation must be >= 0, got {noise}")
    if switching not in SWITCHING_LAWS:
        raise InputError(choice_text("--switching (switching)", SWITCHING_LAWS, switching))
    u = switched_input(input_kind, samples, rng)
    dw = _dwells(samples, dwell, rng)
    noise_rng = np.random.default_rng(rng.integers(2**63))  # always drawn: the noise level does not change the states
    starts = np.cumsum([0] + dw[:-1])
    cyc = np.zeros(samples, dtype=int)
    for i, (s, d) in enumerate(zip(starts, dw)):
        cyc[s : s + d] = i % 3 + 1
    if switching == "time":
        xs, ys, th = _run(u, x0, lambda k, y, prev: int(cyc[k]))
    else:
        _, ypilot, _ = _run(u, x0, lambda k, y, prev: int(cyc[k]))
        c1, c2 = np.quantile(ypilot, [1 / 3, 2 / 3])
        boundary = np.zeros(samples, dtype=bool)
        lo, hi = (dwell, dwell) if np.isscalar(dwell) else dwell
        b = 0
        for d in _dwells(samples, (max(int(lo), 20), max(int(hi), 20)), rng):  # minimum dwell 20 (A2)
            if b < samples:
                boundary[b] = True
            b += d

        def law(k, y, prev):
            if not boundary[k]:
                return prev
            return 1 if y < c1 else (2 if y < c2 else 3)

        xs, ys, th = _run(u, x0, law)
    y = ys[:, None] + (noise_rng.normal(0.0, noise, (samples, 1)) if noise > 0 else 0.0)
    names = {"u": ["u"], "y": ["y"], "z": ["x1", "x2"]}
    return PlantData(u[:, None], y, xs.copy(), xs.copy(), names, None, th)


def switched_paper_run(samples: int = 100, seed: int = 0, switching: str = "time", input_kind: str = "step",
                       noise: float = 0.0) -> PlantData:
    """The paper-replica run (A1, A2, A5, A6): 100 samples, dwell 34, ``x0 = (0.5, 0.5)``.

    Parameters
    ----------
    samples : int
        Samples T (the paper's "100 seconds" are 100 samples, A1).
    seed : int
        Seed of the generator passed to :func:`simulate_switched`.
    switching : {"time", "output"}
        Switching law of assumption A2 (fixed dwell 34 samples).
    input_kind : {"step", "prbs", "sine"}
        Input of assumption A5.
    noise : float
        Standard deviation of the Gaussian noise on ``y`` (none on the replica, A7).

    Returns
    -------
    PlantData
        As in :func:`simulate_switched` (``u`` (T, 1), ``y`` (T, 1), ``z`` (T, 2), ``mode`` (T,)),
        with ``run`` (T,) all 0.
    """
    d = simulate_switched(samples, np.random.default_rng(seed), switching, input_kind, 34, (0.5, 0.5), noise)
    d.run = np.zeros(samples, dtype=int)
    return d


def switched_training_runs(runs: int = 10, samples: int = 1000, seed: int = 0, switching: str = "time",
                           input_kind: str = "prbs", noise: float = 0.0,
                           dwell: int | tuple[int, int] = (20, 50)) -> PlantData:
    """``runs`` long trajectories (A9): random dwell in ``dwell``, the given input, ``x0 ~ U[0, 2]^2``.

    Parameters
    ----------
    runs : int
        Number of trajectories K (>= 1).
    samples : int
        Samples T per trajectory.
    seed : int
        Seed of the one generator that draws every run's input, dwells, noise seed and ``x0``.
    switching : {"time", "output"}
        Switching law of assumption A2.
    input_kind : {"step", "prbs", "sine"}
        Input of assumption A5.
    noise : float
        Standard deviation of the Gaussian noise on ``y``.
    dwell : int or (int, int)
        Fixed dwell or the inclusive range of the random dwell (samples), as in :func:`simulate_switched`.

    Returns
    -------
    PlantData
        The runs stacked: ``u`` (K T, 1), ``y`` (K T, 1), ``z`` (K T, 2), ``mode`` (K T,), ``run`` (K T,).
    """
    if runs < 1:
        raise InputError(f"runs must be >= 1, got {runs}")
    rng = np.random.default_rng(seed)
    parts = [simulate_switched(samples, rng, switching, input_kind, dwell, rng.uniform(0.0, 2.0, 2), noise)
             for _ in range(runs)]
    return stack_runs(parts)
