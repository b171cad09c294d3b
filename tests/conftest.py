"""Shared fixtures of the test suite (all deterministic: every random draw is seeded).

Markers (registered in pyproject.toml): ``rtl`` runs an HDL simulator or linter (Icarus, Verilator),
``synth`` runs Yosys / nextpnr, ``slow`` takes more than about 5 s (every ``rtl`` and ``synth``
test counts as slow: :func:`pytest_collection_modifyitems` adds the mark). The fast subset is
``bash run.sh test -m "not rtl and not synth"``; ``-m "not slow"`` leaves out the slow ones of it too.

Parallel runs: ``bash run.sh test`` runs pytest-xdist workers (``-n auto --dist loadfile``: a test
file stays on one worker, so its module-scoped fixtures are built once; ``PWAS_HDL_TEST_WORKERS=0``
for one process). Every fixture here is per worker (``tmp_path_factory`` folders are per worker;
the simulator build cache is shared but file-locked and keyed by hash), and each worker's BLAS
runs one thread, so that two workers do not oversubscribe two cores.

Hypothesis profiles: ``ci`` (loaded when ``CI=true``) draws more examples, derandomised and without
an example database (the same examples on every CI run); ``dev`` (the default) draws fewer, random
ones. ``HYPOTHESIS_PROFILE=ci`` chooses one explicitly. The CLI fuzz suite scales its per-command
budgets with the profile (tests/test_fuzz_cli.py, ``FUZZ_SCALE``).
"""

from __future__ import annotations

import os
import sys

# PYTHONDONTWRITEBYTECODE=1 (set in some containers) makes every test process recompile the package and
# re-run pytest's assertion rewriting of every test module (about 5 s CPU per xdist worker, and the same
# again in every CLI subprocess and Dask worker): the test run writes its bytecode to __pycache__ (git
# ignores it) unless PWAS_HDL_TEST_BYTECODE=0. Set before anything of the package is imported.
if sys.dont_write_bytecode and os.environ.get("PWAS_HDL_TEST_BYTECODE", "1") != "0":
    sys.dont_write_bytecode = False

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest


def _load_hypothesis_profile() -> None:
    """Register the profiles and load the chosen one (before any test module is imported)."""
    from hypothesis import settings

    #: Examples per property of the profiles (hypothesis' own default is 100).
    settings.register_profile("ci", max_examples=200, derandomize=True, database=None, deadline=None, print_blob=True)
    settings.register_profile("dev", max_examples=100, deadline=None)
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE")
                          or ("ci" if os.environ.get("CI", "").strip().lower() in ("true", "1", "yes") else "dev"))


def pytest_configure(config):
    """Load the Hypothesis profile where tests run (not in the xdist controller, which runs none: its
    import costs ~0.7 s there for nothing). In a pytest-xdist worker, limit BLAS / OpenMP to one
    thread (two workers share two cores)."""
    if os.environ.get("PYTEST_XDIST_WORKER") or not getattr(config.option, "numprocesses", None):
        _load_hypothesis_profile()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        from threadpoolctl import threadpool_limits

        config._pwas_blas_limit = threadpool_limits(1)
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):  # and the tests' subprocesses
            os.environ.setdefault(var, "1")


def pytest_collection_modifyitems(config, items):
    """Simulator and synthesis runs take seconds to minutes each: mark them ``slow`` as well."""
    for item in items:
        if item.get_closest_marker("rtl") or item.get_closest_marker("synth"):
            item.add_marker(pytest.mark.slow)


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

    from pwas_hdl.fit.geometry import Grid  # here: the xdist controller imports this file too

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
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):  # one cache for all workers of the run (builds are file-locked)
        base = base.parent
    path = Path(env) if env else base / "pwas-sim-cache"
    path.mkdir(parents=True, exist_ok=True)
    return path


@dataclass(frozen=True)
class LorenzFit:
    """A fitted Lorenz sensor of :func:`lorenz_fit` and its files.

    ``sensor`` (fitted PWASVirtualSensor), ``train`` / ``test`` (PlantData), ``root`` (folder),
    ``model`` (``root/model.json``), ``test_csv`` (``root/test.csv``: ``y``, ``z``, ``z_true``).
    """

    sensor: object
    train: object
    test: object
    root: Path
    model: Path
    test_csv: Path


#: The Table II sensor (My = 4, p = 7, N = 4096) with a fixed sigma (CV would cost seconds).
TABLE2 = dict(my=4, p=7, sigma=3.2e-4, train=6000, test=300, seed=0)
#: A tiny sensor (My = 2, p = 3, N = 16) for tests that sweep or place and route.
TINY = dict(my=2, p=3, sigma=1e-4, train=1000, test=300, seed=1)


@pytest.fixture(scope="session")
def lorenz_fit(tmp_path_factory):
    """Factory, cached per session: ``lorenz_fit(my, p, sigma, train, test, seed)`` -> :class:`LorenzFit`.

    The data are ``lorenz(train + test, seed)`` split after ``train`` samples; the sensor is fitted
    on the first part with ``gamma = 1.2`` and the given sigma (no cross-validation). Use
    ``lorenz_fit(**TABLE2)`` or ``lorenz_fit(**TINY)`` so that test files share fits.
    """
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
    from pwas_hdl.io.csv_table import write_csv
    from pwas_hdl.systems.lorenz import lorenz

    made: dict[tuple, LorenzFit] = {}

    def get(my: int, p: int, sigma: float, train: int, test: int, seed: int) -> LorenzFit:
        key = (my, p, sigma, train, test, seed)
        if key not in made:
            tr, te = lorenz(train + test, seed=seed).split(train)
            m = PWASVirtualSensor(my=my, partitions=p, gamma=1.2, sigma=sigma, output_names=["y"], target_names=["z"])
            m.fit(None, tr.y, tr.z)
            root = tmp_path_factory.mktemp(f"lorenz-my{my}-p{p}-s{seed}")
            m.save(root / "model.json")
            write_csv(root / "test.csv", te.columns())
            made[key] = LorenzFit(m, tr, te, root, root / "model.json", root / "test.csv")
        return made[key]

    return get


@pytest.fixture(scope="session")
def lorenz_table2(lorenz_fit) -> LorenzFit:
    """The Table II sensor (``TABLE2``): My = 4, p = 7, N = 4096, fitted on lorenz(6300, seed=0)[:6000]."""
    return lorenz_fit(**TABLE2)


@pytest.fixture(scope="session")
def lorenz_tiny(lorenz_fit) -> LorenzFit:
    """A tiny sensor (``TINY``): My = 2, p = 3, N = 16, fitted on lorenz(1300, seed=1)[:1000]."""
    return lorenz_fit(**TINY)
