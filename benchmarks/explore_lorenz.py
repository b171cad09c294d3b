"""Bit-width exploration of the Lorenz sensor (Table II: My = 4, p = 7, N = 4096).

Usage::

    python benchmarks/explore_lorenz.py [--resources ecp5|generic|estimate] [--measure-max 10]
                                        [--workdir DIR] [--outdir benchmarks/results]

Runs the issue's recipe with the command line:

    pwas-hdl make-data lorenz --samples 6000 --test-output test.csv --test-samples 2003 -o train.csv
    pwas-hdl fit train.csv --output y --target z --my 4 -p 7 -o model.json      (sigma by 5-fold CV)
    pwas-hdl explore model.json test.csv -o explore --resources ecp5

i.e. input widths 8..16 (step 2) x weight and output fraction bits from generate's defaults -7 to
+2, the RMSEE of the bit-true estimate over the Ts = 2000 test estimates against the noise-free
z_true, the resource estimate of every point, and Yosys + nextpnr for the ECP5 LFE5U-45F (the
README's target) on up to ``--measure-max`` Pareto points and the default. Copies ``explore.json`` / ``explore.png`` to
``explore_lorenz.json`` / ``explore_lorenz.png`` in ``--outdir`` and writes ``explore_lorenz.md``
(the Pareto table and the default's verdict). Nothing here asserts on times.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pwas_hdl.bench_results import default_outdir
from pwas_hdl.io.atomic import atomic_write_text
from pwas_hdl.flow.explore import format_table

HERE = Path(__file__).resolve().parent


def cli(*args: str, cwd: Path) -> str:
    cmd = [sys.executable, "-m", "pwas_hdl.cli", *args]
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"failed: pwas-hdl {' '.join(args)}\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}")
    return r.stderr


def rounded(obj, digits: int = 7):
    """Floats to ``digits`` significant digits (the committed file stays small; the API keeps all)."""
    if isinstance(obj, float):
        return float(f"{obj:.{digits}g}")
    if isinstance(obj, dict):
        return {k: rounded(v, digits) for k, v in obj.items()}
    if isinstance(obj, list):
        return [rounded(v, digits) for v in obj]
    return obj


def verdict(res: dict) -> str:
    d = res["default"]
    p = res["points"][d["index"]]
    head = (f"Default of `generate` ({d['label']}): cost {p['cost']} bits, RMSEE {p['rmsee'][0]:.4f} "
            f"({(p['rmsee_ratio'] - 1) * 100:+.3f} % over the float model's {res['float']['rmsee'][0]:.4f}).")
    meas = res.get("measured")
    if meas and meas.get("default_on_front") is not None:
        head += (f" Among the synthesised points ({meas['target']}: LUTs, DSPs, block RAMs, RMSEE) it is "
                 f"**{'on' if meas['default_on_front'] else 'not on'}** their front.")
    if d["on_front"]:
        return head + " It is **on** the Pareto front of the estimate."
    lines = [head, "", f"It is **not** on the Pareto front of the estimate: {len(d['dominated_by'])} front point(s) dominate it, e.g.", ""]
    lines += ["| dominating point | cost saved | RMSEE better by | standard error of the difference |", "|---|---:|---:|---:|"]
    for e in d["dominated_by"][:8]:
        lines.append(f"| {e['label']} | {e['cost_saved']} ({100 * e['cost_saved_rel']:.1f} %) | {e['rmsee_better'][0]:+.4f} | "
                     f"{e['rmsee_diff_se'][0]:.3f} |")
    return "\n".join(lines)


def markdown(res: dict, resources: str) -> str:
    """``explore_lorenz.md``: the sweep, the Pareto table and the default's verdict."""
    sw = res["sweep"]
    md = [
        "# Lorenz sensor: bit-width exploration",
        "",
        f"`python benchmarks/explore_lorenz.py --resources {resources}` (model: My = 4, p = 7, N = 4096, sigma by CV; "
        f"{res['data']['samples']} test estimates against `z_true`). Sweep: input bits {sw['input_bits']}, weight fraction "
        f"bits {sw['weight_frac'][0]}..{sw['weight_frac'][-1]}, output fraction bits {sw['output_frac'][0]}..{sw['output_frac'][-1]} "
        f"(generate's defaults: {sw['default_weight_frac']} and {sw['default_output_frac']}); widths the fewest bits that hold "
        f"every weight / output; {len(res['points'])} formats evaluated, {len(res['refused'])} refused, "
        f"{len(res['pareto'])} on the front (cost = {res['resource_model']['cost']}, accuracy = bit-true RMSEE). "
        f"Explore took {res['benchmark']['seconds']['explore']} s.",
        "",
        "Pareto points (and the default):",
        "",
        format_table(res),
        verdict(res),
        "",
    ]
    return "\n".join(md)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resources", default="ecp5", choices=["estimate", "generic", "ecp5", "ice40"])
    ap.add_argument("--measure-max", type=int, default=10)
    ap.add_argument("--workdir", type=Path, default=None, help="keep the data, model and exploration here")
    ap.add_argument("--outdir", type=Path, default=default_outdir())
    args = ap.parse_args()

    own = args.workdir is None
    work = Path(tempfile.mkdtemp(prefix="explore-lorenz-")) if own else args.workdir.resolve()
    work.mkdir(parents=True, exist_ok=True)
    try:
        t0 = time.perf_counter()
        cli("make-data", "lorenz", "--samples", "6000", "--test-output", "test.csv", "--test-samples", "2003",
            "-o", "train.csv", cwd=work)
        fit_log = cli("fit", "train.csv", "--output", "y", "--target", "z", "--my", "4", "-p", "7", "-o", "model.json", cwd=work)
        t1 = time.perf_counter()
        measure = ["--measure-max", str(args.measure_max)] if args.resources != "estimate" else []  # refused without synthesis
        log = cli("explore", "model.json", "test.csv", "-o", "explore", "--resources", args.resources, *measure, cwd=work)
        t2 = time.perf_counter()
        res = json.loads((work / "explore" / "explore.json").read_text())
        res["benchmark"] = {
            "script": "benchmarks/explore_lorenz.py",
            "recipe": [
                "pwas-hdl make-data lorenz --samples 6000 --test-output test.csv --test-samples 2003 -o train.csv",
                "pwas-hdl fit train.csv --output y --target z --my 4 -p 7 -o model.json",
                f"pwas-hdl explore model.json test.csv -o explore --resources {args.resources} --measure-max {args.measure_max}",
            ],
            "fit_log": fit_log.strip().splitlines(),
            "explore_log": log.strip().splitlines()[-2:],
            "seconds": {"data_and_fit": round(t1 - t0, 1), "explore": round(t2 - t1, 1)},
            "platform": {"python": platform.python_version(), "machine": platform.machine(), "cpus": os.cpu_count()},
        }
        args.outdir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(args.outdir / "explore_lorenz.json", json.dumps(rounded(res), separators=(",", ":"), allow_nan=False) + "\n")
        shutil.copyfile(work / "explore" / "explore.png", args.outdir / "explore_lorenz.png")
        md = markdown(res, args.resources)
        atomic_write_text(args.outdir / "explore_lorenz.md", md)
        print(md)
    finally:
        if own:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
