"""Observer-bank sensors with u/y taps in hardware (issue 12): bit-true taps, generate, lint, cocotb on both simulators.

One small battery sensor (3 Kalman observers, taps i[t], v[t-1], v[t]: lags of two depths), fitted
once per module; every test here runs a linter or a simulator (marker ``rtl``).
"""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.rtl


@pytest.fixture(scope="module")
def tapped(tmp_path_factory):
    from pwas_hdl.design.generate import generate
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.systems.battery import make_battery_dataset

    tr, te, _ = make_battery_dataset(3000, 300, seed=0)
    fe = ObserverBankFrontEnd(n_models=3, observer="kalman:0.1").fit([tr.u], [tr.y], [tr.z])
    s = PWASVirtualSensor(mu=1, my=2, partitions=2, gamma=1.0, front_end=fe, sigma=1e-3).fit(tr.u, tr.y, tr.z)
    out = tmp_path_factory.mktemp("taps") / "hw"
    return s, te, generate(s, out, design="sensor")


def test_tapped_bittrue_within_bound_and_manifest(tapped, tmp_path):
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.design.manifest import load_manifest
    from pwas_hdl.flow.toolchain import lint_verilog

    from pwas_hdl.fixedpoint.observer_bank import observer_bank_model

    s, te, gd = tapped
    m = observer_bank_model(s)
    assert hasattr(m, "taps") and [t for t in m.taps.dims] == [(0, 0), (1, 1), (1, 0)]
    codes, _ = m.quantize_signals(te.u, te.y)
    hw = m.core.to_physical_output(m.evaluate(codes)[0])
    ref = m.reference(codes)
    assert hw.shape == ref.shape == (300 - m.first_output, 1)
    assert np.abs(hw - ref).max() <= m.error_bound[0]
    man = load_manifest(gd.outdir)
    fe = man["front_end"]
    assert [t["lag"] for t in fe["taps"]["taps"]] == [0, 1, 0] and man["lags"]["My"] == 2 and man["lags"]["Mu"] == 1
    assert man["lags"]["regressors"] == s._regressor_names(s.lags_) and len(man["lags"]["regressors"]) == 6
    assert man["lags"]["warmup"]["samples_without_output"] == fe["first_output_sample"] == m.first_output
    assert build_design(s, design="sensor").files == gd.files  # byte-identical reruns
    r = lint_verilog(gd.outdir / "pwas_sensor.v", "pwas_sensor")
    assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[:2000]


@pytest.mark.parametrize("simulator, state_bits", [("icarus", 10)])  # both simulators, more layouts: benchmarks/bank_taps_rtl.py
def test_tapped_rtl_bit_exact(tapped, simulator, state_bits, tmp_path, sim_cache):
    """Full speed, stalls with a reset mid-stream, full-scale out-of-range inputs; 10-bit states saturate."""
    from pwas_hdl.design.generate import generate
    from pwas_hdl.verify.simulation import load_design, run_rtl, standard_runs

    s, te, gd = tapped
    out = gd.outdir if state_bits is None else generate(s, tmp_path / "sat", design="sensor", state_bits=state_bits).outdir
    d = load_design(out)
    codes, _ = d.bank.quantize_signals(te.u[:200], te.y[:200])
    rng = np.random.default_rng(1)
    wild = rng.choice([-2048, 2047], size=(30, codes.shape[1]))
    codes = np.vstack([codes, wild, codes[:40]])
    sat = d.bank.bank.trace(codes)["state_saturated"]
    assert bool(sat.any()) == (state_bits is not None)
    res = run_rtl(d, standard_runs(d, codes), simulator, cache_dir=sim_cache)
    assert res.passed, res.report()
    assert res.mismatches == 0 and res.outputs >= 2 * (len(codes) - d.warmup)  # full speed, stalls, the cut prefix
    assert set(res.latencies) == {d.latency} and res.ii == 1.0


TAPPED_SERIAL = {  # --architecture serial with the u/y taps: 1 lane with saturating 10-bit states, 2 lanes unsaturated
    "serial-1lane-saturating": dict(bank_lanes=1, state_bits=10),
    "serial-2lanes": dict(bank_lanes=2),
}


@pytest.mark.parametrize("simulator, config", [("icarus", "serial-1lane-saturating"), ("verilator", "serial-2lanes")])
def test_tapped_serial_rtl_bit_exact(tapped, simulator, config, tmp_path, sim_cache):
    """The tapped sensor on the time-multiplexed bank: lint-clean, byte-identical reruns, the manifest's
    II = cycles_per_sample = the schedule's, and 0 mismatches against the (unchanged) bit-true model at
    full speed, with stalls and a reset mid-stream, full-scale out-of-range inputs; II and latency measured."""
    from pwas_hdl.design.generate import build_design, generate
    from pwas_hdl.flow.toolchain import lint_verilog
    from pwas_hdl.verify.simulation import load_design, run_rtl, standard_runs

    s, te, _ = tapped
    opts = dict(TAPPED_SERIAL[config])
    g = generate(s, tmp_path / "d", design="sensor", architecture="serial", **opts)
    assert build_design(s, design="sensor", architecture="serial", **opts).files == g.files
    lint = lint_verilog(tmp_path / "d" / f"{g.top}.v", g.top)
    assert lint.returncode == 0 and "%Warning" not in lint.stderr, lint.stderr[:2000]
    man = g.manifest
    fe = man["front_end"]
    sch = fe["schedule"]
    assert fe["bank"] == "serial" and "taps" in fe and sch["lanes"] == opts["bank_lanes"]
    n_core = 3 + 3  # 3 features + 3 taps: the serial core takes n + 1 cycles
    assert man["ii"] == fe["ii"] == fe["cycles_per_sample"] == max(sch["steps"], sch["stages_before_core"], n_core + 1) > 1
    assert man["latency_cycles"] == fe["stages_before_core"] + g.component.core.latency
    d = load_design(tmp_path / "d")
    codes, _ = d.bank.quantize_signals(te.u[:120], te.y[:120])
    rng = np.random.default_rng(2)
    codes = np.vstack([codes, rng.choice([-2048, 2047], size=(20, codes.shape[1])), codes[:30]])
    assert bool(d.bank.bank.trace(codes)["state_saturated"].any()) == ("state_bits" in opts)
    res = run_rtl(d, standard_runs(d, codes), simulator, cache_dir=sim_cache)
    assert res.passed, res.report()
    assert res.mismatches == 0 and res.outputs >= 2 * (len(codes) - d.warmup)
    assert set(res.latencies) == {d.latency} and res.ii == float(man["ii"])
