"""Observer-bank sensors on a non-uniform partition (`fit --front-end observer-bank --breakpoints quantile-pow2`), with or without u/y taps.

`generate` refused them before; now the bank's feature codes are the warp's input codes
(:class:`~pwas_hdl.fixedpoint.warp.WarpInputFormat`) and the warp with its register sits between the
feature unit and the uniform core, parallel or serial. The bit-true model is
:class:`~pwas_hdl.fixedpoint.observer_bank.ObserverBankSensorModel` with a
:class:`~pwas_hdl.fixedpoint.warp.WarpedFixedPointModel` core; its error bound uses the slope of the
PWAS function over the *actual* cell widths (:func:`_edge_lipschitz`), not the mean step.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from pwas_hdl.cli import main
from pwas_hdl.design.generate import build_design, generate
from pwas_hdl.design.manifest import load_manifest
from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.fixedpoint.observer_bank import ObserverBankSensorModel, _edge_lipschitz, observer_bank_model
from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel, WarpInputFormat
from pwas_hdl.systems.pv_benchmark import make_pv_dataset


@pytest.fixture(scope="module")
def pv():
    return make_pv_dataset("pv-benchmark", 2000, 300, seed=0)


def _fit(pv, mu=0, my=0, n_models=3, features="11b", order=5, partitions=4):
    tr, _, _ = pv
    fe = ObserverBankFrontEnd(n_models=n_models, observer="deadbeat", features=features, order=order)
    return PWASVirtualSensor(mu=mu, my=my, partitions=partitions, gamma=1.0, front_end=fe, sigma=1e-3,
                             breakpoints="quantile-pow2").fit(tr.u, tr.y, tr.z)


@pytest.fixture(scope="module")
def sensor(pv):
    return _fit(pv)


def test_the_bit_true_sensor_is_warped_and_within_its_bound(sensor, pv):
    _, te, _ = pv
    hm = observer_bank_model(sensor)
    assert isinstance(hm.core, WarpedFixedPointModel)
    assert all(isinstance(f, WarpInputFormat) for f in hm.bank.feature_inputs)
    assert sensor.grid_.breakpoints is not None and not np.allclose(np.diff(sensor.grid_.breakpoints[0]),
                                                                    sensor.grid_.step[0])  # really non-uniform
    codes, _ = hm.quantize_signals(te.u, te.y)
    tr = hm.trace(codes)
    assert not tr["state_saturated"].any()
    b = hm.bank
    fhw = np.stack([f.to_physical(tr["feature_codes"][b.first_output:, j]) for j, f in enumerate(b.feature_inputs)], 1)
    lo, hi = sensor.grid_.lo, sensor.grid_.hi
    err_f = np.abs(np.clip(fhw, lo, hi) - np.clip(b.float_features(codes), lo, hi)).max(axis=0)
    assert np.all(err_f <= np.array(b.feature_error_bound))
    out = hm.core.to_physical_output(tr["out"])
    err = np.abs(out - hm.reference(codes)).max(axis=0)
    assert np.all(err <= np.array(hm.error_bound)) and err.max() > 0


def test_edge_slopes_use_the_cell_widths(sensor):
    """G_j bounds the PWAS slope along j and is reached on some edge; with the mean step instead of the
    cell widths (the code before) the narrow cells' slopes exceed it."""
    grid, w = sensor.grid_, sensor.weights_.reshape(sensor.grid_.n_vertices, -1)
    g = _edge_lipschitz(grid, w)
    rng = np.random.default_rng(0)
    lo, hi = grid.lo, grid.hi
    x = lo + (hi - lo) * rng.random((4000, grid.n))
    worst = np.zeros(grid.n)
    for j in range(grid.n):
        h = 1e-6 * (hi[j] - lo[j])
        x2 = x.copy()
        x2[:, j] = np.minimum(x[:, j] + h, hi[j])
        slope = np.abs(sensor.predict_regressors(x2) - sensor.predict_regressors(x))[:, 0] / np.maximum(x2[:, j] - x[:, j], 1e-300)
        worst[j] = slope.max()
    assert np.all(worst <= g[0] * (1 + 1e-6))
    assert np.all(worst >= 0.5 * g[0])  # 4000 points find most of the steepest edge's slope
    mean_step = np.array([np.abs(np.diff(w[:, 0].reshape([p + 1 for p in grid.partitions]), axis=j)).max() / grid.step[j]
                          for j in range(grid.n)])
    assert np.any(worst > mean_step * 1.05)  # the old bound (mean step) did not hold


