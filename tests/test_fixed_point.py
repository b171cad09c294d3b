"""Fixed-point formats: ranges, rounding, overflow rules, scaling, grid input formats."""

from fractions import Fraction
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pwas_hdl.fixedpoint.formats import (
    FixedFormat,
    InputFormat,
    PortFormat,
    SignalScaling,
    frac_for_bits,
    grid_input_formats,
    shift_round,
    signed_bits_needed,
    unsigned_bits_needed,
)


# ----------------------------------------------------------------------------- FixedFormat
def test_ranges_and_str():
    f = FixedFormat(16, 4)
    assert str(f) == "s16.4"
    assert (f.min_code, f.max_code) == (-32768, 32767)
    assert f.lsb == 0.0625 and f.min_value == -2048.0 and f.max_value == 32767 / 16
    u = FixedFormat(12, 9, signed=False)
    assert str(u) == "u12.9" and (u.min_code, u.max_code) == (0, 4095) and u.max_value == 4095 / 512
    n = FixedFormat(8, -2)
    assert str(n) == "s8.-2" and n.lsb == 4.0 and n.max_value == 127 * 4
    big = FixedFormat(6, 10)
    assert big.max_value == 31 / 1024
    one = FixedFormat(1, 0)
    assert (one.min_code, one.max_code) == (-1, 0)
    assert FixedFormat(64, 0).max_code == 2**63 - 1 and FixedFormat(63, 0, False).max_code == 2**63 - 1


@pytest.mark.parametrize(
    "kwargs, msg",
    [
        (dict(bits=0, frac=0), "at least 1 bit"),
        (dict(bits=65, frac=0), "exceeds 64"),
        (dict(bits=64, frac=0, signed=False), "exceeds 63"),
        (dict(bits=8.0, frac=0), "bits must be an integer"),
        (dict(bits=8, frac=0.5), "frac"),
        (dict(bits=8, frac=0, rounding="nearest"), "rounding"),
        (dict(bits=8, frac=0, overflow="clip"), "overflow"),
        (dict(bits=8, frac=5000), "frac"),
    ],
)
def test_validation(kwargs, msg):
    with pytest.raises(ValueError, match=msg):
        FixedFormat(**kwargs)


def test_string_and_dict_roundtrip():
    for f in (FixedFormat(16, 4), FixedFormat(12, 9, False, "truncate", "error"), FixedFormat(8, -3, True, "half_up", "wrap")):
        assert FixedFormat.from_dict(json.loads(json.dumps(f.to_dict()))) == f
        g = FixedFormat.from_string(str(f), f.rounding, f.overflow)
        assert g == f
    with pytest.raises(ValueError, match="cannot parse"):
        FixedFormat.from_string("q15")


def test_half_up_rounding_ties_and_exactness():
    f = FixedFormat(16, 0)
    vals = [0.5, -0.5, 1.5, -1.5, 2.5, -2.5, 0.49999999999999994, -0.49999999999999994, 0.9999999999999999, 1e-300]
    # exact reference: floor(v + 1/2) in rational arithmetic
    expect = [math.floor(Fraction(v) + Fraction(1, 2)) for v in vals]
    assert f.quantize(vals).tolist() == expect
    assert expect[:6] == [1, 0, 2, -1, 3, -2]
    assert expect[6] == 0  # the classic floor(x + 0.5) float bug would give 1


def test_truncate_is_floor():
    f = FixedFormat(16, 2, rounding="truncate")
    vals = np.array([0.1, -0.1, 0.25, -0.25, 0.2499, -0.2501])
    assert f.quantize(vals).tolist() == [math.floor(Fraction(v) * 4) for v in vals.tolist()]
    assert f.quantize([-0.1]).tolist() == [-1]


def test_quantize_random_matches_rational():
    rng = np.random.default_rng(1)
    for frac in (-3, 0, 5, 17):
        for rnd in ("half_up", "truncate"):
            f = FixedFormat(40, frac, rounding=rnd)
            v = rng.normal(0, 1000, 500) * rng.choice([1e-3, 1, 1e3], 500)
            # include exact ties of the format
            v[:50] = (np.round(rng.normal(0, 100, 50)) + 0.5) * 2.0**-frac
            got = f.quantize(v)
            half = Fraction(1, 2) if rnd == "half_up" else 0
            assert got.tolist() == [math.floor(Fraction(x) * Fraction(2) ** frac + half) for x in v.tolist()]


