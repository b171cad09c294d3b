"""Additive (reduced-complexity) PWAS sensors against the full PWAS sensor (issue 15, item 1).

Accuracy (``run_additive``, format ``pwas-hdl-bench-results``):

* Lorenz (Section VI-A of the paper; the protocol of :mod:`pwas_hdl.benchmarks.lorenz_tables`): per
  seed one trajectory (1000 burn-in samples dropped), training on the first 6000 samples, testing on
  the 2000 estimates of the continuation block (7 samples of history before it, the most any row
  needs), RMSEE against the noise-free ``z``; ``p = 7``, ``gamma = 1.2``, zero-order Tikhonov, sigma
  by 5-fold CV on contiguous blocks. ``My = 4, 5, 6, 8``; sensors: the full PWAS function
  (``N = 8**My``; ``My = 8`` has 16.7 M weights, over the 2**20 limit: refused, recorded as such)
  and the additive ones ``time`` (one part per lag), ``pairs``, ``triples`` (sliding windows).
* Helicopter-size (Table VI, ``pwas_hdl.systems.helicopter``: 25000 samples at 10 ms, fit on the
  first 20000, RMSE of ``psi`` against ``psi_true`` on the rest; ``gamma = 1.1``, first-order
  Tikhonov, ``p = 3`` as :mod:`pwas_hdl.benchmarks.hw_tables`): ``Mu = My = 2`` (``n = 6``, full
  ``N = 4096``) and ``Mu = My = 4`` (``n = 12``: full ``N = 4**12`` refused); additive ``time`` and
  ``pairs`` (first-order additive fits are solved by factorisation, see ``HELI_ROWS``).
* Stages: ``float`` (the fitted sensor) and ``bittrue`` (the fixed-point model with the default
  formats of ``generate``: :class:`~pwas_hdl.fixedpoint.bittrue.FixedPointModel` or
  :class:`~pwas_hdl.fixedpoint.additive.AdditiveFixedPointModel`, 12-bit inputs).

Hardware (``run_hardware``, ``--hardware``; written to ``additive_hw.json``): the additive
Lorenz ``My = 8`` sensors of seed 0 as virtual-sensor tops, the 2000 test samples replayed through
the RTL with cocotb on Icarus and on Verilator (bit-exact against the bit-true model, RMSEE of the
hardware estimates), and, with ``--synth``, one ECP5 place and route of the ``pairs`` core with the
``min`` pipeline (:func:`pwas_hdl.flow.timing_closure.measure_design`, the harness and settings of
``hw_tables``' ``short`` rows: LFE5U-45F, 150 MHz, seed 1) for the resources. Usage::

    python benchmarks/additive.py [--runs 5] [--quick] [--outdir benchmarks/results]
    python benchmarks/additive.py --hardware [--synth]
    python benchmarks/additive.py --heli-hardware      # the additive helicopter cores on ECP5, once

Nothing here asserts on times.
"""

from __future__ import annotations

import sys

import argparse
import json
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from pwas_hdl import bench_results as br
from pwas_hdl.errors import ResourceLimit
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

__all__ = ["BENCH", "LORENZ_ROWS", "HELI_ROWS", "run_additive", "run_hardware", "markdown", "hardware_markdown"]

BENCH = "additive"
KINDS = ("full", "time", "pairs", "triples")
LORENZ_ROWS = [(my, k) for my in (4, 5, 6, 8) for k in KINDS]
#: ``(4, "pairs")``: 3 parts of 6 dimensions, N = 12288, first order; solved by factorisation
#: (:data:`pwas_hdl.fit.additive.ADDITIVE_DIRECT_MAX_UNKNOWNS`: conjugate gradients did not converge on
#: the nearly singular system and fell back to the factorisation after 2000 iterations, per fold and
#: sigma, so that the cross-validation had not finished in 9 minutes).
HELI_ROWS = [(2, "full"), (2, "time"), (4, "full"), (4, "time"), (4, "pairs")]
N_TRAIN, N_TEST, HISTORY, BURN_IN = 6000, 2000, 8, 1000
ASSUMPTIONS = {
    "issue15.parts": "an additive sensor is f = sum_i f_i(x_{S_i}), each f_i a PWAS function on the shared domain box "
                     "restricted to S_i; time: S_i = the regressors of lag i; pairs/triples: sliding windows of 2/3 lags",
    "issue15.fit": "the parts are fitted jointly: stacked basis [H_1 ... H_k], Gamma = blockdiag(Gamma_i), sigma by the "
                   "same 5-fold CV as the full sensor; the split among the parts is the least-penalty one (not identifiable)",
    "issue15.full_limit": "a full sensor with N > 2**20 weights is refused by pwas-hdl (ResourceLimit): no row for it",
    "hw_tables.helicopter": "synthetic closed-loop helicopter (pwas_hdl.systems.helicopter), not the paper's data",
}


