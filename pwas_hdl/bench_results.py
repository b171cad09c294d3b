"""The one results format of every benchmark (``pwas-hdl-bench-results``, version 1).

This module owns the format; its JSON Schema ships as
``pwas_hdl/schemas/bench-results-v1.schema.json``. A result file is::

    {"format": "pwas-hdl-bench-results", "version": 1, "bench": "three-tank",
     "rows": [{"system": "three-tank", "target": "x1", "estimator": "pwas", "stage": "float",
               "metric": "rmse", "value": 0.106, "std": 0.004, "runs": 5, "paper": null,
               "config": {"window": "t>=100", "noise_y": 0.0}}, ...],
     "assumptions": {"seed_001.A1": "signed square root ...", ...},
     "config": {...bench-wide settings...},
     "environment": {"python": "3.11.2", "platform": "...", "packages": {"numpy": "2.1.0", ...}}}

Each row is one number: the mean over ``runs`` runs of ``metric`` of ``estimator`` on ``target``
of ``system`` at ``stage`` (``float`` model, ``bittrue`` fixed-point model, ``rtl`` simulation),
its sample standard deviation (``ddof = 1``; ``null`` for one run) and the paper's printed figure
for the same quantity (or ``null``). ``config`` holds whatever distinguishes the row.

Use :func:`row` (or :func:`row_from_values`) to build rows, :func:`make_results` to wrap them,
:func:`write_results` / :func:`load_results` for files (both validate against the schema) and
:func:`markdown_table` for the human-readable table.
"""

from __future__ import annotations

import json
import math
import os
import platform
import re
import sys
from contextlib import contextmanager
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.io.atomic import atomic_write_text
from pwas_hdl.resources import schemas_dir

__all__ = [
    "script_main",
    "scratch_folder",
    "RESULTS_FORMAT",
    "RESULTS_VERSION",
    "STAGES",
    "METRICS",
    "row",
    "row_from_values",
    "make_results",
    "environment",
    "validate_results",
    "write_results",
    "results_text",
    "load_results",
    "find_rows",
    "markdown_table",
    "schema",
    "map_runs",
    "extend_lists",
    "execution_record",
    "default_outdir",
    "portable_paths",
    "MACHINE_PATH_PREFIXES",
    "check_count",
]

RESULTS_FORMAT = "pwas-hdl-bench-results"
RESULTS_VERSION = 1
STAGES = ("float", "bittrue", "rtl")
METRICS = ("rmse", "mse", "fit", "nrmse", "accuracy", "f1")
_PACKAGES = ("numpy", "scipy", "scikit-learn", "amaranth", "cocotb", "pwas-hdl")


@lru_cache(maxsize=1)
def schema() -> dict:
    """The JSON Schema of the format (``bench-results-v1.schema.json``)."""
    return json.loads((schemas_dir() / "bench-results-v1.schema.json").read_text())


def _num(v: Any) -> float | None:
    if v is None:
        return None
    f = float(v)
    if not math.isfinite(f):
        return None
    return f


def _jsonable(obj: Any) -> Any:
    """Numpy scalars/arrays and tuples -> plain JSON types (non-finite floats -> None)."""
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [_jsonable(v) for v in obj.tolist()]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if math.isfinite(f) else None
    return obj


