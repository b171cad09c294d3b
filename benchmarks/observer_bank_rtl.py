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
    from pwas_hdl.benchmarks.seed004_common import observer_rtl_rows

    t0 = time.perf_counter()
    configs = [CONFIGS[0], CONFIGS[7]] if quick else [c for c in CONFIGS if only in (None, c.get("architecture", "parallel"))]
    rows = observer_rtl_rows(configs, SIMULATORS[:1] if quick else SIMULATORS, partitions=3, prefix="pwas-obs-rtl-")
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

    from pwas_hdl.bench_results import checked_outdir, default_outdir, make_outdir

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the CI smoke: two configurations")
    ap.add_argument("--only", choices=["serial", "parallel"], default=None,
                    help="re-run the configurations of that bank and replace their rows in the results")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="output folder (default: %(default)s)")
    a = ap.parse_args(argv)
    checked_outdir(a.outdir)
    doc = run(a.quick, a.only)
    stem = "observer_bank_rtl_quick" if a.quick else "observer_bank_rtl"
    out = make_outdir(a.outdir)
    if a.only:  # a re-run of one bank's rows: replace them in the results
        from pwas_hdl.benchmarks.seed004_common import replace_rows

        doc["rows"], _ = replace_rows(out / f"{stem}.json", doc["rows"], lambda r: (r["config"], r["simulator"]))
    atomic_write_text(out / f"{stem}.json", json.dumps(doc, indent=1) + "\n")
    atomic_write_text(out / f"{stem}.md", markdown(doc))
    print(markdown(doc))
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main, sys.argv[1:]))
