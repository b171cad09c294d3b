"""CSV input/output of plant data and estimates.

Input files are comma-separated with one header line of column names and one row per sample.
Columns are picked by name. An optional trajectory column (any text or number) marks which
experiment a row belongs to: consecutive rows with the same value form one trajectory, and no
regressor straddles two trajectories.
"""

from __future__ import annotations

import codecs
import csv
import io
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from pwas_hdl.errors import InputError, ResourceLimit, choice_text
from pwas_hdl.io.atomic import atomic_write_text
from pwas_hdl.limits import MAX_CSV_BYTES, MAX_CSV_FIELD, MAX_SAMPLES, check_limit

__all__ = ["Table", "read_csv", "write_csv", "select_signals", "split_trajectories", "format_csv", "parse_number", "BLANK_ROWS",
           "TRAJECTORY_COLUMN_NAMES", "unused_trajectory_column", "reference_column_names"]

#: Column names that usually number the trajectories of a file (``make-data ... --runs`` writes ``run``).
TRAJECTORY_COLUMN_NAMES = ("run", "trajectory", "traj", "experiment", "episode")


#: A number as Python's ``float`` reads it, restricted to ASCII digits and without ``_`` separators
#: (``float`` also takes ``1_0`` and Arabic-Indic or full-width digits: refused here). Surrounding
#: whitespace is stripped first; ``nan`` / ``inf`` parse and are then refused as non-finite.
_NUMBER = re.compile(r"[+-]?(?:(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf(?:inity)?|nan)", re.IGNORECASE)

def reference_column_names(name: str) -> tuple[str, str]:
    """The columns that may hold the reference of quantity ``name``, the preferred one first.

    The one statement of the naming rule: the reference (true or measured values) of a target
    ``t`` is column ``t_true`` (noise-free, as ``make-data`` writes it) if the file has it, else
    ``t``; a classifier's true class likewise ``<label>_true``, else ``<label>``.
    :meth:`Table.reference_column` picks the one a file has.

    Parameters
    ----------
    name : str
        Quantity (target or class label) name.

    Returns
    -------
    tuple of str
        ``(f"{name}_true", name)``.
    """
    return (f"{name}_true", name)


#: What :func:`read_csv` does with a blank row between data rows.
BLANK_ROWS = ("error", "break")


def parse_number(cell: str) -> float | None:
    """The value of a CSV cell, or None when it is not a number (strict: see :data:`_NUMBER`).

    Parameters
    ----------
    cell : str
        Raw cell text; surrounding whitespace is ignored.

    Returns
    -------
    float or None
        ``nan`` / ``inf`` are returned as such (callers refuse them).
    """
    t = cell.strip()
    if not _NUMBER.fullmatch(t):
        return None
    return float(t)


