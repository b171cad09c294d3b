"""`explore` of a recurrent sensor (fit --mz): every point is the closed loop.

Each point runs the bit-true recurrence (:class:`~pwas_hdl.fixedpoint.recurrence.RecurrentFixedPointModel`,
the recurrent top's specification) from reset on every trajectory, row ``t`` against ``z(t + lead)``;
the float column is the model's float recurrence. The tests recompute the default point from the
recurrence itself, compare coarse and fine inputs, and check trajectories and the CLI.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from pwas_hdl.cli import main
from pwas_hdl.design.generate import fixed_point_model
from pwas_hdl.design.recurrent import recurrent_model
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.flow.explore import explore


def _plant(n, seed):
    rng = np.random.default_rng(seed)
    y = np.sin(np.arange(n) * 0.05 + seed) + 0.1 * rng.standard_normal(n)
    z = np.zeros(n)
    for t in range(1, n):
        z[t] = 0.8 * z[t - 1] + 0.2 * y[t - 1] ** 2
    return y, z


@pytest.fixture(scope="module")
def rec():
    y, z = _plant(900, 0)
    s = PWASVirtualSensor(my=1, mz=1, partitions=4, sigma=1e-3, output_names=["y"], target_names=["z"]).fit(None, y, z)
    yt, zt = _plant(500, 1)
    return s, yt, zt


def _rmse(a, b):
    return np.sqrt(np.mean((a - b) ** 2, axis=0))


def test_the_default_point_is_the_bit_true_recurrence(rec):
    s, y, z = rec
    r = explore(s, (None, y, z), input_bits=[8, 12], weight_frac=[4, 8], output_frac=[6, 9])
    assert r["model"]["recurrence"] == {"Mz": 1, "lead": 0, "accuracy": r["model"]["recurrence"]["accuracy"]}
    m, lead = max(s.lags_.memory, 1), s.lead_
    rows = np.arange(m - 1, len(y))
    keep = rows + lead < len(y)
    zref = z[rows[keep] + lead]
    zf = np.asarray(s.predict(None, y), float).reshape(-1, 1)[keep]
    assert r["data"]["samples"] == int(keep.sum())
    assert np.allclose(r["float"]["rmsee"], _rmse(zf, zref[:, None]), rtol=1e-12, atol=0)
    dflt = next(p for p in r["points"] if p["is_default"])
    fxm = fixed_point_model(s)
    rm = recurrent_model(s, fxm)
    zb = fxm.to_physical_output(rm.run(rm.quantize_signals(None, y[:, None]))["out"])[keep]
    assert np.allclose(dflt["rmsee"], _rmse(zb, zref[:, None]), rtol=1e-12, atol=0)
    assert np.isclose(dflt["max_dev_float_lsb"], np.abs(zb - zf).max() / fxm.output_format.lsb, rtol=1e-12)
    # open-loop evaluation (the true past z as regressor) would give another number: the sweep is the closed loop's
    xi = s.lags_.build_series_parallel(None, y[:, None], z[:, None])
    zo = fxm.predict(xi)
    assert not np.isclose(_rmse(zo, z[-len(zo):, None])[0], dflt["rmsee"][0], rtol=1e-6)
    assert all(p["bound_holds"] for p in r["points"])  # per step, at the codes the recurrence produced


def test_coarse_inputs_drift_further_from_the_float_recurrence(rec):
    s, y, z = rec
    r = explore(s, (None, y, z), input_bits=[6, 14], weight_frac=[10], output_frac=[12])
    dev = {p["input_bits"]: p["rms_dev_float"][0] for p in r["points"] if not p["is_default"]}
    assert dev[6] > 4 * dev[14] > 0


def test_trajectories_each_start_from_reset(rec, tmp_path):
    """A CSV of two runs: the samples are both runs' rows; the RMSEE is that of the two runs' recurrences."""
    s, y, z = rec
    y2, z2 = _plant(300, 2)
    data = tmp_path / "d.csv"
    rows = [(0, a, b) for a, b in zip(y, z)] + [(1, a, b) for a, b in zip(y2, z2)]
    data.write_text("run,y,z\n" + "".join(f"{r},{float(a)!r},{float(b)!r}\n" for r, a, b in rows), encoding="utf-8")
    r = explore(s, data, traj_col="run", input_bits=[12], weight_frac=[8], output_frac=[9])
    m = max(s.lags_.memory, 1)
    assert r["data"]["samples"] == (len(y) - m + 1) + (len(y2) - m + 1)
    fxm = fixed_point_model(s, input_bits=12, weight_frac=8, output_frac=9)
    rm = recurrent_model(s, fxm)
    zb = np.concatenate([fxm.to_physical_output(rm.run(rm.quantize_signals(None, yy[:, None]))["out"])
                         for yy in (y, y2)])
    zr = np.concatenate([z[m - 1:], z2[m - 1:]])[:, None]
    pt = next(p for p in r["points"] if (p["input_bits"], p["weight_frac"], p["output_frac"]) == (12, 8, 9))
    assert np.allclose(pt["rmsee"], _rmse(zb, zr), rtol=1e-12, atol=0)


def test_cli(rec, tmp_path):
    s, y, z = rec
    s.save(tmp_path / "m.json")
    data = tmp_path / "d.csv"
    data.write_text("y,z\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(y, z)), encoding="utf-8")
    assert main(["explore", str(tmp_path / "m.json"), str(data), "--input-bits", "8,12", "--weight-frac", "6,8",
                 "--output-frac", "7,9", "-o", str(tmp_path / "ex")]) == 0
    r = json.loads((tmp_path / "ex" / "explore.json").read_text())
    assert r["model"]["recurrence"]["Mz"] == 1 and r["pareto"] and (tmp_path / "ex" / "explore.png").exists()


def test_a_warped_recurrent_sensor_is_swept_with_its_warp(rec):
    """fit --mz --breakpoints quantile-pow2: each point's recurrence goes through the warp (the
    fed-back estimate requantised to the warp's input codes), as the warped recurrent top does."""
    from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel

    _, y, z = rec
    yf, zf_ = _plant(900, 0)
    s = PWASVirtualSensor(my=1, mz=1, partitions=4, breakpoints="quantile-pow2", sigma=1e-3, output_names=["y"],
                          target_names=["z"]).fit(None, yf, zf_)
    r = explore(s, (None, y, z), input_bits=[8, 12], weight_frac=[8], output_frac=[9])
    assert r["model"]["kind"] == "warped" and r["model"]["recurrence"]["Mz"] == 1
    fxm = fixed_point_model(s, input_bits=12, weight_frac=8, output_frac=9)
    assert isinstance(fxm, WarpedFixedPointModel)
    rm = recurrent_model(s, fxm)
    zb = fxm.to_physical_output(rm.run(rm.quantize_signals(None, y[:, None]))["out"])
    pt = next(p for p in r["points"] if (p["input_bits"], p["weight_frac"], p["output_frac"]) == (12, 8, 9))
    assert np.allclose(pt["rmsee"], _rmse(zb, z[max(s.lags_.memory, 1) - 1:, None]), rtol=1e-12, atol=0)
    assert "core_input_bits" in pt and all(p["bound_holds"] for p in r["points"])


def test_a_format_the_recurrent_top_refuses_is_refused_by_the_sweep_too(rec, tmp_path, capsys):
    """An output format whose range is far below the fed-back input's (s4.10 against s8 inputs): the
    top's feedback product has fewer than B_in + S bits, so generate refuses it (one error line,
    nothing written); the sweep lists it under refused with the same reason, not on the front."""
    s, y, z = rec
    r = explore(s, (None, y, z), input_bits=[8], weight_frac=[8], output_frac=[3, 10], output_bits=4)
    assert [p["output_frac"] for p in r["points"] if not p["is_default"]] == [3]
    assert [x["output_frac"] for x in r["refused"]] == [10]
    assert "feedback requantisation of target 0" in r["refused"][0]["reason"]
    s.save(tmp_path / "m.json")
    capsys.readouterr()
    assert main(["generate", str(tmp_path / "m.json"), "--design", "sensor", "--input-bits", "8", "--output-bits", "4",
                 "--output-frac", "10", "-o", str(tmp_path / "hw")]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith("warning:")]
    assert len(err) == 1 and err[0].startswith("error: feedback requantisation of target 0")
    assert r["refused"][0]["reason"] in err[0] and not (tmp_path / "hw").exists()
