"""Bad input met by a new user of the installed wheel (the wheel-journey audit of 2026-12-07).

Each case failed before its fix: a ``--traj-col`` that names a column the model reads (a signal or
the reference of the score) was taken as a run index, a folder given as a JSON file said only
"Is a directory", ``--z0 abc`` pointed to ``logspace:A:B:K`` (which it took), and ``-o .`` was
called an empty path. CLI cases: exit 2, one ``error:`` line, nothing written.
"""

from __future__ import annotations

import pytest
from helpers.cli import CliRunner, assert_refused

from pwas_hdl.cli import app

runner = CliRunner()


def invoke(*args, cwd=None):
    if cwd is None:
        return runner.invoke(app, [str(a) for a in args])
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(cwd)
        return runner.invoke(app, [str(a) for a in args])


def tree(root):
    return sorted((str(p.relative_to(root)), p.stat().st_size if p.is_file() else -1) for p in root.rglob("*"))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Switched-linear runs (columns u (PRBS 0 / 2: integer-valued, so it passes for a run index), y,
    x1, x1_true, mode, run), a lag model of x1 and its sensor design, a classifier of the mode label,
    seed 003's estimator and its design."""
    d = tmp_path_factory.mktemp("journey")
    res = invoke("make-data", "switched-linear", "-o", d / "d.csv", "--runs", 3, "--samples", 120,
                 "--estimator-out", d / "est.json")
    assert res.exit_code == 0, res.output
    res = invoke("fit", d / "d.csv", "-o", d / "m.json", "-u", "u", "-y", "y", "-z", "x1", "--mu", 1, "--my", 2,
                 "-p", 2, "--sigma", "1e-3", "--traj-col", "run")
    assert res.exit_code == 0, res.output
    res = invoke("fit", d / "d.csv", "-o", d / "c.json", "-u", "u", "-y", "y", "-z", "mode", "--classify",
                 "--mu", 1, "--my", 2, "-p", 2, "--sigma", "1e-3", "--traj-col", "run")
    assert res.exit_code == 0, res.output
    res = invoke("generate", d / "m.json", "--design", "sensor", "-o", d / "hw")
    assert res.exit_code == 0, res.output
    res = invoke("generate", d / "est.json", "-o", d / "est")
    assert res.exit_code == 0, res.output
    return d


# --- --traj-col names a column the model reads -------------------------------------------------------------

@pytest.mark.parametrize("col, frag", [
    ("u", "a signal the model reads"),          # u is PRBS {0, 2}: it passed as a run index
    ("y", "a signal the model reads"),
    ("x1_true", "the reference"),
    ("x1", "the reference"),
])
def test_predict_refuses_a_traj_col_the_model_reads(files, tmp_path, col, frag):
    before = tree(tmp_path)
    res = invoke("predict", files / "m.json", files / "d.csv", "-o", tmp_path / "p.csv", "--traj-col", col)
    assert_refused(res, f"--traj-col {col!r}", frag, "give each column one role")
    assert tree(tmp_path) == before


def test_predict_of_a_classifier_refuses_its_label_as_traj_col(files, tmp_path):
    res = invoke("predict", files / "c.json", files / "d.csv", "-o", tmp_path / "p.csv", "--traj-col", "mode")
    assert_refused(res, "--traj-col 'mode'", "the reference")
    assert not (tmp_path / "p.csv").exists()


def test_explore_refuses_a_traj_col_the_model_reads(files, tmp_path):
    res = invoke("explore", files / "m.json", files / "d.csv", "-o", tmp_path / "ex", "--traj-col", "u",
                 "--input-bits", 10)
    assert_refused(res, "--traj-col 'u'", "a signal the model reads")
    assert not (tmp_path / "ex").exists()


@pytest.mark.parametrize("design, col, frag", [
    ("hw", "u", "a signal the model reads"),
    ("hw", "x1_true", "the reference"),
    ("est", "y", "a signal the model reads"),
    ("est", "mode", "the reference"),
])
def test_simulate_refuses_a_traj_col_the_design_reads(files, tmp_path, design, col, frag):
    # refused while reading DATA, before any simulator is started (no rtl marker needed)
    res = invoke("simulate", files / design, files / "d.csv", "-o", tmp_path / "s.csv", "--traj-col", col)
    assert_refused(res, f"--traj-col {col!r}", frag)
    assert list(tmp_path.iterdir()) == []


def test_the_run_column_still_works(files, tmp_path):
    res = invoke("predict", files / "c.json", files / "d.csv", "-o", tmp_path / "p.csv", "--traj-col", "run")
    assert res.exit_code == 0, res.output


