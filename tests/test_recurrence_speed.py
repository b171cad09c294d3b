"""The fast recurrence (RecurrentFixedPointModel.run on FixedPointModel.evaluate_one, Python integers)
equals the straightforward one (a loop of evaluate on one-row arrays, RecurrentFixedPointModel._run_reference)
bit for bit: out, out_of_range, fed_back and regressor, for plain and warped cores, Mz = 1 and 2,
nz = 1 and 2, every memory layout, narrow formats (out of the domain, saturated outputs and fed-back
codes) and trajectories of every length down to the lag memory.

The one-sample step itself is checked against evaluate on random codes (hypothesis): the whole
code range (out of the domain), codes on cell faces (ties of the fractions), saturating outputs,
both roundings and input scales. (The tie rule cannot change an output: the vertex it decides gets
mu = 0. The ties are here for the edge cases around them, not to tell tie rules apart; the trace
tests of test_bittrue.py check the rule.) No test here measures time
(benchmarks/recurrence_speed.py does).
"""

from __future__ import annotations

import warnings
from functools import lru_cache

import numpy as np
import pytest
from hypothesis import event, given, settings, strategies as st

from pwas_hdl.design.generate import fixed_point_model
from pwas_hdl.errors import InputError
from pwas_hdl.fit.geometry import Grid
from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor
from pwas_hdl.fixedpoint.bittrue import FixedPointModel
from pwas_hdl.fixedpoint.recurrence import FeedbackRequant, RecurrentFixedPointModel
from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel

KEYS = ("out", "out_of_range", "fed_back", "regressor")


def _same(a: dict, b: dict) -> None:
    for k in KEYS:
        assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, k
        assert np.array_equal(a[k], b[k]), (k, np.argwhere(a[k] != b[k])[:3])


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
            event("refused")
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
            event("refused")
            return
    lo, hi = fxm.code_range
    q = _codes(fxm, rng, 200)
    q[:20] = rng.integers(lo, hi + 1, size=(20, n))
    _check_steps(fxm, q)
    for wp in fxm.warps:  # the warp alone, every code of the range
        every = np.arange(lo, hi + 1)
        assert wp.apply(every).tolist() == [wp.apply_one(int(v)) for v in every]


@settings(max_examples=200, deadline=None)
@given(out_bits=st.integers(2, 40), in_bits=st.integers(2, 30), mul=st.integers(1, 2**40), shift=st.integers(1, 60),
       add=st.integers(-2**62, 2**62), data=st.data())
def test_feedback_apply_one_is_apply(out_bits, in_bits, mul, shift, add, data):
    """Both arithmetic paths of apply (int64 and Python integers above 62 bits) against apply_one."""
    fb = FeedbackRequant(mul, add, shift, -(1 << (in_bits - 1)), (1 << (in_bits - 1)) - 1, out_bits, in_bits, 0.0)
    o = data.draw(st.lists(st.integers(-(1 << (out_bits - 1)), (1 << (out_bits - 1)) - 1), min_size=1, max_size=20))
    assert fb.apply(np.array(o)).tolist() == [fb.apply_one(v) for v in o]


def _plant(rng, T, nz):
    u = rng.uniform(-1, 1, T)
    y = np.sin(np.arange(T) * 0.05 + rng.random()) + 0.2 * rng.standard_normal(T)
    z = np.zeros((T, nz))
    for t in range(1, T):
        z[t, 0] = 0.7 * z[t - 1, 0] + 0.3 * np.tanh(2 * y[t]) - 0.1 * u[t] ** 2
        if nz > 1:
            z[t, 1] = 0.5 * z[t - 1, 1] + 0.2 * z[t - 1, 0] + 0.1 * u[t]
    return u, y, z


@lru_cache(maxsize=None)
def _sensor(kind: str, mz: int, nz: int) -> PWASVirtualSensor:
    u, y, z = _plant(np.random.default_rng(mz * 10 + nz), 600, nz)
    extra = {"breakpoints": "quantile-pow2"} if kind == "warped" else {}
    s = PWASVirtualSensor(mu=1, my=1, mz=mz, partitions=3, sigma=1e-3, input_names=["u"], output_names=["y"],
                          target_names=[f"z{i}" for i in range(nz)], **extra)
    return s.fit(u, y, z if nz > 1 else z[:, 0])


FORMATS = [({}, "banked"), ({"input_bits": 7}, "corner"), ({"input_bits": 9, "output_bits": 4}, "replicated"),
           ({"input_bits": 12, "output_frac": 2, "rounding": "truncate"}, "banked")]


