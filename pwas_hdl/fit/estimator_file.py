"""The estimator file (``pwas-hdl-estimator``, version 1): seed 003's switched-observer configuration.

The one owner of the format (writing, reading, validation); its JSON Schema ships as
``pwas_hdl/schemas/estimator-v1.schema.json``. It describes the float estimator of seed 003
(Morales-Morales et al.; :func:`pwas_hdl.systems.switched_observer.run_switched_observer`): per
mode ``i`` the matrices of ``x(k+1) = A_i x(k) + B_i u(k)``, ``y(k) = C_i x(k)`` and the observer
gain ``K_i``, and the detector's window (samples summed in the residual window)::

    {"$schema": "urn:pwas-hdl:schema:estimator-v1", "format": "pwas-hdl-estimator", "version": 1,
     "kind": "switched-observer",
     "signals": {"input": "u", "output": "y", "states": ["x1", "x2"]},
     "window": 1,
     "modes": [{"A": [[..n..], ..n rows..], "B": [..n..], "C": [..n..], "K": [..n..]}, ... s modes],
     "source": {"system": "switched-linear", "poles": [0.3, 0.4], ...}}

Why a file of its own and not the model file: the model file (``pwas-hdl-model``) is a fitted PWAS
function (grid, weights, regressors); this estimator has none of them -- it is a set of linear
observers whose constants come from the plant and a pole choice, not from data. ``pwas-hdl
generate`` recognises the file by its ``format`` and builds the estimator's top
(:mod:`pwas_hdl.design.estimator`).

Floats are written in Python's shortest round-trip form, so write/read is bit-exact. Reading
refuses (one :class:`~pwas_hdl.errors.InputError` naming the file and the key) invalid JSON, another
format or version, a key the schema does not allow, and what a schema cannot say: ``A_i`` square of
one order ``n`` in every mode, ``B_i``, ``C_i``, ``K_i`` of length ``n``, finite numbers, distinct
signal names, one state name per state, an output row ``C_i`` with a non-zero entry.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.io.json_contract import check_header, json_text, read_json, validate

__all__ = ["ESTIMATOR_FORMAT", "ESTIMATOR_VERSION", "ESTIMATOR_SCHEMA", "ESTIMATOR_SCHEMA_ID", "SwitchedEstimatorConfig",
           "estimator_text", "write_estimator", "read_estimator", "validate_estimator", "is_estimator_file"]

ESTIMATOR_FORMAT = "pwas-hdl-estimator"
ESTIMATOR_VERSION = 1
ESTIMATOR_SCHEMA = "estimator-v1.schema.json"
ESTIMATOR_SCHEMA_ID = "urn:pwas-hdl:schema:estimator-v1"
_HINT = "write it again with `pwas-hdl make-data switched-linear --estimator-out FILE`"


@dataclass
class SwitchedEstimatorConfig:
    """Seed 003's estimator: per-mode ``A`` (n, n), ``B`` (n,), ``C`` (n,), ``K`` (n,) and the detector window.

    Attributes
    ----------
    A, B, C, K : list of ndarray, one per mode (s modes)
    window : int
        Samples in the window sum of squared residuals (1: eq. (9)).
    input_name, output_name : str
        Names of the scalar input u and output y (CSV columns).
    state_names : list of str
        Names of the n states.
    source : dict
        Free-form provenance (system, poles).
    """

    A: list
    B: list
    C: list
    K: list
    window: int = 1
    input_name: str = "u"
    output_name: str = "y"
    state_names: list = field(default_factory=list)
    source: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.A = [np.atleast_2d(np.asarray(a, dtype=float)) for a in self.A]
        self.B = [np.asarray(b, dtype=float).reshape(-1) for b in self.B]
        self.C = [np.asarray(c, dtype=float).reshape(-1) for c in self.C]
        self.K = [np.asarray(k, dtype=float).reshape(-1) for k in self.K]
        if not self.state_names:
            self.state_names = [f"x{i + 1}" for i in range(self.A[0].shape[0] if self.A else 0)]
        errs = _config_errors(self)
        if errs:
            raise InputError(f"estimator configuration: {errs[0]}")

    @property
    def n_modes(self) -> int:
        """Number of modes ``s``."""
        return len(self.A)

    @property
    def n_states(self) -> int:
        """Number of states ``n`` (the order of every ``A_i``)."""
        return int(self.A[0].shape[0])

    def to_dict(self) -> dict[str, Any]:
        """The file content (validated).

        Returns
        -------
        dict
            The JSON document of the estimator file (header, ``signals``, ``window``, ``modes``
            as lists of floats, and ``source`` when it is not empty).

        Raises
        ------
        InputError
            The configuration does not pass :func:`validate_estimator`.
        """
        d = {"$schema": ESTIMATOR_SCHEMA_ID, "format": ESTIMATOR_FORMAT, "version": ESTIMATOR_VERSION,
             "kind": "switched-observer",
             "signals": {"input": self.input_name, "output": self.output_name, "states": list(self.state_names)},
             "window": int(self.window),
             "modes": [{"A": [[float(v) for v in row] for row in a], "B": [float(v) for v in b], "C": [float(v) for v in c],
                        "K": [float(v) for v in k]} for a, b, c, k in zip(self.A, self.B, self.C, self.K)]}
        if self.source:
            d["source"] = self.source
        validate_estimator(d, "estimator configuration")
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "estimator") -> "SwitchedEstimatorConfig":
        """A configuration from a parsed estimator document (validated first).

        Parameters
        ----------
        d : dict
            The parsed JSON of an estimator file (what :meth:`to_dict` returns).
        source : str
            What to call the document in error messages (e.g. the file path).

        Returns
        -------
        SwitchedEstimatorConfig

        Raises
        ------
        InputError
            ``d`` is not a valid estimator document (:func:`validate_estimator`).
        """
        validate_estimator(d, source)
        m = d["modes"]
        return cls([e["A"] for e in m], [e["B"] for e in m], [e["C"] for e in m], [e["K"] for e in m], window=d["window"],
                   input_name=d["signals"]["input"], output_name=d["signals"]["output"],
                   state_names=list(d["signals"]["states"]), source=dict(d.get("source", {})))

    def signal_names(self) -> tuple[list[str], list[str], list[str]]:
        """(inputs, outputs, states), as :meth:`PWASVirtualSensor.signal_names` (targets = the states).

        Returns
        -------
        inputs, outputs, states : list of str
            ``[input_name]``, ``[output_name]`` and the ``n`` state names.
        """
        return [self.input_name], [self.output_name], list(self.state_names)


def _zero_c(i: int) -> str:
    """The message for a mode whose output row ``C_i`` is all zero."""
    return (f"modes[{i}].C is all zero: the output y = C x of mode {i + 1} would not depend on the state, "
            "so no observer or residual can tell the mode; give C a non-zero entry")


def _config_errors(c: SwitchedEstimatorConfig) -> list[str]:
    errs = []
    s = len(c.A)
    if not (len(c.B) == len(c.C) == len(c.K) == s) or s < 2:
        return [f"A, B, C, K need one entry per mode (at least 2 modes), got {len(c.A)}, {len(c.B)}, {len(c.C)}, {len(c.K)}"]
    n = c.A[0].shape[0]
    for i in range(s):
        if c.A[i].shape != (n, n):
            errs.append(f"modes[{i}].A is {c.A[i].shape[0]} x {c.A[i].shape[1]}, expected {n} x {n} (one order n in every mode)")
        for key, v in (("B", c.B[i]), ("C", c.C[i]), ("K", c.K[i])):
            if v.shape != (n,):
                errs.append(f"modes[{i}].{key} has {v.size} values, expected n = {n}")
        for key, v in (("A", c.A[i]), ("B", c.B[i]), ("C", c.C[i]), ("K", c.K[i])):
            if not np.all(np.isfinite(v)):
                errs.append(f"modes[{i}].{key} holds a value that is not a finite number")
        if c.C[i].shape == (n,) and not np.any(c.C[i]):
            errs.append(_zero_c(i))
    if not isinstance(c.window, (int, np.integer)) or isinstance(c.window, bool) or not 1 <= int(c.window) <= 64:
        errs.append(f"window must be an integer in 1..64, got {c.window!r}")
    names = [c.input_name, c.output_name, *c.state_names]
    if len(c.state_names) != n:
        errs.append(f"signals.states names {len(c.state_names)} states, the matrices have n = {n}")
    if len(set(names)) != len(names):
        errs.append(f"signal names must be distinct, got {names}")
    return errs


def validate_estimator(d: Any, source: str = "estimator") -> None:
    """Check an estimator dict (header, schema, shapes).

    Parameters
    ----------
    d : Any
        The parsed JSON document.
    source : str
        What to call the document in error messages (e.g. the file path).

    Raises
    ------
    InputError
        One message naming ``source`` and the bad key.
    """
    check_header(d, ESTIMATOR_FORMAT, ESTIMATOR_VERSION, source, _HINT)
    validate(d, ESTIMATOR_SCHEMA, source, _HINT)
    m = d["modes"]
    n = len(m[0]["A"])
    for i, e in enumerate(m):
        for r, row in enumerate(e["A"]):
            if len(row) != n:
                raise InputError(f"{source}: modes[{i}].A[{r}] has {len(row)} values, expected n = {n}; {_HINT}")
        if len(e["A"]) != n:
            raise InputError(f"{source}: modes[{i}].A has {len(e['A'])} rows, expected n = {n} (one order in every mode); {_HINT}")
        for key in ("B", "C", "K"):
            if len(e[key]) != n:
                raise InputError(f"{source}: modes[{i}].{key} has {len(e[key])} values, expected n = {n}; {_HINT}")
        for key in ("A", "B", "C", "K"):
            vals = [v for row in e[key] for v in row] if key == "A" else e[key]
            if not all(math.isfinite(float(v)) for v in vals):
                raise InputError(f"{source}: modes[{i}].{key} holds a value that is not a finite number; {_HINT}")
        if not any(float(v) != 0.0 for v in e["C"]):
            raise InputError(f"{source}: {_zero_c(i)}; {_HINT}")
    sig = d["signals"]
    names = [sig["input"], sig["output"], *sig["states"]]
    if len(sig["states"]) != n:
        raise InputError(f"{source}: signals.states names {len(sig['states'])} states, the matrices have n = {n}; {_HINT}")
    if len(set(names)) != len(names):
        raise InputError(f"{source}: the signal names {names} must be distinct; {_HINT}")


def estimator_text(config: SwitchedEstimatorConfig) -> str:
    """The file text (strict JSON, indented, newline at the end; floats round-trip exactly).

    Parameters
    ----------
    config : SwitchedEstimatorConfig

    Returns
    -------
    str
        The JSON text of :meth:`SwitchedEstimatorConfig.to_dict`.
    """
    return json_text(config.to_dict())


def write_estimator(config: SwitchedEstimatorConfig, path: str | os.PathLike) -> Path:
    """Write the estimator file atomically (temporary file + rename).

    Parameters
    ----------
    config : SwitchedEstimatorConfig
    path : str or os.PathLike
        The file to write (replaced if it exists).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    from pwas_hdl.io.atomic import OutputSet

    p = Path(path)
    with OutputSet() as outset:
        outset.add(p, "the estimator file")
        outset.write_text(p, estimator_text(config))
    return p


