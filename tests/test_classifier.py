"""PWAS mode classifier: one-hot targets on one grid, argmax decision; `fit --classify`, `predict`."""

import json

import numpy as np
import pytest
from helpers.cli import CliRunner

from pwas_hdl.cli import app
from pwas_hdl.errors import InputError
from pwas_hdl.fit import classifier as clf
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.io.csv_table import read_csv, write_csv
from pwas_hdl.systems.switched_linear import switched_training_runs


def test_one_hot_decide_and_refusals():
    cls = clf.class_labels(np.array([3, 1, 2, 1]))
    assert cls == [1.0, 2.0, 3.0]
    np.testing.assert_array_equal(clf.one_hot([2, 3, 1], cls), np.eye(3)[[1, 2, 0]])
    assert clf.class_target_names("mode", cls) == ["mode=1", "mode=2", "mode=3"]
    # argmax; a tie goes to the lowest class index
    np.testing.assert_array_equal(clf.decide(np.array([[0.1, 0.7, 0.2], [0.4, 0.4, 0.2], [0, 0, 1]]), cls), [2, 1, 3])
    with pytest.raises(InputError, match="single value"):
        clf.class_labels(np.ones(5))
    with pytest.raises(InputError, match="not one of the classes"):
        clf.one_hot([4], cls)
    sc = clf.class_scores([1, 2, 3, 3], [1, 2, 3, 1], cls)
    assert sc["accuracy"] == 0.75 and sc["f1"][1] == 1.0


def _csv(path, data):
    write_csv(path, data.columns())


def test_fit_classify_and_predict_cli(tmp_path):
    _csv(tmp_path / "train.csv", switched_training_runs(4, 800, seed=0))
    _csv(tmp_path / "test.csv", switched_training_runs(1, 800, seed=7))
    run = CliRunner().invoke
    r = run(app, ["fit", str(tmp_path / "train.csv"), "-o", str(tmp_path / "m.json"), "-u", "u", "-y", "y", "-z", "mode",
                  "--classify", "--mu", "2", "--my", "2", "-p", "4", "--traj-col", "run"])
    assert r.exit_code == 0, r.output
    d = json.loads((tmp_path / "m.json").read_text())
    assert d["classifier"] == {"target": "mode", "classes": [1.0, 2.0, 3.0]}
    assert d["signals"]["targets"] == ["mode=1", "mode=2", "mode=3"]
    m = PWASVirtualSensor.load(tmp_path / "m.json")
    assert m.classifier_["classes"] == [1.0, 2.0, 3.0] and m.to_dict() == d
    r = run(app, ["predict", str(tmp_path / "m.json"), str(tmp_path / "test.csv"), "-o", str(tmp_path / "p.csv"), "--traj-col", "run"])
    assert r.exit_code == 0, r.output
    assert "accuracy of mode_hat" in r.output
    t = read_csv(tmp_path / "p.csv")
    assert t.header == ["row", "mode_hat", "mode_score_1", "mode_score_2", "mode_score_3", "out_of_domain"]
    s = t.numeric(["mode_score_1", "mode_score_2", "mode_score_3"])
    hat = t.numeric(["mode_hat"])[:, 0]
    np.testing.assert_array_equal(hat, np.argmax(s, axis=1) + 1)
    truth = read_csv(tmp_path / "test.csv").numeric(["mode"])[t.numeric(["row"])[:, 0].astype(int), 0]
    assert (hat == truth).mean() > 0.6   # well above chance (1/3) on an independent run