def _estimator(kind: str) -> str:
    return "pwas-full" if kind == "full" else f"pwas-additive-{kind}"


def _fit_and_score(sensor: PWASVirtualSensor, fit_args, xi_test: np.ndarray, z_test: np.ndarray) -> dict[str, Any]:
    """Fit, then the float and bit-true RMSE on the test regressors."""
    from pwas_hdl.design.generate import fixed_point_model

    t0 = time.perf_counter()
    sensor.fit(*fit_args)
    fit_s = time.perf_counter() - t0
    zf = sensor.predict_regressors(xi_test)[:, 0]
    fx = fixed_point_model(sensor)
    zb = fx.predict(xi_test)[:, 0]
    return {"float": float(np.sqrt(np.mean((zf - z_test) ** 2))), "bittrue": float(np.sqrt(np.mean((zb - z_test) ** 2))),
            "N": int(sensor.grid_.n_vertices), "parts": len(getattr(sensor.grid_, "subsets", [()])), "sigma": float(sensor.sigma_),
            "fit_s": fit_s, "weights": str(fx.weight_format), "output": str(fx.output_format)}


def _lorenz_seed(seed: int, rows, progress) -> list[dict[str, Any]]:
    from pwas_hdl.systems.lorenz import lorenz

    n_total = N_TRAIN + N_TEST + HISTORY - 1
    data = lorenz(n_total, seed=seed, burn_in=BURN_IN)
    y_tr, z_tr = data.y[:N_TRAIN], data.z[:N_TRAIN]
    z_te = data.z_true[N_TRAIN + HISTORY - 1 :, 0]
    out = []
    for my, kind in rows:
        sensor = PWASVirtualSensor(mu=0, my=my, partitions=7, gamma=1.2, tikhonov_order=0, cv_folds=5,
                                   additive=None if kind == "full" else kind, output_names=["y"], target_names=["z"])
        xi, _ = sensor._build_regressors(sensor._infer_lags(None, data.y), None, data.y[N_TRAIN + HISTORY - my :])
        try:
            r = _fit_and_score(sensor, (None, y_tr, z_tr), xi, z_te)
        except ResourceLimit as exc:
            r = {"refused": str(exc)}
        out.append({"seed": seed, "my": my, "kind": kind, **r})
        if progress:
            progress(f"lorenz seed {seed} My = {my} {kind}: " + (f"N = {r['N']}, RMSEE {r['float']:.3f} (bit-true {r['bittrue']:.3f})"
                                                                if "refused" not in r else "refused (N over the limit)"))
    return out


def _heli_seed(seed: int, rows, progress) -> list[dict[str, Any]]:
    from pwas_hdl.systems.helicopter import helicopter

    h = helicopter(25000, seed=seed)
    tr, te = slice(0, 20000), slice(20000, None)
    out = []
    for m, kind in rows:
        sensor = PWASVirtualSensor(mu=m, my=m, partitions=3, gamma=1.1, tikhonov_order=1,
                                   additive=None if kind == "full" else kind,
                                   input_names=["psi_d", "phi_d"], output_names=["phi"], target_names=["psi"])
        xi, _ = sensor._build_regressors(sensor._infer_lags(h.u, h.y), h.u[te], h.y[te])
        z_te = h.z_true[te][m - 1 :, 0]
        try:
            r = _fit_and_score(sensor, (h.u[tr], h.y[tr], h.z[tr]), xi, z_te)
        except ResourceLimit as exc:
            r = {"refused": str(exc)}
        out.append({"seed": seed, "m": m, "kind": kind, **r})
        if progress:
            progress(f"helicopter seed {seed} Mu = My = {m} {kind}: " + (f"N = {r['N']}, RMSE {r['float']:.5f}" if "refused" not in r
                                                                        else "refused (N over the limit)"))
    return out


