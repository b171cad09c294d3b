"""Three-tank bench (seed 001): the paper's sensors (27)/(28) beside PWAS sensors of x1 and x3.

Protocol (``seed-specs/seed_001.md`` §4; every assumption is written into the result file):

* test = the paper's run (:func:`pwas_hdl.systems.three_tank.three_tank_paper_run`): x(0) =
  (8, 2, 1), sensors z(0) = (5, 2), u1 = u2 = 1 + sin t, rho ~ U[-0.15, 0.15] from t = 100,
  T = 1000; run ``r`` draws the disturbance (and the y noise) with seed ``r``;
* training (PWAS only; the paper's sensors are model-based) = 20 runs of 1000 steps from random
  admissible levels, random input phase, rho on from t = 0, seed ``1000 (r + 1)``;
* PWAS regressor from ``u1`` and ``y`` lags (u1 = u2, so u2 adds nothing); lags and partitions
  chosen per target by validation among :data:`CANDIDATES` (fit on the first 15 training runs,
  scored on the last 5, noise-free run 0), then refitted on all 20 training runs for every run
  and noise level; sigma by 5-fold CV; gamma 1.1; zero-order Tikhonov;
* PWAS float and bit-true (``FixedPointModel`` default formats, 12-bit inputs);
* RMSE of x1 and x3 over ``t >= 100`` (disturbance on) and over ``M-1 <= t < 100``; a noise
  study with Gaussian noise on y (std 0.01, 0.02, 0.05; the same noise on training and test y),
  scored against the noise-free states. The causal limit for x1 once rho is on is about
  std(rho) = 0.15 / sqrt(3) = 0.087 (seed_001.md §4: x1(t) holds rho(t-1), which reaches y at t+1).

The paper prints no numbers (``paper`` is null everywhere). Usage::

    python benchmarks/three_tank.py [--runs 5] [--quick] [--outdir benchmarks/results]

or ``pwas-hdl bench three-tank --json OUT.json [--md OUT.md] [--plot OUT.png] [--runs 5] [--quick]``.
"""

from __future__ import annotations

import sys

import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from pwas_hdl import bench_results as br
from pwas_hdl.benchmarks.bench_common import QUICK_SIGMA_GRID, PWASConfig, fit_pwas, pwas_estimates, rmse, select_pwas
from pwas_hdl.systems.decoupled_observer import paper_sensors
from pwas_hdl.systems.three_tank import THREE_TANK_ASSUMPTIONS, three_tank_paper_run, three_tank_training_runs

__all__ = ["BENCH", "CANDIDATES", "run_three_tank", "markdown", "plot"]

BENCH = "three-tank"
SYSTEM = "three-tank"
CANDIDATES = (PWASConfig(2, 3, 4), PWASConfig(1, 3, 4), PWASConfig(2, 2, 5), PWASConfig(3, 3, 3), PWASConfig(2, 4, 3))
NOISES = (0.0, 0.01, 0.02, 0.05)
TARGETS = (("x1", 0, "paper-27"), ("x3", 1, "paper-28"))


def _windows(T: int, start: int) -> dict[str, np.ndarray]:
    t = np.arange(T)
    return {"t>=100": t >= 100, f"{start}<=t<100": (t >= start) & (t < 100)}