# --- a folder where a JSON file is expected --------------------------------------------------------------

@pytest.mark.parametrize("cmd", [
    ("info", "{hw}"),
    ("predict", "{hw}", "{d}/d.csv", "-o", "{out}/p.csv"),
    ("generate", "{hw}", "-o", "{out}/g"),
    ("explore", "{hw}", "{d}/d.csv", "-o", "{out}/ex"),
])
def test_a_design_folder_given_as_the_model_names_its_model_file(files, tmp_path, cmd):
    args = [a.format(hw=files / "hw", d=files, out=tmp_path) for a in cmd]
    line = assert_refused(invoke(*args), "is a folder, not a", "model.json")
    assert "Is a directory" not in line
    assert list(tmp_path.iterdir()) == []


def test_a_plain_folder_given_as_the_model_says_give_the_file(files, tmp_path):
    line = assert_refused(invoke("info", tmp_path), "is a folder, not a", "give the")
    assert "model.json" not in line


def test_a_folder_given_as_the_breakpoints_file(files, tmp_path):
    (tmp_path / "bp").mkdir()
    res = invoke("fit", files / "d.csv", "-o", tmp_path / "m.json", "-u", "u", "-y", "y", "-z", "x1", "--mu", 1,
                 "--my", 2, "-p", 2, "--sigma", "1e-3", "--traj-col", "run", "--breakpoints", tmp_path / "bp")
    assert_refused(res, "is a folder")
    assert not (tmp_path / "m.json").exists()


# --- --z0 ----------------------------------------------------------------------------------------------------

def test_fit_z0_hint_lists_what_it_takes(files, tmp_path):
    for z0 in ("abc", "logspace:0:1:1"):
        line = assert_refused(invoke("fit", files / "d.csv", "-o", tmp_path / "m.json", "-u", "u", "-y", "y", "-z",
                                     "x1", "--mu", 1, "--my", 2, "-p", 2, "--sigma", "1e-3", "--traj-col", "run",
                                     "--mz", 1, "--z0", z0), "--z0", "mean", "measured")
        assert "logspace:A" not in line
    assert list(tmp_path.iterdir()) == []


def test_fit_map_z0_hint_lists_what_it_takes(tmp_path):
    (tmp_path / "s.csv").write_text("y,z,zn\n0,0,0\n1,0,0.5\n0,1,0.9\n1,1,1.2\n0.5,0.5,0.6\n")
    for z0 in ("abc", "logspace:0:1:1"):
        line = assert_refused(invoke("fit-map", tmp_path / "s.csv", "-o", tmp_path / "m.json", "-y", "y",
                                     "--state", "z", "-z", "zn", "-p", 1, "--z0", z0), "--z0", "one number per --state column")
        assert "logspace:A" not in line
    assert not (tmp_path / "m.json").exists()


# --- -o . -----------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("out", [".", ".."])
def test_dot_as_a_file_output_is_called_a_folder(tmp_path, out):
    work = tmp_path / "w"
    work.mkdir()
    before = tree(tmp_path)
    line = assert_refused(invoke("make-data", "lorenz", "-o", out, "--samples", 50, cwd=work), "is a folder",
                          "give a file name")
    assert "empty" not in line
    assert tree(tmp_path) == before


# --- generate --state-bits below the bound: said, not only in the manifest -------------------------------------

def test_generate_warns_when_the_bank_states_may_saturate(tmp_path):
    res = invoke("make-data", "pv-benchmark", "-o", tmp_path / "d.csv", "--samples", 1500)
    assert res.exit_code == 0, res.output
    res = invoke("fit", tmp_path / "d.csv", "-o", tmp_path / "b.json", "-u", "u1,u2", "-y", "y", "-z", "rho",
                 "--front-end", "observer-bank", "--models", 2, "--mu", 0, "--my", 0, "-p", 2, "--sigma", "1e-3")
    assert res.exit_code == 0, res.output
    res = invoke("generate", tmp_path / "b.json", "--design", "sensor", "-o", tmp_path / "ok")
    assert res.exit_code == 0, res.output
    assert "may saturate" not in res.output
    res = invoke("generate", tmp_path / "b.json", "--design", "sensor", "--state-bits", 4, "-o", tmp_path / "hw")
    assert res.exit_code == 0, res.output
    warn = [ln for ln in res.output.splitlines() if ln.startswith("warning:")]
    assert len(warn) == 1 and "s4." in warn[0] and "may saturate" in warn[0] and "--state-bits" in warn[0], res.output


