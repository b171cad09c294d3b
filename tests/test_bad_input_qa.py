"""The demanding user's pass over the newer paths (estimator files, explore on every model kind,
a file of one pwas-hdl format given where another belongs): one ``error:`` line that says what is
wrong and how to fix it, exit status 2, nothing written. In-process CLI calls (tests/helpers/cli.py)."""

from __future__ import annotations

import json

import pytest

import pwas_hdl.cli as cli
from helpers.cli import CliRunner
from helpers.folders import tree
from pwas_hdl.errors import InputError
from pwas_hdl.fit.estimator_file import estimator_text, read_estimator
from pwas_hdl.systems.switched_observer import estimator_config

RUNNER = CliRunner()


def _refused(args: list[str], root, *words: str) -> str:
    """Run ``pwas-hdl ARGS`` in ``root``: exit 2, one ``error:`` line holding ``words``, no traceback,
    the file tree unchanged. Returns the error line."""
    before = tree(root)
    res = RUNNER.invoke(cli.app, args)
    out = res.output
    lines = [ln for ln in out.splitlines() if ln.startswith("error:")]
    assert res.exit_code == 2, (args, res.exit_code, out)
    assert len(lines) == 1 and "Traceback" not in out, out
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert tree(root) == before
    return lines[0]


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


# ------------------------------------------------------------------ estimator files
@pytest.mark.parametrize("c", [[0.0, 0.0], [-0.0, 0.0]])
def test_estimator_with_an_all_zero_output_row_is_refused_by_the_reader(in_tmp, c):
    """C_i = 0 made generate crash in the RTL builder (an adder over no terms, exit 3)."""
    d = json.loads(estimator_text(estimator_config()))
    d["modes"][1]["C"] = c
    (in_tmp / "est.json").write_text(json.dumps(d), encoding="utf-8")
    with pytest.raises(InputError, match=r"modes\[1\]\.C is all zero"):
        read_estimator(in_tmp / "est.json")
    _refused(["generate", "est.json", "-o", "hw"], in_tmp, "est.json", "modes[1].C is all zero", "non-zero entry")


@pytest.mark.parametrize("command", [["predict", "est.json", "d.csv", "-o", "p.csv"], ["info", "est.json"],
                                     ["explore", "est.json", "d.csv", "-o", "ex"]])
def test_an_estimator_file_given_for_a_model_is_named_for_what_it_is(in_tmp, command):
    """It was 'not a pwas-hdl-model file (missing "format": ...)' although the file has a format."""
    (in_tmp / "est.json").write_text(estimator_text(estimator_config()), encoding="utf-8")
    (in_tmp / "d.csv").write_text("u,y,z\n1,2,3\n4,5,6\n", encoding="utf-8")
    _refused(command, in_tmp, "est.json is a pwas-hdl-estimator file", "pwas-hdl generate", "not a pwas-hdl-model file")


def test_a_manifest_given_for_a_model_is_named_for_what_it_is(in_tmp, lorenz_tiny):
    (in_tmp / "manifest.json").write_text(json.dumps({"format": "pwas-hdl-manifest", "version": 2}), encoding="utf-8")
    _refused(["info", "manifest.json"], in_tmp, "is a pwas-hdl-manifest file", "take the folder")


# ------------------------------------------------------------------ explore on every model kind
def _tiny_sensor(lorenz_tiny, **kw):
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    tr = lorenz_tiny.train
    return PWASVirtualSensor(my=2, partitions=2, gamma=1.2, sigma=1e-3, output_names=["y"], target_names=["z"],
                             **kw).fit(None, tr.y[:300], tr.z[:300])


def test_explore_of_a_recurrent_model_refuses_a_trajectory_shorter_than_the_lags(in_tmp, lorenz_tiny):
    """Recurrent models are swept now (tests/test_explore_recurrent.py); a trajectory too short for
    the lags is one error line naming it, nothing written."""
    _tiny_sensor(lorenz_tiny, mz=1).save(in_tmp / "rec.json")
    (in_tmp / "short.csv").write_text("run,y,z\n0,0.1,0.2\n0,0.2,0.3\n0,0.3,0.1\n1,0.5,0.4\n", encoding="utf-8")
    _refused(["explore", "rec.json", "short.csv", "--traj-col", "run", "-o", "ex"], in_tmp,
             "trajectory 1 has 1 samples; the lags need 2")