def row(
    system: str,
    target: str,
    estimator: str,
    stage: str,
    metric: str,
    value: float | None,
    std: float | None = None,
    runs: int = 1,
    paper: float | None = None,
    config: Mapping[str, Any] | None = None,
) -> dict:
    """One result row (checked: ``stage`` in :data:`STAGES`, ``metric`` in :data:`METRICS`).

    Non-finite ``value``/``std`` become ``None`` (an estimator that diverged: say why in
    ``config["note"]``).

    Parameters
    ----------
    system : str
        The plant (``three-tank``, ``switched-linear``, ...).
    target : str
        The estimated quantity (``x1``, ``soc``, ...).
    estimator : str
        What estimated it (``pwas``, ``paper``, ``hlnn``, ...).
    stage : {"float", "bittrue", "rtl"}
        Float model, bit-true fixed-point model or RTL simulation.
    metric : {"rmse", "mse", "fit", "nrmse", "accuracy", "f1"}
        The metric; ``value``, ``std`` and ``paper`` are in its units (the target's for ``rmse``,
        squared for ``mse``, dimensionless for the others).
    value : float or None
        Mean over the runs (the value itself for one run).
    std : float or None
        Sample standard deviation over the runs (``ddof = 1``); None for one run.
    runs : int
        Number of runs (>= 1).
    paper : float or None
        The paper's printed figure for the same quantity, if any.
    config : mapping, optional
        Whatever distinguishes the row (made JSON-ready: numpy scalars and arrays to plain types).

    Returns
    -------
    dict
        The row: the ten keys above, ``value``/``std``/``paper`` as float or None.

    Raises
    ------
    InputError
        An unknown ``stage`` or ``metric``, or ``runs < 1``.
    """
    if stage not in STAGES:
        raise InputError(f"stage must be one of {', '.join(STAGES)}, got {stage!r}")
    if metric not in METRICS:
        raise InputError(f"metric must be one of {', '.join(METRICS)}, got {metric!r}")
    if int(runs) < 1:
        raise InputError(f"runs must be >= 1, got {runs}")
    return {
        "system": str(system),
        "target": str(target),
        "estimator": str(estimator),
        "stage": stage,
        "metric": metric,
        "value": _num(value),
        "std": _num(std),
        "runs": int(runs),
        "paper": _num(paper),
        "config": _jsonable(dict(config or {})),
    }


def row_from_values(
    system: str,
    target: str,
    estimator: str,
    stage: str,
    metric: str,
    values: Sequence[float],
    paper: float | None = None,
    config: Mapping[str, Any] | None = None,
) -> dict:
    """A row from the per-run values: mean, sample std (``ddof = 1``, ``None`` for one run).

    Parameters
    ----------
    system, target, estimator, stage, metric : str
        As in :func:`row`.
    values : sequence of float, length = number of runs
        One value per run. If any is not finite the row's value is ``None`` and
        ``config["n_nonfinite"]`` counts them.
    paper : float or None
        The paper's printed figure, as in :func:`row`.
    config : mapping, optional
        As in :func:`row` (copied, not changed).

    Returns
    -------
    dict
        The row of :func:`row` with ``runs = len(values)``.
    """
    v = np.asarray(list(values), dtype=float).reshape(-1)
    if v.size == 0:
        raise InputError("row_from_values needs at least one value")
    cfg = dict(config or {})
    bad = int((~np.isfinite(v)).sum())
    if bad:
        cfg["n_nonfinite"] = bad
        mean, std = None, None
    else:
        mean = float(v.mean())
        std = float(v.std(ddof=1)) if v.size > 1 else None
    return row(system, target, estimator, stage, metric, mean, std, int(v.size), paper, cfg)


