"""Observer-bank sensors in hardware (issue 12): generate, manifest, lint, and 0 mismatches on Icarus and Verilator.

CI runs 2 configurations on Icarus and 1 on Verilator; ``benchmarks/observer_bank_rtl.py`` runs
the >= 6 configurations (N_theta 2..7, M 2..5, deadbeat / poles / Kalman, 11b and 11b-sq) on both.
"""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from pwas_hdl.cli import main
from pwas_hdl.design.generate import build_design, generate
from pwas_hdl.design.manifest import load_manifest
from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.systems.pv_benchmark import make_pv_dataset
from pwas_hdl.verify.simulation import load_design, run_rtl, sim_module, standard_runs


@pytest.fixture(scope="module")
def pv_small():
    return make_pv_dataset("pv-benchmark", 2000, 300, seed=0)


def _fit(data, n_models=3, observer="deadbeat", features="11b", order=5, mu=0, my=0):
    tr, _, _ = data
    fe = ObserverBankFrontEnd(n_models=n_models, observer=observer, features=features, order=order)
    return PWASVirtualSensor(mu=mu, my=my, partitions=3, gamma=1.0, front_end=fe, sigma=1e-3).fit(tr.u, tr.y, tr.z)


@pytest.fixture(scope="module")
def bank_sensor(pv_small):
    return _fit(pv_small)


def test_generate_observer_sensor_manifest_and_reruns(bank_sensor, tmp_path):
    a = generate(bank_sensor, tmp_path / "a", design="sensor")
    b = build_design(bank_sensor, design="sensor")
    assert a.files == b.files  # byte-identical reruns
    man = load_manifest(tmp_path / "a")
    fe = man["front_end"]
    assert fe["kind"] == "observer-bank" and fe["cycles_per_sample"] == 1 and fe["ii"] == 1 == man["ii"]
    assert man["latency_cycles"] == fe["stages_before_core"] + a.component.core.latency
    assert man["lags"]["warmup"]["samples_without_output"] == fe["first_output_sample"] == 5 + 7
    fields = man["ports"][[p["role"] for p in man["ports"]].index("in.payload")]["fields"]
    assert [f["name"] for f in fields] == ["u0", "u1", "y0"]
    assert all(f["format"]["frac"] == fe["formats"]["input_frac"] for f in fields)
    assert fe["error_bound"]["estimate"]["physical"][0] > man["error_bound"]["physical"]
    text = (tmp_path / "a" / "pwas_sensor.v").read_text()
    assert "observer bank: 3 observers of order 5 (deadbeat)" in text and "/tmp" not in text


def test_cli_generate_and_refusals(bank_sensor, pv_small, tmp_path, capsys):
    model = tmp_path / "bank.json"
    bank_sensor.save(model)
    assert main(["generate", str(model), "--design", "sensor", "-o", str(tmp_path / "d")]) == 0
    assert json.loads((tmp_path / "d" / "manifest.json").read_text())["front_end"]["feature_map"] == "11b"
    capsys.readouterr()
    # --clock-mhz is searched for bank sensors too now (tests/test_timing_closure_kinds.py)
    assert main(["generate", str(model), "--design", "core", "-o", str(tmp_path / "e")]) == 2
    err = capsys.readouterr().err  # bank sensors with u/y taps are built now (tests/test_bank_taps_hw.py)
    assert err.strip().startswith("error:") and len(err.strip().splitlines()) == 1 and "--design sensor" in err and not (tmp_path / "e").exists()


@pytest.mark.rtl
def test_verilog_lint_clean(bank_sensor, pv_small, tmp_path):
    from pwas_hdl.flow.toolchain import lint_verilog

    for i, s in enumerate((bank_sensor, _fit(pv_small, 2, "kalman:1", "11b-sq", order=3))):
        g = generate(s, tmp_path / f"l{i}", design="sensor")
        r = lint_verilog(tmp_path / f"l{i}" / f"{g.top}.v", g.top)
        assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[:2000]


