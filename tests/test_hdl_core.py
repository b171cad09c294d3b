"""PWAS core RTL (Amaranth simulation) against the bit-true model, bit for bit.

Covers n = 1..6, power-of-two and other partitions (p_j = 1 included), nz = 1..3, both memory
layouts, the pipeline presets, random bubbles and backpressure, exact latency, reset.
"""

from __future__ import annotations

import numpy as np
import pytest
from amaranth.hdl import ClockDomain, Module
from amaranth.sim import Simulator

from pwas_hdl.hdl import CoreParams, MemoryPlan, PWASCore, Pipeline, build_core
from pwas_hdl.hdl.simulate import pack_fields, run_stream, unpack_fields

from helpers.hdl_models import codes, make_model
from helpers.hdl_reference import reference_eval


def run_core(dut, params, q, **kw):
    b = params.in_width
    r = run_stream(dut, [pack_fields(row, b) for row in q], **kw)
    assert len(r.outputs) == len(q), f"{len(r.outputs)} outputs for {len(q)} inputs in {r.cycles} cycles"
    z = np.array([unpack_fields(w, params.out_width, params.nz) for w in r.outputs], dtype=np.int64)
    oor = np.array([(w >> (params.nz * params.out_width)) & 1 for w in r.outputs], dtype=bool)
    return z, oor, r


def assert_same(q, got, ref):
    bad = np.flatnonzero(np.any(got != ref, axis=1))
    assert bad.size == 0, f"{bad.size} mismatches; first: q={q[bad[0]].tolist()} rtl={got[bad[0]].tolist()} model={ref[bad[0]].tolist()}"


def assert_bittrue_with_stalls(model, dut, n: int, seed: int, stall_seed: int):
    """``n`` input codes (``seed``) through ``dut`` with bubbles and backpressure (valid 0.8, ready
    0.7, ``stall_seed``): every output and out-of-range flag equals the bit-true model's. Returns
    ``(oor, run)`` for further checks."""
    q = codes(model, n, seed=seed)
    z, oor, r = run_core(dut, dut.params, q, p_valid=0.8, p_ready=0.7, seed=stall_seed)
    ref, ref_oor = model.evaluate(q)
    assert_same(q, z, ref)
    assert np.array_equal(oor, ref_oor)
    return oor, r


CASES = [
    # (partitions, nz, memory, pipeline, model options)
    ([5], 1, "banked", "balanced", {}),
    ([1], 2, "banked", "min", {}),
    ([8], 1, "replicated", "max", {"input_fill": 1.0, "rounding": "truncate"}),
    ([7, 3], 2, "banked", "max", {}),
    ([4, 1], 1, "replicated", "balanced", {"input_bits": 8}),
    ([2, 3, 5], 3, "banked", "balanced", {"rounding": "truncate"}),
    ([1, 1, 1], 1, "banked", "min", {"input_bits": 8}),
    ([7, 7, 7, 7], 1, "banked", "balanced", {}),
    ([2, 1, 3, 4], 2, "replicated", "min", {"input_bits": 10}),
    ([2, 2, 2, 2, 2], 1, "banked", "max", {}),
    ([3, 1, 2, 4, 2], 1, "banked", "balanced", {"rounding": "truncate", "input_fill": 1.0}),
    ([1, 2, 1, 2, 1, 3], 2, "banked", "balanced", {"input_bits": 10}),
    ([2, 2, 2, 2, 2, 2], 1, "replicated", "max", {"input_bits": 8}),
    # issue 14: bit-field bank addresses (p + 1 = 4), the rotation from the cells' adder tree and mu
    # in the memory-read cycle (short)
    ([3, 3, 3, 3], 2, "banked", "short", {}),
    # hw14h: replicated + short: bit-field vertex addresses (p + 1 = 4, 8; p_0 = 5 only in the top
    # field), mu after the read; p = 2: strides not powers of two, the base + offset adders
    ([3, 3, 3, 3], 2, "replicated", "short", {}),
    ([5, 7, 3], 1, "replicated", "short", {"rounding": "truncate"}),
    ([1, 3], 2, "replicated", "short", {}),
    ([2, 3, 2], 1, "replicated", "short", {}),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"p{'x'.join(map(str, c[0]))}-z{c[1]}-{c[2]}-{c[3]}")
