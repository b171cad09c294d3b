"""cocotb testbench of a generated PWAS design (core or virtual-sensor top), driven by its manifest.

Nothing about the design is hard-coded: the clock, reset and stream ports are found by their
``role`` in ``manifest.json`` (the reset's level by ``reset.polarity``), the input and output payloads are packed / unpacked with the bit
fields listed there, and the latency is the manifest's ``latency_cycles``.

The host side (:mod:`pwas_runner`, :mod:`pwas_hdl.verify.simulation`) writes a JSON *job* and points the
environment variable ``PWAS_TB_JOB`` at it::

    {"manifest": "/abs/manifest.json", "result": "result.json", "strict": true,
     "clock_ns": 10, "reset_cycles": 2, "debug": false, "probes": ["s_split_c0", ...],
     "runs": [{"name": "random-stalls", "p_valid": 0.7, "p_ready": 0.6, "seed": 3,
               "segments": [{"codes": [[..n_in codes..], ...],       # one row per input transfer
                             "expected": [[z0, .., oor], ...],      # one row per output
                             "src": [input index of each output],
                             "drain": true, "hold": 0}]}]}

Every segment starts with a synchronous reset. ``drain``: wait for all expected outputs (and a
few cycles more, to catch spurious ones); otherwise the next reset comes ``hold`` cycles after the
last input transfer, in the middle of the stream, and the outputs seen before it must be a prefix
of the expected ones. Checked: every output equals the bit-true model (exact, given as
``expected``), no output is missing or extra, ``out.valid`` is low right after a reset, ``warm``
(sensor top) is high exactly from the transfer that yields the first output, and -- when the sink
never stalls -- every latency equals ``latency_cycles`` and, with no source bubbles either, one
sample is accepted and one result produced every ``ii`` clocks (the manifest's ``ii``: 1, or
``n + 1`` for the serial architecture, whose warm-up transfers are not throttled).

The result file holds, per run and segment, the transfer cycles, the output codes, the mismatches
(sample, input codes, expected, actual) and, with ``debug``, the values of the named pipeline
registers while the first failing sample passes through the pipeline (re-run alone, no stalls)
and every word of the weight memories (``memories``: name -> depth). ``probe_output: k`` (with
``debug``) records them for output ``k`` of the first segment even when nothing differs (to check
the probe mapping itself).
With ``strict`` the test fails (AssertionError naming the first mismatch) after writing it.
"""

from __future__ import annotations

import json
import os
import time

import cocotb
from cocotb.clock import Clock

from pwas_drivers import CycleLoop, StreamSink, StreamSource, pack, random_pauses, unpack

from pwas_hdl.design.manifest import load_manifest

MAX_REPORTED = 20


def _load_job() -> dict:
    path = os.environ.get("PWAS_TB_JOB")
    if not path:
        raise RuntimeError("PWAS_TB_JOB is not set: run this testbench through pwas_runner / pwas_hdl.verify.simulation")
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def _port(man: dict, role: str) -> dict:
    for p in man["ports"]:
        if p["role"] == role:
            return p
    raise KeyError(f"the manifest has no port with role {role!r}")


def _handle(dut, name: str):
    return getattr(dut, name)


def _read(h) -> int | None:
    try:
        return int(h.value)
    except (ValueError, TypeError):  # X / Z bits
        return None


