"""Non-uniform against uniform partitions at equal N (issue 15 item 3): Lorenz and the three-tank.

Usage::

    python benchmarks/breakpoints_accuracy.py [--runs 3] [--quick] [--outdir benchmarks/results]

For every configuration the same data are fitted three times, differing only in the partition
(``fit --breakpoints``): ``uniform`` (equal intervals, the default), ``quantile`` (cuts at the
``k / p`` quantiles of the training regressors inside the gamma-expanded domain,
:func:`pwas_hdl.fit.geometry.quantile_breakpoints`) and ``quantile-pow2`` (the same rounded to
power-of-two multiples of a base step, :func:`pwas_hdl.fit.geometry.pow2_breakpoints`). Same
lags, same ``p`` per dimension, hence the same number of weights ``N``; sigma by 5-fold CV on
contiguous blocks (default 21-value grid) for each fit separately.

* Lorenz (the protocol of ``benchmarks/lorenz_tables.py``): run ``r`` = seed ``r``, 6000 training
  samples, RMSEE over the next 2000 against the noise-free ``z = x2 x3``; My = 4, p = 7 (N = 4096,
  the Table II baseline) and My = 2, p = 20 (N = 441); gamma = 1.2.
* Three-tank (the protocol of ``benchmarks/three_tank.py``, noise-free): 20 training runs (seed
  ``1000 (r + 1)``), test = the paper's run with seed ``r``, RMSE over ``t >= 100`` against the
  noise-free states x1 and x3; regressor Mu = 2 (u1), My = 3 (y), p = 4 (N = 3125), gamma = 1.1
  (the first candidate of the three-tank bench, fixed here for both targets).

Rows: ``metric = rmse``, ``stage = float``, config ``breakpoints``, lags, p, N. ``--quick``: one
run, Lorenz My = 2, p = 8 and a 5-value sigma grid, 6 three-tank training runs.

Through the RTL (``--hardware``, :func:`run_hardware`; writes ``breakpoints_hw.json`` / ``.md``):
run 0 of the rows above with the uniform and the ``quantile-pow2`` partition, each generated as the
virtual-sensor top (``generate --design sensor``, default formats, 12-bit inputs; the
``quantile-pow2`` one with the warp in front of the core) and its test data replayed through the
Verilog (``simulate``, Verilator), the hardware RMSE beside the bit-true and the float one, and
the mismatches against the bit-true model.
"""

from __future__ import annotations

import sys

import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from pwas_hdl import bench_results as br

BENCH = "breakpoints-accuracy"
RULES = (None, "quantile", "quantile-pow2")


def _label(rule) -> str:
    return rule or "uniform"


def _lorenz(runs: int, quick: bool, say) -> list[dict]:
    from pwas_hdl.benchmarks.bench_common import QUICK_SIGMA_GRID
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.lorenz import lorenz

    cfgs = [(2, 8)] if quick else [(4, 7), (2, 20)]
    n_train, n_test = 6000, 2000
    hist = max(my for my, _ in cfgs)
    grid = {"sigma_grid": list(QUICK_SIGMA_GRID)} if quick else {}
    vals: dict[tuple, list[float]] = {}
    for r in range(runs):
        data = lorenz(n_train + n_test + hist - 1, seed=r, burn_in=1000)
        z_true = data.z_true[n_train + hist - 1:, 0]
        for my, p in cfgs:
            for rule in RULES:
                say(f"lorenz run {r + 1}/{runs}: My = {my}, p = {p}, {_label(rule)}")
                s = PWASVirtualSensor(mu=0, my=my, partitions=p, gamma=1.2, breakpoints=rule, **grid)
                s.fit(None, data.y[:n_train], data.z[:n_train])
                zhat = s.predict(None, data.y[n_train + hist - my:])[:, 0]
                assert zhat.shape[0] == n_test
                vals.setdefault((my, p, rule), []).append(float(np.sqrt(np.mean((zhat - z_true) ** 2))))
    rows = []
    for (my, p, rule), v in vals.items():
        rows.append(br.row_from_values("lorenz", "z", "pwas", "float", "rmse", v, None, {
            "breakpoints": _label(rule), "My": my, "p": p, "N": (p + 1) ** my, "gamma": 1.2, "metric_is": "RMSEE vs noise-free z, 2000 test samples",
        }))
    return rows


