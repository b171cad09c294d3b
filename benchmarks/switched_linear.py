"""Switched-linear bench (seed 003): the paper's virtual estimator beside PWAS sensors.

Protocol (``seed-specs/seed_003.md`` §4-5; every assumption is written into the result file):

* plant eq. (11), both switching laws of A2 (``time``, ``output``);
* the paper's estimator: bank (8) with output injection (A3, practical variant), residual
  detector (9) (single-sample residual, A3), switched Luenberger observer (10) with poles
  {0.3, 0.4} (A4), all started at 0 (A6); the known-mode baseline [18] is the same observer fed
  the true mode;
* test sets: the **paper replica** (100 samples, step input u = 1, dwell 34, x0 = (0.5, 0.5)) for
  Table 1 (output MSE of ``y - C(theta_hat) x_hat`` over the whole run, A8), and an independent
  **long run** (2000 samples, PRBS input, random dwell 20-50, random x0) for state RMSE and
  mode accuracy / per-mode F1;
* PWAS (trained on 10 runs x 1000 samples, PRBS, random dwell and x0; seed ``1000 (r + 1)``):
  one sensor per state x1, x2 with lags/partitions chosen by validation among
  :data:`CANDIDATES` (last 2 training runs held out, noise-free, run 0), sigma by CV; the mode
  (a) as a rounded scalar regression (``pwas-round``) and (b) as a classifier: one-hot targets
  (nz = 3) on one shared grid, argmax decision (``pwas-classifier``); float and bit-true (default
  formats, 12-bit inputs);
* noise study: Gaussian noise on y (std 0.01, 0.02, 0.05) on training and test data; errors are
  against the noise-free states, the output MSE against the measured y (as the paper's y_r - y_e);
* RTL (``stage: rtl``, noise-free runs): the classifier generated as the virtual-sensor top
  (lag bank + core + argmax stage, default formats) and the long test run replayed through it in
  a Verilog simulator (cocotb, ``rtl="icarus"``; the full run's default, off under ``--quick``);
  mode accuracy / F1 from the RTL's class index, which is also checked against the bit-true argmax
  (``config.rtl.class_mismatches_vs_bittrue``).

Paper figures (Table 1): output MSE 0.0069 (known mode), 0.0966 (unknown mode).
Usage: ``python benchmarks/switched_linear.py [--runs 5] [--quick]`` or
``pwas-hdl bench switched-linear --json OUT.json [--md OUT.md] [--plot OUT.png] [--runs 5] [--quick]``.
"""

from __future__ import annotations

import sys

import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from pwas_hdl import bench_results as br
from pwas_hdl.fit import classifier as clf
from pwas_hdl.benchmarks.bench_common import QUICK_SIGMA_GRID, PWASConfig, fit_pwas, pwas_estimates, rmse, select_pwas
from pwas_hdl.systems.switched_linear import SWITCHED_ASSUMPTIONS, switched_paper_run, switched_training_runs
from pwas_hdl.systems.switched_observer import DEFAULT_POLES, mode_scores, run_switched_observer

__all__ = ["BENCH", "CANDIDATES", "PAPER_TABLE1", "run_switched_linear", "markdown", "plot"]

BENCH = "switched-linear"
SYSTEM = "switched-linear"
CANDIDATES = (PWASConfig(2, 2, 4), PWASConfig(2, 3, 3), PWASConfig(3, 3, 3))
NOISES = (0.0, 0.01, 0.02, 0.05)
LAWS = ("time", "output")
#: Table 1 of the paper: output MSE.
PAPER_TABLE1 = {"known-mode-observer": 0.0069, "switched-observer": 0.0966}
MODES = (1, 2, 3)


def _class_fit(cfg: PWASConfig, train, onehot: bool, grid=None):
    """PWAS of the mode: one-hot scores on one grid (classifier) or the label as a scalar target."""
    zs = [clf.one_hot(d.mode, MODES) if onehot else d.mode[:, None].astype(float) for d in train]
    names = {"u": ["u"], "y": ["y"], "z": clf.class_target_names("mode", MODES) if onehot else ["mode"]}
    return fit_pwas(cfg, [d.u for d in train], [d.y for d in train], zs, names, grid)


