"""Measured speed-up of the Dask execution layer on this machine, and a scale note.

Usage::

    python benchmarks/distributed_speedup.py [--workers 2 | --scheduler tcp://HOST:PORT] [--quick] [--outdir benchmarks/results]

Runs two sweeps twice, serially and on a local Dask cluster of ``--workers`` processes (or an existing
cluster, ``--scheduler``), checks that
the results are identical (timings aside) and writes ``distributed_speedup.{json,md}``:

* ``hw_tables``: the place-and-route runs of ``benchmarks/hw_tables.py`` for the small Lorenz
  designs (``lorenz_my4_p3``, ``lorenz_my4_p1``; short, fast and replicated builds on ECP5: six
  independent nextpnr runs);
* ``explore``: ``explore --resources ecp5`` of a small Lorenz model (every measured Pareto point is
  one Yosys + nextpnr task).

``--quick`` (CI smoke) runs a 4-task toy workload instead of place and route and writes
``distributed_speedup_quick.*``. The scale note in the output estimates the wall time on N workers
from the measured task times (longest-processing-time schedule), assuming one core per worker and a
shared file system; nothing here asserts on times.
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
from typing import Any

import numpy as np

from pwas_hdl.bench_results import default_outdir
from pwas_hdl.flow.executor import Executor, environment_versions
from pwas_hdl.io.atomic import atomic_write_text

HERE = Path(__file__).resolve().parent


def _without_timings(obj):
    if isinstance(obj, dict):
        return {k: _without_timings(v) for k, v in obj.items()
                if not any(t in k for t in ("time", "runtime", "_s", "wall", "execution", "workdir"))}
    if isinstance(obj, list):
        return [_without_timings(v) for v in obj]
    return obj


def _differences(a, b, path: str = "") -> list[str]:
    """Paths (``/key[i]/...``) where two JSON-like values differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{path}/{k}: only in one run" for k in sorted(set(a) ^ set(b))]
        for k in sorted(set(a) & set(b)):
            out += _differences(a[k], b[k], f"{path}/{k}")
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _differences(x, y, f"{path}[{i}]")]
    return [] if a == b else [f"{path}: {json.dumps(a)[:200]} != {json.dumps(b)[:200]}"]


def _lpt_makespan(durations: list[float], workers: int) -> float:
    """Wall time of the longest-processing-time-first schedule of ``durations`` on ``workers``."""
    loads = [0.0] * max(1, workers)
    for d in sorted(durations, reverse=True):
        loads[loads.index(min(loads))] += d
    return max(loads)


def _hw_tables(workers: int | None, outdir: Path, scheduler: str | None = None) -> tuple[dict[str, Any], float]:
    cmd = [sys.executable, str(HERE / "hw_tables.py"), "--designs", "lorenz_my4_p3,lorenz_my4_p1", "--fpga", "ecp5",
           "--outdir", str(outdir), "--workdir", str(outdir / "work")]
    if workers and scheduler:
        cmd += ["--scheduler", scheduler]
    elif workers:
        cmd += ["--workers", str(workers)]
    t0 = time.monotonic()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    wall = time.monotonic() - t0
    return json.loads((outdir / "hw_tables.json").read_text()), wall


def _explore(workers: int | None, root: Path, scheduler: str | None = None) -> tuple[dict[str, Any], float]:
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.flow.explore import explore
    from pwas_hdl.io.csv_table import write_csv
    from pwas_hdl.systems.lorenz import lorenz

    d = lorenz(2300, seed=0)
    train, test = d.split(2000)
    m = PWASVirtualSensor(my=3, partitions=3, gamma=1.2, sigma=1e-4, output_names=["y"], target_names=["z"])
    m.fit(None, train.y, train.z)
    data = root.parent / "explore_test.csv"  # one file for both runs: its path is part of the result
    write_csv(data, test.columns())
    t0 = time.monotonic()
    with Executor(workers=workers, scheduler=scheduler if workers else None) as ex:
        res = explore(m, data, input_bits=[8, 10, 12], resources="ecp5", measure_max=5, executor=ex)
    return res, time.monotonic() - t0


