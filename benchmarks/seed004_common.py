"""Shared parts of the seed-004 benches (pv_benchmark.py, switching4.py, battery.py).

Masti, Bernardini, Bemporad (EJC 2021). Every number of a run comes from fresh data (seed = run
index): excitation, parameter law and noise differ between runs, as in Section 4.1 ("ten different
runs, each one involving different realizations of all the excitation signals u_k, p_k, and
measurement noise"). Rows are written in the shared bench results format
(:mod:`pwas_hdl.bench_results`); training time and peak traced memory of each predictor's fit go
in the row's ``config`` (``train_s``, ``peak_mib``: means over the runs).
"""

from __future__ import annotations

import time
from pathlib import Path
import tracemalloc
from typing import Any, Callable

import numpy as np

from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

#: The PWAS predictor on the (11b) features (P-feat): [v1 .. vN] only, p = 6 per dimension
#: (7^5 = 16 807 vertices for N_theta = 5), domain = the data box (gamma = 1), sigma by 5-fold CV.
PFEAT = {"mu": 0, "my": 0, "partitions": 6, "gamma": 1.0}
#: The raw-lag PWAS (P-raw) of issue 11's measurement: Mu = 2, My = 3, p = 3, sigma by CV.
PRAW = {"mu": 2, "my": 3, "partitions": 3, "gamma": 1.2}

ASSUMPTIONS = {
    "seed_004.A1": "output row of (14a) read as C = [0 0 0 0 1]",
    "seed_004.A2": "x0 = 0, rho0 = 0, no burn-in",
    "seed_004.A4": "noise (std sigma_N after normalisation) on u, y and the rho label; metrics against the true rho",
    "seed_004.A5": "local models gamma(rho): PWL (hat basis, 6 knots) in rho fitted by LAD (dual LP, HiGHS) on 10 000 evenly strided rows, not the paper's ANN",
    "seed_004.A6": "model-selection tree on raw [gamma; rho]",
    "seed_004.A7": "ANN = scikit-learn MLPRegressor (30, 30) ReLU, Adam (no AMSGrad), lr 1e-3, batch 64, early stopping on 5 % with patience 20, standardised features",
    "seed_004.A8": "(11a): all residual lags k-l..k",
    "seed_004.A9": "observer state 0 at k = 0; features from k = M + l (all window residuals after the M-step start-up)",
    "pwas-hdl.front-end": "the bank's 'normalize' standardises u and y again with the training statistics (near identity on normalised data)",
}


class Timer:
    """Wall time and peak traced memory (tracemalloc: numpy and Python allocations) of a block."""

    def __enter__(self) -> "Timer":
        tracemalloc.start()
        self._t = time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        self.seconds = time.perf_counter() - self._t
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        self.peak_mib = peak / 2**20


def fit_sklearn(model, x: np.ndarray, z: np.ndarray) -> tuple[Any, Timer]:
    with Timer() as t:
        model.fit(x, z)
    return model, t


def fit_pwas(cfg: dict, fe: ObserverBankFrontEnd | None, u, y, z) -> tuple[PWASVirtualSensor, Timer]:
    """A PWAS sensor through the toolchain's own fit (front end fitted inside when given)."""
    with Timer() as t:
        m = PWASVirtualSensor(**cfg, front_end=fe if fe is not None else "lags").fit(u, y, z)
    return m, t


class Collector:
    """Per-run values of (key -> list), and the timings of each key."""

    def __init__(self) -> None:
        self.values: dict[tuple, list[float]] = {}
        self.timing: dict[tuple, list[tuple[float, float]]] = {}

    def add(self, key: tuple, value: float) -> None:
        self.values.setdefault(key, []).append(float(value))

    def time(self, key: tuple, timer: Timer) -> None:
        self.timing.setdefault(key, []).append((timer.seconds, timer.peak_mib))

    def extend(self, other: "Collector") -> "Collector":
        """Append another collector's values and timings (one run's, merged in run order)."""
        for k, v in other.values.items():
            self.values.setdefault(k, []).extend(v)
        for k, v in other.timing.items():
            self.timing.setdefault(k, []).extend(v)
        return self

    def timing_of(self, key: tuple) -> dict:
        t = self.timing.get(key)
        if not t:
            return {}
        a = np.array(t)
        return {"train_s": round(float(a[:, 0].mean()), 3), "peak_mib": round(float(a[:, 1].mean()), 2)}