def test_core_matches_bittrue(case):
    parts, nz, mem, pipe, opts = case
    model = make_model(parts, seed=len(parts) * 10 + nz, nz=nz, **opts)
    dut = build_core(model, memory=mem, pipeline=pipe)
    oor, r = assert_bittrue_with_stalls(model, dut, 150, seed=3, stall_seed=5)
    assert not oor.all()
    assert oor.any() or opts.get("input_fill") == 1.0  # fill = 1 may cover every input code


def test_reference_eval_matches_bittrue():
    """The hand-written integer reference (used for configurations the model does not build)."""
    for parts, opts in [([7, 3, 5, 2], {}), ([8, 1, 2], {"rounding": "truncate", "input_fill": 1.0}), ([3], {"input_bits": 6})]:
        model = make_model(parts, seed=1, nz=2, **opts)
        q = codes(model, 2000, seed=1)
        ref, oor = model.evaluate(q)
        got, got_oor = reference_eval(CoreParams.from_model(model), q)
        assert_same(q, got, ref)
        assert np.array_equal(oor, got_oor)


@pytest.mark.parametrize(
    "fb, lo, sh, rnd",
    [
        ((0, 3, 1), (-5, 0, -8), 0, "half_up"),  # F_j = 0, lo_code = 0, no output shift
        ((2, 2, 4), (-128, 100, 120), 3, "truncate"),  # lo at the bottom, domain above the codes
        ((4, 1, 2), (-40, -3, 7), -2, "half_up"),  # output finer than the products
        ((6, 6, 6), (-100, -100, -100), 30, "half_up"),  # every bit shifted out
    ],
)
def test_core_odd_formats(fb, lo, sh, rnd):
    """Formats the default model never picks: F_j = 0, a domain that leaves the code range, sh <= 0."""
    rng = np.random.default_rng(7)
    parts = (3, 5, 2)
    n_v = int(np.prod([p + 1 for p in parts]))
    bw, fw = 9, 4
    fo = max(fb) + fw - sh
    p = CoreParams(parts, 8, lo, fb, bw, fw, 10, fo, rng.integers(-256, 256, (n_v, 2)), rnd)
    q = rng.integers(-128, 128, (200, 3))
    q[:60] = np.clip(np.array(lo) + rng.integers(0, 4, (60, 3)) * (1 << np.array(fb)), -128, 127)
    ref, ref_oor = reference_eval(p, q)
    for mem, pipe in (("banked", "balanced"), ("replicated", "min")):
        z, oor, _ = run_core(PWASCore(p, memory=mem, pipeline=pipe), p, q, seed=1, p_ready=0.8)
        assert_same(q, z, ref)
        assert np.array_equal(oor, ref_oor)


@pytest.mark.parametrize("pipe", ["min", "balanced", "max", Pipeline(split=True, rank=False, mem_out=True, product=False, tree_levels=1),
                                  Pipeline(split=False, rank=False, addr=False, mem_out=False, mul_in=True, product=True, tree_levels=0),
                                  "short", Pipeline(split=False, rank=True, addr=False, offset=True, bank=True, mem_out=False, product=False, tree_levels=0),
                                  Pipeline(split=True, rank=False, addr=True, offset=True, bank=False, tree_levels=2),
                                  Pipeline(mul_halves=True), "max-lut"])
def test_latency_exact_and_ii_1(pipe):
    """Without stalls one sample enters every clock and leaves exactly `latency` cycles later."""
    model = make_model([3, 2, 4, 1], seed=2, nz=2)
    dut = build_core(model, pipeline=pipe)
    q = codes(model, 40, seed=2)
    z, _, r = run_core(dut, dut.params, q)
    assert_same(q, z, model.evaluate(q)[0])
    assert r.accepted_at == list(range(r.accepted_at[0], r.accepted_at[0] + len(q)))  # II = 1
    assert {b - a for a, b in zip(r.accepted_at, r.produced_at)} == {dut.latency}
    assert dut.ii == 1
    assert dut.latency == Pipeline.cast(pipe).latency(4)


