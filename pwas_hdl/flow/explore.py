"""Bit-width exploration: accuracy of the bit-true circuit against its resources.

:func:`explore` sweeps the fixed-point formats of a fitted model -- input width ``B_in``, weight
fraction bits ``Fw`` and output fraction bits ``Fo`` (the widths ``B_w`` and ``B_out`` are the
fewest bits that hold every weight / every reachable output, as ``generate`` chooses them, unless
fixed) -- and, for every combination, runs the bit-true model
(:meth:`FixedPointModel.predict <pwas_hdl.fixedpoint.bittrue.FixedPointModel.predict>`, which quantises the
physical regressors of the data to input codes exactly as the circuit's input does) and estimates
the hardware the generator would build for it. :func:`pareto_front` marks the combinations that no
other one beats in both accuracy and cost; :func:`plot_exploration` draws the result.

Accuracy (per point)
--------------------
``rmsee``
    RMSEE (eq. 17 of the paper) of the bit-true estimate against the reference column of the data:
    ``<target>_true`` when present, else ``<target>``. The float model's RMSEE on the same rows is
    the reference line (``result["float"]``).
``rmsee_ratio``
    ``mean over targets of rmsee / float rmsee``: the accuracy objective of the Pareto front (for
    one target it orders the points exactly as the RMSEE does; it makes targets of different
    units comparable).
``rms_dev_float``, ``max_dev_float``, ``max_dev_float_lsb``
    RMS / largest ``|bit-true - float|`` (the float model at the unquantised regressor), physical
    units and output LSBs. It includes the input quantisation, so it may exceed the error bound.
``max_dev_reference_lsb``
    Largest deviation from the float model at the *represented* input (what the error bound
    covers); ``bound_holds`` checks it against ``error_bound_lsb``.

Accuracy of a classifier (fit ``--classify``)
---------------------------------------------
A classifier's outputs are ``C`` class scores; the design decides by its argmax stage. Its points
are scored by the decisions, not by an RMSEE (no ``rmsee`` / ``rmsee_ratio`` fields). The true class
of each row is column ``<label>_true`` if present, else ``<label>`` (as ``predict`` finds it,
:meth:`Table.reference_column <pwas_hdl.io.csv_table.Table.reference_column>`); the bit-true class
is :func:`pwas_hdl.fixedpoint.argmax.argmax_index` of the output codes (the stage's compare tree:
ties to the lowest class index, the convention of :func:`pwas_hdl.fit.classifier.decide`), the
float classifier's is :func:`~pwas_hdl.fit.classifier.decide` of the float scores at the unquantised
regressors.

``error_rate`` / ``errors``
    Share / number of the samples whose bit-true class is not the true one: the accuracy
    objective of the front (``(cost, error_rate)``). ``result["float"]`` has the float
    classifier's ``error_rate`` and ``errors`` on the same rows; ``error_rate_se`` is the standard
    error of the paired difference of the two (batch means).
``disagreement`` / ``disagreements``
    Share / number of the samples whose bit-true class differs from the float classifier's. The
    count of errors of the two differs by at most ``disagreements``.
``disagreement_at_codes``, ``near_ties``, ``differ_outside_margin``
    Against the float classifier at the *represented* input (:func:`pwas_hdl.fixedpoint.argmax.agreement`):
    the share of differing decisions, the samples whose float margin (best minus runner-up score)
    is at most ``2 error_bound``, and the differences outside that margin (0 whenever the bound
    holds: only near ties can flip).

The deviation fields (``rms_dev_float``, ``max_dev_float*``, ``max_dev_reference_lsb``,
``bound_holds``, ``flagged``) are a sensor's, on the scores. ``result["model"]["classifier"]`` has
the label name, the classes and the tie rule (None for a sensor).

Resources (``resources="estimate"``, every point)
-------------------------------------------------
Exact sizes come from the objects the generator itself uses (:func:`pwas_hdl.hdl.build_core` +
:func:`~pwas_hdl.hdl.design_info`: the memory plan and the arithmetic widths of the manifest; no
Verilog is emitted; with the bit-true run, under 0.1 s a point for N = 4096); the logic is then
counted in bit-level units:

``memory_bits``
    ``words x word_bits`` of the weight memories (exact: the manifest's ``memory.bits``).
``register_bits``
    Flip-flops of the elaborated core: total width of the signals assigned in the ``sync`` domain
    (pipeline registers, output register, valid bits; the memories' read registers are counted in
    the block RAM, not here). Exact before synthesis optimisations.
``mult_bit_products``
    ``(n+1) * nz`` multipliers ``mu (F+1 bits unsigned) x w (B_w bits signed)``:
    ``(n+1) * nz * (F+1) * B_w`` partial-product bits (about one LUT4 each in logic).
``adder_bits``
    Adder/comparator bits: input offset and clamp ``2 n (B_in+1)``, rank comparators
    ``n(n-1)/2 (F+1)``, ``mu`` differences ``n (F+2)``, adder tree ``nz n (F+B_w+1)`` and rounding
    ``nz (F+B_w+1)`` (about one LUT4 + carry per bit).
``logic_bits``
    ``mult_bit_products + adder_bits``.
``total_bits``
    ``memory_bits + logic_bits + register_bits``: a technology-neutral area proxy in which a stored
    bit, a flip-flop, a partial-product bit and an adder bit count alike. This is the default
    ``cost`` of the front. It is dominated by the weight memory when ``N`` is large (FPGA block
    RAM makes a memory bit far cheaper than a LUT: pick ``cost="logic_bits"`` to look at logic
    alone, or measure).
``dsp18``
    18x18 multiplier blocks if the multipliers go to DSPs: ``(n+1) nz ceil((F+2)/18) ceil(B_w/18)``
    (the unsigned ``mu`` takes ``F + 2`` bits as a signed operand).
``bram18k``
    18-kbit block RAMs (ECP5 DP16KD / Xilinx RAMB18 aspect ratios 16k x 1 .. 512 x 36), best
    aspect ratio per bank.

The formulas above are a plain core's. An additive design (:func:`pwas_hdl.hdl.additive_top.build_additive_core`)
sums them over its parts (part ``i``: ``n_i`` inputs, ``F_i``, no output rounding) and adds the sum's
``nz (k - 1)`` adders and ``nz`` roundings of the sum's ``W`` bits (``sum_adder_bits``); memories,
multipliers, DSP and block-RAM counts are the parts' totals (``memory_depth``: the deepest part's;
``parts``: each part's figures). A warped design (:func:`pwas_hdl.hdl.warp.build_warped_core`) is
the uniform core on the warped ``W``-bit codes (``core_input_bits``: its offset and clamp are
``W + 1`` bits wide) plus the warp: per dimension three ``B_in``-bit comparators, the subtraction of
the domain's first code and a ``W``-bit constant addition (``warp_adder_bits``, in ``adder_bits``)
and its register (in ``register_bits``); its case tables and shift multiplexer are not counted.

Measured resources (``resources="generic" | "ecp5" | "ice40"``)
----------------------------------------------------------------
The estimate is computed for every point; then the Pareto points (and the default) are generated
(:func:`pwas_hdl.design.generate.build_design`) and synthesised with :func:`pwas_hdl.flow.synthesis.synthesize`
(Yosys; nextpnr for FPGA targets; for the Lorenz core about 15 s a point for ``generic``, 40 s for
``ecp5``): ``point["measured"]`` holds
LUTs, FFs, DSPs, block RAMs, memory bits (and fmax). The front stays the estimate's front; the
measured numbers check it: ``result["measured"]["pareto"]`` is the front of the synthesised points
alone in (LUTs, DSPs, block RAMs, ``rmsee_ratio``; a classifier's ``error_rate``; the names in
``result["measured"]["objectives"]``), and ``default_on_front`` says whether the
default is on it. Block RAMs and DSPs come in fixed sizes (an 18-bit word costs the same block as
a 10-bit one), so the measured front can differ from the bit-count estimate's.

Model kinds
-----------
Every point's bit-true model is :func:`pwas_hdl.design.generate.fixed_point_model`'s (what
``generate`` builds): a :class:`~pwas_hdl.fixedpoint.bittrue.FixedPointModel` for a plain sensor, an
:class:`~pwas_hdl.fixedpoint.additive.AdditiveFixedPointModel` for an additive one (fit
``--additive``: one core per part, summed before one rounding) and a
:class:`~pwas_hdl.fixedpoint.warp.WarpedFixedPointModel` for power-of-two breakpoints (fit
``--breakpoints quantile-pow2``: the warp in front of a uniform core); the resources are estimated
on the design ``generate`` builds for it (:func:`estimate_resources`), and the measured mode
generates and synthesises that design. ``result["model"]["kind"]`` says which (``plain``,
``additive``, ``warped``, ``observer-bank``). Fields that differ: an additive point's ``input_frac`` is ``F = max_i
F_i`` (the sum's alignment) and ``part_frac`` lists the parts' ``F_i``; a warped point's
``input_bits`` is the input code's ``B_in``, ``core_input_bits`` the width ``W`` of the warped code
``u`` the core takes, ``input_frac`` the core's ``F`` (a core cell is ``2**F`` codes of ``u``), and
its label reads ``in s<B_in> -> u s<W>.<F>``. A recurrent sensor (fit ``--mz``) is swept on its
closed loop (:func:`_evaluate_recurrent`: the bit-true recurrence from reset on each trajectory,
row ``t`` against ``z(t + lead)``, the float recurrence as the float column; the per-step bound at
the regressor codes the recurrence produced); its resources are the core's, and
``result["model"]["recurrence"]`` has ``Mz`` and ``lead`` (None for the other kinds).
A classifier (plain, additive or warped; fit does not make recurrent ones) is the same bit-true
model and design with the argmax stage after the core or the sum (what ``generate`` builds): its
``C - 1`` comparators of ``B_out`` bits are in ``adder_bits`` (``argmax_adder_bits``) and its
registers in ``register_bits``; its accuracy is the error rate above.

An observer-bank sensor (fit ``--front-end observer-bank``, with or without ``--mu/--my`` taps,
uniform or power-of-two) is the model of :func:`pwas_hdl.fixedpoint.observer_bank.observer_bank_model`
(what ``generate`` builds; ``kind`` ``observer-bank``): each trajectory runs from reset through the
bit-true bank, feature unit and core (:func:`bank_bittrue`, the model's ``trace``), the estimate of
sample ``k >= first_output`` against row ``k`` (the one alignment of the sensor top, its warm-up,
as ``simulate`` aligns it; :func:`_evaluate_observer_bank`), the float sensor's ``predict`` the
float column, ``bound_holds`` against the sensor's per-target bound, ``state_saturated`` the
samples whose bank update saturated a state. Besides the core's formats, the bank's ``F_s`` and
``F_c`` may be swept (``state_frac``, ``coef_frac``; default ``generate``'s at each input width) and
``B_s``, ``H`` fixed (``state_bits``, ``input_headroom``); each point's ``bank`` holds them. Its
resources are the parallel sensor top's (:func:`bank_resources` added to the core's figures,
``resources["bank"]``: the products by the non-zero coefficient codes -- one row of operand bits
per set bit of the constant, counted as logic, not DSP --, the ``N`` squarers and their 18x18
blocks, the accumulators, residuals, window sums, roots and feature maps in ``adder_bits``; the
registers of the elaborated top, the front end's elaborated once per bank format and the core's
per core shape). The bank has no memory.

The result's format is ``pwas-hdl-explore`` version 1 (:data:`EXPLORE_FORMAT`), this module its
owner; :func:`check_result` validates a result against the shipped schema
``pwas_hdl/schemas/explore-v1.schema.json`` (a sensor's and a classifier's points alike).

Combinations that the bit-true model refuses (an output finer than the exact product, a weight
that does not fit a fixed ``weight_bits``, an accumulator over 62 bits, an input width too small
for the partition) are skipped and listed in ``result["refused"]`` with the reason.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import warnings
from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from pwas_hdl import __version__
from pwas_hdl.errors import InputError, InternalError, ToolFailed, ToolMissing, choice_text, option_text
from pwas_hdl.fixedpoint.argmax import TIE_RULE
from pwas_hdl.fixedpoint.bittrue import FixedPointModel
from pwas_hdl.io.csv_table import Table, check_trajectory_column, read_csv, reference_column_names, select_signals
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.io.atomic import check_output_path, make_temp_dir
from pwas_hdl.limits import MAX_SWEEP_POINTS, check_limit, check_values

__all__ = [
    "EXPLORE_FORMAT",
    "EXPLORE_VERSION",
    "EXPLORE_SCHEMA",
    "check_result",
    "result_errors",
    "DEFAULT_INPUT_BITS",
    "DEFAULT_FRAC_OFFSETS",
    "DEFAULT_MEASURE_MAX",
    "RESOURCE_MODES",
    "COST_KEYS",
    "explore",
    "pareto_front",
    "bram18k_blocks",
    "mult18_blocks",
    "plot_exploration",
    "format_table",
    "default_verdict",
]

EXPLORE_FORMAT = "pwas-hdl-explore"
EXPLORE_VERSION = 1
#: The shipped JSON Schema of a result (``pwas_hdl/schemas/``): a sensor's and a classifier's sweep.
EXPLORE_SCHEMA = "explore-v1.schema.json"
_HINT = "write it again with `pwas-hdl explore`"

#: Input widths swept by default.
DEFAULT_INPUT_BITS = (8, 10, 12, 14, 16)
#: Weight / output fraction bits swept by default, relative to the defaults of ``generate`` (whose
#: rounding noise is 5 % of the training RMSE, :func:`pwas_hdl.fixedpoint.bittrue.default_weight_frac`): from
#: 4 bits coarser, where the accuracy clearly suffers, to 4 bits finer.
DEFAULT_FRAC_OFFSETS = tuple(range(-4, 5))
#: At most this many Pareto points are synthesised in a measured run (evenly spread, both ends kept).
DEFAULT_MEASURE_MAX = 10
#: ``resources=`` values: the analytic estimate only, or the estimate plus synthesis of the front.
RESOURCE_MODES = ("estimate", "generic", "ecp5", "ice40")
#: Estimate keys that can serve as the cost axis of the front.
COST_KEYS = ("total_bits", "memory_bits", "logic_bits", "register_bits", "mult_bit_products", "adder_bits", "dsp18", "bram18k")

#: (depth, width) aspect ratios of an 18-kbit block RAM.
_BRAM18_SHAPES = ((16384, 1), (8192, 2), (4096, 4), (2048, 9), (1024, 18), (512, 36))

Progress = Callable[[str, int, int], None]


# ------------------------------------------------------------------------------------ Pareto
def pareto_front(points: Sequence, objectives: Sequence[str] | None = None) -> list[int]:
    """Indices of the non-dominated points (every objective minimised).

    Parameters
    ----------
    points : sequence
        Either sequences of numbers (one value per objective) or mappings; with mappings,
        ``objectives`` names the keys (default ``("cost", "rmsee_ratio")``).
    objectives : sequence of str, optional

    Returns
    -------
    list of int
        Point ``i`` is on the front unless some ``j`` is ``<=`` in every objective and ``<`` in
        at least one. Points equal in every objective are all kept. Sorted by the first
        objective, then the next ones.

    Raises
    ------
    InputError
        Points of different lengths, or a NaN objective.
    """
    if len(points) == 0:
        return []
    if isinstance(points[0], dict):
        keys = tuple(objectives) if objectives is not None else ("cost", "rmsee_ratio")
        vals = np.array([[float(p[k]) for k in keys] for p in points], dtype=float)
    else:
        rows = [tuple(float(v) for v in p) for p in points]
        if len({len(r) for r in rows}) != 1 or len(rows[0]) == 0:
            raise InputError("all points need the same (non-zero) number of objectives")
        vals = np.array(rows, dtype=float)
    if np.isnan(vals).any():
        raise InputError("an objective is NaN; every point needs finite objective values (drop or fix the point)")
    front = []
    for i in range(vals.shape[0]):
        le = np.all(vals <= vals[i], axis=1)
        lt = np.any(vals < vals[i], axis=1)
        if not np.any(le & lt):
            front.append(i)
    return sorted(front, key=lambda i: (tuple(vals[i]), i))


# ------------------------------------------------------------------------------------ the format
def result_errors(result: Any) -> list[str]:
    """Every violation of the result format by ``result``, one sentence each (empty when valid).

    Parameters
    ----------
    result : Any
        A parsed ``explore.json`` or what :func:`explore` returns.

    Returns
    -------
    list of str
        The header's problem (format / version), else the schema's
        (:func:`pwas_hdl.io.json_contract.schema_errors` against :data:`EXPLORE_SCHEMA`), most
        relevant first.
    """
    from pwas_hdl.io.json_contract import check_header, schema_errors

    try:
        check_header(result, EXPLORE_FORMAT, EXPLORE_VERSION, "the result", _HINT)
    except InputError as exc:
        return [str(exc)]
    return schema_errors(result, EXPLORE_SCHEMA)


def check_result(result: Any, source: str = "the explore result") -> None:
    """Refuse a result that breaks the ``pwas-hdl-explore`` format (version 1, :data:`EXPLORE_SCHEMA`).

    Parameters
    ----------
    result : Any
        A parsed ``explore.json`` or what :func:`explore` returns (a sensor's or a classifier's).
    source : str
        Its name in the message (e.g. the file's path).

    Raises
    ------
    InputError
        One message: the file is not a ``pwas-hdl-explore`` version 1 result, or the schema's most
        relevant violation, naming the key by its path.
    """
    from pwas_hdl.io.json_contract import check_header, validate

    check_header(result, EXPLORE_FORMAT, EXPLORE_VERSION, source, _HINT)
    validate(result, EXPLORE_SCHEMA, source, _HINT)


# ------------------------------------------------------------------------------------ data
def _load_sensor(model) -> tuple[PWASVirtualSensor, str | None]:
    if isinstance(model, PWASVirtualSensor):
        return model, None
    return PWASVirtualSensor.load(model), str(model)


def _is_bank(sensor: PWASVirtualSensor) -> bool:
    """True for an observer-bank sensor (fit ``--front-end observer-bank``, with or without u/y taps)."""
    return getattr(sensor, "front_end_", None) is not None


def _check_supported(sensor: PWASVirtualSensor, bank_formats: dict[str, Any]) -> None:
    """Refuse, with one :class:`InputError`, what explore cannot sweep.

    Every kind ``generate`` builds is swept: plain, additive (fit --additive), non-uniform
    power-of-two (fit --breakpoints quantile-pow2), recurrent (fit --mz; their accuracy is the
    closed loop's), classifiers (fit --classify: the error rate of the bit-true argmax) and
    observer-bank sensors (fit --front-end observer-bank, with or without u/y taps: the bank, the
    features and the core from reset on each trajectory, :func:`_evaluate_observer_bank`); other
    breakpoints are refused by the bit-true model itself (the message names quantile-pow2).

    Parameters
    ----------
    sensor : PWASVirtualSensor
        The fitted model.
    bank_formats : dict
        The bank's format options given to explore (``state_frac``, ``coef_frac``, ``state_bits``,
        ``input_headroom``; None: not given).

    Raises
    ------
    InputError
        A bank format option given for a model without an observer bank (as ``generate`` refuses it).
    """
    if not _is_bank(sensor):
        given = [k for k, v in bank_formats.items() if v is not None]
        if given:
            raise InputError(f"{_option(given[0])} sets a format of the observer bank: it applies to observer-bank sensors "
                             "(fit --front-end observer-bank) only; leave it out for this model")


def _signals_and_reference(sensor: PWASVirtualSensor, data, traj_col: str | None, blank_rows: str = "error"):
    """The trajectories ``u``, ``y`` and ``z`` (lists, one array per trajectory; ``u`` / ``y`` None
    when the model has no such signal) of the data, and a description of where they came from.

    ``z`` holds the reference of each target (``(T_i, nz)``): column ``<target>_true``, else
    ``<target>`` (:meth:`Table.reference_column <pwas_hdl.io.csv_table.Table.reference_column>`).
    A classifier has one reference, the true class label (``(T_i, 1)``): column ``<label>_true``,
    else ``<label>``, found as ``predict`` finds it; a tuple ``(u, y, z)`` then gives the labels as
    ``z``."""
    ins, outs, tgts = sensor.signal_names()
    clf = getattr(sensor, "classifier_", None)
    refs_of = [clf["target"]] if clf is not None else tgts  # the quantities compared with the data
    lags = sensor.lags_
    # an observer bank takes every input and the output (as simulate feeds the sensor top), whatever its taps
    use_u, use_y = (bool(ins), True) if _is_bank(sensor) else (bool(lags.nu), bool(lags.ny))
    if isinstance(data, (str, os.PathLike)):
        data = read_csv(data, blank_rows=blank_rows)
    if isinstance(data, Table):
        check_trajectory_column(data, traj_col, [*ins, *outs], refs_of)
        u = select_signals(data, ins, traj_col) if use_u else None
        y = select_signals(data, outs, traj_col) if use_y else None
        refs = []
        for t in refs_of:
            col = data.reference_column(t)
            if col is None:
                what = (f"with the true class of classifier {t!r} (its decisions are scored against it)" if clf is not None
                        else f"to compare the estimate of target {t!r} with")
                raise InputError(
                    f"{data.path}: no column {' or '.join(map(repr, reference_column_names(t)))} {what}; "
                    f"the file has columns {', '.join(data.header)}"
                )
            refs.append(col)
        ztab = select_signals(data, refs, traj_col)
        desc = {"path": data.path, "reference_columns": refs, "traj_col": traj_col}
    else:
        try:
            u, y, ztab = data
        except (TypeError, ValueError):
            raise InputError("data must be a CSV path, a pwas_hdl.io.csv_table.Table or a tuple (u, y, z)") from None
        from pwas_hdl.fit.regressors import as_trajectories

        ztab = as_trajectories(ztab, "z (the true class labels)" if clf is not None else "z", len(refs_of))
        desc = {"path": None, "reference_columns": None, "traj_col": None}
    return u, y, ztab, desc


def _regressors_and_reference(sensor: PWASVirtualSensor, data, traj_col: str | None, blank_rows: str = "error"):
    """``xi (m, n)``, reference ``z (m, nz)`` (a classifier's: the true labels, ``(m, 1)``), and a
    description of where they came from."""
    u, y, ztab, desc = _signals_and_reference(sensor, data, traj_col, blank_rows)
    tgts = sensor.signal_names()[2]
    xi, valid = sensor.regressors(u, y)
    if len(ztab) != len(valid):
        raise InputError(f"got {len(ztab)} target trajectories but {len(valid)} input/output trajectories")
    zs = []
    for zt, sl in zip(ztab, valid):
        if zt.shape[0] < sl.stop:
            raise InputError(f"a target trajectory has {zt.shape[0]} samples, its regressors need {sl.stop}")
        zs.append(np.asarray(zt, dtype=float)[sl])
    z = np.concatenate(zs, axis=0)
    if xi.shape[0] == 0:
        raise InputError("the data have no sample with a full regressor (too few samples for the lags)")
    clf = getattr(sensor, "classifier_", None)
    if clf is None:
        for i, t in enumerate(tgts):  # the reference of the RMSEE: its squared errors would overflow
            where = f"{desc['path']}: column {desc['reference_columns'][i]!r}" if desc["path"] is not None else f"z of target {t!r}"
            check_values(where, z[:, i], "fix the data (no RMSEE can be measured against it)")
    else:  # a label no class stands for: most likely another column (a continuous target, say), not a class
        from pwas_hdl.fit.classifier import check_true_labels

        where = f"{desc['path']}: column {desc['reference_columns'][0]!r}" if desc["path"] is not None else "z (the true labels)"
        check_true_labels(z[:, 0], clf["classes"], clf["target"], where)
    desc["samples"] = int(xi.shape[0])
    return xi, z, desc


def _recurrent_data(sensor: PWASVirtualSensor, data, traj_col: str | None, blank_rows: str = "error") -> dict:
    """The data of a recurrent sensor's sweep, aligned as ``simulate`` aligns a recurrent design.

    Each trajectory is one run of the recurrence from reset; its row ``t = M-1 .. T-1`` estimates
    ``z(t + lead)``, so the rows whose reference row exists are kept.

    Returns
    -------
    dict
        ``trajectories`` (list of ``(u, y)``, physical, None for a signal without lags),
        ``keep`` (list of bool arrays, the kept rows of each run), ``z`` (m, nz) the reference and
        ``float`` (m, nz) the float recurrence on the kept rows, ``desc`` (where the data came from).

    Raises
    ------
    InputError
        As :func:`_signals_and_reference`; a trajectory shorter than the lags, trajectories of
        different counts or lengths, no kept row, or a reference value that is not finite.
    """
    from pwas_hdl.fit.regressors import as_trajectories

    u, y, ztab, desc = _signals_and_reference(sensor, data, traj_col, blank_rows)
    lags = sensor.lags_
    tgts = sensor.signal_names()[2]
    us = as_trajectories(u, "u", lags.nu) if lags.nu and lags.mu else None
    ys = as_trajectories(y, "y", lags.ny) if lags.ny and lags.my else None
    for name, tr in (("u", us), ("y", ys)):
        if tr is not None and len(tr) != len(ztab):
            raise InputError(f"got {len(ztab)} target trajectories but {len(tr)} {name} trajectories")
    from pwas_hdl.design.recurrent import estimate_rows

    m_hist, lead = max(lags.memory, 1), int(getattr(sensor, "lead_", 0))
    trajs, keeps, zs, zfs = [], [], [], []
    for i, zt in enumerate(ztab):
        ui, yi = (us[i] if us is not None else None), (ys[i] if ys is not None else None)
        t_len = zt.shape[0]
        for name, a in (("u", ui), ("y", yi)):
            if a is not None and a.shape[0] != t_len:
                raise InputError(f"trajectory {i}: {name} has {a.shape[0]} samples, z {t_len}")
        if t_len < m_hist:
            raise InputError(f"trajectory {i} has {t_len} samples; the lags need {m_hist}")
        rows, keep = estimate_rows(0, t_len, lags, lead)  # simulate's alignment of a recurrent design
        zf = np.asarray(sensor.predict(ui, yi), dtype=float).reshape(-1, len(tgts))
        trajs.append((ui, yi))
        keeps.append(keep)
        zs.append(np.asarray(zt, dtype=float)[rows[keep] + lead])
        zfs.append(zf[keep])
    z = np.concatenate(zs, axis=0)
    if z.shape[0] == 0:
        raise InputError(f"the data have no sample whose estimate has a reference (the lags need {m_hist} samples, "
                         f"the estimate of row t is z(t + {lead}))")
    for i, t in enumerate(tgts):
        where = f"{desc['path']}: column {desc['reference_columns'][i]!r}" if desc["path"] is not None else f"z of target {t!r}"
        check_values(where, z[:, i], "fix the data (no RMSEE can be measured against it)")
    desc["samples"] = int(z.shape[0])
    return {"trajectories": trajs, "keep": keeps, "z": z, "float": np.concatenate(zfs, axis=0), "desc": desc}


def _bank_data(sensor: PWASVirtualSensor, first_output: int, data, traj_col: str | None, blank_rows: str = "error") -> dict:
    """The data of an observer-bank sensor's sweep, aligned as ``simulate`` aligns the sensor top.

    Each trajectory is one run of the bank from reset; its samples ``first_output .. T-1`` have an
    estimate (the bit-true model's :attr:`~pwas_hdl.fixedpoint.observer_bank.ObserverBankSensorModel.first_output`,
    the top's warm-up), compared with the reference rows of the same samples.

    Parameters
    ----------
    sensor : PWASVirtualSensor
        An observer-bank sensor (with or without u/y taps).
    first_output : int
        Sample index (0-based since reset) of the first estimate (``M + l``, or ``max(M + l,
        memory - 1)`` with taps; it does not depend on the formats).
    data, traj_col, blank_rows
        As :func:`explore`.

    Returns
    -------
    dict
        ``trajectories`` (list of ``(u (T_i, nu) or None, y (T_i, 1))``, physical units),
        ``z`` (m, nz) the reference and ``float`` (m, nz) the float sensor
        (:meth:`PWASVirtualSensor.predict`) on the estimated samples, ``desc`` (where the data
        came from; ``samples`` = m) and ``first_output``.

    Raises
    ------
    InputError
        As :func:`_signals_and_reference`; trajectories of different counts or lengths, one with no
        estimated sample (``T_i <= first_output``), or a reference value that is not finite.
    """
    from pwas_hdl.fit.regressors import as_trajectories

    ins, outs, tgts = sensor.signal_names()
    u, y, ztab, desc = _signals_and_reference(sensor, data, traj_col, blank_rows)
    us = as_trajectories(u, "u", len(ins)) if ins else None
    ys = as_trajectories(y, "y", len(outs))
    for name, tr in (("u", us), ("y", ys)):
        if tr is not None and len(tr) != len(ztab):
            raise InputError(f"got {len(ztab)} target trajectories but {len(tr)} {name} trajectories")
    trajs, zs, zfs = [], [], []
    for i, zt in enumerate(ztab):
        ui, yi = (us[i] if us is not None else None), ys[i]
        t_len = zt.shape[0]
        for name, a in (("u", ui), ("y", yi)):
            if a is not None and a.shape[0] != t_len:
                raise InputError(f"trajectory {i}: {name} has {a.shape[0]} samples, z {t_len}")
        if t_len <= first_output:
            raise InputError(f"trajectory {i} has {t_len} samples; the observer bank needs {first_output + 1} (its first "
                             f"estimate is at sample {first_output} after reset)")
        zf = np.asarray(sensor.predict(ui, yi), dtype=float).reshape(-1, len(tgts))
        if zf.shape[0] != t_len - first_output:  # the float sensor's rows are the bit-true model's
            raise InternalError(f"the float observer-bank sensor gave {zf.shape[0]} estimates for {t_len} samples, "
                                f"the bit-true model {t_len - first_output}")
        trajs.append((ui, yi))
        zs.append(np.asarray(zt, dtype=float)[first_output:])
        zfs.append(zf)
    z = np.concatenate(zs, axis=0)
    for i, t in enumerate(tgts):
        where = f"{desc['path']}: column {desc['reference_columns'][i]!r}" if desc["path"] is not None else f"z of target {t!r}"
        check_values(where, z[:, i], "fix the data (no RMSEE can be measured against it)")
    desc["samples"] = int(z.shape[0])
    return {"trajectories": trajs, "z": z, "float": np.concatenate(zfs, axis=0), "desc": desc, "first_output": first_output}


_option = option_text  # ``input_bits`` -> ``--input-bits (input_bits)``: the explore option first


def _int_values(values, what: str, lo: int | None = None) -> list[int]:
    if values is None:
        return []
    if isinstance(values, (int, np.integer)) and not isinstance(values, bool):
        values = [values]
    if hasattr(values, "__len__"):  # before iterating a huge range
        check_limit(f"the number of {what} values", len(values), MAX_SWEEP_POINTS, "sweep fewer values")
    out = []
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise InputError(f"{_option(what)} must be integers, got {v!r}")
        if lo is not None and v < lo:
            raise InputError(f"{_option(what)} must be >= {lo}, got {v}")
        out.append(int(v))
    if not out:
        raise InputError(f"{_option(what)}: the sweep is empty; give at least one value")
    return sorted(set(out))


# ------------------------------------------------------------------------------------ resources
def mult18_blocks(f: int, weight_bits: int) -> int:
    """18x18 multiplier blocks of one product ``u(F+1) x s(B_w)`` (the fraction times the weight).

    Parameters
    ----------
    f : int
        ``F``, fraction bits of the grid coordinate (the unsigned fraction is ``F + 1`` bits wide).
    weight_bits : int
        ``B_w``, the weight width in bits.

    Returns
    -------
    int
        Multiplier blocks.
    """
    return math.ceil((f + 2) / 18) * math.ceil(weight_bits / 18)


def bram18k_blocks(depth: int, width: int) -> int:
    """18-kbit block RAMs (ECP5 DP16KD, any of its aspect ratios) that hold ``depth`` words of ``width`` bits.

    Parameters
    ----------
    depth : int
        Words of the memory.
    width : int
        Word width in bits.

    Returns
    -------
    int
        Block RAMs (the fewest over the aspect ratios).
    """
    return min(math.ceil(depth / d) * math.ceil(width / w) for d, w in _BRAM18_SHAPES)


def _register_bits(core) -> int | None:
    """Total width of the signals the core assigns in its ``sync`` domain (None if unavailable)."""
    try:
        import dataclasses

        from amaranth.hdl import Fragment

        # the register widths do not depend on the memory contents: elaborate with empty
        # initialisers (the weights would cost ~0.1 s a point to convert, for nothing)
        plan = core.memory_plan
        core.memory_plan = dataclasses.replace(plan, contents=tuple(() for _ in plan.contents))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                frag = Fragment.get(core, None)
        finally:
            core.memory_plan = plan
        widths: dict[int, int] = {}
        for st in frag.statements.get("sync", []):
            for sig in st._lhs_signals():
                widths[id(sig)] = len(sig)
        return int(sum(widths.values()))
    except Exception:  # pragma: no cover - private Amaranth API changed
        return None


def _design_register_bits(design, cores) -> int | None:
    """:func:`_register_bits` of a design made of several cores (an additive design's parts, the core
    behind a warp): the ``sync`` signals of the design and of all its submodules (the additive parts
    are submodules), each core elaborated with empty memory initialisers. None if unavailable."""
    try:
        import dataclasses

        from amaranth.hdl import Fragment

        plans = [c.memory_plan for c in cores]
        for c, plan in zip(cores, plans):
            c.memory_plan = dataclasses.replace(plan, contents=tuple(() for _ in plan.contents))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                frag = Fragment.get(design, None)
        finally:
            for c, plan in zip(cores, plans):
                c.memory_plan = plan
        widths: dict[int, int] = {}

        def walk(f) -> None:
            for st in f.statements.get("sync", []):
                for sig in st._lhs_signals():
                    widths[id(sig)] = len(sig)
            for sub, *_ in getattr(f, "subfragments", ()):
                walk(sub)

        walk(frag)
        return int(sum(widths.values()))
    except Exception:  # pragma: no cover - private Amaranth API changed
        return None


#: Register bits of elaborated cores by :func:`_register_key`, shared by every call in the process
#: (an explore sweep elaborates each hardware shape once; a second sweep of the same model -- another
#: cost key, a measured run after an estimate, a narrower range -- elaborates nothing it has seen).
_REGISTER_BITS: "OrderedDict[tuple, int | None]" = OrderedDict()
#: At most this many entries are kept (least recently used dropped first; an entry is a few ints).
_REGISTER_BITS_MAX = 4096


def _core_key(core) -> tuple:
    """The structure of one core that its register widths depend on (see :func:`_register_key`)."""
    p = core.params
    return (type(core).__module__, type(core).__qualname__, getattr(core, "memory_kind", None), core.pipeline,
            getattr(core, "round_output", True), p.partitions, p.nz, p.in_width, p.lo_code, p.frac_bits,
            p.weight_width, p.out_width, p.scaling)


def _register_key(core) -> tuple | None:
    """What the core's register widths depend on: everything of its structure except the weight values,
    the rounding mode and the shift (the weights, the rounding constant and the output alignment are
    combinational; the registers hold the same widths). ``None`` for a core this cache does not
    describe (an extra input stage, or unhashable parameters)."""
    if getattr(core, "input_stage", None) is not None:
        return None
    key = _core_key(core)
    try:
        hash(key)
    except TypeError:
        return None
    return key


def _design_register_key(design, kind: str) -> tuple | None:
    """:func:`_register_key` of an additive design (its parts' keys, the sum's and the output's widths), of
    a warped core (the core's key; the warp register holds ``n`` codes of the core's input width, in
    that key) or of a classifier's core and argmax stage (``kind="classifier"``: the core's key). With
    an argmax stage (``design.argmax``) the key says so: its registers hold ``nz`` scores of the
    output width under the core's pipeline, all in the key. ``None`` if unhashable."""
    argmax = getattr(design, "argmax", None) is not None
    if kind == "additive":
        p = design.params
        key = ("additive", tuple(_core_key(c) for c in design.parts), p.n, p.nz, p.in_width, p.sum_width, p.out_width,
               argmax)
    elif kind == "classifier":
        key = ("classifier", type(design).__qualname__, _core_key(design.core))
    else:
        key = ("warped", type(design).__qualname__, _core_key(design.core), argmax)
    try:
        hash(key)
    except TypeError:
        return None
    return key


def _cached_register_bits(core) -> int | None:
    key = _register_key(core)
    if key is None:
        return _register_bits(core)
    if key in _REGISTER_BITS:
        _REGISTER_BITS.move_to_end(key)
        return _REGISTER_BITS[key]
    regs = _REGISTER_BITS[key] = _register_bits(core)
    while len(_REGISTER_BITS) > _REGISTER_BITS_MAX:
        _REGISTER_BITS.popitem(last=False)
    return regs


def _cached_design_register_bits(design, kind: str, cores) -> int | None:
    key = _design_register_key(design, kind)
    if key is None:
        return _design_register_bits(design, cores)
    if key in _REGISTER_BITS:
        _REGISTER_BITS.move_to_end(key)
        return _REGISTER_BITS[key]
    regs = _REGISTER_BITS[key] = _design_register_bits(design, cores)
    while len(_REGISTER_BITS) > _REGISTER_BITS_MAX:
        _REGISTER_BITS.popitem(last=False)
    return regs


def model_kind(fxm) -> str:
    """``"observer-bank"``, ``"additive"``, ``"warped"`` or ``"plain"``: which design ``generate`` builds
    for a bit-true model (:func:`pwas_hdl.design.generate.fixed_point_model` returns the additive and
    warped ones for additive sensors and non-uniform power-of-two partitions,
    :func:`pwas_hdl.fixedpoint.observer_bank.observer_bank_model` the observer-bank one)."""
    from pwas_hdl.fixedpoint.additive import AdditiveFixedPointModel
    from pwas_hdl.fixedpoint.observer_bank import ObserverBankSensorModel
    from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel

    if isinstance(fxm, ObserverBankSensorModel):
        return "observer-bank"
    if isinstance(fxm, AdditiveFixedPointModel):
        return "additive"
    if isinstance(fxm, WarpedFixedPointModel):
        return "warped"
    return "plain"


def _core_adder_bits(n: int, nz: int, f: int, bw: int, in_width: int, rounding: bool = True) -> int:
    """Adder/comparator bits of one PWAS core (module notes): input offset and clamp, rank comparators,
    ``mu`` differences, adder tree and (``rounding``) the output rounding."""
    acc = f + bw + 1
    return 2 * n * (in_width + 1) + n * (n - 1) // 2 * (f + 1) + n * (f + 2) + nz * n * acc + (nz * acc if rounding else 0)


def estimate_resources(fxm: FixedPointModel, memory: str = "banked", pipeline=None,
                       classifier: dict | None = None, isqrt_every: int | None = None) -> dict[str, Any]:
    """The resource estimate of the core the generator builds for ``fxm`` (see the module notes).

    Parameters
    ----------
    fxm : FixedPointModel
        The bit-true model (:func:`pwas_hdl.design.generate.fixed_point_model`: plain, additive or warped).
    memory : {"banked", "replicated"}
        Weight memory layout.
    pipeline : Pipeline, preset name or None
        As :func:`pwas_hdl.hdl.build_core` (default balanced).
    classifier : dict, optional
        ``sensor.classifier_`` of a classifier model (``{"target", "classes"}``): the design then
        ends with the argmax stage (:func:`pwas_hdl.hdl.api.classifier_stage`), whose ``C - 1``
        comparators of ``B_out`` bits are added to ``adder_bits`` (``argmax_adder_bits``; its
        multiplexers are not counted) and whose registers are in ``register_bits`` (the latency
        is the design's, stage included).

    Returns
    -------
    dict
        The figures of the module notes (bits, blocks, ``latency_cycles``, ``acc_bits``; an
        additive model's ``parts`` and ``sum_adder_bits``, a warped model's ``core_input_bits`` and
        ``warp_adder_bits``, a classifier's ``argmax_adder_bits``).

    The register bits come from an elaboration of the core, cached per process by the parameters
    that shape the hardware (:func:`_register_key`).

    An additive model (:class:`~pwas_hdl.fixedpoint.additive.AdditiveFixedPointModel`) is estimated
    on its design (:func:`pwas_hdl.hdl.additive_top.build_additive_core`, what ``generate`` builds):
    memories and multipliers summed over its parts (part ``i``: ``n_i + 1`` banks, ``F_i``), the
    parts' adders without their rounding, plus the sum (``nz (k - 1)`` adders and ``nz`` roundings
    of ``W`` = the sum's bits); ``memory_depth`` is the deepest part's, ``parts`` lists each part's
    figures. A warped model (:class:`~pwas_hdl.fixedpoint.warp.WarpedFixedPointModel`) is estimated
    on :func:`pwas_hdl.hdl.warp.build_warped_core`: the uniform core behind the warp (its input
    offset and clamp on the core's ``W``-bit codes ``u``, ``core_input_bits``) plus the warp's
    comparators and constant adders (``warp_adder_bits``, in ``adder_bits``: per dimension three
    ``B_in``-bit comparators, a constant subtraction over the domain's codes and a ``W``-bit
    constant addition) and its register (in ``register_bits``); its case tables and shift
    multiplexer are not counted.
    """
    from pwas_hdl.hdl import build_core, design_info

    kind = model_kind(fxm)
    if kind == "observer-bank":
        return _estimate_observer_bank(fxm, memory, pipeline, isqrt_every)
    if kind == "additive":
        return _estimate_additive(fxm, memory, pipeline, classifier)
    if kind == "warped":
        return _estimate_warped(fxm, memory, pipeline, classifier)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        core = build_core(fxm, memory=memory, pipeline=pipeline, classifier=classifier)
        info = design_info(core)
    # the registers depend on the widths only (not on the weights, the shift or the rounding)
    if classifier is None:
        return _core_estimate(info, _cached_register_bits(core))
    am = _argmax_adder_bits(core)
    res = _core_estimate(info, _cached_design_register_bits(core, "classifier", [core.core]), am)
    return {**res, "argmax_adder_bits": am}


def _argmax_adder_bits(design) -> int:
    """Comparator bits of a classifier design's argmax stage (``design.argmax``): ``C - 1`` compare
    nodes of ``B_out`` bits each (0 without a stage)."""
    am = getattr(design, "argmax", None)
    return 0 if am is None else (int(am.n_inputs) - 1) * int(am.width)


def _core_estimate(info: dict, regs: int | None, extra_adder_bits: int = 0) -> dict[str, Any]:
    """The resource figures of one PWAS core from its ``design_info`` (memory, multipliers, adders,
    DSP / block-RAM estimates; the module notes), its register bits ``regs`` and the adder bits of
    logic in front of it (``extra_adder_bits``: a warp's)."""
    mem, ar = info["memory"], info["arithmetic"]
    n, nz, f, bw, bin_ = ar["n"], ar["nz"], ar["F"], ar["weight_width"], ar["in_width"]
    nb = int(mem["memories"])
    mults = nb * nz
    mult_bits = mults * (f + 1) * bw
    adder = _core_adder_bits(n, nz, f, bw, bin_) + extra_adder_bits
    logic = mult_bits + adder
    return {
        "memory_words": int(mem["words"]),
        "memory_word_bits": int(mem["word_bits"]),
        "memory_banks": nb,
        "memory_depth": int(mem["depth"]),
        "memory_bits": int(mem["bits"]),
        "multipliers": mults,
        "multiplier": f"u{f + 1} x s{bw}",
        "mult_bit_products": mult_bits,
        "adder_bits": adder,
        "logic_bits": logic,
        "register_bits": regs,
        "total_bits": int(mem["bits"]) + logic + (regs or 0),
        "dsp18": mults * mult18_blocks(f, bw),
        "bram18k": nb * bram18k_blocks(int(mem["depth"]), int(mem["word_bits"])),
        "latency_cycles": int(info["latency"]),
        "acc_bits": int(ar["sum_bits"]),
    }


def _estimate_additive(fxm, memory: str, pipeline, classifier: dict | None = None) -> dict[str, Any]:
    """:func:`estimate_resources` of an additive model (the design of ``generate``: one core per part, the
    sum, a classifier's argmax stage)."""
    from pwas_hdl.hdl import design_info
    from pwas_hdl.hdl.additive_top import build_additive_core

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        comp = build_additive_core(fxm, memory=memory, pipeline=pipeline, classifier=classifier)
        info = design_info(comp)
    mem, ar = info["memory"], info["arithmetic"]
    nz, bw, bin_ = int(ar["nz"]), int(ar["weight_width"]), int(ar["in_width"])
    k = len(comp.parts)
    w_sum = int(comp.params.sum_width)
    parts, mults, mult_bits, adder, dsp, bram = [], 0, 0, 0, 0, 0
    for core in comp.parts:
        pp, plan = core.params, core.memory_plan
        n_i, f_i, nb = int(pp.n), int(pp.frac), int(plan.n_banks)
        m_i = nb * nz
        part = {"n": n_i, "F": f_i, "memory_banks": nb, "memory_depth": int(plan.depth), "memory_words": int(plan.words),
                "memory_bits": int(plan.bits), "multipliers": m_i, "multiplier": f"u{f_i + 1} x s{bw}",
                "mult_bit_products": m_i * (f_i + 1) * bw, "adder_bits": _core_adder_bits(n_i, nz, f_i, bw, bin_, rounding=False),
                "dsp18": m_i * mult18_blocks(f_i, bw), "bram18k": nb * bram18k_blocks(int(plan.depth), int(plan.word_bits))}
        parts.append(part)
        mults += m_i
        mult_bits += part["mult_bit_products"]
        adder += part["adder_bits"]
        dsp += part["dsp18"]
        bram += part["bram18k"]
    adder += nz * (k - 1) * w_sum + nz * w_sum  # the sum's adder tree and its rounding, W bits each
    am = _argmax_adder_bits(comp)
    adder += am
    regs = _cached_design_register_bits(comp, "additive", comp.parts)
    logic = mult_bits + adder
    kinds = list(dict.fromkeys(p["multiplier"] for p in parts))
    extra = {"argmax_adder_bits": am} if classifier is not None else {}
    return {
        "memory_words": int(mem["words"]),
        "memory_word_bits": int(mem["word_bits"]),
        "memory_banks": int(mem["memories"]),
        "memory_depth": int(mem["depth"]),
        "memory_bits": int(mem["bits"]),
        "multipliers": mults,
        "multiplier": ", ".join(kinds),
        "mult_bit_products": mult_bits,
        "adder_bits": adder,
        "logic_bits": logic,
        "register_bits": regs,
        "total_bits": int(mem["bits"]) + logic + (regs or 0),
        "dsp18": dsp,
        "bram18k": bram,
        "latency_cycles": int(info["latency"]),
        "acc_bits": w_sum,
        "sum_adder_bits": nz * k * w_sum,
        "parts": parts,
        **extra,
    }


def _estimate_warped(fxm, memory: str, pipeline, classifier: dict | None = None) -> dict[str, Any]:
    """:func:`estimate_resources` of a warped model (the design of ``generate``: warp + register + the
    uniform core, a classifier's argmax stage)."""
    from pwas_hdl.hdl import design_info
    from pwas_hdl.hdl.warp import build_warped_core

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        comp = build_warped_core(fxm, memory=memory, pipeline=pipeline, classifier=classifier)
        info = design_info(comp)
    w_core = int(info["arithmetic"]["in_width"])  # the core's W (the warp's output code)
    warp_adder = _warp_adder_bits(fxm)
    am = _argmax_adder_bits(comp)
    res = _core_estimate(info, _cached_design_register_bits(comp, "warped", [comp.core]), warp_adder + am)
    extra = {"argmax_adder_bits": am} if classifier is not None else {}
    return {**res, "core_input_bits": w_core, "warp_adder_bits": warp_adder, **extra}


def _warp_adder_bits(fxm) -> int:
    """Adder/comparator bits of the warps of a :class:`~pwas_hdl.fixedpoint.warp.WarpedFixedPointModel`:
    per dimension three comparators on ``B_in`` bits, ``t = q - B_0`` over the domain's codes and
    ``u = U + L`` on ``W`` bits."""
    bits = 0
    for wp in fxm.warps:
        span = int(wp.code_breaks[-1] - wp.code_breaks[0])
        bits += 3 * int(wp.input_bits) + max(1, (span - 1).bit_length()) + int(wp.width)
    return bits


def _const_mult_bits(k: int, width: int) -> int:
    """Partial-product bits of a multiplication by the constant ``k`` of a ``width``-bit operand: one
    row of ``width`` bits per set bit of ``|k|`` (0 for ``k = 0``, which the RTL leaves out)."""
    return bin(abs(int(k))).count("1") * int(width)


def bank_resources(bm) -> dict[str, Any]:
    """The resource figures of the parallel observer bank, feature unit and u/y taps of a bit-true
    observer-bank sensor (what :func:`pwas_hdl.hdl.observer_sensor_top.build_observer_sensor` /
    :func:`~pwas_hdl.hdl.observer_tap_sensor_top.build_tapped_observer_sensor` build in front of
    the core, ``architecture="parallel"``), in the units of :func:`estimate_resources`.

    Parameters
    ----------
    bm : ObserverBankSensorModel or TappedObserverBankSensorModel
        The bit-true model (:func:`pwas_hdl.fixedpoint.observer_bank.observer_bank_model`).

    Returns
    -------
    dict
        ``constant_multipliers`` (count of the products by a non-zero coefficient: ``a0``, ``b``,
        ``l`` of every observer and state, the feature scale ``K_j`` and the taps' ``K_j``; the
        alignments by powers of two that the structure has -- ``y << (F_s - F_in)``,
        ``x_{i+1} << F_c`` -- are wiring, not counted), ``constant_mult_bit_products`` (one row of
        operand bits per set bit of the constant: ``B_s`` for ``a0``, ``B_in`` for ``b``, ``l`` and
        the taps, the capped root's bits + 1 for ``K_j``), ``squarers`` (``N``, one ``e * e`` of
        ``residual_bits`` each), ``square_bit_products`` (``N residual_bits**2``), ``dsp18`` (the
        squarers' 18x18 blocks; the constant products are counted as logic), ``adder_bits`` (per
        observer and state the accumulator's ``terms - 1`` adders of ``acc_bits + 1`` bits and its
        constant add of ``acc_bits``; per observer the residual ``residual_bits + 1``, the window
        sum's add and subtract ``2 (sum_bits + 1)``, map 11b the square root's digit steps
        ``sum_{i < ceil(sum_bits/2)} (i + 2)``, the feature code's cap compare and constant add;
        per tap its constant add of ``product_bits``), ``state_register_bits`` (``N M B_s``),
        ``delay_line_bits`` (``N (l + 1) sum_bits``), ``window_sum_bits`` (``N sum_bits``),
        ``root_register_bits`` (``N root_bits``), ``lag_bank_bits`` (the taps' input-code delay
        registers, ``B_in`` each), and ``n_models``, ``order``, ``window``, ``feature_map``,
        ``taps``. The bank has no memory: its delay lines are registers. The register entries are
        the main ones, not all: the square roots' pipeline registers and the feature-code
        registers (and the taps' registers beside them) are in the estimate's ``register_bits``,
        which counts the elaborated top's flip-flops, not here.
    """
    b = bm.bank
    fmt = b.formats
    n_obs, mo, nu, lw = b.n_models, b.order, b.nu, b.window
    bs, accw, rb, sumb, rootb = fmt.state_bits, fmt.acc_bits, fmt.residual_bits, fmt.sum_bits, fmt.root_bits
    bin_ = fmt.input_bits
    n_const, cbits, adder = 0, 0, 0
    for j in range(n_obs):
        adder += rb + 1  # e = x_0 - (qy << (F_s - F_in))
        for i in range(mo):
            consts = [(int(b.a0_codes[j, i]), bs)] + [(int(b.b_codes[j, i, c]), bin_) for c in range(nu)] + [(int(b.l_codes[j, i]), bin_)]
            terms = 0
            for k, w in consts:
                if k:
                    n_const += 1
                    cbits += _const_mult_bits(k, w)
                    terms += 1
            terms += 1 if i + 1 < mo else 0  # x_{i+1} << F_c
            if terms:
                adder += (terms - 1) * (accw + 1) + accw  # the sum tree, then + D + the rounding constant
        adder += 2 * (sumb + 1)  # S + sq - sq_{k-l-1}
        if b.feature_map == "11b":
            adder += sum(i + 2 for i in range((sumb + 1) // 2))  # the digit-by-digit root's compare-subtracts
    sw = int(b.widths["scale_product"])
    rs = rootb - int(b.root_shift)
    for k, cap in zip(b.scale_mul, b.root_cap):
        capw = max(1, int(cap).bit_length())
        n_const += 1
        cbits += _const_mult_bits(k, capw + 1)
        adder += (rs if int(cap) < (1 << rs) - 1 else 0) + sw  # min(r >> t, cap), then + C
    taps = getattr(bm, "taps", None)
    lag_bits = 0
    if taps is not None:
        for k in taps.mul:
            n_const += 1
            cbits += _const_mult_bits(k, bin_)
            adder += int(taps.product_bits)
        depth: dict[int, int] = {}
        for sig, lag in taps.dims:
            depth[sig] = max(depth.get(sig, 0), int(lag))
        lag_bits = sum(depth.values()) * bin_
    return {
        "n_models": n_obs, "order": mo, "window": lw, "feature_map": b.feature_map,
        "taps": 0 if taps is None else len(taps.dims),
        "constant_multipliers": n_const,
        "constant_mult_bit_products": cbits,
        "squarers": n_obs,
        "square_bit_products": n_obs * rb * rb,
        "dsp18": n_obs * math.ceil(rb / 18) ** 2,
        "adder_bits": adder,
        "state_register_bits": n_obs * mo * bs,
        "delay_line_bits": n_obs * (lw + 1) * sumb,
        "window_sum_bits": n_obs * sumb,
        "root_register_bits": n_obs * rootb,
        "lag_bank_bits": lag_bits,
    }


def _front_register_key(comp, bm) -> tuple | None:
    """What the registers in front of the core of an observer-bank top depend on: the bank's sizes and
    widths, which input coefficients are non-zero (the parallel bank registers each non-zero
    ``b`` / ``l`` product, stage ``s_in``, and an input sum per state that has one, ``s_in2``), the
    widths of the capped roots and of the feature products (registered inside the affine map), the
    taps, the warp (its register: ``n`` codes of the core's input width), the square root's
    register spacing and the warm-up counter; not the core's weight / output formats nor its pipeline (the core's own
    registers, :func:`_cached_register_bits` of the core alone). ``None`` if unhashable."""
    b = bm.bank
    taps = getattr(bm, "taps", None)
    p = comp.core.params
    key = ("observer-bank-front", type(comp).__qualname__, tuple(sorted(b.formats.to_dict().items())), b.n_models, b.order,
           b.nu, b.window, b.feature_map, None if taps is None else (tuple(taps.dims), int(taps.core_bits)),
           getattr(comp, "warps", None) is not None, int(comp.warmup), p.n, p.in_width,
           getattr(comp, "isqrt_every", None),  # the parallel bank's root registers
           tuple(bool(v) for v in np.asarray(b.b_codes).ravel()), tuple(bool(v) for v in np.asarray(b.l_codes).ravel()),
           tuple(sorted((k, int(v)) for k, v in b.widths.items())), tuple(int(c).bit_length() for c in b.root_cap))
    try:
        hash(key)
    except TypeError:
        return None
    return key


def _estimate_observer_bank(bm, memory: str, pipeline, isqrt_every: int | None = None) -> dict[str, Any]:
    """:func:`estimate_resources` of an observer-bank sensor: the sensor top ``generate`` builds
    (parallel bank -> features [+ u/y taps] [-> warp] -> core; ``isqrt_every``: its root register
    spacing, None: the default), :func:`bank_resources` added to the core's figures (``bank``: the
    bank's own)."""
    spacing = {} if isqrt_every is None else {"isqrt_every": isqrt_every}
    from pwas_hdl.hdl import design_info

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if hasattr(bm, "taps"):
            from pwas_hdl.hdl.observer_tap_sensor_top import build_tapped_observer_sensor

            comp = build_tapped_observer_sensor(bm, memory=memory, pipeline=pipeline, **spacing)
        else:
            from pwas_hdl.hdl.observer_sensor_top import build_observer_sensor

            comp = build_observer_sensor(bm, memory=memory, pipeline=pipeline, **spacing)
        info = design_info(comp)
    warped = getattr(bm.core, "warps", None) is not None
    warp_adder = _warp_adder_bits(bm.core) if warped else 0
    # registers = the front end's (the top's minus its core's: one elaboration of the whole top per
    # bank format) + the core's (the core alone, cached per core shape as a plain core's)
    from pwas_hdl.hdl.core import PWASCore

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        alone = PWASCore(comp.core.params, memory=memory, pipeline=pipeline)
    alone._MustUse__silence = True  # elaborated only when its shape is not cached yet
    core_regs = _cached_register_bits(alone)
    key = _front_register_key(comp, bm)
    if key is not None and key in _REGISTER_BITS:
        _REGISTER_BITS.move_to_end(key)
        front = _REGISTER_BITS[key]
    else:
        whole = _design_register_bits(comp, [comp.core])
        front = None if whole is None or core_regs is None else whole - core_regs
        if key is not None:
            _REGISTER_BITS[key] = front
            while len(_REGISTER_BITS) > _REGISTER_BITS_MAX:
                _REGISTER_BITS.popitem(last=False)
    regs = None if front is None or core_regs is None else front + core_regs
    bank = bank_resources(bm)
    res = _core_estimate(info, regs, warp_adder + bank["adder_bits"])
    bank_mult = bank["constant_mult_bit_products"] + bank["square_bit_products"]
    res["mult_bit_products"] += bank_mult
    res["logic_bits"] += bank_mult
    res["total_bits"] += bank_mult
    res["dsp18"] += bank["dsp18"]
    res["core_multipliers"] = res["multipliers"]
    res["multipliers"] += bank["squarers"]  # the general multipliers (the constant ones are in bank)
    res["bank"] = bank
    if warped:
        res.update(core_input_bits=int(info["arithmetic"]["in_width"]), warp_adder_bits=warp_adder)
    return res


_MEASURED_KEYS = ("luts", "ffs", "carry", "dsp", "bram", "bram_bits", "lutram", "memory_bits", "multipliers_rtl",
                  "logic_cells", "fmax_mhz", "runtime_s")


# ------------------------------------------------------------------------------------ sweep
def _label(p: dict) -> str:
    """``in s<B_in>.<F> / w s<B_w>.<Fw> / out s<B_out>.<Fo>``; a warped model's input reads ``s<B_in> -> u s<W>.<F>``
    (the input code, then the warped code of the core and its fraction bits); an observer-bank point
    ends with ``/ states s<B_s>.<F_s> coef .<F_c>``."""
    if p.get("core_input_bits") is not None:
        inp = f"s{p['input_bits']} -> u s{p['core_input_bits']}.{p['input_frac']}"
    else:
        inp = f"s{p['input_bits']}.{p['input_frac']}"
    lab = f"in {inp} / w s{p['weight_bits']}.{p['weight_frac']} / out s{p['output_bits']}.{p['output_frac']}"
    if p.get("bank") is not None:  # an observer bank's states and coefficients
        bk = p["bank"]
        lab += f" / states s{bk['state_bits']}.{bk['state_frac']} coef .{bk['coef_frac']}"
    return lab


def _batch_se(diff: np.ndarray, blocks: int = 20) -> np.ndarray:
    """Standard error of the mean of ``diff`` (m, d) per column, by batch means.

    The rows are averaged over ``blocks`` contiguous blocks (at least 25 rows each), so that the
    autocorrelation of a time series within a block is accounted for; the standard error is the
    standard deviation of the block means over ``sqrt(blocks)``. Zeros (d,) when fewer than two
    blocks of 25 rows exist.
    """
    k = min(blocks, diff.shape[0] // 25)
    if k < 2:
        return np.zeros(diff.shape[1])
    means = np.stack([b.mean(axis=0) for b in np.array_split(diff, k, axis=0)])
    return np.std(means, axis=0, ddof=1) / math.sqrt(k)


def _paired_se(e_a: np.ndarray, e_b: np.ndarray, blocks: int = 20) -> np.ndarray:
    """Standard error (per target) of ``RMSEE(a) - RMSEE(b)`` measured on the same samples.

    Batch means (:func:`_batch_se`) of the per-sample differences ``e_a^2 - e_b^2`` give the
    standard error of the MSE difference, turned into RMSEE units by the delta method
    (``/ (2 RMSEE(b))``).
    """
    rm = np.sqrt(np.mean(e_b**2, axis=0))
    return _batch_se(e_a**2 - e_b**2, blocks) / (2 * np.where(rm > 0, rm, 1.0))


def _paired_rate_se(wrong_a: np.ndarray, wrong_b: np.ndarray, blocks: int = 20) -> float:
    """Standard error of ``error_rate(a) - error_rate(b)`` measured on the same samples.

    Parameters
    ----------
    wrong_a, wrong_b : numpy.ndarray, shape (m,)
        1.0 where decision ``a`` (``b``) misclassifies the sample, else 0.0.

    Returns
    -------
    float
        Batch means (:func:`_batch_se`) of the per-sample differences ``wrong_a - wrong_b``
        (a fraction of the samples, as the error rates).
    """
    return float(_batch_se((np.asarray(wrong_a, float) - np.asarray(wrong_b, float))[:, None], blocks)[0])


def _kind_fields(fxm, kind: str) -> dict:
    """The point's fields that only an additive or a warped model has (nothing for a plain model).

    Additive: ``part_frac`` (``F_i`` of each part; the point's ``input_frac`` is ``F = max F_i``,
    the alignment of the sum). Warped: ``core_input_bits`` (``W``, the width of the warped code
    ``u`` the core takes; ``input_bits`` is ``B_in``, the circuit's input code, and ``input_frac``
    the core's ``F``: one core cell is ``2**F`` codes of ``u``). Observer bank (``fxm`` its
    :class:`~pwas_hdl.fixedpoint.observer_bank.ObserverBankSensorModel`): ``bank``, the bank's
    formats (``input_frac`` ``F_in`` of the u / y codes, ``input_headroom`` ``H``, ``state_bits``
    ``B_s``, ``state_frac`` ``F_s``, ``coef_frac`` ``F_c``, ``state_bits_needed``,
    ``state_may_saturate``), and ``core_input_bits`` when its core is warped."""
    if kind == "observer-bank":
        b = fxm.bank
        out: dict[str, Any] = {"bank": {"input_frac": int(b.input_frac), "input_headroom": float(b.input_headroom),
                                        "state_bits": int(b.formats.state_bits), "state_frac": int(b.state_frac),
                                        "coef_frac": int(b.coef_frac), "state_bits_needed": int(b.state_bits_needed),
                                        "state_may_saturate": bool(b.state_may_saturate)}}
        if getattr(fxm.core, "warps", None) is not None:
            out["core_input_bits"] = int(fxm.core.warps[0].width)
        return out
    if kind == "additive":
        return {"part_frac": [int(p.F) for p in fxm.parts]}
    if kind == "warped":
        return {"core_input_bits": int(fxm.warps[0].width)}
    return {}


def _evaluate(fxm: FixedPointModel, xi, z, zf, zf_rmsee) -> tuple[dict, np.ndarray]:
    """Accuracy of a feed-forward point on the regressors ``xi`` (m, n): :func:`_accuracy`."""
    zb, flags = fxm.predict(xi, return_flags=True)
    return _accuracy(fxm, zb, flags, fxm.reference(fxm.quantize_inputs(xi)), z, zf, zf_rmsee)


def _evaluate_recurrent(fxm: FixedPointModel, sensor: PWASVirtualSensor, rdata: dict, zf_rmsee) -> tuple[dict, np.ndarray]:
    """Accuracy of a recurrent point: the bit-true recurrence of each trajectory from reset
    (:meth:`RecurrentFixedPointModel.run_many <pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel.run_many>`,
    what the recurrent top computes), against the reference and the float recurrence; the per-step bound is checked at the
    regressor codes the recurrence itself produced (the fed-back ones included).

    Raises
    ------
    InputError
        The recurrent top cannot take these formats (:func:`~pwas_hdl.design.recurrent.recurrent_model`).
    """
    from pwas_hdl.design.recurrent import recurrent_model

    rm = recurrent_model(sensor, fxm)
    outs, flags, refs = [], [], []
    runs = rm.run_many([rm.quantize_signals(u, y) for u, y in rdata["trajectories"]])  # lockstep when there are many
    for run, keep in zip(runs, rdata["keep"]):
        outs.append(run["out"][keep])
        flags.append(run["out_of_range"][keep])
        refs.append(fxm.reference(run["regressor"][keep]))
    zb = fxm.to_physical_output(np.concatenate(outs))
    return _accuracy(fxm, zb, np.concatenate(flags), np.concatenate(refs), rdata["z"], rdata["float"], zf_rmsee)


def bank_bittrue(bm, trajectories: Sequence[tuple]) -> list[dict[str, np.ndarray]]:
    """The bit-true observer-bank sensor on each trajectory from reset: what the sensor top computes.

    Parameters
    ----------
    bm : ObserverBankSensorModel or TappedObserverBankSensorModel
        The bit-true model (:func:`pwas_hdl.fixedpoint.observer_bank.observer_bank_model`).
    trajectories : sequence of (u, y)
        Physical signals of each trajectory: ``u`` (T_i, nu) or None, ``y`` (T_i, 1).

    Returns
    -------
    list of dict
        Per trajectory: ``codes`` (T_i, nu + 1) the input codes
        (:meth:`~pwas_hdl.fixedpoint.observer_bank.ObserverBankSensorModel.quantize_signals`),
        ``out`` (T_i - first_output, nz) the output codes and ``out_of_range`` (T_i - first_output,)
        of samples ``first_output ..`` (:meth:`~pwas_hdl.fixedpoint.observer_bank.ObserverBankSensorModel.trace`),
        ``state_saturated`` (T_i - first_output,) a state of the bank saturated in that sample's update.
    """
    runs = []
    for u, y in trajectories:
        codes, _ = bm.quantize_signals(u, y)
        tr = bm.trace(codes)
        runs.append({"codes": codes, "out": tr["out"], "out_of_range": tr["out_of_range"],
                     "state_saturated": np.asarray(tr["state_saturated"])[bm.first_output:]})
    return runs


def _evaluate_observer_bank(bm, bdata: dict, zf_rmsee: np.ndarray, refs: dict) -> tuple[dict, np.ndarray]:
    """Accuracy of an observer-bank point: :func:`bank_bittrue` on each trajectory of ``bdata``
    (:func:`_bank_data`) against its reference and the float sensor; the deviation from the float
    sensor at the represented signals (:meth:`~pwas_hdl.fixedpoint.observer_bank.ObserverBankSensorModel.reference`)
    is checked against the sensor's bound (``bm.error_bound``: the core's plus the features' and
    taps' through the map's slopes; it holds unless a state saturates: ``state_saturated`` counts
    those samples).

    Parameters
    ----------
    bm : ObserverBankSensorModel
        The point's bit-true model.
    bdata : dict
        :func:`_bank_data`.
    zf_rmsee : numpy.ndarray, shape (nz,)
        The float sensor's RMSEE.
    refs : dict
        Cache of the float sensor at the represented signals, by the input codes' format (filled here).

    Returns
    -------
    (dict, numpy.ndarray)
        The accuracy fields of :func:`_accuracy` plus ``state_saturated``, and the errors (m, nz).
    """
    runs = bank_bittrue(bm, bdata["trajectories"])
    key = (bm.bank.input_bits, bm.bank.input_headroom)  # the represented signals depend on these only
    if key not in refs:
        refs[key] = np.concatenate([bm.reference(r["codes"]) for r in runs])
    zb = bm.core.to_physical_output(np.concatenate([r["out"] for r in runs]))
    flags = np.concatenate([r["out_of_range"] for r in runs])
    acc, err = _accuracy(bm.core, zb, flags, refs[key], bdata["z"], bdata["float"], zf_rmsee, np.asarray(bm.error_bound))
    acc["state_saturated"] = int(np.concatenate([r["state_saturated"] for r in runs]).sum())
    return acc, err


def _accuracy(fxm: FixedPointModel, zb, flags, ref, z, zf, zf_rmsee, bound: np.ndarray | None = None) -> tuple[dict, np.ndarray]:
    """A point's accuracy fields and its errors ``zb - z`` (m, nz): ``zb`` the bit-true estimates,
    ``flags`` (m,) out of the domain, ``ref`` (m, nz) the float model at the codes the circuit saw,
    ``z`` the reference, ``zf`` the float sensor's estimates, ``zf_rmsee`` (nz,) its RMSEE, ``bound``
    (nz,) a per-target error bound in physical units (default the core's, :func:`_precision`)."""
    err = zb - z
    rmsee = np.sqrt(np.mean(err**2, axis=0))
    ratio = float(np.mean(rmsee / np.where(zf_rmsee > 0, zf_rmsee, np.finfo(float).tiny)))
    acc = {
        "rmsee": [float(v) for v in rmsee],
        "rmsee_ratio": ratio,
        "rmsee_ratio_se": float(np.mean(_paired_se(err, zf - z) / np.where(zf_rmsee > 0, zf_rmsee, 1.0))),
        **_precision(fxm, zb, flags, ref, zf, bound),
    }
    return acc, err


def _precision(fxm: FixedPointModel, zb, flags, ref, zf, bound: np.ndarray | None = None) -> dict:
    """The deviation fields of a point (module notes): ``zb`` (m, nz) the bit-true outputs
    (physical units), ``flags`` (m,) out of the domain, ``ref`` (m, nz) the float model at the
    codes the circuit saw, ``zf`` (m, nz) the float model at the unquantised regressors.

    ``bound`` (nz,), physical units: a per-target bound of ``|zb - ref|`` other than the core's
    (an observer-bank sensor's, which adds the features' errors); ``error_bound`` is then its
    largest entry and ``bound_holds`` checks each target against its own."""
    lsb = fxm.output_format.lsb
    dev = zb - zf
    dref = float(np.max(np.abs(zb - ref))) / lsb
    if bound is not None:
        b = np.asarray(bound, dtype=float)
        worst = np.max(np.abs(zb - ref), axis=0) if zb.shape[0] else np.zeros(b.shape)
        return {
            "rms_dev_float": [float(v) for v in np.sqrt(np.mean(dev**2, axis=0))],
            "max_dev_float": [float(v) for v in np.max(np.abs(dev), axis=0)],
            "max_dev_float_lsb": float(np.max(np.abs(dev)) / lsb),
            "max_dev_reference_lsb": dref,
            "error_bound_lsb": float(b.max() / lsb),
            "error_bound": float(b.max()),
            "bound_holds": bool(np.all(worst <= b * (1 + 1e-12))),
            "flagged": int(flags.sum()),
        }
    return {
        "rms_dev_float": [float(v) for v in np.sqrt(np.mean(dev**2, axis=0))],
        "max_dev_float": [float(v) for v in np.max(np.abs(dev), axis=0)],
        "max_dev_float_lsb": float(np.max(np.abs(dev)) / lsb),
        "max_dev_reference_lsb": dref,
        "error_bound_lsb": float(fxm.error_bound_lsb),
        "error_bound": float(fxm.error_bound),
        "bound_holds": bool(dref <= fxm.error_bound_lsb * (1 + 1e-12)),
        "flagged": int(flags.sum()),
    }


def _classifier_reference(sensor: PWASVirtualSensor, xi: np.ndarray, z: np.ndarray) -> dict:
    """The float classifier on the sweep's data: what every point is compared with.

    Parameters
    ----------
    sensor : PWASVirtualSensor
        A classifier (``sensor.classifier_``).
    xi : numpy.ndarray, shape (m, n)
        Physical regressors.
    z : numpy.ndarray, shape (m, 1)
        The true class labels (:func:`_regressors_and_reference`).

    Returns
    -------
    dict
        ``classes`` (C,), ``truth`` (m,) the true labels, ``scores`` (m, C) the float scores,
        ``decided`` (m,) the float classifier's labels (:func:`pwas_hdl.fit.classifier.decide`),
        ``wrong`` (m,) 1.0 where it misclassifies, ``error_rate`` and ``errors``.
    """
    from pwas_hdl.fit.classifier import decide

    classes = np.asarray(sensor.classifier_["classes"], dtype=float)
    truth = np.asarray(z, dtype=float)[:, 0]
    scores = sensor.predict_regressors(xi)
    decided = decide(scores, classes)
    wrong = (decided != truth).astype(float)
    return {"classes": classes, "truth": truth, "scores": scores, "decided": decided, "wrong": wrong,
            "error_rate": float(wrong.mean()), "errors": int(wrong.sum())}


def _evaluate_classifier(fxm: FixedPointModel, xi: np.ndarray, cref: dict) -> tuple[dict, np.ndarray]:
    """Accuracy of a classifier point on the regressors ``xi`` (m, n): its decisions and its scores.

    The decision is the hardware's: :func:`pwas_hdl.fixedpoint.argmax.argmax_index` of the bit-true
    output codes (the argmax stage's compare tree, ties to the lowest class index), against the true
    labels and the float classifier of ``cref`` (:func:`_classifier_reference`). The scores get the
    deviation fields of a sensor point (:func:`_precision`).

    Returns
    -------
    (dict, numpy.ndarray)
        The accuracy fields: ``error_rate`` (fraction of the samples whose bit-true class is not the
        true one), ``errors`` (their count), ``error_rate_se`` (standard error of ``error_rate`` minus
        the float classifier's, paired batch means), ``disagreement`` / ``disagreements`` (bit-true
        class differs from the float classifier's at the unquantised regressors),
        ``disagreement_at_codes``, ``near_ties`` and ``differ_outside_margin`` (against the float
        classifier at the represented inputs, :func:`pwas_hdl.fixedpoint.argmax.agreement`: a
        difference outside the ``2 error_bound`` margin would break the bound; 0 whenever
        ``bound_holds``), then :func:`_precision`'s. And ``wrong`` (m,): 1.0 where the bit-true
        class is wrong.
    """
    from pwas_hdl.fixedpoint.argmax import agreement, argmax_index

    q, sat = fxm.quantize_inputs(xi, return_saturated=True)
    codes, oor = fxm.evaluate(q)
    zb = fxm.to_physical_output(codes)
    ref = fxm.reference(q)
    decided = cref["classes"][argmax_index(codes)]
    wrong = (decided != cref["truth"]).astype(float)
    differ = decided != cref["decided"]
    at_codes = agreement(ref, codes, fxm.error_bound)
    acc = {
        "error_rate": float(wrong.mean()),
        "errors": int(wrong.sum()),
        "error_rate_se": _paired_rate_se(wrong, cref["wrong"]),
        "disagreement": float(differ.mean()),
        "disagreements": int(differ.sum()),
        "disagreement_at_codes": at_codes["differ"] / at_codes["samples"],
        "near_ties": at_codes["near_ties"],
        "differ_outside_margin": at_codes["differ_outside_margin"],
        **_precision(fxm, zb, oor | sat, ref, cref["scores"]),
    }
    return acc, wrong


def explore(
    model: PWASVirtualSensor | str | os.PathLike,
    data: str | os.PathLike | Table | tuple,
    *,
    traj_col: str | None = None,
    input_bits: Sequence[int] = DEFAULT_INPUT_BITS,
    weight_frac: Sequence[int] | None = None,
    output_frac: Sequence[int] | None = None,
    weight_bits: int | None = None,
    output_bits: int | None = None,
    input_fill: float = 0.9,
    rounding: str = "half_up",
    overflow: str = "error",
    memory: str = "banked",
    pipeline: str | None = None,
    resources: str = "estimate",
    cost: str = "total_bits",
    device: str | None = None,
    measure_max: int | None = None,
    workdir: str | os.PathLike | None = None,
    progress: Progress | None = None,
    executor: "Executor | None" = None,
    blank_rows: str = "error",
    state_frac: Sequence[int] | None = None,
    coef_frac: Sequence[int] | None = None,
    state_bits: int | None = None,
    input_headroom: float | None = None,
    isqrt_every: int | None = None,
) -> dict[str, Any]:
    """Sweep the fixed-point formats of a model and measure accuracy against resources.

    Parameters
    ----------
    model : PWASVirtualSensor or path of a model file
        A plain, additive (fit ``--additive``) or power-of-two non-uniform (fit ``--breakpoints
        quantile-pow2``) or recurrent (fit ``--mz``) sensor, an observer-bank sensor (fit
        ``--front-end observer-bank``, with or without ``--mu/--my`` taps, uniform or power-of-two:
        the bank, the features and the core from reset on each trajectory, module notes), or a
        classifier (fit ``--classify``, plain, additive or power-of-two non-uniform: scored by its
        error rate, module notes).
    data : path of a CSV, :class:`~pwas_hdl.io.csv_table.Table`, or tuple ``(u, y, z)``
        The evaluation data. From a CSV/Table the model's input/output columns are read (by
        name) and the reference of target ``t`` is column ``t_true`` if present, else ``t`` (a
        classifier's: the true class in column ``<label>_true`` or ``<label>``).
        A tuple gives arrays (or lists of trajectories) ``u``, ``y`` as for
        :meth:`PWASVirtualSensor.predict` and the reference ``z`` sample by sample (a
        classifier's: the true labels, shape ``(T,)``; the first ``M - 1`` samples of each
        trajectory have no regressor and are skipped).
    traj_col : str, optional
        Trajectory column of the CSV, as for ``fit``.
    input_bits : sequence of int
        Input code widths ``B_in``, bits (default 8, 10, 12, 14, 16).
    weight_frac, output_frac : sequence of int, optional
        Absolute fraction bits ``Fw`` / ``Fo``; default: the defaults of ``generate`` -7 .. +2
        (:data:`DEFAULT_FRAC_OFFSETS`).
    weight_bits, output_bits : int, optional
        Fixed widths (default: the fewest bits for each point; with a fixed ``weight_bits``
        points whose weights do not fit are refused unless ``overflow="saturate"``).
    input_fill, rounding, overflow : as :class:`~pwas_hdl.fixedpoint.bittrue.FixedPointModel`, fixed.
    memory, pipeline : as :func:`pwas_hdl.design.generate.build_design`.
    resources : {"estimate", "generic", "ecp5", "ice40"}
        Estimate only, or also synthesise the Pareto points and the default (see module notes).
    cost : str
        Estimate key used as the cost axis of the front (:data:`COST_KEYS`, default ``total_bits``).
    device : str, optional
        FPGA device for ``ecp5`` / ``ice40`` (checked before the sweep, as ``synth`` checks it).
    measure_max : int, optional
        With measured resources, synthesise at most this many Pareto points (evenly spread along
        the front, both ends kept), plus the default (default :data:`DEFAULT_MEASURE_MAX`).
    workdir : path, optional
        Where the synthesised designs go (kept); default a temporary folder, removed afterwards.
        ``device``, ``measure_max`` and ``workdir`` are about the synthesis: with
        ``resources="estimate"`` they are refused (``ValueError``) rather than ignored.
    progress : callable(stage, done, total), optional
        Called as the sweep and the synthesis runs progress.
    blank_rows : {"error", "break"}
        A blank row in a CSV ``data`` file: an error, or the end of a trajectory
        (:func:`pwas_hdl.io.csv_table.read_csv`).
    executor : pwas_hdl.flow.executor.Executor, optional
        Runs the synthesis of the measured points (one task per point): serially by default, or
        on a local or remote Dask cluster. The result does not depend on it.
    state_frac, coef_frac : sequence of int, optional
        Observer-bank sensors: fraction bits ``F_s`` of the observer states / ``F_c`` of the observer
        coefficients to sweep as well (default: not swept, ``generate``'s default at each input
        width, from the noise budget; :class:`~pwas_hdl.fixedpoint.observer_bank.FixedPointObserverBank`).
    state_bits : int, optional
        Observer-bank sensors: a fixed state width ``B_s`` (default: the width of the state bound;
        fewer bits may saturate, counted in ``state_saturated``).
    input_headroom : float, optional
        Observer-bank sensors: a fixed input head room ``H`` (normalised units, default 8).
        ``state_frac``, ``coef_frac``, ``state_bits`` and ``input_headroom`` are refused for
        other models (as ``generate`` refuses them).
    isqrt_every : int, optional
        Observer-bank sensors with the 11b map: the square root's register spacing of every point
        (``generate --isqrt-every``; default 3): its registers count in the estimate and the
        latency, and ``resources`` other than ``estimate`` build the points with it. A point whose
        root it leaves without a register is refused (as ``generate`` refuses it); other models refuse it.

    Returns
    -------
    dict
        JSON-ready: ``format``, ``version``, ``model`` (``classifier``: None, or the label, the
        classes and the tie rule), ``data``, ``float`` (RMSEE of the float model; a classifier's:
        its ``error_rate`` and ``errors``), ``sweep``, ``resource_model`` (``objectives``: ``cost``
        and ``rmsee_ratio``, a classifier's ``error_rate``), ``points`` (each with its formats,
        accuracy, ``resources``, ``cost``, ``on_front``, ``is_default``, ``label``), ``refused``,
        ``pareto`` (indices into ``points``, by cost), ``default`` (index, on_front, and the
        points dominating it with the margins), ``measured`` (None for the estimate). Valid
        under :func:`check_result`.

    Raises
    ------
    InputError
        Empty sweep, non-integer widths, unknown resource mode or cost key, unknown column,
        missing target column (a classifier's: its class label column), data without a full
        regressor (an observer-bank sensor: a trajectory with no estimated sample); a bank
        format option for a model without an observer bank, or breakpoints whose cells are not
        power-of-two multiples of one step.
    ToolMissing
        Synthesis was asked for and a synthesis tool is not installed.
    ToolFailed, InputError
        Synthesis was asked for and every synthesis run failed (the message quotes the first error).
    """
    if resources not in RESOURCE_MODES:
        raise InputError(f"--fpga / resources must be one of {', '.join(RESOURCE_MODES)}, got {resources!r}")
    if cost not in COST_KEYS:
        raise InputError(f"--cost must be one of {', '.join(COST_KEYS)}, got {cost!r}")
    if memory not in ("banked", "replicated"):
        raise InputError(f"--memory (memory) must be 'banked' or 'replicated' (explore does not sweep the corner memory), "
                         f"got {memory!r}")
    if overflow not in ("error", "saturate"):  # refused up front, not as the reason of every refused point
        raise InputError(choice_text(option_text("overflow"), ("error", "saturate"), overflow))
    if measure_max is not None and (isinstance(measure_max, bool) or not isinstance(measure_max, (int, np.integer)) or measure_max < 1):
        raise InputError(f"--measure-max (measure_max) must be an integer >= 1, got {measure_max!r}")
    if resources == "estimate":  # the synthesis options mean nothing without synthesis: refused, not ignored
        given = [opt for opt, v in (("--device", device), ("--measure-max", measure_max), ("--synth-dir", workdir)) if v is not None]
        if given:
            one = len(given) == 1
            families = "ecp5|ice40" if "--device" in given else "ecp5|ice40|generic"  # generic has no device
            raise InputError(f"{', '.join(given)} {'needs' if one else 'need'} --fpga {families} ({'it is' if one else 'they are'} "
                             f"about the synthesis of the Pareto points); add --fpga or drop {'it' if one else 'them'} for the analytic estimate only")
    elif device is not None:
        if resources == "generic":
            raise InputError("--device needs --fpga ecp5 or ice40 (the generic target has no device); drop it or choose the family")
        from pwas_hdl.flow.synthesis import check_device

        check_device(resources, device)  # an unknown device refused before the sweep, as synth refuses it
    if measure_max is None:
        measure_max = DEFAULT_MEASURE_MAX
    if workdir is not None:
        check_output_path(workdir, "--synth-dir", kind="folder")
    from pwas_hdl.design.generate import fixed_point_model  # the bit-true model generate builds (additive, warped, plain)

    sensor, model_path = _load_sensor(model)
    _check_supported(sensor, {"state_frac": state_frac, "coef_frac": coef_frac, "state_bits": state_bits,
                              "input_headroom": input_headroom})
    from pwas_hdl.hdl.serial_observer_bank import check_isqrt_every_option

    check_isqrt_every_option(isqrt_every, _is_bank(sensor))
    in_bits = _int_values(input_bits, "input_bits", lo=2)
    fixed_wb = None if weight_bits is None else _int_values(weight_bits, "weight_bits", lo=1)[0]
    fixed_ob = None if output_bits is None else _int_values(output_bits, "output_bits", lo=1)[0]
    bank = _is_bank(sensor)  # observer bank -> features [+ taps] -> core: its own model, data and resources
    # the bank's formats: F_s and F_c swept (None: generate's default at each input width), B_s and H fixed
    sfs = _int_values(state_frac, "state_frac") if state_frac is not None else [None]
    cfs = _int_values(coef_frac, "coef_frac") if coef_frac is not None else [None]
    fixed_sb = None if state_bits is None else _int_values(state_bits, "state_bits", lo=2)[0]
    if input_headroom is not None and (isinstance(input_headroom, bool) or not isinstance(input_headroom, (int, float))
                                       or not math.isfinite(input_headroom) or input_headroom <= 0):
        raise InputError(f"{_option('input_headroom')} must be a positive number, got {input_headroom!r}")
    recurrent = not bank and sensor.lags_ is not None and sensor.lags_.recurrent  # the accuracy is the closed loop's
    if bank:
        from pwas_hdl.fixedpoint.observer_bank import observer_bank_model
        from pwas_hdl.hdl.serial_observer_bank import check_root_spacing

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bank_dflt = observer_bank_model(sensor, memory=memory, input_fill=input_fill, rounding=rounding)
        bdata = _bank_data(sensor, bank_dflt.first_output, data, traj_col, blank_rows)
        xi, z, zf, data_desc = None, bdata["z"], bdata["float"], bdata["desc"]
        bank_refs: dict = {}
    elif recurrent:
        rdata = _recurrent_data(sensor, data, traj_col, blank_rows)
        xi, z, zf, data_desc = None, rdata["z"], rdata["float"], rdata["desc"]
    else:
        xi, z, data_desc = _regressors_and_reference(sensor, data, traj_col, blank_rows)
    tgts = sensor.signal_names()[2]
    classifier = getattr(sensor, "classifier_", None)  # its accuracy: the error rate of the bit-true argmax
    acc_key = "error_rate" if classifier is not None else "rmsee_ratio"  # the accuracy objective of the front

    # ---- the defaults of generate (input_bits=12, everything else from the data)
    common = {"input_fill": input_fill, "rounding": rounding, "overflow": overflow, "layout": memory}
    fmt_common = {"input_fill": input_fill, "rounding": rounding, "overflow": overflow}
    if bank:
        dflt = bank_dflt.core
        kind = model_kind(bank_dflt)
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            dflt = fixed_point_model(sensor, memory=memory, input_fill=input_fill, rounding=rounding)
        kind = model_kind(dflt)
    fw0, fo0 = dflt.weight_format.frac, dflt.output_format.frac
    default_key = (dflt.input_bits, fw0, fo0, None, None)
    fws = _int_values(weight_frac, "weight_frac") if weight_frac is not None else [fw0 + d for d in DEFAULT_FRAC_OFFSETS]
    fos = _int_values(output_frac, "output_frac") if output_frac is not None else [fo0 + d for d in DEFAULT_FRAC_OFFSETS]
    check_limit("the number of format combinations", len(in_bits) * len(fws) * len(fos) * len(sfs) * len(cfs),
                MAX_SWEEP_POINTS, "sweep fewer input widths or fraction bits")
    combos = [(b, fw, fo, sf, cf, False) for b in in_bits for fw in fws for fo in fos for sf in sfs for cf in cfs]
    default_in_sweep = (fixed_wb is None and fixed_ob is None and fixed_sb is None and input_headroom is None
                        and (*default_key, False) in combos)
    if default_in_sweep:
        combos[combos.index((*default_key, False))] = (*default_key, True)
    else:  # evaluated all the same, with the default widths, so that it can be compared
        combos.append((*default_key, True))

    # ---- float reference (a recurrent sensor's: its float recurrence, from _recurrent_data; a
    # classifier's: the float classifier's decisions against the true labels)
    if classifier is not None:
        cref = _classifier_reference(sensor, xi, z)
    elif not recurrent and not bank:
        zf = sensor.predict_regressors(xi)
    if classifier is None:
        zf_rmsee = np.sqrt(np.mean((zf - z) ** 2, axis=0))

    points: list[dict] = []
    refused: list[dict] = []
    errors: dict[int, np.ndarray] = {}
    total = len(combos)
    for i, (b, fw, fo, sf, cf, is_default) in enumerate(combos):
        given = {"input_bits": b, "weight_frac": fw, "output_frac": fo}
        if not is_default:
            given.update(weight_bits=fixed_wb, output_bits=fixed_ob)
        bank_given = {}
        if bank:
            bank_given = {"state_frac": sf, "coef_frac": cf}
            if not is_default:
                bank_given.update(state_bits=fixed_sb, input_headroom=input_headroom)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                if bank:
                    bm = observer_bank_model(sensor, memory=memory, **fmt_common, **given, **bank_given)
                    check_root_spacing(bm.bank, isqrt_every)  # a root left without a register: refused, as generate
                    fxm = bm.core
                else:
                    fxm = fixed_point_model(sensor, memory=memory, **fmt_common, **given)
            if recurrent:  # the feedback's requantisation may refuse the formats too
                acc, err = _evaluate_recurrent(fxm, sensor, rdata, zf_rmsee)
        except InputError as exc:  # a combination the formats refuse (anything else is a bug: raised)
            refused.append({**{k: v for k, v in given.items()}, **{k: v for k, v in bank_given.items() if v is not None},
                            "reason": str(exc)})
            if progress:
                progress("sweep", i + 1, total)
            continue
        if bank:
            acc, err = _evaluate_observer_bank(bm, bdata, zf_rmsee, bank_refs)
        elif classifier is not None:
            acc, err = _evaluate_classifier(fxm, xi, cref)
        elif not recurrent:
            acc, err = _evaluate(fxm, xi, z, zf, zf_rmsee)
        res = estimate_resources(bm if bank else fxm, memory, pipeline, classifier=classifier, isqrt_every=isqrt_every)
        pt = {
            "input_bits": fxm.input_bits,
            "input_frac": fxm.F,
            "weight_bits": fxm.weight_format.bits,
            "weight_frac": fxm.weight_format.frac,
            "output_bits": fxm.output_format.bits,
            "output_frac": fxm.output_format.frac,
            "shift": fxm.shift,
            "weight_offset": fxm.weight_format.frac - fw0,
            "output_offset": fxm.output_format.frac - fo0,
            "weights_saturated": fxm.n_weights_saturated,
            "output_may_saturate": fxm.output_may_saturate,
            "warnings": [str(w.message) for w in caught],
            **_kind_fields(bm if bank else fxm, kind),
            **acc,
            "resources": res,
            "is_default": bool(is_default),
        }
        pt["label"] = _label(pt)
        pt["cost"] = pt["resources"][cost]
        errors[len(points)] = err
        points.append(pt)
        if progress:
            progress("sweep", i + 1, total)
    requested = [p for p in points if default_in_sweep or not p["is_default"]]
    if not requested:  # the default alone (evaluated for comparison) is not what was asked for
        raise InputError(
            f"every requested combination of the sweep ({total - (0 if default_in_sweep else 1)}) was refused; "
            "first reason: " + (refused[0]["reason"] if refused else "none")
        )
    if cost == "register_bits" and any(p["cost"] is None for p in points):
        raise InputError("register bits are not available with this Amaranth version; choose another cost")

    front = pareto_front(points, ("cost", acc_key))
    for k, p in enumerate(points):
        p["on_front"] = k in front
    di = next(k for k, p in enumerate(points) if p["is_default"])
    default = _default_summary(points, errors, di, front, acc_key)

    result: dict[str, Any] = {
        "format": EXPLORE_FORMAT,
        "version": EXPLORE_VERSION,
        "generator": {"pwas_hdl": __version__},
        "model": {
            "path": model_path,
            "kind": kind,
            "n": int(sensor.grid_.n),
            "N": int(sensor.grid_.n_vertices),
            "partitions": [int(v) for v in sensor.grid_.partitions],
            "regressors": list(dflt.regressor_names),
            "targets": list(tgts),
            "train_rmse": [float(v) for v in np.ravel(getattr(sensor, "train_rmse_", []))],
            "recurrence": ({"Mz": int(sensor.lags_.mz), "lead": int(getattr(sensor, "lead_", 0)),
                            "accuracy": "the bit-true recurrence from reset on each trajectory (closed loop)"}
                           if recurrent else None),
            "observer_bank": (None if not bank else
                              {"n_models": int(bank_dflt.bank.n_models), "order": int(bank_dflt.bank.order),
                               "window": int(bank_dflt.bank.window), "feature_map": str(bank_dflt.bank.feature_map),
                               "observer": str(bank_dflt.bank.front_end.observer),
                               "taps": [f"{n}[t-{lag}]" if lag else f"{n}[t]" for n, lag in
                                        ((bank_dflt.bank.signal_names[sg], lg) for sg, lg in bank_dflt.taps.dims)]
                                       if hasattr(bank_dflt, "taps") else [],
                               "warped": getattr(bank_dflt.core, "warps", None) is not None,
                               "first_output_sample": int(bank_dflt.first_output),
                               "accuracy": "the bit-true bank, features and core from reset on each trajectory; the "
                                           "estimate of sample k >= first_output_sample against row k of the trajectory"}),
            "classifier": (None if classifier is None else
                           {"target": str(classifier["target"]), "classes": [float(c) for c in classifier["classes"]],
                            "tie_rule": TIE_RULE,
                            "accuracy": "the class index of the bit-true argmax of the output codes against the true "
                                        "label; error_rate = fraction of the samples misclassified"}),
        },
        "data": data_desc,
        "float": ({"rmsee": [float(v) for v in zf_rmsee], "rmsee_ratio": 1.0} if classifier is None
                  else {"error_rate": cref["error_rate"], "errors": cref["errors"]}),
        "sweep": {
            "input_bits": in_bits,
            "weight_frac": fws,
            "output_frac": fos,
            "weight_bits": fixed_wb,
            "output_bits": fixed_ob,
            "input_fill": input_fill,
            "rounding": rounding,
            "overflow": overflow,
            "memory": memory,
            "pipeline": pipeline,
            "default_weight_frac": fw0,
            "default_output_frac": fo0,
            "default_in_sweep": default_in_sweep,
            "combinations": total,
            **({"state_frac": [v for v in sfs if v is not None] or None, "coef_frac": [v for v in cfs if v is not None] or None,
                "state_bits": fixed_sb, "input_headroom": None if input_headroom is None else float(input_headroom),
                "isqrt_every": isqrt_every}
               if bank else {}),
        },
        "resource_model": {
            "mode": resources,
            "cost": cost,
            "objectives": ["cost", acc_key],
            "definition": _COST_DEFINITION,
        },
        "points": points,
        "refused": refused,
        "pareto": front,
        "default": default,
        "measured": None,
    }
    if resources != "estimate":
        if len(front) <= measure_max:
            pick = list(front)
        elif measure_max == 1:
            pick = [front[0]]
        else:
            pick = [front[round(i * (len(front) - 1) / (measure_max - 1))] for i in range(measure_max)]
        result["measured"] = _measure(sensor, points, sorted(set(pick) | {di}), resources, device, workdir, memory,
                                      pipeline, common, progress, executor, acc_key, bank, isqrt_every)
    errs = result_errors(result)
    if errs:  # the owner writes what its schema says (a bug otherwise, as the manifest's builder checks)
        raise InternalError(f"the explore result breaks its schema {EXPLORE_SCHEMA}: {errs[0]}")
    return result


_COST_DEFINITION = {
    "memory_bits": "weight memory words x word bits (exact, the generator's memory plan)",
    "register_bits": "flip-flops of the elaborated core (width of the sync-domain signals; exact before optimisation)",
    "mult_bit_products": "(n+1) nz (F+1) B_w partial-product bits of the mu x w multipliers",
    "adder_bits": "2n(B_in+1) + n(n-1)/2 (F+1) + n(F+2) + nz n (F+B_w+1) + nz (F+B_w+1)",
    "logic_bits": "mult_bit_products + adder_bits",
    "total_bits": "memory_bits + logic_bits + register_bits (a stored bit, a flip-flop, a partial-product bit and an adder bit count alike)",
    "dsp18": "(n+1) nz ceil((F+2)/18) ceil(B_w/18) 18x18 multiplier blocks",
    "bram18k": "18-kbit block RAMs, best aspect ratio (16k x 1 .. 512 x 36) per bank",
}


def _default_summary(points: list[dict], errors: dict[int, np.ndarray], di: int, front: list[int],
                     acc_key: str = "rmsee_ratio") -> dict:
    """Is the default on the front? If not, the points dominating it and by how much.

    Parameters
    ----------
    points : list of dict
        The sweep's points (``cost``, ``on_front``, ``label`` and the accuracy fields).
    errors : dict of int to numpy.ndarray
        Per point: a sensor's errors ``(m, nz)`` (estimate minus reference, physical units), a
        classifier's misclassifications ``(m,)`` (1.0 where the bit-true class is wrong).
    di : int
        Index of the default point.
    front : list of int
        The Pareto front (indices into ``points``).
    acc_key : {"rmsee_ratio", "error_rate"}
        The accuracy objective of the front: a sensor's or a classifier's.

    Returns
    -------
    dict
        ``index``, ``label``, ``on_front``, ``dominated_by`` (largest saving first: ``index``,
        ``label``, ``cost_saved``, ``cost_saved_rel`` and, for a sensor, ``rmsee_better`` (per
        target, physical units), ``rmsee_better_rel`` (of ``rmsee_ratio``), ``rmsee_diff_se``; for a
        classifier ``error_rate_better`` (a fraction of the samples) and ``error_rate_diff_se``) and,
        when dominated, ``max_cost_saved_rel`` and ``max_rmsee_gain_rel`` / ``max_error_rate_gain``.
    """
    d = points[di]
    out: dict[str, Any] = {"index": di, "label": d["label"], "on_front": d["on_front"], "dominated_by": []}
    if d["on_front"]:
        return out
    ed = errors[di]
    for k in front:
        p = points[k]
        if p["cost"] <= d["cost"] and p[acc_key] <= d[acc_key]:
            entry = {
                "index": k,
                "label": p["label"],
                "cost_saved": d["cost"] - p["cost"],
                "cost_saved_rel": (d["cost"] - p["cost"]) / d["cost"] if d["cost"] else 0.0,
            }
            if acc_key == "error_rate":
                entry["error_rate_better"] = d["error_rate"] - p["error_rate"]
                entry["error_rate_diff_se"] = _paired_rate_se(errors[k], ed)
            else:
                entry["rmsee_better"] = [a - b for a, b in zip(d["rmsee"], p["rmsee"])]
                entry["rmsee_better_rel"] = d["rmsee_ratio"] - p["rmsee_ratio"]
                entry["rmsee_diff_se"] = [float(v) for v in _paired_se(errors[k], ed)]
            out["dominated_by"].append(entry)
    out["dominated_by"].sort(key=lambda e: -e["cost_saved"])
    if out["dominated_by"]:
        dom = out["dominated_by"]
        out["max_cost_saved_rel"] = max(e["cost_saved_rel"] for e in dom)
        if acc_key == "error_rate":
            out["max_error_rate_gain"] = max(e["error_rate_better"] for e in dom)
        else:
            out["max_rmsee_gain_rel"] = max(e["rmsee_better_rel"] for e in dom)
    return out


def _measure_point(task: dict) -> dict:
    """One design point: generate the core and synthesise it (a pure task for :class:`Executor`).

    ``task`` holds the sensor, the point's formats, the synthesis target/device, the folder to
    build in (``None``: a private temporary folder, removed) and the common options. Returns
    ``{"measured": {...}}`` or ``{"error": "..."}`` for a point that could not be built.
    """
    from pwas_hdl.design.generate import build_design, write_folder
    from pwas_hdl.flow.synthesis import synthesize

    p, common = task["point"], task["common"]
    own = task["folder"] is None
    root = make_temp_dir(tempfile.gettempdir(), "pwas-explore") if own else Path(task["folder"])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bank_formats = task.get("bank_formats")  # an observer-bank sensor: its sensor top (no core design)
            gd = build_design(task["sensor"], design="core" if bank_formats is None else "sensor", memory=task["memory"],
                              pipeline=task["pipeline"], input_bits=p["input_bits"], input_fill=common["input_fill"],
                              weight_bits=p["weight_bits"], weight_frac=p["weight_frac"],
                              output_bits=p["output_bits"], output_frac=p["output_frac"],
                              overflow=common["overflow"], rounding=common["rounding"], **(bank_formats or {}))
        folder = write_folder(gd.files, root / "design" if own else root)
        res = synthesize(folder, task["target"], device=task["device"])
    except (ToolMissing, ToolFailed, InputError, OSError) as exc:  # not a bug: noted, the sweep goes on (a bug: TaskFailed)
        return {"error": str(exc), "error_kind": _error_kind(exc)}
    finally:
        if own:
            shutil.rmtree(root, ignore_errors=True)
    m = {key: res.get(key) for key in _MEASURED_KEYS}
    m["manifest_memory_bits"] = int(gd.manifest["memory"]["bits"])
    m["estimate_memory_bits_exact"] = m["manifest_memory_bits"] == p["resources"]["memory_bits"]
    return {"measured": m}


def _error_kind(exc: Exception) -> dict:
    """What the caller needs to raise the same kind of error again (tasks return plain, picklable dicts)."""
    if isinstance(exc, ToolMissing):
        return {"class": "ToolMissing", "tool": exc.tool, "hint": exc.hint}
    if isinstance(exc, ToolFailed):
        return {"class": "ToolFailed", "log": exc.log, "tail": exc.tail}
    return {"class": "InputError"}


def _measure(sensor, points, idx, target, device, workdir, memory, pipeline, common, progress, executor=None,
             acc_key: str = "rmsee_ratio", bank: bool = False, isqrt_every: int | None = None) -> dict:
    """Synthesise the points ``idx`` (:func:`_measure_point`, one task each) and the front of the
    synthesised points in (LUTs, DSPs, block RAMs, ``acc_key``: ``rmsee_ratio``, or a classifier's
    ``error_rate``). ``bank``: an observer-bank sensor, whose design is the sensor top (bank,
    features, core) with the point's bank formats (and the root register spacing ``isqrt_every``)."""
    from pwas_hdl.flow.executor import Executor

    root = None if workdir is None else Path(workdir)
    if root is not None:
        root.mkdir(parents=True, exist_ok=True)
    done: dict[str, Any] = {"target": target, "device": device, "points": [], "workdir": None if root is None else str(root)}
    tasks, labels = [], []
    for k in idx:
        p = points[k]
        name = f"i{p['input_bits']}_w{p['weight_bits']}f{p['weight_frac']}_o{p['output_bits']}f{p['output_frac']}"
        bank_formats = None
        if bank:  # the sensor top with the bank's formats of the point (all of them: the default ones too)
            bk = p["bank"]
            bank_formats = {"state_bits": bk["state_bits"], "state_frac": bk["state_frac"], "coef_frac": bk["coef_frac"],
                            "input_headroom": bk["input_headroom"],
                            **({} if isqrt_every is None else {"isqrt_every": isqrt_every})}
            name += f"_s{bk['state_bits']}f{bk['state_frac']}_c{bk['coef_frac']}"
        name = name.replace("-", "m")
        tasks.append({"sensor": sensor, "point": p, "target": target, "device": device, "memory": memory, "pipeline": pipeline,
                      "common": common, "folder": None if root is None else str(root / name), "bank_formats": bank_formats})
        labels.append(p["label"])
    ex = executor if executor is not None else Executor()
    results = ex.map(_measure_point, tasks, labels=labels, return_exceptions=True,
                     progress=(lambda d, t: progress("synthesis", d, t)) if progress else None)
    errors: list[str] = []
    kinds: list[dict] = []
    for k, r in zip(idx, results):
        p = points[k]
        if not isinstance(r, dict):  # TaskFailed: the task raised twice (a bug or a lost worker)
            r = {"error": str(r), "error_kind": {"class": "TaskFailed"}}
        if "error" in r:
            kinds.append(r["error_kind"])
            errors.append(f"{p['label']}: {r['error']}")
            p["measured"] = {"error": r["error"]}
            continue
        p["measured"] = r["measured"]
        done["points"].append(k)
    if not done["points"]:
        first = kinds[0] if kinds else {"class": "none"}
        if first["class"] == "ToolMissing":
            raise ToolMissing(first["tool"], first["hint"])
        msg = "synthesis failed for every point; first error: " + (errors[0] if errors else "none was run")
        if first["class"] == "ToolFailed":
            raise ToolFailed(msg.removesuffix(f"; log: {first['log']}"), first["log"], first["tail"])
        if first["class"] == "InputError":
            raise InputError(msg)
        raise RuntimeError(msg)  # a task that failed twice: a bug or a lost worker (exit 3 with the traceback)
    done["errors"] = errors
    ok = [k for k in done["points"] if all(isinstance(points[k]["measured"].get(key), (int, float)) for key in ("luts", "dsp", "bram"))]
    objs = [[points[k]["measured"][key] for key in ("luts", "dsp", "bram")] + [points[k][acc_key]] for k in ok]
    done["objectives"] = ["luts", "dsp", "bram", acc_key]
    done["pareto"] = [ok[i] for i in pareto_front(objs)] if ok else []
    di = next((k for k in idx if points[k]["is_default"]), None)
    done["default_on_front"] = (di in done["pareto"]) if di in ok else None
    return done


# ------------------------------------------------------------------------------------ reports
def _is_classifier_result(result: dict) -> bool:
    """True for the result of a classifier's sweep (accuracy: the error rate of the bit-true argmax)."""
    return (result.get("model") or {}).get("classifier") is not None


def format_table(result: dict, rows: str = "pareto") -> str:
    """A Markdown table of the Pareto points (``rows="pareto"``, plus the default) or of all points.

    Parameters
    ----------
    result : dict
        What :func:`explore` returns.
    rows : {"pareto", "all"}
        The Pareto points and the default (``"pareto"``), or every point (anything else).

    Returns
    -------
    str
        The table (costs in bits, RMSEE in the targets' physical units, max deviation in output LSB).
        A classifier's table has, instead of the RMSEE columns, the error rate of the bit-true
        decisions (percent of the samples, and their count), its difference to the float
        classifier's (percentage points) and the share of decisions that differ from the float
        classifier's (percent).
    """
    pts = result["points"]
    idx = list(result["pareto"]) if rows == "pareto" else list(range(len(pts)))
    di = result["default"]["index"]
    if di not in idx:
        idx.append(di)
    tg = result["model"]["targets"]
    clf = _is_classifier_result(result)
    meas = result.get("measured") is not None
    if clf:
        acc_head = ["error rate", "vs float (pp)", "differs from float"]
    else:
        acc_head = [f"RMSEE {tg[0]}" if len(tg) == 1 else "RMSEE / float", "vs float", "RMS dev. float"]
    head = ["formats (in / weights / out)", "cost", "memory bits", "logic bits", "FFs", *acc_head, "max dev. (LSB)", "front"]
    if meas:
        head[-1:-1] = ["LUT (meas.)", "FF (meas.)", "DSP", "BRAM"]
        head.append("meas. front")
        mfront = set(result["measured"].get("pareto", []))
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for k in idx:
        p = pts[k]
        r = p["resources"]
        if clf:
            acc = [f"{100 * p['error_rate']:.3f} % ({p['errors']})",
                   f"{100 * (p['error_rate'] - result['float']['error_rate']):+.3f}",
                   f"{100 * p['disagreement']:.3f} %"]
        else:
            acc = [f"{p['rmsee'][0]:.4g}" if len(tg) == 1 else f"{p['rmsee_ratio']:.5f}",
                   f"{(p['rmsee_ratio'] - 1) * 100:+.3f} %", ", ".join(f"{v:.3g}" for v in p["rms_dev_float"])]
        row = [
            p["label"].replace("in ", "").replace("w ", "").replace("out ", "") + (" **(default)**" if p["is_default"] else ""),
            f"{p['cost']}", f"{r['memory_bits']}", f"{r['logic_bits']}", f"{r['register_bits']}", *acc,
            f"{p['max_dev_float_lsb']:.3g}", "yes" if p["on_front"] else "no",
        ]
        if meas:
            m = p.get("measured") or {}
            row[-1:-1] = [str(m.get("luts", "")), str(m.get("ffs", "")), str(m.get("dsp", "")), str(m.get("bram", ""))]
            row.append(("yes" if k in mfront else "no") if "luts" in m else "")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def default_verdict(result: dict) -> str:
    """One sentence on the default formats: on the Pareto front, or which point dominates it by how much.

    Parameters
    ----------
    result : dict
        What :func:`explore` returns.

    Returns
    -------
    str
        ``"on the Pareto front"``, or ``"NOT on the Pareto front: <label> costs x % less with ..."``
        and the accuracy margin with its standard error: the RMSEE of a sensor (physical units), the
        error rate of a classifier (percentage points of the samples).
    """
    d = result["default"]
    if d["on_front"]:
        return "on the Pareto front"
    b = d["dominated_by"][0]
    if _is_classifier_result(result):
        if b["error_rate_better"] == 0:  # the same decisions wrong: an error count, no gain to state
            better = "the same error rate"
        else:
            better = (f"an error rate {100 * b['error_rate_better']:+.4g} percentage points better "
                      f"(standard error {100 * b['error_rate_diff_se']:.2g})")
    else:
        better = f"an RMSEE {b['rmsee_better'][0]:+.4g} better (standard error {b['rmsee_diff_se'][0]:.2g})"
    return f"NOT on the Pareto front: {b['label']} costs {100 * b['cost_saved_rel']:.1f} % less with {better}"


def plot_exploration(result: dict, png_path: str | os.PathLike, *, title: str | None = None) -> Path:
    """Draw an exploration result as a PNG (written atomically).

    Left: accuracy, ``RMSEE / float RMSEE - 1`` in percent (symmetric-log axis; 0 = the float
    model, dashed) of every point against the cost, coloured by input width; the Pareto front as a
    staircase through its points (black edges, with +-1 standard error of their paired RMSEE
    difference to the float model); the default of ``generate`` as a red star. Right: precision,
    the RMS deviation of the bit-true estimate from the float model (log axis), same points and
    marks. With measured resources a third panel plots the same accuracy against the measured LUTs
    of the synthesised points, annotated with DSP and block-RAM counts. A classifier's accuracy
    is its error rate minus the float classifier's, in percentage points of the samples (the
    standard errors of the paired difference), its precision the RMS deviation of the scores.

    Parameters
    ----------
    result : dict
        What :func:`explore` returns.
    png_path : str or os.PathLike
        The PNG file to write.
    title : str, optional
        The figure's title; default: the model's ``n``, ``N``, the samples and the point counts.

    Returns
    -------
    Path
        Where the PNG was written.

    Raises
    ------
    InputError
        The result has no points.
    """
    import io

    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from pwas_hdl.io.atomic import atomic_write_bytes

    pts = result["points"]
    if not pts:
        raise InputError("the result has no points to plot (every combination of the sweep was refused); sweep other word lengths")
    meas = result.get("measured")
    ncol = 3 if meas else 2
    fig, axes = plt.subplots(1, ncol, figsize=(6.4 * ncol, 6.2), layout="constrained")
    bits = sorted({p["input_bits"] for p in pts})
    cmap = plt.get_cmap("viridis")
    color = {b: cmap(0.92 * i / max(len(bits) - 1, 1)) for i, b in enumerate(bits)}
    cost_key = result["resource_model"]["cost"]
    front = list(result["pareto"])
    di = result["default"]["index"]
    dpt = pts[di]
    clf = _is_classifier_result(result)
    if clf:  # percentage points of the samples above the float classifier's error rate
        fer = result["float"]["error_rate"]
        excess = np.array([(p["error_rate"] - fer) * 100 for p in pts])
        se = np.array([p.get("error_rate_se", 0.0) * 100 for p in pts])
        acc_label = "bit-true error rate above the float classifier's (percentage points)"
        front_label = "Pareto front (cost, error rate)"
    else:
        excess = np.array([(p["rmsee_ratio"] - 1) * 100 for p in pts])
        se = np.array([p.get("rmsee_ratio_se", 0.0) * 100 for p in pts])
        acc_label = "bit-true RMSEE above the float model's (%)"
        front_label = "Pareto front (cost, RMSEE)"
    dev = np.array([float(np.sqrt(np.mean(np.square(p["rms_dev_float"])))) for p in pts])
    cost = np.array([p["cost"] for p in pts], dtype=float)
    nz_abs = np.abs(excess[excess != 0])
    lin = float(max(1e-3, np.min(nz_abs))) if nz_abs.size else 1e-3
    lin = float(10 ** np.floor(np.log10(max(lin, float(np.median(se)) if se.size else lin))))
    tg = result["model"]["targets"]
    flt = (f"float classifier (error rate {100 * result['float']['error_rate']:.4g} %)" if clf
           else "float model (RMSEE " + ", ".join(f"{v:.4g}" for v in result["float"]["rmsee"]) + ")")
    dlabel = "generate default: " + dpt["label"] + (" (on the front)" if dpt["on_front"] else " (dominated)")

    def scatter(ax, y, errs=None):
        for b in bits:
            sel = [k for k, p in enumerate(pts) if p["input_bits"] == b and not p["on_front"]]
            ax.scatter(cost[sel], y[sel], s=13, color=color[b], alpha=0.5, linewidths=0)
            fr = [k for k in front if pts[k]["input_bits"] == b]
            ax.scatter(cost[fr], y[fr], s=46, color=color[b], edgecolors="black", linewidths=0.9, zorder=3,
                       label=f"B_in = {b}" + (" (front: black edge)" if b == bits[0] else ""))
            if errs is not None and fr:
                ax.errorbar(cost[fr], y[fr], yerr=errs[fr], fmt="none", ecolor="black", elinewidth=0.7, capsize=2, zorder=2)
        ax.scatter([cost[di]], [y[di]], marker="*", s=280, color="red", edgecolors="black", linewidths=0.8, zorder=4,
                   label=dlabel)
        ax.set_xlabel(f"cost: {cost_key.replace('_', ' ')} (estimate)")
        ax.grid(True, which="both", alpha=0.3)
        # top axis: the weight width of each column of points (the memory dominates the cost)
        groups: dict[int, list[float]] = {}
        for k, p in enumerate(pts):
            groups.setdefault(p["weight_bits"], []).append(cost[k])
        if len(groups) > 1:
            top = ax.twiny()
            top.set_xlim(ax.get_xlim())
            top.set_xticks([float(np.median(v)) for v in groups.values()])
            top.set_xticklabels([str(b) for b in groups], fontsize=7)
            top.set_xlabel("weight width B_w (bits), at the median cost of its points", fontsize=8)

    ax = axes[0]
    scatter(ax, excess, se)
    ax.step(cost[front], excess[front], where="post", color="black", lw=1.0, zorder=2, label=front_label)
    ax.set_yscale("symlog", linthresh=lin)
    ax.axhline(0.0, color="tab:blue", ls="--", lw=1.2, label=flt)
    ax.set_ylabel(acc_label)
    against = ", ".join(result["data"].get("reference_columns") or ([result["model"]["classifier"]["target"]] if clf else tg))
    ax.set_title(("accuracy: misclassification rate against " if clf else "accuracy: RMSEE against ") + against, fontsize=10)
    handles, labels = ax.get_legend_handles_labels()

    ax = axes[1]
    scatter(ax, dev)
    ax.set_yscale("log")
    ax.set_ylabel("RMS |bit-true - float| of the scores" if clf else "RMS |bit-true - float| (physical units)")
    ax.set_title("precision: deviation from the float model" + (" (class scores)" if clf else ""), fontsize=10)

    if meas:
        ax = axes[2]
        mk = [k for k in meas["points"] if isinstance((pts[k].get("measured") or {}).get("luts"), (int, float))]
        for k in mk:
            p, m = pts[k], pts[k]["measured"]
            star = k == di
            ax.scatter([m["luts"]], [excess[k]], s=260 if star else 50, marker="*" if star else "o",
                       color="red" if star else color[p["input_bits"]], edgecolors="black", zorder=3)
            ax.annotate(f"w{p['weight_bits']} DSP {m.get('dsp')} BRAM {m.get('bram')}", (m["luts"], excess[k]),
                        textcoords="offset points", xytext=(5, 3), fontsize=6)
        mf = sorted(meas.get("pareto", []), key=lambda k: pts[k]["measured"]["luts"])
        if mf:
            ax.step([pts[k]["measured"]["luts"] for k in mf], excess[mf], where="post", color="black", lw=1.0, zorder=2)
        ax.set_yscale("symlog", linthresh=lin)
        ax.axhline(0.0, color="tab:blue", ls="--", lw=1.2)
        ax.set_xlabel(f"measured LUTs ({meas['target']}{', ' + meas['device'] if meas.get('device') else ''})")
        ax.set_ylabel(acc_label)
        ax.set_title("synthesised: Pareto points and the default\n(line: their own front in LUTs, DSPs, BRAMs, "
                     + ("error rate)" if clf else "RMSEE)"), fontsize=9)
        ax.grid(True, which="both", alpha=0.3)

    fig.suptitle(title or f"bit-width exploration: n = {result['model']['n']}, N = {result['model']['N']}, "
                 f"{result['data']['samples']} samples; {len(pts)} formats, {len(front)} on the front", fontsize=11)
    note = ("error bars: +-1 standard error of the " + ("error-rate difference to the float classifier" if clf else
                                                         "RMSEE difference to the float model") + " (batch means)")
    dd = result["default"]
    if not dd["on_front"] and dd.get("dominated_by"):
        best = dd["dominated_by"][0]
        note += f". Default dominated, e.g. by {best['label']}: {100 * best['cost_saved_rel']:.0f} % less cost, "
        note += (f"error rate {100 * best['error_rate_better']:+.3g} points better (+-{100 * best['error_rate_diff_se']:.2g})"
                 if clf else f"RMSEE {best['rmsee_better'][0]:+.3g} better (+-{best['rmsee_diff_se'][0]:.2g})")
    leg = fig.legend(handles, labels, loc="outside lower center", ncol=4, fontsize=8, frameon=False, title=note,
                     title_fontsize=7.5)
    leg.get_title().set_color("dimgray")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return atomic_write_bytes(png_path, buf.getvalue())