def test_saturate_reports():
    f = FixedFormat(8, 4)  # [-8, 7.9375]
    codes, sat = f.quantize([100.0, -100.0, 1.0, np.inf, -np.inf, 7.96875, 7.9], return_saturated=True)
    assert codes.tolist() == [127, -128, 16, 127, -128, 127, 126]
    assert sat.tolist() == [True, True, False, True, True, True, False]
    assert int(sat.sum()) == 5
    assert codes.dtype == np.int64


def test_error_policy_message():
    f = FixedFormat(8, 4, overflow="error")
    assert f.quantize([1.0, -8.0]).tolist() == [16, -128]
    with pytest.raises(ValueError) as ei:
        f.quantize([1.0, 9.0, -30.3, 8.5], what="weight")
    msg = str(ei.value)
    assert "weight at index (2,) = -30.3" in msg  # worst value named
    assert "s8.4" in msg and "-8.0" in msg and "7.9375" in msg
    assert "10 bits are needed" in msg  # -30.3 * 16 = -485 -> 10 bits
    assert "3 value(s)" in msg
    with pytest.raises(ValueError, match="NaN"):
        f.quantize([np.nan])
    with pytest.raises(ValueError, match="negative values need a signed"):
        FixedFormat(8, 0, signed=False, overflow="error").quantize([-1.0])


def test_wrap_policy():
    f = FixedFormat(4, 0, overflow="wrap")
    codes, wrapped = f.quantize([7, 8, 9, -9, -8, 23], return_saturated=True)
    assert codes.tolist() == [7, -8, -7, 7, -8, 7]
    assert wrapped.tolist() == [False, True, True, True, False, True]
    u = FixedFormat(4, 0, signed=False, overflow="wrap")
    assert u.quantize([16, 17, -1]).tolist() == [0, 1, 15]


def test_wide_formats_saturate_without_int64_overflow():
    assert FixedFormat(64, 0).quantize([1e30, -1e30, 2.0**62]).tolist() == [2**63 - 1, -(2**63), 2**62]
    assert FixedFormat(63, 0, signed=False).quantize([1e30, -3.0]).tolist() == [2**63 - 1, 0]


def test_fits_and_to_float():
    f = FixedFormat(6, 2)
    assert f.fits([-32, 31, 32, -33]).tolist() == [True, True, False, False]
    assert f.fits(np.array([1.0, 1.5])).tolist() == [True, False]
    assert np.array_equal(f.to_float([-32, 3]), [-8.0, 0.75])


def test_bits_needed():
    for c in range(-300, 300):
        b = signed_bits_needed([c])
        assert -(2 ** (b - 1)) <= c <= 2 ** (b - 1) - 1
        assert b == 1 or not (-(2 ** (b - 2)) <= c <= 2 ** (b - 2) - 1)
    assert signed_bits_needed([-128, 127]) == 8 and signed_bits_needed([128]) == 9 and signed_bits_needed([-129]) == 9
    assert unsigned_bits_needed([0]) == 1 and unsigned_bits_needed([255]) == 8 and unsigned_bits_needed([256]) == 9
    with pytest.raises(ValueError):
        unsigned_bits_needed([-1])


def test_shift_round_matches_rational():
    a = np.arange(-70, 71, dtype=np.int64)
    for sh in range(0, 5):
        hu = shift_round(a, sh, "half_up")
        tr = shift_round(a, sh, "truncate")
        assert hu.tolist() == [math.floor(Fraction(int(x), 2**sh) + Fraction(1, 2)) for x in a]
        assert tr.tolist() == [math.floor(Fraction(int(x), 2**sh)) for x in a]
    assert shift_round(a, 0).tolist() == a.tolist()
    with pytest.raises(ValueError):
        shift_round(a, -1)


def test_frac_for_bits():
    v = [3.3, -7.9, 0.01]
    fr = frac_for_bits(v, 8)
    FixedFormat(8, fr, overflow="error").quantize(v)
    with pytest.raises(ValueError):
        FixedFormat(8, fr + 1, overflow="error").quantize(v)
    assert fr == 4
    assert frac_for_bits([1000.0], 4) == -8  # 1000 / 2**7 rounds to 8 > 7; 1000 / 2**8 -> 4
    assert frac_for_bits([0.75], 3, signed=False) == 3  # 0.75 * 8 = 6 <= 7


