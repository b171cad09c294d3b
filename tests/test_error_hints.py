"""Bad-input messages name what the user gave (option, file, column) with its value, and say how to fix it.

One test per message reworded by the error-message audit: the CLI cases check exit 2 and one
``error:`` line (as tests/test_issue9_bad_input.py), the API cases the text of the ``InputError``.
"""

from __future__ import annotations

import json
import types
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from helpers.cli import CliRunner, assert_refused

from pwas_hdl.cli import app
from pwas_hdl.errors import InputError, choice_text, fault_text

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("hints")
    res = invoke("make-data", "lorenz", "-o", d / "d.csv", "--samples", 600, "--test-out", d / "t.csv",
                 "--test-samples", 200)
    assert res.exit_code == 0, res.output
    res = invoke("fit", d / "d.csv", "-o", d / "m.json", "-y", "y", "-z", "z", "--my", 2, "-p", 3, "--sigma", "1e-3")
    assert res.exit_code == 0, res.output
    res = invoke("generate", d / "m.json", "-o", d / "g")
    assert res.exit_code == 0, res.output
    return d


def fit(data: Path, out: Path, *extra):
    return invoke("fit", data, "-o", out, "-y", "y", "-z", "z", "--my", 2, "-p", 3, *extra)


# --- helpers -------------------------------------------------------------------------------------------

def test_choice_text_and_fault_text():
    assert choice_text("--memory (memory)", ("banked", "replicated"), "dual") == \
        "--memory (memory) must be one of banked, replicated, got 'dual'"
    assert fault_text(KeyError("lpv")) == "the key 'lpv' is missing"
    assert fault_text(IndexError("list index out of range")) == "a list has too few entries"
    assert fault_text(TypeError("bad")).startswith("a value has the wrong type")


# --- CSV files -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("text, words", [
    ("y,,z\n1,2,3\n", ["empty column name (column 2 of 3)", "name every column"]),
    ("y,y,z\n1,2,3\n", ["duplicate column name(s) y", "give each column a name of its own"]),
    ("y,z\n1,2,3\n", ["line 2 has 3 cells but the header has 2 columns", "one cell per column"]),
    ("y,z\n", ["header but no data rows", "add the samples"]),
])
def test_csv_structure_errors_say_how_to_fix(tmp_path, text, words):
    (tmp_path / "bad.csv").write_text(text)
    assert_refused(fit(tmp_path / "bad.csv", tmp_path / "x.json"), "bad.csv", *words)
    assert not (tmp_path / "x.json").exists()


# --- fit options ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("extra, words", [
    (["--gamma", "0.5"], ["--gamma (gamma) must be a number >= 1", "got 0.5"]),
    (["--sigma", "-1"], ["--sigma (sigma) must be a positive number", "leave --sigma out", "got -1.0"]),
    (["--tikhonov", "3"], ["--tikhonov (tikhonov_order) must be 0", "got 3"]),
    (["--sigma-grid", "0,1"], ["(--sigma-grid), got 0.0", "logspace:"]),
    (["--domain", "0:inf,0:1"], ["domain bounds must be finite", "hi = [inf, 1.0]", "give finite bounds"]),
    (["--domain", "1000:2000,1000:2000", "--breakpoints", "quantile"],
     ["no quantiles", "give a --domain that covers the data", "leave --breakpoints out"]),
    (["--additive", "0;0"], ["--additive part 1 (0) repeats part 0", "give each part once"]),
    (["--additive", "0,0"], ["--additive part 0: regressor index 0 appears twice", "name each index of a part once"]),
])
def test_fit_option_errors_name_the_option_and_value(files, tmp_path, extra, words):
    assert_refused(fit(files / "d.csv", tmp_path / "x.json", *extra), *words)
    assert not (tmp_path / "x.json").exists()


def test_classifier_with_one_class_says_what_to_give(tmp_path):
    (tmp_path / "c.csv").write_text("y,z\n" + "".join(f"{i},0\n" for i in range(8)))
    res = invoke("fit", tmp_path / "c.csv", "-o", tmp_path / "x.json", "-y", "y", "-z", "z", "--my", 1, "-p", 1,
                 "--sigma", 1, "--classify")
    assert_refused(res, "single value [0.0]", "two or more labels", "fit without --classify")


