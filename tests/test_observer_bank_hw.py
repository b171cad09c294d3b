"""Bit-true observer-bank front end (pwas_hdl.fixedpoint.observer_bank): bounds, running sum, saturation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pwas_hdl.errors import InputError
from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.fixedpoint.observer_bank import ObserverBankSensorModel, isqrt_floor, l1_gain
from pwas_hdl.systems.pv_benchmark import make_pv_dataset


@pytest.fixture(scope="module")
def pv_data():
    return make_pv_dataset("pv-benchmark", 2500, 800, seed=1)


def _sensor(data, n_models=3, observer="deadbeat", features="11b", p=3):
    tr, _, _ = data
    fe = ObserverBankFrontEnd(n_models=n_models, observer=observer, features=features)
    return PWASVirtualSensor(mu=0, my=0, partitions=p, gamma=1.0, front_end=fe, sigma=1e-3).fit(tr.u, tr.y, tr.z)


@pytest.fixture(scope="module")
def sensor_11b(pv_data):
    return _sensor(pv_data)


def _check_bounds(hm, data):
    _, te, _ = data
    codes, _ = hm.quantize_signals(te.u, te.y)
    tr = hm.trace(codes)
    assert not tr["state_saturated"].any()
    b = hm.bank
    ff = b.float_features(codes)
    fhw = np.stack([f.to_physical(tr["feature_codes"][b.first_output:, j]) for j, f in enumerate(b.feature_inputs)], 1)
    lo, hi = hm.core.grid.lo, hm.core.grid.hi  # the bound is on the features the core uses: clamped to the domain
    err_f = np.abs(np.clip(fhw, lo, hi) - np.clip(ff, lo, hi)).max(axis=0)
    bound_f = np.array(b.feature_error_bound)
    assert np.all(err_f <= bound_f)
    assert np.all(err_f >= 0.3 * bound_f)  # the bound is tight on data (measured 0.6 - 0.9 of it)
    out = hm.core.to_physical_output(tr["out"])
    ref = hm.reference(codes)
    err = np.abs(out - ref).max(axis=0)
    assert np.all(err <= np.array(hm.error_bound))
    assert np.all(err >= 0.05 * np.array(hm.error_bound))
    return err


def test_bounds_11b_deadbeat(pv_data, sensor_11b):
    _check_bounds(ObserverBankSensorModel.from_sensor(sensor_11b), pv_data)


@pytest.mark.parametrize("observer,features", [("deadbeat", "11b-sq"), ("poles:0.4", "11b"), ("kalman:1", "11b")])
def test_bounds_other_gains_and_squared_feature(pv_data, observer, features):
    _check_bounds(ObserverBankSensorModel.from_sensor(_sensor(pv_data, 2, observer, features)), pv_data)


def test_running_sum_is_the_window_sum_and_isqrt_exact(pv_data, sensor_11b):
    hm = ObserverBankSensorModel.from_sensor(sensor_11b)
    _, te, _ = pv_data
    codes, _ = hm.quantize_signals(te.u[:200], te.y[:200])
    tr = hm.trace(codes)
    lw = hm.bank.window
    sq = [[int(v) for v in col] for col in tr["square"].T]
    for j, col in enumerate(sq):
        for k in range(len(col)):
            assert tr["window_sum"][k, j] == sum(col[max(0, k - lw): k + 1])
            assert tr["root"][k, j] == math.isqrt(int(tr["window_sum"][k, j]))
    rng = np.random.default_rng(0)
    a = rng.integers(0, 2**62, size=2000, dtype=np.int64)
    a[:4] = [0, 1, 2**62 - 1, (2**31 - 1) ** 2]
    assert [int(v) for v in isqrt_floor(a)] == [math.isqrt(int(v)) for v in a]


def test_state_bound_reaches_no_saturation_and_narrow_states_saturate(pv_data, sensor_11b):
    _, te, _ = pv_data
    wide = ObserverBankSensorModel.from_sensor(sensor_11b)
    # largest inputs the codes hold, alternating: no saturation at the default width
    hb = wide.bank
    t = 300
    lo, hi = -(1 << (hb.input_bits - 1)), (1 << (hb.input_bits - 1)) - 1
    codes = np.where((np.arange(t)[:, None] // 3) % 2 == 0, hi, lo).repeat(hb.nu + 1, axis=1).astype(np.int64)
    assert not wide.bank.trace(codes)["state_saturated"].any()
    narrow = ObserverBankSensorModel.from_sensor(sensor_11b, state_bits=hb.formats.state_bits - 4)
    tr = narrow.bank.trace(codes)
    assert narrow.bank.state_may_saturate and tr["state_saturated"].any()
    smax = (1 << (narrow.bank.formats.state_bits - 1)) - 1
    assert np.abs(tr["state"]).max() <= smax + 1


def test_state_update_is_the_documented_half_up_recursion(pv_data, sensor_11b):
    """x_i' = sat((A0_i x_0 + ((sum_c Bc_ic qu_c + Lc_i qy) << (F_s - F_in)) + Dc_i + (x_{i+1} << F_c)
    + 2**(F_c-1)) >> F_c), x_M = 0, from x = 0: recomputed step by step in Python integers."""
    _, te, _ = pv_data
    hm = ObserverBankSensorModel.from_sensor(sensor_11b)
    b = hm.bank
    codes, _ = hm.quantize_signals(te.u[:60], te.y[:60])
    tr = b.trace(codes)
    fc, sh = b.coef_frac, b.state_frac - b.input_frac
    smax = (1 << (b.formats.state_bits - 1)) - 1
    m = b.order
    for j in range(b.n_models):
        x = [0] * m
        for k in range(codes.shape[0]):
            assert [int(v) for v in tr["state"][k, j]] == x
            qu, qy = [int(v) for v in codes[k, : b.nu]], int(codes[k, b.nu])
            nxt = []
            for i in range(m):
                inj = sum(int(b.b_codes[j, i, c]) * qu[c] for c in range(b.nu)) + int(b.l_codes[j, i]) * qy
                acc = int(b.a0_codes[j, i]) * x[0] + (inj << sh) + int(b.d_codes[j, i]) + ((x[i + 1] if i + 1 < m else 0) << fc)
                nxt.append(max(-smax - 1, min(smax, (acc + (1 << (fc - 1))) >> fc)))
            x = nxt


def test_state_saturation_is_flagged_in_both_directions(pv_data, sensor_11b):
    """Narrow states follow the wide (never saturating) ones until an update leaves their range, and
    that update is flagged whichever rail it hits: constant top and bottom codes drive the states
    to both signs."""
    wide = ObserverBankSensorModel.from_sensor(sensor_11b).bank
    narrow = ObserverBankSensorModel.from_sensor(sensor_11b, state_bits=wide.formats.state_bits - 4).bank
    assert (narrow.coef_frac, narrow.state_frac) == (wide.coef_frac, wide.state_frac)
    smin, smax = -(1 << (narrow.formats.state_bits - 1)), (1 << (narrow.formats.state_bits - 1)) - 1
    lo, hi = -(1 << (wide.input_bits - 1)), (1 << (wide.input_bits - 1)) - 1
    sides = set()
    for level in (lo, hi):
        codes = np.full((200, wide.nu + 1), level, dtype=np.int64)
        tw, tn = wide.trace(codes), narrow.trace(codes)
        assert not tw["state_saturated"].any()
        leaves = [k for k in range(199) if np.any((tw["state"][k + 1] < smin) | (tw["state"][k + 1] > smax))]
        assert leaves, "the narrow states must saturate on this input"
        k0 = leaves[0]
        assert np.array_equal(tn["state"][: k0 + 1], tw["state"][: k0 + 1])
        assert not tn["state_saturated"][:k0].any() and tn["state_saturated"][k0]
        sides |= {"low" if np.any(tw["state"][k0 + 1] < smin) else "high"}
    assert sides == {"low", "high"}


def test_refusals(pv_data):
    tr, _, _ = pv_data
    fe = ObserverBankFrontEnd(n_models=2, features="11a", window=2)
    s = PWASVirtualSensor(mu=0, my=0, partitions=1, gamma=1.0, front_end=fe, sigma=1e-3).fit(tr.u, tr.y, tr.z)
    with pytest.raises(InputError, match="11b"):
        ObserverBankSensorModel.from_sensor(s)
    fe = ObserverBankFrontEnd(n_models=2)
    s = PWASVirtualSensor(mu=1, my=1, partitions=2, gamma=1.0, front_end=fe, sigma=1e-3).fit(tr.u, tr.y, tr.z)
    with pytest.raises(InputError, match="taps"):
        ObserverBankSensorModel.from_sensor(s)
    with pytest.raises(InputError, match="stable"):
        l1_gain(np.array([[1.0]]), np.ones((1, 1)))
    # an unstable observer (e.g. front_end.models / gains edited in the model file): its terms reached inf
    # and l1_gain returned an infinite bound (generate then failed with OverflowError, exit 3)
    with pytest.raises(InputError, match="not stable"):
        l1_gain(np.array([[0.0, 1.0], [-1.5, 2.4]]), np.eye(2))
    with pytest.raises(InputError, match="not stable"):
        l1_gain(np.array([[np.nan]]), np.ones((1, 1)))
    d = _sensor(pv_data, n_models=2).to_dict()
    d["front_end"]["gains"][0][0] = 0.0
    with pytest.raises(InputError, match="an observer of the bank is not stable"):
        ObserverBankSensorModel.from_sensor(PWASVirtualSensor.from_dict(d))


def test_bare_core_of_a_bank_sensor_is_refused_before_any_hardware(sensor_11b, tmp_path):
    """`generate --design core` of an observer-bank model: a clear refusal (it once built the core, then
    failed its own manifest check as an internal error)."""
    from pwas_hdl.design.generate import build_design

    with pytest.raises(InputError, match=r"--design core of an observer-bank sensor.*--design sensor"):
        build_design(sensor_11b, design="core")


def test_input_width_refusal_names_the_option(sensor_11b):
    with pytest.raises(InputError, match=r"--input-bits \(input_bits\) = 30: an observer-bank design needs 4\.\.24"):
        ObserverBankSensorModel.from_sensor(sensor_11b, input_bits=30)


def test_seed003_estimator_bittrue_within_bounds():
    from pwas_hdl.fixedpoint.observer_bank import FixedPointSwitchedEstimator
    from pwas_hdl.systems.switched_linear import SWITCHED_A, SWITCHED_B, SWITCHED_C, switched_paper_run, switched_training_runs
    from pwas_hdl.systems.switched_observer import observer_gains

    est = FixedPointSwitchedEstimator(SWITCHED_A, SWITCHED_B, SWITCHED_C, observer_gains())
    assert est.state_error_bound is not None and not est.state_may_saturate
    rep = switched_paper_run(seed=0, switching="time", input_kind="step", noise=0.02)
    long = switched_training_runs(1, 1000, seed=5000, switching="time", noise=0.01)
    for d in (rep, long):
        codes = est.quantize_signals(d.u, d.y)
        tr, ref = est.trace(codes), est.reference(codes)
        ws = np.sort(ref.residuals, axis=1)
        margin = ws[:, 1] - ws[:, 0]
        differ = tr["theta"] != ref.theta_hat
        assert not np.any(differ & (margin > 2 * est.sum_error_bound))  # modes differ only at near-ties
        if not differ.any():  # the same modes: the state error bound holds (and is not vacuous)
            err = np.abs(est.to_physical_state(tr["x_hat"]) - ref.x_hat).max()
            assert err <= est.state_error_bound
            yerr = np.abs(tr["y_hat"] * 2.0**-est.state_frac - ref.y_hat).max()
            assert yerr <= est.output_error_bound
    # the paper replica (Table 1 setting): same modes, output MSE equal within the bound
    codes = est.quantize_signals(rep.u, rep.y)
    tr, ref = est.trace(codes), est.reference(codes)
    assert np.array_equal(tr["theta"], ref.theta_hat)
    y = rep.y[:, 0]
    m_hw, m_f = np.mean((y - tr["y_hat"] * 2.0**-est.state_frac) ** 2), np.mean((y - ref.y_hat) ** 2)
    assert abs(m_hw - m_f) <= 2 * math.sqrt(m_f) * est.output_error_bound + est.output_error_bound**2


def test_observer_bank_hw_bench_refuses_bad_options(tmp_path, capsys):
    """benchmarks/observer_bank_hw.py (--architecture serial, --bank-lanes): bad values refused before any
    fit; the script gives one error: line, exit 2 and writes nothing."""
    from pwas_hdl import bench_results as br
    from pwas_hdl.benchmarks import observer_bank_hw as ob

    for kw, msg in ((dict(architecture="bogus"), "--architecture"), (dict(bank_lanes=2), "--bank-lanes"),
                    (dict(architecture="serial", bank_lanes=0), "--bank-lanes"), (dict(runs=0), "--runs"),
                    (dict(systems=("battery",)), "systems")):
        with pytest.raises(InputError, match=msg):
            ob.run(progress=None, **kw)
    rc = br.script_main(ob.main, ["--architecture", "serial", "--bank-lanes", "0", "--outdir", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("error:") and not (tmp_path / "o").exists()


def test_observer_bank_summary_reads_the_results_and_refuses_mixed_designs(tmp_path):
    """benchmarks/observer_bank_summary.py: one row per system from the committed results; a synthesis
    row whose II differs from the RTL bench's (results of different designs) is refused."""
    import json
    import shutil

    from pwas_hdl.benchmarks import observer_bank_summary as sm
    from pwas_hdl.resources import benchmarks_dir

    rows = sm.collect()
    assert [r["system"] for r in rows][:3] == ["pv-benchmark", "switching-4", "battery"]
    assert all(r["synth"] is not None and r["mismatches"].startswith("0 /") for r in rows)
    text = sm.markdown(rows)
    assert text.count("\n") == 2 + len(rows)
    for name in ("observer_bank_hw_serial.json", "observer_bank_synth.json", "battery_rtl_serial.json",
                 "switched_estimator_hw.json", "switched_estimator_serial_synth_ecp5.json"):
        shutil.copy(benchmarks_dir() / "results" / name, tmp_path / name)
    doc = json.loads((tmp_path / "observer_bank_synth.json").read_text())
    for r in doc["rows"]:
        if r["design"] == "pfeat-n5-p6-11b" and r["target"] == "ecp5":
            r["ii"] += 1
    (tmp_path / "observer_bank_synth.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="pv-benchmark.*differs"):
        sm.markdown(sm.collect(tmp_path))


def test_cli_generate_sets_the_bank_formats_and_refuses_them_elsewhere(pv_data, sensor_11b, tmp_path):
    """`generate --state-bits/--state-frac/--coef-frac/--input-headroom` reach the bank (they were
    API-only, while the width refusal told CLI users to change them); a plain PWAS model refuses them."""
    import json

    from helpers.cli import CliRunner
    from helpers.folders import tree

    from pwas_hdl.cli import app

    run = CliRunner()
    model = tmp_path / "bank.json"
    sensor_11b.save(model)
    default = ObserverBankSensorModel.from_sensor(sensor_11b).bank.formats
    want = dict(state_bits=default.state_bits + 3, state_frac=default.state_frac + 2, coef_frac=default.coef_frac - 1)
    res = run.invoke(app, ["generate", str(model), "--design", "sensor", "-o", str(tmp_path / "hw"),
                           "--state-bits", str(want["state_bits"]), "--state-frac", str(want["state_frac"]),
                           "--coef-frac", str(want["coef_frac"]), "--input-headroom", "4"])
    assert res.exit_code == 0, res.output
    man = json.loads((tmp_path / "hw" / "manifest.json").read_text())
    got = man["front_end"]["formats"]
    assert {k: got[k] for k in want} == want
    assert got["input_frac"] == default.input_frac + 1  # head room 4 instead of 8: one more input fraction bit
    assert man["generator"]["options"]["input_headroom"] == 4.0
    # the bit-true model that simulate rebuilds from the manifest's options has the same formats
    ref = ObserverBankSensorModel.from_sensor(sensor_11b, input_headroom=4.0, **want).bank.formats
    assert ref.state_frac == got["state_frac"] and ref.acc_bits == got["acc_bits"]

    tr, _, _ = pv_data
    plain = tmp_path / "plain.json"
    PWASVirtualSensor(mu=0, my=1, partitions=2, sigma=1e-3).fit(tr.u, tr.y, tr.z).save(plain)
    before = tree(tmp_path)
    res = run.invoke(app, ["generate", str(model), "--design", "sensor", "-o", str(tmp_path / "hw2"), "--state-frac", "2"])
    assert res.exit_code == 2 and res.output.startswith("error: --state-frac (state_frac) = 2 must be >= the input "
                                                        "fraction bits"), res.output
    for opt, val in (("--state-bits", "16"), ("--state-frac", "8"), ("--coef-frac", "12"), ("--input-headroom", "2")):
        res = run.invoke(app, ["generate", str(plain), "-o", str(tmp_path / "hw3"), opt, val])
        assert res.exit_code == 2, res.output
        assert res.output.strip() == (f"error: {opt} ({opt[2:].replace('-', '_')}) sets a format of the observer bank: it "
                                      "applies to observer-bank sensors (fit --front-end observer-bank) and estimator "
                                      "files only"), res.output
    assert tree(tmp_path) == before


def test_width_refusal_states_the_formats_it_tried(sensor_11b):
    """A bank datapath over 62 bits is refused with the F_s, B_s and head room that led there and the
    smallest F_s allowed: the line said only 'give fewer state fraction bits', so a user of the
    default formats (three-tank + fit --front-end observer-bank) had no value to start from."""
    default = ObserverBankSensorModel.from_sensor(sensor_11b).bank.formats
    with pytest.raises(InputError) as exc:
        ObserverBankSensorModel.from_sensor(sensor_11b, state_frac=40)
    msg = str(exc.value)
    assert "would need" in msg and "more than 62" in msg and "F_s = 40" in msg and "B_s = " in msg
    assert "input head room 8" in msg and f"at least the input fraction bits {default.input_frac}" in msg
    assert "--state-frac (state_frac)" in msg and "--input-headroom (input_headroom)" in msg


def test_hdl_width_guards_are_internal_errors():
    """The observer-bank HDL builders' width checks guard the formats' plan (which sizes every product for
    its constants; no option or model-file edit reaches them): a failure is a bug (InternalError, exit 3),
    not a plain ValueError that the CLI reported as bad input."""
    from amaranth.hdl import Module, Signal, signed

    from pwas_hdl.errors import InternalError
    from pwas_hdl.hdl.observer_bank import const_product
    from pwas_hdl.hdl.serial_observer_bank import var_product

    m = Module()
    m._MustUse__silence = True  # never elaborated
    with pytest.raises(InternalError, match="constant 1000 does not fit 2 bits"):
        const_product(m, 1000, Signal(signed(4)), 6, "p")
    with pytest.raises(InternalError, match="a 4 x 4-bit product does not fit 6 bits"):
        var_product(m, Signal(signed(4)), Signal(signed(4)), 6, "p")


def test_parallel_root_is_pipelined(sensor_11b):
    """The parallel bank's square root had no register (feature sum -> root register in one cycle:
    86 ns on the ECP5, 11.6 MHz); now a register every ``isqrt_every`` digit steps, loading with the
    core's enable, and a feature-code register after the affine map; the input products and their sum
    are registered in front of the state update (s_in, s_in2), the residuals and their squares in front
    of the window sums (s_res, s_sq), the capped root and the product inside the affine map:
    stages_before_core = 9 + R. ``isqrt_every=None`` keeps the root combinational; a bad value is refused."""
    from pwas_hdl.fixedpoint.observer_bank import observer_bank_model
    from pwas_hdl.hdl.observer_bank_top import FRONT_END_STAGES
    from pwas_hdl.hdl.observer_sensor_top import build_observer_sensor
    from pwas_hdl.hdl.serial_observer_bank import isqrt_registers

    model = observer_bank_model(sensor_11b)
    pairs = (model.bank.formats.sum_bits + 1) // 2
    for every in (3, 1, 5, None):
        top = build_observer_sensor(model, isqrt_every=every)
        r = isqrt_registers(model.bank, every)
        assert r == (0 if every is None else (pairs - 1) // every)
        fe = top.extra_info["front_end"]
        assert top.stages_before_core == FRONT_END_STAGES + r == 9 + r and fe["isqrt_registers"] == r
        assert fe["isqrt_every"] == every and top.latency == top.stages_before_core + top.core.latency and top.ii == 1
    for bad in (0, -1, 2.5, True):
        with pytest.raises(InputError, match="isqrt_every must be a positive integer or None"):
            build_observer_sensor(model, isqrt_every=bad)
