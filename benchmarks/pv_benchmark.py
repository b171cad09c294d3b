"""Seed 004, E1: the parameter-varying benchmark, Tables 1-7 (``pwas-hdl bench pv-benchmark``).

For every case (one column of a paper table) and run: fresh training / test data
(:func:`pwas_hdl.systems.pv_benchmark.make_pv_dataset`, seed = run index), the observer-bank
front end (:class:`pwas_hdl.fit.observer_bank.ObserverBankFrontEnd`), then the predictors on its
features (the paper's u_k, y_k appended): DTR, RFR, ANN (:mod:`pwas_hdl.systems.pv_method`), PWAS
P-feat (the toolchain's sensor with the observer-bank front end, on [v1..vN]) and PWAS P-raw
(the lag regressor Mu = 2, My = 3). FIT (13a) and NRMSE (13b) against the true rho of the test
set, mean and std (ddof 1) over the runs. The front end's local models are learned once per
data set and shared by the cases that differ only in N_theta, observer or feature map.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from pwas_hdl import bench_results as br
from pwas_hdl.benchmarks.seed004_common import (
    ASSUMPTIONS, PFEAT, PRAW, Collector, cell, fit_pwas, fit_sklearn, paper_cell, say,
)
from pwas_hdl.errors import InputError
from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.systems.pv_benchmark import make_pv_dataset
from pwas_hdl.systems.pv_method import fit_ratio, make_predictor, nrmse

SYSTEM = "pv-benchmark"
ESTIMATORS = ("dtr", "rfr", "ann", "pwas-feat", "pwas-raw")


@dataclass(frozen=True)
class Case:
    """One column of a paper table: settings, the estimators run, the paper's figures."""

    name: str
    table: str
    n_train: int = 25000
    noise: float = 0.03
    n_models: int = 5
    observer: str = "deadbeat"
    features: str = "11b"
    rho_law: str = "random-walk"
    test_rho_law: str = "random-walk"
    estimators: tuple = ("dtr", "rfr", "ann")
    #: paper figures: estimator -> (FIT, FIT std, NRMSE, NRMSE std) (None where not printed)
    paper: dict = field(default_factory=dict)

    def data_key(self) -> tuple:
        return (self.n_train, self.noise, self.rho_law, self.test_rho_law)

    def config(self) -> dict:
        return {"case": self.name, "table": self.table, "n_train": self.n_train, "noise": self.noise,
                "n_models": self.n_models, "observer": self.observer, "features": self.features,
                "rho_law": self.rho_law, "test_rho_law": self.test_rho_law}


