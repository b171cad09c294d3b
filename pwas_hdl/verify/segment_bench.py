"""The Python side of the segment bench ``sim/pwas_recurrent_tb.py``, shared by the designs it replays.

The bench takes runs of *segments* (per segment: a reset, then packed input words in, packed
output words compared exactly with the expected ones; random bubbles and backpressure; latency
and II measured at full speed). Two designs are replayed through it, and what they share lives
here, once:

* the recurrent sensor top (issue 13): :mod:`pwas_hdl.verify.recurrent_replay` (API) and
  :mod:`pwas_hdl.verify.recurrent_simulation` (``pwas-hdl simulate``);
* seed 003's estimator (issue 12): :mod:`pwas_hdl.verify.estimator_simulation` (both).

Pieces: :func:`segment_job_ports` (the job's port names from a manifest), :func:`standard_segment_runs`
(the run plans), :func:`plan_job_runs` (plans of row ranges -> the job's runs of words, built once
per range), :func:`replay_segments` (``simulate``: one run of every trajectory through the bench,
in a temporary or waveform folder, every output checked to be there) and :func:`replay_summary`
(the summary's common parts: what was simulated, latency and II, times, testbench failures).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from pwas_hdl.errors import CheckFailed, InternalError

__all__ = ["TEST_MODULE", "segment_job_ports", "standard_segment_runs", "plan_job_runs", "count_outputs",
           "SegmentReplay", "replay_segments", "replay_summary", "rmse"]

#: The cocotb module of the segment bench.
TEST_MODULE = "pwas_recurrent_tb"


def segment_job_ports(manifest: dict, warm: bool = False) -> dict:
    """Port names of the bench's job, from the manifest's roles and reset polarity.

    Parameters
    ----------
    manifest : dict
        The design's manifest (``ports`` with roles, ``clock``, ``reset``).
    warm : bool
        The design has a warm-up port (``manifest["lags"]["warmup"]["port"]``; the recurrent
        top), added as ``"warm"``.

    Returns
    -------
    dict
        ``clock``, ``reset``, ``reset_on`` (1: active high), ``in_valid``, ``in_ready``, ``in_payload``,
        ``out_valid``, ``out_ready``, ``out_payload`` (and ``warm``): port names.
    """
    by_role = {p["role"]: p["name"] for p in manifest["ports"]}
    ports = {"clock": manifest["clock"]["port"], "reset": manifest["reset"]["port"],
             "reset_on": 1 if manifest["reset"]["polarity"] == "high" else 0,
             "in_valid": by_role["in.valid"], "in_ready": by_role["in.ready"], "in_payload": by_role["in.payload"],
             "out_valid": by_role["out.valid"], "out_ready": by_role["out.ready"], "out_payload": by_role["out.payload"]}
    if warm:
        ports["warm"] = manifest["lags"]["warmup"]["port"]
    return ports


def standard_segment_runs(n: int, seed: int = 0, stalls: tuple[float, float] = (0.7, 0.6), *,
                          record_reset_run: bool = False) -> list[dict]:
    """Run plans over ``n`` samples: full speed (latency and II checked), then random bubbles and
    backpressure (``stalls`` = p_valid, p_ready) with a reset after about a third of the samples,
    then the whole run again (its outputs recorded if ``record_reset_run``).

    Parameters
    ----------
    n : int
        Samples (rows) of the codes to replay.
    seed : int
        Seed of the full-speed run (the stall run uses ``seed + 1``).
    stalls : (float, float)
        ``p_valid``, ``p_ready`` of the stall run: per-cycle probabilities of input valid and output ready.
    record_reset_run : bool
        Record the outputs of the stall run's last segment too.

    Returns
    -------
    list of dict
        Two plans, ``"full-speed"`` and ``"stalls-reset"``: ``name``, ``p_valid``, ``p_ready``,
        ``seed``, ``segments`` (``rows`` = (start, stop), ``drain``, ``record``, ``hold`` in cycles).
    """
    cut = max(1, n // 3)
    last = {"rows": (0, n), "drain": True, "record": True} if record_reset_run else {"rows": (0, n), "drain": True}
    return [{"name": "full-speed", "p_valid": 1.0, "p_ready": 1.0, "seed": seed,
             "segments": [{"rows": (0, n), "drain": True, "record": True}]},
            {"name": "stalls-reset", "p_valid": stalls[0], "p_ready": stalls[1], "seed": seed + 1,
             "segments": [{"rows": (0, cut), "drain": False, "hold": 3}, last]}]


def plan_job_runs(plans: Sequence[dict], words: Callable[[int, int], tuple]) -> tuple[list[dict], dict]:
    """The job's runs of ``plans`` (segments of row ranges ``rows`` = (start, stop)).

    Parameters
    ----------
    plans : sequence of dict
        Run plans as :func:`standard_segment_runs` returns them (``name``, ``p_valid``, ``p_ready``,
        ``seed``, ``segments`` with ``rows`` = (start, stop) and optional ``drain`` (default true),
        ``hold`` (cycles, default 0), ``record`` (default false)).
    words : callable
        ``words(start, stop)`` returns ``(input words, expected output words, ...)`` (packed
        integers) of the codes of those rows from reset; called once per range.

    Returns
    -------
    runs : list of dict
        The job's ``"runs"``: per plan ``name``, ``p_valid``, ``p_ready``, ``seed`` and ``segments``
        (``words``, ``expected``, ``drain``, ``hold``, ``record``).
    cache : dict
        The results of ``words`` by range ``(start, stop)``.
    """
    cache: dict = {}
    runs = []
    for plan in plans:
        segs = []
        for seg in plan["segments"]:
            a, b = seg["rows"]
            if (a, b) not in cache:
                cache[(a, b)] = words(a, b)
            ins, outs = cache[(a, b)][:2]
            segs.append({"words": ins, "expected": outs, "drain": bool(seg.get("drain", True)), "hold": int(seg.get("hold", 0)),
                         "record": bool(seg.get("record", False))})
        runs.append({k: plan[k] for k in ("name", "p_valid", "p_ready", "seed")} | {"segments": segs})
    return runs, cache


def count_outputs(res: dict) -> None:
    """Add ``mismatches`` and ``outputs_compared`` (over every segment of every run) to the bench's result.

    Parameters
    ----------
    res : dict
        The bench's result (``runs`` of ``segments`` with ``mismatches``, ``outputs``, ``expected``
        counts); modified in place.
    """
    segs = [s for r in res.get("runs", []) for s in r["segments"]]
    res["mismatches"] = int(sum(s["mismatches"] for s in segs))
    res["outputs_compared"] = int(sum(min(s["outputs"], s["expected"]) for s in segs))


@dataclass
class SegmentReplay:
    """One ``simulate`` replay: the bench's raw result, its build, the runner module and the wall time (s).

    Attributes
    ----------
    raw : dict
        The bench's result (``pwas_runner.run_job``): ``runs`` of ``segments``, ``failures``,
        ``wall_s`` (simulator process, seconds), ``log``, ``waves``, ``passed``.
    build : pwas_runner.Build
        The simulator build used (``build_seconds``, ``reused``).
    runner : module
        The ``pwas_runner`` module (for ``tool_versions``).
    wall_s : float
        Seconds from the build to the end of the run.
    """

    raw: dict
    build: Any  # pwas_runner.Build
    runner: Any  # the pwas_runner module
    wall_s: float

    @property
    def segments(self) -> list[dict]:
        """The segments of the replay run as the bench returned them (``words``, ``latencies``, ``spacings``, ...)."""
        return self.raw["runs"][0]["segments"] if self.raw.get("runs") else []


def replay_segments(verilog_path: Path, top: str, segments: list[dict], *, ports: dict, latency: int, ii: int, warmup: int,
                    simulator: str, stall: float, seed: int, cache_dir: Any, waves: bool, output: str | Path,
                    outset: Any = None, files: dict | None = None, prefix: str) -> SegmentReplay:
    """``pwas-hdl simulate`` through the segment bench: one run ``"replay"`` of ``segments`` (one per
    trajectory: ``words``, ``expected``, ...), with ``p_valid = p_ready = 1 - stall``.

    The bench runs in a temporary folder (``prefix``), removed afterwards, or with ``waves`` in the
    staged folder of ``outset`` (a :class:`~pwas_hdl.io.atomic.OutputSet` to which
    :func:`~pwas_hdl.verify.simulation.waves_folder` of ``output`` was added) that becomes
    ``<output stem>_waves`` beside ``output`` when the caller commits ``outset`` (the run's
    ``raw["waves"]`` names the waveform there).

    Parameters
    ----------
    verilog_path : Path
        The design's Verilog.
    top : str
        Its top module.
    segments : list of dict
        One per trajectory: ``words`` (packed input words), ``expected`` (packed output words),
        ``drain``, ``hold`` (cycles), ``record`` (as the job's segments of :func:`plan_job_runs`).
    ports : dict
        The job's port names (:func:`segment_job_ports`).
    latency : int
        Latency in cycles from the input transfer to ``out.valid`` (checked when the output never stalls).
    ii : int
        Initiation interval in cycles (checked without stalls).
    warmup : int
        Input samples at the start of each segment that give no output (0: none).
    simulator : {"icarus", "verilator"}
        The simulator.
    stall : float
        Probability per cycle of a bubble on the input and of backpressure on the output
        (``p_valid = p_ready = 1 - stall``).
    seed : int
        Seed of the stall pattern.
    cache_dir : str or os.PathLike or None
        Where simulator builds are cached (None: the runner's default).
    waves : bool
        Record a waveform (needs ``outset``).
    output : str or Path
        The command's CSV output (the waveform folder is named after it).
    outset : OutputSet, optional
        The command's output set (only with ``waves``).
    files : dict, optional
        Run-time files of the design (name -> path, e.g. ``$readmemh`` hex files).
    prefix : str
        Name prefix of the temporary folder (and of the kept log).

    Returns
    -------
    SegmentReplay
        The bench's result; ``segments`` holds one replayed segment per entry of ``segments``.

    Raises
    ------
    CheckFailed
        The RTL did not produce every output.
    """
    from pwas_hdl.io.atomic import logs_kept, make_temp_dir
    from pwas_hdl.verify.simulation import sim_module

    p = 1.0 - stall
    job = {"ports": ports, "latency": latency, "ii": ii, "warmup": warmup, "clock_ns": 10.0, "reset_cycles": 2,
           "runs": [{"name": "replay", "p_valid": p, "p_ready": p, "seed": int(seed), "segments": segments}]}
    runner = sim_module("pwas_runner")
    t0 = time.perf_counter()
    b = runner.build(verilog_path, top, simulator, cache_dir=cache_dir, waves=waves)
    if waves:
        from pwas_hdl.verify.simulation import waves_folder, waves_path

        if outset is None:
            raise InternalError("replay_segments: waves needs the command's OutputSet")
        wd = outset.temp_dir(waves_folder(output)).resolve()  # replaced whole on commit, removed on discard
    else:
        wd = make_temp_dir(tempfile.gettempdir(), f"{prefix}-{simulator}")
    try:
        with logs_kept(wd, f"{prefix}-{simulator}"):  # both folders go on failure: the log is copied out
            raw = runner.run_job(b, job, wd, files=files, test_module=TEST_MODULE)
    finally:
        if not waves:
            shutil.rmtree(wd, ignore_errors=True)
    if waves and raw.get("waves"):
        raw["waves"] = waves_path(raw["waves"], wd, output)
    rep = SegmentReplay(raw, b, runner, time.perf_counter() - t0)
    rsegs = rep.segments
    if len(rsegs) != len(segments) or any(len(r["words"] or []) != len(s["expected"]) for r, s in zip(rsegs, segments)):
        raise CheckFailed("the RTL did not produce every output: " + "; ".join(raw.get("failures", [])[:3]))
    return rep


def replay_summary(rep: SegmentReplay, *, design: Any, kind: str, table: Any, simulator: str, engine: str, samples: int,
                   input_transfers: int, latency: int, ii: int, stall: float, ii_note: str,
                   process_seconds: bool = False) -> tuple[dict, dict]:
    """The common parts of a segment replay's ``simulate`` summary, as ``(head, tail)``.

    ``head``: design, design_hash, kind, outdir, data, simulator, engine, simulator_version,
    samples, input_transfers, trajectories. ``tail``: latency_cycles and ii (manifest and measured;
    ``ii_note`` says what the spacing is at full speed), stall, cycles, clock_ns, simulation_seconds,
    samples_per_second, (``process_seconds``: simulator_process_seconds), build_seconds, build_reused,
    total_seconds, testbench_failures, waves. The design's own entries go between them.

    Parameters
    ----------
    rep : SegmentReplay
        The replay (:func:`replay_segments`).
    design : object
        The loaded design: ``top``, ``manifest`` (``design_hash``), ``outdir``.
    kind : str
        The summary's ``kind`` (design kind).
    table : Table
        The replayed data (its ``path``).
    simulator, engine : str
        The simulator and the engine (``"cocotb"``), as the summary reports them.
    samples : int
        Samples with an output.
    input_transfers : int
        Input words sent (the recurrent top: the samples plus each trajectory's warm-up inputs).
    latency : int
        The manifest's latency, cycles.
    ii : int
        The manifest's initiation interval, cycles.
    stall : float
        The replay's stall probability per cycle (latency and II are measured only at 0).
    ii_note : str
        What the measured spacing means at full speed (the ``ii`` entry's ``note``).
    process_seconds : bool
        Also report ``simulator_process_seconds`` (default false).

    Returns
    -------
    head, tail : dict
        The entries listed above, in that order.
    """
    raw, rsegs = rep.raw, rep.segments
    lats = sorted({v for r in rsegs for v in r["latencies"]})
    gaps = sorted({v for r in rsegs for v in r["spacings"]})
    head = {"design": design.top, "design_hash": design.manifest.get("design_hash"), "kind": kind,
            "outdir": str(design.outdir), "data": str(table.path), "simulator": simulator, "engine": engine,
            "simulator_version": rep.runner.tool_versions(simulator),
            "samples": samples, "input_transfers": input_transfers, "trajectories": len(rsegs)}
    sim_s = float(raw.get("wall_s", 0.0))
    tail = {
        "latency_cycles": {"manifest": latency, "measured_min": lats[0] if lats else None,
                           "measured_max": lats[-1] if lats else None,
                           "note": "from the input transfer to out.valid" + ("" if stall == 0 else "; not checked with stalls")},
        "ii": {"manifest": ii, "measured": (gaps[0] if len(gaps) == 1 else None) if stall == 0 else None, "spacings": gaps,
               "note": ii_note if stall == 0 else "not measured with stalls (--stall > 0)"},
        "stall": stall, "cycles": int(rsegs[-1]["cycles"]) if rsegs else 0, "clock_ns": 10.0,
        "simulation_seconds": sim_s,
        "samples_per_second": samples / float(raw["wall_s"]) if raw.get("wall_s") else None,
        **({"simulator_process_seconds": sim_s} if process_seconds else {}),
        "build_seconds": float(rep.build.build_seconds), "build_reused": bool(rep.build.reused), "total_seconds": rep.wall_s,
        "testbench_failures": list(raw.get("failures", [])), "waves": raw.get("waves"),
    }
    if not raw.get("passed") and not tail["testbench_failures"]:
        tail["testbench_failures"] = ["the cocotb test failed (see the simulator log)"]
    return head, tail


def rmse(a: Any, b: Any) -> float | None:
    """Root mean square of ``a - b`` (same shapes), None when empty.

    Parameters
    ----------
    a, b : array_like of float, same shape
        Values in the same units.

    Returns
    -------
    float or None
        The RMS difference, the units of ``a``; None for empty arrays.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.sqrt(np.mean((a - b) ** 2))) if a.size else None
