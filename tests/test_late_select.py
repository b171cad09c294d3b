"""Issue 14 (hw14f): ``late_select``, the bank-address fields as a late select on the comparison bits.

Opt-in (no preset: the latency build measured 32.4-34.0 ns with it against 29.7-30.8 ns without,
benchmarks/results/hw_tables_latency_experiments.md, hw14f). Bit-exact against the bit-true model
in Amaranth simulation with bubbles and backpressure (n = 2..4, nz = 1..2; n = 1 keeps the tables,
as do layouts without bit fields), no rank or step tables left, lint-clean and deterministic.
"""

from __future__ import annotations

import dataclasses

import pytest

from helpers.hdl_models import make_model
from pwas_hdl.hdl import build_core
from pwas_hdl.hdl.core import PWASCore
from pwas_hdl.hdl.emit import emit_verilog
from pwas_hdl.hdl.params import PIPELINE_PRESETS, Pipeline
from test_hdl_core import assert_bittrue_with_stalls
from test_hdl_verilog import VERILATOR, assert_core_lint_clean

LS = dataclasses.replace(PIPELINE_PRESETS["short"], late_select=True)


@pytest.mark.parametrize("parts, nz, opts, late", [
    ([3, 3, 3, 3], 1, {}, True),
    ([3, 3], 2, {"input_bits": 10}, True),  # a last-dimension field (c // (n+1))
    ([5], 1, {}, False),  # n = 1: no comparison bits
])
def test_late_select_matches_bittrue_with_stalls(parts, nz, opts, late, monkeypatch):
    used = []
    orig = PWASCore._late_field
    monkeypatch.setattr(PWASCore, "_late_field", lambda self, *a: used.append(1) or orig(self, *a))
    model = make_model(parts, seed=len(parts) * 3 + nz, nz=nz, **opts)
    dut = build_core(model, pipeline=LS)
    oor, _ = assert_bittrue_with_stalls(model, dut, 60, seed=5, stall_seed=6)
    assert bool(used) == late


def test_late_select_option_and_tables():
    d = LS.to_dict()
    assert d["late_select"] is True and Pipeline.cast(d) == LS
    assert not any(p.late_select for p in PIPELINE_PRESETS.values())
    model = make_model([3, 3], seed=2)
    text = emit_verilog(build_core(model, pipeline=LS), "pwas_core")
    assert " ls0_0_0" in text and "rank0" not in text and "step0_" not in text  # no dead tables
    assert text == emit_verilog(build_core(model, pipeline=LS), "pwas_core")  # deterministic


@pytest.mark.rtl  # runs Verilator's linter
@pytest.mark.skipif(VERILATOR is None, reason="verilator not installed")
def test_late_select_lint_clean(tmp_path):
    assert_core_lint_clean(LS, (([7, 7, 7, 7], 2), ([7, 3, 3], 1)), tmp_path)
