"""Randomly drawn hardware configurations, each generated and replayed in a real simulator against
the bit-true model: the option space beyond the fixed configurations of the RTL tests.

Usage::

    python benchmarks/rtl_random_configs.py [--count 40] [--seed 0] [--simulator icarus|verilator]
                                            [--samples 300] [--quick] [--outdir benchmarks/results] [--stem NAME]
    python benchmarks/rtl_random_configs.py --named [--simulator verilator] [--first K] [--count N]

``--named`` replays the fixed configurations of the RTL tests instead of drawing
(``sim/pwas_designs.RTL_CONFIGS``, all of them unless ``--first`` / ``--count`` take a slice), with
the tests' stimulus (500 transfers, seed = length of the name): the tests replay every one on Icarus
and a cover of them on Verilator; this runs every one on the simulator chosen. Default stem
``rtl_named_configs`` (``_verilator`` added for Verilator).

Configuration ``i`` of seed ``s`` is drawn from ``numpy.random.default_rng([s, i])`` (the same pair
draws the same configuration on every machine and in every run): a core (n = 1..5) or a sensor top
(1..2 inputs with Mu = 0..3, 1..2 outputs with My = 1..3, n <= 6), p = 1..8 per dimension, 1..3
targets, sometimes a classifier (with forced ties) or an additive model, and ``generate`` options:
memory (banked / replicated / corner), a pipeline preset, a goal or a random pipeline (every
register and variant flag drawn; the documented dependencies kept: ``flat_sum`` without adder-tree
registers, ``counter_sum`` on ``flat_sum``, ``sort_late`` on ``mu_late``), input bits 6..16, input
fill and scale, rounding, narrow weights with saturation, narrow outputs, explicit fractions, the
serial architecture (its one memory: no ``memory`` option), Amaranth port names, ``$readmemh`` weights.

Each design is replayed as the RTL tests replay theirs (``pwas_hdl.verify.simulation.standard_runs``:
full speed, random bubbles and backpressure, a reset in the middle of a stream; stimulus of random
points, vertices, simplex faces, corners, out-of-domain and whole-range codes). Outcomes:

* ``pass``: every output equals the bit-true model, lies within the stated error bound, and the
  measured latency and II are the manifest's;
* ``refused``: ``generate`` refused the combination with an input error (its message is recorded:
  a refusal is a valid answer, but each one is listed so that a wrong one can be seen);
* ``FAIL``: the replay differs (the first failures are recorded);
* ``error``: anything else (an exception other than an input error: a bug).

The script exits with status 1 when any configuration is ``FAIL`` or ``error``. ``--quick`` draws
3 configurations of 150 samples (the CI smoke). Writes ``STEM.json`` and ``STEM.md`` (default stem
``rtl_random_configs``, ``_verilator`` added for Verilator, ``_quick`` for ``--quick``).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
import traceback
from pathlib import Path
from typing import Any

import numpy as np

from pwas_hdl.bench_results import default_outdir, scratch_folder

#: The pipeline flags a random pipeline draws (``pwas_hdl.hdl.params.Pipeline``), besides ``tree_levels``.
PIPELINE_FLAGS = ("split", "rank", "mem_out", "product", "addr", "mul_in", "offset", "bank", "mul_halves", "mu_late",
                  "flat_sum", "prune_sat", "raw_compare", "counter_sum", "late_select", "sort_late")
PRESETS = ("min", "short", "balanced", "max", "max-lut")
GOALS = ("latency", "balanced", "throughput")


def _random_pipeline(rng: np.random.Generator) -> dict:
    p: dict[str, Any] = {f: bool(rng.random() < 0.4) for f in PIPELINE_FLAGS}
    p["tree_levels"] = int(rng.integers(0, 4))
    if p["flat_sum"]:
        p["tree_levels"] = 0
    if p["counter_sum"] and not p["flat_sum"]:
        p["counter_sum"] = False
    if p["sort_late"] and not p["mu_late"]:
        p["sort_late"] = False
    return p


def draw_config(seed: int, index: int):
    """The ``index``-th random configuration of ``seed`` (a ``sim/pwas_designs.DesignConfig``)."""
    from pwas_hdl.verify.simulation import sim_module

    DesignConfig = sim_module("pwas_designs").DesignConfig
    rng = np.random.default_rng([seed, index])
    opts: dict[str, Any] = {}
    if rng.random() < 0.5:
        design = "core"
        n = int(rng.integers(1, 6))
        mu, my, nu, ny = 0, n, 0, 1
        parts: Any = [int(v) for v in rng.integers(1, 9, n)]
    else:
        design = "sensor"
        while True:
            nu, ny = int(rng.integers(0, 3)), int(rng.integers(1, 3))
            mu = int(rng.integers(1, 4)) if nu else 0
            my = int(rng.integers(1, 4))
            n = nu * mu + ny * my
            if n <= 6:
                break
        # the sensor top needs one p per signal (all lags of a signal share their domain and cells)
        from pwas_hdl.fit.regressors import LagStructure

        per_signal = [int(v) for v in rng.integers(1, 9, nu + ny)]
        parts = [per_signal[ch if kind == "u" else nu + ch]
                 for kind, ch, _lag in LagStructure(mu, my, nu if mu else 0, ny).signal_of_dimension()]
    nz = int(rng.integers(1, 4))
    classes: tuple = ()
    ties = False
    additive = None
    r = rng.random()
    if r < 0.12 and nz >= 2:
        classes = tuple(float(c) for c in range(nz))
        ties = bool(rng.random() < 0.5)
    elif r < 0.24 and n >= 2:
        additive = str(rng.choice(["pairs", "time"] + (["triples"] if n >= 3 else [])))
    which = rng.random()
    if which < 0.35:
        opts["pipeline"] = str(rng.choice(PRESETS))
    elif which < 0.55:
        opts["goal"] = str(rng.choice(GOALS))
    elif which < 0.9:
        opts["pipeline"] = _random_pipeline(rng)
    if rng.random() < 0.6:
        opts["memory"] = str(rng.choice(["banked", "replicated", "corner"]))
    opts["input_bits"] = int(rng.integers(6, 17))
    if rng.random() < 0.3:
        opts["input_fill"] = round(float(rng.uniform(0.6, 1.0)), 3)
    if rng.random() < 0.25:
        opts["input_scale"] = "exact"
    if rng.random() < 0.3:
        opts["rounding"] = "truncate"
    if rng.random() < 0.15:
        opts["weight_bits"], opts["overflow"] = int(rng.integers(6, 11)), "saturate"
    if rng.random() < 0.15:
        opts["output_bits"] = int(rng.integers(6, 12))
    if rng.random() < 0.15:
        opts["weight_frac"] = int(rng.integers(2, 12))
    if rng.random() < 0.15:
        opts["output_frac"] = int(rng.integers(0, 10))
    if rng.random() < 0.2:
        opts["architecture"] = "serial"
        opts.pop("memory", None)  # one memory of N words: --memory does not apply (refused)
    if rng.random() < 0.2:
        opts["ports"] = "amaranth"
    if rng.random() < 0.15:
        opts["memory_init"] = "readmemh"
    name = f"r{seed}-{index}-{design[0]}-n{n}-z{nz}"
    return DesignConfig(name, design, mu, my, nu, ny, parts, nz, opts, seed=int(rng.integers(0, 2**31)), classes=classes,
                        ties=ties, additive=additive)


def _describe(cfg) -> dict:
    return {"name": cfg.name, "design": cfg.design, "mu": cfg.mu, "my": cfg.my, "nu": cfg.nu, "ny": cfg.ny,
            "partitions": cfg.partitions, "nz": cfg.nz, "classes": list(cfg.classes), "ties": cfg.ties,
            "additive": cfg.additive, "options": cfg.options, "model_seed": cfg.seed}


def run_config(cfg, simulator: str, samples: int, root: Path, cache: Path, stimulus_seed: int | None = None) -> dict:
    """Generate and replay one configuration; the outcome record (see the module docstring). The
    stimulus seed is the model seed mod 1000 unless ``stimulus_seed`` is given."""
    from pwas_hdl.errors import InputError
    from pwas_hdl.verify.simulation import load_design, run_rtl, segment, sim_module, standard_runs

    stim = sim_module("pwas_stimulus")
    rec = _describe(cfg)
    t0 = time.perf_counter()
    try:
        cfg.generate(root / cfg.name)
    except (InputError, ValueError) as exc:
        rec.update(outcome="refused", message=str(exc), seconds=time.perf_counter() - t0)
        return rec
    except Exception as exc:  # a bug
        rec.update(outcome="error", stage="generate", message=f"{type(exc).__name__}: {exc}",
                   traceback=traceback.format_exc(limit=8), seconds=time.perf_counter() - t0)
        return rec
    try:
        d = load_design(root / cfg.name)
        seed = cfg.seed % 1000 if stimulus_seed is None else stimulus_seed
        codes = stim.design_codes(d, samples, seed=seed)
        runs = standard_runs(d, codes, seed=seed)
        res = run_rtl(d, runs, simulator, cache_dir=cache, work_dir=root / f"{cfg.name}-work", strict=False)
        man = d.manifest
        per_stream = len(segment(d, codes).src)
        checks = {
            "bit_exact": res.passed,
            "within_bound": bool(res.within_bound),
            "latency": set(int(v) for v in res.latencies) <= {int(man["latency_cycles"])},
            "ii": float(res.ii) == float(man["ii"]),
            "outputs_compared": res.outputs >= 2 * per_stream,
        }
        rec.update(outcome="pass" if all(checks.values()) else "FAIL", checks=checks, outputs=int(res.outputs),
                   mismatches=int(res.mismatches), latency=int(man["latency_cycles"]), ii=man["ii"],
                   failures=[str(f) for f in res.failures[:3]], seconds=time.perf_counter() - t0)
    except Exception as exc:  # noqa: BLE001 - a bug in the design, the bench or the model: recorded
        rec.update(outcome="error", stage="simulate", message=f"{type(exc).__name__}: {exc}",
                   traceback=traceback.format_exc(limit=8), seconds=time.perf_counter() - t0)
    return rec


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=None, help="configurations to draw (1..1000; default 40; --named: all from --first)")
    ap.add_argument("--named", action="store_true",
                    help="replay the RTL tests' fixed configurations (sim/pwas_designs.RTL_CONFIGS) instead of drawing")
    ap.add_argument("--seed", type=int, default=0, help="seed of the draw (>= 0; default 0)")
    ap.add_argument("--first", type=int, default=0, help="index of the first configuration (>= 0; default 0)")
    ap.add_argument("--simulator", default="icarus", choices=("icarus", "verilator"))
    ap.add_argument("--samples", type=int, default=None, help="input transfers per replay (20..100000; default 300, --named 500)")
    ap.add_argument("--quick", action="store_true", help="3 configurations of 150 samples (the CI smoke)")
    ap.add_argument("--outdir", type=Path, default=default_outdir())
    ap.add_argument("--stem", default=None, help="output file stem (default rtl_random_configs[_verilator][_quick], --named: rtl_named_configs[_verilator][_quick])")
    args = ap.parse_args(argv)
    from pwas_hdl.bench_results import check_count, check_stem
    from pwas_hdl.errors import InputError
    from pwas_hdl.io.atomic import OutputSet, check_output_path
    from pwas_hdl.verify.simulation import sim_module

    named = list(sim_module("pwas_designs").RTL_CONFIGS) if args.named else None
    if args.quick:
        args.count, args.samples = 3, 150
    if named is not None and args.first >= len(named):
        raise InputError(f"--first must be below {len(named)}, the number of named configurations, got {args.first}")
    if args.count is None:
        args.count = len(named) - args.first if named is not None else 40
    if args.samples is None:
        args.samples = 500 if named is not None else 300
    check_count("--count", args.count, 1000)
    if args.seed < 0 or args.first < 0:
        raise InputError("--seed and --first must be >= 0")
    if not 20 <= args.samples <= 100_000:
        raise InputError(f"--samples must be in 20..100000, got {args.samples}")
    stem = check_stem(args.stem or (("rtl_named_configs" if named is not None else "rtl_random_configs") + ("_verilator" if args.simulator == "verilator" else "")
                                    + ("_quick" if args.quick else "")))
    check_output_path(args.outdir, "--outdir", kind="folder").mkdir(parents=True, exist_ok=True)
    with OutputSet() as outs:
        jpath = outs.add(args.outdir / f"{stem}.json", "--outdir")
        mpath = outs.add(args.outdir / f"{stem}.md", "--outdir")
        with scratch_folder("pwas-rtl-random-") as root:
            cache = root / "cache"
            rows = []
            t0 = time.perf_counter()
            indices = range(args.first, args.first + args.count)
            if named is not None:
                indices = range(args.first, min(args.first + args.count, len(named)))
            for i in indices:
                if named is not None:
                    cfg = named[i]
                    rec = run_config(cfg, args.simulator, args.samples, root, cache, stimulus_seed=len(cfg.name))
                else:
                    cfg = draw_config(args.seed, i)
                    rec = run_config(cfg, args.simulator, args.samples, root, cache)
                rec["index"] = i
                rows.append(rec)
                extra = rec.get("message", "") if rec["outcome"] != "pass" else f"{rec['outputs']} outputs"
                print(f"[{i}] {cfg.name}: {rec['outcome']} ({rec['seconds']:.1f} s) {extra[:160]}", flush=True)
            counts = {k: sum(r["outcome"] == k for r in rows) for k in ("pass", "refused", "FAIL", "error")}
            result = {"configurations": "named" if named is not None else "random",
                      "seed": args.seed, "first": args.first, "count": len(rows), "simulator": args.simulator,
                      "samples": args.samples, "counts": counts, "seconds": time.perf_counter() - t0,
                      "machine": {"python": platform.python_version(), "processor": platform.processor() or platform.machine()},
                      "configs": rows}
            outs.write_text(jpath, json.dumps(result, indent=2) + "\n")
            outs.write_text(mpath, markdown(result))
    print(f"{counts['pass']} pass, {counts['refused']} refused, {counts['FAIL']} FAIL, {counts['error']} error; "
          f"wrote {jpath} and {mpath}")
    return 1 if counts["FAIL"] or counts["error"] else 0


def _options_text(options: dict) -> str:
    """The options of a configuration in a table cell: a random pipeline as its set flags and tree levels."""
    parts = []
    for k, v in options.items():
        if k == "pipeline" and isinstance(v, dict):
            on = [f for f in PIPELINE_FLAGS if v.get(f)]
            v = "{" + "+".join(on + [f"tree{v.get('tree_levels', 0)}"]) + "}"
        parts.append(f"{k}={v}")
    return ", ".join(parts)


def markdown(result: dict) -> str:
    """The Markdown report of a result dict."""
    c = result["counts"]
    named = result.get("configurations") == "named"
    title = "The RTL tests' fixed configurations" if named else "Random hardware configurations"
    how = "--named" if named else f"--seed {result['seed']}"
    md = [f"# {title} against the bit-true model", "",
          f"`benchmarks/rtl_random_configs.py {how} --first {result['first']} --count {result['count']} "
          f"--simulator {result['simulator']} --samples {result['samples']}`: {c['pass']} pass, {c['refused']} refused by "
          f"`generate`, {c['FAIL']} FAIL, {c['error']} error ({result['seconds']:.0f} s).", "",
          "| # | design | n (Mu, My, nu, ny) | p | nz | kind | options | outcome | detail |", "|---:|---|---|---|---:|---|---|---|---|"]
    for r in result["configs"]:
        kind = ("classifier" + (" (ties)" if r["ties"] else "")) if r["classes"] else (f"additive {r['additive']}" if r["additive"] else "plain")
        n = r["nu"] * r["mu"] + r["ny"] * r["my"]
        detail = (f"{r['outputs']} outputs, latency {r['latency']}, II {r['ii']}" if r["outcome"] == "pass"
                  else r.get("message", "; ".join(r.get("failures", [])) or json.dumps(r.get("checks"))))
        md.append(f"| {r['index']} | {r['design']} | {n} ({r['mu']}, {r['my']}, {r['nu']}, {r['ny']}) | {r['partitions']} | {r['nz']} | "
                  f"{kind} | {_options_text(r['options'])} | {r['outcome']} | {detail.replace('|', '/')[:300]} |")
    return "\n".join(md) + "\n"


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
