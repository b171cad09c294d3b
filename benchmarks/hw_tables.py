"""Hardware rows of the seed paper's Tables III, IV and VI, measured with open tools (nextpnr).

Usage::

    python benchmarks/hw_tables.py [--quick] [--fpga ecp5,ice40] [--designs KEY,...] [--outdir benchmarks/results]
                                   [--workdir DIR] [--resume]

Designs (12-bit inputs, weights in the fewest bits that hold them, as ``pwas-hdl generate`` does):

* Lorenz (paper eq. 18), fitted on ``pwas_hdl.systems.lorenz.lorenz(6000, seed=0)`` with sigma by 5-fold
  cross-validation, gamma = 1.2, zero-order Tikhonov: My = 3, p = 7 (N = 512); My = 4, p = 7
  (N = 4096, Table II); My = 5, p = 7 (N = 32768); My = 4, p = 3 (N = 256); My = 4, p = 1 (N = 16).
* Helicopter size (Table VI: n = 6, Mu = 2 with nu = 2, My = 2 with ny = 1, p = 3, N = 4096). There
  is no helicopter data here: the model is fitted on a *synthetic* closed-loop plant
  (:func:`pwas_hdl.systems.helicopter.helicopter`: a nonlinear 2-DOF elevation/azimuth system with propeller motors and
  two PID loops, references as inputs, azimuth measured, elevation estimated), gamma = 1.1,
  first-order Tikhonov as in the paper, sigma by cross-validation.

Every design is generated as the core (``design="core"``) in the builds of ``generate --goal``
(:data:`pwas_hdl.hdl.params.GOALS`), with the goal's memory (``--memory`` not given,
:mod:`pwas_hdl.design.goal_memory`: banked, except the ECP5 latency build, replicated where its
bit-field addresses and block RAMs fit; the JSON's ``memory`` per build says which):

* ``latency``: ``--goal latency`` (fewest nanoseconds; the ``short`` preset);
* ``default``: no option (``--goal balanced``, the ``balanced`` preset);
* ``throughput``: ``--goal throughput --fpga F`` (highest clock; ``max`` on ECP5, ``max-lut`` on iCE40,
  :func:`pwas_hdl.hdl.params.goal_preset`);

ECP5 gets all three, iCE40 the throughput build. Each is placed and routed with nextpnr
(``--freq`` 150 MHz on ECP5 LFE5U-45F speed 6, 100 MHz on iCE40 HX8K) by
:func:`pwas_hdl.flow.synthesis.synthesize` inside its timing harness (every port registered, so the
input and output paths count in fmax; the harness ``pwas-hdl synth`` and ``generate --clock-mhz``
use), with the ECP5 multiplier / block-RAM registers packed (:mod:`pwas_hdl.flow.hard_registers`) and
synth's default floorplan (:mod:`pwas_hdl.flow.floorplan`: the latency build's block RAMs and multipliers
on fixed sites of the LFE5U-45F; the other builds placed freely).
The N = 4096 Lorenz core is placed with nextpnr seeds 1, 2, 3 and its figures are the seed
averages (fmax is the mean; latency = cycles / mean fmax); the other designs use seed 1. Reported: cycles, fmax, latency in ns (cycles / fmax), LUT4 / FF (core,
harness excluded) / DSP / BRAM, beside the paper's L (ns) and SO (Spartan-3 xc3s200 slice
occupation). On ECP5 the ``short`` build is also made with ``n + 1`` replicated copies of the
memory, for the banked-versus-replicated words and BRAMs. For the N = 4096 Lorenz core the script
also runs a ``target_mhz`` timing closure (ECP5, 125 MHz) and simulates the three builds
(Amaranth, no stalls) to measure the initiation interval and check them bit for bit against the
bit-true model; the must-show section checks the figures issue 14 asks for.

``--quick``: the N = 4096 Lorenz core, ECP5, ``default`` build, seed 1 (a smoke test; writes
``hw_tables_quick.{json,md}``). Every place-and-route run is an independent task of
:class:`pwas_hdl.flow.executor.Executor`: serially by default, on a local Dask cluster with
``--workers N``, or on an existing cluster with ``--scheduler tcp://HOST:PORT`` (identical numbers;
the timing closure's candidates are measured speculatively on the workers). Results are written
after the place-and-route batch and after each later step (partial files); ``--resume`` reuses the
measurements of an earlier JSON made with the same settings.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent

from pwas_hdl.bench_results import default_outdir
from pwas_hdl import __version__  # noqa: E402
from pwas_hdl.io.atomic import atomic_write_text  # noqa: E402

FORMAT = "pwas-hdl-hw-tables"
SEED = 1
#: nextpnr seeds of the must-show design (its figures are the averages); other designs: SEED
SEEDS = (1, 2, 3)
#: build name -> generate --goal (None: the default)
GOAL_OF_BUILD = {"latency": "latency", "default": None, "throughput": "throughput"}
BUILDS = {"ecp5": ("latency", "default", "throughput"), "ice40": ("throughput",)}
FREQ = {"ecp5": 150.0, "ice40": 100.0}
DEMO_TARGET = {"ecp5": 125.0}
XC3S200_SLICES = 1920  # Spartan-3 XC3S200: 1920 slices (2 LUT4 + 2 FF each), 12 BRAM18, 12 MULT18X18

DESIGNS: list[dict[str, Any]] = [
    {"key": "lorenz_my3_p7", "plant": "lorenz", "table": "III", "mu": 0, "my": 3, "p": 7, "N": 512, "paper_L_ns": 65, "paper_SO_pct": 32},
    {"key": "lorenz_my4_p7", "plant": "lorenz", "table": "II-V", "mu": 0, "my": 4, "p": 7, "N": 4096, "paper_L_ns": 65, "paper_SO_pct": 28},
    {"key": "lorenz_my5_p7", "plant": "lorenz", "table": "III", "mu": 0, "my": 5, "p": 7, "N": 32768, "paper_L_ns": 70, "paper_SO_pct": 33},
    {"key": "lorenz_my4_p3", "plant": "lorenz", "table": "IV", "mu": 0, "my": 4, "p": 3, "N": 256, "paper_L_ns": 70, "paper_SO_pct": 20},
    {"key": "lorenz_my4_p1", "plant": "lorenz", "table": "IV", "mu": 0, "my": 4, "p": 1, "N": 16, "paper_L_ns": 66, "paper_SO_pct": 19},
    {"key": "heli_mu2_my2_p3", "plant": "helicopter (synthetic)", "table": "VI", "mu": 2, "my": 2, "p": 3, "N": 4096, "paper_L_ns": 74, "paper_SO_pct": 29},
]
MUST_SHOW = "lorenz_my4_p7"


# ---------------------------------------------------------------------------------------------
# models
# ---------------------------------------------------------------------------------------------
def fit_model(d: dict[str, Any], workdir: Path, log) -> tuple[Path, dict[str, Any]]:
    """Fit (or reuse) the model of design ``d``; returns the model file and a few fit numbers."""
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.helicopter import helicopter
    from pwas_hdl.systems.lorenz import lorenz

    path = workdir / "models" / f"{d['key']}.json"
    info_path = path.with_suffix(".info.json")
    if path.is_file() and info_path.is_file():
        return path, json.loads(info_path.read_text())
    path.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    if d["plant"] == "lorenz":
        data = lorenz(6000, seed=0)
        m = PWASVirtualSensor(mu=0, my=d["my"], partitions=d["p"], gamma=1.2, tikhonov_order=0,
                              output_names=["y"], target_names=["z"]).fit(None, data.y, data.z)
        info = {"data": "pwas_hdl.systems.lorenz.lorenz(6000, seed=0)", "gamma": 1.2, "tikhonov_order": 0}
    else:
        log("simulating the synthetic helicopter (25000 samples) ...")
        heli = helicopter(25000, seed=0)
        u, y, z, zt = heli.u, heli.y, heli.z, heli.z_true
        tr, te = slice(0, 20000), slice(20000, None)
        m = PWASVirtualSensor(mu=d["mu"], my=d["my"], partitions=d["p"], gamma=1.1, tikhonov_order=1,
                              input_names=["psi_d", "phi_d"], output_names=["phi"], target_names=["psi"]).fit(u[tr], y[tr], z[tr])
        zh = m.predict(u[te], y[te])
        lag = max(d["mu"], d["my"]) - 1
        rmse = float(np.sqrt(np.mean((zh[:, 0] - zt[te][lag:, 0]) ** 2)))
        info = {"data": "synthetic closed-loop 2-DOF helicopter (pwas_hdl.systems.helicopter.helicopter), "
                        "T = 25000 at 10 ms, fit on the first 20000", "gamma": 1.1, "tikhonov_order": 1,
                "rmse_test_rad": round(rmse, 5), "std_psi_rad": round(float(np.std(zt)), 5),
                "note": "not the paper's helicopter data (none is available here); only the size (n, p, N) matches Table VI"}
    assert m.grid_.n_vertices == d["N"], (d["key"], m.grid_.n_vertices)
    info.update(sigma=float(m.sigma_), n=int(m.grid_.n), fit_s=round(time.monotonic() - t0, 2))
    m.save(path)
    info_path.write_text(json.dumps(info, indent=1) + "\n")
    return path, info


# ---------------------------------------------------------------------------------------------
# measurements
# ---------------------------------------------------------------------------------------------
def _stat_needs(work: Path, fpga: str) -> dict[str, Any] | None:
    """Resources Yosys mapped (``stat.json``) when nextpnr found that the design does not fit."""
    from pwas_hdl.flow.synthesis import _count_resources, _read_stat

    stat = work / "pnr" / "stat.json"
    if not stat.is_file():
        return None
    try:
        st = _read_stat(stat, json.loads((work / "manifest.json").read_text())["top"])
    except (KeyError, ValueError):
        return None
    r = _count_resources(fpga, st["cells"])
    return {k: r[k] for k in ("luts", "ffs", "dsp", "bram", "bram_bits")}


def measure(model_path: Path, fpga: str, pipeline, memory: str | None, workdir: Path, memory_init: str = "inline",
            seed: int = SEED, goal: str | None = None) -> dict[str, Any]:
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.flow.timing_closure import measure_design

    gd = build_design(model_path, pipeline=pipeline, memory=memory, memory_init=memory_init, goal=goal, fpga_target=fpga)
    man = gd.manifest
    memory = man["generator"]["options"]["memory"]  # None given: the goal's (pwas_hdl.design.goal_memory)
    base = {"fpga": fpga, "memory": memory, "memory_init": memory_init, "goal": goal, "seed": seed,
            "pipeline": man["pipeline"], "latency_cycles": man["latency_cycles"],
            "ii": man["ii"], "freq_constraint_mhz": FREQ[fpga], "memory_plan": {k: man["memory"][k] for k in ("memories", "depth", "word_bits", "words", "bits")}}
    t0 = time.monotonic()
    try:
        r = measure_design(gd, fpga, freq_mhz=FREQ[fpga], seed=seed, workdir=workdir)
    except ValueError as exc:
        msg = str(exc).split(" (see ")[0]
        base.update(fits=False, error=msg, yosys_mapped=_stat_needs(workdir, fpga), runtime_s=round(time.monotonic() - t0, 1))
        return base
    util = r.get("utilization") or {}
    base.update(
        fits=True, part=r["part"], fmax_mhz=r["fmax_mhz"], latency_ns=r["latency_ns"], luts=r["luts"], carry=r["carry"],
        ffs_core=r["ffs_core"], ffs_with_harness=r["ffs"], dsp=r["dsp"], bram=r["bram"], bram_bits=r["bram_bits"],
        logic_cells=r["logic_cells"], critical_path=r["critical_path"], hard_registers=r.get("hard_registers"),
        floorplan=r.get("floorplan"),
        utilization_pct={k: v["percent"] for k, v in util.items() if v["used"]},
        tools=r["tools"], runtime_s=round(time.monotonic() - t0, 1),
    )
    return base


def _measure_task(job: dict[str, Any]) -> dict[str, Any]:
    """One place-and-route measurement as a pure task for :class:`~pwas_hdl.flow.executor.Executor`."""
    return measure(Path(job["model"]), job["fpga"], job["pipeline"], job["memory"], Path(job["workdir"]), job["memory_init"],
                   job.get("seed", SEED), job.get("goal"))


def aggregate(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """One build's figures over its nextpnr seeds: mean fmax, latency = cycles / mean fmax.

    Resources come from Yosys (the same for every seed); ``seeds`` / ``fmax_seeds`` /
    ``critical_paths`` keep the per-seed numbers; ``critical_path`` is the slowest seed's.
    """
    runs = sorted(runs, key=lambda r: r["seed"])
    if len(runs) == 1 or not all(r.get("fits") for r in runs):
        out = dict(runs[0])
        out["seeds"] = [r["seed"] for r in runs]
        return out
    out = dict(runs[0])
    fm = [r["fmax_mhz"] for r in runs]
    mean = sum(fm) / len(fm)
    out.update(seeds=[r["seed"] for r in runs], fmax_seeds=fm, fmax_mhz=round(mean, 3),
               fmax_min_mhz=min(fm), fmax_max_mhz=max(fm),
               latency_ns=round(runs[0]["latency_cycles"] * 1000.0 / mean, 3),
               critical_paths=[r["critical_path"] for r in runs],
               critical_path=min(runs, key=lambda r: r["fmax_mhz"])["critical_path"],
               runtime_s=round(sum(r.get("runtime_s") or 0 for r in runs), 1))
    return out


def simulate_ii(model_path: Path, goal: str | None, samples: int = 300, fpga: str = "ecp5") -> dict[str, Any]:
    """Amaranth simulation without stalls of the ``generate --goal`` build (for ``fpga``): measured II and latency, bit-exact check."""
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.hdl.simulate import pack_fields, run_stream, unpack_fields

    gd = build_design(model_path, goal=goal, fpga_target=fpga)
    fxm, dut = gd.model, gd.component
    p = dut.params
    rng = np.random.default_rng(0)
    lo = np.array(fxm.lo_codes)
    span = np.array(fxm.grid.partitions) << np.array(fxm.frac_bits)
    q = lo + (rng.random((samples, p.n)) * (span + 1)).astype(np.int64)
    q[: samples // 10] = rng.integers(-(1 << (p.in_width - 1)), 1 << (p.in_width - 1), (samples // 10, p.n))
    r = run_stream(dut, [pack_fields(row, p.in_width) for row in q])
    z = np.array([unpack_fields(w, p.out_width, p.nz) for w in r.outputs], dtype=np.int64)
    ref, _ = fxm.evaluate(q)
    acc = r.accepted_at
    gaps = {b - a for a, b in zip(acc, acc[1:])}
    return {"samples": samples, "ii_measured": max(gaps) if gaps else None, "latency_measured": sorted({b - a for a, b in zip(acc, r.produced_at)}),
            "bit_exact": bool(np.array_equal(z, ref)), "simulator": "amaranth (pysim)"}


# ---------------------------------------------------------------------------------------------
# output
# ---------------------------------------------------------------------------------------------
#: issue 14's figures: (check, build, FPGA, key, comparison, bound)
TARGETS = [
    ("latency-first latency (ns)", "latency", "ecp5", "latency_ns", "<=", 30.0),
    ("throughput-first fmax (MHz)", "throughput", "ecp5", "fmax_mhz", ">=", 200.0),
    ("default latency (ns)", "default", "ecp5", "latency_ns", "<=", 65.0),
    ("default fmax (MHz)", "default", "ecp5", "fmax_mhz", ">=", 100.0),
    ("iCE40 HX8K throughput-first fmax (MHz)", "throughput", "ice40", "fmax_mhz", ">=", 100.0),
    ("default LUT4 on ECP5", "default", "ecp5", "luts", "<=", 800),
]


def must_show(d: dict[str, Any], sims: dict[str, Any]) -> dict[str, Any]:
    """Issue 14's figures for the must-show design, each with what was measured and whether it is met."""
    checks = []
    for what, build, fpga, key, op, bound in TARGETS:
        b = d.get("builds", {}).get(fpga, {}).get(build)
        if not b or not b.get("fits") or b.get(key) is None:
            continue
        v = b[key]
        met = v <= bound if op == "<=" else v >= bound
        checks.append({"what": what, "build": build, "fpga": fpga, "measured": v, "bound": f"{op} {bound:g}", "met": bool(met),
                       "cycles": b["latency_cycles"], "seeds": b.get("seeds"), "critical_path": b.get("critical_path")})
    return {"design": d["key"], "checks": checks,
            "ii_simulated": {k: v["ii_measured"] for k, v in sims.items()},
            "bit_exact": {k: v["bit_exact"] for k, v in sims.items()}, "sim_samples": next(iter(sims.values()))["samples"] if sims else None}


