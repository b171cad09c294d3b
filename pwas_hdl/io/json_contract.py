"""Reading JSON files that have a contract: strict JSON, a format/version header, a shipped JSON Schema.

The owners of the file formats (:mod:`pwas_hdl.fit.model_file`, :mod:`pwas_hdl.design.manifest`)
call these helpers, so every format refuses bad files the same way: ONE
:class:`~pwas_hdl.errors.InputError` whose message names the file, the bad key by its path
(``lags.My``, ``ports[3].width``) and what was expected, e.g.
``model.json: lags.My must be an integer, got 2.7``.

The schemas are JSON Schema draft 2020-12 files in ``pwas_hdl/schemas/`` (found with
:func:`pwas_hdl.resources.schemas_dir`), validated with ``jsonschema``.
"""

from __future__ import annotations

import json
import math
import os
import re
import uuid
from functools import lru_cache
from pathlib import Path
from typing import Any, Iterable

from pwas_hdl.errors import InputError, InternalError, ResourceLimit
from pwas_hdl.limits import MAX_JSON_BYTES
from pwas_hdl.resources import schemas_dir

__all__ = ["load_schema", "read_json", "check_header", "validate", "schema_errors", "json_path", "json_text"]


@lru_cache(maxsize=None)
def _schema_and_validator(name: str):
    import jsonschema

    path = schemas_dir() / name
    try:
        schema = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise InternalError(f"the JSON Schema {path} cannot be read ({exc}); the pwas-hdl installation is broken") from exc
    # The shipped schemas are checked against their metaschema by the test suite
    # (tests/test_json_contract.py), not on every load: the draft 2020-12 metaschema check costs
    # about 0.6 s per schema per process, more than most commands' own work.
    cls = jsonschema.validators.validator_for(schema)
    return schema, cls(schema)


def load_schema(name: str) -> dict[str, Any]:
    """The shipped JSON Schema ``pwas_hdl/schemas/<name>`` (parsed; do not modify it).

    Parameters
    ----------
    name : str
        File name in ``pwas_hdl/schemas/``, e.g. ``"model-v2.schema.json"``.

    Returns
    -------
    dict
        The schema, cached per process (the same object on every call).

    Raises
    ------
    InternalError
        The schema file cannot be read or parsed (a broken installation).
    """
    return _schema_and_validator(name)[0]


def _refuse_constant(name: str) -> float:
    raise InputError(f"{name} is not a JSON number")


def read_json(path: str | os.PathLike, hint: str) -> Any:
    """Parse a UTF-8 strict-JSON file (``NaN`` / ``Infinity`` refused).

    Parameters
    ----------
    path : path-like
        The file.
    hint : str
        How to get a good file (e.g. "re-run `pwas-hdl fit`"), appended to the message.

    Returns
    -------
    Any
        The parsed value (``dict``, ``list``, ``str``, ``int``, ``float``, ``bool`` or ``None``).

    Raises
    ------
    FileNotFoundError, OSError
        The file cannot be read.
    InputError
        Not UTF-8, not JSON, or holds a non-JSON constant such as NaN.
    ResourceLimit
        Larger than :data:`~pwas_hdl.limits.MAX_JSON_BYTES`.
    """
    p = Path(path)
    if p.is_dir():  # not "Is a directory": say which file to give (a generate folder's own model file)
        made = [p / n for n in ("model.json", "estimator.json") if (p / "manifest.json").is_file() and (p / n).is_file()]
        if made:
            raise InputError(f"{p} is a folder, not a JSON file: a `pwas-hdl generate` folder, whose model file is "
                             f"{made[0]}; give that file")
        raise InputError(f"{p} is a folder, not a JSON file; give the file's path")
    size = p.stat().st_size if p.is_file() else 0
    if size > MAX_JSON_BYTES:  # before reading: a JSON file of pwas-hdl is at most about 100 MB
        raise ResourceLimit(f"{p} is {size} bytes, more than the limit of {MAX_JSON_BYTES} bytes of a JSON file "
                            f"pwas-hdl reads; {hint}")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{p} is not UTF-8 text (corrupt?): byte 0x{exc.object[exc.start]:02x} at offset {exc.start} cannot be decoded; {hint}"
        ) from exc
    try:
        return json.loads(text, parse_constant=_refuse_constant)
    except json.JSONDecodeError as exc:
        raise InputError(f"{p} is not valid JSON ({exc.msg} at line {exc.lineno}); it is corrupt or truncated, {hint}") from exc
    except ValueError as exc:  # NaN / Infinity
        raise InputError(f"{p} is not valid JSON ({exc}); {hint}") from exc