def _observer_bank_fit(tmp_path: Path, u, y, z):
    with open(tmp_path / "ob.csv", "w") as f:
        f.write("u,y,z\n" + "".join(f"{float(a)!r},{float(b)!r},{float(c)!r}\n" for a, b, c in zip(u, y, z)))
    return invoke("fit", tmp_path / "ob.csv", "-o", tmp_path / "x.json", "-u", "u", "-y", "y", "-z", "z", "--mu", 1,
                  "--my", 1, "-p", 2, "--sigma", 1, "--front-end", "observer-bank", "--models", 2)


def test_observer_bank_constant_input_names_the_option(tmp_path):
    rng = np.random.default_rng(0)
    res = _observer_bank_fit(tmp_path, np.ones(400), rng.normal(size=400), rng.normal(size=400))
    assert_refused(res, "input column 1 of -u/--inputs is constant", "remove it from -u/--inputs")


def test_observer_bank_constant_target_says_so(tmp_path):
    rng = np.random.default_rng(0)
    res = _observer_bank_fit(tmp_path, rng.normal(size=400), rng.normal(size=400), np.full(400, 3.0))
    assert_refused(res, "-z/--targets column) is constant", "always 3", "give data in which it varies")


def test_observer_bank_short_trajectory_says_what_to_change(tmp_path):
    rng = np.random.default_rng(0)
    res = _observer_bank_fit(tmp_path, rng.normal(size=9), rng.normal(size=9), rng.normal(size=9))
    assert_refused(res, "has 9 samples", "give longer trajectories", "--order", "--window")


def test_local_models_short_trajectory_says_what_to_change():
    from pwas_hdl.fit.observer_bank import arx_regressors

    with pytest.raises(InputError, match="need more than M; give longer trajectories or a smaller --order"):
        arx_regressors(np.zeros((3, 1)), np.zeros((3, 1)), 3)


# --- make-data -----------------------------------------------------------------------------------------

def test_make_data_sample_counts_show_the_values(tmp_path):
    res = invoke("make-data", "lorenz", "-o", tmp_path / "l.csv", "--samples", 0)
    assert_refused(res, "--samples and --test-samples must be >= 1", "got --samples 0, --test-samples")


# --- generate ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("extra, words", [
    (["--design", "gpu"], ["--design (design) must be core or sensor", "got 'gpu'"]),
    (["--memory", "dual"], ["--memory (memory) must be one of banked, replicated, corner, got 'dual'"]),
    (["--architecture", "tiny"], ["--architecture (architecture) must be one of parallel, serial, got 'tiny'"]),
    (["--memory-init", "rom"], ["--memory-init (memory_init) must be one of inline, readmemh, got 'rom'"]),
    (["--rounding", "up"], ["--rounding (rounding) must be one of half_up, truncate, got 'up'"]),
    (["--overflow", "wrap"], ["--overflow (overflow) must be one of error, saturate, got 'wrap'"]),
    (["--goal", "fast"], ["unknown goal 'fast' (--goal); choose one of latency"]),
    (["--pipeline", "fastest"], ["unknown pipeline preset 'fastest' (--pipeline); choose one of min"]),
])
def test_generate_option_errors_name_the_option(files, tmp_path, extra, words):
    assert_refused(invoke("generate", files / "m.json", "-o", tmp_path / "g", *extra), *words)
    assert not (tmp_path / "g").exists()


def test_observer_bank_input_scale_says_leave_it_out(tmp_path, files):
    res = invoke("fit", files / "d.csv", "-o", tmp_path / "ob.json", "-y", "y", "-z", "z", "--my", 0, "-p", 2,
                 "--sigma", 1, "--front-end", "observer-bank", "--models", 2)
    assert res.exit_code == 0, res.output
    res = invoke("generate", tmp_path / "ob.json", "-o", tmp_path / "g", "--design", "sensor", "--input-scale", "exact")
    assert_refused(res, "--input-scale (input_scale) 'exact' does not apply", "leave --input-scale out")


def test_corrupt_front_end_names_the_missing_key(tmp_path, files):
    res = invoke("fit", files / "d.csv", "-o", tmp_path / "ob.json", "-y", "y", "-z", "z", "--my", 0, "-p", 2,
                 "--sigma", 1, "--front-end", "observer-bank", "--models", 2)
    assert res.exit_code == 0, res.output
    d = json.loads((tmp_path / "ob.json").read_text())
    del d["front_end"]["lpv"]
    (tmp_path / "ob.json").write_text(json.dumps(d))
    msg = assert_refused(invoke("generate", tmp_path / "ob.json", "-o", tmp_path / "g"),
                         "front_end is corrupt or incomplete (the key 'lpv' is missing)", "re-run `pwas-hdl fit`")
    assert "KeyError" not in msg


