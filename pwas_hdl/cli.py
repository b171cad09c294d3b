"""Command-line interface: a thin layer over the public API.

Every command has ``-h/--help``. What the command line does with each error class of
:mod:`pwas_hdl.errors` (one place: :func:`_report_error`):

* bad input (:class:`~pwas_hdl.errors.InputError`, any ``ValueError``, ``OSError``) and Click usage
  errors (unknown option, non-numeric value, missing file): one ``error:`` line on stderr, exit 2,
  nothing written;
* a missing tool (:class:`~pwas_hdl.errors.ToolMissing`): an ``error:`` line with the install step,
  exit 2; a tool that ran and failed (:class:`~pwas_hdl.errors.ToolFailed`): an ``error:`` line
  naming its log, exit 2;
* a verification that found a difference (:class:`~pwas_hdl.errors.CheckFailed`): ``error:``
  line, exit 1;
* anything else (:class:`~pwas_hdl.errors.InternalError`, a ``RuntimeError`` from a bug, ...): the
  traceback and "this is a bug in pwas-hdl, please report it", exit 3.

``pwas-hdl -q COMMAND`` drops the progress and information lines (warnings and errors stay);
``pwas-hdl -v COMMAND`` adds the traceback to every error and the end of a failed tool's log.
"""

from __future__ import annotations

import functools
import json
import os
import sys
import traceback
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, Iterator, Optional, Sequence

import click
import numpy as np
import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from pwas_hdl import __version__
from pwas_hdl.errors import CheckFailed, InputError, InternalError, ToolFailed, ToolMissing
from pwas_hdl.io.atomic import OutputSet, check_output_path, install_termination_handler
from pwas_hdl.io.csv_table import check_trajectory_column, check_trajectory_lengths, format_csv, read_csv, select_signals, split_trajectories
from pwas_hdl.limits import MAX_NOISE, MAX_SAMPLES, MAX_SIGMA_CANDIDATES, MAX_SWEEP_POINTS, check_limit, check_values

#: ``-h`` as well as ``--help`` on every command (sub-commands inherit the setting).
_CONTEXT = {"help_option_names": ["-h", "--help"]}

app = typer.Typer(
    name="pwas-hdl",
    help="PWAS virtual sensors: fit from plant data, generate verified Verilog, simulate, synthesize, report.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help printed literally: no Rich markup, no emoji codes (logspace:A:B:K)
    context_settings=_CONTEXT,
)
bench_app = typer.Typer(help="Reproduce the seed paper's benchmarks.", no_args_is_help=True, rich_markup_mode=None,
                        context_settings=_CONTEXT)
app.add_typer(bench_app, name="bench")
data_app = typer.Typer(help="Write the built-in example data sets as CSV.", no_args_is_help=True, rich_markup_mode=None,
                       context_settings=_CONTEXT)
app.add_typer(data_app, name="make-data")

err = Console(stderr=True, soft_wrap=True, emoji=False)  # ":a:" in a message is text, not an emoji code
stdout = Console(soft_wrap=True, emoji=False)

#: Global flags of this invocation (set by the root callback: ``-q``, ``-v``).
_STATE = {"quiet": False, "verbose": False}

#: Usage errors of the command-line parser: Click's, and Typer's own copy of Click (typer >= 0.2x
#: vendors Click, with its own exception classes).
_USAGE_ERRORS: tuple[type[Exception], ...] = (click.ClickException,) + (
    (typer.TyperException,) if hasattr(typer, "TyperException") else ()
)
#: Exceptions that end a command on purpose (``--help``, ``--version``, an exit status).
_EXITS: tuple[type[BaseException], ...] = tuple({typer.Exit, typer.Abort, click.exceptions.Exit, click.exceptions.Abort})

#: Exit statuses.
EXIT_CHECK_FAILED, EXIT_INPUT, EXIT_BUG = 1, 2, 3
BUG_NOTE = "this is a bug in pwas-hdl, please report it (with the traceback above and the command line)"


#: From this many memory words, ``generate`` with inline weights says that ``--memory-init readmemh``
#: exists (at N = 10^6 Verilator built the inline form in 64 s / 2.8 GB, the readmemh form in 13 s).
INLINE_NOTE_WORDS = 1 << 17


def _say(msg: str) -> None:
    """One plain information line on stderr (no Rich markup: names like y[t-3] must print as they are).

    Silent under ``-q``.
    """
    if not _STATE["quiet"]:
        err.print(msg, highlight=False, markup=False)


def _warn(msg: str) -> None:
    """A warning line on stderr (printed even under ``-q``)."""
    err.print(msg, highlight=False, markup=False)


def _trajectory_warning(table: Any, traj_col: str | None, used: Sequence[str]) -> str | None:
    """The warning line about DATA's runs, or None.

    Without ``--traj-col`` (``traj_col`` None): DATA has a run index (``run``, ...) that is not in ``used``
    (the columns read as signals): its runs are then read as one trajectory
    (:func:`pwas_hdl.io.csv_table.unused_trajectory_column`). With ``--traj-col``: a run label that comes
    back after another run, whose separate blocks are then read as runs of their own
    (:func:`pwas_hdl.io.csv_table.split_runs`; ``used`` is not consulted). Printed by the command once
    its work succeeded (bad input stays one ``error:`` line)."""
    from pwas_hdl.io.csv_table import split_runs, unused_trajectory_column

    if traj_col is not None:  # a run label that comes back after another run: read as runs of their own
        return split_runs(table, traj_col)
    hit = unused_trajectory_column(table, traj_col, used)
    if hit is None:
        return None
    name, runs = hit
    return (f"warning: column {name!r} numbers {runs} runs, but without --traj-col {name} they are read as one "
            f"trajectory (regressors straddle their boundaries); give --traj-col {name} to keep them apart")


def _error_line(msg: str) -> None:
    """``error: MESSAGE`` on stderr, always one line (a message's line breaks become spaces)."""
    one = " ".join(part.strip() for part in msg.splitlines() if part.strip())
    err.print(f"error: {one}", highlight=False, markup=False)


def _os_message(exc: OSError) -> str:
    if exc.filename is not None and exc.strerror:
        return f"{exc.filename}: {exc.strerror}"
    return str(exc)


def report_error(exc: BaseException) -> int:
    """Print what the user needs to see about ``exc`` on stderr (one ``error:`` line; a traceback
    only for a bug or under ``-v``) and return the exit status of the mapping above (2 for bad
    input, an OS error or a missing tool, 1 for a failed check, 3 for a bug). Also used by the
    benchmark scripts (:func:`pwas_hdl.bench_results.script_main`)."""
    return _report_error(exc)


def _report_error(exc: BaseException) -> int:
    """Print what the user needs to see about ``exc`` and return the exit status (the mapping above)."""
    verbose = _STATE["verbose"]
    if isinstance(exc, _USAGE_ERRORS) and type(exc).__name__ == "NoArgsIsHelpError":
        stdout.print(exc.format_message(), highlight=False, markup=False)  # the help text
        return EXIT_INPUT
    if isinstance(exc, _USAGE_ERRORS):
        hint = ""
        ctx = getattr(exc, "ctx", None)
        if ctx is not None:
            hint = f" (see `{ctx.command_path} --help`)"
        _error_line(" ".join(exc.format_message().split()) + hint)
        return EXIT_INPUT
    if isinstance(exc, CheckFailed):
        code, msg = EXIT_CHECK_FAILED, str(exc)
    elif isinstance(exc, (ToolMissing, ToolFailed)):
        code, msg = EXIT_INPUT, str(exc)
    elif isinstance(exc, InternalError) or not isinstance(exc, (ValueError, OSError)):
        traceback.print_exception(exc, file=sys.stderr)
        _error_line(f"internal error ({type(exc).__name__}: {exc}); {BUG_NOTE}")
        return EXIT_BUG
    elif isinstance(exc, OSError):
        code, msg = EXIT_INPUT, _os_message(exc)
    else:
        code, msg = EXIT_INPUT, str(exc)
    if verbose:
        traceback.print_exception(exc, file=sys.stderr)
    _error_line(msg)
    if verbose and isinstance(exc, ToolFailed) and exc.tail:
        _warn(exc.tail)
    return code


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A Python warning raised in a command body (e.g. the API's UserWarning of ``generate --overflow
    saturate``) as one ``warning:`` line, like the command's own warnings: not Python's default
    ``/path/to/module.py:482: UserWarning: ...`` and the source line after it."""
    _warn("warning: " + " ".join(str(message).split()))


@contextmanager
def _user_errors() -> Iterator[None]:
    """Run a command body: every exception becomes its message and exit status (:func:`_report_error`),
    every Python warning one ``warning:`` line (:func:`_show_warning`)."""
    import warnings

    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            yield
    except _EXITS:
        raise
    except Exception as exc:  # noqa: BLE001 - the one place where every error is turned into an exit status
        raise typer.Exit(_report_error(exc)) from None


# ------------------------------------------------------------------ one option name per concept
# Every command uses the same names: -o/--out for the file or folder it writes, -u/--inputs,
# -y/--outputs, -z/--targets for data columns, --fpga for the FPGA family, --clock-mhz for the
# clock. The names of earlier versions still work as hidden options (--output-model, --outdir,
# --output, --input, --target, --resources, --freq, --target-mhz, --md / --json where they named
# the main output); _merge() folds them into the new one.
#: The metavar of the options that name a folder (the other ``Path`` options name files).
FOLDER_METAVAR = "<dir>"


def _hidden(*names: str) -> Any:
    """A hidden old name of an option (merged into the new one by :func:`_merge`)."""
    return typer.Option(*names, hidden=True, show_default=False)


def _hidden_dir(*names: str) -> Any:
    """A hidden old name of a folder option (``metavar=FOLDER_METAVAR``: a trailing ``/`` is allowed)."""
    return typer.Option(*names, hidden=True, show_default=False, metavar=FOLDER_METAVAR)


def _merge(new: str, value: Any, **old: Any) -> Any:
    """The value of option ``new`` given under its name or one of its old names (``old``: name -> value).

    Raises
    ------
    InputError
        The option was given under two names with different values.
    """
    given = {new: value} if value is not None else {}
    given.update({("--" + k.replace("_", "-")): v for k, v in old.items() if v is not None})
    if len({json.dumps(v, default=str) for v in given.values()}) > 1:
        raise InputError(f"{' and '.join(given)} are one option (the second is the old name); give it once")
    return next(iter(given.values()), None)


def _merge_lists(*values: Optional[list[str]]) -> Optional[list[str]]:
    """Repeated list options given under the new and the old name: all of them, in order."""
    given = [v for v in values if v]
    return [x for v in given for x in v] if given else None


def _required(value: Any, option: str, what: str) -> Any:
    if value is None:
        raise InputError(f"give {what} with {option}")
    return value


def _int_list(text: str, what: str) -> list[int]:
    try:
        vals = [int(v) for v in text.replace(" ", "").split(",") if v]
    except ValueError:
        raise InputError(f"{what} must be an integer or a comma-separated list of integers, got {text!r}") from None
    if not vals:
        raise InputError(f"{what} is empty; give one or more integers separated by commas")
    return vals


def _number_list(text: str, what: str, takes: str) -> list[float]:
    """Comma list of floats (no ``logspace:``: values, not candidates); ``takes`` says what the option takes."""
    try:
        return [float(v) for v in text.replace(" ", "").split(",") if v]
    except ValueError:
        raise InputError(f"{what} must be {takes}, got {text!r}") from None


def _float_list(text: str, what: str) -> list[float]:
    """Comma list of floats, or ``logspace:A:B:K`` (K values from 1eA to 1eB)."""
    t = text.replace(" ", "")
    try:
        if t.startswith("logspace:"):
            a, b, k = t.split(":")[1:]
            k_count = int(k)
        else:
            return [float(v) for v in t.split(",") if v]
    except ValueError:
        raise InputError(f"{what} must be a comma-separated list of numbers or logspace:A:B:K, got {text!r}") from None
    check_limit(f"the number of {what} candidates K", k_count, MAX_SIGMA_CANDIDATES, "give fewer candidates")
    try:
        with np.errstate(over="ignore", under="ignore"):  # an exponent out of the float range: refused below
            vals = [float(v) for v in np.logspace(float(a), float(b), k_count)]
    except ValueError:
        raise InputError(f"{what} must be a comma-separated list of numbers or logspace:A:B:K, got {text!r}") from None
    if not all(0.0 < v < np.inf for v in vals):
        raise InputError(f"{what} {text}: 10**A .. 10**B must be positive finite numbers; give exponents A and B "
                         f"between -307 and 308")
    return vals


WorkersOpt = Annotated[Optional[int], typer.Option("--workers", help="Run the independent tasks on a local Dask cluster of this many worker processes (default: serially).")]
SchedulerOpt = Annotated[Optional[str], typer.Option("--scheduler", help="Run the independent tasks on an existing Dask cluster: its scheduler address tcp://HOST:PORT (default: $PWAS_HDL_SCHEDULER).")]
# the same argument / option, with the same text, on several commands
ModelArg = Annotated[Path, typer.Argument(metavar="MODEL", help="Model file written by `pwas-hdl fit`.")]
BlankRowsOpt = Annotated[str, typer.Option("--blank-rows", help="A blank row in DATA: error, or break (it ends a trajectory).")]
TrajColOpt = Annotated[Optional[str], typer.Option("--traj-col", help="Trajectory column, as for fit.")]


def _executor(workers: Optional[int], scheduler: Optional[str]):
    from pwas_hdl.flow.executor import Executor

    if workers is not None and scheduler is not None:
        raise InputError("give --workers (a local cluster) or --scheduler (an existing one), not both")

    return Executor(workers=workers, scheduler=scheduler)


def _distinct_columns(*roles: tuple[str, list[str]]) -> None:
    """Refuse a data column named twice in one option or given two roles (``(option, names)`` pairs)."""
    seen: dict[str, str] = {}
    for opt, names in roles:
        for nm in names:
            if nm not in seen:
                seen[nm] = opt
            elif seen[nm] == opt:
                raise InputError(f"column {nm!r} is named twice in {opt}; name each column once")
            else:
                pair = {seen[nm], opt}
                why = ("the model would read what it estimates" if "-z/--targets" in pair else
                       "it labels trajectories, it is no signal" if "--traj-col" in pair else
                       "the regressor would hold the same samples twice")
                raise InputError(f"column {nm!r} is given both as {seen[nm]} and as {opt} ({why}); give each column one role")


def _design_folder(outdir: Path) -> Path:
    """OUTDIR of simulate / synth / report / export-testbench: a folder (a file, even its manifest.json, is refused)."""
    if outdir.is_file():
        raise InputError(f"OUTDIR {str(outdir)!r} is a file, not a folder written by `pwas-hdl generate`; give the design folder")
    return outdir


def _names(values: Optional[list[str]]) -> list[str]:
    res: list[str] = []
    for v in values or []:
        res += [s.strip() for s in v.split(",") if s.strip()]  # spaces inside a name are part of it
    return res


def _rmse(estimate: np.ndarray, reference: np.ndarray) -> float:
    """RMS of ``estimate - reference`` without a numpy overflow warning: where the squares overflow (a
    model or data near the float limit), both are scaled by their largest magnitude first, so the RMSE
    printed is the huge number it is, not inf beside a RuntimeWarning."""
    with np.errstate(over="ignore"):  # the overflow is the case handled below
        plain = float(np.sqrt(np.mean((estimate - reference) ** 2))) if estimate.size else float("nan")
    if not plain == np.inf:
        return plain
    scale = float(max(np.max(np.abs(estimate)), np.max(np.abs(reference))))
    if scale == np.inf:  # an infinite estimate
        return scale
    d = estimate / scale - reference / scale
    return scale * float(np.sqrt(np.mean(d * d)))  # a Python float product: inf above the float range, no warning


@contextmanager
def _progress(description: str) -> Iterator:
    """A transient progress bar on stderr, shown on a terminal only (piped or captured, rich would
    leave a blank line before the command's own messages) and not under ``-q``."""
    with Progress(
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), console=err, transient=True,
        disable=_STATE["quiet"] or not err.is_terminal,
    ) as prog:
        task = prog.add_task(description, total=None)

        def update(done: int, total: int) -> None:
            prog.update(task, completed=done, total=total)

        yield update


