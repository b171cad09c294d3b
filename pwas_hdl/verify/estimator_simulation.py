"""RTL replay of seed 003's estimator design (manifest design ``"estimator"``) on Icarus or Verilator.

A folder that ``pwas-hdl generate EST.json`` wrote (:mod:`pwas_hdl.design.estimator`) is replayed
by the segment bench ``sim/pwas_recurrent_tb.py`` (generic: per segment, a reset, then packed input
words in and packed output words compared exactly with the expected ones; random bubbles and
backpressure; latency and II measured at full speed), driven from the manifest: port names, reset
polarity, latency, II, the payload bit fields. The expected words come from the bit-true
estimator (:class:`~pwas_hdl.fixedpoint.observer_bank.FixedPointSwitchedEstimator`, rebuilt from
``estimator.json`` and ``generator.options``); the float column is the float estimator
(:func:`pwas_hdl.systems.switched_observer.run_switched_observer`) on the unquantised data.

:func:`replay_estimator` is the API for benches and tests (runs of segments of codes, including a
reset in mid-stream); :func:`simulate_estimator_data` is ``pwas-hdl simulate`` of an estimator
folder (called by :func:`pwas_hdl.verify.simulation.simulate_data`).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.io.atomic import logs_kept
from pwas_hdl.fixedpoint.bitfields import pack_fields, unpack_fields
from pwas_hdl.verify.simulation import ManifestView
from pwas_hdl.verify.segment_bench import (
    TEST_MODULE,
    count_outputs,
    plan_job_runs,
    replay_segments,
    replay_summary,
    rmse,
    segment_job_ports,
    standard_segment_runs,
)

__all__ = ["EstimatorDesign", "load_estimator_design", "estimator_job_ports", "expected_words", "replay_estimator",
           "standard_estimator_runs", "simulate_estimator_data"]


@dataclass
class EstimatorDesign(ManifestView):
    """A generated estimator folder: manifest, configuration, bit-true estimator, Verilog path
    (top, latency, ports and fields: :class:`~pwas_hdl.verify.simulation.ManifestView`).

    Attributes
    ----------
    outdir : Path
        The design folder.
    manifest : dict
        Its parsed ``manifest.json``.
    config : SwitchedEstimatorConfig
        The estimator configuration (``estimator.json``).
    est : FixedPointSwitchedEstimator
        The bit-true estimator rebuilt from ``config`` and ``generator.options``.
    verilog_path : Path
        The Verilog to simulate.
    """

    outdir: Path
    manifest: dict
    config: Any  # SwitchedEstimatorConfig
    est: Any  # FixedPointSwitchedEstimator
    verilog_path: Path

    @property
    def kind(self) -> str:
        """``"estimator"``."""
        return "estimator"

    @property
    def ii(self) -> int:
        """Initiation interval in cycles, the manifest's ``ii``."""
        return int(self.manifest["ii"])


