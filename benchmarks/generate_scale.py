"""Hardware generation at scale: `generate` and `simulate` time and peak memory against N.

Usage::

    python benchmarks/generate_scale.py [--points 2:63,2:255,2:999,3:99] [--samples 2000]
                                        [--simulator icarus|verilator|none] [--stem generate_scale] [--label TEXT]
                                        [--quick] [--outdir DIR]

For each point ``n:p`` (``n`` lags of the Lorenz output, ``p`` partitions each, N = (p+1)^n
weights) a model is fitted on 20 000 Lorenz samples (zero-order Tikhonov, sigma fixed at 1e-3: the
weights' values do not change the hardware's size), then, each in a fresh process of its own:

* ``pwas-hdl generate MODEL -o DIR`` (the weights inline in the Verilog) and
  ``--memory-init readmemh`` (the weights in ``.hex`` files): wall time, peak resident memory
  (``ru_maxrss`` from ``wait4``: the largest process of the command's tree), the Verilog's size;
* ``pwas-hdl simulate`` of both folders on ``--samples`` test samples with ``--simulator``, each
  with a build folder of its own (the simulator's compilation is measured, never a cached build):
  wall time, peak memory, the mismatch count against the bit-true model.

Prints a table and writes ``STEM.json`` and ``STEM.md`` into ``--outdir`` (``--quick``: one point
of N = 256, 200 samples, written as ``STEM_quick.*``). Nothing asserts on time.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from pwas_hdl.bench_results import default_outdir, environment, scratch_folder, script_main
from pwas_hdl.errors import InputError

DEFAULT_POINTS = "2:63,2:255,2:999,3:99"
QUICK_POINTS = "2:15"
TRAIN_SAMPLES = 20_000
SIGMA = 1e-3
#: the largest N a point may ask for (a million-word ROM; the model file holds N numbers a target)
MAX_WEIGHTS = 1 << 22


def parse_points(text: str) -> list[tuple[int, int]]:
    """``"2:63,3:99"`` -> ``[(2, 63), (3, 99)]``; refused with :class:`InputError` when malformed or
    over :data:`MAX_WEIGHTS` weights."""
    pts = []
    for item in text.split(","):
        try:
            n, p = (int(v) for v in item.split(":"))
        except ValueError:
            raise InputError(f"--points takes n:p pairs separated by commas (e.g. {DEFAULT_POINTS}), got {item!r}") from None
        if not (1 <= n <= 6 and 1 <= p):
            raise InputError(f"--points: n must be in 1..6 and p >= 1, got {item!r}")
        if (p + 1) ** n > MAX_WEIGHTS:
            raise InputError(f"--points: at most {MAX_WEIGHTS} weights a point, {item} has {(p + 1) ** n}")
        pts.append((n, p))
    return pts


def _run(cmd: list[str]) -> dict:
    """Run ``cmd`` as a child process; its wall time (s), peak RSS (MiB) and exit status."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    proc.stdout.close()
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[2:5])} failed (exit {proc.returncode}): {out.decode(errors='replace')[-2000:]}")
    return {"wall_s": round(wall, 3), "peak_rss_mib": round(usage.ru_maxrss / 1024, 1)}


def run_point(n: int, p: int, root: Path, samples: int, simulator: str, progress=print) -> dict:
    """Fit one point, generate it both ways and simulate both folders; one JSON-ready row."""
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.io.csv_table import write_csv
    from pwas_hdl.systems.lorenz import lorenz

    cli = [sys.executable, "-m", "pwas_hdl"]
    data = lorenz(TRAIN_SAMPLES + samples, seed=0)
    train, test = data.split(TRAIN_SAMPLES)
    model = PWASVirtualSensor(my=n, partitions=p, gamma=1.2, sigma=SIGMA, output_names=["y"], target_names=["z"])
    t0 = time.perf_counter()
    model.fit(None, train.y, train.z)
    fit_s = time.perf_counter() - t0
    mpath = root / f"m{n}_{p}.json"
    model.save(mpath)
    csv = root / f"t{n}_{p}.csv"
    write_csv(csv, {"y": test.y[:, 0], "z": test.z[:, 0]})
    if model.grid_.n_vertices != (p + 1) ** n:
        raise RuntimeError(f"the model of point {n}:{p} has {model.grid_.n_vertices} weights, not {(p + 1) ** n}")
    row = {"n": n, "p": p, "N": (p + 1) ** n, "fit_s": round(fit_s, 3), "model_file_mib": round(mpath.stat().st_size / 2**20, 2)}
    for form in ("inline", "readmemh"):
        out = root / f"g{n}_{p}_{form}"
        g = _run([*cli, "generate", str(mpath), "-o", str(out), "--memory-init", form])
        v = next(q for q in out.glob("*.v") if not q.name.endswith("_inst.v"))
        g["verilog_bytes"] = v.stat().st_size
        g["verilog_mib"] = round(v.stat().st_size / 2**20, 2)
        row[f"generate_{form}"] = g
        progress(f"n = {n}, p = {p} (N = {row['N']}): generate {form}: {g['wall_s']} s, {g['peak_rss_mib']} MiB, "
                 f"Verilog {g['verilog_mib']} MiB")
        if simulator != "none":
            res = root / f"s{n}_{p}_{form}.csv"
            # a build folder of this run's own: a simulator build cached by an earlier run of the same
            # Verilog would skip the compilation (the larger part of the time and memory at N = 10^6)
            s = _run([*cli, "simulate", str(out), str(csv), "-o", str(res), "--simulator", simulator,
                      "--build-dir", str(root / f"build{n}_{p}_{form}")])
            summary = json.loads(res.with_suffix(".json").read_text())
            if summary.get("build_reused"):
                raise RuntimeError(f"simulate of point {n}:{p} ({form}) reused a simulator build; nothing to measure")
            s["mismatches"] = summary.get("mismatches")
            s["samples"] = samples
            row[f"simulate_{form}"] = s
            progress(f"    simulate {form} ({simulator}, {samples} samples): {s['wall_s']} s, {s['peak_rss_mib']} MiB, "
                     f"mismatches {s['mismatches']}")
    return row