#: The file formats of pwas-hdl (their ``format`` names; each module owns its own) and what each is
#: for, so that a file given to the wrong command is named for what it is.
FILE_KINDS = {
    "pwas-hdl-model": "a fitted model of `pwas-hdl fit`: predict, info, generate and explore take it",
    "pwas-hdl-estimator": "seed 003's estimator of `make-data switched-linear --estimator-out`: `pwas-hdl generate` takes it",
    "pwas-hdl-manifest": "the manifest of a `pwas-hdl generate` folder: simulate, synth, report and export-testbench take the folder",
    "pwas-hdl-breakpoints": "cuts for `pwas-hdl fit --breakpoints FILE`",
    "pwas-hdl-bench-results": "results of `pwas-hdl bench`",
    "pwas-hdl-explore": "results of `pwas-hdl explore`",
}


def check_header(d: Any, fmt: str, version: int, source: str, hint: str) -> None:
    """Check ``format`` and ``version`` before the schema (an old file gets a version message, not a key list).

    Parameters
    ----------
    d : Any
        The parsed file (:func:`read_json`).
    fmt : str
        Expected ``format``, e.g. ``"pwas-hdl-model"`` (:data:`FILE_KINDS`).
    version : int
        The one supported ``version``.
    source, hint : str
        File name for the message, and how to get a good file (appended).

    Raises
    ------
    InputError
        ``d`` is not an object with ``"format": fmt``, or its version is not ``version``.
    """
    if not isinstance(d, dict) or d.get("format") != fmt:
        other = d.get("format") if isinstance(d, dict) else None
        if isinstance(other, str) and other in FILE_KINDS:  # another pwas-hdl file given where this one belongs
            # the file is good, of another kind: "re-run fit to write it again" would send the user the wrong way
            wanted = f" ({FILE_KINDS[fmt]})" if fmt in FILE_KINDS else ""
            raise InputError(f"{source} is a {other} file ({FILE_KINDS[other]}), not a {fmt} file{wanted}; "
                             f"give a {fmt} file here")
        raise InputError(f'{source} is not a {fmt} file (missing "format": "{fmt}"); {hint}')
    v = d.get("version")
    if type(v) is not int or v != version:
        raise InputError(f"{source}: {fmt} version {v!r} is not supported (this pwas-hdl reads version {version}); {hint}")


def json_path(parts: Iterable[Any]) -> str:
    """``["lags", "My"]`` -> ``lags.My``; ``["ports", 3, "width"]`` -> ``ports[3].width``.

    Parameters
    ----------
    parts : iterable
        Keys (``str``) and list indices (``int``), outermost first.

    Returns
    -------
    str
        The dotted path; ``""`` for no parts.
    """
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def _show(value: Any) -> str:
    text = json.dumps(value, allow_nan=True, default=str)
    return text if len(text) <= 60 else text[:57] + "..."


_TYPE_WORDS = {"integer": "an integer", "number": "a number", "string": "a string", "boolean": "true or false",
               "object": "an object", "array": "a list", "null": "null"}


def _describe(err) -> str:
    """One sentence for one :class:`jsonschema.ValidationError`, naming the key by its path."""
    path = json_path(err.absolute_path)
    where = path or "the top level"
    kind, want, inst = err.validator, err.validator_value, err.instance
    if kind == "type":
        types = [want] if isinstance(want, str) else list(want)
        return f"{where} must be {' or '.join(_TYPE_WORDS.get(t, t) for t in types)}, got {_show(inst)}"
    if kind == "required":
        missing = [k for k in want if isinstance(inst, dict) and k not in inst]
        return f"{json_path([*err.absolute_path, missing[0]]) if missing else where} is missing"
    if kind == "additionalProperties":
        known = set((err.schema.get("properties") or {}))
        extra = sorted(k for k in inst if k not in known) if isinstance(inst, dict) else []
        return f"{where} has the unknown key{'s' if len(extra) > 1 else ''} {', '.join(repr(k) for k in extra)}"
    if kind == "const":
        return f"{where} must be {_show(want)}, got {_show(inst)}"
    if kind == "enum":
        return f"{where} must be one of {', '.join(_show(v) for v in want)}, got {_show(inst)}"
    if kind in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        op = {"minimum": ">=", "maximum": "<=", "exclusiveMinimum": ">", "exclusiveMaximum": "<"}[kind]
        return f"{where} must be {op} {want}, got {_show(inst)}"
    if kind == "minItems":
        return f"{where} must have at least {want} item{'s' if want != 1 else ''}, got {len(inst)}"
    if kind == "maxItems":
        return f"{where} must have at most {want} item{'s' if want != 1 else ''}, got {len(inst)}"
    if kind == "minLength":
        return f"{where} must not be empty" if want == 1 else f"{where} must have at least {want} characters"
    if kind == "pattern":
        return f"{where} must match {want}, got {_show(inst)}"
    if kind == "uniqueItems":
        return f"{where} has repeated items"
    if kind == "not" and isinstance(want, dict):  # "not": {"required": [...]} or an anyOf of them: keys that must be absent
        alts = want.get("anyOf", [want])
        keys = [k for a in alts if isinstance(a, dict) and set(a) == {"required"} for k in a["required"]]
        if keys and len(keys) == sum(len(a["required"]) for a in alts if isinstance(a, dict) and "required" in a):
            present = [k for k in keys if isinstance(inst, dict) and k in inst]
            return f"{where} must not have the key{'s' if len(present) > 1 else ''} {', '.join(repr(k) for k in present)}"
    return f"{where}: {err.message}"


