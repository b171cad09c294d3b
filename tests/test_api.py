"""The public API of ``pwas_hdl``: every exported name resolves, lazily; simulate_arrays checks its input."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import pwas_hdl


def test_every_exported_name_resolves_to_its_owner():
    for name in pwas_hdl.__all__:
        obj = getattr(pwas_hdl, name)
        assert getattr(obj, "__name__", name) == name, name
        assert obj.__module__.startswith("pwas_hdl."), (name, obj.__module__)
    assert {"generate", "simulate_data", "simulate_arrays", "synthesize", "FixedPointModel", "PWASVirtualSensor",
            "collect_report", "report_markdown"} <= set(pwas_hdl.__all__)
    with pytest.raises(AttributeError):
        pwas_hdl.no_such_thing  # noqa: B018


def test_import_is_light():
    """``import pwas_hdl`` and the CLI's start load neither Amaranth nor scikit-learn nor cocotb."""
    code = ("import sys, pwas_hdl, pwas_hdl.cli; "
            "print(sorted(m for m in ('amaranth', 'sklearn', 'cocotb') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_simulate_arrays_refuses_bad_signals_before_simulating(lorenz_tiny, tmp_path):
    from pwas_hdl import generate, simulate_arrays

    generate(lorenz_tiny.model, tmp_path / "hw", design="sensor")
    y = lorenz_tiny.test.y
    cases = [
        (dict(), "pass y="),
        (dict(y=np.hstack([y, y])), "2 columns"),
        (dict(y=y, z_true=[y[:10], y[10:]]), "trajectories"),
        (dict(y=y, z_true=y[:-1]), "samples"),
        (dict(y=y, traj_col="run"), "lists of arrays"),
    ]
    for kw, msg in cases:
        with pytest.raises((ValueError, TypeError), match=msg):
            simulate_arrays(tmp_path / "hw", tmp_path / "o.csv", **kw)
    assert not (tmp_path / "o.csv").exists()
