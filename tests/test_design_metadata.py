"""What ``generate`` says about a design: the manifest, the Verilog header, the report and the console
line name what was built (build only, no simulation).

Each test was written for a statement a review found untrue: a serial design recorded
``generator.options.memory = "banked"``; a recurrent top's ``architecture.meaning`` said II = 1 next
to ``ii`` = latency; an additive design's header gave the largest part's depth for every memory;
the ``--clock-mhz`` labels of a serial design named registers the serial core does not build; the
critical path of a classifier ended at ``scores_payload``; the console line said neither serial nor
classifier.
"""

from __future__ import annotations

import warnings
from functools import lru_cache

import numpy as np
import pytest

from pwas_hdl.design.generate import build_design, fixed_point_model
from pwas_hdl.design.manifest import manifest_errors
from pwas_hdl.verify.simulation import sim_module

designs = sim_module("pwas_designs")

#: Tiny synthetic models (no fitting): (mu, my, nu, ny, partitions, nz, keyword options of synthetic_model).
MODELS = {
    "plain": (0, 2, 0, 1, 3, 1, {}),
    "sensor": (1, 2, 1, 1, 2, 1, {}),
    "classifier": (0, 2, 0, 1, [3, 2], 3, {"classes": (0, 1, 2)}),
    "additive": (0, 3, 0, 1, [3, 2, 4], 2, {"additive": "0;1,2"}),
}


@lru_cache(maxsize=None)
def _model(kind: str):
    if kind == "recurrent":  # a recurrent sensor (fit --mz): the three-tank observer map on a 4 x 4 grid
        from pwas_hdl.fit.map_approximation import fit_map, recurrent_sensor_from_map
        from pwas_hdl.systems.decoupled_observer import observer_map_28

        a = fit_map(lambda x: observer_map_28(x[:, 0], x[:, 1]), ([0.0, 0.0], [25.0, 25.0]), 4)
        return recurrent_sensor_from_map(a, [], ["y"], ["x3"], [2.0])
    if kind == "bank":  # an observer-bank sensor (fit --front-end observer-bank) on 300 samples
        from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
        from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
        from pwas_hdl.systems.pv_benchmark import make_pv_dataset

        tr, _, _ = make_pv_dataset("pv-benchmark", 300, 10, seed=0)
        fe = ObserverBankFrontEnd(n_models=2, observer="deadbeat", features="11b", order=2)
        return PWASVirtualSensor(mu=0, my=0, partitions=2, gamma=1.0, front_end=fe, sigma=1e-3).fit(tr.u, tr.y, tr.z)
    mu, my, nu, ny, parts, nz, kw = MODELS[kind]
    return designs.synthetic_model(mu, my, nu, ny, parts, nz, seed=3, **kw)