def test_classifier_through_the_api_equals_the_cli(tmp_path):
    """classify=True (the API; the CLI's --classify is a thin layer over it): the same file as the CLI's,
    predict_class = the argmax of the scores, a loaded classifier refits as a classifier, clone keeps it."""
    from sklearn.base import clone

    data = switched_training_runs(4, 800, seed=0)
    _csv(tmp_path / "train.csv", data)
    r = CliRunner().invoke(app, ["fit", str(tmp_path / "train.csv"), "-o", str(tmp_path / "cli.json"), "-u", "u", "-y", "y",
                                 "-z", "mode", "--classify", "--mu", "2", "--my", "2", "-p", "4", "--traj-col", "run"])
    assert r.exit_code == 0, r.output
    t = read_csv(tmp_path / "train.csv")
    from pwas_hdl.io.csv_table import select_signals

    u, y, z = (select_signals(t, [c], "run") for c in ("u", "y", "mode"))
    m = PWASVirtualSensor(mu=2, my=2, partitions=4, input_names=["u"], output_names=["y"], target_names=["mode"],
                          classify=True).fit(u, y, z)
    assert m.classifier_ == {"target": "mode", "classes": [1.0, 2.0, 3.0]}
    assert m.to_json() == (tmp_path / "cli.json").read_text()
    scores = m.predict(u, y)
    assert scores.shape[1] == 3
    np.testing.assert_array_equal(m.predict_class(u, y), np.array([1.0, 2.0, 3.0])[np.argmax(scores, axis=1)])
    loaded = PWASVirtualSensor.load(tmp_path / "cli.json")
    assert loaded.get_params()["classify"] and loaded.target_names == ["mode"]
    np.testing.assert_array_equal(clone(loaded).fit(u, y, z).weights_, m.weights_)
    with pytest.raises(InputError, match="predict_class needs a classifier"):
        PWASVirtualSensor(mu=2, my=2, partitions=4, sigma=1e-3).fit(u, y, y).predict_class(u, y)
    with pytest.raises(InputError, match="one target name"):
        PWASVirtualSensor(my=1, classify=True, target_names=["a", "b"]).fit(None, y, z)
    with pytest.raises(InputError, match="classify .* needs the lag front end"):
        PWASVirtualSensor(my=1, mz=1, classify=True).fit(None, y, z)
    with pytest.raises(InputError, match="one label column"):
        PWASVirtualSensor(my=1, classify=True).fit(None, y, [np.column_stack([zi, zi]) for zi in z])


def test_classify_bad_input_writes_nothing(tmp_path):
    d = switched_training_runs(1, 200, seed=0)
    cols = d.columns()
    cols["one"] = np.ones(200)
    write_csv(tmp_path / "d.csv", cols)
    for extra in (["-z", "one"], ["-z", "mode,x1"]):
        r = CliRunner().invoke(app, ["fit", str(tmp_path / "d.csv"), "-o", str(tmp_path / "m.json"), "-u", "u", "-y", "y",
                                     "--mu", "1", "--my", "1", "--classify", *extra])
        assert r.exit_code == 2 and "error:" in r.output, r.output
        assert not (tmp_path / "m.json").exists()
    good = PWASVirtualSensor(my=1, partitions=2).fit(None, d.y, np.eye(3)[d.mode - 1]).to_dict()
    good["classifier"] = {"target": "mode", "classes": [1, 2]}
    with pytest.raises(ValueError, match="classes"):
        PWASVirtualSensor.from_dict(good)


@pytest.mark.parametrize("labels", [[0.0, 0.5, 1.0], [0.0, 1.0, 1e20]])
def test_non_integral_class_labels_are_scored(tmp_path, labels):
    """fit --classify accepts any finite labels; scikit-learn's metrics refused a non-integral one
    (0.5, or 1e20 beyond int64) as "continuous", so predict against the label column (and simulate)
    failed with a bare ValueError after the model was fitted. class_scores now counts by equality."""
    sc = clf.class_scores([0.5, 0.0, 1.0, 0.5], [0.5, 0.0, 0.5, 1.0], [0.0, 0.5, 1.0])
    assert sc["accuracy"] == 0.5 and sc["f1"] == [1.0, 0.5, 0.0]
    t = np.arange(60, dtype=float)
    y = np.sin(t / 5)
    mode = np.array(labels)[np.digitize(y, [-0.3, 0.3])]
    write_csv(tmp_path / "d.csv", {"y": y, "mode": mode})
    run = CliRunner().invoke
    r = run(app, ["fit", str(tmp_path / "d.csv"), "-o", str(tmp_path / "m.json"), "-y", "y", "-z", "mode",
                  "--classify", "--my", "1", "-p", "3", "--sigma", "1e-6"])
    assert r.exit_code == 0, r.output
    r = run(app, ["predict", str(tmp_path / "m.json"), str(tmp_path / "d.csv"), "-o", str(tmp_path / "p.csv")])
    assert r.exit_code == 0, r.output
    assert "accuracy of mode_hat against column mode" in r.output
