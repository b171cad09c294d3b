"""Seed 003's bit-true estimator (FixedPointSwitchedEstimator): the default state width comes from an
invariant box of the switched arithmetic (every mode sequence), not from the per-mode l1 gain, which
bounds the bank only; a switched observer sized by that gain saturates at extreme input codes."""

from __future__ import annotations

import math

import numpy as np

from pwas_hdl.fixedpoint.formats import signed_bits_needed
from pwas_hdl.fixedpoint.observer_bank import FixedPointSwitchedEstimator, switched_state_bound

# two modes whose F_i = A_i - K_i C_i move x2 into x1 and x1 into x2 (0.85 each): either alone is
# nilpotent, alternating them adds up a geometric series; C_i make the detector alternate
A = [[[-0.1768, 0.7106], [0.052, 0.041]], [[-0.5612, 0.414], [0.6548, 0.144]]]
B = [[-0.55, 0.98], [-0.31, -0.33]]
C = [[-0.52, -0.41], [-2.44, 1.8]]
K = [[0.34, -0.1], [0.23, 0.08]]


def _extreme_codes(est, seed=172, t=200):
    lo, hi = -(1 << (est.input_bits - 1)), (1 << (est.input_bits - 1)) - 1
    return np.random.default_rng(seed).choice([lo, hi], size=(t, 2))


def test_default_state_width_holds_the_switched_observer():
    est = FixedPointSwitchedEstimator(A, B, C, K)
    assert est.state_bound_proven and not est.state_may_saturate
    codes = _extreme_codes(est)
    tr = est.trace(codes)
    reach = float(np.abs(tr["x_hat"]).max()) * 2.0**-est.state_frac
    assert not tr["state_saturated"].any()
    assert len(set(tr["theta"].tolist())) == 2  # the detector switches
    assert est.bank_state_bound + 1.0 < reach <= est.state_bound  # past the per-mode bound, inside the box
    # the width of the per-mode rule (l1 gain + 1) saturates the switched observer on the same codes
    top = math.ceil((est.bank_state_bound + 1.0) * 2.0**est.state_frac)
    old = int(signed_bits_needed(np.array([top, -top])))
    assert old < est.state_bits
    narrow = FixedPointSwitchedEstimator(A, B, C, K, state_bits=old, state_frac=est.state_frac, coef_frac=est.coef_frac)
    assert narrow.state_may_saturate and narrow.trace(codes)["state_saturated"].any()


def test_switched_state_bound_is_an_invariant_box_or_none():
    f = np.array([[[0.0, 0.5], [0.0, 0.0]], [[0.0, 0.0], [0.5, 0.0]]])
    v = switched_state_bound(f, np.ones((2, 2)))
    assert np.allclose(v, [2.0, 2.0], rtol=1e-6)  # b = 0.5 b + 1
    assert np.all(np.max(np.einsum("smn,n->sm", np.abs(f), v) + 1.0, axis=0) <= v)
    grow = np.array([[[0.5, 1.5], [0.0, 0.5]], [[0.5, 0.0], [1.5, 0.5]]])  # each stable, no common contraction
    assert switched_state_bound(grow, np.ones((2, 2))) is None


def test_no_invariant_box_makes_saturation_explicit():
    f = [np.array([[0.5, 1.5], [0.0, 0.5]]), np.array([[0.5, 0.0], [1.5, 0.5]])]
    c = [np.array([1.0, 0.0]), np.array([0.0, 1.0])]
    k = [np.array([0.5, 0.5])] * 2
    est = FixedPointSwitchedEstimator([fi + np.outer(ki, ci) for fi, ki, ci in zip(f, k, c)], [[1.0, 0.0], [0.0, 1.0]], c, k)
    assert not est.state_bound_proven and est.state_may_saturate