def run_additive(runs: int = 5, quick: bool = False, progress: Callable[[str], None] | None = print) -> tuple[dict, dict]:
    """The accuracy comparison (see the module docstring); ``quick``: one seed, My = 4 and 8, no helicopter."""
    t0 = time.monotonic()
    lrows = [(my, k) for my, k in LORENZ_ROWS if my in (4, 8) and k in ("full", "pairs")] if quick else LORENZ_ROWS
    seeds = range(1 if quick else runs)
    lor = [r for s in seeds for r in _lorenz_seed(s, lrows, progress)]
    heli = [] if quick else [r for s in range(min(runs, 2)) for r in _heli_seed(s, HELI_ROWS, progress)]
    rows = []
    for system, key, recs, cfgrows, target in (("lorenz", "my", lor, lrows, "z"), ("helicopter", "m", heli, [] if quick else HELI_ROWS, "psi")):
        for lag, kind in cfgrows:
            sel = [r for r in recs if r[key] == lag and r["kind"] == kind]
            cfg = {("My" if key == "my" else "Mu=My"): lag, "p": 7 if system == "lorenz" else 3, "kind": kind}
            if "refused" in sel[0]:
                rows.append(br.row(system, target, _estimator(kind), "float", "rmse", None, runs=len(sel),
                                   config={**cfg, "note": sel[0]["refused"]}))
                continue
            cfg.update(N=sel[0]["N"], parts=sel[0]["parts"], sigma=[r["sigma"] for r in sel],
                       fit_s_mean=round(float(np.mean([r["fit_s"] for r in sel])), 3),
                       weight_format=sel[0]["weights"], output_format=sel[0]["output"])
            for stage in ("float", "bittrue"):
                rows.append(br.row_from_values(system, target, _estimator(kind), stage, "rmse", [r[stage] for r in sel], config=cfg))
    doc = br.make_results(BENCH, rows, ASSUMPTIONS, config={"lorenz": {"n_train": N_TRAIN, "n_test": N_TEST, "p": 7, "gamma": 1.2,
                                                                      "tikhonov_order": 0, "folds": 5, "seeds": list(seeds)},
                                                           "helicopter": {"samples": 25000, "train": 20000, "p": 3, "gamma": 1.1,
                                                                          "tikhonov_order": 1, "seeds": list(range(min(runs, 2))) if not quick else []}},
                          description="full vs additive PWAS sensors: weights N and RMSE(E) of the float and bit-true models",
                          quick=quick, elapsed_s=time.monotonic() - t0)
    return doc, {}


