"""Seed 004, E3: battery state of charge, Fig. 5 (``pwas-hdl bench battery``).

Per run (seed = run index): 25 000 training / 5 000 test samples of model (19)-(20) with the
SUBSTITUTE coefficients of seed_004.md C1 (Chen & Rincon-Mora 2006, C_c = 3060 A s; not the
unprinted values of the paper's reference [4]), normalised, noise 0.03 on i, v and the SoC label
(C3). Estimators of the SoC:

* RFR: the paper's sensor, a bank of N_theta = 5 stationary Kalman predictors (lambda = 0.1),
  (11b), l = 7, RFR on [v1..v5, i_k, v_k];
* PWAS P-feat: the toolchain's sensor with the same observer-bank front end, on [v1..v5, i_k, v_k]
  (p = 3, 4^7 vertices), sigma by CV;
* PWAS P-raw: lags Mu = My = 2 (seed_004.md E3.4), p = 6;
* four EKFs on model (19) (analytic Jacobians), with (Q, R) as stated in :data:`EKF_SETTINGS`,
  run in physical units on the de-normalised noisy current and voltage, started at x(0) (C4).

The paper prints no numbers for E3 (Fig. 5 only): the rows carry ``paper = null``.
"""

from __future__ import annotations

import copy
import time
from typing import Callable

import numpy as np

from pwas_hdl import bench_results as br
from pwas_hdl.benchmarks.seed004_common import ASSUMPTIONS, Collector, Timer, cell, fit_pwas, fit_sklearn, say
from pwas_hdl.errors import InputError
from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.systems.battery import BatteryEKF, make_battery_dataset
from pwas_hdl.systems.pv_method import fit_ratio, make_predictor, nrmse

SYSTEM = "battery"
PFEAT_B = {"mu": 1, "my": 1, "partitions": 3, "gamma": 1.0}
PRAW_B = {"mu": 2, "my": 2, "partitions": 6, "gamma": 1.2}
#: (name, diag Q, R as a multiple of the voltage-noise variance (0.03 std_v)^2). The SoC entry q1
#: sets the EKF's bandwidth: with q1 = 1e-8 it tracks a discharge to 1e-3 but never recovers from
#: a reset (SoC jumping back to 1, which model (19) does not contain); q1 = 1e-3 recovers within
#: tens of samples and is noisier (measured on run 0: test RMSE 0.44 / 0.16 / 0.028 / 0.019).
EKF_SETTINGS = [
    ("ekf-1", (1e-8, 1e-6, 1e-6), 1.0),
    ("ekf-2", (1e-6, 1e-6, 1e-6), 1.0),
    ("ekf-3", (1e-4, 1e-6, 1e-6), 1.0),
    ("ekf-4", (1e-3, 1e-6, 1e-6), 10.0),
]
ASSUMPTIONS_E3 = ASSUMPTIONS | {
    "seed_004.C1": "battery coefficients: Chen & Rincon-Mora 2006 values, C_c = 3060 A s (SUBSTITUTE, not [4]'s)",
    "seed_004.C2": "one RK4 step per 5 s sample, current constant within the step",
    "seed_004.C3": "noise 0.03 after normalisation on i, v and the SoC label; metrics against the true SoC",
    "seed_004.C4": "EKF settings as EKF_SETTINGS (Q diagonal per step, R in V^2), x0 = [1, 0, 0], P0 = diag(1e-2, 1e-4, 1e-4)",
    "seed_004.C5": "local models M = 5, l = 7",
}