@app.command()
def fit(
    data: Annotated[Path, typer.Argument(metavar="DATA", help="CSV file with a header line; one row per sample.")],
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="Model file to write (JSON). Required.", show_default=False)] = None,
    inputs: Annotated[Optional[list[str]], typer.Option("-u", "--inputs", help="Input column(s) u (repeat or comma-separate).")] = None,
    outputs: Annotated[Optional[list[str]], typer.Option("-y", "--outputs", help="Measured output column(s) y.")] = None,
    targets: Annotated[Optional[list[str]], typer.Option("-z", "--targets", help="Column(s) z to estimate.")] = None,
    mu: Annotated[int, typer.Option("--mu", help="Mu: past input samples in the regressor (0 = inputs unused).")] = 0,
    my: Annotated[int, typer.Option("--my", help="My: past output samples in the regressor.")] = 1,
    partitions: Annotated[Optional[str], typer.Option("-p", "--partitions", help="Intervals per dimension: one integer or a comma list (one per regressor); default 7. With a --breakpoints FILE, the file's (it sets the cells): leave it out or repeat them.", show_default=False)] = None,
    gamma: Annotated[Optional[float], typer.Option("--gamma", help="Domain expansion factor (>= 1) about the centre of the data box; default 1.2. Not with a --breakpoints FILE (it sets the domain).", show_default=False)] = None,
    sigma: Annotated[Optional[float], typer.Option("--sigma", help="Tikhonov weight (unnormalised, eq. 14). Omit to choose it by cross-validation.")] = None,
    sigma_grid: Annotated[Optional[str], typer.Option("--sigma-grid", help="CV candidates: comma list or logspace:A:B:K.")] = None,
    folds: Annotated[int, typer.Option("--folds", help="Cross-validation folds.")] = 5,
    cv_shuffle: Annotated[bool, typer.Option("--cv-shuffle", help="Shuffle samples across CV folds (default: contiguous blocks).")] = False,
    tikhonov: Annotated[int, typer.Option("--tikhonov", help="Tikhonov order: 0 (Gamma = I) or 1 (gradient penalty).")] = 0,
    traj_col: Annotated[Optional[str], typer.Option("--traj-col", help="Column naming the trajectory of each row (no regressor straddles two).")] = None,
    domain: Annotated[Optional[str], typer.Option("--domain", help="Explicit domain 'lo:hi,lo:hi,...' (one pair per regressor) instead of the gamma-expanded data box.")] = None,
    separate_lag_domains: Annotated[bool, typer.Option("--separate-lag-domains", help="Give each lag its own data range (default: all lags of a signal share one interval, as the hardware scales once per signal).")] = False,
    breakpoints: Annotated[Optional[str], typer.Option("--breakpoints", help="Non-uniform partition (same N as the uniform grid): quantile (cuts at the k/p data quantiles inside the domain), quantile-pow2 (the same, cell widths rounded to power-of-two multiples of a base step: no divider in hardware), or FILE: JSON {\"format\": \"pwas-hdl-breakpoints\", \"version\": 1, \"breakpoints\": [[b0, .., bp], ...]} with one strictly increasing list per regressor (it sets the partitions and the domain). Default: equal intervals.")] = None,
    output_model: Annotated[Optional[Path], _hidden("--output-model")] = None,
    input_old: Annotated[Optional[list[str]], _hidden("--input")] = None,
    output_old: Annotated[Optional[list[str]], _hidden("--output")] = None,
    target_old: Annotated[Optional[list[str]], _hidden("--target")] = None,
    classify: Annotated[bool, typer.Option("--classify", help="The one -z/--targets column is a class label: fit one-hot scores (one per distinct value) on one shared grid; predict decides by argmax.")] = False,
    front_end: Annotated[str, typer.Option("--front-end", help="lags: PWAS on the lag regressor; observer-bank: PWAS on the residual features of a bank of learned local models (seed 004), followed by the --mu/--my taps (0 allowed).")] = "lags",
    models: Annotated[int, typer.Option("--models", help="observer-bank: N_theta, local models / observers in the bank.")] = 5,
    observer: Annotated[str, typer.Option("--observer", help="observer-bank: deadbeat, poles:R (all poles at radius R) or kalman:LAMBDA (stationary Kalman, measurement variance LAMBDA).")] = "deadbeat",
    window: Annotated[int, typer.Option("--window", help="observer-bank: window l of the feature map.")] = 7,
    features: Annotated[str, typer.Option("--features", help="observer-bank: feature map 11b (windowed residual RMS per observer), 11b-sq (its square: no square root in hardware) or 11a (all residual lags).")] = "11b",
    order: Annotated[int, typer.Option("--order", help="observer-bank: order M of the local ARX models.")] = 5,
    blank_rows: BlankRowsOpt = "error",
    mz: Annotated[int, typer.Option("--mz", help="Mz: past estimates z_hat(t-1..t-Mz) of every target fed back as regressors (a dynamical sensor; fitted series-parallel, predict runs the recurrence). 0 = static.")] = 0,
    refine: Annotated[int, typer.Option("--refine", help="With --mz: up to K closed-loop refinements (refit on the simulated estimates while the closed-loop error improves).")] = 0,
    z0: Annotated[Optional[str], typer.Option("--z0", help="With --mz: initial past estimates, mean (training mean, default), measured (the measured z before the first estimate; predict then reads the target columns) or one value per target (comma list).")] = None,
    additive: Annotated[Optional[str], typer.Option("--additive", help="Reduced-complexity additive sensor, a sum of PWAS parts on subsets of the regressors, fitted jointly: time (one part per time instant), pairs / triples (sliding windows of 2 / 3 lags), or regressor indices '0,1;1,2;...' (0-based, in the order fit prints them; parts separated by ';').")] = None,
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
) -> None:
    """Fit a PWAS virtual sensor to DATA and write the model file.

    With --workers / --scheduler the cross-validation folds (each fold's sigma sweep) run as Dask
    tasks; from 50 000 unknowns --workers N instead runs them on N forked processes that share
    the data (no cluster start-up); the chosen sigma and the weights are the serial run's.

    The weights are checked afresh against the normal equations (model file fit.solve): where the
    iterative solver stopped at its iteration cap, fit prints a warning: line with the relative
    residual and a bound on the weights' error, and one when cross-validation solves did.
    """
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd, parse_observer

    with _user_errors():
        if front_end not in ("lags", "observer-bank"):
            raise InputError(f"--front-end must be lags or observer-bank, got {front_end!r}")
        bank = front_end == "observer-bank"
        # every option value is checked, whether this front end uses it or not (a typo is an error)
        parse_observer(observer)
        bank_fe = ObserverBankFrontEnd(n_models=models, observer=observer, window=window, features=features, order=order)
        bank_fe.check_params()
        fe: Any = bank_fe if bank else "lags"
        output = _required(_merge("-o/--out", out, output_model=output_model), "-o/--out", "the model file to write")
        outset = OutputSet(inputs=[(data, "DATA")])
        outset.add(output, "-o/--out")
        ins = _names(_merge_lists(inputs, input_old))
        outs = _names(_merge_lists(outputs, output_old))
        tgts = _names(_merge_lists(targets, target_old))
        if not tgts:
            raise InputError("give the column(s) to estimate with -z/--targets")
        if classify and len(tgts) != 1:
            raise InputError(f"--classify needs exactly one -z/--targets column (the class label), got {len(tgts)}")
        if bank and classify:
            raise InputError("--classify is not available with --front-end observer-bank")
        if bank and len(outs) != 1:
            raise InputError("--front-end observer-bank needs exactly one measured output column: give one -y/--outputs")
        if my and not outs:
            raise InputError(f"--my {my} needs measured output column(s): give -y/--outputs (or --my 0)")
        _executor(workers, scheduler)  # --workers / --scheduler checked before the data are read
        if mu < 0 or my < 0:
            raise InputError(f"--mu and --my must be >= 0 (past samples in the regressor), got {mu} and {my}")
        if sigma is not None and sigma_grid is not None:
            raise InputError("give --sigma (a fixed weight) or --sigma-grid (the cross-validation's candidates), not both")
        if mu and not ins:
            raise InputError(f"--mu {mu} needs input column(s): give -u/--inputs (or --mu 0)")
        if ins and not mu and not bank:
            raise InputError(f"-u/--inputs {','.join(ins)} is given but --mu is 0 (inputs unused): give --mu K, the past "
                             "input samples in the regressor, or leave -u out")
        if outs and not my and not bank:
            raise InputError(f"-y/--outputs {','.join(outs)} is given but --my is 0 (outputs unused): give --my K or leave -y out")
        _distinct_columns(("-u/--inputs", ins), ("-y/--outputs", outs), ("-z/--targets", tgts),
                          ("--traj-col", [traj_col] if traj_col is not None else []))
        table = read_csv(data, blank_rows=blank_rows)
        if traj_col is not None:
            table.column_index(traj_col)
        traj_warning = _trajectory_warning(table, traj_col, [*ins, *outs, *tgts])
        use_u = bool(mu or (bank and ins))
        from pwas_hdl.limits import MAX_REGRESSORS

        # a run shorter than the lags: named with its file lines (too many regressors: the limit's message first)
        if not bank and max(mu, my) > 1 and len(ins) * mu + len(outs) * my <= MAX_REGRESSORS:
            check_trajectory_lengths(table, traj_col, max(mu, my))
        u = select_signals(table, ins, traj_col) if use_u else None
        y = select_signals(table, outs, traj_col) if (my or bank) else None
        z = select_signals(table, tgts, traj_col)
        dom = None
        if domain is not None:
            try:
                pairs = [tuple(float(v) for v in s.split(":")) for s in domain.replace(" ", "").split(",")]
                dom = ([a for a, _ in pairs], [b for _, b in pairs])
            except ValueError:
                raise InputError(f"--domain must look like 'lo:hi,lo:hi,...', got {domain!r}") from None
        # the estimator's own defaults (PWASVirtualSensor: partitions 7, gamma 1.2) where the options are not given
        grid_opts: dict[str, Any] = {}
        if partitions is not None:
            parts = _int_list(partitions, "--partitions")
            grid_opts["partitions"] = parts[0] if len(parts) == 1 else parts
        if gamma is not None:
            grid_opts["gamma"] = gamma
        if mz < 0 or refine < 0:
            raise InputError(f"--mz and --refine must be >= 0, got {mz} and {refine}")
        if (refine or z0 is not None) and not mz:
            raise InputError("--refine and --z0 need a dynamical sensor: give --mz K (K >= 1)")
        if mz and (bank or classify):
            raise InputError("--mz needs the lag front end and a regression target (not --front-end observer-bank or --classify)")
        init: Any = "mean"
        if z0 is not None:
            init = z0.strip() if z0.strip() in ("mean", "measured") else _number_list(
                z0, "--z0", "mean, measured or one number per -z/--targets column (comma-separated)")
            if not isinstance(init, str) and len(init) != len(tgts):
                raise InputError(f"--z0 needs one value per target ({len(tgts)}), got {len(init)}")
            if not isinstance(init, str) and not all(np.isfinite(init)):
                raise InputError(f"--z0 values must be finite numbers, got {z0!r}")
        bps, bp_names = breakpoints, None
        if breakpoints is not None and breakpoints not in ("quantile", "quantile-pow2"):
            from pwas_hdl.fit.breakpoints import read_breakpoints

            if dom is not None:
                raise InputError("--domain and a --breakpoints FILE both set the domain: give one of them")
            bpath = Path(breakpoints)
            if bpath.is_dir():
                raise InputError(f"--breakpoints {breakpoints!r} is a folder; give a breakpoints file (JSON) or quantile / quantile-pow2")
            if not bpath.is_file():
                raise InputError(f"--breakpoints must be quantile, quantile-pow2 or a breakpoints file; {breakpoints!r} is neither")
            if gamma is not None:
                raise InputError("a --breakpoints FILE sets the domain: --gamma does not apply; leave it out")
            bps, bp_names = read_breakpoints(bpath)
            if partitions is not None:  # may repeat the file's intervals, not contradict them
                file_parts = [len(b) - 1 for b in bps]
                asked = grid_opts["partitions"]
                asked = [asked] * len(file_parts) if isinstance(asked, int) else list(asked)
                if asked != file_parts:
                    raise InputError(f"-p/--partitions {partitions} differs from the intervals of --breakpoints {breakpoints} "
                                     f"({','.join(map(str, file_parts))}); leave -p out (the file sets the cells)")
        from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor  # imports scikit-learn: only when needed
        model = PWASVirtualSensor(
            mu=mu,
            my=my,
            **grid_opts,
            sigma=sigma,
            tikhonov_order=tikhonov,
            cv_folds=folds,
            sigma_grid=_float_list(sigma_grid, "--sigma-grid") if sigma_grid else None,
            cv_shuffle=cv_shuffle,
            domain=dom,
            share_lag_domain=not separate_lag_domains,
            input_names=ins if use_u else [],
            output_names=outs if (my or bank) else [],
            target_names=tgts,
            front_end=fe,
            mz=mz,
            refine=refine,
            initial_state=init,
            additive=additive,
            breakpoints=bps,
            classify=classify,
        )
        if additive is not None and not bank:  # the parts are checked before the data are read into a fit
            from pwas_hdl.fit.additive import ADDITIVE_KINDS, parse_additive
            from pwas_hdl.fit.regressors import LagStructure

            dims = LagStructure(mu, my, len(ins) if mu else 0, len(outs) if my else 0).signal_of_dimension()
            parts = parse_additive(additive, dims)
            if len(parts) == 1 and len(parts[0]) == len(dims):  # one part over every regressor: nothing is dropped
                _say(f"note: --additive {additive} gives one part over all {len(dims)} regressors, i.e. the full PWAS "
                     "sensor; " + ("more lags (--my/--mu) give more parts" if additive.strip() in ADDITIVE_KINDS
                                   else "give parts over fewer regressors"))
        if sigma is not None and (workers is not None or scheduler is not None):  # accepted (checked), but idle
            _say(f"note: {'--workers' if workers is not None else '--scheduler'} runs the cross-validation folds; "
                 "with a given --sigma there are none, the fit runs in this process")
        with _progress("cross-validating sigma" if sigma is None else "solving") as update, _executor(workers, scheduler) as ex:
            model.fit(u, y, z, progress=update, executor=ex)
        cv = getattr(model, "cv_", None)
        plan = cv.solver.get("memory_plan") if cv is not None else None
        if plan and plan["reason"]:  # fewer workers, or one factor at a time, than --workers asked (the memory limit)
            _say(f"note: {plan['reason']}")
        if bp_names is not None and bp_names != model.to_dict()["regressors"]:
            raise InputError(f"--breakpoints {breakpoints}: the file is for regressors {bp_names}, the fit has "
                             f"{model.to_dict()['regressors']}")
        with outset:
            outset.write_text(output, model.to_json())
        d = model.to_dict()
        parts = f" in {len(d['additive']['parts'])} additive parts ({d['additive']['spec']})" if "additive" in d else ""
        _say(
            f"fitted n = {model.grid_.n} ({', '.join(d['regressors'])}), N = {model.grid_.n_vertices} weights{parts}, "
            f"sigma = {model.sigma_:.3g}{' (CV)' if sigma is None else ''}, "
            f"train RMSE = {', '.join(f'{t}: {v:.4g}' for t, v in d['fit']['train_rmse'].items())}"
        )
        if "recurrence" in d:
            rf = d["recurrence"]["fit"]
            _say(f"dynamical sensor (Mz = {mz}): series-parallel RMSE "
                 f"{', '.join(f'{t}: {v:.4g}' for t, v in rf['series_parallel_rmse'].items())}; closed-loop RMSE "
                 f"{', '.join(f'{t}: {v:.4g}' for t, v in rf['closed_loop_rmse'].items())} "
                 f"({rf['iterations_used']} of {refine} refinement(s) kept)")
        from pwas_hdl.fit.regularized_lsq import solve_warnings

        for line in solve_warnings(getattr(model, "solve_", None), model.sigma_):
            _warn(line)
        if not mz:
            from pwas_hdl.fit.training_data import training_data_warnings

            for line in training_data_warnings(model, table, traj_col, u, y, z, given_domain=dom is not None,
                                               classify=classify):
                _warn(line)
        if not classify and not bank:
            from pwas_hdl.fit.training_data import class_label_note

            note = class_label_note(z, tgts)
            if note:
                _say(note)
        if traj_warning:
            _warn(traj_warning)
        _say(f"wrote {output}")


