"""Public entry points: build a design from a bit-true model, describe it for a manifest."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pwas_hdl.errors import InputError, choice_text, option_text
from pwas_hdl.hdl.core import PWASCore
from pwas_hdl.hdl.emit import port_list, port_names
from pwas_hdl.hdl.names import check_module_name
from pwas_hdl.hdl.params import PIPELINE_REGISTERS, CoreParams, Pipeline

if TYPE_CHECKING:
    from pwas_hdl.fit.regressors import LagStructure
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel
    from pwas_hdl.hdl.argmax import ArgmaxStage
    from pwas_hdl.hdl.sensor_top import PWASSensorTop

__all__ = ["build_core", "build_sensor", "design_info", "pipeline_registers"]


def _check_name(name: str) -> str:
    return check_module_name(name, "module name")


def build_core(model: FixedPointModel | CoreParams, *, memory: str = "banked", pipeline: Pipeline | str | None = None, name: str = "pwas_core",
               classifier: dict | None = None, architecture: str = "parallel") -> PWASCore:
    """The pipelined PWAS core of a bit-true model.

    Parameters
    ----------
    model : pwas_hdl.fixedpoint.bittrue.FixedPointModel or CoreParams
        The bit-true model (or its integer description).
    memory : {"banked", "replicated", "corner"}
        Weight memory layout (:mod:`pwas_hdl.fixedpoint.memory_layout`), independent of ``model.layout``.
    pipeline : Pipeline, "min", "balanced" (default) or "max"
        Which optional pipeline registers exist (:class:`~pwas_hdl.hdl.params.Pipeline`, :meth:`Pipeline.cast`).
    name : str
        Verilog module name used by :func:`~pwas_hdl.hdl.emit.emit_verilog` and :func:`design_info`.
    classifier : dict, optional
        ``{"target": name, "classes": [labels]}`` of a classifier model (``sensor.classifier_``,
        one class per target, in target order): adds the argmax stage after the core
        (:class:`~pwas_hdl.hdl.classifier_top.PWASClassifierCore`); the output payload then ends
        with the ``class_index`` field.
    architecture : {"parallel", "serial"}
        ``"serial"``: :class:`~pwas_hdl.hdl.serial_core.SerialPWASCore` (one multiplier per
        target, II = n + 1, one memory of N words; ``memory`` is then ignored); with
        ``classifier`` the argmax stage follows the serial core.

    Returns
    -------
    PWASCore or SerialPWASCore or PWASClassifierCore
        ``.latency`` (cycles), ``.ii`` (1, serial: n + 1), ``.memory_plan``, ``.params``.

    Raises
    ------
    InputError
        ``name`` is not a plain Verilog identifier, an unknown ``architecture``, a classifier whose
        class count differs from ``nz``, or parameters the core refuses.
    TypeError
        ``model`` is neither a bit-true model nor ``CoreParams``.
    """
    name = _check_name(name)
    params = CoreParams.from_model(model)
    if classifier is not None:
        from pwas_hdl.hdl.classifier_top import PWASClassifierCore

        check_classifier(classifier, params)
        comp = PWASClassifierCore(params, memory=memory, pipeline=pipeline, architecture=architecture)
        core = comp.core
    else:
        comp = core = _make_core(params, memory, pipeline, architecture)
    comp.module_name = name
    comp._MustUse__silence = True  # often only described (design_info), not elaborated
    core.input_names = list(getattr(model, "regressor_names", [f"x{j}" for j in range(params.n)]))
    core.target_names = list(getattr(model, "target_names", [f"z{i}" for i in range(params.nz)]))
    comp.classifier = dict(classifier) if classifier is not None else None
    return comp


def check_classifier(classifier: dict, params: CoreParams) -> None:
    """Refuse what no classifier design builds: not one class per score target.

    The argmax stage follows the parallel and the serial core alike (both drive it through the
    same output stream, :func:`~pwas_hdl.hdl.classifier_top.inline_core_and_argmax`).

    Parameters
    ----------
    classifier : dict
        ``{"target": name, "classes": [labels]}`` (``sensor.classifier_``).
    params : CoreParams
        The core's parameters (``nz`` score targets).

    Raises
    ------
    InputError
        The number of classes differs from ``nz``.
    """
    if len(classifier["classes"]) != params.nz:
        raise InputError(f"the classifier has {len(classifier['classes'])} classes for nz = {params.nz} score targets")


def classifier_stage(classifier: dict | None, params: CoreParams, pipeline: Pipeline | str | None) -> ArgmaxStage | None:
    """The argmax stage a top inlines after its core for a classifier model (None without one).

    Used by :func:`build_sensor` and the warped builders (:mod:`pwas_hdl.hdl.warp`).

    Parameters
    ----------
    classifier : dict or None
        As :func:`build_core`.
    params : CoreParams
        The core's parameters.
    pipeline : Pipeline, preset name or None
        The design's pipeline (its ``tree_levels`` place the stage's registers, behind the parallel
        or the serial core).

    Returns
    -------
    ArgmaxStage or None
        :func:`~pwas_hdl.hdl.classifier_top.classifier_argmax`, not elaborated on its own.

    Raises
    ------
    InputError
        As :func:`check_classifier`.
    """
    if classifier is None:
        return None
    from pwas_hdl.hdl.classifier_top import classifier_argmax

    check_classifier(classifier, params)
    argmax = classifier_argmax(params, pipeline)
    argmax._MustUse__silence = True  # inlined by the top
    return argmax


def _make_core(params: CoreParams, memory: str, pipeline, architecture: str) -> PWASCore:
    """The core of ``architecture`` ("parallel" or "serial")."""
    from pwas_hdl.hdl.serial_core import ARCHITECTURES, SerialPWASCore

    if architecture not in ARCHITECTURES:
        raise InputError(choice_text(option_text("architecture"), ARCHITECTURES, architecture))
    if architecture == "serial":
        return SerialPWASCore(params, pipeline=pipeline)
    return PWASCore(params, memory=memory, pipeline=pipeline)


def _fields(names_widths):
    out, lsb = [], 0
    for name, width, signed in names_widths:
        out.append({"name": name, "lsb": lsb, "width": width, "signed": signed})
        lsb += width
    return out


def pipeline_registers(component: Any) -> list[str]:
    """The pipeline registers a built design has: the options of its pipeline that its cores and
    stages build and that are on (the manifest's ``architecture.pipeline_registers``).

    The serial core ignores ``bank``, ``mul_in``, ``mul_halves`` and ``tree_levels``
    (:data:`~pwas_hdl.hdl.serial_core.SERIAL_REGISTERS`); a classifier's argmax stage takes
    ``tree_levels``; an additive design's parts have pipelines of their own (equal latencies).

    Parameters
    ----------
    component : Component
        A core or a top of :mod:`pwas_hdl.hdl` (its ``core``, the core's ``parts``, the ``argmax``).

    Returns
    -------
    list of str
        Names of :data:`~pwas_hdl.hdl.params.PIPELINE_REGISTERS`, in stage order (``tree_levels``:
        some adder-tree or compare-tree register).
    """
    core = getattr(component, "core", component)
    stages = list(getattr(core, "parts", None) or [core])
    argmax = getattr(component, "argmax", None) or getattr(core, "argmax", None)
    if argmax is not None and argmax.latency:  # its registers (none for tree_levels = 0)
        stages.append(argmax)
    on = {k for st in stages for k in st.pipeline_registers if getattr(st.pipeline, k)}  # tree_levels > 0: >= 1 register
    return [k for k in PIPELINE_REGISTERS if k in on]


def design_info(component: Any, ports: str = "axis") -> dict:
    """JSON-ready description of a built design (core or sensor top).

    Parameters
    ----------
    component : Component
        What :func:`build_core` or :func:`build_sensor` (or another top of :mod:`pwas_hdl.hdl`)
        returned: it needs ``latency``, ``ii`` and a ``core`` (or is the core).
    ports : {"axis", "amaranth"}
        Port naming (:func:`~pwas_hdl.hdl.emit.port_names`).

    Returns
    -------
    dict
        Keys: ``module``, ``kind``, ``latency`` (cycles), ``ii`` (cycles), ``ports`` (Verilog ports
        in module order with their roles, see :func:`~pwas_hdl.hdl.emit.port_list`),
        ``port_naming``, ``clock`` and ``reset`` (port, edge / polarity, kind), ``payload`` (bit
        fields of the input and output payload ports, by port name, LSB first), ``flow_control``,
        ``memory`` (memories, depth, word bits, words, bits), ``pipeline``, ``arithmetic``,
        ``architecture``; the sensor top adds ``lags`` and ``warmup``, a classifier ``classifier``.
    """
    nm = port_names(ports)
    rst = f"~{nm['reset']}" if ports == "axis" else nm["reset"]
    core = getattr(component, "core", component)
    p: CoreParams = core.params
    in_fields = getattr(component, "input_fields", None)
    if in_fields is None:
        names = getattr(core, "input_names", [f"x{j}" for j in range(p.n)])
        in_fields = _fields([(nm, p.in_width, True) for nm in names])
    tnames = getattr(core, "target_names", [f"z{i}" for i in range(p.nz)])
    out_fields = _fields([(nm, p.out_width, True) for nm in tnames] + [("out_of_range", 1, False)])
    classifier = getattr(component, "classifier", None)
    if classifier is not None:  # the argmax stage's class index, in the top bits of the output payload
        from pwas_hdl.hdl.classifier_top import classifier_info

        cinfo = classifier_info(component, classifier["target"], classifier["classes"], tnames)
        cinfo["port"] = nm["out.payload"]
        out_fields.append({"name": cinfo["field"], "lsb": cinfo["lsb"], "width": cinfo["width"], "signed": False})
    info = {
        "module": getattr(component, "module_name", None),
        "kind": getattr(component, "kind", "core"),
        "latency": int(component.latency),
        "ii": int(component.ii),
        "ports": port_list(component, ports),
        "port_naming": ports,
        "clock": {"port": nm["clock"], "edge": "rising"},
        "reset": {"port": nm["reset"], "polarity": "low" if ports == "axis" else "high", "kind": "synchronous"},
        "payload": {nm["in.payload"]: in_fields, nm["out.payload"]: out_fields},
        "flow_control": {
            "advance": f"~{nm['out.valid']} | {nm['out.ready']}",
            nm["in.ready"]: "advance",
            "reset": f"{nm['reset']}: synchronous, active {'low' if ports == 'axis' else 'high'} "
            f"(the design resets while {rst} is 1), clears the valid bits only",
            "latency": f"a transfer on the input stream in cycle t gives {nm['out.valid']} with its result in cycle "
            f"t + latency when {nm['out.ready']} stays high; stalls delay it by the stalled cycles",
        },
        "memory": core.memory_plan.to_dict(),
        "pipeline": core.pipeline.to_dict(),
        "arithmetic": {
            "n": p.n,
            "nz": p.nz,
            "partitions": list(p.partitions),
            "in_width": p.in_width,
            "lo_code": list(p.lo_code),
            "frac_bits": list(p.frac_bits),
            "F": p.frac,
            "weight_width": p.weight_width,
            "weight_frac": p.weight_frac,
            "out_width": p.out_width,
            "out_frac": p.out_frac,
            "shift": p.shift,
            "rounding": p.rounding,
            "product_bits": p.acc_width,
            "sum_bits": p.acc_width + 1,
        },
    }
    from pwas_hdl.hdl.serial_core import architecture_info

    if hasattr(core, "flow_control"):  # the serial core's input throttle
        info["flow_control"].update(core.flow_control(nm))
    if component is not core and hasattr(component, "flow_control"):  # a top's own input throttle (serial observer bank)
        info["flow_control"].update(component.flow_control(nm))
    # the design's II: a top may take samples more slowly than its core (its ii_meaning says why)
    info["architecture"] = architecture_info(core, int(component.ii), getattr(component, "ii_meaning", None))
    info.update(getattr(component, "extra_info", {}))
    # which of the pipeline's registers the design builds (the serial core ignores some)
    info["architecture"] = {**info["architecture"], "pipeline_registers": pipeline_registers(component)}
    if classifier is not None:
        info["classifier"] = cinfo
    return info


def build_sensor(
    model: FixedPointModel | CoreParams,
    lags: LagStructure | None = None,
    *,
    memory: str = "banked",
    pipeline: Pipeline | str | None = None,
    name: str = "pwas_sensor",
    classifier: dict | None = None,
    architecture: str = "parallel",
) -> PWASSensorTop:
    """The virtual-sensor top (lag bank + core) of a bit-true model.

    Parameters
    ----------
    model : pwas_hdl.fixedpoint.bittrue.FixedPointModel (or CoreParams together with ``lags``)
        The bit-true model.
    lags : LagStructure, optional
        Default: derived from ``model.regressor_signals`` (as ``FixedPointModel.from_sensor``
        sets them); pass ``sensor.lags_`` to be explicit.
    memory, pipeline, name, classifier, architecture : as :func:`build_core` (``classifier``: the argmax stage
        follows the core inside the top)

    Returns
    -------
    PWASSensorTop
        ``.latency``, ``.ii``, ``.warmup`` (= M - 1), ``.core``, ``.signals``, ``.dims``, ``.argmax``.

    Raises
    ------
    InputError
        ``lags`` is recurrent (the lag top has no feedback path).
        As :func:`build_core`; also a signal whose lags have different input formats, or
        ``lags`` that do not match the model (or neither ``lags`` nor ``model.regressor_signals``).
    """
    from pwas_hdl.hdl.sensor_top import PWASSensorTop, lag_plan

    name = _check_name(name)
    params = CoreParams.from_model(model)
    if hasattr(model, "signal_input_formats"):
        model.signal_input_formats()  # raises unless all lags of each signal share one format
    signals, dims = lag_plan(model, lags)
    argmax = classifier_stage(classifier, params, pipeline)
    top = PWASSensorTop(params, signals, dims, memory=memory, pipeline=pipeline, argmax=argmax,
                        architecture=architecture)
    top.classifier = dict(classifier) if classifier is not None else None
    top.module_name = name
    top._MustUse__silence = True
    top.core.input_names = list(getattr(model, "regressor_names", [f"x{j}" for j in range(params.n)]))
    top.core.target_names = list(getattr(model, "target_names", [f"z{i}" for i in range(params.nz)]))
    return top