def load_estimator_design(outdir: str | os.PathLike, manifest: dict | None = None,
                          verilog: str | os.PathLike | None = None) -> EstimatorDesign:
    """Read an estimator folder and rebuild its bit-true estimator (checked against the manifest's formats).

    Parameters
    ----------
    outdir : str or os.PathLike
        A folder written by ``pwas-hdl generate`` for an estimator file (design ``"estimator"``).
    manifest : dict, optional
        Its parsed ``manifest.json`` when already read (default: read and validated here).
    verilog : str or os.PathLike, optional
        Simulate this file instead of the folder's.

    Returns
    -------
    EstimatorDesign
        The manifest, the configuration, the rebuilt bit-true estimator and the Verilog path.

    Raises
    ------
    FileNotFoundError
        No manifest, configuration or Verilog.
    InputError
        The folder is not an estimator design, or was edited after ``generate`` (formats differ).
    """
    from pwas_hdl.design.estimator import ESTIMATOR_OPTIONS, fixed_point_estimator
    from pwas_hdl.design.manifest import load_manifest
    from pwas_hdl.fit.estimator_file import read_estimator

    out = Path(outdir)
    man = manifest if manifest is not None else load_manifest(out)
    if man["design"] != "estimator":
        raise InputError(f"{out}: the design is {man['design']!r}, not an estimator")
    cfg_path = out / man["files"]["model"]
    if not cfg_path.is_file():
        raise FileNotFoundError(f"{cfg_path} is missing; regenerate the folder with `pwas-hdl generate`")
    cfg = read_estimator(cfg_path)
    opts = man["generator"]["options"]
    est = fixed_point_estimator(cfg, **{k: opts.get(k) for k in ESTIMATOR_OPTIONS})
    want = man["estimator"]["formats"]
    mine = est.to_dict()["formats"]
    if json.dumps(mine, sort_keys=True) != json.dumps({k: want[k] for k in mine}, sort_keys=True):
        raise InputError(f"{out}: the estimator rebuilt from {cfg_path.name} has formats {mine}, the manifest says {want}; "
                         "the folder was modified after `pwas-hdl generate`: regenerate it")
    v = man["files"]["verilog"]
    vpath = Path(verilog) if verilog is not None else out / (v if isinstance(v, str) else v[0])
    if not vpath.is_file():
        raise FileNotFoundError(f"{vpath} is missing; regenerate the folder with `pwas-hdl generate`")
    return EstimatorDesign(out, man, cfg, est, vpath)


def estimator_job_ports(manifest: dict) -> dict:
    """Port names of the bench's job, from the manifest's roles and reset polarity (no ``warm``: no warm-up).

    Parameters
    ----------
    manifest : dict
        The estimator design's manifest.

    Returns
    -------
    dict
        As :func:`~pwas_hdl.verify.segment_bench.segment_job_ports`.
    """
    return segment_job_ports(manifest)


def _trace_rows(tr: dict) -> np.ndarray:
    """The bit-true trace as output-field rows (x_hat..., y_hat, mode index, state_saturated)."""
    return np.column_stack([tr["x_hat"], tr["y_hat"], tr["theta"] - 1, tr["state_saturated"].astype(np.int64)])


def expected_words(design: EstimatorDesign, codes: np.ndarray) -> tuple[list[int], list[int], dict]:
    """Packed input words, the expected packed output words and the bit-true trace of ``codes`` (T, 2) from reset.

    Parameters
    ----------
    design : EstimatorDesign
        The loaded design (:func:`load_estimator_design`).
    codes : ndarray of int, shape (T, 2)
        The u and y input codes (LSB) of ``T`` samples.

    Returns
    -------
    ins : list of int
        ``T`` packed input words.
    outs : list of int
        ``T`` expected packed output words.
    trace : dict
        The bit-true trace (:meth:`FixedPointSwitchedEstimator.trace`).
    """
    codes = np.asarray(codes, dtype=np.int64)
    tr = design.est.trace(codes)
    ins = [pack_fields([int(v) for v in row], design.in_fields) for row in codes]
    outs = [pack_fields([int(v) for v in row], design.out_fields) for row in _trace_rows(tr)]
    return ins, outs, tr


def standard_estimator_runs(n: int, seed: int = 0, stalls: tuple[float, float] = (0.7, 0.6)) -> list[dict]:
    """Run plans over ``n`` samples: full speed (latency and II checked), then random bubbles and
    backpressure with a reset after about a third of the samples, then the whole run again (recorded).

    Parameters
    ----------
    n : int
        Samples (rows) of the codes to replay.
    seed : int
        Seed of the full-speed run (the stall run uses ``seed + 1``).
    stalls : (float, float)
        ``p_valid``, ``p_ready`` of the stall run: per-cycle probabilities of input valid and output ready.

    Returns
    -------
    list of dict
        As :func:`~pwas_hdl.verify.segment_bench.standard_segment_runs` (``record_reset_run=True``).
    """
    return standard_segment_runs(n, seed, stalls, record_reset_run=True)