# --- synth, simulate, report ---------------------------------------------------------------------------

@pytest.mark.parametrize("extra, words", [
    (["--fpga", "xilinx"], ["unknown synthesis target 'xilinx' (--fpga)"]),
    (["--fpga", "ice40", "--device", "hx9k"], ["unknown iCE40 device 'hx9k' (--device)"]),
    (["--fpga", "ecp5", "--device", "99k"], ["unknown ECP5 device '99k' (--device)"]),
])
def test_synth_errors_name_the_option(files, extra, words):
    assert_refused(invoke("synth", files / "g", *extra), *words)


def test_simulate_short_trajectory_gives_file_lines_and_hint(files, tmp_path):
    lines = (files / "d.csv").read_text().splitlines()
    rows = [lines[0] + ",run"] + [ln + (",0" if i == 0 else ",1") for i, ln in enumerate(lines[1:40])]
    (tmp_path / "sh.csv").write_text("\n".join(rows) + "\n")
    res = invoke("simulate", files / "g", tmp_path / "sh.csv", "-o", tmp_path / "s.csv", "--traj-col", "run")
    assert_refused(res, "sh.csv: run '0' (column run) on line 2 has 1 samples", "the lags need 2",
                   "drop that run or give it at least 2 rows")


def test_manifest_of_the_wrong_shape_names_the_key_not_the_exception(files):
    """What the manifest's schema lets through but the readers trip over (a key, a list entry) is named in
    the file's terms, not as a Python exception class."""
    from pwas_hdl.design import report
    from pwas_hdl.verify import simulation

    with mock.patch.object(simulation, "_load_design", side_effect=KeyError("ii")):
        with pytest.raises(InputError, match=r"manifest.json is incomplete or corrupt \(the key 'ii' is missing\); regenerate"):
            simulation.load_design(files / "g")
    with mock.patch.object(report, "_design_summary", side_effect=IndexError("list index out of range")):
        with pytest.raises(InputError, match=r"incomplete or corrupt \(a list has too few entries\); regenerate"):
            report.collect_report(files / "g")
    with mock.patch.object(report, "report_markdown", side_effect=TypeError("unsupported format string")):
        with pytest.raises(InputError, match=r"wrong kind \(a value has the wrong type \(unsupported format string\)\)"):
            report.collect_report(files / "g")


def test_fixed_format_from_dict_names_the_missing_key():
    from pwas_hdl.fixedpoint.formats import FixedFormat

    with pytest.raises(InputError, match=r"not a fixed-point format description \(the key 'bits' is missing\)"):
        FixedFormat.from_dict({"frac": 3})


# --- API-side messages ---------------------------------------------------------------------------------

def test_unreachable_scheduler_says_what_to_do():
    from pwas_hdl.flow.executor import Executor

    with mock.patch("distributed.Client", side_effect=OSError("connection refused")):
        ex = Executor(scheduler="tcp://127.0.0.1:1")
        with pytest.raises(InputError, match=r"\(--scheduler\): connection refused; start the scheduler .* --workers N"):
            ex._connect()


def test_output_set_slot_of_an_unknown_path(tmp_path):
    from pwas_hdl.io.atomic import OutputSet

    with pytest.raises(InputError, match=r"was not added to this OutputSet; call OutputSet.add\(\) with it first"):
        OutputSet()._slot(tmp_path / "x.csv")


# --- counts and lengths (the lead's follow-up) -----------------------------------------------------------

def test_empty_partition_list_and_domain_count_say_what_to_give(tmp_path):
    (tmp_path / "s.csv").write_text("a,b,f\n" + "".join(f"{i % 7},{i % 5},{i}\n" for i in range(40)))
    (tmp_path / "d.csv").write_text("y,z\n" + "".join(f"{i % 7},{i}\n" for i in range(40)))
    assert_refused(fit(tmp_path / "d.csv", tmp_path / "x.json", "-p", ","), "is empty", "one or more integers")
    res = invoke("fit-map", tmp_path / "s.csv", "-o", tmp_path / "m.json", "-u", "a,b", "-z", "f", "-p", 2,
                 "--domain", "0:7")
    assert_refused(res, "--domain gives 1 interval(s) for 2 argument(s)", "one lo:hi a column", "(a, b)")
    assert not (tmp_path / "x.json").exists() and not (tmp_path / "m.json").exists()


