"""Non-uniform partitions (issue 15 item 3): geometry, fit --breakpoints, model file, the power-of-two warp.

* :class:`~pwas_hdl.fit.geometry.Grid` with breakpoints: the warp to grid units, vertices at the
  cut points, PWAS values continuous and exact at the vertices; without breakpoints the uniform
  path is untouched (same object state, same results).
* ``fit --breakpoints quantile | quantile-pow2 | FILE``: same N as the uniform grid, the model file
  round trip, ``predict``; bad files and values give one ``error:`` line, exit 2, nothing written.
* The power-of-two warp: bit-true model against the float model (error bound), the RTL warp
  exhaustively against the bit-true warp (Amaranth simulation); the warped designs in
  ``generate`` / ``simulate``: ``tests/test_warped_design.py``.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers.cli import CliRunner

from pwas_hdl.fit.geometry import Grid, pow2_breakpoints, pow2_exponents, quantile_breakpoints


# ------------------------------------------------------------------------------------------ geometry
def test_uniform_grid_is_unchanged_and_equal_breakpoints_give_the_same_function(rng):
    g = Grid([0.0, -1.0], [2.0, 3.0], [4, 3])
    assert g.uniform and g.breakpoints is None
    gb = Grid([0.0, -1.0], [2.0, 3.0], [4, 3], breakpoints=[np.linspace(0, 2, 5), np.linspace(-1, 3, 4)])
    assert not gb.uniform and gb != g
    x = rng.uniform([-0.5, -2], [2.5, 4], (500, 2))
    w = rng.normal(size=g.n_vertices)
    np.testing.assert_allclose(gb.evaluate(w, x), g.evaluate(w, x), rtol=0, atol=1e-12)
    np.testing.assert_allclose(gb.vertex_points(), g.vertex_points())


def test_non_uniform_grid_interpolates_its_vertices(rng):
    b0, b1 = np.array([0.0, 0.1, 0.5, 2.0]), np.array([-1.0, 2.5, 3.0])
    g = Grid([0.0, -1.0], [2.0, 3.0], [3, 2], breakpoints=[b0, b1])
    pts = g.vertex_points()
    assert set(pts[:, 0]) == set(b0) and set(pts[:, 1]) == set(b1)
    w = rng.normal(size=g.n_vertices)
    np.testing.assert_allclose(g.evaluate(w, pts), w, atol=1e-12)  # exact at every vertex
    # affine inside one simplex: the midpoint value is the mean of the ends
    a, b = np.array([[0.3, 2.6]]), np.array([[0.46, 2.6]])  # fractions (0.5, 0.2) .. (0.9, 0.2): one simplex
    mid = (a + b) / 2
    np.testing.assert_allclose(g.evaluate(w, mid), (g.evaluate(w, a) + g.evaluate(w, b)) / 2, atol=1e-12)
    s, out = g.to_grid_units(np.array([[0.3, 2.75], [-1.0, 9.0]]))
    np.testing.assert_allclose(s[0], [1.5, 1.5])
    assert list(out) == [False, True] and list(s[1]) == [0.0, 2.0]


@pytest.mark.parametrize("bad, msg", [
    ([[0.0, 1.0, 0.5, 2.0], None], "increase strictly"),
    ([[0.0, 1.0, 2.0], None], "need 4"),
    ([[0.1, 1.0, 1.5, 2.0], None], "must start at lo"),
    ([[0.0, 1.0, np.nan, 2.0], None], "NaN"),
])
def test_bad_breakpoints_are_refused(bad, msg):
    with pytest.raises(ValueError, match=msg):
        Grid([0.0, 0.0], [2.0, 1.0], [3, 2], breakpoints=bad)


def test_quantile_and_pow2_breakpoints(rng):
    x = np.concatenate([rng.normal(0, 1, (4000, 1)), rng.uniform(-5, 5, (4000, 1))], axis=1)
    lo, hi = np.array([-6.0, -6.0]), np.array([6.0, 6.0])
    q = quantile_breakpoints(x, lo, hi, [6, 4])
    assert [len(b) for b in q] == [7, 5] and all(b[0] == -6 and b[-1] == 6 for b in q)
    # the normal column: each cell holds about 1/6 of the samples
    counts = np.histogram(x[:, 0], q[0])[0] / len(x)
    assert np.all(np.abs(counts - 1 / 6) < 0.02)
    p2 = pow2_breakpoints(x, lo, hi, [6, 4])
    for b in p2:
        e, h0 = pow2_exponents(b)
        assert e.min() == 0 and e.max() <= 4 and np.isclose(h0 * np.sum(2.0 ** e), 12.0)
    # a heavy-tailed column gets narrow central cells
    assert np.diff(p2[0])[2] < np.diff(p2[0])[0]
    assert pow2_exponents(q[0]) is None


def test_pow2_cell_widths_are_rounded_in_the_log_domain():
    """Hand-worked: samples 0, 1, 2 on [0, 4] with p = 2 have the median 1, quantile cells 1 and 3 wide;
    log2(3) = 1.58 rounds to 2, so the cells are 1 and 4 base steps, h0 = 4 / 5. Widths 1 and 1.5
    (log2 = 0.58) round to 2 and 1 base steps too; 1 and 1.4 (0.49) to equal cells."""
    p2 = pow2_breakpoints(np.array([[0.0], [1.0], [2.0]]), [0.0], [4.0], 2)
    np.testing.assert_allclose(p2[0], [0.0, 0.8, 4.0], rtol=1e-15)
    e, h0 = pow2_exponents(p2[0])
    assert e.tolist() == [0, 2] and h0 == pytest.approx(0.8)
    p2 = pow2_breakpoints(np.array([[0.0], [1.0], [2.0]]), [0.0], [2.5], 2)
    assert pow2_exponents(p2[0])[0].tolist() == [0, 1]
    p2 = pow2_breakpoints(np.array([[0.0], [1.0], [2.0]]), [0.0], [2.4], 2)
    assert pow2_exponents(p2[0])[0].tolist() == [0, 0]


def test_pow2_exponents_refuses_near_powers_of_two():
    """The warp shifts by e_k exactly: a cell 1 % off a power-of-two multiple is not one."""
    assert pow2_exponents(np.array([0.0, 1.0, 3.0, 7.0]))[0].tolist() == [0, 1, 2]
    assert pow2_exponents(np.array([0.0, 1.0, 3.01])) is None
    assert pow2_exponents(np.array([0.0, 1.0, 1.99])) is None


def test_quantile_groups_pool_the_samples_of_a_group(rng):
    x = np.stack([rng.normal(0, 1, 3000), rng.normal(0.5, 2, 3000), rng.uniform(-5, 5, 3000)], axis=1)
    lo, hi = np.array([-6.0, -6.0, -6.0]), np.array([6.0, 6.0, 6.0])
    q = quantile_breakpoints(x, lo, hi, 4, groups=[[0, 1], [2]])
    np.testing.assert_array_equal(q[0], q[1])
    pooled = x[:, :2].reshape(-1)
    np.testing.assert_allclose(q[0][1:-1], np.quantile(pooled[np.abs(pooled) <= 6], [0.25, 0.5, 0.75]))
    np.testing.assert_array_equal(q[2], quantile_breakpoints(x, lo, hi, 4)[2])
    hi2 = np.array([6.0, 7.0, 6.0])  # another domain: not pooled
    q2 = quantile_breakpoints(x, lo, hi2, 4, groups=[[0, 1]])
    np.testing.assert_array_equal(q2[0], quantile_breakpoints(x, lo, hi2, 4)[0])


# ------------------------------------------------------------------------------------------ fit / model file / CLI
@pytest.fixture(scope="module")
def lorenz_csv(tmp_path_factory):
    from pwas_hdl.systems.lorenz import lorenz

    d = lorenz(2500, seed=3)
    path = tmp_path_factory.mktemp("bp") / "lorenz.csv"
    path.write_text("y,z\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(d.y[:, 0], d.z[:, 0])))
    return path


@pytest.mark.parametrize("rule", ["quantile", "quantile-pow2", "file"])
def test_fit_breakpoints_cli_round_trip(rule, lorenz_csv, tmp_path):
    from pwas_hdl.cli import app
    from pwas_hdl.fit.model_file import read_model

    arg = rule
    if rule == "file":
        arg = str(tmp_path / "bp.json")
        Path(arg).write_text(json.dumps({"format": "pwas-hdl-breakpoints", "version": 1, "regressors": ["y[t-1]", "y[t]"],
                                         "breakpoints": [[-25, -8, 0, 8, 25], [-25, -5, 0, 5, 25]]}))
    out = tmp_path / "m.json"
    r = CliRunner().invoke(app, ["fit", str(lorenz_csv), "-y", "y", "-z", "z", "--my", "2", "-p", "4", "--sigma", "1e-3",
                                 "--breakpoints", arg, "-o", str(out)])
    assert r.exit_code == 0, r.output
    m = read_model(out)
    assert m.grid_.n_vertices == 25 and not m.grid_.uniform
    d = json.loads(out.read_text())
    assert d["fit"]["breakpoints"] == ("given" if rule == "file" else rule)
    if rule == "file":
        assert d["grid"]["breakpoints"][1] == [-25, -5, 0, 5, 25] and d["grid"]["lo"] == [-25, -25]
    pred = tmp_path / "p.csv"
    r = CliRunner().invoke(app, ["predict", str(out), str(lorenz_csv), "-o", str(pred)])
    assert r.exit_code == 0, r.output
    zhat = np.loadtxt(pred, delimiter=",", skiprows=1)[:, 1]
    from pwas_hdl.systems.lorenz import lorenz

    y = lorenz(2500, seed=3).y
    np.testing.assert_allclose(zhat, m.predict(None, y)[:, 0], rtol=1e-9)


@pytest.mark.parametrize("content, msg", [
    ('{"format": "pwas-hdl-breakpoints", "version": 1, "breakpoints": [[0, 1, 0.5], [0, 1]]}', "increase strictly"),
    ('{"format": "pwas-hdl-breakpoints", "version": 1, "breakpoints": [[0, 1]]}', "1 breakpoint lists for n = 2"),
    ('{"format": "pwas-hdl-breakpoints", "version": 1, "breakpoints": [[0, "a"], [0, 1]]}', "breakpoints[0][1]"),
    ('{"format": "pwas-hdl-breakpoints", "version": 1, "breakpoints": [[0, 1e999], [0, 1]]}', "is not a finite number"),
    ('{"format": "pwas-hdl-breakpoints", "version": 1, "breakpoints": [[0, 1], [0, 1]], "extra": 1}', "extra"),
    ('{"format": "other", "version": 1, "breakpoints": [[0, 1], [0, 1]]}', "format"),
    ('{"format": "pwas-hdl-breakpoints", "version": 1, "regressors": ["a", "b"], "breakpoints": [[-30, 30], [-30, 30]]}',
     "the file is for regressors"),
    ("[[0, 1]", "JSON"),
    (None, "neither"),
])
def test_bad_breakpoints_file_is_one_error_line(content, msg, lorenz_csv, tmp_path):
    from pwas_hdl.cli import app

    path = tmp_path / "bp.json"
    if content is not None:
        path.write_text(content)
    out = tmp_path / "m.json"
    r = CliRunner().invoke(app, ["fit", str(lorenz_csv), "-y", "y", "-z", "z", "--my", "2", "--sigma", "1e-3",
                                 "--breakpoints", str(path), "-o", str(out)])  # no -p: the file sets the cells
    assert r.exit_code == 2, r.output
    errs = [ln for ln in r.output.splitlines() if ln.startswith("error:")]
    assert len(errs) == 1 and msg in r.output, r.output
    assert "Traceback" not in r.output and not out.exists()


def test_generate_refuses_a_non_pow2_partition_clearly(lorenz_csv, tmp_path):
    """Quantile cuts are not power-of-two multiples of a base step: no warp, one error line (quantile-pow2 is built)."""
    from pwas_hdl.cli import app

    out = tmp_path / "m.json"
    assert CliRunner().invoke(app, ["fit", str(lorenz_csv), "-y", "y", "-z", "z", "--my", "2", "-p", "4", "--sigma", "1e-3",
                                    "--breakpoints", "quantile", "-o", str(out)]).exit_code == 0
    r = CliRunner().invoke(app, ["generate", str(out), "-o", str(tmp_path / "g")])
    assert r.exit_code == 2 and "power-of-two multiples" in r.output and "quantile-pow2" in r.output, r.output
    assert not (tmp_path / "g").exists()


# ------------------------------------------------------------------------------------------ the warp
@pytest.fixture(scope="module")
def warped():
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel
    from pwas_hdl.systems.lorenz import lorenz

    d = lorenz(3000, seed=5)
    m = PWASVirtualSensor(my=2, partitions=5, breakpoints="quantile-pow2", sigma=1e-3, output_names=["y"], target_names=["z"])
    m.fit(None, d.y, d.z)
    return m, WarpedFixedPointModel.from_sensor(m, input_bits=10)


def test_warped_bittrue_model_within_the_error_bound(warped, rng):
    m, w = warped
    assert any(len(set(wp.exps)) > 1 for wp in w.warps)  # really non-uniform cells
    x = rng.uniform(m.grid_.lo - 3, m.grid_.hi + 3, (20000, 2))
    q = w.quantize_inputs(x)
    xq = w.represented_inputs(q)
    err = np.abs(w.predict(xq) - m.predict_regressors(xq))
    assert err.max() <= w.error_bound * (1 + 1e-9)
    _, oor = w.evaluate(q)
    inside = np.all((xq >= m.grid_.lo) & (xq <= m.grid_.hi), axis=1)
    assert oor.any() and np.array_equal(oor, ~inside)
    for j, wp in enumerate(w.warps):  # every breakpoint is an input code
        np.testing.assert_allclose(w.offset[j] + w.lsb[j] * np.array(wp.code_breaks), m.grid_.breakpoints[j], rtol=0,
                                   atol=1e-9 * (m.grid_.hi[j] - m.grid_.lo[j]))


@pytest.mark.parametrize("bits, dim", [(10, 0), (10, 1), (3, 0), (3, 1)])
def test_warp_rtl_equals_the_bittrue_warp_for_every_code(bits, dim, warped):
    """Every input code, both dimensions; 3-bit inputs give f0 = 0 (no offset bits below a base step)."""
    from amaranth.hdl import Module, Signal
    from amaranth.sim import Simulator

    from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel
    from pwas_hdl.hdl.warp import warp_into

    m, w = warped
    if bits != w.input_bits:
        w = WarpedFixedPointModel.from_sensor(m, input_bits=bits)
    wp = w.warps[dim]
    if bits == 3:
        assert wp.f0 == 0
    mm = Module()
    q = Signal(wp.input_bits)
    u = Signal(wp.width)
    mm.d.comb += u.eq(warp_into(mm, q, wp, "w0"))
    codes = np.arange(-(1 << (wp.input_bits - 1)), 1 << (wp.input_bits - 1))
    want = wp.apply(codes)
    got = []

    async def tb(ctx):
        for c in codes:
            ctx.set(q, int(c) & ((1 << wp.input_bits) - 1))
            v = ctx.get(u)
            got.append(v - (1 << wp.width) if v >> (wp.width - 1) else v)

    sim = Simulator(mm)
    sim.add_testbench(tb)
    sim.run()
    np.testing.assert_array_equal(np.array(got), want)


# The warped core and sensor top through generate / simulate (lint, byte-identical reruns, cocotb on both
# simulators with stalls, a mid-stream reset and out-of-range codes): tests/test_warped_design.py.
