"""Seed 003's estimator time-multiplexed over one row unit (issue 12: ``generate EST.json --architecture serial``).

Fast tests: the refusals of the options (nothing is built). ``rtl`` tests: Amaranth's simulator
against the bit-true model for several configurations (modes 2..4, states 2..3, window 1 and > 1,
saturating states) with random bubbles and backpressure; the generated folder on Icarus and
Verilator through the manifest-driven cocotb bench (stalls, a reset mid-stream, out-of-range
inputs, latency and II measured equal to the manifest), lint and byte-identical reruns.
"""

from __future__ import annotations

import numpy as np
import pytest

from pwas_hdl.errors import InputError
from pwas_hdl.fit.estimator_file import SwitchedEstimatorConfig
from pwas_hdl.systems.switched_observer import estimator_config


def _random_config(modes: int, states: int, window: int, seed: int) -> SwitchedEstimatorConfig:
    """A switched linear system with stable modes and pole-placed observer gains (poles 0.3, 0.4, ..)."""
    from scipy.signal import place_poles

    rng = np.random.default_rng(seed)
    A, B, C, K = [], [], [], []
    for _ in range(modes):
        a = rng.normal(size=(states, states))
        a *= 0.9 / max(abs(np.linalg.eigvals(a)))
        c = rng.normal(size=states)
        k = place_poles(a.T, c[:, None], 0.3 + 0.1 * np.arange(states)).gain_matrix.reshape(-1)
        A.append(a)
        B.append(rng.normal(size=states))
        C.append(c)
        K.append(k)
    return SwitchedEstimatorConfig(A, B, C, K, window=window, input_name="u", output_name="y",
                                   state_names=[f"x{i + 1}" for i in range(states)], source={"system": "random test"})


def _stimulus(est, n: int, seed: int) -> np.ndarray:
    """Random-mode switched run of the estimator's own plant (noisy), then out-of-range inputs (saturated codes)."""
    rng = np.random.default_rng(seed)
    x = np.zeros(est.n)
    u = rng.uniform(-1.5, 1.5, n)
    y = np.empty(n)
    mode = 0
    for k in range(n):
        if k % 17 == 0:
            mode = int(rng.integers(est.n_modes))
        y[k] = est.C[mode] @ x + 0.02 * rng.normal()
        x = est.A[mode] @ x + est.B[mode] * u[k]
    wild = rng.choice([-1.0, 1.0], size=(20, 2)) * 40.0
    return est.quantize_signals(np.concatenate([u, wild[:, 0]]), np.concatenate([y, wild[:, 1]]))


def test_serial_estimator_option_refusals():
    from pwas_hdl.design.generate import build_design

    cfg = estimator_config()
    with pytest.raises(InputError, match=r"--bank-lanes must be an integer in 1 \.\. 3"):
        build_design(cfg, architecture="serial", bank_lanes=4)
    with pytest.raises(InputError, match="--bank-lanes applies to --architecture serial only"):
        build_design(cfg, bank_lanes=1)
    with pytest.raises(InputError, match="architecture"):
        build_design(cfg, architecture="systolic")


def test_serial_estimator_schedule_counts():
    from pwas_hdl.design.estimator import fixed_point_estimator
    from pwas_hdl.hdl.switched_estimator_top import serial_estimator_schedule

    est = fixed_point_estimator(estimator_config())
    sch = serial_estimator_schedule(est)
    # 3 modes, 2 states: 3 residual rows + 6 bank rows + y_hat + 2 observer rows + 1 (the product register)
    assert sch["cycles_per_sample"] == 13 and sch["latency"] == 14 and sch["row_unit_multipliers"] == 4
    assert sch["mac_pipeline"] == 1 and serial_estimator_schedule(est, 0)["cycles_per_sample"] == 12
    with pytest.raises(ValueError, match="mac_pipeline"):
        serial_estimator_schedule(est, 2)


# ------------------------------------------------------------------------------------------ rtl
_CONFIGS = [  # (modes, states, window, state_bits, seed, mac_pipeline, lanes)
    (2, 3, 1, None, 1, 1, 1),
    (4, 2, 3, None, 2, 1, 1),
    (3, 3, 4, 22, 3, 1, 1),  # 22-bit states: saturate in 1/3 of the samples (bank only in 17, switched observer only in 21)
    (3, 2, 2, 19, 4, 0, 1),  # without the product register; saturating (bank only in 7 samples, observer only in 3)
    (2, 1, 2, None, 5, 0, 1),  # one state: an idle step before the switched observer (the detector's latency)
    (4, 2, 3, None, 2, 1, 2),  # two lanes of 2 modes
    (3, 3, 4, 22, 3, 1, 3),  # one lane per mode, saturating
    (3, 2, 1, 19, 4, 0, 2),  # lanes of 2 and 1 modes, without the product register
]