def test_uniform_grid_slopes_unchanged(pv):
    tr, _, _ = pv
    fe = ObserverBankFrontEnd(n_models=2, observer="deadbeat", order=3)
    s = PWASVirtualSensor(mu=0, my=0, partitions=3, gamma=1.0, front_end=fe, sigma=1e-3).fit(tr.u, tr.y, tr.z)
    w = s.weights_.reshape(s.grid_.n_vertices, -1)
    shape = [p + 1 for p in s.grid_.partitions]
    expect = [np.abs(np.diff(w[:, 0].reshape(shape), axis=j)).max() / s.grid_.step[j] for j in range(s.grid_.n)]
    assert np.allclose(_edge_lipschitz(s.grid_, w)[0], expect, rtol=0, atol=0)


@pytest.mark.parametrize("architecture, ii", [("parallel", 1), ("serial", None)])
def test_generate_manifest_header_and_reruns(sensor, tmp_path, architecture, ii):
    g = generate(sensor, tmp_path / "d", design="sensor", architecture=architecture)
    assert build_design(sensor, design="sensor", architecture=architecture).files == g.files  # deterministic
    man = load_manifest(tmp_path / "d")
    assert man["front_end"]["kind"] == "observer-bank" and man["warp"]["kind"] == "pow2"
    assert [i["input_scale"] for i in man["formats"]["inputs"]] == ["warp"] * 3
    core = g.component.core
    assert man["latency_cycles"] == man["front_end"]["stages_before_core"] + core.latency
    assert core.warps is not None and core.input_stage is not None  # the warp register counts in core.latency
    if ii is not None:
        # the input (2), residual, square, sum, root, affine (2) and code registers, those inside the root (every 3 digit steps)
        fe = man["front_end"]
        assert man["ii"] == ii and fe["stages_before_core"] == 9 + fe["isqrt_registers"] and fe["isqrt_every"] == 3
        assert fe["isqrt_registers"] == ((fe["formats"]["sum_bits"] + 1) // 2 - 1) // 3 > 0
    else:
        assert man["ii"] == man["front_end"]["cycles_per_sample"] > 1
    text = (tmp_path / "d" / "pwas_sensor.v").read_text()
    assert "non-uniform partition (power-of-two cells): a warp maps" in text and "observer bank: 3 observers" in text


def test_the_warp_adds_one_cycle_to_the_uniform_bank_sensor(pv, sensor):
    """The same bank on equal intervals: one cycle less (the warp register), the same II."""
    tr, _, _ = pv
    uni = PWASVirtualSensor(mu=0, my=0, partitions=4, gamma=1.0, front_end=sensor.front_end_, sigma=1e-3).fit(tr.u, tr.y, tr.z)
    a = build_design(sensor, design="sensor", pipeline="balanced")
    b = build_design(uni, design="sensor", pipeline="balanced")
    assert a.manifest["latency_cycles"] == b.manifest["latency_cycles"] + 1 and a.manifest["ii"] == b.manifest["ii"] == 1


@pytest.fixture(scope="module")
def tapped(pv):
    return _fit(pv, mu=1, my=1, n_models=2, order=3, partitions=2)


def test_taps_beside_the_features_go_through_the_warp_too(tapped, pv):
    """u/y taps (--mu/--my) on the non-uniform partition: the taps' affine requantisation targets the
    warp's input codes of their dimensions, as the features' does; the estimate within its bound."""
    _, te, _ = pv
    m = observer_bank_model(tapped)
    assert hasattr(m, "taps") and isinstance(m.core, WarpedFixedPointModel)
    assert all(isinstance(f, WarpInputFormat) for f in m.taps.tap_inputs)
    codes, _ = m.quantize_signals(te.u, te.y)
    hw = m.core.to_physical_output(m.evaluate(codes)[0])
    err = np.abs(hw - m.reference(codes)).max(axis=0)
    assert np.all(err <= np.array(m.error_bound)) and err.max() > 0
    g = build_design(tapped, design="sensor")
    assert "warp" in g.manifest and "taps" in g.manifest["front_end"]
    assert g.manifest["latency_cycles"] == g.manifest["front_end"]["stages_before_core"] + g.component.core.latency


def test_cli_fit_generate(pv, tmp_path):
    tr, _, _ = pv
    data = tmp_path / "tr.csv"
    np.savetxt(data, np.column_stack([tr.u, tr.y, tr.z]), delimiter=",", header="u0,u1,y,z", comments="")
    assert main(["fit", str(data), "-o", str(tmp_path / "m.json"), "-u", "u0,u1", "-y", "y", "-z", "z", "--mu", "0",
                 "--my", "0", "-p", "3", "--sigma", "1e-3", "--front-end", "observer-bank", "--models", "2",
                 "--breakpoints", "quantile-pow2"]) == 0
    assert main(["generate", str(tmp_path / "m.json"), "--design", "sensor", "-o", str(tmp_path / "g")]) == 0
    man = json.loads((tmp_path / "g" / "manifest.json").read_text())
    assert "warp" in man and man["front_end"]["kind"] == "observer-bank"
    assert isinstance(ObserverBankSensorModel.from_sensor(PWASVirtualSensor.load(tmp_path / "m.json")).core, WarpedFixedPointModel)


@pytest.mark.rtl
@pytest.mark.parametrize("simulator, architecture, model", [
    ("icarus", "parallel", "sensor"), ("icarus", "serial", "sensor"),
    ("icarus", "serial", "tapped"), ("verilator", "parallel", "tapped"),
])
def test_rtl_bit_exact_and_lint_clean(request, pv, tmp_path, sim_cache, simulator, architecture, model):
    from pwas_hdl.flow.toolchain import lint_verilog
    from pwas_hdl.verify.simulation import load_design, run_rtl, sim_module, standard_runs

    generate(request.getfixturevalue(model), tmp_path / "d", design="sensor", architecture=architecture)
    if simulator == "verilator":
        r = lint_verilog(tmp_path / "d" / "pwas_sensor.v", "pwas_sensor")
        assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[:2000]
    d = load_design(tmp_path / "d")
    _, te, _ = pv
    data, _ = d.bank.quantize_signals(te.u, te.y)
    codes = sim_module("pwas_stimulus").observer_codes(d.bank.bank, 360, seed=3, data=data)
    res = run_rtl(d, standard_runs(d, codes), simulator, cache_dir=sim_cache)
    assert res.passed, res.report()
    assert res.mismatches == 0 and res.outputs > 800 and set(res.latencies) == {d.latency}
    assert res.within_bound


@pytest.mark.rtl
def test_rtl_catches_a_corrupted_warp(sensor, pv, tmp_path, sim_cache):
    """The same design with bit 8 of the first warp's output flipped (its register's input): the run fails."""
    import re

    from pwas_hdl.verify.simulation import load_design, run_rtl, sim_module, standard_runs

    generate(sensor, tmp_path / "d", design="sensor")
    v = tmp_path / "d" / "pwas_sensor.v"
    text = v.read_text()
    mo = re.search(r"s_warp_u0 <= (\\\S+) ;", text)
    assert mo, "no warp register to corrupt"
    v.write_text(text.replace(mo.group(0), f"s_warp_u0 <= {mo.group(1)}  ^ 15'h0100;", 1))
    d = load_design(tmp_path / "d")
    _, te, _ = pv
    data, _ = d.bank.quantize_signals(te.u, te.y)
    codes = sim_module("pwas_stimulus").observer_codes(d.bank.bank, 200, seed=3, data=data)
    res = run_rtl(d, standard_runs(d, codes), "icarus", cache_dir=sim_cache)
    assert not res.passed and res.mismatches > 0
