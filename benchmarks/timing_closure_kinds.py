"""Timing closure (`generate --clock-mhz`) of every design kind: the chosen pipeline, its fmax and latency.

Usage::

    python benchmarks/timing_closure_kinds.py [--kinds plain-core,additive-core,...] [--clock-mhz 100]
                                              [--fpga ecp5|ice40] [--stem timing_closure_kinds] [--label TEXT]
                                              [--quick] [--outdir DIR] [--isqrt-every K]

Each kind is a small model fitted here (seeded: the same models every run) and built by
:func:`pwas_hdl.design.generate.build_design` with ``target_mhz``: the search places and routes its
candidates (nextpnr, seed 1, inside the timing harness) until the shallowest one that reaches the
clock, or reports the best fmax when none does (``met`` false). The kinds:

* ``plain-core`` / ``plain-sensor``: Lorenz, 2 lags of y, p = 5 (N = 36);
* ``classifier-core``: the same regressors, 2 classes (the argmax stage's registers follow the pipeline);
* ``additive-core`` / ``additive-sensor``: 3 lags of y in sliding pairs, p = 3 (2 parts, N = 32);
* ``warped-core``: ``--breakpoints quantile-pow2``, 2 lags, p = 5 (the warp register);
* ``recurrent-sensor``: My = 2, Mz = 1, p = 3 (II = latency);
* ``serial-core``: the plain core with ``--architecture serial`` (II = n + 1);
* ``bank-sensor`` / ``bank-serial``: an observer bank (2 models of order 2, 11b features) + core,
  parallel and time-multiplexed;
* ``additive-serial``: the additive core on serial part cores (II = the largest part's n + 1);
* ``recurrent-serial``: the recurrent top around the serial core (II = latency);
* ``recurrent-warped``: the recurrent top with the warp in front of its core (``--breakpoints
  quantile-pow2``, My = 1, Mz = 1, p = 4);
* ``warped-bank-serial``: the observer bank of ``bank-serial`` on a ``quantile-pow2`` partition
  (p = 4): time-multiplexed bank, warp, serial core.

``--isqrt-every K`` builds the observer-bank kinds with a square-root register every ``K`` digit
steps (``generate --isqrt-every``; default 3) and is refused when ``--kinds`` names none of them.

Prints a table and writes ``STEM.json`` / ``STEM.md`` into ``--outdir`` (``--quick``: the plain
core only, written as ``STEM_quick.*``). Nothing asserts on time.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any, Callable

from pwas_hdl.bench_results import default_outdir, environment, script_main
from pwas_hdl.errors import InputError

#: kind -> (design, architecture)
KINDS: dict[str, tuple[str, str]] = {
    "plain-core": ("core", "parallel"),
    "plain-sensor": ("sensor", "parallel"),
    "classifier-core": ("core", "parallel"),
    "additive-core": ("core", "parallel"),
    "additive-sensor": ("sensor", "parallel"),
    "warped-core": ("core", "parallel"),
    "recurrent-sensor": ("sensor", "parallel"),
    "serial-core": ("core", "serial"),
    "bank-sensor": ("sensor", "parallel"),
    "bank-serial": ("sensor", "serial"),
    "additive-serial": ("core", "serial"),
    "recurrent-serial": ("sensor", "serial"),
    "recurrent-warped": ("sensor", "parallel"),
    "warped-bank-serial": ("sensor", "serial"),
}
#: kinds whose model is not named by the first word of the kind
FAMILIES = {"recurrent-warped": "recurrent-warped", "warped-bank-serial": "warped-bank"}
QUICK_KINDS = "plain-core"


def _series(n: int = 1500):
    from pwas_hdl.systems.lorenz import lorenz

    d = lorenz(n, seed=5)
    return d.y[:, 0], d.z[:, 0]


def _model(kind: str) -> Any:
    """The seeded small model of ``kind``."""
    import numpy as np

    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    y, z = _series()
    family = FAMILIES.get(kind, kind.split("-")[0])
    if family in ("plain", "serial"):
        return PWASVirtualSensor(my=2, partitions=5, sigma=1e-3, output_names=["y"], target_names=["z"]).fit(None, y, z)
    if family == "classifier":
        return PWASVirtualSensor(my=2, partitions=5, sigma=1e-3, classify=True, output_names=["y"],
                                 target_names=["c"]).fit(None, y, (z > np.median(z)).astype(int))
    if family == "additive":
        return PWASVirtualSensor(my=3, partitions=3, sigma=1e-2, additive="pairs", output_names=["y"],
                                 target_names=["z"]).fit(None, y, z)
    if family == "warped":
        return PWASVirtualSensor(my=2, partitions=5, breakpoints="quantile-pow2", sigma=1e-3, output_names=["y"],
                                 target_names=["z"]).fit(None, y, z)
    if family == "recurrent":
        return PWASVirtualSensor(my=2, mz=1, partitions=3, sigma=1e-3, output_names=["y"], target_names=["z"]).fit(None, y, z)
    if family == "recurrent-warped":
        return PWASVirtualSensor(my=1, mz=1, partitions=4, breakpoints="quantile-pow2", sigma=1e-3, output_names=["y"],
                                 target_names=["z"]).fit(None, y, z)
    if family in ("bank", "warped-bank"):
        from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
        from pwas_hdl.systems.pv_benchmark import make_pv_dataset

        tr, _, _ = make_pv_dataset("pv-benchmark", 2000, 300, seed=0)
        fe = ObserverBankFrontEnd(n_models=2, observer="deadbeat", features="11b", order=2)
        warp = {"partitions": 4, "breakpoints": "quantile-pow2"} if family == "warped-bank" else {"partitions": 3}
        return PWASVirtualSensor(mu=0, my=0, gamma=1.0, front_end=fe, sigma=1e-3, **warp).fit(tr.u, tr.y, tr.z)
    raise InputError(f"unknown kind {kind!r}")


def parse_kinds(text: str) -> list[str]:
    """``"plain-core,bank-serial"`` -> the kinds, in order; unknown or repeated names are refused."""
    kinds = [k.strip() for k in text.split(",") if k.strip()]
    bad = [k for k in kinds if k not in KINDS]
    if not kinds or bad:
        raise InputError(f"--kinds takes names from {', '.join(KINDS)} separated by commas, got {text!r}")
    if len(set(kinds)) != len(kinds):
        raise InputError(f"--kinds names a kind twice: {text!r}")
    return kinds


def is_bank_kind(kind: str) -> bool:
    """The kind's design has an observer bank (whose square root ``--isqrt-every`` spaces)."""
    return FAMILIES.get(kind, kind.split("-")[0]) in ("bank", "warped-bank")


