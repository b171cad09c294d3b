"""Resources, fmax, latency and samples/s of observer-bank sensors on ECP5 and iCE40 (issue 12), one place and route each.

Designs (fitted on the seed 004 pv-benchmark data, seed 0): the P-feat sensor of the benches
(N_theta = 5, M = 5, l = 7, 11b, p = 6: 16 807 vertices; also fitted on the switching-4 data,
``switching4-pfeat-n5-p6-11b``), and a small one (N_theta = 3, p = 3,
64 vertices) plus its 11b-sq twin (no square root); and the tapped battery sensor of the tests
(seed 004 E3 data, seed 0: 3 Kalman observers, taps ``u0[t], y0[t-1], y0[t]``, p = 2, 729
vertices; the tapped top :mod:`pwas_hdl.hdl.observer_tap_sensor_top`). Each is generated with ``generate --design
sensor`` as the **serial** design (``--architecture serial``: the time-multiplexed bank of
:mod:`pwas_hdl.hdl.serial_observer_bank`, one lane, and the serial core) and, for reference, the
**parallel** one (constant multipliers, II = 1), and goes through
:func:`pwas_hdl.flow.synthesis.synthesize` (Yosys + nextpnr, seed 1) on ECP5 LFE5U-45F and on
iCE40 HX8K (no DSPs; 32 block RAMs of 4 kbit: a design whose weight memory is larger is not run
there, reason recorded). Every run is a child process with a wall-clock limit (``--limit-min``,
default 20); a run that does not finish is recorded as such. Samples/s = fmax / II.

Where the cost is (step 1 of the issue's item 2): every design row also carries the multiplier
inventory of its Verilog (:func:`multiplier_inventory`: each ``*`` by its net name and operand
widths, grouped as observer-bank / squares / feature scale / core), so the DSP count of a run can
be traced to the parts that need it.

``python -m pwas_hdl.benchmarks.observer_bank_synth [--quick] [--limit-min M] [--only serial|parallel]
[--designs a,b] [--targets ecp5,ice40]`` (the last two re-run those rows and replace them in the results)
writes ``results/observer_bank_synth.{json,md}`` (``--quick``: the small serial design on ECP5 only,
``..._quick.{json,md}``).
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pwas_hdl.bench_results import portable_paths
from pwas_hdl.io.atomic import atomic_write_text

DESIGNS = {
    "small-n3-p3-11b": dict(n_models=3, features="11b", partitions=3, n_train=3000),
    "small-n3-p3-11b-sq": dict(n_models=3, features="11b-sq", partitions=3, n_train=3000),
    "pfeat-n5-p6-11b": dict(n_models=5, features="11b", partitions=6, n_train=25000),
    # the switching-4 P-feat sensor of observer_bank_hw.py's run 0 (seed 004 E2 data, seed 0): same structure
    "switching4-pfeat-n5-p6-11b": dict(system="switching-4", n_models=5, features="11b", partitions=6, n_train=25000),
    # the tapped battery sensor of tests/test_bank_taps_hw.py (seed 004 E3 data: 3 Kalman observers M = 5,
    # l = 7, 11b, taps u0[t], y0[t-1], y0[t] (--mu 1 --my 2), p = 2: 729 vertices)
    "battery-taps-n3-p2-11b": dict(system="battery", n_models=3, observer="kalman:0.1", features="11b", partitions=2,
                                   mu=1, my=2, n_train=3000),
    # the P-feat sensor of battery.py (battery_rtl_serial.md's run 0: 5 Kalman observers, taps i_k, v_k (PFEAT_B:
    # mu = my = 1, p = 3: 4^7 = 16 384 vertices), sigma by CV, 25 000 training samples, seed 0)
    "battery-pfeat-n5-p3-11b": dict(system="battery", n_models=5, observer="kalman:0.1", features="11b", partitions=3,
                                    mu=1, my=1, n_train=25000, sigma=None),
}
BANKS = ("serial", "parallel")
#: iCE40 HX8K block RAM: 32 x 4 kbit; a design whose weight memory is larger is not run on it.
ICE40_BRAM_BITS = 32 * 4096
TARGETS = {"ecp5": "45k", "ice40": "hx8k"}
KEYS = ("luts", "ffs", "carry", "dsp", "bram", "bram_bits", "logic_cells", "fmax_mhz", "latency_cycles", "latency_ns", "ii",
        "throughput_msps", "runtime_s", "critical_path")
#: Net-name prefixes of the multipliers -> part of the design.
PARTS = (("bank", re.compile(r"^(obs\d+_p|lane\d+_p)")), ("square", re.compile(r"_sq$")),
         ("feature scale", re.compile(r"(feat\d+_prod|lane\d+_fprod)$")))


def _sensor(cfg: dict):
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    if cfg.get("system") == "battery":  # the tapped sensor (u/y taps beside the bank features)
        from pwas_hdl.systems.battery import make_battery_dataset

        tr, _, _ = make_battery_dataset(cfg["n_train"], 300, seed=0, noise=0.03)
        fe = ObserverBankFrontEnd(n_models=cfg["n_models"], observer=cfg["observer"], features=cfg["features"])
        fe = fe.fit([tr.u], [tr.y], [tr.z])
        return PWASVirtualSensor(mu=cfg["mu"], my=cfg["my"], partitions=cfg["partitions"], gamma=1.0, front_end=fe,
                                 sigma=cfg.get("sigma", 1e-3)).fit(tr.u, tr.y, tr.z)
    tr, _, _ = make_pv_dataset(cfg.get("system", "pv-benchmark"), cfg["n_train"], 200, seed=0)
    fe = ObserverBankFrontEnd(n_models=cfg["n_models"], features=cfg["features"])
    return PWASVirtualSensor(mu=0, my=0, partitions=cfg["partitions"], gamma=1.0, front_end=fe).fit(tr.u, tr.y, tr.z)


def multiplier_inventory(verilog: str) -> dict:
    """The ``*`` operators of a generated Verilog file, by part, with their operand widths.

    Returns ``{part: {"count": .., "operand_bits": [[a, b], ..], "mult18x18_estimate": ..}}`` where
    constant operands count with the width of their literal, and ``mult18x18_estimate`` is
    ``sum ceil(a / 18) * ceil(b / 18)`` over the non-power-of-two products (what a DSP mapping of
    full products would need; synthesis may do better for small constants).
    """
    widths: dict[str, int] = {}
    for mt in re.finditer(r"^\s*(?:wire|reg)\s+(?:signed\s+)?(?:\[(\d+):0\]\s+)?\\?([\w$]+)", verilog, re.M):
        widths[mt.group(2)] = int(mt.group(1)) + 1 if mt.group(1) else 1
    out: dict[str, dict] = {}
    for mt in re.finditer(r"assign\s+\\?([\w$]+)\s*=\s*([^;*]+?)\s*\*\s*([^;]+);", verilog):
        name, ops = mt.group(1), []
        pow2 = False
        for op in (mt.group(2), mt.group(3)):
            op = op.strip()
            if op.startswith("$signed(") and op.endswith(")"):
                op = op[8:-1].strip()
            lit = re.match(r"^(\d+)'s?h([0-9a-fA-F]+)$", op)
            if lit:  # a constant: its own two's-complement width, not the literal's
                w, v = int(lit.group(1)), int(lit.group(2), 16)
                v = v - (1 << w) if v >> (w - 1) else v
                ops.append(max(2, (v.bit_length() if v >= 0 else (-v - 1).bit_length()) + 1))
                pow2 = pow2 or (v > 0 and v & (v - 1) == 0)
            elif op.startswith("{"):
                ops.append(sum(int(w) for w in re.findall(r"(\d+)'h", op)) + sum(widths.get(n, 1) for n in re.findall(r"\b([a-zA-Z_]\w*)\b", op)))
            else:
                sl = re.match(r"^\\?([\w$]+)\s*\[(\d+)(?::(\d+))?\]$", op)
                ops.append(int(sl.group(2)) - int(sl.group(3) or sl.group(2)) + 1 if sl else widths.get(op.lstrip("\\").strip(), 0))
        if pow2:
            continue  # a shift (alignment), not a multiplier
        part = next((p for p, rx in PARTS if rx.search(name)), "core")
        e = out.setdefault(part, {"count": 0, "operand_bits": [], "mult18x18_estimate": 0})
        e["count"] += 1
        e["operand_bits"].append(ops)
        e["mult18x18_estimate"] += math.ceil(max(ops[0], 1) / 18) * math.ceil(max(ops[1], 1) / 18)
    return out


def _one_run(folder: str, target: str, device: str, limit_s: float) -> dict:
    """:func:`synthesize` in a child process (own process group), killed after ``limit_s`` seconds."""
    code = ("import json,sys; from pwas_hdl.flow.synthesis import synthesize\n"
            "try:\n r = synthesize(sys.argv[1], sys.argv[2], device=sys.argv[3]); print('RESULT ' + json.dumps(r, default=str))\n"
            "except (ValueError, RuntimeError) as e:\n print('FAILED ' + str(e).splitlines()[0][:300])\n")
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", code, folder, target, device], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=limit_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return {"fits": None, "finished": False, "reason": f"not finished within the limit of {limit_s / 60:.0f} min wall clock "
                f"(killed; shared 2-core machine)", "wall_s": round(time.perf_counter() - t0, 1)}
    wall = round(time.perf_counter() - t0, 1)
    for line in out.splitlines():
        if line.startswith("RESULT "):
            res = json.loads(line[7:])
            return {**{k: res.get(k) for k in KEYS}, "device": res.get("part"), "fits": True, "finished": True, "wall_s": wall}
        if line.startswith("FAILED "):  # the tool's log is named relative to the design folder (a temporary one)
            return {"fits": False, "finished": True, "reason": portable_paths(line[7:], [folder]), "wall_s": wall}
    last = (err or out).strip().splitlines()[-1][:300] if (err or out).strip() else "no output"
    return {"fits": None, "finished": False, "reason": f"the run failed: {portable_paths(last, [folder])}", "wall_s": wall}


def run(quick: bool = False, limit_min: float = 20.0, only: str | None = None, designs: list | None = None,
        targets: list | None = None) -> dict:
    from pwas_hdl.design.generate import generate

    t0 = time.perf_counter()
    names = ["small-n3-p3-11b"] if quick else list(designs or DESIGNS)
    targets = ["ecp5"] if quick else list(targets or TARGETS)
    banks = ["serial"] if quick else [b for b in BANKS if only in (None, b)]
    rows = []
    for bank in banks:
        for name in names:
            s = _sensor(DESIGNS[name])
            with tempfile.TemporaryDirectory(prefix="pwas-obs-synth-") as tmp:
                folder = Path(tmp) / "d"
                g = generate(s, folder, design="sensor", architecture=bank)
                fe = g.manifest["front_end"]
                inv = multiplier_inventory((folder / f"{g.top}.v").read_text())
                base = {"design": name, "bank": bank, "n_vertices": g.manifest["domain"]["n_vertices"],
                        "memory_bits": g.manifest["memory"]["bits"], "feature_map": fe["feature_map"],
                        "cycles_per_sample": fe["cycles_per_sample"], "ii_manifest": g.manifest["ii"],
                        "latency_manifest": g.manifest["latency_cycles"], "multipliers": inv}
                for target in targets:
                    device = TARGETS[target]
                    row = {**base, "target": target, "device": device}
                    if target == "ice40" and g.manifest["memory"]["bits"] > ICE40_BRAM_BITS:
                        row.update(fits=False, finished=True, reason=f"not run: {g.manifest['memory']['bits']} bits of weight memory > "
                                   f"the {ICE40_BRAM_BITS} bits of block RAM of an HX8K")
                    else:
                        print(f"{name} ({bank}) on {target} {device} ...", flush=True)
                        row.update(_one_run(str(folder), target, device, limit_min * 60))
                    print(json.dumps({k: row.get(k) for k in ("design", "bank", "target", "device", "luts", "ffs", "dsp", "bram",
                                                                "fmax_mhz", "ii", "fits", "reason", "wall_s")}), flush=True)
                    rows.append(row)
    return {"bench": "observer-bank-synth", "quick": quick, "limit_min": limit_min, "rows": rows,
            "elapsed_s": round(time.perf_counter() - t0, 1)}


def _dsp_est(r: dict) -> str:
    return " / ".join(f"{p} {v['count']}x ~{v['mult18x18_estimate']}" for p, v in r["multipliers"].items())


def markdown(doc: dict) -> str:
    lines = [f"# Observer-bank sensors: resources on ECP5 and iCE40{' (QUICK)' if doc['quick'] else ''}", "",
             f"One Yosys + nextpnr run each (seed 1, time limit {doc['limit_min']} min wall per run), "
             "`benchmarks/observer_bank_synth.py`; designs fitted on pv-benchmark data (seed 0; switching4-* on the switching-4 data, seed 0), battery-taps on the "
             "seed 004 E3 battery data (seed 0; u/y taps beside the bank features, the tapped top). "
             "serial = `generate --architecture serial` (time-multiplexed bank, 1 lane, serial core); "
             "parallel = constant multipliers, II 1. DSP = MULT18X18D (ECP5); iCE40 HX8K has none. "
             "Multipliers (RTL `*` by part, count x estimated 18x18 blocks) from the Verilog.", "",
             "| design | bank | part | LUT4 | FF | DSP | BRAM | fmax MHz | latency (cycles / ns) | cycles/sample (II) | Msamples/s | multipliers in the RTL | critical path (nextpnr) | note |",
             "|---|---|---|---:|---:|---:|---:|---:|---|---:|---:|---|---|---|"]
    for r in doc["rows"]:
        head = f"| {r['design']} | {r['bank']} | {r['target']} {r.get('device') or ''} |"
        cp = r.get("critical_path")
        cps = f"{cp['from']} -> {cp['to']} ({cp['delay_ns']:.1f} ns, routing {cp['routing_ns']:.1f})" if cp else ""
        if r.get("fits"):
            lines.append(f"{head} {r['luts']} | {r['ffs']} | {r['dsp']} | {r['bram']} | {r['fmax_mhz']:.1f} | "
                         f"{r['latency_cycles']} / {r['latency_ns']:.0f} | {r['ii']} | {r['throughput_msps']:.3f} | {_dsp_est(r)} | {cps} | |")
        else:
            lines.append(f"{head} | | | | | {r['latency_manifest']} / | {r['ii_manifest']} | | {_dsp_est(r)} | | {r['reason']} |")
    for note in doc.get("notes", []):  # measured context recorded with the results (e.g. before / after a change)
        lines += ["", note]
    if not any(r["bank"] == "parallel" for r in doc["rows"]):
        lines += ["", "The parallel bank was not re-run here (`--only serial`). The earlier run of this script "
                  "(commit be0d869, `results/observer_bank_synth.md` there) measured the parallel small-n3-p3-11b on an "
                  "LFE5U-85F: 6778 LUT4, 2009 FF, 80 MULT18X18D, fmax 11.4 MHz, II 1; it does not fit the LFE5U-45F "
                  "(80 multipliers, 72 there), nor does the parallel P-feat sensor (129); its iCE40 HX8K synthesis "
                  "did not finish in 22 CPU-minutes."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """The command line of the module docstring."""
    import argparse

    from pwas_hdl.bench_results import checked_outdir, default_outdir, make_outdir
    from pwas_hdl.errors import InputError

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the small serial design on ECP5 only")
    ap.add_argument("--limit-min", type=float, default=20.0, help="time limit per run in minutes (default 20)")
    ap.add_argument("--only", choices=list(BANKS), default=None, help="the designs of that bank only")
    ap.add_argument("--designs", default=None, help="comma list of designs to re-run (their rows are replaced)")
    ap.add_argument("--targets", default=None, help="comma list of targets to re-run (their rows are replaced)")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="output folder (default: %(default)s)")
    a = ap.parse_args(argv)
    if not (math.isfinite(a.limit_min) and a.limit_min > 0):
        raise InputError(f"--limit-min must be a positive number of minutes, got {a.limit_min}")
    limit = a.limit_min
    designs = a.designs.split(",") if a.designs else None
    targets = a.targets.split(",") if a.targets else None
    checked_outdir(a.outdir)
    doc = run(a.quick, limit, a.only, designs, targets)
    out = make_outdir(a.outdir)
    stem = "observer_bank_synth_quick" if a.quick else "observer_bank_synth"
    if designs or targets:  # a re-run of some rows: replace them in the results
        from pwas_hdl.benchmarks.seed004_common import replace_rows

        doc["rows"], old = replace_rows(out / f"{stem}.json", doc["rows"], lambda r: (r["design"], r["bank"], r["target"]))
        if old is not None:
            doc["limit_min"] = f"{old['limit_min']} (re-run rows: {limit:g})"
            doc["notes"] = old.get("notes", [])  # the measured context recorded with the earlier rows
    atomic_write_text(out / f"{stem}.json", json.dumps(doc, indent=1) + "\n")
    atomic_write_text(out / f"{stem}.md", markdown(doc))
    print(markdown(doc))
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main, sys.argv[1:]))
