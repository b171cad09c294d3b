"""Independent integer oracle of the PWAS core for hand-built :class:`CoreParams` (tests only).

It evaluates the datapath in the hardware's own form (ranks by pairwise comparison, vertex
``k`` = ``c + (rank < k)``, no sorting), so it cross-checks the bit-true model
(:mod:`pwas_hdl.fixedpoint.bittrue`, the specification) on the formats both accept, and serves as the
reference for formats the model never builds (``F_j = 0``, domains leaving the code range,
``sh <= 0``). Python integers (object arrays) in the accumulation: no overflow.
"""

from __future__ import annotations

import numpy as np

from pwas_hdl.hdl import CoreParams


def reference_eval(p: CoreParams, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Integer evaluation of the core: ``(codes (m, nz) int64, out_of_range (m,) bool)``."""
    q = np.atleast_2d(np.asarray(q, dtype=np.int64))
    m, n = q.shape
    assert n == p.n
    parts = np.array(p.partitions, dtype=np.int64)
    fb = np.array(p.frac_bits, dtype=np.int64)
    big_f = p.frac
    t = q - np.array(p.lo_code, dtype=np.int64)
    tmax = parts << fb
    oor = np.any((t < 0) | (t > tmax), axis=1)
    t = np.clip(t, 0, tmax)
    c = np.minimum(t >> fb, parts - 1)
    d = (t - (c << fb)) << (big_f - fb)
    rank = np.zeros_like(d)
    for j in range(n):
        for i in range(n):
            if i != j:
                rank[:, j] += (d[:, i] > d[:, j]) | ((d[:, i] == d[:, j]) & (i < j))
    strides = np.array(p.strides, dtype=np.int64)
    acc = np.zeros((m, p.nz), dtype=object)
    dsorted = np.zeros((m, n + 2), dtype=np.int64)
    dsorted[:, 0] = 1 << big_f
    for k in range(1, n + 1):
        dsorted[:, k] = np.sum(np.where(rank == k - 1, d, 0), axis=1)
    for k in range(n + 1):
        mu = dsorted[:, k] - dsorted[:, k + 1]
        v = c + (rank < k)
        idx = v @ strides
        acc = acc + mu[:, None].astype(object) * p.weights[idx].astype(object)
    sh = p.shift
    if sh > 0:
        rnd = (1 << (sh - 1)) if p.rounding == "half_up" else 0
        r = (acc + rnd) // (1 << sh)  # floor division == arithmetic shift
    else:
        r = acc * (1 << (-sh))
    lo, hi = -(1 << (p.out_width - 1)), (1 << (p.out_width - 1)) - 1
    r = np.clip(r, lo, hi).astype(np.int64)
    return r, oor
