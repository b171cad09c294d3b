"""Serial against parallel PWAS architecture on an iCE40 UP5K (issue 15 item 2): resources and throughput.

Usage::

    python benchmarks/serial_vs_parallel.py [--quick] [--outdir benchmarks/results]

The Lorenz virtual sensor of Table II (My = 4, p = 7, N = 4096, 12-bit inputs, sigma fixed at
3.2e-4, the value 5-fold CV picks), generated as the virtual-sensor top (the narrow interface:
one 12-bit sample in, one estimate out) with ``--architecture parallel`` and ``serial`` (balanced
pipeline), each placed and routed once with Yosys + nextpnr-ice40 on the iCE40 UP5K in the SG48
package (``synth --fpga ice40 --device up5k``, seed 1, nextpnr's default 12 MHz target; fmax is
what nextpnr reports). Throughput = fmax / II. Writes ``serial_vs_parallel.json`` and ``.md``
into ``--outdir`` (``--quick``: My = 2, p = 4, ``serial_vs_parallel_quick.*``).
"""

from __future__ import annotations

import sys

import argparse
import json
from pathlib import Path

from pwas_hdl.bench_results import scratch_folder

KEYS = ("luts", "ffs", "carry", "dsp", "bram", "bram_bits", "logic_cells", "fmax_mhz", "latency_cycles", "latency_ns", "ii",
        "throughput_msps", "utilization")


def run(quick: bool, progress=print) -> dict:
    from pwas_hdl.design.generate import generate
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.flow.synthesis import synthesize
    from pwas_hdl.systems.lorenz import lorenz

    my, p = (2, 4) if quick else (4, 7)
    with scratch_folder("pwas-serial-") as root:
        train, _ = lorenz(6000, seed=0).split(6000)
        m = PWASVirtualSensor(my=my, partitions=p, gamma=1.2, sigma=3.2e-4, output_names=["y"], target_names=["z"])
        m.fit(None, train.y, train.z)
        rows = []
        for arch in ("parallel", "serial"):
            out = root / arch
            gd = generate(m, out, design="sensor", architecture=arch)
            man = gd.manifest
            r = synthesize(out, target="ice40", device="up5k")
            row = {"architecture": arch, "memory": {k: man["memory"][k] for k in ("kind", "memories", "depth", "word_bits", "words", "bits")},
                   "multipliers_rtl": r.get("multipliers_rtl"), "port_bits": sum(pt["width"] for pt in man["ports"]),
                   "part": r.get("part"), **{k: r.get(k) for k in KEYS}}
            progress(f"{arch:8s}: " + ", ".join(f"{k} {row[k]}" for k in KEYS if k != "utilization"))
            rows.append(row)
        return {"design": f"Lorenz virtual-sensor top My = {my}, p = {p}, N = {(p + 1) ** my}, 12-bit input",
                "device": "iCE40 UP5K SG48 (nextpnr-ice40 --up5k --package sg48), seed 1", "rows": rows}


def markdown(doc: dict) -> str:
    md = [f"# Serial against parallel architecture ({doc['design']}; `benchmarks/serial_vs_parallel.py`)", "",
          f"Device: {doc['device']}.", "",
          "| architecture | memories x depth | LUT4 | FF | carry | SB_MAC16 | EBR (4 kbit) | logic cells | fmax MHz | II | Msamples/s | latency cycles | latency ns |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in doc["rows"]:
        mem = r["memory"]
        md.append(f"| {r['architecture']} | {mem['memories']} x {mem['depth']} | {r['luts']} | {r['ffs']} | {r['carry']} | {r['dsp']} | "
                  f"{r['bram']} | {r['logic_cells']} | {r['fmax_mhz']} | {r['ii']} | {r['throughput_msps']} | {r['latency_cycles']} | "
                  f"{r['latency_ns']} |")
    md.append("")
    return "\n".join(md)


def main(argv=None) -> None:
    from pwas_hdl.io.atomic import atomic_write_text

    from pwas_hdl.bench_results import default_outdir
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a small sensor (My = 2, p = 4); writes serial_vs_parallel_quick.*")
    ap.add_argument("--outdir", type=Path, default=default_outdir())
    a = ap.parse_args(argv)
    doc = run(a.quick)
    a.outdir.mkdir(parents=True, exist_ok=True)
    stem = "serial_vs_parallel_quick" if a.quick else "serial_vs_parallel"
    atomic_write_text(a.outdir / f"{stem}.json", json.dumps(doc, indent=1) + "\n")
    atomic_write_text(a.outdir / f"{stem}.md", markdown(doc))
    print(markdown(doc))


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
