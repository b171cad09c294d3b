"""Small synthetic PWAS designs for the RTL tests (no fitting: a model file written directly).

:func:`synthetic_model` returns a fitted :class:`~pwas_hdl.fit.virtual_sensor.PWASVirtualSensor`
built with ``from_dict``: an explicit domain, random weights of a chosen scale and a stated
"training RMSE" (which sets the default weight/output LSBs, pwas_hdl.fixedpoint.bittrue.default_weight_frac).
:class:`DesignConfig` names one hardware configuration (model + ``generate`` options) and
:meth:`DesignConfig.generate` writes its folder.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

__all__ = ["synthetic_model", "DesignConfig"]


def synthetic_model(mu: int, my: int, nu: int, ny: int, partitions: Sequence[int] | int, nz: int = 1, *,
                    seed: int = 0, weight_scale: float | None = None, rmse: float | None = None,
                    classes: Sequence[float] | None = None, ties: bool = False, additive: str | None = None):
    """A PWAS virtual sensor with lags ``(Mu, My)`` of ``nu`` inputs / ``ny`` outputs.

    ``partitions``: one integer, or one per regressor dimension (for the sensor top all lags of a
    signal need the same value). Lags of one signal share their domain (as ``fit`` does by default).

    ``classes``: make it a classifier (:mod:`pwas_hdl.fit.classifier`) of a label ``mode`` with these
    ``nz`` classes (score targets ``mode=<label>``). ``ties``: force equal scores -- score 1 has the
    weights of score 0 everywhere and score 3 those of score 2 on every other vertex -- so that the
    output codes tie often and the argmax tie rule (lowest index) is exercised.

    ``additive``: an additive sensor (``fit --additive``: ``time``, ``pairs``, ``triples``,
    ``"0,1;1,2"``), with random weights on every part.
    """
    from pwas_hdl.fit.regressors import LagStructure
    from pwas_hdl.fit.model_file import MODEL_FORMAT, MODEL_SCHEMA_ID, MODEL_VERSION, model_from_dict

    rng = np.random.default_rng(seed)
    lags = LagStructure(mu, my, nu if mu else 0, ny if my else 0)
    ins = [f"u{i}" for i in range(nu)] if mu else []
    outs = [f"y{i}" for i in range(ny)] if my else []
    if classes is not None:
        from pwas_hdl.fit.classifier import class_target_names

        if len(classes) != nz:
            raise ValueError(f"{len(classes)} classes for nz = {nz}")
        tgts = class_target_names("mode", classes)
    else:
        tgts = [f"z{i}" for i in range(nz)]
    n = lags.dimension
    parts = [int(partitions)] * n if np.ndim(partitions) == 0 else [int(p) for p in partitions]
    if len(parts) != n:
        raise ValueError(f"{len(parts)} partitions for n = {n}")
    sig_dom = {}
    lo, hi = [], []
    for kind, ch, _lag in lags.signal_of_dimension():
        key = (kind, ch)
        if key not in sig_dom:
            a = float(rng.uniform(-20, 5))
            sig_dom[key] = (a, a + float(rng.uniform(0.5, 40)))
        lo.append(sig_dom[key][0])
        hi.append(sig_dom[key][1])
    subsets = [tuple(range(n))]
    if additive is not None:
        from pwas_hdl.fit.additive import parse_additive

        subsets = list(parse_additive(additive, lags.signal_of_dimension()))
    scale = weight_scale if weight_scale is not None else float(10.0 ** rng.uniform(-1, 2))
    weights = {t: [] for t in tgts}
    for sub in subsets:
        sp = [parts[j] for j in sub]
        n_v = int(np.prod([p + 1 for p in sp]))
        # a smooth part plus noise, so that neighbouring weights are related but not equal
        coords = np.stack(np.unravel_index(np.arange(n_v), [p + 1 for p in sp]), axis=1) / np.maximum(sp, 1)
        for t in range(nz):
            smooth = np.sin(coords @ rng.normal(0, 2, len(sp)) + rng.uniform(0, 6))
            weights[tgts[t]] += (scale * (smooth + 0.3 * rng.normal(0, 1, n_v))).tolist()
    if ties:
        if nz < 2:
            raise ValueError("ties need nz >= 2")
        weights[tgts[1]] = list(weights[tgts[0]])
        if nz >= 4:
            weights[tgts[3]] = [a if v % 2 == 0 else b for v, (a, b) in enumerate(zip(weights[tgts[2]], weights[tgts[3]]))]
    r = rmse if rmse is not None else scale / 20
    d = {
        "$schema": MODEL_SCHEMA_ID,
        "format": MODEL_FORMAT,
        "version": MODEL_VERSION,
        "signals": {"inputs": ins, "outputs": outs, "targets": tgts},
        "lags": {"Mu": mu, "My": my},
        "regressors": lags.names(ins, outs),
        "grid": {"lo": lo, "hi": hi, "partitions": parts},
        "weights": weights,
        "fit": {"sigma": 1e-3, "sigma_given": True, "tikhonov_order": 0, "gamma": 1.2, "domain_from": "explicit",
                "share_lag_domain": True, "n_train": 0, "n_trajectories": 1, "train_rmse": {t: r for t in tgts}, "cv": None},
    }
    if classes is not None:
        d["classifier"] = {"target": "mode", "classes": [float(c) for c in classes]}
    if additive is not None:
        d["additive"] = {"spec": additive, "parts": [list(s) for s in subsets]}
    return model_from_dict(d, source="synthetic model")


@dataclass(frozen=True)
class DesignConfig:
    """One hardware configuration: the model (lags, partitions, nz, seed) and ``generate`` options."""

    name: str
    design: str  # "core" or "sensor"
    mu: int
    my: int
    nu: int
    ny: int
    partitions: Any
    nz: int = 1
    options: dict = field(default_factory=dict, hash=False)
    seed: int = 0
    classes: tuple = ()  # a classifier of these nz classes (argmax stage after the core)
    ties: bool = False  # force tied scores (see synthetic_model)
    additive: str | None = None  # an additive sensor (fit --additive), e.g. "pairs"

    @property
    def n(self) -> int:
        return self.nu * self.mu + self.ny * self.my

    def model(self):
        return synthetic_model(self.mu, self.my, self.nu, self.ny, self.partitions, self.nz, seed=self.seed,
                               classes=self.classes or None, ties=self.ties,
                               additive=self.additive)

    def generate(self, outdir: str | Path):
        """Write the design folder (``pwas_hdl.design.generate.generate``); returns the GeneratedDesign."""
        import warnings

        from pwas_hdl.design.generate import generate

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # deliberate saturation in some configurations
            return generate(self.model(), outdir, design=self.design, **self.options)


#: The fixed configurations of the RTL tests (``tests/test_rtl_cocotb.py``: every one on Icarus, those of
#: :data:`VERILATOR_RTL_CONFIGS` on Verilator too) and of ``benchmarks/rtl_random_configs.py --named``
#: (every one on the simulator chosen): n = 1..6, cores and sensor tops, 1 and 2 targets, the memories,
#: pipeline presets, goals and opt-in registers, input, weight and output formats, port names and
#: ``$readmemh`` weights.
RTL_CONFIGS = [
    # name, design, Mu, My, nu, ny, partitions, nz, generate options
    DesignConfig("c-n1-p5", "core", 0, 1, 0, 1, [5], 1, {}),
    DesignConfig("c-n1-p8-z2-repl-min-b8", "core", 0, 1, 0, 1, [8], 2, {"memory": "replicated", "pipeline": "min", "input_bits": 8}),
    DesignConfig("c-n2-p4x3-max-trunc", "core", 0, 2, 0, 1, [4, 3], 1, {"pipeline": "max", "rounding": "truncate"}),
    DesignConfig("c-n2-p1x1", "core", 0, 2, 0, 1, [1, 1], 1, {"input_bits": 6}),
    DesignConfig("c-n2-p7x7-z2-b10", "core", 0, 2, 0, 1, [7, 7], 2, {"input_bits": 10}),
    DesignConfig("c-n3-p2x3x5-min-fill1", "core", 0, 3, 0, 1, [2, 3, 5], 1, {"pipeline": "min", "input_fill": 1.0}),
    DesignConfig("c-n3-p4x4x4-z2-repl-sat", "core", 0, 3, 0, 1, [4, 4, 4], 2, {"memory": "replicated", "output_bits": 9}),
    DesignConfig("c-n3-p6x2x3-wsat", "core", 0, 3, 0, 1, [6, 2, 3], 1, {"weight_bits": 8, "overflow": "saturate"}),
    DesignConfig("c-n4-p3x1x2x4", "core", 0, 4, 0, 1, [3, 1, 2, 4], 1, {}),
    DesignConfig("c-n4-p8x4x8x2-z2-b14", "core", 0, 4, 0, 1, [8, 4, 8, 2], 2, {"input_bits": 14, "pipeline": "max"}),
    DesignConfig("c-n5-p2x2x2x2x2-z2-trunc-max", "core", 0, 5, 0, 1, [2, 2, 2, 2, 2], 2, {"rounding": "truncate", "pipeline": "max"}),
    DesignConfig("c-n5-p3x1x2x4x2-repl-min-b14", "core", 0, 5, 0, 1, [3, 1, 2, 4, 2], 1, {"memory": "replicated", "pipeline": "min", "input_bits": 14}),
    DesignConfig("c-n6-p2x2x2x2x2x2", "core", 0, 6, 0, 1, [2] * 6, 1, {}),
    DesignConfig("c-n6-p1x2x1x3x2x1-z2-b10-wf", "core", 0, 6, 0, 1, [1, 2, 1, 3, 2, 1], 2, {"input_bits": 10, "weight_frac": 9, "output_frac": 6}),
    DesignConfig("c-n3-p5x3x2-readmemh", "core", 0, 3, 0, 1, [5, 3, 2], 1, {"memory_init": "readmemh"}),
    DesignConfig("c-n4-p2x3x2x3-addr-reg", "core", 0, 4, 0, 1, [2, 3, 2, 3], 1,
                 {"pipeline": {"split": True, "rank": True, "addr": True, "mem_out": True, "product": True, "tree_levels": 1}}),
    DesignConfig("s-y1-p6", "sensor", 0, 1, 0, 1, 6, 1, {}),
    DesignConfig("s-y4-p3", "sensor", 0, 4, 0, 1, 3, 1, {}),
    DesignConfig("s-u2y3-p4-2-z2", "sensor", 2, 3, 1, 1, [4, 4, 2, 2, 2], 2, {}),
    DesignConfig("s-u1y1-nu2-p3-repl-min", "sensor", 1, 1, 2, 1, 3, 1, {"memory": "replicated", "pipeline": "min"}),
    DesignConfig("s-u2y1-ny2-z2-trunc", "sensor", 2, 1, 1, 2, [2, 2, 3, 5], 2, {"rounding": "truncate"}),
    DesignConfig("s-u3y3-p2-max", "sensor", 3, 3, 1, 1, 2, 1, {"pipeline": "max"}),
    DesignConfig("s-y2-ny2-p5x3-b8", "sensor", 0, 2, 0, 2, [5, 3, 5, 3], 1, {"input_bits": 8}),
    DesignConfig("s-u1y2-p8-6-z2-b16", "sensor", 1, 2, 1, 1, [8, 6, 6], 2, {"input_bits": 16}),
    DesignConfig("c-n2-p3x2-amaranth-ports", "core", 0, 2, 0, 1, [3, 2], 1, {"ports": "amaranth"}),
    DesignConfig("c-n3-p8x4x1-exact-scale-b10", "core", 0, 3, 0, 1, [8, 4, 1], 2, {"input_scale": "exact", "input_bits": 10}),
    DesignConfig("s-y2-p8-exact-scale-fill95-max", "sensor", 0, 2, 0, 1, 8, 1, {"input_scale": "exact", "input_fill": 0.95, "pipeline": "max"}),
    DesignConfig("s-y2-p5-amaranth-ports", "sensor", 0, 2, 0, 1, 5, 1, {"ports": "amaranth", "pipeline": "max"}),
    DesignConfig("s-y3-p4-addr-reg-repl", "sensor", 0, 3, 0, 1, 4, 1,
                 {"memory": "replicated", "pipeline": {"split": False, "rank": True, "addr": True, "mem_out": False, "product": False, "tree_levels": 0}}),
    # issue 14: the generate --goal builds (latency = short: min + product; throughput = max, every
    # register incl. mul_in, offset and bank; the max configurations above and the default ones run
    # the new max / balanced presets too), and the offset / bank registers without the others
    DesignConfig("c-n4-p3x2x5x2-goal-throughput", "core", 0, 4, 0, 1, [3, 2, 5, 2], 1, {"goal": "throughput"}),
    DesignConfig("c-n3-p5x2x3-z2-goal-latency", "core", 0, 3, 0, 1, [5, 2, 3], 2, {"goal": "latency"}),
    DesignConfig("c-n3-p3x2x4-z2-max-lut", "core", 0, 3, 0, 1, [3, 2, 4], 2, {"pipeline": "max-lut"}),
    DesignConfig("s-y4-p3-offset-bank", "sensor", 0, 4, 0, 1, 3, 1,
                 {"pipeline": {"split": False, "rank": False, "addr": False, "offset": True, "bank": True, "mem_out": True,
                               "mul_in": False, "product": False, "tree_levels": 2}}),
    # the banked core without the address rotation (bank addresses as bit fields c_j + step, the
    # rotation from the cells' adder tree): p + 1 a power of two in the middle dimensions; latency =
    # mu in the memory cycle; p = 7, n = 3 has a last-dimension field (v // (n+1))
    # (--memory banked: these grids' goal memory is the replicated one, below)
    DesignConfig("c-n4-p3-goal-latency", "core", 0, 4, 0, 1, 3, 1, {"goal": "latency", "memory": "banked"}),
    DesignConfig("c-n3-p7-z2-goal-throughput", "core", 0, 3, 0, 1, 7, 2, {"goal": "throughput"}),
    DesignConfig("c-n3-p7-z2-goal-latency-b10", "core", 0, 3, 0, 1, 7, 2, {"goal": "latency", "input_bits": 10, "memory": "banked"}),
    # the latency build's one-sum adder (flat_sum) with a saturation the weights reach (9-bit
    # outputs: kept by prune_sat), and truncation (no rounding constant in the sum)
    DesignConfig("c-n3-p4x4x4-z2-sat-goal-latency", "core", 0, 3, 0, 1, [4, 4, 4], 2, {"goal": "latency", "output_bits": 9}),
    DesignConfig("c-n2-p5x3-trunc-goal-latency", "core", 0, 2, 0, 1, [5, 3], 1, {"goal": "latency", "rounding": "truncate"}),  # the goal's memory: replicated
    # issue 14, the latency-first front (opt-in, no preset): corner banks (2**n memories addressed by
    # the cells; vertex k's word chosen among its corners after the memory's output register) and the
    # comparators on the input bits with the rotation from residue tables (raw_compare)
    DesignConfig("c-n3-p3x2x4-z2-corner-memout", "core", 0, 3, 0, 1, [3, 2, 4], 2,
                 {"memory": "corner", "pipeline": {"split": False, "rank": False, "addr": False, "mem_out": True, "mul_in": False,
                                                   "product": True, "tree_levels": 0, "mu_late": True}}),
    DesignConfig("s-y3-p3-raw-compare", "sensor", 0, 3, 0, 1, 3, 1,
                 {"pipeline": {"split": False, "rank": False, "addr": False, "mem_out": False, "mul_in": False, "product": True,
                               "tree_levels": 0, "mu_late": True, "raw_compare": True}}),
    # hw14e (opt-in, no preset): the latency build's one sum through column counters (counter_sum)
    DesignConfig("c-n4-p3x2x3x2-z2-counter-sum", "core", 0, 4, 0, 1, [3, 2, 3, 2], 2,
                 {"pipeline": {"split": False, "rank": False, "addr": False, "mem_out": False, "mul_in": True, "product": False,
                               "tree_levels": 0, "mu_late": True, "flat_sum": True, "prune_sat": True, "raw_compare": True,
                               "counter_sum": True}}),
    # hw14h: the latency build with the replicated memory (bit-field vertex addresses, mu after the
    # read; p + 1 = 4, 8 with the first dimension's p = 5 in the top field), and a sensor top
    DesignConfig("c-n3-p5x7x3-z2-repl-goal-latency", "core", 0, 3, 0, 1, [5, 7, 3], 2, {"memory": "replicated", "goal": "latency"}),
    DesignConfig("s-y4-p3-repl-goal-latency", "sensor", 0, 4, 0, 1, 3, 1, {"memory": "replicated", "goal": "latency"}),
    # --goal latency without --memory: the goal's memory (replicated: power-of-two strides, pwas_hdl.design.goal_memory), n = 4
    DesignConfig("c-n4-p3x3x3x7-goal-latency-goal-memory", "core", 0, 4, 0, 1, [3, 3, 3, 7], 1, {"goal": "latency"}),
]


#: The configurations of :data:`RTL_CONFIGS` that the RTL tests also replay on Verilator (a cover of what
#: its 2-state, width-strict simulation could treat differently: n = 1, 2, 3, 4, 6, cores and sensor tops,
#: the replicated and corner memories, ``$readmemh``, Amaranth port names, truncation, weight saturation,
#: the latency build's one-sum adder with ``prune_sat`` and column counters, bit-field addresses). The
#: others run on Verilator in ``benchmarks/rtl_random_configs.py --named --simulator verilator``.
VERILATOR_RTL_CONFIGS = (
    "c-n1-p8-z2-repl-min-b8", "c-n2-p4x3-max-trunc", "c-n3-p5x3x2-readmemh", "c-n3-p3x2x4-z2-corner-memout",
    "c-n6-p1x2x1x3x2x1-z2-b10-wf", "c-n3-p6x2x3-wsat", "s-u1y1-nu2-p3-repl-min", "s-u2y1-ny2-z2-trunc",
    "c-n2-p3x2-amaranth-ports", "c-n3-p4x4x4-z2-sat-goal-latency", "c-n4-p3x2x3x2-z2-counter-sum",
    "c-n3-p7-z2-goal-latency-b10",
)


#: The additive designs of the RTL benches (issue 15; ``tests/test_additive_rtl.py``): a sensor top with
#: the sliding-pair parts (y[t-2], y[t-1]) and (y[t-1], y[t]) behind one lag bank,
#: and a core with parts of 1 to 3 dimensions, two targets, the deepest pipeline and truncation, whose
#: 1-dimensional part has a coarser fraction (F_i < F: its accumulator is shifted before the sum).
ADDITIVE_CONFIGS = [
    DesignConfig("a-s-y3-pairs", "sensor", 0, 3, 0, 1, 3, 1, {}, seed=1, additive="pairs"),
    DesignConfig("a-c-n4-z2-max-trunc", "core", 0, 4, 0, 1, [3, 2, 4, 2], 2, {"pipeline": "max", "rounding": "truncate"},
                 seed=2, additive="2;0,1;1,2,3;0,3"),
    # additive classifiers: the argmax stage after the sum (forced ties: score 1 equals score 0)
    DesignConfig("a-s-y3-pairs-cls3-ties", "sensor", 0, 3, 0, 1, 3, 3, {}, seed=3, classes=(0, 1, 2), ties=True,
                 additive="pairs"),
    DesignConfig("a-c-n4-cls2-max", "core", 0, 4, 0, 1, [3, 2, 4, 2], 2, {"pipeline": "max"}, seed=4, classes=(-1, 1),
                 additive="2;0,1;1,2,3;0,3"),
]


#: The additive designs on the serial architecture (``generate --architecture serial``:
#: ``tests/test_additive_serial.py``): the serial versions of the two additive regressions above
#: (equal parts behind a lag bank; parts of 1 to 3 dimensions, an aligned part, two targets, the
#: deepest pipeline), and a sensor top with a 1- and a 3-dimensional part (II 4, the 1-dimensional
#: part's sum waits 2 cycles in its output register) on the shallowest pipeline.
ADDITIVE_SERIAL_CONFIGS = [
    DesignConfig("as-s-y3-pairs", "sensor", 0, 3, 0, 1, 3, 1, {"architecture": "serial"}, seed=1, additive="pairs"),
    DesignConfig("as-c-n4-z2-max-trunc", "core", 0, 4, 0, 1, [3, 2, 4, 2], 2,
                 {"pipeline": "max", "rounding": "truncate", "architecture": "serial"}, seed=2, additive="2;0,1;1,2,3;0,3"),
    DesignConfig("as-s-u2y2-1+3-min", "sensor", 2, 2, 1, 1, 3, 1, {"pipeline": "min", "architecture": "serial"}, seed=5,
                 additive="0;1,2,3"),
]

#: Classifiers on the serial architecture (``generate --architecture serial`` of a ``fit --classify``
#: model: ``tests/test_serial_classifier.py``): the argmax stage after the serial core or the serial
#: additive sum. The serial versions of ``tests/test_rtl_classifier.py``'s tie-forcing core (nz = 4,
#: pipeline ``max``: 2 argmax registers behind the serial output register) and of the additive
#: classifiers of :data:`ADDITIVE_CONFIGS` (a core with parts of 1 to 3 dimensions, ``max``), plus a
#: sensor top on the ``min`` pipeline (the index combinational from the serial core's output register)
#: with parts of 1 and 3 dimensions (II 4) and forced ties.
CLASSIFIER_SERIAL_CONFIGS = [
    DesignConfig("cs-c-n2-nz4-ties-max", "core", 0, 2, 0, 1, [4, 3], 4, {"pipeline": "max", "architecture": "serial"}, seed=5,
                 classes=(1, 2, 3, 4), ties=True),
    DesignConfig("acs-c-n4-cls2-max", "core", 0, 4, 0, 1, [3, 2, 4, 2], 2, {"pipeline": "max", "architecture": "serial"}, seed=4,
                 classes=(-1, 1), additive="2;0,1;1,2,3;0,3"),
    DesignConfig("acs-s-u2y2-1+3-cls3-ties-min", "sensor", 2, 2, 1, 1, 3, 3, {"pipeline": "min", "architecture": "serial"},
                 seed=6, classes=(0, 1, 2), ties=True, additive="0;1,2,3"),
]

#: Serial-architecture configurations (``generate --architecture serial``, issue 15 item 2): the
#: serial versions of two configurations of ``tests/test_rtl_cocotb.py`` (same model, same
#: options), so their parallel twins are byte-identical to those and share the cached simulator
#: builds: a core with two targets and a saturating output (``c-n3-p4x4x4-z2-repl-sat``), and a
#: sensor top with lag bank, warm-up and the deepest pipeline (``s-u3y3-p2-max``, n = 6, II = 7).
SERIAL_CONFIGS = [
    DesignConfig("serial-c-n3-p4x4x4-z2-sat", "core", 0, 3, 0, 1, [4, 4, 4], 2,
                 {"output_bits": 9, "architecture": "serial"}),
    DesignConfig("serial-s-u3y3-p2-max", "sensor", 3, 3, 1, 1, 2, 1, {"pipeline": "max", "architecture": "serial"}),
]

#: Options of the parallel twin of a serial configuration that the serial design refuses (its one memory
#: of N words takes no ``memory``): with them the twin is the ``tests/test_rtl_cocotb.py`` configuration.
SERIAL_TWIN_OPTIONS = {"serial-c-n3-p4x4x4-z2-sat": {"memory": "replicated"}}