def markdown(doc: dict) -> str:
    """The comparison table (one line per system, lags and sensor)."""
    lines = ["# Full vs additive PWAS sensors (issue 15)", "",
             "Generated by `python benchmarks/additive.py`; numbers in `additive.json`. RMSE(E) mean +- std over the runs "
             "(Lorenz: RMSEE against the noise-free z, 2000 test samples; helicopter: RMSE of psi [rad] against psi_true). "
             "Bit-true: the default formats of `generate` (12-bit inputs). A full sensor over 2^20 weights is refused.", "",
             "| system | lags | sensor | parts | N | RMSE float | RMSE bit-true | weights | fit (s) |", "|---|---|---|---:|---:|---:|---:|---|---:|"]
    by = {}
    for r in doc["rows"]:
        by.setdefault((r["system"], json.dumps({k: v for k, v in r["config"].items() if k in ("My", "Mu=My")}), r["estimator"]), {})[r["stage"]] = r
    for (system, lags, est), st in by.items():
        f = st["float"]
        cfg = f["config"]
        lag = ", ".join(f"{k} = {v}" for k, v in json.loads(lags).items())
        name = est.replace("pwas-", "")
        if f["value"] is None:
            lines.append(f"| {system} | {lag} | {name} | 1 | {cfg['note'].split(' vertices')[0].split('N = prod(p_j + 1) = ')[-1]} (refused) | - | - | - | - |")
            continue

        def pm(r):
            return f"{r['value']:.4g}" + (f" +- {r['std']:.2g}" if r["std"] is not None else "")

        lines.append(f"| {system} | {lag} | {name} | {cfg['parts']} | {cfg['N']} | {pm(f)} | {pm(st['bittrue'])} | "
                     f"{cfg['weight_format']} | {cfg['fit_s_mean']:.2f} |")
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------------ hardware
def run_hardware(kinds=("pairs", "triples"), synth: bool = False, workdir: Path | None = None,
                 progress: Callable[[str], None] | None = print) -> dict[str, Any]:
    """The additive Lorenz My = 8 sensors (seed 0) in RTL: 2000 test samples on Icarus and Verilator; optional ECP5 resources."""
    from pwas_hdl.design.generate import build_design, generate
    from pwas_hdl.io.csv_table import format_csv
    from pwas_hdl.systems.lorenz import lorenz
    from pwas_hdl.verify.simulation import simulate_data

    say = progress or (lambda m: None)
    with br.scratch_folder("pwas-additive-hw-", workdir) as work:
        n_total = N_TRAIN + N_TEST + HISTORY - 1
        data = lorenz(n_total, seed=0, burn_in=BURN_IN)
        te = slice(N_TRAIN, n_total)
        csv = work / "test.csv"
        work.mkdir(parents=True, exist_ok=True)
        csv.write_text(format_csv({"y": data.y[te, 0], "z_true": data.z_true[te, 0]}))
        out: dict[str, Any] = {"data": "lorenz seed 0: trained on samples 0..5999, replayed 6000..8006 (2000 estimates)", "designs": []}
        for kind in kinds:
            sensor = PWASVirtualSensor(mu=0, my=8, partitions=7, gamma=1.2, additive=kind, output_names=["y"], target_names=["z"])
            sensor.fit(None, data.y[:N_TRAIN], data.z[:N_TRAIN])
            folder = work / f"my8_{kind}"
            gd = generate(sensor, folder, design="sensor")
            rec = {"kind": kind, "N": int(sensor.grid_.n_vertices), "parts": len(sensor.grid_.subsets), "latency_cycles": gd.manifest["latency_cycles"],
                   "weights": gd.manifest["formats"]["weight"]["str"], "output": gd.manifest["formats"]["output"]["str"],
                   "memory": {k: gd.manifest["memory"][k] for k in ("memories", "depth", "word_bits", "words", "bits")}, "sim": {}}
            for sim in ("icarus", "verilator"):
                t0 = time.monotonic()
                r = simulate_data(folder, csv, work / f"my8_{kind}_{sim}.csv", simulator=sim, cache_dir=work / "cache")
                s = r["summary"]
                rec["sim"][sim] = {"passed": bool(s["checks"]["passed"]), "outputs": int(len(r["rows"])),
                                   "mismatches": int(r["result"].mismatches), "ii": r["result"].ii,
                                   "latencies": sorted(set(r["result"].latencies)),
                                   "rmsee_hw": float(np.sqrt(np.mean((r["estimates"][:, 0] - data.z_true[te, 0][r["rows"]]) ** 2))),
                                   "wall_s": round(time.monotonic() - t0, 1)}
                say(f"My = 8 {kind}: {sim}: {rec['sim'][sim]}")
            if synth and kind == "pairs":
                from pwas_hdl.flow.timing_closure import measure_design

                for pipe in ("min",):  # once (the `short` build of hw_tables: no optional registers)
                    core = build_design(sensor, design="core", pipeline=pipe)
                    t0 = time.monotonic()
                    m = measure_design(core, "ecp5", freq_mhz=150.0, seed=1, workdir=work / f"synth_{kind}_{pipe}")
                    rec.setdefault("ecp5_core", {})[pipe] = {
                        k: m.get(k) for k in ("part", "fmax_mhz", "latency_cycles", "latency_ns", "luts", "ffs_core", "dsp", "bram", "bram_bits")}
                    rec["ecp5_core"][pipe]["runtime_s"] = round(time.monotonic() - t0, 1)
                    say(f"My = 8 {kind} core ({pipe}) on ECP5: {rec['ecp5_core'][pipe]}")
            out["designs"].append(rec)
        out["environment"] = br.environment()
        return out


#: The full Table VI-size helicopter core of ``hw_tables`` (``heli_mu2_my2_p3``, default build, ECP5
#: LFE5U-45F, 150 MHz constraint, seed 1, the same harness), read from ``hw_tables.json`` for the table.
HELI_FULL_DESIGN = "heli_mu2_my2_p3"


def _results_name(path: Path) -> str:
    """``path`` as the results say where a number came from: relative to the checkout, or to the working folder."""
    from pwas_hdl.resources import benchmarks_dir

    for base in (benchmarks_dir().parent, Path.cwd()):
        try:
            return path.resolve().relative_to(base.resolve()).as_posix()
        except ValueError:
            pass
    return path.name


