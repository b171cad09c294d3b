"""Independent tasks on a few forked worker processes that share the parent's data read-only.

The cross-validation of a large fit (issue 18) maps one function over a handful of fold tasks,
each needing the same large read-only arrays (``H``, ``H'H``, ``Gamma``, the solver). A Dask
local cluster pickles those to every worker and costs seconds to start (measured at n = 2,
N = 10^6, zero order: 139.9 s wall instead of 15.8 s serially); a *fork* gives each worker the
parent's memory copy-on-write, nothing is pickled but the task index and its (small) result.

Only where the operating system can fork (POSIX); :func:`fork_available` says so.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
import time
from typing import Any, Callable, Sequence

from pwas_hdl.errors import ResourceLimit

__all__ = ["fork_available", "fork_map"]

#: the function of the running :func:`fork_map` (set in the parent before the fork, so the
#: children inherit it; never pickled)
_TASK: Callable[[Any], Any] | None = None


def fork_available() -> bool:
    """True when worker processes can be started by ``fork``."""
    return "fork" in multiprocessing.get_all_start_methods()


def _init_worker(processes: int) -> None:
    from pwas_hdl.fit.blas_threads import worker_blas_threads

    worker_blas_threads(processes)


def _run(item: tuple[int, Any]) -> tuple[int, Any, float, int]:
    index, arg = item
    assert _TASK is not None
    c0 = time.process_time()
    result = _TASK(arg)
    return index, result, time.process_time() - c0, os.getpid()


def _kill_workers(pool: ProcessPoolExecutor) -> None:
    """SIGKILL the workers left in a broken pool.

    CPython's own clean-up of a broken pool terminates the other workers and joins them; once (a
    pytest-xdist run on the loaded 2-core machine, 2026-12-05) a surviving worker sat blocked on the
    result queue's lock and the join, and with it the parent, waited for ever. Killed, it cannot.
    The executor keeps its processes in a private attribute; without it nothing is done here.
    """
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        try:
            proc.kill()
        except (OSError, ValueError):  # pragma: no cover - already reaped or closed
            pass


def fork_map(fn: Callable[[Any], Any], items: Sequence[Any], processes: int,
             progress: Callable[[int, int], None] | None = None, stats: list | None = None,
             parent_work: Callable[[], Any] | None = None) -> list:
    """``[fn(x) for x in items]`` on ``processes`` forked workers, results in the order of ``items``.

    Parameters
    ----------
    fn : callable
        Called in the workers; it may be a closure over large arrays (inherited, not pickled).
        Its results must be picklable.
    items : sequence
        The tasks' arguments (picklable), handed out one at a time (dynamic balancing).
    processes : int
        Worker processes (``>= 1``; capped at ``len(items)``).
    progress : callable(done, total), optional
        Called in the parent as each task finishes.
    stats : list, optional
        Gets one ``(cpu_s, pid)`` per task, in the order of ``items``: the task's CPU seconds in
        its worker and the worker's process id (for the benchmarks' load accounting).
    parent_work : callable, optional
        Called once in the parent after the workers are started, while they run (the parent
        would otherwise only wait): work for after the map, e.g. the set-up of a final solve.

    Returns
    -------
    list
        The results, as the serial loop would return them. An exception in a task is raised here;
        a worker that dies raises :class:`~pwas_hdl.errors.ResourceLimit`.
    """
    global _TASK
    items = list(items)
    if not items:
        return []
    if _TASK is not None:
        raise RuntimeError("fork_map is not re-entrant")
    ctx = multiprocessing.get_context("fork")
    out: list = [None] * len(items)
    info: list = [None] * len(items)
    _TASK = fn
    # a worker that dies (killed, out of memory) raises BrokenProcessPool here instead of leaving
    # the parent waiting for ever (multiprocessing.Pool would)
    n_proc = max(1, min(int(processes), len(items)))
    # each worker's BLAS threads at most its share of the cores (pwas_hdl.fit.blas_threads)
    pool = ProcessPoolExecutor(max_workers=n_proc, mp_context=ctx, initializer=_init_worker, initargs=(n_proc,))
    broken = False
    try:
        futures = [pool.submit(_run, (i, x)) for i, x in enumerate(items)]
        if parent_work is not None:  # the fork context starts every worker at the first submit
            parent_work()
        for done, fut in enumerate(as_completed(futures), 1):
            index, result, cpu, pid = fut.result()
            out[index], info[index] = result, (cpu, pid)
            if progress is not None:
                progress(done, len(items))
    except BrokenProcessPool:
        broken = True
        raise ResourceLimit(f"a worker process of the {processes} forked ones died (killed, e.g. out of memory); "
                            "run with fewer --workers or on a machine with more memory") from None
    finally:
        _TASK = None
        if broken:
            _kill_workers(pool)
        # a task's exception: the tasks not started are cancelled, the running ones finish
        pool.shutdown(wait=not broken, cancel_futures=True)
    if stats is not None:
        stats.extend(info)
    return out