@dataclass
class Table:
    """A CSV file read into memory.

    Attributes
    ----------
    path : str
    header : list of str
        Column names in file order.
    rows : list of list of str
        The raw text cells (numbers are converted on demand so that text columns are allowed).
    lines : list of int
        File line number (1-based) of each row, for messages.
    breaks : list of int
        Rows that start a new trajectory because a blank row preceded them (``blank_rows="break"``).
    """

    path: str
    header: list[str]
    rows: list[list[str]]
    lines: list[int] = field(default_factory=list)
    breaks: list[int] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.rows)

    def _line(self, r: int) -> int:
        return self.lines[r] if r < len(self.lines) else r + 2

    def short_trajectory(self, sl: slice, need: int, what: str, traj_column: str | None = None) -> InputError:
        """The error for the trajectory ``sl`` of this file, shorter than the ``need`` samples ``what`` needs.

        Parameters
        ----------
        sl : slice
            The trajectory's rows (data rows, 0-based, ``stop`` exclusive).
        need : int
            Samples (rows) the trajectory would need.
        what : str
            What needs them, worded to go before the number (e.g. ``"the lags need"``).
        traj_column : str or None
            The trajectory column: the run's label is named, and a label whose rows are not
            consecutive (it comes back after another run) is said to be split, with the fix (sort by run).

        Returns
        -------
        InputError
            The error to raise, naming the file's line numbers of the trajectory.
        """
        lines = f"lines {self._line(sl.start)}..{self._line(sl.stop - 1)}" if sl.stop - sl.start > 1 else \
            f"line {self._line(sl.start)}"
        if traj_column is None:
            return InputError(f"{self.path}: the trajectory on {lines} has {sl.stop - sl.start} samples; {what} {need}; "
                              f"give trajectories of at least {need} rows (or check --traj-col)")
        label = self.text(traj_column)[sl.start]
        blocks = len(_label_blocks(self, traj_column)[label])
        fix = (f"the rows of run {label!r} are not consecutive (it is split into {blocks} separate blocks, each read as "
               f"a run of its own): sort the rows by {traj_column} (each run's rows in time order), or give each "
               "experiment a label of its own") if blocks > 1 else \
            f"drop that run or give it at least {need} rows" + (", or use fewer lags (--mu, --my)" if "lags" in what else "")
        return InputError(f"{self.path}: run {label!r} (column {traj_column}) on {lines} has {sl.stop - sl.start} "
                          f"samples; {what} {need}; {fix}")

    def numeric(self, names: Sequence[str]) -> np.ndarray:
        """The named columns as a float array.

        Parameters
        ----------
        names : sequence of str
            Column names (exact match), in the order of the result's columns.

        Returns
        -------
        ndarray of float64, shape (len(self), len(names))

        Raises
        ------
        InputError
            Unknown column, a cell that is not a number, or a NaN / infinite value.
        """
        idx = [self.column_index(nm) for nm in names]
        out = np.empty((len(self.rows), len(idx)))
        for r, row in enumerate(self.rows):
            for k, c in enumerate(idx):
                cell = row[c]
                v = parse_number(cell)
                if v is None and not cell.strip():  # a missing sample: said as such, with the fix
                    raise InputError(
                        f"{self.path}: line {self._line(r)}, column '{names[k]}' is empty (a missing sample); fill it "
                        "(e.g. interpolate), or empty the whole row and give --blank-rows break to end the trajectory there"
                    )
                if v is None:
                    raise InputError(
                        f"{self.path}: line {self._line(r)}, column '{names[k]}': {cell.strip()!r} is not a number "
                        "(ASCII digits, one '.', an optional exponent; no '_' separators)"
                    )
                if not math.isfinite(v):
                    raise InputError(
                        f"{self.path}: line {self._line(r)}, column '{names[k]}' is {cell.strip()!r} (NaN/inf); "
                        "remove or interpolate missing samples first"
                    )
                out[r, k] = v
        return out

    def text(self, name: str) -> list[str]:
        """A column as text, each cell stripped of surrounding whitespace.

        Parameters
        ----------
        name : str
            Column name.

        Returns
        -------
        list of str
            One per row.

        Raises
        ------
        InputError
            No column has that name.
        """
        c = self.column_index(name)
        return [row[c].strip() for row in self.rows]

    def reference_column(self, name: str) -> str | None:
        """The column with the reference (measured or true) values of quantity ``name``.

        Parameters
        ----------
        name : str
            Quantity (target) name.

        Returns
        -------
        str or None
            ``<name>_true`` if the file has it, else ``<name>``, else None
            (:func:`reference_column_names`).
        """
        return next((c for c in reference_column_names(name) if c in self.header), None)

    def column_index(self, name: str) -> int:
        """Index of the column ``name`` in :attr:`header`.

        Parameters
        ----------
        name : str
            A column name (exact match).

        Returns
        -------
        int
            The index of its first occurrence.

        Raises
        ------
        InputError
            No column has that name (the message lists the columns).
        """
        try:
            return self.header.index(name)
        except ValueError:
            raise InputError(
                f"{self.path}: no column named {name!r}; the file has columns {', '.join(self.header)}"
            ) from None


