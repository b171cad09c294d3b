"""`pwas-hdl explore` of observer-bank sensors (fit --front-end observer-bank, with and without u/y taps).

A point is the bit-true bank, feature unit and core from reset on each trajectory (what `generate`
builds and `simulate` replays): its estimates are compared here with `simulate`'s bit-true replay
(:func:`pwas_hdl.verify.simulation.segment` of the sensor top `build_design` makes, data rows
aligned by the manifest's warm-up as `simulate` aligns them); its resources with `build_design`'s
manifest and component. Tiny fits, a few points, no RTL simulation, no synthesis (a stub
synthesiser for ``--fpga``).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from helpers.cli import CliRunner, assert_refused
from helpers.folders import tree
from helpers.synth_stub import stub_synthesis

from pwas_hdl import cli
from pwas_hdl.design.generate import build_design
from pwas_hdl.errors import InputError
from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.fixedpoint.observer_bank import observer_bank_model
from pwas_hdl.flow.explore import _design_register_bits, bank_bittrue, check_result, explore
from pwas_hdl.io.csv_table import write_csv

RUNNER = CliRunner()

#: model -> fit options: the bank alone, with u/y taps, non-uniform
KINDS = {"bank": dict(my=0, partitions=3), "taps": dict(my=1, partitions=2),
         "pow2": dict(my=0, partitions=4, breakpoints="quantile-pow2")}


@pytest.fixture(scope="module")
def pv():
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    tr, te, _ = make_pv_dataset("pv-benchmark", 1500, 300, seed=0)
    return tr, te


@pytest.fixture(scope="module")
def fitted(pv):
    tr, _ = pv
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for kind, kw in KINDS.items():
            fe = ObserverBankFrontEnd(n_models=2, observer="deadbeat", features="11b", order=2)
            out[kind] = PWASVirtualSensor(mu=0, gamma=1.0, front_end=fe, sigma=1e-3, **kw).fit(tr.u, tr.y, tr.z)
    return out


def _two_trajectories(te):
    """The test set cut in two trajectories (a reset between them)."""
    return [te.u[:160], te.u[160:]], [te.y[:160], te.y[160:]], [te.z[:160], te.z[160:]]


def _simulate_replay(sensor, us, ys, zs, **formats):
    """What `simulate` computes bit-true for the sensor top of these formats: `segment` of each
    trajectory's codes, rows aligned by the manifest's warm-up (simulate's rows sl.start + warmup ..)."""
    from pwas_hdl.verify.simulation import Design, segment

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gd = build_design(sensor, design="sensor", **formats)
        bm = observer_bank_model(sensor, memory=gd.manifest["generator"]["options"]["memory"], **formats)
    design = Design(Path("."), gd.manifest, sensor, bm.core, Path("unused.v"), bm)
    outs, refs = [], []
    for u, y, z in zip(us, ys, zs):
        codes, _ = bm.quantize_signals(u, y)
        seg = segment(design, codes)
        outs.append(seg.expected)
        refs.append(z[design.warmup:])  # simulate: rows sl.start + (warmup + 1) - 1 .. sl.stop
    return bm, np.concatenate(outs), np.concatenate(refs)


@pytest.mark.parametrize("kind", list(KINDS))
def test_a_point_is_simulates_bit_true_replay_and_the_widest_matches_the_float_sensor(fitted, pv, kind):
    """explore's bit-true estimates are `simulate`'s (segment of the sensor top), its RMSEE is theirs
    against the same rows, and at the widest formats the bank sensor is within its bound of the float
    sensor and as accurate as it (RMSEE ratio within 1 % of 1)."""
    s = fitted[kind]
    _, te = pv
    us, ys, zs = _two_trajectories(te)
    dflt = observer_bank_model(s)
    fw, fo = dflt.core.weight_format.frac + 4, dflt.core.output_format.frac + 4
    res = explore(s, (us, ys, zs), input_bits=[16], weight_frac=[fw], output_frac=[fo])
    check_result(res)
    assert res["model"]["kind"] == "observer-bank"
    assert res["model"]["observer_bank"]["first_output_sample"] == dflt.first_output
    p = next(q for q in res["points"] if not q["is_default"])
    bm, expected, z = _simulate_replay(s, us, ys, zs, input_bits=16, weight_frac=fw, output_frac=fo)
    mine = np.concatenate([r["out"] for r in bank_bittrue(bm, list(zip(us, ys)))])
    np.testing.assert_array_equal(mine, expected)
    assert res["data"]["samples"] == len(z)
    rmsee = np.sqrt(np.mean((bm.core.to_physical_output(expected) - z) ** 2, axis=0))
    np.testing.assert_allclose(p["rmsee"], rmsee, rtol=1e-12)
    zf = np.concatenate([s.predict(u, y) for u, y in zip(us, ys)])
    np.testing.assert_allclose(res["float"]["rmsee"], np.sqrt(np.mean((zf - z) ** 2, axis=0)), rtol=1e-12)
    assert p["bound_holds"] and p["state_saturated"] == 0
    assert abs(p["rmsee_ratio"] - 1) < 0.01, p["rmsee_ratio"]
    assert max(p["rms_dev_float"]) < 0.05 * min(res["float"]["rmsee"])


@pytest.mark.parametrize("kind", list(KINDS))
def test_the_default_estimate_agrees_with_build_designs_manifest(fitted, pv, kind):
    """Memory, latency, the bank's state registers and constant multipliers are the manifest's;
    the register bits are the elaborated sensor top's (also for a point that is not the first of its
    bank format: the front end's registers are elaborated once per bank format)."""
    s = fitted[kind]
    _, te = pv
    dflt = observer_bank_model(s)
    fw0 = dflt.core.weight_format.frac
    res = explore(s, (te.u, te.y, te.z), input_bits=[12], weight_frac=[fw0 - 1, fw0],
                  output_frac=[dflt.core.output_format.frac])
    check_result(res)
    for p in res["points"]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gd = build_design(s, design="sensor", input_bits=p["input_bits"], weight_frac=p["weight_frac"],
                              output_frac=p["output_frac"])
        man, r, bk = gd.manifest, p["resources"], p["resources"]["bank"]
        fe = man["front_end"]
        assert r["memory_bits"] == man["memory"]["bits"]
        assert (r["memory_words"], r["memory_banks"], r["memory_depth"]) == (man["memory"]["words"], man["memory"]["memories"],
                                                                             man["memory"]["depth"])
        assert r["latency_cycles"] == man["latency_cycles"]
        f = fe["formats"]
        assert bk["state_register_bits"] == fe["n_models"] * fe["order"] * f["state_bits"]
        assert bk["delay_line_bits"] == fe["n_models"] * (fe["window"] + 1) * f["sum_bits"]
        assert bk["squarers"] == fe["n_models"] and bk["square_bit_products"] == fe["n_models"] * f["residual_bits"] ** 2
        co = fe["coefficients"]
        nonzero = sum(int(np.count_nonzero(co[k])) for k in ("a0", "b", "l")) + len(fe["feature_scale"]["mul"])
        nonzero += len(fe["taps"]["mul"]) if "taps" in fe else 0
        assert bk["constant_multipliers"] == nonzero
        assert p["bank"]["state_bits"] == f["state_bits"] and p["bank"]["state_frac"] == f["state_frac"]
        assert p["bank"]["coef_frac"] == f["coef_frac"]
        assert r["register_bits"] == _design_register_bits(gd.component, [gd.component.core])
        assert r["total_bits"] == r["memory_bits"] + r["logic_bits"] + r["register_bits"]
        assert r["mult_bit_products"] > bk["constant_mult_bit_products"] + bk["square_bit_products"]


def test_the_front_register_cache_key_sees_the_input_coefficients_and_affine_widths(fitted):
    """The parallel bank registers each non-zero input product (``s_in``) and the capped root and
    product of the affine map: two banks of one format whose input coefficients differ in which are
    zero have different front-end registers, so different keys of the per-process cache."""
    import copy

    from pwas_hdl.flow.explore import _front_register_key
    from pwas_hdl.hdl.observer_sensor_top import build_observer_sensor

    bm = observer_bank_model(fitted["bank"])
    other = copy.deepcopy(bm)
    j, i, c = (int(v) for v in np.argwhere(other.bank.b_codes != 0)[0])
    other.bank.b_codes[j, i, c] = 0  # one input coefficient quantised to 0: one product register fewer
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tops = [build_observer_sensor(m) for m in (bm, other)]
    keys = [_front_register_key(t, m) for t, m in zip(tops, (bm, other))]
    regs = [_design_register_bits(t, [t.core]) for t in tops]
    assert None not in keys and keys[0] != keys[1] and regs[0] != regs[1]


def test_the_root_register_spacing_is_an_option_of_the_estimate(fitted, pv, lorenz_free_sensor):
    """isqrt_every (--isqrt-every): every point's estimate is the top generate builds with it (latency,
    register bits); recorded in the sweep; a spacing that leaves a point's root without a register
    refuses that point with generate's reason; refused for a model without a bank and when not a
    positive integer."""
    s = fitted["taps"]
    _, te = pv
    dflt = observer_bank_model(s)
    one = dict(input_bits=[12], weight_frac=[dflt.core.weight_format.frac], output_frac=[dflt.core.output_format.frac])
    res = explore(s, (te.u, te.y, te.z), isqrt_every=2, **one)
    check_result(res)
    base = explore(s, (te.u, te.y, te.z), **one)
    assert res["sweep"]["isqrt_every"] == 2 and base["sweep"]["isqrt_every"] is None
    (p,) = res["points"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gd = build_design(s, design="sensor", isqrt_every=2)
    assert gd.manifest["front_end"]["isqrt_every"] == 2
    assert p["resources"]["latency_cycles"] == gd.manifest["latency_cycles"] > base["points"][0]["resources"]["latency_cycles"]
    assert p["resources"]["register_bits"] == _design_register_bits(gd.component, [gd.component.core])
    assert p["resources"]["register_bits"] > base["points"][0]["resources"]["register_bits"]
    steps = (dflt.bank.formats.sum_bits + 1) // 2
    with pytest.raises(InputError) as ei:  # every point refused: explore's own refusal, with generate's reason in it
        explore(s, (te.u, te.y, te.z), isqrt_every=steps, **one)
    assert "puts no register inside the square root" in str(ei.value)
    for bad in (0, -1, 2.5, True):
        with pytest.raises(InputError, match=r"--isqrt-every \(isqrt_every\) must be a positive integer"):
            explore(s, (te.u, te.y, te.z), isqrt_every=bad, **one)
    with pytest.raises(InputError, match=r"--isqrt-every \(isqrt_every\) applies to observer-bank sensors"):
        explore(lorenz_free_sensor[0], lorenz_free_sensor[1], input_bits=[12], isqrt_every=2)


def test_bank_formats_are_swept_axes_and_refused_elsewhere(fitted, pv, lorenz_free_sensor):
    """--state-frac / --coef-frac sweep the bank's formats (a state fraction below the input's is
    refused with the bank's reason); a bank option for a model without a bank is refused."""
    s = fitted["bank"]
    _, te = pv
    dflt = observer_bank_model(s, input_bits=10)
    fin, fs0, fc0 = dflt.bank.input_frac, dflt.bank.state_frac, dflt.bank.coef_frac
    res = explore(s, (te.u, te.y, te.z), input_bits=[10], weight_frac=[dflt.core.weight_format.frac],
                  output_frac=[dflt.core.output_format.frac], state_frac=[fin - 1, fs0], coef_frac=[fc0 - 2, fc0])
    check_result(res)
    assert res["sweep"]["state_frac"] == [fin - 1, fs0] and res["sweep"]["coef_frac"] == [fc0 - 2, fc0]
    got = {(p["bank"]["state_frac"], p["bank"]["coef_frac"]) for p in res["points"] if not p["is_default"]}
    assert got == {(fs0, fc0 - 2), (fs0, fc0)}
    assert len(res["refused"]) == 2 and all(r["state_frac"] == fin - 1 and "state_frac" in r["reason"] for r in res["refused"])
    coarse = next(p for p in res["points"] if not p["is_default"] and p["bank"]["coef_frac"] == fc0 - 2)
    fine = next(p for p in res["points"] if not p["is_default"] and p["bank"]["coef_frac"] == fc0)
    assert coarse["resources"]["bank"]["constant_mult_bit_products"] < fine["resources"]["bank"]["constant_mult_bit_products"]
    with pytest.raises(InputError, match=r"--state-frac \(state_frac\) sets a format of the observer bank"):
        explore(lorenz_free_sensor[0], lorenz_free_sensor[1], input_bits=[12], state_frac=[12])


@pytest.fixture(scope="module")
def lorenz_free_sensor():
    """A plain sensor and its data (a model without a bank)."""
    from pwas_hdl.systems.lorenz import lorenz

    d = lorenz(400, seed=5)
    s = PWASVirtualSensor(my=2, partitions=3, sigma=1e-3, output_names=["y"]).fit(None, d.y[:, 0], d.z[:, 0])
    return s, (None, d.y[:, 0], d.z[:, 0])


def test_cli_refuses_data_without_the_banks_columns(fitted, pv, tmp_path, monkeypatch):
    """Data without the output the bank takes, or without the reference: one error line, exit 2,
    nothing written."""
    monkeypatch.chdir(tmp_path)
    _, te = pv
    fitted["bank"].save(tmp_path / "m.json")
    write_csv(tmp_path / "noy.csv", {"u0": te.u[:, 0], "u1": te.u[:, 1], "z0": te.z[:, 0]})
    write_csv(tmp_path / "noz.csv", {"u0": te.u[:, 0], "u1": te.u[:, 1], "y0": te.y[:, 0]})
    write_csv(tmp_path / "short.csv", {"u0": te.u[:5, 0], "u1": te.u[:5, 1], "y0": te.y[:5, 0], "z0": te.z[:5, 0]})
    for csv, words in (("noy.csv", ("y0",)), ("noz.csv", ("no column 'z0_true' or 'z0'",)),
                       ("short.csv", ("the observer bank needs", "first estimate is at sample"))):
        before = tree(tmp_path)
        res = RUNNER.invoke(cli.app, ["explore", "m.json", csv, "-o", "ex", "--input-bits", "12"])
        assert_refused(res, *words)
        assert tree(tmp_path) == before and not (tmp_path / "ex").exists()


def test_cli_sweeps_a_bank_sensor_and_measured_mode_generates_its_sensor_top(fitted, pv, tmp_path, monkeypatch):
    """The CLI writes a valid result with the bank options; --fpga generates the sensor top (the
    manifest's front end) of every measured point, with the point's bank formats and --isqrt-every."""
    monkeypatch.chdir(tmp_path)
    _, te = pv
    s = fitted["taps"]
    s.save(tmp_path / "m.json")
    write_csv(tmp_path / "d.csv", {"u0": te.u[:, 0], "u1": te.u[:, 1], "y0": te.y[:, 0], "z0": te.z[:, 0]})
    dflt = observer_bank_model(s, input_bits=10)
    built = stub_synthesis(monkeypatch)
    res = RUNNER.invoke(cli.app, ["explore", "m.json", "d.csv", "-o", "ex", "--input-bits", "10",
                                  "--weight-frac", str(dflt.core.weight_format.frac), "--output-frac", str(dflt.core.output_format.frac),
                                  "--state-frac", str(dflt.bank.state_frac + 1), "--isqrt-every", "2",
                                  "--fpga", "generic", "--synth-dir", "syn"])
    assert res.exit_code == 0, res.output
    out = json.loads((tmp_path / "ex" / "explore.json").read_text())
    check_result(out)
    assert built and all(man["design"] == "sensor" and "front_end" in man for _, _, man in built)
    for k in out["measured"]["points"]:
        p = out["points"][k]
        man = next(m for name, _, m in built if name.endswith(f"_s{p['bank']['state_bits']}f{p['bank']['state_frac']}"
                                                              f"_c{p['bank']['coef_frac']}"))
        assert man["front_end"]["formats"]["state_frac"] == p["bank"]["state_frac"]
        assert man["front_end"]["isqrt_every"] == 2 == out["sweep"]["isqrt_every"]  # built as estimated
        assert man["latency_cycles"] == p["resources"]["latency_cycles"]
        assert p["measured"]["estimate_memory_bits_exact"]
