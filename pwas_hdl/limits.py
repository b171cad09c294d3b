"""The size limits of pwas-hdl, in one place, and the checks that refuse a request before it allocates.

Every limit is a named constant; a request above one raises
:class:`~pwas_hdl.errors.ResourceLimit` (an ``InputError``: on the command line one ``error:``
line and exit status 2) whose message names the requested size, the limit and what to change.
The checks compute sizes with Python integers, so they never overflow, and run before any array
of that size exists.

=========================  =============  ===============================================
constant                   value          what it bounds
=========================  =============  ===============================================
``MAX_VERTICES``           1 048 576      weights per target ``N = prod(p_j + 1)``
``MAX_WEIGHTS``            4 194 304      weights over all targets ``N x nz`` (a model
                                          file of about 100 MB)
``MAX_REGRESSORS``         20             regressor dimension ``n = nu*Mu + ny*My``
``MAX_SAMPLES``            1 000 000      data rows of a CSV file, ``make-data --samples``
``MAX_SIGMA_CANDIDATES``   1 000          cross-validation candidates (``--sigma-grid``)
``MAX_SWEEP_POINTS``       10 000         format combinations of one ``explore``
``MAX_CSV_FIELD``          131 072        characters in one CSV cell (128 KiB)
``MAX_CSV_BYTES``          1 GiB          size of a CSV file read
``MAX_JSON_BYTES``         256 MiB        size of a JSON file read (model, breakpoints,
                                          manifest, results)
``MAX_NAME_LENGTH``        200            Verilog module name (``--name``), so that the
                                          file names made from it fit a 255-byte name
``MAX_BENCH_COUNT``        1 000          a bench's count options (``--runs``, ``--seeds``;
                                          :func:`pwas_hdl.bench_results.check_count`)
``MAX_NOISE``              1 000          ``make-data --noise`` (a standard deviation)
``MAX_VALUE``              1e150          magnitude of a fitted target / map value and of
                                          a reference column (``explore``, ``simulate``)
=========================  =============  ===============================================
"""

from __future__ import annotations

import math
from typing import Iterable

from pwas_hdl.errors import InputError, ResourceLimit, option_text

__all__ = [
    "MAX_VERTICES",
    "MAX_WEIGHTS",
    "MAX_JSON_BYTES",
    "MAX_REGRESSORS",
    "MAX_SAMPLES",
    "MAX_SIGMA_CANDIDATES",
    "MAX_SWEEP_POINTS",
    "MAX_CSV_FIELD",
    "MAX_CSV_BYTES",
    "MAX_NAME_LENGTH",
    "MAX_LATENCY_CYCLES",
    "MAX_PORT_BITS",
    "MAX_BENCH_COUNT",
    "MAX_MEMORY_WORDS",
    "MAX_NOISE",
    "check_limit",
    "check_seed",
    "check_vertices",
    "check_weights",
]

#: Largest number of vertices (weights per target) ``N = prod(p_j + 1)`` of a partition.
MAX_VERTICES = 2**20
#: Largest number of weights over all targets, ``N x nz``: a model file of about 24 bytes a weight
#: (100 MB), written with about 140 bytes a weight at its peak (the JSON text of every float).
MAX_WEIGHTS = 2**22
#: Largest JSON file read (model, breakpoints, manifest, results files), in bytes: a model at
#: :data:`MAX_WEIGHTS` is about 100 MB.
MAX_JSON_BYTES = 2**28
#: Largest regressor dimension ``n``; with ``p_j >= 1`` it also bounds ``N >= 2**n``.
MAX_REGRESSORS = 20
#: Largest number of samples: data rows of a CSV file, ``make-data --samples`` (+ ``--test-samples``).
MAX_SAMPLES = 1_000_000
#: Largest number of sigma candidates of the cross-validation.
MAX_SIGMA_CANDIDATES = 1_000
#: Largest number of format combinations one ``explore`` evaluates.
MAX_SWEEP_POINTS = 10_000
#: Largest CSV cell, in characters (128 KiB; also Python's ``csv.field_size_limit`` default).
MAX_CSV_FIELD = 128 * 1024
#: Largest CSV file read, in bytes.
MAX_CSV_BYTES = 2**30
#: Longest Verilog module name.
MAX_NAME_LENGTH = 200
#: Largest value of a bench's count option (``--runs``, ``--seeds``, ...): the papers average 5-10 runs,
#: no real use comes near it; a typo such as ``--runs 1000000000`` is refused instead of running for ever.
MAX_BENCH_COUNT = 1000
#: Largest ``latency_cycles`` a manifest may state (the benches wait that long for an output; the
#: deepest generated design has a few dozen cycles).
MAX_LATENCY_CYCLES = 2**16
#: Widest port a manifest may state, in bits (a payload packs at most 20 regressors or a few outputs).
MAX_PORT_BITS = 2**16
#: Most words a weight-memory layout may hold over all its banks (the corner layout's ``2**n`` banks
#: of ``2**sum(cell bits)`` words grow far faster than ``N``: n = 10, p = 3 would be 2**30 words);
#: 4 Mi words is about 12 times what the largest ECP5 (LFE5U-85F, 208 x 18 kbit of block RAM) holds at 11 bits.
MAX_MEMORY_WORDS = 2**22
#: Largest ``make-data --noise`` (standard deviation of the added Gaussian noise). The signals are of
#: order 1-10 (seed 004's are normalised to unit std), so 1000 already drowns them; far larger values
#: overflow to inf / NaN data (``--noise 1e308``) that every later command refuses.
MAX_NOISE = 1000.0
#: Largest magnitude of a value a fit approximates or an error is measured against (``fit``'s
#: targets, ``fit-map``'s values, the reference column of ``explore``'s and ``simulate``'s RMSEE):
#: the squared errors, summed over up to :data:`MAX_SAMPLES` samples, stay below the float limit
#: (``(2 * 1e150)**2 * 1e6 = 4e306``); above it the fit's RMSE and the summaries overflowed to inf.
MAX_VALUE = 1e150


