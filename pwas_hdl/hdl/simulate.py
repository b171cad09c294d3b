"""Run the generated components in Amaranth's own simulator (stream in, stream out).

Used by the tests; handy to locate a mismatch against the bit-true model without a Verilog tool.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from amaranth.sim import Simulator

# equal-width payload fields, element 0 in the LSBs (the one implementation: pwas_hdl.fixedpoint.bitfields)
from pwas_hdl.fixedpoint.bitfields import pack as pack_fields
from pwas_hdl.fixedpoint.bitfields import unpack as unpack_fields

__all__ = ["StreamRun", "run_stream", "pack_fields", "unpack_fields"]


@dataclass
class StreamRun:
    """Result of :func:`run_stream`.

    Attributes
    ----------
    outputs : list of int
        Output payload words, in order.
    accepted_at : list of int
        Cycle of each input transfer (cycle 0: the first after the ``reset_cycles``).
    produced_at : list of int
        Cycle of each output transfer.
    cycles : int
        Cycles simulated after the ``reset_cycles``.
    extra : dict of str to list of int
        Per watched attribute, its value at each output transfer.
    """

    outputs: list[int]  # output payload words, in order
    accepted_at: list[int]  # cycle of each input transfer
    produced_at: list[int]  # cycle of each output transfer
    cycles: int
    extra: dict


def run_stream(
    dut: Any,
    words: Iterable[int],
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

    A transfer happens in a cycle when valid and ready are both high before the clock edge that
    ends it. The run stops when every word is taken and ``n_expected`` outputs have come, or after
    ``max_cycles`` cycles (no error: the result then has fewer outputs).

    Parameters
    ----------
    dut : amaranth.lib.wiring.Component
        A component with an input stream ``in`` and an output stream ``out``.
    words : iterable of int
        Input payload words, in order.
    seed : int
        Seed of the random bubbles and backpressure.
    p_valid, p_ready : float
        Probability that the source offers a word / the sink accepts in a cycle.
    max_cycles : int, optional
        Cycle limit after the ``reset_cycles``; default ``8 * len(words) + 200``.
    reset_cycles : int
        Idle clock cycles (valid and ready low) before the stream starts; the reset is not asserted.
    watch : tuple of str
        Names of extra attributes of ``dut`` (signals) sampled at every output transfer.
    n_expected : int, optional
        Outputs to wait for (default: one per input word).

    Returns
    -------
    StreamRun
        The outputs, the cycles of the transfers and the watched values.
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
