"""One source of truth for the reference column of a data file: the reference of quantity ``t`` (a
target, or a classifier's class label) is column ``t_true`` if the file has it, else ``t``
(:func:`pwas_hdl.io.csv_table.reference_column_names`, :meth:`Table.reference_column
<pwas_hdl.io.csv_table.Table.reference_column>`), for every command that scores against it.
"""

from __future__ import annotations

import pytest

from pwas_hdl.errors import InputError
from pwas_hdl.io.csv_table import Table, check_trajectory_column, reference_column_names


def _table(header, n=4):
    return Table("d.csv", list(header), [[repr(float(i))] * len(header) for i in range(n)])


def test_reference_column_names_and_the_lookup_agree():
    assert reference_column_names("z") == ("z_true", "z")
    assert _table(["y", "z", "z_true"]).reference_column("z") == "z_true"
    assert _table(["y", "z"]).reference_column("z") == "z"
    assert _table(["y"]).reference_column("z") is None


@pytest.mark.parametrize("col", reference_column_names("c"))
def test_a_trajectory_column_is_never_a_reference_column(col):
    t = _table(["y", "c", "c_true"])
    with pytest.raises(InputError, match="is the reference the estimates are compared with"):
        check_trajectory_column(t, col, ["y"], ["c"])


# ------------------------------------------------------------------ a classifier's true class
import numpy as np  # noqa: E402

from helpers.cli import CliRunner, assert_refused  # noqa: E402
from helpers.folders import tree  # noqa: E402

from pwas_hdl import cli  # noqa: E402
from pwas_hdl.fit import classifier as clf  # noqa: E402
from pwas_hdl.io.csv_table import read_csv, write_csv  # noqa: E402

RUNNER = CliRunner()
N = 60


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """A 3-class classifier of c = tercile of y (0, 1, 2; lag My = 1: every row scored), its sensor
    design (generated, ~0.5 s; never simulated here) and the data."""
    from pwas_hdl.design.generate import generate
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    root = tmp_path_factory.mktemp("reference-column")
    y = np.sin(np.arange(N) / 5.0)
    c = np.digitize(y, [-0.3, 0.3]).astype(float)
    m = PWASVirtualSensor(my=1, partitions=3, sigma=1e-6, output_names=["y"], target_names=["c"], classify=True).fit(None, y[:, None], c)
    assert m.classifier_ == {"target": "c", "classes": [0.0, 1.0, 2.0]} and m.memory == 1
    m.save(root / "model.json")
    generate(m, root / "hw", design="sensor")
    return {"root": root, "model": m, "y": y, "c": c}


def test_check_true_labels_names_the_values_rows_and_classes():
    clf.check_true_labels([0, 1, 2, 1], [0, 1, 2], "c", "d.csv: column 'c'")  # every label a class: nothing
    with pytest.raises(InputError) as e:
        clf.check_true_labels([0, 7, 1, 7], [0.0, 1.0, 2.0], "c", "d.csv: column 'c'")
    assert str(e.value).startswith("d.csv: column 'c': label 7 is not one of the classes ['0', '1', '2'] of classifier 'c' "
                                   "(2 of 4 rows); give the true class labels")
    with pytest.raises(InputError) as e:  # a continuous column under the label's name: the first values, the rest counted
        clf.check_true_labels([0.5, 1, 0.25, 3, 9, 0.5], [0.0, 1.0], "c", "d.csv: column 'c_true'")
    assert str(e.value).startswith("d.csv: column 'c_true': labels 0.5, 0.25, 3 and 1 more are not among the classes "
                                   "['0', '1'] of classifier 'c' (5 of 6 rows)")


def _data(case, path, **cols):
    write_csv(path, {"y": case["y"], **cols})
    return path


def _bad(case, k=17, value=7.0):
    c = case["c"].copy()
    c[k] = value
    return c