def schema_errors(d: Any, schema_name: str) -> list[str]:
    """Every schema violation of ``d`` as one sentence each, most relevant first.

    Parameters
    ----------
    d : Any
        The parsed file.
    schema_name : str
        Shipped schema file name (:func:`load_schema`).

    Returns
    -------
    list of str
        Empty when ``d`` is valid.
    """
    from jsonschema.exceptions import best_match, relevance

    _, validator = _schema_and_validator(schema_name)
    errs = list(validator.iter_errors(d))
    if not errs:
        return []
    first = best_match(errs)
    rest = sorted((e for e in errs if e is not first), key=relevance)
    return [_describe(e) for e in [first, *rest]]


def validate(d: Any, schema_name: str, source: str, hint: str) -> None:
    """Validate ``d`` against a shipped schema.

    Parameters
    ----------
    d : Any
        The parsed file.
    schema_name : str
        Shipped schema file name (:func:`load_schema`).
    source, hint : str
        As :func:`check_header`: the file's name and the advice appended to the message.

    Raises
    ------
    InputError
        ``"<source>: <path> must be ..., got ...; <hint>"`` for the most relevant violation
        (``jsonschema.exceptions.best_match``).
    """
    errs = schema_errors(d, schema_name)
    if errs:
        more = f" (and {len(errs) - 1} more problem{'s' if len(errs) > 2 else ''})" if len(errs) > 1 else ""
        raise InputError(f"{source}: {errs[0]}{more}; {hint}")


#: Lists of at least this many numbers are written by :func:`json_text` in one pass.
_LONG_LIST = 256


def json_text(obj: Any) -> str:
    """The text of a contract file: ``json.dumps(obj, indent=1, allow_nan=False) + "\n"``, byte
    for byte, but fast for long lists of numbers.

    ``json.dumps`` with an indent runs Python's pure-Python encoder: ~2.4 s for the 10^6 weights
    of a model file (one number a line). Here every list of at least 256 plain ``float`` / ``int``
    items is set aside, the rest dumped by ``json``, and each list put back as the text ``json``
    would give it (``repr`` of each item, one a line, indented one space deeper than the line that
    holds it).

    Parameters
    ----------
    obj : JSON-ready object
        Dicts with string keys, lists, strings, numbers, booleans, None.

    Returns
    -------
    str
        Ends with a newline.

    Raises
    ------
    InputError
        A float that is not finite (strict JSON has no NaN or infinity).
    """
    lists: list[list] = []
    mark = f"@pwas-json-{uuid.uuid4().hex}-"

    def not_finite(where: list, value: Any) -> InputError:
        return InputError(f"{json_path(where) or 'the value'} is {value!r}, not a finite number: strict JSON cannot hold "
                          "it (a NaN or an infinity came out of the computation)")

    def set_aside(o: Any, where: list) -> Any:
        if isinstance(o, dict):
            return {k: set_aside(v, [*where, k]) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            types = set(map(type, o)) if len(o) >= _LONG_LIST else None
            if types is not None and types <= {float, int}:
                floats = o if types == {float} else [v for v in o if type(v) is float]
                if not all(map(math.isfinite, floats)):
                    k = next(k for k, v in enumerate(o) if type(v) is float and not math.isfinite(v))
                    raise not_finite([*where, k], o[k])
                lists.append(o)
                return f"{mark}{len(lists) - 1}"
            return [set_aside(v, [*where, k]) for k, v in enumerate(o)]
        if isinstance(o, float) and not math.isfinite(o):
            raise not_finite(where, o)
        return o

    text = json.dumps(set_aside(obj, []), indent=1, allow_nan=False)
    if not lists:
        return text + "\n"

    def put_back(m: re.Match) -> str:
        head = m.string[m.string.rfind("\n", 0, m.start()) + 1:m.start()]  # the line up to the list
        level = len(head) - len(head.lstrip(" "))
        pad = "\n" + " " * (level + 1)
        return "[" + pad + ("," + pad).join(map(repr, lists[int(m.group(1))])) + "\n" + " " * level + "]"

    return re.sub(f'"{re.escape(mark)}(\\d+)"', put_back, text) + "\n"