@app.command("fit-map")
def fit_map_cmd(
    data: Annotated[Path, typer.Argument(metavar="SAMPLES", help="CSV of samples of the map: its argument columns and its value columns.")],
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="Model file to write (JSON). Required.", show_default=False)] = None,
    inputs: Annotated[Optional[list[str]], typer.Option("-u", "--inputs", help="Argument column(s) that are inputs u (current sample).")] = None,
    outputs: Annotated[Optional[list[str]], typer.Option("-y", "--outputs", help="Argument column(s) that are measured outputs y (current sample).")] = None,
    state: Annotated[Optional[list[str]], typer.Option("--state", help="Argument column(s) that are the observer state z(t): the model becomes a recurrent sensor z(t+1) = f(u(t), y(t), z(t)) (one per -z column, same order).")] = None,
    targets: Annotated[Optional[list[str]], typer.Option("-z", "--targets", help="Column(s) holding the map's values f (with --state: z(t+1)).")] = None,
    partitions: Annotated[str, typer.Option("-p", "--partitions", help="Intervals per argument: one integer or a comma list (order: -u, -y, --state).")] = "7",
    sigma: Annotated[float, typer.Option("--sigma", help="Tikhonov weight (zero order, unnormalised).")] = 1e-8,
    test_fraction: Annotated[float, typer.Option("--test-fraction", help="Share of the samples held out to measure the max / RMS approximation error (0: measured on the fitting samples).")] = 0.2,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the hold-out split.")] = 0,
    domain: Annotated[Optional[str], typer.Option("--domain", help="The box 'lo:hi,lo:hi,...' (one pair per argument; default the samples' bounding box).")] = None,
    z0: Annotated[Optional[str], typer.Option("--z0", help="With --state: the initial state z(0), one value per state (comma list). Required with --state.")] = None,
    blank_rows: Annotated[str, typer.Option("--blank-rows", help="A blank row in SAMPLES: error, or break.")] = "error",
) -> None:
    """Fit a PWAS approximation of a map f from samples and write a model file (issue 13).

    The arguments are the -u columns, then the -y columns, then the --state columns. Without
    --state the model is a static sensor of the current samples (Mu = 1 / My = 1, usable by
    generate / simulate); with --state it is a recurrent sensor (Mz = 1, lead 1): predict runs
    z(t+1) = f(u(t), y(t), z(t)) from --z0. The max and RMS error on the held-out samples are
    printed and stored (model key map_fit).
    """
    with _user_errors():
        from pwas_hdl.fit.map_approximation import fit_map_samples, recurrent_sensor_from_map, static_sensor_from_map

        output = _required(out, "-o/--out", "the model file to write")
        outset = OutputSet(inputs=[(data, "SAMPLES")])
        outset.add(output, "-o/--out")
        ins, outs, sts, tgts = _names(inputs), _names(outputs), _names(state), _names(targets)
        if not tgts:
            raise InputError("give the column(s) of the map's values with -z/--targets")
        if not (ins or outs or sts):
            raise InputError("give the map's argument columns with -u/--inputs, -y/--outputs and/or --state")
        if sts and len(sts) != len(tgts):
            raise InputError(f"--state names {len(sts)} column(s) but -z/--targets {len(tgts)}: one next-state column per state")
        if sts and z0 is None:
            raise InputError("--state needs the initial state: give --z0 (one value per state)")
        if z0 is not None and not sts:
            raise InputError("--z0 needs --state (a recurrent map)")
        init = _number_list(z0, "--z0", "one number per --state column (comma-separated)") if z0 is not None else None
        if init is not None and len(init) != len(sts):
            raise InputError(f"--z0 needs one value per state ({len(sts)}), got {len(init)}")
        if init is not None and not all(np.isfinite(init)):
            raise InputError(f"--z0 values must be finite numbers, got {z0!r}")
        cols = ins + outs + sts
        _distinct_columns(("-u/--inputs", ins), ("-y/--outputs", outs), ("--state", sts), ("-z/--targets", tgts))
        if not (0.0 <= test_fraction <= 0.9):
            raise InputError(f"--test-fraction must be in [0, 0.9], got {test_fraction}")
        parts = _int_list(partitions, "--partitions")
        box = None
        if domain is not None:
            try:
                pairs = [tuple(float(v) for v in p_.split(":")) for p_ in domain.replace(" ", "").split(",")]
                box = ([a for a, _ in pairs], [b for _, b in pairs])
            except ValueError:
                raise InputError(f"--domain must look like 'lo:hi,lo:hi,...', got {domain!r}") from None
            if len(pairs) != len(cols):
                raise InputError(f"--domain gives {len(pairs)} interval(s) for {len(cols)} argument(s); give one lo:hi "
                                 f"a column, in the order -u/--inputs, -y/--outputs, --state ({', '.join(cols)})")
        table = read_csv(data, blank_rows=blank_rows)
        x = table.numeric(cols)
        fx = table.numeric(tgts)
        for t, col in zip(tgts, fx.T):  # named here; fit_map_samples checks f(x) as a whole
            check_values(f"{data}: column {t!r}", col, "rescale it (divide it by a power of ten)")
        approx = fit_map_samples(x, fx, parts[0] if len(parts) == 1 else parts, box=box, sigma=sigma,
                                 test_fraction=test_fraction, seed=seed)
        if sts:
            model = recurrent_sensor_from_map(approx, ins, outs, sts, init)
        else:
            model = static_sensor_from_map(approx, ins, outs, tgts)
        text = model.to_json()
        with outset:
            outset.write_text(output, text)
        e = approx.errors
        names = tgts  # the errors are of the value columns (with --state: the next states z(t+1))
        _say(f"fitted a PWAS of {', '.join(tgts)} over {', '.join(cols)}: n = {approx.grid.n}, N = {approx.grid.n_vertices} weights; "
             f"error on {e['test']}: max {', '.join(f'{t}: {v:.4g}' for t, v in zip(names, e['max']))}, RMS "
             f"{', '.join(f'{t}: {v:.4g}' for t, v in zip(names, e['rms']))}")
        _say(f"wrote {output}")


@app.command()
def predict(
    model_path: ModelArg,
    data: Annotated[Path, typer.Argument(metavar="DATA", help="CSV with the model's input/output columns.")],
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="CSV of estimates to write. Required.", show_default=False)] = None,
    traj_col: TrajColOpt = None,
    output_old: Annotated[Optional[Path], _hidden("--output")] = None,
    blank_rows: BlankRowsOpt = "error",
) -> None:
    """Estimate the targets for every row of DATA that has a full regressor.

    Writes columns: row (0-based data row), TARGET_hat for each target, out_of_domain (1 when a
    regressor was outside the model's domain and was clamped). When DATA holds the target column
    (or TARGET_true), the RMSE of the estimate against it is printed. A classifier (fit --classify)
    writes LABEL_hat and LABEL_score_K instead and prints the accuracy and F1 against LABEL_true or
    LABEL; a value there that is none of the model's classes is refused (nothing written).
    """
    with _user_errors():
        output = _required(_merge("-o/--out", out, output=output_old), "-o/--out", "the CSV file to write")
        from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor  # imports scikit-learn: only when needed
        outset = OutputSet(inputs=[(model_path, "MODEL"), (data, "DATA")])
        outset.add(output, "-o/--out")
        model = PWASVirtualSensor.load(model_path)
        ins, outs, tgts = model.signal_names()
        table = read_csv(data, blank_rows=blank_rows)
        classifier = getattr(model, "classifier_", None)
        check_trajectory_column(table, traj_col, [*ins, *outs], [classifier["target"]] if classifier else tgts)
        traj_warning = _trajectory_warning(table, traj_col, [*ins, *outs])
        if model.memory > 1:  # a run shorter than the lags: named with its file lines
            check_trajectory_lengths(table, traj_col, model.memory, "the observer bank needs"
                                     if getattr(model, "front_end_", None) is not None else "the lags need")
        u = select_signals(table, ins, traj_col) if model.n_inputs else None
        y = select_signals(table, outs, traj_col) if model.n_outputs else None
        lags = model.lags_
        measured = lags is not None and lags.recurrent and model.initial_state_rule_ == "measured"
        zin = select_signals(table, tgts, traj_col) if measured else None
        zhat, flags = model.predict(u, y, return_flags=True, z=zin)
        first = lags.start if measured else model.memory - 1
        lead = int(getattr(model, "lead_", 0))
        spans = split_trajectories(table, traj_col)
        rows = np.concatenate([np.arange(sl.start, sl.stop)[first:] for sl in spans])
        # row t of a recurrent map sensor estimates z(t + lead): compared with the row `lead` later
        ends = np.concatenate([np.full(max(0, sl.stop - sl.start - first), sl.stop) for sl in spans])
        scored = rows + lead < ends
        cols: dict = {"row": rows}
        # the scores against DATA's reference columns are computed before the CSV is written: a bad cell
        # there (NaN, text) is refused with nothing written
        scores: list[str] = []
        classifier = getattr(model, "classifier_", None)
        if classifier is not None:
            from pwas_hdl.fit import classifier as clf

            ct, classes = classifier["target"], classifier["classes"]
            label = clf.decide(zhat, classes)
            cols[f"{ct}_hat"] = clf.label_column(label, classes)
            for i, c in enumerate(classes):
                cols[clf.score_column(ct, c)] = zhat[:, i]
            truth = clf.true_labels(table, ct, classes, rows)  # LABEL_true or LABEL; a value no class is refused
            if truth is not None:
                ref, lab = truth
                sc = clf.class_scores(lab, label, classes)
                f1 = ", ".join(f"{clf.label_text(c)}: {v:.4f}" for c, v in zip(classes, sc["f1"]))
                scores.append(f"accuracy of {ct}_hat against column {ref}: {sc['accuracy']:.4f} over {rows.size} samples; F1 per class {f1}")
        else:
            for i, t in enumerate(tgts):
                cols[f"{t}_hat"] = zhat[:, i]
            for i, t in enumerate(tgts):
                ref = table.reference_column(t)
                if ref is not None:
                    ztrue = table.numeric([ref])[rows[scored] + lead, 0]
                    rmse = _rmse(zhat[scored, i], ztrue)
                    shift = f" (row t estimates {t}(t+{lead}))" if lead else ""
                    scores.append(f"RMSE of {t}_hat against column {ref}: {rmse:.6g} over {int(scored.sum())} samples{shift}")
        cols["out_of_domain"] = flags
        with outset:
            outset.write_text(output, format_csv(cols))
        for line in scores:
            _say(line)
        if flags.any():
            _warn(f"warning: {int(flags.sum())} of {flags.size} regressors were outside the domain (clamped)")
        if traj_warning:
            _warn(traj_warning)
        _say(f"wrote {output} ({rows.size} rows)")