def run(runs: int = 10, quick: bool = False, progress: Callable[[str], None] | None = None, executor=None,
        rtl: str | None = None, architecture: str = "parallel", bank_lanes: int | None = None) -> dict:
    """Run E3; return the results document (plus ``_traces`` of run 0 for :func:`plot`).

    ``rtl`` (``"verilator"`` or ``"icarus"``): also generate the PWAS P-feat sensor's hardware (observer
    bank + residual features + the ``i_k, v_k`` taps + core, :mod:`pwas_hdl.hdl.observer_tap_sensor_top`)
    and replay the whole test trajectory through it (:func:`~pwas_hdl.benchmarks.seed004_common.rtl_estimates`):
    rows ``stage: rtl`` for ``pwas-feat`` with the mismatches against the bit-true model, the measured
    latency / II and the largest |RTL - float| beside the stated bound. ``architecture="serial"``
    (``bank_lanes``): the same sensor on the time-multiplexed bank (``generate --architecture serial``).
    """
    if runs < 1:
        raise InputError("--runs must be >= 1")
    t0 = time.perf_counter()
    n_train, n_test = (3000, 1000) if quick else (25000, 5000)
    col = Collector()
    traces = {}
    def one_run(r: int):
        """Run r (fresh data, seed r): its values and timings."""
        col = Collector()
        traces = {}
        tr, te, norm = make_battery_dataset(n_train, n_test, seed=r, noise=0.03)
        soc_true = norm.invert("z", te.z_true)[:, 0]
        est = {}
        fe = ObserverBankFrontEnd(n_models=5, observer="kalman:0.1").fit([tr.u], [tr.y], [tr.z])
        f_tr, v_tr = fe.transform([tr.u], [tr.y])
        f_te, v_te = fe.transform([te.u], [te.y])
        x_tr = np.column_stack([f_tr, tr.u[v_tr[0]], tr.y[v_tr[0]]])
        x_te = np.column_stack([f_te, te.u[v_te[0]], te.y[v_te[0]]])
        rfr, tm = fit_sklearn(make_predictor("rfr", r), x_tr, tr.z[v_tr[0], 0])
        est["rfr"] = (v_te[0].start, norm.invert("z", rfr.predict(x_te)[:, None])[:, 0], tm)
        for name, cfg, tmpl in (("pwas-feat", PFEAT_B, copy.deepcopy(fe)), ("pwas-raw", PRAW_B, None)):
            model, tm = fit_pwas(cfg, tmpl, tr.u, tr.y, tr.z)
            est[name] = (model.memory - 1, norm.invert("z", model.predict(te.u, te.y))[:, 0], tm)
            if rtl is not None and name == "pwas-feat":  # the same sensor through its generated RTL
                import tempfile
                from pathlib import Path

                from pwas_hdl.benchmarks.seed004_common import rtl_estimates

                with tempfile.TemporaryDirectory(prefix="pwas-battery-rtl-") as tmp:
                    hw = rtl_estimates(model, te.u, te.y, Path(tmp), simulator=rtl, architecture=architecture,
                                       bank_lanes=bank_lanes)
                est["pwas-feat@rtl"] = (model.memory - 1, norm.invert("z", hw["zhat"])[:, 0], tm)
                for k in ("mismatches", "outputs"):
                    col.add(("pwas-feat@rtl", f"_{k}"), float(hw[k]))
                col.add(("pwas-feat@rtl", "_latency"), float(hw["latency"][0]) if hw["latency"] else float("nan"))
                col.add(("pwas-feat@rtl", "_latency_manifest"), float(hw["latency_manifest"]))
                col.add(("pwas-feat@rtl", "_ii"), float(hw["ii"]) if hw["ii"] is not None else float("nan"))
                col.add(("pwas-feat@rtl", "_err_max"), hw["err_max"])
                col.add(("pwas-feat@rtl", "_bound"), hw["bound"])
                say(progress, f"run {r + 1}: pwas-feat RTL ({rtl}): {hw['outputs']} outputs, {hw['mismatches']} mismatches, "
                              f"latency {hw['latency']}, II {hw['ii']}, |rtl - float| {hw['err_max']:.4g} (bound {hw['bound']:.4g})")
        cur = norm.invert("u", te.u)[:, 0]
        volt = norm.invert("y", te.y)[:, 0]
        r0 = float((0.03 * norm.std["y"][0]) ** 2)
        for name, q, rmul in EKF_SETTINGS:
            with Timer() as tm:
                xs = BatteryEKF(q=q, r=rmul * r0).run(cur, volt)
            est[name] = (0, xs[:, 0], tm)
        start = max(s for s, _, _ in est.values())  # compare every estimator on the same samples
        for name, (s, zh, tm) in est.items():
            zh = zh[start - s :]
            zt = soc_true[start:]
            col.add((name, "rmse"), float(np.sqrt(np.mean((zh - zt) ** 2))))
            col.add((name, "fit"), fit_ratio(zt, zh))
            col.add((name, "nrmse"), nrmse(zt, zh))
            col.time((name,), tm)
            if r == 0:
                traces[name] = zh
        if r == 0:
            traces["true"] = soc_true[start:]
            traces["start"] = start
            traces["r0"] = r0
        say(progress, f"run {r + 1}/{runs}: " + ", ".join(f"{k[0]} RMSE {v[-1]:.4f}" for k, v in col.values.items() if k[1] == "rmse"))
        return col, traces

    for part, tr in br.map_runs(one_run, range(runs), executor, labels=[f"run {r}" for r in range(runs)]):
        col.extend(part)
        traces = traces or tr
    rows = []
    for (name, metric), vals in col.values.items():
        if metric.startswith("_"):  # RTL meta values: in the rtl rows' config
            continue
        cfg = {"n_train": n_train, "n_test": n_test, "units": "SoC fraction" if metric == "rmse" else "1"}
        cfg |= col.timing_of((name,))
        if name == "pwas-feat@rtl":
            g = lambda k: col.values[(name, f"_{k}")]  # noqa: E731
            cfg |= {"front_end": "observer-bank", "n_models": 5, "observer": "kalman:0.1", "features": "11b+u,y", "pwas": PFEAT_B,
                    "simulator": f"{rtl} ({'native' if rtl == 'verilator' else 'cocotb'} engine), the generated folder's Verilog",
                    "architecture": architecture, "bank_lanes": bank_lanes,
                    "mismatches": int(sum(g("mismatches"))), "rtl_outputs": int(sum(g("outputs"))),
                    "latency_cycles": float(max(g("latency"))), "latency_manifest": float(max(g("latency_manifest"))),
                    "ii": float(max(g("ii"))), "abs_err_max_vs_float_normalised": float(max(g("err_max"))),
                    "error_bound_normalised": float(max(g("bound"))),
                    "note": "the P-feat sensor's whole test trajectory through its RTL (taps i_k, v_k beside the bank features); "
                            "errors in normalised SoC units (the sensor's target), metrics in SoC fraction"}
            rows.append(br.row_from_values(SYSTEM, "soc", "pwas-feat", "rtl", metric, vals, None, cfg))
            continue
        if name == "rfr":
            cfg |= {"front_end": "observer-bank", "n_models": 5, "observer": "kalman:0.1", "features": "11b+u,y"}
        elif name == "pwas-feat":
            cfg |= {"front_end": "observer-bank", "n_models": 5, "observer": "kalman:0.1", "features": "11b+u,y", "pwas": PFEAT_B}
        elif name == "pwas-raw":
            cfg |= {"front_end": "lags", "pwas": PRAW_B}
        else:
            q, rmul = next((q, m) for n, q, m in EKF_SETTINGS if n == name)
            cfg |= {"Q_diag": list(q), "R_over_noise_var": rmul, "R_V2": rmul * traces.get("r0", float("nan"))}
        rows.append(br.row_from_values(SYSTEM, "soc", name, "float", metric, vals, None, cfg))
    doc = br.make_results(
        SYSTEM, rows, ASSUMPTIONS_E3,
        config={"runs": runs, "n_train": n_train, "n_test": n_test, "compared_from_sample": traces.get("start"),
                "ekf_settings": [{"name": n, "Q_diag": list(q), "R_over_noise_var": m} for n, q, m in EKF_SETTINGS]},
        description="Seed 004 E3 (Masti et al., EJC 2021), Fig. 5: SoC estimation, virtual sensors vs EKFs (substitute battery coefficients)",
        quick=quick, elapsed_s=time.perf_counter() - t0,
    )
    doc["_traces"] = traces
    return doc


