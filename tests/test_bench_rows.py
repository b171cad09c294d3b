"""The benches' shared re-run merge (pwas_hdl.benchmarks.seed004_common.replace_rows): the rows of a
re-run replace those with the same key in place, the others stay, new keys go at the end."""

from __future__ import annotations

import json

from pwas_hdl.benchmarks.seed004_common import replace_rows


def _key(r: dict) -> tuple:
    return (r["config"], r["simulator"])


def test_replace_rows_keeps_order_and_appends_new_keys(tmp_path):
    old = [{"config": c, "simulator": s, "v": 0} for c in ("a", "b", "c") for s in ("icarus", "verilator")]
    path = tmp_path / "r.json"
    path.write_text(json.dumps({"rows": old, "note": "kept"}))
    new = [{"config": "b", "simulator": "verilator", "v": 1}, {"config": "d", "simulator": "icarus", "v": 2}]
    rows, doc = replace_rows(path, new, _key)
    assert doc["note"] == "kept"
    assert [_key(r) for r in rows] == [_key(r) for r in old] + [("d", "icarus")]
    assert [r["v"] for r in rows] == [0, 0, 0, 1, 0, 0, 2]


def test_replace_rows_without_a_results_file_returns_the_new_rows(tmp_path):
    new = [{"config": "a", "simulator": "icarus"}]
    assert replace_rows(tmp_path / "missing.json", new, _key) == (new, None)
