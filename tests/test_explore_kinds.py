"""`pwas-hdl explore` on additive sensors (fit --additive) and non-uniform power-of-two partitions
(fit --breakpoints quantile-pow2): each point is the bit-true model and the design `generate` builds
(`fixed_point_model`, `build_additive_core`, `build_warped_core`). Classifiers of both kinds:
tests/test_explore_classifier.py; observer-bank sensors: tests/test_explore_observer_bank.py."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from helpers.cli import CliRunner
from helpers.folders import tree
from helpers.synth_stub import stub_synthesis

from pwas_hdl import cli
from pwas_hdl.design.generate import build_design, fixed_point_model
from pwas_hdl.errors import InputError
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.fixedpoint.additive import AdditiveFixedPointModel
from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel
from pwas_hdl.flow.explore import DEFAULT_FRAC_OFFSETS, estimate_resources, explore

RUNNER = CliRunner()

#: model kind -> (fit options, bit-true class, result["model"]["kind"])
KINDS = {
    "additive": (dict(my=3, partitions=3, sigma=1e-2, additive="pairs"), AdditiveFixedPointModel, "additive"),
    "pow2": (dict(my=2, partitions=3, sigma=1e-3, breakpoints="quantile-pow2"), WarpedFixedPointModel, "warped"),
}


@pytest.fixture(scope="module")
def fitted(lorenz_tiny, tmp_path_factory):
    """kind -> (sensor, model path, test CSV): tiny additive / quantile-pow2 Lorenz sensors (the tiny
    fixture's data)."""
    out = {}
    tr = lorenz_tiny.train
    for kind, (kw, _cls, _k) in KINDS.items():
        m = PWASVirtualSensor(output_names=["y"], target_names=["z"], **kw).fit(None, tr.y, tr.z)
        root = tmp_path_factory.mktemp(f"explore-{kind}")
        m.save(root / "model.json")
        out[kind] = (m, root / "model.json", lorenz_tiny.test_csv)
    return out


@pytest.fixture(scope="module")
def results(fitted):
    return {kind: explore(path, csv, input_bits=[8, 12]) for kind, (_m, path, csv) in fitted.items()}


@pytest.mark.parametrize("kind", list(KINDS))
def test_default_point_is_what_generate_builds(kind, fitted, results):
    m, _, _ = fitted[kind]
    res = results[kind]
    assert res["model"]["kind"] == KINDS[kind][2]
    gd = build_design(m, design="core", memory="banked")  # generate's defaults (its default memory on ECP5)
    fx, man = gd.model, gd.manifest
    assert isinstance(fx, KINDS[kind][1])
    d = res["points"][res["default"]["index"]]
    assert d["is_default"] and res["sweep"]["default_in_sweep"] and d["weight_offset"] == d["output_offset"] == 0
    assert (d["input_bits"], d["input_frac"], d["weight_bits"], d["weight_frac"], d["output_bits"], d["output_frac"], d["shift"]) == (
        fx.input_bits, fx.F, fx.weight_format.bits, fx.weight_format.frac, fx.output_format.bits, fx.output_format.frac, fx.shift)
    assert d["error_bound"] == man["error_bound"]["physical"] and d["error_bound_lsb"] == man["error_bound"]["lsb"]
    r = d["resources"]
    assert (r["memory_bits"], r["memory_words"], r["memory_banks"], r["memory_word_bits"]) == (
        man["memory"]["bits"], man["memory"]["words"], man["memory"]["memories"], man["memory"]["word_bits"])
    assert r["latency_cycles"] == man["latency_cycles"]
    assert isinstance(r["register_bits"], int) and r["register_bits"] > 0
    assert r["total_bits"] == r["memory_bits"] + r["logic_bits"] + r["register_bits"] and d["cost"] == r["total_bits"]
    if kind == "additive":  # a fraction per part; the resources add up the parts
        assert d["part_frac"] == [p.F for p in fx.parts] and d["input_frac"] == max(d["part_frac"])
        parts = r["parts"]
        assert len(parts) == len(fx.parts)
        for key in ("memory_bits", "memory_words", "multipliers", "mult_bit_products", "dsp18", "bram18k"):
            assert r[key] == sum(p[key] for p in parts), key
        assert r["memory_banks"] == sum(p["memory_banks"] for p in parts) == sum(len(s) + 1 for s in fx.subsets)
        assert r["adder_bits"] == sum(p["adder_bits"] for p in parts) + r["sum_adder_bits"]
        assert r["acc_bits"] == fx.sum_bits
    else:  # the input code (B_in) is not the core's (W)
        assert d["core_input_bits"] == man["warp"]["core_input_bits"] == man["arithmetic"]["in_width"] != d["input_bits"]
        assert d["label"].startswith(f"in s{d['input_bits']} -> u s{d['core_input_bits']}.{d['input_frac']} / ")
        assert 0 < r["warp_adder_bits"] < r["adder_bits"]
        assert r["multipliers"] == (m.grid_.n + 1) * fx.nz


@pytest.mark.parametrize("kind", list(KINDS))
def test_every_point_within_its_bound_and_a_front(kind, fitted, results):
    m, _, csv = fitted[kind]
    res = results[kind]
    n_off = len(DEFAULT_FRAC_OFFSETS)
    assert len(res["points"]) + len(res["refused"]) == 2 * n_off * n_off and len(res["points"]) > n_off * n_off
    for p in res["points"]:
        assert p["bound_holds"] and p["max_dev_reference_lsb"] <= p["error_bound_lsb"] * (1 + 1e-12), p["label"]
    assert res["pareto"] and [k for k, p in enumerate(res["points"]) if p["on_front"]] == sorted(res["pareto"])
    json.dumps(res, allow_nan=False)
    # a point off the default: its model and resources are those generate builds with its formats
    p = next(q for q in res["points"] if q["input_bits"] == 8 and q["weight_offset"] == -2 and q["output_offset"] == 1)
    fmt = {k: p[k] for k in ("input_bits", "weight_frac", "output_frac")}
    gd = build_design(m, design="core", memory="banked", **fmt)
    assert (gd.model.weight_format.bits, gd.model.output_format.bits) == (p["weight_bits"], p["output_bits"])
    assert p["error_bound"] == gd.manifest["error_bound"]["physical"]
    assert p["resources"]["memory_bits"] == gd.manifest["memory"]["bits"]
    assert p["resources"] == estimate_resources(gd.model, "banked")


def test_register_bits_of_the_new_kinds_are_cached_and_exact(fitted):
    """The cached register bits of an additive / warped design equal a fresh elaboration's."""
    import pwas_hdl.flow.explore as ex
    from pwas_hdl.hdl.additive_top import build_additive_core
    from pwas_hdl.hdl.warp import build_warped_core

    for kind, build in (("additive", build_additive_core), ("pow2", build_warped_core)):
        m = fitted[kind][0]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fx = fixed_point_model(m, input_bits=10)
        comp = build(fx)
        cores = comp.parts if kind == "additive" else [comp.core]
        fresh = ex._design_register_bits(comp, cores)
        assert fresh > 0 and estimate_resources(fx)["register_bits"] == fresh
        assert estimate_resources(fx)["register_bits"] == fresh  # from the cache


@pytest.mark.parametrize("kind", list(KINDS))
def test_cli_explore_writes_the_json(kind, fitted, tmp_path):
    m, path, csv = fitted[kind]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fx = fixed_point_model(m)
    fw, fo = fx.weight_format.frac, fx.output_format.frac
    out = tmp_path / "ex"
    r = RUNNER.invoke(cli.app, ["explore", str(path), str(csv), "-o", str(out), "--input-bits", "10,12",
                                "--weight-frac", f"{fw - 1}:{fw}", "--output-frac", str(fo)])
    assert r.exit_code == 0, r.output
    res = json.loads((out / "explore.json").read_text())
    assert res["model"]["kind"] == KINDS[kind][2] and len(res["points"]) == 4 and res["pareto"]
    assert (out / "explore.png").read_bytes()[:4] == b"\x89PNG" and "(default)" in r.stdout


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _refused(args, root, *words):
    before = tree(root)
    res = RUNNER.invoke(cli.app, args)
    lines = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert res.exit_code == 2, res.output
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert tree(root) == before


def test_additive_and_warped_classifiers_refuse_a_reference_that_holds_no_class(lorenz_tiny, in_tmp):
    """Additive or warped classifiers are swept now (tests/test_explore_classifier.py; observer-bank
    sensors: tests/test_explore_observer_bank.py). A classifier's reference is
    its true class: the tiny fixture's CSV has the continuous z_true under the label's name, whose
    values are no class -- one error line naming the column, exit 2, nothing written (it was a sweep
    with an error rate of 100 %). (The old refusal named 'additive sensors' for an additive classifier.)"""
    tr = lorenz_tiny.train
    z = tr.z[:400, 0]
    for kw in (dict(my=3, additive="pairs", classify=True), dict(my=2, breakpoints="quantile-pow2", classify=True)):
        PWASVirtualSensor(partitions=3, sigma=1e-3, output_names=["y"], target_names=["z"], **kw).fit(
            None, tr.y[:400], (z > np.median(z)).astype(float)).save(in_tmp / "m.json")
        _refused(["explore", "m.json", str(lorenz_tiny.test_csv), "-o", "ex"], in_tmp,
                 "column 'z_true'", "are not among the classes ['0', '1'] of classifier 'z'", "give the true class labels")
        (in_tmp / "m.json").unlink()


def test_measured_mode_generates_the_new_kinds(fitted, monkeypatch):
    """--fpga: the front points and the default go through generate (the additive / warped design);
    the manifest's memory bits are the estimate's (stub synthesiser: no tools needed)."""
    built = stub_synthesis(monkeypatch)
    for kind in KINDS:
        m, _, csv = fitted[kind]
        built.clear()
        res = explore(m, csv, input_bits=[8, 12], weight_frac=[-2, 0], output_frac=[0], resources="generic", measure_max=2)
        meas = res["measured"]
        assert meas["errors"] == [] and res["default"]["index"] in meas["points"] and len(built) == len(meas["points"])
        assert all(("additive" in man) == (kind == "additive") and ("warp" in man) == (kind == "pow2") for _, _, man in built)
        for k in meas["points"]:
            assert res["points"][k]["measured"]["estimate_memory_bits_exact"] is True
