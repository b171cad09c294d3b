"""Regressor vectors from lagged inputs and outputs (paper Section II).

For ``nu`` inputs with ``Mu`` lags and ``ny`` outputs with ``My`` lags the regressor at time ``t`` is

    xi(t) = [u(t-Mu+1)' ... u(t)'  y(t-My+1)' ... y(t)']'          (n = nu*Mu + ny*My)

i.e. oldest sample first, and within one time instant all channels of the signal in column order.
Rows exist for ``t = M-1 .. T-1`` (0-based) of each trajectory with ``M = max(Mu, My)``, so that no
regressor straddles two trajectories.

A *dynamical* (recurrent) sensor (``Mz >= 1``, issue 13) appends the ``nz * Mz`` past estimates

    xi(t) = [ ... u/y lags ...  z(t-Mz)' ... z(t-1)' ]'            (n = nu*Mu + ny*My + nz*Mz)

(oldest first, targets in column order). :meth:`LagStructure.build` forms the u/y part only;
:meth:`LagStructure.build_series_parallel` fills the z part with the *measured* z (the
series-parallel form used to fit); the recurrence itself (the estimates fed back) is run by
:mod:`pwas_hdl.fit.recurrent`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.limits import MAX_REGRESSORS, check_limit

__all__ = ["LagStructure", "as_trajectories"]


def as_trajectories(data: np.ndarray | Sequence[np.ndarray] | None, name: str, width: int | None = None) -> list[np.ndarray]:
    """Normalise one array or a list of arrays (one per trajectory) to a list of 2-D float arrays.

    Parameters
    ----------
    data : ndarray (T,) or (T, k), or a list of them, or None (no such signal)
        A plain list of numbers is one trajectory of one channel; a list of lists is refused (rows or
        trajectories? pass arrays).
    name : str
        Signal name for error messages ("u", "y", "z").
    width : int, optional
        Expected number of columns ``k`` (channels).

    Returns
    -------
    list of ndarray, each shape (T_i, k)

    Raises
    ------
    InputError
        Not 1-D / 2-D, complex, sparse, not numeric, a list of lists, NaN or infinite values, or not
        ``width`` columns.
    """
    if data is None:
        return []
    if type(data).__module__.startswith("scipy.sparse"):
        raise InputError(f"{name} is a scipy sparse matrix; pass a dense array ({name}.toarray()), samples x channels")
    if isinstance(data, np.ndarray) and data.dtype != object:
        items = [data]
    else:
        items = list(data)
        if items and all(np.ndim(a) == 0 for a in items):  # a plain list of numbers: one trajectory
            items = [np.asarray(items, dtype=float)]
        elif items and all(isinstance(a, (list, tuple)) for a in items):
            # rows of one trajectory ((T, k).tolist()) or k trajectories? Read as trajectories, rows of 2
            # channels became T two-sample trajectories of one channel and the fit went on: refused
            raise InputError(f"{name} is a list of lists, which could be the rows of one trajectory or several "
                             f"trajectories; pass a numpy array (samples x channels) for one trajectory, or a list "
                             f"of numpy arrays (one per trajectory)")
    out = []
    for i, a in enumerate(items):
        if np.iscomplexobj(a):  # numpy would drop the imaginary part with only a warning
            raise InputError(f"{name} trajectory {i} is complex; pass real signals (the real part, or magnitude and phase as two channels)")
        try:
            arr = np.asarray(a, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InputError(f"{name} trajectory {i} is not an array of numbers ({exc}); pass float arrays, samples x channels") from exc
        if arr.ndim == 1:
            arr = arr[:, None]
        if arr.ndim != 2:
            raise InputError(f"{name} trajectory {i} must be 1-D or 2-D (samples x channels), got shape {arr.shape}")
        if width is not None and arr.shape[1] != width:
            raise InputError(f"{name} trajectory {i} has {arr.shape[1]} channels, expected {width}")
        if not np.all(np.isfinite(arr)):
            bad = np.argwhere(~np.isfinite(arr))[0]
            raise InputError(
                f"{name} trajectory {i} has a NaN or infinite value at sample {bad[0]}, channel {bad[1]}; "
                "remove or interpolate missing samples before fitting"
            )
        out.append(arr)
    return out


@dataclass(frozen=True)
class LagStructure:
    """How many past samples of each signal form the regressor.

    Parameters
    ----------
    mu : int
        Number of input samples ``Mu >= 0`` (0: the inputs are not used).
    my : int
        Number of output samples ``My >= 0``.
    nu : int
        Number of input channels.
    ny : int
        Number of output channels.
    mz : int
        Number of past estimates ``Mz >= 0`` fed back (0: a static sensor).
    nz : int
        Number of fed-back targets (0 unless ``mz >= 1``).
    """

    mu: int
    my: int
    nu: int
    ny: int
    mz: int = 0
    nz: int = 0

    def __post_init__(self) -> None:
        for nm in ("mu", "my", "nu", "ny", "mz", "nz"):
            v = getattr(self, nm)
            if not isinstance(v, (int, np.integer)) or v < 0:
                raise InputError(f"{nm} must be a non-negative integer, got {v!r}")
        if self.mz and self.nz:
            check_limit("the regressor dimension n = nu*Mu + ny*My + nz*Mz", self.dimension, MAX_REGRESSORS,
                        "use fewer lags (--mu, --my, --mz) or fewer signals")
        check_limit("the regressor dimension n = nu*Mu + ny*My", self.dimension, MAX_REGRESSORS,
                    "use fewer lags (--mu, --my) or fewer signals")
        if self.mz and self.nz and self.io_dimension == 0:
            raise InputError("a recurrent sensor (Mz >= 1) needs at least one lag of a measured signal (Mu or My >= 1)")
        if self.dimension == 0:
            raise InputError(
                "the regressor is empty: give at least one lag of one signal (Mu*nu + My*ny >= 1)"
            )

    @property
    def dimension(self) -> int:
        """Regressor dimension ``n = nu*Mu + ny*My + nz*Mz``."""
        return self.nu * self.mu + self.ny * self.my + self.nz * self.mz

    @property
    def recurrent(self) -> bool:
        """True when past estimates are fed back (``Mz >= 1`` and at least one target)."""
        return bool(self.mz and self.nz)

    @property
    def io_dimension(self) -> int:
        """Dimensions from the measured u, y (``nu*Mu + ny*My``); the z lags follow them."""
        return self.nu * self.mu + self.ny * self.my

    @property
    def start(self) -> int:
        """First sample of a trajectory whose series-parallel regressor exists: ``max(M - 1, Mz)``."""
        return max(self.memory - 1, self.mz if self.nz else 0)

    @property
    def memory(self) -> int:
        """``M = max(Mu, My)``: samples of history a regressor needs."""
        return max(self.mu if self.nu else 0, self.my if self.ny else 0)

    def signal_of_dimension(self) -> list[tuple[str, int, int]]:
        """For each regressor dimension: (kind 'u', 'y' or 'z', channel, lag) with lag 0 = current sample.

        Returns
        -------
        list of (str, int, int)
            ``n`` tuples in regressor order: the inputs ``u`` (lags ``Mu - 1 .. 0``), the outputs
            ``y`` (lags ``My - 1 .. 0``), then the past estimates ``z`` (lags ``Mz .. 1``), each lag
            listing its channels in order.
        """
        out: list[tuple[str, int, int]] = []
        # no loop over the lags of a signal without channels (Mu = 10**30 with nu = 0 would never end)
        for lag in range(self.mu - 1, -1, -1) if self.nu else ():
            out += [("u", c, lag) for c in range(self.nu)]
        for lag in range(self.my - 1, -1, -1) if self.ny else ():
            out += [("y", c, lag) for c in range(self.ny)]
        for lag in range(self.mz, 0, -1) if self.nz else ():  # past estimates: lag >= 1
            out += [("z", c, lag) for c in range(self.nz)]
        return out

    def names(self, inputs: Sequence[str], outputs: Sequence[str], targets: Sequence[str] = ()) -> list[str]:
        """Human-readable regressor names such as ``y[t-3]``; past estimates are ``z_hat[t-1]``.

        Parameters
        ----------
        inputs, outputs, targets : sequence of str
            Names of the ``nu`` inputs, ``ny`` outputs and ``nz`` targets.

        Returns
        -------
        list of str
            ``n`` names in regressor order.
        """
        res = []
        for kind, ch, lag in self.signal_of_dimension():
            if kind == "z":
                base = f"{targets[ch] if ch < len(targets) else f'z{ch}'}_hat"
            else:
                base = inputs[ch] if kind == "u" else outputs[ch]
            res.append(f"{base}[t]" if lag == 0 else f"{base}[t-{lag}]")
        return res

    def build(self, u: np.ndarray | None, y: np.ndarray | None) -> np.ndarray:
        """Regressors of one trajectory.

        Parameters
        ----------
        u : ndarray, shape (T, nu) or None when nu == 0
        y : ndarray, shape (T, ny) or None when ny == 0

        Returns
        -------
        ndarray, shape (T - M + 1, n)
            Row ``i`` is ``xi(t)`` for ``t = M - 1 + i``.
        """
        t_len = self._length(u, y)
        m = self.memory
        if t_len < m:
            raise InputError(
                f"a trajectory has {t_len} samples but the lags need at least M = max(Mu, My) = {m}; "
                "use longer trajectories or fewer lags"
            )
        rows = t_len - m + 1
        cols = []
        for kind, ch, lag in self.signal_of_dimension():
            if kind == "z":
                continue  # the fed-back part: build_series_parallel / pwas_hdl.fit.recurrent
            sig = u if kind == "u" else y
            start = m - 1 - lag
            cols.append(sig[start : start + rows, ch])
        return np.stack(cols, axis=1) if cols else np.empty((rows, 0))

    def build_series_parallel(self, u: np.ndarray | None, y: np.ndarray | None, z: np.ndarray) -> np.ndarray:
        """Full regressors of one trajectory with the *measured* ``z`` in the fed-back dimensions.

        Parameters
        ----------
        u, y : as in :meth:`build`
        z : ndarray, shape (T, nz)
            The measured targets.

        Returns
        -------
        ndarray, shape (T - start, n)
            Row ``i`` is ``xi(t)`` for ``t = start + i`` (:attr:`start` ``= max(M - 1, Mz)``).
        """
        io = self.build(u, y)  # rows t = M-1 ..
        t_len = io.shape[0] + self.memory - 1
        if z.shape[0] != t_len:
            raise InputError(f"a target trajectory has {z.shape[0]} samples, its inputs/outputs {t_len}")
        s = self.start
        if t_len <= s:
            raise InputError(f"a trajectory has {t_len} samples but the lags and Mz = {self.mz} need more than {s}; give "
                             f"longer trajectories (or check --traj-col), or a smaller --mz")
        rows = t_len - s
        cols = []
        j = 0
        for kind, ch, lag in self.signal_of_dimension():
            if kind == "z":
                cols.append(z[s - lag : s - lag + rows, ch])
            else:
                cols.append(io[s - (self.memory - 1):, j])
                j += 1
        return np.stack(cols, axis=1)

    def _length(self, u: np.ndarray | None, y: np.ndarray | None) -> int:
        lens = []
        if self.nu:
            if u is None:
                raise InputError("the lag structure has inputs but no input data was given")
            lens.append(u.shape[0])
        if self.ny:
            if y is None:
                raise InputError("the lag structure has outputs but no output data was given")
            lens.append(y.shape[0])
        if len(set(lens)) > 1:
            raise InputError(f"inputs and outputs of a trajectory have different lengths {lens}")
        return lens[0]

    def build_many(self, us: list[np.ndarray], ys: list[np.ndarray], n_traj: int) -> tuple[np.ndarray, list[slice]]:
        """Regressors of several trajectories, stacked; also the sample slice each row block covers.

        Parameters
        ----------
        us, ys : list of ndarray, shapes (T_i, nu) and (T_i, ny)
            Inputs and outputs per trajectory (ignored when ``nu`` / ``ny`` is 0; then may be empty).
        n_traj : int
            Number of trajectories.

        Returns
        -------
        xi : ndarray, shape (sum_i (T_i - M + 1), n)
        valid : list of slice
            For trajectory ``i``, the samples ``t`` whose regressor exists (``slice(M - 1, T_i)``).
        """
        blocks, valid = [], []
        for i in range(n_traj):
            ui = us[i] if self.nu else None
            yi = ys[i] if self.ny else None
            xi = self.build(ui, yi)
            blocks.append(xi)
            valid.append(slice(self.memory - 1, self.memory - 1 + xi.shape[0]))
        return np.concatenate(blocks, axis=0), valid