@app.command()
def info(model_path: Annotated[Path, typer.Argument(metavar="MODEL", help="Model file.")]) -> None:
    """Print a summary of a model file as JSON (everything but the weights)."""
    with _user_errors():
        from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor  # imports scikit-learn: only when needed
        model = PWASVirtualSensor.load(model_path)
        d = model.to_dict()
        d.pop("weights")
        d["N"] = model.grid_.n_vertices
        d["n"] = model.grid_.n
        d["weight_range"] = [float(model.weights_.min()), float(model.weights_.max())]
        stdout.print_json(json.dumps(d))


@app.command()
def generate(
    model_path: Annotated[Path, typer.Argument(metavar="MODEL", help="Model file written by `pwas-hdl fit`, or an estimator file (make-data switched-linear --estimator-out): seed 003's estimator top (options --name, --ports, --input-bits).")],
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="Folder to write (created; in a folder an earlier `generate` made, only its files are replaced: sim/, synth/ and your files stay). Required.", show_default=False, metavar=FOLDER_METAVAR)] = None,
    design: Annotated[str, typer.Option("--design", help="core: the PWAS core (input = regressor codes); sensor: lag bank + core (input = one (u, y) sample per transfer), or for an observer-bank model (fit --front-end observer-bank) the observer bank + residual features (+ the --mu/--my taps) + core; of a recurrent model (fit --mz, fit-map --state) sensor is the recurrent top: lag bank + core + feedback of the estimates, II = latency (manifest design recurrent; use --input-bits 16). An additive model (fit --additive) gets one core per part (parallel or serial), summed before one rounding. A non-uniform model (fit --breakpoints quantile-pow2) gets a warp of every input code in front of the core (one more register; core, sensor, recurrent, parallel or serial; of an observer-bank sensor, between its features (and --mu/--my taps) and the core; manifest warp). A classifier (fit --classify; also additive or non-uniform) gets an argmax stage after the core or the sum (parallel or serial).")] = "core",
    name: Annotated[Optional[str], typer.Option("--name", help="Verilog module name (default pwas_core / pwas_sensor).")] = None,
    memory: Annotated[Optional[str], typer.Option("--memory", help="Weight memory: banked (n+1 banks, about N words), replicated (n+1 copies of N words) or corner (2**n banks addressed by the cell alone). Default: banked, except --goal latency on ECP5, which takes replicated where its bit-field addresses and its block RAMs fit the floorplan's row (a plain parallel core or sensor, power-of-two strides as p = 7, n > 1; manifest generator.options.memory says which).", show_default=False)] = None,
    pipeline: Annotated[Optional[str], typer.Option("--pipeline", help="Pipeline preset: min, short, balanced (default), max or max-lut (the registers themselves; see --goal).")] = None,
    goal: Annotated[Optional[str], typer.Option("--goal", help="Choose the pipeline by what matters: latency (fewest ns input to output), throughput (highest clock, II = 1) or balanced (the default). Each is a pipeline preset measured on ECP5 (README hardware tables). One of --goal, --pipeline, --clock-mhz.")] = None,
    memory_init: Annotated[str, typer.Option("--memory-init", help="inline: weights inside the Verilog; readmemh: the Verilog loads the .hex files (relative names).")] = "inline",
    architecture: Annotated[str, typer.Option("--architecture", help="parallel: n+1 memories and multipliers per target, one sample per clock (II = 1); serial: one multiplier per target and one memory of N words, n+1 clocks per sample (II = n+1), bit-exact with parallel, for small FPGAs (iCE40 UP5K); for an additive model (fit --additive) every part on the serial core, all parts taking each sample together (II = the largest part's n+1); for a classifier (fit --classify; plain, additive or non-uniform) the argmax stage after the serial core or sum (one class index every II clocks, its registers in the latency); for an observer-bank sensor also the time-multiplexed bank (--bank-lanes state-update units, II = the manifest's front_end.cycles_per_sample); for a recurrent model (fit --mz) the serial core inside the recurrent top (one sample in flight: II = latency, the serial core's); for an estimator file (seed 003) every row of the bank, detector and switched observer on --bank-lanes units of n+2 variable multipliers, bit-exact, II = the manifest's estimator.cycles_per_sample (13 for 3 modes x 2 states and one lane): parallel stays the default (II 1, more samples per second), serial fits where parallel's multipliers do not (LFE5U-45F, iCE40 HX8K). With --clock-mhz the search runs over the registers the serial core takes.")] = "parallel",
    isqrt_every: Annotated[Optional[int], typer.Option("--isqrt-every", help="Observer-bank sensor with the 11b feature map: digit steps of each feature's integer square root between pipeline registers (1 .. the root's digit steps - 1; default 3). Smaller: a higher clock, more registers and cycles of latency (measured on ECP5, the README's observer-bank section: 77.4 MHz at 3, 91.9 at 2 for a 2-observer bank). Manifest front_end.isqrt_every / isqrt_registers. Not given, --clock-mhz searches again with 2, then 1 when the best pipeline misses inside the root.")] = None,
    bank_lanes: Annotated[Optional[int], typer.Option("--bank-lanes", help="Observer-bank sensor with --architecture serial: state-update units sharing the N_theta x M observer updates (1 .. N_theta; default 1: about N_theta*M clocks per sample). An estimator file with --architecture serial: row units 1 .. the number of modes sharing the bank's modes (lane 0 also runs the switched observer; default 1).")] = None,
    ports: Annotated[str, typer.Option("--ports", help="Port names: axis (aclk, aresetn active low, s_axis_tvalid/tready/tdata, m_axis_tvalid/tready/tdata) or amaranth (clk, rst active high, in__*, out__*).")] = "axis",
    input_bits: Annotated[int, typer.Option("--input-bits", help="Width of the signed input codes (of a non-uniform model: the codes in front of the warp).")] = 12,
    input_fill: Annotated[float, typer.Option("--input-fill", help="Largest fraction of the input code range the domain may take (the rest detects out-of-range).")] = 0.9,
    input_scale: Annotated[str, typer.Option("--input-scale", help="pow2: one grid cell = 2^F input codes, no arithmetic (a power-of-two p uses at most half the code range); exact: the domain takes the whole --input-fill for any p, with a constant multiplier per input in the front end.")] = "pow2",
    weight_bits: Annotated[Optional[int], typer.Option("--weight-bits", help="Weight width (default: the fewest bits that hold every weight).")] = None,
    weight_frac: Annotated[Optional[int], typer.Option("--weight-frac", help="Weight fraction bits (default: rounding noise <= 5 % of the training RMSE).")] = None,
    output_bits: Annotated[Optional[int], typer.Option("--output-bits", help="Output width (default: never saturates).")] = None,
    output_frac: Annotated[Optional[int], typer.Option("--output-frac", help="Output fraction bits (default: weight fraction + 1, at most the exact product's: input fraction + weight fraction).")] = None,
    overflow: Annotated[str, typer.Option("--overflow", help="Weights that do not fit: error (refuse) or saturate (with a warning).")] = "error",
    rounding: Annotated[str, typer.Option("--rounding", help="Rounding of weights and output: half_up or truncate.")] = "half_up",
    state_bits: Annotated[Optional[int], typer.Option("--state-bits", help="Observer-bank sensor or estimator file: width B_s of the observer states (default: from the l1 state bound; smaller saturates, flagged, and the error bound then does not hold).")] = None,
    state_frac: Annotated[Optional[int], typer.Option("--state-frac", help="Observer-bank sensor or estimator file: fraction bits F_s of the states (default: from the noise budget; at least the input fraction bits).")] = None,
    coef_frac: Annotated[Optional[int], typer.Option("--coef-frac", help="Observer-bank sensor or estimator file: fraction bits F_c of the observer coefficients (default: from the noise budget).")] = None,
    input_headroom: Annotated[Optional[float], typer.Option("--input-headroom", help="Observer-bank sensor or estimator file: H, the input codes hold (-H, H) (normalised units for a bank, physical for an estimator; default 8). Smaller: more input fraction bits, narrower datapaths.")] = None,
    clock_mhz: Annotated[Optional[float], typer.Option("--clock-mhz", help="Choose the pipeline by timing closure instead of --pipeline: the shallowest one whose fmax, measured by place and route (nextpnr, --fpga), reaches this clock in MHz. One P&R run per candidate tried (ECP5 ~25 s, iCE40 ~100 s for a Lorenz-size core).")] = None,
    fpga: Annotated[str, typer.Option("--fpga", help="FPGA family of --clock-mhz and --goal: ecp5 (LFE5U-45F) or ice40 (HX8K; --goal throughput then splits the LUT multipliers: preset max-lut).")] = "ecp5",
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
    outdir_old: Annotated[Optional[Path], _hidden_dir("--outdir")] = None,
    target_mhz_old: Annotated[Optional[float], _hidden("--target-mhz")] = None,
) -> None:
    """Generate the Verilog, weight memory (.hex), manifest.json and report.md of a model.

    Same inputs give byte-identical files. Nothing is written unless the whole design builds.
    A classifier model (fit --classify) gets an argmax stage after the core: the class index
    (ties to the lowest class) in the top bits of the output payload, field class_index; on a
    non-uniform partition (--breakpoints quantile-pow2) the warp goes in front of the core, also
    in a recurrent model's top (fit --mz; II = latency).
    """
    from pwas_hdl.design.generate import generate as _generate

    with _user_errors():
        outdir = _required(_merge("-o/--out", out, outdir=outdir_old), "-o/--out", "the folder to write")
        target_mhz = _merge("--clock-mhz", clock_mhz, target_mhz=target_mhz_old)
        bank_formats = {k: v for k, v in (("state_bits", state_bits), ("state_frac", state_frac), ("coef_frac", coef_frac),
                                          ("input_headroom", input_headroom)) if v is not None}
        if target_mhz is None:
            _executor(workers, scheduler)  # checks --workers / --scheduler (unused without --clock-mhz: still refused when bad)
            if workers is not None or scheduler is not None:
                _say(f"note: {'--workers' if workers is not None else '--scheduler'} runs the place-and-route candidates "
                     "of --clock-mhz; without it there are none, the design is built in this process")
            with _progress("building the design"):
                gd = _generate(
                    model_path, outdir, design=design, name=name, memory=memory, pipeline=pipeline, memory_init=memory_init, ports=ports,
                    architecture=architecture, bank_lanes=bank_lanes, isqrt_every=isqrt_every, input_bits=input_bits, input_fill=input_fill, input_scale=input_scale, weight_bits=weight_bits, weight_frac=weight_frac,
                    output_bits=output_bits, output_frac=output_frac, overflow=overflow, rounding=rounding, goal=goal,
                    fpga_target=fpga, **bank_formats,
                )
        else:
            with _executor(workers, scheduler) as ex:
                gd = _generate(
                    model_path, outdir, design=design, name=name, memory=memory, pipeline=pipeline, memory_init=memory_init, ports=ports,
                    architecture=architecture, bank_lanes=bank_lanes, isqrt_every=isqrt_every, input_bits=input_bits, input_fill=input_fill, input_scale=input_scale, weight_bits=weight_bits, weight_frac=weight_frac,
                    output_bits=output_bits, output_frac=output_frac, overflow=overflow, rounding=rounding,
                    target_mhz=target_mhz, fpga_target=fpga, goal=goal,
                    progress=_say, executor=ex, **bank_formats,
                )
        man = gd.manifest
        if man["design"] == "estimator":  # seed 003's estimator (an estimator file): no PWAS core
            e = man["estimator"]
            _say(f"{man['top']}: seed 003 estimator, {e['modes']} modes, {e['states']} states, latency {man['latency_cycles']} "
                 f"cycle{'s' if man['latency_cycles'] != 1 else ''}, II {man['ii']}, states s{e['formats']['state_bits']}.{e['formats']['state_frac']}, "
                 + (f"|x_hat - float| <= {e['error_bound']['state']:.4g} where the modes agree" if e["error_bound"]["state"] is not None
                    else "no state bound (max_i ||A_i - K_i C_i||_inf >= 1)"))
            if e.get("state_may_saturate"):
                sf = f"s{e['formats']['state_bits']}.{e['formats']['state_frac']}"
                if getattr(gd.model, "state_bound_proven", True):  # a --state-bits below the proven bound's width
                    _warn(f"warning: the states ({sf}) may saturate: the stated bounds do not hold in those samples (the "
                          "output state_saturated flags them); leave --state-bits out for the width of the state bound")
                else:  # no invariant box: the default width holds each mode's own bound only
                    _warn(f"warning: the states ({sf}) may saturate: no bound of the switched observer's states holds over "
                          "every mode sequence (the modes' A_i - K_i C_i have no common contraction; the width holds each "
                          "mode's own bound); the output state_saturated flags those samples, where the stated bounds do not hold")
            _say(f"wrote {outdir}/ ({len(gd.files)} files)")
            return
        from pwas_hdl.design.generate import design_summary

        eb = man["error_bound"]
        mem = man["memory"]
        _say(
            f"{man['top']}: {design_summary(man)}, latency {man['latency_cycles']} cycles, II {man['ii']}, memory {mem['words']} words "
            f"({mem['words'] / mem['n_vertices']:.3g} N) x {mem['word_bits']} bits, error bound {eb['lsb']:.4g} LSB "
            f"= {eb['physical']:.4g}"
        )
        fe = man.get("front_end") or {}
        if fe.get("state_may_saturate"):
            f = fe["formats"]
            _warn(f"warning: the observer states (s{f['state_bits']}.{f['state_frac']}) are narrower than the "
                  f"{fe['state_bits_needed']} bits of their bound: they may saturate, and the error bound does not hold "
                  "then; leave --state-bits out (or give at least that many bits)")
        if mem["words"] >= INLINE_NOTE_WORDS and (mem.get("init") or {}).get("kind") != "readmemh":
            _say(f"note: {mem['words']} weight words are inline in the Verilog; with --memory-init readmemh they stay in "
                 f"the .hex files, which simulators load much faster")
        from pwas_hdl.design.report import STALE_NOTE, stale_results

        stale = stale_results(gd.outdir)
        if stale:
            _say(f"kept {', '.join(stale)} ({STALE_NOTE}; `pwas-hdl report` marks them)")
        tm = man.get("timing")
        if tm:
            c = tm["candidates"][tm["chosen"]]
            _say(f"timing: {c['latency_cycles']} cycles ({c['label']}) reach {c['fmax_mhz']:.1f} MHz >= {tm['target_mhz']:g} MHz "
                      f"on {tm['part']} = {c['latency_ns']:.1f} ns")
        _say(f"wrote {outdir}/ ({len(gd.files)} files)")


