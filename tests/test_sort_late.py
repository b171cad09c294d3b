"""Issue 14 (hw14g): ``sort_late``, the one-hot sort of the fractions moved into the memory-read cycle.

Opt-in (no preset; measured in benchmarks/results/hw_tables_latency_experiments.md, hw14g). The
fractions in dimension order and the comparison bits go through the memory register instead of the
sorted fractions; ``d_(k)`` and ``mu`` are made after it. Bit-exact against the bit-true model in
Amaranth simulation with bubbles and backpressure (n = 1..4, nz = 1..2), no sort tables left in the
front's cycle, lint-clean and deterministic.
"""

from __future__ import annotations

import dataclasses

import pytest

from helpers.hdl_models import make_model
from pwas_hdl.hdl import build_core
from pwas_hdl.hdl.emit import emit_verilog
from pwas_hdl.hdl.params import PIPELINE_PRESETS, Pipeline
from test_hdl_core import assert_bittrue_with_stalls
from test_hdl_verilog import VERILATOR, assert_core_lint_clean

SL = dataclasses.replace(PIPELINE_PRESETS["short"], sort_late=True)


@pytest.mark.parametrize("parts, nz, opts", [
    ([3, 3, 3, 3], 1, {}),
    ([3, 3, 3], 2, {}),
    ([3, 3], 2, {"input_bits": 10}),
    ([5], 1, {}),  # n = 1: no comparison bits, nothing to sort
])
def test_sort_late_matches_bittrue_with_stalls(parts, nz, opts):
    model = make_model(parts, seed=len(parts) * 5 + nz, nz=nz, **opts)
    dut = build_core(model, pipeline=SL)
    assert dut.latency == PIPELINE_PRESETS["short"].latency(len(parts))  # no register added
    oor, _ = assert_bittrue_with_stalls(model, dut, 60, seed=7, stall_seed=8)


def test_sort_late_option_and_registers():
    d = SL.to_dict()
    assert d["sort_late"] is True and Pipeline.cast(d) == SL
    assert "sort_late" not in PIPELINE_PRESETS["short"].to_dict()  # the other manifests stay as they were
    assert not any(p.sort_late for p in PIPELINE_PRESETS.values())
    with pytest.raises(ValueError, match="sort_late needs mu_late"):
        Pipeline(sort_late=True)
    model = make_model([3, 3], seed=2)
    text = emit_verilog(build_core(model, pipeline=SL), "pwas_core")
    # the memory register holds d_0, d_1 and the comparison bit (short: the two sorted fractions)
    assert "s_mem_ds2" in text and "s_mem_ds3" not in text
    assert text == emit_verilog(build_core(model, pipeline=SL), "pwas_core")  # deterministic


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.skipif(VERILATOR is None, reason="verilator not installed")
def test_sort_late_lint_clean(tmp_path):
    assert_core_lint_clean(SL, (([7, 7, 7, 7], 2), ([7, 3, 3], 1)), tmp_path)
