"""Simplicial (Kuhn / Freudenthal "type-1") partition of a hyper-rectangle, uniform or with given breakpoints.

This module is the single source of truth for the geometry used by the fit, the float and
fixed-point models and the hardware generator.

Conventions
-----------
Domain
    ``S = [lo_0, hi_0] x ... x [lo_{n-1}, hi_{n-1}]`` (physical units of each regressor).
Partition
    Dimension ``j`` is cut into ``p_j >= 1`` equal intervals of width ``h_j = (hi_j - lo_j) / p_j``,
    so there are ``p_j + 1`` vertex coordinates ``0 .. p_j`` per dimension, ``N = prod(p_j + 1)``
    vertices and ``L = n! * prod(p_j)`` simplices.
Vertex numbering
    A vertex with integer coordinates ``v = (v_0, ..., v_{n-1})``, ``0 <= v_j <= p_j``, has the
    linear index ``k = sum_j v_j * stride_j`` with ``stride_{n-1} = 1`` and
    ``stride_j = stride_{j+1} * (p_{j+1} + 1)`` (row-major / C order: the *last* dimension varies
    fastest, exactly as :func:`numpy.ravel_multi_index`). Weight vectors, the columns of the
    basis matrix ``H`` and the ROM contents all use this numbering.
Location of a point (Kuhn's lemma)
    1. grid coordinate ``s_j = (x_j - lo_j) / h_j``, clamped to ``[0, p_j]``;
    2. cell ``c_j = min(floor(s_j), p_j - 1)``, fractional part ``d_j = s_j - c_j`` in ``[0, 1]``;
    3. order: ``rank_j = #{i : d_i > d_j or (d_i == d_j and i < j)}`` -- descending ``d``,
       **ties broken by the lower dimension index first**; ``perm[k]`` is the dimension of rank
       ``k``;
    4. vertices ``v_0 = c``, ``v_k = v_{k-1} + e_{perm[k-1]}`` (``k = 1..n``);
    5. barycentric weights ``mu_0 = 1 - d_perm[0]``, ``mu_k = d_perm[k-1] - d_perm[k]``,
       ``mu_n = d_perm[n-1]``; all ``>= 0`` and summing to 1.
    The value of a PWAS function with vertex weights ``w`` is ``sum_k mu_k * w[vertex_k]``.
    The tie rule only decides which of several simplices sharing a face is reported; the value is
    the same on both sides of the face (continuity).

Equivalently (the form used by the hardware, with no sorter): dimension ``j`` has stepped at
vertex ``k`` exactly when ``rank_j < k``.

Non-uniform partitions (``breakpoints``, issue 15 item 3)
    Dimension ``j`` may instead be cut at given breakpoints ``lo_j = b_j0 < b_j1 < ... < b_jp = hi_j``
    (``p_j + 1`` values). Only step 1 changes: the grid coordinate is the piecewise-linear warp
    ``s_j = c + (x_j - b_jc) / (b_j(c+1) - b_jc)`` for ``b_jc <= x_j < b_j(c+1)`` (then clamped to
    ``[0, p_j]`` as above), and vertex ``v`` sits at ``b_jv_j``. Cells, fractions, ordering,
    vertices, barycentric weights, the vertex numbering and everything that works in grid units
    (basis matrix, regularisation, memory layouts) are those of the uniform partition; a grid
    without breakpoints takes exactly the uniform code path. :attr:`Grid.step` is then the mean
    cell width ``(hi - lo) / p``. :func:`quantile_breakpoints` places them at data quantiles,
    :func:`pow2_breakpoints` rounds their cell widths to power-of-two multiples of a base step
    (the hardware-friendly variant: the fraction needs a shift, no divider).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.limits import MAX_REGRESSORS, check_limit, check_vertices

if TYPE_CHECKING:
    import scipy.sparse

__all__ = ["Grid", "Location", "quantile_breakpoints", "pow2_breakpoints", "pow2_exponents", "BREAKPOINT_RULES", "MAX_POW2_RATIO"]

#: Rules of ``fit --breakpoints`` besides a file: data quantiles, or quantiles rounded to
#: power-of-two multiples of a base step.
BREAKPOINT_RULES = ("quantile", "quantile-pow2")
#: Largest ratio of two cell widths of one dimension in the power-of-two variant (each doubling
#: costs one bit of the warped code).
MAX_POW2_RATIO = 16


@dataclass(frozen=True)
class Location:
    """Result of locating points in the Kuhn partition (all arrays have ``m`` rows).

    Attributes
    ----------
    s : ndarray, shape (m, n), float
        Clamped grid coordinates (grid units, ``0 <= s_j <= p_j``).
    cell : ndarray, shape (m, n), int64
        Cell (lower corner) integer coordinates, ``0 <= c_j <= p_j - 1``.
    frac : ndarray, shape (m, n), float
        Fractional parts ``d_j = s_j - c_j`` in ``[0, 1]``.
    rank : ndarray, shape (m, n), int64
        Rank of each dimension in descending order of ``frac`` (ties: lower index first).
    perm : ndarray, shape (m, n), int64
        ``perm[:, k]`` is the dimension with rank ``k`` (the step taken at vertex ``k + 1``).
    vertices : ndarray, shape (m, n + 1), int64
        Linear indices of the simplex vertices ``v_0 .. v_n``.
    mu : ndarray, shape (m, n + 1), float
        Barycentric weights of the vertices (``>= 0``, sum 1).
    out_of_domain : ndarray, shape (m,), bool
        True where at least one coordinate was clamped to the domain.
    """

    s: np.ndarray
    cell: np.ndarray
    frac: np.ndarray
    rank: np.ndarray
    perm: np.ndarray
    vertices: np.ndarray
    mu: np.ndarray
    out_of_domain: np.ndarray


def _as_partitions(p: int | Sequence[int], n: int) -> tuple[int, ...]:
    arr = np.atleast_1d(np.asarray(p))
    if arr.size == 1 and n > 1:
        arr = np.repeat(arr, n)
    if arr.shape != (n,):
        raise InputError(f"-p/--partitions (partitions) must be one integer or {n} integers (one per dimension), got {p!r}; "
                         f"give one value for every dimension or {n} comma-separated values")
    out = []
    for j, v in enumerate(arr.tolist()):
        if isinstance(v, float) and not float(v).is_integer():
            raise InputError(f"-p/--partitions (partitions[{j}]) = {v!r} is not an integer; use a whole number of intervals >= 1")
        iv = int(v)
        if iv < 1:
            raise InputError(f"-p/--partitions (partitions[{j}]) = {iv}, but every dimension needs p >= 1 intervals; "
                             "give whole numbers >= 1")
        out.append(iv)
    return tuple(out)


def _as_breakpoints(bps, lo: np.ndarray, hi: np.ndarray, parts: tuple[int, ...]):
    if len(bps) != len(parts):
        raise InputError(f"breakpoints need {len(parts)} entries (one per dimension, None = uniform), got {len(bps)}")
    out = []
    for j, b in enumerate(bps):
        if b is None:
            out.append(None)
            continue
        arr = np.asarray(b, dtype=float).reshape(-1)
        if arr.size != parts[j] + 1:
            raise InputError(f"breakpoints of dimension {j} have {arr.size} values; p = {parts[j]} intervals need {parts[j] + 1}")
        if not np.all(np.isfinite(arr)):
            raise InputError(f"breakpoints of dimension {j} contain NaN or infinite values")
        if not np.all(np.diff(arr) > 0):
            k = int(np.flatnonzero(~(np.diff(arr) > 0))[0])
            raise InputError(f"breakpoints of dimension {j} must increase strictly: b[{k}] = {float(arr[k])!r} >= b[{k + 1}] = {float(arr[k + 1])!r}")
        if arr[0] != lo[j] or arr[-1] != hi[j]:
            raise InputError(f"breakpoints of dimension {j} must start at lo = {float(lo[j])!r} and end at hi = {float(hi[j])!r}, "
                             f"got {float(arr[0])!r} .. {float(arr[-1])!r}")
        out.append(arr)
    return tuple(out) if any(b is not None for b in out) else None


class Grid:
    """Kuhn simplicial partition of the box ``[lo, hi]``, uniform or cut at given breakpoints.

    Parameters
    ----------
    lo, hi : array_like, shape (n,)
        Lower and upper bounds of the domain, physical units; ``hi > lo`` elementwise.
    partitions : int or array_like of int, shape (n,)
        Number of intervals ``p_j >= 1`` per dimension (one int is used for every dimension).
    breakpoints : sequence of (array_like, shape (p_j + 1,), or None), optional
        Per dimension, the ``p_j + 1`` strictly increasing cut points from ``lo_j`` to ``hi_j``
        (physical units), or None for equal intervals. Default: uniform in every dimension.

    Examples
    --------
    >>> g = Grid([0.0, 0.0], [1.0, 2.0], [2, 4])
    >>> g.n_vertices, g.n_simplices
    (15, 16)
    """

    def __init__(self, lo: Sequence[float], hi: Sequence[float], partitions: int | Sequence[int],
                 breakpoints: Sequence[Sequence[float] | None] | None = None):
        lo_a = np.asarray(lo, dtype=float).reshape(-1)
        hi_a = np.asarray(hi, dtype=float).reshape(-1)
        if lo_a.shape != hi_a.shape or lo_a.size == 0:
            raise InputError(f"lo and hi must be non-empty and of equal length, got {lo_a.size} and {hi_a.size}")
        if not (np.all(np.isfinite(lo_a)) and np.all(np.isfinite(hi_a))):
            raise InputError(f"domain bounds must be finite numbers, got lo = {lo_a.tolist()}, hi = {hi_a.tolist()}; "
                             "give finite bounds (e.g. --domain -1:1,0:5)")
        bad = np.flatnonzero(~(hi_a > lo_a))
        if bad.size:
            j = int(bad[0])
            raise InputError(
                f"domain dimension {j} has zero or negative width ([{lo_a[j]}, {hi_a[j]}]); "
                "every dimension needs hi > lo; a constant regressor cannot be partitioned: drop that signal or "
                "give a domain wider than its value"
            )
        with np.errstate(over="ignore"):
            wide = np.flatnonzero(~np.isfinite(hi_a - lo_a))
        if wide.size:
            j = int(wide[0])
            raise InputError(f"domain dimension {j} ([{lo_a[j]}, {hi_a[j]}]) is wider than a float can hold; "
                             "give a narrower domain (--domain) or rescale the signal")
        check_limit("the regressor dimension n", lo_a.size, MAX_REGRESSORS, "use fewer lags or signals")
        parts = _as_partitions(partitions, lo_a.size)
        check_vertices(parts)  # before any int64 array: N and the strides fit in int64 below the limit
        self.lo = lo_a
        self.hi = hi_a
        self.n = lo_a.size
        self.partitions = np.array(parts, dtype=np.int64)
        self.shape = tuple(int(v) for v in self.partitions + 1)
        strides = np.ones(self.n, dtype=np.int64)
        for j in range(self.n - 2, -1, -1):
            strides[j] = strides[j + 1] * self.shape[j + 1]
        self.strides = strides
        self.step = (self.hi - self.lo) / self.partitions
        #: None (uniform), or per dimension None / the p_j + 1 cut points (float arrays)
        self.breakpoints = None if breakpoints is None else _as_breakpoints(breakpoints, self.lo, self.hi, parts)

    @property
    def uniform(self) -> bool:
        """True when every dimension has equal intervals."""
        return self.breakpoints is None

    # ------------------------------------------------------------------ sizes
    @property
    def n_vertices(self) -> int:
        """Number of vertices (= weights) ``N = prod(p_j + 1)``."""
        return int(np.prod(self.shape))

    @property
    def n_simplices(self) -> int:
        """Number of simplices ``L = n! * prod(p_j)``."""
        return math.factorial(self.n) * int(np.prod(self.partitions))

    def __repr__(self) -> str:
        bp = "" if self.breakpoints is None else f", breakpoints={[None if b is None else b.tolist() for b in self.breakpoints]}"
        return f"Grid(lo={self.lo.tolist()}, hi={self.hi.tolist()}, partitions={self.partitions.tolist()}{bp})"

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Grid)
            and np.array_equal(self.lo, other.lo)
            and np.array_equal(self.hi, other.hi)
            and np.array_equal(self.partitions, other.partitions)
            and _same_breakpoints(self.breakpoints, other.breakpoints)
        )

    __hash__ = None  # mutable numpy members

    # --------------------------------------------------------------- vertices
    def vertex_index(self, coords: np.ndarray) -> np.ndarray:
        """Linear index of integer vertex coordinates.

        Parameters
        ----------
        coords : ndarray, shape (..., n), int
            Vertex coordinates, ``0 <= coords[..., j] <= p_j``.

        Returns
        -------
        ndarray, shape (...), int64
        """
        return np.asarray(coords, dtype=np.int64) @ self.strides

    def vertex_coords(self, index: np.ndarray | int | None = None) -> np.ndarray:
        """Integer coordinates of vertices (all of them, in index order, when ``index`` is None).

        Parameters
        ----------
        index : ndarray of int, any shape ``(...)``, or int, optional
            Linear vertex indices, ``0 <= index < N``; None for all ``N`` vertices (``(...) = (N,)``).

        Returns
        -------
        ndarray, shape (..., n), int64
        """
        if index is None:
            index = np.arange(self.n_vertices)
        return np.stack(np.unravel_index(np.asarray(index, dtype=np.int64), self.shape), axis=-1).astype(np.int64)

    def vertex_points(self, index: np.ndarray | int | None = None) -> np.ndarray:
        """Physical coordinates of vertices, shape (..., n).

        Parameters
        ----------
        index : ndarray of int, any shape ``(...)``, or int, optional
            Linear vertex indices, ``0 <= index < N``; None for all ``N`` vertices (``(...) = (N,)``).

        Returns
        -------
        ndarray, shape (..., n), float
            Vertex positions in physical units: ``lo + coords * step``, or the breakpoints of a
            dimension cut at given breakpoints.
        """
        coords = self.vertex_coords(index)
        pts = self.lo + coords * self.step
        bps = getattr(self, "breakpoints", None)
        if bps is not None:
            for j, b in enumerate(bps):
                if b is not None:
                    pts[..., j] = b[coords[..., j]]
        return pts

    # --------------------------------------------------------------- location
    def to_grid_units(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Scale physical points to clamped grid units.

        Parameters
        ----------
        x : array_like, shape (m, n) or (n,)
            Points in physical units.

        Returns
        -------
        s : ndarray, shape (m, n)
            Grid coordinates clamped to ``[0, p_j]``.
        out_of_domain : ndarray, shape (m,), bool
            True where a coordinate was outside the domain and has been clamped.
        """
        xa = np.atleast_2d(np.asarray(x, dtype=float))
        if xa.shape[1] != self.n:
            raise InputError(f"points have {xa.shape[1]} coordinates but the grid has n = {self.n} dimensions")
        if not np.all(np.isfinite(xa)):
            raise InputError("points contain NaN or infinite values; clean the data before evaluating")
        with np.errstate(over="ignore"):  # a point far outside a tiny cell: s = +-inf, clamped below like any outside point
            s = (xa - self.lo) / self.step
            bps = getattr(self, "breakpoints", None)  # pwas_hdl.fit.additive.AdditiveGrid calls this with its own box
            if bps is not None:
                for j, b in enumerate(bps):
                    if b is not None:  # piecewise-linear warp: cell c, then the fraction within it
                        c = np.clip(np.searchsorted(b, xa[:, j], side="right") - 1, 0, b.size - 2)
                        s[:, j] = c + (xa[:, j] - b[c]) / (b[c + 1] - b[c])
        # flagged in physical units: (hi - lo) / step may round above p, and s > p at x = hi itself
        # (about 1 grid in 20) would flag a point on the domain's own boundary
        out = np.any((xa < self.lo) | (xa > self.hi), axis=1)
        np.clip(s, 0, self.partitions, out=s)
        return s, out

    def locate_grid_units(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Kuhn location from clamped grid coordinates (shared by the float and fixed-point models).

        Parameters
        ----------
        s : ndarray, shape (m, n)
            Grid coordinates, already clamped to ``[0, p_j]``. May be float or integer-valued
            (the fixed-point model passes integer cells and fractions separately, see
            :meth:`simplex_from_cell`).

        Returns
        -------
        cell, frac, rank, perm, vertices, mu : see :class:`Location`.
        """
        cell = np.minimum(np.floor(s).astype(np.int64), self.partitions - 1)
        frac = s - cell
        rank, perm = self.order(frac)
        vertices = self.simplex_vertices(cell, perm)
        mu = self.barycentric(frac, perm)
        return cell, frac, rank, perm, vertices, mu

    def locate(self, x: np.ndarray) -> Location:
        """Locate points: cell, fractional parts, ordering, simplex vertices and weights.

        Parameters
        ----------
        x : array_like, shape (m, n) or (n,)
            Points in physical units; coordinates outside the domain are clamped and flagged.

        Returns
        -------
        Location
        """
        s, out = self.to_grid_units(x)
        cell, frac, rank, perm, vertices, mu = self.locate_grid_units(s)
        return Location(s, cell, frac, rank, perm, vertices, mu, out)

    @staticmethod
    def order(frac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Descending order of fractional parts with the documented tie rule.

        Works for float or integer arrays (the fixed-point model uses integer fractions).

        Parameters
        ----------
        frac : ndarray, shape (m, n)

        Returns
        -------
        rank : ndarray, shape (m, n), int64
            ``rank[:, j] = #{i : frac_i > frac_j or (frac_i == frac_j and i < j)}``.
        perm : ndarray, shape (m, n), int64
            Inverse of ``rank``: ``perm[:, k]`` is the dimension of rank ``k``.
        """
        # A stable sort of the negated values keeps equal values in increasing index order,
        # which is exactly "lower index first" on ties.
        perm = np.argsort(-frac, axis=1, kind="stable").astype(np.int64)
        rank = np.empty_like(perm)
        rows = np.arange(perm.shape[0])[:, None]
        rank[rows, perm] = np.arange(perm.shape[1])[None, :]
        return rank, perm

    def simplex_vertices(self, cell: np.ndarray, perm: np.ndarray) -> np.ndarray:
        """Linear indices of the ``n + 1`` vertices of the Kuhn simplex (cell, perm).

        Parameters
        ----------
        cell : ndarray, shape (m, n), int
            Integer cell coordinates, ``0 <= cell[:, j] < p_j``.
        perm : ndarray, shape (m, n), int
            Dimensions in descending order of the fractional parts (:meth:`order`).

        Returns
        -------
        ndarray, shape (m, n + 1), int64
        """
        base = cell @ self.strides
        steps = np.cumsum(self.strides[perm], axis=1)
        return np.concatenate([base[:, None], base[:, None] + steps], axis=1)

    @staticmethod
    def barycentric(frac: np.ndarray, perm: np.ndarray, one: float | int = 1) -> np.ndarray:
        """Barycentric weights ``mu`` from fractional parts and their ordering.

        Parameters
        ----------
        frac : ndarray, shape (m, n)
            Fractional parts, float in ``[0, 1]`` or integers in ``[0, one]``.
        perm : ndarray, shape (m, n), int
            Ordering from :meth:`order`.
        one : float or int
            The value that stands for 1 (default 1). The fixed-point model passes integer
            fractions in units of ``2**-F`` together with ``one = 2**F``; the result then is exact
            integer ``mu`` summing to ``2**F``.

        Returns
        -------
        ndarray, shape (m, n + 1), dtype of ``frac``
        """
        m = frac.shape[0]
        d_sorted = np.take_along_axis(frac, perm, axis=1)
        one = np.full((m, 1), one, dtype=frac.dtype)
        zero = np.zeros((m, 1), dtype=frac.dtype)
        upper = np.concatenate([one, d_sorted], axis=1)
        lower = np.concatenate([d_sorted, zero], axis=1)
        return upper - lower

    # ------------------------------------------------------------- evaluation
    def evaluate(self, weights: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Value of the PWAS function with vertex weights ``weights`` at points ``x``.

        Parameters
        ----------
        weights : ndarray, shape (N,) or (N, nz)
        x : array_like, shape (m, n)
            Points, physical units (clamped to the domain).

        Returns
        -------
        ndarray, shape (m,) or (m, nz)
        """
        w = np.asarray(weights, dtype=float)
        if w.shape[0] != self.n_vertices:
            raise InputError(f"weights have {w.shape[0]} rows but the grid has N = {self.n_vertices} vertices")
        loc = self.locate(x)
        if w.ndim == 1:
            return np.einsum("mk,mk->m", loc.mu, w[loc.vertices])
        return np.einsum("mk,mkz->mz", loc.mu, w[loc.vertices])

    def basis_matrix(self, x: np.ndarray) -> scipy.sparse.csr_array:
        """Sparse alpha-basis matrix ``H`` (``H[t, k] = alpha_k(x_t)``), n + 1 entries per row.

        Parameters
        ----------
        x : array_like, shape (m, n)

        Returns
        -------
        scipy.sparse.csr_array, shape (m, N)
        """
        from scipy import sparse

        loc = self.locate(x)
        m = loc.mu.shape[0]
        indptr = np.arange(0, m * (self.n + 1) + 1, self.n + 1, dtype=np.int64)
        # Vertices of one simplex are distinct, so a row has no duplicate column.
        order = np.argsort(loc.vertices, axis=1)
        cols = np.take_along_axis(loc.vertices, order, axis=1).reshape(-1)
        vals = np.take_along_axis(loc.mu, order, axis=1).reshape(-1)
        return sparse.csr_array((vals, cols, indptr), shape=(m, self.n_vertices))

    # ----------------------------------------------------------- neighbours
    def axis_edges(self, dim: int) -> tuple[np.ndarray, np.ndarray]:
        """All grid edges parallel to axis ``dim``: pairs (a, a + e_dim) of vertex indices.

        Parameters
        ----------
        dim : int
            The axis, ``0 <= dim < n``.

        Returns
        -------
        a, b : ndarray, shape (E,), int64
            Linear indices of the two ends of each edge (``b = a + strides[dim]``), ``E = N p_dim /
            (p_dim + 1)`` edges in increasing order of ``a``.
        """
        coords = self.vertex_coords()
        keep = coords[:, dim] < self.partitions[dim]
        a = np.flatnonzero(keep).astype(np.int64)
        return a, a + self.strides[dim]


def _same_breakpoints(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return len(a) == len(b) and all((x is None and y is None) or (x is not None and y is not None and np.array_equal(x, y))
                                    for x, y in zip(a, b))


def quantile_breakpoints(x: np.ndarray, lo: Sequence[float], hi: Sequence[float], partitions: int | Sequence[int],
                         min_width: float = 0.05, groups: Sequence[Sequence[int]] | None = None) -> list[np.ndarray]:
    """Breakpoints at the data quantiles: every cell of dimension ``j`` holds about ``1/p_j`` of the samples.

    Parameters
    ----------
    x : ndarray, shape (m, n)
        Regressor samples (physical units).
    lo, hi : array_like, shape (n,)
        The domain (e.g. the data range expanded by ``gamma``); the outer breakpoints are ``lo``
        and ``hi``, the inner ones the ``k / p_j`` quantiles (``k = 1 .. p_j - 1``) of the samples
        inside ``[lo_j, hi_j]``.
    partitions : int or sequence of int
    min_width : float
        A dimensionless fraction: no cell narrower than ``min_width`` times the uniform width
        ``(hi - lo) / p`` (repeated values and tails would give empty cells): the cuts are then
        pushed apart, keeping their order.
    groups : sequence of sequence of int, optional
        Dimensions that share one set of cuts (e.g. the lags of one signal, which the sensor top
        feeds one input code): the quantiles of their pooled samples. A group is pooled only when
        its dimensions have the same domain and partitions; other dimensions are cut alone.

    Returns
    -------
    list of ndarray, one per dimension, ``p_j + 1`` strictly increasing values
    """
    xa = np.atleast_2d(np.asarray(x, dtype=float))
    lo_a, hi_a = np.asarray(lo, dtype=float).reshape(-1), np.asarray(hi, dtype=float).reshape(-1)
    parts = _as_partitions(partitions, lo_a.size)
    if xa.shape[1] != lo_a.size or xa.shape[0] < 1:
        raise InputError(f"quantile breakpoints need samples with {lo_a.size} columns, got shape {xa.shape}")
    if not 0 < min_width < 1:
        raise InputError(f"min_width must be in (0, 1), got {min_width!r}")
    pool = {j: [j] for j in range(lo_a.size)}
    for g in groups or ():
        g = [int(j) for j in g]
        if len({(lo_a[j], hi_a[j], int(parts[j])) for j in g}) == 1:
            for j in g:
                pool[j] = g
    out = []
    for j, p in enumerate(parts):
        col = xa[:, pool[j]].reshape(-1)
        col = col[(col >= lo_a[j]) & (col <= hi_a[j])]
        if col.size == 0:
            raise InputError(f"no sample of dimension {j} lies inside its domain [{lo_a[j]}, {hi_a[j]}]: no quantiles; "
                             "give a --domain that covers the data, or leave --breakpoints out (equal intervals)")
        inner = np.quantile(col, np.arange(1, p) / p) if p > 1 else np.empty(0)
        out.append(_spread(np.concatenate([[lo_a[j]], inner, [hi_a[j]]]), min_width * (hi_a[j] - lo_a[j]) / p))
    return out


def _spread(b: np.ndarray, gap: float) -> np.ndarray:
    """Push the inner cuts of ``b`` (ends fixed) apart so that every cell is at least ``gap`` wide."""
    b = b.copy()
    p = b.size - 1
    for k in range(1, p):  # forward: at least gap above the previous cut, room for the cells left
        b[k] = min(max(b[k], b[k - 1] + gap), b[-1] - (p - k) * gap)
    for k in range(p - 1, 0, -1):
        b[k] = min(b[k], b[k + 1] - gap)
    return b


def pow2_breakpoints(x: np.ndarray, lo: Sequence[float], hi: Sequence[float], partitions: int | Sequence[int],
                     max_ratio: int = MAX_POW2_RATIO, groups: Sequence[Sequence[int]] | None = None) -> list[np.ndarray]:
    """Quantile breakpoints whose cell widths are power-of-two multiples of one base step per dimension.

    The quantile cell widths ``t_k`` (:func:`quantile_breakpoints`) are rounded in the log domain:
    ``e_k = round(log2(t_k / min t))``, capped at ``log2(max_ratio)``; the cells are then
    ``2**e_k * h0`` wide with ``h0 = (hi - lo) / sum 2**e_k`` (the domain is kept). In hardware a
    cell of ``2**e_k`` base steps is ``2**(e_k + f0)`` input codes, and the fraction within it is
    a shift of the code offset (:mod:`pwas_hdl.fixedpoint.warp`).

    Parameters
    ----------
    x : ndarray, shape (m, n)
        Regressor samples (physical units).
    lo, hi : array_like, shape (n,)
        The domain; the outer breakpoints are kept at ``lo`` and ``hi``.
    partitions : int or sequence of int
        Intervals ``p_j`` per dimension.
    max_ratio : int
        Largest ratio of two cell widths of one dimension, a power of two ``>= 1`` (1 gives
        uniform cells).
    groups : sequence of sequence of int, optional
        Dimensions sharing one set of cuts, as in :func:`quantile_breakpoints`.

    Returns
    -------
    list of ndarray, one per dimension, ``p_j + 1`` strictly increasing values
    """
    if not isinstance(max_ratio, (int, np.integer)) or max_ratio < 1 or max_ratio & (max_ratio - 1):
        raise InputError(f"max_ratio must be a power of two >= 1, got {max_ratio!r}")
    emax = int(max_ratio).bit_length() - 1
    q = quantile_breakpoints(x, lo, hi, partitions, groups=groups)  # groups: identical cuts, identical rounding
    out = []
    for b in q:
        t = np.diff(b)
        e = np.clip(np.rint(np.log2(t / t.min())), 0, emax).astype(np.int64)
        units = np.concatenate([[0], np.cumsum(1 << e)])
        h0 = (b[-1] - b[0]) / units[-1]
        nb = b[0] + h0 * units
        nb[-1] = b[-1]
        out.append(nb)
    return out


def pow2_exponents(b: np.ndarray) -> tuple[np.ndarray, float] | None:
    """``(e, h0)`` when the cells of ``b`` are ``2**e_k * h0`` wide (to 1e-9 relative), else None.

    Parameters
    ----------
    b : ndarray, shape (p + 1,)
        Strictly increasing breakpoints of one dimension (physical units).

    Returns
    -------
    tuple of (ndarray, float) or None
        ``e``, shape (p,), int64 exponents (``e_k >= 0``) and ``h0``, the narrowest cell width
        (physical units); None when a cell is not a power-of-two multiple of ``h0``.
    """
    t = np.diff(np.asarray(b, dtype=float))
    h0 = float(t.min())
    r = t / h0
    e = np.rint(np.log2(r)).astype(np.int64)
    if np.all(np.abs(r - (1 << e)) <= 1e-9 * r):
        return e, h0
    return None
