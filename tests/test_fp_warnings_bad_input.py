"""Bad input gives one ``error:`` line and no numpy RuntimeWarning beside it (D16).

Each case runs with warnings turned into errors: a numpy floating-point warning that reaches the user
then shows as an internal error (exit 3) instead of the one ``error:`` line.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from helpers.cli import CliRunner
from helpers.folders import tree

import pwas_hdl.cli as cli
from pwas_hdl.errors import InputError

RUNNER = CliRunner()


def _run(*args):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return RUNNER.invoke(cli.app, [str(a) for a in args])


def _refused(root, *args) -> str:
    before = tree(root)
    res = _run(*args)
    lines = res.output.strip().splitlines()
    assert res.exit_code == 2, res.output
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    assert tree(root) == before
    return lines[0]


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    d = tmp_path_factory.mktemp("fpw")
    assert RUNNER.invoke(cli.app, ["make-data", "lorenz", "-o", str(d / "d.csv"), "--samples", "400"]).exit_code == 0
    res = RUNNER.invoke(cli.app, ["fit", str(d / "d.csv"), "-o", str(d / "m.json"), "-y", "y", "-z", "z", "--my", "2",
                                  "-p", "3", "--sigma", "1e-3"])
    assert res.exit_code == 0, res.output
    return d


@pytest.mark.parametrize("grid", ["logspace:300:400:3", "logspace:-400:-350:3"])
def test_a_sigma_grid_beyond_the_float_range_is_refused_without_a_warning(work, grid):
    line = _refused(work, "fit", work / "d.csv", "-o", work / "o.json", "-y", "y", "-z", "z", "--my", "2", "-p", "3",
                    "--sigma-grid", grid)
    assert "--sigma-grid" in line and "between -307 and 308" in line, line


def test_a_gamma_that_overflows_the_domain_is_refused_without_a_warning(work):
    line = _refused(work, "fit", work / "d.csv", "-o", work / "o.json", "-y", "y", "-z", "z", "--my", "2", "-p", "3",
                    "--sigma", "1e-3", "--gamma", "1e308")
    assert "--gamma" in line and "y[t-1]" in line, line


@pytest.mark.parametrize("weight", [1e308, -1.7e308])
def test_predict_with_huge_weights_prints_a_finite_rmse_without_a_warning(work, tmp_path, weight):
    doc = json.loads((work / "m.json").read_text())
    w = doc["weights"]["z"]
    doc["weights"]["z"] = [weight * (-1) ** i for i in range(len(w))]
    (tmp_path / "big.json").write_text(json.dumps(doc))
    res = _run("predict", tmp_path / "big.json", work / "d.csv", "-o", tmp_path / "p.csv")
    assert res.exit_code == 0, res.output
    rmse = [ln for ln in res.output.splitlines() if ln.startswith("RMSE")]
    assert len(rmse) == 1 and "Warning" not in res.output, res.output
    value = float(rmse[0].split(":")[1].split()[0])
    assert 1e306 < value < np.inf, rmse[0]


def test_predict_rmse_of_an_ordinary_model_is_unchanged(work, tmp_path):
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.io.csv_table import read_csv

    res = _run("predict", work / "m.json", work / "d.csv", "-o", tmp_path / "p.csv")
    assert res.exit_code == 0, res.output
    model = PWASVirtualSensor.load(work / "m.json")
    t = read_csv(work / "d.csv")
    zhat = model.predict(None, t.numeric(["y"]))[:, 0]
    ztrue = t.numeric(["z_true"])[model.memory - 1:, 0]
    expected = float(np.sqrt(np.mean((zhat - ztrue) ** 2)))
    assert f"RMSE of z_hat against column z_true: {expected:.6g} " in res.output, res.output


def test_observer_bank_features_of_huge_residuals_are_refused_without_a_warning():
    from pwas_hdl.fit.observer_bank import residual_features

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for fm in ("11b", "11b-sq"):
            with pytest.raises(InputError, match="rescale or clean the data"):
                residual_features(np.full((50, 3), 1e300), 7, fm)
        ok = residual_features(np.full((50, 3), 2.0), 7, "11b")
    np.testing.assert_allclose(ok, 2.0 * np.sqrt(8 / 7))  # l + 1 = 8 squares over l = 7


def test_observer_bank_normalisation_of_signals_near_the_float_limit():
    """Signals of ~1e300 have a finite spread (the plain std overflowed to inf, every normalised signal
    became 0 and the fit said the features were constant); ordinary signals keep numpy's own mean and std."""
    from pwas_hdl.fit.observer_bank import _mean_std
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    rng = np.random.default_rng(3)
    x = rng.normal(2.0, 3.0, size=(500, 2))
    mean, std = _mean_std(x)
    assert np.array_equal(mean, x.mean(axis=0)) and np.array_equal(std, x.std(axis=0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        big_mean, big_std = _mean_std(x * 1e300)
    np.testing.assert_allclose(big_mean / 1e300, mean, rtol=1e-12)
    np.testing.assert_allclose(big_std / 1e300, std, rtol=1e-12)

    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd

    tr, _, _ = make_pv_dataset("pv-benchmark", 1200, 10, seed=2)
    us, ys, zs, big = [tr.u], [tr.y], [tr.z], 2.0**1000  # exact scaling: the same data to the last bit
    plain = ObserverBankFrontEnd(n_models=2).fit(us, ys, zs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        huge = ObserverBankFrontEnd(n_models=2).fit([tr.u * big], [tr.y * big], zs)
    np.testing.assert_allclose(huge.u_std_ / big, plain.u_std_, rtol=1e-12)
    np.testing.assert_allclose(huge.y_std_ / big, plain.y_std_, rtol=1e-12)
    f_plain, _ = plain.transform(us, ys)
    f_huge, _ = huge.transform([tr.u * big], [tr.y * big])
    assert np.ptp(f_huge, axis=0).min() > 0
    np.testing.assert_allclose(f_huge, f_plain, rtol=1e-9, atol=1e-9)


def test_observer_bank_accumulator_bound_of_huge_coefficient_codes_is_exact():
    """The accumulator's bound is computed in Python integers: with input coefficients near 1e5 (local
    models of collinear inputs, as three-tank's u1 = u2) the codes times 2**(B_in - 1) passed 2**63, the
    numpy int64 product wrapped with a RuntimeWarning and could under-size the accumulator; now the
    width is exact and refused, without a warning."""
    from pwas_hdl.fit.observer_bank import ObserverBankFrontEnd
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.fixedpoint.observer_bank import observer_bank_model
    from pwas_hdl.systems.pv_benchmark import make_pv_dataset

    tr, _, _ = make_pv_dataset("pv-benchmark", 1200, 10, seed=2)
    m = PWASVirtualSensor(mu=0, my=0, partitions=2, sigma=0.1, front_end=ObserverBankFrontEnd(n_models=2)).fit(tr.u, tr.y, tr.z)
    fe = m.front_end_
    b = slice(fe.order, fe.order + fe.order * fe.nu_)  # the b_i of [a_M .. a_1, b_M .. b_1, c]
    fe.models_[:, b] *= 2e5
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError, match=r"acc would need (\d+) bits") as exc:
            observer_bank_model(m)
    assert "--state-frac (state_frac)" in str(exc.value) and "--input-headroom (input_headroom)" in str(exc.value)


def test_explore_of_a_model_with_a_subnormal_domain_saturates_the_input_codes_without_a_warning(work, tmp_path):
    # a hand-edited domain of width 1e-310: the input lsb is subnormal, (x - lo) / lsb overflows; the
    # codes saturate like those of any value outside the domain (as Grid.to_grid_units clamps)
    doc = json.loads((work / "m.json").read_text())
    doc["grid"]["lo"], doc["grid"]["hi"] = [0.0, 0.0], [1e-310, 1e-310]
    (tmp_path / "tiny.json").write_text(json.dumps(doc))
    res = _run("explore", tmp_path / "tiny.json", work / "d.csv", "-o", tmp_path / "ex", "--input-bits", "12",
               "--weight-frac", "4", "--output-frac", "4")
    assert res.exit_code == 0 and "Warning" not in res.output, res.output
    assert (tmp_path / "ex" / "explore.json").is_file()


def _scaled(src, dst, column, factor, row=None):
    """``src`` with ``column`` multiplied by ``factor`` (every row, or only ``row``)."""
    lines = src.read_text().splitlines()
    c = lines[0].split(",").index(column)
    for i in range(1, len(lines)):
        if row is None or i == row:
            cells = lines[i].split(",")
            cells[c] = repr(float(cells[c]) * factor)
            lines[i] = ",".join(cells)
    dst.write_text("\n".join(lines) + "\n")
    return dst


def test_fit_of_targets_whose_squares_overflow_is_refused_without_a_warning(work, tmp_path):
    # |z| ~ 1e162: the fit's squared errors overflowed (RuntimeWarnings, then "Out of range float values
    # are not JSON compliant: inf" as the only explanation); refused before the solve, with the limit
    _scaled(work / "d.csv", tmp_path / "big.csv", "z", 1e160)
    for extra in (["--sigma", "1e-3"], []):
        line = _refused(tmp_path, "fit", tmp_path / "big.csv", "-o", tmp_path / "o.json", "-y", "y", "-z", "z",
                        "--my", "2", "-p", "3", *extra)
        assert "'z'" in line and "1e+150" in line and "rescale" in line, line
    line = _refused(tmp_path, "fit-map", tmp_path / "big.csv", "-o", tmp_path / "o.json", "-z", "z", "-y", "y", "-p", "3")
    assert "column 'z'" in line and "1e+150" in line, line
    # below the limit the fit runs as before
    _scaled(work / "d.csv", tmp_path / "ok.csv", "z", 1e140)
    res = _run("fit", tmp_path / "ok.csv", "-o", tmp_path / "ok.json", "-y", "y", "-z", "z", "--my", "2", "-p", "3",
               "--sigma", "1e-3")
    assert res.exit_code == 0 and "Warning" not in res.output, res.output


def test_explore_and_simulate_refuse_a_reference_whose_squares_overflow_before_any_work(work, tmp_path):
    from unittest import mock

    _scaled(work / "d.csv", tmp_path / "big.csv", "z_true", 1e308 / 400, row=50)  # one reference cell ~1e306
    line = _refused(tmp_path, "explore", work / "m.json", tmp_path / "big.csv", "-o", tmp_path / "ex", "--input-bits", "12",
                    "--weight-frac", "4", "--output-frac", "4")
    assert "column 'z_true'" in line and "1e+150" in line, line
    assert _run("generate", work / "m.json", "--design", "sensor", "-o", tmp_path / "hw").exit_code == 0
    with mock.patch("pwas_hdl.verify.simulation.run_rtl", side_effect=AssertionError("the simulator ran")):
        line = _refused(tmp_path, "simulate", tmp_path / "hw", tmp_path / "big.csv", "-o", tmp_path / "s.csv")
    assert "column 'z_true'" in line and "1e+150" in line, line


@pytest.mark.parametrize("column", ["x1_true", "y"])
def test_simulate_of_an_estimator_refuses_a_reference_whose_squares_overflow_before_any_work(tmp_path, column):
    """The estimator's state RMSE (against ``<x>_true``) and output MSE (against ``y``) overflowed after
    the simulator had run ('Out of range float values are not JSON compliant: inf')."""
    from unittest import mock

    assert _run("make-data", "switched-linear", "-o", tmp_path / "d.csv", "--estimator-out", tmp_path / "est.json",
                "--samples", "200").exit_code == 0
    assert _run("generate", tmp_path / "est.json", "-o", tmp_path / "g").exit_code == 0
    big = _scaled(tmp_path / "d.csv", tmp_path / "big.csv", column, 1e300, row=5)
    with mock.patch("pwas_hdl.verify.estimator_simulation.replay_segments", side_effect=AssertionError("the simulator ran")):
        line = _refused(tmp_path, "simulate", tmp_path / "g", big, "-o", tmp_path / "s.csv", "--traj-col", "run")
    assert f"column '{column}'" in line and "1e+150" in line, line