@lru_cache(maxsize=None)
def _design(kind: str, design: str = "core", architecture: str = "parallel", pipeline: str | None = None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # saturation warnings of the random weights
        return build_design(_model(kind), design=design, architecture=architecture, pipeline=pipeline)


SERIAL = [("plain", "core"), ("sensor", "sensor"), ("classifier", "core"), ("additive", "core"), ("recurrent", "sensor")]


# ------------------------------------------------------------------------------ 1. the serial core's memory
@pytest.mark.parametrize("kind, design", SERIAL)
def test_a_serial_design_records_its_single_memory(kind, design):
    """``generator.options.memory`` said "banked" for the serial core's one memory of N words."""
    man = _design(kind, design, "serial").manifest
    assert man["generator"]["options"]["memory"] == man["memory"]["kind"] == man["memory"]["layout_spec"]["kind"] == "single"
    assert not manifest_errors(man)
    # folders generated before the fix (options.memory "banked" beside memory.kind "single") stay readable
    old = {**man, "generator": {**man["generator"], "options": {**man["generator"]["options"], "memory": "banked"}}}
    assert not manifest_errors(old)
    wrong = {**man, "generator": {**man["generator"], "options": {**man["generator"]["options"], "memory": "replicated"}}}
    assert any("generator.options.memory is 'replicated' but memory.kind is 'single'" in e for e in manifest_errors(wrong))


def test_the_single_memory_rebuilds_the_bit_true_model_and_gets_no_floorplan(tmp_path):
    """What reads ``generator.options.memory`` takes "single": simulate rebuilds the bit-true model
    (the replicated layout, whose copy 0 is the serial memory) and synth plans no block-RAM rows."""
    from pwas_hdl.design.generate import write_folder
    from pwas_hdl.flow.floorplan import plan_sites
    from pwas_hdl.hdl import Pipeline
    from pwas_hdl.verify.simulation import load_design

    gd = _design("plain", "core", "serial")
    fxm = fixed_point_model(_model("plain"), memory="single")
    assert fxm.layout.kind == "replicated"
    q = np.random.default_rng(0).integers(-(1 << (fxm.input_bits - 1)), 1 << (fxm.input_bits - 1), (200, fxm.n))
    assert all(np.array_equal(a, b) for a, b in zip(fxm.evaluate(q), gd.model.evaluate(q)))
    write_folder(gd.files, tmp_path / "d")
    assert load_design(tmp_path / "d").model.layout.kind == "replicated"
    rec = plan_sites({"wmem0": "DP16KD", "prod0": "MULT18X18D"}, "45k", pipeline=Pipeline.cast("short").to_dict(),
                     memory=gd.manifest["memory"]["kind"])
    assert not rec["applied"] and "'single'" in rec["reason"]


# ------------------------------------------------------------------------------ 2. the design's II in words
@pytest.mark.parametrize("kind, design, architecture", [
    ("recurrent", "sensor", "parallel"),  # II = latency (the feedback), the parallel core's II is 1
    ("recurrent", "sensor", "serial"),  # II = latency, the serial core's n + 1
    ("bank", "sensor", "serial"),  # II = the time-multiplexed bank's cycles per sample
    ("plain", "core", "parallel"),
    ("plain", "core", "serial"),
    ("additive", "core", "serial"),
])
def test_architecture_meaning_states_the_designs_ii(kind, design, architecture):
    """A recurrent top's ``architecture.meaning`` said "II = 1" beside ``ii`` = latency."""
    man = _design(kind, design, architecture).manifest
    a = man["architecture"]
    assert a["ii"] == man["ii"] and a["kind"] == architecture
    if a["ii"] == a["cycles_per_sample"]:  # the core's own rate: parallel "II = 1", serial "n + 1 cycles per sample"
        assert ("II = 1" in a["meaning"]) == (a["ii"] == 1) and ("n + 1 cycles per sample" in a["meaning"]) == (architecture == "serial")
        assert "the design's II" not in a["meaning"]
    else:  # a top around the core takes samples more slowly: the text gives the field's value and why
        assert a["meaning"].endswith(f"the design's II = {man['ii']}: " + ("one sample in flight, the estimate fed back into "
                                     "the next regressor: II = latency" if kind == "recurrent" else
                                     "the time-multiplexed observer bank's cycles per sample (front_end.cycles_per_sample)"))
    if kind == "recurrent":
        assert man["ii"] == man["latency_cycles"] > a["cycles_per_sample"]


def test_architecture_info_needs_a_reason_for_another_ii():
    from pwas_hdl.errors import InternalError
    from pwas_hdl.hdl import build_core
    from pwas_hdl.hdl.serial_core import architecture_info

    core = build_core(_design("plain").model)
    assert architecture_info(core)["ii"] == architecture_info(core, 1)["ii"] == 1
    with pytest.raises(InternalError, match="differs from its core's 1"):
        architecture_info(core, 5)


# ------------------------------------------------------------------------------ 3. an additive design's memories
@pytest.mark.parametrize("kind, architecture", [("additive", "parallel"), ("additive", "serial"), ("plain", "parallel")])
def test_header_and_report_give_every_parts_memory(kind, architecture):
    """The header said ``memories x depth`` with the largest part's depth for all of an additive design's
    memories (12 x 15 words where the parts hold 90), the report the same."""
    gd = _design(kind, "core", architecture)
    man = gd.manifest
    mem = man["memory"]
    line = next(ln for ln in gd.files[f"{gd.top}.v"].splitlines() if ln.startswith("// weights "))
    report = gd.files["report.md"]
    if kind == "plain":
        assert f"({mem['kind']} memory, {mem['memories']} x {mem['depth']} words of {mem['word_bits']} bits)" in line
        assert f"Layout **{mem['kind']}**: {mem['memories']} x {mem['depth']} words of {mem['word_bits']} bits = {mem['words']} words" in report
        return
    parts = [p["memory"] for p in man["additive"]["parts"]]
    assert len({p["depth"] for p in parts}) > 1 and sum(p["memories"] * p["depth"] for p in parts) == mem["words"]
    shape = " + ".join(f"{p['memories']} x {p['depth']}" for p in parts) + f" words of {mem['word_bits']} bits"
    assert f"({mem['kind']} memories, one set per additive part: {shape} = {mem['words']} words)" in line
    assert f"Layout **{mem['kind']}**: one set per additive part: {shape} = {mem['words']} words" in report
    assert f"{mem['memories']} x {mem['depth']} words" not in line + report  # mem['depth'] is the largest part's


# ------------------------------------------------------------------------------ 4. the registers a serial design builds
@pytest.mark.parametrize("kind", ["plain", "classifier"])
def test_serial_timing_labels_name_the_registers_the_serial_core_builds(kind, monkeypatch):
    """``--clock-mhz`` of a serial design labelled candidates ``balanced`` or ``...+mul_in+product+tree/1``:
    registers (``tree_levels``, ``mul_in``, ``bank``) the serial core does not build."""
    import pwas_hdl.flow.timing_closure as tc
    from helpers.timing import FakePlaceAndRoute
    from pwas_hdl.hdl import PIPELINE_PRESETS, Pipeline
    from pwas_hdl.hdl.serial_core import SERIAL_REGISTERS

    monkeypatch.setattr(tc, "measure_design", FakePlaceAndRoute(mhz_per_cycle=10.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        man = build_design(_model(kind), design="core", architecture="serial", target_mhz=120.0).manifest
    takes = SERIAL_REGISTERS + (("tree_levels",) if kind == "classifier" else ())  # the argmax stage's
    cands = man["timing"]["candidates"]
    for c in cands:
        pl = Pipeline.cast(c["pipeline"])
        built = [k for k in ("split", "rank", "offset", "addr", "mem_out", "product", "tree_levels") if k in takes and getattr(pl, k)]
        if c["label"] == "min":  # no register built
            assert built == [], c
        elif c["label"] in PIPELINE_PRESETS:  # a preset's name: that pipeline, every register of it built
            assert PIPELINE_PRESETS[c["label"]] == pl and all(not getattr(pl, k) or k in takes for k in ("bank", "mul_in", "tree_levels")), c
        else:
            assert ["tree_levels" if k.startswith("tree/") else k for k in c["label"].split("+")] == built, c
    assert len({c["label"] for c in cands}) == len(cands)
    chosen = cands[man["timing"]["chosen"]]
    assert man["architecture"]["pipeline_registers"] == [k for k in takes if getattr(Pipeline.cast(chosen["pipeline"]), k)]
    assert any(Pipeline.cast(c["pipeline"]).mul_in or Pipeline.cast(c["pipeline"]).tree_levels for c in cands)  # ignored ones were on


def test_label_of_a_pipeline_and_the_registers_built():
    from pwas_hdl.flow.timing_closure import _label
    from pwas_hdl.hdl import Pipeline
    from pwas_hdl.hdl.serial_core import SERIAL_REGISTERS

    mx = Pipeline.cast("max")
    assert _label(mx) == "max" and _label(Pipeline()) == "balanced"  # the parallel core's: unchanged
    assert _label(mx, SERIAL_REGISTERS) == "split+rank+offset+addr+mem_out+product"
    assert _label(Pipeline(), SERIAL_REGISTERS) == "rank+addr+mem_out+product"
    assert _label(Pipeline(), SERIAL_REGISTERS + ("tree_levels",)) == "balanced"
    assert _label(Pipeline.cast("short"), SERIAL_REGISTERS) == "min"


@pytest.mark.parametrize("kind, architecture, pipeline, want", [
    ("plain", "parallel", "max", ["split", "rank", "offset", "addr", "bank", "mem_out", "mul_in", "product", "tree_levels"]),
    ("plain", "serial", "max", ["split", "rank", "offset", "addr", "mem_out", "product"]),
    ("plain", "serial", "short", []),  # mul_in alone: nothing the serial core builds
    ("classifier", "serial", "balanced", ["rank", "addr", "mem_out", "product", "tree_levels"]),  # the argmax stage's tree
    ("recurrent", "parallel", "balanced", ["rank", "addr", "mem_out", "product", "tree_levels"]),
    ("additive", "serial", "max", ["split", "rank", "offset", "addr", "mem_out", "product"]),
])
def test_manifest_says_which_pipeline_registers_are_built(kind, architecture, pipeline, want):
    design = "sensor" if kind == "recurrent" else "core"
    man = _design(kind, design, architecture, pipeline).manifest
    assert man["architecture"]["pipeline_registers"] == want
    if "additive" not in man:
        bad = {**man, "architecture": {**man["architecture"], "pipeline_registers": ["mul_halves"]}}
        assert any("architecture.pipeline_registers names ['mul_halves']" in e for e in manifest_errors(bad))


def test_built_pipeline_registers_reads_the_manifest_and_falls_back_to_pipeline():
    """One answer to "which registers does this design build": ``architecture.pipeline_registers``;
    a manifest without it, the registers ``pipeline`` has on that its architecture builds (a serial
    manifest written before the field: no mul_in); the estimator (no pipeline), none."""
    from pwas_hdl.design.manifest import built_pipeline_registers

    man = _design("plain", "core", "serial", "short").manifest
    assert man["pipeline"]["mul_in"] and built_pipeline_registers(man) == []
    old = {**man, "architecture": {k: v for k, v in man["architecture"].items() if k != "pipeline_registers"}}
    assert built_pipeline_registers(old) == []
    assert built_pipeline_registers({k: v for k, v in old.items() if k != "architecture"}) == ["mul_in"]
    # an old serial classifier manifest: its argmax stage builds tree_levels registers on the serial core
    cls = {**old, "classifier": {"n_classes": 3}, "pipeline": {**old["pipeline"], "tree_levels": 1}}
    assert "tree_levels" in built_pipeline_registers(cls) and "tree_levels" not in built_pipeline_registers(
        {k: v for k, v in cls.items() if k != "classifier"})
    parallel = _design("plain", "core", "parallel", "short").manifest
    old_par = {**parallel, "architecture": {k: v for k, v in parallel["architecture"].items() if k != "pipeline_registers"}}
    assert built_pipeline_registers(old_par) == built_pipeline_registers(parallel)
    assert built_pipeline_registers({"design": "estimator"}) == []


@pytest.mark.parametrize("architecture, mult_first", [("serial", False), ("parallel", True)])
def test_synth_packs_and_plans_by_the_registers_the_design_builds(architecture, mult_first, tmp_path, monkeypatch):
    """synth ordered the ECP5 hard-register packing (and the floorplan's rule) by ``pipeline``: a
    serial design on ``short`` (mul_in, no mem_out) was packed multipliers first as if it had the
    mul_in register the serial core does not build. Yosys and nextpnr are stand-ins here."""
    import json

    from pwas_hdl.design.generate import write_folder
    from pwas_hdl.flow import floorplan, hard_registers, synthesis

    class Stop(Exception):
        pass

    seen = {}

    def run_tool(tool, args, cwd, log):
        assert tool == "yosys", tool
        for f in ("stat.json", "stat_rtl.json"):
            (cwd / f).write_text(json.dumps({"design": {"num_cells_by_type": {}}}), encoding="utf-8")
        return 0

    def pack(netlist, top, *, mult_first=False):
        seen["mult_first"] = mult_first
        return {"ffs_absorbed": 0}

    def plan(netlist, top, device, *, pipeline, **kw):
        seen["planned"] = floorplan.applies_to_pipeline(pipeline)
        raise Stop  # before nextpnr

    monkeypatch.setattr(synthesis, "_check_tool", lambda tool: None)
    monkeypatch.setattr(synthesis, "_run_tool", run_tool)
    monkeypatch.setattr(hard_registers, "pack_ecp5_registers", pack)
    monkeypatch.setattr(floorplan, "apply_floorplan", plan)
    gd = _design("plain", "core", architecture, "short")
    write_folder(gd.files, tmp_path / "d")
    with pytest.raises(Stop):
        synthesis.synthesize(tmp_path / "d", "ecp5", harness=False)
    assert seen == {"mult_first": mult_first, "planned": mult_first}


# ------------------------------------------------------------------------------ 5. a classifier's critical path
@pytest.mark.parametrize("architecture, pipeline", [("parallel", "min"), ("parallel", "balanced"), ("serial", "balanced")])
def test_a_classifiers_score_register_is_named_in_the_critical_path(architecture, pipeline):
    """A classifier's critical path ended at ``scores_payload``, a raw net name: it is the core's output
    register (the scores), which the argmax stage reads, whatever the stage's registers."""
    import re

    from pwas_hdl.flow.timing_closure import _stage_of_cell

    gd = _design("classifier", "core", architecture, pipeline)
    v = gd.files[f"{gd.top}.v"]
    assert re.search(r"^\s*reg \[\d+:0\] scores_payload;$", v, re.M) and re.search(r"^\s*scores_payload <= ", v, re.M)
    for cell in ("core.scores_payload_TRELLIS_FF", "scores_payload[3]", "core.scores_valid_q"):
        assert _stage_of_cell(cell) == "score register (argmax input)"
    assert _stage_of_cell("core.scores_x") == "scores_x"  # only the register's own names


def test_a_serial_cores_registers_are_named_in_the_critical_path():
    """The serial core's registers beside the memory read (``m_*``), its mem_out (``mo_*``) and product
    (``p_*``) registers, ``acc_done`` / ``acc_oor`` and the throttle's ``gap`` ended a critical path
    as raw net names; they get the parallel core's stage names (s_mem, s_memout, s_prod) or the
    serial core's own. Every register of a serial ``max`` design's Verilog gets a stage name."""
    import re

    from pwas_hdl.flow.timing_closure import _critical_path, _stage_of_cell

    gd = _design("plain", "core", "serial", "max")
    regs = set(re.findall(r"always @\(posedge \w+\)\s*\n\s*(\w+) <= ", gd.files[f"{gd.top}.v"]))
    assert {"m_mu", "mo_data", "p_prod0", "acc_done", "gap"} <= regs
    assert {r: _stage_of_cell(f"core.{r}_TRELLIS_FF") for r in regs if _stage_of_cell(f"core.{r}_TRELLIS_FF") == r} == {}
    want = {"m_": "s_mem", "mo_": "s_memout", "p_": "s_prod", "acc": "serial accumulator", "gap": "serial input throttle"}
    for r in regs:
        pre = next((p for p in ("mo_", "m_", "p_", "acc", "gap") if r.startswith(p) and not r.startswith("m_axis")), None)
        if pre:
            assert _stage_of_cell(r) == want[pre], r
    # a synthetic nextpnr report: a path from the memory-read cycle's mu to the product register
    hop = {"type": "logic", "delay": 1.5}
    report = {"critical_paths": [{"from": "posedge aclk", "to": "posedge aclk", "path": [
        {**hop, "from": {"cell": "core.m_mu_TRELLIS_FF"}, "to": {"cell": "x"}},
        {"type": "routing", "delay": 0.5, "from": {"cell": "x"}, "to": {"cell": "core.p_prod0_TRELLIS_FF"}}]}]}
    assert _critical_path(report) == {"from": "s_mem", "to": "s_prod", "delay_ns": 2.0, "routing_ns": 0.5}


# ------------------------------------------------------------------------------ 6. the console line
@pytest.mark.parametrize("kind, design, architecture, want", [
    ("plain", "core", "parallel", "parallel core"),
    ("plain", "core", "serial", "serial core"),
    ("sensor", "sensor", "serial", "serial sensor top"),
    ("classifier", "core", "serial", "serial core, classifier, 3 classes"),
    ("additive", "core", "parallel", "parallel core, additive, 2 parts"),
    ("recurrent", "sensor", "serial", "serial recurrent sensor top"),
    ("bank", "sensor", "serial", "serial sensor top, observer bank (2 observers)"),
])
def test_design_summary_names_architecture_and_kind(kind, design, architecture, want):
    from pwas_hdl.design.generate import design_summary

    assert design_summary(_design(kind, design, architecture).manifest) == want


def test_generate_console_line_says_serial_and_classifier(tmp_path):
    """The line said ``pwas_core: latency 13 cycles, II 3, ...``: neither serial nor classifier."""
    from helpers.cli import CliRunner

    from pwas_hdl.cli import app

    model = tmp_path / "m.json"
    model.write_text(_model("classifier").to_json(), encoding="utf-8")
    r = CliRunner().invoke(app, ["generate", str(model), "-o", str(tmp_path / "o"), "--architecture", "serial"])
    assert r.exit_code == 0, r.output
    assert "pwas_core: serial core, classifier, 3 classes, latency " in r.output, r.output