@pytest.mark.parametrize("cols, words", [
    (lambda case: {"c": _bad(case)}, ("d.csv: column 'c': label 7 is not one of the classes ['0', '1', '2'] of classifier 'c'",
                                      "(1 of 60 rows)")),
    # LABEL_true is the reference when both are there (a good LABEL does not hide it)
    (lambda case: {"c": case["c"], "c_true": _bad(case, value=0.5)}, ("d.csv: column 'c_true': label 0.5 is not one of the classes",)),
])
def test_predict_refuses_a_label_that_is_no_class(case, tmp_path, monkeypatch, cols, words):
    """It was scored as a wrong decision (the accuracy printed, the CSV written): now refused as explore
    refuses it -- one error line naming the file, the column, the value and the classes, exit 2,
    nothing written."""
    monkeypatch.chdir(tmp_path)
    _data(case, tmp_path / "d.csv", **cols(case))
    before = tree(tmp_path)
    res = RUNNER.invoke(cli.app, ["predict", str(case["root"] / "model.json"), "d.csv", "-o", "p.csv"])
    assert_refused(res, *words)
    assert tree(tmp_path) == before


def test_predict_explore_and_simulate_refuse_the_same_way(case, tmp_path, monkeypatch):
    """The one check (pwas_hdl.fit.classifier.check_true_labels) behind the three commands: the same
    message for the same file, and simulate refuses before any simulator runs."""
    from pwas_hdl.verify import simulation

    def no_simulator(*a, **k):
        raise AssertionError("the simulator ran")

    monkeypatch.setattr(simulation, "run_rtl", no_simulator)
    monkeypatch.chdir(tmp_path)
    _data(case, tmp_path / "d.csv", c=case["c"], c_true=_bad(case))
    before = tree(tmp_path)
    lines = []
    for args in (["predict", str(case["root"] / "model.json"), "d.csv", "-o", "p.csv"],
                 ["explore", str(case["root"] / "model.json"), "d.csv", "-o", "ex", "--input-bits", "10"],
                 ["simulate", str(case["root"] / "hw"), "d.csv", "-o", "s.csv"]):
        lines.append(assert_refused(RUNNER.invoke(cli.app, args), "d.csv: column 'c_true': label 7 is not one of the classes "
                                    "['0', '1', '2'] of classifier 'c' (1 of 60 rows)"))
        assert tree(tmp_path) == before, args
    assert len(set(lines)) == 1, lines
    assert not (case["root"] / "hw" / "sim").exists()


def _perfect_rtl(monkeypatch):
    """run_rtl replaced by an RTL that outputs exactly the bit-true expectation (no simulator): what
    simulate makes of the outputs is then testable in a fraction of a second."""
    from pwas_hdl.verify import simulation

    def run_rtl(design, runs, simulator, **kw):
        raw = {"passed": True, "runs": [{"cycles": 0, "wall_s": 0.0, "segments": [
            {"got": s.rows().tolist(), "latencies": [design.latency] * len(s.expected), "accepted_at": []} for s in r.segments]}
            for r in runs]}
        return simulation._summarise(design, list(runs), raw, simulator, {}, 0.0)

    monkeypatch.setattr(simulation, "run_rtl", run_rtl)
    monkeypatch.setattr(simulation.sim_module("pwas_runner"), "tool_versions", lambda simulator: "none (test stand-in)")


def test_simulate_scores_the_class_against_label_true(case, tmp_path, monkeypatch):
    """simulate found the true class only in column LABEL (here a constant class 0): it now reads
    LABEL_true when the file has it, as predict and explore do."""
    from pwas_hdl.verify.simulation import simulate_data

    _perfect_rtl(monkeypatch)
    data = _data(case, tmp_path / "d.csv", c=np.zeros(N), c_true=case["c"])
    s = simulate_data(case["root"] / "hw", data, tmp_path / "s.csv")["summary"]
    c = s["classifier"]
    assert c["class_mismatches"] == 0 and c["reference_column"] == "c_true"
    hat = read_csv(tmp_path / "s.csv").numeric(["c_hat_bittrue"])[:, 0]
    assert c["scores_bittrue"]["accuracy"] == pytest.approx(np.mean(hat == case["c"]))
    # the file's own label column, when there is no c_true
    data = _data(case, tmp_path / "e.csv", c=case["c"])
    c2 = simulate_data(case["root"] / "hw", data, tmp_path / "s2.csv")["summary"]["classifier"]
    assert c2["reference_column"] == "c" and c2["scores_bittrue"] == c["scores_bittrue"]


