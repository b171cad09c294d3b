"""Seed 004 virtual sensors through the RTL (issue 12): pv-benchmark and switching-4, ``stage: rtl`` rows.

Per run (seed = run index, the data of :mod:`pwas_hdl.benchmarks.pv_benchmark` / ``switching4``):
the observer-bank front end (deadbeat, N_theta = 5, M = 5, l = 7, 11b) and the PWAS P-feat sensor
(:data:`~pwas_hdl.benchmarks.seed004_common.PFEAT`) are fitted as in the float benches; then
``generate --design sensor`` builds the hardware, and the **whole test trajectory** is replayed
through the generated Verilog on Verilator (native engine, full speed; every output compared
with the bit-true model: the ``mismatches`` in the row's config). The hardware estimates are the
RTL's output codes (physical = code * 2**-Fo) and the input codes are the test signals quantised
by the design's input formats. Rows: FIT / NRMSE of rho (pv-benchmark, switching-4) and per-mode
F1 (switching-4, minimum-distance classifier) at ``stage: float`` (the same sensor in float on
the unquantised signals) and ``stage: rtl``, with the latency and II measured, and the largest
|RTL - float| beside the stated bound.

Battery (P-feat with the u/y taps i_k, v_k) runs through its RTL in :mod:`pwas_hdl.benchmarks.battery`
(``--rtl verilator [--architecture serial]``), seed 003's estimator in ``switched_estimator_hw``;
:mod:`pwas_hdl.benchmarks.observer_bank_summary` puts the four systems in one table.

``--architecture serial [--bank-lanes L]``: the same sensors on the time-multiplexed bank
(``generate --architecture serial``, :mod:`pwas_hdl.hdl.serial_observer_bank`, and the serial
core): the design that fits an LFE5U-45F (the parallel one needs 129 multipliers); II is then its
cycles per sample, measured.

``python -m pwas_hdl.benchmarks.observer_bank_hw [--runs 3] [--quick] [--architecture parallel|serial]
[--bank-lanes L]`` writes ``results/observer_bank_hw.{json,md}`` (serial: ``observer_bank_hw_serial.*``).
"""

from __future__ import annotations

import copy
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

from pwas_hdl import bench_results as br
from pwas_hdl.benchmarks.seed004_common import ASSUMPTIONS, PFEAT, Collector, cell, fit_pwas, rtl_estimates, say
from pwas_hdl.errors import InputError
from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.systems.pv_benchmark import MODES, make_pv_dataset
from pwas_hdl.systems.pv_method import f1_per_mode, fit_ratio, min_distance_classify, nrmse

BENCH = "observer-bank-hw"
SYSTEMS = ("pv-benchmark", "switching-4")


#: The issue's must-show: |rtl - float| of pv-benchmark's FIT and of switching-4's per-mode F1.
MUST_SHOW = {("pv-benchmark", "fit"): 0.01, ("switching-4", "f1"): 0.005}
ARCHITECTURES = ("parallel", "serial")