@pytest.mark.rtl
@pytest.mark.parametrize("opts", [
    dict(pipeline="min", memory="corner", ports="amaranth"),
    dict(pipeline="max-lut", memory_init="readmemh", input_bits=7, state_bits=10),
    dict(pipeline="short", memory="replicated", rounding="truncate"),
], ids=["min-corner-amaranth", "maxlut-readmemh-7bit-state10", "short-replicated-truncate"])
def test_option_sets_lint_clean_and_byte_identical(bank_sensor, tmp_path, opts):
    """The bank sensor behind other pipelines, memories, ports and widths than the default build the lint
    tests above use: clean under verilator -Wall and byte-identical when built again."""
    from pwas_hdl.flow.toolchain import lint_verilog

    g = generate(bank_sensor, tmp_path / "d", design="sensor", **opts)
    assert build_design(bank_sensor, design="sensor", **opts).files == g.files
    r = lint_verilog(tmp_path / "d" / f"{g.top}.v", g.top)
    assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[:2000]


CONFIGS = {  # the first with a register every 2 digit steps of the root (generate --isqrt-every 2; default 3 elsewhere)
    "n3-m5-deadbeat-11b-root2": dict(n_models=3, observer="deadbeat", features="11b", order=5, isqrt_every=2),
    "n2-m3-kalman-11bsq-saturating": dict(n_models=2, observer="kalman:1", features="11b-sq", order=3, state_bits=14),
}


@pytest.mark.rtl
@pytest.mark.parametrize("simulator,config", [("icarus", "n3-m5-deadbeat-11b-root2"), ("icarus", "n2-m3-kalman-11bsq-saturating"),
                                              ("verilator", "n2-m3-kalman-11bsq-saturating")])