def full_reference(say: Callable[[str], None] = print) -> dict[str, Any] | None:
    """The full Table VI-size core's ECP5 build (:data:`HELI_FULL_DESIGN`) as ``hw_tables.json`` holds it.

    Read from the results folder (:func:`pwas_hdl.bench_results.default_outdir`), not measured again;
    None (and a line said) when that file does not hold it.
    """
    ref = br.default_outdir() / "hw_tables.json"  # the committed results in a checkout; from the wheel, where hw_tables wrote
    try:
        hwt = json.loads(ref.read_text())
        full = next(d for d in hwt["designs"] if d["key"] == HELI_FULL_DESIGN)
        b = full["builds"]["ecp5"]["default"]
        return {"design": HELI_FULL_DESIGN, "source": _results_name(ref), "n": full["n"],
                "N": full["N"], "weights_bits": full["memory"]["weight_bits"],
                "memories": b["memory_plan"]["memories"], "words": b["memory_plan"]["words"],
                **{k: b.get(k) for k in ("part", "fmax_mhz", "latency_cycles", "latency_ns", "luts", "ffs_core", "dsp",
                                         "bram", "bram_bits")}}
    except (OSError, ValueError, KeyError, StopIteration) as exc:
        say(f"no full-core reference row: {ref} does not hold {HELI_FULL_DESIGN}'s ECP5 build ({type(exc).__name__}); "
            "run benchmarks/hw_tables.py first for it")
        return None


def run_heli_hardware(kinds=("time", "pairs"), workdir: Path | None = None,
                      progress: Callable[[str], None] | None = print) -> dict[str, Any]:
    """The additive helicopter ``Mu = My = 4`` cores (seed 0, the accuracy protocol) placed and routed
    once on ECP5 with the settings of ``hw_tables`` (default pipeline, LFE5U-45F, 150 MHz, seed 1,
    timing harness), beside that table's full ``Mu = My = 2`` core (Table VI size)."""
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.flow.timing_closure import measure_design
    from pwas_hdl.systems.helicopter import helicopter

    say = progress or (lambda m: None)
    with br.scratch_folder("pwas-additive-heli-", workdir) as work:
        h = helicopter(25000, seed=0)
        tr = slice(0, 20000)
        out: dict[str, Any] = {"data": "helicopter seed 0, trained on samples 0..19999 (the accuracy protocol)", "designs": []}
        for kind in kinds:
            sensor = PWASVirtualSensor(mu=4, my=4, partitions=3, gamma=1.1, tikhonov_order=1, additive=kind,
                                       input_names=["psi_d", "phi_d"], output_names=["phi"], target_names=["psi"])
            sensor.fit(h.u[tr], h.y[tr], h.z[tr])
            gd = build_design(sensor, design="core")
            t0 = time.monotonic()
            m = measure_design(gd, "ecp5", freq_mhz=150.0, seed=1, workdir=work / f"heli_{kind}")
            rec = {"kind": kind, "n": 12, "N": int(sensor.grid_.n_vertices), "parts": len(sensor.grid_.subsets),
                   "weights": gd.manifest["formats"]["weight"]["str"],
                   "memory": {k: gd.manifest["memory"][k] for k in ("memories", "depth", "word_bits", "words", "bits")},
                   **{k: m.get(k) for k in ("part", "fmax_mhz", "latency_cycles", "latency_ns", "luts", "ffs_core", "dsp", "bram", "bram_bits")},
                   "runtime_s": round(time.monotonic() - t0, 1)}
            say(f"helicopter Mu = My = 4 {kind} core on ECP5: {rec}")
            out["designs"].append(rec)
        out["full_reference"] = full_reference(say)
        out["environment"] = br.environment()
        return out


