"""pwas_hdl.benchmarks.lorenz_tables: the paper's rows, the experiment protocol and the Markdown output."""

import json

import pytest

from pwas_hdl import bench_results as br
from pwas_hdl.benchmarks.lorenz_tables import PAPER_ROWS, find_row, markdown_table, run_lorenz_tables


def test_paper_rows_are_the_eight_distinct_configurations():
    keys = [(r.my, r.p, r.gamma) for r in PAPER_ROWS]
    assert keys == [(4, 7, 1.2), (3, 7, 1.2), (5, 7, 1.2), (4, 3, 1.2), (4, 1, 1.2), (4, 7, 1.1), (4, 7, 1.5), (4, 7, 2.0)]
    assert all(r.n_vertices == (r.p + 1) ** r.my for r in PAPER_ROWS)
    assert [r.n_vertices for r in PAPER_ROWS] == [4096, 512, 32768, 256, 16, 4096, 4096, 4096]
    base = find_row(4, 7, 1.2)
    assert base.tables == ("II", "III", "IV", "V") and base.rmsee == 22.45 and base.sigma == 5.57e-4
    assert len({r.id for r in PAPER_ROWS}) == len(PAPER_ROWS)
    with pytest.raises(KeyError, match="known rows"):
        find_row(6, 7, 1.2)


def test_quick_run_is_deterministic_plain_json_and_scored_on_n_test_estimates():
    kw = dict(seeds=[0], rows=["My4-p7-g1.2"], n_train=1500, n_test=400, sigma_grid=[1e-4, 1e-2, 1.0])
    res = run_lorenz_tables(**kw)
    json.dumps(res, allow_nan=False)
    br.validate_results(res)  # the shared bench results format (bench-results-v1), written directly
    assert res["format"] == br.RESULTS_FORMAT and res["bench"] == "lorenz" and "timestamp" not in json.dumps(res)
    (row,) = res["rows"]
    assert (row["system"], row["target"], row["estimator"], row["stage"], row["metric"]) == ("lorenz", "z", "pwas", "float", "rmse")
    assert row["config"]["N"] == 4096 and row["std"] is None and row["runs"] == 1 and row["paper"] == 22.45
    rec = row["config"]["per_seed"][0]
    assert rec["sigma"] in (1e-4, 1e-2, 1.0)
    assert 0 < rec["rmsee"] < 100 and rec["test_out_of_domain"] >= 0 and row["value"] == rec["rmsee"]
    assert res["config"]["setup"]["trajectory_samples"] == 1500 + 400 + 4
    again = run_lorenz_tables(**kw)["rows"][0]["config"]["per_seed"][0]
    assert (again["rmsee"], again["sigma"]) == (rec["rmsee"], rec["sigma"])
    md = markdown_table(res)
    assert "| II, III, IV, V | 4 | 7 | 1.2 | 4096 |" in md and "22.45" in md


def test_rows_share_training_and_test_samples():
    res = run_lorenz_tables(seeds=[0, 1], rows=[(3, 7, 1.2), (4, 1, 1.2)], n_train=800, n_test=200, sigma_grid=[1e-3])
    assert [r["config"]["id"] for r in res["rows"]] == ["My3-p7-g1.2", "My4-p1-g1.2"]
    assert all(r["std"] is not None and r["runs"] == 2 and len(r["config"]["per_seed"]) == 2 for r in res["rows"])
    assert res["config"]["setup"]["test_estimates"] == "[804, 1004)"


@pytest.mark.parametrize(
    "kw, exc",
    [
        (dict(seeds=[]), ValueError),
        (dict(seeds=[0, 0]), ValueError),
        (dict(seeds=[0], folds=1), ValueError),
        (dict(seeds=[0], n_test=0), ValueError),
        (dict(seeds=[0], sigma_grid=[0.0]), ValueError),
        (dict(seeds=[0], rows=["nope"]), KeyError),
        (dict(seeds=[0], rows=[3.5]), TypeError),
    ],
)
def test_bad_arguments(kw, exc):
    with pytest.raises(exc):
        run_lorenz_tables(**kw)