def run_kind(kind: str, target: float, fpga: str, progress: Callable[[str], None] = print,
             isqrt_every: int | None = None) -> dict:
    """Fit the kind's model and run the timing closure; one JSON-ready row (``isqrt_every``: the
    bank kinds' root register spacing, ignored for the others)."""
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.flow.timing_closure import TimingNotMet

    design, arch = KINDS[kind]
    model = _model(kind)
    spacing = {"isqrt_every": isqrt_every} if isqrt_every is not None and is_bank_kind(kind) else {}
    t0 = time.perf_counter()
    try:
        gd = build_design(model, design=design, architecture=arch, target_mhz=target, fpga_target=fpga, **spacing)
        rec, man = gd.manifest["timing"], gd.manifest
    except TimingNotMet as exc:
        rec, man = exc.record, None
    wall = time.perf_counter() - t0
    measured = [c for c in rec["candidates"] if c["measured"]]
    chosen = rec["candidates"][rec["chosen"]] if rec["met"] else None
    row = {"kind": kind, "design": design, "architecture": arch, "target_mhz": target, "fpga": fpga,
           "part": rec.get("part"), "met": rec["met"], "candidates": len(rec["candidates"]),
           "measured": [{"latency_cycles": c["latency_cycles"], "label": c["label"], "fmax_mhz": c["fmax_mhz"],
                         "critical_path": c.get("critical_path")} for c in measured],
           "search_order_cycles": list(rec["measurements"]), "best_fmax_mhz": rec["best_fmax_mhz"],
           "search_wall_s": round(wall, 1), **spacing,
           # an observer bank whose best pipeline missed inside its square root: the root spacings searched
           **({"isqrt_every_searched": rec["isqrt_every_searched"]} if "isqrt_every_searched" in rec else {})}
    if chosen is not None:
        row.update(chosen_latency_cycles=chosen["latency_cycles"], chosen_label=chosen["label"],
                   chosen_fmax_mhz=chosen["fmax_mhz"], chosen_latency_ns=chosen["latency_ns"],
                   luts=chosen["luts"], dsp=chosen["dsp"], bram=chosen["bram"], ii=man["ii"],
                   manifest_latency_cycles=man["latency_cycles"])
    progress(f"{kind}: {'met' if rec['met'] else 'NOT met'} {target:g} MHz; "
             + ", ".join(f"{c['latency_cycles']} cyc {c['fmax_mhz']:.1f} MHz" for c in row["measured"])
             + f" ({row['search_wall_s']} s)")
    return row


