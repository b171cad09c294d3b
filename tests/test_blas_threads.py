"""BLAS threads while the fit solves (issue 18): one thread in the solves (their BLAS work is
level-1 on long vectors, which a second thread only slows), at most a worker's share of the cores
in a forked worker. Measured at n = 2, p = 315, first order, two forked workers with two BLAS
threads each: 24-27 s wall instead of 8.6 s (``pwas_hdl.fit.blas_threads``)."""

from __future__ import annotations

import os

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from pwas_hdl.fit.blas_threads import blas_thread_counts, single_blas_thread, worker_blas_threads
from pwas_hdl.fit.fork_map import fork_available, fork_map
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.regularized_lsq import cross_validate_sigma, solve_regularized, tikhonov_matrix


@pytest.fixture
def two_threads():
    """Every BLAS library at two threads (skip where none takes two: nothing to limit)."""
    with single_blas_thread():  # loads the solvers' libraries (cvxopt's too) before the limit
        pass
    with threadpool_limits(limits=2, user_api="blas"):
        counts = blas_thread_counts()
        if max(counts.values(), default=1) < 2:
            pytest.skip(f"no BLAS library runs two threads here: {counts}")
        yield counts


def _problem():
    rng = np.random.default_rng(0)
    x = rng.uniform(-1, 1, (400, 2))
    z = np.sin(3 * x).sum(axis=1)
    grid = Grid(np.full(2, -1.2), np.full(2, 1.2), 7)
    return grid.basis_matrix(x), z, tikhonov_matrix(grid, 1)


def test_single_blas_thread_limits_and_restores(two_threads):
    with single_blas_thread():
        assert set(blas_thread_counts().values()) == {1}
    assert blas_thread_counts() == two_threads


def test_the_cv_and_the_solve_run_on_one_blas_thread(two_threads):
    h, z, gam = _problem()
    seen = []
    cross_validate_sigma(h, z, gam, sigmas=[1e-3, 1e-1], folds=2,
                         progress=lambda d, t: seen.append(blas_thread_counts()))
    assert seen and all(set(c.values()) == {1} for c in seen)
    w = solve_regularized(h, z, 1e-2, gam)
    assert np.all(np.isfinite(w))
    assert blas_thread_counts() == two_threads  # restored after either (the solve's own count is not observable)


@pytest.mark.skipif(not fork_available(), reason="needs fork")
def test_forked_workers_take_their_share_of_the_cores(two_threads):
    share = max(1, (os.cpu_count() or 1) // 2)
    counts = fork_map(lambda _: blas_thread_counts(), [0, 1, 2], processes=2)
    for c in counts:
        assert max(c.values()) <= share, (c, share)
    # a library limited below the share keeps its count
    with single_blas_thread():
        assert worker_blas_threads(1) == max(1, os.cpu_count() or 1)
        assert set(blas_thread_counts().values()) == {1}
