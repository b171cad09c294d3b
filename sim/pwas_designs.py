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