@pytest.mark.parametrize("kind", ["plain", "warped"])
@pytest.mark.parametrize("mz, nz", [(1, 1), (2, 1), (1, 2), (2, 2)])
@pytest.mark.parametrize("fmt", range(len(FORMATS)))
def test_run_is_the_reference_loop(kind, mz, nz, fmt):
    s = _sensor(kind, mz, nz)
    opts, memory = FORMATS[fmt]
    if kind == "warped":
        memory = "banked"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            fxm = fixed_point_model(s, memory=memory, **opts)
        except InputError:
            pytest.skip("format refused for this model")
    assert isinstance(fxm, WarpedFixedPointModel if kind == "warped" else FixedPointModel)
    rm = RecurrentFixedPointModel(fxm, s.lags_, s.initial_values_)  # not recurrent_model: narrow feedbacks allowed too
    m = max(s.lags_.memory, 1)
    rng = np.random.default_rng([mz, nz, fmt])
    oor = 0
    for T in (m, m + 1, 9, 150):
        u, y, _ = _plant(rng, T, nz)
        codes = rm.quantize_signals(1.4 * u[:, None], 1.4 * y[:, None])  # beyond the training domain: clamped, flagged
        got, ref = rm.run(codes), rm._run_reference(codes)
        _same(got, ref)
        assert got["out"].shape == (T - m + 1, nz)
        oor += int(got["out_of_range"].sum())
    assert oor > 0


def test_run_checks_the_codes_as_the_reference_does():
    s = _sensor("plain", 1, 1)
    rm = RecurrentFixedPointModel(fixed_point_model(s, input_bits=8), s.lags_, s.initial_values_)
    codes = rm.quantize_signals(np.zeros((20, 1)), np.zeros((20, 1)))
    codes[7, 1] = 1000  # outside the 8-bit range
    for fn in (rm.run, rm._run_reference):
        with pytest.raises(InputError, match="outside the 8-bit range"):
            fn(codes)
        with pytest.raises(InputError, match="codes must have shape"):
            fn(codes[:, :1])
    short = codes[:1]  # shorter than the lag memory: both refuse or both return nothing alike
    try:
        ref = rm._run_reference(short)
    except InputError as exc:
        with pytest.raises(InputError, match=str(exc)[:30]):
            rm.run(short)
    else:
        _same(rm.run(short), ref)


def test_a_model_without_the_one_sample_path_runs_the_array_loop():
    """A core that only has evaluate (e.g. a user's subclass or wrapper) still runs, on the reference loop."""
    s = _sensor("plain", 2, 2)
    fxm = fixed_point_model(s)

    class Wrapped:
        def __init__(self, inner):
            self._inner = inner

        def __getattr__(self, name):
            if name in ("evaluate_one",):
                raise AttributeError(name)
            return getattr(self._inner, name)

    rm = RecurrentFixedPointModel(fxm, s.lags_, s.initial_values_)
    rw = RecurrentFixedPointModel(Wrapped(fxm), s.lags_, s.initial_values_)
    u, y, _ = _plant(np.random.default_rng(3), 60, 2)
    codes = rm.quantize_signals(u[:, None], y[:, None])
    _same(rw.run(codes), rm.run(codes))


@pytest.mark.parametrize("kind, mz, nz", [("plain", 1, 1), ("plain", 2, 2), ("warped", 2, 1), ("warped", 1, 2)])
@pytest.mark.parametrize("lockstep", [True, False, None])
def test_run_many_is_run_of_each(kind, mz, nz, lockstep):
    """Trajectories of different lengths (and equal ones, and one of a single estimate) in lockstep or
    one by one: each result is the reference loop's of that trajectory."""
    s = _sensor(kind, mz, nz)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fxm = fixed_point_model(s, input_bits=8)
    rm = RecurrentFixedPointModel(fxm, s.lags_, s.initial_values_)
    m = max(s.lags_.memory, 1)
    rng = np.random.default_rng([mz, nz, 7])
    codes = []
    for T in (40, m, 3 + m, 40, 17, m + 1):
        u, y, _ = _plant(rng, T, nz)
        codes.append(rm.quantize_signals(1.3 * u[:, None], 1.3 * y[:, None]))
    got = rm.run_many(codes, lockstep=lockstep)
    assert len(got) == len(codes)
    for g, c in zip(got, codes):
        _same(g, rm._run_reference(c))
    assert rm.run_many([], lockstep=lockstep) == []


def test_run_many_checks_the_codes():
    s = _sensor("plain", 1, 1)
    rm = RecurrentFixedPointModel(fixed_point_model(s, input_bits=8), s.lags_, s.initial_values_)
    good = rm.quantize_signals(np.zeros((20, 1)), np.zeros((20, 1)))
    bad = good.copy()
    bad[5, 0] = -1000
    for lockstep in (True, False):
        with pytest.raises(InputError, match="outside the 8-bit range"):
            rm.run_many([good, bad], lockstep=lockstep)


def test_an_additive_model_has_no_one_sample_path():
    """The plain model's evaluate_one read one grid's strides: an additive model (its grid has parts)
    inherited it and raised AttributeError; it has none, and the recurrence falls back to evaluate."""
    from pwas_hdl.fit.additive import AdditiveGrid
    from pwas_hdl.fixedpoint.additive import AdditiveFixedPointModel

    grid = AdditiveGrid([0.0] * 3, [1.0] * 3, [3, 3, 3], [(0,), (1, 2), (0, 2)])
    w = np.linspace(-1.0, 1.0, grid.n_vertices)[:, None]
    fxm = AdditiveFixedPointModel(grid, w)
    assert fxm.evaluate_one is None
    q = fxm.quantize_inputs(np.array([[0.2, 0.5, 0.9]]))
    out, oor = fxm.evaluate(q)
    assert out.shape == (1, 1) and not oor[0]