def test_a_trajectory_too_short_for_the_fed_back_estimates_says_what_to_change(tmp_path):
    rows = "".join(f"{r},{0.1 * i},{0.3 * (i % 4)},{0.2 * (i % 3)}\n" for r, n in ((0, 40), (1, 3)) for i in range(n))
    (tmp_path / "t.csv").write_text("run,u,y,z\n" + rows)
    res = invoke("fit", tmp_path / "t.csv", "-o", tmp_path / "x.json", "-u", "u", "-y", "y", "-z", "z", "--mu", 1, "--my", 1,
                 "-p", 2, "--sigma", "1e-3", "--mz", 3, "--z0", 0, "--traj-col", "run")
    assert_refused(res, "a trajectory has 3 samples but the lags and Mz = 3 need more than 3", "longer trajectories",
                   "a smaller --mz")
    assert not (tmp_path / "x.json").exists()


# --- the second audit: fit options named as typed ------------------------------------------------------

@pytest.mark.parametrize("extra, words", [
    (["--observer", "poles:2"], ["--observer (observer) must be deadbeat", "got 'poles:2'", "e.g. --observer poles:0.5"]),
    (["--features", "12"], ["--features (features) must be 11a or 11b", "got '12'"]),
    (["--blank-rows", "skip"], ["--blank-rows (blank_rows) must be one of error, break, got 'skip'"]),
    (["-p", "0"], ["-p/--partitions (partitions[0]) = 0", "give whole numbers >= 1"]),
    (["-p", "3,3,3"], ["-p/--partitions (partitions) must be one integer or 2 integers", "got [3, 3, 3]",
                       "2 comma-separated values"]),
    (["--domain", "0:1"], ["--domain (domain) gives 1 lower and 1 upper bound(s) for 2 regressors (y[t-1], y[t])",
                           "one lo:hi per regressor"]),
    (["--domain", "1:0,0:1"], ["--domain (domain): the interval of regressor y[t-1] is 1.0:0.0", "give lo < hi"]),
])
def test_fit_options_are_named_as_typed(files, tmp_path, extra, words):
    assert_refused(fit(files / "d.csv", tmp_path / "x.json", *extra), *words)
    assert not (tmp_path / "x.json").exists()


def test_grid_of_zero_width_says_what_each_dimension_needs():
    from pwas_hdl.fit.geometry import Grid

    with pytest.raises(InputError, match=r"zero or negative width \(\[1\.0, 0\.0\]\); every dimension needs hi > lo"):
        Grid([1.0], [0.0], 2)


# --- the second audit: fixed-point formats (generate, explore) -------------------------------------------

@pytest.fixture(scope="module")
def models(files):
    """More models of the Lorenz data: per-lag partitions, non-uniform partitions, an additive sensor."""
    for name, extra in (("perlag", ["-p", "3,4"]), ("quantile", ["--breakpoints", "quantile"]),
                        ("pow2", ["--breakpoints", "quantile-pow2"]), ("additive", ["--my", 3, "--additive", "pairs"])):
        res = fit(files / "d.csv", files / f"{name}.json", "--sigma", "1e-3", *extra)
        assert res.exit_code == 0, res.output
    return files


@pytest.mark.parametrize("model, extra, words", [
    ("m", ["--weight-frac", 100], ["--weight-frac (weight_frac) = 100 makes the weights too large for 64-bit codes",
                                   "use fewer fraction bits (--weight-frac 51 at most)"]),
    ("m", ["--weight-frac", 51], ["the outputs would need 65 bits at --output-frac (output_frac) = 52 (the default)",
                                  "use a smaller --output-frac (at most 51) or --weight-frac"]),
    ("m", ["--weight-frac", 50], ["the accumulator would need", "fewer input bits (--input-bits)",
                                  "a smaller --weight-frac or --weight-bits"]),
    ("m", ["--weight-bits", 3], ["does not fit the weight format", "or --overflow saturate"]),
    ("m", ["--design", "recurrent"], ["--design recurrent needs a recurrent model", "use --design sensor or core"]),
    ("perlag", ["--design", "sensor"], ["the lags of signal 'y' have different input formats",
                                        "fit without --separate-lag-domains", "one -p value for all lags"]),
    ("pow2", ["--input-bits", 2], ["2-bit inputs cannot give each one a code", "use --input-bits", "or more (input_bits)"]),
    ("additive", ["--output-frac", 100], ["--output-frac (output_frac) = 100 is finer than the exact sum",
                                          "use --output-frac <= "]),
    ("additive", ["--output-frac", -40], ["--output-frac (output_frac) = -40 (LSB 2^40) rounds every output",
                                          "use a larger --output-frac (at most "]),
])
def test_generate_format_errors_name_the_option(models, tmp_path, model, extra, words):
    msg = assert_refused(invoke("generate", models / f"{model}.json", "-o", tmp_path / "g", *extra), *words)
    assert "output_frac =" not in msg.replace("(output_frac) =", "")  # the option, not only the parameter
    assert not (tmp_path / "g").exists()


