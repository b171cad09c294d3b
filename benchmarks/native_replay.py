"""Replay speed of `pwas-hdl simulate --engine native` (Verilator C++ bench) against the cocotb bench.

Usage::

    python benchmarks/native_replay.py [--vectors 1000000] [--outdir benchmarks/results]

1. The paper's Table II sensor (Lorenz, My = 4, p = 7, N = 4096; sigma fixed at 3.2e-4, the value
   5-fold CV picks, to keep the run short) generated as the virtual-sensor top with the default
   options, and its 2000-sample test continuation replayed by ``simulate_data`` with the native
   engine and, for comparison, with the cocotb bench on Verilator (the same build options).
2. ``--vectors`` random input transfers (``sim/pwas_stimulus.sensor_codes``: random points,
   vertices, faces, corners, out-of-domain and whole-range codes) through the same design with
   the three standard runs of the RTL tests (full speed; random bubbles 30 % / backpressure 40 %;
   a reset in the middle of the stream, then the rest): every output compared with the bit-true model.

Speeds are samples (outputs) per second of simulation time measured inside each bench (the
C++ loop; the cocotb test) -- excluding the build (cached) and the Python-side preparation, which
are reported separately. Nothing asserts on time; the mismatch counts must be 0.
Writes ``native_replay.json`` and ``native_replay.md`` into ``--outdir``.
"""

from __future__ import annotations

import sys

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

from pwas_hdl.bench_results import default_outdir, scratch_folder

HERE = Path(__file__).resolve().parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vectors", type=int, default=1_000_000,
                    help="random input vectors (1..1000000, pwas_hdl.limits.MAX_SAMPLES)")
    ap.add_argument("--outdir", type=Path, default=default_outdir())
    ap.add_argument("--md-only", action="store_true", help="rebuild native_replay.md from native_replay.json")
    args = ap.parse_args()
    from pwas_hdl.bench_results import check_count
    from pwas_hdl.limits import MAX_SAMPLES

    check_count("--vectors", args.vectors, MAX_SAMPLES)
    if args.md_only:
        write_md(json.loads((args.outdir / "native_replay.json").read_text()), args.outdir)
        return

    from pwas_hdl.design.generate import generate
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.io.csv_table import write_csv
    from pwas_hdl.systems.lorenz import lorenz
    from pwas_hdl.verify.simulation import load_design, run_rtl, sim_module, simulate_data, standard_runs

    with scratch_folder("pwas-native-bench-") as root:
        d = lorenz(8003, seed=0)
        train, test = d.split(6000)
        m = PWASVirtualSensor(my=4, partitions=7, gamma=1.2, sigma=3.2e-4, output_names=["y"], target_names=["z"])
        m.fit(None, train.y, train.z)
        generate(m, root / "sensor", design="sensor")
        write_csv(root / "test.csv", test.columns())
        result: dict = {"machine": {"python": platform.python_version(), "processor": platform.processor() or platform.machine()},
                        "design": "Table II sensor (My = 4, p = 7, N = 4096), generate --design sensor (defaults)"}

        lorenz_rows = {}
        for engine in ("native", "cocotb"):
            t0 = time.perf_counter()
            r = simulate_data(root / "sensor", root / "test.csv", root / f"{engine}.csv", simulator="verilator", engine=engine)
            s = r["summary"]
            lorenz_rows[engine] = {
                "samples": s["samples"], "mismatches": s["mismatches"], "samples_per_second": s["samples_per_second"],
                "simulation_seconds": s["simulation_seconds"], "build_seconds": s["build_seconds"], "build_reused": s["build_reused"],
                "total_seconds": time.perf_counter() - t0, "rmsee_hw": s["targets"]["z"]["rmsee_hw"],
                "latency_cycles": s["latency_cycles"]["measured_max"], "ii": s["ii"]["measured"],
            }
            print(f"lorenz test set, {engine}: {s['samples']} samples, {s['mismatches']} mismatches, "
                  f"{s['samples_per_second']:.4g} samples/s (build {s['build_seconds']:.1f} s)")
        result["lorenz_test_set"] = lorenz_rows
        same = (root / "native.csv").read_text() == (root / "cocotb.csv").read_text()
        result["lorenz_test_set"]["csv_identical"] = same

        design = load_design(root / "sensor")
        stim = sim_module("pwas_stimulus")
        t0 = time.perf_counter()
        codes = stim.sensor_codes(design.model, [f.get("signal", f["name"]) for f in design.in_fields], args.vectors, seed=1)
        runs = standard_runs(design, codes, seed=1, stalls=(0.7, 0.6))
        prep = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = run_rtl(design, runs, "verilator", engine="native", strict=False)
        wall = time.perf_counter() - t0
        per_run = []
        for run, rr in zip(runs, res.raw["runs"]):
            n_out = sum(int(sr["outputs"]) for sr in rr["segments"])
            per_run.append({"run": run.name, "p_valid": run.p_valid, "p_ready": run.p_ready, "outputs": n_out,
                            "mismatches": sum(int(sr["mismatches"]) for sr in rr["segments"]), "cycles": int(rr["cycles"]),
                            "seconds": float(rr["wall_s"]), "samples_per_second": n_out / float(rr["wall_s"]),
                            "cycles_per_second": int(rr["cycles"]) / float(rr["wall_s"])})
            print(f"{args.vectors} random vectors, {run.name}: {n_out} outputs, {per_run[-1]['mismatches']} mismatches, "
                  f"{per_run[-1]['samples_per_second']:.4g} samples/s, {per_run[-1]['cycles_per_second']:.4g} cycles/s")
        result["random_vectors"] = {
            "vectors": args.vectors, "runs": per_run, "outputs": res.outputs, "mismatches": res.mismatches, "passed": res.passed,
            "failures": res.failures[:5], "latencies": sorted(set(int(v) for v in res.latencies)), "ii": res.ii,
            "within_error_bound": res.within_bound, "samples_per_second": res.outputs / res.sim_seconds,
            "python_preparation_seconds": prep, "run_rtl_wall_seconds": wall,
            "end_to_end_samples_per_second": res.outputs / wall,
        }
        print(f"all: {res.outputs} outputs, {res.mismatches} mismatches, {res.outputs / res.sim_seconds:.4g} samples/s in the bench, "
              f"{res.outputs / wall:.4g} samples/s end to end (job writing, run, result reading; bit-true model {prep:.1f} s before)")
        args.outdir.mkdir(parents=True, exist_ok=True)
        (args.outdir / "native_replay.json").write_text(json.dumps(result, indent=2) + "\n")
        write_md(result, args.outdir)


