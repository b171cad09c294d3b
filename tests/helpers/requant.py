"""The check of a feedback requantisation over every output code (recurrent tests, uniform and warped inputs)."""

from __future__ import annotations

import numpy as np

from pwas_hdl.fixedpoint.formats import FixedFormat
from pwas_hdl.fixedpoint.recurrence import FeedbackRequant


def check_requant_over_every_output_code(inp, bits: int, frac: int) -> FeedbackRequant:
    """``FeedbackRequant.between(s<bits>.<frac>, inp)`` applied to every output code: inside the
    range, the fed-back value is within ``error_bound`` of the output's and equals the input format's
    own half-up quantisation but for ties within the constants' rounding (> 99.9 %); outside it
    saturates. ``inp``: an InputFormat or a WarpInputFormat (their physical rule is one:
    ``to_physical(q) = offset + lsb q``, checked too). Returns the requantisation."""
    out = FixedFormat(bits, frac, True, "half_up", "saturate")
    fb = FeedbackRequant.between(out, inp)
    o = np.arange(out.min_code, out.max_code + 1, dtype=np.int64)
    q = fb.apply(o)
    x = o * 2.0**-frac
    inside = (q > fb.qmin) & (q < fb.qmax)
    assert inside.sum() > 100
    np.testing.assert_allclose(inp.to_physical(q), inp.offset + inp.lsb * q, rtol=0, atol=1e-12)
    assert np.all(np.abs(inp.to_physical(q)[inside] - x[inside]) <= fb.error_bound + 1e-12)
    assert np.mean(q == inp.quantize(x)) > 0.999  # only ties within eps of a half code may round the other way
    assert np.all(q[x > inp.to_physical(fb.qmax + 1)] == fb.qmax)
    assert np.all(q[x < inp.to_physical(fb.qmin - 1)] == fb.qmin)
    return fb
