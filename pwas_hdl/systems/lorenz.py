"""Benchmark plants that generate (u, y, z) data, seeded and reproducible.

Each generator returns a :class:`PlantData` whose arrays have one row per sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.limits import check_seed

__all__ = ["PlantData", "stack_runs", "lorenz", "LORENZ_PARAMS"]

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
    run : ndarray of int, shape (T,), optional
        Trajectory index of each sample (several runs stacked; column ``run``). None: one run.
    mode : ndarray of int, shape (T,), optional
        The true active mode of a switched plant at each sample (column ``mode``).
    """

    u: np.ndarray
    y: np.ndarray
    z: np.ndarray
    z_true: np.ndarray
    names: dict
    run: np.ndarray | None = None
    mode: np.ndarray | None = None

    def _rows(self, sl: slice) -> "PlantData":
        pick = lambda a: None if a is None else a[sl]  # noqa: E731
        return PlantData(self.u[sl], self.y[sl], self.z[sl], self.z_true[sl], self.names, pick(self.run), pick(self.mode))

    def split(self, n_first: int) -> tuple["PlantData", "PlantData"]:
        """The first ``n_first`` samples and the rest, as two contiguous data sets.

        Parameters
        ----------
        n_first : int
            Samples in the first set (``0 <= n_first <= T``).

        Returns
        -------
        first, rest : PlantData
            Samples ``0 .. n_first-1`` and ``n_first .. T-1`` (every array cut along its rows).
        """
        return self._rows(slice(None, n_first)), self._rows(slice(n_first, None))

    def runs(self) -> list["PlantData"]:
        """One :class:`PlantData` per trajectory (consecutive samples with the same ``run``).

        Returns
        -------
        list of PlantData
            In sample order; ``[self]`` when there is no ``run`` column.
        """
        if self.run is None or len(self.run) == 0:
            return [self]
        cuts = [0] + [int(i) for i in np.flatnonzero(np.diff(self.run)) + 1] + [len(self.run)]
        return [self._rows(slice(a, b)) for a, b in zip(cuts[:-1], cuts[1:])]

    def columns(self, with_truth: bool = True) -> dict[str, np.ndarray]:
        """Named columns for a CSV file (:func:`pwas_hdl.io.csv_table.write_csv`).

        Parameters
        ----------
        with_truth : bool
            Add ``<z>_true``, the noise-free target, after the measured signals.

        Returns
        -------
        dict of str to ndarray, each shape (T,)
            The inputs, outputs and targets by name (physical units), then ``<z>_true``, then
            ``mode`` and ``run`` when the data have them.
        """
        cols: dict[str, np.ndarray] = {}
        for key, arr in (("u", self.u), ("y", self.y), ("z", self.z)):
            for i, nm in enumerate(self.names[key]):
                cols[nm] = arr[:, i]
        if with_truth:
            for i, nm in enumerate(self.names["z"]):
                cols[f"{nm}_true"] = self.z_true[:, i]
        if self.mode is not None:
            cols["mode"] = np.asarray(self.mode, dtype=int)
        if self.run is not None:
            cols["run"] = np.asarray(self.run, dtype=int)
        return cols


def stack_runs(parts: list[PlantData]) -> PlantData:
    """Concatenate trajectories into one :class:`PlantData` with a ``run`` index 0..K-1.

    Parameters
    ----------
    parts : list of PlantData
        K >= 1 trajectories with the same columns (the names and the presence of ``mode`` are
        taken from the first); their own ``run`` columns are ignored.

    Returns
    -------
    PlantData
        Every array concatenated along its rows (sum of the T_i samples); ``run`` (sum T_i,) is
        the index i of the part each sample comes from.
    """
    if not parts:
        raise InputError("stack_runs needs at least one trajectory")
    cat = lambda k: np.concatenate([getattr(p, k) for p in parts], axis=0)  # noqa: E731
    run = np.concatenate([np.full(len(p.y), i, dtype=int) for i, p in enumerate(parts)])
    mode = None if parts[0].mode is None else np.concatenate([p.mode for p in parts]).astype(int)
    return PlantData(cat("u"), cat("y"), cat("z"), cat("z_true"), parts[0].names, run, mode)


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
        raise InputError(f"n_samples must be >= 1, got {n_samples}")
    check_seed(seed)
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
