"""The recurrent design of ``pwas-hdl generate`` (issue 13): a recurrent model's sensor top.

A recurrent model (``Mz >= 1``: a dynamical sensor fitted with ``fit --mz``, or the PWAS of a map
run as a recurrence, ``fit-map --state``) has the past estimates ``z_hat(t-Mz) .. z_hat(t-1)`` at
the end of its regressor. ``generate --design sensor`` on such a model builds
:class:`~pwas_hdl.hdl.recurrent_top.PWASRecurrentTop` (lag bank + core + feedback registers),
whose bit-true specification is
:class:`~pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel`; the manifest's ``design`` is
``"recurrent"`` and its ``recurrence`` block (built by :mod:`pwas_hdl.design.manifest`) states
which output feeds which regressors, the requantisation rule (``K``/``C``/``S`` = ``mul``/
``add``/``shift``), the reset state codes, II = latency and the flow control. The core inside is
the parallel or the serial one (``--architecture``), with the warp in front of it for a model
fitted with power-of-two ``breakpoints``.

This module holds what only the recurrent design needs: the component, the bit-true recurrence
of a folder, and the lines it adds to the Verilog header and ``report.md``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pwas_hdl.errors import InputError

if TYPE_CHECKING:
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel
    from pwas_hdl.fixedpoint.recurrence import RecurrentFixedPointModel

__all__ = ["recurrent_model", "build_recurrent_component", "recurrence_header_lines", "recurrence_report_text", "loop_text"]


def estimate_rows(start: int, stop: int, lags: Any, lead: int) -> tuple[Any, Any]:
    """The rows of one trajectory a recurrent design estimates, and which of them have a reference.

    The one alignment rule of ``simulate`` and ``explore`` for recurrent designs: after a reset the
    first ``max(M, 1) - 1`` transfers only fill the lags, so the estimates are rows ``start +
    max(M, 1) - 1 .. stop - 1``; row ``t`` estimates ``z(t + lead)``, which exists when
    ``t + lead < stop``.

    Parameters
    ----------
    start, stop : int
        The trajectory's rows, ``start .. stop - 1`` (data rows, or 0 .. T for one array).
    lags : LagStructure
        The sensor's lags (``memory`` = M).
    lead : int
        ``sensor.lead_`` (0, or 1 for a map fitted with ``fit-map``).

    Returns
    -------
    rows : ndarray of int, shape (R,)
        The estimated rows, ``R = stop - start - max(M, 1) + 1``.
    has_reference : ndarray of bool, shape (R,)
        ``rows + lead < stop``.
    """
    import numpy as np

    rows = np.arange(start + max(int(lags.memory), 1) - 1, stop)
    return rows, rows + int(lead) < stop


def recurrent_model(sensor: "PWASVirtualSensor", fxm: "FixedPointModel") -> "RecurrentFixedPointModel":
    """The bit-true recurrence of a recurrent ``sensor`` whose circuit is ``fxm``.

    Parameters
    ----------
    sensor : PWASVirtualSensor
        A fitted recurrent sensor (``Mz > 0``) with constant initial states.
    fxm : FixedPointModel
        Its bit-true core.

    Returns
    -------
    RecurrentFixedPointModel

    Raises
    ------
    InputError
        The model is not recurrent, or its initial state is the measured one (the hardware
        starts from constant reset codes), or the lags of one signal have different formats, or
        the top's feedback product would be narrower than ``B_in + S``
        (:meth:`~pwas_hdl.fixedpoint.recurrence.FeedbackRequant.check_top_product`).
    """
    from pwas_hdl.fixedpoint.recurrence import RecurrentFixedPointModel

    lags = sensor.lags_
    if lags is None or not lags.recurrent:
        raise InputError("the model is not recurrent (Mz = 0): use --design sensor or core")
    if sensor.initial_state_rule_ != "value":
        raise InputError("the recurrent hardware starts from constant initial states: fit with --z0 VALUE or 'mean', "
                         "not 'measured'")
    try:
        rm = RecurrentFixedPointModel(fxm, lags, sensor.initial_values_)
    except ValueError as exc:  # e.g. separate lag domains of one signal: the lag bank needs one format per signal
        raise InputError(f"the recurrent top cannot be built for this model: {exc}") from None
    for c, fb in enumerate(rm.feedback):  # the top's feedback product (generate and explore refuse alike)
        fb.check_top_product(c)
    return rm


def build_recurrent_component(sensor: "PWASVirtualSensor", fxm: "FixedPointModel", *, memory: str, name: str,
                              pipeline: Any = None, classifier: Any = None,
                              architecture: str = "parallel") -> tuple[Any, "RecurrentFixedPointModel"]:
    """The Amaranth recurrent top and its bit-true recurrence.

    Parameters
    ----------
    sensor : PWASVirtualSensor
        Recurrent (``sensor.lags_.mz >= 1``), initial-state rule "value".
    fxm : FixedPointModel or WarpedFixedPointModel
        The bit-true circuit (:func:`pwas_hdl.design.generate.fixed_point_model`; a warped model,
        of a non-uniform partition, puts the warp in front of the core).
    memory, name, pipeline, architecture : as :func:`pwas_hdl.design.generate.build_design`
    classifier : None
        A classifier model is refused (no argmax stage in the recurrent top).

    Returns
    -------
    (PWASRecurrentTop, RecurrentFixedPointModel)
    """
    from pwas_hdl.hdl.recurrent_top import build_recurrent_sensor

    if classifier is not None:
        raise InputError("a recurrent classifier is not supported: the recurrent top has no argmax stage")
    rm = recurrent_model(sensor, fxm)
    try:
        top = build_recurrent_sensor(rm, memory=memory, pipeline=pipeline, name=name, architecture=architecture)
    except ValueError as exc:  # e.g. a requantisation product narrower than B_in + S
        raise InputError(f"the recurrent top cannot be built with these formats: {exc}") from None
    return top, rm


def recurrence_header_lines(man: dict) -> list[str]:
    """Lines of the Verilog header that state the feedback path (from the manifest).

    Parameters
    ----------
    man : dict
        A recurrent design's manifest (it has ``recurrence``).

    Returns
    -------
    list of str
        Without comment markers or line ends.
    """
    r = man["recurrence"]
    lines = [f"recurrence: Mz = {r['Mz']}, lead {r['lead']}; one sample in flight through {loop_text(man)}, "
             f"II = latency = {r['ii_cycles']} cycles"]
    for fb in r["feedback"]:
        q = fb["requant"]
        lines.append(f"  feedback {fb['output_field']} -> {', '.join(fb['regressors'])}: q = clip((o * {q['mul']} + {q['add']}) "
                     f">> {q['shift']}, {q['qmin']}, {q['qmax']}) ({fb['input_format']}); reset codes {fb['initial_codes']}")
    lines.append("  (the |hw - float| bound above is per step; over the recurrence the deviation is measured, see report.md)")
    return lines


def loop_text(man: dict) -> str:
    """What a sample passes through in the recurrent top, from its manifest.

    Parameters
    ----------
    man : dict
        A recurrent design's manifest (``architecture.kind``, ``warp`` if warped).

    Returns
    -------
    str
        ``"the parallel core"``, ``"the warp and the serial core"``, ...
    """
    kind = man.get("architecture", {}).get("kind", "parallel")
    return ("the warp and " if "warp" in man else "") + f"the {kind} core"


def recurrence_report_text(man: dict) -> str:
    """The ``## Recurrence`` section of ``report.md``.

    Parameters
    ----------
    man : dict
        A recurrent design's manifest (it has ``recurrence``).

    Returns
    -------
    str
        Markdown, starting with a blank line.
    """
    r = man["recurrence"]
    rows = ["| target | feeds | requantisation q = clip((o K + C) >> S) | input format | reset codes (oldest first) | |q - o| bound |",
            "|---|---|---|---|---|---|"]
    for fb in r["feedback"]:
        q = fb["requant"]
        rows.append(f"| `{fb['target']}` | {', '.join(f'`{x}`' for x in fb['regressors'])} | K = {q['mul']}, C = {q['add']}, "
                    f"S = {q['shift']}, [{q['qmin']}, {q['qmax']}] | {fb['input_format']} | {fb['initial_codes']} | "
                    f"{q['error_bound']:.4g} |")
    return (f"\n## Recurrence\n\nThe past estimates are fed back (Mz = {r['Mz']}, lead {r['lead']}: row t estimates "
            f"z(t + {r['lead']})). Flow control: {r['flow']} (through {loop_text(man)}). II = latency = {r['ii_cycles']} cycles. Reset restores the initial state "
            f"codes (physical {r['initial_state']['values']}).\n\n" + "\n".join(rows) + "\n\n"
            "The error bound above is that of one step; the recurrence filters the per-step errors with its own gain, so "
            "the deviation of the hardware from the float recurrence is measured (simulate: bit-true and float columns), "
            "not bounded.\n")
