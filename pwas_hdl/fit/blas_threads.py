"""How many threads the BLAS libraries may use while the fit solves (threadpoolctl).

The fit's iterative solves (conjugate gradients, the multigrid-preconditioned CG) call BLAS only
for level-1 operations on long vectors (``x @ y``, norms): memory-bound work that a second thread
does not speed up. numpy's and scipy's OpenBLAS (0.3.30-0.3.31, AVX2 and AVX-512 kernels) split
such a dot product over their threads from 10 000 entries on, and each such call must wake a
thread. How long that takes is the machine's (its scheduler, a virtual machine's vCPUs). Measured
on this project's 2-core machine (2026-12-05), ``x @ y`` of 11 000 entries: 6.4 ms on two threads
against 11 us on one; of 100 000 entries: 367 us against 31 us (9 000 entries: 2.3 us both, not
threaded). The whole fit (n = 2, p = 315, T = 10^5, first order, 5-fold CV over 21 sigmas and the
final solve):

- serially: 18.4 s wall and 36.2 s CPU with the libraries' default of two threads, 13.8 s wall and
  CPU with one;
- on two forked workers (``fit --workers 2``, four BLAS threads on two cores): 23.4-27.1 s wall
  (46-54 s CPU) against 8.6 s (16.3 s CPU) with one thread each; the iterations were the same.

So the fit's solves run with :func:`single_blas_thread` (one thread for every BLAS library loaded,
restored afterwards), and a forked worker of :mod:`pwas_hdl.fit.fork_map` with its share of the
cores (:func:`worker_blas_threads`), as Dask's nanny does for its workers (``OPENBLAS_NUM_THREADS=1``).
CHOLMOD's OpenBLAS (the cvxopt wheel's) is single-threaded already.
"""

from __future__ import annotations

import contextlib
import os
from typing import Iterator

__all__ = ["single_blas_thread", "worker_blas_threads", "blas_thread_counts"]


def _controller():
    """A threadpoolctl controller of the libraries loaded now (a scan of the process: ~1 ms).

    The libraries the solves call are loaded first (scipy's OpenBLAS; cvxopt's, with the kernels
    :func:`~pwas_hdl.fit.sparse_cholesky.import_cholmod` chooses), so that the scan finds them.
    """
    import scipy.sparse.linalg  # noqa: F401  (scipy's own OpenBLAS)
    from threadpoolctl import ThreadpoolController

    from pwas_hdl.fit.sparse_cholesky import cholmod_available

    cholmod_available()
    return ThreadpoolController()


@contextlib.contextmanager
def single_blas_thread() -> Iterator[None]:
    """Every loaded BLAS library limited to one thread within the block (restored afterwards)."""
    with _controller().limit(limits=1, user_api="blas"):
        yield


def worker_blas_threads(processes: int) -> int:
    """Limit this (worker) process's BLAS libraries to at most its share of the cores.

    A library already limited to fewer threads (e.g. inherited from a parent inside
    :func:`single_blas_thread`) keeps its count.

    Parameters
    ----------
    processes : int
        How many worker processes share the machine (``>= 1``).

    Returns
    -------
    int
        The share: ``max(1, cpu_count // processes)``.
    """
    share = max(1, (os.cpu_count() or 1) // max(int(processes), 1))
    for lib in _controller().lib_controllers:
        if lib.user_api == "blas" and lib.num_threads > share:
            lib.set_num_threads(share)
    return share


def blas_thread_counts() -> dict[str, int]:
    """The thread count of each loaded BLAS library (file name -> threads), for tests and reports."""
    from threadpoolctl import threadpool_info

    return {os.path.basename(i["filepath"]): int(i["num_threads"]) for i in threadpool_info()
            if i.get("user_api") == "blas"}
