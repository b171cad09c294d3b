"""The PWAS classifier in hardware: the core's ``nz`` one-hot scores, then an argmax stage.

A classifier model (:mod:`pwas_hdl.fit.classifier`: ``C`` score targets sharing one locator) is
generated as the core (or the virtual-sensor top, :class:`~pwas_hdl.hdl.sensor_top.PWASSensorTop`
with ``argmax=``; with a non-uniform partition the warped core or top of :mod:`pwas_hdl.hdl.warp`,
``classifier=``) followed by :class:`~pwas_hdl.hdl.argmax.ArgmaxStage` over the ``C`` output codes,
both inlined into one module. The output payload keeps the core's fields (the ``C`` scores, then
``out_of_range``) and adds the class index in its top bits (``class_index``, ``index_width`` bits,
ties to the lowest index); the latency is the core's (with a warp: + its register) plus the stage's
(:func:`~pwas_hdl.hdl.argmax.argmax_latency`: 0 with the ``min`` pipeline). Every one of these
designs connects its core and the stage by :func:`inline_core_and_argmax`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from amaranth.hdl import Module, Signal, Value, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from pwas_hdl.errors import InputError
from pwas_hdl.fixedpoint.argmax import TIE_RULE
from pwas_hdl.hdl.argmax import ArgmaxStage
from pwas_hdl.hdl.core import core_input_layout, core_output_layout
from pwas_hdl.hdl.params import CoreParams, Pipeline

__all__ = ["CLASS_FIELD", "classifier_argmax", "classifier_info", "argmax_extent", "inline_core_and_argmax",
           "PWASClassifierCore"]

#: Name of the class-index field of the output payload (manifest ``classifier.field``).
CLASS_FIELD = "class_index"


def classifier_argmax(params: CoreParams, pipeline: Pipeline | str | None = None) -> ArgmaxStage:
    """The argmax stage after a core of ``params``: ``nz`` signed ``B_out`` scores, ``out_of_range`` carried.

    Parameters
    ----------
    params : CoreParams
        The core's parameters: ``nz`` scores of ``out_width`` (``B_out``) bits.
    pipeline : Pipeline, preset name or None
        Its ``tree_levels`` places the stage's registers (:class:`~pwas_hdl.hdl.argmax.ArgmaxStage`);
        default balanced.

    Returns
    -------
    ArgmaxStage
        ``select="max"``, one extra bit (``out_of_range``) carried through.
    """
    return ArgmaxStage(params.nz, params.out_width, signed=True, extra_bits=1, pipeline=pipeline, select="max")


def argmax_extent(argmax: ArgmaxStage | None, score_bits: int) -> tuple[int, int]:
    """The cycles and output bits an optional argmax stage adds after a core (or an additive sum)
    whose output payload has ``score_bits`` bits; the one check that the stage reads that payload.

    Parameters
    ----------
    argmax : ArgmaxStage or None
        The classifier's stage, or None (no classifier: nothing added).
    score_bits : int
        Bits of the output payload before the stage (the scores and ``out_of_range``).

    Returns
    -------
    (int, int)
        ``argmax.latency`` (cycles) and ``argmax.index_width`` (bits of the class index), or ``(0, 0)``.

    Raises
    ------
    InputError
        The stage's ``index_lsb`` is not ``score_bits``.
    """
    if argmax is None:
        return 0, 0
    if argmax.index_lsb != score_bits:
        raise InputError(f"the argmax stage takes {argmax.index_lsb} payload bits, the core gives {score_bits}")
    return int(argmax.latency), int(argmax.index_width)


def inline_core_and_argmax(m: Module, core: Any, argmax: ArgmaxStage | None, payload: Value, valid: Value,
                           advance: Signal, out: Any) -> None:
    """Inline ``core`` into ``m`` and, if there is one, the argmax stage after it (one module).

    The composition of every classifier design (:class:`PWASClassifierCore`, the sensor top, the
    warped core of :mod:`pwas_hdl.hdl.warp`): the core's output stream feeds the stage, whose
    output is ``out``; without a stage the core drives ``out`` itself.

    Parameters
    ----------
    m : Module
        Module the logic is added to.
    core : PWASCore or SerialPWASCore
        Its :meth:`~pwas_hdl.hdl.core.PWASCore.build_into` (with its input stage, e.g. a warp).
    argmax : ArgmaxStage or None
        The stage after the core (``index_lsb`` = the core's output payload bits), or None.
    payload, valid : Value
        The core's input payload and its valid bit.
    advance : Signal
        The core's input ready (driven here).
    out : stream interface
        The design's output stream (the core's, then the class index with ``argmax``).
    """
    if argmax is None:
        core.build_into(m, payload, valid, advance, out)
        return
    scores = argmax.scores_stream(out)
    core.build_into(m, payload, valid, advance, scores)
    argmax.build_into(m, scores.payload, scores.valid, scores.ready, out)


def classifier_info(component: Any, target: str, classes: Sequence[float], score_names: Sequence[str]) -> dict:
    """The manifest's ``classifier`` entry of a design with an argmax stage (before port naming).

    Parameters
    ----------
    component : Component
        A design with an ``argmax`` (:class:`~pwas_hdl.hdl.argmax.ArgmaxStage`): a
        :class:`PWASClassifierCore` or a sensor top built with ``argmax=``.
    target : str
        Name of the classified target.
    classes : sequence of float
        Class labels, one per score, in score (target) order.
    score_names : sequence of str
        Names of the score fields of the output payload.

    Returns
    -------
    dict
        ``target``, ``classes``, ``n_classes``, ``field`` (:data:`CLASS_FIELD`), ``lsb`` and
        ``width`` (bits of the class index in the output payload), ``scores``, ``select``,
        ``tie_rule``, ``stage_latency_cycles``, ``meaning``, ``float_agreement``. The caller adds
        ``port``.
    """
    am: ArgmaxStage = component.argmax
    return {
        "target": str(target),
        "classes": [float(c) for c in classes],
        "n_classes": int(am.n_inputs),
        "field": CLASS_FIELD,
        "lsb": int(am.index_lsb),
        "width": int(am.index_width),
        "scores": [str(s) for s in score_names],
        "select": am.select,
        "tie_rule": TIE_RULE,
        "stage_latency_cycles": int(am.latency),
        "meaning": f"{CLASS_FIELD} = i: the class classes[i] (the i-th score field has the largest code)",
        "float_agreement": "the class equals the float classifier's (at the represented inputs) wherever the "
                           "best float score leads every other by more than 2 * error_bound.physical",
    }


class PWASClassifierCore(wiring.Component):
    """PWAS core + argmax stage (one regressor in, scores and class index out, every ``ii`` clocks).

    Parameters
    ----------
    params : CoreParams
        ``nz = C`` score targets.
    memory, pipeline : as :class:`~pwas_hdl.hdl.core.PWASCore`
    architecture : {"parallel", "serial"}
        The core before the stage: :class:`~pwas_hdl.hdl.core.PWASCore` (II = 1) or
        :class:`~pwas_hdl.hdl.serial_core.SerialPWASCore` (II = n + 1, ``memory`` ignored). The
        stage's registers advance with its own output's handshake; the core's output register
        feeds it, and a stalled stage stalls the core (throttle included) as a stalled sink would.

    Raises
    ------
    InputError
        As :class:`~pwas_hdl.hdl.core.PWASCore` (parameters or a pipeline the core refuses), or an
        unknown ``architecture``.

    Attributes
    ----------
    core : PWASCore or SerialPWASCore (inlined), argmax : ArgmaxStage (inlined)
    latency : int
        ``core.latency + argmax.latency``.
    ii, params, memory_plan, pipeline : as the core's.
    """

    kind = "core"

    def __init__(self, params: CoreParams, *, memory: str = "banked", pipeline: Pipeline | str | None = None,
                 architecture: str = "parallel"):
        from pwas_hdl.hdl.api import _make_core

        self._MustUse__silence = True
        self.core = _make_core(params, memory, pipeline, architecture)
        self.core._MustUse__silence = True  # inlined by elaborate()
        self.argmax = classifier_argmax(params, self.core.pipeline)
        self.argmax._MustUse__silence = True
        self.params = params
        self.memory_plan = self.core.memory_plan
        self.pipeline = self.core.pipeline
        self.memory_kind = self.core.memory_kind
        cycles, index_bits = argmax_extent(self.argmax, core_output_layout(params).size)
        self.latency = self.core.latency + cycles
        self.ii = self.core.ii
        super().__init__({
            "in": In(stream.Signature(unsigned(core_input_layout(params).size))),
            "out": Out(stream.Signature(unsigned(core_output_layout(params).size + index_bits))),
        })
        self._MustUse__silence = False

    def elaborate(self, platform: Any) -> Module:
        """The PWAS core and the argmax stage, connected.

        Parameters
        ----------
        platform : Any
            Amaranth build platform; not used.

        Returns
        -------
        Module
            One module: the core's logic, then the argmax stage's (both inlined).
        """
        m = Module()
        inp = getattr(self, "in")
        inline_core_and_argmax(m, self.core, self.argmax, inp.payload, inp.valid, inp.ready, self.out)
        return m
