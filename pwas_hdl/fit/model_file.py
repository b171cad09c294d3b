"""The model file: the one owner of its format (name, version, JSON Schema, writing, reading).

``pwas-hdl fit`` writes it, every later stage reads it (``predict``, ``generate``, ``simulate``,
``explore``, ``report``). Format ``pwas-hdl-model``, version 2, schema
``pwas_hdl/schemas/model-v2.schema.json`` (its ``$id`` is the file's ``$schema``)::

    {
      "$schema": "urn:pwas-hdl:schema:model-v2", "format": "pwas-hdl-model", "version": 2,
      "signals": {"inputs": [...], "outputs": [...], "targets": [...]},
      "lags": {"Mu": int, "My": int},
      "regressors": ["y[t-3]", ...],                 # order of the regressor dimensions
      "grid": {"lo": [...], "hi": [...], "partitions": [...]},
      "weights": {"<target>": [w_0, ..., w_{N-1}], ...},   # vertex order of pwas_hdl.fit.geometry
      "fit": {"sigma": ..., "sigma_given": bool, "tikhonov_order": 0 | 1, "gamma": ..., "domain_from":
              "data" | "explicit", "share_lag_domain": bool, "n_train": int, "n_trajectories": int,
              "train_rmse": {"<target>": ...}, "cv": {"sigmas", "mse", "best_sigma", "folds"[, "shuffle"]} | null,
              "solve": {...}}     # optional, see below
    }

Optional ``fit.solve`` block (issue 18; absent in earlier files and for dynamical sensors, which load
as before -- no version bump, but a reader from before the block refuses a file that has it, as
``fit`` admits no unknown key): how well the weights solve the regularised normal equations at
``sigma``, checked afresh from the weights (:func:`pwas_hdl.fit.regularized_lsq.solve_report`; a
non-finite residual or bound is written as null)::

      "solve": {"method": str | null, "iterations": int | null, "converged": bool,
                "rel_residual": float, "weight_bound": float | null,   # ||w - w_exact||_2 <= weight_bound
                "cv_solves": int | null, "cv_unconverged": int | null}

Optional ``recurrence`` block (issue 13, a dynamical sensor: :mod:`pwas_hdl.fit.recurrent`; absent
for a static sensor, so files without it load as before -- no version bump)::

      "recurrence": {"Mz": int >= 1, "lead": 0 | 1,
                     "initial_state": {"rule": "value", "values": {"<target>": [z(t0-Mz), .., z(t0-1)]}}
                                    | {"rule": "measured"},
                     "fit": {"mode": "series-parallel" | "map", "refine": int, "iterations_used": int,
                             "series_parallel_rmse": {...}, "closed_loop_rmse": {...}, "history": [...],
                             "map_error": {"max": .., "rms": .., "n_test": ..}}}   # stats per mode

The regressors then end with the ``nz * Mz`` past estimates ``<target>_hat[t-Mz] .. <target>_hat[t-1]``.
Optional ``map_fit`` block (a PWAS approximation of a given map, :mod:`pwas_hdl.fit.map_approximation`)::

      "map_fit": {"max_error": {"<target>": ..}, "rms_error": {"<target>": ..}, "n_test": int, "test": "how"}
An additive sensor (:mod:`pwas_hdl.fit.additive`, ``fit --additive``) adds the optional key
``"additive": {"spec": "pairs", "parts": [[0, 1], [1, 2], ...]}`` (the rule as given and the
regressor indices of each part); ``grid`` is then the shared domain box of all ``n`` regressors and
each weight list holds the parts' weights one after the other (``sum_i prod_{j in S_i} (p_j + 1)``
values, part order, each part in the vertex order of its own grid). Files without the key are full
PWAS sensors, as before.

Floats are written with Python's shortest round-trip representation, so a save / load round trip
is bit-exact. Reading checks, in this order: strict JSON (no NaN), ``format`` and ``version`` (a
file of another version is refused with "version N is not supported; re-run `pwas-hdl fit`"),
the schema (every key, its type and range: the message names the key, e.g.
``m.json: lags.My must be an integer, got 2.7``), then the consistency the schema cannot state
(regressor names, dimensions, N weights per target). There are no fallbacks for missing or
renamed keys.

Version history: 1 (no ``$schema``; ``int()`` of the lags accepted 2.7 as 2), 2 (this one).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pwas_hdl.errors import InputError, ResourceLimit, fault_text
from pwas_hdl.io.atomic import atomic_write_text
from pwas_hdl.limits import check_vertices, check_weights
from pwas_hdl.io.json_contract import check_header, json_text, read_json, schema_errors, validate

if TYPE_CHECKING:
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

__all__ = [
    "MODEL_FORMAT", "MODEL_VERSION", "MODEL_SCHEMA", "MODEL_SCHEMA_ID",
    "model_to_dict", "model_text", "write_model", "validate_model", "model_errors", "model_from_dict", "read_model",
]

MODEL_FORMAT = "pwas-hdl-model"
MODEL_VERSION = 2
#: File name of the schema in ``pwas_hdl/schemas/``.
MODEL_SCHEMA = "model-v2.schema.json"
#: The schema's ``$id``, written as ``$schema`` in every model file.
MODEL_SCHEMA_ID = "urn:pwas-hdl:schema:model-v2"

_HINT = "re-run `pwas-hdl fit` to write the model file again"


def model_to_dict(sensor: "PWASVirtualSensor") -> dict[str, Any]:
    """The model-file content of a fitted sensor as a JSON-ready dict (valid against the schema).

    Parameters
    ----------
    sensor : PWASVirtualSensor
        A fitted (or loaded) sensor.

    Returns
    -------
    dict
        Header, ``signals``, ``lags``, ``regressors``, ``grid`` (physical units), ``weights`` (one
        list of ``N`` floats per target, in target units), ``fit``; and the optional
        ``classifier``, ``front_end``, ``recurrence``, ``map_fit`` and ``additive`` blocks.

    Raises
    ------
    sklearn.exceptions.NotFittedError
        ``sensor`` is not fitted.
    """
    sensor._check_fitted()
    ins, outs, tgts = sensor.signal_names()
    lags, grid = sensor.lags_, sensor.grid_
    d = {
        "$schema": MODEL_SCHEMA_ID,
        "format": MODEL_FORMAT,
        "version": MODEL_VERSION,
        "signals": {"inputs": ins, "outputs": outs, "targets": tgts},
        "lags": {"Mu": int(lags.mu if lags is not None else sensor.mu), "My": int(lags.my if lags is not None else sensor.my)},
        "regressors": sensor._regressor_names(lags),
        "grid": {
            "lo": [float(v) for v in grid.lo],
            "hi": [float(v) for v in grid.hi],
            "partitions": [int(v) for v in grid.partitions],
            **({"breakpoints": [None if b is None else [float(v) for v in b] for b in grid.breakpoints]}
               if getattr(grid, "breakpoints", None) is not None else {}),
        },
        "weights": {t: np.asarray(sensor.weights_[:, i], dtype=float).tolist() for i, t in enumerate(tgts)},
        "fit": {
            "sigma": float(sensor.sigma_),
            "sigma_given": sensor.sigma is not None,
            "tikhonov_order": int(sensor.tikhonov_order),
            "gamma": float(sensor.gamma),
            "domain_from": "explicit" if sensor.domain is not None else "data",
            "share_lag_domain": bool(sensor.share_lag_domain),
            "n_train": int(sensor.n_train_),
            "n_trajectories": int(sensor.n_trajectories_),
            "train_rmse": {t: float(v) for t, v in zip(tgts, sensor.train_rmse_)},
            "cv": sensor.cv_.to_dict() if sensor.cv_ is not None else None,
            **({"solve": _solve_to_dict(sensor.solve_)} if getattr(sensor, "solve_", None) is not None else {}),
            **({"breakpoints": sensor.breakpoints if isinstance(sensor.breakpoints, str) else "given"}
               if getattr(grid, "breakpoints", None) is not None else {}),
        },
    }
    classifier = getattr(sensor, "classifier_", None)
    if classifier is not None:  # optional: one-hot class scores (pwas_hdl.fit.classifier)
        d["classifier"] = {"target": str(classifier["target"]), "classes": [float(c) for c in classifier["classes"]]}
    # ---- front end (seed 004): only for observer-bank sensors; owned by pwas_hdl.fit.observer_bank
    front_end = getattr(sensor, "front_end_", None)
    if front_end is not None:
        d["front_end"] = front_end.to_dict()
    if lags is not None and lags.recurrent:  # dynamical sensor (issue 13): pwas_hdl.fit.recurrent
        d["recurrence"] = _recurrence_to_dict(sensor, tgts)
    map_fit = getattr(sensor, "map_fit_", None)
    if map_fit is not None:  # a PWAS approximation of a given map (pwas_hdl.fit.map_approximation)
        d["map_fit"] = {"max_error": {t: float(v) for t, v in zip(tgts, map_fit["max"])},
                        "rms_error": {t: float(v) for t, v in zip(tgts, map_fit["rms"])},
                        "n_test": int(map_fit["n_test"]), "test": str(map_fit["test"])}
    # ---- additive sensor (issue 15): the parts' regressor subsets; owned by pwas_hdl.fit.additive
    subsets = getattr(grid, "subsets", None)
    if subsets is not None:
        from pwas_hdl.fit.additive import format_subsets

        spec = sensor.additive if isinstance(sensor.additive, str) else format_subsets(subsets)
        d["additive"] = {"spec": spec, "parts": [[int(v) for v in s] for s in subsets]}
    return d


def _stat(v: Any) -> Any:
    """JSON-ready copy of a statistic: arrays to lists, numpy scalars to float."""
    if isinstance(v, dict):
        return {k: _stat(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_stat(x) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    return float(v)


def _recurrence_to_dict(sensor: "PWASVirtualSensor", tgts: list[str]) -> dict[str, Any]:
    from pwas_hdl.fit.recurrent import initial_state_dict

    lags = sensor.lags_
    fit = dict(getattr(sensor, "recurrence_fit_", None) or {"mode": "series-parallel"})
    out_fit: dict[str, Any] = {"mode": str(fit.pop("mode"))}
    for key, val in fit.items():
        if key in ("series_parallel_rmse", "closed_loop_rmse", "series_parallel_closed_loop_rmse"):
            vals = [val[t] for t in tgts] if isinstance(val, dict) else np.asarray(val, dtype=float).reshape(-1)
            out_fit[key] = {t: float(v) for t, v in zip(tgts, vals)}
        else:
            out_fit[key] = _stat(val)
    return {
        "Mz": int(lags.mz),
        "lead": int(getattr(sensor, "lead_", 0)),
        "initial_state": initial_state_dict(sensor.initial_state_rule_, getattr(sensor, "initial_values_", None), tgts),
        "fit": out_fit,
    }


def _front_end_regressors(d: dict[str, Any]) -> tuple[Any, Any, list[str]]:
    """The observer-bank block of ``d``: (front end, tap lag structure or None, regressor names).

    Raises
    ------
    InputError
        The block is incomplete or inconsistent with the signals.
    """
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
    from pwas_hdl.fit.regressors import LagStructure

    try:
        fe = ObserverBankFrontEnd.from_dict(d["front_end"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"front_end is corrupt or incomplete ({fault_text(exc)})") from None
    ins, outs = d["signals"]["inputs"], d["signals"]["outputs"]
    if fe.nu_ != len(ins) or len(outs) != 1:
        raise InputError(f"front_end has {fe.nu_} inputs and 1 output, signals.inputs {len(ins)} and signals.outputs {len(outs)}")
    mu, my = d["lags"]["Mu"], d["lags"]["My"]
    taps = LagStructure(mu, my, len(ins) if mu else 0, 1 if my else 0) if (mu * len(ins) + my) else None
    return fe, taps, fe.feature_names() + (taps.names(ins, outs) if taps is not None else [])


def model_text(sensor: "PWASVirtualSensor") -> str:
    """The model file's text (strict JSON, one key per line at the top, newline at the end).

    Parameters
    ----------
    sensor : PWASVirtualSensor
        A fitted (or loaded) sensor.

    Returns
    -------
    str
        The JSON text of :func:`model_to_dict`.

    Raises
    ------
    InputError
        A weight or statistic is not finite (not representable in JSON).
    """
    return json_text(model_to_dict(sensor))


def write_model(sensor: "PWASVirtualSensor", path: str | os.PathLike) -> Path:
    """Write the model file atomically (nothing is left half-written on error); returns the path.

    Parameters
    ----------
    sensor : PWASVirtualSensor
        A fitted (or loaded) sensor.
    path : str or os.PathLike
        The model file to write (replaced if it exists).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        A weight or statistic is not finite (:func:`model_text`).
    """
    return atomic_write_text(path, model_text(sensor))


def _consistency_errors(d: dict[str, Any]) -> list[str]:
    """What the schema cannot say: names, dimensions and sizes that must agree (``d`` is schema-valid)."""
    from pwas_hdl.fit.regressors import LagStructure

    sig, lags, g = d["signals"], d["lags"], d["grid"]
    ins, outs, tgts = sig["inputs"], sig["outputs"], sig["targets"]
    errs = []
    if lags["Mu"] and not ins:
        errs.append(f"lags.Mu is {lags['Mu']} but signals.inputs is empty")
    if lags["My"] and not outs:
        errs.append(f"lags.My is {lags['My']} but signals.outputs is empty")
    if errs:
        return errs
    if "front_end" in d:
        try:
            _, _, names = _front_end_regressors(d)
        except ValueError as exc:
            return [str(exc)]
        n = len(names)
    else:
        mz = d["recurrence"]["Mz"] if "recurrence" in d else 0
        try:
            ls = LagStructure(lags["Mu"], lags["My"], len(ins) if lags["Mu"] else 0, len(outs) if lags["My"] else 0,
                              mz, len(tgts) if mz else 0)
        except ValueError as exc:
            return [str(exc)]
        n = ls.dimension
        names = ls.names(ins, outs, tgts)
        rec = d.get("recurrence")
        if rec is not None and rec["initial_state"]["rule"] == "value":
            vals = rec["initial_state"].get("values")
            if vals is None or list(vals) != tgts or any(len(v) != mz for v in vals.values()):
                return [f"recurrence.initial_state.values must give Mz = {mz} values for each of the targets {tgts}"]
    for key in ("lo", "hi", "partitions") + (("breakpoints",) if "breakpoints" in g else ()):
        if len(g[key]) != n:
            errs.append(f"grid.{key} has {len(g[key])} values, the lags give n = {n} regressors")
    if errs:
        return errs
    if d["regressors"] != names:
        errs.append(f"regressors {d['regressors']} do not match the lags and signal names ({names})")
    if "additive" in d:
        errs += _additive_errors(d, names)
        if errs:
            return errs
        n_vertices = sum(int(np.prod([g["partitions"][j] + 1 for j in part], dtype=object)) for part in d["additive"]["parts"])
    else:
        try:  # a grid above the vertex limit is refused as such, whatever the weights say
            n_vertices = check_vertices(g["partitions"])
        except ResourceLimit as exc:
            return [str(exc)]
    try:
        check_weights(n_vertices, len(tgts))
    except ResourceLimit as exc:
        return [str(exc)]
    for what, keys in (("weights", list(d["weights"])), ("fit.train_rmse", list(d["fit"]["train_rmse"]))):
        if keys != tgts:
            errs.append(f"{what} has the keys {keys}, signals.targets are {tgts}")
    for t, w in d["weights"].items():
        if len(w) != n_vertices:
            errs.append(f"weights.{t} has {len(w)} values, the grid has N = {n_vertices} vertices")
    rec_fit = d["recurrence"]["fit"] if "recurrence" in d else {}
    for k in ("series_parallel_rmse", "closed_loop_rmse", "series_parallel_closed_loop_rmse"):
        if k in rec_fit and list(rec_fit[k]) != tgts:
            errs.append(f"recurrence.fit.{k} has the keys {list(rec_fit[k])}, signals.targets are {tgts}")
    if "map_fit" in d and any(list(d["map_fit"][k]) != tgts for k in ("max_error", "rms_error")):
        errs.append(f"map_fit.max_error / map_fit.rms_error must have the keys {tgts}")
    if "classifier" in d and len(d["classifier"]["classes"]) != len(tgts):
        errs.append(f"classifier.classes has {len(d['classifier']['classes'])} classes, signals.targets {len(tgts)} targets")
    cv = d["fit"]["cv"]
    if cv is not None and len(cv["mse"]) != len(cv["sigmas"]):
        errs.append(f"fit.cv.mse has {len(cv['mse'])} values for {len(cv['sigmas'])} fit.cv.sigmas")
    return errs


def _additive_errors(d: dict[str, Any], names: list[str]) -> list[str]:
    """The ``additive`` block: parts that are valid subsets of the ``n`` regressors and agree with the spec."""
    from pwas_hdl.fit.additive import parse_additive
    from pwas_hdl.fit.regressors import LagStructure

    if "front_end" in d:
        return ["additive is given together with front_end (an additive sensor has the lag front end)"]
    if "recurrence" in d:
        return ["additive is given together with recurrence (an additive sensor with past estimates is not available)"]
    n = len(names)
    parts = d["additive"]["parts"]
    for k, part in enumerate(parts):
        if part != sorted(set(part)) or part[0] < 0 or part[-1] >= n:
            return [f"additive.parts[{k}] = {part} is not a sorted list of distinct regressor indices 0..{n - 1}"]
    sig, lags = d["signals"], d["lags"]
    ls = LagStructure(lags["Mu"], lags["My"], len(sig["inputs"]) if lags["Mu"] else 0, len(sig["outputs"]) if lags["My"] else 0)
    try:
        want = [list(s) for s in parse_additive(d["additive"]["spec"], ls.signal_of_dimension())]
    except InputError as exc:
        return [f"additive.spec {d['additive']['spec']!r} is not valid ({exc})"]
    if want != parts:
        return [f"additive.parts {parts} differ from the parts of additive.spec {d['additive']['spec']!r} ({want})"]
    return []


def _schema_view(d: Any) -> Any:
    """``d`` as the schema check sees it: each weight list cut to its first item when every item
    is a JSON number (``int`` or ``float``, not ``bool``).

    The schema asks of a weight list only that it is non-empty and holds numbers; checked here in
    one pass, the schema validator's cost no longer grows with N (20 s for 10^6 weights). Any
    other content, including a list with a non-number, is left whole: the validator's message then
    names the bad item.
    """
    w = d.get("weights") if isinstance(d, dict) else None
    if not isinstance(w, dict) or not all(isinstance(v, list) and all(type(x) is float or type(x) is int for x in v)
                                           for v in w.values()):
        return d
    return {**d, "weights": {k: v[:1] for k, v in w.items()}}


def model_errors(d: Any) -> list[str]:
    """Every problem of a model-file dict, one sentence each (empty: a valid model file).

    A wrong format or version is the only problem reported; then the schema's violations, or,
    when there are none, the consistency problems (names, dimensions, sizes).

    Parameters
    ----------
    d : Any
        The parsed JSON document.

    Returns
    -------
    list of str
    """
    if not isinstance(d, dict) or d.get("format") != MODEL_FORMAT:
        return [f'not a {MODEL_FORMAT} file (missing "format": "{MODEL_FORMAT}")']
    if type(d.get("version")) is not int or d.get("version") != MODEL_VERSION:
        return [f"version {d.get('version')!r} is not supported (this pwas-hdl reads version {MODEL_VERSION})"]
    return schema_errors(_schema_view(d), MODEL_SCHEMA) or _consistency_errors(d)


def validate_model(d: Any, source: str = "model") -> None:
    """Check a model-file dict against the format (header, schema, consistency).

    Parameters
    ----------
    d : Any
        The parsed JSON document.
    source : str
        What to call the document in error messages (e.g. the file path).

    Raises
    ------
    InputError
        One message that names ``source``, the bad key and what was expected.
    """
    check_header(d, MODEL_FORMAT, MODEL_VERSION, source, _HINT)
    validate(_schema_view(d), MODEL_SCHEMA, source, _HINT)
    errs = _consistency_errors(d)
    if errs:
        raise InputError(f"{source}: {errs[0]}; {_HINT}")


def model_from_dict(d: Any, source: str = "model") -> "PWASVirtualSensor":
    """A fitted sensor from a model-file dict (validated first, see :func:`validate_model`).

    Parameters
    ----------
    d : Any
        The parsed JSON of a model file (what :func:`model_to_dict` returns).
    source : str
        What to call the document in error messages (e.g. the file path).

    Returns
    -------
    PWASVirtualSensor
        A fitted sensor: grid, weights ``(N, nz)``, ``sigma_``, CV result and the optional
        front end, recurrence, classifier and additive parts restored.

    Raises
    ------
    InputError
        ``d`` is not a valid model document, or its grid is impossible (the message names
        ``source``).
    """
    from pwas_hdl.fit.geometry import Grid
    from pwas_hdl.fit.regressors import LagStructure
    from pwas_hdl.fit.regularized_lsq import CVResult
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    validate_model(d, source)
    sig, lags, g, fit = d["signals"], d["lags"], d["grid"], d["fit"]
    ins, outs, tgts = list(sig["inputs"]), list(sig["outputs"]), list(sig["targets"])
    try:
        if "additive" in d:
            from pwas_hdl.fit.additive import AdditiveGrid

            grid = AdditiveGrid(g["lo"], g["hi"], g["partitions"], d["additive"]["parts"])
        else:
            grid = Grid(g["lo"], g["hi"], g["partitions"], breakpoints=g.get("breakpoints"))
    except ValueError as exc:  # widths <= 0, too many vertices, ...
        raise InputError(f"{source}: grid: {exc}; {_HINT}") from exc
    w = np.array([d["weights"][t] for t in tgts], dtype=float).T.reshape(grid.n_vertices, len(tgts))
    obj = PWASVirtualSensor(
        mu=lags["Mu"],
        my=lags["My"],
        partitions=list(g["partitions"]),
        gamma=float(fit["gamma"]),
        sigma=float(fit["sigma"]) if fit["sigma_given"] else None,
        tikhonov_order=fit["tikhonov_order"],
        domain=(grid.lo, grid.hi) if fit["domain_from"] == "explicit" else None,
        share_lag_domain=fit["share_lag_domain"],
        input_names=ins,
        output_names=outs,
        target_names=tgts,
        additive=d["additive"]["spec"] if "additive" in d else None,
    )
    if getattr(grid, "breakpoints", None) is not None:  # the rule, or the cut points themselves when they were given
        rule = fit.get("breakpoints", "given")
        obj.breakpoints = rule if rule != "given" else [None if b is None else b.tolist() for b in grid.breakpoints]
    cv = fit["cv"]
    if cv is not None:  # the CV's own settings, so that clone(loaded).fit(...) cross-validates as the original did
        from pwas_hdl.fit.regularized_lsq import DEFAULT_SIGMA_GRID

        obj.cv_folds = int(cv["folds"])
        obj.cv_shuffle = bool(cv.get("shuffle", False))
        sigmas = [float(v) for v in cv["sigmas"]]
        obj.sigma_grid = None if np.array_equal(sigmas, DEFAULT_SIGMA_GRID) else sigmas
    if "front_end" in d:
        fe, taps, _ = _front_end_regressors(d)
        obj.front_end = fe
        obj.front_end_ = fe
        obj.lags_ = taps
        obj.nu_, obj.ny_ = fe.nu_, 1
    else:
        obj.front_end_ = None
        rec = d.get("recurrence")
        mz = rec["Mz"] if rec is not None else 0
        obj.lags_ = LagStructure(obj.mu, obj.my, len(ins) if obj.mu else 0, len(outs) if obj.my else 0, mz, len(tgts) if mz else 0)
        obj.nu_, obj.ny_ = obj.lags_.nu, obj.lags_.ny
        obj.lead_ = 0
        if rec is not None:
            st = rec["initial_state"]
            obj.mz = mz
            obj.refine = int(rec["fit"].get("refine", 0))
            obj.lead_ = int(rec["lead"])
            obj.initial_state_rule_ = st["rule"]
            if st["rule"] == "value":
                obj.initial_values_ = np.array([st["values"][t] for t in tgts], dtype=float).T.reshape(mz, len(tgts))
                obj.initial_state = obj.initial_values_.copy()
            else:
                obj.initial_state = "measured"
            obj.recurrence_fit_ = dict(rec["fit"])
    obj.grid_ = grid
    obj.weights_ = w
    obj.sigma_ = float(fit["sigma"])
    obj.cv_ = (CVResult(np.array(cv["sigmas"], dtype=float), np.array(cv["mse"], dtype=float), float(cv["best_sigma"]),
                        int(cv["folds"]), shuffle=bool(cv.get("shuffle", False))) if cv is not None else None)
    obj.solve_ = dict(fit["solve"]) if "solve" in fit else None
    obj.n_train_ = int(fit["n_train"])
    obj.n_trajectories_ = int(fit["n_trajectories"])
    obj.train_rmse_ = np.array([fit["train_rmse"][t] for t in tgts], dtype=float)
    if "map_fit" in d:
        mf = d["map_fit"]
        obj.map_fit_ = {"max": [mf["max_error"][t] for t in tgts], "rms": [mf["rms_error"][t] for t in tgts],
                        "n_test": mf["n_test"], "test": mf["test"]}
    if "classifier" in d:  # the estimator's own parameters (classify, the label's name), so that a refit classifies
        obj.classify, obj.target_names = True, [d["classifier"]["target"]]
        obj.classifier_ = {"target": d["classifier"]["target"], "classes": [float(c) for c in d["classifier"]["classes"]]}
    return obj


#: The keys of the optional ``fit.solve`` block, in file order (see :func:`pwas_hdl.fit.regularized_lsq.solve_report`).
SOLVE_KEYS = ("method", "iterations", "converged", "rel_residual", "weight_bound", "cv_solves", "cv_unconverged")


def _solve_to_dict(report: dict) -> dict:
    """The ``fit.solve`` block: the solve report's keys in file order, numbers as plain floats and ints."""
    out = {}
    for k in SOLVE_KEYS:
        v = report.get(k)
        if v is None or isinstance(v, (bool, str)):
            out[k] = v
        elif k in ("iterations", "cv_solves", "cv_unconverged"):
            out[k] = int(v)
        else:
            out[k] = float(v) if math.isfinite(float(v)) else None
    return out


def read_model(path: str | os.PathLike) -> "PWASVirtualSensor":
    """Read and validate a model file written by :func:`write_model`.

    Parameters
    ----------
    path : str or os.PathLike
        The model file.

    Returns
    -------
    PWASVirtualSensor
        The fitted sensor (:func:`model_from_dict`).

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    InputError
        Not UTF-8 / strict JSON, not a pwas-hdl model, another version, or a key missing, of the
        wrong type or out of range (the message names it), or inconsistent content.
    """
    p = Path(path)
    return model_from_dict(read_json(p, _HINT), source=str(p))