def read_estimator(path: str | os.PathLike) -> SwitchedEstimatorConfig:
    """Read and validate an estimator file.

    Parameters
    ----------
    path : str or os.PathLike
        The estimator file.

    Returns
    -------
    SwitchedEstimatorConfig

    Raises
    ------
    FileNotFoundError
        No such file.
    InputError
        Not strict JSON, not an estimator file, another version, or a key missing, unknown, of the
        wrong type or inconsistent (the message names it).
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p} does not exist")
    d = read_json(p, _HINT)
    return SwitchedEstimatorConfig.from_dict(d, str(p))


def is_estimator_file(path: str | os.PathLike) -> bool:
    """True when ``path`` is a file whose JSON ``format`` is ``pwas-hdl-estimator`` (no validation).

    A file that cannot be read, or larger than 64 MiB, is not one (the model reader then reports
    it); a file that names the estimator format in its first 4 kB but is not valid JSON
    (truncated, NaN, not UTF-8) is one, so that :func:`read_estimator` reports it with the
    estimator's own hint.

    Parameters
    ----------
    path : str or os.PathLike
        Any path.

    Returns
    -------
    bool
    """
    try:
        p = Path(path)
        if not p.is_file() or p.stat().st_size > (64 << 20):
            return False
        with open(p, "rb") as f:
            head = f.read(4096)
    except OSError:
        return False
    if b'"pwas-hdl-estimator"' not in head:
        return False
    try:
        d = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return True
    return isinstance(d, dict) and d.get("format") == ESTIMATOR_FORMAT


def config_from_arrays(A: Sequence, B: Sequence, C: Sequence, K: Sequence, **kw: Any) -> SwitchedEstimatorConfig:
    """A configuration from per-mode arrays (as :func:`pwas_hdl.systems.switched_observer.observer_gains` gives ``K``)."""
    return SwitchedEstimatorConfig(list(A), list(B), list(C), list(K), **kw)