class Bench:
    def __init__(self, dut, job: dict, man: dict):
        self.dut, self.job, self.man = dut, job, man
        self.latency = int(man["latency_cycles"])
        self.ii = int(man["ii"])  # serial architecture: one sample every n + 1 clocks
        # the manifest is validated (pwas_hdl.design.manifest): a sensor design has lags.warmup, a core none
        warm = man["lags"]["warmup"] if man["design"] == "sensor" else None
        self.warmup = int(warm["samples_without_output"]) if warm else 0
        pin, pout = _port(man, "in.payload"), _port(man, "out.payload")
        self.in_fields = pin["fields"]
        self.out_fields = pout["fields"]  # targets then out_of_range, as listed
        self.clk = _handle(dut, man["clock"]["port"])
        self.rst = _handle(dut, man["reset"]["port"])
        # asserted / released levels of the reset port (AXI-Stream aresetn is active low)
        self.rst_on = 0 if man["reset"]["polarity"] == "low" else 1
        self.src = StreamSource(_handle(dut, _port(man, "in.valid")["name"]), _handle(dut, _port(man, "in.ready")["name"]),
                                _handle(dut, pin["name"]))
        self.out_valid = _handle(dut, _port(man, "out.valid")["name"])
        self.sink = StreamSink(self.out_valid, _handle(dut, _port(man, "out.ready")["name"]), _handle(dut, pout["name"]))
        self.warm = _handle(dut, warm["port"]) if warm else None
        self.warm_log: list[int] = []
        self.loop = CycleLoop(self.clk, [self.src, self.sink], hooks=[self._watch])
        self.rst.value = 1 - self.rst_on

    def _watch(self, cycle: int) -> None:
        if self.warm is not None and self.src.sent_at and self.src.sent_at[-1] == cycle:
            self.warm_log.append(_read(self.warm))

    async def reset(self, cycles: int) -> int | None:
        """Synchronous reset for ``cycles`` clock edges; returns out.valid in the cycle after it."""
        self.src.enabled = False
        self.sink.enabled = False  # nothing is transferred while rst is high
        for i in range(cycles):
            await self.loop.step(before=lambda c: setattr(self.rst, "value", self.rst_on))
        await self.loop.step(before=lambda c: setattr(self.rst, "value", 1 - self.rst_on))
        valid_after = _read(self.out_valid)
        self.src.enabled = True
        self.sink.enabled = True
        return valid_after

    def _limit(self, n_in: int, run: dict) -> int:
        pv, pr = max(float(run.get("p_valid", 1.0)), 0.05), max(float(run.get("p_ready", 1.0)), 0.05)
        return int(4 * (n_in * self.ii + self.latency + 8) / (pv * pr)) + 200  # ii: one sample per ii cycles

    async def segment(self, run: dict, seg: dict, ri: int, si: int, res: dict) -> None:
        codes, expected, srcidx = seg["codes"], seg["expected"], seg["src"]
        self.src.sent_at.clear()
        self.sink.clear()
        self.warm_log = []
        valid_after = await self.reset(int(self.job.get("reset_cycles", 2)))
        self.src.send(pack(row, self.in_fields) for row in codes)
        limit = self._limit(len(codes), run)
        ok = await self.loop.run_until(self.src.idle, limit)
        problems = []
        if not ok:
            problems.append(f"only {len(self.src.sent_at)} of {len(codes)} inputs were accepted in {limit} cycles (in.ready stuck low?)")
        if seg.get("drain", True):
            await self.loop.run_until(lambda: len(self.sink.words) >= len(expected), limit)
            for _ in range(self.latency + 3):  # anything more is spurious
                await self.loop.step()
        else:
            for _ in range(int(seg.get("hold", 0))):
                await self.loop.step()
        got = [unpack(w, self.out_fields) for w in self.sink.words]
        n_cmp = min(len(got), len(expected))
        mism = [i for i in range(n_cmp) if got[i] != expected[i]]
        if seg.get("drain", True):
            if len(got) != len(expected):
                problems.append(f"{len(got)} outputs for {len(expected)} expected")
        elif len(got) > len(expected):
            problems.append(f"{len(got)} outputs before the reset, more than the {len(expected)} inputs can give")
        if valid_after not in (0, None):
            problems.append("out.valid was high in the cycle after a reset")
        # latency of each output (from the transfer of the input that completed its regressor)
        acc = list(self.src.sent_at)
        lat = [self.sink.received_at[i] - acc[srcidx[i]] for i in range(n_cmp) if srcidx[i] < len(acc)]
        stall_free_sink = float(run.get("p_ready", 1.0)) >= 1.0
        if stall_free_sink and any(v != self.latency for v in lat):
            problems.append(f"latency {sorted(set(lat))} cycles, the manifest says {self.latency}")
        full_speed = stall_free_sink and float(run.get("p_valid", 1.0)) >= 1.0
        ii = self.ii
        # II > 1: the warm-up transfers (not throttled) are left out; every later one comes ii cycles apart
        core_acc = acc if ii == 1 else acc[self.warmup:]
        if full_speed and len(core_acc) > 1 and any(b - a != ii for a, b in zip(core_acc, core_acc[1:])):
            gaps = sorted({b - a for a, b in zip(core_acc, core_acc[1:])})
            problems.append(f"inputs were not accepted every {ii} cycle(s) (II = {ii}): gaps {gaps} between {len(core_acc)} transfers")
        rc = list(self.sink.received_at)
        if full_speed and len(rc) > 1 and any(b - a != ii for a, b in zip(rc, rc[1:])):
            gaps = sorted({b - a for a, b in zip(rc, rc[1:])})
            problems.append(f"outputs did not come every {ii} cycle(s): gaps {gaps} between {len(rc)} outputs")
        if self.warm is not None and self.warm_log:
            want = [int(i >= self.warmup) for i in range(len(self.warm_log))]
            if self.warm_log != want:
                k = next(i for i, (a, b) in enumerate(zip(self.warm_log, want)) if a != b)
                problems.append(f"warm = {self.warm_log[k]} at input transfer {k} after reset, expected {want[k]}")
        res.update(
            accepted=len(acc), outputs=len(got), expected=len(expected), accepted_at=acc, produced_at=rc,
            latencies=lat, got=got, mismatches=len(mism), problems=problems,
            first_mismatches=[
                {"run": run.get("name", ri), "segment": si, "output": i, "input": srcidx[i], "input_codes": codes[srcidx[i]],
                 "expected": expected[i], "actual": got[i]}
                for i in mism[:MAX_REPORTED]
            ],
        )

    async def probe(self, codes: list, last: int, names: list[str]) -> dict:
        """Re-run inputs ``codes[first..last]`` alone (no stalls) and record the pipeline registers
        ``names`` in the cycles after the last one is accepted (offset 1 .. latency)."""
        first = max(0, last - self.warmup)
        self.src.set_pause_generator(None)
        self.sink.set_pause_generator(None)
        self.src.sent_at.clear()
        self.sink.clear()
        await self.reset(int(self.job.get("reset_cycles", 2)))
        self.src.send(pack(row, self.in_fields) for row in codes[first : last + 1])
        await self.loop.run_until(self.src.idle, 10 * (last - first + 2) * self.ii)
        handles = {}
        for nm in names:
            try:
                handles[nm] = _handle(self.dut, nm)
            except AttributeError:
                pass
        rec = {nm: [None] for nm in handles}  # offset 0: the cycle of the transfer
        for _ in range(self.latency):
            await self.loop.step()
            for nm, h in handles.items():
                rec[nm].append(_read(h))
        return {"input": last, "accepted_at": self.src.sent_at[-1] if self.src.sent_at else None, "values": rec}

    def read_memories(self, memories: dict) -> dict:
        """Every word of the weight memories ``{name: depth}`` (None where unreadable)."""
        out = {}
        for name, depth in memories.items():
            try:
                mem = _handle(self.dut, name)
                out[name] = [_read(mem[i]) for i in range(int(depth))]
            except (AttributeError, IndexError, TypeError, KeyError) as exc:
                out[name] = f"not readable: {type(exc).__name__}"
        return out


