"""The fit's account of its own solve (issue 18): the weights' residual and error bound, checked
afresh from the weights, in the model file (``fit.solve``) and as ``warning:`` lines of ``fit``
when a solve stopped at its iteration cap (at scale, e.g. zero order at N = 10^6 in 4-D, Jacobi-CG
stops there at sigma = 1e-7 and the weights were silently 5.2 off the direct solve)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pwas_hdl.fit import regularized_lsq as rl
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.regularized_lsq import solve_regularized, solve_report, solve_warnings, tikhonov_matrix

from helpers.cli import CliRunner


def _problem(order: int, t: int = 300, seed: int = 0):
    rng = np.random.default_rng(seed)
    grid = Grid(np.full(2, -1.2), np.full(2, 1.2), 12)
    x = rng.uniform(-1.0, 1.0, (t, 2))
    z = np.sin(3 * x).sum(axis=1) + 0.1 * rng.standard_normal(t)
    return grid.basis_matrix(x), z, tikhonov_matrix(grid, order)


@pytest.mark.parametrize("order", [0, 1])
def test_report_of_the_direct_solve_and_of_perturbed_weights(order):
    h, z, gam = _problem(order)
    sigma = 1e-3
    w, info = solve_regularized(h, z, sigma, gam, method="direct", return_info=True)
    rep = solve_report(h, z, w, sigma, gam, info)
    assert rep["method"] == "direct" and rep["converged"] and rep["rel_residual"] < 1e-12
    assert rep["cv_solves"] is None and rep["cv_unconverged"] is None
    # weights off the solution: the residual says so, and the bound covers the actual error
    wrong = w + 1e-3 * np.random.default_rng(1).standard_normal(w.shape)
    bad = solve_report(h, z, wrong, sigma, gam)
    assert not bad["converged"] and bad["rel_residual"] > rl.CG_RTOL and bad["method"] is None
    assert bad["weight_bound"] >= float(np.linalg.norm(wrong - w))
    # the bound is exactly ||r|| / (sigma lambda_min(Gamma)) of the residual computed here
    a = (h.T @ h + sigma * gam).tocsr()
    r = h.T @ z - a @ wrong
    assert bad["weight_bound"] == pytest.approx(np.linalg.norm(r) / (sigma * rl.gamma_min_eigenvalue(gam)), rel=1e-9)
    assert bad["rel_residual"] == pytest.approx(np.linalg.norm(r) / np.linalg.norm(h.T @ z), rel=1e-9)
    assert solve_warnings(rep, sigma) == []
    # the solver's word is not enough: a "converged" info with weights that do not solve the system
    assert not solve_report(h, z, wrong, sigma, gam, info)["converged"]


def test_non_finite_weights_are_not_converged_and_warn():
    h, z, gam = _problem(1)
    w = solve_regularized(h, np.column_stack([z, -z]), 1e-2, gam, method="direct")
    w[3, 1] = np.nan  # the second target only: the report must not lose it
    rep = solve_report(h, np.column_stack([z, -z]), w, 1e-2, gam)
    assert not rep["converged"] and rep["rel_residual"] == np.inf and rep["weight_bound"] == np.inf
    lines = solve_warnings(rep, 1e-2)
    assert len(lines) == 1 and "no finite residual" in lines[0] and "no bound" in lines[0]
    # as read back from a model file (non-finite written as null)
    from_file = dict(rep, rel_residual=None, weight_bound=None, iterations=None)
    assert "did not converge" in solve_warnings(from_file, 1e-2)[0]


def test_unconverged_cg_is_reported_with_a_bound_that_holds():
    h, z, gam = _problem(0)
    sigma = 1e-6
    hth = (h.T @ h).tocsr()
    solver = rl.NormalEquationSolver(hth, gam, 2, method="cg", maxiter=3)
    w, info = solver.solve(solver.restrict_matrix(hth), h.T @ z, sigma)
    assert not info.converged
    rep = solve_report(h, z, w, sigma, gam, info)
    w_exact = solve_regularized(h, z, sigma, gam, method="direct")
    assert not rep["converged"] and rep["iterations"] == info.iterations == 3
    assert rep["weight_bound"] >= float(np.linalg.norm(w - w_exact))
    lines = solve_warnings(rep, sigma)
    assert len(lines) == 1 and lines[0].startswith("warning: the weights did not converge")
    assert "stopped after 3 iterations" in lines[0] and "--sigma" in lines[0]


def _csv(tmp_path, t=400):
    rng = np.random.default_rng(3)
    y = rng.uniform(-1, 1, t)
    z = np.sin(3 * y) + 0.05 * rng.standard_normal(t)
    p = tmp_path / "d.csv"
    p.write_text("y,z\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(y, z)))
    return p


def test_fit_writes_the_solve_block_and_reads_it_back(tmp_path):
    from pwas_hdl.fit.virtual_sensor import load_model
    from pwas_hdl.cli import app

    out = tmp_path / "m.json"
    res = CliRunner().invoke(app, ["fit", str(_csv(tmp_path)), "-y", "y", "-z", "z", "--my", "2", "-p", "6",
                                   "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "warning:" not in res.output
    solve = json.loads(out.read_text())["fit"]["solve"]
    assert solve["converged"] and solve["rel_residual"] <= rl.CG_RTOL
    assert solve["cv_solves"] == 5 * rl.DEFAULT_SIGMA_GRID.size and solve["cv_unconverged"] == 0
    assert load_model(out).solve_ == solve


def test_fit_warns_when_the_solves_stop_at_the_cap(tmp_path, monkeypatch):
    """Every CV solve and the final one by Jacobi-CG capped at 2 iterations (no direct fallback at
    this size): two warning lines, the model file says so, and the exit status stays 0."""
    from pwas_hdl.cli import app

    monkeypatch.setattr(rl, "CG_MAXITER", 2)
    for table in (rl.DIRECT_MAX_UNKNOWNS, rl.DIRECT_MAX_UNKNOWNS_CHOLMOD):
        monkeypatch.setitem(table, (0, 2), 2)
    monkeypatch.setattr(rl, "DIRECT_FLOPS_PER_ENTRY", 0.0)  # nor a factor the analysis finds cheap
    out = tmp_path / "m.json"
    res = CliRunner().invoke(app, ["-q", "fit", str(_csv(tmp_path)), "-y", "y", "-z", "z", "--my", "2", "-p", "6",
                                   "--tikhonov", "0", "-o", str(out)])
    assert res.exit_code == 0, res.output
    warn = [ln for ln in res.output.splitlines() if ln.startswith("warning:")]
    assert len(warn) == 2, res.output
    assert "the weights did not converge" in warn[0] and "stopped after" in warn[0]
    assert f"of {5 * rl.DEFAULT_SIGMA_GRID.size} cross-validation solves stopped unconverged" in warn[1]
    solve = json.loads(out.read_text())["fit"]["solve"]
    assert not solve["converged"] and solve["method"] == "cg" and solve["iterations"] == 2
    assert solve["cv_unconverged"] > 0 and solve["rel_residual"] > rl.CG_RTOL


def test_report_says_when_the_weights_did_not_converge():
    from pwas_hdl.design.report import _solve_sentence

    ok = {"method": "direct", "iterations": 0, "converged": True, "rel_residual": 1e-15, "weight_bound": 1e-6,
          "cv_solves": 105, "cv_unconverged": 0}
    assert _solve_sentence(ok) == "" and _solve_sentence(None) == ""
    bad = dict(ok, converged=False, rel_residual=4.1e-6, weight_bound=1.4e4, cv_unconverged=12)
    text = _solve_sentence(bad)
    assert "did not converge" in text and "4.1e-06" in text and "1.4e+04" in text
    assert "12 of 105 CV solves stopped unconverged" in text
    assert "within" not in _solve_sentence(dict(bad, weight_bound=None))
