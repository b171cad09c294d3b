"""Bit-true model: exactness of the integer datapath, the stated error bound (and that it is tight),
format defaults, overflow policies, trace/evaluate consistency."""

import itertools
import json
import warnings

import numpy as np
import pytest

from pwas_hdl.fixedpoint.bittrue import TRACE_STAGES, FixedPointModel, default_weight_frac
from pwas_hdl.fixedpoint.formats import FixedFormat, frac_for_bits, shift_round, signed_bits_needed
from pwas_hdl.fit.geometry import Grid

# (partitions, input_bits, input_fill, weight_bits, rounding, output_frac offset from Fw or None)
CASES = [
    ([1], 8, 0.9, 10, "half_up", -2),
    ([7], 12, 0.9, 16, "half_up", -2),
    ([8], 12, 1.0, 12, "truncate", -3),
    ([3, 4], 12, 0.9, 14, "half_up", -2),
    ([1, 2], 8, 0.9, 10, "truncate", -2),
    ([4, 4], 16, 0.9, 20, "half_up", -4),
    ([2, 3, 5], 12, 0.9, 12, "half_up", -1),
    ([1, 1, 1], 8, 1.0, 11, "truncate", -2),
    ([7, 7, 7, 7], 12, 0.9, 16, "half_up", -2),
    ([2, 1, 3, 2], 16, 0.75, 18, "truncate", -5),
    ([2, 2, 2, 2, 2], 12, 0.9, 13, "half_up", -2),
    ([1, 2, 1, 2, 1, 3], 10, 0.9, 15, "half_up", -3),
    ([2, 2, 2, 2, 2, 2], 8, 0.9, 10, "truncate", -2),
]


def _ids(c):
    return f"p{'x'.join(map(str, c[0]))}-in{c[1]}-f{c[2]}-w{c[3]}-{c[4]}"


def _problem(parts, seed, nz=2):
    rng = np.random.default_rng(seed)
    n = len(parts)
    lo = rng.uniform(-30, 5, n)
    hi = lo + rng.uniform(0.3, 50, n)
    g = Grid(lo, hi, parts)
    scale = 10.0 ** rng.uniform(-1, 3)
    w = rng.normal(0, scale, (g.n_vertices, nz))
    return g, w


def _model(case, seed=0, **kw):
    parts, b_in, fill, b_w, rnd, dfo = case
    g, w = _problem(parts, seed)
    fw = frac_for_bits(w, b_w, rounding=rnd)
    args = dict(input_bits=b_in, input_fill=fill, weight_bits=b_w, weight_frac=fw, output_frac=fw + dfo, rounding=rnd)
    args.update(kw)
    return FixedPointModel(g, w, **args)