def test_generate_warns_when_the_estimator_states_may_saturate(files, tmp_path):
    res = invoke("generate", files / "est.json", "--state-bits", 8, "-o", tmp_path / "est")
    assert res.exit_code == 0, res.output
    warn = [ln for ln in res.output.splitlines() if ln.startswith("warning:")]
    assert len(warn) == 1 and "s8." in warn[0] and "may saturate" in warn[0], res.output


# --- a JSON file given as DATA ------------------------------------------------------------------------------

def test_a_model_file_given_as_data_is_named_as_such(files, tmp_path):
    line = assert_refused(invoke("predict", files / "m.json", files / "m.json", "-o", tmp_path / "p.csv"),
                          "is a pwas-hdl-model file (JSON), not CSV data", "give the CSV file")
    assert "cells" not in line
    line = assert_refused(invoke("simulate", files / "hw", files / "hw" / "manifest.json", "-o", tmp_path / "s.csv"),
                          "is a pwas-hdl-manifest file (JSON), not CSV data")
    (tmp_path / "x.json").write_text('[{"a": 1}]')
    assert_refused(invoke("fit", tmp_path / "x.json", "-o", tmp_path / "m.json", "-y", "y", "-z", "z", "--my", 1,
                          "-p", 1, "--sigma", 1), "is a JSON file, not CSV data")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.json"]


# --- report --sim ---------------------------------------------------------------------------------------------

def _summary(files, tmp_path, top):
    """A simulate summary as `simulate` writes it, for the top level ``top`` (another design's hash)."""
    import json

    doc = {"design": top, "design_hash": "0" * 64, "simulator": "icarus", "samples": 10, "mismatches": 0,
           "latency_cycles": {"manifest": 7, "measured_min": 7, "measured_max": 7}, "ii": {"manifest": 1, "measured": 1.0},
           "targets": {}}
    p = tmp_path / "other.json"
    p.write_text(json.dumps(doc))
    return p


def test_report_refuses_a_given_summary_of_another_design(files, tmp_path):
    import json

    top = json.loads((files / "hw" / "manifest.json").read_text())["top"]
    other = _summary(files, tmp_path, top + "_other")
    res = invoke("report", files / "hw", "--sim", other, "-o", tmp_path / "r.md")
    assert_refused(res, "is a result for the top", "not this folder's", "leave it out of --sim")
    assert not (tmp_path / "r.md").exists()
    # the same top with another hash: an earlier version of this design, shown and marked stale
    same = _summary(files, tmp_path, top)
    res = invoke("report", files / "hw", "--sim", same, "-o", tmp_path / "r.md")
    assert res.exit_code == 0, res.output
    assert "stale" in (tmp_path / "r.md").read_text()


def test_report_says_how_many_estimates_were_clamped(files, tmp_path):
    """The report showed the RMSEE of an out-of-domain test set without a word on the clamped estimates
    (simulate's summary has their count, out_of_range); now a line under the table says so, and a
    negative count is refused as a corrupt summary."""
    import json

    man = json.loads((files / "hw" / "manifest.json").read_text())
    p = _summary(files, tmp_path, man["top"])
    doc = json.loads(p.read_text())
    for n, shown in ((187, True), (0, False)):
        p.write_text(json.dumps({**doc, "design_hash": man["design_hash"], "samples": 299, "out_of_range": n}))
        res = invoke("report", files / "hw", "--sim", p, "--json", tmp_path / "r.json", "-o", tmp_path / "r.md")
        assert res.exit_code == 0, res.output
        assert json.loads((tmp_path / "r.json").read_text())["simulation"][0]["out_of_range"] == n
        assert ("icarus (other.json): 187 of 299 estimates had a regressor outside the domain (clamped"
                in (tmp_path / "r.md").read_text()) is shown
    p.write_text(json.dumps({**doc, "out_of_range": -1}))
    assert_refused(invoke("report", files / "hw", "--sim", p, "-o", tmp_path / "r2.md"), "out_of_range")
    assert not (tmp_path / "r2.md").exists()


def test_report_sim_folder_says_give_the_summary(files, tmp_path):
    (tmp_path / "sim").mkdir()
    line = assert_refused(invoke("report", files / "hw", "--sim", tmp_path / "sim"), "is a folder", "JSON summary")
    assert "Is a directory" not in line


def test_generate_weight_frac_too_fine_names_the_option(files, tmp_path):
    assert_refused(invoke("generate", files / "m.json", "-o", tmp_path / "g", "--weight-frac", 999),
                   "--weight-frac (weight_frac) = 999", "too large for 64-bit codes", "fewer")
    assert list(tmp_path.iterdir()) == []