def _three_tank(runs: int, quick: bool, say) -> list[dict]:
    from pwas_hdl.benchmarks.bench_common import QUICK_SIGMA_GRID, PWASConfig, fit_pwas, rmse
    from pwas_hdl.systems.three_tank import three_tank_paper_run, three_tank_training_runs

    cfg = PWASConfig(2, 3, 4)
    train_runs, samples = (6 if quick else 20), 1000
    grid = QUICK_SIGMA_GRID if quick else None
    names = {"u": ["u1"], "y": ["y"]}
    vals: dict[tuple, list[float]] = {}
    for r in range(runs):
        train = three_tank_training_runs(train_runs, samples, seed=1000 * (r + 1), noise=0.0).runs()
        test = three_tank_paper_run(samples, seed=r, noise=0.0)
        win = np.arange(samples) >= 100
        for tgt, col in (("x1", 0), ("x3", 1)):
            for rule in RULES:
                say(f"three-tank run {r + 1}/{runs}: {tgt}, {_label(rule)}")
                m = _fit_with(fit_pwas, rule, cfg, [d.u[:, :1] for d in train], [d.y for d in train],
                              [d.z[:, col:col + 1] for d in train], names | {"z": [tgt]}, grid)
                xi, _ = m.regressors(test.u[:, :1], test.y)
                zf = np.full(samples, np.nan)
                zf[m.lags_.memory - 1:] = m.predict_regressors(xi)[:, 0]
                vals.setdefault((tgt, rule), []).append(rmse(zf - test.z_true[:, col], win))
    rows = []
    for (tgt, rule), v in vals.items():
        rows.append(br.row_from_values("three-tank", tgt, "pwas", "float", "rmse", v, None, {
            "breakpoints": _label(rule), "Mu": cfg.mu, "My": cfg.my, "p": cfg.p, "N": (cfg.p + 1) ** (cfg.mu + cfg.my),
            "gamma": cfg.gamma, "window": "t>=100", "train_runs": train_runs,
        }))
    return rows


def _fit_with(fit_pwas, rule, cfg, us, ys, zs, names, grid):
    """:func:`fit_pwas` with a breakpoint rule (the shared helper fits uniform grids)."""
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    if rule is None:
        return fit_pwas(cfg, us, ys, zs, names, grid)
    extra = {"sigma_grid": list(grid)} if grid is not None else {}
    m = PWASVirtualSensor(mu=cfg.mu, my=cfg.my, partitions=cfg.p, gamma=cfg.gamma, tikhonov_order=cfg.tikhonov,
                          input_names=names.get("u"), output_names=names.get("y"), target_names=names.get("z"),
                          breakpoints=rule, **extra)
    return m.fit(list(us), list(ys), list(zs))


def run(runs: int = 3, quick: bool = False, progress: Callable[[str], None] | None = None) -> tuple[dict, dict]:
    say = progress or (lambda s: None)
    t0 = time.monotonic()
    if quick:
        runs = 1
    rows = _lorenz(runs, quick, say) + _three_tank(runs, quick, say)
    config = {"runs": runs, "rules": [_label(r) for r in RULES],
              "seeds": "Lorenz run r: seed r; three-tank: test seed r, training seed 1000 (r + 1)"}
    assumptions = {"equal-N": "same lags and p per dimension for every partition: the same number of weights N",
                   "sigma": "chosen by 5-fold CV for each fit separately",
                   "quantile-min-width": "no quantile cell narrower than 5 % of the uniform cell width",
                   "pow2-max-ratio": "power-of-two cells: widths 2**e * h0 with e = 0..4 (ratio <= 16)"}
    doc = br.make_results(BENCH, rows, assumptions, config, "Non-uniform (quantile, quantile-pow2) vs uniform partitions at equal N",
                          quick, time.monotonic() - t0)
    traces = {(r["system"], r["target"], r["config"]["breakpoints"], r["config"]["N"]): r["value"] for r in rows}
    return doc, traces