def environment(elapsed_s: float | None = None) -> dict:
    """Python, platform and the versions of the packages that produce the numbers.

    Parameters
    ----------
    elapsed_s : float, optional
        Wall-clock time of the run in seconds, recorded rounded to 0.01 s (None: not recorded).

    Returns
    -------
    dict
        ``{"python": version, "platform": text, "packages": {name: version}}`` (installed packages
        only), plus ``"elapsed_s"`` when given.
    """
    pk: dict[str, str] = {}
    for name in _PACKAGES:
        try:
            pk[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    env: dict[str, Any] = {"python": platform.python_version(), "platform": platform.platform(), "packages": pk}
    if elapsed_s is not None:
        env["elapsed_s"] = round(float(elapsed_s), 2)
    return env


def map_runs(fn: Any, items: Iterable[Any], executor: Any = None, *, labels: Sequence[str] | None = None) -> list:
    """The independent runs of a bench, through the one execution layer (:mod:`pwas_hdl.flow.executor`).

    Parameters
    ----------
    fn : callable
        One run: a pure function of its item (seeds inside the item) returning JSON-ready or
        picklable results. A function nested in the bench's ``run`` is fine: Dask ships it with
        cloudpickle, the bench module itself is imported on the worker.
    items : iterable
        The runs' inputs, in the order the serial bench loops over them.
    executor : pwas_hdl.flow.executor.Executor, optional
        ``None``: serially in this process (the same results, in the same order).
    labels : sequence of str, optional
        A label per run for the error of a run that failed twice.

    Returns
    -------
    list
        ``[fn(item) for item in items]`` in input order, whatever ran them.
    """
    from pwas_hdl.flow.executor import Executor

    return (executor if executor is not None else Executor()).map(fn, list(items), labels=labels)


def extend_lists(into: dict, part: Mapping[Any, Sequence[Any]]) -> dict:
    """Append the per-run value lists of ``part`` to those of ``into`` (key by key; ``into`` returned).

    Merging the parts of :func:`map_runs` in input order gives the lists of the serial loop.

    Parameters
    ----------
    into : dict
        Key -> list of per-run values; extended in place (a missing key gets a new list).
    part : mapping of key to sequence
        One part's per-run values.

    Returns
    -------
    dict
        ``into``.
    """
    for k, v in part.items():
        into.setdefault(k, []).extend(v)
    return into


def execution_record(executor: Any = None) -> dict:
    """What ran a bench's tasks, for the results' ``config["execution"]``.

    ``{"kind": "serial" | "local-cluster" | "scheduler", "workers": N, "scheduler": address or None,
    "tool_versions": {...}}``; the tool versions come from every worker and are checked to be equal
    (:meth:`pwas_hdl.flow.executor.Executor.tool_versions` raises when they differ).

    Parameters
    ----------
    executor : pwas_hdl.flow.executor.Executor, optional
        What ran the tasks; ``None``: the serial executor.

    Returns
    -------
    dict
        The executor's description with its ``"tool_versions"``.
    """
    from pwas_hdl.flow.executor import Executor

    ex = executor if executor is not None else Executor()
    return ex.describe() | {"tool_versions": ex.tool_versions()}


def make_results(
    bench: str,
    rows: Iterable[dict],
    assumptions: Mapping[str, str],
    config: Mapping[str, Any] | None = None,
    description: str | None = None,
    quick: bool = False,
    elapsed_s: float | None = None,
) -> dict:
    """The result document (validated against the schema).

    Parameters
    ----------
    bench : str
        Bench name (``three-tank``, ``switched-linear``, ``lorenz-hlnn``, ...).
    rows : iterable of dict
        Rows from :func:`row` / :func:`row_from_values`.
    assumptions : mapping id -> text
        The spec assumptions applied (ids like ``seed_001.A1``).
    config : mapping, optional
        Bench-wide settings.
    description : str, optional
        One line on what the bench measures (omitted from the document when empty).
    quick : bool
        A reduced smoke run (``--quick``), not a result to quote.
    elapsed_s : float, optional
        Wall-clock time of the run in seconds, for :func:`environment`.

    Returns
    -------
    dict
        The document: ``format``, ``version``, ``bench``, ``description``, ``quick``, ``rows``,
        ``assumptions``, ``config``, ``environment``.

    Raises
    ------
    InputError
        The document violates the schema.
    """
    doc: dict[str, Any] = {
        "format": RESULTS_FORMAT,
        "version": RESULTS_VERSION,
        "bench": str(bench),
    }
    if description:
        doc["description"] = description
    doc["quick"] = bool(quick)
    doc["rows"] = [dict(r) for r in rows]
    doc["assumptions"] = {str(k): str(v) for k, v in assumptions.items()}
    doc["config"] = _jsonable(dict(config or {}))
    doc["environment"] = environment(elapsed_s)
    validate_results(doc)
    return doc


def validate_results(doc: Any) -> None:
    """Raise :class:`~pwas_hdl.errors.InputError` naming the first violation of the schema.

    Parameters
    ----------
    doc : Any
        A parsed result document (anything: a non-dict is a violation too).

    Raises
    ------
    InputError
        With the JSON path (``rows/3/metric``) and the message of the first violation.
    """
    import jsonschema

    validator = jsonschema.Draft202012Validator(schema())
    errors = sorted(validator.iter_errors(doc), key=lambda e: list(e.absolute_path))
    if errors:
        e = errors[0]
        where = "/".join(str(p) for p in e.absolute_path) or "(top level)"
        raise InputError(f"not a valid {RESULTS_FORMAT} v{RESULTS_VERSION} document at {where}: {e.message}")


def results_text(doc: dict) -> str:
    """Validate ``doc`` and return the text of its file (indented JSON, no NaN).

    Parameters
    ----------
    doc : dict
        A result document (:func:`make_results`).

    Returns
    -------
    str
        The JSON text, one-space indent, ending in a newline.
    """
    validate_results(doc)
    return json.dumps(doc, indent=1, allow_nan=False) + "\n"


def write_results(path: str | Path, doc: dict) -> Path:
    """Validate and write ``doc`` atomically (indented JSON, no NaN).

    Parameters
    ----------
    path : str or Path
        The result file.
    doc : dict
        A result document (:func:`make_results`).

    Returns
    -------
    Path
        The file written.
    """
    return atomic_write_text(path, results_text(doc))


def check_stem(stem: str) -> str:
    """A ``--stem`` option: a plain file name (no folder, not empty), checked before a benchmark runs.

    Raises
    ------
    pwas_hdl.errors.InputError
    """
    from pwas_hdl.errors import InputError

    if not stem or stem in (".", "..") or "/" in stem or "\\" in stem or "\0" in stem:
        raise InputError(f"--stem must be a plain file name without a folder, e.g. my_run; got {stem!r}")
    return stem


def write_json_and_markdown(outdir: str | Path, stem: str, doc: dict, md: str) -> None:
    """Write a benchmark's own (not results-format) ``STEM.json`` (indented, no NaN) and ``STEM.md``
    atomically into ``outdir`` and print the Markdown."""
    out = Path(outdir)
    atomic_write_text(out / f"{stem}.json", json.dumps(doc, indent=1, allow_nan=False) + "\n")
    atomic_write_text(out / f"{stem}.md", md)
    print(md)


def load_results(path: str | Path) -> dict:
    """Read and validate a result file.

    Parameters
    ----------
    path : str or Path
        A ``pwas-hdl-bench-results`` JSON file.

    Returns
    -------
    dict
        The document.

    Raises
    ------
    InputError
        The file is not JSON or not a valid document.
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"{p}: not JSON ({exc}); expected a {RESULTS_FORMAT} file") from None
    validate_results(doc)
    return doc


def find_rows(doc: Mapping[str, Any], **match: Any) -> list[dict]:
    """Rows whose fields equal every ``match`` item (``config`` keys via ``config={"k": v}``).

    Parameters
    ----------
    doc : mapping
        A result document.
    **match
        Row field -> required value (``system="three-tank", metric="rmse"``); ``config`` a mapping of
        config key -> required value.

    Returns
    -------
    list of dict
        The matching rows, in document order.
    """
    cfg = match.pop("config", {}) or {}
    res = []
    for r in doc["rows"]:
        if all(r.get(k) == v for k, v in match.items()) and all(r["config"].get(k) == v for k, v in cfg.items()):
            res.append(r)
    return res


def _fmt(v: float | None) -> str:
    if v is None:
        return "—"
    a = abs(v)
    if a != 0 and (a < 1e-3 or a >= 1e5):
        return f"{v:.3g}"
    return f"{v:.4g}"


def markdown_table(doc: Mapping[str, Any], config_keys: Sequence[str] = ()) -> str:
    """All rows as one Markdown table (mean ± std, the paper's figure, chosen config keys).

    Parameters
    ----------
    doc : mapping
        A result document.
    config_keys : sequence of str
        Config keys shown as extra columns after ``metric`` (empty cell for a row without the key).

    Returns
    -------
    str
        The table, one line per row, ending in a newline.
    """
    keys = list(config_keys)
    head = ["system", "target", "estimator", "stage", "metric", *keys, "ours (mean ± std)", "runs", "paper"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * (len(head) - 3) + "---:|---:|---:|"]
    for r in doc["rows"]:
        val = _fmt(r["value"]) + (f" ± {_fmt(r['std'])}" if r["std"] is not None else "")
        cells = [r["system"], r["target"], r["estimator"], r["stage"], r["metric"]]
        cells += [str(r["config"].get(k, "")) for k in keys]
        cells += [val, str(r["runs"]), _fmt(r["paper"]) if r["paper"] is not None else ""]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":  # pragma: no cover
    for f in sys.argv[1:]:
        print(markdown_table(load_results(f)))


def save_figure(fig: Any, path: str | Path, dpi: int = 110) -> Path:
    """Save a matplotlib figure as PNG atomically (a temporary file renamed into place) and close it."""
    import matplotlib.pyplot as plt

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp.png")
    fig.savefig(tmp, dpi=dpi)
    plt.close(fig)
    tmp.replace(p)
    return p


#: Prefixes of absolute paths that name one machine's files (a results file must hold none of them).
MACHINE_PATH_PREFIXES = ("/tmp/", "/work/", "/home/")
#: An absolute POSIX path in running text: a ``/`` not preceded by a word character, ``.``, ``:`` or
#: another ``/`` (so ``a/b``, ``1/2``, ``https://`` are left alone), up to white space, a bracket, a
#: quote or a separator.
_ABS_PATH = re.compile(r"(?<![\w.:/])/[^\s()\[\]{}'\"`,;|]+")


def portable_paths(text: str, roots: Sequence[str | os.PathLike] = ()) -> str:
    """``text`` with every absolute path made machine independent, for the text of a results file.

    A path inside one of ``roots`` (e.g. the temporary folder a bench ran a tool in) becomes relative
    to that root (``/tmp/pwas-x/d/synth/ice40/nextpnr.log`` with root ``/tmp/pwas-x/d`` ->
    ``synth/ice40/nextpnr.log``); any other absolute path becomes its file name. Relative paths,
    fractions (``1/2``) and URLs are left as they are.

    Parameters
    ----------
    text : str
        A message, a reason, a command line.
    roots : sequence of path-like
        Folders whose contents are named relative to them (the first that contains a path wins).

    Returns
    -------
    str
    """
    bases = [str(r).rstrip("/") for r in roots if str(r).startswith("/")]
    bases += [os.path.realpath(b) for b in bases if os.path.realpath(b) != b]

    def fix(m: re.Match) -> str:
        path = m.group(0)
        for b in bases:
            if path == b:
                return "."
            if path.startswith(b + "/"):
                return path[len(b) + 1:]
        return path.rstrip("/").rsplit("/", 1)[-1] or path

    return _ABS_PATH.sub(fix, text)


def check_count(option: str, value: Any, limit: int | None = None) -> int:
    """A bench's count option (``--runs``, ``--seeds``, ...): an integer ``1 <= value <= limit``.

    The one rule of every bench command and benchmark script.

    Parameters
    ----------
    option : str
        The option as the user typed it (``"--runs"``).
    value : int
    limit : int, optional
        The upper limit (default :data:`pwas_hdl.limits.MAX_BENCH_COUNT`).

    Returns
    -------
    int
        ``value``.

    Raises
    ------
    InputError
        ``value`` is not an integer or below 1; :class:`~pwas_hdl.errors.ResourceLimit` above ``limit``.
    """
    from pwas_hdl.limits import MAX_BENCH_COUNT, check_limit

    limit = MAX_BENCH_COUNT if limit is None else int(limit)
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(f"{option} must be >= 1 and an integer, got {value!r}")
    return check_limit(option, int(value), limit, f"{option} counts independent runs; at most {limit}")


def default_outdir() -> Path:
    """Default ``--outdir`` of the benchmark scripts.

    ``benchmarks/results/`` when the scripts run from a source checkout (the committed results),
    otherwise ``./benchmarks-results`` in the current directory: never inside an installed package
    (``site-packages``) when the scripts run from the wheel.
    """
    from pwas_hdl.resources import benchmarks_dir, source_checkout

    here = benchmarks_dir()
    if source_checkout() is not None and (here / "results").is_dir():
        return here / "results"
    return Path.cwd() / "benchmarks-results"


def checked_outdir(outdir: str | os.PathLike) -> Path:
    """A script's ``--outdir``, checked before its run (a file there, a path through a file, an
    unwritable parent: one ``error:`` line before minutes of work, not after them); create it with
    :func:`make_outdir` when the results are written.

    Raises
    ------
    InputError
        As :func:`pwas_hdl.io.atomic.check_output_path` for a folder.
    """
    from pwas_hdl.io.atomic import check_output_path

    return check_output_path(outdir, "--outdir", kind="folder")


def make_outdir(outdir: str | os.PathLike) -> Path:
    """Create ``--outdir`` (with its parents) where the results are about to be written: from the
    wheel it is ``./benchmarks-results``, absent in a new folder."""
    path = Path(outdir)
    path.mkdir(parents=True, exist_ok=True)
    return path


@contextmanager
def scratch_folder(prefix: str, keep: str | os.PathLike | None = None) -> Iterator[Path]:
    """The work folder of a benchmark run (generated designs, simulator and synthesis files).

    ``keep`` (a script's ``--workdir``): that folder, created if needed and kept. Otherwise a new
    folder in the system's temporary directory, removed when the block ends, also on an error or
    Ctrl-C: a benchmark writes its results to ``--outdir`` and leaves nothing else behind (the
    100-configuration RTL sweep used to leave up to 3 GB in ``/tmp`` per run).

    Parameters
    ----------
    prefix : str
        Name prefix of the temporary folder.
    keep : str or path-like, optional
        A folder to use and keep instead.

    Yields
    ------
    Path
        The work folder.
    """
    import shutil
    import tempfile

    if keep is not None:
        path = Path(keep)
        path.mkdir(parents=True, exist_ok=True)
        yield path
        return
    path = Path(tempfile.mkdtemp(prefix=prefix))
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)


def script_main(main: Any, argv: Sequence[str] | None = None) -> int:
    """Run a benchmark script's ``main(argv)`` under the command line's error contract.

    Bad input (an :class:`~pwas_hdl.errors.InputError`, an OS error, a missing tool) gives one
    ``error:`` line and exit status 2 instead of a traceback; a bug a traceback and 3
    (:func:`pwas_hdl.cli.report_error`). ``main`` returning None counts as success.

    Parameters
    ----------
    main : callable
        The script's ``main``; called as ``main(argv)``, or ``main()`` when ``argv`` is None.
    argv : sequence of str, optional
        Command-line arguments (None: ``main`` reads ``sys.argv`` itself).

    Returns
    -------
    int
        The exit status: ``main``'s return value (0 for None), else 2 or 3 as above.
    """
    from pwas_hdl.cli import report_error

    try:
        rv = main(argv) if argv is not None else main()
    except SystemExit:
        raise
    except Exception as exc:  # noqa: BLE001 - mapped to an exit status like the CLI's
        return report_error(exc)
    return int(rv or 0)


def bench_main(argv: Sequence[str] | None, *, stem: str, description: str, run: Any, markdown: Any, plot: Any,
               default_runs: int = 5, add_arguments: Any = None, other_mode: Any = None) -> None:
    """The script entry of a system bench: ``--runs``, ``--quick``, ``--outdir``; writes JSON, Markdown and PNG.

    ``run(runs, quick, progress=print)`` returns ``(doc, traces)``; ``markdown(doc)`` the table text;
    ``plot(traces, path)`` the figure. ``--quick`` writes ``STEM_quick.*`` so a smoke run never
    overwrites the committed results. A script with another mode declares its options with
    ``add_arguments(parser)`` (so that ``--help`` lists them) and runs it in ``other_mode(args)``,
    which returns True when it did (the bench above is then not run).
    """
    import argparse

    from pwas_hdl.io.atomic import atomic_write_text

    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--runs", type=int, default=default_runs, help="independent runs (1..1000, pwas_hdl.limits.MAX_BENCH_COUNT)")
    ap.add_argument("--quick", action="store_true", help=f"a reduced smoke run, written as {stem}_quick.*: not a result to quote")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="folder of the result files (default: %(default)s)")
    if add_arguments is not None:
        add_arguments(ap)
    a = ap.parse_args(argv)
    if other_mode is not None and other_mode(a):
        return
    check_count("--runs", a.runs)
    doc, traces = run(a.runs, a.quick, progress=print)
    a.outdir.mkdir(parents=True, exist_ok=True)
    name = f"{stem}_quick" if a.quick else stem
    write_results(a.outdir / f"{name}.json", doc)
    atomic_write_text(a.outdir / f"{name}.md", markdown(doc))
    plot(traces, a.outdir / f"{name}.png")
    print(markdown(doc))