@app.command()
def synth(
    outdir: Annotated[Path, typer.Argument(metavar="OUTDIR", help="Folder written by `pwas-hdl generate`.")],
    fpga: Annotated[Optional[str], typer.Option("--fpga", help="FPGA family: ecp5 (yosys + nextpnr-ecp5, the default), ice40 (yosys + nextpnr-ice40) or generic (yosys only, 4-input LUTs).", show_default=False)] = None,
    device: Annotated[Optional[str], typer.Option("--device", help="Device (ice40: hx8k, hx1k, lp8k, up5k, ...; ecp5: 25k, 45k, 85k, ...). Default: ice40 hx8k, ecp5 45k.")] = None,
    package: Annotated[Optional[str], typer.Option("--package", help="Package (default per device).")] = None,
    clock_mhz: Annotated[Optional[float], typer.Option("--clock-mhz", help="Clock constraint in MHz for place and route (default: nextpnr's).")] = None,
    seed: Annotated[int, typer.Option("--seed", help="Placer seed, 0 .. 2^63-1.")] = 1,
    harness: Annotated[Optional[bool], typer.Option("--harness/--no-harness", help="Place and route inside the timing harness that registers every port (the default on ecp5 and ice40; refused with generic, which has no place and route), so fmax covers the input and output paths, as generate --clock-mhz and benchmarks/hw_tables.py measure it; --no-harness: the bare design, register-to-register paths only.", show_default=False)] = None,
    floorplan: Annotated[str, typer.Option("--floorplan", help="ECP5 hard-block placement: auto (default) fixes the block RAMs to the central EBR row and the multipliers to the DSP row below it where that was measured to help: the latency-first pipeline (--goal latency; mul_in without mem_out) with the banked or replicated memory on the LFE5U-45F (--device 45k), at most 36 of each; none: nextpnr places them freely. synth.json's floorplan records the sites or why there are none.")] = "auto",
    json_out: Annotated[Optional[Path], typer.Option("--json", help="Also copy the JSON report here.")] = None,
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="Folder for the tool files and results (default OUTDIR/synth/FPGA, where `report` finds them).", show_default=False, metavar=FOLDER_METAVAR)] = None,
    target_old: Annotated[Optional[str], _hidden("--target")] = None,
    freq_old: Annotated[Optional[float], _hidden("--freq")] = None,
) -> None:
    """Synthesize (and place and route) a generated design with open tools from PyPI (YoWASP).

    Writes OUTDIR/synth/FPGA/synth.json (LUTs, FFs, carries, DSPs, block RAMs and bits, fmax
    after place and route, latency in ns = latency cycles / fmax) and synth.txt.
    """
    from pwas_hdl.flow.synthesis import synth_summary_text, synthesize

    with _user_errors():
        _design_folder(outdir)
        family = _merge("--fpga", fpga, target=target_old)
        family = "ecp5" if family is None else family  # an empty --fpga is refused by synthesize, not taken for ecp5
        freq = _merge("--clock-mhz", clock_mhz, freq=freq_old)
        from pwas_hdl.design.manifest import folder_inputs

        outset = OutputSet(inputs=folder_inputs(outdir))  # no --json over the Verilog or a hex file it reads
        if json_out is not None:
            outset.add(json_out, "--json")
        if out is not None:
            check_output_path(out, "-o/--out", kind="folder")
        res = synthesize(outdir, family, device=device, package=package, freq_mhz=freq, seed=seed, workdir=out,
                         progress=_say, harness=harness, floorplan=floorplan)
        if json_out is not None:
            with outset:
                outset.write_text(json_out, json.dumps(res, indent=2) + "\n")
        stdout.print(synth_summary_text(res), highlight=False, markup=False)


@app.command()
def simulate(
    outdir: Annotated[Path, typer.Argument(metavar="OUTDIR", help="Folder written by `pwas-hdl generate` (core, sensor or recurrent design).")],
    data: Annotated[Path, typer.Argument(metavar="DATA", help="CSV with the model's input/output columns (and optionally the target or TARGET_true).")],
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="CSV of the per-sample hardware outputs to write (default: OUTDIR/sim/SIMULATOR.csv, beside its summary where `report` reads it).", show_default=False)] = None,
    simulator: Annotated[Optional[str], typer.Option("--simulator", help="icarus or verilator (default: icarus; verilator with --engine native).")] = None,
    engine: Annotated[str, typer.Option("--engine", help="cocotb: the cocotb bench (reference, debug trace); native: a generated Verilator C++ bench (same checks and outputs, millions of samples/s; Verilator only).")] = "cocotb",
    summary: Annotated[Optional[Path], typer.Option("--json", help="JSON summary to write (default: the -o/--out file with the suffix .json).")] = None,
    traj_col: Annotated[Optional[str], typer.Option("--traj-col", help="Trajectory column, as for fit (the sensor design is reset between trajectories).")] = None,
    stall: Annotated[float, typer.Option("--stall", help="Probability of a random bubble on the input and of backpressure on the output in each cycle (0 = none: latency and II are measured at full speed).")] = 0.0,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the random stalls (an integer >= 0).")] = 0,
    build_dir: Annotated[Optional[Path], typer.Option("--build-dir", help="Cache of simulator builds (default: $PWAS_HDL_SIM_CACHE or ~/.cache/pwas-hdl/sim); a design is built once and reused.", metavar=FOLDER_METAVAR)] = None,
    waves: Annotated[bool, typer.Option("--waves", help="Record waveforms (Icarus: FST, Verilator: VCD) next to the build; the path is in the summary.")] = False,
    output_old: Annotated[Optional[Path], _hidden("--output")] = None,
    blank_rows: BlankRowsOpt = "error",
) -> None:
    """Replay DATA through the generated RTL in a simulator (cocotb) and check it bit for bit.

    Writes the -o/--out CSV (one row per hardware output: row, TARGET_hw, TARGET_bittrue, TARGET_float,
    out_of_range, mismatch (1 where the RTL differs from the bit-true model)) and a JSON summary: samples, mismatches against the bit-true model, the largest
    error against the float model (LSB and physical units), the RMSEE of the hardware estimate
    against TARGET_true (or TARGET) when DATA has it, the measured latency (cycles) and II, and
    the simulation speed (samples/s). Exit status 1 when the RTL differs from the bit-true model.
    A classifier design adds C_hat_hw, C_hat_bittrue, C_hat_float (class labels of the RTL's
    class_index, of the bit-true and of the float argmax; the class is compared too) and scores them
    against C_true or C when DATA has it, as predict does (a value there that is none of the
    classes is refused before the simulator runs).
    A recurrent design runs the recurrent bench (one reset per trajectory) against the bit-true
    recurrence; it adds estimate_of_row (row + lead), TARGET_float is the float recurrence, and
    --engine native is refused.
    """
    from pwas_hdl.verify.simulation import resolve_simulator

    made = None  # OUTDIR/sim, made for the default -o: removed again if the command ends with nothing in it
    try:
        with _user_errors():
            _design_folder(outdir)
            output = _merge("-o/--out", out, output=output_old)
            if output is None:  # the design folder's results, where `report` reads them
                from pwas_hdl.design.report import SIM_RESULTS

                output = Path(outdir) / SIM_RESULTS / f"{resolve_simulator(simulator, engine)}.csv"
                if not output.parent.exists():
                    output.parent.mkdir()
                    made = output.parent
            _simulate(outdir, data, output, simulator, engine, summary, traj_col, stall, seed, build_dir, waves, blank_rows)
    finally:
        if made is not None and made.is_dir() and not any(made.iterdir()):
            made.rmdir()


def _simulate(outdir: Path, data: Path, output: Path, simulator: Optional[str], engine: str, summary: Optional[Path],
              traj_col: Optional[str], stall: float, seed: int, build_dir: Optional[Path], waves: bool, blank_rows: str) -> None:
    """The body of ``simulate``, with the CSV ``output`` decided."""
    from pwas_hdl.verify.simulation import simulate_data

    # DATA is read once: for the run warnings here and, passed as the Table, for the replay. A file that cannot be read
    # is passed as its path: simulate_data reports it, after its checks of the options and output paths (as before)
    try:
        table = read_csv(data, blank_rows=blank_rows)
    except (OSError, ValueError):
        table = None
    traj_warning = None
    if table is not None:
        try:  # a run index without --traj-col, or a run label that comes back after another run
            traj_warning = _trajectory_warning(table, traj_col, ())
        except ValueError:  # e.g. a --traj-col that DATA lacks: the replay reports it
            pass
    res = simulate_data(
        outdir, table if table is not None else data, output, simulator=simulator, engine=engine, summary_path=summary,
        traj_col=traj_col, stall=stall, seed=seed, cache_dir=build_dir, waves=waves,
        progress=_say, blank_rows=blank_rows,
    )
    s = res["summary"]
    stdout.print_json(json.dumps(s))
    clamped, estimates = s.get("out_of_range"), s.get("samples")
    if isinstance(clamped, int) and clamped > 0:  # as predict warns of out_of_domain: the same regressors, clamped
        _warn(f"warning: {clamped} of {estimates} estimates had a regressor outside the domain (clamped; column "
              f"out_of_range of {output}): there the sensor extrapolates from the domain's edge")
    if traj_warning:
        _warn(traj_warning)
    _say(f"wrote {output} and {res['summary_path']}")
    fails = s["checks"]["failures"]  # mismatches, testbench failures, latency / II against the manifest
    if fails:
        more = f" (and {len(fails) - 1} more, see {res['summary_path']})" if len(fails) > 1 else ""
        raise CheckFailed(f"{fails[0]}{more}; the outputs are in {output}")


@app.command("export-testbench")
def export_testbench(
    outdir: Annotated[Path, typer.Argument(metavar="OUTDIR", help="Folder written by `pwas-hdl generate`.")],
    output: Annotated[Optional[Path], typer.Option("-o", "--out", help="Folder to write (default OUTDIR/tb; replaced only if an earlier export made it).", metavar=FOLDER_METAVAR)] = None,
    samples: Annotated[int, typer.Option("--samples", help="Input transfers of the stimulus (random points, plus vertices, faces, corners, out-of-domain codes).")] = 1000,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the stimulus and of the stall pattern.")] = 0,
    stall: Annotated[float, typer.Option("--stall", help="Probability of a bubble / of backpressure per cycle in the stalled passes.")] = 0.3,
) -> None:
    """Write a self-checking plain-Verilog testbench of a generated design (no Python needed to run it).

    The folder holds tb_TOP.v, the input and expected-output vectors ($readmemh, from the bit-true
    model), a copy of the design and run_icarus.sh / run_verilator.sh. The testbench prints PASS or
    FAIL and exits non-zero on failure ($fatal).
    """
    from pwas_hdl.verify.testbench import export_testbench as _export

    with _user_errors():
        _design_folder(outdir)
        if output is not None:
            check_output_path(output, "-o/--out", kind="folder")
        res = _export(outdir, output, samples=samples, seed=seed, stall=stall)
    stdout.print_json(json.dumps(res))
    _say(f"wrote {res['outdir']}/ ({len(res['files'])} files); run it with {res['outdir']}/run_icarus.sh or run_verilator.sh")