def markdown(doc: dict) -> str:
    lines = [f"# Timing closure of every design kind (`benchmarks/timing_closure_kinds.py`"
             f"{', ' + doc['label'] if doc.get('label') else ''})", "",
             f"Target {doc['target_mhz']:g} MHz on {doc['fpga']} (nextpnr seed 1, the timing harness); small seeded "
             "models (see the script). Measured candidates shallowest first (the search jumps ahead when the "
             "pre-screen allows, then checks the skipped ones downwards); the chosen one is the shallowest "
             "measured that reaches the target above the last miss (latency counts the whole design).", "",
             "| kind | design | architecture | met | chosen (cycles, pipeline) | fmax MHz | latency ns | II | LUT4 | DSP | "
             "measured (cycles: MHz) | candidates | search s |",
             "|---|---|---|---|---|---:|---:|---:|---:|---:|---|---:|---:|"]
    for r in doc["rows"]:
        kind = r["kind"] + (f" (isqrt_every {r['isqrt_every']})" if r.get("isqrt_every") is not None else "")
        if r.get("isqrt_every_searched"):
            kind += f" (root spacing searched: {', '.join(map(str, r['isqrt_every_searched']))})"
        meas = ", ".join(f"{c['latency_cycles']}: {c['fmax_mhz']:.1f}" for c in r["measured"])
        if r["met"]:
            cells = [kind, r["design"], r["architecture"], "yes", f"{r['chosen_latency_cycles']}, {r['chosen_label']}",
                     f"{r['chosen_fmax_mhz']:.1f}", f"{r['chosen_latency_ns']:.1f}", r["ii"], r["luts"], r["dsp"]]
        else:
            cells = [kind, r["design"], r["architecture"], f"no (best {r['best_fmax_mhz']:.1f})", "-", "-", "-", "-", "-", "-"]
        lines.append("| " + " | ".join(str(c) for c in [*cells, meas, r["candidates"], r["search_wall_s"]]) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", default=None, help=f"kinds, comma-separated (default: all of {', '.join(KINDS)}; --quick: {QUICK_KINDS})")
    ap.add_argument("--clock-mhz", type=float, default=100.0, help="target clock in MHz (default: %(default)s)")
    ap.add_argument("--fpga", choices=("ecp5", "ice40"), default="ecp5", help="FPGA family (default: %(default)s)")
    ap.add_argument("--stem", default="timing_closure_kinds", help="file-name stem of the results (default: %(default)s)")
    ap.add_argument("--label", default="", help="a note for the table's title, e.g. the commit measured")
    ap.add_argument("--quick", action="store_true", help="the plain core only, written as STEM_quick.*: not a result to quote")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="folder of the result files (default: %(default)s)")
    ap.add_argument("--isqrt-every", type=int, default=None,
                    help="observer-bank kinds: digit steps of the square root between registers (generate --isqrt-every; default 3)")
    a = ap.parse_args(argv)
    from pwas_hdl.bench_results import check_stem, checked_outdir, make_outdir, write_json_and_markdown

    stem = check_stem(a.stem) + ("_quick" if a.quick else "")
    kinds = parse_kinds(a.kinds or (QUICK_KINDS if a.quick else ",".join(KINDS)))
    if not 0 < a.clock_mhz < 2000:
        raise InputError(f"--clock-mhz must be in (0, 2000) MHz, got {a.clock_mhz:g}")
    if a.isqrt_every is not None:
        if a.isqrt_every < 1:
            raise InputError(f"--isqrt-every must be a positive integer, got {a.isqrt_every}")
        if not any(is_bank_kind(k) for k in kinds):
            raise InputError(f"--isqrt-every applies to the observer-bank kinds, and --kinds names none: {','.join(kinds)}")
    checked_outdir(a.outdir)  # refused before minutes of place and route, not after
    t0 = time.perf_counter()
    rows = [run_kind(k, a.clock_mhz, a.fpga, isqrt_every=a.isqrt_every) for k in kinds]
    outdir = make_outdir(a.outdir)
    doc = {"format": "pwas-hdl-timing-closure-kinds", "version": 1, "label": a.label, "target_mhz": a.clock_mhz,
           "fpga": a.fpga, "rows": rows, "environment": environment(time.perf_counter() - t0)}
    write_json_and_markdown(outdir, stem, doc, markdown(doc))


if __name__ == "__main__":
    sys.exit(script_main(main))
