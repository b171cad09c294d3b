"""Normalisation and measurement noise of seed 004's data (Masti, Bernardini, Bemporad, EJC 2021).

Section 4.2 of the paper: "All signals are then normalized using the empirical average and
standard deviation computed on the training set and superimposed with a zero-mean white Gaussian
noise with a standard deviation of 0.03". So the noise is added *after* normalisation, in
normalised units, to every signal (u, y and the label z: assumption A4 of
``shared/design/seed-specs/seed_004.md``; E2 keeps its mode labels noise-free, B5). The true
label ``z_true`` is normalised with the same statistics and carries no noise (the metrics of
eq. 13 are taken against it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.systems.lorenz import PlantData

__all__ = ["Normalization", "normalize_with_noise"]


@dataclass(frozen=True)
class Normalization:
    """Empirical mean and standard deviation of each column of the training set.

    Attributes
    ----------
    mean, std : dict of str -> ndarray, shape (k,)
        Keys ``"u"``, ``"y"``, ``"z"``; physical units of each signal.
    """

    mean: dict
    std: dict

    @classmethod
    def of(cls, data: PlantData) -> "Normalization":
        """Statistics of ``data`` (the training set). A constant column gets std 1 (left unscaled).

        Parameters
        ----------
        data : PlantData
            The training set, physical units; ``u`` (T, nu), ``y`` (T, ny), ``z`` (T, nz).

        Returns
        -------
        Normalization
            ``mean[key]`` and ``std[key]`` of shape (k,) per column of ``data.<key>`` (``(0,)`` for no columns).
        """
        mean, std = {}, {}
        for key in ("u", "y", "z"):
            arr = getattr(data, key)
            m = arr.mean(axis=0) if arr.shape[1] else np.zeros(0)
            s = arr.std(axis=0) if arr.shape[1] else np.zeros(0)
            mean[key], std[key] = m, np.where(s > 0, s, 1.0)
        return cls(mean, std)

    def apply(self, key: str, arr: np.ndarray) -> np.ndarray:
        """``(arr - mean) / std`` of signal ``key``.

        Parameters
        ----------
        key : {"u", "y", "z"}
            Which signal's statistics.
        arr : numpy.ndarray, shape (T, k)
            Values in physical units, k the number of columns of that signal (a (k,) row broadcasts too).

        Returns
        -------
        numpy.ndarray
            Shape of ``arr``: the normalised values (dimensionless).
        """
        return (arr - self.mean[key]) / self.std[key]

    def invert(self, key: str, arr: np.ndarray) -> np.ndarray:
        """Physical units from normalised values of signal ``key``.

        Parameters
        ----------
        key : {"u", "y", "z"}
            Which signal's statistics.
        arr : numpy.ndarray, shape (T, k)
            Normalised values, k the number of columns of that signal (a (k,) row broadcasts too).

        Returns
        -------
        numpy.ndarray
            Shape of ``arr``: ``arr * std + mean``, in the signal's physical units.
        """
        return arr * self.std[key] + self.mean[key]

    def to_dict(self) -> dict:
        """JSON-ready statistics.

        Returns
        -------
        dict
            ``{key: {"mean": [...], "std": [...]}}`` for ``key`` in ``"u"``, ``"y"``, ``"z"`` (lists
            of floats, physical units).
        """
        return {k: {"mean": [float(v) for v in self.mean[k]], "std": [float(v) for v in self.std[k]]} for k in self.mean}


def normalize_with_noise(
    train: PlantData,
    others: list[PlantData],
    noise: float,
    rng: np.random.Generator,
    noisy_target: bool = True,
) -> tuple[PlantData, list[PlantData], Normalization]:
    """Normalise with the training statistics, then add white Gaussian noise of std ``noise``.

    Parameters
    ----------
    train : PlantData
        Noise-free training data in physical units (its ``z`` equals ``z_true``).
    others : list of PlantData
        Further noise-free sets (test sets), normalised with the *training* statistics.
    noise : float
        Standard deviation of the noise in normalised units (paper: 0.03; Table 2: 0.01, 0.06).
    rng : numpy.random.Generator
        Source of the noise.
    noisy_target : bool
        Add noise to the label ``z`` too (E1, E3: assumption A4). ``False`` for E2 (clean modes).

    Returns
    -------
    train_n, others_n : PlantData
        ``u``, ``y``, ``z`` normalised and noisy; ``z_true`` normalised and noise-free.
    norm : Normalization
        The statistics used.
    """
    if not (noise >= 0 and np.isfinite(noise)):
        raise InputError(f"noise must be a standard deviation >= 0 (normalised units), got {noise!r}")
    norm = Normalization.of(train)

    def one(d: PlantData) -> PlantData:
        u = norm.apply("u", d.u)
        y = norm.apply("y", d.y)
        zt = norm.apply("z", d.z_true)
        u = u + rng.normal(0.0, noise, u.shape)
        y = y + rng.normal(0.0, noise, y.shape)
        z = zt + rng.normal(0.0, noise, zt.shape) if noisy_target else zt.copy()
        return PlantData(u, y, z, zt, d.names)

    tr = one(train)
    return tr, [one(d) for d in others], norm
