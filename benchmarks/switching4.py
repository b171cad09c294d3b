"""Seed 004, E2: mode reconstruction of the 4-mode switching system, Tables 8-9 (``pwas-hdl bench switching-4``).

Per run (seed = run index): 25 000 training / 5 000 test samples of (14a) with alpha = 0 and
rho from (18) (each set with its own N, B2), normalised, noise 0.03 on u and y, clean mode labels
(B5). The observer bank (deadbeat, l = 7, (11b)) with N_theta = 2..5 feeds an RFR (Table 8). With
N_theta = 5: the RFC on the mode index, the RFR + minimum-distance classifier, and the PWAS
sensor (P-feat through the toolchain's observer-bank front end, P-raw on lags) + minimum-distance
classifier: per-mode F1 (Table 9) and FIT/NRMSE of the mode signal.
"""

from __future__ import annotations

import copy
import time
from typing import Callable

import numpy as np

from pwas_hdl import bench_results as br
from pwas_hdl.benchmarks.seed004_common import ASSUMPTIONS, PFEAT, PRAW, Collector, cell, fit_pwas, fit_sklearn, paper_cell, say
from pwas_hdl.errors import InputError
from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.systems.pv_benchmark import MODES, make_pv_dataset
from pwas_hdl.systems.pv_method import f1_per_mode, fit_ratio, make_predictor, min_distance_classify, nrmse

SYSTEM = "switching-4"
#: Table 8 (RFR): N_theta -> (FIT, std, NRMSE, std)
PAPER_T8 = {2: (0.800, 0.030, 0.925, 0.011), 3: (0.938, 0.014, 0.977, 0.005), 4: (0.951, 0.007, 0.982, 0.003),
            5: (0.950, 0.009, 0.981, 0.003)}
#: Table 9: F1 per mode (mean, std) for RFC and RFR + minimum distance
PAPER_T9 = {"rfc": [(0.997, 0.001), (0.995, 0.002), (0.996, 0.001), (0.998, 0.001)],
            "rfr": [(0.997, 0.001), (0.995, 0.001), (0.996, 0.001), (0.998, 0.002)]}
PAPER_RFC_FIT = (0.946, 0.011)
ASSUMPTIONS_E2 = ASSUMPTIONS | {
    "seed_004.B1": "settings as E1: u ~ N(0, I2), normalisation, noise 0.03, M = 5, l = 7, deadbeat",
    "seed_004.B2": "training and test sets each use their own N in (18)",
    "seed_004.B3": "minimum distance and F1 on the 4 normalised mode values",
    "seed_004.B4": "RFC: 10 trees, max_depth 15",
    "seed_004.B5": "mode labels noise-free",
}