def markdown(doc: dict) -> str:
    c = doc["config"]
    lines = [f"# Seed 004 E3: battery SoC (runs = {c['runs']}{', QUICK' if doc.get('quick') else ''})", "",
             "Substitute coefficients (Chen & Rincon-Mora 2006, C_c = 3060 A s), not the paper's [4]. The paper shows "
             "Fig. 5 only (no numbers). SoC RMSE in SoC fraction, FIT (13a), NRMSE (13b) on the test set against the "
             "true SoC, mean ± std over runs.", "",
             "| estimator | SoC RMSE | FIT | NRMSE | train [s] | setting |", "|---|---|---|---|---:|---|"]
    names = []
    for r in doc["rows"]:
        if (r["estimator"], r["stage"]) not in names:
            names.append((r["estimator"], r["stage"]))
    for n, stage in names:
        rs = {m: br.find_rows(doc, estimator=n, metric=m, stage=stage)[0] for m in ("rmse", "fit", "nrmse")}
        if stage != "float":
            k = rs["rmse"]["config"]
            bank = f"{k['architecture']} bank, " if k.get("architecture") else ""
            lines.append(f"| {n} ({stage}: {bank}{k['simulator']}) | {rs['rmse']['value']:.4f}"
                         + (f" ± {rs['rmse']['std']:.4f}" if rs["rmse"]["std"] is not None else "")
                         + f" | {cell(rs['fit'])} | {cell(rs['nrmse'])} | | {k['mismatches']} mismatches / {k['rtl_outputs']} "
                         f"outputs, latency {k['latency_cycles']:g} (manifest {k['latency_manifest']:g}), II {k['ii']:g}, "
                         f"max abs(rtl - float) {k['abs_err_max_vs_float_normalised']:.3g} <= bound {k['error_bound_normalised']:.3g} |")
            continue
        cfg = rs["rmse"]["config"]
        setting = (f"Q = diag{tuple(cfg['Q_diag'])}, R = {cfg['R_over_noise_var']:g} x noise var" if "Q_diag" in cfg
                   else f"{cfg.get('front_end')}, {cfg.get('observer', '')} {cfg.get('pwas', '')}".strip())
        rm = rs["rmse"]
        rmse_txt = f"{rm['value']:.4f}" + (f" ± {rm['std']:.4f}" if rm["std"] is not None else "")
        lines.append(f"| {n} | {rmse_txt} | {cell(rs['fit'])} | {cell(rs['nrmse'])} | "
                     f"{cfg.get('train_s', float('nan')):.2f} | {setting} |")
    return "\n".join(lines) + "\n"