# ---------------------------------------------------------------------- scaling / ports
def test_port_format_physical():
    p = PortFormat(FixedFormat(10, 3), SignalScaling(scale=2.0, offset=-5.0))
    assert p.physical_lsb == 0.25
    codes = np.array([-512, 0, 7, 511])
    x = p.to_physical(codes)
    assert np.array_equal(x, -5.0 + 2.0 * codes / 8)
    assert np.array_equal(p.quantize(x), codes)
    d = json.loads(json.dumps(p.to_dict()))
    assert d["scale"] == 2.0 and d["offset"] == -5.0 and d["str"] == "s10.3"
    assert PortFormat.from_dict(d) == p
    with pytest.raises(ValueError):
        SignalScaling(scale=0.0)
    with pytest.raises(ValueError):
        SignalScaling(offset=math.inf)


# ---------------------------------------------------------------------- input formats
@pytest.mark.parametrize(
    "bits, p, fill, expect_f",
    [(12, 7, 0.9, 9), (12, 1, 0.9, 11), (12, 4, 0.9, 9), (8, 3, 0.9, 6), (16, 10, 0.9, 12), (12, 3686, 0.9, 0), (12, 5, 1.0, 9)],
)
def test_input_frac_bits(bits, p, fill, expect_f):
    f = InputFormat.for_interval(-1.0, 3.0, p, bits, fill)
    assert f.frac == expect_f
    assert expect_f == math.floor(math.log2(fill * 2**bits / p))  # the spec formula (fill < 1 or p * 2**F < 2**bits)
    assert f.cell_codes == 2**expect_f
    assert f.lo_code == -((p * 2**expect_f + 1) // 2)
    assert f.hi_code == f.lo_code + p * 2**expect_f
    assert f.format.min_code <= f.lo_code and f.hi_code <= f.format.max_code


@settings(max_examples=400, deadline=None)
@given(bits=st.integers(2, 24), p=st.integers(1, 5000), fill=st.one_of(st.just(1.0), st.floats(0.01, 1.0)))
def test_input_domain_codes_are_codes_at_every_fill(bits, p, fill):
    """lo_code and hi_code are representable at every fill (the off-by-one of fill = 1: 8-bit inputs
    gave domain codes [-128, 128]), and F is the largest that fits both fill and the code range."""
    try:
        f = InputFormat.for_interval(-1.0, 3.0, p, bits, fill)
    except ValueError:
        assert p > min(fill * 2**bits, 2**bits - 1)  # not even one code per cell
        return
    assert f.format.min_code <= f.lo_code < f.hi_code <= f.format.max_code
    assert f.span_codes <= fill * 2**bits and f.span_codes <= 2**bits - 1
    assert not (2 * f.span_codes <= fill * 2**bits and 2 * f.span_codes <= 2**bits - 1)  # F + 1 would not fit
    # centred: the codes left below and above the domain differ by at most one
    below, above = f.lo_code - f.format.min_code, f.format.max_code - f.hi_code
    assert abs(below - above) <= 1
    # the top vertex is reachable and the flag can rise above it whenever a code is left there
    assert f.quantize([3.0]).tolist() == [f.hi_code]


@settings(max_examples=300, deadline=None)
@given(bits=st.integers(2, 14), p=st.integers(1, 600), fill=st.one_of(st.just(1.0), st.floats(0.05, 1.0)))
def test_exact_input_scale_uses_the_whole_range(bits, p, fill):
    """input_scale="exact": the domain takes min(floor(fill 2^B), 2^B - 1) codes for any p, and the
    constant scale t' = (t K) >> R maps them onto the grid exactly at both ends and monotonically."""
    smax = min(math.floor(fill * 2**bits), 2**bits - 1)
    try:
        f = InputFormat.for_interval(-1.0, 3.0, p, bits, fill, scale="exact")
    except ValueError:
        assert smax < p
        return
    assert f.input_span == smax and f.hi_code - f.lo_code == smax
    assert f.format.min_code <= f.lo_code < f.hi_code <= f.format.max_code
    assert (p << f.frac) >= smax and (f.frac == 0 or (p << (f.frac - 1)) < smax)  # F: the smallest that resolves every code
    t = np.arange(smax + 1)
    ts = f.scaled(t)
    assert ts[0] == 0 and ts[-1] == p << f.frac and np.all(np.diff(ts) >= 1)  # exact ends, strictly increasing
    assert f.quantize([-1.0, 3.0]).tolist() == [f.lo_code, f.hi_code]
    pow2 = InputFormat.for_interval(-1.0, 3.0, p, bits, fill)
    assert f.input_span >= pow2.input_span  # never fewer codes than the power-of-two cell


def test_exact_scale_doubles_the_codes_of_a_power_of_two_p():
    pow2 = InputFormat.for_interval(0.0, 1.0, 8, 12, 0.9)
    exact = InputFormat.for_interval(0.0, 1.0, 8, 12, 0.9, scale="exact")
    assert pow2.input_span == 2048 and exact.input_span == 3686  # half vs 90 % of the 4096 codes
    assert exact.scale == "exact" and pow2.scale == "pow2" and exact.to_dict()["scale_mul"] == exact.scale_mul
    same = InputFormat.for_interval(0.0, 1.0, 7, 12, 3584 / 4096, scale="exact")  # 7 * 512 codes: no scale needed
    assert same.scale == "pow2" and same.input_span == 3584


@pytest.mark.parametrize("p", [1, 2, 3, 4, 5, 7, 8, 255])
def test_fill_one_8bit_domain_codes(p):
    f = InputFormat.for_interval(0.0, 1.0, p, 8, 1.0)
    assert -128 <= f.lo_code and f.hi_code <= 127
    assert f.quantize([0.0, 1.0]).tolist() == [f.lo_code, f.hi_code]


def test_input_bits_too_small():
    with pytest.raises(ValueError, match="B_in too small for p_2 = 300 intervals.*input_bits >= 9"):
        InputFormat.for_interval(0.0, 1.0, 300, bits=8, fill=0.9, dim=2)
    with pytest.raises(ValueError, match="input_fill"):
        InputFormat.for_interval(0.0, 1.0, 3, bits=8, fill=1.5)
    with pytest.raises(ValueError, match="hi > lo"):
        InputFormat.for_interval(1.0, 1.0, 3)


def test_input_cell_is_power_of_two_codes():
    lo, hi, p = -22.88370340513261, 22.787703944405283, 7
    f = InputFormat.for_interval(lo, hi, p, 12, 0.9)
    assert f.lsb == (hi - lo) / p / 512
    assert math.isclose(f.offset + f.lsb * f.lo_code, lo, rel_tol=0, abs_tol=1e-12)
    # the domain bounds and every vertex land exactly on multiples of 2**F from lo_code
    verts = lo + np.arange(p + 1) * f.step
    q = f.quantize(verts)
    assert q.tolist() == (f.lo_code + np.arange(p + 1) * 512).tolist()
    assert f.quantize([lo]).tolist() == [f.lo_code] and f.quantize([hi]).tolist() == [f.hi_code]
    assert f.to_physical([f.lo_code]).tolist() == [lo]
    assert math.isclose(float(f.to_physical([f.hi_code])[0]), hi, rel_tol=1e-14)
    assert np.array_equal(f.grid_units([f.lo_code, f.lo_code + 256, f.hi_code]), [0.0, 0.5, 7.0])
    # port view agrees
    codes = np.array([-2048, -1792, 0, 5, 2047])
    assert np.allclose(f.port.to_physical(codes), f.to_physical(codes), rtol=0, atol=1e-12)
    d = json.loads(json.dumps(f.to_dict()))
    assert d["F"] == 9 and d["lo_code"] == -1792 and d["format"] == "s12.9"


def test_input_quantize_round_trip_and_saturation():
    f = InputFormat.for_interval(0.0, 1.0, 5, 10, 0.9)
    q = np.arange(f.format.min_code, f.format.max_code + 1)
    assert np.array_equal(f.quantize(f.to_physical(q)), q)
    codes, sat = f.quantize([-100.0, 100.0, 0.5], return_saturated=True)
    assert codes.tolist()[:2] == [f.format.min_code, f.format.max_code]
    assert sat.tolist() == [True, True, False]


def test_input_quantize_ties_round_up():
    f = InputFormat.for_interval(0.0, 5.0, 5, 10, 0.9)  # F = 7, lsb = 1/128 exactly
    assert f.frac == 7 and f.lsb == 2.0**-7
    q = np.arange(f.format.min_code, f.format.max_code)
    mid = f.to_physical(q) + 0.5 * f.lsb  # exact ties
    assert np.array_equal(f.quantize(mid), q + 1)
    assert np.array_equal(f.quantize(mid - 2.0**-20), q)


def test_fill_one_power_of_two_top_face():
    f = InputFormat.for_interval(0.0, 1.0, 4, 8, 1.0)
    assert f.frac == 5 and f.lo_code == -64 and f.hi_code == 64  # 4 * 2**6 = 256 steps do not fit in 256 codes
    codes, sat = f.quantize([1.0, 1.0 + f.lsb], return_saturated=True)
    assert codes.tolist() == [64, 65] and sat.tolist() == [False, False]  # hi is a code, above it is seen


def test_grid_input_formats():
    fmts = grid_input_formats([0, -1], [1, 1], [3, 8], bits=12)
    assert [f.frac for f in fmts] == [10, 8]
    assert [f.partitions for f in fmts] == [3, 8]