@app.command()
def explore(
    model_path: ModelArg,
    data: Annotated[Path, typer.Argument(metavar="DATA", help="CSV with the model's input/output columns and TARGET_true or TARGET (the reference of the RMSEE; of a classifier, LABEL_true or LABEL: the true class of its error rate).")],
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="Folder for explore.json and explore.png (created if missing). Required.", show_default=False, metavar=FOLDER_METAVAR)] = None,
    traj_col: TrajColOpt = None,
    input_bits: Annotated[str, typer.Option("--input-bits", help="Input widths to sweep: comma list or A:B (inclusive).")] = "8,10,12,14,16",
    weight_frac: Annotated[Optional[str], typer.Option("--weight-frac", help="Weight fraction bits to sweep (comma list or A:B; default: generate's default -4..+4).")] = None,
    output_frac: Annotated[Optional[str], typer.Option("--output-frac", help="Output fraction bits to sweep (comma list or A:B; default: generate's default -4..+4).")] = None,
    weight_bits: Annotated[Optional[int], typer.Option("--weight-bits", help="Fixed weight width (default: the fewest bits for each point).")] = None,
    output_bits: Annotated[Optional[int], typer.Option("--output-bits", help="Fixed output width (default: the fewest bits for each point).")] = None,
    state_frac: Annotated[Optional[str], typer.Option("--state-frac", help="Observer-bank sensor: state fraction bits F_s to sweep too (comma list or A:B; default: generate's default at each input width).")] = None,
    coef_frac: Annotated[Optional[str], typer.Option("--coef-frac", help="Observer-bank sensor: coefficient fraction bits F_c to sweep too (comma list or A:B; default: generate's default at each input width).")] = None,
    state_bits: Annotated[Optional[int], typer.Option("--state-bits", help="Observer-bank sensor: fixed state width B_s (default: the width of the state bound; fewer bits may saturate).")] = None,
    input_headroom: Annotated[Optional[float], typer.Option("--input-headroom", help="Observer-bank sensor: fixed input head room H, normalised units (default 8).")] = None,
    isqrt_every: Annotated[Optional[int], typer.Option("--isqrt-every", help="Observer-bank sensor (11b map): the square root's register spacing of every point, as generate --isqrt-every (default 3); its registers count in the estimate and the latency.")] = None,
    input_fill: Annotated[float, typer.Option("--input-fill", help="As for generate.")] = 0.9,
    rounding: Annotated[str, typer.Option("--rounding", help="As for generate: half_up or truncate.")] = "half_up",
    overflow: Annotated[str, typer.Option("--overflow", help="As for generate: error (refuse the point) or saturate.")] = "error",
    memory: Annotated[str, typer.Option("--memory", help="As for generate: banked or replicated.")] = "banked",
    pipeline: Annotated[Optional[str], typer.Option("--pipeline", help="As for generate: min, short, balanced (default), max or max-lut.")] = None,
    fpga: Annotated[Optional[str], typer.Option("--fpga", help="Also synthesise the Pareto points and the default on this FPGA family: generic, ecp5 or ice40 (default: the analytic resource estimate only).", show_default=False)] = None,
    cost: Annotated[str, typer.Option("--cost", help="Cost axis of the front: total_bits, memory_bits, logic_bits, register_bits, mult_bit_products, adder_bits, dsp18 or bram18k.")] = "total_bits",
    device: Annotated[Optional[str], typer.Option("--device", help="FPGA device for --fpga ecp5/ice40 (as for synth).")] = None,
    measure_max: Annotated[Optional[int], typer.Option("--measure-max", help="With --fpga: synthesise at most this many Pareto points (spread along the front) besides the default (default 10).", show_default=False)] = None,
    synth_dir: Annotated[Optional[Path], typer.Option("--synth-dir", help="Keep the synthesised designs here (default: a temporary folder, removed).", metavar=FOLDER_METAVAR)] = None,
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
    outdir_old: Annotated[Optional[Path], _hidden_dir("--outdir")] = None,
    resources_old: Annotated[Optional[str], _hidden("--resources")] = None,
    blank_rows: BlankRowsOpt = "error",
) -> None:
    """Sweep input, weight and output word lengths: bit-true RMSEE (or error rate) against resources.

    Writes OUTDIR/explore.json (every point: formats, RMSEE against the data, deviation from the
    float model, error bound, resource estimate, Pareto flag; the refused combinations and why;
    whether generate's default formats are on the front) and OUTDIR/explore.png, and prints the
    Pareto points (and the default) as a table. Plain, additive (fit --additive) and power-of-two
    non-uniform (fit --breakpoints quantile-pow2) models, recurrent ones (fit --mz:
    the closed loop from reset on each trajectory, row t against z(t + lead)) and observer-bank
    sensors (fit --front-end observer-bank, with or without --mu/--my taps: the bit-true bank,
    features and core from reset on each trajectory, the estimate of sample k against row k; the
    cost includes the bank; --state-frac / --coef-frac sweep the bank's formats too). A classifier (fit --classify; plain, additive or non-uniform) is scored by its
    decisions: error_rate = share of the rows whose bit-true class (the argmax stage's, ties to the
    lowest class) is not the true one in column LABEL_true or LABEL, beside the float classifier's
    error rate and the share of decisions that differ from it (disagreement); the front is
    (cost, error_rate).
    """
    from pwas_hdl.flow.explore import default_verdict, explore as _explore, format_table, plot_exploration

    def ints(text: str, what: str) -> list[int]:
        t = text.replace(" ", "")
        if ":" in t:
            a, _, b = t.partition(":")
            if ":" in b or "," in t:
                raise InputError(f"{what}: {text!r} is not a range A:B (two integers, A <= B) nor a comma list")
            lo, hi = _int_list(a, what), _int_list(b, what)
            if len(lo) != 1 or len(hi) != 1 or hi[0] < lo[0]:
                raise InputError(f"{what}: {text!r} is not a range A:B with A <= B")
            check_limit(f"the number of values in {what} {text}", hi[0] - lo[0] + 1, MAX_SWEEP_POINTS, "sweep a shorter range")
            return list(range(lo[0], hi[0] + 1))
        return _int_list(t, what)

    with _user_errors():
        outdir = _required(_merge("-o/--out", out, outdir=outdir_old), "-o/--out", "the folder to write")
        family = _merge("--fpga", fpga, resources=None if resources_old == "estimate" else resources_old)
        from pwas_hdl.flow.explore import RESOURCE_MODES

        families = [m for m in RESOURCE_MODES if m != "estimate"]
        if family is not None and family not in families:
            raise InputError(f"--fpga must be one of {', '.join(families)} (omit it for the analytic estimate only), got {family!r}")
        resources = family or "estimate"
        sweep = dict(
            input_bits=ints(input_bits, "--input-bits"),
            weight_frac=ints(weight_frac, "--weight-frac") if weight_frac is not None else None,
            output_frac=ints(output_frac, "--output-frac") if output_frac is not None else None,
            state_frac=ints(state_frac, "--state-frac") if state_frac is not None else None,
            coef_frac=ints(coef_frac, "--coef-frac") if coef_frac is not None else None,
        )
        check_output_path(outdir, "-o/--out", kind="folder")
        if outdir.is_dir():
            for nm in ("explore.json", "explore.png"):
                check_output_path(outdir / nm, "-o/--out")
        with _progress("exploring formats") as update, _executor(workers, scheduler) as ex:
            res = _explore(
                model_path, data, blank_rows=blank_rows, traj_col=traj_col, **sweep, weight_bits=weight_bits, output_bits=output_bits,
                state_bits=state_bits, input_headroom=input_headroom, isqrt_every=isqrt_every,
                input_fill=input_fill, rounding=rounding, overflow=overflow, memory=memory, pipeline=pipeline,
                resources=resources, cost=cost, device=device, measure_max=measure_max, workdir=synth_dir,
                progress=lambda stage, done, total: update(done, total), executor=ex,
            )
        text = json.dumps(res, indent=1, allow_nan=False) + "\n"
        outdir.mkdir(parents=True, exist_ok=True)
        with OutputSet(inputs=[(model_path, "MODEL"), (data, "DATA")]) as outset:
            outset.add(outdir / "explore.json", "-o/--out")
            outset.add(outdir / "explore.png", "-o/--out")
            outset.write_text(outdir / "explore.json", text)
            plot_exploration(res, outset.temp_path(outdir / "explore.png"))
        stdout.print(format_table(res), highlight=False, markup=False)
        d = res["default"]
        if res["model"]["classifier"] is not None:
            f = res["float"]
            _say(f"float classifier: error rate {100 * f['error_rate']:.4g} % ({f['errors']} of {res['data']['samples']} "
                 f"samples) against column {', '.join(res['data']['reference_columns'])}")
        _say(f"{len(res['points'])} formats ({len(res['refused'])} refused), {len(res['pareto'])} on the front; "
                  f"the default {d['label']} is {default_verdict(res)}")
        _say(f"wrote {outdir / 'explore.json'} and {outdir / 'explore.png'}")


@app.command()
def report(
    outdir: Annotated[Path, typer.Argument(metavar="OUTDIR", help="Folder written by `pwas-hdl generate`.")],
    sim: Annotated[Optional[list[str]], typer.Option("--sim", help="Extra `simulate` JSON summaries (OUTDIR/sim/*.json are read anyway).")] = None,
    json_out: Annotated[Optional[Path], typer.Option("--json", help="Write the collected numbers as JSON.")] = None,
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="Write the Markdown report here (it is printed anyway).", show_default=False)] = None,
    md_old: Annotated[Optional[Path], _hidden("--md")] = None,
) -> None:
    """Accuracy, latency and resources of a generated design in one table.

    Collects the manifest and model (generate), simulation summaries (simulate) and synthesis
    results (OUTDIR/synth/FPGA/synth.json from synth).
    """
    from pwas_hdl.design.report import collect_report, report_markdown

    with _user_errors():
        _design_folder(outdir)
        from pwas_hdl.design.report import report_inputs

        markdown = _merge("-o/--out", out, md=md_old)
        sims = _names(sim)
        if sim and not sims:
            raise InputError("--sim is empty; give the path of a `simulate` JSON summary")
        outset = OutputSet(inputs=report_inputs(outdir, sims))
        for path, what in ((json_out, "--json"), (markdown, "-o/--out")):
            if path is not None:
                outset.add(path, what)
        rep = collect_report(outdir, sims)
        text = report_markdown(rep)
        with outset:
            if json_out is not None:
                outset.write_text(json_out, json.dumps(rep, indent=2) + "\n")
            if markdown is not None:
                outset.write_text(markdown, text)
        stdout.print(text, highlight=False, markup=False)


@data_app.command("lorenz")
def make_data_lorenz(
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="CSV to write (columns y, z, z_true). Required.", show_default=False)] = None,
    samples: Annotated[int, typer.Option("--samples", help="Number of samples in the -o/--out file.")] = 6000,
    test_out: Annotated[Optional[Path], typer.Option("--test-out", help="Also write the continuation of the same trajectory here (a test set).", show_default=False)] = None,
    test_samples: Annotated[int, typer.Option("--test-samples", help="Samples in the test file.")] = 2000,
    seed: Annotated[int, typer.Option("--seed", help="Random seed (initial state and noise).")] = 0,
    output_old: Annotated[Optional[Path], _hidden("--output")] = None,
    test_output_old: Annotated[Optional[Path], _hidden("--test-output")] = None,
) -> None:
    """The discrete Lorenz system of the paper (eq. 18): y = x1 + noise(0.02), z = x2*x3 + noise(20).

    The columns are y (measured output), z (the real sensor's noisy measurement) and z_true (the
    noise-free value, used for the RMSEE of eq. 17).
    """
    from pwas_hdl.systems.lorenz import lorenz

    _write_plant_data(lorenz, samples, test_samples, seed, out=out, output_old=output_old, test_out=test_out,
                      test_output_old=test_output_old)


def _write_plant_data(plant, samples: int, test_samples: int, seed: int, *, out: Optional[Path], test_out: Optional[Path],
                      output_old: Optional[Path] = None, test_output_old: Optional[Path] = None) -> None:
    """``make-data``: ``plant(total, seed=seed)`` split into the -o/--out file and the optional test file."""
    with _user_errors():
        output = _required(_merge("-o/--out", out, output=output_old), "-o/--out", "the CSV file to write")
        test_output = _merge("--test-out", test_out, test_output=test_output_old)
        _check_sample_counts(samples, test_samples)
        outset = OutputSet()
        outset.add(output, "-o/--out")
        if test_output is not None:
            outset.add(test_output, "--test-out")
        total = samples + (test_samples if test_output is not None else 0)
        check_limit("--samples + --test-samples" if test_output is not None else "--samples", total, MAX_SAMPLES,
                    "ask for fewer samples")
        d = plant(total, seed=seed)
        train, test = d.split(samples)
        with outset:
            outset.write_text(output, format_csv(train.columns()))
            if test_output is not None:
                outset.write_text(test_output, format_csv(test.columns()))
        _say(f"wrote {output} ({samples} samples, seed {seed})")
        if test_output is not None:
            _say(f"wrote {test_output} ({test_samples} samples following {output})")


@data_app.command("helicopter")
def make_data_helicopter(
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="CSV to write (columns psi_d, phi_d, phi, psi, psi_true). Required.", show_default=False)] = None,
    samples: Annotated[int, typer.Option("--samples", help="Number of samples in the -o/--out file (10 ms each).")] = 20000,
    test_out: Annotated[Optional[Path], typer.Option("--test-out", help="Also write the continuation of the same run here (a test set).", show_default=False)] = None,
    test_samples: Annotated[int, typer.Option("--test-samples", help="Samples in the test file.")] = 5000,
    seed: Annotated[int, typer.Option("--seed", help="Random seed (reference steps and noise).")] = 0,
) -> None:
    """A synthetic closed-loop 2-DOF helicopter (stand-in for the paper's CE150, Section VI-B).

    The columns are the references psi_d and phi_d (inputs u), the measured azimuth phi (output y),
    the measured elevation psi (the target z, noise 0.01 rad) and psi_true (noise-free). Fit the
    paper's Table VI sensor with `fit DATA.csv -u psi_d,phi_d -y phi -z psi --mu 2 --my 2 -p 3
    --gamma 1.1 --tikhonov 1 -o MODEL.json`. The simulation takes about 1 ms per sample.
    """
    from pwas_hdl.systems.helicopter import helicopter

    _write_plant_data(helicopter, samples, test_samples, seed, out=out, test_out=test_out)


