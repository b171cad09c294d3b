"""The argmax stage of the hardware classifier: bit-true function and Amaranth component.

The RTL (Amaranth simulation) must equal the bit-true compare tree exactly, and that must equal
numpy.argmax (ties to the lowest index) -- the software classifier's decision rule.
"""

from __future__ import annotations

import numpy as np
import pytest
from amaranth.hdl import ClockDomain, Elaboratable, Module

from pwas_hdl.errors import InputError
from pwas_hdl.fixedpoint.argmax import agreement, argmax_index, compare_levels, index_width, margins
from pwas_hdl.hdl.argmax import ArgmaxStage, argmax_latency
from pwas_hdl.hdl.simulate import run_stream
from pwas_hdl.fixedpoint.bitfields import pack


def tie_heavy_codes(m: int, c: int, width: int, seed: int) -> np.ndarray:
    """Signed codes with many exact ties (few distinct values) and the extreme codes."""
    rng = np.random.default_rng(seed)
    lo, hi = -(1 << (width - 1)), (1 << (width - 1)) - 1
    pool = np.array([lo, lo + 1, -1, 0, 1, hi - 1, hi])
    a = rng.choice(pool, (m // 2, c))
    b = rng.integers(lo, hi + 1, (m - m // 2, c))
    b[:, rng.integers(0, c)] = b.max(axis=1)  # a tie at the top in every row of this half
    return np.concatenate([a, b]).astype(np.int64)


@pytest.mark.parametrize("c", [1, 2, 3, 4, 5, 8, 9])
@pytest.mark.parametrize("select", ["max", "min"])
def test_bittrue_tree_is_numpy_arg(c, select):
    q = tie_heavy_codes(400, c, 6, seed=c)
    want = np.argmax(q, axis=1) if select == "max" else np.argmin(q, axis=1)
    assert np.array_equal(argmax_index(q, select), want)


def test_ties_go_to_lowest_index():
    q = np.array([[3, 3, 3, 3], [0, 5, 5, 1], [-2, -2, -3, -2], [1, 2, 3, 3]])
    assert argmax_index(q).tolist() == [0, 1, 0, 2]
    assert argmax_index(q, "min").tolist() == [0, 0, 2, 0]


def test_widths_and_levels():
    assert [index_width(c) for c in (1, 2, 3, 4, 5, 8, 9)] == [1, 1, 2, 2, 3, 3, 4]
    assert [compare_levels(c) for c in (1, 2, 3, 4, 5, 8, 9)] == [0, 1, 2, 2, 3, 3, 4]
    assert [argmax_latency(c, "min") for c in (2, 3, 4, 8)] == [0, 0, 0, 0]
    assert [argmax_latency(c, "balanced") for c in (2, 3, 4, 8)] == [1, 1, 1, 1]  # tree_levels = 3 (issue 14)
    assert [argmax_latency(c, "balanced") for c in (9, 16)] == [2, 2]
    assert [argmax_latency(c, "max") for c in (2, 3, 4, 8)] == [1, 2, 2, 3]
    assert argmax_latency(1, "max") == 0


def test_bad_input():
    with pytest.raises(InputError):
        argmax_index(np.zeros((3, 2)))  # floats are not output codes
    with pytest.raises(InputError):
        argmax_index(np.zeros(3, dtype=int))
    with pytest.raises(InputError):
        argmax_index(np.zeros((3, 2), dtype=int), "median")
    with pytest.raises(ValueError):
        ArgmaxStage(0, 8)


def test_agreement_bound():
    """Differences from the float decision only where the float margin is within 2 e."""
    rng = np.random.default_rng(1)
    s = rng.normal(0, 1, (2000, 3))
    lsb, e = 2.0 ** -4, 2.0 ** -5  # round to nearest: |code*lsb - s| <= lsb/2 = e
    codes = np.round(s / lsb).astype(np.int64)
    a = agreement(s, codes, e)
    assert a["samples"] == 2000 and a["differ_outside_margin"] == 0
    assert a["differ"] == a["differ_within_margin"] > 0  # this quantisation does flip some near ties
    assert np.all(margins(s) >= 0)


def test_agreement_margin_exactly_two_e_counts_as_near():
    """Hand-worked: scores 0 and 1, e = 1/2 (lsb 1/2, codes within e of the scores): the codes may both
    be 1 (0.5), a tie the hardware gives to class 0 while the float winner is class 1. The margin
    1 = 2 e is inside the documented "<= 2 e" region: within margin, never outside."""
    a = agreement(np.array([[0.0, 1.0], [1.0, 0.0]]), np.array([[1, 1], [2, 0]]), 0.5)
    assert a["margin_limit"] == 1.0 and a["near_ties"] == 2
    assert a["differ"] == 1 and a["differ_within_margin"] == 1 and a["differ_outside_margin"] == 0


class _Clocked(Elaboratable):
    """A stage with a sync domain even when it has no register (latency 0), for run_stream."""

    def __init__(self, stage):
        self.stage, self.out = stage, stage.out
        setattr(self, "in", getattr(stage, "in"))

    def elaborate(self, platform):
        m = Module()
        m.submodules.stage = self.stage
        m.domains.sync = ClockDomain("sync")
        return m


def _run(stage, q, extra, **kw):
    width, c = stage.width, stage.n_inputs
    words = [pack(row, width) | (int(x) << (c * width)) for row, x in zip(q, extra)]
    r = run_stream(_Clocked(stage), words, **kw)
    assert len(r.outputs) == len(q)
    return r, words


@pytest.mark.parametrize("c,width,pipe", [(3, 9, "balanced"), (4, 6, "max"), (4, 6, "min"), (2, 5, "max"),
                                          (5, 7, "balanced"), (8, 4, "max"), (1, 4, "balanced")])
def test_stage_matches_bittrue_with_stalls(c, width, pipe):
    stage = ArgmaxStage(c, width, extra_bits=1, pipeline=pipe)
    q = tie_heavy_codes(160, c, width, seed=c + width)
    extra = np.arange(len(q)) % 2
    r, words = _run(stage, q, extra, p_valid=0.7, p_ready=0.6, seed=c)
    idx = np.array([w >> stage.index_lsb for w in r.outputs])
    passed = [w & ((1 << stage.index_lsb) - 1) for w in r.outputs]
    assert passed == words  # scores and the extra bit come out unchanged, in order
    assert np.array_equal(idx, argmax_index(q))


@pytest.mark.parametrize("pipe", ["min", "balanced", "max"])
def test_stage_latency_and_ii(pipe):
    stage = ArgmaxStage(4, 6, pipeline=pipe)
    q = tie_heavy_codes(40, 4, 6, seed=2)
    r, _ = _run(stage, q, np.zeros(len(q), dtype=int))
    assert [p - a for p, a in zip(r.produced_at, r.accepted_at)] == [stage.latency] * len(q)
    assert r.accepted_at == list(range(r.accepted_at[0], r.accepted_at[0] + len(q)))


def test_stage_select_min_unsigned():
    stage = ArgmaxStage(3, 5, signed=False, select="min", pipeline="max")
    q = np.random.default_rng(3).integers(0, 32, (80, 3))
    r, _ = _run(stage, q, np.zeros(len(q), dtype=int), p_ready=0.5, seed=1)
    assert np.array_equal(np.array([w >> stage.index_lsb for w in r.outputs]), np.argmin(q, axis=1))


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.parametrize("c,width,pipe", [(3, 9, "balanced"), (8, 4, "max")])
def test_stage_verilog_lint_clean_and_deterministic(c, width, pipe, tmp_path):
    from pwas_hdl.hdl.emit import emit_verilog
    from test_hdl_verilog import VERILATOR, lint

    if VERILATOR is None:
        pytest.skip("verilator not installed")
    text = emit_verilog(ArgmaxStage(c, width, extra_bits=1, pipeline=pipe), "argmax_stage", ports="amaranth")
    assert text == emit_verilog(ArgmaxStage(c, width, extra_bits=1, pipeline=pipe), "argmax_stage", ports="amaranth")
    assert lint(text, "argmax_stage", tmp_path) == []