def run_three_tank(
    runs: int = 5,
    quick: bool = False,
    noises: Sequence[float] = NOISES,
    train_runs: int = 20,
    samples: int = 1000,
    progress: Callable[[str], None] | None = None,
    executor=None,
) -> tuple[dict, dict]:
    """Run the bench; returns the result document and the traces of run 0 without noise (for :func:`plot`).

    ``executor`` (:class:`pwas_hdl.flow.executor.Executor`, default serial) runs the (noise, run)
    tasks; the document is the same whatever runs them.
    """
    say = progress or (lambda s: None)
    t0 = time.monotonic()
    if quick:
        runs, noises, train_runs, cands = 1, (0.0,), 6, (CANDIDATES[0],)
    else:
        cands = CANDIDATES
    names = {"u": ["u1"], "y": ["y"]}
    grid = QUICK_SIGMA_GRID if quick else None
    chosen: dict[str, PWASConfig] = {}
    validation: dict[str, dict] = {}
    sel = three_tank_training_runs(train_runs, samples, seed=1000, noise=0.0).runs()
    for tgt, col, _ in TARGETS:
        if len(cands) == 1:
            chosen[tgt], validation[tgt] = cands[0], {}
            continue
        say(f"selecting lags/partitions for {tgt} ...")
        holdout = max(1, train_runs // 4)
        chosen[tgt], validation[tgt] = select_pwas(cands, [r.u[:, :1] for r in sel], [r.y for r in sel],
                                                   [r.z[:, col : col + 1] for r in sel], holdout, names | {"z": [tgt]}, say)
    start = max(max(c.mu, c.my) for c in chosen.values()) - 1  # first sample every PWAS estimates

    def one_run(task: tuple[float, int]) -> tuple[dict, dict, dict]:
        """Run r at one noise level: its values, extra statistics and (run 0, no noise) traces."""
        noise, r = task
        vals: dict[tuple, list[float]] = {}
        extra: dict[tuple, list[float]] = {}
        traces: dict = {}
        say(f"noise {noise}: run {r + 1}/{runs}")
        train = three_tank_training_runs(train_runs, samples, seed=1000 * (r + 1), noise=noise).runs()
        test = three_tank_paper_run(samples, seed=r, noise=noise)
        win = _windows(samples, start)
        paper = paper_sensors(test.u[:, 0], test.y)
        for tgt, col, pname in TARGETS:
            cfg = chosen[tgt]
            m = fit_pwas(cfg, [d.u[:, :1] for d in train], [d.y for d in train], [d.z[:, col : col + 1] for d in train],
                         names | {"z": [tgt]}, grid)
            est = pwas_estimates(m, test.u[:, :1], test.y)
            truth = test.z_true[:, col]
            for wname, w in win.items():
                for est_name, stage, zhat in ((pname, "float", paper[:, col]), ("pwas", "float", est["float"][:, 0]),
                                              ("pwas", "bittrue", est["bittrue"][:, 0])):
                    vals.setdefault((tgt, est_name, stage, wname, noise), []).append(rmse(zhat - truth, w))
            key = (tgt, noise)
            extra.setdefault(key + ("ood",), []).append(float(est["out_of_domain"][start:].mean()))
            extra.setdefault(key + ("sigma",), []).append(float(m.sigma_))
            if noise == 0.0 and r == 0:
                traces[tgt] = {"t": np.arange(samples), "true": truth, pname: paper[:, col], "pwas": est["float"][:, 0],
                               "pwas_bittrue": est["bittrue"][:, 0]}
                traces[f"{tgt}_fixed_point"] = str(est["fixed_point"])
        return vals, extra, traces

    vals: dict[tuple, list[float]] = {}
    extra: dict[tuple, list[float]] = {}
    traces: dict = {}
    tasks = [(noise, r) for noise in noises for r in range(runs)]
    for v, e, t in br.map_runs(one_run, tasks, executor, labels=[f"noise {n} run {r}" for n, r in tasks]):
        br.extend_lists(vals, v)
        br.extend_lists(extra, e)
        traces.update(t)
    # issue 13: recurrent sensors (dynamical PWAS, PWAS of maps 27/28; float, bit-true, RTL) and Lorenz Mz = 1, 2
    from pwas_hdl.benchmarks.recurrent import lorenz_rows, recurrent_rows

    rec_rows, rec_traces, rec_conf = recurrent_rows(runs, quick, train_runs, samples, chosen, _windows(samples, start), say)
    lz_rows, lz_conf = lorenz_rows(runs, quick, say)
    for tgt, tr in rec_traces.items():
        traces[tgt].update({k: v for k, v in tr.items() if k.startswith(("pwas-map", "pwas-dyn"))})
    rows = rec_rows + lz_rows
    for (tgt, est_name, stage, wname, noise), v in vals.items():
        cfg = {"window": wname, "noise_y": noise, "test": "paper run (x0 = (8, 2, 1), rho from t = 100, T = 1000)"}
        if est_name == "pwas":
            c = chosen[tgt]
            cfg |= {"Mu": c.mu, "My": c.my, "p": c.p, "gamma": c.gamma, "tikhonov": c.tikhonov, "inputs": "u1, y",
                    "train_runs": train_runs, "sigma_median": float(np.median(extra[(tgt, noise, "sigma")])),
                    "out_of_domain_fraction_mean": float(np.mean(extra[(tgt, noise, "ood")]))}
            if stage == "bittrue":
                cfg["formats"] = "default (12-bit inputs, 5 % noise budget)"
        else:
            cfg |= {"z0": [5.0, 2.0], "eq": est_name.split("-")[1]}
        rows.append(br.row_from_values(SYSTEM, tgt, est_name, stage, "rmse", v, None, cfg))
    config = {
        "runs": runs, "noise_levels": list(noises), "train_runs": train_runs, "samples_per_run": samples,
        "candidates": [c.label() for c in cands], "chosen": {t: c.label() for t, c in chosen.items()},
        "validation_rmse": validation, "causal_limit_x1": 0.15 / np.sqrt(3.0),
        "seeds": "test run r: seed r; training runs: seed 1000 (r + 1); selection: seed 1000, noise 0",
        "recurrent": rec_conf | lz_conf,
    }
    assumptions = dict(THREE_TANK_ASSUMPTIONS)
    assumptions["seed_001.4-split"] = "PWAS lags/partitions chosen on the training runs only (hold-out of the last quarter)"
    doc = br.make_results(BENCH, rows, assumptions, config,
                          "Seed 001: sensors (27)/(28) vs PWAS (float, bit-true) on the paper's run", quick,
                          time.monotonic() - t0)
    return doc, traces


def markdown(doc: dict) -> str:
    """Compact table: per noise level and window, mean ± std RMSE of every estimator."""
    def cell(**kw):
        r = br.find_rows(doc, **kw)
        if not r or r[0]["value"] is None:
            return "—"
        v = r[0]
        return f"{v['value']:.4g}" + (f" ± {v['std']:.2g}" if v["std"] is not None else "")

    noises = doc["config"]["noise_levels"]
    wins = sorted({r["config"]["window"] for r in doc["rows"] if "window" in r["config"]}, key=lambda w: w != "t>=100")
    lines = [f"Three-tank (seed 001), RMSE on the paper's run, mean ± std over {doc['config']['runs']} runs "
             f"(PWAS x1: {doc['config']['chosen']['x1']}, x3: {doc['config']['chosen']['x3']}; inputs u1, y)", "",
             "| noise y | window | x1 sensor (27) | x1 PWAS float | x1 PWAS bit-true | x3 sensor (28) | x3 PWAS float | x3 PWAS bit-true |",
             "|---:|---|---:|---:|---:|---:|---:|---:|"]
    for nz in noises:
        for w in wins:
            c = lambda tgt, est, st: cell(target=tgt, estimator=est, stage=st, config={"window": w, "noise_y": nz})  # noqa: E731
            lines.append(f"| {nz} | {w} | {c('x1', 'paper-27', 'float')} | {c('x1', 'pwas', 'float')} | {c('x1', 'pwas', 'bittrue')} "
                         f"| {c('x3', 'paper-28', 'float')} | {c('x3', 'pwas', 'float')} | {c('x3', 'pwas', 'bittrue')} |")
    lines += ["", f"Causal limit for x1 with rho on: about {doc['config']['causal_limit_x1']:.3f}. The paper prints no numbers.", ""]
    lines += _recurrent_markdown(doc, cell, wins)
    return "\n".join(lines)


def _recurrent_markdown(doc: dict, cell, wins) -> list[str]:
    """Issue 13 tables: recurrent sensors of x1 / x3 (noise-free paper run) and Lorenz with Mz."""
    rec = doc["config"].get("recurrent")
    if rec is None:
        return []
    ests = [("paper-27", "paper-28", "sensor (27)/(28)", ("float",)), ("pwas", "pwas", "lag-window PWAS", ("float", "bittrue")),
            ("pwas-dyn", "pwas-dyn", "dynamical PWAS (Mz = 1)", ("float", "bittrue", "rtl")),
            ("pwas-map-27", "pwas-map-28", "PWAS of map (27)/(28), recurrent", ("float", "bittrue", "rtl")),
            (None, "pwas-map-28-12bit", "PWAS of map (28), 12-bit inputs", ("bittrue",))]
    lines = [f"Recurrent sensors (issue 13), noise-free paper run, RMSE mean ± std over {doc['config']['runs']} runs "
             f"(RTL: run 0 on Icarus, its own output codes; bit-true of recurrent sensors: {rec['rec_input_bits']}-bit inputs)", "",
             "| window | estimator | stage | x1 | x3 |", "|---|---|---|---:|---:|"]
    for w in wins:
        for e1, e3, label, stages in ests:
            for st in stages:
                c1 = cell(target="x1", estimator=e1, stage=st, config={"window": w, "noise_y": 0.0}) if e1 else "—"
                c3 = cell(target="x3", estimator=e3, stage=st, config={"window": w, "noise_y": 0.0})
                lines.append(f"| {w} | {label} | {st} | {c1} | {c3} |")
    rtl = rec.get("rtl", {})
    if rtl:
        lines += ["", "RTL replays (run 0): " + "; ".join(f"{k}: {v['outputs']} outputs, {v['mismatches']} mismatches vs bit-true, "
                                                        f"latency {v['latency']}, II {v['ii']}" for k, v in rtl.items())]
    lz = br.find_rows(doc, system="lorenz")
    if lz:
        lines += ["", "Lorenz (eq. 18), RMSEE on the test samples, mean ± std", "", "| sensor | float | bit-true |", "|---|---:|---:|"]
        for label in dict.fromkeys(r["config"]["label"] for r in lz):
            f = [cell(system="lorenz", stage=st, config={"label": label}) for st in ("float", "bittrue")]
            lines.append(f"| {label} | {f[0]} | {f[1]} |")
    return lines + [""]


def plot(traces: dict, path: str | Path) -> Path:
    """Fig. 2 of the paper: x1, x3 and their estimates on the paper's run (noise-free run 0)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for ax, (tgt, pname, lab) in zip(axes, (("x1", "paper-27", "sensor (27)"), ("x3", "paper-28", "sensor (28)"))):
        tr = traces[tgt]
        ax.plot(tr["t"], tr["true"], "k-", lw=1.2, label=f"{tgt} (plant)")
        ax.plot(tr["t"], tr[pname], "C0--", lw=1, label=lab)
        ax.plot(tr["t"], tr["pwas"], "C3-", lw=0.8, alpha=0.8, label="PWAS (float)")
        ax.axvline(100, color="0.6", lw=0.8, ls=":")
        ax.set_ylabel(tgt)
        ax.legend(loc="lower right", fontsize=8)
    axes[1].set_xlabel("t (steps); disturbance on from t = 100")
    axes[0].set_title("Three-tank (seed 001): paper's run, states and virtual sensors")
    fig.tight_layout()
    return br.save_figure(fig, path)


def main(argv: Sequence[str] | None = None) -> None:  # pragma: no cover - script entry
    br.bench_main(argv, stem="three_tank", description=__doc__.splitlines()[0], run=run_three_tank, markdown=markdown, plot=plot)


if __name__ == "__main__":  # pragma: no cover
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