def test_explore_refuses_what_it_cannot_sweep_up_front(models, tmp_path):
    # non-uniform cells that are not power-of-two multiples of one step: the warp's own message (explore
    # sweeps quantile-pow2 partitions, tests/test_explore_kinds.py)
    res = invoke("explore", models / "quantile.json", models / "t.csv", "-o", tmp_path / "ex")
    assert_refused(res, "are not power-of-two multiples of one base step", "--breakpoints quantile-pow2")
    res = invoke("explore", models / "m.json", models / "t.csv", "-o", tmp_path / "ex", "--overflow", "wrap")
    msg = assert_refused(res, "--overflow (overflow) must be one of error, saturate, got 'wrap'")
    assert "every requested combination" not in msg
    assert not (tmp_path / "ex").exists()


def test_fixed_point_model_of_a_non_uniform_grid_names_the_warped_model():
    from pwas_hdl.fit.geometry import Grid
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel

    grid = Grid([0.0], [1.0], 2, breakpoints=[[0.0, 0.25, 1.0]])
    with pytest.raises(InputError, match=r"build pwas_hdl\.fixedpoint\.warp\.WarpedFixedPointModel, as generate and simulate do"):
        FixedPointModel(grid, np.zeros(3))


# --- the second audit: make-data and fit-map options -----------------------------------------------------

@pytest.mark.parametrize("args, words", [
    (["switched-linear", "--switching", "random"], ["--switching (switching) must be one of time, output, got 'random'"]),
    (["switched-linear", "--input-signal", "chirp"], ["--input-signal (input_kind) must be one of step, prbs, sine, got 'chirp'"]),
    (["pv-benchmark", "--rho-law", "linear"], ["--rho-law (rho_law) must be one of random-walk, cosine, got 'linear'"]),
    (["three-tank", "--noise", "-1"], ["got -1.0", "give a --noise from 0 (no noise) to 1000"]),
])
def test_make_data_options_are_named_as_typed(tmp_path, args, words):
    msg = assert_refused(invoke("make-data", args[0], "-o", tmp_path / "x.csv", *args[1:]), *words)
    assert "smaller --noise" not in msg
    assert not (tmp_path / "x.csv").exists()


def test_fit_map_and_z0_options_are_named_as_typed(files, tmp_path):
    (tmp_path / "s.csv").write_text("a,b,f\n" + "".join(f"{i % 7},{i % 5},{i}\n" for i in range(40)))
    args = ["fit-map", tmp_path / "s.csv", "-o", tmp_path / "m.json", "-u", "a,b", "-z", "f", "-p", 2]
    assert_refused(invoke(*args, "--domain", "1:0,0:1"), "the box (--domain) must have finite bounds with lo < hi",
                   "lo = [1.0, 0.0]", "give one lo:hi with lo < hi per argument")
    assert_refused(invoke(*args, "--sigma", "-1"), "--sigma (sigma) must be a positive number, got -1.0", "e.g. --sigma")
    res = invoke("fit-map", tmp_path / "s.csv", "-o", tmp_path / "m.json", "-u", "a", "--state", "b", "-z", "f",
                 "--z0", "zero")
    msg = assert_refused(res, "--z0 must be one number per --state column (comma-separated), got 'zero'")
    assert "logspace" not in msg
    msg = assert_refused(fit(files / "d.csv", tmp_path / "x.json", "--mz", 1, "--z0", "zero"),
                         "--z0 must be mean, measured or one number per -z/--targets column", "got 'zero'")
    assert "logspace" not in msg
    assert not (tmp_path / "m.json").exists() and not (tmp_path / "x.json").exists()