ALL5 = ("dtr", "rfr", "ann", "pwas-feat", "pwas-raw")
CASES = [
    # Table 2 sigma = 0.03 = Table 3 (11b, 25 000) = Table 4 PP z = 0 = Table 5 N = 5; Table 1 ANN rows
    Case("base", "T1-T5", estimators=ALL5, paper={
        "dtr": (0.736, 0.031, None, None), "rfr": (0.787, 0.023, 0.954, 0.002), "ann": (0.796, 0.023, 0.956, 0.002)}),
    Case("11a", "T1/T3", features="11a", paper={
        "dtr": (0.615, 0.042, None, None), "rfr": (0.740, 0.024, None, None), "ann": (0.794, 0.028, 0.956, 0.002)}),
    Case("11b-N5000", "T1/T3", n_train=5000, estimators=("dtr", "rfr", "ann", "pwas-feat"), paper={
        "dtr": (0.593, 0.161, None, None), "rfr": (0.663, 0.145, None, None), "ann": (0.711, 0.062, 0.937, 0.014)}),
    Case("11b-N15000", "T1/T3", n_train=15000, estimators=("dtr", "rfr", "ann", "pwas-feat"), paper={
        "dtr": (0.713, 0.041, None, None), "rfr": (0.766, 0.033, None, None), "ann": (0.783, 0.028, 0.954, 0.004)}),
    Case("11a-N5000", "T1/T3", n_train=5000, features="11a", paper={
        "dtr": (0.376, 0.158, None, None), "rfr": (0.568, 0.168, None, None), "ann": (0.695, 0.072, 0.934, 0.016)}),
    Case("11a-N15000", "T1/T3", n_train=15000, features="11a", paper={
        "dtr": (0.568, 0.061, None, None), "rfr": (0.715, 0.046, None, None), "ann": (0.773, 0.030, 0.952, 0.003)}),
    Case("noise0.01", "T2", noise=0.01, estimators=("dtr", "rfr", "ann", "pwas-feat"), paper={
        "dtr": (0.752, 0.026, None, None), "rfr": (0.804, 0.021, None, None), "ann": (0.815, 0.018, None, None)}),
    Case("noise0.06", "T2", noise=0.06, estimators=("dtr", "rfr", "ann", "pwas-feat"), paper={
        "dtr": (0.698, 0.036, None, None), "rfr": (0.755, 0.029, None, None), "ann": (0.764, 0.032, None, None)}),
    Case("pp0.4", "T4", observer="poles:0.4", estimators=("rfr",), paper={"rfr": (0.708, 0.030, 0.937, 0.003)}),
    Case("pp0.8", "T4", observer="poles:0.8", estimators=("rfr",), paper={"rfr": (0.467, 0.053, 0.886, 0.005)}),
    Case("kf1", "T4", observer="kalman:1", estimators=("rfr",), paper={"rfr": (0.785, 0.021, 0.954, 0.002)}),
    Case("kf10", "T4", observer="kalman:10", estimators=("rfr",), paper={"rfr": (0.777, 0.022, 0.952, 0.002)}),
    Case("kf0.1", "T4", observer="kalman:0.1", estimators=("rfr",), paper={"rfr": (0.787, 0.024, 0.954, 0.002)}),
    Case("ntheta2", "T5", n_models=2, estimators=("rfr",), paper={"rfr": (0.684, 0.033, 0.932, 0.005)}),
    Case("ntheta3", "T5", n_models=3, estimators=("rfr",), paper={"rfr": (0.781, 0.023, 0.953, 0.001)}),
    Case("ntheta7", "T5", n_models=7, estimators=("rfr",), paper={"rfr": (0.793, 0.024, 0.956, 0.001)}),
    Case("cosine", "T6", rho_law="cosine", test_rho_law="cosine", estimators=ALL5, paper={
        "dtr": (0.842, 0.005, 0.953, 0.001), "rfr": (0.876, 0.004, 0.963, 0.001), "ann": (0.873, 0.003, 0.962, 0.001)}),
    Case("rw-to-cosine", "T7", test_rho_law="cosine", estimators=ALL5, paper={
        "dtr": (0.753, 0.066, 0.924, 0.020), "rfr": (0.801, 0.046, 0.939, 0.014), "ann": (0.844, 0.009, 0.952, 0.003)}),
]
TABLES = sorted({c.table for c in CASES})


def select_cases(tables: list[str] | None = None, cases: list[str] | None = None) -> list[Case]:
    """Cases of the given table labels (``T4``, ``T1/T3`` ...; ``T1-T5`` is the base) or names."""
    sel = CASES
    if cases:
        unknown = set(cases) - {c.name for c in CASES}
        if unknown:
            raise InputError(f"unknown case(s) {', '.join(sorted(unknown))}; known: {', '.join(c.name for c in CASES)}")
        sel = [c for c in sel if c.name in cases]
    if tables:
        sel = [c for c in sel if any(t in c.table for t in tables)]
    if not sel:
        raise InputError("no case selected")
    return sel