def check_limit(what: str, value: int, limit: int, hint: str) -> int:
    """Refuse ``value > limit``.

    Parameters
    ----------
    what : str
        What is counted, as the user named it (e.g. ``"--samples"``, ``"sigma candidates"``).
    value, limit : int
    hint : str
        How to stay within the limit (one clause).

    Returns
    -------
    int
        ``value``.

    Raises
    ------
    ResourceLimit
        ``value > limit``.
    """
    if value > limit:
        raise ResourceLimit(f"{what} = {value} exceeds the limit of {limit}; {hint}")
    return value


def check_seed(seed: int, param: str = "seed") -> int:
    """Refuse a seed that numpy's random generators do not take (a negative one, a non-integer).

    ``numpy.random.default_rng(-1)`` raises ``ValueError: expected non-negative integer``, which
    names neither the option nor the fix.

    Parameters
    ----------
    seed : int
    param : str
        The API parameter (and, as ``--seed``, the option) that gave it.

    Returns
    -------
    int
        ``seed``.

    Raises
    ------
    InputError
        ``seed`` is not an integer ``>= 0``.
    """
    import numbers

    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise InputError(f"{option_text(param)} must be an integer >= 0, got {seed!r}")
    return int(seed)


def check_values(what: str, values: np.ndarray, hint: str) -> None:
    """Refuse values of magnitude above :data:`MAX_VALUE` (their squared errors would overflow).

    Parameters
    ----------
    what : str
        What the values are, as the user named them (e.g. ``"target column 'z'"``).
    values : array_like
        Finite values.
    hint : str
        How to stay within the limit (one clause).

    Raises
    ------
    ResourceLimit
        Some ``|value| > MAX_VALUE``.
    """
    import numpy as np  # here: the limits are imported where numpy is not needed

    top = float(np.max(np.abs(values))) if np.size(values) else 0.0
    if top > MAX_VALUE:
        raise ResourceLimit(f"{what} has a value of magnitude {top:.6g}, more than the limit of {MAX_VALUE:g} "
                            f"(its squared errors would overflow); {hint}")


def check_vertices(partitions: Iterable[int]) -> int:
    """Number of vertices ``N = prod(p_j + 1)`` of a partition, refused above :data:`MAX_VERTICES`.

    Parameters
    ----------
    partitions : iterable of int
        Intervals per dimension (already checked to be integers >= 1).

    Returns
    -------
    int
        ``N`` (a Python integer: no int64 overflow, whatever the sizes).

    Raises
    ------
    ResourceLimit
        More dimensions than :data:`MAX_REGRESSORS` or ``N > MAX_VERTICES``.
    """
    parts = [int(p) for p in partitions]
    check_limit("the regressor dimension n", len(parts), MAX_REGRESSORS, "use fewer lags or signals")
    n_vertices = math.prod(p + 1 for p in parts)
    if n_vertices > MAX_VERTICES:
        raise ResourceLimit(
            f"the partition {_short(parts)} has N = prod(p_j + 1) = {n_vertices} vertices, more than the limit of "
            f"{MAX_VERTICES}; use fewer intervals (-p) or fewer lags"
        )
    return n_vertices


def _short(parts: list[int]) -> str:
    if len(set(parts)) == 1:
        return f"p = {parts[0]} in {len(parts)} dimension(s)"
    text = ", ".join(str(p) for p in parts)
    return f"p = [{text if len(text) < 80 else text[:77] + '...'}]"


def check_weights(n_vertices: int, n_targets: int) -> int:
    """Weights over all targets ``N x nz``, refused above :data:`MAX_WEIGHTS`.

    Parameters
    ----------
    n_vertices : int
        Weights per target ``N``.
    n_targets : int
        Targets ``nz``.

    Returns
    -------
    int
        ``N x nz``.

    Raises
    ------
    ResourceLimit
        ``N x nz > MAX_WEIGHTS``.
    """
    return check_limit(f"the weights N x targets ({int(n_vertices)} x {int(n_targets)})", int(n_vertices) * int(n_targets),
                       MAX_WEIGHTS, "fit fewer targets in one model (one model per target) or use a coarser partition (-p)")