FLAT = Pipeline(rank=False, addr=False, mem_out=False, product=True, tree_levels=0, mu_late=True, flat_sum=True, prune_sat=True)


@pytest.mark.parametrize("parts, nz, opts", [([3, 2, 4, 1], 2, {}), ([7, 3], 1, {"rounding": "truncate"})])
def test_flat_sum_and_pruned_saturation_bit_exact(parts, nz, opts):
    """flat_sum (one modular sum, rounding constant included) and prune_sat (no saturation the
    weights cannot reach: these models' outputs never clip) against the bit-true model, with
    bubbles and backpressure."""
    model = make_model(parts, seed=7, nz=nz, **opts)
    dut = build_core(model, pipeline=FLAT)
    assert all(dut._sat_unreachable(z) for z in range(nz))
    oor, _ = assert_bittrue_with_stalls(model, dut, 120, seed=4, stall_seed=2)
    assert dut.latency == 3


def test_flat_sum_keeps_a_reachable_saturation():
    """Odd formats (sh < 0: the output is finer than the products, so large weights clip): the
    saturation stays, and the results are the model's."""
    rng = np.random.default_rng(7)
    parts, fb, lo = (3, 5, 2), (4, 1, 2), (-40, -3, 7)
    n_v = int(np.prod([p + 1 for p in parts]))
    p = CoreParams(parts, 8, lo, fb, 9, 4, 10, max(fb) + 4 + 2, rng.integers(-256, 256, (n_v, 2)), "half_up")
    dut = PWASCore(p, pipeline=FLAT)
    assert not any(dut._sat_unreachable(z) for z in range(2))
    q = rng.integers(-128, 128, (150, 3))
    z, oor, _ = run_core(dut, p, q, seed=1, p_ready=0.8)
    ref, ref_oor = reference_eval(p, q)
    assert_same(q, z, ref)
    assert (np.abs(ref) == 511).any() or (ref == -512).any()  # the saturation really acted
    assert np.array_equal(oor, ref_oor)


def test_flat_sum_options():
    with pytest.raises(ValueError, match="tree_levels = 0"):
        Pipeline(flat_sum=True)  # the default tree_levels = 3 has adder-tree registers
    d = FLAT.to_dict()
    assert d["flat_sum"] is True and d["prune_sat"] is True and Pipeline.cast(d) == FLAT
    assert "flat_sum" not in Pipeline().to_dict() and "prune_sat" not in Pipeline().to_dict()


def test_latency_formula():
    for n in range(1, 9):
        assert Pipeline.cast("min").latency(n) == 2
        levels = int(np.ceil(np.log2(n + 1)))
        assert Pipeline.cast("balanced").latency(n) == 6 + (levels + 2) // 3
        assert Pipeline.cast("max").latency(n) == 10 + levels
        assert Pipeline.cast("short").latency(n) == 3
        assert Pipeline.cast("max-lut").latency(n) == 11 + levels
        assert Pipeline() == Pipeline.cast("balanced") == Pipeline.cast(None)


def test_backpressure_holds_output():
    """While the sink refuses, out.payload / out.valid stay put and nothing is lost or repeated."""
    model = make_model([3, 3], seed=4, nz=1)
    dut = build_core(model, pipeline="balanced")
    q = codes(model, 100, seed=4)
    z, _, r = run_core(dut, dut.params, q, p_valid=1.0, p_ready=0.3, seed=9)
    assert_same(q, z, model.evaluate(q)[0])
    # the pipeline fills, then accepts only when the sink takes something
    assert r.cycles > len(q) * 2