def test_explore_of_a_classifier_needs_its_label_column(in_tmp, lorenz_tiny):
    """A classifier got "no column 'mode=1_true' or 'mode=1'" (its one-hot score targets), then was
    refused; now it is swept (tests/test_explore_classifier.py) and DATA without the class label column
    is one error line naming the label's columns, nothing written."""
    import numpy as np

    from pwas_hdl.io.csv_table import write_csv

    rng = np.random.default_rng(0)
    y = rng.normal(size=300)
    mode = (y > 0).astype(int) + 1
    write_csv(in_tmp / "c.csv", {"y": y, "mode": mode})
    write_csv(in_tmp / "nolabel.csv", {"y": y})
    res = RUNNER.invoke(cli.app, ["fit", "c.csv", "-o", "cls.json", "-y", "y", "-z", "mode", "--classify", "--my", "1",
                                  "-p", "2", "--sigma", "1e-3"])
    assert res.exit_code == 0, res.output
    _refused(["explore", "cls.json", "nolabel.csv", "-o", "ex"], in_tmp,
             "nolabel.csv: no column 'mode_true' or 'mode' with the true class of classifier 'mode'", "the file has columns y")


# ------------------------------------------------------------------ manifests edited by hand
@pytest.fixture(scope="module")
def tiny_folder(tmp_path_factory):
    """The folder of seed 003's estimator (the one generated design of this file: ~1 s) and a CSV for it."""
    from pwas_hdl.design.generate import generate

    root = tmp_path_factory.mktemp("qa-design")
    (root / "est.json").write_text(estimator_text(estimator_config()), encoding="utf-8")
    generate(root / "est.json", root / "hw")
    (root / "d.csv").write_text("u,y,run\n" + "".join(f"{i % 3 - 1},{(i % 5) / 4},0\n" for i in range(20)), encoding="utf-8")
    return root / "hw", root / "d.csv"


def _edited(tiny_folder, tmp_path, edit):
    import shutil

    src, _ = tiny_folder
    dst = tmp_path / "hw"
    shutil.copytree(src, dst)
    m = json.loads((dst / "manifest.json").read_text(encoding="utf-8"))
    edit(m)
    (dst / "manifest.json").write_text(json.dumps(m, indent=1), encoding="utf-8")
    return dst


def test_a_hand_edited_huge_latency_is_refused_before_simulating(tiny_folder, in_tmp):
    """latency_cycles = 10^12 passed the schema (minimum 0 only) and simulate then waited for an output for
    10^12 cycles (it ran > 20 min until killed); a moderately wrong latency stays a failed check (exit 1)."""
    from pwas_hdl.design.manifest import load_manifest
    from pwas_hdl.limits import MAX_LATENCY_CYCLES

    hw = _edited(tiny_folder, in_tmp, lambda m: m.__setitem__("latency_cycles", 10**12))
    with pytest.raises(InputError, match=f"latency_cycles 1000000000000 exceeds the limit of {MAX_LATENCY_CYCLES}"):
        load_manifest(hw)
    (in_tmp / "d.csv").write_text(tiny_folder[1].read_text(encoding="utf-8"), encoding="utf-8")
    _refused(["simulate", "hw", "d.csv", "-o", "s.csv", "--simulator", "icarus", "--traj-col", "run"], in_tmp,
             "latency_cycles 1000000000000 exceeds the limit", "re-run `pwas-hdl generate`")
    ok = json.loads((tiny_folder[0] / "manifest.json").read_text(encoding="utf-8"))
    assert ok["latency_cycles"] <= MAX_LATENCY_CYCLES
    ok["latency_cycles"] = MAX_LATENCY_CYCLES
    from pwas_hdl.design.manifest import validate_manifest

    # the limit itself is allowed: the limit check comes first, so it would be the error reported; the
    # consistency checks that follow it refuse this edit for another reason (the estimator's latency is 1)
    with pytest.raises(InputError) as exc:
        validate_manifest(ok)
    assert "exceeds the limit" not in str(exc.value) and f"latency_cycles is {MAX_LATENCY_CYCLES}" in str(exc.value)


