"""pwas-hdl: piecewise-affine simplicial (PWAS) virtual sensors, from plant data to verified Verilog.

The public API, importable from ``pwas_hdl`` (each name is loaded on first use, so that
``import pwas_hdl`` and the command line stay fast; the owning module is in brackets):

Fit (``pwas_hdl.fit``)
    :class:`PWASVirtualSensor` (a scikit-learn estimator), :func:`load_model`, :class:`Grid`,
    :class:`Location`, :class:`LagStructure`, :func:`solve_regularized`, :func:`tikhonov_matrix`,
    :func:`cross_validate_sigma`, :class:`CVResult`.
Fixed point (``pwas_hdl.fixedpoint``)
    :class:`FixedPointModel` (the bit-true model, the specification of the RTL),
    :func:`fixed_point_model` (the one ``generate`` builds for a sensor and options).
Design (``pwas_hdl.design``)
    :func:`generate` (write a design folder), :func:`build_design` (the same, in memory),
    :class:`GeneratedDesign`, :func:`collect_report`, :func:`report_markdown`.
Verification (``pwas_hdl.verify``)
    :func:`load_design`, :func:`simulate_data` (replay a CSV file), :func:`simulate_arrays`
    (replay arrays) through Icarus or Verilator against the bit-true model.
Flow (``pwas_hdl.flow``)
    :func:`synthesize` (Yosys + nextpnr), :func:`explore` (formats versus accuracy and size).
Systems (``pwas_hdl.systems``)
    :class:`PlantData`, :func:`lorenz`, :func:`helicopter`.
Errors (``pwas_hdl.errors``)
    :class:`InputError`, :class:`ResourceLimit`, :class:`ToolMissing`, :class:`CheckFailed`,
    :class:`InternalError`.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

#: public name -> module that owns it
_EXPORTS = {
    "Grid": "pwas_hdl.fit.geometry",
    "Location": "pwas_hdl.fit.geometry",
    "LagStructure": "pwas_hdl.fit.regressors",
    "CVResult": "pwas_hdl.fit.regularized_lsq",
    "cross_validate_sigma": "pwas_hdl.fit.regularized_lsq",
    "solve_regularized": "pwas_hdl.fit.regularized_lsq",
    "tikhonov_matrix": "pwas_hdl.fit.regularized_lsq",
    "PWASVirtualSensor": "pwas_hdl.fit.virtual_sensor",
    "load_model": "pwas_hdl.fit.virtual_sensor",
    "FixedPointModel": "pwas_hdl.fixedpoint.bittrue",
    "fixed_point_model": "pwas_hdl.design.generate",
    "generate": "pwas_hdl.design.generate",
    "build_design": "pwas_hdl.design.generate",
    "GeneratedDesign": "pwas_hdl.design.generate",
    "collect_report": "pwas_hdl.design.report",
    "report_markdown": "pwas_hdl.design.report",
    "load_design": "pwas_hdl.verify.simulation",
    "simulate_data": "pwas_hdl.verify.simulation",
    "simulate_arrays": "pwas_hdl.verify.simulation",
    "synthesize": "pwas_hdl.flow.synthesis",
    "explore": "pwas_hdl.flow.explore",
    "PlantData": "pwas_hdl.systems.lorenz",
    "lorenz": "pwas_hdl.systems.lorenz",
    "helicopter": "pwas_hdl.systems.helicopter",
    "InputError": "pwas_hdl.errors",
    "ResourceLimit": "pwas_hdl.errors",
    "ToolMissing": "pwas_hdl.errors",
    "CheckFailed": "pwas_hdl.errors",
    "InternalError": "pwas_hdl.errors",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'pwas_hdl' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # loaded once
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


if TYPE_CHECKING:  # what static tools see
    from pwas_hdl.design.generate import GeneratedDesign, build_design, fixed_point_model, generate
    from pwas_hdl.design.report import collect_report, report_markdown
    from pwas_hdl.errors import CheckFailed, InputError, InternalError, ResourceLimit, ToolMissing
    from pwas_hdl.fit.geometry import Grid, Location
    from pwas_hdl.fit.regressors import LagStructure
    from pwas_hdl.fit.regularized_lsq import CVResult, cross_validate_sigma, solve_regularized, tikhonov_matrix
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor, load_model
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel
    from pwas_hdl.flow.explore import explore
    from pwas_hdl.flow.synthesis import synthesize
    from pwas_hdl.systems.helicopter import helicopter
    from pwas_hdl.systems.lorenz import PlantData, lorenz
    from pwas_hdl.verify.simulation import load_design, simulate_arrays, simulate_data