def test_simulate_arrays_takes_a_classifiers_true_labels(case, tmp_path, monkeypatch):
    """z_true of a classifier design is its label column (it was refused: 'the model's signals are
    c=0_true, c=1_true, c=2_true', the one-hot scores); a label no class is refused as by simulate."""
    from pwas_hdl.verify.simulation import simulate_arrays

    _perfect_rtl(monkeypatch)
    c = simulate_arrays(case["root"] / "hw", tmp_path / "s.csv", y=case["y"], z_true=case["c"])["summary"]["classifier"]
    assert c["reference_column"] == "c_true" and c["scores_bittrue"]["accuracy"] > 0.5
    with pytest.raises(InputError, match=r"column 'c_true': label 7 is not one of the classes \['0', '1', '2'\]"):
        simulate_arrays(case["root"] / "hw", tmp_path / "t.csv", y=case["y"], z_true=_bad(case))
    assert not (tmp_path / "t.csv").exists()


def test_simulate_takes_no_reference_for_a_classifiers_scores(case, tmp_path, monkeypatch):
    """A file carrying predict's score columns (<c>_score_<k>) got an RMSEE of the RTL's scores
    against them, and a value there beyond MAX_VALUE was not refused as every reference is (classifier
    designs skip that check): a score has no reference, the class decision is scored against the
    label column. Now no score column is read, whatever it holds."""
    from pwas_hdl.limits import MAX_VALUE
    from pwas_hdl.verify.simulation import simulate_data

    _perfect_rtl(monkeypatch)
    scores = {clf.score_column("c", k): (case["c"] == k).astype(float) for k in case["model"].classifier_["classes"]}
    scores[clf.score_column("c", 2.0)][5] = 10 * MAX_VALUE
    scores[clf.score_column("c", 1.0) + "_true"] = np.zeros(N)
    data = _data(case, tmp_path / "d.csv", c=case["c"], **scores)
    s = simulate_data(case["root"] / "hw", data, tmp_path / "s.csv")["summary"]
    assert set(s["targets"]) == {clf.score_column("c", k) for k in (0.0, 1.0, 2.0)}
    assert all("reference_column" not in t and "rmsee_hw" not in t for t in s["targets"].values()), s["targets"]
    assert s["classifier"]["reference_column"] == "c" and s["classifier"]["class_mismatches"] == 0


@pytest.mark.parametrize("col", reference_column_names("mode"))
def test_simulate_of_an_estimator_reads_mode_true_and_refuses_a_value_that_is_no_mode(col, tmp_path_factory, monkeypatch):
    """Seed 003's estimator scores its detected modes (1..3) against the true mode: found as every
    reference column (mode_true, else mode; it read mode only) and a value that is no mode (a
    0-based column, say) refused before the simulator runs, as a classifier's label is (it scored
    every such row as wrong)."""
    from pwas_hdl.design.generate import generate
    from pwas_hdl.fit.estimator_file import estimator_text
    from pwas_hdl.systems.switched_observer import estimator_config
    from pwas_hdl.verify import estimator_simulation
    from pwas_hdl.verify.simulation import simulate_data

    def no_simulator(*a, **k):
        raise AssertionError("the simulator ran")

    monkeypatch.setattr(estimator_simulation, "replay_segments", no_simulator)
    root = tmp_path_factory.mktemp("estimator")
    (root / "est.json").write_text(estimator_text(estimator_config()), encoding="utf-8")
    generate(root / "est.json", root / "hw")
    n = 20
    cols = {"u": [i % 3 - 1 for i in range(n)], "y": [(i % 5) / 4 for i in range(n)], "mode": [1 + i % 3 for i in range(n)]}
    cols[col] = [i % 3 for i in range(n)]  # 0-based: 0 is no mode
    write_csv(root / "d.csv", cols)
    with pytest.raises(InputError, match=rf"d.csv: column '{col}': label 0 is not one of the classes \['1', '2', '3'\] of the "
                                         r"estimator's mode detector \(3 modes\) \(7 of 20 rows\)"):
        simulate_data(root / "hw", root / "d.csv", root / "s.csv")
    assert not (root / "s.csv").exists()
