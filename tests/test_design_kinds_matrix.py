"""The README's table "What `generate` builds for each model" is what the code does.

Every row's model is fitted (small, seeded), every cell checked: "yes" must build with
:func:`~pwas_hdl.design.generate.build_design` (or, for the `explore` column, sweep its default point
with :func:`~pwas_hdl.flow.explore.explore`: a classifier on its error rate, a sensor on its RMSEE),
"refused" must raise :class:`~pwas_hdl.errors.InputError`.
The bit-exactness of each kind is the business of its own tests; this one keeps the table honest.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from pwas_hdl.errors import InputError

README = Path(__file__).resolve().parents[1] / "README.md"
TITLE = "**What `generate` builds for each model**"

#: column header -> build_design options (None: the explore column)
COLUMNS = {
    "core, parallel": {"design": "core"},
    "core, serial": {"design": "core", "architecture": "serial"},
    "sensor, parallel": {"design": "sensor"},
    "sensor, serial": {"design": "sensor", "architecture": "serial"},
    "sensor, `--memory-init readmemh`": {"design": "sensor", "memory_init": "readmemh"},
    "`explore`": None,
}


def _table() -> tuple[list[str], dict[str, list[str]]]:
    lines = README.read_text(encoding="utf-8").splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith(TITLE))
    rows = []
    for ln in lines[start + 1:]:
        if ln.startswith("|"):
            rows.append([c.strip() for c in ln.strip().strip("|").split("|")])
        elif rows:
            break
    header, body = rows[0], rows[2:]
    return header[1:], {r[0]: r[1:] for r in body}


@pytest.fixture(scope="module")
def data():
    from pwas_hdl.systems.lorenz import lorenz
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    d = lorenz(700, seed=5)
    tr, _, _ = make_pv_dataset("pv-benchmark", 1500, 300, seed=0)
    return d.y[:, 0], d.z[:, 0], tr


def _fit(label: str, data):
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

    y, z, tr = data
    lab = (z > np.median(z)).astype(int)
    pow2 = {"breakpoints": "quantile-pow2"}
    lag = dict(sigma=1e-3, output_names=["y"])
    kinds = {
        "plain": (dict(my=2, partitions=3), z),
        "classifier (`--classify`)": (dict(my=2, partitions=3, classify=True), lab),
        "additive (`--additive`)": (dict(my=3, partitions=3, additive="pairs"), z),
        "additive classifier": (dict(my=3, partitions=3, additive="pairs", classify=True), lab),
        "non-uniform (`--breakpoints quantile-pow2`)": (dict(my=2, partitions=4, **pow2), z),
        "non-uniform classifier": (dict(my=2, partitions=4, classify=True, **pow2), lab),
        "recurrent (`--mz`)": (dict(my=1, mz=1, partitions=3), z),
        "non-uniform recurrent": (dict(my=1, mz=1, partitions=4, **pow2), z),
    }
    if label in kinds:
        kw, target = kinds[label]
        names = ["c"] if kw.get("classify") else ["z"]
        return PWASVirtualSensor(target_names=names, **lag, **kw).fit(None, y, target), (None, y, target)
    banks = {
        "observer bank (`--front-end observer-bank`)": dict(my=0, partitions=3),
        "observer bank with u/y taps (`--mu/--my`)": dict(my=1, partitions=2),
        "non-uniform observer bank": dict(my=0, partitions=4, **pow2),
        "non-uniform observer bank with u/y taps": dict(my=1, partitions=2, **pow2),
    }
    fe = ObserverBankFrontEnd(n_models=2, observer="deadbeat", features="11b", order=2)
    s = PWASVirtualSensor(mu=0, gamma=1.0, front_end=fe, sigma=1e-3, **banks[label]).fit(tr.u, tr.y, tr.z)
    return s, (tr.u, tr.y, tr.z)


HEADER, ROWS = _table()


def test_the_table_has_the_checked_columns():
    assert HEADER == list(COLUMNS)
    assert all(set(cells) <= {"yes", "refused"} and len(cells) == len(COLUMNS) for cells in ROWS.values()), ROWS


@pytest.mark.parametrize("label", list(ROWS))
def test_every_cell_of_the_row(label, data):
    from pwas_hdl.design.generate import build_design, fixed_point_model
    from pwas_hdl.fixedpoint.observer_bank import observer_bank_model
    from pwas_hdl.flow.explore import explore

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sensor, xy = _fit(label, data)
        got = []
        for col, opts in COLUMNS.items():
            try:
                if opts is None:
                    # an observer-bank sensor's core formats are its bank model's (fixed_point_model refuses it)
                    d = (observer_bank_model(sensor).core if getattr(sensor, "front_end_", None) is not None
                         else fixed_point_model(sensor))
                    res = explore(sensor, xy, input_bits=[12], weight_frac=[d.weight_format.frac],
                                  output_frac=[d.output_format.frac])
                    # a classifier is swept on its decisions (error rate), a sensor on its RMSEE
                    acc = "error_rate" if getattr(sensor, "classifier_", None) is not None else "rmsee_ratio"
                    assert res["resource_model"]["objectives"] == ["cost", acc]
                    assert all(acc in p for p in res["points"])
                else:
                    build_design(sensor, **opts)
                got.append("yes")
            except InputError as exc:
                got.append("refused")
                assert re.search(r"\S", str(exc))  # a message, not an empty refusal
    assert got == ROWS[label], dict(zip(COLUMNS, got))