def run(runs: int = 10, quick: bool = False, progress: Callable[[str], None] | None = None, executor=None) -> dict:
    """Run E2; return the results document (:mod:`pwas_hdl.bench_results`)."""
    if runs < 1:
        raise InputError("--runs must be >= 1")
    t0 = time.perf_counter()
    n_train, n_test = (3000, 1000) if quick else (25000, 5000)
    thetas = (5,) if quick else (2, 3, 4, 5)
    col = Collector()
    def one_run(r: int):
        """Run r (fresh data, seed r): its values and timings."""
        col = Collector()
        tr, te, norm = make_pv_dataset(SYSTEM, n_train, n_test, seed=r, noise=0.03)
        modes_n = norm.apply("z", MODES[:, None])[:, 0]
        lpv = None
        for nth in thetas:
            fe = ObserverBankFrontEnd(n_models=nth).fit([tr.u], [tr.y], [tr.z], lpv=lpv)
            lpv = fe.lpv_
            f_tr, v_tr = fe.transform([tr.u], [tr.y])
            f_te, v_te = fe.transform([te.u], [te.y])
            x_tr = np.column_stack([f_tr, tr.u[v_tr[0]], tr.y[v_tr[0]]])
            x_te = np.column_stack([f_te, te.u[v_te[0]], te.y[v_te[0]]])
            z_tr, z_te = tr.z[v_tr[0], 0], te.z_true[v_te[0], 0]
            true_idx = min_distance_classify(z_te, modes_n)
            rfr, tm = fit_sklearn(make_predictor("rfr", r), x_tr, z_tr)
            zh = rfr.predict(x_te)
            key = (nth, "rfr")
            col.add(key + ("fit",), fit_ratio(z_te, zh))
            col.add(key + ("nrmse",), nrmse(z_te, zh))
            col.time(key, tm)
            if nth != 5:
                continue
            for m, f in enumerate(f1_per_mode(true_idx, min_distance_classify(zh, modes_n), 4)):
                col.add(key + (f"f1_mode{m + 1}",), f)
            rfc, tm = fit_sklearn(make_predictor("rfc", r), x_tr, min_distance_classify(z_tr, modes_n))
            pred = rfc.predict(x_te)
            for m, f in enumerate(f1_per_mode(true_idx, pred, 4)):
                col.add((5, "rfc", f"f1_mode{m + 1}"), f)
            col.add((5, "rfc", "fit"), fit_ratio(z_te, modes_n[pred]))
            col.add((5, "rfc", "nrmse"), nrmse(z_te, modes_n[pred]))
            col.time((5, "rfc"), tm)
            for est, cfg, tmpl in (("pwas-feat", PFEAT, copy.deepcopy(fe)), ("pwas-raw", PRAW, None)):
                model, tm = fit_pwas(cfg, tmpl, tr.u, tr.y, tr.z)
                zh = model.predict(te.u, te.y)[:, 0]
                zt = te.z_true[model.memory - 1 :, 0]
                ti = min_distance_classify(zt, modes_n)
                col.add((5, est, "fit"), fit_ratio(zt, zh))
                col.add((5, est, "nrmse"), nrmse(zt, zh))
                for m, f in enumerate(f1_per_mode(ti, min_distance_classify(zh, modes_n), 4)):
                    col.add((5, est, f"f1_mode{m + 1}"), f)
                col.time((5, est), tm)
        say(progress, f"run {r + 1}/{runs}: " + ", ".join(
            f"{k[1]}(N={k[0]}) FIT {v[-1]:.3f}" for k, v in col.values.items() if k[2] == "fit"))
        return col

    for part in br.map_runs(one_run, range(runs), executor, labels=[f"run {r}" for r in range(runs)]):
        col.extend(part)
    rows = []
    for key, vals in col.values.items():
        nth, est, metric = key
        cfg = {"n_models": nth, "observer": "deadbeat", "features": "11b", "n_train": n_train, "n_test": n_test}
        cfg |= col.timing_of((nth, est))
        if est.startswith("pwas"):
            cfg |= {"pwas": PFEAT if est == "pwas-feat" else PRAW, "classifier": "minimum distance"}
        elif est == "rfr" and metric.startswith("f1"):
            cfg |= {"classifier": "minimum distance"}
        paper = None
        if metric.startswith("f1"):
            m = int(metric[-1]) - 1
            ref = PAPER_T9.get(est)
            if ref is not None:
                paper = ref[m][0]
                cfg |= {"paper_std": ref[m][1]}
            target, met = f"mode{m + 1}", "f1"
        else:
            target, met = "rho", metric
            if est == "rfr":
                p = PAPER_T8[nth]
                paper, cfg = (p[0], cfg | {"paper_std": p[1]}) if metric == "fit" else (p[2], cfg | {"paper_std": p[3]})
            elif est == "rfc" and metric == "fit":
                paper, cfg = PAPER_RFC_FIT[0], cfg | {"paper_std": PAPER_RFC_FIT[1]}
        rows.append(br.row_from_values(SYSTEM, target, est, "float", met, vals, paper, cfg))
    return br.make_results(
        SYSTEM, rows, ASSUMPTIONS_E2,
        config={"runs": runs, "n_train": n_train, "n_test": n_test, "n_models": list(thetas), "pfeat": PFEAT, "praw": PRAW},
        description="Seed 004 E2 (Masti et al., EJC 2021), Tables 8-9: mode reconstruction, mean and std over runs",
        quick=quick, elapsed_s=time.perf_counter() - t0,
    )


def markdown(doc: dict) -> str:
    """Table 8 (RFR vs N_theta, plus PWAS at 5) and Table 9 (F1 per mode) beside the paper."""
    c = doc["config"]
    lines = [f"# Seed 004 E2: 4-mode switching system (runs = {c['runs']}{', QUICK' if doc.get('quick') else ''})", "",
             "## Table 8: FIT / NRMSE of the mode signal", "",
             "| estimator | N_theta | paper FIT | ours FIT | paper NRMSE | ours NRMSE |", "|---|---|---|---|---|---|"]
    for est in ("rfr", "rfc", "pwas-feat", "pwas-raw"):
        for nth in c["n_models"]:
            f = br.find_rows(doc, estimator=est, metric="fit", config={"n_models": nth})
            n = br.find_rows(doc, estimator=est, metric="nrmse", config={"n_models": nth})
            if not f:
                continue
            f, n = f[0], n[0]
            lines.append(f"| {est} | {nth} | {paper_cell(f['paper'], f['config'].get('paper_std'))} | {cell(f)} | "
                         f"{paper_cell(n['paper'], n['config'].get('paper_std'))} | {cell(n)} |")
    lines += ["", "## Table 9: F1 per mode (N_theta = 5, deadbeat; regressors + minimum-distance classifier)", "",
              "| estimator | mode 1 | mode 2 | mode 3 | mode 4 |", "|---|---|---|---|---|"]
    for est, label in (("rfc", "RFC"), ("rfr", "RFR + min. distance"), ("pwas-feat", "PWAS P-feat + min. distance"),
                       ("pwas-raw", "PWAS P-raw + min. distance")):
        rs = [br.find_rows(doc, estimator=est, metric="f1", target=f"mode{m}") for m in range(1, 5)]
        if not all(rs):
            continue
        if est in PAPER_T9:
            lines.append(f"| paper {label} | " + " | ".join(paper_cell(r[0]["paper"], r[0]["config"].get("paper_std")) for r in rs) + " |")
        lines.append(f"| ours {label} | " + " | ".join(cell(r[0]) for r in rs) + " |")
    lines += ["", "## Training time and peak traced memory per predictor (mean over runs)", "",
              "| estimator | N_theta | train [s] | peak [MiB] |", "|---|---|---:|---:|"]
    for r in doc["rows"]:
        if r["metric"] in ("fit",) and "train_s" in r["config"]:
            lines.append(f"| {r['estimator']} | {r['config']['n_models']} | {r['config']['train_s']:.2f} | {r['config']['peak_mib']:.1f} |")
    return "\n".join(lines) + "\n"