@pytest.mark.parametrize("edit, words", [
    (lambda m: _port(m, "in.payload").__setitem__("width", 10**8), "100000000 bits wide, more than the limit of 65536"),
    (lambda m: _port(m, "out.payload").__setitem__("width", 1000), "1000 bits wide but its fields end at bit"),
    (lambda m: _port(m, "in.valid").__setitem__("width", 2), "must be 1 bit wide, got 2"),
    (lambda m: (_port(m, "out.payload")["fields"][0].__setitem__("width", 10**12),
                _port(m, "out.payload").__setitem__("width", 10**12 + 1)), "more than the limit of 65536"),
])
def test_a_hand_edited_port_width_is_refused_before_anything_is_sized_by_it(tiny_folder, in_tmp, edit, words):
    """A payload edited to 10^8 bits passed validation: simulate ignored it, export-testbench sized its
    vectors by it (14 GB resident, killed after 2 min); a 10^12-bit field made the validator's own
    overlap mask that big."""
    _edited(tiny_folder, in_tmp, edit)
    _refused(["export-testbench", "hw", "-o", "tb"], in_tmp, words, "re-run `pwas-hdl generate`")
    _refused(["report", "hw"], in_tmp, words)


def _port(m: dict, role: str) -> dict:
    return next(p for p in m["ports"] if p["role"] == role)


# ------------------------------------------------------------------ error texts name the CLI options
@pytest.mark.parametrize("args, words, api_words", [
    (["generate", "{model}", "-o", "hw", "--goal", "latency", "--clock-mhz", "50"],
     "give one of --goal, --pipeline or --clock-mhz, not --goal with --clock-mhz", "target_mhz"),
    (["generate", "{model}", "-o", "hw", "--goal", "latency", "--pipeline", "min"],
     "not --goal with --pipeline", "pipeline (--pipeline)"),
    (["generate", "{model}", "-o", "hw", "--input-bits", "1"], "--input-bits (input_bits) = 1", None),
    (["generate", "{model}", "-o", "hw", "--input-fill", "2"], "--input-fill (input_fill) = 2.0", None),
    (["generate", "{model}", "-o", "hw", "--input-scale", "odd"], "--input-scale (input_scale) must be", None),
    (["generate", "{model}", "-o", "hw", "--clock-mhz", "-5"], "--clock-mhz (target_mhz) must be a positive", None),
    (["generate", "{est}", "-o", "hw", "--clock-mhz", "50"], "--clock-mhz 50.0 belongs to the PWAS designs", "option target_mhz"),
    (["generate", "{est}", "-o", "hw", "--memory", "replicated"], "--memory 'replicated' belongs to the PWAS designs", None),
    (["explore", "{model}", "{data}", "-o", "ex", "--input-bits", "0"], "--input-bits (input_bits) must be >= 2", None),
    (["explore", "{model}", "{data}", "-o", "ex", "--measure-max", "0"], "--measure-max (measure_max) must be", None),
    (["explore", "{model}", "{data}", "-o", "ex", "--cost", "area"], "--cost must be one of", None),
    (["generate", "{model}", "-o", "hw", "--weight-bits", "100000"], "--weight-bits (weight_bits) = 100000: need", "exceeds"),
    (["generate", "{model}", "-o", "hw", "--output-bits", "0"], "--output-bits (output_bits) = 0: need", None),
    (["generate", "{model}", "-o", "hw", "--weight-frac", "-100"], "use a larger --weight-frac (--weight-frac", None),
    # the message named only --output-frac (= 1001), an option the user had not given
    (["generate", "{model}", "-o", "hw", "--weight-frac", "1000"],
     "--weight-frac (weight_frac) = 1000 gives the default --output-frac (output_frac) = 1001, out of the supported range",
     None),
])
def test_error_texts_name_the_cli_options(in_tmp, lorenz_tiny, args, words, api_words):
    """Messages said 'give one of goal (--goal), pipeline (--pipeline) or target_mhz (--clock-mhz)',
    'option target_mhz = 50.0 belongs ...', 'input_bits = 1: ...', 'measure_max must be ...'."""
    (in_tmp / "est.json").write_text(estimator_text(estimator_config()), encoding="utf-8")
    args = [a.format(model=lorenz_tiny.model, est="est.json", data=lorenz_tiny.test_csv) for a in args]
    line = _refused(args, in_tmp, words)
    if api_words:
        assert api_words not in line, line


