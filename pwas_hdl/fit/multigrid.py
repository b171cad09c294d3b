"""Geometric multigrid on the Kuhn vertex grid, for ``(M + sigma Gamma) w = b`` over many sigmas.

Cross-validation of sigma solves ``A(sigma) = M_k + sigma Gamma`` for every fold ``k`` and each of
the candidate sigmas. With nested grids and prolongations ``P_l`` (tensor products of 1-D linear
interpolation, fine level ``0``), the Galerkin operator of level ``l`` is
``Q_l' A Q_l = Q_l' M_k Q_l + sigma Q_l' Gamma Q_l`` (``Q_l = P_0 ... P_{l-1}``): a *linear
combination of two matrices*, one per fold and one for all folds. :class:`GridHierarchy` builds the
prolongations and the coarse ``Gamma`` once; :meth:`GridHierarchy.for_matrix` the coarse ``M_k`` of
one fold, each level's sum stored on the union pattern, so that setting a sigma
(:meth:`FoldMultigrid.set_sigma`) is one vector axpy per level and a small sparse factorisation of
the coarsest level. One V-cycle (forward Gauss-Seidel before, backward after, from pyamg's C++
kernels; a symmetric preconditioner) preconditions conjugate gradients
(:meth:`FoldMultigrid.solve`, stopping on the residual computed afresh).

Where the data term dominates (small sigma) the V-cycle's fine level also solves exactly with
``M_TT + sigma diag(Gamma)_TT`` on the vertices ``T`` that some sample touches
(:class:`DataBlockSmoother`): Gauss-Seidel alone leaves the error in the null space of ``H'H`` (a
simplex with one sample constrains one combination of its weights), which only ``sigma Gamma``
damps and no coarse grid represents; the exact data block turns that part into Jacobi on ``Gamma``.

The grid shape is that of the vertex numbering of :mod:`pwas_hdl.fit.geometry` (C order, the last
dimension fastest); :func:`grid_shape_of` recovers it from a first-order ``Gamma``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse import linalg as splinalg

from pwas_hdl.errors import InternalError
from pwas_hdl.fit.conjugate_gradients import pcg
from pwas_hdl.fit.sparse_cholesky import OutsidePattern

__all__ = [
    "COARSEST_MAX",
    "INTERLEAVE",
    "interleaved_order",
    "interpolation_1d",
    "prolongation",
    "grid_shape_of",
    "GridHierarchy",
    "FoldMultigrid",
    "DataBlockSmoother",
    "MGInfo",
]

#: Coarsening stops once a level has at most this many unknowns (it is then factorised directly,
#: once per sigma).
COARSEST_MAX = 4096

#: Every level numbers its vertices in the order of :func:`interleaved_order` with this many slabs.
#: A Gauss-Seidel sweep in the grid's own (C) order is a chain: each row waits for the division
#: of the row before, its neighbour. Interleaving ``k`` slabs of the grid (consecutive rows in
#: different slabs, not coupled) keeps ``k`` chains in flight, while within each slab the sweep
#: is still the lexicographic one (Gauss-Seidel on ``k`` slabs, their boundaries with the other
#: slabs' last values). Measured at n = 2, N = 10^6 (T = 10^5, one fold, sigma = 1, single
#: precision, pyamg's kernel, CPU ms a forward sweep): C order 15.2, 2 / 4 / 8 / 16 slabs
#: 10.4 / 10.7 / 8.7 / 8.6 (a product with the same matrix: 7.3-8.5; a four-colour order: 9.0);
#: the next level (N = 251 001): 4.5 against 2.7-3.0. Multigrid-PCG iterations of the fold's ten
#: Gauss-Seidel sigmas: 89 in C order, 91-92 with 4 or 8 slabs, 95 with four colours.
INTERLEAVE = 16


def interpolation_1d(m: int) -> sparse.csr_array:
    """Linear interpolation from a coarse 1-D vertex set onto ``m`` fine vertices, shape (m, mc).

    The coarse vertices are the even fine indices ``0, 2, 4, ...`` and, when ``m`` is even, also the
    last index ``m - 1`` (so both ends are kept): ``mc = m // 2 + 1``. An even fine vertex is a
    coarse one (weight 1); an odd one between two coarse ones takes 1/2 of each, except the
    last-but-one of an even ``m``, which lies between coarse neighbours at distances 1 and 1 too.

    Parameters
    ----------
    m : int
        Fine vertex count (``>= 3``).

    Returns
    -------
    scipy.sparse.csr_array, shape (m, m // 2 + 1), rows summing to 1
    """
    if m < 3:
        raise InternalError(f"a 1-D level needs at least 3 vertices to coarsen, got {m}")  # prolongation() skips them
    coarse = list(range(0, m, 2))
    if m % 2 == 0:
        coarse.append(m - 1)
    pos = np.asarray(coarse, dtype=float)
    mc = len(coarse)
    rows, cols, vals = [], [], []
    for i in range(m):
        k = int(np.searchsorted(pos, i))
        if k < mc and pos[k] == i:
            rows.append(i), cols.append(k), vals.append(1.0)
            continue
        lo, hi = pos[k - 1], pos[k]
        t = (i - lo) / (hi - lo)
        rows += [i, i]
        cols += [k - 1, k]
        vals += [1.0 - t, t]
    return sparse.csr_array((vals, (rows, cols)), shape=(m, mc))


def prolongation(shape: tuple[int, ...]) -> tuple[sparse.csr_array, tuple[int, ...]]:
    """Multilinear interpolation from the next coarser grid onto a grid of ``shape`` vertices.

    Dimensions with fewer than 3 vertices are not coarsened. The vertex numbering is C order
    (the last dimension fastest), as in :class:`pwas_hdl.fit.geometry.Grid`, so the prolongation
    is the Kronecker product of the 1-D interpolations in dimension order.

    Parameters
    ----------
    shape : tuple of int
        Vertex counts per dimension of the fine grid.

    Returns
    -------
    P : scipy.sparse.csr_array, shape (prod(shape), prod(coarse_shape))
    coarse_shape : tuple of int
    """
    p = sparse.csr_array(np.ones((1, 1)))
    coarse = []
    for m in shape:
        pj = interpolation_1d(m) if m >= 3 else sparse.csr_array(sparse.identity(m, format="csr"))
        coarse.append(pj.shape[1])
        p = sparse.csr_array(sparse.kron(p, pj, format="csr"))
    return p, tuple(coarse)


def interleaved_order(n: int, k: int = INTERLEAVE) -> np.ndarray:
    """The vertex order of a level: ``k`` consecutive slabs of ``0 .. n - 1`` interleaved.

    Slab ``j`` holds the vertices ``j * s .. (j + 1) * s - 1`` (``s = ceil(n / k)``); the order runs
    through ``i = 0, 1, ...`` and, for each, the slabs ``j = 0 .. k - 1``, giving vertex ``j * s + i``
    (those ``>= n``, in the last slabs when ``k`` does not divide ``n``, skipped).

    Parameters
    ----------
    n : int
        Vertex count of the level.
    k : int
        Number of slabs (values below 1 count as 1).

    Returns
    -------
    ndarray of int64, shape (n,)
        ``order[i]``: the vertex (C-order number) at position ``i``; a permutation of ``0 .. n - 1``.
    """
    n, k = int(n), max(int(k), 1)
    step = -(-n // k) if n else 0
    order = np.arange(k * step, dtype=np.int64).reshape(k, step).T.ravel()
    return order[order < n]


def _inverse(order: np.ndarray) -> np.ndarray:
    inv = np.empty_like(order)
    inv[order] = np.arange(order.size, dtype=order.dtype)
    return inv


def _permuted(m, rows: np.ndarray, cols: np.ndarray) -> sparse.csr_matrix:
    """``m[rows][:, cols]`` as a canonical ``csr_matrix`` (``cols`` a permutation of the columns).

    The rows are gathered, the column indices renumbered through the inverse of ``cols`` and each
    row sorted again: measured at n = 2, N = 10^6 (one fold's normal matrix, CPU) 61 ms instead of
    145 ms through scipy's column fancy indexing, which builds a selection matrix first.
    """
    m = _csr(m)
    g = m[np.asarray(rows)]
    out = sparse.csr_matrix((g.data, _inverse(np.asarray(cols))[g.indices].astype(g.indices.dtype), g.indptr),
                            shape=g.shape)
    out.has_sorted_indices = False
    out.sort_indices()
    return out


class _Triangle:
    """The strict upper (or lower) triangle of a level pattern: which of its entries (``keep``,
    indices into the pattern's values) and their own CSR index arrays; shared by every matrix on
    that pattern."""

    def __init__(self, pattern: sparse.csr_matrix, upper: bool):
        rows = np.repeat(np.arange(pattern.shape[0], dtype=pattern.indices.dtype), np.diff(pattern.indptr))
        mask = pattern.indices > rows if upper else pattern.indices < rows
        keep = np.flatnonzero(mask)
        # positions in the pattern's values: int32 only where every one of them fits
        self.keep = keep.astype(np.int32) if pattern.nnz < 2**31 else keep
        self.indices = pattern.indices[mask]
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(rows[mask], minlength=pattern.shape[0]))]).astype(
            pattern.indptr.dtype)
        self.shape = pattern.shape


class _NegTriangle:
    """Minus the strict upper (or lower) triangle of a level's ``m + sigma Gamma``, for residuals.

    The triangle's values of ``m`` are taken once (negated, in ``dtype``) and those of ``Gamma``
    are the pattern's (:class:`LevelPatterns`, shared by the folds), so that :meth:`set_sigma` is
    two passes over them rather than a gather from the level's matrix.
    """

    def __init__(self, tri: _Triangle, m_vals: np.ndarray, neg_g: np.ndarray, dtype):
        self._m = np.negative(m_vals[tri.keep]).astype(dtype, copy=False)
        self._g = neg_g
        self.matrix = sparse.csr_matrix((np.zeros(self._m.size, dtype=dtype), tri.indices, tri.indptr),
                                        shape=tri.shape)
        self.matrix.has_sorted_indices = True
        self.sigma: float | None = None

    def set_sigma(self, sigma: float) -> None:
        if self.sigma != sigma:
            np.multiply(self._g, sigma, out=self.matrix.data)
            self.matrix.data += self._m
            self.sigma = sigma


def grid_shape_of(gamma: sparse.sparray, n_dims: int) -> tuple[int, ...] | None:
    """The vertex-grid shape of a first-order ``Gamma`` (:func:`~pwas_hdl.fit.regularized_lsq.tikhonov_matrix`).

    Vertex 0 is coupled to vertex ``stride_j`` along every axis ``j``; the strides give the shape
    (``shape[j] = stride_{j-1} / stride_j``, ``shape[0] = N / stride_0``). The result is checked
    against the number of non-zeros of the grid Laplacian of that shape; ``None`` when ``Gamma``
    is not such a matrix (e.g. zero order, or a grid with a dimension of one interval... whose
    pattern does not identify the strides).

    Parameters
    ----------
    gamma : sparse array, shape (N, N)
        The Tikhonov matrix, vertices in C order.
    n_dims : int
        Number of grid dimensions ``n``.

    Returns
    -------
    tuple of int or None
        Vertex counts per dimension (product ``N``), or None.
    """
    g = sparse.csr_array(gamma)
    n_v = g.shape[0]
    cols = np.sort(g.indices[g.indptr[0]:g.indptr[1]])
    strides = sorted((int(c) for c in cols if c != 0), reverse=True)
    if len(strides) != n_dims or n_v == 0:
        return None
    shape = []
    prev = n_v
    for s in strides:
        if s <= 0 or prev % s:
            return None
        shape.append(prev // s)
        prev = s
    if prev != 1:
        return None
    edges = sum(n_v // m * (m - 1) for m in shape)
    if g.nnz != n_v + 2 * edges:
        return None
    return tuple(shape)


def _csr(m) -> sparse.csr_matrix:
    """A canonical scipy ``csr_matrix`` (sorted, summed duplicates): the type pyamg's kernels take."""
    out = sparse.csr_matrix(m)
    out.sum_duplicates()
    out.sort_indices()
    return out


def _keys(m: sparse.csr_matrix) -> np.ndarray:
    """``row * n_cols + col`` of every stored entry (int64; increasing for a canonical matrix)."""
    return np.repeat(np.arange(m.shape[0], dtype=np.int64), np.diff(m.indptr)) * m.shape[1] + m.indices


def _aligned(pattern: sparse.csr_matrix, m, keys: np.ndarray | None = None) -> np.ndarray:
    """Values of ``m`` at the entries of ``pattern`` (which must contain ``m``'s non-zeros).

    Explicit zeros of ``m`` (e.g. ``H'H - H_v'H_v`` cancelling exactly) are dropped first: the
    union pattern does not hold them. ``keys``: :func:`_keys` of ``pattern``, if already made.

    Raises
    ------
    OutsidePattern
        ``m`` has a non-zero outside ``pattern``.
    """
    m = _csr(m)
    m.eliminate_zeros()
    keys_p = _keys(pattern) if keys is None else keys
    keys_m = _keys(m)
    pos = np.searchsorted(keys_p, keys_m)
    if keys_m.size and (pos.max() >= keys_p.size or np.any(keys_p[pos] != keys_m)):
        raise OutsidePattern("matrix has non-zeros outside the pattern")
    out = np.zeros(keys_p.size)
    out[pos] = m.data
    return out


def _union_aligned(a, b) -> tuple[sparse.csr_matrix, np.ndarray, np.ndarray]:
    """The union pattern of ``a`` and ``b`` and the values of each on it (zeros where it has none).

    One sparse addition of *position markers* instead of a key search per matrix: entry ``i`` of
    ``a`` carries ``i + 1``, entry ``j`` of ``b`` carries ``(j + 1) * 2^k`` (``2^k > nnz(a)``), so
    every sum is positive (no entry of the union cancels) and exact in double precision while
    ``2^k (nnz(b) + 2) < 2^53``; the sum says which entries of ``a`` and ``b`` meet
    there. Explicit zeros are dropped first (as in :func:`_aligned`). Measured at n = 2,
    N = 10^6 (5 levels of one fold): 0.1 s instead of 1.1-1.5 s with :func:`_aligned` twice.
    """
    a, b = _csr(a), _csr(b)
    a.eliminate_zeros()
    b.eliminate_zeros()
    shift = int(np.ceil(np.log2(a.nnz + 2)))
    big = float(2**shift)
    if big * (b.nnz + 2) >= 2.0**53:  # pragma: no cover - beyond any grid of this project
        pat = _union_pattern(a, b)
        return pat, _aligned(pat, a), _aligned(pat, b)
    ma = sparse.csr_matrix((np.arange(1, a.nnz + 1, dtype=float), a.indices, a.indptr), shape=a.shape)
    mb = sparse.csr_matrix((np.arange(1, b.nnz + 1, dtype=float) * big, b.indices, b.indptr), shape=b.shape)
    pat = _csr(ma + mb)
    code = pat.data.astype(np.int64)
    # position 0 (no entry) picks the appended 0.0
    va = np.append(a.data, 0.0)[(code & (2**shift - 1)) - 1]
    vb = np.append(b.data, 0.0)[(code >> shift) - 1]
    pat.data[:] = 1.0
    return pat, va, vb


def _galerkin(r: sparse.csr_matrix, m: sparse.csr_matrix, p: sparse.csr_matrix) -> sparse.csr_matrix:
    """The coarse operator ``r m p`` (canonical), multiplied as ``r (m p)`` rather than ``(r m) p``,
    whose middle product has more entries a row: measured at n = 2, N = 10^6 (fine level, CPU)
    382 instead of 568 ms for ``Gamma``, 109 instead of 140 ms for a fold's normal matrix."""
    return _csr(r @ (m @ p))


def _single(m: sparse.csr_matrix) -> sparse.csr_matrix:
    """``m`` with its values in single precision (index arrays shared, not copied)."""
    return sparse.csr_matrix((m.data.astype(np.float32), m.indices, m.indptr), shape=m.shape)


def _union_pattern(a, b) -> sparse.csr_matrix:
    s = _csr(abs(_csr(a)) + abs(_csr(b)))
    s.data[:] = 1.0
    return s


class GridHierarchy:
    """Prolongations and the Galerkin ``Gamma`` of every level, built once for all folds and sigmas.

    Every level's vertices are numbered in the order of :func:`interleaved_order` (see
    :data:`INTERLEAVE`): position ``i`` of level ``l`` is the vertex ``orders[l][i]`` of that level's
    grid in C order. The prolongations ``p``, restrictions ``r`` and ``gammas`` are stored in
    these orders; :meth:`internal` maps a matrix of the fine grid's C order into the fine level's.

    Parameters
    ----------
    shape : tuple of int
        Vertex counts per dimension of the fine grid.
    gamma : sparse array, shape (prod(shape), prod(shape))
        In the fine grid's C order.
    coarsest_max : int, optional
        Stop coarsening at this many unknowns (default :data:`COARSEST_MAX`).
    """

    def __init__(self, shape: tuple[int, ...], gamma: sparse.sparray, coarsest_max: int | None = None):
        coarsest_max = COARSEST_MAX if coarsest_max is None else int(coarsest_max)
        self.shape = tuple(int(s) for s in shape)
        if gamma.shape[0] != int(np.prod(self.shape)):
            raise InternalError(f"Gamma has {gamma.shape[0]} rows, the grid {int(np.prod(self.shape))} vertices")
        self.orders: list[np.ndarray] = [interleaved_order(int(np.prod(self.shape)))]
        self.p: list[sparse.csr_matrix] = []
        self.r: list[sparse.csr_matrix] = []
        self.gammas: list[sparse.csr_matrix] = [self.internal(gamma)]
        self.shapes = [self.shape]
        cur = self.shape
        while int(np.prod(cur)) > coarsest_max and max(cur) >= 3:
            p, cur = prolongation(cur)
            self.orders.append(interleaved_order(int(np.prod(cur))))
            p = _permuted(p, self.orders[-2], self.orders[-1])
            self.p.append(p)
            self.r.append(_csr(p.T))
            self.gammas.append(_galerkin(self.r[-1], self.gammas[-1], p))
            self.shapes.append(cur)
        self._inv0 = _inverse(self.orders[0])
        #: the level patterns of :meth:`share` (None until then)
        self.shared: LevelPatterns | None = None

    @property
    def levels(self) -> int:
        """Number of levels, the fine one included."""
        return len(self.gammas)

    def internal(self, m: sparse.sparray) -> sparse.csr_matrix:
        """A fine-grid matrix (C order) in the fine level's vertex order.

        Parameters
        ----------
        m : sparse array, shape (N, N)

        Returns
        -------
        scipy.sparse.csr_matrix, shape (N, N)
            Canonical (sorted indices), rows and columns permuted by ``orders[0]``.
        """
        return _permuted(m, self.orders[0], self.orders[0])

    def to_internal(self, v: np.ndarray) -> np.ndarray:
        """A fine-grid vector (C order, first axis) in the fine level's vertex order (a copy).

        Parameters
        ----------
        v : ndarray, shape (N,) or (N, k)

        Returns
        -------
        ndarray, same shape and dtype
        """
        return np.asarray(v)[self.orders[0]]

    def to_natural(self, v: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`to_internal`: a fine-level vector back in C order (a copy).

        Parameters
        ----------
        v : ndarray, shape (N,) or (N, k)

        Returns
        -------
        ndarray, same shape and dtype
        """
        return np.asarray(v)[self._inv0]

    def coarsen(self, m: sparse.sparray) -> list[sparse.csr_matrix]:
        """``[m, P_0' m P_0, ...]``: the Galerkin operators of ``m`` on every level.

        Parameters
        ----------
        m : sparse array, shape (N, N)
            Fine grid, C order.

        Returns
        -------
        list of scipy.sparse.csr_matrix
            One per level (:attr:`levels`), each in its level's vertex order.
        """
        out = [self.internal(m)]
        for p, r in zip(self.p, self.r):
            out.append(_galerkin(r, out[-1], p))
        return out

    def share(self, m: sparse.sparray) -> "LevelPatterns":
        """Build the level patterns of ``m`` for every later :meth:`for_matrix`, and keep them.

        Parameters
        ----------
        m : sparse array, shape (N, N)
            Fine grid, C order; e.g. the full data's normal matrix.

        Returns
        -------
        LevelPatterns
            Also stored as :attr:`shared`.
        """
        self.shared = LevelPatterns(self, m)
        return self.shared

    def for_matrix(self, m: sparse.sparray) -> "FoldMultigrid":
        """The multigrid solver of ``m + sigma Gamma`` (``m`` one fold's normal matrix, C order).

        On the patterns of :meth:`share` where they hold ``m``'s (a CV fold's ``H'H - H_v'H_v``
        within the full data's ``H'H``); the shared matrix itself is not coarsened again.

        Parameters
        ----------
        m : sparse array, shape (N, N)

        Returns
        -------
        FoldMultigrid
            On the shared patterns, or on ``m``'s own when it has a non-zero outside them.
        """
        sh = self.shared
        if sh is not None and sh.is_reference(m):
            return FoldMultigrid(self, [sh.fine_m], shared=sh, m_vals=sh.ref_vals)
        return FoldMultigrid(self, self.coarsen(m), shared=sh)


class LevelPatterns:
    """Every level's union pattern of ``Gamma`` and a reference ``m``'s Galerkin operator, shared.

    A CV fold's normal matrix ``H'H - H_v'H_v`` has no entry outside the full data's ``H'H``, so
    its levels fit the patterns of the full data's: built once (before the folds are forked, so
    that the workers inherit them), with ``Gamma``'s values on them, the positions of the strict
    triangles (:class:`_NegTriangle`) and the entries' sort keys, each fold's
    :class:`FoldMultigrid` only places its own values (a key search) instead of forming the union
    patterns, ``Gamma``'s values and the triangles again. Measured at n = 2, N = 10^6, T = 10^5
    (one fold, CPU): the levels of a fold 1.18 -> 0.4 s; these patterns 1.1 s, once.
    A pattern may hold entries where the fold's matrix is zero (explicit zeros: the same
    arithmetic, a few more entries a sweep).

    Parameters
    ----------
    hier : GridHierarchy
    m : sparse array, shape (N, N)
        The reference matrix (fine grid, C order).
    """

    def __init__(self, hier: "GridHierarchy", m: sparse.sparray):
        #: the reference matrix (None: built from another matrix's levels, :meth:`of_levels`)
        self.reference: sparse.sparray | None = m
        self._build(hier, hier.coarsen(m))

    @classmethod
    def of_levels(cls, hier: "GridHierarchy", ms: list[sparse.csr_matrix]) -> "LevelPatterns":
        """The patterns of the levels ``ms`` themselves (no reference matrix).

        Parameters
        ----------
        hier : GridHierarchy
        ms : list of scipy.sparse.csr_matrix
            One matrix per level (:meth:`GridHierarchy.coarsen`).

        Returns
        -------
        LevelPatterns
        """
        out = cls.__new__(cls)
        out.reference = None
        out._build(hier, ms)
        return out

    def _build(self, hier: "GridHierarchy", ms: list[sparse.csr_matrix]) -> None:
        #: the reference's fine level (the levels' vertex order)
        self.fine_m = ms[0]
        last = len(ms) - 1
        self.patterns: list[sparse.csr_matrix] = []
        #: the reference's values on every level's pattern (double)
        self.ref_vals: list[np.ndarray] = []
        #: Gamma's values on every level's pattern: double, and single on the levels the V-cycle smooths
        self.g64: list[np.ndarray] = []
        self.g32: list[np.ndarray] = []
        for level, (mm, g) in enumerate(zip(ms, hier.gammas)):
            pat, m_vals, g_vals = _union_aligned(mm, g)
            pat.data = np.empty(0)  # the structure alone: only its index arrays are used (see matrix)
            self.patterns.append(pat)
            self.ref_vals.append(m_vals)
            self.g64.append(g_vals)
            if level < last:
                self.g32.append(g_vals.astype(np.float32))
        self.keys = [_keys(pat) for pat in self.patterns]
        #: the strict upper triangles of the smoothed levels, the fine level's lower one, and minus
        #: Gamma's values on them (single precision; the fine level's also double, for the data-block cycle)
        self.upper = [_Triangle(pat, True) for pat in self.patterns[:max(last, 1)]]
        self.lower0 = _Triangle(self.patterns[0], False)
        self.neg_g_upper32 = [np.negative(g[tri.keep]) for g, tri in zip(self.g32, self.upper)]
        self.neg_g_tri64 = [np.negative(self.g64[0][tri.keep]) for tri in (self.upper[0], self.lower0)]

    def is_reference(self, m: sparse.sparray) -> bool:
        """Whether ``m`` is the reference matrix.

        Parameters
        ----------
        m : sparse array

        Returns
        -------
        bool
            True for the same object, or a CSR matrix with equal shape, index and value arrays.
        """
        ref = self.reference
        if m is ref:
            return True
        if ref is None or not (sparse.issparse(m) and m.format == "csr" and m.shape == ref.shape and m.nnz == ref.nnz):
            return False
        return all(a is b or np.array_equal(a, b) for a, b in
                   ((m.indptr, ref.indptr), (m.indices, ref.indices), (m.data, ref.data)))

    def values_of(self, ms: list[sparse.csr_matrix]) -> list[np.ndarray]:
        """Every level's values of ``ms`` (:meth:`GridHierarchy.coarsen`) on these patterns.

        Parameters
        ----------
        ms : list of scipy.sparse.csr_matrix
            One per level.

        Returns
        -------
        list of ndarray of float64
            One per level, ``patterns[l].nnz`` values (0 where ``ms[l]`` has no entry).

        Raises
        ------
        OutsidePattern
            Another number of levels, or a level has a non-zero outside its pattern.
        """
        if len(ms) != len(self.patterns):
            raise OutsidePattern("another number of levels")
        return [_aligned(pat, m, keys) for pat, m, keys in zip(self.patterns, ms, self.keys)]

    def matrix(self, level: int, values: np.ndarray) -> sparse.csr_matrix:
        """A canonical matrix of ``values`` on the pattern of ``level`` (index arrays shared).

        Parameters
        ----------
        level : int
        values : ndarray, shape (patterns[level].nnz,)
            Used as the data array (not copied).

        Returns
        -------
        scipy.sparse.csr_matrix
        """
        pat = self.patterns[level]
        out = sparse.csr_matrix((values, pat.indices, pat.indptr), shape=pat.shape)
        out.has_sorted_indices = True
        out.has_canonical_format = True
        return out


@dataclass
class MGInfo:
    """One multigrid-preconditioned CG solve: iterations and the residual computed afresh.

    Attributes
    ----------
    iterations : int
        CG iterations (0 for ``b = 0``).
    rel_residual : float
        ``||b - A w|| / ||b||`` of the returned ``w``, computed afresh in double precision.
    abs_residual : float
        ``||b - A w||`` (the units of ``b``).
    converged : bool
        CG stopped within ``maxiter`` and ``rel_residual <= rtol``.
    """

    iterations: int
    rel_residual: float
    abs_residual: float
    converged: bool


class FoldMultigrid:
    """V-cycle preconditioned CG for ``(m + sigma Gamma) w = b`` of one ``m`` and any sigma.

    The V-cycle runs in single precision (the levels between the fine and the coarsest held in
    single only, the fine level's values cast from double, the prolongations cast, the index
    arrays shared; the coarsest solve in double): it is only the preconditioner, while CG,
    its products with the fine operator and the stopping test on the residual computed afresh
    stay in double precision, so the weight bound is unchanged. Half the bytes of values to
    stream per Gauss-Seidel sweep and product: measured at n = 2, N = 10^6, T = 10^5 (one fold,
    its 11 multigrid sigmas, loaded machine, CPU): 6.7 s instead of 7.9 s, the same iteration
    counts (9 9 8 8 8 8 8 9 10 12 19).

    The operators :attr:`ops` are in the levels' vertex orders (:class:`GridHierarchy`); the
    public methods take and return vectors in the fine grid's C order. Each residual after a
    Gauss-Seidel sweep is half a product: from zero, ``(D + L) x = b`` makes ``b - A x = -U x``;
    from ``x0``, ``b - A x = -U (x - x0)`` (forward) or ``-L (x - x0)`` (backward), with the strict
    triangles kept per level (:class:`_NegTriangle`). With the interleaved orders and CG's vector
    work in place (:func:`~pwas_hdl.fit.conjugate_gradients.pcg`), measured at n = 2, N = 10^6,
    T = 10^5 (one fold, one BLAS thread, CPU ms): V-cycle 62 -> 42, data-block cycle 110 -> 70;
    the serial first-order CV 113 -> 85 s (886 -> 902 iterations).

    Parameters
    ----------
    hier : GridHierarchy
    ms : list of sparse matrices
        ``m`` on every level (:meth:`GridHierarchy.coarsen`), in the levels' vertex orders (only
        the fine level where ``m_vals`` is given).
    shared : LevelPatterns, optional
        Patterns that hold every level of ``m`` (:meth:`GridHierarchy.share`); where they do not,
        or without them, the levels' own.
    m_vals : list of ndarray, each shape (nnz_l,), optional
        ``m``'s values on every level of ``shared``, one per level ``l`` on its pattern's ``nnz_l``
        entries (the reference matrix's, :attr:`LevelPatterns.ref_vals`).
    """

    def __init__(self, hier: GridHierarchy, ms: list[sparse.csr_matrix], shared: LevelPatterns | None = None,
                 m_vals: list[np.ndarray] | None = None):
        self.hier = hier
        #: the data-block smoother of the fine level, built on the first :meth:`set_block`
        self.block: DataBlockSmoother | None = None
        self._fine_m = ms[0]
        self._block_sigma: float | None = None
        if m_vals is None and shared is not None:
            try:
                m_vals = shared.values_of(ms)
            except OutsidePattern:  # not within the shared patterns: this matrix's own
                shared = None
        if shared is None:
            shared = LevelPatterns.of_levels(hier, ms)
            m_vals = shared.ref_vals
        #: the level patterns this fold's matrices are on (:class:`LevelPatterns`)
        self.shared = shared
        last = len(m_vals) - 1
        self._last = last
        # m's values in the precision each level is used in: double on the fine level (CG's
        # products, the data-block cycle; single too for the V-cycle) and the coarsest (its
        # factor), single on the levels between (only smoothed)
        self._m64 = {level: m_vals[level] for level in {0, last}}
        self._m32 = {level: m_vals[level].astype(np.float32) for level in range(1, last)}
        #: every level's operator ``m_l + sigma Gamma_l`` (values set by :meth:`set_sigma`) in the
        #: precision it is used in (see above); the fine level's single-precision copy is ``_ops32[0]``
        self.ops: list[sparse.csr_matrix] = [
            shared.matrix(level, np.zeros(v.size, dtype=np.float64 if level in (0, last) else np.float32))
            for level, v in enumerate(m_vals)]
        self._ops32 = ([shared.matrix(0, np.zeros(m_vals[0].size, dtype=np.float32))] + self.ops[1:last]
                       if last > 0 else [])
        self._p32 = [_single(p) for p in hier.p]
        self._r32 = [_single(r) for r in hier.r]
        # minus the strict upper triangle of every smoothed level (single precision, values set by
        # set_sigma): after a forward Gauss-Seidel sweep from zero, (D + L) x = b, so the residual
        # b - A x is -U x, half a product (see _vcycle)
        self._neg_upper32 = [_NegTriangle(tri, m_vals[level], neg_g, np.float32)
                             for level, (tri, neg_g) in enumerate(zip(shared.upper, shared.neg_g_upper32))]
        # the fine level's -U and -L in double precision for the data-block cycle (built by set_block)
        self._neg_tri64: list[_NegTriangle] | None = None
        self.sigma: float | None = None
        #: the sigma of the fine level's single-precision values (``_ops32[0]``, ``_neg_upper32[0]``):
        #: the data-block cycle does not use them, so :meth:`set_block` leaves them
        self._fine32_sigma: float | None = None
        self._coarse = None
        self._coarse_chol = None

    def set_sigma(self, sigma: float) -> None:
        """Every level's operator ``m_l + sigma Gamma_l`` (in place) and the coarsest factor.

        Parameters
        ----------
        sigma : float
            Tikhonov weight (> 0).
        """
        self._set_values(sigma, fine32=True)

    def _set_values(self, sigma: float, fine32: bool) -> None:
        """:meth:`set_sigma`; ``fine32=False`` leaves the fine level's single-precision values."""
        sh = self.shared
        if self.sigma != sigma:
            self.sigma = self._fine32_sigma = None  # until every level and the coarsest factor hold sigma's values
            for level, a in enumerate(self.ops):
                double = a.dtype == np.float64
                # in place: no temporary of the level's size
                np.multiply(sh.g64[level] if double else sh.g32[level], sigma, out=a.data)
                a.data += self._m64[level] if double else self._m32[level]
            for tri in self._neg_upper32[1:] + (self._neg_tri64 or []):
                tri.set_sigma(sigma)
            self._coarse = self._coarse_solver()
            self.sigma = sigma
        if fine32 and self._last > 0 and self._fine32_sigma != sigma:
            np.copyto(self._ops32[0].data, self.ops[0].data, casting="same_kind")
            self._neg_upper32[0].set_sigma(sigma)
            self._fine32_sigma = sigma

    def _coarse_solver(self):
        """The coarsest level's factor at the current values (``.solve(b)``, double precision).

        CHOLMOD on the level's pattern, analysed once (5.6 ms a numeric factorisation against
        SuperLU's 12.8 ms at n = 2, 4 096 unknowns); SuperLU without cvxopt.
        """
        from pwas_hdl.fit.sparse_cholesky import NotPositiveDefinite, PatternCholesky, cholmod_available

        a = self.ops[-1]
        if cholmod_available():
            if self._coarse_chol is None:
                self._coarse_chol = PatternCholesky(a)
            try:
                self._coarse_chol.factorize(self._coarse_chol.align(a))
                return self._coarse_chol
            except NotPositiveDefinite:  # rounding in H'H - H_v'H_v at a tiny sigma: SuperLU as before
                pass
        return splinalg.splu(sparse.csc_matrix(a), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                             options={"SymmetricMode": True})

    def vcycle(self, b: np.ndarray) -> np.ndarray:
        """One V-cycle from a zero initial guess: an SPD approximation of ``A^{-1} b``.

        Parameters
        ----------
        b : ndarray, shape (N,)
            Fine grid's C order.

        Returns
        -------
        ndarray of float64, shape (N,)
            C order. The cycle itself runs in single precision (see the class) and in the
            levels' vertex orders.
        """
        return self.hier.to_natural(self._vcycle_fine(self.hier.to_internal(b)))

    def _vcycle_fine(self, b: np.ndarray) -> np.ndarray:
        if self._last > 0 and self._fine32_sigma != self.sigma:  # after set_block: the fine level's single values too
            self._set_values(self.sigma, fine32=True)
        return self._vcycle(np.asarray(b, dtype=np.float32), 0).astype(float)

    def set_block(self, sigma: float) -> None:
        """Factorise the data block ``M_TT + sigma diag(Gamma)_TT`` for :meth:`vcycle_block` (and
        :meth:`set_sigma` to ``sigma``).

        Parameters
        ----------
        sigma : float
            Tikhonov weight (> 0).

        Raises
        ------
        pwas_hdl.fit.sparse_cholesky.NotPositiveDefinite
            The fold's data block is not numerically positive definite at this sigma.
        """
        self._set_values(sigma, fine32=False)
        if self.block is None:
            self.block = DataBlockSmoother(self._fine_m, self.hier.gammas[0].diagonal())
        if self._neg_tri64 is None:
            sh = self.shared
            self._neg_tri64 = [_NegTriangle(tri, self._m64[0], neg_g, np.float64)
                               for tri, neg_g in zip((sh.upper[0], sh.lower0), sh.neg_g_tri64)]
        for tri in self._neg_tri64:
            tri.set_sigma(sigma)
        if self._block_sigma != sigma:
            self._block_sigma = None
            self.block.factorize(sigma)
            self._block_sigma = sigma

    def vcycle_block(self, b: np.ndarray) -> np.ndarray:
        """One V-cycle whose fine level is smoothed by the exact data block and Gauss-Seidel.

        The data-block solve (:class:`DataBlockSmoother`) from zero, forward Gauss-Seidel, the
        coarse-grid correction (the single-precision cycle of the coarser levels), backward
        Gauss-Seidel and the data-block correction: the post-smoothing is the adjoint of the
        pre-smoothing, so the cycle is a symmetric preconditioner. Measured against Gauss-Seidel
        before the block (fold 0, T = 10^5, the data-block sigmas, warm-started, CPU): n = 3,
        N = 262 144: 92 instead of 109 iterations, 7.7 instead of 9.5 s; n = 2, N = 10^6: 80 / 95,
        7.2 / 9.0 s; with one block solve between two coarse corrections: 134 iterations, 8.8 s
        (n = 3). The fine level stays in double precision (in single the CG stalls at
        sigma = 1e-7: measured n = 3, N = 262 144). Call :meth:`set_block` first.

        Parameters
        ----------
        b : ndarray, shape (N,)
            Fine grid's C order.

        Returns
        -------
        ndarray of float64, shape (N,)
            C order.
        """
        return self.hier.to_natural(self._vcycle_block_fine(self.hier.to_internal(np.asarray(b, dtype=float))))

    def _vcycle_block_fine(self, b: np.ndarray) -> np.ndarray:
        """:meth:`vcycle_block` in the fine level's vertex order."""
        from pyamg.relaxation.relaxation import gauss_seidel

        a = self.ops[0]
        neg_upper, neg_lower = (tri.matrix for tri in self._neg_tri64)
        x = self.block.solve(b)
        before = x.copy()
        gauss_seidel(a, x, b, iterations=1, sweep="forward")
        # (D + L) x = b - U before, so b - A x = -U (x - before): half a product
        r = neg_upper @ np.subtract(x, before, out=before)
        if len(self.ops) > 1:
            x += self._p32[0] @ self._vcycle(self._r32[0] @ r.astype(np.float32), 1)
        else:  # pragma: no cover - a fine level at most COARSEST_MAX unknowns is not coarsened
            x += self._coarse.solve(r)
        np.copyto(before, x)
        gauss_seidel(a, x, b, iterations=1, sweep="backward")
        # (D + U) x = b - L before, so b - A x = -L (x - before)
        x += self.block.solve(neg_lower @ np.subtract(x, before, out=before))
        return x

    def _vcycle(self, b: np.ndarray, level: int) -> np.ndarray:
        from pyamg.relaxation.relaxation import gauss_seidel

        if level == len(self.ops) - 1:
            return self._coarse.solve(b.astype(float)).astype(np.float32)
        a = self._ops32[level]
        x = np.zeros_like(b)
        gauss_seidel(a, x, b, iterations=1, sweep="forward")
        r = self._neg_upper32[level].matrix @ x  # b - A x after the sweep from zero (see __init__)
        x += self._p32[level] @ self._vcycle(self._r32[level] @ r, level + 1)
        gauss_seidel(a, x, b, iterations=1, sweep="backward")
        return x

    def solve(self, b: np.ndarray, sigma: float, x0: np.ndarray | None = None, rtol: float = 1e-10,
              maxiter: int = 500, block: bool = False) -> tuple[np.ndarray, MGInfo]:
        """``(m + sigma Gamma)^{-1} b`` by PCG to ``||b - A w|| <= rtol ||b||`` (one column ``b``).

        Parameters
        ----------
        b : ndarray, shape (N,)
            Right-hand side, fine grid's C order.
        sigma : float
            Tikhonov weight (> 0).
        x0 : ndarray, shape (N,), optional
            Initial guess (C order); default zero.
        rtol : float
            Relative residual to reach.
        maxiter : int
            CG iteration limit.
        block : bool
            Precondition with :meth:`vcycle_block` (the data-block smoother) instead of
            :meth:`vcycle`.

        Returns
        -------
        w : ndarray of float64, shape (N,)
            C order; zero for ``b = 0``.
        info : MGInfo
            Iterations and the residual computed afresh (``converged``: within ``rtol``).

        Raises
        ------
        pwas_hdl.fit.sparse_cholesky.NotPositiveDefinite
            ``block`` and the data block is not numerically positive definite (see :meth:`set_block`).
        """
        if block:
            self.set_block(float(sigma))
        else:
            self.set_sigma(float(sigma))
        a = self.ops[0]
        b = np.asarray(b, dtype=float)
        nb = float(np.linalg.norm(b))
        if nb == 0.0:
            return np.zeros_like(b), MGInfo(0, 0.0, 0.0, True)
        b = self.hier.to_internal(b)
        w, its, done = pcg(a, b, self._vcycle_block_fine if block else self._vcycle_fine,
                           None if x0 is None else self.hier.to_internal(np.asarray(x0, dtype=float)), rtol, maxiter,
                           fresh_result=True)  # both cycles return a new array
        r = float(np.linalg.norm(b - a @ w))
        return self.hier.to_natural(w), MGInfo(its, r / nb, r, done and r <= rtol * nb)


class DataBlockSmoother:
    """Exact solves with ``P = M_TT + sigma diag(Gamma)_TT`` on the vertices ``T`` that ``M`` touches.

    ``M`` is one fold's normal matrix (``H_k'H_k``), ``T`` the vertices with a positive diagonal of
    ``M``; elsewhere ``P`` is ``sigma diag(Gamma)`` alone. ``M_TT``'s pattern is analysed once (a
    fold's own pattern: the validation samples' entries cancel in ``H'H - H_v'H_v``, so it is
    smaller than the full data's), and each sigma is one numeric factorisation of a matrix without
    ``Gamma``'s grid edges, whose fill is that of a zero-order fit (CHOLMOD choosing a simplicial or
    supernodal factor; SuperLU without cvxopt).

    As the fine-level smoother of :meth:`FoldMultigrid.vcycle_block` it makes the multigrid-PCG
    iteration count nearly independent of sigma (fold 0 of T = 10^5, warm-started from the largest
    sigma down, rtol 1e-10): 1-15 iterations at every sigma of 1e-7 .. 0.1 at n = 3, N = 262 144 and
    4-15 of 1e-7 .. 3e-3 at n = 2, N = 10^6, where Gauss-Seidel alone needs 28 -> > 4000 and
    34 -> > 500.

    Parameters
    ----------
    m : sparse array, shape (N, N)
        The fold's normal matrix.
    gamma_diag : ndarray, shape (N,)
        The diagonal of ``Gamma`` (positive).
    """

    def __init__(self, m: sparse.sparray, gamma_diag: np.ndarray):
        from pwas_hdl.fit.sparse_cholesky import PatternCholesky, cholmod_available

        m = _csr(m)
        m.eliminate_zeros()
        self.n = m.shape[0]
        self.gamma_diag = np.asarray(gamma_diag, dtype=float).reshape(-1)
        if self.gamma_diag.shape != (self.n,) or not np.all(self.gamma_diag > 0):
            raise InternalError("gamma_diag must be the positive diagonal of Gamma, one entry per vertex")
        self.touched = np.flatnonzero(m.diagonal() > 0)
        self._m_t = _csr(m[self.touched][:, self.touched])
        g_t = sparse.diags(self.gamma_diag[self.touched])
        self._g_t = _csr(g_t)
        if cholmod_available():
            self._chol = PatternCholesky(abs(self._m_t) + abs(self._g_t), supernodal=False)
            self._m_vals, self._g_vals = self._chol.align(self._m_t), self._chol.align(self._g_t)
        else:
            self._chol = None
        self._lu = None
        self._inv: np.ndarray | None = None
        self.factorizations = 0

    def factorize(self, sigma: float) -> None:
        """Factorise ``P`` at ``sigma``.

        Parameters
        ----------
        sigma : float
            Tikhonov weight (> 0).

        Raises
        ------
        pwas_hdl.fit.sparse_cholesky.NotPositiveDefinite
        """
        from pwas_hdl.fit.sparse_cholesky import NotPositiveDefinite

        sigma = float(sigma)
        self._inv = 1.0 / (sigma * self.gamma_diag)  # P's inverse off the touched vertices
        if self._chol is not None:
            self._chol.factorize(self._m_vals + sigma * self._g_vals)
        else:
            try:
                self._lu = splinalg.splu(sparse.csc_matrix(self._m_t + sigma * self._g_t), permc_spec="MMD_AT_PLUS_A",
                                         diag_pivot_thresh=0.0, options={"SymmetricMode": True})
            except RuntimeError as exc:  # an exactly singular pivot
                raise NotPositiveDefinite(f"SuperLU: data block singular ({exc})") from None
        self.factorizations += 1

    def solve(self, r: np.ndarray) -> np.ndarray:
        """``P^{-1} r`` with the last factorisation (:meth:`factorize` first).

        Parameters
        ----------
        r : ndarray of float64, shape (N,)

        Returns
        -------
        ndarray of float64, shape (N,)
        """
        out = r * self._inv  # one pass over all vertices, then the touched ones overwritten
        rt = r[self.touched]
        out[self.touched] = self._chol.solve(rt) if self._chol is not None else self._lu.solve(rt)
        return out