def write_md(result: dict, outdir: Path) -> None:
    """``native_replay.md`` from the result dict (``--md-only`` rebuilds it from the JSON)."""
    L, R = result["lorenz_test_set"], result["random_vectors"]
    md = [
        "# Native replay speed (`pwas-hdl simulate --engine native`)",
        "",
        f"Design: {result['design']}. Written by `benchmarks/native_replay.py`; speeds are outputs per second of",
        "simulation time inside each bench (build cached and reported apart). The machine is shared (2 cores).",
        "",
        f"## Lorenz test set ({L['native']['samples']} estimates of the 2003-sample continuation)",
        "",
        "| engine | samples | mismatches | samples/s | simulation s | build s (reused) | RMSEE hw |",
        "|---|---|---|---|---|---|---|",
    ]
    for eng in ("native", "cocotb"):
        row = L[eng]
        md.append(f"| {eng} | {row['samples']} | {row['mismatches']} | {row['samples_per_second']:.4g} | {row['simulation_seconds']:.3g} | "
                  f"{row['build_seconds']:.1f} ({row['build_reused']}) | {row['rmsee_hw']:.5g} |")
    md += ["", f"Output CSVs of the two engines identical: {L['csv_identical']}.", "",
           f"## {R['vectors']} random input transfers (three runs: full speed, stalls, reset mid-stream)", "",
           "| run | p_valid | p_ready | outputs | mismatches | cycles | samples/s | cycles/s |", "|---|---|---|---|---|---|---|---|"]
    for row in R["runs"]:
        md.append(f"| {row['run']} | {row['p_valid']} | {row['p_ready']} | {row['outputs']} | {row['mismatches']} | {row['cycles']} | "
                  f"{row['samples_per_second']:.4g} | {row['cycles_per_second']:.4g} |")
    md += ["", f"All runs: {R['outputs']} outputs, {R['mismatches']} mismatches, latency {R['latencies']}, II {R['ii']}, "
           f"within the error bound: {R['within_error_bound']}; {R['samples_per_second']:.4g} samples/s in the bench, "
           f"{R['end_to_end_samples_per_second']:.4g} samples/s end to end of `run_rtl` (job file, run, result), after "
           f"{R['python_preparation_seconds']:.1f} s of stimulus and bit-true model in Python.", ""]
    (outdir / "native_replay.md").write_text("\n".join(md))
    print(f"wrote {outdir / 'native_replay.md'}")


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
