"""Sparse Cholesky of many SPD matrices that share one sparsity pattern (CHOLMOD via cvxopt).

Cross-validation of sigma solves ``(M_k + sigma Gamma) w = b`` for every fold ``k`` and every
candidate ``sigma``: for one fold all these matrices have the pattern of ``M_k + Gamma``.
:class:`PatternCholesky` analyses a pattern once (fill-reducing ordering and supernodal
structure, CHOLMOD ``symbolic``) and then does only the numeric factorisation per matrix
(CHOLMOD ``numeric``): measured on this project's 2-core machine (T = 10^5, one BLAS
thread, CPU s per factorisation): n = 3, N = 262 144 zero order (141 358 touched vertices)
0.19 s instead of 2.0 s with SuperLU; n = 2, N = 10^6 first order 1.2-1.6 s (SuperLU: ~25 s).

CHOLMOD comes with the ``cvxopt`` wheel (SuiteSparse bundled, no system library needed). Where it
cannot be imported, :func:`cholmod_available` is False and the caller falls back to SuperLU.

The wheel's CHOLMOD calls the OpenBLAS 0.3.15 bundled with it, whose run-time CPU detection does not
know processors newer than it and then takes its oldest kernels (``Prescott``, SSE3): on this
project's 2-core machine (an Intel Xeon of family 6, model 207, with AVX-512) a supernodal
factorisation ran 2.7x slower than with the AVX-512 kernels. :func:`import_cholmod` therefore loads
cvxopt with ``OPENBLAS_CORETYPE`` set to the newest kernel set the CPU's own feature flags allow
(:func:`openblas_coretype`), unless the variable is already set, and removes it again afterwards
(numpy's own OpenBLAS is loaded by then and detects the CPU itself; child processes do not
inherit the setting).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import sparse

from pwas_hdl.errors import InternalError

if TYPE_CHECKING:
    from types import ModuleType

__all__ = ["cholmod_available", "import_cholmod", "openblas_coretype", "PatternCholesky", "NotPositiveDefinite", "OutsidePattern",
           "grid_nested_dissection", "ND_LEAF", "FactorCounts"]


class NotPositiveDefinite(ArithmeticError):
    """CHOLMOD found a non-positive pivot: the matrix is not (numerically) positive definite."""


class OutsidePattern(ValueError):
    """A matrix has a non-zero outside the sparsity pattern it is to be placed on (its callers then
    analyse the matrix's own pattern). A class of its own so that those fallbacks catch this and
    nothing else (a plain ``ValueError`` from a bug is not taken for it)."""


#: OpenBLAS kernel sets by the CPU features they need, newest first (``/proc/cpuinfo`` flag names).
#: Measured (n = 3, N = 262 144 zero order, T = 10^5, one CV fold, 21 numeric CHOLMOD
#: factorisations, CPU s, 2026-12-05, Xeon family 6 model 207): Prescott (what the bundled
#: OpenBLAS 0.3.15 detects there) 15.1 s, Haswell 7.1 s, SkylakeX 5.5 s.
OPENBLAS_CORETYPES: tuple[tuple[str, frozenset[str]], ...] = (
    ("SkylakeX", frozenset({"avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl"})),
    ("Haswell", frozenset({"avx2", "fma"})),
)


def openblas_coretype(cpuinfo: str | None = None) -> str | None:
    """The newest OpenBLAS kernel set (:data:`OPENBLAS_CORETYPES`) that this CPU's flags allow.

    Parameters
    ----------
    cpuinfo : str, optional
        The text of ``/proc/cpuinfo`` (read when not given).

    Returns
    -------
    str or None
        None where the flags cannot be read (not Linux) or allow none of them: OpenBLAS then
        detects the CPU itself.
    """
    if cpuinfo is None:
        try:
            with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
                cpuinfo = f.read()
        except OSError:
            return None
    flags: set[str] | None = None
    for line in cpuinfo.splitlines():  # the features every CPU has (the intersection over them)
        key, _, value = line.partition(":")
        if key.strip() == "flags":
            these = set(value.split())
            flags = these if flags is None else flags & these
    if not flags:
        return None
    for core, needs in OPENBLAS_CORETYPES:
        if needs <= flags:
            return core
    return None


def import_cholmod() -> "ModuleType":
    """``cvxopt.cholmod``, imported with the OpenBLAS kernels of :func:`openblas_coretype` (see the
    module) unless ``OPENBLAS_CORETYPE`` is set or cvxopt was imported before (its OpenBLAS then
    keeps the kernels it has); ``ImportError`` where cvxopt is not installed."""
    import sys

    # cvxopt's every extension (base first) loads the OpenBLAS: once any is in, its kernels are set
    if "cvxopt" in sys.modules or "OPENBLAS_CORETYPE" in os.environ:
        import cvxopt.cholmod

        return cvxopt.cholmod
    core = openblas_coretype()
    if core is not None:
        os.environ["OPENBLAS_CORETYPE"] = core
    try:
        import cvxopt.cholmod
    finally:
        if core is not None:
            os.environ.pop("OPENBLAS_CORETYPE", None)
    return cvxopt.cholmod


def cholmod_available() -> bool:
    """True when ``cvxopt.cholmod`` can be imported (by :func:`import_cholmod`)."""
    try:
        import_cholmod()
    except ImportError:
        return False
    return True


def _lower_keys(m: sparse.sparray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, columns and values of the lower triangle of ``m``, column-major sorted (CCS order)."""
    low = sparse.csc_array(sparse.tril(m, format="csc"))
    low.sum_duplicates()
    low.sort_indices()
    cols = np.repeat(np.arange(low.shape[1], dtype=np.int64), np.diff(low.indptr))
    return low.indices.astype(np.int64), cols, low.data


#: Boxes of at most this many vertices end the recursion of :func:`grid_nested_dissection` (ordered
#: in C order within). See :class:`PatternCholesky` for the measurements.
ND_LEAF = 64


def grid_nested_dissection(shape: tuple[int, ...], leaf: int = ND_LEAF) -> np.ndarray:
    """Geometric nested-dissection ordering of a vertex grid (C order, the last axis fastest).

    A box of vertices is cut by the mid-plane of its longest axis into two halves and the plane;
    the halves are ordered first (recursively), the plane last. Every non-zero of a Kuhn-grid
    ``H'H`` or first-order ``Gamma`` joins vertices that differ by at most 1 in every coordinate, so
    the plane separates the halves and the factor's fill stays within the boxes and their
    separators (fill ``O(N^(2 - 2/n))``-like in n-D against AMD's much larger fronts on a 3-D grid).

    Parameters
    ----------
    shape : tuple of int
        Vertices per axis.
    leaf : int
        Boxes of at most this many vertices are not cut.

    Returns
    -------
    ndarray of int, shape (prod(shape),)
        ``perm[k]`` = the vertex eliminated ``k``-th (a permutation of ``0 .. N - 1``).
    """
    shape = tuple(int(s) for s in shape)
    idx = np.arange(int(np.prod(shape)), dtype=np.int64).reshape(shape)
    out: list[np.ndarray] = []

    def rec(box: np.ndarray) -> None:
        if box.size <= max(int(leaf), 1) or max(box.shape) < 3:
            out.append(box.reshape(-1))
            return
        ax = int(np.argmax(box.shape))
        mid = box.shape[ax] // 2
        rec(np.take(box, np.arange(mid), axis=ax))
        rec(np.take(box, np.arange(mid + 1, box.shape[ax]), axis=ax))
        out.append(np.take(box, [mid], axis=ax).reshape(-1))

    rec(idx)
    return np.concatenate(out) if out else np.zeros(0, dtype=np.int64)


@dataclass(frozen=True)
class FactorCounts:
    """What CHOLMOD's symbolic analysis says of a factor ``L`` before any numeric work.

    Attributes
    ----------
    n : int
        Order of the matrix.
    lnz : int
        Non-zeros of ``L`` (the column counts' sum, diagonal included).
    flops : float
        Sum of the squared column counts: the multiply-adds of the numeric factorisation, up to
        a small factor.
    stored : int
        Values CHOLMOD allocates for ``L`` (supernodal: with the padding of its supernodes) plus the
        row indices and the largest update matrix of the numeric factorisation.
    """

    n: int
    lnz: int
    flops: float
    stored: int

    @property
    def bytes(self) -> float:
        """Bytes the numeric factorisation holds (8 per stored value or index)."""
        return 8.0 * self.stored


def _factor_struct():
    """``ctypes`` layout of CHOLMOD's public ``cholmod_factor`` struct (``cholmod_core.h``, CHOLMOD
    3 to 5), the fields up to its flags."""
    import ctypes

    class CholmodFactor(ctypes.Structure):
        _fields_ = ([(name, ctypes.c_size_t) for name in ("n", "minor")]
                    + [(name, ctypes.c_void_p) for name in ("Perm", "ColCount", "IPerm")]
                    + [("nzmax", ctypes.c_size_t)]
                    + [(name, ctypes.c_void_p) for name in ("p", "i", "x", "z", "nz", "next", "prev")]
                    + [(name, ctypes.c_size_t) for name in ("nsuper", "ssize", "xsize", "maxcsize", "maxesize")]
                    + [(name, ctypes.c_void_p) for name in ("super", "pi", "px", "s")]
                    + [(name, ctypes.c_int) for name in ("ordering", "is_ll", "is_super", "is_monotonic", "itype",
                                                          "xtype", "dtype", "useGPU")])

    return CholmodFactor


def factor_counts(factor, n: int, nnz_lower: int) -> FactorCounts | None:
    """The column counts of a symbolic CHOLMOD factor (a ``cvxopt.cholmod.symbolic`` result).

    cvxopt returns the factor as a capsule around CHOLMOD's ``cholmod_factor``, whose column counts
    (``ColCount``, set by the analysis) it does not expose; they are read from the struct here. The
    result is checked against what must hold (the order ``n``; counts between 1 and the rows below
    the diagonal; at least ``nnz_lower`` non-zeros, those of the lower triangle of the matrix) and
    ``None`` is returned where the struct does not look like one (another CHOLMOD layout).

    Parameters
    ----------
    factor : PyCapsule
        ``cvxopt.cholmod.symbolic(A)``.
    n : int
        Order of ``A``.
    nnz_lower : int
        Non-zeros of the lower triangle of ``A``, diagonal included.
    """
    import ctypes

    try:
        name_of = ctypes.pythonapi.PyCapsule_GetName
        name_of.restype, name_of.argtypes = ctypes.c_char_p, [ctypes.py_object]
        pointer_of = ctypes.pythonapi.PyCapsule_GetPointer
        pointer_of.restype, pointer_of.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
        name = name_of(factor)
        if not name or not name.startswith(b"CHOLMOD FACTOR"):
            return None
        f = _factor_struct().from_address(pointer_of(factor, name))
        if f.n != n or f.itype not in (0, 2) or not f.ColCount or n == 0:
            return None
        ctype = ctypes.c_int32 if f.itype == 0 else ctypes.c_int64
        counts = np.ctypeslib.as_array((ctype * n).from_address(f.ColCount)).astype(np.int64)
    except (TypeError, ValueError, AttributeError):  # pragma: no cover - not a capsule of this kind
        return None
    rows_left = n - np.arange(n, dtype=np.int64)  # column j of L has at most n - j entries
    lnz = int(counts.sum())
    if np.any(counts < 1) or np.any(counts > rows_left) or lnz < nnz_lower:
        return None
    stored = (f.xsize + f.ssize + f.maxcsize) if f.is_super else 2 * lnz
    return FactorCounts(n=n, lnz=lnz, flops=float(np.square(counts, dtype=float).sum()), stored=int(stored))


class PatternCholesky:
    """Cholesky factorisations ``A = L L'`` of SPD matrices within one fixed sparsity pattern.

    Parameters
    ----------
    pattern : sparse array, shape (N, N)
        A symmetric matrix whose non-zeros contain those of every matrix to be factorised
        (for the CV: ``M_k + Gamma`` of one fold, restricted to the unknowns). Only its structure
        is used.
    perm : ndarray of int, shape (N,), optional
        A fill-reducing elimination order to use instead of CHOLMOD's own (e.g.
        :func:`grid_nested_dissection`).
    supernodal : bool
        A supernodal factor (the default), or CHOLMOD's own choice between supernodal and
        simplicial (``False``), which takes the simplicial one for factors of little fill: measured
        for the data block of :class:`~pwas_hdl.fit.multigrid.DataBlockSmoother` at n = 2,
        N = 10^6, T = 10^5 (203 021 unknowns, nnz(L) 5.2e5): a solve 2.6-2.9 ms instead of 9.8 ms;
        at n = 3 (nnz(L) 1.5e7) CHOLMOD keeps the supernodal factor (numeric 0.5 s, simplicial 11 s).

    Notes
    -----
    The symbolic analysis (CHOLMOD's default ordering, AMD or the best of its methods, and the
    supernodal structure) is done once here. A geometric nested-dissection ordering of the Kuhn
    grid was measured too: 12.7 s instead of 48 s per first-order factorisation at n = 3,
    N = 262 144, no gain at n = 2 (1.2 s both), and no gain for zero order, where the solver
    uses the direct method; so the default ordering is kept there, and the 3-D factor chain of
    :data:`pwas_hdl.fit.regularized_lsq.FACTOR_DOMINANCE_CG` passes ``perm``. Measured again
    (fifth pass, fold 0, T = 10^5, one BLAS thread, CPU s, loaded machine): n = 3, p = 63, leaves
    of 64 / 256 vertices: symbolic 1.0-1.5 / 1.2 s, numeric 12.2-14.3 / 15.9 s, solve 0.20-0.26 /
    0.23 s, the factor ~1.8 GiB resident; n = 2, p = 999: symbolic (with building the pattern)
    2.1 / 1.9 s against AMD's 1.7-2.1 s, numeric 1.5-2.0 s all three: no gain.
    """

    def __init__(self, pattern: sparse.sparray, perm: np.ndarray | None = None, supernodal: bool = True):
        cholmod = import_cholmod()
        from cvxopt import matrix, spmatrix

        self._cholmod, self._matrix, self._spmatrix = cholmod, matrix, spmatrix
        self.n = int(pattern.shape[0])
        r, c, _ = _lower_keys(pattern)
        # keys of the lower-triangle entries in CCS order (by column, then row): monotone
        self._ccs = c * self.n + r
        self._a = spmatrix(np.ones(r.size), matrix(r.astype(np.int_)), matrix(c.astype(np.int_)), (self.n, self.n))
        cholmod.options["supernodal"] = 2 if supernodal else 1  # 1: CHOLMOD_AUTO (read by symbolic)
        if perm is None:
            self._factor = cholmod.symbolic(self._a)
        else:
            perm = np.asarray(perm, dtype=np.int_)
            if perm.shape != (self.n,) or not np.array_equal(np.sort(perm), np.arange(self.n)):
                raise InternalError("perm must be a permutation of 0 .. N - 1")  # our own ordering (grid_nested_dissection)
            self._factor = cholmod.symbolic(self._a, p=matrix(perm))
        self.factorizations = 0

    @property
    def nnz_lower(self) -> int:
        """Non-zeros of the pattern's lower triangle, diagonal included."""
        return int(self._ccs.size)

    def counts(self) -> FactorCounts | None:
        """The factor's size and cost from the symbolic analysis (:func:`factor_counts`; ``None``
        where CHOLMOD's struct cannot be read)."""
        return factor_counts(self._factor, self.n, self.nnz_lower)

    def align(self, m: sparse.sparray) -> np.ndarray:
        """Values of ``m`` (lower triangle) at the pattern's entries (zeros where ``m`` has none).

        Parameters
        ----------
        m : sparse array, shape (N, N)
            A symmetric matrix within the pattern (only its lower triangle is read).

        Returns
        -------
        ndarray of float64, shape (nnz_lower,)
            The values in the pattern's CCS order (:attr:`nnz_lower` entries), for :meth:`factorize`.

        Raises
        ------
        OutsidePattern
            ``m`` has a non-zero outside the pattern.
        """
        r, c, v = _lower_keys(m)
        key = c * self.n + r
        pos = np.searchsorted(self._ccs, key)
        if key.size and (pos.max(initial=0) >= self._ccs.size or np.any(self._ccs[np.minimum(pos, self._ccs.size - 1)] != key)):
            raise OutsidePattern("matrix has non-zeros outside the analysed pattern")
        out = np.zeros(self._ccs.size)
        out[pos] = v  # the keys are unique (duplicates summed in _lower_keys)
        return out

    def factorize(self, values: np.ndarray) -> None:
        """Numeric factorisation of the matrix with these values on the pattern (see :meth:`align`).

        Parameters
        ----------
        values : ndarray, shape (nnz_lower,)
            The matrix's lower-triangle values in the pattern's CCS order (:meth:`align`).

        Raises
        ------
        NotPositiveDefinite
        pwas_hdl.errors.ResourceLimit
            CHOLMOD could not allocate the factor (the callers check the analysed size against the
            memory limit first where the estimate had no measured bound; this is the last guard).
        """
        from pwas_hdl.errors import ResourceLimit

        self._a.V = self._matrix(np.ascontiguousarray(values, dtype=float))
        try:
            self._cholmod.numeric(self._a, self._factor)
        except ArithmeticError as exc:
            raise NotPositiveDefinite(f"CHOLMOD: matrix not positive definite (column {exc})") from None
        except MemoryError:
            raise ResourceLimit(
                f"the sparse Cholesky factor of {self.n} unknowns did not fit in memory (CHOLMOD could not allocate "
                f"it); use the iterative solver (method 'auto' or 'cg'), or fewer partitions or samples") from None
        self.factorizations += 1

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``A^{-1} b`` with the last factorisation.

        Parameters
        ----------
        b : ndarray, shape (N,) or (N, k)
            Right-hand side(s).

        Returns
        -------
        ndarray, shape as ``b``
            The solution (float64).
        """
        b = np.asarray(b, dtype=float)
        bm = self._matrix(np.array(b.reshape(self.n, -1), dtype=float, order="F"))
        self._cholmod.solve(self._factor, bm)
        return np.array(bm).reshape(b.shape)
