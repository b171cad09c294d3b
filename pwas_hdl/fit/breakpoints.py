"""The breakpoints file of ``fit --breakpoints FILE`` (non-uniform partitions, issue 15 item 3).

Format (strict JSON, UTF-8)::

    {"format": "pwas-hdl-breakpoints", "version": 1,
     "regressors": ["y[t-2]", "y[t-1]", "y[t]"],          # optional: checked against the fit's regressors
     "breakpoints": [[-20, -8, -3, 0, 4, 9, 22],         # one list per regressor dimension, in regressor
                     [-20, -8, -3, 0, 4, 9, 22],         # order: p_j + 1 strictly increasing finite
                     [-20, -8, -3, 0, 4, 9, 22]]}        # numbers, physical units (at least 2)

Dimension ``j`` is cut into ``p_j = len(list_j) - 1`` intervals at these points; the first and
last fix its domain. So the file sets the partitions and the domain of the fit (``--partitions``
and ``--gamma`` are not used; ``--domain`` is refused with a file). The geometry is
:class:`pwas_hdl.fit.geometry.Grid` with ``breakpoints``.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from pwas_hdl.errors import InputError
from pwas_hdl.io.json_contract import check_header, read_json, schema_errors
from pwas_hdl.limits import MAX_REGRESSORS, MAX_VERTICES, check_limit

__all__ = ["BREAKPOINTS_FORMAT", "BREAKPOINTS_VERSION", "SCHEMA", "read_breakpoints", "breakpoints_errors"]

BREAKPOINTS_FORMAT = "pwas-hdl-breakpoints"
BREAKPOINTS_VERSION = 1
_HINT = "see the format in `pwas-hdl fit --help` and the README (non-uniform partitions)"


SCHEMA = "breakpoints-v1.schema.json"


def breakpoints_errors(d: object) -> list[str]:
    """What is wrong with a parsed breakpoints document (empty when it is valid).

    The shipped schema's violations first, then what a schema cannot say (finite, strictly
    increasing cut points, as many regressor names as lists).

    Parameters
    ----------
    d : object
        The parsed JSON document (any value; a non-dict is reported by the schema check).

    Returns
    -------
    list of str
        One message per problem; empty when ``d`` is a valid breakpoints document.
    """
    errs = schema_errors(d, SCHEMA)
    if errs:
        return errs
    bps, regs = d["breakpoints"], d.get("regressors")
    for j, b in enumerate(bps):
        bad = [k for k, v in enumerate(b) if not math.isfinite(v)]  # e.g. 1e999 parses as inf
        if bad:
            errs.append(f"breakpoints[{j}][{bad[0]}] = {b[bad[0]]!r} is not a finite number")
            continue
        dec = [k for k in range(len(b) - 1) if not b[k + 1] > b[k]]
        if dec:
            k = dec[0]
            errs.append(f"breakpoints[{j}] must increase strictly: [{k}] = {b[k]!r}, [{k + 1}] = {b[k + 1]!r}")
    if regs is not None and len(regs) != len(bps):
        errs.append(f"{len(regs)} regressor names for {len(bps)} breakpoint lists")
    return errs


def read_breakpoints(path: str | os.PathLike) -> tuple[list[list[float]], list[str] | None]:
    """Read and validate a breakpoints file.

    Parameters
    ----------
    path : str or os.PathLike
        The breakpoints file (strict JSON, format ``pwas-hdl-breakpoints``).

    Returns
    -------
    breakpoints : list of list of float
        One list of cut points per regressor dimension.
    regressors : list of str or None
        The regressor names the file states (None when it states none).

    Raises
    ------
    InputError
        Not strict JSON, wrong format / version, or a list that is too short, not numeric or not
        strictly increasing (the message names it).
    FileNotFoundError, OSError
        The file cannot be read.
    """
    p = Path(path)
    d = read_json(p, _HINT)
    if isinstance(d, dict):
        check_header(d, BREAKPOINTS_FORMAT, BREAKPOINTS_VERSION, str(p), _HINT)
        bps = d.get("breakpoints")
        if isinstance(bps, list) and all(isinstance(b, list) for b in bps):  # the sizes before the (slow) schema check
            check_limit(f"{p}: the breakpoint lists", len(bps), MAX_REGRESSORS, "give one list per regressor")
            n_vertices = math.prod(max(len(b), 1) for b in bps)  # cut points per dimension = p_j + 1
            check_limit(f"{p}: the vertices N = prod(cut points per list)", n_vertices, MAX_VERTICES,
                        "give fewer cut points")
    errs = breakpoints_errors(d)
    if errs:
        raise InputError(f"{p}: {errs[0]}; {_HINT}")
    return [[float(v) for v in b] for b in d["breakpoints"]], d.get("regressors")
