"""Reduced-complexity additive PWAS functions: ``f(x) = sum_i f_i(x_{S_i})`` (issue 15, item 1).

Each part ``f_i`` is a PWAS function (:class:`~pwas_hdl.fit.geometry.Grid`, Kuhn partition) on a
subset ``S_i`` of the regressor dimensions. A full PWAS function with ``n`` regressors and ``p``
intervals per dimension has ``(p + 1)**n`` weights (``n = 8``, ``p = 7``: 16.7 M); the sum of
``k`` parts of ``d`` dimensions each has ``k (p + 1)**d`` (``d = 2``: 448).

Subsets (:func:`parse_additive`, the ``fit --additive`` values)
    ``time``: one part per time instant (every regressor of lag ``l``, all signals);
    ``pairs`` / ``triples``: sliding windows of 2 / 3 consecutive lags (all signals of those lags);
    ``"0,1;1,2;..."``: the given regressor indices (``0 .. n-1``, the order of
    ``LagStructure.names``), parts separated by ``;``. Inside a part the indices are sorted (the
    part's grid keeps the regressor order); a part may not be empty, repeat an index, or repeat
    another part. Parts may overlap, and a regressor may be in no part.
Shared domain
    Every part uses the sensor's domain box and partitions on its dimensions
    (``lo[S_i], hi[S_i], p[S_i]``), so one regressor has the same grid coordinate, and the same
    input code, in every part (the hardware scales each signal once).
Weights
    Stacked in part order: ``w = [w_1; w_2; ...; w_k]`` (``sum_i N_i`` rows), each block in the
    vertex order of its own grid. The basis matrix is ``H = [H_1 ... H_k]`` (sparse,
    ``sum_i (|S_i| + 1)`` entries per row).
Fit
    Jointly, by the one regularised least-squares machinery of
    :mod:`pwas_hdl.fit.regularized_lsq` with ``Gamma = blockdiag(Gamma_1, ..., Gamma_k)`` (one
    Tikhonov term per part; sigma by cross-validation as for the full sensor).
Identifiability
    The sum is not identifiable: a constant (and, for overlapping parts, any function of the shared
    regressors that is PWAS on both grids) can move from one part to another without changing
    ``f``. ``H'H`` is then singular; the Tikhonov term makes ``H'H + sigma Gamma`` positive
    definite, so the fit is unique: the split of ``f`` among the parts is the one with the least
    penalty (zero order: the least ``sum_i ||w_i||^2``; first order: the least gradient energy
    plus the small ridge ``FIRST_ORDER_RIDGE``). The parts are therefore not meaningful alone,
    only their sum is.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Sequence

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.fit.geometry import Grid, _as_partitions
from pwas_hdl.limits import MAX_VERTICES, check_limit

if TYPE_CHECKING:
    import scipy.sparse

__all__ = ["ADDITIVE_KINDS", "ADDITIVE_DIRECT_MAX_UNKNOWNS", "parse_additive", "AdditiveGrid", "additive_tikhonov_matrix",
           "additive_solver_method"]

#: The named subset rules of ``fit --additive`` (besides explicit index lists).
ADDITIVE_KINDS = ("time", "pairs", "triples")

_WINDOW = {"time": 1, "pairs": 2, "triples": 3}


def _lags_of(dims: Sequence[tuple[str, int, int]]) -> list[int]:
    """Distinct lags, oldest first."""
    return sorted({lag for _, _, lag in dims}, reverse=True)


def parse_additive(spec: str | Sequence[Sequence[int]], dims: Sequence[tuple[str, int, int]]) -> tuple[tuple[int, ...], ...]:
    """The regressor subsets of an additive sensor.

    Parameters
    ----------
    spec : str or sequence of sequences of int
        ``"time"``, ``"pairs"``, ``"triples"``, an explicit ``"0,1;1,2"`` or the subsets themselves.
    dims : sequence of (kind, channel, lag)
        One per regressor dimension (:meth:`LagStructure.signal_of_dimension`); ``n = len(dims)``.

    Returns
    -------
    tuple of tuple of int
        The parts, each a sorted tuple of regressor indices; parts of the named rules come oldest
        lag first.

    Raises
    ------
    InputError
        Unknown rule, too few lags for the window, an index that is not an integer in
        ``0 .. n-1``, an empty part, an index twice in one part, or the same part twice.
    """
    n = len(dims)
    if n == 0:
        raise InputError("an additive sensor needs at least one regressor")
    if isinstance(spec, str):
        text = spec.strip()
        if text in _WINDOW:
            width = _WINDOW[text]
            lags = _lags_of(dims)
            if len(lags) < width:
                raise InputError(
                    f"--additive {text} needs at least {width} lags per signal, the regressor has {len(lags)} "
                    f"distinct lag{'s' if len(lags) != 1 else ''} ({', '.join(f't-{v}' if v else 't' for v in lags)}); use more "
                    f"lags (--my/--mu) or another --additive"
                )
            parts = []
            for i in range(len(lags) - width + 1):
                window = set(lags[i : i + width])
                parts.append(tuple(j for j, (_, _, lag) in enumerate(dims) if lag in window))
            return tuple(parts)
        if not text:
            raise InputError(f"--additive is empty; give one of {', '.join(ADDITIVE_KINDS)} or index lists such as '0,1;1,2'")
        raw = []
        for k, part in enumerate(text.split(";")):
            items = [s.strip() for s in part.split(",")] if part.strip() else []
            if not items or any(s == "" for s in items):
                raise InputError(f"--additive {spec!r}: part {k} is empty or has an empty index; write parts as '0,1;1,2'")
            idx = []
            for s in items:
                if not re.fullmatch(r"[0-9]+", s):
                    raise InputError(
                        f"--additive {spec!r}: {s!r} in part {k} is not a regressor index (an integer 0..{n - 1}) "
                        f"and {text!r} is not one of {', '.join(ADDITIVE_KINDS)}"
                    )
                idx.append(int(s))
            raw.append(idx)
    else:
        try:
            raw = [[v for v in part] for part in spec]
        except TypeError:
            raise InputError(f"additive must be one of {', '.join(ADDITIVE_KINDS)}, an index string or a list of index lists, got {spec!r}") from None
        for k, part in enumerate(raw):
            for v in part:
                if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                    raise InputError(f"additive part {k}: {v!r} is not an integer regressor index")
    if not raw:
        raise InputError("an additive sensor needs at least one part")
    out: list[tuple[int, ...]] = []
    for k, idx in enumerate(raw):
        if not idx:
            raise InputError(f"--additive part {k} is empty; every part needs at least one regressor index")
        bad = [int(v) for v in idx if not 0 <= int(v) < n]
        if bad:
            raise InputError(f"--additive part {k}: regressor index {bad[0]} is out of range; the regressor has n = {n} dimensions "
                             f"(0..{n - 1})")
        if len(set(int(v) for v in idx)) != len(idx):
            dup = next(int(v) for v in idx if [int(u) for u in idx].count(int(v)) > 1)
            raise InputError(f"--additive part {k}: regressor index {dup} appears twice; name each index of a part once")
        part = tuple(sorted(int(v) for v in idx))
        if part in out:
            raise InputError(f"--additive part {k} ({','.join(map(str, part))}) repeats part {out.index(part)}; give each part once")
        out.append(part)
    return tuple(out)


def format_subsets(subsets: Sequence[Sequence[int]]) -> str:
    """The explicit spec string of subsets (``"0,1;1,2"``)."""
    return ";".join(",".join(str(int(v)) for v in s) for s in subsets)


class AdditiveGrid:
    """The grids of the parts of an additive PWAS function on one domain box.

    Parameters
    ----------
    lo, hi : array_like, shape (n,)
        The domain box (physical units), all ``n`` regressors.
    partitions : int or array_like of int, shape (n,)
        Intervals per regressor dimension.
    subsets : sequence of sequence of int
        The parts (see :func:`parse_additive`).

    Attributes
    ----------
    lo, hi, step : ndarray, shape (n,)
    partitions : ndarray of int64, shape (n,)
    n : int
        Regressor dimension of the whole function.
    subsets : tuple of tuple of int
    parts : list of Grid
        Part ``i``'s grid on ``lo[S_i], hi[S_i], partitions[S_i]``.
    offsets : ndarray of int64, shape (k + 1,)
        Part ``i``'s weights are rows ``offsets[i]:offsets[i+1]`` of the stacked weights.
    n_vertices : int
        ``sum_i N_i``: the number of weights.
    """

    def __init__(self, lo: Sequence[float], hi: Sequence[float], partitions: int | Sequence[int], subsets: Sequence[Sequence[int]]):
        lo_a = np.asarray(lo, dtype=float).reshape(-1)
        hi_a = np.asarray(hi, dtype=float).reshape(-1)
        if lo_a.shape != hi_a.shape or lo_a.size == 0:
            raise InputError(f"lo and hi must be non-empty and of equal length, got {lo_a.size} and {hi_a.size}")
        self.n = lo_a.size
        self.partitions = np.array(_as_partitions(partitions, self.n), dtype=np.int64)
        self.subsets = tuple(tuple(int(v) for v in s) for s in subsets)
        if not self.subsets:
            raise InputError("an additive grid needs at least one part")
        for k, s in enumerate(self.subsets):
            if not s or list(s) != sorted(set(s)) or s[0] < 0 or s[-1] >= self.n:
                raise InputError(f"part {k} {s} must be sorted distinct indices in 0..{self.n - 1}")
        self.parts = [Grid(lo_a[list(s)], hi_a[list(s)], self.partitions[list(s)]) for s in self.subsets]
        sizes = [g.n_vertices for g in self.parts]
        check_limit("the number of weights of the additive sensor (sum of the parts' N)", int(sum(sizes)), MAX_VERTICES,
                    "use fewer or smaller parts, or fewer intervals (-p)")
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.lo = lo_a
        self.hi = hi_a
        self.step = (hi_a - lo_a) / self.partitions

    @property
    def n_vertices(self) -> int:
        """Number of weights ``sum_i N_i``."""
        return int(self.offsets[-1])

    @property
    def basis_dims(self) -> int:
        """``sum_i (|S_i| + 1) - 1``: the stacked ``H`` has ``basis_dims + 1`` entries per row (as a
        full grid of that dimension; what the solver choice and the memory estimate read)."""
        return int(sum(len(s) + 1 for s in self.subsets) - 1)

    @property
    def n_parts(self) -> int:
        """Number of parts (PWAS functions summed)."""
        return len(self.parts)

    @property
    def part_sizes(self) -> list[int]:
        """Vertices ``N_i`` of each part (rows of its block of the stacked weights)."""
        return [g.n_vertices for g in self.parts]

    @property
    def n_simplices(self) -> int:
        """Simplices of all parts together."""
        return int(sum(g.n_simplices for g in self.parts))

    def __repr__(self) -> str:
        return f"AdditiveGrid(n={self.n}, subsets={format_subsets(self.subsets)!r}, N={self.n_vertices})"

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, AdditiveGrid) and self.subsets == other.subsets and np.array_equal(self.lo, other.lo)
                and np.array_equal(self.hi, other.hi) and np.array_equal(self.partitions, other.partitions))

    __hash__ = None

    def split_weights(self, weights: np.ndarray) -> list[np.ndarray]:
        """The blocks ``w_i`` of stacked weights (shape (N, ...)) in part order.

        Parameters
        ----------
        weights : ndarray, shape (N,) or (N, nz)
            Stacked weights of all parts.

        Returns
        -------
        list of ndarray
            ``k`` views, part ``i``'s of shape ``(N_i,)`` or ``(N_i, nz)``.

        Raises
        ------
        InputError
            ``weights`` has not ``N`` rows.
        """
        w = np.asarray(weights)
        if w.shape[0] != self.n_vertices:
            raise InputError(f"weights have {w.shape[0]} rows but the additive grid has N = {self.n_vertices}")
        return [w[self.offsets[i] : self.offsets[i + 1]] for i in range(self.n_parts)]

    def to_grid_units(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Clamped grid coordinates of all ``n`` regressors and the out-of-domain flags (as :meth:`Grid.to_grid_units`).

        Parameters
        ----------
        x : array_like, shape (m, n) or (n,)
            Regressors, physical units.

        Returns
        -------
        s : ndarray, shape (m, n)
            Grid coordinates clamped to ``[0, p_j]``.
        out_of_domain : ndarray, shape (m,), bool
        """
        return Grid.to_grid_units(self, x)  # reads only lo, hi, step, partitions and n, which this box has

    def basis_matrix(self, x: np.ndarray) -> scipy.sparse.csr_array:
        """Stacked sparse basis ``H = [H_1 ... H_k]``, shape (m, sum_i N_i).

        Parameters
        ----------
        x : array_like, shape (m, n)
            Regressors, physical units (clamped to the domain).

        Returns
        -------
        scipy.sparse.csr_array, shape (m, N)
            At most ``sum_i (|S_i| + 1)`` entries per row.
        """
        from scipy import sparse

        xa = np.atleast_2d(np.asarray(x, dtype=float))
        self.to_grid_units(xa)  # shape and finiteness checks
        return sparse.hstack([g.basis_matrix(xa[:, list(s)]) for g, s in zip(self.parts, self.subsets)], format="csr")

    def evaluate(self, weights: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Value of the additive function: ``sum_i f_i(x_{S_i})``.

        Parameters
        ----------
        weights : ndarray, shape (N,) or (N, nz)
            Stacked weights.
        x : array_like, shape (m, n)

        Returns
        -------
        ndarray, shape (m,) or (m, nz)
        """
        xa = np.atleast_2d(np.asarray(x, dtype=float))
        self.to_grid_units(xa)
        blocks = self.split_weights(np.asarray(weights, dtype=float))
        return sum(g.evaluate(w, xa[:, list(s)]) for g, s, w in zip(self.parts, self.subsets, blocks))


def additive_tikhonov_matrix(grid: AdditiveGrid, order: int = 0) -> scipy.sparse.csc_array:
    """``Gamma = blockdiag(Gamma_1, ..., Gamma_k)``, one Tikhonov term per part
    (:func:`pwas_hdl.fit.regularized_lsq.tikhonov_matrix` of each part's grid).

    Parameters
    ----------
    grid : AdditiveGrid
    order : int
        Tikhonov order (0: ``I``; 1: the gradient penalty), as
        :func:`~pwas_hdl.fit.regularized_lsq.tikhonov_matrix`.

    Returns
    -------
    scipy.sparse.csc_array, shape (N, N)
    """
    from scipy import sparse

    from pwas_hdl.fit.regularized_lsq import tikhonov_matrix

    return sparse.block_diag([tikhonov_matrix(g, order) for g in grid.parts], format="csc")


#: Unknowns up to which a first-order additive fit is solved by sparse factorisation (issue 15).
#: The ``auto`` rule of :mod:`pwas_hdl.fit.regularized_lsq` keys on the non-zeros per row of ``H``
#: (here the sum over the parts, e.g. 21 for 3 parts of 6 dimensions) and picks conjugate gradients
#: above 2000 unknowns; on an additive first-order system CG does not converge: the constants the
#: parts share are fixed only by the 1e-6 ridge of the gradient penalty (condition number ~1e6 /
#: sigma), so it stops at its 2000 iterations and falls back to the factorisation for every (fold,
#: sigma). Measured on the helicopter ``Mu = My = 4`` ``pairs`` sensor (3 parts of 6 dimensions,
#: N = 12288, T = 20000, nnz(H'H) = 66 715: the data occupy few simplices): CG 2000 iterations,
#: 38 s, relative residual 1.4e-7 at sigma = 1e-3 (641 iterations, 16 s at sigma = 1); the direct
#: solve 1.0-1.3 s, relative residual 2e-15, at every sigma.
ADDITIVE_DIRECT_MAX_UNKNOWNS = 100_000


def additive_solver_method(grid: AdditiveGrid, order: int) -> str:
    """The solver of an additive fit: ``"direct"`` for a first-order penalty up to
    :data:`ADDITIVE_DIRECT_MAX_UNKNOWNS` unknowns, else ``"auto"`` (the rule of
    :func:`pwas_hdl.fit.regularized_lsq.choose_method`). Zero order: ``sigma I`` keeps the system
    well conditioned and CG converges.

    Parameters
    ----------
    grid : AdditiveGrid
    order : int
        Tikhonov order.

    Returns
    -------
    str
        ``"direct"`` or ``"auto"``.
    """
    return "direct" if int(order) >= 1 and grid.n_vertices <= ADDITIVE_DIRECT_MAX_UNKNOWNS else "auto"
