"""Resource cost of `generate --input-scale exact` (whole code range for any p) against the default pow2 cells.

Usage::

    python benchmarks/input_scale_cost.py [--outdir benchmarks/results]

The Table II sensor (Lorenz, My = 4, p = 7, N = 4096, 12-bit inputs; sigma fixed at 3.2e-4, the
value 5-fold CV picks) and the same sensor with p = 8 (a power of two: the pow2 cells use half the
code range there), each generated as the virtual-sensor top with ``--input-scale pow2`` and
``exact``, synthesised once with Yosys (generic) and Yosys + nextpnr (ECP5 LFE5U-45F, seed 1).
Writes ``input_scale_cost.json`` and ``input_scale_cost.md`` into ``--outdir``.
"""

from __future__ import annotations

import sys

import argparse
import json
from pathlib import Path

from pwas_hdl.bench_results import default_outdir, scratch_folder

HERE = Path(__file__).resolve().parent
KEYS = ("luts", "ffs", "carry", "dsp", "bram", "fmax_mhz", "latency_cycles")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--outdir", type=Path, default=default_outdir())
    args = ap.parse_args()

    from pwas_hdl.design.generate import generate
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.flow.synthesis import synthesize
    from pwas_hdl.systems.lorenz import lorenz

    with scratch_folder("pwas-input-scale-") as root:
        train, _ = lorenz(6000, seed=0).split(6000)
        rows = []
        for p in (7, 8):
            m = PWASVirtualSensor(my=4, partitions=p, gamma=1.2, sigma=3.2e-4, output_names=["y"], target_names=["z"])
            m.fit(None, train.y, train.z)
            for scale in ("pow2", "exact"):
                out = root / f"p{p}-{scale}"
                gd = generate(m, out, design="sensor", input_scale=scale)
                inp = gd.manifest["formats"]["inputs"][0]
                row = {"p": p, "input_scale": scale, "domain_codes": [inp["lo_code"], inp["hi_code"]],
                       "codes_used": inp["hi_code"] - inp["lo_code"], "code_range": 2 ** inp["bits"], "F": inp["F"]}
                for target in ("generic", "ecp5"):
                    r = synthesize(out, target=target)
                    row[target] = {k: r.get(k) for k in KEYS}
                    print(f"p = {p} {scale:5s} {target:7s}: " + ", ".join(f"{k} {row[target][k]}" for k in KEYS))
                rows.append(row)
        args.outdir.mkdir(parents=True, exist_ok=True)
        (args.outdir / "input_scale_cost.json").write_text(json.dumps({"design": "Lorenz sensor My = 4, 12-bit inputs", "rows": rows},
                                                                      indent=2) + "\n")
        md = ["# Cost of `--input-scale exact` (Lorenz sensor, My = 4, 12-bit inputs; `benchmarks/input_scale_cost.py`)", "",
              "| p | input scale | codes of the domain | generic LUTs | generic DSP | ECP5 LUTs | ECP5 FFs | ECP5 carry | ECP5 DSP | ECP5 fmax MHz |",
              "|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            g, e = r["generic"], r["ecp5"]
            md.append(f"| {r['p']} | {r['input_scale']} | {r['codes_used']} of {r['code_range']} ({100 * r['codes_used'] / r['code_range']:.1f} %) | "
                      f"{g['luts']} | {g['dsp']} | {e['luts']} | {e['ffs']} | {e['carry']} | {e['dsp']} | {e['fmax_mhz']} |")
        md.append("")
        (args.outdir / "input_scale_cost.md").write_text("\n".join(md))
        print(f"wrote {args.outdir / 'input_scale_cost.md'}")


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
