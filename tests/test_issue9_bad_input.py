"""Issue 9: every bad-input class of the CLI fuzz run, one regression test (or more) each.

The promise checked: exit status 2 with one ``error:`` line that says what is wrong, and the file
tree unchanged (no output, no temporary); or, for a verification that found a difference, exit 1.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from helpers.cli import CliRunner, assert_refused

from pwas_hdl.cli import app
from pwas_hdl.errors import InputError, ResourceLimit
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.io.atomic import TEMP_MARK, OutputSet, check_output_path, clean_stale_temps, make_temp_dir
from pwas_hdl.io.csv_table import read_csv, split_trajectories
from pwas_hdl.limits import MAX_CSV_FIELD, MAX_REGRESSORS, MAX_SAMPLES, MAX_SIGMA_CANDIDATES, MAX_VERTICES
from helpers.folders import tree

runner = CliRunner()


def invoke(*args, cwd: Path | None = None):
    old = os.getcwd()
    if cwd is not None:
        os.chdir(cwd)
    try:
        return runner.invoke(app, [str(a) for a in args])
    finally:
        os.chdir(old)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("issue9")
    res = invoke("make-data", "lorenz", "-o", d / "d.csv", "--samples", 600, "--test-out", d / "t.csv",
                 "--test-samples", 200)
    assert res.exit_code == 0, res.output
    res = invoke("fit", d / "d.csv", "-o", d / "m.json", "-y", "y", "-z", "z", "--my", 2, "-p", 3,
                 "--sigma", "1e-3")
    assert res.exit_code == 0, res.output
    return d


@pytest.fixture(scope="module")
def design(files):
    res = invoke("generate", files / "m.json", "-o", files / "g")
    assert res.exit_code == 0, res.output
    return files / "g"


@pytest.fixture
def work(tmp_path, files):
    """A scratch folder holding copies of the data and the model."""
    for nm in ("d.csv", "t.csv", "m.json"):
        (tmp_path / nm).write_bytes((files / nm).read_bytes())
    return tmp_path


# ----------------------------------------------------------------------------------- output paths
@pytest.mark.parametrize(
    "out, frag",
    [
        ("", "the output path is empty"),
        ("d.csv/x.csv", "goes through 'd.csv', which is a file"),
        ("a" * 300 + ".csv", "more than the 255 bytes a file name may have"),
        ("nodir/x.csv", "folder 'nodir' does not exist"),
        (".", "'.' is a folder; give a file name"),
    ],
)
def test_bad_output_path_refused_before_work(work, out, frag):
    before = tree(work)
    assert_refused(invoke("make-data", "lorenz", "-o", out, "--samples", 50, cwd=work), frag)
    assert_refused(invoke("predict", "m.json", "t.csv", "-o", out, cwd=work), frag)
    assert_refused(invoke("fit", "d.csv", "-o", out, "-y", "y", "-z", "z", "--sigma", 1, cwd=work), frag)
    assert tree(work) == before


def test_output_folder_path_too_long(work):
    long = "/".join(["x" * 200] * 25)  # > PATH_MAX
    before = tree(work)
    assert_refused(invoke("generate", "m.json", "-o", long, cwd=work), "the path is")
    assert tree(work) == before


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_unwritable_output_folder(work):
    ro = work / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert_refused(invoke("make-data", "lorenz", "-o", ro / "x.csv", "--samples", 50), "is not writable")
    finally:
        ro.chmod(0o755)


def test_unwritable_check_uses_access(tmp_path, monkeypatch):
    """The writability test itself (also where the tests run as root): os.access(W_OK) false -> refused."""
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: False if Path(p) == tmp_path else real(p, mode, **kw))
    with pytest.raises(InputError, match="is not writable"):
        check_output_path(tmp_path / "x.csv", "-o")


def test_same_file_twice_is_refused(work):
    before = tree(work)
    assert_refused(invoke("make-data", "lorenz", "-o", "n.csv", "--test-out", "n.csv", cwd=work),
                   "-o/--out and --test-out both name 'n.csv'")
    assert_refused(invoke("make-data", "lorenz", "-o", "n.csv", "--test-out", "./n.csv", cwd=work),
                   "both name")
    # an output that is also the input: the training data would be overwritten by the model
    assert_refused(invoke("fit", "d.csv", "-o", "d.csv", "-y", "y", "-z", "z", "--sigma", 1, cwd=work),
                   "is also the input DATA")
    assert tree(work) == before


def test_second_output_bad_writes_neither(work, design):
    """All-or-nothing across several outputs: the good first path is not written when the second is bad."""
    before = tree(work)
    assert_refused(invoke("report", design, "--md", work / "r.md", "--json", work / "nodir" / "r.json"), "nodir")
    assert_refused(invoke("bench", "lorenz", "--json", work / "b.json", "--md", work / "nodir" / "b.md", "--quick"), "nodir")
    # simulate: refused before the simulator is started (no RTL run needed for this test)
    assert_refused(invoke("simulate", design, work / "t.csv", "-o", work / "s.csv", "--json", work / "nodir" / "s.json"),
                   "nodir")
    assert_refused(invoke("simulate", design, work / "t.csv", "-o", work / "s.json"), "both name")
    assert tree(work) == before


def test_output_set_all_or_nothing(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old")
    with pytest.raises(RuntimeError):
        with OutputSet() as outs:
            outs.add(a, "-o")
            outs.add(b, "--json")
            outs.write_text(a, "new")
            raise RuntimeError("the work failed after the first output was staged")
    assert a.read_text() == "old" and sorted(os.listdir(tmp_path)) == ["a.txt"]
    with OutputSet() as outs:
        outs.add(a, "-o")
        outs.add(b, "--json")
        outs.write_text(a, "new")
        outs.write_text(b, "B")
    assert a.read_text() == "new" and b.read_text() == "B" and sorted(os.listdir(tmp_path)) == ["a.txt", "b.txt"]


def test_build_dir_that_is_a_file(work, design):
    before = tree(work)
    assert_refused(invoke("simulate", design, work / "t.csv", "-o", work / "s.csv", "--build-dir", work / "d.csv"),
                   "--build-dir", "is not a folder")
    assert_refused(invoke("explore", work / "m.json", work / "t.csv", "-o", work / "e", "--input-bits", 12,
                          "--fpga", "generic", "--synth-dir", work / "d.csv"), "--synth-dir", "is not a folder")
    assert tree(work) == before


def test_generate_outdir_checked_before_building(work):
    before = tree(work)
    assert_refused(invoke("generate", work / "m.json", "-o", work / "d.csv"), "exists and is not a folder")
    assert_refused(invoke("generate", work / "m.json", "-o", work / "d.csv" / "g"), "which is a file")
    assert tree(work) == before


# ----------------------------------------------------------------------------------- temporaries
def test_stale_temporaries_of_a_killed_run_are_cleaned(tmp_path, work):
    """A run killed outright leaves pid-named temporaries; the next run in that folder removes them
    (and only those whose process is gone)."""
    code = textwrap.dedent(
        f"""
        import os, signal
        from pwas_hdl.io.atomic import make_temp_dir
        d = make_temp_dir({str(work)!r}, "g")
        (d / "half.v").write_text("module")
        os.kill(os.getpid(), signal.SIGKILL)
        """
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True)
    assert proc.returncode == -signal.SIGKILL
    stale = [p for p in os.listdir(work) if TEMP_MARK in p]
    assert len(stale) == 1 and stale[0].startswith(".g" + TEMP_MARK)
    mine = make_temp_dir(work, "live")  # this process is alive: its temporaries stay
    res = invoke("generate", work / "m.json", "-o", work / "g")
    assert res.exit_code == 0, res.output
    left = sorted(p for p in os.listdir(work) if TEMP_MARK in p)
    assert left == [mine.name]
    mine.rmdir()
    assert clean_stale_temps(work) == []


def _sigterm_during(cmd_code: str, tmp: Path) -> subprocess.CompletedProcess:
    """Run ``cmd_code`` in a fresh interpreter with the CLI's SIGTERM handler; the patched write
    sends SIGTERM to the process itself once the first temporary has content (deterministic)."""
    code = textwrap.dedent(
        """
        import os, signal, sys
        from pwas_hdl.io import atomic
        atomic.install_termination_handler()
        """
    ) + textwrap.dedent(cmd_code)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp)


def test_sigterm_during_generate_leaves_nothing(work):
    before = tree(work)
    proc = _sigterm_during(
        """
        import pathlib
        from pwas_hdl.design import generate as gen
        real = pathlib.Path.write_text
        def write_then_term(self, *a, **k):
            n = real(self, *a, **k)
            os.kill(os.getpid(), signal.SIGTERM)   # mid-way through writing the folder
            return n
        pathlib.Path.write_text = write_then_term
        gen.generate("m.json", "g")
        print("not reached")
        """,
        work,
    )
    assert proc.returncode == 128 + signal.SIGTERM, proc.stderr
    assert "not reached" not in proc.stdout
    assert tree(work) == before


def test_sigterm_during_fit_output_leaves_nothing(work):
    before = tree(work)
    proc = _sigterm_during(
        """
        from pwas_hdl.io.atomic import OutputSet
        with OutputSet() as outs:
            outs.add("m2.json", "-o")
            outs.add("m3.json", "--json")
            outs.write_text("m2.json", "x" * 1000)
            os.kill(os.getpid(), signal.SIGTERM)
            outs.write_text("m3.json", "y")
        """,
        work,
    )
    assert proc.returncode == 128 + signal.SIGTERM, proc.stderr
    assert tree(work) == before


# ----------------------------------------------------------------------------------- CSV
def _csv(tmp_path, name: str, data: bytes) -> Path:
    p = tmp_path / name
    p.write_bytes(data)
    return p


@pytest.mark.parametrize("cell", ["1_0", "1_000.5", "\u0661", "\uff13", "\u0663.5", "١e3"])
def test_csv_numbers_are_ascii_without_underscores(tmp_path, cell):
    assert float(cell) is not None  # Python's float takes all of these
    t = read_csv(_csv(tmp_path, "d.csv", f"u,y\n1,2\n{cell},3\n".encode()))
    with pytest.raises(InputError, match=r"line 3, column 'u': .* is not a number"):
        t.numeric(["u"])


@pytest.mark.parametrize("cell, value", [(" 1e3 ", 1e3), ("+.5", 0.5), ("-7.", -7.0), ("1E-2", 0.01), ("\u00a02", 2.0)])
def test_csv_numbers_python_accepts_still_read(tmp_path, cell, value):
    t = read_csv(_csv(tmp_path, "d.csv", f"u,y\n1,2\n{cell},3\n".encode()))
    assert t.numeric(["u"])[1, 0] == value


def test_csv_field_over_128_kib(tmp_path, work):
    p = _csv(work, "big.csv", b"y,z\n1,2\n3," + b"9" * (MAX_CSV_FIELD + 1) + b"\n")
    with pytest.raises(ResourceLimit, match=rf"line 3 has a cell longer than the limit of {MAX_CSV_FIELD}"):
        read_csv(p)
    before = tree(work)
    assert_refused(invoke("fit", p, "-o", work / "x.json", "-y", "y", "-z", "z"), "131072")
    assert tree(work) == before
    ok = _csv(tmp_path, "ok.csv", b"y,z\n1," + b"9" * (MAX_CSV_FIELD - 10) + b"\n")  # just below: read
    assert len(read_csv(ok).rows[0][1]) == MAX_CSV_FIELD - 10


def test_csv_blank_row_is_an_error_unless_asked(tmp_path, work):
    p = _csv(tmp_path, "b.csv", b"y,z\n1,2\n3,4\n\n5,6\n7,x\n\n")
    with pytest.raises(InputError, match="line 4 is blank; .*--blank-rows break"):
        read_csv(p)
    t = read_csv(p, blank_rows="break")
    assert split_trajectories(t, None) == [slice(0, 2), slice(2, 4)]
    with pytest.raises(InputError, match="line 6, column 'z'"):  # line numbers count the blank row
        t.numeric(["z"])
    # trailing blank lines are not rows between data: accepted
    assert len(read_csv(_csv(tmp_path, "trail.csv", b"y,z\n1,2\n\n\n"))) == 1
    # through the CLI: error by default; with break, no regressor straddles the blank row
    lines = (work / "t.csv").read_text().splitlines()
    blank = work / "blank.csv"
    blank.write_text("\n".join(lines[:101] + [""] + lines[101:]) + "\n")
    before = tree(work)
    assert_refused(invoke("predict", work / "m.json", blank, "-o", work / "p.csv"), "line 102 is blank")
    assert tree(work) == before
    res = invoke("predict", work / "m.json", blank, "-o", work / "p.csv", "--blank-rows", "break")
    assert res.exit_code == 0, res.output
    rows = [int(r.split(",")[0]) for r in (work / "p.csv").read_text().splitlines()[1:]]
    assert 100 not in rows  # My = 2: the first row after the break has no regressor
    assert len(rows) == 200 - 2 * 1


def test_csv_trajectory_cuts_at_the_first_and_last_rows(tmp_path):
    """A one-sample trajectory at either end is a trajectory of its own, whether a trajectory column
    or a blank row marks it; several blank lines in a row are one break, named by the first."""
    t = read_csv(_csv(tmp_path, "runs.csv", b"run,y\na,1\nb,2\nb,3\nc,4\n"))
    assert split_trajectories(t, "run") == [slice(0, 1), slice(1, 3), slice(3, 4)]
    assert split_trajectories(t, None) == [slice(0, 4)]
    t = read_csv(_csv(tmp_path, "ends.csv", b"y\n1\n\n2\n3\n\n\n4\n"), blank_rows="break")
    assert split_trajectories(t, None) == [slice(0, 1), slice(1, 3), slice(3, 4)]
    assert t.lines == [2, 4, 5, 8]
    with pytest.raises(InputError, match="line 6 is blank"):
        read_csv(_csv(tmp_path, "two.csv", b"y\n1\n2\n3\n4\n\n\n5\n"))


def test_csv_bom_is_dropped_and_never_shown(tmp_path):
    p = _csv(tmp_path, "bom.csv", b"\xef\xbb\xbfy,z\n1,2\n")
    t = read_csv(p)
    assert t.header == ["y", "z"] and t.numeric(["y"])[0, 0] == 1.0
    with pytest.raises(InputError) as exc:
        t.column_index("q")
    assert "\ufeff" not in str(exc.value) and "columns y, z" in str(exc.value)
    # a second BOM (or another invisible character) inside a name is refused, not shown
    with pytest.raises(InputError, match="invisible character"):
        read_csv(_csv(tmp_path, "bom2.csv", b"\xef\xbb\xbf\xef\xbb\xbfy,z\n1,2\n"))


def test_csv_spaces_in_column_names_are_kept(work):
    lines = (work / "d.csv").read_text().splitlines()
    lines[0] = lines[0].replace("y", "my y", 1).replace("z", " the z ", 1)
    p = work / "sp.csv"
    p.write_text("\n".join(lines) + "\n")
    assert read_csv(p).header[:2] == ["my y", "the z"]
    res = invoke("fit", p, "-o", work / "sp.json", "--output", "my y", "--target", "the z", "--my", 2, "-p", 2,
                 "--sigma", 1)
    assert res.exit_code == 0, res.output
    assert json.loads((work / "sp.json").read_text())["signals"]["outputs"] == ["my y"]
    assert_refused(invoke("fit", p, "-o", work / "sp2.json", "--output", "myy", "--target", "the z", "--sigma", 1),
                   "no column named 'myy'")


def test_csv_not_utf8_names_file_and_offset(work):
    p = _csv(work, "latin.csv", b"y,z\n1,2\n3,\xe94\n")
    with pytest.raises(InputError, match=r"latin.csv is not UTF-8 text: byte 0xe9 at offset 10 \(line 3\)"):
        read_csv(p)
    assert_refused(invoke("predict", work / "m.json", p, "-o", work / "p.csv"), "latin.csv", "offset 10")


def test_csv_column_name_with_newline_refused(tmp_path):
    with pytest.raises(InputError, match="line break"):
        read_csv(_csv(tmp_path, "nl.csv", b'"y\nz",z\n1,2\n'))


def test_csv_malformed_quotes_refused(tmp_path):
    with pytest.raises(InputError, match=r"line 2: malformed CSV"):
        read_csv(_csv(tmp_path, "q.csv", b'y,z\n1,"2\n'))


def test_csv_unreadable_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="is a folder"):
        read_csv(tmp_path)


# ----------------------------------------------------------------------------------- resource limits
def test_vertices_refused_before_allocating():
    with pytest.raises(ResourceLimit, match=rf"N = prod\(p_j \+ 1\) = {10**8} vertices, more than the limit of {MAX_VERTICES}"):
        Grid([0.0] * 4, [1.0] * 4, 99)
    # int64 strides would overflow: refused with Python integers, never wrapped
    with pytest.raises(ResourceLimit, match="more than the limit"):
        Grid([0.0] * 3, [1.0] * 3, [2**40, 2**40, 2**40])
    with pytest.raises(ResourceLimit, match="more than the limit"):
        Grid([0.0], [1.0], 10**30)
    g = Grid([0.0] * 2, [1.0] * 2, 1023)  # exactly the limit: accepted
    assert g.n_vertices == MAX_VERTICES


def test_weights_over_all_targets_refused_before_the_fit(work):
    """N x targets over MAX_WEIGHTS: refused before any array (20 targets at N = 2^20 once fitted at
    2.8 GB under a 1 GB limit, wrote a 170 MB model and took minutes to load)."""
    from pwas_hdl.limits import MAX_WEIGHTS

    rng = np.random.default_rng(0)
    targets = [f"z{i}" for i in range(5)]
    p = work / "many.csv"
    p.write_text(",".join(["y"] + targets) + "\n" + "\n".join(",".join(repr(float(v)) for v in r)
                                                             for r in rng.standard_normal((60, 6))) + "\n")
    before = tree(work)
    # My = 20, p = 1: N = 2^20 per target, 5 targets = 5 x 2^20 weights > MAX_WEIGHTS = 2^22
    assert_refused(invoke("fit", p, "-o", work / "w.json", "-y", "y", "-z", ",".join(targets), "--my", 20, "-p", 1,
                          "--sigma", 1e-3), f"the weights N x targets (1048576 x 5) = 5242880 exceeds the limit of {MAX_WEIGHTS}",
                   "one model per target")
    assert tree(work) == before


def test_model_file_over_the_weight_limit_and_json_size_cap(work, monkeypatch):
    from pwas_hdl.fit import model_file
    from pwas_hdl.io import json_contract

    d = json.loads((work / "m.json").read_text())
    monkeypatch.setattr("pwas_hdl.limits.MAX_WEIGHTS", 10)  # N = 16 > 10: as a model over 2^22 weights would be
    errs = model_file._consistency_errors(d)
    assert errs and "the weights N x targets (16 x 1) = 16 exceeds the limit of 10" in errs[0]
    monkeypatch.setattr(json_contract, "MAX_JSON_BYTES", 100)
    assert_refused(invoke("info", work / "m.json"), "bytes, more than the limit of 100 bytes of a JSON file")


def test_breakpoints_sizes_refused_before_the_schema_check(work):
    big = work / "bp.json"
    big.write_text(json.dumps({"format": "pwas-hdl-breakpoints", "version": 1, "breakpoints": [list(range(2_000_000))]}))
    before = tree(work)
    assert_refused(invoke("fit", work / "d.csv", "-o", work / "w.json", "-y", "y", "-z", "z", "--my", 1,
                          "--breakpoints", big, "--sigma", 1), "the vertices N = prod(cut points per list) = 2000000",
                   f"limit of {MAX_VERTICES}")
    assert tree(work) == before


def test_many_inputs_refused_not_a_segfault(work):
    """64+ inputs overflowed the int64 strides (a segfault); now the dimension limit refuses them."""
    rng = np.random.default_rng(0)
    cols = [f"y{i}" for i in range(70)]
    data = rng.uniform(0, 1, (40, 71))
    p = work / "wide.csv"
    p.write_text(",".join(cols + ["z"]) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in data) + "\n")
    before = tree(work)
    assert_refused(invoke("fit", p, "-o", work / "w.json", "--output", ",".join(cols), "--target", "z", "-p", 1,
                          "--sigma", 1), f"= 70 exceeds the limit of {MAX_REGRESSORS}")
    assert_refused(invoke("fit", work / "d.csv", "-o", work / "w.json", "-y", "y", "-z", "z",
                          "--my", 10**6, "--sigma", 1), "exceeds the limit of 20")
    assert_refused(invoke("fit", work / "d.csv", "-o", work / "w.json", "-y", "y", "-z", "z",
                          "--my", 4, "-p", 10**20, "--sigma", 1), "more than the limit of 1048576")
    assert tree(work) == before


def test_sigma_grid_and_samples_limits(work):
    before = tree(work)
    assert_refused(invoke("fit", work / "d.csv", "-o", work / "x.json", "-y", "y", "-z", "z",
                          "--sigma-grid", "logspace:-3:3:1000000000"), f"exceeds the limit of {MAX_SIGMA_CANDIDATES}")
    assert_refused(invoke("make-data", "lorenz", "-o", work / "x.csv", "--samples", 10**8),
                   f"--samples = {10**8} exceeds the limit of {MAX_SAMPLES}")
    assert_refused(invoke("make-data", "lorenz", "-o", work / "x.csv", "--samples", MAX_SAMPLES,
                          "--test-out", work / "y.csv"), "--samples + --test-samples")
    assert_refused(invoke("explore", work / "m.json", work / "t.csv", "-o", work / "e", "--input-bits", "2:100000000"),
                   "exceeds the limit of 10000")
    assert tree(work) == before
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    with pytest.raises(ResourceLimit, match="sigma candidates"):
        PWASVirtualSensor(my=1, sigma_grid=np.ones(MAX_SIGMA_CANDIDATES + 1)).fit(None, np.arange(10.0), np.arange(10.0))


# ----------------------------------------------------------------------------------- Verilog names
@pytest.mark.parametrize(
    "name, frag",
    [("module", "keyword"), ("logic", "keyword"), ("always_ff", "keyword"), ("wire", "keyword"),
     ("a b", "not a Verilog identifier"), ("1abc", "not a Verilog identifier"), ("x$y", "not a Verilog identifier"),
     ("top\nmodule", "not a Verilog identifier"), ("\\esc", "not a Verilog identifier"), ("a" * 201, "more than the limit")],
)
def test_generate_refuses_bad_module_names(work, name, frag):
    before = tree(work)
    assert_refused(invoke("generate", work / "m.json", "-o", work / "g", "--name", name), frag)
    assert tree(work) == before


def test_generate_accepts_a_keyword_in_another_case(work):
    res = invoke("generate", work / "m.json", "-o", work / "g", "--name", "Module")  # Verilog is case-sensitive
    assert res.exit_code == 0, res.output
    assert (work / "g" / "Module.v").read_text().count("module Module") == 1


def test_generate_refuses_signal_names_with_newlines(work):
    d = json.loads((work / "m.json").read_text())
    d["signals"]["outputs"] = ["y\nmodule evil;"]
    d["regressors"] = [r.replace("y", "y\nmodule evil;", 1) for r in d["regressors"]]
    (work / "nl.json").write_text(json.dumps(d))
    before = tree(work)
    assert_refused(invoke("generate", work / "nl.json", "-o", work / "g"), "line break")
    assert tree(work) == before


# ----------------------------------------------------------------------------------- model files
@pytest.mark.parametrize("key, value", [("My", 2.7), ("My", "2"), ("My", True), ("My", -1), ("Mu", 0.5)])
def test_model_with_non_integer_lags_refused(work, key, value):
    """`"My": 2.7` was read as 2 (the model-file schema of pwas_hdl.fit.model_file refuses it now)."""
    d = json.loads((work / "m.json").read_text())
    d["lags"][key] = value
    (work / "bad.json").write_text(json.dumps(d))
    for cmd in (["info", work / "bad.json"], ["predict", work / "bad.json", work / "t.csv", "-o", work / "p.csv"]):
        assert_refused(invoke(*cmd), f"lags.{key} must be")
    assert not (work / "p.csv").exists()


# ----------------------------------------------------------------------------------- formats
@pytest.mark.parametrize("opt, frag", [("--weight-frac", "rounds every weight to 0"), ("--output-frac", "rounds every output to 0")])
def test_format_that_loses_every_weight_refused(work, opt, frag):
    before = tree(work)
    assert_refused(invoke("generate", work / "m.json", "-o", work / "g", opt, -100), frag)
    assert tree(work) == before


def test_suggested_weight_frac_keeps_a_weight(work):
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.fixedpoint.bittrue import FixedPointModel

    m = PWASVirtualSensor.load(work / "m.json")
    with pytest.raises(InputError, match=r"--weight-frac (-?\d+) keeps") as exc:
        FixedPointModel.from_sensor(m, weight_frac=-100)
    fw = int(str(exc.value).split("--weight-frac ")[-1].split()[0])
    assert np.any(FixedPointModel.from_sensor(m, weight_frac=fw).weight_codes)
    with pytest.raises(InputError):
        FixedPointModel.from_sensor(m, weight_frac=fw - 2)


# ----------------------------------------------------------------------------------- explore, report
def test_explore_fails_when_every_requested_point_is_refused(work):
    before = tree(work)
    assert_refused(invoke("explore", work / "m.json", work / "t.csv", "-o", work / "e", "--input-bits", 12,
                          "--weight-frac", 0, "--output-frac", 30), "every requested combination", "finer than the exact product")
    assert tree(work) == before


@pytest.mark.parametrize("content", ["{}", "", "[]", '{"target": "ecp5"}', '{"target": "ecp5", "luts": null, "ffs": 1, "fmax_mhz": 1}'])
def test_report_with_empty_or_incomplete_synth_json(tmp_path, design, content):
    g = tmp_path / "g"
    g.mkdir()
    for f in design.iterdir():
        (g / f.name).write_bytes(f.read_bytes())
    (g / "synth" / "ecp5").mkdir(parents=True)
    (g / "synth" / "ecp5" / "synth.json").write_text(content)
    res = invoke("report", g)
    assert_refused(res, "synth.json")
    assert "None" not in res.output


# ----------------------------------------------------------------------------------- simulate
@pytest.mark.rtl
def test_simulate_exits_1_when_latency_disagrees_with_the_manifest(tmp_path, design, files, sim_cache):
    g = tmp_path / "g"
    g.mkdir()
    for f in design.iterdir():
        (g / f.name).write_bytes(f.read_bytes())
    man = json.loads((g / "manifest.json").read_text())
    man["latency_cycles"] -= 1
    # a self-consistent manifest (one register fewer in its pipeline, as the latency says) over the
    # unchanged Verilog: only the measurement can tell (an inconsistent one is refused when read, exit 2)
    stage = next(k for k in ("rank", "addr", "mem_out", "product") if man["pipeline"].get(k))
    man["pipeline"][stage] = False
    man["architecture"]["pipeline_registers"].remove(stage)  # the registers built, as the pipeline says
    (g / "manifest.json").write_text(json.dumps(man))
    res = invoke("simulate", g, files / "t.csv", "-o", tmp_path / "s.csv", "--build-dir", sim_cache)
    assert res.exit_code == 1, res.output
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["mismatches"] == 0  # every value is right: only the latency is wrong
    assert not summary["checks"]["passed"]
    assert any("the manifest says" in f for f in summary["checks"]["failures"])
    assert [ln for ln in res.output.splitlines() if ln.startswith("error:")][0].count("latency") >= 1


def test_error_line_is_printed_verbatim(work):
    """Rich would turn ':a:' into an emoji; the error line shows the text as it is."""
    res = invoke("fit", work / "d.csv", "-o", work / "x.json", "-y", "y", "-z", "z", "--sigma-grid", "logspace:a:b:3")
    assert_refused(res, "logspace:A:B:K", "'logspace:a:b:3'")


def test_model_file_not_utf8_names_the_offset(work):
    (work / "bad.json").write_bytes(b'{"format": "\xff"}')
    assert_refused(invoke("info", work / "bad.json"), "byte 0xff at offset 12")


def test_explore_api_refuses_a_huge_sweep_before_iterating(work):
    from pwas_hdl.flow.explore import explore

    with pytest.raises(ResourceLimit, match="input_bits values = 1000000000 exceeds the limit of 10000"):
        explore(work / "m.json", work / "t.csv", input_bits=range(10**9))


# the keys each command reads (a missing key it does not read is the manifest schema's business)
@pytest.mark.parametrize("key, report, simulate", [
    ("latency_cycles", True, True), ("formats", True, True), ("ports", False, True), ("domain", True, True),
    ("lags", True, False), ("error_bound", True, False), ("files", True, False), ("memory", True, False)])
def test_manifest_missing_a_key_is_one_error(tmp_path, design, files, key, report, simulate):
    """A hand-edited manifest: report and simulate refuse it (no KeyError), simulate before any simulator runs."""
    g = tmp_path / "g"
    shutil.copytree(design, g)
    man = json.loads((g / "manifest.json").read_text())
    del man[key]
    (g / "manifest.json").write_text(json.dumps(man))
    before = tree(tmp_path)
    if report:
        assert_refused(invoke("report", g), "manifest.json")
    if simulate:
        assert_refused(invoke("simulate", g, files / "t.csv", "-o", tmp_path / "s.csv"), "manifest.json")
    assert tree(tmp_path) == before


@pytest.mark.parametrize("path, value", [(("fit", "train_rmse", "z"), None), (("fit", "cv"), {"sigmas": [1], "mse": None, "best_sigma": 1, "folds": 2}),
                                         (("fit", "train_rmse"), {"z": "x"})])
def test_model_values_of_the_wrong_kind_refused_at_load(work, path, value):
    """Found by the fuzz suite: a null train RMSE loaded and then broke `info` with a TypeError."""
    d = json.loads((work / "m.json").read_text())
    node = d
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    (work / "w.json").write_text(json.dumps(d))
    assert_refused(invoke("info", work / "w.json"), ".".join(path[:2]))


def test_model_with_huge_lags_of_an_unused_signal_loads_at_once(work):
    """Found by the fuzz suite: "Mu": 10**30 with no inputs looped over 10**30 lags (a hang)."""
    d = json.loads((work / "m.json").read_text())
    d["lags"]["Mu"] = 10**30
    (work / "h.json").write_text(json.dumps(d))
    res = invoke("info", work / "h.json")
    assert res.exit_code in (0, 2), res.output
    if res.exit_code == 2:
        assert_refused(res)


def test_memory_estimate_counts_writing_the_model():
    """The model file's text is charged (about 140 bytes a weight at its peak): 4 targets at N = 2^20 need
    about 590 MB to write, which the estimate of the fit must hold."""
    from pwas_hdl.fit.regularized_lsq import MODEL_TEXT_BYTES_PER_WEIGHT, estimate_fit_memory

    one = estimate_fit_memory(600, 2**20, 20, n_targets=1, order=0)
    four = estimate_fit_memory(600, 2**20, 20, n_targets=4, order=0)
    assert four["model_file"] == MODEL_TEXT_BYTES_PER_WEIGHT * 4 * 2**20
    assert four["total"] - one["total"] >= 3 * MODEL_TEXT_BYTES_PER_WEIGHT * 2**20


@pytest.mark.parametrize("args, fragment", [
    (["-y", "y", "-z", "z,z"], "column 'z' is named twice in -z/--targets"),
    (["-y", "y,y", "-z", "z"], "column 'y' is named twice in -y/--outputs"),
    (["-y", "z", "-z", "z"], "given both as -y/--outputs and as -z/--targets (the model would read what it estimates)"),
    (["-u", "y", "--mu", "1", "-y", "y", "-z", "z"], "given both as -u/--inputs and as -y/--outputs"),
    (["-y", "y", "-z", "z", "--traj-col", "z"], "given both as -z/--targets and as --traj-col"),
    (["-u", "z_true", "-y", "y", "-z", "z"], "-u/--inputs z_true is given but --mu is 0"),
    (["-y", "y", "-z", "z", "--my", "0", "--mu", "1", "-u", "z_true"], "-y/--outputs y is given but --my is 0"),
    (["-y", "y", "-z", "z", "--mu", "-1"], "--mu and --my must be >= 0"),
    (["-y", "y", "-z", "z", "--sigma", "1", "--sigma-grid", "1,2"], "give --sigma (a fixed weight) or --sigma-grid"),
    (["-y", "y", "-z", "z", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "give --workers (a local cluster) or --scheduler"),
])
def test_fit_refuses_columns_with_two_roles_and_conflicting_options(work, args, fragment):
    """Each was accepted: a repeated target wrote a model every other command refused, a target read as
    a regressor leaked it, and a conflicting option was silently dropped."""
    before = tree(work)
    assert_refused(invoke("fit", work / "d.csv", "-o", work / "w.json", "-p", 2, *args), fragment)
    assert tree(work) == before


def test_fit_map_refuses_a_value_column_that_is_an_argument(work):
    rng = np.random.default_rng(0)
    a, b = rng.uniform(-1, 1, (2, 200))
    (work / "map.csv").write_text("a,b,f,s,s1\n" + "".join(f"{x},{y},{x * y},{x / 2},{x / 3 + y / 5}\n" for x, y in zip(a, b)))
    before = tree(work)
    assert_refused(invoke("fit-map", work / "map.csv", "-u", "a", "-z", "a", "-o", work / "o.json"),
                   "column 'a' is given both as -u/--inputs and as -z/--targets")
    assert_refused(invoke("fit-map", work / "map.csv", "-u", "a", "--state", "s1", "-z", "s1", "--z0", "0", "-o", work / "o.json"),
                   "column 's1' is given both as --state and as -z/--targets")
    assert tree(work) == before
    res = invoke("fit-map", work / "map.csv", "-u", "a", "--state", "s", "-z", "s1", "--z0", "0", "-o", work / "o.json")
    assert res.exit_code == 0 and "max s1:" in res.output, res.output  # the errors are the next state's


@pytest.mark.parametrize("args", [
    ["synth", "{g}", "--fpga", "generic", "-o", ""],
    ["explore", "m.json", "d.csv", "-o", " "],
    ["simulate", "{g}", "t.csv", "-o", "s.csv", "--build-dir", ""],
    ["export-testbench", "{g}", "-o", ""],
    ["synth", "{g}", "--fpga", "generic", "--out="],
    ["-q", "predict", "m.json", "t.csv", "-o", ""],
])
def test_an_empty_path_is_refused_not_taken_for_the_working_folder(work, design, args):
    """Click turns "" into Path(".") (the working folder): synth, explore and simulate wrote their files there."""
    before = tree(work)
    res = invoke(*[a.format(g=design) for a in args], cwd=work)
    assert_refused(res, "the output path is empty")
    assert tree(work) == before


@pytest.mark.skipif(not os.path.isdir("/sys") or os.access("/sys", os.W_OK) is False, reason="needs /sys, where access() says writable to root")
def test_a_folder_where_nothing_can_be_created_is_refused_naming_the_option(work):
    """root on /sys: access() says writable, creating fails; the message named the internal temporary file."""
    res = invoke("predict", work / "m.json", work / "t.csv", "-o", "/sys/pwas-probe.csv")
    assert_refused(res, "-o/--out '/sys/pwas-probe.csv': nothing can be written in the folder '/sys'")
    assert "pwas-tmp" not in res.output


def test_a_bad_sim_cache_variable_is_named_before_the_work(work, design, monkeypatch):
    """PWAS_HDL_SIM_CACHE naming a file: it said only 'cachefile: File exists', once simulating had started."""
    (work / "cachefile").write_text("x")
    monkeypatch.setenv("PWAS_HDL_SIM_CACHE", str(work / "cachefile"))
    before = tree(work)
    res = invoke("simulate", design, work / "t.csv", "-o", work / "s.csv")
    assert_refused(res, "$PWAS_HDL_SIM_CACHE", "exists and is not a folder")
    assert "simulating" not in res.output and tree(work) == before


@pytest.mark.parametrize("args", [["simulate", "{x}", "t.csv", "-o", "s.csv"], ["synth", "{x}"], ["report", "{x}"],
                                  ["export-testbench", "{x}"]])
@pytest.mark.parametrize("which", ["d.csv", "manifest"])
def test_a_file_given_as_the_design_folder_is_named_as_such(work, design, args, which):
    """A data file said 'd.csv is not valid JSON ... re-run generate'; the manifest itself 'manifest.json/model.json: Not a directory'."""
    x = str(work / "d.csv") if which == "d.csv" else str(design / "manifest.json")
    before = tree(work)
    assert_refused(invoke(*[a.format(x=x) for a in args], cwd=work), "is a file, not a folder written by `pwas-hdl generate`")
    assert tree(work) == before


def test_a_breakpoints_file_with_partitions_or_gamma_is_refused(work):
    """The file sets the cells and the domain: --gamma and a -p other than the file's were silently ignored."""
    bp = work / "bp.json"
    bp.write_text(json.dumps({"format": "pwas-hdl-breakpoints", "version": 1,
                              "breakpoints": [[-25, -8, 0, 8, 25], [-25, -5, 0, 5, 25]]}))
    before = tree(work)
    for extra, named in ((["-p", "7"], "-p/--partitions 7 differs from the intervals of --breakpoints"),
                         (["-p", "4,3"], "-p/--partitions 4,3 differs"), (["--gamma", "2"], "--gamma does not apply")):
        assert_refused(invoke("fit", work / "d.csv", "-o", work / "w.json", "-y", "y", "-z", "z", "--my", 2, "--sigma", 1e-3,
                              "--breakpoints", bp, *extra), named)
    assert tree(work) == before
    for same in ([], ["-p", "4"], ["-p", "4,4"]):  # leave -p out, or repeat the file's intervals
        assert invoke("fit", work / "d.csv", "-o", work / "w.json", "-y", "y", "-z", "z", "--my", 2, "--sigma", 1e-3,
                      "--breakpoints", bp, *same).exit_code == 0


