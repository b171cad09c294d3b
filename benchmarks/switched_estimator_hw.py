"""Seed 003's estimator in hardware (issue 12): float vs bit-true vs RTL, output MSE and mode accuracy.

The estimator of Morales-Morales et al. (bank (8) with injection, single-sample residual detector
(9) as argmin, switched observer (10), poles {0.3, 0.4}, A3/A4/A6 of ``seed_003.md``) as
:class:`pwas_hdl.fixedpoint.observer_bank.FixedPointSwitchedEstimator` (default formats: 12-bit
inputs with 8 units of head room) and :class:`pwas_hdl.hdl.switched_estimator_top.SwitchedEstimatorTop`
(``--architecture parallel``) / :class:`~pwas_hdl.hdl.switched_estimator_top.SerialSwitchedEstimatorTop`
(``--architecture serial``): one set of ``rtl`` rows per architecture (``config.architecture``).
Test sets as :mod:`pwas_hdl.benchmarks.switched_linear`: the paper replica (100 samples, step
u = 1, time switching) and a long run (2000 samples, PRBS, dwell 20-50), noise on y 0 .. 0.05.
Stages: ``float`` (the float estimator on the unquantised signals), ``bittrue`` (the fixed-point
model on the quantised signals) and ``rtl`` (the replica through the Amaranth netlist the
Verilog is emitted from, simulated with bubbles and backpressure; every output compared with the
bit-true model: ``mismatches`` in the row config). Also the number of samples whose detected mode
differs from the float detector's, and how many of those had a float margin above ``2 dS`` (the
stated bound: must be 0).

The full run replays every set (replica and long runs) through the Verilog of the generated folder
(``pwas-hdl generate`` of the plant's estimator file) on Verilator under cocotb, at full speed and
with bubbles and backpressure, a reset before every set; ``--quick`` keeps the Amaranth-netlist
replay of the replica (no simulator).

``python -m pwas_hdl.benchmarks.switched_estimator_hw [--runs 3] [--quick]``.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from pwas_hdl import bench_results as br
from pwas_hdl.systems.switched_linear import (SWITCHED_A, SWITCHED_ASSUMPTIONS, SWITCHED_B, SWITCHED_C, switched_paper_run,
                                              switched_training_runs)
from pwas_hdl.systems.switched_observer import mode_scores, observer_gains, run_switched_observer

SYSTEM = "switched-linear"
PAPER_MSE = 0.0966  # Table 1, unknown mode
NOISES = (0.0, 0.01, 0.02, 0.05)
#: The designs replayed: ``generate EST.json --architecture parallel`` (II 1) and ``serial`` (one row unit).
ARCHITECTURES = ("parallel", "serial")


def _rtl_replays(design, sets: dict, simulator: str, progress) -> dict:
    """Every test set through the generated Verilog on ``simulator`` in one cocotb job: each set one
    segment after a reset, at full speed (latency and II measured) and again with bubbles (p_valid
    0.8) and backpressure (p_ready 0.7). Returns per key the decoded RTL outputs of the stalled pass
    and the counts (mismatches over both passes, outputs, latencies, spacings)."""
    import numpy as np

    from pwas_hdl.verify.estimator_simulation import replay_estimator

    keys = list(sets)
    codes = np.concatenate([sets[k] for k in keys])
    bounds, a = [], 0
    for k in keys:
        bounds.append((a, a + len(sets[k])))
        a += len(sets[k])
    plans = [{"name": "full-speed", "p_valid": 1.0, "p_ready": 1.0, "seed": 0,
              "segments": [{"rows": b, "drain": True, "record": False} for b in bounds]},
             {"name": "stalls", "p_valid": 0.8, "p_ready": 0.7, "seed": 1,
              "segments": [{"rows": b, "drain": True, "record": True} for b in bounds]}]
    if progress:
        progress(f"RTL: {len(codes)} samples x 2 passes through {design.top} on {simulator} (cocotb) ...")
    res = replay_estimator(design, codes, simulator, runs=plans)
    out = {}
    for i, k in enumerate(keys):
        segs = [r["segments"][i] for r in res["runs"]]
        out[k] = {"hw": res["rtl"]["stalls"][i], "mismatches": sum(s["mismatches"] for s in segs),
                  "outputs": sum(s["outputs"] for s in segs), "failures": res.get("failures", [])}
    out["_summary"] = {"latency": res["latency"], "ii": res["ii"], "passed": res["passed"], "wall_s": res.get("wall_s"),
                       "simulator": simulator, "samples": int(len(codes))}
    return out


def run(runs: int = 3, quick: bool = False, progress: Callable[[str], None] | None = print,
        simulator: str | None = "auto", architectures: tuple = ARCHITECTURES) -> tuple[dict, dict]:
    """``simulator``: ``"icarus"`` / ``"verilator"``: the ``rtl`` rows replay every test set (replica and
    long runs) through the Verilog of the generated estimator folder (``pwas-hdl generate`` of the
    plant's estimator file) under cocotb; ``None``: the replica through the Amaranth netlist only
    (no simulator needed); ``"auto"``: ``None`` with ``quick``, else ``"verilator"``.
    ``architectures``: the ``generate --architecture`` values replayed (one set of ``rtl`` rows each,
    ``config.architecture``)."""
    import tempfile

    from pwas_hdl.design.generate import generate
    from pwas_hdl.fit.estimator_file import write_estimator
    from pwas_hdl.hdl.switched_estimator_top import SerialSwitchedEstimatorTop, SwitchedEstimatorTop, simulate_estimator
    from pwas_hdl.systems.switched_observer import estimator_config
    from pwas_hdl.verify.estimator_simulation import load_estimator_design

    t0 = time.perf_counter()
    if simulator == "auto":
        simulator = None if quick else "verilator"
    noises = (0.0, 0.02) if quick else NOISES
    long_n = 300 if quick else 2000
    archs = tuple(architectures)
    designs: dict = {}
    tops: dict = {}
    tmpdir = tempfile.TemporaryDirectory(prefix="pwas-est-bench-")
    if simulator is not None:  # the generated folders: what `pwas-hdl generate EST.json [--architecture serial]` writes
        cfgp = write_estimator(estimator_config(), f"{tmpdir.name}/estimator.json")
        for arch in archs:
            generate(cfgp, f"{tmpdir.name}/hw_{arch}", architecture=arch)
            designs[arch] = load_estimator_design(f"{tmpdir.name}/hw_{arch}")
        est = designs[archs[0]].est
    else:
        from pwas_hdl.fixedpoint.observer_bank import FixedPointSwitchedEstimator

        est = FixedPointSwitchedEstimator(SWITCHED_A, SWITCHED_B, SWITCHED_C, observer_gains())
        tops = {a: (SwitchedEstimatorTop if a == "parallel" else SerialSwitchedEstimatorTop)(est) for a in archs}
    timing = {a: ((tops[a].latency, tops[a].ii) if a in tops else (designs[a].latency, designs[a].ii)) for a in archs}
    vals: dict[tuple, list[float]] = {}
    extra: dict[tuple, dict] = {}

    def put(key, v):
        vals.setdefault(key, []).append(float(v))

    data = {(noise, r): {"replica": switched_paper_run(seed=r, switching="time", input_kind="step", noise=noise),
                         "long": switched_training_runs(1, long_n, seed=5000 + r, switching="time", noise=noise)}
            for noise in noises for r in range(runs)}
    rtl = None
    if designs:
        sets = {(nr, t): est.quantize_signals(d.u, d.y) for nr, tests in data.items() for t, d in tests.items()}
        rtl = {a: _rtl_replays(designs[a], sets, simulator, progress) for a in archs}
    tmpdir.cleanup()
    for noise in noises:
        for r in range(runs):
            tests = data[(noise, r)]
            for tname, d in tests.items():
                y = d.y[:, 0]
                codes = est.quantize_signals(d.u, d.y)
                fl = run_switched_observer(d.u, d.y)
                tr = est.trace(codes)
                stages = {"float": (fl.x_hat, fl.y_hat, fl.theta_hat),
                          "bittrue": (est.to_physical_state(tr["x_hat"]), tr["y_hat"] * 2.0**-est.state_frac, tr["theta"])}
                for arch in archs:
                    if rtl is not None:
                        got = rtl[arch][((noise, r), tname)]
                        hw = got["hw"]
                        mism, n_out = int(got["mismatches"]), int(got["outputs"])  # exact word compare in the bench, both passes
                    elif tname == "replica":
                        hw = simulate_estimator(tops[arch], codes, p_valid=0.8, p_ready=0.7, seed=r)
                        mism = int(np.sum((hw["theta"] != tr["theta"]) | (hw["y_hat"] != tr["y_hat"])
                                          | np.any(hw["x_hat"] != tr["x_hat"], axis=1)))
                        n_out = len(hw["theta"])
                    else:
                        continue
                    stages[("rtl", arch)] = (est.to_physical_state(hw["x_hat"]), hw["y_hat"] * 2.0**-est.state_frac, hw["theta"])
                    ex = extra.setdefault((tname, noise, arch), {"mismatches": 0, "rtl_outputs": 0})
                    ex["mismatches"] += mism
                    ex["rtl_outputs"] += n_out
                ref = est.reference(codes)  # float at the represented signals: the bound's reference
                ws = np.sort(ref.residuals, axis=1)
                margin = ws[:, 1] - ws[:, 0]
                differ = tr["theta"] != ref.theta_hat
                ex = extra.setdefault((tname, noise), {})
                ex["mode_differs"] = ex.get("mode_differs", 0) + int(differ.sum())
                ex["mode_differs_beyond_bound"] = ex.get("mode_differs_beyond_bound", 0) + int(np.sum(differ & (margin > 2 * est.sum_error_bound)))
                for stage, (xh, yh, th) in stages.items():
                    put((tname, "y", stage, "mse", noise), np.mean((y - yh) ** 2))
                    put((tname, "mode", stage, "accuracy", noise), mode_scores(d.mode, th)["accuracy"])
                    for col, tgt in enumerate(("x1", "x2")):
                        put((tname, tgt, stage, "rmse", noise), float(np.sqrt(np.mean((xh[:, col] - d.z_true[:, col]) ** 2))))
            if progress:
                progress(f"noise {noise} run {r + 1}/{runs}: replica MSE float {vals[('replica', 'y', 'float', 'mse', noise)][-1]:.5f} "
                         f"rtl {vals[('replica', 'y', ('rtl', archs[0]), 'mse', noise)][-1]:.5f}; long accuracy float "
                         f"{vals[('long', 'mode', 'float', 'accuracy', noise)][-1]:.4f} bittrue {vals[('long', 'mode', 'bittrue', 'accuracy', noise)][-1]:.4f}")
    rows = []
    for (tname, tgt, stage_key, metric, noise), v in vals.items():
        stage, arch = stage_key if isinstance(stage_key, tuple) else (stage_key, None)
        cfg = {"test": tname, "switching": "time", "noise_y": noise, "estimator_formats": est.to_dict()["formats"]}
        if arch is not None:
            latency, ii = timing[arch]
            cfg["architecture"] = arch
        if stage != "float":
            cfg |= {k: extra[(tname, noise)][k] for k in ("mode_differs", "mode_differs_beyond_bound")}
            cfg |= {"error_bound": est.to_dict()["error_bound"]}
        if stage == "rtl" and rtl is None:
            cfg |= {"simulator": "amaranth (the netlist of the emitted Verilog)", "mismatches": extra[(tname, noise, arch)]["mismatches"],
                    "rtl_outputs": extra[(tname, noise, arch)]["rtl_outputs"], "latency_cycles": latency, "ii": ii,
                    "stalls": {"p_valid": 0.8, "p_ready": 0.7}}
        elif stage == "rtl":
            sm = rtl[arch]["_summary"]
            cfg |= {"simulator": f"{sm['simulator']} (cocotb, the generated folder's Verilog)",
                    "mismatches": extra[(tname, noise, arch)]["mismatches"], "rtl_outputs": extra[(tname, noise, arch)]["rtl_outputs"],
                    "latency_cycles": latency, "ii": ii, "latency_measured": sm["latency"], "ii_measured": sm["ii"],
                    "bench_passed": sm["passed"],
                    "passes": "full speed, then p_valid 0.8 / p_ready 0.7 (values of the stalled pass); a reset before every set"}
        paper = PAPER_MSE if (tname == "replica" and tgt == "y" and metric == "mse" and noise == 0.0) else None
        rows.append(br.row_from_values(SYSTEM, tgt, "switched-observer", stage, metric, v, paper, cfg))
    doc = br.make_results("switched-estimator-hw", rows, SWITCHED_ASSUMPTIONS,
                          config={"runs": runs, "noises": list(noises), "long_samples": long_n, "switching": "time",
                                  "architectures": list(archs),
                                  "rtl": ({a: rtl[a]["_summary"] for a in archs} if rtl is not None
                                          else "amaranth netlist, replica only")},
                          description="Seed 003's switched observer: float, bit-true and RTL", quick=quick,
                          elapsed_s=time.perf_counter() - t0)
    return doc, {}


def _rtl_note(doc: dict) -> str:
    r = doc["config"].get("rtl")
    if not isinstance(r, dict):
        return "RTL: the replica through the Amaranth netlist of the emitted Verilog (bubbles and backpressure)."
    if "simulator" in r:  # a results file of one architecture (before the serial design)
        r = {"parallel": r}
    parts = [f"{a}: latency {x['latency']} cycles and II {x['ii']} measured at full speed, bench passed: {x['passed']}"
             for a, x in r.items()]
    x = next(iter(r.values()))
    return (f"RTL: every set through the generated folders' Verilog (`generate --architecture parallel` / `serial`) on "
            f"{x['simulator']} (cocotb), a reset before each, at full speed and with bubbles (p_valid 0.8) and backpressure "
            f"(p_ready 0.7): {x['samples']} samples x 2 passes each; {'; '.join(parts)}; "
            "the rtl columns are the stalled pass, mismatches count both passes.")


def markdown(doc: dict) -> str:
    lines = [f"# Seed 003 estimator in hardware (runs = {doc['config']['runs']}{', QUICK' if doc.get('quick') else ''})", "",
             _rtl_note(doc), "",
             "| test | noise | metric | float | bit-true | rtl parallel | rtl serial | modes differing (beyond bound) "
             "| rtl mismatches parallel | rtl mismatches serial |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for tname in ("replica", "long"):
        for noise in doc["config"]["noises"]:
            for tgt, metric in (("y", "mse"), ("mode", "accuracy"), ("x1", "rmse"), ("x2", "rmse")):
                get = lambda st: br.find_rows(doc, target=tgt, stage=st, metric=metric, config={"test": tname, "noise_y": noise})  # noqa: E731
                f, b = get("float"), get("bittrue")
                if not f:
                    continue
                rr = get("rtl")
                ra = {a: [x for x in rr if x["config"].get("architecture", "parallel") == a] for a in ARCHITECTURES}
                c = lambda x: f"{x[0]['value']:.5f}" if x else "—"  # noqa: E731
                k = b[0]["config"]
                mm = lambda x: f"{x[0]['config']['mismatches']} / {x[0]['config']['rtl_outputs']}" if x else "—"  # noqa: E731
                lines.append(f"| {tname} | {noise} | {tgt} {metric} | {c(f)} | {c(b)} | {c(ra['parallel'])} | {c(ra['serial'])} "
                             f"| {k['mode_differs']} ({k['mode_differs_beyond_bound']}) | {mm(ra['parallel'])} | {mm(ra['serial'])} |")
    return "\n".join(lines) + "\n"


def plot(traces, path) -> None:
    return None


if __name__ == "__main__":
    import sys

    br.bench_main(sys.argv[1:], stem="switched_estimator_hw", description=__doc__.splitlines()[0], run=run, markdown=markdown,
                  plot=plot, default_runs=3)
