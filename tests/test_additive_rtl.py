"""The additive designs (issue 15) in both simulators, bit-exact against the additive bit-true model.

Configurations: ``sim/pwas_designs.ADDITIVE_CONFIGS``. Each is replayed as the other RTL benches
(``tests/test_rtl_cocotb.py``): at full speed (latency = manifest, II = 1), with random bubbles and
backpressure, and with a synchronous reset in the middle of a stream.
"""

from __future__ import annotations

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

    def get(name):
        if name not in made:
            BY_NAME[name].generate(root / name)
            made[name] = root / name
        return made[name]

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
