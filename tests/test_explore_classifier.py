"""`pwas-hdl explore` of classifiers (fit --classify; plain, additive, non-uniform power-of-two).

A classifier's point is scored by its decisions: the class index of the bit-true argmax of the
output codes (ties to the lowest class) against the true class column, beside the float classifier
and the decisions that differ from it; the front is (cost, error_rate). The expected figures are
computed here from the public pieces (the bit-true model's codes, ``numpy.argmax`` -- the tie rule
of ``pwas_hdl.fit.classifier.decide`` --, ``predict_class``), never copied from a run. Tiny fits and
sweeps of a few points: no RTL simulation, no synthesis (a stub synthesiser for ``--fpga``).
"""

from __future__ import annotations

import copy
import json
import warnings

import numpy as np
import pytest

from helpers.cli import CliRunner, assert_refused
from helpers.folders import tree
from helpers.synth_stub import stub_synthesis

from pwas_hdl import cli
from pwas_hdl.design.generate import build_design, fixed_point_model
from pwas_hdl.errors import InputError
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.fixedpoint.argmax import margins
from pwas_hdl.flow.explore import check_result, default_verdict, estimate_resources, explore, format_table, pareto_front
from pwas_hdl.io.csv_table import write_csv

RUNNER = CliRunner()

#: model kind -> fit options (three classes: the terciles of the Lorenz z)
KINDS = {
    "plain": dict(my=2, partitions=3),
    "additive": dict(my=3, partitions=3, additive="pairs"),
    "pow2": dict(my=2, partitions=4, breakpoints="quantile-pow2"),
}


@pytest.fixture(scope="module")
def case(lorenz_tiny, tmp_path_factory):
    """The tiny fixture's Lorenz data with the class c = tercile of z (0, 1, 2); the classifiers of
    ``KINDS`` fitted on its training part; the test part as arrays and as a CSV (y, c)."""
    tr, te = lorenz_tiny.train, lorenz_tiny.test
    cuts = np.quantile(tr.z[:, 0], [1 / 3, 2 / 3])
    lab_tr, lab_te = np.digitize(tr.z[:, 0], cuts), np.digitize(te.z[:, 0], cuts)
    models = {kind: PWASVirtualSensor(sigma=1e-3, output_names=["y"], target_names=["c"], classify=True, **kw).fit(None, tr.y, lab_tr)
              for kind, kw in KINDS.items()}
    root = tmp_path_factory.mktemp("explore-classifier")
    models["plain"].save(root / "model.json")
    write_csv(root / "test.csv", {"y": te.y[:, 0], "c": lab_te})
    return {"models": models, "y": te.y, "labels": lab_te, "root": root}