@cocotb.test()
async def stream_replay(dut):
    """Replay the job's runs through the design, compare with the bit-true expectations."""
    job = _load_job()
    man = load_manifest(job["manifest"])  # validated: the bench reads keys without fallbacks
    bench = Bench(dut, job, man)
    cocotb.start_soon(Clock(bench.clk, float(job.get("clock_ns", 10)), unit="ns").start())
    result = {"top": man["top"], "latency_cycles": bench.latency, "runs": []}
    failures: list[str] = []

    def save():
        tmp = job["result"] + ".tmp"
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(result, f)
        os.replace(tmp, job["result"])

    for ri, run in enumerate(job["runs"]):
        t0 = time.perf_counter()
        c0 = bench.loop.cycle
        bench.src.set_pause_generator(random_pauses(1.0 - float(run.get("p_valid", 1.0)), int(run.get("seed", 0))))
        bench.sink.set_pause_generator(random_pauses(1.0 - float(run.get("p_ready", 1.0)), int(run.get("seed", 0)) + 7919))
        rr = {"name": run.get("name", str(ri)), "segments": []}
        for si, seg in enumerate(run["segments"]):
            sres: dict = {}
            await bench.segment(run, seg, ri, si, sres)
            rr["segments"].append(sres)
            for prob in sres["problems"]:
                failures.append(f"run {rr['name']!r} segment {si}: {prob}")
            if sres["mismatches"]:
                m = sres["first_mismatches"][0]
                failures.append(
                    f"run {rr['name']!r} segment {si}: {sres['mismatches']} output(s) differ from the bit-true model; first: "
                    f"output {m['output']} (input transfer {m['input']}, codes {m['input_codes']}): expected {m['expected']}, "
                    f"RTL gave {m['actual']} (fields {[f['name'] for f in bench.out_fields]})"
                )
                if job.get("debug") and "probe" not in rr:
                    rr["probe"] = {"segment": si, **(await bench.probe(seg["codes"], m["input"], list(job.get("probes", []))))}
                    if job.get("memories"):
                        rr["probe"]["memories"] = bench.read_memories(job["memories"])
            elif job.get("probe_output") is not None and "probe" not in rr and seg["src"]:
                # debug self-check: record the registers for one output even though it matched
                k = min(int(job["probe_output"]), len(seg["src"]) - 1)
                rr["probe"] = {"segment": si, **(await bench.probe(seg["codes"], seg["src"][k], list(job.get("probes", []))))}
                if job.get("memories"):
                    rr["probe"]["memories"] = bench.read_memories(job["memories"])
        rr["cycles"] = bench.loop.cycle - c0
        rr["wall_s"] = time.perf_counter() - t0
        result["runs"].append(rr)
        save()
    result["failures"] = failures
    save()
    if job.get("strict", True) and failures:
        raise AssertionError("; ".join(failures[:5]) + (f" (+{len(failures) - 5} more)" if len(failures) > 5 else ""))