# --- the second audit: cross-validation folds, sensor-top messages in CLI terms ----------------------------

def test_folds_are_named_as_typed(files, tmp_path):
    assert_refused(fit(files / "d.csv", tmp_path / "x.json", "--folds", 1),
                   "--folds (cv_folds) must be an integer >= 2, got 1", "give --folds 2 or more")
    res = invoke("fit", files / "d.csv", "-o", tmp_path / "x.json", "-y", "y", "-z", "z", "--my", 2, "-p", 3, "--folds", 1000)
    assert_refused(res, "cannot split 599 samples into 1000 folds (--folds)", "use --folds 599 or fewer")
    assert not (tmp_path / "x.json").exists()


def test_sensor_top_messages_say_which_command_builds_what(models):
    from pwas_hdl.fit.model_file import read_model
    from pwas_hdl.fit.regressors import LagStructure
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel
    from pwas_hdl.hdl import lag_plan
    from pwas_hdl.hdl.params import CoreParams
    from pwas_hdl.hdl.sensor_top import PWASSensorTop

    with pytest.raises(InputError, match=r"no feedback path; build the recurrent top instead \(generate --design sensor does"):
        lag_plan(types.SimpleNamespace(n=3, regressor_signals=[]), LagStructure(1, 1, 1, 1, mz=1, nz=1))
    params = CoreParams.from_model(FixedPointModel.from_sensor(read_model(models / "perlag.json")))
    with pytest.raises(InputError, match=r"fit without --separate-lag-domains \(share_lag_domain=True\) and with one -p value"):
        PWASSensorTop(params, [("y", 2)], [(0, 1), (0, 0)])


@pytest.mark.parametrize("extra,words", [
    (["--coef-frac", "41"], ["--coef-frac (coef_frac) must be in 1..40, got 41"]),
    (["--state-frac", "41"], ["--state-frac (state_frac) must be <= 40, got 41"]),
])
def test_observer_bank_fractions_name_the_value_that_is_wrong(tmp_path, files, extra, words):
    """One check said '--coef-frac must be in 1..40 and --state-frac <= 40, got 41, 21': which one?"""
    res = invoke("fit", files / "d.csv", "-o", tmp_path / "ob.json", "-y", "y", "-z", "z", "--my", 0, "-p", 2,
                 "--sigma", 1, "--front-end", "observer-bank", "--models", 2)
    assert res.exit_code == 0, res.output
    assert_refused(invoke("generate", tmp_path / "ob.json", "-o", tmp_path / "g", "--design", "sensor", *extra), *words)
    assert not (tmp_path / "g").exists()


def test_a_target_too_small_for_fixed_point_says_to_rescale_it(tmp_path):
    """A target of ~1e-310 fits (RMSE 0 at print precision); generate then said '--weight-frac
    (weight_frac) = 1043 is out of the supported range', an option the user never gave."""
    rng = np.random.default_rng(0)
    y = rng.normal(size=400)
    z = 1e-310 * (1 + 0.5 * np.tanh(y) + 0.01 * rng.normal(size=400))
    (tmp_path / "d.csv").write_text("y,z\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(y, z)))
    res = invoke("fit", tmp_path / "d.csv", "-o", tmp_path / "m.json", "-y", "y", "-z", "z", "--my", 1, "-p", 3,
                 "--sigma", "1e-3")
    assert res.exit_code == 0, res.output
    assert_refused(invoke("generate", tmp_path / "m.json", "-o", tmp_path / "g"), "the default --weight-frac (weight_frac) = ",
                   "the target's values are too small for fixed point", "rescale the target column")
    assert not (tmp_path / "g").exists()


@pytest.mark.parametrize("text", ["y,z\n1,2\n,3\n2,4\n", "y,z\n1,2\n2, \n2,4\n"])
def test_an_empty_cell_is_called_a_missing_sample_with_the_fix(tmp_path, text):
    """An empty cell read as "'' is not a number (ASCII digits, ...)"; it is a missing sample."""
    (tmp_path / "e.csv").write_text(text)
    assert_refused(invoke("fit", tmp_path / "e.csv", "-o", tmp_path / "m.json", "-y", "y", "-z", "z", "--my", 1, "-p", 1,
                          "--sigma", 1), "line 3, column", "is empty (a missing sample)", "--blank-rows break")
    assert not (tmp_path / "m.json").exists()