def markdown(doc: dict) -> str:
    sim = doc["simulator"]
    head = ["| n | p | N | fit s | generate inline s / MiB | Verilog MiB | generate readmemh s / MiB |"
            + (f" simulate inline ({sim}) s / MiB | simulate readmemh ({sim}) s / MiB | mismatches |" if sim != "none" else ""),
            "|---:|---:|---:|---:|---:|---:|---:|" + ("---:|---:|---:|" if sim != "none" else "")]
    lines = [f"# `generate` / `simulate` at scale (`benchmarks/generate_scale.py`{', ' + doc['label'] if doc.get('label') else ''})", "",
             f"Lorenz model, zero-order fit at sigma = {SIGMA} on {TRAIN_SAMPLES} samples; each command in a fresh process "
             f"(wall time, peak RSS); simulation of {doc['samples']} samples.", "", *head]
    for r in doc["rows"]:
        gi, gr = r["generate_inline"], r["generate_readmemh"]
        cells = [r["n"], r["p"], r["N"], r["fit_s"], f"{gi['wall_s']} / {gi['peak_rss_mib']}", gi["verilog_mib"],
                 f"{gr['wall_s']} / {gr['peak_rss_mib']}"]
        if sim != "none":
            si, sr = r["simulate_inline"], r["simulate_readmemh"]
            cells += [f"{si['wall_s']} / {si['peak_rss_mib']}", f"{sr['wall_s']} / {sr['peak_rss_mib']}",
                      f"{si['mismatches']} / {sr['mismatches']}"]
        lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", default=None, help=f"n:p pairs (default {DEFAULT_POINTS}; --quick: {QUICK_POINTS})")
    ap.add_argument("--samples", type=int, default=None, help="test samples simulated (20..100000; default 2000, --quick 200)")
    ap.add_argument("--simulator", choices=("icarus", "verilator", "none"), default="icarus",
                    help="simulator of the simulate step, or none (default: %(default)s)")
    ap.add_argument("--stem", default="generate_scale", help="file-name stem of the results (default: %(default)s)")
    ap.add_argument("--label", default="", help="a note for the table's title, e.g. the commit measured")
    ap.add_argument("--quick", action="store_true", help="one small point, written as STEM_quick.*: not a result to quote")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="folder of the result files (default: %(default)s)")
    a = ap.parse_args(argv)
    from pwas_hdl.bench_results import check_stem, write_json_and_markdown

    stem = check_stem(a.stem) + ("_quick" if a.quick else "")
    points = parse_points(a.points or (QUICK_POINTS if a.quick else DEFAULT_POINTS))
    samples = a.samples if a.samples is not None else (200 if a.quick else 2000)
    if not 20 <= samples <= 100_000:
        raise InputError(f"--samples must be in 20..100000, got {samples}")
    t0 = time.perf_counter()
    with scratch_folder("pwas-generate-scale-") as root:
        rows = [run_point(n, p, root, samples, a.simulator) for n, p in points]
    doc = {"format": "pwas-hdl-generate-scale", "version": 1, "label": a.label, "simulator": a.simulator, "samples": samples,
           "train_samples": TRAIN_SAMPLES, "sigma": SIGMA, "rows": rows,
           "environment": environment(time.perf_counter() - t0)}
    a.outdir.mkdir(parents=True, exist_ok=True)
    write_json_and_markdown(a.outdir, stem, doc, markdown(doc))


if __name__ == "__main__":
    sys.exit(script_main(main))