def _test_codes(m, rng, n_random=4000):
    """Random codes over the whole input range plus vertices, mid-edges, tied fractions, faces, extremes."""
    n = m.n
    lo = np.array([f.lo_code for f in m.inputs])
    cc = np.array([f.cell_codes for f in m.inputs])
    parts = m.grid.partitions
    qmin = np.array([f.format.min_code for f in m.inputs])
    qmax = np.array([f.format.max_code for f in m.inputs])
    blocks = [rng.integers(qmin, qmax + 1, (n_random, n))]
    # inside the domain only
    blocks.append(rng.integers(lo, np.minimum(lo + parts * cc, qmax) + 1, (n_random, n)))
    # vertices (all, or a sample)
    nv = m.grid.n_vertices
    vidx = np.arange(nv) if nv <= 3000 else rng.integers(0, nv, 3000)
    vc = m.grid.vertex_coords(vidx)
    vq = np.minimum(lo + vc * cc, qmax)
    blocks.append(vq)
    # mid-edges and quarter points along random directions
    for num in (1, 2, 3):
        step = rng.integers(0, 2, vq.shape) * (cc * num // 4)
        blocks.append(np.minimum(vq + np.where(vc < parts, step, -step), qmax))
    # tied fractions: one random fraction shared by several dimensions of a random cell
    k = 2000
    cell = rng.integers(0, parts, (k, n))
    d = rng.integers(0, 2**30, (k, 1)) % (cc + 1)
    mask = rng.integers(0, 2, (k, n)).astype(bool)
    own = rng.integers(0, 2**30, (k, n)) % (cc + 1)
    blocks.append(np.minimum(lo + cell * cc + np.where(mask, d, own), qmax))
    # domain corners and the extreme codes
    corners = np.array(list(itertools.product(*[[l, min(l + p * c, mx), mn, mx] for l, p, c, mn, mx in zip(lo, parts, cc, qmin, qmax)])))
    if len(corners) > 3000:
        corners = corners[rng.integers(0, len(corners), 3000)]
    blocks.append(corners)
    return np.concatenate(blocks, axis=0).astype(np.int64)


@pytest.mark.parametrize("case", CASES, ids=_ids)
def test_bittrue_within_bound_and_tight(case):
    m = _model(case)
    rng = np.random.default_rng(42)
    q = _test_codes(m, rng)
    out, oor = m.evaluate(q)
    ref = m.reference(q)
    err = np.abs(m.to_physical_output(out) - ref)
    tol = 1e-9 * (1.0 + np.abs(m.weights).max())
    assert err.max() <= m.error_bound + tol, (err.max(), m.error_bound)
    # tight: the worst observed error is >= 0.8 of the bound (>= 0.9 seen over 8 seeds per case)
    assert err.max() >= 0.8 * m.error_bound, (err.max(), m.error_bound)
    # out_of_range flag = some code outside [lo_code, hi_code]
    lo = np.array([f.lo_code for f in m.inputs])
    hi = np.array([f.hi_code for f in m.inputs])
    assert np.array_equal(oor, np.any((q < lo) | (q > hi), axis=1))
    qmin = np.array([f.format.min_code for f in m.inputs])
    qmax = np.array([f.format.max_code for f in m.inputs])
    can_leave = bool(np.any((qmin < lo) | (qmax > hi)))  # not with fill = 1 and p = 2**k (documented)
    assert oor.any() == can_leave and not oor.all()
    # reference = the float model at the physical input the code represents
    x = m.represented_inputs(q)
    assert np.allclose(ref, m.grid.evaluate(m.weights, x), rtol=0, atol=tol)
    # the bound in LSBs
    assert m.error_bound_lsb == pytest.approx(m.error_bound / m.output_format.lsb)


@pytest.mark.parametrize("rounding,e_out", [("truncate", (1 - 2.0**-3) / 16), ("half_up", 0.5 / 16)])
def test_output_rounding_bound_is_exact_and_attained(rounding, e_out):
    """Hand-worked: p = 1 on [0, 1], weights 0 and 1 (exact at Fw = 0), 8 input bits at fill 0.9 give
    F = 7, so acc = mu_1 = 0 .. 128 and the output (Fo = 4) drops sh = 3 bits. Truncation loses up to
    7/8 of an output lsb (acc = 8 k + 7), half up 1/2 of one: the documented e_out, attained."""
    m = FixedPointModel(Grid([0.0], [1.0], 1), np.array([0.0, 1.0]), input_bits=8, input_fill=0.9, weight_frac=0,
                        output_frac=4, rounding=rounding)
    assert m.F == 7 and m.shift == 3 and m.weight_error_max == 0.0
    assert m.error_bound_output == e_out
    q = np.arange(m.inputs[0].lo_code, m.inputs[0].hi_code + 1)[:, None]
    err = np.abs(m.to_physical_output(m.evaluate(q)[0]) - m.reference(q))
    assert err.max() == e_out


@pytest.mark.parametrize("case", CASES, ids=_ids)
def test_trace_consistent_exact_and_within_widths(case):
    m = _model(case, seed=3)
    rng = np.random.default_rng(5)
    q = _test_codes(m, rng, n_random=1000)
    tr = m.trace(q)
    assert tuple(tr) == TRACE_STAGES or set(tr) == set(TRACE_STAGES)
    out, oor = m.evaluate(q)
    assert np.array_equal(tr["out"], out) and np.array_equal(tr["out_of_range"], oor)
    F = m.F
    # mu: exact integers in [0, 2**F] summing to 2**F
    mu = tr["mu"]
    assert mu.dtype == np.int64 and mu.min() >= 0 and mu.max() <= 2**F
    assert np.all(mu.sum(axis=1) == 2**F)
    # integer location == float geometry on the exact grid coordinates
    fj = np.array([f.frac for f in m.inputs])
    s = np.ldexp(tr["t_clamped"].astype(float), -fj)
    cell, frac, rank, perm, verts, fmu = m.grid.locate_grid_units(s)
    assert np.array_equal(tr["cell"], cell) and np.array_equal(tr["rank"], rank) and np.array_equal(tr["perm"], perm)
    assert np.array_equal(tr["vertices"], verts)
    assert np.array_equal(np.ldexp(tr["frac"].astype(float), -F), frac)
    assert np.array_equal(np.ldexp(mu.astype(float), -F), fmu)
    # frac alignment and ranges
    assert np.array_equal(tr["frac"], tr["frac_raw"] << (F - fj))
    assert tr["frac_raw"].min() >= 0 and np.all(tr["frac_raw"] <= 2**fj)
    # memory read-back, products, accumulator, rounding, saturation
    assert np.array_equal(tr["w"], m.weight_codes[tr["vertices"]])
    rows = np.arange(len(q))[:, None]
    assert np.array_equal(tr["w_by_bank"][rows, tr["bank"]], tr["w"])
    assert np.array_equal(tr["addr_by_bank"][rows, tr["bank"]], tr["addr"])
    assert np.array_equal(tr["bank"], (tr["rot"][:, None] + np.arange(m.n + 1)) % (m.n + 1))
    assert np.array_equal(tr["products"], tr["mu"][:, :, None] * tr["w"])
    assert np.array_equal(tr["acc"], tr["products"].sum(axis=1))
    assert np.array_equal(tr["acc_rounded"], shift_round(tr["acc"], m.shift, m.rounding))
    half = 0.5 if m.rounding == "half_up" and m.shift > 0 else 0.0
    assert np.array_equal(tr["acc_rounded"], np.floor(np.ldexp(tr["acc"].astype(float), -m.shift) + half).astype(np.int64))
    assert not tr["out_saturated"].any()
    # every stage fits its declared width
    wd = m.widths

    def fits_signed(a, b):
        return a.min() >= -(2 ** (b - 1)) and a.max() <= 2 ** (b - 1) - 1

    assert fits_signed(tr["t"], wd["t"])
    assert tr["frac"].max() < 2 ** wd["frac"] and tr["mu"].max() < 2 ** wd["mu"]
    assert fits_signed(tr["w"], wd["weight"])
    assert fits_signed(tr["products"], wd["product"]) and fits_signed(tr["acc"], wd["acc"])
    assert fits_signed(tr["out"], wd["out"])
    assert all(tr["cell"][:, j].max() < 2 ** wd["cell"][j] for j in range(m.n))


@pytest.mark.parametrize("case", CASES[:8], ids=_ids)
def test_vertices_give_rounded_weight_codes(case):
    m = _model(case, seed=11)
    lo = np.array([f.lo_code for f in m.inputs])
    cc = np.array([f.cell_codes for f in m.inputs])
    qmax = np.array([f.format.max_code for f in m.inputs])
    vc = m.grid.vertex_coords()
    q = lo + vc * cc
    inside = np.all(q <= qmax, axis=1)  # fill = 1 with p = 2**k: the top face is one code too far
    out, oor = m.evaluate(q[inside])
    assert not oor.any()
    expect = shift_round(m.weight_codes[inside] << m.F, m.shift, m.rounding)
    assert np.array_equal(out, expect)
    # with Fo = Fw the output at a vertex is the weight code itself
    m2 = _model(case, seed=11, output_frac=m.weight_format.frac)
    out2, _ = m2.evaluate(q[inside])
    assert np.array_equal(out2, m2.weight_codes[inside])


@pytest.mark.parametrize("rounding, expect", [("half_up", (56, -55)), ("truncate", (55, -56))])
def test_known_answer(rounding, expect):
    """Hand-computed example: n = 2, p = 2, B_in = 8 -> F = 6, lo_code = -64, Fw = Fo = 0 (sh = 6)."""
    g = Grid([0.0, 0.0], [1.0, 1.0], [2, 2])
    w = np.zeros((9, 2))
    w[4], w[5], w[8], w[7] = (40, -40), (50, -50), (82, -82), (1, 1)
    m = FixedPointModel(g, w, input_bits=8, weight_frac=0, output_frac=0, rounding=rounding)
    assert m.F == 6 and [f.lo_code for f in m.inputs] == [-64, -64] and m.shift == 6
    tr = m.trace([[-64 + 64 + 16, -64 + 64 + 48], [64, 64], [-64 + 64 + 16, -64 + 64 + 16], [-100, 100]])
    assert tr["t_clamped"].tolist() == [[80, 112], [128, 128], [80, 80], [0, 128]]
    assert tr["out_of_range"].tolist() == [False, False, False, True]
    assert tr["cell"].tolist() == [[1, 1], [1, 1], [1, 1], [0, 1]]
    assert tr["frac"].tolist() == [[16, 48], [64, 64], [16, 16], [0, 64]]
    assert tr["perm"].tolist() == [[1, 0], [0, 1], [0, 1], [1, 0]]  # ties: lower dimension first
    assert tr["rank"].tolist() == [[1, 0], [0, 1], [0, 1], [1, 0]]
    assert tr["vertices"][:3].tolist() == [[4, 5, 8], [4, 7, 8], [4, 7, 8]]
    assert tr["mu"][:3].tolist() == [[16, 32, 16], [0, 0, 64], [48, 0, 16]]
    assert tr["bank"][:3].tolist() == [[2, 0, 1], [2, 0, 1], [2, 0, 1]]  # (|c| + k) mod 3, |c| = 2
    assert tr["acc"][0].tolist() == [3552, -3552]  # 16*40 + 32*50 + 16*82 = 55.5 * 64
    assert tuple(tr["out"][0].tolist()) == expect
    assert tr["out"][1].tolist() == [82, -82]  # top face corner: the weight itself


def test_replicated_layout_same_outputs():
    case = CASES[6]
    a, b = _model(case), _model(case, layout="replicated")
    q = _test_codes(a, np.random.default_rng(0), 500)
    assert np.array_equal(a.evaluate(q)[0], b.evaluate(q)[0])
    assert b.layout.total_words == (a.n + 1) * a.grid.n_vertices


def test_quantize_inputs_and_predict():
    m = _model(CASES[3])
    rng = np.random.default_rng(2)
    q = _test_codes(m, rng, 500)
    x = m.represented_inputs(q)
    assert np.array_equal(m.quantize_inputs(x), q)
    far = np.array([[1e6, 0.0], [-1e6, 0.0]]) + m.grid.lo
    qq, sat = m.quantize_inputs(far, return_saturated=True)
    assert sat.tolist() == [True, True]
    assert qq[0, 0] == m.inputs[0].format.max_code and qq[1, 0] == m.inputs[0].format.min_code
    z, flags = m.predict(np.concatenate([x[:10], far]), return_flags=True)
    o, oor = m.evaluate(np.concatenate([q[:10], qq]))
    assert np.array_equal(z, o * m.output_format.lsb) and flags[-2:].all()
    with pytest.raises(ValueError, match="outside the 12-bit range"):
        m.evaluate([[5000, 0]])
    with pytest.raises(ValueError, match="integers"):
        m.evaluate([[0.5, 0]])
    with pytest.raises(ValueError, match="shape"):
        m.evaluate([[0, 0, 0]])


# ------------------------------------------------------------------------------ overflow
def test_weight_overflow_error_message():
    g = Grid([0.0, 0.0], [1.0, 1.0], [2, 2])
    w = np.zeros((9, 1))
    w[5, 0] = 1000.3
    w[1, 0] = -3.0
    with pytest.raises(ValueError) as ei:
        FixedPointModel(g, w, weight_bits=10, weight_frac=2, output_frac=0)
    msg = str(ei.value)
    assert "weight 5 (vertex (1, 2))" in msg and "1000.3" in msg and "'z0'" in msg
    assert "s10.2" in msg and "-128.0" in msg and "127.75" in msg
    assert "13 bits are needed" in msg  # 1000.3 * 4 = 4001 -> 13 bits signed


def test_weight_saturate_warns_and_bound_includes_it():
    g, w = _problem([3, 2], seed=9, nz=1)
    fw = frac_for_bits(w, 12)
    with pytest.warns(UserWarning, match="saturated"):
        m = FixedPointModel(g, w, weight_bits=10, weight_frac=fw, output_frac=fw - 2, overflow="saturate")
    fmt = m.weight_format
    big = np.abs(w * 2.0**fw) > 511
    assert big.any() and m.n_weights_saturated == int(big.sum())
    assert np.all(np.isin(m.weight_codes[big], [fmt.min_code, fmt.max_code]))
    assert m.error_bound >= m.weight_error_max + m.error_bound_output - 1e-12
    assert m.to_dict()["error_bound"]["includes_weight_saturation"] is True
    q = _test_codes(m, np.random.default_rng(1), 2000)
    out, _ = m.evaluate(q)
    err = np.abs(out * m.output_format.lsb - m.reference(q))
    assert err.max() <= m.error_bound + 1e-9 * np.abs(w).max()
    assert err.max() >= 0.5 * m.error_bound


def test_output_too_narrow_warns_and_saturates():
    case = CASES[3]
    m0 = _model(case)
    with pytest.warns(UserWarning, match="may saturate"):
        m = _model(case, output_bits=m0.output_format.bits - 2)
    assert m.output_may_saturate
    tr = m.trace(_test_codes(m, np.random.default_rng(0), 500))
    assert tr["out_saturated"].any()
    assert tr["out"].max() <= m.output_format.max_code and tr["out"].min() >= m.output_format.min_code


def test_bad_formats_refused():
    g, w = _problem([2, 2], 0)
    with pytest.raises(ValueError, match="output_frac"):
        FixedPointModel(g, w, weight_frac=4, output_frac=4 + 11 + 1, input_bits=12)  # F = 10 for p = 2
    with pytest.raises(ValueError, match="accumulator would need"):
        FixedPointModel(g, w, input_bits=40, weight_frac=20)
    with pytest.raises(ValueError, match="B_in too small for p_1 = 5"):
        FixedPointModel(Grid([0, 0], [1, 1], [2, 5]), np.zeros((18, 1)), input_bits=2)
    with pytest.raises(ValueError, match="overflow"):
        FixedPointModel(g, w, overflow="wrap")
    with pytest.raises(ValueError, match="shape"):
        FixedPointModel(g, w[:-1])


# ------------------------------------------------------------------------------ defaults
def test_defaults_from_reference_error():
    g, w = _problem([3, 3], 4, nz=2)
    ref = 0.37
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = FixedPointModel(g, w, reference_error=ref)
    fw = m.weight_format.frac
    lsb_w = 2.0**-fw
    # largest power of two whose rounding noise (weights + output at half the lsb) is within 5 % of ref
    assert np.sqrt(1.25 * lsb_w**2 / 12) <= 0.05 * ref < np.sqrt(1.25 * (2 * lsb_w) ** 2 / 12)
    assert m.output_format.frac == fw + 1
    bw = m.weight_format.bits
    FixedFormat(bw, fw, overflow="error").quantize(w)
    with pytest.raises(ValueError):
        FixedFormat(bw - 1, fw, overflow="error").quantize(w)
    # B_out is minimal and never saturates: the extreme weight codes map to reachable output codes
    reach = [shift_round(np.array([c << m.F]), m.shift, m.rounding)[0] for c in (m.weight_codes.min(), m.weight_codes.max())]
    assert m.output_format.bits == signed_bits_needed(reach)
    assert not m.output_may_saturate
    assert m.error_bound_lsb == pytest.approx(1.5)  # 0.5 * 2 (weight lsb = 2 output lsb) + 0.5
    # no reference error: the weight range / 2**10
    m2 = FixedPointModel(g, w)
    r2 = (w.max() - w.min()) / 2**10
    assert m2.weight_format.frac == default_weight_frac(r2)
    assert m2.to_dict()["reference_error"]["source"] == "weight_range"


@pytest.mark.parametrize("input_bits", [3, 4, 6])
def test_default_output_frac_at_the_fewest_input_bits(input_bits):
    """With few input bits (input fraction F small) the default output fraction is the exact
    product's, never finer: the default formats must not be refused (they were at 3 bits, p = 7)."""
    g, w = _problem([7], 5, nz=1)
    m = FixedPointModel(g, w, input_bits=input_bits, reference_error=0.01)
    fw = m.weight_format.frac
    assert m.output_format.frac == min(fw + 1, m.F + fw) and m.shift >= 0
    if m.F == 0:
        assert m.output_format.frac == fw and m.shift == 0  # the exact product, no rounding
    q = _test_codes(m, np.random.default_rng(3))
    out, _ = m.evaluate(q)
    assert np.abs(m.to_physical_output(out) - m.reference(q)).max() <= m.error_bound + 1e-9 * (1 + np.abs(w).max())


def test_from_sensor_lorenz_defaults():
    from pwas_hdl import PWASVirtualSensor
    from pwas_hdl.systems.lorenz import lorenz

    d = lorenz(6000, seed=0)
    s = PWASVirtualSensor(my=4, partitions=7, gamma=1.2).fit(None, d.y, d.z)
    m = FixedPointModel.from_sensor(s)
    assert [str(f.format) for f in m.inputs] == ["s12.9"] * 4 and m.F == 9
    assert [f.lo_code for f in m.inputs] == [-1792] * 4
    assert m.lo_codes == (-1792,) * 4 and m.frac_bits == (9,) * 4
    assert np.allclose(m.input_offset + m.input_lsb * -1792, s.grid_.lo, rtol=0, atol=1e-12)
    assert np.allclose(m.input_lsb * 512, s.grid_.step, rtol=1e-15, atol=0)
    ref = float(np.max(s.train_rmse_))
    assert m.weight_format.frac == default_weight_frac(ref) == -2  # weight lsb 4 for a training RMSE of ~27
    assert m.output_format.frac == -1
    assert m.error_bound_lsb == pytest.approx(1.5)
    assert m.layout.total_words == 5120 <= 1.3 * 4096
    sig = m.signal_input_formats()
    assert len(sig) == 1 and len(set(m.inputs)) == 1  # all lags of y share one format
    dd = json.loads(json.dumps(m.to_dict()))
    assert dd["reference_error"]["source"] == "train_rmse"
    assert [i["lag"] for i in dd["inputs"]] == [3, 2, 1, 0]
    assert dd["signals"] is not None and dd["layout"]["kind"] == "banked"
    # bit-true on the training regressors stays within the bound of the float predictor
    xi, _ = s.regressors(None, d.y)
    q, sat = m.quantize_inputs(xi, return_saturated=True)
    assert not sat.any()
    out, oor = m.evaluate(q)
    assert not oor.any()
    err = np.abs(m.to_physical_output(out) - m.reference(q))
    assert err.max() <= m.error_bound + 1e-9
    # same inputs, same model description
    assert FixedPointModel.from_sensor(s).to_dict() == m.to_dict()


def test_signal_formats_differ_refused():
    """An InputError (the model file's fit, not a bug), as the warped model's refusal."""
    from pwas_hdl.errors import InputError

    g = Grid([0.0, 0.0], [1.0, 2.0], [2, 2])
    m = FixedPointModel(g, np.ones((9, 1)), regressor_signals=[("y", 1), ("y", 0)])
    with pytest.raises(InputError, match="share_lag_domain"):
        m.signal_input_formats()
    assert m.to_dict()["signals"] is None


@pytest.mark.parametrize("case", CASES[:10], ids=_ids)
def test_exact_input_scale_within_bound(case):
    """input_scale="exact": the stated bound holds against the float model at the points the circuit
    evaluates, out_of_range = some code outside [lo_code, hi_code], and both domain corners are
    reached exactly (their outputs are the rounded corner weights)."""
    m = _model(case, input_scale="exact")
    rng = np.random.default_rng(7)
    q = _test_codes(m, rng)
    out, oor = m.evaluate(q)
    ref = m.reference(q)
    tol = 1e-9 * (1.0 + np.abs(m.weights).max())
    assert np.abs(m.to_physical_output(out) - ref).max() <= m.error_bound + tol
    assert np.allclose(ref, m.grid.evaluate(m.weights, m.represented_inputs(q)), rtol=0, atol=tol)
    lo = np.array([f.lo_code for f in m.inputs])
    hi = np.array([f.hi_code for f in m.inputs])
    assert np.array_equal(oor, np.any((q < lo) | (q > hi), axis=1))
    assert all(f.input_span == min(int(f.fill * 2**f.bits), 2**f.bits - 1) for f in m.inputs)
    corners, flags = m.evaluate(np.stack([lo, hi]))
    assert not flags.any()
    vid = [0, m.grid.n_vertices - 1]
    assert np.array_equal(corners, shift_round(m.weight_codes[vid] << m.F, m.shift, m.rounding))
