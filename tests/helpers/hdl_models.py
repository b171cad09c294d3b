"""Hand-built bit-true models and input codes for the HDL tests (no fitting)."""

from __future__ import annotations

import numpy as np

from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fixedpoint.bittrue import FixedPointModel

__all__ = ["make_model", "codes"]


def make_model(parts, seed=0, nz=1, **kw):
    rng = np.random.default_rng(seed)
    n = len(parts)
    lo = rng.uniform(-20, 5, n)
    hi = lo + rng.uniform(0.5, 40, n)
    g = Grid(lo, hi, parts)
    w = rng.normal(0, 10.0 ** rng.uniform(-1, 2), (g.n_vertices, nz))
    return FixedPointModel(g, w, **kw)


def codes(model, m, seed=0):
    """Input codes: random in range, inside the domain, vertices, tied fractions, the clamp edges."""
    rng = np.random.default_rng(seed)
    n, b = model.n, model.input_bits
    qmin, qmax = -(1 << (b - 1)), (1 << (b - 1)) - 1
    lo = np.array(model.lo_codes)
    fb = np.array(model.frac_bits)
    parts = model.grid.partitions
    span = parts << fb
    k = m // 5
    blocks = [
        rng.integers(qmin, qmax + 1, (k, n)),
        lo + (rng.random((k, n)) * (span + 1)).astype(np.int64),
        lo + rng.integers(0, parts + 1, (k, n)) * (1 << fb),  # vertices
    ]
    # tied aligned fractions in a random cell
    big_f = model.F
    v = rng.integers(0, 1 << big_f, (k, 1)) if big_f else np.zeros((k, 1), dtype=np.int64)
    v = np.where(rng.random((k, 1)) < 0.3, rng.choice([0, 1 << max(big_f - 1, 0)], (k, 1)), v)
    frac = v >> (big_f - fb)
    cell = rng.integers(0, parts, (k, n))
    tie = lo + cell * (1 << fb) + np.where(rng.random((k, n)) < 0.7, frac, rng.integers(0, 1 << fb, (k, n)))
    blocks.append(tie)
    edges = lo + rng.choice([-1, 0, 1], (k, n)) + np.where(rng.random((k, n)) < 0.5, 0, span)
    blocks.append(edges)
    q = np.concatenate(blocks)[:m]
    q = np.concatenate([q, rng.integers(qmin, qmax + 1, (m - len(q), n))])
    return np.clip(q, qmin, qmax)