def _plant_outputs(output: Path, test_output: Optional[Path], extra: Optional[tuple] = None) -> OutputSet:
    """The outputs of a make-data command, checked before the data are made (``extra``: (path, option, text maker))."""
    outset = OutputSet()
    outset.add(output, "-o/--out")
    if test_output is not None:
        outset.add(test_output, "--test-out")
    if extra is not None:
        outset.add(extra[0], extra[1])
    return outset


def _write_plant(output: Path, test_output: Optional[Path], train, test, what: str, extra: Optional[tuple] = None) -> None:
    with _plant_outputs(output, test_output, extra) as outset:  # all files or none
        outset.write_text(output, format_csv(train.columns()))
        if test_output is not None and test is not None:
            outset.write_text(test_output, format_csv(test.columns()))
        if extra is not None:
            outset.write_text(extra[0], extra[2]())
    _say(f"wrote {output} ({what})")
    if test_output is not None and test is not None:
        _say(f"wrote {test_output} (test run)")
    if extra is not None:
        _say(f"wrote {extra[0]} ({extra[3]})")


def _check_sample_counts(samples: int, test_samples: int) -> None:
    """Refuse a make-data ``--samples`` / ``--test-samples`` below 1 (``--test-samples`` too without ``--test-out``:
    a bad value is refused, not ignored)."""
    if samples < 1 or test_samples < 1:
        raise InputError(f"--samples and --test-samples must be >= 1, got --samples {samples}, --test-samples {test_samples}")


def _check_noise(noise: float, what: str) -> None:
    """Refuse a make-data ``--noise`` outside ``[0, MAX_NOISE]`` (NaN / inf / huge noise: NaN / inf data)."""
    if not 0 <= noise <= MAX_NOISE:
        raise InputError(f"--noise must be a finite number >= 0 and at most {MAX_NOISE:g} ({what}), got {noise}; "
                         f"give a --noise from 0 (no noise) to {MAX_NOISE:g}")


def _write_runs(out: Optional[Path], test_out: Optional[Path], samples: int, runs: int, noise: float, seed: int,
               make_train, make_test, extra: Optional[tuple] = None) -> None:
    """``make-data`` of a multi-run plant: options checked, paths checked, then the data made and written."""
    with _user_errors():
        output = _required(out, "-o/--out", "the CSV file to write")
        if samples < 1 or runs < 1 or seed < 0:
            raise InputError(f"--samples and --runs must be >= 1 and --seed >= 0, got "
                             f"--samples {samples}, --runs {runs}, --seed {seed}")
        _check_noise(noise, "a standard deviation on y")
        _plant_outputs(output, test_out, extra)  # the paths are checked before the work
        check_limit("--samples x --runs", samples * runs, MAX_SAMPLES, "ask for fewer samples or runs")
        train = make_train()
        test = make_test() if test_out is not None else None
        _write_plant(output, test_out, train, test, f"{runs} runs x {samples} samples, seed {seed}", extra)


@data_app.command("three-tank")
def make_data_three_tank(
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="CSV to write (columns u1, u2, y, x1, x3, x1_true, x3_true, run). Required.", show_default=False)] = None,
    samples: Annotated[int, typer.Option("--samples", help="Samples per run.")] = 1000,
    runs: Annotated[int, typer.Option("--runs", help="Training runs from random admissible levels (column run).")] = 20,
    noise: Annotated[float, typer.Option("--noise", help="Standard deviation of the Gaussian noise on y (the paper has none); 0..1000.")] = 0.0,
    test_out: Annotated[Optional[Path], typer.Option("--test-out", help="Also write the paper's run here (x(0) = (8, 2, 1), rho from t = 100).", show_default=False)] = None,
    seed: Annotated[int, typer.Option("--seed", help="Random seed (levels, phases, disturbance, noise).")] = 0,
) -> None:
    """The three-tank plant of seed 001 (eq. 26): y = x2, targets x1 and x3; see pwas_hdl.systems.three_tank."""
    from pwas_hdl.systems.three_tank import three_tank_paper_run, three_tank_training_runs

    _write_runs(out, test_out, samples, runs, noise, seed,
                lambda: three_tank_training_runs(runs, samples, seed=seed, noise=noise),
                lambda: three_tank_paper_run(samples, seed=seed, noise=noise))


@data_app.command("switched-linear")
def make_data_switched_linear(
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="CSV to write (columns u, y, x1, x2, x1_true, x2_true, mode, run). Required.", show_default=False)] = None,
    samples: Annotated[int, typer.Option("--samples", help="Samples per run.")] = 1000,
    runs: Annotated[int, typer.Option("--runs", help="Runs (column run), random dwell 20-50 and random x0.")] = 10,
    noise: Annotated[float, typer.Option("--noise", help="Standard deviation of the Gaussian noise on y; 0..1000.")] = 0.0,
    switching: Annotated[str, typer.Option("--switching", help="Switching law: time (cyclic) or output (thresholds on y).")] = "time",
    input_kind: Annotated[str, typer.Option("--input-signal", help="Input: step, prbs or sine.")] = "prbs",
    test_out: Annotated[Optional[Path], typer.Option("--test-out", help="Also write the paper-replica run here (100 samples, dwell 34, step input).", show_default=False)] = None,
    seed: Annotated[int, typer.Option("--seed", help="Random seed (input, dwell times, x0, noise).")] = 0,
    estimator_out: Annotated[Optional[Path], typer.Option("--estimator-out", help="Also write the plant's seed 003 estimator here (estimator file pwas-hdl-estimator v1: per-mode A, B, C and observer gains K for the poles 0.3, 0.4, detector window 1); `pwas-hdl generate FILE -o DIR` turns it into RTL.", show_default=False)] = None,
) -> None:
    """The switched linear plant of seed 003 (eq. 11), three modes; see pwas_hdl.systems.switched_linear."""
    from pwas_hdl.systems.switched_linear import switched_paper_run, switched_training_runs

    extra = None
    if estimator_out is not None:
        def estimator_text_of_plant() -> str:
            from pwas_hdl.fit.estimator_file import estimator_text
            from pwas_hdl.systems.switched_observer import estimator_config

            return estimator_text(estimator_config())

        extra = (estimator_out, "--estimator-out", estimator_text_of_plant, "seed 003 estimator, poles 0.3, 0.4")
    _write_runs(out, test_out, samples, runs, noise, seed,
                lambda: switched_training_runs(runs, samples, seed=seed, switching=switching, input_kind=input_kind, noise=noise),
                lambda: switched_paper_run(seed=seed, switching=switching, noise=noise), extra)


def _bench_outputs(json_out: Path, markdown: Optional[Path], plot: Optional[Path]) -> OutputSet:
    """The output set of a bench command (checked before the bench runs)."""
    outset = OutputSet()
    outset.add(json_out, "-o/--out")
    if markdown is not None:
        outset.add(markdown, "--md")
    if plot is not None:
        outset.add(plot, "--plot")
    return outset


def _system_bench(module: str, json_out: Optional[Path], json_old: Optional[Path], markdown: Optional[Path], plot_out: Optional[Path], runs: int, quick: bool,
                  workers: Optional[int] = None, scheduler: Optional[str] = None) -> None:
    """Run one of the system benches (benchmarks/<module>.py) and write its pwas-hdl-bench-results JSON."""
    import importlib

    from pwas_hdl import bench_results

    with _user_errors():
        json_out = _required(_merge("-o/--out", json_out, json=json_old), "-o/--out", "the JSON result file to write")
        bench_results.check_count("--runs", runs)
        mod = importlib.import_module(f"pwas_hdl.benchmarks.{module}")
        for p in (json_out, markdown, plot_out):
            if p is not None and not p.parent.is_dir():
                raise InputError(f"folder {p.parent} does not exist; create it first")
        outset = _bench_outputs(json_out, markdown, plot_out)
        with _executor(workers, scheduler) as ex:
            doc, traces = getattr(mod, f"run_{module}")(runs=runs, quick=quick, progress=_say, executor=ex)
            doc["config"]["execution"] = bench_results.execution_record(ex)
        table = mod.markdown(doc)
        with outset:  # the JSON, the tables and the figure: all or nothing
            outset.write_text(json_out, bench_results.results_text(doc))
            if markdown is not None:
                outset.write_text(markdown, table)
            if plot_out is not None:
                mod.plot(traces, outset.temp_path(plot_out))
        stdout.print(table, highlight=False, markup=False)
        _say(f"wrote {json_out}")


BenchJson = Annotated[Optional[Path], typer.Option("-o", "--out", help="Result file to write (format pwas-hdl-bench-results v1). Required.", show_default=False)]
BenchJsonOld = Annotated[Optional[Path], _hidden("--json")]
BenchMd = Annotated[Optional[Path], typer.Option("--md", help="Also write the Markdown tables here.")]
BenchPlot = Annotated[Optional[Path], typer.Option("--plot", help="Also write the figure (PNG) here.")]
BenchRuns = Annotated[int, typer.Option("--runs", help="Independent runs (seeds 0..runs-1) to average over; 1..1000.")]
BenchQuick = Annotated[bool, typer.Option("--quick", help="A reduced smoke run (1 run, no noise study): not a result to quote.")]


@bench_app.command("three-tank")
def bench_three_tank(json_out: BenchJson = None, markdown: BenchMd = None, plot_out: BenchPlot = None, runs: BenchRuns = 5,
                     quick: BenchQuick = False, workers: WorkersOpt = None, scheduler: SchedulerOpt = None,
                     json_old: BenchJsonOld = None) -> None:
    """Seed 001: sensors (27)/(28) vs PWAS (float, bit-true) on the paper's three-tank run, with a y-noise study."""
    _system_bench("three_tank", json_out, json_old, markdown, plot_out, runs, quick, workers, scheduler)


@bench_app.command("switched-linear")
def bench_switched_linear(json_out: BenchJson = None, markdown: BenchMd = None, plot_out: BenchPlot = None, runs: BenchRuns = 5,
                          quick: BenchQuick = False, workers: WorkersOpt = None, scheduler: SchedulerOpt = None,
                          json_old: BenchJsonOld = None) -> None:
    """Seed 003: virtual estimator (Table 1) and known-mode observer vs PWAS states and mode classifier."""
    _system_bench("switched_linear", json_out, json_old, markdown, plot_out, runs, quick, workers, scheduler)


@bench_app.command("lorenz-hlnn")
def bench_lorenz_hlnn(json_out: BenchJson = None, markdown: BenchMd = None, plot_out: BenchPlot = None, runs: BenchRuns = 5,
                      quick: BenchQuick = False, workers: WorkersOpt = None, scheduler: SchedulerOpt = None,
                      json_old: BenchJsonOld = None) -> None:
    """Seed 000: HLNN vs PWAS on Lorenz (Table II) and on the helicopter surrogate (Table VI)."""
    _system_bench("lorenz_hlnn", json_out, json_old, markdown, plot_out, runs, quick, workers, scheduler)
def _write_seed004_data(system: str, out: Optional[Path], samples: int, test_out: Optional[Path], test_samples: int,
                        seed: int, noise: float, rho_law: str = "random-walk") -> None:
    """Shared body of the seed-004 make-data commands (normalised with the training statistics, noisy)."""
    from pwas_hdl.systems.battery import make_battery_dataset
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    output = _required(out, "-o/--out", "the CSV file to write")
    _check_sample_counts(samples, test_samples)
    check_limit("--test-samples", test_samples, MAX_SAMPLES, "ask for fewer samples")
    _check_noise(noise, "a standard deviation in normalised units")
    outset = _plant_outputs(output, test_out)  # the paths are checked before the work, and written all or none
    n_test = test_samples if test_out is not None else 1
    if system == "battery":
        train, test, _ = make_battery_dataset(samples, n_test, seed, noise)
    else:
        train, test, _ = make_pv_dataset(system, samples, n_test, seed, noise, rho_law=rho_law)
    with outset:
        outset.write_text(output, format_csv(train.columns()))
        if test_out is not None:
            outset.write_text(test_out, format_csv(test.columns()))
    _say(f"wrote {output} ({samples} samples, seed {seed}, noise {noise})")
    if test_out is not None:
        _say(f"wrote {test_out} ({test_samples} samples of an independent run, normalised with the statistics of {output})")


Seed004Out = Annotated[Optional[Path], typer.Option("-o", "--out", help="CSV to write. Required.", show_default=False)]
Seed004Samples = Annotated[int, typer.Option("--samples", help="Number of samples in the -o/--out file (paper: up to 25 000).")]
Seed004TestOut = Annotated[Optional[Path], typer.Option("--test-out", help="Also write an independent test run here, normalised with the training statistics.", show_default=False)]
Seed004TestSamples = Annotated[int, typer.Option("--test-samples", help="Samples in the test file (paper: 5 000).")]
Seed004Seed = Annotated[int, typer.Option("--seed", help="Random seed of the run (excitation, parameter law and noise).")]
Seed004Noise = Annotated[float, typer.Option("--noise", help="Std of the white noise added after normalisation (paper: 0.03); 0..1000.")]


@data_app.command("pv-benchmark")
def make_data_pv(
    out: Seed004Out = None,
    samples: Seed004Samples = 25000,
    test_out: Seed004TestOut = None,
    test_samples: Seed004TestSamples = 5000,
    seed: Seed004Seed = 0,
    noise: Seed004Noise = 0.03,
    rho_law: Annotated[str, typer.Option("--rho-law", help="random-walk (eq. 14c-d) or cosine (eq. 16).")] = "random-walk",
) -> None:
    """Seed 004's parameter-varying benchmark (eq. 14): columns u1, u2, y, rho (noisy), rho_true.

    All columns are normalised with the training mean and std, then noise is added (Section 4.2).
    """
    with _user_errors():
        _write_seed004_data("pv-benchmark", out, samples, test_out, test_samples, seed, noise, rho_law)