def test_breakpoint_errors_print_plain_numbers(in_tmp, lorenz_tiny):
    """'b[0] = np.float64(20.37...) >= b[1] = np.float64(10.1...)': numpy reprs in a user's error line."""
    d = json.loads(lorenz_tiny.model.read_text(encoding="utf-8"))
    lo, hi = d["grid"]["lo"][0], d["grid"]["hi"][0]
    d["grid"]["breakpoints"] = [[hi, (lo + hi) / 2, (lo + hi) / 3, lo], None]
    (in_tmp / "w.json").write_text(json.dumps(d), encoding="utf-8")
    line = _refused(["info", "w.json"], in_tmp, "breakpoints of dimension 0 must increase strictly", f"b[0] = {hi!r}")
    assert "np.float64" not in line


# ------------------------------------------------------------------ domains at the ends of the float range
def test_a_domain_wider_than_a_float_is_refused(in_tmp, lorenz_tiny):
    """--domain -1e308:1e308 (or a breakpoints file spanning it) was accepted: hi - lo = inf, step = inf."""
    from pwas_hdl.fit.geometry import Grid

    with pytest.raises(ValueError, match=r"domain dimension 1 .* is wider than a float can hold"):
        Grid([0.0, -1e308], [1.0, 1e308], 2)
    (in_tmp / "bp.json").write_text(json.dumps({"format": "pwas-hdl-breakpoints", "version": 1,
                                                "breakpoints": [[-25, 25], [-1e308, 1e308]]}), encoding="utf-8")
    _refused(["fit", str(lorenz_tiny.test_csv), "-o", "m.json", "-y", "y", "-z", "z", "--my", "2", "--sigma", "1e-3",
              "--breakpoints", "bp.json"], in_tmp, "is wider than a float can hold", "--domain")


def test_points_far_outside_a_tiny_cell_are_clamped_without_a_warning():
    """A cell of 1e-320 (a --domain or a breakpoints file) printed numpy's 'RuntimeWarning: overflow
    encountered in divide' with a source line to the user; the coordinate is clamped like any outside point."""
    import warnings

    import numpy as np

    from pwas_hdl.fit.geometry import Grid

    uniform = Grid([0.0, 0.0], [1e-320, 1.0], 2)
    warped = Grid([0.0, 0.0], [1.0, 1.0], [2, 1], breakpoints=[[0.0, 5e-324, 1.0], None])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for g, x in ((uniform, [[50.0, 0.5], [-50.0, 0.5]]), (warped, [[0.9, 0.5], [-3.0, 0.5]])):
            s, out = g.to_grid_units(np.array(x))
            assert np.all(np.isfinite(s)) and np.all((s >= 0) & (s <= g.partitions))
    np.testing.assert_array_equal(uniform.to_grid_units(np.array([[50.0, 0.5]]))[0], [[2.0, 1.0]])


@pytest.mark.parametrize("args", [["make-data", "three-tank", "-o", "d.csv", "--runs", "1", "--samples", "5", "--noise", "nan"],
                                  ["make-data", "switched-linear", "-o", "d.csv", "--runs", "1", "--samples", "5", "--noise", "inf"],
                                  ["make-data", "pv-benchmark", "-o", "d.csv", "--samples", "50", "--noise", "inf"]])
def test_make_data_refuses_a_noise_that_is_not_a_finite_number(in_tmp, args):
    """--noise inf wrote a CSV of inf outputs (and nan one of NaN or noise-free data) that every later command refuses."""
    _refused(args, in_tmp, "--noise", "finite number >= 0")


def test_export_testbench_of_the_estimator_design(tiny_folder):
    """It said 'estd/estimator.json is ... not a pwas-hdl-model file; re-run `pwas-hdl fit`', then that the
    estimator design was not supported; it is exported now (the RTL runs: tests/test_export_testbench.py)."""
    out = tiny_folder[0].parent / "tb"
    res = RUNNER.invoke(cli.app, ["export-testbench", str(tiny_folder[0]), "-o", str(out), "--samples", "40"])
    assert res.exit_code == 0, res.output
    assert {"tb_pwas_estimator.v", "pwas_estimator_tb_in.hex", "pwas_estimator_tb_expected.hex", "pwas_estimator.v",
            "run_icarus.sh", "run_verilator.sh", "files.f"} <= {f.name for f in out.iterdir()}
    assert len((out / "pwas_estimator_tb_expected.hex").read_text().splitlines()) == 40  # no warm-up: one output a sample
