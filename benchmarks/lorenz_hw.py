"""The full Lorenz test set replayed through the generated RTL (Icarus and Verilator, cocotb).

Usage::

    python benchmarks/lorenz_hw.py [--seeds 5] [--bits 8,10,12,14,16] [--workdir DIR] [--outdir benchmarks/results]

Seed 0 follows the issue's recipe with the command line, exactly:

    pwas-hdl make-data lorenz --samples 6000 --test-output test.csv --test-samples 2003 -o train.csv
    pwas-hdl fit train.csv --output y --target z --my 4 -p 7 -o model.json      (sigma by 5-fold CV)
    pwas-hdl generate model.json --design sensor -o sensor   (and the core: -o core)
    pwas-hdl simulate sensor test.csv --simulator icarus|verilator -o hw.csv

(the Table II sensor: My = 4, p = 7, gamma = 1.2, N = 4096, 12-bit inputs; Ts = 2000 estimates
against the noise-free z). The RMSEE of the hardware estimate is reported beside the float
model's and beside the paper's 12-bit FPGA figure (27.05, against 22.45 in float: +20 %).
Then, on Icarus and through the API: the same replay for seeds 1..K-1 (does the quantisation loss
depend on the fit?) and an input word-length sweep at seed 0 (``--bits``).

Writes ``lorenz_hw.json`` and ``lorenz_hw.md`` into ``--outdir``. Every replay must be bit-exact
(0 mismatches); the script exits 1 otherwise. Nothing here asserts on times.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pwas_hdl.bench_results import default_outdir
from pwas_hdl.design.manifest import load_manifest
from pwas_hdl.io.atomic import atomic_write_text

HERE = Path(__file__).resolve().parent
PAPER = {"rmsee_float": 22.45, "rmsee_fpga_12bit": 27.05}


def cli(*args: str, cwd: Path) -> None:
    cmd = [sys.executable, "-m", "pwas_hdl.cli", *args]
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"failed: pwas-hdl {' '.join(args)}\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}")


def replay_cli(design: str, simulator: str, work: Path, cache: Path) -> dict:
    out = f"hw_{design}_{simulator}.csv"
    t0 = time.perf_counter()
    cli("simulate", design, "test.csv", "--simulator", simulator, "-o", out, "--build-dir", str(cache), cwd=work)
    s = json.loads((work / out).with_suffix(".json").read_text())
    s["cli_seconds"] = time.perf_counter() - t0
    return s


def row_of(s: dict, label: str, **extra) -> dict:
    z = s["targets"]["z"]
    return {
        "label": label,
        "design": s["kind"],
        "simulator": s["simulator"],
        "samples": s["samples"],
        "mismatches": s["mismatches"],
        "rmsee_float": z["rmsee_float"],
        "rmsee_bittrue": z["rmsee_bittrue"],
        "rmsee_hw": z["rmsee_hw"],
        "increase_percent": z["rmsee_increase_hw_vs_float_percent"],
        "max_err_vs_float_lsb": s["max_error_vs_float_lsb"],
        "error_bound_lsb": s["error_bound_lsb"],
        "output_lsb": s["output_lsb"],
        "out_of_range": s["out_of_range"],
        "latency_manifest": s["latency_cycles"]["manifest"],
        "latency_measured": [s["latency_cycles"]["measured_min"], s["latency_cycles"]["measured_max"]],
        "ii_measured": s["ii"]["measured"],
        "samples_per_second": s["samples_per_second"],
        "cycles_per_second": s["cycles_per_second"],
        "build_seconds": s["build_seconds"],
        "build_reused": s["build_reused"],
        "simulator_process_seconds": s["simulator_process_seconds"],
        **extra,
    }


def api_replay(seed: int, bits: int, work: Path, cache: Path, simulator: str = "icarus") -> dict:
    """make-data / fit (CV) / generate sensor / simulate through the Python API."""
    from pwas_hdl.io.csv_table import write_csv
    from pwas_hdl.design.generate import generate
    from pwas_hdl.systems.lorenz import lorenz
    from pwas_hdl.verify.simulation import simulate_data
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    d = lorenz(6000 + 2003, seed=seed)
    train, test = d.split(6000)
    folder = work / f"seed{seed}_b{bits}"
    folder.mkdir(parents=True, exist_ok=True)
    write_csv(folder / "test.csv", test.columns())
    model_file = work / f"model_seed{seed}.json"
    if model_file.is_file():
        m = PWASVirtualSensor.load(model_file)
    else:
        m = PWASVirtualSensor(my=4, partitions=7, gamma=1.2, output_names=["y"], target_names=["z"]).fit(None, train.y, train.z)
        m.save(model_file)
    generate(m, folder / "sensor", design="sensor", input_bits=bits)
    res = simulate_data(folder / "sensor", folder / "test.csv", folder / "hw.csv", simulator=simulator, cache_dir=cache)
    return res["summary"]


def fmt(v, nd=2):
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{nd}f}"
    return str(v)


def markdown(res: dict) -> str:
    p = res["paper"]
    lines = [
        "# Lorenz test set through the RTL (cocotb: Icarus, Verilator)",
        "",
        f"Generated by `python benchmarks/lorenz_hw.py {res['args']}`; numbers in `lorenz_hw.json`.",
        "",
        "Table II sensor (My = 4, p = 7, gamma = 1.2, N = 4096, sigma by 5-fold CV, 12-bit inputs), seed 0,",
        "Ts = 2000 estimates against the noise-free z. Made with the CLI exactly as in the script's docstring.",
        "",
        "| design | simulator | samples | mismatches vs bit-true | RMSEE float | RMSEE hardware | increase | paper float | paper 12-bit FPGA | paper increase | max err vs float (LSB) | bound (LSB) | latency manifest / measured | II | sim speed (samples/s) | build (s) |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in res["main"]:
        lat = r["latency_measured"]
        lines.append(
            f"| {r['design']} | {r['simulator']} | {r['samples']} | {r['mismatches']} | {fmt(r['rmsee_float'])} | {fmt(r['rmsee_hw'])} | "
            f"{fmt(r['increase_percent'])} % | {p['rmsee_float']} | {p['rmsee_fpga_12bit']} | "
            f"{100 * (p['rmsee_fpga_12bit'] / p['rmsee_float'] - 1):.1f} % | {fmt(r['max_err_vs_float_lsb'], 3)} | "
            f"{fmt(r['error_bound_lsb'], 3)} | {r['latency_manifest']} / {lat[0]}..{lat[1]} | {fmt(r['ii_measured'], 0)} | "
            f"{r['samples_per_second']:.0f} | {r['build_seconds']:.1f}{' (cached)' if r['build_reused'] else ''} |"
        )
    m0 = res["main"][0]
    lines += [
        "",
        f"Output LSB {m0['output_lsb']} (default formats: quantisation noise <= 5 % of the train RMSE, pwas_hdl.fixedpoint.bittrue.default_weight_frac); the hardware RMSEE equals the",
        "bit-true model's to the last digit (every output identical). Simulation speed is measured inside the",
        "simulator for the replay (cocotb drives one transfer per clock); builds are cached by the hash of the",
        "Verilog (the first Verilator build also compiles Verilator's run-time library, later ones reuse it).",
        "",
    ]
    if res.get("seeds"):
        lines += ["## Other seeds (sensor, Icarus, 12-bit inputs)", "",
                  "| seed | RMSEE float | RMSEE hardware | increase | mismatches |", "|---:|---:|---:|---:|---:|"]
        for r in res["seeds"]:
            lines.append(f"| {r['seed']} | {fmt(r['rmsee_float'])} | {fmt(r['rmsee_hw'])} | {fmt(r['increase_percent'])} % | {r['mismatches']} |")
        inc = [r["increase_percent"] for r in res["seeds"]]
        lines += ["", f"Increase over seeds: mean {np.mean(inc):.2f} %, max {np.max(inc):.2f} % (paper at 12 bits: "
                  f"{100 * (p['rmsee_fpga_12bit'] / p['rmsee_float'] - 1):.1f} %).", ""]
    if res.get("bits"):
        lines += ["## Input word length (sensor, Icarus, seed 0)", "",
                  "| input bits | input LSB (y units) | RMSEE float | RMSEE hardware | increase | mismatches | out of range |",
                  "|---:|---:|---:|---:|---:|---:|---:|"]
        for r in res["bits"]:
            lines.append(f"| {r['input_bits']} | {r['input_lsb']:.3g} | {fmt(r['rmsee_float'])} | {fmt(r['rmsee_hw'])} | "
                         f"{fmt(r['increase_percent'])} % | {r['mismatches']} | {r['out_of_range']} |")
        lines.append("")
    env = res["environment"]
    lines.append(f"Environment: {env['simulators']['icarus']}; {env['simulators']['verilator']}; cocotb {env['cocotb']}; "
                 f"Python {env['python']}; {env['cpus']} CPUs. Total run time {res['total_seconds']:.0f} s.")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5, help="seeds 0..K-1 for the per-seed table (default 5; 1 = seed 0 only; 1..1000, pwas_hdl.limits.MAX_BENCH_COUNT)")
    ap.add_argument("--bits", default="8,10,12,14,16", help="input word lengths of the sweep ('' = none)")
    ap.add_argument("--workdir", type=Path, default=None, help="keep the data, models, designs and outputs here")
    ap.add_argument("--outdir", type=Path, default=default_outdir())
    args = ap.parse_args(argv)
    from pwas_hdl.bench_results import check_count, portable_paths

    check_count("--seeds", args.seeds)
    t_start = time.perf_counter()
    tmp = None
    if args.workdir is None:
        tmp = tempfile.TemporaryDirectory(prefix="lorenz_hw-")
        work = Path(tmp.name)
    else:
        work = args.workdir
        work.mkdir(parents=True, exist_ok=True)
    cache = work / "sim-cache"

    # ---- seed 0 with the CLI, both designs, both simulators
    cli("make-data", "lorenz", "--samples", "6000", "--test-output", "test.csv", "--test-samples", "2003", "-o", "train.csv", cwd=work)
    cli("fit", "train.csv", "--output", "y", "--target", "z", "--my", "4", "-p", "7", "-o", "model.json", cwd=work)
    cli("generate", "model.json", "--design", "sensor", "-o", "sensor", cwd=work)
    cli("generate", "model.json", "--design", "core", "-o", "core", cwd=work)
    main_rows = []
    for design in ("sensor", "core"):
        for simulator in ("icarus", "verilator"):
            s = replay_cli(design, simulator, work, cache)
            main_rows.append(row_of(s, f"{design}-{simulator}"))
            print(f"{design:6s} {simulator:9s} mismatches {s['mismatches']}  RMSEE hw {s['targets']['z']['rmsee_hw']:.3f} "
                  f"float {s['targets']['z']['rmsee_float']:.3f}  latency {s['latency_cycles']}  II {s['ii']['measured']}  "
                  f"{s['samples_per_second']:.0f} samples/s", flush=True)
    model = json.loads((work / "model.json").read_text())

    # ---- other seeds and the word-length sweep (API, Icarus)
    seeds = []
    for seed in range(1, args.seeds):
        s = api_replay(seed, 12, work, cache)
        seeds.append({"seed": seed, **{k: v for k, v in row_of(s, f"seed{seed}").items() if k != "label"}})
        print(f"seed {seed}: RMSEE hw {seeds[-1]['rmsee_hw']:.3f} float {seeds[-1]['rmsee_float']:.3f}", flush=True)
    if seeds:
        r0 = main_rows[0]
        seeds.insert(0, {"seed": 0, **{k: v for k, v in r0.items() if k != "label"}})
    bits = []
    for b in [int(v) for v in args.bits.split(",") if v.strip()]:
        s = api_replay(0, b, work, cache)
        man = load_manifest(work / f"seed0_b{b}" / "sensor")
        lsb = man["formats"]["inputs"][0]["lsb"]  # physical LSB of the input codes
        bits.append({"input_bits": b, "input_lsb": float(lsb), **{k: v for k, v in row_of(s, f"bits{b}").items() if k != "label"}})
        print(f"{b:2d}-bit inputs: RMSEE hw {bits[-1]['rmsee_hw']:.3f} (+{bits[-1]['increase_percent']:.2f} %)", flush=True)

    import cocotb

    sim_runner = __import__("pwas_hdl.verify.simulation", fromlist=["sim_module"]).sim_module("pwas_runner")
    res = {
        "format": "pwas-hdl-lorenz-hw",
        "version": 1,
        # the command line without machine paths (--workdir /tmp/x is recorded as --workdir x)
        "args": portable_paths(" ".join(argv if argv is not None else sys.argv[1:])),
        "recipe": "make-data lorenz --samples 6000 --test-output test.csv --test-samples 2003 (seed 0); fit --my 4 -p 7 "
                  "(gamma 1.2, sigma by 5-fold CV); generate --design sensor|core (12-bit inputs); simulate test.csv",
        "model": {"sigma": model["fit"]["sigma"], "train_rmse": model["fit"]["train_rmse"], "N": 4096},
        "paper": PAPER,
        "main": main_rows,
        "seeds": seeds,
        "bits": bits,
        "all_bit_exact": all(r["mismatches"] == 0 for r in main_rows + seeds + bits),
        "environment": {
            "python": platform.python_version(),
            "cocotb": cocotb.__version__,
            "simulators": {s: sim_runner.tool_versions(s) for s in ("icarus", "verilator")},
            "cpus": os.cpu_count(),
        },
        "total_seconds": time.perf_counter() - t_start,
    }
    args.outdir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.outdir / "lorenz_hw.json", json.dumps(res, indent=1, allow_nan=False) + "\n")
    md = markdown(res)
    atomic_write_text(args.outdir / "lorenz_hw.md", md)
    print()
    print(md)
    if tmp is not None:
        tmp.cleanup()
    return 0 if res["all_bit_exact"] else 1


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