def test_sync_reset_clears_valid():
    """A synchronous reset empties the pipeline (valid bits only); it then works normally."""
    model = make_model([2, 2], seed=5)
    dut = build_core(model, pipeline="balanced")
    b, ow = dut.params.in_width, dut.params.out_width
    top = Module()
    top.submodules.dut = dut
    top.domains.sync = cd = ClockDomain("sync")
    q = codes(model, 4, seed=5)
    seen = {}

    async def bench(ctx):
        inp = getattr(dut, "in")
        ctx.set(dut.out.ready, 0)
        ctx.set(inp.valid, 1)
        ctx.set(inp.payload, pack_fields(q[0], b))
        for _ in range(dut.latency + 3):
            await ctx.tick()
        seen["full"] = (ctx.get(dut.out.valid), ctx.get(inp.ready))
        ctx.set(inp.valid, 0)
        ctx.set(cd.rst, 1)
        await ctx.tick()
        ctx.set(cd.rst, 0)
        seen["after_reset"] = (ctx.get(dut.out.valid), ctx.get(inp.ready))
        ctx.set(dut.out.ready, 1)
        valid_seen = 0
        for _ in range(dut.latency + 2):  # nothing stale comes out
            valid_seen |= ctx.get(dut.out.valid)
            await ctx.tick()
        seen["stale"] = valid_seen
        ctx.set(inp.valid, 1)
        ctx.set(inp.payload, pack_fields(q[1], b))
        await ctx.tick()
        ctx.set(inp.valid, 0)
        for _ in range(dut.latency - 1):
            await ctx.tick()
        seen["out"] = (ctx.get(dut.out.valid), unpack_fields(ctx.get(dut.out.payload), ow, 1))

    sim = Simulator(top)
    sim.add_clock(1e-8, domain="sync")
    sim.add_testbench(bench)
    sim.run()
    assert seen["full"] == (1, 0)
    assert seen["after_reset"] == (0, 1)
    assert seen["stale"] == 0
    assert seen["out"] == (1, model.evaluate(q[1:2])[0][0].tolist())


def test_memory_plan_is_the_model_rom():
    for mem in ("banked", "replicated"):
        model = make_model([3, 4, 2], seed=6, nz=2, layout=mem)
        plan = MemoryPlan.build(CoreParams.from_model(model), mem)
        bw = model.weight_format.bits
        assert (plan.n_banks, plan.depth) == model.rom.shape[:2]
        for b in range(plan.n_banks):
            for a in range(plan.depth):
                word = plan.contents[b][a]
                assert unpack_fields(word, bw, 2) == model.rom[b, a].tolist()


def test_resource_numbers_lorenz_like():
    """Banked: ~N words (rows padded to a multiple of n+1); replicated: (n+1)*N."""
    p = CoreParams((7, 7, 7, 7), 12, (-1792,) * 4, (9,) * 4, 16, 10, 16, 8, np.zeros((8**4, 1), dtype=np.int64))
    banked = MemoryPlan.build(p, "banked")
    repl = MemoryPlan.build(p, "replicated")
    assert (banked.n_banks, banked.depth, banked.words) == (5, 1024, 5120)
    assert (repl.n_banks, repl.depth, repl.words) == (5, 4096, 20480)


def test_banked_addresses_are_bit_fields_where_aligned():
    """The rotation-free banked core (issue 14): bit fields when the strides are aligned powers of
    two (p + 1 = 8, 4 in the middle dimensions), per-bank adders otherwise (p = 2)."""

    def core(parts, pipe="balanced"):
        n_v = int(np.prod([q + 1 for q in parts]))
        p = CoreParams(tuple(parts), 12, (-1792,) * len(parts), (8,) * len(parts), 10, 4, 12, 4,
                       np.arange(n_v, dtype=np.int64)[:, None] % 300 - 150)
        c = PWASCore(p, pipeline=pipe)
        c._MustUse__silence = True  # only its address layout is looked at
        return c

    assert core([7, 7, 7, 7])._address_fields() == [(7, 3, 0), (4, 3, 1), (1, 3, 2), (0, 1, 3)]
    assert core([3, 3, 3, 3])._address_fields() == [(4, 2, 0), (2, 2, 1), (0, 2, 2)]  # 3 // 5 = 0: no last field
    assert core([2, 2, 2])._address_fields() is None  # strides 3 * row_words: adders
    assert Pipeline.cast(Pipeline(mu_late=True).to_dict()) == Pipeline(mu_late=True)
    assert Pipeline.cast("short").mu_late and not Pipeline.cast("balanced").mu_late
