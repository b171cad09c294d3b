"""Virtual-sensor top (lag bank + core) against LagStructure + the bit-true model."""

from __future__ import annotations

import numpy as np
import pytest

from pwas_hdl.fixedpoint.bittrue import FixedPointModel
from pwas_hdl.hdl import build_sensor, design_info, lag_plan
from pwas_hdl.hdl.simulate import pack_fields, run_stream, unpack_fields
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor


def plant(t_len, nu, ny, seed):
    rng = np.random.default_rng(seed)
    u = rng.normal(0, 1, (t_len, nu)) if nu else None
    y = np.zeros((t_len, ny))
    for t in range(1, t_len):
        drive = u[t - 1].sum() if nu else rng.normal()
        y[t] = 0.8 * y[t - 1] + 0.3 * np.tanh(drive + np.arange(ny))
    z = np.sin(y.sum(axis=1)) + (u[:, 0] if nu else 0.0)
    return u, y, z


def signal_codes(model, top, u, y):
    """Per-signal input codes (the format all lags of a signal share)."""
    fmts = model.signal_input_formats()
    cols = []
    for name, _ in top.signals:
        kind, ch = name[0], int(name[1:])
        data = u[:, ch] if kind == "u" else y[:, ch]
        cols.append(fmts[name].quantize(data))
    return np.stack(cols, axis=1).astype(np.int64)


@pytest.mark.parametrize(
    "mu, my, nu, ny, parts, pipe",
    [
        (2, 3, 1, 1, [3, 3, 2, 2, 2], "balanced"),  # Mu != My, inputs and outputs
        (0, 4, 0, 1, 2, "min"),  # Lorenz-like: outputs only
        (1, 1, 2, 1, 3, "max"),  # M = 1: no warm-up
        (2, 1, 1, 2, [2, 2, 3, 1], "balanced"),  # two output channels in one time step
    ],
)
def test_sensor_top_matches_lagstructure_and_model(mu, my, nu, ny, parts, pipe):
    u, y, z = plant(300, nu, ny, seed=mu * 10 + my)
    names = [f"u{i}" for i in range(nu)], [f"y{i}" for i in range(ny)]
    sensor = PWASVirtualSensor(mu=mu, my=my, partitions=parts, sigma=1e-3, input_names=names[0], output_names=names[1])
    sensor.fit(u, y, z)
    model = FixedPointModel.from_sensor(sensor)
    top = build_sensor(model, sensor.lags_, pipeline=pipe)
    assert lag_plan(model) == lag_plan(model, sensor.lags_)
    m_hist = sensor.lags_.memory
    assert top.warmup == m_hist - 1

    t_len = 60
    codes = signal_codes(model, top, u[:t_len] if nu else None, y[:t_len])
    b = model.input_bits
    r = run_stream(top, [pack_fields(row, b) for row in codes], p_valid=0.8, p_ready=0.6, seed=3,
                   n_expected=t_len - top.warmup, watch=("warm",))
    assert len(r.outputs) == t_len - top.warmup
    assert all(r.extra["warm"])
    # reference: regressors of the code sequence in LagStructure order, through the bit-true model
    cu = codes[:, :nu] if nu else None
    cy = codes[:, nu:]
    xi = sensor.lags_.build(cu, cy).astype(np.int64)
    ref, ref_oor = model.evaluate(xi)
    ow, nz = model.output_format.bits, model.nz
    got = np.array([unpack_fields(w, ow, nz) for w in r.outputs])
    assert np.array_equal(got, ref)
    assert np.array_equal(np.array([(w >> (nz * ow)) & 1 for w in r.outputs], dtype=bool), ref_oor)
    # no stalls: first output `latency` cycles after the sample that completes the regressor
    r2 = run_stream(top, [pack_fields(row, b) for row in codes[:10]], n_expected=10 - top.warmup)
    assert r2.produced_at[0] - r2.accepted_at[top.warmup] == top.latency
    assert r2.accepted_at == list(range(r2.accepted_at[0], r2.accepted_at[0] + 10))


def test_sensor_design_info_documents_ports_and_warmup():
    u, y, z = plant(200, 1, 1, seed=1)
    sensor = PWASVirtualSensor(mu=1, my=3, partitions=2, sigma=1e-3).fit(u, y, z)
    model = FixedPointModel.from_sensor(sensor)
    top = build_sensor(model, name="vs_top")
    top._MustUse__silence = True  # described, not elaborated
    info = design_info(top, "amaranth")
    assert info["module"] == "vs_top" and info["kind"] == "sensor"
    assert [p["name"] for p in info["ports"]] == [  # clock, reset, input stream, output stream (issue 8)
        "clk", "rst", "in__valid", "in__ready", "in__payload", "out__valid", "out__ready", "out__payload", "warm"
    ]
    axis = design_info(top)  # the default naming
    assert [p["name"] for p in axis["ports"]] == [
        "aclk", "aresetn", "s_axis_tvalid", "s_axis_tready", "s_axis_tdata", "m_axis_tvalid", "m_axis_tready", "m_axis_tdata", "warm"
    ]
    assert [f["name"] for f in axis["payload"]["s_axis_tdata"]] == ["u0", "y0"]
    assert [f["name"] for f in info["payload"]["in__payload"]] == ["u0", "y0"]
    assert [f["name"] for f in info["payload"]["out__payload"]] == ["z0", "out_of_range"]
    assert info["warmup"]["samples_without_output"] == 2
    assert info["lags"]["regressor"] == [{"signal": "u0", "lag": 0}] + [{"signal": "y0", "lag": k} for k in (2, 1, 0)]


def test_sensor_rejects_lags_with_different_formats():
    u, y, z = plant(200, 1, 1, seed=2)
    sensor = PWASVirtualSensor(mu=2, my=1, partitions=[3, 2, 2], sigma=1e-3).fit(u, y, z)
    model = FixedPointModel.from_sensor(sensor)
    with pytest.raises(ValueError, match="lags of signal"):
        build_sensor(model)