def read_csv(path: str | os.PathLike, *, blank_rows: str = "error") -> Table:
    """Read a CSV file with a header line (UTF-8, an optional byte-order mark is dropped).

    Parameters
    ----------
    path : path
    blank_rows : {"error", "break"}
        A blank row between data rows is an error (default: it would shift every later line
        number and join the samples around it), or ``"break"``: it ends one trajectory and the
        next row starts another (no regressor straddles it). Blank rows at the end are ignored.

    Returns
    -------
    Table
        Cells kept as text; at least one data row.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    InputError
        An unknown ``blank_rows``, a folder, unreadable, not UTF-8 (the byte offset is named), empty, duplicate or empty column
        names, a control character in a column name, a row with the wrong number of cells, a
        blank row (``blank_rows="error"``), malformed quoting.
    ResourceLimit
        A cell longer than :data:`~pwas_hdl.limits.MAX_CSV_FIELD` characters, more than
        :data:`~pwas_hdl.limits.MAX_SAMPLES` rows or a file over :data:`~pwas_hdl.limits.MAX_CSV_BYTES`.
    """
    if blank_rows not in BLANK_ROWS:
        raise InputError(choice_text("--blank-rows (blank_rows)", BLANK_ROWS, blank_rows))
    p = Path(path)
    try:
        size = p.stat().st_size
        if p.is_dir():
            raise InputError(f"{p} is a folder, not a CSV file")
        check_limit(f"the size of {p} in bytes", size, MAX_CSV_BYTES, "split the data into several files")
        raw = p.read_bytes()
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise InputError(f"cannot read {p}: {exc.strerror or exc}; check the path and its permissions") from exc
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        off = exc.start + (3 if raw.startswith(codecs.BOM_UTF8) else 0)
        line = raw.count(b"\n", 0, off) + 1
        raise InputError(
            f"{p} is not UTF-8 text: byte 0x{raw[off]:02x} at offset {off} (line {line}) "
            "cannot be decoded; save the file as UTF-8"
        ) from None
    del raw
    _refuse_json(p, text)
    old_limit = csv.field_size_limit(MAX_CSV_FIELD)
    rows: list[list[str]] = []
    lines: list[int] = []
    breaks: list[int] = []
    blank_at: int | None = None  # first blank line since the last data row
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    start = 1
    try:
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise InputError(f"{p}: the file is empty; expected a header line of column names") from None
        if not any(header):
            raise InputError(f"{p}: line 1 is blank; the first line must be the header of column names")
        if len(header) == 1:  # another separator (a spreadsheet's ';' export, a tab-separated file)
            _refuse_other_separator(p, text, repr(header[0]))
        if any(not h for h in header):
            raise InputError(f"{p}: the header has an empty column name (column {header.index('') + 1} of {len(header)}); "
                             "name every column, or remove the extra comma")
        for h in header:
            if not h.isprintable():
                raise InputError(
                    f"{p}: column name {h!r} contains a control or invisible character (a line break inside quotes?); "
                    "rename the column"
                )
        dup = sorted({h for h in header if header.count(h) > 1})
        if dup:
            raise InputError(f"{p}: duplicate column name(s) {', '.join(dup)}; give each column a name of its own")
        start = reader.line_num + 1
        for row in reader:
            line_no, start = start, reader.line_num + 1
            if not row or all(not c.strip() for c in row):
                if blank_at is None:
                    blank_at = line_no
                continue
            if blank_at is not None:
                if blank_rows == "error" or not rows:
                    if blank_rows == "error":
                        raise InputError(
                            f"{p}: line {blank_at} is blank; remove blank rows, or pass --blank-rows break to make "
                            "each blank row end a trajectory"
                        )
                else:
                    breaks.append(len(rows))
                blank_at = None
            if len(row) != len(header):
                raise InputError(f"{p}: line {line_no} has {len(row)} cells but the header has {len(header)} columns; "
                                 "give every row one cell per column (check for a missing or extra comma)")
            rows.append(row)
            lines.append(line_no)
            if len(rows) > MAX_SAMPLES:
                raise ResourceLimit(
                    f"{p} has more than {MAX_SAMPLES} data rows (the limit); split the data into several files"
                )
    except csv.Error as exc:
        line = reader.line_num
        if line <= 1:  # a header quoted in another separator's form ("u";"y") is malformed as CSV
            _refuse_other_separator(p, text, "(line 1)")
        if "field larger than field limit" in str(exc):
            raise ResourceLimit(
                f"{p}: line {line} has a cell longer than the limit of {MAX_CSV_FIELD} characters (128 KiB); "
                "is it a CSV file of numbers?"
            ) from None
        raise InputError(f"{p}: line {line}: malformed CSV ({exc}); check the quoting") from None
    finally:
        csv.field_size_limit(old_limit)
    if not rows:
        raise InputError(f"{p}: the file has a header but no data rows; add the samples, one row per line below the header")
    return Table(str(p), header, rows, lines, breaks)


def _refuse_json(p: Path, text: str) -> None:
    """A JSON document given as DATA (a model, manifest or results file: the other files pwas-hdl
    writes) is named as such, not reported as a row with the wrong number of cells."""
    if text.lstrip()[:1] not in ("{", "["):
        return
    import json

    try:
        doc = json.loads(text)
    except ValueError:
        return
    fmt = doc.get("format") if isinstance(doc, dict) else None
    what = f"a {fmt} file (JSON)" if isinstance(fmt, str) and fmt.startswith("pwas-hdl") else "a JSON file"
    raise InputError(f"{p} is {what}, not CSV data; give the CSV file of samples (a header line of column names, "
                     "one row per sample)")