def test_rtl_bit_exact(pv_small, tmp_path, sim_cache, simulator, config):
    cfg = dict(CONFIGS[config])
    opts = {k: cfg.pop(k) for k in ("state_bits", "isqrt_every") if k in cfg}
    s = _fit(pv_small, **cfg)
    generate(s, tmp_path / "d", design="sensor", **opts)
    d = load_design(tmp_path / "d")
    if "isqrt_every" in opts:  # the root's registers as asked, counted in the latency the stream shows below
        fe = d.manifest["front_end"]
        assert fe["isqrt_every"] == opts["isqrt_every"] == d.manifest["generator"]["options"]["isqrt_every"]
        assert fe["isqrt_registers"] == ((fe["formats"]["sum_bits"] + 1) // 2 - 1) // opts["isqrt_every"]
    _, te, _ = pv_small
    data, _ = d.bank.quantize_signals(te.u, te.y)
    codes = sim_module("pwas_stimulus").observer_codes(d.bank.bank, 360, seed=3, data=data)
    saturating = d.bank.bank.trace(codes)["state_saturated"]
    assert saturating.any() == ("state_bits" in opts)
    r = run_rtl(d, standard_runs(d, codes), simulator, cache_dir=sim_cache)
    assert r.passed, r.report()
    assert r.mismatches == 0 and r.outputs > 900
    assert set(r.latencies) == {d.latency} and r.ii == 1.0
    if "state_bits" not in opts:
        assert r.within_bound  # the core's bound at the feature codes


def test_isqrt_every_option_and_refusals(bank_sensor, pv_small, tmp_path, capsys):
    """generate --isqrt-every K: the root's registers every K digit steps (parallel and serial bank), in
    the manifest and the latency; refused with one error line and nothing written when it is not a
    positive integer, for a model without a bank and for the 11b-sq map (no root)."""
    model = tmp_path / "bank.json"
    bank_sensor.save(model)
    lat = {}
    for k in (1, 3):
        assert main(["generate", str(model), "--design", "sensor", "--isqrt-every", str(k), "-o", str(tmp_path / f"d{k}")]) == 0
        man = json.loads((tmp_path / f"d{k}" / "manifest.json").read_text())
        fe = man["front_end"]
        pairs = (fe["formats"]["sum_bits"] + 1) // 2
        assert fe["isqrt_every"] == k == man["generator"]["options"]["isqrt_every"] and fe["isqrt_registers"] == (pairs - 1) // k
        lat[k] = man["latency_cycles"]
    assert lat[1] - lat[3] == (pairs - 1) - (pairs - 1) // 3  # the same design but for the root's registers
    # the default build records no option (it rebuilds as before) and equals --isqrt-every 3 but for that entry
    assert build_design(bank_sensor, design="sensor").manifest["front_end"]["isqrt_every"] == 3
    top = build_design(bank_sensor, design="sensor", architecture="serial", isqrt_every=2).manifest["front_end"]["schedule"]
    assert top["isqrt_every"] == 2
    capsys.readouterr()
    plain = tmp_path / "plain.json"
    tr, _, _ = pv_small
    PWASVirtualSensor(mu=1, my=1, partitions=3, sigma=1e-3).fit(tr.u, tr.y, tr.z).save(plain)
    sq = tmp_path / "sq.json"
    _fit(pv_small, 2, "deadbeat", "11b-sq", order=2).save(sq)
    for m, val, words in ((model, "0", "positive integer"), (model, "-2", "positive integer"),
                          (model, str(pairs), f"has {pairs} digit steps"), (model, "10" * 12, "no register inside"),
                          (plain, "2", "has no observer bank"), (sq, "2", "11b-sq")):
        out = tmp_path / "bad"
        assert main(["generate", str(m), "--design", "sensor", "--isqrt-every", val, "-o", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("error:") and len(err.splitlines()) == 1 and "--isqrt-every" in err and words in err, err
        assert not out.exists()


def test_serial_bank_manifest_and_refusals(bank_sensor, tmp_path):
    """--architecture serial: the time-multiplexed bank's II in the design info (front_end and top) without
    elaborating; bad --bank-lanes refused before anything is written (the manifest itself: the rtl tests)."""
    from typer.testing import CliRunner

    from pwas_hdl.cli import app
    from pwas_hdl.errors import InputError
    from pwas_hdl.fixedpoint.observer_bank import observer_bank_model
    from pwas_hdl.hdl.api import design_info
    from pwas_hdl.hdl.observer_sensor_top import build_observer_sensor

    top = build_observer_sensor(observer_bank_model(bank_sensor), architecture="serial")
    info = design_info(top, "axis")
    fe = info["front_end"]
    sch = fe["schedule"]
    assert fe["bank"] == "serial" and sch["lanes"] == 1 and sch["steps"] == 3 * 5
    # N M steps + the flush of the pipelined update, or half the feature pipeline's tail (double-buffered
    # codes: two samples between input and core), or the last window sum's read of the slot, or the core's n + 1
    assert sch["double_buffered_codes"] is True
    ii = max(15 + 1, -(-sch["stages_before_core"] // 2), 2 * 5 + 3, 3 + 1)
    assert fe["cycles_per_sample"] == fe["ii"] == info["ii"] == ii == 16 < sch["stages_before_core"]
    assert info["latency"] == fe["stages_before_core"] + top.core.latency
    assert "bank idle" in info["flow_control"]["s_axis_tready"]
    two = build_observer_sensor(observer_bank_model(bank_sensor), architecture="serial", lanes=2)
    assert two.plan.lanes == ((0, 1), (2,)) and two.ii < top.ii
    with pytest.raises(InputError, match="bank lanes"):
        build_design(bank_sensor, design="sensor", architecture="serial", bank_lanes=4)
    with pytest.raises(InputError, match="--architecture serial"):
        build_design(bank_sensor, design="sensor", bank_lanes=2)
    model = tmp_path / "bank.json"
    bank_sensor.save(model)
    r = CliRunner().invoke(app, ["generate", str(model), "--design", "sensor", "--architecture", "serial", "--bank-lanes", "0",
                                 "-o", str(tmp_path / "bad")])
    assert r.exit_code == 2 and r.output.strip().startswith("error:") and "bank lanes" in r.output and not (tmp_path / "bad").exists()


SERIAL_CONFIGS = {  # the time-multiplexed bank: a0 != 0, saturating states, 11b-sq; 2 lanes, 11b, isqrt pipeline
    # (CI: Icarus; benchmarks/observer_bank_rtl.py runs the serial configurations on Verilator too)
    "serial-n2-m3-kalman-11bsq-saturating": dict(n_models=2, observer="kalman:1", features="11b-sq", order=3, state_bits=14, bank_lanes=1),
    "serial-n3-m3-poles-11b-2lanes": dict(n_models=3, observer="poles:0.4", features="11b", order=3, bank_lanes=2),
}


@pytest.mark.rtl
@pytest.mark.parametrize("simulator,config", [("icarus", "serial-n2-m3-kalman-11bsq-saturating"),
                                              ("icarus", "serial-n3-m3-poles-11b-2lanes")])
def test_serial_bank_rtl_bit_exact(pv_small, tmp_path, sim_cache, simulator, config):
    from pwas_hdl.flow.toolchain import lint_verilog

    cfg = dict(SERIAL_CONFIGS[config])
    opts = {k: cfg.pop(k) for k in ("state_bits", "bank_lanes") if k in cfg}
    s = _fit(pv_small, **cfg)
    g = generate(s, tmp_path / "d", design="sensor", architecture="serial", **opts)
    if "state_bits" in opts:  # byte-identical reruns
        assert build_design(s, design="sensor", architecture="serial", **opts).files == g.files
    lint = lint_verilog(tmp_path / "d" / f"{g.top}.v", g.top)
    assert lint.returncode == 0 and "%Warning" not in lint.stderr, lint.stderr[:2000]
    d = load_design(tmp_path / "d")
    ii = d.manifest["ii"]
    assert ii == d.manifest["front_end"]["cycles_per_sample"] > 1
    _, te, _ = pv_small
    data, _ = d.bank.quantize_signals(te.u, te.y)
    codes = sim_module("pwas_stimulus").observer_codes(d.bank.bank, 200, seed=4, data=data)
    assert d.bank.bank.trace(codes)["state_saturated"].any() == ("state_bits" in opts)
    r = run_rtl(d, standard_runs(d, codes), simulator, cache_dir=sim_cache)
    assert r.passed, r.report()
    assert r.mismatches == 0 and r.outputs > 500
    assert set(r.latencies) == {d.latency} and r.ii == float(ii)  # in.ready honours the II at full speed


@pytest.mark.rtl
@pytest.mark.parametrize("window", [1, 3])
def test_seed003_estimator_rtl_bit_exact_and_lint(tmp_path, window):
    """Seed 003's estimator top (bank + argmin + switched observer) in Amaranth's simulator, with
    random bubbles and backpressure, against the bit-true model; its Verilog lint-clean."""
    from pwas_hdl.fixedpoint.observer_bank import FixedPointSwitchedEstimator
    from pwas_hdl.flow.toolchain import lint_verilog
    from pwas_hdl.hdl.emit import emit_verilog
    from pwas_hdl.hdl.switched_estimator_top import SwitchedEstimatorTop, simulate_estimator
    from pwas_hdl.systems.switched_linear import SWITCHED_A, SWITCHED_B, SWITCHED_C, switched_training_runs
    from pwas_hdl.systems.switched_observer import observer_gains

    est = FixedPointSwitchedEstimator(SWITCHED_A, SWITCHED_B, SWITCHED_C, observer_gains(), window=window)
    top = SwitchedEstimatorTop(est)
    (tmp_path / "switched_estimator.v").write_text(emit_verilog(top, "switched_estimator"))
    r = lint_verilog(tmp_path / "switched_estimator.v", "switched_estimator")
    assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[:2000]
    d = switched_training_runs(1, 150, seed=7, switching="time", noise=0.01)
    codes = est.quantize_signals(d.u, d.y)
    tr = est.trace(codes)
    res = simulate_estimator(top, codes, p_valid=0.7, p_ready=0.6, seed=window)
    assert np.array_equal(res["x_hat"], tr["x_hat"]) and np.array_equal(res["y_hat"], tr["y_hat"])
    assert np.array_equal(res["theta"], tr["theta"])
    assert np.array_equal(res["state_saturated"], tr["state_saturated"])


@pytest.mark.rtl
def test_estimator_whose_output_row_quantises_to_zero_builds_and_is_bit_exact():
    """A mode with a tiny C (every code of the row rounds to 0) made the RTL builder add over no
    terms (IndexError, exit 3 from generate); the row is the constant 0, as in the bit-true model."""
    from pwas_hdl.fixedpoint.observer_bank import FixedPointSwitchedEstimator
    from pwas_hdl.hdl.switched_estimator_top import SwitchedEstimatorTop, simulate_estimator
    from pwas_hdl.systems.switched_linear import SWITCHED_A, SWITCHED_B, SWITCHED_C, switched_training_runs
    from pwas_hdl.systems.switched_observer import observer_gains

    c = [np.array(ci, dtype=float) for ci in SWITCHED_C]
    k = [np.array(ki, dtype=float) for ki in observer_gains()]
    c[0] = np.array([1e-9, 0.0]).reshape(c[0].shape)
    k[0] = np.zeros_like(k[0])
    est = FixedPointSwitchedEstimator(SWITCHED_A, SWITCHED_B, c, k, window=1)
    assert not np.any(est.h_codes[0])
    d = switched_training_runs(1, 60, seed=2, switching="time", noise=0.01)
    codes = est.quantize_signals(d.u, d.y)
    tr = est.trace(codes)
    res = simulate_estimator(SwitchedEstimatorTop(est), codes, p_valid=0.8, p_ready=0.7, seed=1)
    assert np.array_equal(res["x_hat"], tr["x_hat"]) and np.array_equal(res["y_hat"], tr["y_hat"])
    assert np.array_equal(res["theta"], tr["theta"])


@pytest.mark.rtl
def test_cli_simulate_observer_sensor(bank_sensor, pv_small, tmp_path, sim_cache, monkeypatch):
    monkeypatch.setenv("PWAS_HDL_SIM_CACHE", str(sim_cache))
    _, te, _ = pv_small
    model = tmp_path / "bank.json"
    bank_sensor.save(model)
    ins, outs, tg = bank_sensor.signal_names()
    cols = {**{n: te.u[:, i] for i, n in enumerate(ins)}, outs[0]: te.y[:, 0], f"{tg[0]}_true": te.z_true[:, 0]}
    lines = [",".join(cols)] + [",".join(repr(float(c[k])) for c in cols.values()) for k in range(len(te.y))]
    (tmp_path / "test.csv").write_text("\n".join(lines) + "\n")
    assert main(["generate", str(model), "--design", "sensor", "-o", str(tmp_path / "d")]) == 0
    assert main(["simulate", str(tmp_path / "d"), str(tmp_path / "test.csv"), "-o", str(tmp_path / "hw.csv")]) == 0
    summ = json.loads((tmp_path / "hw.json").read_text())
    assert summ["mismatches"] == 0 and summ["checks"]["passed"] and summ["samples"] == len(te.y) - 12
    hw = np.genfromtxt(tmp_path / "hw.csv", delimiter=",", names=True)
    zf = bank_sensor.predict(te.u, te.y)[:, 0]
    assert np.allclose(hw[f"{tg[0]}_float"], zf)


@pytest.mark.slow
def test_switched_estimator_bench_quick_smoke():
    from pwas_hdl import bench_results as br
    from pwas_hdl.benchmarks.switched_estimator_hw import markdown, run

    doc, _ = run(runs=1, quick=True, progress=None)
    br.validate_results(doc)
    rtl = br.find_rows(doc, stage="rtl", metric="mse")
    assert rtl and all(r["config"]["mismatches"] == 0 for r in rtl)
    assert all(r["config"]["mode_differs_beyond_bound"] == 0 for r in br.find_rows(doc, stage="bittrue"))
    assert "| replica |" in markdown(doc)


def test_header_counts_cycles_in_words(bank_sensor):
    """The Verilog header of a serial bank sensor read '… 11 cycle per sample'; the count now agrees with its noun."""
    par = build_design(bank_sensor, design="sensor").files["pwas_sensor.v"]
    ser = build_design(bank_sensor, design="sensor", architecture="serial")
    n = ser.manifest["front_end"]["cycles_per_sample"]
    assert n > 1 and f"; {n} cycles per sample;" in ser.files["pwas_sensor.v"]
    assert "; 1 cycle per sample;" in par and "cycle(s)" not in par
