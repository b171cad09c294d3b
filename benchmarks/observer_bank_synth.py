"""Resources, fmax and latency of observer-bank sensors on ECP5 and iCE40 (issue 12), one place and route each.

Designs (fitted on the seed 004 pv-benchmark data, seed 0): the P-feat sensor of the benches
(N_theta = 5, M = 5, l = 7, 11b, p = 6: 16 807 vertices), and a small one (N_theta = 3, p = 3,
64 vertices) that also fits an iCE40 HX8K, plus its 11b-sq twin (no square root). Every design
goes through ``generate --design sensor`` and :func:`pwas_hdl.flow.synthesis.synthesize`
(Yosys + nextpnr, seed 1) for ECP5 (LFE5U-45F, then LFE5U-85F if it does not fit) and iCE40
(HX8K); a design that does not fit a device is recorded with the reason. Samples/s = fmax / II (one sample per clock).

``python -m pwas_hdl.benchmarks.observer_bank_synth [--quick]`` writes
``results/observer_bank_synth.{json,md}`` (``--quick``: the small design on ECP5 only).
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

from pwas_hdl.io.atomic import atomic_write_text
from pwas_hdl.resources import benchmarks_dir

DESIGNS = {
    "small-n3-p3-11b": dict(n_models=3, features="11b", partitions=3, n_train=3000),
    "small-n3-p3-11b-sq": dict(n_models=3, features="11b-sq", partitions=3, n_train=3000),
    "pfeat-n5-p6-11b": dict(n_models=5, features="11b", partitions=6, n_train=25000),
}
#: iCE40 HX8K block RAM: 32 x 4 kbit; a design whose weight memory is larger is not run on it.
ICE40_BRAM_BITS = 32 * 4096
#: Parts tried in order per family (the next one only when a design does not fit).
FALLBACK = {"ecp5": ("45k", "85k"), "ice40": ("hx8k",)}
KEYS = ("luts", "ffs", "carry", "dsp", "bram", "bram_bits", "logic_cells", "fmax_mhz", "latency_cycles", "latency_ns", "ii",
        "throughput_msps", "runtime_s")


def _sensor(cfg: dict):
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    tr, _, _ = make_pv_dataset("pv-benchmark", cfg["n_train"], 200, seed=0)
    fe = ObserverBankFrontEnd(n_models=cfg["n_models"], features=cfg["features"])
    return PWASVirtualSensor(mu=0, my=0, partitions=cfg["partitions"], gamma=1.0, front_end=fe).fit(tr.u, tr.y, tr.z)


def run(quick: bool = False) -> dict:
    from pwas_hdl.design.generate import generate
    from pwas_hdl.flow.synthesis import synthesize

    t0 = time.perf_counter()
    names = ["small-n3-p3-11b"] if quick else list(DESIGNS)
    targets = ["ecp5"] if quick else ["ecp5", "ice40"]
    rows = []
    for name in names:
        s = _sensor(DESIGNS[name])
        with tempfile.TemporaryDirectory(prefix="pwas-obs-synth-") as tmp:
            g = generate(s, Path(tmp) / "d", design="sensor")
            fe = g.manifest["front_end"]
            for target in targets:
                print(f"{name} on {target} ...", flush=True)
                if target == "ice40" and g.manifest["memory"]["bits"] > ICE40_BRAM_BITS:
                    rows.append({"design": name, "target": target, "device": "hx8k", "n_vertices": g.manifest["domain"]["n_vertices"],
                                 "memory_bits": g.manifest["memory"]["bits"], "fits": False,
                                 "reason": f"not run: {g.manifest['memory']['bits']} bits of weight memory > the "
                                           f"{ICE40_BRAM_BITS} bits of block RAM of an HX8K"})
                    continue
                row = {"design": name, "target": target, "n_vertices": g.manifest["domain"]["n_vertices"],
                       "memory_bits": g.manifest["memory"]["bits"], "formats": fe["formats"], "feature_map": fe["feature_map"],
                       "cycles_per_sample": fe["cycles_per_sample"]}
                for device in FALLBACK.get(target, (None,)):  # a larger part when the default does not fit
                    r = dict(row)
                    try:
                        res = synthesize(Path(tmp) / "d", target, device=device)
                        r.update({k: res.get(k) for k in KEYS}, device=res.get("part"), fits=True)
                    except (ValueError, RuntimeError) as exc:  # does not fit the device, or a tool failed
                        r.update(fits=False, device=device, reason=str(exc).splitlines()[0][:300])
                    print(json.dumps({k: r.get(k) for k in ("design", "target", "device", "luts", "ffs", "dsp", "bram", "fmax_mhz",
                                                            "fits", "reason")}), flush=True)
                    rows.append(r)
                    if r["fits"]:
                        break
    return {"bench": "observer-bank-synth", "quick": quick, "rows": rows, "elapsed_s": round(time.perf_counter() - t0, 1)}


def markdown(doc: dict) -> str:
    lines = [f"# Observer-bank sensors: resources on ECP5 and iCE40{' (QUICK)' if doc['quick'] else ''}", "",
             "| design | part | N | LUT4 | FF | carry | DSP | BRAM | fmax MHz | latency (cycles / ns) | Msamples/s | note |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---|"]
    # device in the target column
    for r in doc["rows"]:
        if r["fits"]:
            lines.append(f"| {r['design']} | {r['device']} | {r['n_vertices']} | {r['luts']} | {r['ffs']} | {r['carry']} | {r['dsp']} | "
                         f"{r['bram']} | {r['fmax_mhz']:.1f} | {r['latency_cycles']} / {r['latency_ns']:.0f} | {r['throughput_msps']:.1f} | |")
        else:
            lines.append(f"| {r['design']} | {r['target']} {r.get('device') or ''} | {r['n_vertices']} | | | | | | | | | {r['reason']} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    quick = "--quick" in sys.argv[1:]
    doc = run(quick)
    out = benchmarks_dir() / "results"
    stem = "observer_bank_synth_quick" if quick else "observer_bank_synth"
    atomic_write_text(out / f"{stem}.json", json.dumps(doc, indent=1) + "\n")
    atomic_write_text(out / f"{stem}.md", markdown(doc))
    print(markdown(doc))