def run(runs: int = 3, quick: bool = False, progress: Callable[[str], None] | None = print,
        systems: tuple = SYSTEMS, architecture: str = "parallel", bank_lanes: int | None = None) -> tuple[dict, dict]:
    """Run the hardware rows; returns ``(doc, traces)`` (written by :func:`main`).

    Parameters
    ----------
    runs : int
        Runs (seed = run index), >= 1.
    quick : bool
        3 000 / 1 000 samples instead of 25 000 / 5 000.
    systems : tuple of str
        Subset of :data:`SYSTEMS`.
    architecture : {"parallel", "serial"}
        The bank of the generated sensor (``generate --architecture``).
    bank_lanes : int, optional
        State-update units of the serial bank (default 1); serial only.
    """
    if runs < 1:
        raise InputError("--runs must be >= 1")
    if architecture not in ARCHITECTURES:
        raise InputError(f"--architecture must be one of {', '.join(ARCHITECTURES)}, got {architecture!r}")
    if bank_lanes is not None and (architecture != "serial" or bank_lanes < 1):
        raise InputError("--bank-lanes needs --architecture serial and a value >= 1")
    if not systems or any(s not in SYSTEMS for s in systems):
        raise InputError(f"systems must be among {', '.join(SYSTEMS)}, got {list(systems)}")
    t0 = time.perf_counter()
    n_train, n_test = (3000, 1000) if quick else (25000, 5000)
    col = Collector()
    hw_info: dict = {}
    for r in range(runs):
        for system in systems:
            tr, te, norm = make_pv_dataset(system, n_train, n_test, seed=r, noise=0.03)
            fe = ObserverBankFrontEnd(n_models=5, observer="deadbeat", features="11b")
            model, tm = fit_pwas(PFEAT, copy.deepcopy(fe), tr.u, tr.y, tr.z)
            zf = model.predict(te.u, te.y)[:, 0]
            zt = te.z_true[model.memory - 1 :, 0]
            with tempfile.TemporaryDirectory(prefix="pwas-obs-hw-") as tmp:
                hw = rtl_estimates(model, te.u, te.y, Path(tmp), architecture=architecture, bank_lanes=bank_lanes)
            if not hw["passed"] or hw["mismatches"]:
                raise AssertionError(f"{system} run {r}: the RTL differs from the bit-true model ({hw['mismatches']} mismatches)")
            zh = hw["zhat"][:, 0]
            assert zh.shape == zf.shape, (zh.shape, zf.shape)
            for stage, z in (("float", zf), ("rtl", zh)):
                col.add((system, stage, "rho", "fit"), fit_ratio(zt, z))
                col.add((system, stage, "rho", "nrmse"), nrmse(zt, z))
                if system == "switching-4":
                    modes_n = norm.apply("z", MODES[:, None])[:, 0]
                    ti = min_distance_classify(zt, modes_n)
                    for m, f in enumerate(f1_per_mode(ti, min_distance_classify(z, modes_n), 4)):
                        col.add((system, stage, f"mode{m + 1}", "f1"), f)
            col.add((system, "rtl", "abs", "err_max"), hw["err_max"])
            col.time((system, "float"), tm)
            man = hw["manifest"]
            hw_info[system] = {"latency_cycles": man["latency_cycles"], "ii": man["ii"],
                               "cycles_per_sample": man["front_end"]["cycles_per_sample"],
                               "formats": man["front_end"]["formats"], "n_vertices": man["domain"]["n_vertices"],
                               "memory_bits": man["memory"]["bits"]}
            col.add((system, "rtl", "meta", "latency"), float(hw["latency"][0]) if hw["latency"] else float("nan"))
            col.add((system, "rtl", "meta", "ii"), float(hw["ii"]) if hw["ii"] is not None else float("nan"))
            col.add((system, "rtl", "meta", "bound"), hw["bound"])
            col.add((system, "rtl", "meta", "mismatches"), float(hw["mismatches"]))
            col.add((system, "rtl", "meta", "outputs"), float(hw["outputs"]))
            say(progress, f"run {r + 1}/{runs} {system}: FIT float {col.values[(system, 'float', 'rho', 'fit')][-1]:.4f} "
                          f"rtl {col.values[(system, 'rtl', 'rho', 'fit')][-1]:.4f}, {hw['outputs']} RTL outputs, "
                          f"{hw['mismatches']} mismatches, |rtl - float| <= {hw['err_max']:.4g} (bound {hw['bound']:.4g})")
    rows = []
    for (system, stage, target, metric), vals in col.values.items():
        if metric not in br.METRICS:
            continue
        cfg = {"case": "base", "n_models": 5, "observer": "deadbeat", "features": "11b", "pwas": PFEAT,
               "n_train": n_train, "n_test": n_test}
        if stage == "rtl":
            g = lambda k: col.values[(system, "rtl", "meta", k)]  # noqa: E731
            cfg |= {"simulator": "verilator (native engine)", "bank": architecture,
                    "bank_lanes": (bank_lanes or 1) if architecture == "serial" else None, "rtl_outputs": int(sum(g("outputs"))),
                    "mismatches": int(sum(g("mismatches"))), "latency_cycles": int(max(g("latency"))),
                    "ii": float(max(g("ii"))), "abs_err_max_vs_float": float(max(col.values[(system, 'rtl', 'abs', 'err_max')])),
                    "estimate_bound": float(max(g("bound"))), **hw_info[system]}
            if metric.startswith("f1"):
                cfg["classifier"] = "minimum distance"
        else:
            cfg |= col.timing_of((system, "float"))
        rows.append(br.row_from_values(system, target, "pwas-feat", stage, metric, vals, None, cfg))
    doc = br.make_results(
        BENCH, rows, ASSUMPTIONS,
        config={"runs": runs, "n_train": n_train, "n_test": n_test, "systems": list(systems), "pfeat": PFEAT,
                "architecture": architecture, "bank_lanes": bank_lanes},
        description="Seed 004 P-feat sensors through the generated RTL (observer bank + residual features + PWAS core): "
                    "hardware FIT / NRMSE / F1 beside float",
        quick=quick, elapsed_s=time.perf_counter() - t0,
    )
    return doc, {}


