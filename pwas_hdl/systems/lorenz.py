"""Benchmark plants that generate (u, y, z) data, seeded and reproducible.

Each generator returns a :class:`PlantData` whose arrays have one row per sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PlantData", "lorenz", "LORENZ_PARAMS"]

#: Parameters of the discrete Lorenz system, paper eq. (18).
LORENZ_PARAMS = {"tau": 0.01, "s": 10.0, "beta": 8.0 / 3.0, "rho": 28.0, "noise_y": 0.02, "noise_z": 20.0}


@dataclass
class PlantData:
    """Sampled data of a plant.

    Attributes
    ----------
    u : ndarray, shape (T, nu)
        Inputs (``nu`` may be 0).
    y : ndarray, shape (T, ny)
        Measured outputs, with measurement noise.
    z : ndarray, shape (T, nz)
        The quantity to estimate as a real sensor measures it (with its noise).
    z_true : ndarray, shape (T, nz)
        The noise-free quantity (for RMSEE, eq. 17).
    names : dict
        Column names: ``{"u": [...], "y": [...], "z": [...]}``.
    """

    u: np.ndarray
    y: np.ndarray
    z: np.ndarray
    z_true: np.ndarray
    names: dict

    def split(self, n_first: int) -> tuple["PlantData", "PlantData"]:
        """The first ``n_first`` samples and the rest, as two contiguous data sets."""
        a = PlantData(self.u[:n_first], self.y[:n_first], self.z[:n_first], self.z_true[:n_first], self.names)
        b = PlantData(self.u[n_first:], self.y[n_first:], self.z[n_first:], self.z_true[n_first:], self.names)
        return a, b

    def columns(self, with_truth: bool = True) -> dict[str, np.ndarray]:
        """Named columns for a CSV file (``<z>_true`` holds the noise-free target)."""
        cols: dict[str, np.ndarray] = {}
        for key, arr in (("u", self.u), ("y", self.y), ("z", self.z)):
            for i, nm in enumerate(self.names[key]):
                cols[nm] = arr[:, i]
        if with_truth:
            for i, nm in enumerate(self.names["z"]):
                cols[f"{nm}_true"] = self.z_true[:, i]
        return cols


def lorenz(n_samples: int, seed: int = 0, burn_in: int = 1000, x0: np.ndarray | None = None) -> PlantData:
    """Discrete-time Lorenz system of paper eq. (18), autonomous (``nu = 0``).

    ``x1(t+1) = (1 - tau s) x1 + tau s x2``,
    ``x2(t+1) = (1 - tau) x2 - tau x1 x3 + tau rho x1``,
    ``x3(t+1) = (1 - tau beta) x3 + tau x1 x2``;
    ``y = x1 + eta_y``, ``z = x2 x3 + eta_z`` with Gaussian noise of standard deviation 0.02 and 20.

    Parameters
    ----------
    n_samples : int
        Samples returned (after the burn-in).
    seed : int
        Seed of the initial state and of the noise (``numpy.random.default_rng``).
    burn_in : int
        Samples simulated and dropped first so that the state is on the attractor.
    x0 : ndarray, shape (3,), optional
        Initial state (default: drawn uniformly in [-10, 10] x [-10, 10] x [10, 30]).

    Returns
    -------
    PlantData
        ``u`` is empty (T, 0); ``y`` is (T, 1) named ``y``; ``z`` is (T, 1) named ``z``.
    """
    if n_samples < 1:
        raise ValueError(f"n_samples must be >= 1, got {n_samples}")
    prm = LORENZ_PARAMS
    tau, s, beta, rho = prm["tau"], prm["s"], prm["beta"], prm["rho"]
    rng = np.random.default_rng(seed)
    x = np.array(x0, dtype=float) if x0 is not None else rng.uniform([-10, -10, 10], [10, 10, 30])
    total = burn_in + n_samples
    traj = np.empty((total, 3))
    for t in range(total):
        traj[t] = x
        x1, x2, x3 = x
        x = np.array(
            [
                (1 - tau * s) * x1 + tau * s * x2,
                (1 - tau) * x2 - tau * x1 * x3 + tau * rho * x1,
                (1 - tau * beta) * x3 + tau * x1 * x2,
            ]
        )
    traj = traj[burn_in:]
    z_true = (traj[:, 1] * traj[:, 2])[:, None]
    y = traj[:, :1] + rng.normal(0.0, prm["noise_y"], (n_samples, 1))
    z = z_true + rng.normal(0.0, prm["noise_z"], (n_samples, 1))
    return PlantData(np.empty((n_samples, 0)), y, z, z_true, {"u": [], "y": ["y"], "z": ["z"]})