def _with_taps(feats: np.ndarray, valid: slice, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The paper's I_k: bank features then u_k, y_k."""
    return np.column_stack([feats, u[valid], y[valid]])


def run(cases: list[Case], runs: int = 10, quick: bool = False, progress: Callable[[str], None] | None = None,
        predictors: tuple = ESTIMATORS, ann_cases: tuple | None = None, executor=None) -> dict:
    """Run the cases; return the results document (:mod:`pwas_hdl.bench_results`).

    Parameters
    ----------
    cases : list of Case
    runs : int
        Runs (seeds 0 .. runs-1) per case.
    quick : bool
        Smoke run: 3000 training / 1000 test samples, no ANN.
    predictors : tuple of str
        Estimators to run (subset of :data:`ESTIMATORS`), where a case lists them.
    ann_cases : tuple of str, optional
        Run the ANN only in these cases (it costs ~30 s a fit on 25 000 samples, 2 cores).
    """
    if quick:
        predictors = tuple(p for p in predictors if p != "ann")
    if runs < 1:
        raise InputError("--runs must be >= 1")
    t0 = time.perf_counter()
    col = Collector()
    n_test = 1000 if quick else 5000
    def one_run(r: int):
        """Run r (fresh data, seed r): its values and timings."""
        col = Collector()
        data, lpvs = {}, {}
        for case in cases:
            n_train = 3000 if quick else case.n_train
            dkey = (n_train,) + case.data_key()[1:]
            if dkey not in data:
                data[dkey] = make_pv_dataset(SYSTEM, n_train, n_test, seed=r, noise=case.noise, rho_law=case.rho_law,
                                             test_rho_law=case.test_rho_law)
            tr, te, _ = data[dkey]
            fe = ObserverBankFrontEnd(n_models=case.n_models, observer=case.observer, features=case.features)
            fe.fit([tr.u], [tr.y], [tr.z], lpv=lpvs.get(dkey))
            lpvs[dkey] = fe.lpv_
            f_tr, v_tr = fe.transform([tr.u], [tr.y])
            f_te, v_te = fe.transform([te.u], [te.y])
            x_tr, x_te = _with_taps(f_tr, v_tr[0], tr.u, tr.y), _with_taps(f_te, v_te[0], te.u, te.y)
            z_tr, z_te = tr.z[v_tr[0], 0], te.z_true[v_te[0], 0]
            for est in case.estimators:
                if est not in predictors or (est == "ann" and ann_cases is not None and case.name not in ann_cases):
                    continue
                key = (case.name, est)
                if est in ("dtr", "rfr", "ann"):
                    model, tm = fit_sklearn(make_predictor(est, random_state=r), x_tr, z_tr)
                    zhat, ztrue = model.predict(x_te), z_te
                else:
                    if est == "pwas-feat":
                        tmpl = copy.deepcopy(fe)
                        model, tm = fit_pwas(PFEAT, tmpl, tr.u, tr.y, tr.z)
                        if not np.array_equal(model.front_end_.models_, fe.models_):
                            raise AssertionError("the sensor's front end differs from the bench's")
                    else:
                        model, tm = fit_pwas(PRAW, None, tr.u, tr.y, tr.z)
                    zhat = model.predict(te.u, te.y)[:, 0]
                    ztrue = te.z_true[model.memory - 1 :, 0]
                col.add(key + ("fit",), fit_ratio(ztrue, zhat))
                col.add(key + ("nrmse",), nrmse(ztrue, zhat))
                col.time(key, tm)
            say(progress, f"run {r + 1}/{runs} {case.name}: " + ", ".join(
                f"{e} {col.values[(case.name, e, 'fit')][-1]:.3f}" for e in case.estimators if (case.name, e, "fit") in col.values))
        return col

    for part in br.map_runs(one_run, range(runs), executor, labels=[f"run {r}" for r in range(runs)]):
        col.extend(part)
    rows = []
    for case in cases:
        for est in case.estimators:
            if (case.name, est, "fit") not in col.values:
                continue
            pap = case.paper.get(est, (None, None, None, None))
            cfg = case.config() | col.timing_of((case.name, est))
            if quick:
                cfg |= {"n_train": 3000, "n_test": n_test}
            if est == "pwas-feat":
                cfg |= {"pwas": PFEAT}
            elif est == "pwas-raw":
                cfg |= {"pwas": PRAW}
            for metric, pv, ps in (("fit", pap[0], pap[1]), ("nrmse", pap[2], pap[3])):
                c = cfg | ({"paper_std": ps} if ps is not None else {})
                rows.append(br.row_from_values(SYSTEM, "rho", est, "float", metric, col.values[(case.name, est, metric)], pv, c))
    return br.make_results(
        SYSTEM, rows, ASSUMPTIONS,
        config={"runs": runs, "n_test": n_test, "cases": [c.name for c in cases], "order_M": 5, "window_l": 7,
                "predictors": list(predictors), "ann_cases": list(ann_cases) if ann_cases is not None else "all",
                "pfeat": PFEAT, "praw": PRAW},
        description="Seed 004 E1 (Masti et al., EJC 2021), Tables 1-7: FIT/NRMSE of rho on the test set, mean and std over runs",
        quick=quick, elapsed_s=time.perf_counter() - t0,
    )


def merge(docs: list[dict]) -> dict:
    """One document from several partial runs (e.g. the ANN with fewer runs than the trees).

    A (case, estimator, metric) row of a later document is dropped when an earlier one has it.
    """
    seen, rows, cases = set(), [], []
    for d in docs:
        for r in d["rows"]:
            key = (r["config"]["case"], r["estimator"], r["metric"])
            if key not in seen:
                seen.add(key)
                rows.append(r)
        cases += [c for c in d["config"]["cases"] if c not in cases]
    cases = [c.name for c in CASES if c.name in cases]
    return br.make_results(
        SYSTEM, rows, docs[0]["assumptions"],
        config={"runs": max(d["config"]["runs"] for d in docs), "n_test": docs[0]["config"]["n_test"], "cases": cases,
                "order_M": 5, "window_l": 7, "pfeat": PFEAT, "praw": PRAW, "parts": [d["config"] for d in docs]},
        description=docs[0].get("description"), quick=any(d.get("quick") for d in docs),
        elapsed_s=sum(d["environment"].get("elapsed_s", 0.0) for d in docs),
    )


def markdown(doc: dict) -> str:
    """Paper | ours per case: DTR / RFR / ANN / PWAS P-feat / PWAS P-raw, FIT then NRMSE."""
    runs = doc["config"]["runs"]

    def c(r):
        return cell(r) + (f" ({r['runs']} runs)" if r is not None and r["runs"] != runs else "")

    lines = [
        f"# Seed 004 E1: parameter-varying benchmark (runs = {runs} unless stated{', QUICK' if doc.get('quick') else ''})",
        "",
        "FIT (13a) and NRMSE (13b) of rho on the test set, mean ± std over runs; paper figures of Tables 1-7 beside.",
        "PWAS P-feat: the toolchain's sensor with the observer-bank front end on [v1..vN], p = 6, sigma by CV; "
        "P-raw: lag regressor Mu = 2, My = 3, p = 3. `—`: not run / not printed.",
        "",
    ]
    for metric in ("fit", "nrmse"):
        lines += [f"## {metric.upper()}", "",
                  "| table | case | paper DTR | ours DTR | paper RFR | ours RFR | paper ANN | ours ANN | PWAS P-feat | PWAS P-raw |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for name in doc["config"]["cases"]:
            rs = {r["estimator"]: r for r in br.find_rows(doc, metric=metric, config={"case": name})}
            if not rs:
                continue
            any_r = next(iter(rs.values()))
            cells = [any_r["config"]["table"], name]
            for est in ("dtr", "rfr", "ann"):
                r = rs.get(est)
                cells += [paper_cell(r["paper"], r["config"].get("paper_std")) if r else "—", c(r)]
            cells += [c(rs.get("pwas-feat")), c(rs.get("pwas-raw"))]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["## Training time and peak traced memory per predictor (mean over runs)", "",
              "| case | estimator | train [s] | peak [MiB] |", "|---|---|---:|---:|"]
    for r in doc["rows"]:
        if r["metric"] == "fit" and "train_s" in r["config"]:
            lines.append(f"| {r['config']['case']} | {r['estimator']} | {r['config']['train_s']:.2f} | {r['config']['peak_mib']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Merge partial result files: ``python -m pwas_hdl.benchmarks.pv_benchmark OUT.json OUT.md IN.json...``."""
    import argparse

    from pwas_hdl.io.atomic import atomic_write_text

    ap = argparse.ArgumentParser(description="merge partial pv-benchmark result files (bench-results-v1)")
    ap.add_argument("out_json")
    ap.add_argument("out_md")
    ap.add_argument("inputs", nargs="+", help="partial result files to merge")
    a = ap.parse_args(argv)
    merged = merge([br.load_results(p) for p in a.inputs])
    br.write_results(a.out_json, merged)
    atomic_write_text(a.out_md, markdown(merged))
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(br.script_main(main, sys.argv[1:]))