def split_trajectories(table: Table, traj_column: str | None) -> list[slice]:
    """Row slices of the trajectories: consecutive rows with equal values of ``traj_column``, also
    cut where a blank row was read as a trajectory break (:attr:`Table.breaks`).

    Parameters
    ----------
    table : Table
    traj_column : str or None
        Trajectory column (compared as stripped text); None: only the blank-row breaks cut.

    Returns
    -------
    list of slice
        Contiguous, in row order, covering every row.

    Raises
    ------
    InputError
        No column named ``traj_column``.
    """
    n = len(table)
    cuts = set(b for b in table.breaks if 0 < b < n)
    if traj_column is not None:
        labels = table.text(traj_column)
        cuts |= {i for i in range(1, n) if labels[i] != labels[i - 1]}
    edges = [0] + sorted(cuts) + [n]
    return [slice(a, b) for a, b in zip(edges[:-1], edges[1:])]


def _refuse_other_separator(p: Path, text: str, header: str) -> None:
    """Refuse a file whose first line reads as two or more column names with ';' or tabs between them
    (a spreadsheet's export); the line read with that separator, so a quoted name keeps its quotes'
    meaning. ``header``: how the message names the line."""
    for sep, called in ((";", "';'"), ("\t", "tabs")):
        try:
            alt = next(csv.reader(io.StringIO(text, newline=""), delimiter=sep, strict=True), [])
        except csv.Error:  # e.g. a quote that opens a field only with this separator
            alt = []
        if len([h for h in alt if h.strip()]) >= 2:
            raise InputError(f"{p}: the header {header} is separated by {called}, not commas; pwas-hdl "
                             "reads comma-separated values: save the file with ',' between the cells "
                             "(and '.' as the decimal point)")


def _label_blocks(table: Table, traj_column: str) -> dict[str, list[slice]]:
    """Each label of ``traj_column`` -> its blocks of consecutive rows, in row order."""
    labels = table.text(traj_column)
    blocks: dict[str, list[slice]] = {}
    edges = [0] + [i for i in range(1, len(table)) if labels[i] != labels[i - 1]] + [len(table)]
    for a, b in zip(edges[:-1], edges[1:]):
        if b > a:
            blocks.setdefault(labels[a], []).append(slice(a, b))
    return blocks


def check_trajectory_lengths(table: Table, traj_column: str | None, need: int, what: str = "the lags need") -> None:
    """Refuse a trajectory of fewer than ``need`` rows, naming the file, its lines and its run
    (:meth:`Table.short_trajectory`).

    Raises
    ------
    InputError
        The first trajectory shorter than ``need`` rows.
    """
    for sl in split_trajectories(table, traj_column):
        if sl.stop - sl.start < need:
            raise table.short_trajectory(sl, need, what, traj_column)


def split_runs(table: Table, traj_column: str | None) -> str | None:
    """The warning when a run label comes back after another run: its rows are read as separate runs.

    Returns
    -------
    str or None
        ``warning: ...`` naming the first such label, its blocks (file lines) and the fix; None when every
        label is one block of consecutive rows (or there is no trajectory column).
    """
    if traj_column is None:
        return None
    split = [(lab, sls) for lab, sls in _label_blocks(table, traj_column).items() if len(sls) > 1]
    if not split:
        return None
    lab, sls = split[0]
    where = ", ".join(f"{table._line(s.start)}..{table._line(s.stop - 1)}" for s in sls[:4]) + (", ..." if len(sls) > 4 else "")
    more = f" ({len(split) - 1} more run(s) likewise)" if len(split) > 1 else ""
    return (f"warning: run {lab!r} of column {traj_column} comes back after another run: its {len(sls)} separate blocks "
            f"(lines {where}) are read as runs of their own{more}; sort the rows by {traj_column} if a run is one experiment")


