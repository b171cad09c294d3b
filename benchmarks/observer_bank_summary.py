"""One table of issue 12's benchmark systems in hardware: the design that fits the LFE5U-45F per system.

Every number is read from the committed results (no number of its own): accuracy float vs RTL
from the system's RTL bench, resources / fmax / latency / II / samples/s from the design's
synthesis row (one Yosys + nextpnr run, seed 1):

* pv-benchmark, switching-4: ``observer_bank_hw_serial.json`` (P-feat on the serial bank, 3
  runs) and ``observer_bank_synth.json`` (``pfeat-n5-p6-11b`` / ``switching4-pfeat-n5-p6-11b``,
  the run-0 sensors);
* battery: ``battery_rtl_serial.json`` (P-feat with the i_k, v_k taps, serial bank, 3 runs) and
  ``observer_bank_synth.json`` (``battery-pfeat-n5-p3-11b``, its run-0 sensor);
* switched-linear: ``switched_estimator_hw.json`` (seed 003's estimator, serial, the paper's
  replica at noise 0) and ``switched_estimator_serial_synth_ecp5.json``.

A row whose synthesis row is missing says so. ``python -m pwas_hdl.benchmarks.observer_bank_summary``
writes ``results/observer_bank_summary.md`` (the README's copy).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from pwas_hdl.errors import InputError
from pwas_hdl.io.atomic import atomic_write_text

SYNTH_KEYS = ("luts", "ffs", "dsp", "bram", "fmax_mhz", "latency_cycles", "latency_ns", "ii", "throughput_msps")


def _load(folder: Path, name: str) -> dict:
    p = folder / name
    if not p.is_file():
        raise InputError(f"results file {p} not found: run its benchmark first (it writes there), or give --results FOLDER")
    return json.loads(p.read_text())


def _row(rows: list, **kw) -> dict | None:
    hit = [r for r in rows if all(r.get(k) == v or r.get("config", {}).get(k) == v for k, v in kw.items())]
    return hit[0] if hit else None


def _synth(doc: dict, design: str) -> dict | None:
    r = next((r for r in doc["rows"] if r["design"] == design and r["bank"] == "serial" and r["target"] == "ecp5"), None)
    return {k: r.get(k) for k in SYNTH_KEYS} | {"device": r.get("device")} if r and r.get("fits") else None


def _pm(r: dict | None, d: int = 3) -> str:
    if r is None:
        return "—"
    return f"{r['value']:.{d}f}" + (f" ± {r['std']:.{d}f}" if r.get("std") else "")


def collect(folder: Path | None = None) -> list[dict]:
    """The table's rows (dicts of strings and numbers) from the results in ``folder``.

    Default: the folder the benchmarks write to (:func:`pwas_hdl.bench_results.default_outdir`): the
    committed ``benchmarks/results/`` in a checkout, ``./benchmarks-results`` from an installed wheel.
    """
    from pwas_hdl.bench_results import default_outdir

    folder = Path(folder) if folder is not None else default_outdir()
    hw = _load(folder, "observer_bank_hw_serial.json")
    syn = _load(folder, "observer_bank_synth.json")
    bat = _load(folder, "battery_rtl_serial.json")
    est = _load(folder, "switched_estimator_hw.json")
    est_syn = _load(folder, "switched_estimator_serial_synth_ecp5.json")
    out = []
    for system, design, metrics in (("pv-benchmark", "pfeat-n5-p6-11b", [("rho", "fit")]),
                                    ("switching-4", "switching4-pfeat-n5-p6-11b",
                                     [("rho", "fit")] + [(f"mode{m}", "f1") for m in range(1, 5)])):
        acc_f, acc_r = [], []
        k = None
        for target, metric in metrics:
            f = _row(hw["rows"], system=system, stage="float", target=target, metric=metric)
            r = _row(hw["rows"], system=system, stage="rtl", target=target, metric=metric)
            label = f"{metric.upper()} {target}" if metric == "f1" else metric.upper()
            acc_f.append(f"{label} {_pm(f)}")
            acc_r.append(f"{_pm(r)}")
            k = r["config"]
        out.append({"system": system, "design": f"P-feat N5 M5 p6 11b, serial bank ({design})",
                    "float": "; ".join(acc_f), "rtl": "; ".join(acc_r),
                    "mismatches": f"{k['mismatches']} / {k['rtl_outputs']}", "rtl_ii": k["ii"], "synth": _synth(syn, design),
                    "source": "observer_bank_hw_serial, observer_bank_synth"})
    f = _row(bat["rows"], estimator="pwas-feat", stage="float", metric="rmse")
    r = _row(bat["rows"], estimator="pwas-feat", stage="rtl", metric="rmse")
    out.append({"system": "battery", "design": "P-feat N5 Kalman + taps i_k, v_k, p3, serial bank (battery-pfeat-n5-p3-11b)",
                "float": f"SoC RMSE {_pm(f, 4)}", "rtl": _pm(r, 4),
                "mismatches": f"{r['config']['mismatches']} / {r['config']['rtl_outputs']}", "rtl_ii": r["config"]["ii"],
                "synth": _synth(syn, "battery-pfeat-n5-p3-11b"), "source": "battery_rtl_serial, observer_bank_synth"})
    acc_f, acc_r, mm = [], [], []
    for target, metric, label in (("y", "mse", "y MSE"), ("mode", "accuracy", "mode accuracy")):
        f = _row(est["rows"], stage="float", target=target, metric=metric, test="replica", noise_y=0.0)
        r = _row(est["rows"], stage="rtl", target=target, metric=metric, test="replica", noise_y=0.0, architecture="serial")
        acc_f.append(f"{label} {_pm(f, 5)}")
        acc_r.append(_pm(r, 5))
        mm.append(r["config"])
    out.append({"system": "switched-linear (seed 003 estimator)", "design": "3 modes, serial row unit (`generate est.json --architecture serial`)",
                "float": "; ".join(acc_f) + " (replica, noise 0)", "rtl": "; ".join(acc_r),
                "mismatches": f"{mm[0]['mismatches']} / {mm[0]['rtl_outputs']} (this set)", "rtl_ii": mm[0]["ii"],
                "synth": {k: est_syn.get(k) for k in SYNTH_KEYS} | {"device": est_syn.get("part")},
                "source": "switched_estimator_hw, switched_estimator_serial_synth_ecp5"})
    return out


def markdown(rows: list[dict]) -> str:
    lines = ["| system | design | accuracy float | accuracy RTL | mismatches | LUT4 | FF | DSP | BRAM | fmax MHz | latency cycles / ns | II | Msamples/s | from (results/) |",
             "|---|---|---|---|---|---:|---:|---:|---:|---:|---|---:|---:|---|"]
    for r in rows:
        s = r["synth"]
        if s is None:
            hwc = f"no synthesis row | | | | | | {r['rtl_ii']:g} (RTL bench) |"
        else:
            if float(s["ii"]) != float(r["rtl_ii"]):
                raise InputError(f"{r['system']}: the synthesis row's II {s['ii']} differs from the RTL bench's {r['rtl_ii']}: "
                                 "results of different designs; re-run one of them")
            hwc = (f"{s['luts']} | {s['ffs']} | {s['dsp']} | {s['bram']} | {s['fmax_mhz']:.1f} | "
                   f"{s['latency_cycles']} / {s['latency_ns']:.0f} | {s['ii']} | {s['throughput_msps']:.2f} |")
        lines.append(f"| {r['system']} | {r['design']} | {r['float']} | {r['rtl']} | {r['mismatches']} | {hwc} {r['source']} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    from pwas_hdl.bench_results import checked_outdir, default_outdir, make_outdir

    ap.add_argument("--results", type=Path, default=default_outdir(), help="results folder read (default: where the benchmarks write, "
                    "%(default)s: the committed results in a checkout, ./benchmarks-results from the wheel)")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="where observer_bank_summary.md goes (default: %(default)s)")
    a = ap.parse_args(argv)
    checked_outdir(a.outdir)
    text = "# Issue 12's systems in hardware: the designs that fit the LFE5U-45F\n\n" + markdown(collect(a.results))
    atomic_write_text(make_outdir(a.outdir) / "observer_bank_summary.md", text)
    print(text)


if __name__ == "__main__":
    from pwas_hdl import bench_results as br

    sys.exit(br.script_main(main, sys.argv[1:]))
