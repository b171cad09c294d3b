"""The public API documents itself: every parameter of what ``pwas_hdl`` exports is annotated and named
in its numpydoc Parameters section (the project standard: type hints on public functions, numpydoc
docstrings that say units and shapes).

Checked for each name of ``pwas_hdl.__all__``: a function's parameters and return; a class's
constructor parameters (in the class docstring's Parameters or, for dataclass fields, Attributes
section, as numpydoc documents a constructor) and its public methods (those the class defines, not
the inherited scikit-learn ones). The sections are parsed by hand (numpydoc is not a dependency):
a section is a title line over a line of dashes; an entry is ``name : type`` (or ``a, b : type``)
at the section's indentation, its description indented below.

The same rules hold for the modules' own API (:data:`DOCUMENTED_PACKAGES`): every function and
class that a submodule of those packages lists in its ``__all__`` and defines itself, and for the
single-file modules of :data:`DOCUMENTED_MODULES`.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil
import re
import textwrap

import pytest

import pwas_hdl

_DASHES = re.compile(r"\s*-{3,}\s*")
_TITLE = re.compile(r"\s*([A-Z][A-Za-z ]*?)\s*(\(.*\))?\s*")


def _sections(doc: str) -> dict[str, list[str]]:
    """Section title (``Parameters``, ``Returns``, ...) -> its lines (dedented)."""
    lines = (doc or "").expandtabs().splitlines()
    lines = lines[:1] + textwrap.dedent("\n".join(lines[1:])).splitlines()
    out: dict[str, list[str]] = {}
    title = None
    for i, line in enumerate(lines):
        if _DASHES.fullmatch(line):  # a title's underline
            continue
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        m = _TITLE.fullmatch(line)
        if m and line.strip() and _DASHES.fullmatch(nxt):
            title = m.group(1)
            out.setdefault(title, [])
        elif title is not None:
            out[title].append(line)
    return out


def _entries(lines: list[str]) -> dict[str, str]:
    """Parameter name -> its type and description, of one Parameters-like section."""
    base = None
    out: dict[str, str] = {}
    current: list[str] = []
    for line in lines:
        if not line.strip():
            continue
        indent = len(line) - len(line.lstrip())
        base = indent if base is None else base
        if indent <= base:
            head, _, typ = line.strip().partition(" :")
            current = [n.strip().lstrip("*") for n in head.split(",") if n.strip()]
            for name in current:
                out[name] = typ
        else:
            for name in current:
                out[name] += " " + line.strip()
    return out


def _documented(doc: str, titles: tuple[str, ...]) -> dict[str, str]:
    secs = _sections(doc)
    out: dict[str, str] = {}
    for title, lines in secs.items():
        if title.startswith(titles):
            out.update(_entries(lines))
    return out


def _public_callables(names: list[tuple[str, object]] | None = None) -> list[tuple[str, object, str, bool]]:
    """(qualified name, function, docstring holding its Parameters, is a constructor) for the exported API
    (``names``: (qualified name, object) pairs; default ``pwas_hdl.__all__``)."""
    items = []
    if names is None:
        names = [(name, getattr(pwas_hdl, name)) for name in pwas_hdl.__all__]
    for name, obj in names:
        if not inspect.isclass(obj):
            items.append((name, obj, inspect.getdoc(obj) or "", False))
            continue
        own_init = vars(obj).get("__init__")
        if own_init is not None or dataclasses.is_dataclass(obj):  # error classes without their own: Exception's
            doc = (obj.__doc__ or "") + "\n" + (getattr(own_init, "__doc__", None) or "")
            items.append((f"{name}.__init__", obj.__init__, doc, True))
        for attr, member in vars(obj).items():
            if attr.startswith("_"):
                continue
            fn = member.__func__ if isinstance(member, (staticmethod, classmethod)) else member
            if inspect.isfunction(fn):
                items.append((f"{name}.{attr}", fn, inspect.getdoc(fn) or "", False))
    return items


_ITEMS = _public_callables()

#: Packages whose submodules' ``__all__`` follow the standard too (not only what ``pwas_hdl`` exports).
DOCUMENTED_PACKAGES = ("pwas_hdl.fit", "pwas_hdl.fixedpoint", "pwas_hdl.design", "pwas_hdl.io", "pwas_hdl.flow",
                       "pwas_hdl.verify", "pwas_hdl.hdl", "pwas_hdl.systems")

#: Modules outside those packages whose ``__all__`` follows the standard too.
DOCUMENTED_MODULES = ("pwas_hdl.bench_results",)


def _module_api() -> dict[str, list[tuple[str, object, str, bool]]]:
    """Module name -> the :func:`_public_callables` of every function and class that a submodule of
    :data:`DOCUMENTED_PACKAGES`, or a module of :data:`DOCUMENTED_MODULES`, lists in ``__all__`` and
    defines itself (re-exports are checked where they are defined)."""
    out = {}
    module_names = list(DOCUMENTED_MODULES)
    for pkg_name in DOCUMENTED_PACKAGES:
        pkg = importlib.import_module(pkg_name)
        module_names += [info.name for info in pkgutil.iter_modules(pkg.__path__, pkg_name + ".")]
    for module_name in module_names:
        mod = importlib.import_module(module_name)
        names = [(f"{mod.__name__}.{name}", getattr(mod, name)) for name in getattr(mod, "__all__", ())]
        names = [(q, obj) for q, obj in names
                 if (inspect.isfunction(obj) or inspect.isclass(obj)) and obj.__module__ == mod.__name__]
        if names:
            out[mod.__name__] = _public_callables(names)
    return out


#: One test per module (not per function: a thousand parametrised cases would cost seconds).
_MODULE_ITEMS = _module_api()


def _params(fn: object) -> list[inspect.Parameter]:
    """The parameters of ``fn`` but a method's ``self`` / ``cls`` (a function's own ``cls`` stays)."""
    params = list(inspect.signature(fn).parameters.values())
    if params and params[0].name in ("self", "cls") and "." in getattr(fn, "__qualname__", ""):
        params = params[1:]
    return params


def test_the_walk_covers_the_readme_api():
    names = {q for q, *_ in _ITEMS}
    assert {"PWASVirtualSensor.fit", "PWASVirtualSensor.predict", "PWASVirtualSensor.__init__", "FixedPointModel.evaluate",
            "generate", "simulate_arrays", "synthesize", "explore", "collect_report", "load_model", "load_design"} <= names


def test_the_module_walk_covers_the_packages():
    names = {q for items in _MODULE_ITEMS.values() for q, *_ in items}
    assert {"pwas_hdl.fit.regularized_lsq.check_fit_memory", "pwas_hdl.fit.regularized_lsq.plan_fit_memory",
            "pwas_hdl.fixedpoint.formats.FixedFormat.quantize", "pwas_hdl.fixedpoint.formats.quantize_input",
            "pwas_hdl.flow.explore.format_table", "pwas_hdl.io.atomic.logs_kept",
            "pwas_hdl.systems.three_tank.simulate_three_tank", "pwas_hdl.bench_results.make_results"} <= names


@pytest.mark.parametrize("qual, fn, doc, ctor", _ITEMS, ids=[q for q, *_ in _ITEMS])
def test_parameters_are_annotated_and_documented(qual, fn, doc, ctor):
    assert doc.strip(), f"{qual} has no docstring"
    params = _params(fn)
    unannotated = [p.name for p in params if p.annotation is inspect.Parameter.empty]
    assert not unannotated, f"{qual}: parameters without a type hint: {unannotated}"
    if not ctor:
        assert inspect.signature(fn).return_annotation is not inspect.Signature.empty, f"{qual}: no return annotation"
    if not params:
        return
    documented = _documented(doc, ("Parameters", "Other Parameters") + (("Attributes",) if ctor else ()))
    missing = [p.name for p in params if p.name not in documented]
    assert not missing, f"{qual}: parameters missing from the docstring's Parameters section: {missing}"
    if not ctor and not any(p.kind is p.VAR_KEYWORD for p in params):
        unknown = sorted(set(documented) - {p.name for p in params})
        assert not unknown, f"{qual}: the Parameters section names parameters that do not exist: {unknown}"


@pytest.mark.parametrize("qual, fn, doc, ctor", _ITEMS, ids=[q for q, *_ in _ITEMS])
def test_array_parameters_give_a_shape(qual, fn, doc, ctor):
    """A parameter annotated as an ndarray says its shape (``shape (T, n)``, ``(N,)``, or "as in" a method that does)."""
    documented = _documented(doc, ("Parameters", "Other Parameters") + (("Attributes",) if ctor else ()))
    shape = re.compile(r"shape|\([^()]*,[^()]*\)|as in :|scalar")
    for p in _params(fn):
        if "ndarray" in str(p.annotation) and p.name in documented:
            assert shape.search(documented[p.name]), f"{qual}: array parameter {p.name!r} has no shape in its docstring"


@pytest.mark.parametrize("module", sorted(_MODULE_ITEMS))
def test_module_api_is_annotated_and_documented(module):
    """The rules of the two tests above for every name of one module's ``__all__``, all failures at once."""
    failures = []
    for item in _MODULE_ITEMS[module]:
        for check in (test_parameters_are_annotated_and_documented, test_array_parameters_give_a_shape):
            try:
                check(*item)
            except AssertionError as exc:
                failures.append(str(exc).splitlines()[0])
    assert not failures, "\n".join(failures)
