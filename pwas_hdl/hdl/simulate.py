"""Run the generated components in Amaranth's own simulator (stream in, stream out).

Used by the tests; handy to locate a mismatch against the bit-true model without a Verilog tool.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from amaranth.sim import Simulator

# equal-width payload fields, element 0 in the LSBs (the one implementation: pwas_hdl.fixedpoint.bitfields)
from pwas_hdl.fixedpoint.bitfields import pack as pack_fields
from pwas_hdl.fixedpoint.bitfields import unpack as unpack_fields

__all__ = ["StreamRun", "run_stream", "pack_fields", "unpack_fields"]


@dataclass
class StreamRun:
    """Result of :func:`run_stream`."""

    outputs: list[int]  # output payload words, in order
    accepted_at: list[int]  # cycle of each input transfer
    produced_at: list[int]  # cycle of each output transfer
    cycles: int
    extra: dict


def run_stream(
    dut,
    words,
    *,
    seed: int = 0,
    p_valid: float = 1.0,
    p_ready: float = 1.0,
    max_cycles: int | None = None,
    reset_cycles: int = 2,
    watch: tuple[str, ...] = (),
    n_expected: int | None = None,
) -> StreamRun:
    """Feed ``words`` (input payload integers) to ``dut.in`` and collect ``dut.out``.

    ``p_valid`` / ``p_ready``: probability that the source offers a word / the sink accepts in a
    cycle (random bubbles and backpressure, seeded). A transfer happens in a cycle when valid and
    ready are both high before the clock edge that ends it. ``watch``: names of extra output
    attributes of ``dut`` sampled at every output transfer (returned in ``extra``).
    ``n_expected``: outputs to wait for (default: one per input word).
    """
    rng = np.random.default_rng(seed)
    words = [int(w) for w in words]
    limit = max_cycles or (len(words) * 8 + 200)
    inp = getattr(dut, "in")
    out = dut.out
    res = StreamRun([], [], [], 0, {k: [] for k in watch})
    expected = len(words) if n_expected is None else n_expected

    async def bench(ctx):
        for _ in range(reset_cycles):
            await ctx.tick()
        i = 0
        cyc = 0
        while cyc < limit and (i < len(words) or len(res.outputs) < expected):
            offer = i < len(words) and rng.random() < p_valid
            take = rng.random() < p_ready
            ctx.set(inp.valid, int(offer))
            if offer:
                ctx.set(inp.payload, words[i])
            ctx.set(out.ready, int(take))
            if offer and ctx.get(inp.ready):
                res.accepted_at.append(cyc)
                i += 1
            if take and ctx.get(out.valid):
                res.outputs.append(ctx.get(out.payload))
                res.produced_at.append(cyc)
                for k in watch:
                    res.extra[k].append(ctx.get(getattr(dut, k)))
            await ctx.tick()
            cyc += 1
        res.cycles = cyc

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    sim.run()
    return res
