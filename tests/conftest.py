"""Shared fixtures of the fitting test suite (all deterministic: every random draw is seeded)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from pwas_hdl.fit.geometry import Grid

@pytest.fixture
def rng() -> np.random.Generator:
    """A freshly seeded generator per test (tests do not depend on their execution order)."""
    return np.random.default_rng(20240613)


@pytest.fixture
def make_grid(rng):
    """Factory: ``make_grid(p, n=None, unit=False)`` -> Grid with a random box (or the unit-step box).

    ``unit=True`` gives ``lo = 0`` and ``hi = p`` (step 1), so physical coordinates are grid units
    exactly and fractional parts can be constructed without rounding.
    """

    def _make(p, n: int | None = None, unit: bool = False) -> Grid:
        parts = np.atleast_1d(np.asarray(p, dtype=np.int64))
        if n is None:
            n = parts.size
        if parts.size == 1:
            parts = np.repeat(parts, n)
        if unit:
            return Grid(np.zeros(n), parts.astype(float), parts)
        lo = rng.uniform(-3.0, 1.0, n)
        hi = lo + rng.uniform(0.5, 4.0, n)
        return Grid(lo, hi, parts)

    return _make


@pytest.fixture
def inside_points(rng):
    """Factory: ``inside_points(grid, m)`` -> m uniform random points strictly inside the domain."""

    def _pts(grid: Grid, m: int) -> np.ndarray:
        return grid.lo + rng.uniform(0.0, 1.0, (m, grid.n)) * (grid.hi - grid.lo)

    return _pts



@pytest.fixture(scope="session")
def sim_cache(tmp_path_factory) -> Path:
    """Simulator builds shared by the RTL tests of one run ($PWAS_HDL_SIM_CACHE to keep them across runs);
    Verilator's run-time library is compiled once per cache."""
    env = os.environ.get("PWAS_HDL_SIM_CACHE")
    path = Path(env) if env else tmp_path_factory.getbasetemp() / "pwas-sim-cache"
    path.mkdir(parents=True, exist_ok=True)
    return path