@data_app.command("switching-4")
def make_data_switching4(
    out: Seed004Out = None,
    samples: Seed004Samples = 25000,
    test_out: Seed004TestOut = None,
    test_samples: Seed004TestSamples = 5000,
    seed: Seed004Seed = 0,
    noise: Seed004Noise = 0.03,
) -> None:
    """Seed 004's 4-mode switching system (eq. 14 with alpha = 0, rho from eq. 18): u1, u2, y, rho, rho_true.

    Normalised and noisy as pv-benchmark, except the mode label rho, which is noise-free.
    """
    with _user_errors():
        _write_seed004_data("switching-4", out, samples, test_out, test_samples, seed, noise)


@data_app.command("battery")
def make_data_battery(
    out: Seed004Out = None,
    samples: Seed004Samples = 25000,
    test_out: Seed004TestOut = None,
    test_samples: Seed004TestSamples = 5000,
    seed: Seed004Seed = 0,
    noise: Seed004Noise = 0.03,
) -> None:
    """Seed 004's battery (eq. 19-20, RK4, T_s = 5 s): columns i, v, soc (noisy), soc_true.

    The model coefficients are a SUBSTITUTE (Chen & Rincon-Mora 2006, C_c = 3060 A s), not the
    values of the paper's reference [4], which it does not print. Normalised and noisy as pv-benchmark.
    """
    with _user_errors():
        _write_seed004_data("battery", out, samples, test_out, test_samples, seed, noise)


@bench_app.command("lorenz")
def bench_lorenz(
    out: Annotated[Optional[Path], typer.Option("-o", "--out", help="Result file to write (format pwas-hdl-bench-results v1). Required.", show_default=False)] = None,
    markdown: Annotated[Optional[Path], typer.Option("--md", help="Also write a Markdown table here.")] = None,
    seeds: Annotated[int, typer.Option("--seeds", help="Number of seeds (0..seeds-1) to average over; 1..1000.")] = 5,
    quick: Annotated[bool, typer.Option("--quick", help="Only the Table II row (My=4, p=7, gamma=1.2).")] = False,
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
    json_old: Annotated[Optional[Path], _hidden("--json")] = None,
) -> None:
    """Reproduce Tables II-V of the paper (Lorenz): RMSEE over seeds, beside the paper's values."""
    from pwas_hdl.benchmarks import lorenz_tables

    with _user_errors():
        json_out = _required(_merge("-o/--out", out, json=json_old), "-o/--out", "the JSON file to write")
        from pwas_hdl.bench_results import check_count

        check_count("--seeds", seeds)
        outset = OutputSet()
        outset.add(json_out, "-o/--out")
        if markdown is not None:
            outset.add(markdown, "--md")
        rows = [r for r in lorenz_tables.PAPER_ROWS if (r.my, r.p, r.gamma) == (4, 7, 1.2)] if quick else None

        with _executor(workers, scheduler) as ex:
            result = lorenz_tables.run_lorenz_tables(seeds=range(seeds), rows=rows, progress=_say, executor=ex, quick=quick)
        table = lorenz_tables.markdown_table(result)
        with outset:
            outset.write_text(json_out, json.dumps(result, indent=2) + "\n")
            if markdown is not None:
                outset.write_text(markdown, table)
        stdout.print(table, highlight=False, markup=False)
        _say(f"wrote {json_out}")


def _seed004_bench(module: str, json_out: Optional[Path], json_old: Optional[Path], markdown: Optional[Path],
                   plot: Optional[Path], workers: Optional[int] = None, scheduler: Optional[str] = None, **kw) -> None:
    """Shared body of the seed-004 benches: run, write JSON (+ Markdown, + plot), print the table."""
    import importlib

    from pwas_hdl import bench_results

    json_out = _required(_merge("-o/--out", json_out, json=json_old), "-o/--out", "the JSON result file to write")
    bench_results.check_count("--runs", kw.get("runs", 1))  # checked with --quick too (which then runs once)
    if kw.get("quick"):
        kw["runs"] = 1
    for p in (json_out, markdown, plot):
        if p is not None and not p.parent.is_dir():
            raise InputError(f"folder {p.parent} does not exist; create it first")
    mod = importlib.import_module(f"pwas_hdl.benchmarks.{module}")
    outset = _bench_outputs(json_out, markdown, plot if hasattr(mod, "plot") else None)
    with _executor(workers, scheduler) as ex:
        doc = mod.run(progress=_say, executor=ex, **kw)
        doc["config"]["execution"] = bench_results.execution_record(ex)
    table = mod.markdown(doc)
    with outset:  # the JSON, the tables and the figure: all or nothing
        outset.write_text(json_out, bench_results.results_text({k: v for k, v in doc.items() if not k.startswith("_")}))
        if markdown is not None:
            outset.write_text(markdown, table)
        if plot is not None and hasattr(mod, "plot"):
            mod.plot(doc, outset.temp_path(plot))
    stdout.print(table, highlight=False, markup=False)
    _say(f"wrote {json_out}")


@bench_app.command("pv-benchmark")
def bench_pv(
    json_out: BenchJson = None,
    markdown: BenchMd = None,
    runs: Annotated[int, typer.Option("--runs", help="Runs (fresh data, seeds 0..K-1) per case; the paper averages 10; 1..1000.")] = 10,
    quick: Annotated[bool, typer.Option("--quick", help="Smoke run: base case, 3000/1000 samples, no ANN: not a result to quote.")] = False,
    tables: Annotated[Optional[str], typer.Option("--tables", help="Only these paper tables, comma list (T1..T7).")] = None,
    cases: Annotated[Optional[str], typer.Option("--cases", help="Only these cases, comma list (base, 11a, pp0.4, kf0.1, ntheta3, cosine, ...).")] = None,
    predictors: Annotated[str, typer.Option("--predictors", help="Estimators to run: comma list of dtr, rfr, ann, pwas-feat, pwas-raw.")] = "dtr,rfr,ann,pwas-feat,pwas-raw",
    ann_cases: Annotated[Optional[str], typer.Option("--ann-cases", help="Run the ANN only in these cases (comma list; default: every case that lists it).")] = None,
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
    json_old: BenchJsonOld = None,
) -> None:
    """Seed 004 E1, Tables 1-7: FIT/NRMSE of rho for DTR, RFR, ANN, PWAS P-feat and P-raw beside the paper."""
    with _user_errors():
        from pwas_hdl.benchmarks import pv_benchmark as pvb

        import re

        case_names = [c.name for c in pvb.CASES]
        table_names = sorted({t for c in pvb.CASES for t in re.findall(r"T\d+", c.table)}, key=lambda t: int(t[1:]))
        # every list is checked, --quick or not: an empty or misspelt one is refused, not ignored
        preds = tuple(_known_names("--predictors", predictors, pvb.ESTIMATORS))
        table_sel = _known_names("--tables", tables, table_names)
        case_sel = _known_names("--cases", cases, case_names, "case(s) ")
        ann_sel = _known_names("--ann-cases", ann_cases, case_names, "case(s) ")
        sel = pvb.select_cases(table_sel, case_sel)
        if quick:
            sel = pvb.select_cases(None, ["base"])
        _seed004_bench("pv_benchmark", json_out, json_old, markdown, None, workers, scheduler, cases=sel, runs=runs, quick=quick,
                       predictors=preds, ann_cases=tuple(ann_sel) if ann_sel is not None else None)


def _known_names(option: str, text: Optional[str], known: Sequence[str], what: str = "") -> Optional[list[str]]:
    """The comma list of ``option`` (None if not given), refused when empty or with a name not in ``known``."""
    if text is None:
        return None
    names = _names([text])
    if not names:
        raise InputError(f"{option} is empty; give a comma list of {', '.join(known)}, or leave the option out")
    bad = sorted(set(names) - set(known))
    if bad:
        raise InputError(f"{option}: unknown {what}{', '.join(bad)}; use {', '.join(known)}")
    return names


@bench_app.command("switching-4")
def bench_switching4(
    json_out: BenchJson = None,
    markdown: BenchMd = None,
    runs: Annotated[int, typer.Option("--runs", help="Runs (fresh data, seeds 0..K-1); the paper averages 10; 1..1000.")] = 10,
    quick: Annotated[bool, typer.Option("--quick", help="Smoke run: N_theta = 5 only, 3000/1000 samples, one run: not a result to quote.")] = False,
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
    json_old: BenchJsonOld = None,
) -> None:
    """Seed 004 E2, Tables 8-9: mode reconstruction (FIT, NRMSE, per-mode F1) for RFR, RFC, PWAS beside the paper."""
    with _user_errors():
        _seed004_bench("switching4", json_out, json_old, markdown, None, workers, scheduler, runs=runs, quick=quick)


@bench_app.command("battery")
def bench_battery(
    json_out: BenchJson = None,
    markdown: BenchMd = None,
    plot: Annotated[Optional[Path], typer.Option("--plot", help="Also write a Fig. 5-like plot (PNG) of run 0 here.")] = None,
    runs: Annotated[int, typer.Option("--runs", help="Runs (fresh data, seeds 0..K-1); 1..1000.")] = 10,
    quick: Annotated[bool, typer.Option("--quick", help="Smoke run: 3000/1000 samples, one run: not a result to quote.")] = False,
    workers: WorkersOpt = None,
    scheduler: SchedulerOpt = None,
    json_old: BenchJsonOld = None,
) -> None:
    """Seed 004 E3 (Fig. 5): SoC RMSE/FIT of the RFR and PWAS sensors and of 4 EKFs (substitute battery coefficients)."""
    with _user_errors():
        _seed004_bench("battery", json_out, json_old, markdown, plot, workers, scheduler, runs=runs, quick=quick)


def _version(value: bool) -> None:
    if value:
        stdout.print(f"pwas-hdl {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")] = False,
    quiet: Annotated[bool, typer.Option("-q", "--quiet", help="No progress or information lines (warnings and errors are still printed).")] = False,
    verbose: Annotated[bool, typer.Option("-v", "--verbose", help="On an error, also print the Python traceback and the end of a failed tool's log.")] = False,
) -> None:
    """PWAS virtual sensors: fit from plant data, evaluate, benchmark, generate verified Verilog.

    Exit status: 0 success, 1 a verification found a difference (simulate), 2 bad input or a
    missing / failing tool (one error: line), 3 an internal error (a bug: traceback printed).
    """
    _STATE["quiet"], _STATE["verbose"] = bool(quiet), bool(verbose)


@functools.lru_cache(maxsize=None)
def command() -> Any:
    """The Click command of :data:`app`, built once per process.

    Calling a ``typer.Typer`` builds its Click command tree again (every command's signature and type
    hints: about 50 ms); :func:`main` and in-process callers (tests, notebooks) run this one instead.
    """
    cmd = typer.main.get_command(app)
    _refuse_empty_paths(cmd)
    _name_list_metavars(cmd)
    return cmd


def _name_list_metavars(cmd: Any) -> None:
    """The help shows a repeatable option's value as ``<column>`` (``--sim``: ``<path>``), not as
    typer's ``<list[str]>``."""
    for p in getattr(cmd, "params", []):
        td = getattr(p, "type_descriptor", None)
        if getattr(p, "param_type_name", "") == "option" and p.metavar is None and \
                str(getattr(td, "annotation", "")).startswith("list["):
            p.metavar = "<path>" if "--sim" in p.opts else "<column>"
    for sub in getattr(cmd, "commands", {}).values():
        _name_list_metavars(sub)


def _refuse_empty_paths(cmd: Any) -> None:
    """Make every ``Path`` option of the tree (all name outputs) pass an empty value (``-o ""``) on as
    the empty text, which the command's output check refuses (:func:`pwas_hdl.io.atomic.check_output_path`),
    and refuse a file option (every one whose metavar is not :data:`FOLDER_METAVAR`) whose value ends
    with ``/``.

    Click turns ``""`` into ``Path("")``, which is ``Path(".")``: the working folder, where
    ``synth``, ``explore`` and ``simulate --build-dir`` then wrote their files. The raw string is
    seen where the option takes its value from the parsed command line (``handle_parse_result``).
    """
    for p in getattr(cmd, "params", []):
        td = getattr(p, "type_descriptor", None)
        if getattr(p, "param_type_name", "") == "option" and getattr(td, "annotation", None) is Path:
            def checked(ctx, opts, args, _p=p, _orig=p.handle_parse_result):
                value, rest = _orig(ctx, opts, args)
                raw = opts.get(_p.name)
                if isinstance(raw, str) and not raw.strip() and _p.expose_value:
                    # the command gets the empty text, which its output check refuses (check_output_path)
                    ctx.params[_p.name] = value = raw
                elif isinstance(raw, str) and raw.endswith(("/", os.sep)) and _p.metavar != FOLDER_METAVAR:
                    # Path("p.csv/") is Path("p.csv"): the slash, which names a folder, would be lost
                    raise typer.BadParameter(f"{raw!r} ends with '/', which names a folder; give a file name", ctx=ctx, param=_p)
                return value, rest

            p.handle_parse_result = checked
    for sub in getattr(cmd, "commands", {}).values():
        _refuse_empty_paths(sub)


def main(argv: Sequence[str] | None = None) -> int:
    """Console-script entry point: run the command line ``argv`` (default ``sys.argv[1:]``).

    Returns the exit status (0, 1, 2 or 3; see the module docstring). Click usage errors are printed
    as one ``error:`` line (Click runs with ``standalone_mode=False``, so they reach this function).
    """
    _STATE["quiet"] = _STATE["verbose"] = False
    install_termination_handler()  # SIGTERM runs the cleanup of temporaries instead of killing on the spot
    try:
        rv = command()(args=list(argv) if argv is not None else None, prog_name="pwas-hdl", standalone_mode=False)
    except (typer.Abort, click.exceptions.Abort):
        _error_line("aborted")
        return 130
    except Exception as exc:  # noqa: BLE001 - usage errors, and anything raised outside a command body
        return _report_error(exc)
    return rv if isinstance(rv, int) else 0


if __name__ == "__main__":
    sys.exit(main())