def markdown(doc: dict) -> str:
    """Float vs RTL per system and metric."""
    c = doc["config"]
    arch = c.get("architecture", "parallel")
    bank = ("parallel bank (constant multipliers, II 1)" if arch == "parallel" else
            f"serial bank (`generate --architecture serial`, {c.get('bank_lanes') or 1} lane(s), serial core)")
    lines = [f"# Seed 004 P-feat through the RTL, {arch} bank (runs = {c['runs']}{', QUICK' if doc.get('quick') else ''})", "",
             f"Observer bank (N_theta = 5, deadbeat, M = 5, l = 7, 11b with an integer square root) + PWAS core, {bank}, "
             "whole test trajectory replayed on Verilator; hardware metrics from the RTL's output codes.", "",
             "| system | target | metric | float | rtl | rtl - float | mismatches | latency | II |", "|---|---|---|---|---|---|---|---|---|"]
    for system in c["systems"]:
        for r in br.find_rows(doc, system=system, stage="rtl"):
            f = br.find_rows(doc, system=system, stage="float", target=r["target"], metric=r["metric"])[0]
            k = r["config"]
            lines.append(f"| {system} | {r['target']} | {r['metric']} | {cell(f)} | {cell(r)} | {r['value'] - f['value']:+.5f} | "
                         f"{k['mismatches']} / {k['rtl_outputs']} | {k['latency_cycles']} | {k['ii']:g} |")
    lines += ["", "| system | max |rtl - float| | stated bound | formats |", "|---|---|---|---|"]
    for system in c["systems"]:
        r = br.find_rows(doc, system=system, stage="rtl", metric="fit")[0]["config"]
        f = r["formats"]
        lines.append(f"| {system} | {r['abs_err_max_vs_float']:.4g} | {r['estimate_bound']:.4g} | states s{f['state_bits']}.{f['state_frac']}, "
                     f"coefficients .{f['coef_frac']}, inputs s{f['input_bits']}.{f['input_frac']} |")
    lines += ["", "| must-show (issue 12) | largest abs(rtl - float) of the means | limit | met |", "|---|---|---|---|"]
    for (system, metric), lim in MUST_SHOW.items():
        if system not in c["systems"]:
            continue
        d = max(abs(r["value"] - br.find_rows(doc, system=system, stage="float", target=r["target"], metric=metric)[0]["value"])
                for r in br.find_rows(doc, system=system, stage="rtl", metric=metric))
        lines.append(f"| {system} {metric.upper()} | {d:.5f} | {lim:g} | {'yes' if d <= lim else 'NO'} |")
    return "\n".join(lines) + "\n"


def plot(traces: dict, path) -> None:  # no figure for this bench
    return None


def main(argv: list[str] | None = None) -> None:
    """The script: ``--runs``, ``--quick``, ``--outdir``, ``--architecture``, ``--bank-lanes``; writes JSON and Markdown."""
    import argparse

    from pwas_hdl.io.atomic import atomic_write_text

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="independent runs (1..1000, pwas_hdl.limits.MAX_BENCH_COUNT)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--outdir", type=Path, default=br.default_outdir())
    ap.add_argument("--architecture", default="parallel", choices=list(ARCHITECTURES),
                    help="the sensor's bank: parallel (II 1) or the time-multiplexed one (observer_bank_hw_serial.*)")
    ap.add_argument("--bank-lanes", type=int, default=None, help="state-update units of the serial bank (default 1)")
    a = ap.parse_args(argv)
    br.check_count("--runs", a.runs)
    doc, _ = run(a.runs, a.quick, progress=print, architecture=a.architecture, bank_lanes=a.bank_lanes)
    a.outdir.mkdir(parents=True, exist_ok=True)
    name = "observer_bank_hw" + ("_serial" if a.architecture == "serial" else "") + ("_quick" if a.quick else "")
    br.write_results(a.outdir / f"{name}.json", doc)
    atomic_write_text(a.outdir / f"{name}.md", markdown(doc))
    print(markdown(doc))


if __name__ == "__main__":
    import sys

    sys.exit(br.script_main(main, sys.argv[1:]))