def heli_hardware_markdown(hw: dict[str, Any]) -> str:
    """The additive helicopter cores beside the full Table VI-size core (ECP5, the settings of ``hw_tables``)."""
    lines = ["## Helicopter size: additive Mu = My = 4 cores beside the full Mu = My = 2 core", "",
             f"{hw['data']}; core designs, default pipeline, 12-bit inputs, ECP5 LFE5U-45F, 150 MHz constraint, nextpnr seed 1, "
             "the timing harness of `hw_tables` (the full core: `hw_tables.json`, design heli_mu2_my2_p3, fitted on the same plant).", "",
             "| sensor | n | parts | N | weights | memories (words) | cycles | fmax (MHz) | latency (ns) | LUT4 | FF | DSP | BRAM |",
             "|---|---:|---:|---:|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    f = hw.get("full_reference")
    if f:
        lines.append(f"| full Mu = My = 2 | {f['n']} | 1 | {f['N']} | {f['weights_bits']} bits | {f.get('memories', '-')} ({f.get('words', '-')}) | {f['latency_cycles']} | "
                     f"{f['fmax_mhz']:.1f} | {f['latency_ns']:.1f} | {f['luts']} | {f['ffs_core']} | {f['dsp']} | {f['bram']} |")
    for d in hw["designs"]:
        lines.append(f"| additive {d['kind']} Mu = My = 4 | {d['n']} | {d['parts']} | {d['N']} | {d['weights']} | "
                     f"{d['memory']['memories']} ({d['memory']['words']}) | {d['latency_cycles']} | {d['fmax_mhz']:.1f} | "
                     f"{d['latency_ns']:.1f} | {d['luts']} | {d['ffs_core']} | {d['dsp']} | {d['bram']} |")
    return "\n".join(lines) + "\n"


def hardware_markdown(hw: dict[str, Any]) -> str:
    lines = ["## Additive Lorenz My = 8 in hardware", "", f"{hw['data']}; virtual-sensor top (lag bank + parts + sum), cocotb.", "",
             "| sensor | parts | N | weights | latency | memories (words) | simulator | outputs | mismatches | II | RMSEE (hw) |",
             "|---|---:|---:|---|---:|---|---|---:|---:|---:|---:|"]
    for d in hw["designs"]:
        for sim, s in d["sim"].items():
            lines.append(f"| {d['kind']} | {d['parts']} | {d['N']} | {d['weights']} | {d['latency_cycles']} | "
                         f"{d['memory']['memories']} ({d['memory']['words']}) | {sim} | {s['outputs']} | {s['mismatches']} | "
                         f"{s['ii']} | {s['rmsee_hw']:.4g} |")
    syn = [(d["kind"], p, r) for d in hw["designs"] for p, r in d.get("ecp5_core", {}).items()]
    if syn:
        lines += ["", "ECP5 (LFE5U-45F, 150 MHz constraint, nextpnr seed 1, the timing harness of `hw_tables`), core designs:", "",
                  "| sensor | pipeline | cycles | fmax (MHz) | latency (ns) | LUT4 | FF | DSP | BRAM |", "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
        for kind, p, r in syn:
            lines.append(f"| {kind} | {p} | {r['latency_cycles']} | {r['fmax_mhz']:.1f} | {r['latency_ns']:.1f} | {r['luts']} | "
                         f"{r['ffs_core']} | {r['dsp']} | {r['bram']} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from pwas_hdl.io.atomic import atomic_write_text
    from pwas_hdl.bench_results import default_outdir

    ap = argparse.ArgumentParser(description="full vs additive PWAS sensors (issue 15)")
    ap.add_argument("--runs", type=int, default=5, help="independent runs (1..1000, pwas_hdl.limits.MAX_BENCH_COUNT)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--outdir", type=Path, default=default_outdir())
    ap.add_argument("--hardware", action="store_true", help="the My = 8 additive sensors in RTL (writes additive_hw.json/.md)")
    ap.add_argument("--synth", action="store_true", help="with --hardware: one ECP5 place and route of the pairs core")
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--heli-hardware", action="store_true",
                    help="the additive helicopter Mu = My = 4 cores on ECP5, once (writes additive_heli_hw.json)")
    a = ap.parse_args(argv)
    br.check_count("--runs", a.runs)
    a.outdir.mkdir(parents=True, exist_ok=True)
    if a.heli_hardware:
        hw = run_heli_hardware(workdir=a.workdir)
        atomic_write_text(a.outdir / "additive_heli_hw.json", json.dumps(hw, indent=1) + "\n")
        atomic_write_text(a.outdir / "additive_heli_hw.md", heli_hardware_markdown(hw))
        print(heli_hardware_markdown(hw))
        return 0
    if a.hardware:
        hw = run_hardware(synth=a.synth, workdir=a.workdir)
        atomic_write_text(a.outdir / "additive_hw.json", json.dumps(hw, indent=1) + "\n")
        atomic_write_text(a.outdir / "additive_hw.md", hardware_markdown(hw))
        print(hardware_markdown(hw))
        return 0
    doc, _ = run_additive(a.runs, a.quick)
    name = f"{BENCH}_quick" if a.quick else BENCH
    br.write_results(a.outdir / f"{name}.json", doc)
    atomic_write_text(a.outdir / f"{name}.md", markdown(doc))
    print(markdown(doc))
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
