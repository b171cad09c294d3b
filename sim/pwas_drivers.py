"""Valid/ready stream drivers for cocotb 2.x (in the style of cocotbext-axi's stream source/sink).

A transfer happens in a clock cycle when ``valid`` and ``ready`` are both high before the rising
edge that ends it (``amaranth.lib.stream`` semantics). The drivers are *stepped* by one
:class:`CycleLoop` so that every cycle is handled in a fixed order, identically on Icarus and
Verilator (no reliance on which value a simulator shows right at a clock edge):

1. ``await FallingEdge(clk)``: the registers hold the values of this cycle; every driver writes
   its inputs for the coming rising edge (:meth:`drive`);
2. ``await ReadOnly()``: the combinational outputs (``in.ready`` depends on ``out.ready``) have
   settled; every driver samples and records what is transferred at the coming edge
   (:meth:`sample`).

Cycle ``c`` is the ``c``-th falling edge after the loop started; an input transferred in cycle ``c``
is visible in the first pipeline register in cycle ``c + 1``, so a design of latency ``L`` shows its
output with ``out.valid`` in cycle ``c + L`` (when the sink never stalls).

Random stalls: ``pause`` generators as in cocotbext-axi (``set_pause_generator``); an iterator of
booleans, True = pause this cycle (bubble on a source, backpressure on a sink).
"""

from __future__ import annotations

import itertools
import random
from collections import deque
from typing import Callable, Iterable, Iterator, Sequence

from cocotb.triggers import FallingEdge, ReadOnly

# payload words by the manifest's bit fields (lsb, width, signed): the package's one implementation
from pwas_hdl.fixedpoint.bitfields import pack_fields as pack
from pwas_hdl.fixedpoint.bitfields import unpack_fields as unpack

__all__ = [
    "random_pauses",
    "pack",
    "unpack",
    "StreamSource",
    "StreamSink",
    "CycleLoop",
]


def random_pauses(p_pause: float, seed: int) -> Iterator[bool]:
    """Endless iterator: True with probability ``p_pause`` (seeded, reproducible)."""
    if p_pause <= 0:
        return itertools.repeat(False)
    rng = random.Random(seed)
    return (rng.random() < p_pause for _ in itertools.count())


class StreamSource:
    """Offers queued payload words on ``valid``/``payload``; records the cycle of each transfer."""

    def __init__(self, valid, ready, payload):
        self.valid, self.ready, self.payload = valid, ready, payload
        self.queue: deque[int] = deque()
        self.pause: Iterator[bool] = itertools.repeat(False)
        self.enabled = True
        self.offering = False
        self.sent_at: list[int] = []
        self.valid.value = 0

    def set_pause_generator(self, gen: Iterable[bool] | None) -> None:
        self.pause = iter(gen) if gen is not None else itertools.repeat(False)

    def send(self, words: Iterable[int]) -> None:
        self.queue.extend(int(w) for w in words)

    def idle(self) -> bool:
        return not self.queue

    def drive(self, cycle: int) -> None:
        paused = next(self.pause)
        self.offering = bool(self.enabled and self.queue and not paused)
        self.valid.value = int(self.offering)
        if self.offering:
            self.payload.value = self.queue[0]

    def sample(self, cycle: int) -> None:
        if self.offering and int(self.ready.value):
            self.queue.popleft()
            self.sent_at.append(cycle)


class StreamSink:
    """Drives ``ready`` (with pauses); records the payload and cycle of every transfer."""

    def __init__(self, valid, ready, payload, watch: dict | None = None):
        self.valid, self.ready, self.payload = valid, ready, payload
        self.pause: Iterator[bool] = itertools.repeat(False)
        self.accepting = False
        self.enabled = True
        self.words: list[int] = []
        self.received_at: list[int] = []
        self.ready.value = 0

    def set_pause_generator(self, gen: Iterable[bool] | None) -> None:
        self.pause = iter(gen) if gen is not None else itertools.repeat(False)

    def drive(self, cycle: int) -> None:
        self.accepting = bool(self.enabled and not next(self.pause))
        self.ready.value = int(self.accepting)

    def sample(self, cycle: int) -> None:
        if self.accepting and int(self.valid.value):
            self.words.append(int(self.payload.value))
            self.received_at.append(cycle)

    def clear(self) -> None:
        self.words.clear()
        self.received_at.clear()


class CycleLoop:
    """Steps drivers once per clock cycle (falling edge: drive; read-only phase: sample).

    ``hooks``: extra callables ``f(cycle)`` run in the read-only phase after the drivers (monitors).
    """

    def __init__(self, clk, drivers: Sequence, hooks: Sequence[Callable[[int], None]] = ()):
        self.clk = clk
        self.drivers = list(drivers)
        self.hooks = list(hooks)
        self.cycle = 0

    async def step(self, before: Callable[[int], None] | None = None) -> int:
        """Run one cycle; ``before(cycle)`` may write other inputs (e.g. reset) in the drive phase."""
        await FallingEdge(self.clk)
        self.cycle += 1
        if before is not None:
            before(self.cycle)
        for d in self.drivers:
            d.drive(self.cycle)
        await ReadOnly()
        for d in self.drivers:
            d.sample(self.cycle)
        for h in self.hooks:
            h(self.cycle)
        return self.cycle

    async def run_until(self, done: Callable[[], bool], max_cycles: int) -> bool:
        """Step until ``done()`` or ``max_cycles`` more cycles; True when done."""
        for _ in range(max_cycles):
            if done():
                return True
            await self.step()
        return done()