@pytest.mark.parametrize("args, named", [
    (["-q", "predict", "m.json", "t.csv", "-o", "p.csv/"], "'-o' / '--out': 'p.csv/'"),
    (["fit", "d.csv", "-y", "y", "-z", "z", "-p", "2", "-o", "w.json/"], "'-o' / '--out': 'w.json/'"),
    (["make-data", "lorenz", "-o", "n.csv", "--test-out", "q.csv/"], "'--test-out': 'q.csv/'"),
    (["simulate", "{g}", "t.csv", "-o", "s.csv", "--json", "s.json/"], "'--json': 's.json/'"),
])
def test_a_file_option_ending_with_a_slash_is_refused(work, design, args, named, capsys, monkeypatch):
    """Click's Path("p.csv/") is Path("p.csv"): `-o p.csv/`, which names a folder, wrote the file p.csv.
    A usage error of the command line (refused while parsing it): run through the entry point."""
    from pwas_hdl.cli import main

    monkeypatch.chdir(work)
    before = tree(work)
    capsys.readouterr()
    assert main([a.format(g=design) for a in args]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith("error: Invalid value for ") and named in err[0], err
    assert "ends with '/', which names a folder; give a file name" in err[0], err
    assert tree(work) == before


def test_a_folder_option_may_end_with_a_slash(work):
    res = invoke("generate", "m.json", "-o", "hw/", cwd=work)
    assert res.exit_code == 0, res.output
    assert (work / "hw" / "manifest.json").is_file()


def test_an_output_that_is_a_symbolic_link_is_written_where_it_points(work):
    """Outputs are written by rename: a link at the output path was replaced by a regular file (a shell
    redirection, cp and the like write where it points)."""
    (work / "out").mkdir()
    (work / "link.csv").symlink_to(Path("out") / "real.csv")  # dangling: the file is created
    for _ in range(2):  # then replaced, the link kept
        res = invoke("-q", "predict", "m.json", "t.csv", "-o", "link.csv", cwd=work)
        assert res.exit_code == 0, res.output
        assert (work / "link.csv").is_symlink() and os.readlink(work / "link.csv") == os.path.join("out", "real.csv")
        assert (work / "out" / "real.csv").read_text().startswith("row,")
    (work / "hw").mkdir()
    (work / "hwlink").symlink_to("hw")  # a folder output through a link: the folder it names is written
    res = invoke("generate", "m.json", "-o", "hwlink", cwd=work)
    assert res.exit_code == 0, res.output
    assert (work / "hwlink").is_symlink() and (work / "hw" / "manifest.json").is_file()
    (work / "loop.csv").symlink_to("loop.csv")
    before = tree(work)
    assert_refused(invoke("-q", "predict", "m.json", "t.csv", "-o", "loop.csv", cwd=work),
                   "-o/--out 'loop.csv' is a symbolic link that leads to itself")
    assert_refused(invoke("make-data", "lorenz", "-o", "link.csv", "--test-out", "out/real.csv", cwd=work), "both name")
    assert tree(work) == before


@pytest.mark.parametrize("cell, frag", [("nan", "column 'z_true' is 'nan'"), ("abc", "'abc' is not a number")])
def test_predict_bad_reference_column_writes_nothing(work, cell, frag):
    """A bad cell in DATA's reference column (z_true, read only for the RMSE) used to be found after
    the estimates were written: exit 2 with -o left behind. The RMSE is now computed before writing."""
    lines = (work / "t.csv").read_text().splitlines()
    head = lines[0].split(",")
    row = lines[50].split(",")
    row[head.index("z_true")] = cell
    (work / "badz.csv").write_text("\n".join(lines[:50] + [",".join(row)] + lines[51:]) + "\n")
    before = tree(work)
    assert_refused(invoke("predict", "m.json", "badz.csv", "-o", "p.csv", cwd=work), "badz.csv", "line 51", frag)
    assert tree(work) == before


@pytest.mark.parametrize("args", [
    ["make-data", "lorenz", "-o", "o.csv", "--samples", 50],
    ["make-data", "helicopter", "-o", "o.csv", "--samples", 50],
    ["make-data", "pv-benchmark", "-o", "o.csv", "--samples", 50],
    ["make-data", "switching-4", "-o", "o.csv", "--samples", 50],
    ["make-data", "battery", "-o", "o.csv", "--samples", 50],
    ["fit-map", "d.csv", "-o", "o.json", "-y", "y", "-z", "z", "-p", 2],
])
def test_negative_seed_refused_with_the_option_named(work, args):
    """numpy's generators raised 'ValueError: expected non-negative integer' (no option named; exit 2
    only through the CLI's catch-all for ValueError). The seed is now checked first."""
    before = tree(work)
    assert_refused(invoke(*args, "--seed", -1, cwd=work), "--seed (seed) must be an integer >= 0, got -1")
    assert tree(work) == before


def test_negative_seed_api_is_input_error():
    from pwas_hdl.fit.map_approximation import fit_map_samples
    from pwas_hdl.systems.battery import make_battery_dataset
    from pwas_hdl.systems.helicopter import helicopter
    from pwas_hdl.systems.lorenz import lorenz
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    for call in (lambda: lorenz(10, seed=-1), lambda: helicopter(10, seed=-1), lambda: make_battery_dataset(10, 10, seed=-1),
                 lambda: make_pv_dataset("pv-benchmark", 10, 10, seed=-1),
                 lambda: fit_map_samples(np.linspace(0, 1, 20)[:, None], np.linspace(0, 1, 20), 2, seed=-1)):
        with pytest.raises(InputError, match=r"--seed \(seed\) must be an integer >= 0, got -1"):
            call()