def check_trajectory_column(table: Table, traj_column: str | None, signals: Sequence[str] = (),
                            references: Sequence[str] = ()) -> None:
    """Refuse a ``--traj-col`` that DATA lacks or that names a column the model reads.

    A trajectory column labels runs; one that is also a signal of the model (an integer-valued input
    such as a PRBS passes for a run index) or the reference its estimates are scored against would
    be read in two roles, as ``fit`` refuses for the columns it is given.

    Parameters
    ----------
    table : Table
    traj_column : str or None
        The trajectory column (None: nothing to check).
    signals : sequence of str
        The columns the model reads as inputs / outputs (or states).
    references : sequence of str
        Target names; ``<t>`` and ``<t>_true`` are the reference columns of their scores.

    Raises
    ------
    InputError
        No such column, or it is one of ``signals`` or a reference column.
    """
    if traj_column is None:
        return
    table.column_index(traj_column)
    fix = ("give each column one role: --traj-col names the column that numbers the runs (such as run), "
           "or leave it out for one trajectory")
    if traj_column in signals:
        raise InputError(f"--traj-col {traj_column!r} is a signal the model reads ({', '.join(signals)}); {fix}")
    refs = [c for t in references for c in reference_column_names(t)]
    if traj_column in refs:
        raise InputError(f"--traj-col {traj_column!r} is the reference the estimates are compared with; {fix}")


def unused_trajectory_column(table: Table, traj_column: str | None, used: Sequence[str] = ()) -> tuple[str, int] | None:
    """A column that looks like a trajectory index but is not given as one.

    Parameters
    ----------
    table : Table
    traj_column : str or None
        The trajectory column the command was given (``--traj-col``); with one, nothing is reported.
    used : sequence of str
        Columns the command reads as signals (never reported).

    Returns
    -------
    (name, runs) or None
        The first column named as in :data:`TRAJECTORY_COLUMN_NAMES` whose values are integers in
        contiguous blocks of at least 2 distinct values (``runs``); without ``--traj-col`` its runs
        are read as one trajectory, and regressors straddle their boundaries.
    """
    if traj_column is not None:
        return None
    for name in TRAJECTORY_COLUMN_NAMES:
        if name not in table.header or name in used:
            continue
        try:
            v = table.numeric([name])[:, 0]
        except InputError:
            continue
        if len(v) < 2 or not np.all(v == np.round(v)):
            continue
        starts = np.flatnonzero(np.diff(v) != 0) + 1
        runs = len(starts) + 1
        if runs >= 2 and len(np.unique(v)) == runs:  # each value in one block: an index, not a signal
            return name, runs
    return None


def select_signals(
    table: Table, names: Sequence[str], traj_column: str | None = None
) -> list[np.ndarray]:
    """Named numeric columns, split into trajectories (:func:`split_trajectories`).

    Parameters
    ----------
    table : Table
    names : sequence of str
        Column names; empty gives ``[]``.
    traj_column : str, optional
        Trajectory column.

    Returns
    -------
    list of ndarray of float64, shape (T_i, len(names))
        One per trajectory, ``T_i`` samples each.

    Raises
    ------
    InputError
        As :meth:`Table.numeric`.
    """
    if not names:
        return []
    data = table.numeric(names)
    return [data[sl] for sl in split_trajectories(table, traj_column)]


def write_csv(path: str | os.PathLike, columns: Mapping[str, np.ndarray | Sequence]) -> Path:
    """Write named columns (equal lengths) atomically; floats with round-trip precision.

    Parameters
    ----------
    path : path
        Target file (its folder must exist).
    columns : mapping of str to 1-D array or sequence, each shape (T,)
        Header name -> values, in column order (see :func:`format_csv`); ``T`` rows.

    Returns
    -------
    Path
        Where the file was written (:func:`~pwas_hdl.io.atomic.atomic_write_bytes`).

    Raises
    ------
    InputError
        Columns of different lengths.
    """
    return atomic_write_text(path, format_csv(columns))


def format_csv(columns: Mapping[str, np.ndarray | Sequence]) -> str:
    """The text :func:`write_csv` writes (for an :class:`~pwas_hdl.io.atomic.OutputSet`).

    Parameters
    ----------
    columns : mapping of str to 1-D array or sequence, each shape (T,)
        Header name -> values (``T`` rows). Booleans are written ``1`` / ``0``, integers as integers, floats
        as ``repr`` (round-trip), anything else with ``str``.

    Returns
    -------
    str
        Header line, then one line per row (``\\n`` line ends).

    Raises
    ------
    InputError
        Columns of different lengths.
    """
    names = list(columns)
    arrays = [np.asarray(columns[nm]) for nm in names]
    lens = {a.shape[0] for a in arrays}
    if len(lens) > 1:
        raise InputError(f"columns have different lengths {sorted(lens)}; give every column the same number of rows")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(names)
    for r in range(lens.pop() if lens else 0):
        w.writerow([_fmt(a[r]) for a in arrays])
    return buf.getvalue()


def _fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "1" if v else "0"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    return str(v)