def plot(doc: dict, path) -> None:
    """A Fig. 5-like plot of run 0: true SoC, the virtual sensors and the EKFs over the test set."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pwas_hdl.io.atomic import atomic_write_bytes

    tr = doc["_traces"]
    t_h = (tr["start"] + np.arange(tr["true"].size)) * 5.0 / 3600.0
    fig, ax = plt.subplots(figsize=(9, 4.2))
    ax.plot(t_h, tr["true"], "k", lw=2, label="true SoC")
    for name, style in (("rfr", "-"), ("pwas-feat", "-"), ("ekf-1", "--"), ("ekf-2", "--"), ("ekf-3", "--"), ("ekf-4", "--")):
        if name in tr:
            ax.plot(t_h, tr[name], style, lw=0.8, label=name)
    ax.set_xlabel("time [h]")
    ax.set_ylabel("state of charge")
    ax.set_title("Seed 004 E3 (substitute coefficients): virtual sensors vs EKFs, run 0")
    ax.legend(ncol=4, fontsize=8, loc="lower left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, metadata={"Software": None})
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def main(argv: list[str] | None = None) -> int:
    """``python -m pwas_hdl.benchmarks.battery [--runs N] [--quick] --rtl verilator``: battery_rtl.{json,md}."""
    import argparse

    from pwas_hdl.io.atomic import atomic_write_text

    ap = argparse.ArgumentParser(description="Seed 004 E3 with the PWAS P-feat sensor through its RTL")
    ap.add_argument("--runs", type=int, default=3, help="independent runs (1..1000, pwas_hdl.limits.MAX_BENCH_COUNT)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--rtl", default="verilator", choices=["verilator", "icarus"])
    ap.add_argument("--architecture", default="parallel", choices=["parallel", "serial"],
                    help="the sensor's hardware: parallel bank (II 1) or the time-multiplexed bank (battery_rtl_serial.*)")
    ap.add_argument("--bank-lanes", type=int, default=None, help="state-update units of the serial bank (default 1)")
    ap.add_argument("--outdir", type=str, default=str(br.default_outdir()))
    a = ap.parse_args(argv)
    br.check_count("--runs", a.runs)
    d = run(a.runs, a.quick, progress=print, rtl=a.rtl, architecture=a.architecture, bank_lanes=a.bank_lanes)
    stem = f"{a.outdir}/battery_rtl" + ("_serial" if a.architecture == "serial" else "") + ("_quick" if a.quick else "")
    br.write_results(f"{stem}.json", {k: v for k, v in d.items() if not k.startswith("_")})
    atomic_write_text(f"{stem}.md", markdown(d))
    print(markdown(d))
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(br.script_main(main, sys.argv[1:]))
