"""Stimulus for the RTL tests: input codes that reach every corner of the PWAS datapath.

Host side (numpy), not imported by the cocotb testbench. Codes are what the design's input
payload carries: for the core one code per regressor dimension, for the sensor top one code per
signal (its lag bank builds the regressors, so the same kinds of points are made as sequences).

Kinds of points (each a block of rows, concatenated in this order, then truncated to ``m``):

``random``      uniform over the domain (codes ``lo_code .. hi_code``);
``vertices``    grid vertices (every fraction 0; the top edge ``hi_code`` included);
``ties``        points on faces of the Kuhn simplices: equal fractional parts in several
                dimensions (tie rule: lower index first), fraction 0 and 1/2 included;
``corners``     the domain corners ``lo``/``hi`` in every combination (2**n, or random ones for n > 6)
                and their neighbours one code inside / outside;
``outside``     out-of-domain values (flag set, value clamped): just outside an edge, far
                outside, and the extreme codes of the input range;
``fullrange``   uniform over the whole signed code range (mostly outside when the domain is small).
"""

from __future__ import annotations

import itertools

import numpy as np

__all__ = ["core_codes", "sensor_codes", "observer_codes", "KINDS", "OBSERVER_KINDS"]

KINDS = ("random", "vertices", "ties", "corners", "outside", "fullrange")


def _dims(model):
    lo = np.array(model.lo_codes, dtype=np.int64)
    fb = np.array(model.frac_bits, dtype=np.int64)
    parts = np.asarray(model.grid.partitions, dtype=np.int64)
    span = parts << fb
    b = int(model.input_bits)
    return lo, fb, parts, span, -(1 << (b - 1)), (1 << (b - 1)) - 1


