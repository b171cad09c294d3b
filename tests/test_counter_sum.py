"""Issue 14 (latency-first sum, hw14e): ``counter_sum``, the one sum's carry-save part as column counters.

In the ``short`` preset since hw14f (opt-in before): bit-exact against the bit-true model in Amaranth simulation with bubbles
and backpressure (n = 1..4, nz = 1..2, both roundings; n + 1 < 4 products: the plain one sum),
lint-clean, and refused without ``flat_sum``.
"""

from __future__ import annotations

import dataclasses

import pytest

from helpers.hdl_models import make_model
from pwas_hdl.hdl import build_core
from pwas_hdl.hdl.core import PWASCore
from pwas_hdl.hdl.params import PIPELINE_PRESETS, Pipeline
from test_hdl_core import assert_bittrue_with_stalls
from test_hdl_verilog import VERILATOR, assert_core_lint_clean

CSUM = dataclasses.replace(PIPELINE_PRESETS["short"], counter_sum=True)


@pytest.mark.parametrize("parts, nz, opts, counted", [
    ([7, 7, 7, 7], 2, {}, True),
    ([3, 2, 4], 1, {"rounding": "truncate"}, True),  # no rounding constant in the counters
    ([3, 1, 3, 2], 2, {"input_bits": 10}, True),
    ([2, 3], 1, {}, False),  # 3 products: the plain one sum
    ([5], 2, {}, False),
], ids=lambda v: v if isinstance(v, str) else None)
def test_counter_sum_matches_bittrue_with_stalls(parts, nz, opts, counted, monkeypatch):
    used = []
    orig = PWASCore._counter_sum
    monkeypatch.setattr(PWASCore, "_counter_sum", staticmethod(lambda *a: used.append(1) or orig(*a)))
    model = make_model(parts, seed=len(parts) * 5 + nz, nz=nz, **opts)
    dut = build_core(model, pipeline=CSUM)
    oor, _ = assert_bittrue_with_stalls(model, dut, 120, seed=7, stall_seed=8)
    assert oor.any() and not oor.all()
    assert bool(used) == counted


def test_counter_sum_option():
    # hw14f: in the short preset (with the floorplan of synth it measured 30.13 against 31.65 ns)
    assert PIPELINE_PRESETS["short"].to_dict()["counter_sum"] is True and CSUM == PIPELINE_PRESETS["short"]
    assert not any(p.counter_sum for k, p in PIPELINE_PRESETS.items() if k != "short")
    d = CSUM.to_dict()
    assert d["counter_sum"] is True and Pipeline.cast(d) == CSUM
    with pytest.raises(ValueError, match="counter_sum needs flat_sum"):
        Pipeline(counter_sum=True, tree_levels=0)


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.skipif(VERILATOR is None, reason="verilator not installed")
def test_counter_sum_lint_clean(tmp_path):
    assert_core_lint_clean(CSUM, (([7, 7, 7, 7], 2), ([3, 2, 4], 1)), tmp_path)