def _so_estimate(b: dict[str, Any]) -> float | None:
    if not b.get("fits") or b.get("luts") is None:
        return None
    return 100.0 * math.ceil(max(b["luts"], b["ffs_core"]) / 2) / XC3S200_SLICES


def _f(v, fmt="{:.1f}") -> str:
    return "-" if v is None else fmt.format(v)


def markdown(res: dict[str, Any]) -> str:
    s = res["settings"]
    lines = [
        "# Hardware of the paper's Tables III, IV and VI, measured (pwas-hdl)",
        "",
        f"Generated by `python benchmarks/hw_tables.py{' --quick' if s['quick'] else ''}`; numbers in "
        f"`{'hw_tables_quick' if s['quick'] else 'hw_tables'}.json`. {'**Partial: the run has not finished.**' if not res.get('complete') else ''}",
        "",
        f"Core designs, 12-bit inputs, the goal's memory (banked; replicated where the build says so). `--freq` {s['freq_mhz']['ecp5']:g} MHz on ECP5 "
        f"(LFE5U-45F-6, {s['parts'].get('ecp5', 'CABGA381')}) and {s['freq_mhz']['ice40']:g} MHz on iCE40 (HX8K CT256); every run "
        "inside the timing harness of `pwas-hdl synth` (all ports registered, so fmax covers the input and output paths), "
        "ECP5 multiplier and block-RAM registers packed into the hard blocks. Builds = `generate --goal latency`, the default "
        "(`balanced`), `--goal throughput`. nextpnr seeds: "
        f"{', '.join(str(v) for v in s.get('seeds', [s['seed']]))} for {s.get('seeds_design', '-')} (fmax = the mean, "
        "min-max in brackets; latency (ns) = cycles / mean fmax), seed 1 elsewhere. FF = the core's flip-flops outside the "
        "hard blocks (harness excluded). Critical path: start -> end stage (delay) of the slowest seed.",
        "",
        "Paper: Xilinx Spartan-3 xc3s200 (1920 slices, 12 BRAM, 12 multipliers), 12-bit inputs; SO = slice occupation. "
        "*logic use* = nextpnr's share of the device's LUT cells (ECP5 TRELLIS_COMB of 43848, iCE40 logic cells of 7680). "
        "*~SO* (ECP5 rows, which use hard multipliers like the Spartan-3) turns our LUT4/FF count into xc3s200 slices as "
        "max(LUT4, FF)/2 over 1920: a rough equivalence across vendors, not a Spartan-3 result.",
        "",
        "| design | table | n | N | FPGA | build | cycles | fmax (MHz) | latency (ns) | LUT4 | FF | DSP | BRAM | logic use | ~SO | critical path | paper L (ns) | paper SO |",
        "|---|---|---:|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|",
    ]
    for d in res["designs"]:
        first = True
        for fpga in ("ecp5", "ice40"):
            for build in GOAL_OF_BUILD:
                b = d.get("builds", {}).get(fpga, {}).get(build)
                if b is None:
                    continue
                head = [d["key"], d["table"], str(d.get("n", "")), str(d["N"])] if first else ["", "", "", ""]
                paper = [str(d["paper_L_ns"]), f"{d['paper_SO_pct']} %"] if first else ["", ""]
                first = False
                if b.get("fits"):
                    so = _so_estimate(b) if fpga == "ecp5" else None
                    use = (b.get("utilization_pct") or {}).get("TRELLIS_COMB" if fpga == "ecp5" else "ICESTORM_LC")
                    fm = _f(b["fmax_mhz"])
                    if b.get("fmax_seeds"):
                        fm += f" ({b['fmax_min_mhz']:.1f}-{b['fmax_max_mhz']:.1f})"
                    cp = b.get("critical_path") or {}
                    cpt = f"{cp.get('from')} -> {cp.get('to')} ({cp.get('delay_ns')} ns)" if cp else "-"
                    bname = build + (f" ({b['memory']})" if b.get("memory", "banked") != "banked" else "")
                    row = [fpga, bname, str(b["latency_cycles"]), fm, _f(b["latency_ns"]), str(b["luts"]),
                           str(b["ffs_core"]), str(b["dsp"]), str(b["bram"]), _f(use, "{:.0f} %"), _f(so, "{:.0f} %"), cpt]
                else:
                    y = b.get("yosys_mapped") or {}
                    why = b.get("error", "does not fit")
                    short = "does not fit" + (f" (needs {y['bram']} BRAM)" if y.get("bram") is not None and "RAM" in why else "")
                    if "logic cells" in why or "LUT4" in why:
                        short = "does not fit" + (f" (needs {y.get('luts')} LUT4)" if y.get("luts") else "") + (" + BRAM" if "RAM" in why else "")
                    row = [fpga, build, str(b["latency_cycles"]), short, "-", _f(y.get("luts"), "({})"), "-", _f(y.get("dsp"), "({})"),
                           _f(y.get("bram"), "({})"), "-", "-", "-"]
                lines.append("| " + " | ".join(head + row + paper) + " |")
    lines += [
        "",
        "## Memory: banked (n + 1 banks, about N words, `default` build) against n + 1 copies of the N words (`min` pipeline), ECP5",
        "",
        "| design | n | N | weight bits | banked words | banked BRAM (bits) | replicated words | replicated BRAM (bits) | (n+1) N w bits |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for d in res["designs"]:
        e = d.get("builds", {}).get("ecp5", {})
        b, r = e.get("default"), e.get("replicated")
        if b is None and r is None:
            continue
        mem = d.get("memory", {})

        def bram(x):
            if x is None:
                return "-"
            if x.get("fits"):
                return f"{x['bram']} ({x['bram_bits']})"
            y = x.get("yosys_mapped") or {}
            return f"does not fit: needs {y.get('bram')} DP16KD ({y.get('bram_bits')})" if y.get("bram") is not None else "does not fit"

        lines.append(f"| {d['key']} | {d.get('n')} | {d['N']} | {mem.get('weight_bits')} | {mem.get('banked_words')} | {bram(b)} | "
                     f"{mem.get('replicated_words')} | {bram(r)} | {mem.get('replicated_bits')} |")
    tc = res.get("timing_closure")
    if tc:
        lines += ["", f"## Timing closure demo: `generate --target-mhz {tc['target_mhz']:g} --fpga {tc['fpga']}` on {tc['design']}", ""]
        if tc.get("error"):
            lines.append(f"Error: {tc['error']}")
        lines += [
            "| cycles | pipeline | fmax (MHz) | latency (ns) | critical path | result |",
            "|---:|---|---:|---:|---|---|",
        ]
        for k, c in enumerate(tc["candidates"]):
            if not c["measured"]:
                continue
            if c["measured"]:
                cp = c.get("critical_path") or {}
                lines.append(f"| {c['latency_cycles']} | {c['label']} | {_f(c['fmax_mhz'])} | {_f(c['latency_ns'])} | "
                             f"{cp.get('from')} -> {cp.get('to')} ({cp.get('delay_ns')} ns) | "
                             f"{'**chosen**' if tc.get('chosen') == k else ('meets' if c['meets_target'] else 'misses')} |")
        skipped: dict[str, list[str]] = {}
        for c in tc["candidates"]:
            if not c["measured"]:
                skipped.setdefault(c["note"], []).append(str(c["latency_cycles"]))
        lines.append("")
        for note, cyc in skipped.items():
            lines.append(f"Not measured, {note}: {', '.join(cyc)} cycles.  ")
        lines.append(f"Measured in the order {tc['measurements']} (cycles); {tc.get('runtime_s')} s.")
    ms = res.get("must_show")
    if ms:
        lines += ["", f"## Must show (issue 14): the N = 4096 Lorenz design ({ms['design']})", "",
                  "| figure | build | FPGA | cycles | measured | target | met | critical path (slowest seed) |",
                  "|---|---|---|---:|---:|---|---|---|"]
        for c in ms.get("checks", []):
            cp = c.get("critical_path") or {}
            cpt = f"{cp.get('from')} -> {cp.get('to')} ({cp.get('delay_ns')} ns, routing {cp.get('routing_ns')} ns)" if cp else "-"
            lines.append(f"| {c['what']} | {c['build']} | {c['fpga']} | {c['cycles']} | {c['measured']} | {c['bound']} | "
                         f"{'yes' if c['met'] else '**no**'} | {cpt} |")
        lines += ["", f"Amaranth simulation without stalls ({ms.get('sim_samples')} samples): II "
                      f"{ms.get('ii_simulated')}, bit-exact against the bit-true model: {ms.get('bit_exact')}."]
    lines += ["", "## Notes", ""]
    lines += [f"- {t}" for t in res.get("notes", [])]
    env = res.get("environment", {})
    tools = env.get("tools") or {}
    tool_txt = ", ".join(f"{k} {v}" for k, v in tools.items() if k.startswith("yowasp")) or "-"
    lines += ["", f"Tools: {tools.get('yosys', '-')}; {tool_txt}. Python {env.get('python')}, {env.get('cpus')} CPUs "
                  f"(shared with other jobs). Synthesis + place and route time summed over all measurements: "
                  f"{res.get('measure_s')} s; this invocation {res.get('runtime_s')} s."]
    return "\n".join(lines) + "\n"


def write(res: dict[str, Any], outdir: Path, stem: str) -> None:
    builds = [b for d in res["designs"] for f in d.get("builds", {}).values() for b in f.values()]
    tools: dict[str, str] = {}
    for b in builds:
        tools.update(b.get("tools") or {})
    tools.pop("nextpnr", None)
    res["environment"]["tools"] = dict(sorted(tools.items())) or None
    res["measure_s"] = round(sum(b.get("runtime_s") or 0 for b in builds) + ((res.get("timing_closure") or {}).get("runtime_s") or 0), 1)
    outdir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(outdir / f"{stem}.json", json.dumps(res, indent=1) + "\n")
    atomic_write_text(outdir / f"{stem}.md", markdown(res))


# ---------------------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="N = 4096 Lorenz, ECP5, default build, seed 1 only")
    ap.add_argument("--no-replicated", action="store_true", help="skip the replicated-memory builds (memory table)")
    ap.add_argument("--other-builds", default=None,
                    help="comma-separated builds (latency, default, throughput) of the designs other than the N = 4096 Lorenz "
                         "core (default: all); an FPGA whose builds are all left out is skipped for them")
    ap.add_argument("--redo", default="", help="with --resume: comma-separated FPGA:BUILD measured again (e.g. ice40:throughput)")
    ap.add_argument("--no-timing-closure", action="store_true", help="skip the generate --clock-mhz demo")
    ap.add_argument("--fpga", default="ecp5,ice40", help="comma-separated: ecp5, ice40")
    ap.add_argument("--designs", default=None, help="comma-separated design keys (default: all)")
    ap.add_argument("--outdir", type=Path, default=default_outdir())
    ap.add_argument("--workdir", type=Path, default=None, help="place-and-route folders (default: a folder under /tmp)")
    ap.add_argument("--resume", action="store_true", help="reuse measurements of an earlier JSON with the same settings")
    ap.add_argument("--workers", type=int, default=None, help="place and route on a local Dask cluster of N workers (default: serially)")
    ap.add_argument("--scheduler", default=None, help="place and route on an existing Dask cluster (tcp://HOST:PORT)")
    args = ap.parse_args(argv)
    from pwas_hdl.flow.executor import Executor

    with Executor(workers=args.workers, scheduler=args.scheduler) as ex:
        return _run(args, ex)


def _run(args: argparse.Namespace, ex) -> int:

    from pwas_hdl.flow.timing_closure import close_timing, TimingNotMet, pipeline_candidates
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.design.goal_memory import goal_memory

    stem = "hw_tables_quick" if args.quick else "hw_tables"
    fpgas = ["ecp5"] if args.quick else [f.strip() for f in args.fpga.split(",") if f.strip()]
    keys = [MUST_SHOW] if args.quick else ([k.strip() for k in args.designs.split(",")] if args.designs else [d["key"] for d in DESIGNS])
    designs = [dict(d) for d in DESIGNS if d["key"] in keys]
    work = args.workdir or Path(os.environ.get("TMPDIR", "/tmp")) / "pwas-hw-tables"
    work.mkdir(parents=True, exist_ok=True)

    def log(msg: str) -> None:
        print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)

    settings = {"quick": args.quick, "other_builds": args.other_builds, "replicated": not args.no_replicated, "seed": SEED, "seeds": list(SEEDS) if not args.quick else [SEED], "seeds_design": MUST_SHOW,
                "freq_mhz": FREQ, "fpgas": fpgas, "input_bits": 12,
                "parts": {"ecp5": "CABGA381", "ice40": "CT256"}}
    old: dict[str, Any] = {}
    if args.resume and (args.outdir / f"{stem}.json").is_file():
        prev = json.loads((args.outdir / f"{stem}.json").read_text())
        if prev.get("settings", {}).get("seed") == SEED and prev.get("settings", {}).get("freq_mhz") == FREQ:
            old = {d["key"]: d for d in prev.get("designs", [])}
            tc = prev.get("timing_closure")
            if tc and tc.get("target_mhz") == DEMO_TARGET["ecp5"]:
                old["__tc__"] = tc
    res: dict[str, Any] = {
        "format": FORMAT, "version": 1, "pwas_hdl": __version__, "settings": settings, "complete": False,
        "designs": designs, "timing_closure": None, "must_show": None,
        "notes": [
            "The helicopter row is fitted on a synthetic closed-loop plant (pwas_hdl.systems.helicopter; no helicopter data "
            "is available here); only its size (n = 6, p = 3, N = 4096) matches Table VI.",
            "Sigma by 5-fold cross-validation over logspace(-7, 3, 21) for every model.",
            "iCE40 HX8K has no DSPs (the multipliers are built from LUTs and carries) and 32 block RAMs of 4 kbit.",
            "A row 'does not fit' is a nextpnr refusal; the bracketed numbers are what Yosys mapped.",
            "BRAM 0: Yosys put the small weight banks in LUTs (ROM logic), which also removes the block RAM's long "
            "clock-to-output from the critical path (hence the higher fmax of the small designs).",
            "The pipelines of the three builds are the presets of pwas_hdl.hdl.params.goal_preset(goal, fpga) (the manifest's "
            "pipeline: latency = short, default = balanced, throughput = max on ECP5 and max-lut on iCE40); "
            "the ECP5 multiplier and block-RAM registers are packed by pwas_hdl.flow.hard_registers (hard_registers in "
            "the JSON counts them per build).",
            "Memory: generate's default for the goal (--memory not given, pwas_hdl.design.goal_memory): banked, except "
            "the ECP5 latency build, which takes the n + 1 replicated copies where their addresses are bit fields (p = 7, 3, 1) "
            "and their block RAMs fit the floorplan's row (not lorenz_my5_p7: 6 x 24 DP16KD); the build column names it.",
            "Hard-block floorplan (pwas-hdl synth --floorplan auto, pwas_hdl.flow.floorplan): the latency build's block RAMs "
            "on fixed sites of the LFE5U-45F's central EBR row (Y34; a replicated copy's blocks adjacent) and its multipliers "
            "on the DSP row Y46, cell k on site k; every other build (mem_out, or no mul_in) is placed freely by nextpnr "
            "(floorplan in the JSON per build).",
            "Weights inline in the Verilog, except the replicated-memory builds of the memory table, which load them with $readmemh "
            "(Yosys parses (n+1) N inline initialisers very slowly); the memory contents are the same.",
            "Fixed-point formats are generate's defaults (the noise-budget rule of pwas_hdl.fixedpoint.bittrue); the weight width "
            "of each design is in the memory table.",
        ],
        "environment": {"python": platform.python_version(), "cpus": os.cpu_count(), "tools": None},
    }
    t_start = time.monotonic()
    # 1. fit every model and list the place-and-route jobs (those not reused from --resume)
    jobs: list[dict[str, Any]] = []
    builds_of: dict[str, dict[str, Any]] = {}
    models: dict[str, Path] = {}
    for d in designs:
        prev = old.get(d["key"], {})
        model_path, info = fit_model(d, work, log)
        d["fit"] = info
        d["n"] = info["n"]
        models[d["key"]] = model_path
        n = info["n"]
        gd = build_design(model_path, pipeline="min")
        wb = gd.model.weight_format.bits
        d["memory"] = {"weight_bits": wb, "banked_words": gd.manifest["memory"]["words"], "banked_bits": gd.manifest["memory"]["bits"],
                       "replicated_words": (n + 1) * d["N"], "replicated_bits": (n + 1) * d["N"] * wb}
        builds_of[d["key"]] = dict(GOAL_OF_BUILD)
        d["builds"] = {}
        seeds = SEEDS if (d["key"] == MUST_SHOW and not args.quick) else (SEED,)
        for fpga in fpgas:
            d["builds"][fpga] = {}
            names = ("default",) if args.quick else BUILDS[fpga]
            if args.other_builds and d["key"] != MUST_SHOW:
                keep = {b.strip() for b in args.other_builds.split(",")}
                names = tuple(b for b in names if b in keep)
            todo = [(b, None, GOAL_OF_BUILD[b], None, "inline") for b in names]  # None: the goal's memory
            if not args.quick and fpga == "ecp5" and not args.no_replicated:
                # $readmemh: Yosys reads (n+1) N inline initialisers very slowly (N = 32768: > 10 min)
                todo.append(("replicated", "min", None, "replicated", "readmemh"))
            for name, pipe, goal, mem, init in todo:
                cached = prev.get("builds", {}).get(fpga, {}).get(name)
                # a build measured with another memory than the goal's now (pwas_hdl.design.goal_memory) is redone
                now = mem or goal_memory(goal, fpga, gd.model, plain=True)
                if cached is not None and cached.get("memory", "banked") != now:
                    cached = None
                if cached is not None and f"{fpga}:{name}" not in {r.strip() for r in args.redo.split(",")}:
                    d["builds"][fpga][name] = cached
                    log(f"{d['key']} {fpga} {name}: reused")
                    continue
                for sd in (seeds if name != "replicated" else (SEED,)):
                    jobs.append({"key": d["key"], "name": name, "model": str(model_path), "fpga": fpga, "pipeline": pipe,
                                 "goal": goal, "seed": sd, "memory": mem, "memory_init": init,
                                 "workdir": str(work / "pnr" / f"{d['key']}_{fpga}_{name}_s{sd}")})

    # 2. every place-and-route run is an independent task (serial, or on the Dask workers)
    log(f"{len(jobs)} place-and-route runs on {ex.kind} ({ex.describe()['workers']} worker(s)) ...")
    t_pnr = time.monotonic()
    by_key = {d["key"]: d for d in designs}
    labels = [f"{j['key']} {j['fpga']} {j['name']} ({j['memory'] or 'goal memory'}, seed {j['seed']})" for j in jobs]
    runs: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for j, label, b in zip(jobs, labels, ex.map(_measure_task, jobs, labels=labels)):
        runs.setdefault((j["key"], j["fpga"], j["name"]), []).append(b)
        res["environment"]["tools"] = res["environment"]["tools"] or b.get("tools")
        log(f"{label} -> {b['latency_cycles']} cycles, " + (f"{b['fmax_mhz']} MHz, {b['latency_ns']} ns, LUT {b['luts']} FF {b['ffs_core']} "
            f"DSP {b['dsp']} BRAM {b['bram']} ({b['runtime_s']} s)" if b.get("fits") else f"{b.get('error')}"))
    for (key, fpga, name), rs in runs.items():
        by_key[key]["builds"][fpga][name] = aggregate(rs)
    res["execution"] = {**ex.describe(), "pnr_runs": len(jobs), "pnr_wall_s": round(time.monotonic() - t_pnr, 1)}
    res["runtime_s"] = round(time.monotonic() - t_start, 1)
    write(res, args.outdir, stem)

    # 3. the timing-closure demo and the II simulations of the must-show design
    for d in designs:
        model_path, n, builds = models[d["key"]], d["n"], builds_of[d["key"]]
        if d["key"] == MUST_SHOW:
            if not args.quick and "ecp5" in fpgas and not args.no_timing_closure:
                tc_old = old.get("__tc__")
                if tc_old and [c["pipeline"] for c in tc_old["candidates"]] == [p.to_dict() for p in pipeline_candidates(n)]:
                    res["timing_closure"] = tc_old
                else:
                    log(f"{d['key']}: timing closure at {DEMO_TARGET['ecp5']:g} MHz on ECP5 ...")
                    t0 = time.monotonic()

                    def cand(p):
                        return build_design(model_path, pipeline=p)

                    try:
                        _, rec = close_timing(cand, n, DEMO_TARGET["ecp5"], fpga="ecp5", seed=SEED, progress=log,
                                              workdir=work / "pnr" / "timing_closure", executor=ex)
                    except TimingNotMet as exc:
                        rec = dict(exc.record, error=str(exc))
                    rec["runtime_s"] = round(time.monotonic() - t0, 1)
                    rec["design"] = d["key"]
                    res["timing_closure"] = rec
            sims = {}
            for name in ("default",) if args.quick else tuple(GOAL_OF_BUILD):
                log(f"{d['key']}: Amaranth simulation of the {name} build ...")
                sims[name] = simulate_ii(model_path, builds[name])
            if not args.quick and "ice40" in fpgas:  # --goal throughput --fpga ice40 is its own pipeline (max-lut)
                log(f"{d['key']}: Amaranth simulation of the iCE40 throughput build ...")
                sims["throughput-ice40"] = simulate_ii(model_path, "throughput", fpga="ice40")
            d["simulation"] = sims
            res["must_show"] = must_show(d, sims)
            res["runtime_s"] = round(time.monotonic() - t_start, 1)
            write(res, args.outdir, stem)
    res["complete"] = True
    res["runtime_s"] = round(time.monotonic() - t_start, 1)
    write(res, args.outdir, stem)
    log(f"wrote {args.outdir / (stem + '.json')} and .md ({res['runtime_s']} s)")
    for c in (res.get("must_show") or {}).get("checks", []):
        log(f"must show: {c['what']}: {c['measured']} ({'met' if c['met'] else 'NOT met'})")
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
