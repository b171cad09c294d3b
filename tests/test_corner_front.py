"""Issue 14 (latency-first front): the corner-bank memory layout and the raw_compare front option.

Both are opt-in (no preset uses them): bit-exact against the bit-true model in Amaranth simulation
with bubbles and backpressure; the corner layout read through by the bit-true model itself.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from helpers.hdl_models import codes, make_model
from pwas_hdl.fixedpoint.memory_layout import CornerLayout, make_layout
from pwas_hdl.hdl import build_core
from pwas_hdl.hdl.core import PWASCore
from pwas_hdl.hdl.params import PIPELINE_PRESETS, Pipeline
from test_hdl_core import assert_bittrue_with_stalls


def _pipe(name: str, **kw) -> Pipeline:
    return dataclasses.replace(PIPELINE_PRESETS[name], **kw)


def test_corner_layout_geometry_and_bittrue():
    """Bank s at the cell's bit-field address holds W[c + s]; the bit-true model reading through it
    gives the banked model's codes."""
    a = make_model([3, 1, 4], seed=4, nz=2)
    b = make_model([3, 1, 4], seed=4, nz=2, layout="corner")
    lay = b.layout
    assert isinstance(lay, CornerLayout) and lay.n_banks == 8
    assert lay.cell_bits == (2, 0, 2) and lay.field_shifts == (2, 2, 0) and lay.depth == 16
    q = codes(a, 400, seed=2)
    for x, y in zip(a.evaluate(q), b.evaluate(q)):
        assert np.array_equal(x, y)
    rom = lay.contents(b.weight_codes)
    cell = np.array([2, 0, 1])
    for s in range(8):
        v = cell + ((s >> np.arange(3)) & 1)
        assert np.array_equal(rom[s, 2 << 2 | 1], b.weight_codes[b.grid.vertex_index(v)])
    assert not rom[:, 3 << 2].any()  # c_0 = 3 >= p_0: padding
    verts = b.grid.simplex_vertices(np.array([[2, 0, 3]]), np.array([[2, 0, 1]]))
    bank, addr = lay.simplex_bank_addr(verts)
    assert bank.tolist() == [[0, 4, 5, 7]] and len(set(addr[0].tolist())) == 1
    with pytest.raises(ValueError, match="corner"):
        make_layout(b.grid, "cornered")


@pytest.mark.parametrize("parts, nz, mem, pipe", [
    ([3, 1, 2], 2, "corner", _pipe("short", mem_out=True)),  # the 4-cycle build: DP16KD output register
    ([2, 2, 2, 2], 1, "corner", _pipe("short", mem_out=True, mul_in=True)),
    ([2, 3], 1, "corner", "max"),
    ([5], 2, "corner", "min"),
    ([3, 3, 3, 3], 2, "banked", _pipe("short", raw_compare=True)),
    ([2, 1, 3, 4], 2, "banked", _pipe("balanced", raw_compare=True)),  # mixed F_j, offset L_j
], ids=lambda v: v if isinstance(v, str) else None)
def test_matches_bittrue_with_stalls(parts, nz, mem, pipe, monkeypatch):
    used = []
    orig = PWASCore._raw_ge
    monkeypatch.setattr(PWASCore, "_raw_ge", lambda self, *a, **k: used.append(1) or orig(self, *a, **k))
    opts = {"input_bits": 10} if len(parts) == 4 and parts[1] == 1 else {}
    model = make_model(parts, seed=len(parts) * 10 + nz, nz=nz, **opts)
    dut = build_core(model, memory=mem, pipeline=pipe)
    oor, _ = assert_bittrue_with_stalls(model, dut, 120, seed=3, stall_seed=5)
    assert oor.any() and not oor.all()
    assert bool(used) == (Pipeline.cast(pipe).raw_compare and len(parts) > 1 and mem != "corner")  # raw comparators built
    assert dut.memory_plan.n_banks == (1 << len(parts) if mem == "corner" else len(parts) + 1)


def test_raw_compare_in_manifest_only_when_set():
    assert "raw_compare" not in Pipeline().to_dict()
    d = _pipe("short", raw_compare=True).to_dict()
    assert d["raw_compare"] is True and Pipeline.cast(d) == _pipe("short", raw_compare=True)


def test_a_corner_memory_too_large_is_refused_before_it_is_built():
    """2**n corner banks of 2**(cell bits) words grow far faster than N: n = 10, p = 3 (N = 4**10)
    would be 2**30 words; the layout refuses it (ResourceLimit, an InputError: the CLI's error line,
    exit 2) before any table or content is allocated."""
    from pwas_hdl.errors import ResourceLimit
    from pwas_hdl.fit.geometry import Grid

    with pytest.raises(ResourceLimit, match=r"corner memory's words .* = 1073741824 exceeds the limit"):
        CornerLayout(Grid(np.zeros(10), np.ones(10), [3] * 10))


@pytest.mark.slow
def test_generate_refuses_a_too_large_corner_memory(tmp_path):
    """The same through the CLI: one error line, exit 2, nothing written (~2.5 s: a 65 536-weight model)."""
    from helpers.cli import CliRunner

    from pwas_hdl.cli import app
    from pwas_hdl.verify.simulation import sim_module

    model = tmp_path / "m.json"  # n = 8, p = 3: N = 65 536 (banked fine), corner 256 x 65 536 words
    model.write_text(sim_module("pwas_designs").synthetic_model(0, 8, 0, 1, 3).to_json())
    out = tmp_path / "hw"
    res = CliRunner().invoke(app, ["generate", str(model), "--memory", "corner", "-o", str(out)])
    assert res.exit_code == 2, res.output
    assert res.output.count("error:") == 1 and "use the banked memory" in res.output and "Traceback" not in res.output
    assert not out.exists()