def mean_std(values: list[float]) -> tuple[float, float | None]:
    v = np.asarray(values, dtype=float)
    return float(v.mean()), (float(v.std(ddof=1)) if v.size > 1 else None)


def cell(r: dict | None) -> str:
    """``0.787 ± 0.023`` of a row (or ``—``)."""
    if r is None or r["value"] is None:
        return "—"
    return f"{r['value']:.3f}" + (f" ± {r['std']:.3f}" if r["std"] is not None else "")


def paper_cell(v: float | None, s: float | None = None) -> str:
    if v is None:
        return "—"
    return f"{v:.3f}" + (f" ± {s:.3f}" if s is not None else "")


def say(progress: Callable[[str], None] | None, msg: str) -> None:
    if progress is not None:
        progress(msg)


def rtl_estimates(sensor, u: np.ndarray, y: np.ndarray, workdir: Path, simulator: str = "verilator",
                  architecture: str = "parallel", bank_lanes: int | None = None) -> dict:
    """Generate the sensor's hardware and replay one trajectory through it.

    Returns
    -------
    dict with ``zhat`` (physical RTL estimates, rows k >= M + l), ``mismatches``, ``outputs``,
    ``latency`` (measured, cycles), ``latency_manifest``, ``ii``, ``err_max`` (|RTL - float sensor
    at the represented signals|, physical) and ``bound`` (the manifest's estimate bound), ``manifest``.
    Bank sensors with u/y taps (battery: ``i_k, v_k``) get the tapped top
    (:mod:`pwas_hdl.hdl.observer_tap_sensor_top`); rows then start at ``max(M + l, memory - 1)``.
    ``architecture`` / ``bank_lanes``: as ``generate --architecture serial --bank-lanes L`` (the
    time-multiplexed bank; ``ii`` is then its cycles per sample, measured).
    """
    from pwas_hdl.design.generate import generate
    from pwas_hdl.verify.simulation import Run, load_design, run_rtl, segment

    out = workdir / "design"
    generate(sensor, out, design="sensor", architecture=architecture, bank_lanes=bank_lanes)
    d = load_design(out)
    codes, _ = d.bank.quantize_signals(u, y)
    engine = "native" if simulator == "verilator" else "cocotb"
    r = run_rtl(d, [Run("full-speed", [segment(d, codes)])], simulator, engine=engine)
    got, _oor = r.hw[0][0]
    zhat = d.model.to_physical_output(got)
    ref = d.bank.reference(codes)
    return {"zhat": zhat, "mismatches": int(r.mismatches), "outputs": int(r.outputs), "passed": bool(r.passed),
            "latency": sorted(set(r.latencies)), "latency_manifest": d.latency, "ii": r.ii,
            "err_max": float(np.max(np.abs(zhat - ref))) if len(zhat) else 0.0,
            "bound": float(d.manifest["front_end"]["error_bound"]["estimate"]["physical"][0]), "manifest": d.manifest}