def core_codes(model, m: int, seed: int = 0) -> np.ndarray:
    """``m`` rows of regressor codes (``model``: :class:`pwas_hdl.fixedpoint.bittrue.FixedPointModel`), shuffled.

    The domain corners come first (all ``2**n`` of them up to ``n = 6``, at most ``m // 3``), the
    other kinds share the rest equally.
    """
    rng = np.random.default_rng(seed)
    n = model.n
    lo, fb, parts, span, qmin, qmax = _dims(model)
    # corners (exact), one code inside, and some one code outside
    corners = np.array(list(itertools.product([0, 1], repeat=n)), dtype=np.int64) if n <= 6 else rng.integers(0, 2, (64, n))
    c = lo + corners * span
    c_in = c + (1 - 2 * corners) * (rng.random(c.shape) < 0.5)
    c_out = c + (2 * corners - 1) * (rng.random(c.shape) < 0.5)
    cap = max(1, m // 3)
    corner_rows = np.concatenate([c, c_in, c_out])[:cap]
    k = max(1, -(-(m - len(corner_rows)) // 5))
    blocks = [corner_rows]
    # random inside the domain
    blocks.append(lo + (rng.random((k, n)) * (span + 1)).astype(np.int64))
    # vertices
    blocks.append(lo + rng.integers(0, parts + 1, (k, n)) * (1 << fb))
    # ties: a common aligned fraction f (units 2**-F) in a random subset of the dimensions
    big_f = int(model.F)
    rows = []
    for _ in range(k):
        cell = rng.integers(0, parts)
        f = int(rng.choice([0, 1 << max(big_f - 1, 0), int(rng.integers(0, (1 << big_f) + 1))]))
        own = np.array([f >> (big_f - int(fj)) for fj in fb], dtype=np.int64)
        rnd = rng.integers(0, (1 << fb) + 1)
        rows.append(lo + cell * (1 << fb) + np.where(rng.random(n) < 0.7, own, rnd))
    blocks.append(np.array(rows, dtype=np.int64).reshape(-1, n))
    # outside: one dimension pushed out (by one code, far, or to the end of the code range)
    rows = []
    for i in range(k):
        q = lo + (rng.random(n) * (span + 1)).astype(np.int64)
        j = int(rng.integers(0, n))
        d = 1 if i % 3 == 0 else int(rng.integers(1, 1 << 10))
        q[j] = lo[j] - d if rng.random() < 0.5 else lo[j] + span[j] + d
        if i % 7 == 3:
            q[j] = qmin if i % 2 else qmax
        rows.append(q)
    blocks.append(np.array(rows, dtype=np.int64))
    # the whole code range
    blocks.append(rng.integers(qmin, qmax + 1, (k, n)))
    q = np.concatenate(blocks)[:m]
    return np.clip(q[rng.permutation(len(q))], qmin, qmax)


def sensor_codes(model, signals: list[str], t_len: int, seed: int = 0) -> np.ndarray:
    """``t_len`` transfers of per-signal codes for the sensor top (columns in ``signals`` order).

    Sequences are built block-wise so that the regressors (lags of the same signals) land on
    random points, vertices (every sample on a grid code), ties (consecutive samples with equal
    fractions), the domain corners (runs of ``lo`` / ``hi``), and outside the domain.
    """
    rng = np.random.default_rng(seed)
    fmts = model.signal_input_formats()
    cols = []
    for s, name in enumerate(signals):
        f = fmts[name]
        lo, fbits, p = int(f.lo_code), int(f.frac), int(f.partitions)
        span = p << fbits
        b = int(model.input_bits)
        qmin, qmax = -(1 << (b - 1)), (1 << (b - 1)) - 1
        seq = []
        while len(seq) < t_len:
            kind = KINDS[int(rng.integers(0, len(KINDS)))] if len(seq) >= 8 * len(KINDS) else KINDS[(len(seq) // 8) % len(KINDS)]
            L = int(rng.integers(4, 12))
            if kind == "random":
                blk = lo + rng.integers(0, span + 1, L)
            elif kind == "vertices":
                blk = lo + rng.integers(0, p + 1, L) * (1 << fbits)
            elif kind == "ties":
                fr = int(rng.choice([0, 1 << max(fbits - 1, 0), int(rng.integers(0, (1 << fbits) + 1))]))
                blk = lo + rng.integers(0, p, L) * (1 << fbits) + fr
            elif kind == "corners":
                blk = np.where(rng.random(L) < 0.5, lo, lo + span) + rng.choice([0, 0, 0, -1, 1], L)
            elif kind == "outside":
                blk = np.where(rng.random(L) < 0.5, lo - rng.integers(1, 64, L), lo + span + rng.integers(1, 64, L))
                blk[rng.random(L) < 0.2] = qmax
                blk[rng.random(L) < 0.2] = qmin
            else:
                blk = rng.integers(qmin, qmax + 1, L)
            seq.extend(int(v) for v in blk)
        cols.append(np.clip(np.array(seq[:t_len], dtype=np.int64), qmin, qmax))
    return np.stack(cols, axis=1)


def design_codes(design, m: int, seed: int = 0) -> np.ndarray:
    """``m`` input transfers for a loaded design (:class:`pwas_hdl.verify.simulation.Design`): the
    core's regressor codes (:func:`core_codes`) or, for a sensor top, per-signal codes of its input
    fields in port order (:func:`sensor_codes`)."""
    if design.kind == "core":
        return core_codes(design.model, m, seed=seed)
    return sensor_codes(design.model, [f.get("signal", f["name"]) for f in design.in_fields], m, seed=seed)


#: Blocks of :func:`observer_codes`.
OBSERVER_KINDS = ("data", "steps", "fullscale", "saturating", "silence")


def observer_codes(bank, t_len: int, seed: int = 0, data: np.ndarray | None = None) -> np.ndarray:
    """``t_len`` transfers of (u0 .., y0) codes for the observer-bank top (``bank``: FixedPointObserverBank).

    Blocks (lengths 8 .. 40 samples, so the windows and the observers see each kind long enough):
    ``data`` (rows of the given codes, e.g. a quantised test trajectory; without it a random walk
    of about one standard deviation), ``steps`` (piecewise-constant levels), ``fullscale`` (uniform
    over the whole code range: out-of-range inputs for every feature), ``saturating`` (the largest
    codes alternating with the smallest every few samples: drives the observer states to their
    limits), ``silence`` (all zero).
    """
    rng = np.random.default_rng(seed)
    b = int(bank.input_bits)
    qmin, qmax = -(1 << (b - 1)), (1 << (b - 1)) - 1
    one = 1 << int(bank.input_frac)  # one standard deviation of the normalised signal
    k = int(bank.nu) + 1
    rows, pos = [], 0
    while sum(len(r) for r in rows) < t_len:
        kind = OBSERVER_KINDS[len(rows) % len(OBSERVER_KINDS)] if len(rows) < 2 * len(OBSERVER_KINDS) else \
            OBSERVER_KINDS[int(rng.integers(0, len(OBSERVER_KINDS)))]
        L = int(rng.integers(8, 41))
        if kind == "data":
            if data is not None and len(data):
                blk = np.asarray(data, dtype=np.int64)[np.arange(pos, pos + L) % len(data)]
                pos += L
            else:
                blk = np.cumsum(rng.normal(0, one / 4, (L, k)), axis=0) + rng.normal(0, one, (1, k))
        elif kind == "steps":
            blk = np.repeat(rng.normal(0, 2 * one, (max(1, L // 6), k)), 6, axis=0)[:L]
        elif kind == "fullscale":
            blk = rng.integers(qmin, qmax + 1, (L, k))
        elif kind == "saturating":
            per = int(rng.integers(1, 5))
            sgn = np.where((np.arange(L) // per) % 2 == 0, 1, -1)[:, None] * rng.choice([1, -1], (1, k))
            blk = np.where(sgn > 0, qmax, qmin)
        else:
            blk = np.zeros((L, k))
        rows.append(np.clip(np.round(np.asarray(blk, dtype=float)), qmin, qmax).astype(np.int64))
    return np.concatenate(rows)[:t_len]
