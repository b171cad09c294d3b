"""Hardware cost of the power-of-two warp (non-uniform partitions, issue 15 item 3) on ECP5.

Usage::

    python benchmarks/warp_cost.py [--outdir benchmarks/results]

The Lorenz sensor of Table II (My = 4, p = 7, N = 4096, sigma fixed at 3.2e-4, 6000 training
samples, seed 0) fitted twice, with the uniform partition and with ``--breakpoints quantile-pow2``;
the core design of each (12-bit inputs, default formats, balanced pipeline): the uniform one by
``generate``, the warped one by :func:`pwas_hdl.hdl.warp.write_warped_folder` (warp + register +
the same core). Both synthesised and placed with Yosys + nextpnr-ecp5 (LFE5U-45F, seed 1).
Writes ``warp_cost.json`` and ``warp_cost.md``.
"""

from __future__ import annotations

import sys

import argparse
import json
from pathlib import Path

KEYS = ("luts", "ffs", "carry", "dsp", "bram", "fmax_mhz", "latency_cycles")


def main(argv=None) -> None:
    from pwas_hdl.design.generate import generate
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.flow.synthesis import synthesize
    from pwas_hdl.hdl.warp import write_warped_folder
    from pwas_hdl.io.atomic import atomic_write_text
    from pwas_hdl.systems.lorenz import lorenz

    from pwas_hdl.bench_results import default_outdir, scratch_folder
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--outdir", type=Path, default=default_outdir())
    a = ap.parse_args(argv)
    with scratch_folder("pwas-warp-") as root:
        train, _ = lorenz(6000, seed=0).split(6000)
        rows = []
        for rule in (None, "quantile-pow2"):
            m = PWASVirtualSensor(my=4, partitions=7, gamma=1.2, sigma=3.2e-4, output_names=["y"], target_names=["z"], breakpoints=rule)
            m.fit(None, train.y, train.z)
            out = root / (rule or "uniform")
            if rule is None:
                generate(m, out, design="core")
                extra = {}
            else:
                wm, _ = write_warped_folder(m, out)
                extra = {"warp": [w.to_dict() for w in wm.warps][:1], "core_input_bits": wm.warps[0].width}
            r = synthesize(out, target="ecp5")
            row = {"partition": rule or "uniform", **{k: r.get(k) for k in KEYS}, **extra}
            print(row["partition"], ", ".join(f"{k} {row[k]}" for k in KEYS))
            rows.append(row)
        a.outdir.mkdir(parents=True, exist_ok=True)
        doc = {"design": "Lorenz core My = 4, p = 7, N = 4096, 12-bit inputs", "device": "ECP5 LFE5U-45F, nextpnr seed 1", "rows": rows}
        atomic_write_text(a.outdir / "warp_cost.json", json.dumps(doc, indent=1) + "\n")
        md = ["# Cost of the power-of-two warp (Lorenz core My = 4, p = 7, N = 4096; `benchmarks/warp_cost.py`)", "",
              "ECP5 LFE5U-45F, nextpnr seed 1, 12-bit inputs, default formats, balanced pipeline.", "",
              "| partition | LUT4 | FF | carry | DSP | BRAM | fmax MHz | latency cycles |", "|---|---|---|---|---|---|---|---|"]
        md += [f"| {r['partition']} | {r['luts']} | {r['ffs']} | {r['carry']} | {r['dsp']} | {r['bram']} | {r['fmax_mhz']} | {r['latency_cycles']} |"
               for r in rows]
        atomic_write_text(a.outdir / "warp_cost.md", "\n".join(md) + "\n")
        print("\n".join(md))


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