def markdown(doc: dict) -> str:
    out = [f"# Non-uniform vs uniform partitions at equal N (`benchmarks/breakpoints_accuracy.py`, {doc['config']['runs']} run(s))", "",
           "RMSE (mean over runs, sample std in parentheses); lower is better. Relative change against uniform.", "",
           "| system | target | lags, p | N | uniform | quantile | quantile-pow2 |", "|---|---|---|---|---|---|---|"]
    keys = []
    for r in doc["rows"]:
        c = r["config"]
        k = (r["system"], r["target"], c.get("Mu", 0), c["My"], c["p"], c["N"])
        if k not in keys:
            keys.append(k)
    for k in keys:
        sysname, tgt, mu, my, p, n = k
        cells = {}
        for r in doc["rows"]:
            c = r["config"]
            if (r["system"], r["target"], c.get("Mu", 0), c["My"], c["p"], c["N"]) == k:
                cells[c["breakpoints"]] = r
        base = cells["uniform"]["value"]

        def cell(name):
            r = cells[name]
            sd = f" ({r['std']:.3g})" if r["std"] is not None else ""
            rel = "" if name == "uniform" else f", {100 * (r['value'] / base - 1):+.1f} %"
            return f"{r['value']:.4g}{sd}{rel}"

        lags = (f"Mu = {mu}, " if mu else "") + f"My = {my}, p = {p}"
        out.append(f"| {sysname} | {tgt} | {lags} | {n} | {cell('uniform')} | {cell('quantile')} | {cell('quantile-pow2')} |")
    out.append("")
    return "\n".join(out)