def _decode(design: EstimatorDesign, words: Sequence[int]) -> dict[str, np.ndarray]:
    n = design.est.n
    a = np.array([unpack_fields(w, design.out_fields) for w in words], dtype=np.int64).reshape(-1, n + 3)
    return {"x_hat": a[:, :n], "y_hat": a[:, n], "theta": a[:, n + 1] + 1, "state_saturated": a[:, n + 2].astype(bool)}


def replay_estimator(design: EstimatorDesign, codes: np.ndarray, simulator: str = "icarus", *, runs: Sequence[dict] | None = None,
                     cache_dir: str | os.PathLike | None = None, work_dir: str | os.PathLike | None = None,
                     waves: bool = False) -> dict:
    """Replay (u, y) codes (T, 2) through the RTL; every segment starts after a reset.

    Parameters
    ----------
    design : EstimatorDesign (:func:`load_estimator_design`)
    codes : ndarray (T, 2) of int
        :meth:`FixedPointSwitchedEstimator.quantize_signals` of the physical u, y (saturated:
        out-of-range inputs become the extreme codes).
    simulator : {"icarus", "verilator"}
    runs : list of dict, optional
        Plans as :func:`standard_estimator_runs` (segments give ``rows`` = (start, stop)).
    cache_dir : str or os.PathLike, optional
        Where simulator builds are cached (default: the runner's cache).
    work_dir : str or os.PathLike, optional
        Where the run's files go (default: a temporary folder, removed afterwards unless ``waves``).
    waves : bool
        Build the simulator with waveform tracing (the temporary ``work_dir`` is then kept).

    Returns
    -------
    dict
        The bench's result (``runs`` with per-segment outputs, mismatches, latencies, spacings;
        ``failures``), ``passed``, ``mismatches``, ``outputs_compared``, ``rtl`` (the decoded
        outputs of every recorded segment, by run name: list of dicts ``x_hat``, ``y_hat``,
        ``theta``, ``state_saturated``), ``latency`` / ``ii`` measured at full speed,
        ``build_s``, ``wall_s``, ``simulator``.
    """
    from pwas_hdl.verify.simulation import sim_module

    codes = np.asarray(codes, dtype=np.int64)
    plans = list(runs) if runs is not None else standard_estimator_runs(codes.shape[0])
    job: dict = {"ports": estimator_job_ports(design.manifest), "latency": design.latency, "ii": design.ii, "warmup": 0,
                 "clock_ns": 10.0, "reset_cycles": 2, "runs": []}
    job["runs"], _ = plan_job_runs(plans, lambda a, b: expected_words(design, codes[a:b]))
    runner = sim_module("pwas_runner")
    bld = runner.build(design.verilog_path, design.top, simulator, cache_dir=cache_dir, waves=waves)
    tmp = Path(tempfile.mkdtemp(prefix=f"pwas-est-{simulator}-")) if work_dir is None else Path(work_dir)
    try:
        with logs_kept(tmp if work_dir is None and not waves else None, f"pwas-est-{simulator}"):
            res = runner.run_job(bld, job, tmp, test_module=TEST_MODULE)
    finally:
        if work_dir is None and not waves:
            shutil.rmtree(tmp, ignore_errors=True)
    res["rtl"] = {}
    for plan, rr in zip(plans, res.get("runs", [])):
        res["rtl"][plan["name"]] = [_decode(design, s["words"]) if s.get("words") is not None else None for s in rr["segments"]]
    count_outputs(res)
    full = [s for p, r in zip(plans, res.get("runs", [])) if p["p_valid"] >= 1 and p["p_ready"] >= 1 for s in r["segments"]]
    res["latency"] = sorted({v for s in full for v in s["latencies"]})
    res["ii"] = sorted({v for s in full for v in s["spacings"]})
    res["build_s"] = bld.build_seconds
    res["simulator"] = simulator
    res["passed"] = bool(res.get("passed")) and not res.get("failures")
    return res


