"""CSV input/output of plant data and estimates.

Input files are comma-separated with one header line of column names and one row per sample.
Columns are picked by name. An optional trajectory column (any text or number) marks which
experiment a row belongs to: consecutive rows with the same value form one trajectory, and no
regressor straddles two trajectories.
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from pwas_hdl.io.atomic import atomic_write_text

__all__ = ["Table", "read_csv", "write_csv", "select_signals"]


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
    """

    path: str
    header: list[str]
    rows: list[list[str]]

    def __len__(self) -> int:
        return len(self.rows)

    def numeric(self, names: Sequence[str]) -> np.ndarray:
        """The named columns as a float array of shape (rows, len(names)).

        Raises
        ------
        ValueError
            Unknown column, a cell that is not a number, or a NaN / infinite value.
        """
        idx = [self.column_index(nm) for nm in names]
        out = np.empty((len(self.rows), len(idx)))
        for r, row in enumerate(self.rows):
            for k, c in enumerate(idx):
                cell = row[c].strip()
                try:
                    v = float(cell)
                except ValueError:
                    raise ValueError(
                        f"{self.path}: line {r + 2}, column '{names[k]}': {cell!r} is not a number"
                    ) from None
                if not math.isfinite(v):
                    raise ValueError(
                        f"{self.path}: line {r + 2}, column '{names[k]}' is {cell!r} (NaN/inf); "
                        "remove or interpolate missing samples first"
                    )
                out[r, k] = v
        return out

    def text(self, name: str) -> list[str]:
        """A column as raw text."""
        c = self.column_index(name)
        return [row[c].strip() for row in self.rows]

    def column_index(self, name: str) -> int:
        try:
            return self.header.index(name)
        except ValueError:
            raise ValueError(
                f"{self.path}: no column named {name!r}; the file has columns {', '.join(self.header)}"
            ) from None


def read_csv(path: str | os.PathLike) -> Table:
    """Read a CSV file with a header line.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    ValueError
        Empty file, duplicate or empty column names, or a row with the wrong number of cells.
    """
    p = Path(path)
    with p.open(newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise ValueError(f"{p}: the file is empty; expected a header line of column names") from None
        if any(not h for h in header):
            raise ValueError(f"{p}: the header has an empty column name")
        dup = sorted({h for h in header if header.count(h) > 1})
        if dup:
            raise ValueError(f"{p}: duplicate column name(s) {', '.join(dup)}")
        rows = []
        for line_no, row in enumerate(reader, start=2):
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) != len(header):
                raise ValueError(f"{p}: line {line_no} has {len(row)} cells but the header has {len(header)} columns")
            rows.append(row)
    if not rows:
        raise ValueError(f"{p}: the file has a header but no data rows")
    return Table(str(p), header, rows)


def split_trajectories(table: Table, traj_column: str | None) -> list[slice]:
    """Row slices of the trajectories: consecutive rows with equal values of ``traj_column``."""
    n = len(table)
    if traj_column is None:
        return [slice(0, n)]
    labels = table.text(traj_column)
    cuts = [0] + [i for i in range(1, n) if labels[i] != labels[i - 1]] + [n]
    return [slice(a, b) for a, b in zip(cuts[:-1], cuts[1:])]


def select_signals(
    table: Table, names: Sequence[str], traj_column: str | None = None
) -> list[np.ndarray]:
    """Named numeric columns, split into trajectories: a list of arrays (T_i, len(names))."""
    if not names:
        return []
    data = table.numeric(names)
    return [data[sl] for sl in split_trajectories(table, traj_column)]


def write_csv(path: str | os.PathLike, columns: Mapping[str, np.ndarray | Sequence]) -> Path:
    """Write named columns (equal lengths) atomically; floats with round-trip precision."""
    names = list(columns)
    arrays = [np.asarray(columns[nm]) for nm in names]
    lens = {a.shape[0] for a in arrays}
    if len(lens) > 1:
        raise ValueError(f"columns have different lengths {sorted(lens)}")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(names)
    for r in range(lens.pop() if lens else 0):
        w.writerow([_fmt(a[r]) for a in arrays])
    return atomic_write_text(path, buf.getvalue())


def _fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "1" if v else "0"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    return str(v)
