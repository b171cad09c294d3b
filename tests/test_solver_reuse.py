"""The first-order CV at scale (issue 18, second pass): the data-dominated sigmas of a fold by PCG
preconditioned with the factor of a smaller sigma (within the stated weight bound, refactorising
by the documented rule), and the folds on forked worker processes (the serial result)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from pwas_hdl.fit import fork_map as fm
from pwas_hdl.fit import regularized_lsq as rl
from pwas_hdl.fit.regularized_lsq import NormalEquationSolver, cross_validate_sigma
from pwas_hdl.fit.sparse_cholesky import cholmod_available
from pwas_hdl.flow.executor import Executor

from helpers.factor_sweep import large_problem_rules, random_problem, sweep_against_direct

pytestmark = pytest.mark.skipif(not cholmod_available(), reason="needs CHOLMOD (cvxopt)")

SIGMAS = np.logspace(-7, 2, 10)


@pytest.fixture()
def large_rules(monkeypatch):
    """The size rules of a large problem on a tiny one (31 x 31 vertices)."""
    large_problem_rules(monkeypatch)


def _problem(t=600, seed=4):
    return random_problem(2, 30, t, seed)


def test_factor_pcg_within_the_stated_bound_of_the_direct_solve(large_rules):
    h, z, gam = _problem(t=300)
    hth = sparse.csr_array(h.T @ h)
    b = h.T @ z
    solver = NormalEquationSolver(hth, gam, 2, block_smoother=False)
    assert solver.factor_pcg and solver.method == "direct"
    small = [i for i in solver.sweep_order(hth, SIGMAS) if not solver.uses_mg(hth, SIGMAS[i])]
    assert small == sorted(small) and len(small) >= 3  # the data-dominated sigmas from the smallest up
    methods = sweep_against_direct(solver, hth, b, gam, SIGMAS, small, rl.FACTOR_PCG_MAXITER)
    assert methods[0] == "direct" and methods[1] == "factor-pcg"


def test_factor_pcg_refactorises_at_the_cap_and_stops_trying(large_rules, monkeypatch):
    h, z, gam = _problem(t=300)
    hth = sparse.csr_array(h.T @ h)
    monkeypatch.setattr(rl, "FACTOR_PCG_MAXITER", 1)  # no PCG solve converges in one iteration
    solver = NormalEquationSolver(hth, gam, 2, block_smoother=False)
    small = [i for i in solver.sweep_order(hth, SIGMAS) if not solver.uses_mg(hth, SIGMAS[i])]
    w = None
    for i in small:
        w, info = solver.solve(hth, h.T @ z, float(SIGMAS[i]), x0=w)
        assert info.method == "direct"
    assert solver.factor_pcg_failures == 1  # one failed attempt, then every sigma factorised


def test_cv_with_factor_pcg_matches_the_direct_cv(large_rules):
    h, z, gam = _problem()
    ca = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, block_smoother=False)
    cd = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, method="direct", block_smoother=False)
    by = ca.solver["solves_by_method"]
    assert by.get("factor-pcg", 0) > 0 and by.get("direct", 0) > 0 and by.get("mg", 0) > 0
    assert sum(by.values()) == 3 * SIGMAS.size and ca.solver["all_converged"]
    assert ca.best_sigma == cd.best_sigma
    np.testing.assert_allclose(ca.fold_mse, cd.fold_mse, rtol=1e-6)


def test_forked_folds_give_the_serial_result(large_rules):
    h, z, gam = _problem()
    serial = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, block_smoother=False)
    with Executor(workers=2) as ex:
        forked = cross_validate_sigma(h, z, gam, SIGMAS, folds=3, executor=ex, block_smoother=False)
        assert ex._client is None  # the Dask cluster was not started
    assert forked.best_sigma == serial.best_sigma
    np.testing.assert_allclose(forked.fold_mse, serial.fold_mse, rtol=0, atol=1e-12)
    np.testing.assert_allclose(forked.mse, serial.mse, rtol=0, atol=1e-12)
    assert forked.solver["solves_by_method"] == serial.solver["solves_by_method"]
    assert forked.solver["iterations"] == serial.solver["iterations"]
    tasks = forked.solver["fork_tasks"]
    # one task per segment of every fold's sweep: its multigrid chain, its factor-PCG chain, and
    # every larger data-dominated sigma alone
    hth = sparse.csr_array(h.T @ h)
    solver = NormalEquationSolver(hth, gam, 2, block_smoother=False)
    labels = rl.fold_labels(h.shape[0], 3)
    segs = []
    for f in range(3):
        hv = h[np.flatnonzero(labels == f)]
        segs.append(solver.sweep_segments((hth - sparse.csr_array(hv.T @ hv)).tocsr(), SIGMAS))
    assert all(len(s) >= 3 for s in segs)
    assert len(tasks) == sum(len(s) for s in segs) and len({t["pid"] for t in tasks}) <= 2  # two workers
    assert serial.solver["fork_tasks"] == []


def test_fork_rule_by_size_and_executor(monkeypatch):
    local = Executor(workers=2)
    assert rl.fork_workers(local, rl.FORK_MIN_UNKNOWNS) == (2 if fm.fork_available() else 0)
    assert rl.fork_workers(local, rl.FORK_MIN_UNKNOWNS - 1) == 0
    assert rl.fork_workers(Executor(), 10**6) == 0
    assert rl.fork_workers(None, 10**6) == 0


def test_fork_map_order_and_errors():
    assert fm.fork_map(lambda x: x * x, range(7), 2) == [x * x for x in range(7)]

    def boom(x):
        if x == 3:
            raise ValueError("task 3")
        return x

    with pytest.raises(ValueError, match="task 3"):
        fm.fork_map(boom, range(5), 2)
    assert fm._TASK is None


def test_forked_segments_one_factor_at_a_time_run_in_one_task_under_the_lock():
    """_fork_segments with ``heavy``: every factorising segment of every fold in one task that holds
    the lock (and calls ``after_group`` before it lets go), the others a task each; results in
    (fold, segment) order as without the grouping."""
    import multiprocessing
    import os

    if not fm.fork_available():
        pytest.skip("needs fork")
    ctx = multiprocessing.get_context("fork")
    lock, freed = ctx.Lock(), ctx.Value("i", 0)
    segments = [[[0, 1], [2]], [[0], [1, 2]], [[2], [0, 1]]]  # 3 folds; segment 1 of each is heavy

    def run(f, seg):
        held = not lock.acquire(block=False)
        if not held:
            lock.release()
        return f, tuple(seg), held, os.getpid()

    def after():
        with freed.get_lock():
            freed.value += 1

    stats: list = []
    out = rl._fork_segments(run, segments, lambda f, i: 1.0, 2, 3, None, stats, heavy=lambda f, k: k == 1,
                            factor_lock=lock, after_group=after)
    assert [[(r[0], r[1]) for r in fold] for fold in out] == [[(f, tuple(s)) for s in segs] for f, segs in enumerate(segments)]
    # the heavy ones under the lock (a light one may run while the other worker holds it)
    assert [fold[1][2] for fold in out] == [True] * 3
    assert len({fold[1][3] for fold in out}) == 1  # one task: one process ran every heavy segment
    assert freed.value == 1 and len(stats) == 1 + 3
    plain = rl._fork_segments(run, segments, lambda f, i: 1.0, 2, 3, None, None)
    assert [[(r[0], r[1]) for r in fold] for fold in plain] == [[(r[0], r[1]) for r in fold] for fold in out]


def test_fold_tasks_keep_whole_folds_where_their_set_up_costs_more_than_the_balance():
    """_fold_tasks: every segment in exactly one task; without a set-up cost one task per segment;
    with the multigrid set-up of five equal folds on two workers some folds run whole (set up once),
    with an estimated finish no later than one task per segment."""
    segments = [[list(range(10)), list(range(10, 21))] for _ in range(5)]
    cost = lambda f, i: 0.4 if i < 10 else 0.8  # noqa: E731 - Gauss-Seidel and data-block sigmas
    plain = rl._fold_tasks(segments, cost, 2, lambda f, k: 0.0)
    assert plain == [((f, k),) for f in range(5) for k in range(2)]
    tasks = rl._fold_tasks(segments, cost, 2, lambda f, k: rl._MG_SETUP_COST)
    assert sorted(pair for t in tasks for pair in t) == [(f, k) for f in range(5) for k in range(2)]
    whole = [t for t in tasks if len(t) == 2]
    assert whole and all(t[0][0] == t[1][0] for t in whole)

    def span(ts):
        return rl._makespan([sum(cost(f, i) for f, k in t for i in segments[f][k]) + rl._MG_SETUP_COST for t in ts], 2)

    assert span(tasks) <= span(plain)
    # many workers: splitting every fold balances best
    assert rl._fold_tasks(segments, cost, 8, lambda f, k: rl._MG_SETUP_COST) == plain


def test_forked_whole_folds_run_their_segments_in_one_process_in_order():
    import os

    if not fm.fork_available():
        pytest.skip("needs fork")
    segments = [[[0, 1], [2, 3, 4]] for _ in range(5)]

    def run(f, seg):
        return f, tuple(seg), os.getpid()

    out = rl._fork_segments(run, segments, lambda f, i: 1.0, 2, 5, None, None, setup_of=lambda f, k: 3.0)
    assert [[(r[0], r[1]) for r in fold] for fold in out] == [[(f, tuple(s)) for s in segs] for f, segs in enumerate(segments)]
    assert any(fold[0][2] == fold[1][2] for fold in out)  # some fold ran whole in one worker


def test_fork_map_worker_that_dies_is_an_error_not_a_hang():
    """A killed worker (e.g. by the out-of-memory killer) left multiprocessing.Pool waiting for ever."""
    import os

    from pwas_hdl.errors import ResourceLimit

    def die(x):
        if x == 2:
            os._exit(9)
        return x

    with pytest.raises(ResourceLimit, match="fewer --workers"):
        fm.fork_map(die, range(4), 2)
    assert fm._TASK is None


def test_fork_map_worker_that_ignores_sigterm_does_not_hang_the_parent():
    """A worker that survives the broken pool's SIGTERM (here: it ignores it and blocks, as a worker
    blocked on a queue lock the dead one held was seen to) is killed, so the parent gets its error.
    Run in a child process: without the kill the parent would wait for ever (the timeout is only a
    guard against that hang, generous on any machine)."""
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent("""
        import os, signal, threading
        from pwas_hdl.fit import fork_map as fm
        from pwas_hdl.errors import ResourceLimit

        def task(x):
            if x == 0:
                signal.signal(signal.SIGTERM, signal.SIG_IGN)
                threading.Event().wait()
            os._exit(9)

        try:
            fm.fork_map(task, range(2), 2)
        except ResourceLimit as exc:
            print("refused:", exc)
    """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "refused: a worker process of the 2 forked ones died" in done.stdout


def test_memory_estimate_counts_each_forked_worker():
    one = rl.estimate_fit_memory(10**5, 10**6, 2, 1, 1, block_smoother=False)
    two = rl.estimate_fit_memory(10**5, 10**6, 2, 1, 1, processes=2, block_smoother=False)
    assert one["workers"] == 0 and one["fold_matrices"] == 0
    # each worker: its fold's matrices, its own numeric factor (the first-order CHOLMOD analysis is
    # the parent's, shared: worker_factor is the factor without it), multigrid levels, vectors and
    # the transient of forming the shifted matrix
    assert two["worker_factor"] == one["worker_factor"] < one["factor"]
    shared = rl.GRID_FACTOR_BOUND[2][3] * 10**6 if rl.cholmod_available() else 0.0
    assert one["factor"] - one["worker_factor"] == pytest.approx(shared)
    per = (one["HtH"] * 2 / 3 + one["worker_factor"] + one["multigrid"] + one["vectors"] + one["shift"]
           + rl.FORK_WORKER_OVERHEAD)
    # and the parent holds the other four folds' normal matrices (H'H's pattern each), inherited
    fold = rl._sparse_bytes(min(10.0**12, 10**5 * 9.0), 10**6)
    assert two["fold_matrices"] == pytest.approx(4 * fold)
    assert two["total"] == pytest.approx(one["total"] + per + 4 * fold)


def test_sweep_segments_cover_every_sigma_once_by_the_rule(large_rules):
    """A fold's sweep in independent segments: its multigrid sigmas from the largest down, then its
    FACTOR_PCG_SEGMENT smallest data-dominated sigmas from the smallest up (the factor-PCG chain),
    then every other data-dominated sigma alone; a segment starts without the previous one's factor."""
    h, z, gam = _problem()
    hth = sparse.csr_array(h.T @ h)
    sig = np.logspace(-7, 2, 19)
    solver = NormalEquationSolver(hth, gam, 2, block_smoother=False)
    segs = solver.sweep_segments(hth, sig)
    mg_idx = [i for i in range(sig.size) if solver.uses_mg(hth, float(sig[i]))]
    small = [i for i in range(sig.size) if i not in mg_idx]
    assert len(small) > rl.FACTOR_PCG_SEGMENT + 1 and mg_idx  # the rule has all three kinds here
    assert segs[0] == sorted(mg_idx, key=lambda i: -sig[i])
    assert segs[1] == sorted(small, key=lambda i: sig[i])[: rl.FACTOR_PCG_SEGMENT]
    assert segs[2:] == [[i] for i in sorted(small, key=lambda i: sig[i])[rl.FACTOR_PCG_SEGMENT:]]
    # the chain's second sigma reuses the factor; a segment started after it neither reuses
    # nor tries to (no factor-PCG attempt, no failure counted)
    b = h.T @ z
    solver.start_segment()
    w, i0 = solver.solve(hth, b, float(sig[segs[1][0]]))
    _, i1 = solver.solve(hth, b, float(sig[segs[1][1]]), x0=w)
    assert (i0.method, i1.method) == ("direct", "factor-pcg")
    w, _ = solver.solve(hth, b, float(sig[segs[1][0]]))  # a fresh factor, reuse not stopped
    solver.start_segment()
    _, i2 = solver.solve(hth, b, float(sig[segs[2][0]]), x0=w)
    assert i2.method == "direct" and solver.factor_pcg_failures == 0
