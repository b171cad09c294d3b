"""The in-place PCG loop (issue 18): scipy's iteration, without temporaries."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse
from scipy.sparse import linalg as splinalg

from pwas_hdl.fit.conjugate_gradients import pcg


def _spd(n=400, seed=0):
    rng = np.random.default_rng(seed)
    m = sparse.random(n, n, density=0.02, random_state=seed)
    a = (m @ m.T + sparse.diags(rng.uniform(0.1, 10.0, n))).tocsr()
    return a, rng.standard_normal(n)


@pytest.mark.parametrize("precond", ["none", "jacobi", "operator"])
@pytest.mark.parametrize("warm", [False, True])
def test_pcg_takes_scipys_iterations(precond, warm):
    a, b = _spd()
    d = a.diagonal()
    op = splinalg.LinearOperator(a.shape, matvec=lambda r: r / d, dtype=float)
    m = {"none": None, "jacobi": lambda r: r / d, "operator": op}[precond]
    x0 = np.full(b.size, 0.1) if warm else None
    keep = None if x0 is None else x0.copy()
    count = [0]
    xs, flag = splinalg.cg(a, b, x0=x0, rtol=1e-10, atol=0.0, maxiter=500,
                           M=None if m is None else op,
                           callback=lambda _x: count.__setitem__(0, count[0] + 1))
    x, its, done = pcg(a, b, m, x0, 1e-10, 500)
    assert flag == 0 and done
    assert its == count[0]
    # the same iterates up to rounding (BLAS daxpy against numpy's temporaries)
    assert np.linalg.norm(x - xs) <= 1e-9 * np.linalg.norm(xs)
    assert np.linalg.norm(b - a @ x) <= 1e-9 * np.linalg.norm(b)
    if keep is not None:
        np.testing.assert_array_equal(x0, keep)  # the initial guess is not modified


def test_pcg_stops_at_maxiter_and_says_so():
    a, b = _spd()
    x, its, done = pcg(a, b, None, None, 1e-14, 3)
    assert its == 3 and not done
    assert np.linalg.norm(b - a @ x) < np.linalg.norm(b)


def test_pcg_of_a_zero_right_hand_side_is_zero():
    a, b = _spd()
    x, its, done = pcg(a, np.zeros_like(b), None, np.ones_like(b), 1e-10, 10)
    assert its == 0 and done and not x.any()


def test_pcg_with_a_preconditioner_returning_its_argument():
    """z may be r itself (an identity preconditioner): p must not alias r."""
    a, b = _spd()
    x, its, done = pcg(a, b, lambda r: r, None, 1e-10, 500)
    xr, its_r, _ = pcg(a, b, None, None, 1e-10, 500)
    assert done and its == its_r
    np.testing.assert_allclose(x, xr, rtol=1e-12)


def test_pcg_breakdown_is_not_converged_and_not_an_exception():
    """A preconditioner that returns zero for a non-zero residual (e.g. underflow): r'z = 0."""
    a, b = _spd()
    x, its, done = pcg(a, b, lambda r: np.zeros_like(r), None, 1e-10, 50)
    assert not done and its == 0 and not x.any()


@pytest.mark.parametrize("fresh", [False, True])
def test_pcg_direction_update_into_a_fresh_preconditioner_result(fresh):
    """``fresh_result``: p = z + beta p is written into the preconditioner's new array; the
    iterates are those of the two-pass update up to rounding."""
    a, b = _spd()
    d = a.diagonal()
    calls, copies = [], []

    def jacobi(r):
        z = r / d  # a new array on every call
        calls.append(z)
        copies.append(z.copy())
        return z

    x, its, done = pcg(a, b, jacobi, None, 1e-10, 500, fresh_result=fresh)
    xr, its_r, done_r = pcg(a, b, lambda r: r / d, None, 1e-10, 500)
    assert done and done_r and its == its_r == len(calls)
    # the same iterates up to rounding (daxpy may fuse the multiply-add), as against scipy above
    assert np.linalg.norm(x - xr) <= 1e-9 * np.linalg.norm(xr)
    assert np.linalg.norm(b - a @ x) <= 1e-9 * np.linalg.norm(b)
    # fresh: every array after the first (which p copies) now holds a direction; else untouched
    changed = [not np.array_equal(z, z0) for z, z0 in zip(calls, copies)]
    assert changed == ([False] + [True] * (its - 1) if fresh else [False] * its)


def test_pcg_fresh_result_without_a_preconditioner_leaves_r_alone():
    """Without a preconditioner z is r itself: ``fresh_result`` must not write the direction into it."""
    a, b = _spd()
    x, its, done = pcg(a, b, None, None, 1e-10, 500, fresh_result=True)
    xr, its_r, _ = pcg(a, b, None, None, 1e-10, 500)
    assert done and its == its_r
    np.testing.assert_allclose(x, xr, rtol=1e-12)
