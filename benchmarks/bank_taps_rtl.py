"""Observer-bank sensors with u/y taps on both simulators (issue 12): bit-exact RTL, several tap layouts.

Each configuration (N_theta, M, gain, feature map, taps ``--mu/--my``, optional narrow states) is
fitted on seed 004 pv-benchmark data (two inputs u1, u2; 2 000 training samples, p = 2, seed 0),
generated with ``generate --design sensor`` (the tapped top, :mod:`pwas_hdl.hdl.observer_tap_sensor_top`)
and replayed by the manifest-driven cocotb bench (``sim/pwas_tb.py``) on Icarus and on Verilator:
the standard runs (full speed; random bubbles and backpressure; a reset in the middle of a
stream) over 400 transfers of :func:`sim.pwas_stimulus.observer_codes` (the quantised test
trajectory, steps, full-scale out-of-range codes, saturating alternations, silence). The ``serial-``
configurations are generated with ``--architecture serial --bank-lanes L`` (the time-multiplexed
bank; II = the manifest's cycles_per_sample, measured at full speed). Recorded as
:mod:`pwas_hdl.benchmarks.observer_bank_rtl` (same table), plus the taps.

``python -m pwas_hdl.benchmarks.bank_taps_rtl [--quick]`` writes ``results/bank_taps_rtl.{json,md}``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from pwas_hdl.io.atomic import atomic_write_text

CONFIGS = [
    dict(name="n2-m5-deadbeat-11b-mu1-my1", n_models=2, order=5, observer="deadbeat", features="11b", mu=1, my=1),
    dict(name="n3-m3-kalman0.1-11b-mu2-my0", n_models=3, order=3, observer="kalman:0.1", features="11b", mu=2, my=0),
    dict(name="n2-m2-poles0.4-11b-sq-mu0-my3", n_models=2, order=2, observer="poles:0.4", features="11b-sq", mu=0, my=3),
    dict(name="n2-m3-kalman1-11b-sq-mu1-my2-saturating", n_models=2, order=3, observer="kalman:1", features="11b-sq", mu=1, my=2,
         state_bits=14),
    # the serial (time-multiplexed) bank with the taps: generate --architecture serial --bank-lanes L
    dict(name="serial-n2-m5-deadbeat-11b-mu1-my1-1lane", n_models=2, order=5, observer="deadbeat", features="11b", mu=1, my=1,
         architecture="serial", bank_lanes=1),
    dict(name="serial-n3-m3-kalman0.1-11b-mu2-my0-3lanes", n_models=3, order=3, observer="kalman:0.1", features="11b", mu=2,
         my=0, architecture="serial", bank_lanes=3),
    dict(name="serial-n2-m3-kalman1-11b-sq-mu1-my2-saturating-2lanes", n_models=2, order=3, observer="kalman:1",
         features="11b-sq", mu=1, my=2, state_bits=14, architecture="serial", bank_lanes=2),
]
SIMULATORS = ("icarus", "verilator")


def run(quick: bool = False) -> dict:
    """All layouts on both simulators (``quick``: the first on Icarus)."""
    from pwas_hdl.benchmarks.seed004_common import observer_rtl_rows

    t0 = time.perf_counter()
    rows = observer_rtl_rows(
        CONFIGS[:1] if quick else CONFIGS, SIMULATORS[:1] if quick else SIMULATORS,
        mu=lambda cfg: cfg["mu"], my=lambda cfg: cfg["my"], partitions=2, prefix="pwas-taps-rtl-",
        extra=lambda cfg, d: {"mu": cfg["mu"], "my": cfg["my"], "taps": d.manifest["lags"]["regressors"][d.bank.bank.n_models:],
                              "warmup": d.warmup})
    return {"bench": "bank-taps-rtl", "quick": quick, "rows": rows, "elapsed_s": round(time.perf_counter() - t0, 1)}


def markdown(doc: dict) -> str:
    lines = [f"# Observer-bank sensors with u/y taps: bit-exact RTL on Icarus and Verilator{' (QUICK)' if doc['quick'] else ''}", "",
             "| configuration | taps | simulator | state bits | state saturations in stimulus | outputs | mismatches | "
             "latency (measured / manifest) | II (measured / manifest) | warm-up |",
             "|---|---|---|---:|---:|---:|---:|---|---|---:|"]
    for r in doc["rows"]:
        lines.append(f"| {r['config']} | {', '.join(r['taps'])} | {r['simulator']} | {r['state_bits']} | {r['stimulus_state_saturations']} | "
                     f"{r['outputs']} | {r['mismatches']} | {r['latency_measured']} / {r['latency_manifest']} | "
                     f"{r['ii']} / {r.get('ii_manifest', 1)} | {r['warmup']} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m pwas_hdl.benchmarks.bank_taps_rtl [--quick] [--outdir DIR]``."""
    import argparse

    from pwas_hdl.bench_results import checked_outdir, default_outdir, make_outdir

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the CI smoke: fewer layouts and samples")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="output folder (default: %(default)s)")
    a = ap.parse_args(argv)
    checked_outdir(a.outdir)
    doc = run(a.quick)
    stem = "bank_taps_rtl_quick" if a.quick else "bank_taps_rtl"
    make_outdir(a.outdir)
    atomic_write_text(a.outdir / f"{stem}.json", json.dumps(doc, indent=1) + "\n")
    atomic_write_text(a.outdir / f"{stem}.md", markdown(doc))
    print(markdown(doc))
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main, sys.argv[1:]))