def simulate_estimator_data(outdir: str | os.PathLike, table: Any, output: str | os.PathLike, spath: Path, outset: Any,
                            *, simulator: str, engine: str, traj_col: str | None, stall: float, seed: int, cache_dir: Any, waves: bool,
                            say: Callable[[str], None]) -> dict:
    """``pwas-hdl simulate`` of an estimator folder (called by :func:`pwas_hdl.verify.simulation.simulate_data`).

    Each trajectory of ``table`` is one segment after a reset. Writes ``output`` (CSV, one row per
    sample: ``row``, ``mode_hat_hw``, ``mode_hat_bittrue``, ``mode_hat_float``, then per state
    ``<x>_hat_hw``, ``<x>_hat_bittrue``, ``<x>_hat_float``, the same for ``<y>_hat``,
    ``state_saturated``, ``mismatch``) and the JSON summary: mismatches, latency / II (manifest
    and measured), the modes that differ from the float detector and how many of them had a float
    margin above the bound ``2 dS``, the largest state and y_hat deviation from the float estimator
    over the samples whose modes agree, and with the reference columns in the data (``mode``,
    ``<x>_true`` or ``<x>``, ``<y>``) mode accuracy, state RMSE and output MSE of hw, bit-true and float.

    Parameters
    ----------
    outdir : str or os.PathLike
        The estimator folder (:func:`load_estimator_design`).
    table : Table
        The data (:func:`~pwas_hdl.io.csv_table.read_csv`; signals in physical units).
    output : str or os.PathLike
        The CSV to write.
    spath : Path
        The JSON summary to write.
    outset : OutputSet
        The command's :class:`~pwas_hdl.io.atomic.OutputSet` holding ``output``, ``spath`` (and
        the waveform folder); committed here.
    simulator : {"icarus", "verilator"}
        The simulator.
    engine : str
        Must be ``"cocotb"``.
    traj_col : str or None
        Column that numbers the trajectories (a reset between them); None: one trajectory.
    stall : float
        Probability per cycle of a bubble on the input and of backpressure on the output.
    seed : int
        Seed of the stall pattern.
    cache_dir : str or os.PathLike or None
        Where simulator builds are cached (None: the runner's default).
    waves : bool
        Record a waveform (in ``<output stem>_waves``).
    say : callable
        Called with one line of progress text.

    Returns
    -------
    dict
        ``summary`` (the JSON summary), ``summary_path``, ``output``, ``result`` (the bench's raw
        result), ``rows`` (data row per sample, shape ``(T,)``), ``estimates`` (hw state
        estimates, physical units, shape ``(T, nx)``), ``mode_hat`` (hw modes, ``(T,)``),
        ``y_hat`` (hw output estimates, ``(T,)``).

    Raises
    ------
    InputError
        ``--engine native`` (the estimator is replayed by the cocotb bench), a missing column.
    CheckFailed
        The RTL did not produce every output (nothing is written).
    """
    from pwas_hdl.fit.classifier import check_true_labels, class_scores
    from pwas_hdl.io.csv_table import check_trajectory_column, format_csv, split_trajectories
    from pwas_hdl.systems.switched_observer import run_switched_observer
    from pwas_hdl.limits import check_values
    from pwas_hdl.verify.simulation import _check_references, _checks, _json_default

    if engine != "cocotb":
        raise InputError("--engine native drives the PWAS designs only; simulate an estimator design with --engine cocotb")
    design = load_estimator_design(outdir)
    cfg, est = design.config, design.est
    u_all = table.numeric([cfg.input_name])[:, 0]
    y_all = table.numeric([cfg.output_name])[:, 0]
    # the state RMSE and output MSE square these: refused before the simulator runs, not as an overflow after it
    _check_references(table, cfg.state_names)
    check_values(f"{table.path}: column {cfg.output_name!r}", y_all, "fix the data (no output MSE can be measured against it)")
    check_trajectory_column(table, traj_col, [cfg.input_name, cfg.output_name], [*cfg.state_names, "mode"])
    slices = list(split_trajectories(table, traj_col))
    # the true mode (mode_true, else mode, as every reference column): a value that is no mode is refused, as a classifier's
    mode_ref = table.reference_column("mode")
    if mode_ref is not None:
        mode = table.numeric([mode_ref])[:, 0]
        check_true_labels(mode, list(range(1, cfg.n_modes + 1)), "mode", f"{table.path}: column {mode_ref!r}",
                          owner=f"the estimator's mode detector ({cfg.n_modes} modes)")
    segs, bts, fls, codes_all = [], [], [], []
    for sl in slices:
        u, y = u_all[sl], y_all[sl]
        codes = est.quantize_signals(u, y)
        ins, outs, tr = expected_words(design, codes)
        segs.append({"words": ins, "expected": outs, "drain": True, "hold": 0, "record": True})
        bts.append(tr)
        fls.append(run_switched_observer(u, y, K=cfg.K, window=cfg.window, A=cfg.A, B=cfg.B, C=cfg.C))
        codes_all.append(codes)
    n = int(sum(len(s["expected"]) for s in segs))
    say(f"simulating {n} samples of {table.path} through the estimator {design.top} on {simulator} (cocotb) ...")
    rep = replay_segments(design.verilog_path, design.top, segs, ports=estimator_job_ports(design.manifest),
                          latency=design.latency, ii=design.ii, warmup=0, simulator=simulator, stall=stall, seed=seed,
                          cache_dir=cache_dir, waves=waves, output=output, outset=outset, prefix="pwas-esim")
    raw, rsegs = rep.raw, rep.segments
    hw = [_decode(design, r["words"]) for r in rsegs]
    cat = lambda key, src: np.concatenate([d[key] for d in src])  # noqa: E731
    th_hw, th_bt = cat("theta", hw), cat("theta", bts)
    x_hw, x_bt = cat("x_hat", hw), cat("x_hat", bts)
    y_hw, y_bt = cat("y_hat", hw), cat("y_hat", bts)
    sat_hw, sat_bt = cat("state_saturated", hw), cat("state_saturated", bts)
    th_fl = np.concatenate([f.theta_hat for f in fls])
    x_fl = np.concatenate([f.x_hat for f in fls])
    y_fl = np.concatenate([f.y_hat for f in fls])
    mism = (th_hw != th_bt) | (y_hw != y_bt) | np.any(x_hw != x_bt, axis=1) | (sat_hw != sat_bt)
    fs = est.state_frac
    xs_hw, xs_bt = x_hw * 2.0**-fs, x_bt * 2.0**-fs
    ys_hw, ys_bt = y_hw * 2.0**-fs, y_bt * 2.0**-fs
    rows = np.concatenate([np.arange(sl.start, sl.stop) for sl in slices])
    cols: dict[str, Any] = {"row": rows, "mode_hat_hw": th_hw, "mode_hat_bittrue": th_bt, "mode_hat_float": th_fl}
    for i, nm in enumerate(cfg.state_names):
        cols[f"{nm}_hat_hw"], cols[f"{nm}_hat_bittrue"], cols[f"{nm}_hat_float"] = xs_hw[:, i], xs_bt[:, i], x_fl[:, i]
    yn = cfg.output_name
    cols[f"{yn}_hat_hw"], cols[f"{yn}_hat_bittrue"], cols[f"{yn}_hat_float"] = ys_hw, ys_bt, y_fl
    cols["state_saturated"] = sat_hw
    cols["mismatch"] = mism
    # the bound's reference: the float estimator at the represented signals (per trajectory)
    refs = [est.reference(c) for c in codes_all]
    th_ref = np.concatenate([r.theta_hat for r in refs])
    ws = np.sort(np.concatenate([r.residuals for r in refs]), axis=1)
    margin = ws[:, 1] - ws[:, 0]
    differ = th_hw != th_ref
    eb = design.manifest["estimator"]["error_bound"]
    beyond = int(np.sum(differ & (margin > 2 * eb["window_sum"])))
    # state / y_hat bound: on trajectories whose whole mode sequence equals the float one and never saturates
    same = np.concatenate([np.full(len(r.theta_hat), bool(np.all(h["theta"] == r.theta_hat) and not np.any(h["state_saturated"])))
                           for h, r in zip(hw, refs)])
    x_ref = np.concatenate([r.x_hat for r in refs])
    y_ref = np.concatenate([r.y_hat for r in refs])
    dx = float(np.max(np.abs(xs_hw[same] - x_ref[same]), initial=0.0))
    dy = float(np.max(np.abs(ys_hw[same] - y_ref[same]), initial=0.0))
    # no state bound when max_i ||A_i - K_i C_i||_inf >= 1 (FixedPointSwitchedEstimator): only the modes are checked then
    within = beyond == 0 and (eb["state"] is None or (dx <= eb["state"] and dy <= eb["y_hat"]))
    metrics: dict[str, Any] = {}
    if mode_ref is not None:
        for st, th in (("hw", th_hw), ("bittrue", th_bt), ("float", th_fl)):
            metrics[f"mode_accuracy_{st}"] = float(class_scores(mode, th.astype(float), sorted(set(mode.tolist())))["accuracy"])
        metrics["mode_reference_column"] = mode_ref
    for i, nm in enumerate(cfg.state_names):
        ref = table.reference_column(nm)
        if ref is not None:
            xt = table.numeric([ref])[:, 0]
            for st, v in (("hw", xs_hw[:, i]), ("bittrue", xs_bt[:, i]), ("float", x_fl[:, i])):
                metrics[f"{nm}_rmse_{st}"] = rmse(v, xt)
            metrics[f"{nm}_reference_column"] = ref
    for st, v in (("hw", ys_hw), ("bittrue", ys_bt), ("float", y_fl)):
        metrics[f"{yn}_mse_{st}"] = float(np.mean((y_all - v) ** 2))
    lsb = 2.0**-fs
    first = None
    if mism.any():
        k = int(np.flatnonzero(mism)[0])
        first = {"row": int(rows[k]), "expected": [int(th_bt[k]), int(y_bt[k]), *x_bt[k].tolist()],
                 "actual": [int(th_hw[k]), int(y_hw[k]), *x_hw[k].tolist()], "order": "mode, y_hat, x_hat codes"}
    head, tail = replay_summary(rep, design=design, kind="estimator", table=table, simulator=simulator, engine=engine,
                                samples=n, input_transfers=n, latency=design.latency, ii=design.ii, stall=stall,
                                ii_note="cycles between accepted samples at full speed")
    summary = {
        **head,
        "mismatches": int(mism.sum()), "first_mismatch": first,
        "state_saturated": int(sat_hw.sum()),
        "output_lsb": lsb,
        "error_bound": eb["state"], "error_bound_lsb": eb["state"] / lsb if eb["state"] is not None else None,
        "error_bound_note": ("state estimate against the float estimator at the represented signals, on trajectories whose "
                             "detected modes all equal the float detector's and no state saturates; modes may differ only "
                             "where the float margin is <= 2 * window_sum bound"),
        "within_error_bound": bool(within),
        "max_error_vs_float": dx, "max_error_vs_float_lsb": dx / lsb,
        "y_hat_max_error_vs_float": dy, "y_hat_error_bound": eb["y_hat"],
        "samples_with_same_modes": int(same.sum()),
        "modes": {"differ_from_float": int(differ.sum()), "differ_beyond_bound": beyond,
                  "margin_bound": 2 * float(eb["window_sum"])},
        "metrics": metrics,
        **tail,
    }
    summary["checks"] = _checks(summary, stall)
    if beyond:
        summary["checks"]["passed"] = False
        summary["checks"]["failures"].append(f"{beyond} detected mode(s) differ from the float detector where its margin exceeds the bound")
    outset.write_text(output, format_csv(cols))
    outset.write_text(spath, json.dumps(summary, indent=2, allow_nan=False, default=_json_default) + "\n")
    outset.commit()
    return {"summary": summary, "summary_path": str(spath), "output": str(output), "result": raw, "rows": rows,
            "estimates": xs_hw, "mode_hat": th_hw, "y_hat": ys_hw}