# --- a good file of another kind: say what to give, not "re-run fit" ---------------------------------------------

def test_an_estimator_file_given_to_info_says_what_to_give(files):
    line = assert_refused(invoke("info", files / "est.json"), "is a pwas-hdl-estimator file",
                          "not a pwas-hdl-model file (a fitted model of `pwas-hdl fit`", "give a pwas-hdl-model file")
    assert "re-run" not in line


# --- a CSV file with another separator ---------------------------------------------------------------------

@pytest.mark.parametrize("sep, called", [(";", "';'"), ("\t", "tabs")])
def test_a_csv_with_another_separator_is_named_as_such(tmp_path, sep, called):
    rows = ["y,z", *(f"{i * 0.5},{i * 0.25}" for i in range(40))]
    (tmp_path / "d.csv").write_text("\n".join(r.replace(",", sep) for r in rows) + "\n")
    line = assert_refused(invoke("fit", tmp_path / "d.csv", "-o", tmp_path / "m.json", "-y", "y", "-z", "z", "--my", 1,
                                 "-p", 1, "--sigma", 1), f"separated by {called}, not commas", "save the file with ','")
    assert "control" not in line
    assert not (tmp_path / "m.json").exists()


# --- help text --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("cmd, shown", [("fit", "-u, --inputs <column>"), ("fit-map", "--state <column>"),
                                        ("report", "--sim <path>")])
def test_help_shows_repeatable_options_by_what_they_take(cmd, shown):
    res = invoke(cmd, "--help")
    assert res.exit_code == 0
    assert "list[str]" not in res.output
    assert shown in res.output, res.output


def test_generate_does_not_tell_to_leave_out_a_state_bits_never_given(files, tmp_path):
    """An estimator whose |F_i| have no common contraction may saturate at its default width (no
    invariant box: the width holds each mode's own bound). The warning told the user to 'leave
    --state-bits out', which they had done; it now says why the default width may saturate."""
    import json

    import numpy as np

    doc = json.loads((files / "est.json").read_text())
    f = [np.array([[0.5, 1.5], [0.0, 0.5]]), np.array([[0.5, 0.0], [1.5, 0.5]])]
    c = [np.array([1.0, 0.0]), np.array([0.0, 1.0])]
    k = np.array([0.5, 0.5])
    doc["modes"] = [{"A": (fi + np.outer(k, ci)).tolist(), "B": b, "C": ci.tolist(), "K": k.tolist()}
                    for fi, ci, b in zip(f, c, ([1.0, 0.0], [0.0, 1.0]))]
    (tmp_path / "e.json").write_text(json.dumps(doc))
    res = invoke("generate", tmp_path / "e.json", "-o", tmp_path / "hw")
    assert res.exit_code == 0, res.output
    warn = [ln for ln in res.output.splitlines() if ln.startswith("warning:")]
    assert len(warn) == 1 and "may saturate" in warn[0], res.output
    assert "--state-bits out" not in warn[0] and "every mode sequence" in warn[0], warn[0]


def test_a_one_column_csv_with_a_quoted_semicolon_in_its_name_is_read(tmp_path):
    """A comma CSV of one column whose quoted name holds ';' (a static one-input model's DATA) is valid:
    the ';' check looked at the parsed name, not at the line, and refused it."""
    from pwas_hdl.io.csv_table import read_csv

    (tmp_path / "d.csv").write_text('"flow;l/min"\n1.5\n2.5\n')
    t = read_csv(tmp_path / "d.csv")
    assert t.header == ["flow;l/min"] and len(t.rows) == 2
    (tmp_path / "e.csv").write_text("flow;level\n1.5;2\n")  # unquoted: still named as ';'-separated
    with pytest.raises(Exception, match="separated by ';', not commas"):
        read_csv(tmp_path / "e.csv")


def test_a_quoted_semicolon_header_is_named_as_such(tmp_path):
    """A ';' export with quoted names ("u";"y") failed as "malformed CSV (',' expected after '\"')"."""
    (tmp_path / "q.csv").write_text('"u";"y"\n1;2\n3;4\n')
    assert_refused(invoke("fit", tmp_path / "q.csv", "-o", tmp_path / "m.json", "-y", "y", "-z", "u", "--my", 1,
                          "-p", 1, "--sigma", 1), "the header (line 1) is separated by ';', not commas",
                   "save the file with ','")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["q.csv"]