def observer_rtl_rows(configs: list[dict], simulators: tuple[str, ...], *, mu: Callable[[dict], int] = lambda cfg: 0,
                      my: Callable[[dict], int] = lambda cfg: 0, partitions: int, prefix: str,
                      extra: Callable[[dict, Any], dict] | None = None) -> list[dict]:
    """The observer-bank RTL benches' loop (observer_bank_rtl.py, bank_taps_rtl.py): per configuration
    fit, generate, simulate on each simulator, compare with the bit-true model.

    Each configuration (``name``, ``n_models``, ``order``, ``observer``, ``features``; optional
    ``state_bits``, ``architecture``, ``bank_lanes``: the ``generate`` options) is fitted on seed 004
    pv-benchmark data (2 000 training samples, seed 0; ``mu(cfg)`` / ``my(cfg)`` taps, ``partitions``
    per dimension, gamma 1, sigma 1e-3), generated with ``generate --design sensor`` in a temporary
    folder (``prefix``) and replayed by the manifest-driven cocotb bench: the standard runs over 400
    transfers of :func:`sim.pwas_stimulus.observer_codes` (the quantised test trajectory, steps,
    out-of-range codes, saturating alternations, silence; seed 5).

    Parameters
    ----------
    configs : list of dict
    simulators : tuple of {"icarus", "verilator"}
    mu, my : callable (cfg -> int)
        The u / y taps of the fit (0: the bank's features only, P-feat).
    partitions : int
        ``p`` of every dimension.
    prefix : str
        Prefix of the temporary design folders.
    extra : callable (cfg, design -> dict), optional
        More entries of the row (after the common ones).

    Returns
    -------
    list of dict
        One row per (configuration, simulator), printed as JSON as it is made: the configuration,
        bank, state bits, state saturations of the stimulus, outputs, mismatches, passed, latency
        measured / manifest (cycles), II measured / manifest, the first failures, ``wall_s`` (s).
    """
    import json
    import tempfile

    from pwas_hdl.design.generate import generate
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset
    from pwas_hdl.verify.simulation import load_design, run_rtl, sim_module, standard_runs

    tr, te, _ = make_pv_dataset("pv-benchmark", 2000, 400, seed=0)
    stim = sim_module("pwas_stimulus")
    rows = []
    for cfg in configs:
        fe = ObserverBankFrontEnd(n_models=cfg["n_models"], observer=cfg["observer"], features=cfg["features"], order=cfg["order"])
        s = PWASVirtualSensor(mu=mu(cfg), my=my(cfg), partitions=partitions, gamma=1.0, front_end=fe,
                              sigma=1e-3).fit(tr.u, tr.y, tr.z)
        opts = {k: cfg[k] for k in ("state_bits", "architecture", "bank_lanes") if k in cfg}
        with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
            generate(s, Path(tmp) / "d", design="sensor", **opts)
            d = load_design(Path(tmp) / "d")
            data, _ = d.bank.quantize_signals(te.u, te.y)
            codes = stim.observer_codes(d.bank.bank, 400, seed=5, data=data)
            sat = int(d.bank.bank.trace(codes)["state_saturated"].sum())
            for sim in simulators:
                t1 = time.perf_counter()
                r = run_rtl(d, standard_runs(d, codes), sim)
                row = {"config": cfg["name"], "simulator": sim, "n_models": d.bank.bank.n_models, "order": d.bank.bank.order,
                       "observer": cfg["observer"], "features": cfg["features"], "state_bits": d.bank.bank.formats.state_bits,
                       "stimulus_state_saturations": sat, "outputs": r.outputs, "mismatches": r.mismatches, "passed": r.passed,
                       "bank": cfg.get("architecture", "parallel"), "bank_lanes": cfg.get("bank_lanes", 1 if "architecture" in cfg else None),
                       "latency_measured": sorted(set(r.latencies)), "latency_manifest": d.latency, "ii": r.ii,
                       "ii_manifest": int(d.manifest["ii"]),
                       "failures": r.failures[:3], "wall_s": round(time.perf_counter() - t1, 1)}
                if extra is not None:
                    row.update(extra(cfg, d))
                print(json.dumps(row), flush=True)
                rows.append(row)
    return rows


def replace_rows(path: Path, rows: list[dict], key: Callable[[dict], tuple]) -> tuple[list[dict], dict | None]:
    """A re-run of some rows of a bench: ``rows`` replace the rows of the results file ``path`` that have
    the same ``key`` (in place), the others are kept; new keys go at the end.

    Returns ``(merged rows, the old document)``, or ``(rows, None)`` when ``path`` does not exist.
    """
    import json

    if not path.exists():
        return rows, None
    old = json.loads(path.read_text())
    new = {key(r): r for r in rows}
    return [new.pop(key(r), r) for r in old["rows"]] + list(new.values()), old