def plot(traces: dict, path: str | Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = sorted({(s, t, n) for s, t, _, n in traces})
    fig, ax = plt.subplots(figsize=(8, 3.5))
    w = 0.27
    for i, rule in enumerate(("uniform", "quantile", "quantile-pow2")):
        base = [traces[(s, t, "uniform", n)] for s, t, n in groups]
        rel = [traces[(s, t, rule, n)] / b for (s, t, n), b in zip(groups, base)]
        ax.bar(np.arange(len(groups)) + (i - 1) * w, rel, w, label=rule)
    ax.set_xticks(np.arange(len(groups)), [f"{s} {t}\nN={n}" for s, t, n in groups], fontsize=8)
    ax.set_ylabel("RMSE / uniform RMSE")
    ax.axhline(1.0, color="black", lw=0.8)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return br.save_figure(fig, path)


HW_RULES = (None, "quantile-pow2")


def _replay(sensor, design_dir: Path, cols: dict, window, z_true: np.ndarray, simulator: str, cache: Path, say) -> dict:
    """Generate the sensor top of ``sensor``, replay ``cols`` (CSV columns) and score the estimates on ``window``."""
    from pwas_hdl.design.generate import generate
    from pwas_hdl.io.csv_table import format_csv
    from pwas_hdl.verify.simulation import simulate_data

    gd = generate(sensor, design_dir, design="sensor")
    csv = design_dir.parent / f"{design_dir.name}.csv"
    csv.write_text(format_csv(cols))
    t0 = time.monotonic()
    res = simulate_data(design_dir, csv, design_dir.parent / f"{design_dir.name}_hw.csv", simulator=simulator,
                        engine="native" if simulator == "verilator" else "cocotb", cache_dir=cache)
    s = res["summary"]
    rows = res["rows"]
    keep = window[rows]
    from pwas_hdl.io.csv_table import read_csv

    out = read_csv(design_dir.parent / f"{design_dir.name}_hw.csv")
    t = sensor.signal_names()[2][0]
    e = {stage: float(np.sqrt(np.mean((out.numeric([f"{t}_{stage}"])[keep, 0] - z_true[rows][keep]) ** 2)))
         for stage in ("hw", "bittrue", "float")}
    say(f"  {design_dir.name}: {s['samples']} outputs, {s['mismatches']} mismatches, RMSE hw {e['hw']:.4g} float {e['float']:.4g}")
    return {"design": gd.manifest["design"], "latency_cycles": gd.manifest["latency_cycles"], "ii": gd.manifest["ii"],
            "warp": "warp" in gd.manifest, "input_bits": gd.manifest["generator"]["options"]["input_bits"] or 12,
            "weights": gd.manifest["formats"]["weight"]["str"], "outputs": int(s["samples"]), "mismatches": int(s["mismatches"]),
            "passed": bool(s["checks"]["passed"]), "simulator": simulator, "rmse": e, "sim_wall_s": round(time.monotonic() - t0, 1)}


def run_hardware(workdir: Path, simulator: str = "verilator", progress: Callable[[str], None] | None = print,
                 synth: bool = False) -> dict:
    """Run 0 of the Lorenz (My = 4, p = 7) and three-tank rows, uniform and quantile-pow2, through the RTL;
    ``synth``: the two Lorenz sensor tops placed and routed once on ECP5 (``pwas-hdl synth`` defaults)."""
    from pwas_hdl.benchmarks.bench_common import PWASConfig, fit_pwas
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.lorenz import lorenz
    from pwas_hdl.systems.three_tank import three_tank_paper_run, three_tank_training_runs

    say = progress or (lambda m: None)
    work = Path(workdir)
    work.mkdir(parents=True, exist_ok=True)
    cache = work / "sim-cache"
    recs = []
    n_train, n_test, my, p = 6000, 2000, 4, 7
    data = lorenz(n_train + n_test + my - 1, seed=0, burn_in=1000)
    te = slice(n_train, None)
    for rule in HW_RULES:
        say(f"lorenz My = {my}, p = {p}, {_label(rule)}")
        s = PWASVirtualSensor(mu=0, my=my, partitions=p, gamma=1.2, breakpoints=rule, output_names=["y"], target_names=["z"])
        s.fit(None, data.y[:n_train], data.z[:n_train])
        win = np.ones(len(data.y[te]), dtype=bool)
        r = _replay(s, work / f"lorenz_{_label(rule)}", {"y": data.y[te, 0], "z_true": data.z_true[te, 0]}, win,
                    data.z_true[te, 0], simulator, cache, say)
        if synth:
            from pwas_hdl.flow.synthesis import synthesize

            sy = synthesize(work / f"lorenz_{_label(rule)}", "ecp5")
            r["ecp5"] = {k: sy.get(k) for k in ("part", "luts", "ffs", "carry", "dsp", "bram", "fmax_mhz", "latency_cycles")}
            say(f"  ECP5: {r['ecp5']}")
        recs.append({"system": "lorenz", "target": "z", "breakpoints": _label(rule), "My": my, "p": p, "N": (p + 1) ** my, **r})
    cfg = PWASConfig(2, 3, 4)
    samples = 1000
    train = three_tank_training_runs(20, samples, seed=1000, noise=0.0).runs()
    test = three_tank_paper_run(samples, seed=0, noise=0.0)
    win = np.arange(samples) >= 100
    for tgt, col in (("x1", 0), ("x3", 1)):
        for rule in HW_RULES:
            say(f"three-tank {tgt}, {_label(rule)}")
            m = _fit_with(fit_pwas, rule, cfg, [d.u[:, :1] for d in train], [d.y for d in train],
                          [d.z[:, col:col + 1] for d in train], {"u": ["u1"], "y": ["y"], "z": [tgt]}, None)
            r = _replay(m, work / f"three_tank_{tgt}_{_label(rule)}", {"u1": test.u[:, 0], "y": test.y[:, 0],
                                                                      f"{tgt}_true": test.z_true[:, col]}, win,
                        test.z_true[:, col], simulator, cache, say)
            recs.append({"system": "three-tank", "target": tgt, "breakpoints": _label(rule), "Mu": cfg.mu, "My": cfg.my, "p": cfg.p,
                         "N": (cfg.p + 1) ** (cfg.mu + cfg.my), **r})
    return {"bench": "breakpoints-hw", "run": 0, "rows": recs, "environment": br.environment(),
            "note": "float = the fitted sensor at the real inputs, bittrue = the fixed-point model at the quantised inputs, "
                    "hw = the Verilog's outputs (simulate); Lorenz: RMSEE vs noise-free z over 2000 test samples; three-tank: "
                    "RMSE vs the noise-free state over t >= 100 of the paper's run"}


def hardware_markdown(hw: dict) -> str:
    out = ["# Non-uniform vs uniform partitions through the RTL (`benchmarks/breakpoints_accuracy.py --hardware`)", "",
           f"Run 0; virtual-sensor tops, default formats, 12-bit input codes, replayed with `simulate` ({hw['rows'][0]['simulator']}). "
           + hw["note"] + ".", "",
           "| system | target | lags, p | N | partition | latency | weights | outputs | mismatches | RMSE float | RMSE bit-true | RMSE hw |",
           "|---|---|---|---:|---|---:|---|---:|---:|---:|---:|---:|"]
    for r in hw["rows"]:
        lags = (f"Mu = {r['Mu']}, " if r.get("Mu") else "") + f"My = {r['My']}, p = {r['p']}"
        e = r["rmse"]
        out.append(f"| {r['system']} | {r['target']} | {lags} | {r['N']} | {r['breakpoints']} | {r['latency_cycles']} | {r['weights']} | "
                   f"{r['outputs']} | {r['mismatches']} | {e['float']:.4g} | {e['bittrue']:.4g} | {e['hw']:.4g} |")
    syn = [r for r in hw["rows"] if r.get("ecp5")]
    if syn:
        out += ["", "ECP5 (`pwas-hdl synth` defaults: LFE5U-45F, timing harness, nextpnr seed 1), the Lorenz sensor tops:", "",
                "| partition | LUT4 | FF | carry | DSP | BRAM | fmax (MHz) | cycles |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
        out += [f"| {r['breakpoints']} | {r['ecp5']['luts']} | {r['ecp5']['ffs']} | {r['ecp5']['carry']} | {r['ecp5']['dsp']} | "
                f"{r['ecp5']['bram']} | {r['ecp5']['fmax_mhz']} | {r['ecp5']['latency_cycles']} |" for r in syn]
    return "\n".join(out) + "\n"


def _hardware_arguments(ap) -> None:
    """The options of the RTL replay mode (``--hardware``)."""
    g = ap.add_argument_group("hardware mode (the RTL replay of the two partitions; writes breakpoints_hw.json / .md)")
    g.add_argument("--hardware", action="store_true", help="replay the Lorenz sensors of both partitions through the RTL "
                   "instead of the accuracy bench")
    g.add_argument("--simulator", default="verilator", choices=("icarus", "verilator"), help="simulator of the replay")
    g.add_argument("--workdir", type=Path, default=None, help="folder of the generated designs (default: a new temporary one)")
    g.add_argument("--synth", action="store_true", help="also place and route the two Lorenz sensor tops on ECP5, once")


def _hardware_mode(a) -> bool:
    """Run the RTL replay when ``--hardware`` is given (not a pwas-hdl-bench-results document)."""
    if not a.hardware:
        return False
    import json
    from pwas_hdl.io.atomic import atomic_write_text

    with br.scratch_folder("pwas-bp-hw-", a.workdir) as work:
        hw = run_hardware(work, a.simulator, synth=a.synth)
    a.outdir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(a.outdir / "breakpoints_hw.json", json.dumps(hw, indent=1) + "\n")
    atomic_write_text(a.outdir / "breakpoints_hw.md", hardware_markdown(hw))
    print(hardware_markdown(hw))
    return True


def main(argv: Sequence[str] | None = None) -> None:  # pragma: no cover - script entry
    br.bench_main(argv, stem="breakpoints_accuracy", description=__doc__.splitlines()[0], run=run, markdown=markdown,
                  plot=plot, default_runs=3, add_arguments=_hardware_arguments, other_mode=_hardware_mode)


if __name__ == "__main__":  # pragma: no cover
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
