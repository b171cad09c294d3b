"""The one-sample path of the bit-true models (FixedPointModel.evaluate_one, WarpedFixedPointModel.evaluate_one,
Python integers, the step of the recurrence) equals evaluate bit for bit.

The one-sample step itself is checked against evaluate on random codes (hypothesis): the whole
code range (out of the domain), codes on cell faces (ties of the fractions), saturating outputs,
both roundings and input scales. (The tie rule cannot change an output: the vertex it decides gets
mu = 0. The ties are here for the edge cases around them, not to tell tie rules apart; the trace
tests of test_bittrue.py check the rule.) No test here measures time
(benchmarks/recurrence_speed.py does).
"""

from __future__ import annotations

import warnings

import numpy as np
from hypothesis import given, settings, strategies as st

from pwas_hdl.errors import InputError
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fixedpoint.bittrue import FixedPointModel
from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel


def _codes(fxm, rng, m: int) -> np.ndarray:
    """Random codes: the whole B_in range, cell faces plus one offset shared by the row (ties of the
    fractions), and the domain's lower edge +- 2."""
    n = fxm.n
    lo = np.array([f.format.min_code for f in fxm.inputs])
    hi = np.array([f.format.max_code for f in fxm.inputs])
    if isinstance(fxm, WarpedFixedPointModel):
        faces = [np.array(w.code_breaks) for w in fxm.warps]
    else:
        faces = [f.lo_code + (np.arange(p + 1) * f.input_span) // p for f, p in zip(fxm.inputs, fxm.grid.partitions)]
    q = rng.integers(lo, hi + 1, size=(m, n))
    on_face = np.stack([fc[rng.integers(0, len(fc), m)] for fc in faces], axis=1)
    on_face += rng.integers(0, 2, size=(m, 1)) * rng.integers(0, 4, size=(m, 1))
    pick = rng.random((m, n))
    q = np.where(pick < 0.5, on_face, q)
    q = np.where(pick > 0.9, np.array(fxm.lo_codes) + rng.integers(-2, 3, size=(m, n)), q)
    return np.clip(q, lo, hi)


def _check_steps(fxm, q: np.ndarray) -> None:
    out, oor = fxm.evaluate(q)
    for i, row in enumerate(q.tolist()):
        o, f = fxm.evaluate_one(row)
        assert o == tuple(int(v) for v in out[i]) and f == bool(oor[i]), (row, o, out[i], f, oor[i])
        assert all(type(v) is int for v in o) and type(f) is bool


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 4), nz=st.integers(1, 3),
       layout=st.sampled_from(["banked", "replicated", "corner"]), rounding=st.sampled_from(["half_up", "truncate"]),
       scale=st.sampled_from(["pow2", "exact"]), bits=st.integers(3, 14), narrow=st.booleans())
def test_evaluate_one_is_evaluate(seed, n, nz, layout, rounding, scale, bits, narrow):
    rng = np.random.default_rng(seed)
    grid = Grid(-rng.random(n), 0.5 + rng.random(n), rng.integers(1, 6, n))
    w = rng.standard_normal((grid.n_vertices, nz)) * 10.0 ** rng.uniform(-2, 2)
    opts = dict(input_bits=bits, layout=layout, rounding=rounding, input_scale=scale)
    if narrow:  # saturated weights and outputs
        opts.update(weight_bits=4, overflow="saturate", output_bits=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            fxm = FixedPointModel(grid, w, **opts)
        except InputError:
            return  # a refused combination (e.g. too few input bits for p)
    _check_steps(fxm, _codes(fxm, rng, 200))


def _pow2_grid(rng, n):
    bps, parts = [], []
    for _ in range(n):
        e = rng.integers(0, 3, rng.integers(1, 5))
        lo = -rng.random()
        bps.append(lo + np.concatenate([[0.0], np.cumsum(2.0 ** e)]) * (0.1 + rng.random()))
        parts.append(len(e))
    return Grid([b[0] for b in bps], [b[-1] for b in bps], parts, breakpoints=bps)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 3), nz=st.integers(1, 2), bits=st.integers(6, 14),
       narrow=st.booleans())
def test_warped_evaluate_one_is_evaluate(seed, n, nz, bits, narrow):
    rng = np.random.default_rng(seed)
    grid = _pow2_grid(rng, n)
    w = rng.standard_normal((grid.n_vertices, nz))
    opts = dict(output_bits=3) if narrow else {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            fxm = WarpedFixedPointModel(grid, w, input_bits=bits, **opts)
        except InputError:
            return
    lo, hi = fxm.code_range
    q = _codes(fxm, rng, 200)
    q[:20] = rng.integers(lo, hi + 1, size=(20, n))
    _check_steps(fxm, q)
    for wp in fxm.warps:  # the warp alone, every code of the range
        every = np.arange(lo, hi + 1)
        assert wp.apply(every).tolist() == [wp.apply_one(int(v)) for v in every]
