"""The additive designs (issue 15) in both simulators, bit-exact against the additive bit-true model.

Configurations: ``sim/pwas_designs.ADDITIVE_CONFIGS``. Each is replayed as the other RTL benches
(``tests/test_rtl_cocotb.py``): at full speed (latency = manifest, II = 1), with random bubbles and
backpressure, and with a synchronous reset in the middle of a stream; and with ``--memory-init readmemh``
(the weights loaded from the parts' ``.hex`` files).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pwas_hdl.verify.simulation import load_design, run_rtl, segment, sim_module, standard_runs

designs = sim_module("pwas_designs")
stimulus = sim_module("pwas_stimulus")
BY_NAME = {c.name: c for c in designs.ADDITIVE_CONFIGS}


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    made = {}
    root = tmp_path_factory.mktemp("additive_designs")

    def get(name, memory_init="inline"):
        key = name if memory_init == "inline" else f"{name}-{memory_init}"
        if key not in made:
            cfg = BY_NAME[name]
            replace(cfg, options={**cfg.options, "memory_init": memory_init}).generate(root / key)
            made[key] = root / key
        return made[key]

    return get


def test_the_additive_configurations():
    """Two additive designs: a sensor top and a core; parts of different sizes; an aligned part."""
    from pwas_hdl.design.generate import fixed_point_model

    assert {c.design for c in designs.ADDITIVE_CONFIGS} == {"core", "sensor"}
    fxs = [fixed_point_model(c.model()) for c in designs.ADDITIVE_CONFIGS]
    assert any(len({len(s) for s in fx.subsets}) > 1 for fx in fxs)
    assert any(a > 0 for fx in fxs for a in fx.align)


@pytest.mark.parametrize("simulator", ("icarus", "verilator"))
@pytest.mark.parametrize("name", list(BY_NAME))
@pytest.mark.rtl
def test_additive_rtl_equals_bittrue_model(name, simulator, folder, sim_cache, tmp_path):
    d = load_design(folder(name))
    assert "additive" in d.manifest
    if d.kind == "core":
        codes = stimulus.core_codes(d.model, 300, seed=7)
    else:
        codes = stimulus.sensor_codes(d.model, [f["signal"] for f in d.in_fields], 300, seed=7)
    runs = standard_runs(d, codes, seed=7)
    res = run_rtl(d, runs, simulator, cache_dir=sim_cache, work_dir=tmp_path, debug=False)
    assert res.passed, res.report()
    per_stream = len(segment(d, codes).src)
    assert res.outputs >= 2 * per_stream + len(runs[2].segments[1].src)
    assert set(res.latencies) == {d.latency} == {int(d.manifest["latency_cycles"])}, res.report()
    assert res.ii == 1.0 == d.manifest["ii"]
    assert res.within_bound, res.report()
    oor = np.concatenate([o for run in res.hw for _, o in run])
    assert oor.any() and not oor.all()


@pytest.mark.parametrize("name, simulator", [("a-c-n4-z2-max-trunc", "icarus"), ("a-s-y3-pairs", "icarus"),
                                             ("a-c-n4-z2-max-trunc", "verilator")])
@pytest.mark.rtl
def test_additive_readmemh_rtl_equals_bittrue_model_and_inline(name, simulator, folder, sim_cache, tmp_path):
    """--memory-init readmemh of an additive design: the simulator loads every part's weights from its
    .hex files (MEM_DIR "./": the work folder they are copied to) and the RTL is bit-exact with the
    bit-true model; on Icarus its outputs are also those of the inline design, run for run."""
    d = load_design(folder(name, "readmemh"))
    assert d.manifest["memory"]["init"]["kind"] == "readmemh" and "additive" in d.manifest
    assert '$readmemh({MEM_DIR, "' in d.verilog and "_wmem0[0] =" not in d.verilog
    if d.kind == "core":
        codes = stimulus.core_codes(d.model, 200, seed=11)
    else:
        codes = stimulus.sensor_codes(d.model, [f["signal"] for f in d.in_fields], 200, seed=11)
    runs = standard_runs(d, codes, seed=11)
    res = run_rtl(d, runs, simulator, cache_dir=sim_cache, work_dir=tmp_path / "readmemh", debug=False)
    assert res.passed, res.report()
    assert res.mismatches == 0 and res.outputs >= 2 * len(segment(d, codes).src)
    assert set(res.latencies) == {d.latency} and res.ii == 1.0
    if simulator == "icarus":
        inline = load_design(folder(name))
        assert "$readmemh" not in inline.verilog
        ref = run_rtl(inline, runs, simulator, cache_dir=sim_cache, work_dir=tmp_path / "inline", debug=False)
        assert ref.passed, ref.report()
        assert len(res.hw) == len(ref.hw) and all(
            len(a) == len(b) and all(np.array_equal(ca, cb) and np.array_equal(oa, ob) for (ca, oa), (cb, ob) in zip(a, b))
            for a, b in zip(res.hw, ref.hw))