def _decide(scores: np.ndarray, onehot: bool) -> np.ndarray:
    """Mode labels from PWAS outputs: argmax of the one-hot scores, or the rounded scalar (clipped)."""
    if onehot:
        return clf.decide(scores, MODES).astype(int)
    return np.clip(np.rint(scores[:, 0]), 1, 3).astype(int)


def run_switched_linear(
    runs: int = 5,
    quick: bool = False,
    noises: Sequence[float] = NOISES,
    laws: Sequence[str] = LAWS,
    train_runs: int = 10,
    samples: int = 1000,
    test_samples: int = 2000,
    progress: Callable[[str], None] | None = None,
    rtl: str | None = "default",
    executor=None,
) -> tuple[dict, dict]:
    """Run the bench; returns the document and traces (time law, no noise, run 0) for :func:`plot`.

    ``rtl``: simulator of the RTL replay of the classifier (``"icarus"`` or ``"verilator"``), or
    None for none; ``"default"``: ``"icarus"`` for the full run, None with ``quick``.
    ``executor`` (:class:`pwas_hdl.flow.executor.Executor`, default serial) runs the (law, noise,
    run) tasks; the document is the same whatever runs them.
    """
    say = progress or (lambda s: None)
    t0 = time.monotonic()
    if rtl == "default":
        rtl = None if quick else "icarus"
    rtl_info: dict = {"simulator": rtl, "replays": 0, "samples": 0, "class_mismatches_vs_bittrue": 0}
    if quick:
        runs, noises, laws, train_runs, test_samples, cands = 1, (0.0,), ("time",), 4, 1000, (CANDIDATES[0],)
    else:
        cands = CANDIDATES
    grid = QUICK_SIGMA_GRID if quick else None
    chosen: dict[str, PWASConfig] = {}
    validation: dict[str, dict] = {}
    sel = switched_training_runs(train_runs, samples, seed=1000, switching="time").runs()
    holdout = max(1, train_runs // 5)
    for col, tgt in enumerate(("x1", "x2")):
        if len(cands) == 1:
            chosen[tgt], validation[tgt] = cands[0], {}
            continue
        say(f"selecting lags/partitions for {tgt} ...")
        chosen[tgt], validation[tgt] = select_pwas(cands, [d.u for d in sel], [d.y for d in sel],
                                                   [d.z[:, col : col + 1] for d in sel], holdout,
                                                   {"u": ["u"], "y": ["y"], "z": [tgt]}, say)
    # the mode uses the state sensors' richer configuration (largest regressor of the chosen ones)
    chosen["mode"] = max(chosen.values(), key=lambda c: (c.mu + c.my, c.p))
    def one_run(task: tuple[str, float, int]) -> tuple[dict, dict, dict]:
        """Run r of one switching law and noise level: its values, (time law, no noise, run 0) traces
        and its RTL replay counts."""
        law, noise, r = task
        vals: dict[tuple, list[float]] = {}
        traces: dict = {}
        rtl_info = {"replays": 0, "samples": 0, "class_mismatches_vs_bittrue": 0}

        def put(key, v):
            vals.setdefault(key, []).append(float(v))

        say(f"switching {law}, noise {noise}: run {r + 1}/{runs}")
        train = switched_training_runs(train_runs, samples, seed=1000 * (r + 1), switching=law, noise=noise).runs()
        tests = {
            "replica": switched_paper_run(seed=r, switching=law, input_kind="step", noise=noise),
            "long": switched_training_runs(1, test_samples, seed=5000 + r, switching=law, noise=noise),
        }
        obs = {name: {"known-mode-observer": run_switched_observer(d.u, d.y, known_mode=d.mode),
                      "switched-observer": run_switched_observer(d.u, d.y)} for name, d in tests.items()}
        for tname, d in tests.items():
            for est, o in obs[tname].items():
                put((tname, "y", est, "float", "mse", law, noise), np.mean((d.y[:, 0] - o.y_hat) ** 2))
                for col, tgt in enumerate(("x1", "x2")):
                    put((tname, tgt, est, "float", "rmse", law, noise), rmse(o.x_hat[:, col] - d.z_true[:, col]))
                if est == "switched-observer":
                    sc = mode_scores(d.mode, o.theta_hat, MODES)
                    put((tname, "mode", est, "float", "accuracy", law, noise), sc["accuracy"])
                    for c in MODES:
                        put((tname, f"mode={c}", est, "float", "f1", law, noise), sc["f1"][c])
        d = tests["long"]
        start = max(max(c.mu, c.my) for c in chosen.values()) - 1
        pw_tr = {}
        for col, tgt in enumerate(("x1", "x2")):
            m = fit_pwas(chosen[tgt], [t.u for t in train], [t.y for t in train], [t.z[:, col : col + 1] for t in train],
                         {"u": ["u"], "y": ["y"], "z": [tgt]}, grid)
            est = pwas_estimates(m, d.u, d.y)
            for stage in ("float", "bittrue"):
                put(("long", tgt, "pwas", stage, "rmse", law, noise), rmse(est[stage][start:, 0] - d.z_true[start:, col]))
            pw_tr[tgt] = est["float"][:, 0]
        for onehot, ename in ((False, "pwas-round"), (True, "pwas-classifier")):
            m = _class_fit(chosen["mode"], train, onehot, grid)
            est = pwas_estimates(m, d.u, d.y)
            for stage in ("float", "bittrue"):
                pred = _decide(est[stage][start:], onehot)
                sc = mode_scores(d.mode[start:], pred, MODES)
                put(("long", "mode", ename, stage, "accuracy", law, noise), sc["accuracy"])
                for c in MODES:
                    put(("long", f"mode={c}", ename, stage, "f1", law, noise), sc["f1"][c])
                if onehot and stage == "float":
                    pw_tr["mode"] = np.concatenate([np.zeros(start, dtype=int), pred])
            if onehot and rtl and noise == 0.0:
                say(f"  RTL replay of the classifier ({rtl}, {len(d.y)} samples) ...")
                pred, n_mism = _rtl_classes(m, d, rtl)
                ok = np.arange(len(d.y)) >= start
                sc = mode_scores(d.mode[ok], pred[ok], MODES)
                put(("long", "mode", ename, "rtl", "accuracy", law, noise), sc["accuracy"])
                for c in MODES:
                    put(("long", f"mode={c}", ename, "rtl", "f1", law, noise), sc["f1"][c])
                rtl_info["replays"] += 1
                rtl_info["samples"] += int(ok.sum())
                rtl_info["class_mismatches_vs_bittrue"] += n_mism
        if law == "time" and noise == 0.0 and r == 0:
            rep = tests["replica"]
            traces = {"replica": {"y": rep.y[:, 0], **{k: o.y_hat for k, o in obs["replica"].items()}},
                      "long": {"x": d.z_true, "obs": obs["long"]["switched-observer"].x_hat,
                               "known": obs["long"]["known-mode-observer"].x_hat, "pwas_x1": pw_tr["x1"],
                               "pwas_x2": pw_tr["x2"], "mode": d.mode,
                               "mode_obs": obs["long"]["switched-observer"].theta_hat, "mode_pwas": pw_tr["mode"]}}
        return vals, traces, rtl_info

    vals: dict[tuple, list[float]] = {}
    traces: dict = {}
    tasks = [(law, noise, r) for law in laws for noise in noises for r in range(runs)]
    for v, t, counts in br.map_runs(one_run, tasks, executor, labels=[f"{law} noise {n} run {r}" for law, n, r in tasks]):
        br.extend_lists(vals, v)
        traces = traces or t
        for k, c in counts.items():
            rtl_info[k] += c
    rows = []
    for (tname, tgt, est, stage, metric, law, noise), v in vals.items():
        cfg = {"test": tname, "switching": law, "noise_y": noise}
        if est in PAPER_TABLE1:
            cfg |= {"poles": list(DEFAULT_POLES), "bank": "practical", "detector_window": 1}
        else:
            c = chosen["mode" if tgt.startswith("mode") else tgt]
            cfg |= {"Mu": c.mu, "My": c.my, "p": c.p, "gamma": c.gamma, "train_runs": train_runs}
        paper = PAPER_TABLE1.get(est) if (tgt == "y" and metric == "mse" and tname == "replica") else None
        rows.append(br.row_from_values(SYSTEM, tgt, est, stage, metric, v, paper, cfg))
    config = {
        "runs": runs, "noise_levels": list(noises), "switching_laws": list(laws), "train_runs": train_runs,
        "samples_per_train_run": samples, "long_test_samples": test_samples, "replica_samples": 100,
        "candidates": [c.label() for c in cands], "chosen": {t: c.label() for t, c in chosen.items()},
        "validation_rmse": validation,
        "seeds": "replica run r: seed r; long test: seed 5000 + r; training: seed 1000 (r + 1); selection: seed 1000",
        "rtl": rtl_info | {"design": "sensor (lag bank + core + argmax stage), default formats", "noise_levels": [0.0],
                           "test": "long"},
    }
    assumptions = dict(SWITCHED_ASSUMPTIONS)
    assumptions["seed_003.A3"] = ("detector theta_hat = argmin_i |y_k - C_i xhat^i_k| (single-sample residual); bank = "
                                  "per-mode Luenberger observers with the same gains (practical variant)")
    assumptions["seed_003.A4"] = "observer poles {0.3, 0.4} for every mode (scipy.signal.place_poles)"
    assumptions["seed_003.A8"] = "Table 1 MSE over the whole 100-sample replica, initial transient included"
    doc = br.make_results(BENCH, rows, assumptions, config,
                          "Seed 003: virtual estimator (bank + detector + switched observer) vs PWAS state sensors and mode classifier",
                          quick, time.monotonic() - t0)
    return doc, traces


def _rtl_classes(model, d, simulator: str) -> tuple[np.ndarray, int]:
    """The classifier's RTL (sensor top) replaying test run ``d``: the mode label of every sample
    (0 before the first output) and the number of class indices differing from the bit-true argmax."""
    import tempfile

    from pwas_hdl.design.generate import generate
    from pwas_hdl.verify.simulation import simulate_arrays

    model.classifier_ = {"target": "mode", "classes": [float(c) for c in MODES]}
    with tempfile.TemporaryDirectory(prefix="pwas-bench-rtl-") as tmp:
        generate(model, Path(tmp) / "design", design="sensor")
        r = simulate_arrays(Path(tmp) / "design", Path(tmp) / "hw.csv", u=d.u, y=d.y, simulator=simulator)
    s = r["summary"]
    if not s["checks"]["passed"]:
        raise RuntimeError(f"the RTL replay of the classifier failed: {s['checks']['failures'][:2]}")
    pred = np.zeros(len(d.y), dtype=int)
    pred[r["rows"]] = np.asarray(MODES)[r["class_index"]]
    return pred, int(s["classifier"]["class_mismatches"])


def markdown(doc: dict) -> str:
    """Tables: Table 1 next to ours; state RMSE; mode accuracy and F1."""
    def cell(**kw):
        r = br.find_rows(doc, **kw)
        if not r or r[0]["value"] is None:
            return "—"
        v = r[0]
        return f"{v['value']:.4g}" + (f" ± {v['std']:.2g}" if v["std"] is not None else "")

    cfg = doc["config"]
    out = [f"Switched linear system (seed 003), mean ± std over {cfg['runs']} runs; PWAS x1: {cfg['chosen']['x1']}, "
           f"x2: {cfg['chosen']['x2']}, mode: {cfg['chosen']['mode']}", ""]
    out += ["**Table 1 (output MSE, paper replica: 100 samples, step input, dwell 34)**", "",
            "| switching | noise y | known mode [18] ours | paper | unknown mode (detector) ours | paper |", "|---|---:|---:|---:|---:|---:|"]
    for law in cfg["switching_laws"]:
        for nz in cfg["noise_levels"]:
            c = {"test": "replica", "switching": law, "noise_y": nz}
            out.append(f"| {law} | {nz} | {cell(target='y', estimator='known-mode-observer', metric='mse', config=c)} | 0.0069 "
                       f"| {cell(target='y', estimator='switched-observer', metric='mse', config=c)} | 0.0966 |")
    out += ["", f"**State RMSE (long test run, {cfg['long_test_samples']} samples, PRBS input)**", "",
            "| switching | noise y | x1 known mode | x1 detector | x1 PWAS float | x1 PWAS bit-true | x2 known mode | x2 detector | x2 PWAS float | x2 PWAS bit-true |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for law in cfg["switching_laws"]:
        for nz in cfg["noise_levels"]:
            c = {"test": "long", "switching": law, "noise_y": nz}
            cells = []
            for tgt in ("x1", "x2"):
                cells += [cell(target=tgt, estimator="known-mode-observer", config=c), cell(target=tgt, estimator="switched-observer", config=c),
                          cell(target=tgt, estimator="pwas", stage="float", config=c), cell(target=tgt, estimator="pwas", stage="bittrue", config=c)]
            out.append(f"| {law} | {nz} | " + " | ".join(cells) + " |")
    out += ["", "**Mode (long test run): accuracy and per-mode F1**", "",
            "| switching | noise y | estimator | stage | accuracy | F1 mode 1 | F1 mode 2 | F1 mode 3 |", "|---|---:|---|---|---:|---:|---:|---:|"]
    for law in cfg["switching_laws"]:
        for nz in cfg["noise_levels"]:
            c = {"test": "long", "switching": law, "noise_y": nz}
            for est, stage in (("switched-observer", "float"), ("pwas-round", "float"), ("pwas-round", "bittrue"),
                               ("pwas-classifier", "float"), ("pwas-classifier", "bittrue"), ("pwas-classifier", "rtl")):
                if stage == "rtl" and not br.find_rows(doc, target="mode", estimator=est, stage=stage, config=c):
                    continue
                f1 = [cell(target=f"mode={m}", estimator=est, stage=stage, config=c) for m in MODES]
                out.append(f"| {law} | {nz} | {est} | {stage} | {cell(target='mode', estimator=est, stage=stage, config=c)} | "
                           + " | ".join(f1) + " |")
    out.append("")
    return "\n".join(out)


def plot(traces: dict, path: str | Path) -> Path:
    """Figs. 3-5 of the paper: output and its estimates (replica), states and modes (long run)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(4, 1, figsize=(9, 10))
    rep = traces["replica"]
    k = np.arange(len(rep["y"]))
    ax[0].plot(k, rep["y"], "k-", lw=1.2, label="y (plant)")
    ax[0].plot(k, rep["known-mode-observer"], "C2--", label="known mode [18]")
    ax[0].plot(k, rep["switched-observer"], "C0:", lw=1.5, label="unknown mode (detector)")
    ax[0].set_title("Paper replica (step input, dwell 34): output and estimates (Figs. 3-4)")
    ax[0].legend(fontsize=8)
    lg = traces["long"]
    n = min(300, len(lg["mode"]))
    kk = np.arange(n)
    for i, tgt in enumerate(("x1", "x2")):
        a = ax[1 + i]
        a.plot(kk, lg["x"][:n, i], "k-", lw=1.2, label=f"{tgt} (plant)")
        a.plot(kk, lg["obs"][:n, i], "C0:", lw=1.5, label="switched observer (detector)")
        a.plot(kk, lg[f"pwas_{tgt}"][:n], "C3-", lw=0.8, label="PWAS (float)")
        a.set_ylabel(tgt)
        a.legend(fontsize=8, loc="upper right")
    ax[1].set_title("Long test run (PRBS input), first 300 samples: states")
    ax[3].step(kk, lg["mode"][:n], "k-", where="post", label="true mode")
    ax[3].step(kk, lg["mode_obs"][:n] + 0.08, "C0-", where="post", lw=0.8, label="detector (9)")
    ax[3].step(kk, lg["mode_pwas"][:n] - 0.08, "C3-", where="post", lw=0.8, label="PWAS classifier")
    ax[3].set_yticks([1, 2, 3])
    ax[3].set_xlabel("k (samples)")
    ax[3].set_title("Commutation signal: real vs estimated (Fig. 5)")
    ax[3].legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    return br.save_figure(fig, path)


def main(argv: Sequence[str] | None = None) -> None:  # pragma: no cover - script entry
    br.bench_main(argv, stem="switched_linear", description=__doc__.splitlines()[0], run=run_switched_linear, markdown=markdown, plot=plot)


if __name__ == "__main__":  # pragma: no cover
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