def _toy(x: float) -> float:
    t_end = time.monotonic() + x
    acc = 0.0
    while time.monotonic() < t_end:
        acc += float(np.sum(np.arange(1000.0) ** 0.5))
    return round(x, 3)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scheduler", default=None,
                    help="run the distributed half on an existing Dask cluster (tcp://HOST:PORT) instead of a LocalCluster of --workers")
    ap.add_argument("--quick", action="store_true", help="a 4-task toy workload (CI smoke)")
    ap.add_argument("--outdir", type=Path, default=default_outdir())
    ap.add_argument("--sweeps", default="hw_tables,explore", help="comma list of hw_tables, explore")
    args = ap.parse_args(argv)
    out: dict[str, Any] = {"format": "pwas-hdl-bench-distributed", "version": 1, "workers": args.workers,
                           "environment": {"python": platform.python_version(), "cpus": os.cpu_count(),
                                           "load_avg_at_start": os.getloadavg(), "tools": environment_versions()},
                           "sweeps": {}}
    with tempfile.TemporaryDirectory(prefix="pwas-dist-") as tmp:
        tmp = Path(tmp)
        if args.quick:
            items = [0.2, 0.2, 0.2, 0.2]
            t0 = time.monotonic()
            serial = Executor().map(_toy, items)
            ts = time.monotonic() - t0
            t0 = time.monotonic()
            with Executor(workers=args.workers, scheduler=args.scheduler) as ex:
                dist = ex.map(_toy, items)
            td = time.monotonic() - t0
            out["sweeps"]["toy"] = {"tasks": len(items), "serial_s": round(ts, 2), "distributed_s": round(td, 2),
                                    "speedup": round(ts / td, 2), "identical": serial == dist,
                                    "note": "includes the LocalCluster start-up (about 2-4 s)" if args.scheduler is None else "on an existing cluster (--scheduler)"}
        else:
            chosen = [x.strip() for x in args.sweeps.split(",") if x.strip()]
            for name, fn in (("hw_tables", _hw_tables), ("explore", _explore)):
                if name not in chosen:
                    continue
                (tmp / f"{name}_s").mkdir()
                (tmp / f"{name}_d").mkdir()
                print(f"{name}: serial ...", flush=True)
                a, ts = fn(None, tmp / f"{name}_s")
                print(f"{name}: {args.workers} workers ...", flush=True)
                b, td = fn(args.workers, tmp / f"{name}_d", args.scheduler)
                diffs = _differences(_without_timings(a), _without_timings(b))
                same = not diffs
                rec: dict[str, Any] = {"serial_s": round(ts, 1), "distributed_s": round(td, 1), "speedup": round(ts / td, 2),
                                       "identical": same, "differences": diffs[:20]}
                if name == "hw_tables":
                    runs = [bb for dd in a["designs"] for f in dd["builds"].values() for bb in f.values()]
                    durs = [float(bb["runtime_s"]) for bb in runs]
                    rec["tasks"] = len(durs)
                    rec["task_s"] = durs
                    rec["data_per_task"] = "the model file path (a few kB of JSON) and the build options; each task writes its own place-and-route folder"
                    rec["expected_wall_s_on_N_workers"] = {str(n): round(_lpt_makespan(durs, n), 1) for n in (1, 2, 4, 8, 16)}
                else:
                    rec["tasks"] = len(a["measured"]["points"])
                    rec["data_per_task"] = "the fitted sensor (pickled, N weights as float64) and one point's formats"
                out["sweeps"][name] = rec
                print(f"{name}: serial {ts:.1f} s, {args.workers} workers {td:.1f} s, x{ts / td:.2f}, identical {same}", flush=True)
    out["environment"]["load_avg_at_end"] = os.getloadavg()
    stem = "distributed_speedup_quick" if args.quick else "distributed_speedup"
    args.outdir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.outdir / f"{stem}.json", json.dumps(out, indent=1) + "\n")
    lines = ["# Dask execution layer: measured speed-up", "",
             f"Generated by `python benchmarks/distributed_speedup.py{' --quick' if args.quick else ''} --workers {args.workers}` "
             f"on {os.cpu_count()} CPUs (load average at start {out['environment']['load_avg_at_start'][0]:.1f}: "
             "the machine may have been shared with other jobs).", "",
             "| sweep | tasks | serial (s) | distributed (s) | speed-up | identical results |", "|---|---:|---:|---:|---:|---|"]
    for name, r in out["sweeps"].items():
        lines.append(f"| {name} | {r.get('tasks', '')} | {r['serial_s']} | {r['distributed_s']} | {r['speedup']} | {r['identical']} |")
    hw = out["sweeps"].get("hw_tables")
    if hw:
        lines += ["", "Scale note (hw_tables tasks, longest-processing-time schedule of the measured task times, one core per worker): "
                  + ", ".join(f"{n} workers ~{v} s" for n, v in hw["expected_wall_s_on_N_workers"].items())
                  + f". Data per task: {hw['data_per_task']}."]
    atomic_write_text(args.outdir / f"{stem}.md", "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
