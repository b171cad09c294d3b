"""Bit-exactness of observer-bank sensors on both simulators (issue 12): >= 6 configurations.

Each configuration (N_theta, M, gain, feature map, optional narrow states, parallel or serial
bank with its lanes) is fitted on seed 004
pv-benchmark data (2 000 training samples, p = 3, seed 0), generated with ``generate --design
sensor`` and replayed by the manifest-driven cocotb bench (``sim/pwas_tb.py``) on Icarus and on
Verilator: the three standard runs (full speed; random bubbles and backpressure; a reset in the
middle of a stream) over 400 transfers of :func:`sim.pwas_stimulus.observer_codes` (the quantised
test trajectory, steps, full-scale out-of-range codes, saturating alternations, silence).
Recorded: outputs, mismatches against the bit-true model, measured latency (== the manifest's)
and II, and whether the stimulus saturated an observer state.

``python -m pwas_hdl.benchmarks.observer_bank_rtl [--quick]`` writes ``results/observer_bank_rtl.{json,md}``.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

from pwas_hdl.io.atomic import atomic_write_text

CONFIGS = [
    dict(name="n2-m2-deadbeat-11b", n_models=2, order=2, observer="deadbeat", features="11b"),
    dict(name="n3-m5-deadbeat-11b", n_models=3, order=5, observer="deadbeat", features="11b"),
    dict(name="n4-m3-poles0.4-11b", n_models=4, order=3, observer="poles:0.4", features="11b"),
    dict(name="n5-m4-kalman1-11b-sq", n_models=5, order=4, observer="kalman:1", features="11b-sq"),
    dict(name="n7-m5-kalman0.1-11b", n_models=7, order=5, observer="kalman:0.1", features="11b"),
    dict(name="n3-m2-poles0.4-11b-sq", n_models=3, order=2, observer="poles:0.4", features="11b-sq"),
    dict(name="n2-m3-kalman1-11b-sq-saturating", n_models=2, order=3, observer="kalman:1", features="11b-sq", state_bits=14),
    # the time-multiplexed bank (generate --architecture serial [--bank-lanes L]): II = cycles per sample
    dict(name="serial-n3-m5-deadbeat-11b", n_models=3, order=5, observer="deadbeat", features="11b", architecture="serial"),
    dict(name="serial-n5-m4-kalman1-11b-sq-2lanes", n_models=5, order=4, observer="kalman:1", features="11b-sq",
         architecture="serial", bank_lanes=2),
    dict(name="serial-n7-m2-kalman0.1-11b-3lanes", n_models=7, order=2, observer="kalman:0.1", features="11b",
         architecture="serial", bank_lanes=3),
    dict(name="serial-n2-m3-kalman1-11b-sq-saturating", n_models=2, order=3, observer="kalman:1", features="11b-sq", state_bits=14,
         architecture="serial"),
]
SIMULATORS = ("icarus", "verilator")


def run(quick: bool = False, only: str | None = None) -> dict:
    """All configurations (``only="serial"`` / ``"parallel"``: those of that bank only) on both simulators."""
    from pwas_hdl.design.generate import generate
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset
    from pwas_hdl.verify.simulation import load_design, run_rtl, sim_module, standard_runs

    t0 = time.perf_counter()
    tr, te, _ = make_pv_dataset("pv-benchmark", 2000, 400, seed=0)
    stim = sim_module("pwas_stimulus")
    rows = []
    for cfg in [CONFIGS[0], CONFIGS[7]] if quick else [c for c in CONFIGS if only in (None, c.get("architecture", "parallel"))]:
        fe = ObserverBankFrontEnd(n_models=cfg["n_models"], observer=cfg["observer"], features=cfg["features"], order=cfg["order"])
        s = PWASVirtualSensor(mu=0, my=0, partitions=3, gamma=1.0, front_end=fe, sigma=1e-3).fit(tr.u, tr.y, tr.z)
        opts = {k: cfg[k] for k in ("state_bits", "architecture", "bank_lanes") if k in cfg}
        with tempfile.TemporaryDirectory(prefix="pwas-obs-rtl-") as tmp:
            generate(s, Path(tmp) / "d", design="sensor", **opts)
            d = load_design(Path(tmp) / "d")
            data, _ = d.bank.quantize_signals(te.u, te.y)
            codes = stim.observer_codes(d.bank.bank, 400, seed=5, data=data)
            sat = int(d.bank.bank.trace(codes)["state_saturated"].sum())
            for sim in SIMULATORS[:1] if quick else SIMULATORS:
                t1 = time.perf_counter()
                r = run_rtl(d, standard_runs(d, codes), sim)
                row = {"config": cfg["name"], "simulator": sim, "n_models": d.bank.bank.n_models, "order": d.bank.bank.order,
                       "observer": cfg["observer"], "features": cfg["features"], "state_bits": d.bank.bank.formats.state_bits,
                       "stimulus_state_saturations": sat, "outputs": r.outputs, "mismatches": r.mismatches, "passed": r.passed,
                       "bank": cfg.get("architecture", "parallel"), "bank_lanes": cfg.get("bank_lanes", 1 if "architecture" in cfg else None),
                       "latency_measured": sorted(set(r.latencies)), "latency_manifest": d.latency, "ii": r.ii,
                       "ii_manifest": int(d.manifest["ii"]),
                       "failures": r.failures[:3], "wall_s": round(time.perf_counter() - t1, 1)}
                print(json.dumps(row), flush=True)
                rows.append(row)
    return {"bench": "observer-bank-rtl", "quick": quick, "rows": rows, "elapsed_s": round(time.perf_counter() - t0, 1)}


def markdown(doc: dict) -> str:
    lines = [f"# Observer-bank sensors: bit-exact RTL on Icarus and Verilator{' (QUICK)' if doc['quick'] else ''}", "",
             "| configuration | bank | simulator | state bits | state saturations in stimulus | outputs | mismatches | "
             "latency (measured / manifest) | II (measured / manifest) |",
             "|---|---|---|---:|---:|---:|---:|---|---|"]
    for r in doc["rows"]:
        bank = r.get("bank", "parallel") + (f", {r['bank_lanes']} lane(s)" if r.get("bank_lanes") else "")
        lines.append(f"| {r['config']} | {bank} | {r['simulator']} | {r['state_bits']} | {r['stimulus_state_saturations']} | {r['outputs']} | "
                     f"{r['mismatches']} | {r['latency_measured']} / {r['latency_manifest']} | {r['ii']} / {r.get('ii_manifest', 1)} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m pwas_hdl.benchmarks.observer_bank_rtl [--quick] [--only serial|parallel] [--outdir DIR]``."""
    import argparse

    from pwas_hdl.bench_results import default_outdir

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the CI smoke: two configurations")
    ap.add_argument("--only", choices=["serial", "parallel"], default=None,
                    help="re-run the configurations of that bank and replace their rows in the results")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="output folder (default: %(default)s)")
    a = ap.parse_args(argv)
    doc = run(a.quick, a.only)
    stem = "observer_bank_rtl_quick" if a.quick else "observer_bank_rtl"
    out = a.outdir
    if a.only and (out / f"{stem}.json").exists():
        old = json.loads((out / f"{stem}.json").read_text())
        new = {(r["config"], r["simulator"]): r for r in doc["rows"]}
        doc["rows"] = [new.pop((r["config"], r["simulator"]), r) for r in old["rows"]] + list(new.values())
    atomic_write_text(out / f"{stem}.json", json.dumps(doc, indent=1) + "\n")
    atomic_write_text(out / f"{stem}.md", markdown(doc))
    print(markdown(doc))
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main, sys.argv[1:]))
