"""Speed of the bit-true recurrence (``RecurrentFixedPointModel``) and of ``explore`` of a recurrent sensor.

Usage::

    python benchmarks/recurrence_speed.py [--quick] [--samples 1500] [--outdir DIR] [--stem NAME]

1. Per sample: the straightforward loop (``RecurrentFixedPointModel._run_reference``: one
   ``evaluate`` of a one-row array and one ``FeedbackRequant.apply`` per sample, what ``run`` was)
   against ``run`` (``evaluate_one`` in Python integers) on one trajectory of ``--samples``
   samples of the Lorenz system (eq. 18), for sensors with ``My = 2``, ``p = 7``: ``Mz = 1`` on a
   uniform grid, ``Mz = 1`` with ``--breakpoints quantile-pow2`` (the warp in front), and ``Mz = 2``.
   Both results are compared bit for bit (``identical``).
2. Many trajectories (100 samples each): ``run_many`` in lockstep (one ``evaluate`` per time step
   over every trajectory) against one by one on ``run``'s path, for 1 .. 128 trajectories: where
   the lockstep starts to pay (``recurrence.LOCKSTEP_MIN``).
3. ``explore`` of the ``Mz = 1`` sensor on the trajectory (the default sweep, the README's example): wall seconds now, and with ``run_many`` (what explore calls) replaced by the
   reference loop on the first ``--before-points`` points (a whole sweep of the old loop takes minutes), per point.

Times are medians of ``--repeats`` runs (wall clock, ``time.perf_counter``; the machine may be
shared). Nothing asserts on times. Writes ``STEM.json`` and ``STEM.md`` (default stem
``recurrence_speed``, ``recurrence_speed_quick`` with ``--quick``: 300 samples, one repeat, 2
trajectory counts and a 12-point sweep).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from pwas_hdl.bench_results import check_stem, default_outdir, environment, write_json_and_markdown

#: Trajectory counts of part 2 (quick: the first and the lockstep threshold's neighbourhood).
COUNTS = (1, 4, 16, 32, 64, 128)
QUICK_COUNTS = (1, 8)
#: Samples of each trajectory of part 2.
MANY_SAMPLES = 100


def _median_seconds(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    times, res = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), res


def _same(a: dict, b: dict) -> bool:
    return all(a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k]) for k in ("out", "out_of_range", "fed_back", "regressor"))


def _sensors(train_y: np.ndarray, train_z: np.ndarray, quick: bool) -> dict:
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    cases = {"Mz=1": {"mz": 1}, "Mz=1 warped": {"mz": 1, "breakpoints": "quantile-pow2"}, "Mz=2": {"mz": 2}}
    if quick:
        cases = {k: cases[k] for k in ("Mz=1", "Mz=1 warped")}
    out = {}
    for label, kw in cases.items():
        s = PWASVirtualSensor(my=2, partitions=7, sigma=1e-3, output_names=["y"], target_names=["z"], **kw)
        out[label] = s.fit(None, train_y, train_z)
    return out


def run(samples: int, repeats: int, quick: bool, before_points: int, say: Callable[[str], None]) -> dict:
    """The three parts of the module notes; the JSON document."""
    from pwas_hdl.design.generate import fixed_point_model
    from pwas_hdl.design.recurrent import recurrent_model
    from pwas_hdl.fixedpoint.recurrence import LOCKSTEP_MIN, RecurrentFixedPointModel
    from pwas_hdl.flow.explore import explore
    from pwas_hdl.systems.lorenz import lorenz

    t_all = time.perf_counter()
    d = lorenz(2000 + samples + MANY_SAMPLES * 8, seed=0)
    y, z = d.y[:, 0], d.z[:, 0]
    sensors = _sensors(y[:2000], z[:2000], quick)
    test_y, test_z = y[2000:2000 + samples], z[2000:2000 + samples]

    per_sample = []
    for label, s in sensors.items():
        fxm = fixed_point_model(s)
        rm = recurrent_model(s, fxm)
        codes = rm.quantize_signals(None, test_y[:, None])
        t_ref, ref = _median_seconds(lambda: rm._run_reference(codes), repeats)
        t_new, new = _median_seconds(lambda: rm.run(codes), repeats)
        rows = int(new["out"].shape[0])
        rec = {"sensor": label, "n": int(fxm.n), "kind": type(fxm).__name__, "samples": rows,
               "reference_us_per_sample": 1e6 * t_ref / rows, "run_us_per_sample": 1e6 * t_new / rows,
               "speedup": t_ref / t_new, "identical": _same(new, ref)}
        per_sample.append(rec)
        say(f"{label}: reference {rec['reference_us_per_sample']:.1f} us/sample, run {rec['run_us_per_sample']:.1f} "
            f"us/sample ({rec['speedup']:.1f}x), identical: {rec['identical']}")

    s = sensors["Mz=1"]
    rm = recurrent_model(s, fixed_point_model(s))
    rng = np.random.default_rng(0)
    pool = y[2000:]
    many = []
    for k in (QUICK_COUNTS if quick else COUNTS):
        starts = rng.integers(0, len(pool) - MANY_SAMPLES, k)
        trajs = [rm.quantize_signals(None, pool[a:a + MANY_SAMPLES, None]) for a in starts]
        t_lock, lock = _median_seconds(lambda: rm.run_many(trajs, lockstep=True), repeats)
        t_one, one = _median_seconds(lambda: rm.run_many(trajs, lockstep=False), repeats)
        rows = sum(int(r["out"].shape[0]) for r in one)
        rec = {"trajectories": k, "samples": rows, "lockstep_us_per_sample": 1e6 * t_lock / rows,
               "one_by_one_us_per_sample": 1e6 * t_one / rows, "identical": all(_same(a, b) for a, b in zip(lock, one))}
        many.append(rec)
        say(f"{k} trajectories: lockstep {rec['lockstep_us_per_sample']:.1f} us/sample, one by one "
            f"{rec['one_by_one_us_per_sample']:.1f} us/sample, identical: {rec['identical']}")

    sweep: dict[str, Any] = {} if not quick else {"input_bits": [8, 12, 16], "weight_frac": [-2, 0], "output_frac": [-1, 1]}
    data = (None, test_y[:, None], test_z[:, None])
    t0 = time.perf_counter()
    res = explore(s, data, **sweep)
    t_after = time.perf_counter() - t0
    points = len(res["points"]) + len(res.get("refused", []))
    # before: the same sweep's first points with run replaced by the reference loop
    small = {"input_bits": [8, 12, 16][:max(1, min(before_points, 3))], "weight_frac": [res["sweep"]["default_weight_frac"]],
             "output_frac": [res["sweep"]["default_output_frac"]]}
    t0 = time.perf_counter()
    res_new_small = explore(s, data, **small)
    t_small_after = time.perf_counter() - t0
    fast_many = RecurrentFixedPointModel.run_many  # what explore calls: replaced by the reference loop

    def reference_many(self, codes, lockstep=None):
        return [self._run_reference(c) for c in codes]

    RecurrentFixedPointModel.run_many = reference_many  # type: ignore[method-assign]
    try:
        t0 = time.perf_counter()
        res_old_small = explore(s, data, **small)
        t_small_before = time.perf_counter() - t0
    finally:
        RecurrentFixedPointModel.run_many = fast_many  # type: ignore[method-assign]
    n_small = len(res_new_small["points"])
    same_points = res_new_small["points"] == res_old_small["points"]
    ex = {"samples": int(res["data"]["samples"]), "points": points, "evaluated": len(res["points"]),
          "refused": len(res.get("refused", [])),
          "sweep": {k: res["sweep"][k] for k in ("input_bits", "weight_frac", "output_frac")},
          "seconds": t_after, "seconds_per_point": t_after / max(len(res["points"]), 1),
          "before": {"points": n_small, "sweep": small, "seconds_reference_loop": t_small_before,
                     "seconds_now": t_small_after, "seconds_per_point_reference_loop": t_small_before / n_small,
                     "seconds_per_point_now": t_small_after / n_small, "identical_points": bool(same_points),
                     "estimated_whole_sweep_seconds_reference_loop": t_small_before / n_small * len(res["points"])}}
    say(f"explore ({points} points, {ex['samples']} samples): {t_after:.1f} s now; the reference loop "
        f"{ex['before']['seconds_per_point_reference_loop']:.2f} s a point against {ex['before']['seconds_per_point_now']:.3f} "
        f"(about {ex['before']['estimated_whole_sweep_seconds_reference_loop']:.0f} s for the sweep)")
    return {"benchmark": "recurrence_speed", "quick": quick, "samples": samples, "repeats": repeats,
            "lockstep_min": LOCKSTEP_MIN, "per_sample": per_sample, "many_trajectories": many, "explore": ex,
            "environment": environment(time.perf_counter() - t_all)}


def markdown(res: dict) -> str:
    """``STEM.md`` of a result document."""
    out = ["# Speed of the bit-true recurrence", "",
           f"`benchmarks/recurrence_speed.py{' --quick' if res['quick'] else ''}`: Lorenz (eq. 18) sensors with My = 2, "
           f"p = 7, default formats; median of {res['repeats']} run(s), wall clock on a shared machine. *Reference*: the "
           "loop `run` was (one `evaluate` of a one-row array a sample, `RecurrentFixedPointModel._run_reference`); *run*: "
           "`evaluate_one` in Python integers. *Identical*: out, out_of_range, fed_back and regressor equal bit for bit.", "",
           "| sensor | model | n | samples | reference us/sample | run us/sample | speed-up | identical |",
           "|---|---|---:|---:|---:|---:|---:|---|"]
    for r in res["per_sample"]:
        out.append(f"| {r['sensor']} | {r['kind']} | {r['n']} | {r['samples']} | {r['reference_us_per_sample']:.1f} | "
                   f"{r['run_us_per_sample']:.1f} | {r['speedup']:.1f}x | {r['identical']} |")
    out += ["", f"Many trajectories of {MANY_SAMPLES} samples (Mz = 1): `run_many` in lockstep (one `evaluate` a time step over "
            f"the trajectories still running) against one by one; `run_many` takes the lockstep from "
            f"{res['lockstep_min']} trajectories on.", "",
            "| trajectories | lockstep us/sample | one by one us/sample | identical |", "|---:|---:|---:|---|"]
    for r in res["many_trajectories"]:
        out.append(f"| {r['trajectories']} | {r['lockstep_us_per_sample']:.1f} | {r['one_by_one_us_per_sample']:.1f} | {r['identical']} |")
    ex, b = res["explore"], res["explore"]["before"]
    out += ["", f"`explore` of the Mz = 1 sensor on one trajectory of {ex['samples']} estimates: {ex['points']} format points "
            f"({ex['evaluated']} evaluated, {ex['refused']} refused; input bits {ex['sweep']['input_bits']}, weight fraction {ex['sweep']['weight_frac']}, output fraction "
            f"{ex['sweep']['output_frac']}) in **{ex['seconds']:.1f} s** ({ex['seconds_per_point']:.3f} s an evaluated point, everything "
            f"included). With the reference loop, {b['points']} of its points took {b['seconds_reference_loop']:.1f} s "
            f"({b['seconds_per_point_reference_loop']:.2f} s a point, now {b['seconds_per_point_now']:.3f}; points identical: "
            f"{b['identical_points']}): about {b['estimated_whole_sweep_seconds_reference_loop']:.0f} s for the whole sweep.", ""]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="300 samples, one repeat, a 12-point sweep (the CI smoke)")
    ap.add_argument("--samples", type=int, default=None, help="samples of the trajectory (50..100000; default 1500)")
    ap.add_argument("--repeats", type=int, default=None, help="timed runs of each measurement, median (1..20; default 3)")
    ap.add_argument("--before-points", type=int, default=3, help="points of the sweep timed with the reference loop (1..3)")
    ap.add_argument("--outdir", type=Path, default=default_outdir(), help="output folder")
    ap.add_argument("--stem", default=None, help="output file stem (default recurrence_speed[_quick])")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    from pwas_hdl.bench_results import checked_outdir, make_outdir
    from pwas_hdl.errors import InputError

    samples = args.samples if args.samples is not None else (300 if args.quick else 1500)
    repeats = args.repeats if args.repeats is not None else (1 if args.quick else 3)
    if not 50 <= samples <= 100_000:
        raise InputError(f"--samples must be in 50..100000, got {samples}")
    if not 1 <= repeats <= 20:
        raise InputError(f"--repeats must be in 1..20, got {repeats}")
    if not 1 <= args.before_points <= 3:
        raise InputError(f"--before-points must be in 1..3, got {args.before_points}")
    stem = check_stem(args.stem or ("recurrence_speed_quick" if args.quick else "recurrence_speed"))
    checked_outdir(args.outdir)
    res = run(samples, repeats, args.quick, args.before_points, say=lambda m: print(m, flush=True))
    make_outdir(args.outdir)
    write_json_and_markdown(args.outdir, stem, res, markdown(res))
    return 0


if __name__ == "__main__":
    from pwas_hdl.bench_results import script_main

    sys.exit(script_main(main))