def _formats(sensor, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fixed_point_model(sensor, **kw)


def _decisions(sensor, fxm, y):
    """Bit-true and float classes of every row with a full regressor, from the public pieces:
    the codes of the bit-true model, numpy.argmax (ties to the lowest index), predict_class."""
    classes = np.asarray(sensor.classifier_["classes"])
    xi = sensor.lags_.build(None, y)
    codes, _ = fxm.evaluate(fxm.quantize_inputs(xi))
    return classes[np.argmax(codes, axis=1)], sensor.predict_class(None, y), xi


@pytest.fixture(scope="module")
def plain_result(case):
    m = case["models"]["plain"]
    d = _formats(m)
    fw, fo = d.weight_format.frac, d.output_format.frac
    return explore(m, (None, case["y"], case["labels"]), input_bits=[8, 12], weight_frac=[fw - 4, fw - 2, fw],
                   output_frac=[fo - 2, fo])


def test_points_report_error_rates_of_the_bittrue_decisions(case, plain_result):
    m, res = case["models"]["plain"], plain_result
    truth = case["labels"][m.lags_.memory - 1:]
    assert res["model"]["classifier"]["target"] == "c" and res["model"]["classifier"]["classes"] == [0.0, 1.0, 2.0]
    assert res["model"]["targets"] == ["c=0", "c=1", "c=2"] and res["resource_model"]["objectives"] == ["cost", "error_rate"]
    float_wrong = m.predict_class(None, case["y"]) != truth
    assert res["float"] == {"error_rate": float(float_wrong.mean()), "errors": int(float_wrong.sum())}
    assert res["data"]["samples"] == truth.size and res["sweep"]["default_in_sweep"]
    assert len(res["points"]) + len(res["refused"]) == 2 * 3 * 2 and len(res["points"]) > 6
    rates = set()
    for p in res["points"]:
        assert "rmsee" not in p and "rmsee_ratio" not in p
        fxm = _formats(m, **{k: p[k] for k in ("input_bits", "weight_frac", "output_frac")})
        hw, fl, _ = _decisions(m, fxm, case["y"])
        assert p["errors"] == int(np.sum(hw != truth)) and p["error_rate"] == p["errors"] / truth.size, p["label"]
        assert p["disagreements"] == int(np.sum(hw != fl)) and p["disagreement"] == p["disagreements"] / truth.size
        # no decision differs from the float classifier at the represented inputs outside the 2 e margin
        assert p["bound_holds"] and p["differ_outside_margin"] == 0
        # the two error counts differ by at most the decisions that differ
        assert abs(p["errors"] - res["float"]["errors"]) <= p["disagreements"]
        rates.add(p["error_rate"])
    assert len(rates) > 1  # coarse formats cost decisions: the sweep has something to trade
    check_result(res)  # the result format's schema (pwas_hdl/schemas/explore-v1.schema.json)
    json.dumps(res, allow_nan=False)


def test_widest_formats_decide_as_the_float_classifier_up_to_near_ties(case):
    """At 16-bit inputs and 4 more weight / output fraction bits than generate's defaults, a bit-true
    class can differ from the float classifier's only where the float margin (best minus runner-up
    score, at the real input) is at most 2 (e + d): e the error bound, d the largest change of a
    float score between the real input and the one the input codes represent."""
    m = case["models"]["plain"]
    d = _formats(m)
    fw, fo = d.weight_format.frac + 4, d.output_format.frac + 4
    res = explore(m, (None, case["y"], case["labels"]), input_bits=[16], weight_frac=[fw], output_frac=[fo])
    p = next(q for q in res["points"] if not q["is_default"])
    fxm = _formats(m, input_bits=16, weight_frac=fw, output_frac=fo)
    hw, fl, xi = _decisions(m, fxm, case["y"])
    zf = m.predict_regressors(xi)
    delta = float(np.max(np.abs(zf - fxm.reference(fxm.quantize_inputs(xi)))))
    near = int(np.sum(margins(zf) <= 2 * (p["error_bound"] + delta)))
    assert p["disagreements"] == int(np.sum(hw != fl)) <= near
    assert abs(p["errors"] - res["float"]["errors"]) <= p["disagreements"]
    if near == 0:
        assert p["error_rate"] == res["float"]["error_rate"]


def test_error_rate_against_a_hand_count(case, tmp_path):
    """Twelve rows: the true classes are the bit-true decisions with three of them changed, so the
    error count is 3 whatever the model decides; the CSV's c_true wins over c (as for predict)."""
    m = case["models"]["plain"]
    y = case["y"][:12]
    fxm = _formats(m)
    hw, fl, _ = _decisions(m, fxm, y)
    truth = hw.copy()
    for i in (1, 4, 7):
        truth[i] = (truth[i] + 1) % 3
    n = 12 - (m.lags_.memory - 1)  # the rows with a full regressor
    assert truth.size == n and int(np.sum(truth != hw)) == 3
    lead = np.zeros(m.lags_.memory - 1)  # the rows without a full regressor: not scored
    write_csv(tmp_path / "t.csv", {"y": y[:, 0], "c_true": np.concatenate([lead, truth]), "c": np.full(12, 5.0)})
    res = explore(m, tmp_path / "t.csv", input_bits=[fxm.input_bits], weight_frac=[fxm.weight_format.frac],
                  output_frac=[fxm.output_format.frac])
    (p,) = res["points"]
    assert res["data"]["reference_columns"] == ["c_true"] and res["data"]["samples"] == n
    assert (p["errors"], p["error_rate"]) == (3, 3 / n)
    assert res["float"]["errors"] == int(np.sum(fl != truth))
    assert p["disagreements"] == int(np.sum(fl != hw))


def test_ties_go_to_the_lowest_class(case):
    """Three equal score columns: every code ties, the argmax stage decides class 0 (the lowest
    index), as the float classifier does; scored against all-0 and all-2 labels."""
    m = copy.deepcopy(case["models"]["plain"])
    m.weights_ = np.repeat(m.weights_[:, :1], 3, axis=1)
    n = case["y"].shape[0] - (m.lags_.memory - 1)
    for label, rate in ((0, 0.0), (2, 1.0)):
        res = explore(m, (None, case["y"], np.full(case["y"].shape[0], label)), input_bits=[12], weight_frac=[4],
                      output_frac=[5])
        assert res["float"]["error_rate"] == rate
        for p in res["points"]:
            assert (p["error_rate"], p["errors"], p["disagreements"]) == (rate, round(rate * n), 0)


def test_front_and_default_use_the_error_rate(plain_result):
    res = plain_result
    pts = res["points"]
    assert res["pareto"] == pareto_front(pts, ("cost", "error_rate"))
    for k, p in enumerate(pts):
        dominated = any(q["cost"] <= p["cost"] and q["error_rate"] <= p["error_rate"]
                        and (q["cost"], q["error_rate"]) != (p["cost"], p["error_rate"]) for q in pts)
        assert p["on_front"] == (k in res["pareto"]) == (not dominated)
    d = res["default"]
    dp = pts[d["index"]]
    assert dp["is_default"] and d["on_front"] == dp["on_front"]
    assert bool(d["dominated_by"]) == (not d["on_front"])
    for e in d["dominated_by"]:
        q = pts[e["index"]]
        assert q["cost"] <= dp["cost"] and q["error_rate"] <= dp["error_rate"] and "rmsee_better" not in e
        assert e["error_rate_better"] == dp["error_rate"] - q["error_rate"] and e["error_rate_diff_se"] >= 0
    tab = format_table(res)
    assert "| error rate | vs float (pp) | differs from float |" in tab and "RMSEE" not in tab
    assert f"{100 * dp['error_rate']:.3f} % ({dp['errors']})" in tab


def test_verdict_of_a_default_dominated_at_the_same_error_rate(plain_result):
    """A cheaper point with the same errors: the verdict says so (it printed "+0 percentage points
    better"); with fewer errors it states the gain."""
    res = copy.deepcopy(plain_result)
    base = {"label": "i8 w-2 o3", "cost_saved_rel": 0.25, "error_rate_diff_se": 0.004}
    res["default"] = {**res["default"], "on_front": False, "dominated_by": [{**base, "error_rate_better": 0.0}]}
    assert default_verdict(res) == "NOT on the Pareto front: i8 w-2 o3 costs 25.0 % less with the same error rate"
    res["default"]["dominated_by"] = [{**base, "error_rate_better": 0.01}]
    assert default_verdict(res).endswith("with an error rate +1 percentage points better (standard error 0.4)")


@pytest.mark.parametrize("kind", list(KINDS))
def test_default_point_is_the_classifier_generate_builds(kind, case):
    """Plain, additive and warped classifiers: the default point's formats, error bound, memory and
    latency (the argmax stage's included) are the manifest's; its resources the estimate of that
    design, with the stage's C - 1 comparators of B_out bits."""
    m = case["models"][kind]
    d0 = _formats(m)
    res = explore(m, (None, case["y"], case["labels"]), input_bits=[12], weight_frac=[d0.weight_format.frac],
                  output_frac=[d0.output_format.frac])
    assert res["model"]["kind"] == {"plain": "plain", "additive": "additive", "pow2": "warped"}[kind]
    (p,) = res["points"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gd = build_design(m, design="core", memory="banked")
    man, fx = gd.manifest, gd.model
    assert p["is_default"] and (p["weight_frac"], p["output_bits"], p["output_frac"]) == (
        fx.weight_format.frac, fx.output_format.bits, fx.output_format.frac)
    assert p["error_bound"] == man["error_bound"]["physical"] and man["classifier"]["n_classes"] == 3
    r = p["resources"]
    assert r["latency_cycles"] == man["latency_cycles"] and r["memory_bits"] == man["memory"]["bits"]
    assert r["argmax_adder_bits"] == 2 * fx.output_format.bits
    assert r == estimate_resources(fx, "banked", classifier=m.classifier_)
    assert r["adder_bits"] - r["argmax_adder_bits"] == estimate_resources(fx, "banked")["adder_bits"]
    assert r["register_bits"] > estimate_resources(fx, "banked")["register_bits"] or man["classifier"]["stage_latency_cycles"] == 0
    hw, _, _ = _decisions(m, fx, case["y"])
    assert p["errors"] == int(np.sum(hw != case["labels"][m.lags_.memory - 1:]))
    check_result(res)


def test_measured_mode_front_uses_the_error_rate(case, monkeypatch):
    """--fpga with a stub synthesiser: the synthesised designs are the classifier's (manifest
    classifier), the measured front is in (LUTs, DSPs, BRAMs, error_rate)."""
    built = stub_synthesis(monkeypatch)
    m = case["models"]["plain"]
    d = _formats(m)
    res = explore(m, (None, case["y"], case["labels"]), input_bits=[8], weight_frac=[d.weight_format.frac - 2],
                  output_frac=[d.output_format.frac], resources="generic", measure_max=1)
    meas = res["measured"]
    assert meas["objectives"] == ["luts", "dsp", "bram", "error_rate"] and meas["errors"] == []
    assert built and all(man["classifier"]["n_classes"] == 3 for _, _, man in built) and len(built) == len(meas["points"])
    objs = [[res["points"][k]["measured"][key] for key in ("luts", "dsp", "bram")] + [res["points"][k]["error_rate"]]
            for k in meas["points"]]
    assert meas["pareto"] == [meas["points"][i] for i in pareto_front(objs)]
    check_result(res)
    assert "LUT (meas.)" in format_table(res)


def test_result_format_tells_a_classifier_from_a_sensor(plain_result):
    """The schema keeps the two accuracies apart: an RMSEE in a classifier's point, or the sensor
    objective in its front, is named by its path."""
    bad = copy.deepcopy(plain_result)
    bad["points"][2]["rmsee"] = [0.1]
    with pytest.raises(InputError, match=r"points\[2\] must not have the key 'rmsee'"):
        check_result(bad, "ex.json")
    bad = copy.deepcopy(plain_result)
    bad["resource_model"]["objectives"] = ["cost", "rmsee_ratio"]
    with pytest.raises(InputError, match=r'ex.json: resource_model.objectives\[1\] must be "error_rate"'):
        check_result(bad, "ex.json")


def test_cli_explore_of_a_classifier(case, tmp_path):
    root = case["root"]
    out = tmp_path / "ex"
    d = _formats(case["models"]["plain"])
    r = RUNNER.invoke(cli.app, ["explore", str(root / "model.json"), str(root / "test.csv"), "-o", str(out), "--input-bits", "8,12",
                                "--weight-frac", str(d.weight_format.frac), "--output-frac", str(d.output_format.frac)])
    assert r.exit_code == 0, r.output
    res = json.loads((out / "explore.json").read_text())
    check_result(res, "explore.json")
    assert res["data"]["reference_columns"] == ["c"] and (out / "explore.png").read_bytes()[:4] == b"\x89PNG"
    f = res["float"]
    assert "| error rate |" in r.stdout and "(default)" in r.stdout
    assert (f"float classifier: error rate {100 * f['error_rate']:.4g} % ({f['errors']} of {res['data']['samples']} samples) "
            "against column c") in r.output


def test_cli_bad_data_of_a_classifier(case, tmp_path, monkeypatch):
    """DATA without the class column, a class column holding a value that is no class, a trajectory
    column that is the class column: one error line, exit 2, nothing written."""
    monkeypatch.chdir(tmp_path)
    root = case["root"]
    y = case["y"][:40, 0]
    write_csv(tmp_path / "nolabel.csv", {"y": y, "z": np.ones(40)})
    write_csv(tmp_path / "other.csv", {"y": y, "c": np.where(np.arange(40) == 17, 7.0, 1.0)})
    write_csv(tmp_path / "run.csv", {"y": y, "c": np.ones(40)})
    cases = (
        ("nolabel.csv", [], ("nolabel.csv: no column 'c_true' or 'c' with the true class of classifier 'c'", "the file has columns y, z")),
        ("other.csv", [], ("other.csv: column 'c': label 7 is not one of the classes ['0', '1', '2'] of classifier 'c'",
                           "give the true class labels")),
        ("run.csv", ["--traj-col", "c"], ("--traj-col",)),
    )
    for csv, extra, words in cases:
        before = tree(tmp_path)
        res = RUNNER.invoke(cli.app, ["explore", str(root / "model.json"), csv, "-o", "ex", *extra])
        assert_refused(res, *words)
        assert tree(tmp_path) == before and not (tmp_path / "ex").exists()