@pytest.mark.rtl
@pytest.mark.parametrize("modes, states, window, state_bits, seed, mac_pipeline, lanes", _CONFIGS)
def test_serial_estimator_amaranth_bit_exact(modes, states, window, state_bits, seed, mac_pipeline, lanes):
    from pwas_hdl.design.estimator import fixed_point_estimator
    from pwas_hdl.hdl.switched_estimator_top import SerialSwitchedEstimatorTop, simulate_estimator

    est = fixed_point_estimator(_random_config(modes, states, window, seed), state_bits=state_bits)
    codes = _stimulus(est, 90, seed)
    tr = est.trace(codes)
    if state_bits is not None:  # some samples saturate, not all (the flag must follow the bank's and the observer's)
        assert 0 < tr["state_saturated"].sum() < len(codes)
    assert len(set(tr["theta"].tolist())) > 1  # the detector switches
    top = SerialSwitchedEstimatorTop(est, mac_pipeline=mac_pipeline, lanes=lanes)
    s0 = -(-modes // lanes)
    assert top.ii == max(s0 + s0 * states, s0 + mac_pipeline + 3) + 1 + states + mac_pipeline
    res = simulate_estimator(top, codes, p_valid=0.7, p_ready=0.5, seed=seed)
    assert np.array_equal(res["theta"], tr["theta"])
    assert np.array_equal(res["x_hat"], tr["x_hat"]) and np.array_equal(res["y_hat"], tr["y_hat"])
    assert np.array_equal(res["state_saturated"], tr["state_saturated"])


@pytest.fixture(scope="module")
def serial_folders(tmp_path_factory):
    from pwas_hdl.design.generate import generate
    from pwas_hdl.fit.estimator_file import write_estimator

    root = tmp_path_factory.mktemp("serial_est")
    out = {}
    for name, cfg, opts in (("seed003", estimator_config(window=1), {}),
                            ("m4w3sat", _random_config(4, 3, 3, 5), {"state_bits": 22, "ports": "amaranth", "bank_lanes": 2}),
                            ("m3lanes3", _random_config(3, 2, 1, 7), {"bank_lanes": 3})):  # lint only
        path = write_estimator(cfg, root / f"{name}.json")
        out[name] = (path, opts, generate(path, root / name, architecture="serial", **opts))
    return out


@pytest.mark.rtl
def test_serial_estimator_folder_manifest_lint_reruns(serial_folders, tmp_path):
    from pwas_hdl.design.generate import generate
    from pwas_hdl.design.manifest import load_manifest
    from pwas_hdl.flow.toolchain import lint_verilog

    path, opts, gd = serial_folders["seed003"]
    man = load_manifest(gd.outdir)
    e = man["estimator"]
    assert e["architecture"] == "serial" and man["ii"] == e["cycles_per_sample"] == 13 and man["latency_cycles"] == 14
    assert man["generator"]["options"]["architecture"] == "serial" and e["schedule"]["lanes"] == 1
    lanes = load_manifest(serial_folders["m4w3sat"][2].outdir)
    assert lanes["estimator"]["schedule"]["modes_per_lane"] == [[0, 1], [2, 3]] and lanes["ii"] == 2 + 2 * 3 + 1 + 3 + 1
    again = generate(path, tmp_path / "again", architecture="serial", **opts)
    assert again.files == gd.files
    for p, _, g in serial_folders.values():
        r = lint_verilog(g.outdir / "pwas_estimator.v", "pwas_estimator")
        assert r.returncode == 0 and "%Warning" not in r.stderr, r.stderr[:2000]
    assert "one sample every 13 clocks" in gd.files["pwas_estimator.v"]


@pytest.mark.rtl
@pytest.mark.parametrize("name, simulator", [("seed003", "icarus"), ("seed003", "verilator"), ("m4w3sat", "icarus"),
                                             ("m4w3sat", "verilator")])
def test_serial_estimator_rtl_bit_exact_stalls_reset_ii(serial_folders, name, simulator, sim_cache):
    from pwas_hdl.verify.estimator_simulation import load_estimator_design, replay_estimator

    _, opts, gd = serial_folders[name]
    design = load_estimator_design(gd.outdir)
    codes = _stimulus(design.est, 100, 11)
    assert np.abs(codes).max() == 1 << (design.est.input_bits - 1)  # out-of-range inputs reach the extreme codes
    tr = design.est.trace(codes)
    if "state_bits" in opts:
        assert 0 < tr["state_saturated"].sum() < len(codes)
    res = replay_estimator(design, codes, simulator, cache_dir=sim_cache)
    assert res["passed"], res.get("failures")
    assert res["mismatches"] == 0 and res["outputs_compared"] > 2 * len(codes)
    assert res["latency"] == [design.latency] and res["ii"] == [design.ii] and design.ii > 1
    hw = res["rtl"]["full-speed"][0]
    assert np.array_equal(hw["theta"], tr["theta"]) and np.array_equal(hw["x_hat"], tr["x_hat"])


@pytest.mark.rtl
def test_serial_estimator_lanes_tie_to_the_lowest_mode():
    """Modes 2 and 3 identical (always equal window sums), lanes (1, 2) and (3, 4): mode 3 is compared a
    step before mode 2, so the tie must be broken by the mode number (numpy.argmin), not by the order."""
    from pwas_hdl.design.estimator import fixed_point_estimator
    from pwas_hdl.hdl.switched_estimator_top import SerialSwitchedEstimatorTop, simulate_estimator

    cfg = _random_config(4, 2, 2, 6)
    for arr in (cfg.A, cfg.B, cfg.C, cfg.K):
        arr[2] = arr[1].copy()
    est = fixed_point_estimator(cfg)
    codes = _stimulus(est, 80, 6)
    tr = est.trace(codes)
    assert 2 in tr["theta"] and 3 not in tr["theta"]  # the tie happens and goes to mode 2
    res = simulate_estimator(SerialSwitchedEstimatorTop(est, lanes=2), codes, p_valid=0.8, p_ready=0.7, seed=6)
    assert np.array_equal(res["theta"], tr["theta"]) and np.array_equal(res["x_hat"], tr["x_hat"])
