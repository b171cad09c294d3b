"""Messy plant data met by a control engineer (the messy-plant audit of 2026-12-07).

Each case failed before its fix: a run shorter than the lags (or a run whose rows are not
consecutive) was refused by ``fit`` / ``predict`` as "a trajectory has 1 samples" with no file, line or
run named; a run label that comes back after another run was silently split in two; ``simulate``
printed no warning when estimates were clamped outside the domain (``predict`` does); a ``--domain``
that leaves most training samples outside it, and a few target outliers that dominate the
training error (and so the default hardware word lengths), were taken without a word.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers.cli import CliRunner, assert_refused

from pwas_hdl.cli import app

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def tree(root):
    return sorted((str(p.relative_to(root)), p.stat().st_size if p.is_file() else -1) for p in root.rglob("*"))


def plant(t_len, seed, amp=1.0):
    """A first-order plant with a tanh input and a nonlinear measurement: rows u, y, z."""
    r = np.random.default_rng(seed)
    u = np.repeat(r.uniform(-amp, amp, t_len // 10 + 1), 10)[:t_len]
    x, rows = 0.0, []
    for t in range(t_len):
        x = 0.8 * x + 0.5 * np.tanh(u[t])
        rows.append((u[t], np.sin(x) + 0.3 * x * x + 0.01 * r.standard_normal(), x))
    return rows


def write(path, runs):
    lines = ["run,u,y,z"] + [f"{rid},{u:.6g},{y:.6g},{z:.6g}" for rid, rows in runs for u, y, z in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


FIT = ("-u", "u", "-y", "y", "-z", "z", "--mu", 2, "--my", 2, "-p", 2, "--sigma", "1e-3", "--traj-col", "run")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("messy")
    write(d / "train.csv", [(1, plant(300, 1)), (2, plant(200, 2))])
    res = invoke("fit", d / "train.csv", "-o", d / "m.json", *FIT)
    assert res.exit_code == 0, res.output
    return d


def test_fit_names_the_run_shorter_than_the_lags(files, tmp_path):
    data = write(tmp_path / "d.csv", [(1, plant(100, 1)), (2, plant(1, 2)), (3, plant(100, 3))])
    before = tree(tmp_path)
    msg = assert_refused(invoke("fit", data, "-o", tmp_path / "m.json", *FIT), "d.csv", "run '2'", "line 102",
                         "1 samples", "the lags need 2")
    assert "fewer lags" in msg
    assert tree(tmp_path) == before


def test_predict_names_the_run_shorter_than_the_lags(files, tmp_path):
    data = write(tmp_path / "d.csv", [(1, plant(100, 1)), ("exp-B", plant(1, 2))])
    assert_refused(invoke("predict", files / "m.json", data, "-o", tmp_path / "p.csv", "--traj-col", "run"),
                   "run 'exp-B'", "line 102", "the lags need 2")
    assert not (tmp_path / "p.csv").exists()


def test_fit_says_the_rows_of_a_run_are_not_consecutive(tmp_path):
    a, b = plant(100, 1), plant(100, 2)
    data = write(tmp_path / "d.csv", [r for pair in zip([(1, [x]) for x in a], [(2, [x]) for x in b]) for r in pair])
    msg = assert_refused(invoke("fit", data, "-o", tmp_path / "m.json", *FIT), "run '1'", "100 separate blocks",
                         "sort")
    assert "1 samples" in msg
    assert not (tmp_path / "m.json").exists()


def test_a_run_that_comes_back_is_warned_about(files, tmp_path):
    a = plant(300, 1)
    data = write(tmp_path / "d.csv", [(1, a[:150]), (2, plant(100, 2)), (1, a[150:])])
    for args in (("fit", data, "-o", tmp_path / "m.json", *FIT),
                 ("predict", files / "m.json", data, "-o", tmp_path / "p.csv", "--traj-col", "run")):
        res = invoke(*args)
        assert res.exit_code == 0, res.output
        warn = [ln for ln in res.output.splitlines() if ln.startswith("warning:") and "run '1'" in ln]
        assert len(warn) == 1, res.output
        assert "2 separate blocks" in warn[0] and "lines 2..151, 252..401" in warn[0], warn[0]


def test_fit_warns_when_domain_leaves_training_samples_out(files, tmp_path):
    res = invoke("fit", files / "train.csv", "-o", tmp_path / "m.json", *FIT,
                 "--domain", "-0.1:0.1,-0.1:0.1,-5:5,-5:5")
    assert res.exit_code == 0, res.output
    warn = [ln for ln in res.output.splitlines() if ln.startswith("warning:") and "--domain" in ln]
    assert len(warn) == 1, res.output
    assert "outside" in warn[0] and "clamped" in warn[0], warn[0]
    res = invoke("fit", files / "train.csv", "-o", tmp_path / "m2.json", *FIT, "--domain", "-5:5,-5:5,-5:5,-5:5")
    assert res.exit_code == 0, res.output
    assert "warning" not in res.output, res.output


def test_fit_warns_about_target_outliers(files, tmp_path):
    rows = [list(r) for r in plant(500, 1)]
    for i in (100, 250, 400):
        rows[i][2] = 250.0
    data = write(tmp_path / "d.csv", [(1, [tuple(r) for r in rows])])
    res = invoke("fit", data, "-o", tmp_path / "m.json", *FIT)
    assert res.exit_code == 0, res.output
    warn = [ln for ln in res.output.splitlines() if ln.startswith("warning:") and "outlier" in ln]
    assert len(warn) == 1, res.output
    assert "3 training samples" in warn[0] and "lines 102, 252, 402" in warn[0], warn[0]
    res = invoke("fit", files / "train.csv", "-o", tmp_path / "m2.json", *FIT)
    assert "outlier" not in res.output, res.output


@pytest.mark.rtl
def test_simulate_warns_when_estimates_are_clamped(files, tmp_path):
    res = invoke("generate", files / "m.json", "--design", "sensor", "-o", tmp_path / "hw")
    assert res.exit_code == 0, res.output
    data = write(tmp_path / "ood.csv", [(1, plant(60, 5, amp=3.0))])
    res = invoke("simulate", tmp_path / "hw", data, "--traj-col", "run")
    assert res.exit_code == 0, res.output
    warn = [ln for ln in res.output.splitlines() if ln.startswith("warning:")]
    assert len(warn) == 1 and "outside the domain" in warn[0] and "of 59" in warn[0], res.output


@pytest.mark.parametrize("labels, noted", [((0, 1, 2), True), ((0.0, 0.5, 1.0), False), (tuple(range(40)), False)])
def test_a_target_that_looks_like_a_class_label_gets_a_note(tmp_path, labels, noted):
    """A target of a few integer values (a mode, a class) was fitted as a regression without a word;
    now a note points to --classify (and stays quiet for non-integer or many-valued targets)."""
    rows = plant(600, 3)
    lab = [labels[(k // 50) % len(labels)] for k in range(len(rows))]
    (tmp_path / "d.csv").write_text("u,y,mode\n" + "".join(f"{float(u)!r},{float(y)!r},{m!r}\n" for (u, y, _), m in zip(rows, lab)))
    res = invoke("fit", tmp_path / "d.csv", "-o", tmp_path / "m.json", "-u", "u", "-y", "y", "-z", "mode", "--mu", 1,
                 "--my", 1, "-p", 2, "--sigma", "1e-3")
    assert res.exit_code == 0, res.output
    assert ("note: mode takes only 3 integer values (0, 1, 2); if it is a class label, fit with --classify" in res.output) is noted
    assert ("--classify" in res.output) is noted
    res = invoke("fit", tmp_path / "d.csv", "-o", tmp_path / "c.json", "-u", "u", "-y", "y", "-z", "mode", "--mu", 1,
                 "--my", 1, "-p", 2, "--sigma", "1e-3", "--classify")
    if noted:  # with --classify: no note
        assert res.exit_code == 0 and "takes only" not in res.output, res.output
