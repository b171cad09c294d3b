"""cocotb testbench of the recurrent sensor top (:mod:`pwas_hdl.hdl.recurrent_top`), issue 13.

Driven by a JSON job (``PWAS_TB_JOB``, built by :mod:`pwas_hdl.verify.segment_bench` for the recurrent top's
replays and seed 003's estimator's)::

    {"result": "result.json" (in the run folder), "ports": {"clock", "reset", "reset_on", "in_valid", "in_ready",
     "in_payload", "out_valid", "out_ready", "out_payload", "warm"}, "latency": L, "ii": II, "warmup": W,
     "clock_ns": 10, "reset_cycles": 2,
     "runs": [{"name", "p_valid", "p_ready", "seed",
               "segments": [{"words": [packed input words], "expected": [packed output words],
                             "drain": true, "hold": 0, "record": false}]}]}

``record``: return the output words of the segment (``words``).

Every segment starts with a synchronous reset (so a segment with ``drain: false`` followed by
another one is a reset in the middle of a run). Checked: every output word equals the bit-true
recurrence's (exact), none missing or extra (a cut segment: a prefix), ``out.valid`` low after a
reset; with a sink that never stalls every latency equals ``L``; with no bubbles and no stalls the
samples after the warm-up are accepted exactly every ``II`` cycles (``in.ready`` low in between).
"""

from __future__ import annotations

import json
import os

import cocotb
from cocotb.clock import Clock

from pwas_drivers import CycleLoop, StreamSink, StreamSource, random_pauses

MAX_REPORTED = 10


@cocotb.test()
async def recurrent_replay(dut):
    with open(os.environ["PWAS_TB_JOB"], encoding="utf-8") as f:
        job = json.load(f)
    ports = job["ports"]
    h = {k: getattr(dut, v) for k, v in ports.items() if k not in ("reset_on",)}
    rst_on = int(ports["reset_on"])
    lat, ii, warmup = int(job["latency"]), int(job["ii"]), int(job["warmup"])
    cocotb.start_soon(Clock(h["clock"], float(job.get("clock_ns", 10)), unit="ns").start())
    src = StreamSource(h["in_valid"], h["in_ready"], h["in_payload"])
    sink = StreamSink(h["out_valid"], h["out_ready"], h["out_payload"])
    loop = CycleLoop(h["clock"], [src, sink])
    h["reset"].value = 1 - rst_on
    result = {"runs": []}
    failures: list[str] = []
    for run in job["runs"]:
        src.set_pause_generator(random_pauses(1.0 - float(run.get("p_valid", 1.0)), int(run.get("seed", 0))))
        sink.set_pause_generator(random_pauses(1.0 - float(run.get("p_ready", 1.0)), int(run.get("seed", 0)) + 7919))
        rr = {"name": run["name"], "segments": []}
        for si, seg in enumerate(run["segments"]):
            src.sent_at.clear()
            sink.clear()
            src.enabled = sink.enabled = False
            for _ in range(int(job.get("reset_cycles", 2))):
                await loop.step(before=lambda c: setattr(h["reset"], "value", rst_on))
            await loop.step(before=lambda c: setattr(h["reset"], "value", 1 - rst_on))
            valid_after = int(h["out_valid"].value)
            src.enabled = sink.enabled = True
            words, expected = seg["words"], seg["expected"]
            src.send(words)
            pv, pr = max(float(run.get("p_valid", 1.0)), 0.05), max(float(run.get("p_ready", 1.0)), 0.05)
            limit = int(4 * len(words) * (ii + 2) / (pv * pr)) + 200
            problems = []
            if not await loop.run_until(src.idle, limit):
                problems.append(f"only {len(src.sent_at)} of {len(words)} inputs accepted in {limit} cycles")
            if seg.get("drain", True):
                await loop.run_until(lambda: len(sink.words) >= len(expected), limit)
                for _ in range(lat + ii + 3):
                    await loop.step()
            else:
                for _ in range(int(seg.get("hold", 0))):
                    await loop.step()
            got = sink.words
            n = min(len(got), len(expected))
            mism = [i for i in range(n) if got[i] != expected[i]]
            if seg.get("drain", True) and len(got) != len(expected):
                problems.append(f"{len(got)} outputs for {len(expected)} expected")
            if len(got) > len(expected):
                problems.append(f"{len(got)} outputs, more than the {len(expected)} expected")
            if valid_after:
                problems.append("out.valid was high in the cycle after a reset")
            acc, rc = list(src.sent_at), list(sink.received_at)
            lats = [rc[i] - acc[i + warmup] for i in range(n) if i + warmup < len(acc)]
            if pr >= 1.0 and any(v != lat for v in lats):
                problems.append(f"latency {sorted(set(lats))} cycles, expected {lat}")
            gaps = [acc[i + 1] - acc[i] for i in range(warmup, len(acc) - 1)]
            if pr >= 1.0 and pv >= 1.0 and any(g != ii for g in gaps):
                problems.append(f"accepted-sample spacing {sorted(set(gaps))} cycles, expected II = {ii}")
            if gaps and min(gaps) < ii:
                problems.append(f"a sample was accepted {min(gaps)} cycles after the previous one (II = {ii}): in.ready high too early")
            rr["segments"].append({"accepted": len(acc), "outputs": len(got), "expected": len(expected), "mismatches": len(mism),
                                   "first_mismatches": [{"output": i, "expected": expected[i], "actual": got[i]} for i in mism[:MAX_REPORTED]],
                                   "latencies": sorted(set(lats)), "spacings": sorted(set(gaps)), "cycles": loop.cycle,
                                   "words": [int(w) for w in got] if seg.get("record", False) else None,
                                   "problems": problems})
            failures += [f"run {run['name']!r} segment {si}: {p}" for p in problems]
            if mism:
                failures.append(f"run {run['name']!r} segment {si}: {len(mism)} output(s) differ from the bit-true recurrence "
                                f"(first: output {mism[0]}, expected word {expected[mism[0]]}, RTL {got[mism[0]]})")
        result["runs"].append(rr)
    result["failures"] = failures
    with open(job["result"], "w", encoding="utf-8") as f:
        json.dump(result, f)
    if failures:
        raise AssertionError("; ".join(failures[:5]))
