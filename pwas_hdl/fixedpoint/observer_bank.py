"""Bit-true model of the observer-bank front end (seed 004) and of the whole observer-bank sensor.

THE specification of the RTL of :mod:`pwas_hdl.hdl.observer_bank`, :mod:`pwas_hdl.hdl.residual_features`
and :mod:`pwas_hdl.hdl.observer_sensor_top`: every integer the circuit computes is computed here,
with the same widths, rounding and saturation, in ``numpy.int64``. The float reference is
:class:`pwas_hdl.fit.observer_bank.ObserverBankFrontEnd` (+ the PWAS sensor) evaluated at the
physical signals the input codes represent.

Signals (one transfer = one sample ``k`` of every input ``u_c`` and of the output ``y``)
------------------------------------------------------------------------------------
The bank works on normalised signals ``un = (u - u_mean) / u_std``, ``yn = (y - y_mean) / y_std``
(the front end's training statistics). The input code of signal ``s`` is the normalised value in
``s<B_in>.<F_in>``: ``physical = mean_s + std_s * code * 2**-F_in`` (a :class:`PortFormat` with
scale ``std``, offset ``mean``), ``F_in = B_in - 1 - ceil(log2(H))`` with the head room ``H``
(default 8 standard deviations), so ``|normalised| < H`` is representable.

Observer ``j`` (canonical form (6), gain ``L``; :func:`pwas_hdl.fit.observer_bank.canonical_form`)
------------------------------------------------------------------------------------------------
``A_cl = A - L C`` has first column ``a0_i = -a_{i+1} - L_i`` and ones on the superdiagonal, so
with state codes ``x_i`` (``s<B_s>.<F_s>``, ``F_s >= F_in``) and coefficient codes with ``F_c``
fraction bits (half up: ``A0 = round(a0 2**F_c)``, ``Bc = round(b 2**F_c)``, ``Lc = round(L 2**F_c)``,
``Dc = round(d 2**(F_c + F_s))``)::

    e    = x_0 - (qy << (F_s - F_in))                                   residual yhat - y, frac F_s
    acc_i = A0_i x_0 + ((sum_c Bc_ic qu_c + Lc_i qy) << (F_s - F_in)) + Dc_i + (x_{i+1} << F_c)
    x_i' = sat_{B_s}((acc_i + 2**(F_c-1)) >> F_c)                       (x_M = 0)

``e`` is computed from the state *before* the update with sample ``k`` (``yhat_k = C xi_k``);
states are 0 after reset (``xi_0 = 0``, A9). A saturated state is flagged (``state_saturated``).

Feature unit (map 11b, ``v = sqrt(1/l sum_{r=k-l}^{k} e_r^2)``, or 11b-sq, ``s = 1/l sum e_r^2``)
------------------------------------------------------------------------------------------------
``sq = e * e`` (frac ``2 F_s``); the window sum over ``l + 1`` samples is a running sum,
``S_k = S_{k-1} + sq_k - sq_{k-l-1}`` with a delay line of ``l + 1`` squares that is 0 after
reset, exact in integers (so ``S_k`` equals the window sum once ``k >= l``). 11b: ``r = isqrt(S)``
(floor of the square root, an integer square root in hardware), 11b-sq: ``r = S``. The PWAS core's
input code of feature ``j`` (its :class:`InputFormat`) is the constant affine map
``q_j = sat_{B_in}((min(r >> t, cap_j) K_j + C_j) >> R)`` (``t``: the bits of ``r`` below 1/16 code, ``cap_j``:
where ``q_j`` saturates anyway) with ``K_j = round(2**(R+t) 2**-F_s / (sqrt(l) lsb_j))``
(11b-sq: ``2**(R+t) 2**-2F_s / (l lsb_j)``) and ``C_j = round(-2**R offset_j / lsb_j) + 2**(R-1)``
(the half-up rounding folded in). Then the PWAS core's bit-true model
(:class:`pwas_hdl.fixedpoint.bittrue.FixedPointModel`) on the feature codes.

Sample ``k`` (0-based since reset) has an estimate for ``k >= M + l`` (as the float front end).

Which feature map and why
-------------------------
Both are supported: 11b (the paper's RMS feature) with an integer square root in hardware -- the
model file needs no change and the PWAS grid is the one fitted on the paper's feature -- and
11b-sq (the squared feature, an equivalent monotone map ``s = v**2``; the fit path has it as
``features="11b-sq"``), which needs no square root (fewer LUTs, one stage less) but spreads the
grid over a quadratic range. The default is what the model was fitted with.

Formats from a noise budget
---------------------------
The front end's worst-case feature error (below) is split: the state-rounding term and the
coefficient term each at most ``budget`` (default 1/8) of the smallest feature input LSB of the
PWAS core: ``F_s`` and ``F_c`` are the smallest that meet it. ``B_s`` holds the largest state the
observers can reach with inputs within the code range (their l1 gain, no saturation by default).
``R`` makes the scale-constant rounding <= 1/16 code.

Error bound (holds unless an observer state saturates)
------------------------------------------------------
With ``G = sum_t ||C A_cl^t||_1`` (l1 gain from a per-step state error to the residual), the
per-step injection ``eta = 2**-(F_s+1)`` (state rounding) ``+ 2**-(F_c+1) (X_0 + nu H + H) +
2**-(F_c+F_s+1)`` (coefficient rounding against the largest state ``X_0`` and inputs ``H``):
``|e_hw - e_float| <= de = G eta``. Feature 11b: ``|v_hw - v| <= sqrt((l+1)/l) de`` (triangle
inequality in l2) ``+ 2**-F_s / sqrt(l)`` (isqrt floor); 11b-sq: ``(l+1)/l (2 E de + de**2)``
(``E = sqrt(l hi)``: where hw and float can differ some window lies in the domain); then the code
map: ``r`` is shifted right by ``t`` (the bits below 1/16 code: ``(2**t - 1) c_j`` codes, ``c_j``
codes per unit of ``r``), capped at ``cap_j`` (beyond it ``q_j`` saturates, out of the domain), and
``(cap/2 + 1/2) 2**-R + 1/2`` codes for ``K``, ``C`` and the final rounding. The
estimate: ``|z_hw - z_float(v)| <= core bound + sum_j G_j dv_j`` with ``G_j`` the largest
``|w(v + e_j) - w(v)| / h_j`` over the grid's edges along ``j`` (the Kuhn simplices' gradient
components; clamping to the domain is 1-Lipschitz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from pwas_hdl.errors import InputError, InternalError, option_text
from pwas_hdl.fixedpoint.bittrue import MAX_DATAPATH_BITS, FixedPointModel
from pwas_hdl.fixedpoint.formats import FixedFormat, InputFormat, PortFormat, SignalScaling, signed_bits_needed
from pwas_hdl.fixedpoint.memory_layout import model_layout
from pwas_hdl.fit.observer_bank import FRONT_END_KIND, ObserverBankFrontEnd, canonical_form

if TYPE_CHECKING:
    from pwas_hdl.fit.virtual_sensor import PWASVirtualSensor

__all__ = [
    "observer_bank_model", "BANK_FORMAT_OPTIONS", "ObserverBankFormats", "FixedPointObserverBank", "ObserverBankSensorModel", "isqrt_floor",
    "l1_gain", "HW_FEATURE_MAPS", "FEATURE_BUDGET", "BANK_TRACE_STAGES",
]

#: Options of the bank's formats that ``generate`` accepts besides the core's (None: the default).
BANK_FORMAT_OPTIONS = ("state_bits", "state_frac", "coef_frac", "input_headroom")
#: Feature maps the hardware implements.
HW_FEATURE_MAPS = ("11b", "11b-sq")
#: Each of the two front-end error terms may use this fraction of the smallest feature input LSB.
FEATURE_BUDGET = 0.125
#: Keys of :meth:`FixedPointObserverBank.trace`.
BANK_TRACE_STAGES = ("codes", "state", "state_saturated", "residual", "square", "window_sum", "root", "root_capped",
                     "feature_codes")


def switched_state_bound(f: np.ndarray, c: np.ndarray, max_steps: int = 100_000) -> np.ndarray | None:
    """A componentwise bound of the states of a switched system, whatever the mode sequence.

    For ``x_{t+1} = F_{theta_t} x_t + e_t`` with ``|e_t| <= c_{theta_t}`` (elementwise) and ``x_0 = 0``
    the iteration ``b_{k+1} = max_i (|F_i| b_k + c_i)`` (``b_0 = 0``) bounds ``|x_k|`` by induction;
    it is monotone, so its limit ``b*`` bounds every state of every mode sequence. The limit is
    accepted only when ``v = b* (1 + 1e-9)`` verifies ``max_i (|F_i| v + c_i) <= v``: then ``v`` is an
    invariant box (``|x_t| <= v`` implies ``|x_{t+1}| <= v``) -- a proof, not an estimate. The
    per-mode l1 gain bounds only the bank (one mode each); a switched observer can go further.

    Parameters
    ----------
    f : ndarray (s, n, n)
        The modes' state matrices (as the arithmetic uses them: quantised).
    c : ndarray (s, n)
        Per mode, the elementwise bound of everything added in one step (inputs, rounding).

    Returns
    -------
    ndarray (n,) or None
        The invariant box ``v``; None when there is none (the switched system can grow without
        bound, e.g. no common contraction of the ``|F_i|``).
    """
    fa = np.abs(np.asarray(f, float))
    ca = np.abs(np.asarray(c, float))
    b = np.zeros(fa.shape[1])
    for _ in range(max_steps):
        nb = np.max(np.einsum("smn,n->sm", fa, b) + ca, axis=0)
        if not np.all(np.isfinite(nb)) or np.max(nb) > 2.0**60:
            return None
        if np.max(nb - b) <= 1e-12 * max(1.0, float(np.max(nb))):
            b = nb
            break
        b = nb
    v = b * (1 + 1e-9) + 1e-12
    return v if np.all(np.max(np.einsum("smn,n->sm", fa, v) + ca, axis=0) <= v) else None


def isqrt_floor(a: np.ndarray) -> np.ndarray:
    """Elementwise ``floor(sqrt(a))`` of non-negative int64 (exact, corrected float guess).

    Parameters
    ----------
    a : ndarray of int
        Non-negative integers (converted to int64), any shape.

    Returns
    -------
    ndarray of int64, shape of ``a``

    Raises
    ------
    InternalError
        A negative entry (a window sum cannot be negative).
    """
    a = np.asarray(a, dtype=np.int64)
    if np.any(a < 0):
        raise InternalError("isqrt of a negative number (a window sum below 0 cannot happen)")
    r = np.floor(np.sqrt(a.astype(np.float64))).astype(np.int64)
    for _ in range(3):
        r = np.where(r * r > a, r - 1, r)
        r = np.where((r + 1) * (r + 1) <= a, r + 1, r)
    return r


def l1_gain(a_cl: np.ndarray, b: np.ndarray, tol: float = 1e-13, max_steps: int = 100_000) -> np.ndarray:
    """``sum_t |A_cl^t b|`` (elementwise absolute values), shape of ``b``.

    Parameters
    ----------
    a_cl : ndarray (M, M), a stable matrix (spectral radius < 1)
    b : ndarray (M, m)
    tol : float
        Stop when the current term is below ``tol`` times the sum (at least 1); the geometric
        tail is then added as a bound.
    max_steps : int
        Most terms summed.

    Returns
    -------
    ndarray of float, shape (M, m)
        The elementwise sum (an upper bound: it includes the tail bound).

    Raises
    ------
    InputError
        The sum does not converge (an unstable or marginally stable observer).
    """
    unstable = InputError("an observer of the bank is not stable (A - L C has a pole on or outside the unit circle); "
                          "choose another gain (poles:R with R < 1, or kalman), or, for a model file edited by hand "
                          "(front_end.models / gains), fit the model again")
    # an unstable observer is refused before summing: its terms grow to inf, and once the sum is inf
    # the stopping test below (term < tol * sum) passed and returned an infinite bound
    if not np.all(np.isfinite(a_cl)):
        raise unstable
    rho = float(np.max(np.abs(np.linalg.eigvals(a_cl)))) if a_cl.size else 0.0
    if not rho < 1:
        raise unstable
    acc = np.zeros_like(b, dtype=float)
    term = np.array(b, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(max_steps):
            acc += np.abs(term)
            if not np.all(np.isfinite(acc)):  # a stable but huge transient: no usable bound either
                raise unstable
            if np.max(np.abs(term), initial=0.0) < tol * max(1.0, float(np.max(acc, initial=0.0))):
                # geometric tail: bound the rest by the current term over (1 - rho)
                acc += np.abs(term) * (rho / (1 - rho) if rho > 0 else 0.0)
                return acc
            term = a_cl @ term
    raise unstable


@dataclass(frozen=True)
class ObserverBankFormats:
    """Formats and widths of the bank and the feature unit (all integers: bits).

    Attributes
    ----------
    input_bits : int
        ``B_in``, width in bits of the u and y codes.
    input_frac : int
        ``F_in``, fraction bits of the u and y codes.
    coef_frac : int
        ``F_c``, fraction bits of the observer coefficients.
    state_bits : int
        ``B_s``, width in bits of the observer states.
    state_frac : int
        ``F_s``, fraction bits of the states.
    residual_bits : int
        Width in bits of the residual ``x0 - y`` (widened so that its square holds the window sum).
    square_bits : int
        Width in bits of the squared residual (``2 * residual_bits``).
    sum_bits : int
        Width in bits of the window sum of squares.
    root_bits : int
        Width in bits of the square root (feature map 11b) or of the sum itself (11b-sq).
    scale_shift : int
        ``R``, the right shift in bits of the feature scale ``(r * K + c) >> R``.
    scale_mul_bits : int
        Width in bits of the scale constants ``K`` (signed).
    acc_bits : int
        Width in bits of the state update's accumulator.
    """

    input_bits: int
    input_frac: int
    coef_frac: int
    state_bits: int
    state_frac: int
    residual_bits: int
    square_bits: int
    sum_bits: int
    root_bits: int
    scale_shift: int
    scale_mul_bits: int
    acc_bits: int

    def to_dict(self) -> dict:
        """JSON-ready: every field name -> its value (int, bits).

        Returns
        -------
        dict of str to int
        """
        return {k: int(v) for k, v in self.__dict__.items()}


class FixedPointObserverBank:
    """Bit-true observer bank + feature unit producing the PWAS core's feature input codes.

    Parameters
    ----------
    front_end : ObserverBankFrontEnd (fitted; feature map 11b or 11b-sq)
    feature_inputs : list of InputFormat
        The PWAS core's input formats of the ``N_theta`` feature dimensions.
    input_bits : int
        ``B_in``, bits of the u / y codes (default 12).
    input_headroom : float
        ``H``: normalised values in ``(-H, H)`` are representable (default 8).
    coef_frac, state_frac, state_bits : int, optional
        ``F_c``, ``F_s``, ``B_s``; default from the noise budget / the l1 state bound. A smaller
        ``state_bits`` makes the states saturate (flagged; the error bound then does not hold).
    budget : float
        Fraction of the smallest feature LSB each front-end error term may use.
    """

    def __init__(self, front_end: ObserverBankFrontEnd, feature_inputs: list[InputFormat], *, input_bits: int = 12,
                 input_headroom: float = 8.0, coef_frac: int | None = None, state_frac: int | None = None,
                 state_bits: int | None = None, budget: float = FEATURE_BUDGET):
        if getattr(front_end, "kind", None) != FRONT_END_KIND or not hasattr(front_end, "models_"):
            raise InputError("the fixed-point observer bank needs a fitted observer-bank front end")
        if front_end.features not in HW_FEATURE_MAPS:
            raise InputError(f"hardware supports the observer-bank feature maps {', '.join(HW_FEATURE_MAPS)}; "
                             f"this model uses {front_end.features!r} (refit with --features 11b)")
        for nm, v in (("input_bits", input_bits), ("coef_frac", coef_frac), ("state_frac", state_frac), ("state_bits", state_bits)):
            if v is not None and (not isinstance(v, (int, np.integer)) or isinstance(v, bool)):
                raise InputError(f"{option_text(nm)} must be an integer, got {v!r}")
        if not 4 <= input_bits <= 24:
            raise InputError(f"{option_text('input_bits')} = {input_bits}: an observer-bank design needs 4..24")
        if not (math.isfinite(input_headroom) and input_headroom > 0):
            raise InputError(f"{option_text('input_headroom')} must be a positive number, got {input_headroom!r}")
        fe = front_end
        self.front_end = fe
        self.n_models = fe.n_models_
        self.order = int(fe.order)
        self.nu = int(fe.nu_)
        self.window = int(fe.window)
        self.feature_map = fe.features
        if len(feature_inputs) != self.n_models:
            raise InputError(f"{len(feature_inputs)} feature input formats for {self.n_models} observers")
        self.feature_inputs = list(feature_inputs)
        m, nu, l_w = self.order, self.nu, self.window

        # ---- inputs: normalised value in s<B_in>.<F_in>
        self.input_bits = int(input_bits)
        self.input_headroom = float(input_headroom)
        fin = self.input_bits - 1 - max(0, math.ceil(math.log2(self.input_headroom)))
        self.input_frac = fin
        h_in = (2 ** (self.input_bits - 1)) * 2.0**-fin  # largest |normalised input| the codes hold
        self.signal_names = [f"u{c}" for c in range(nu)] + ["y0"]
        means = list(np.asarray(fe.u_mean_, float)) + [float(fe.y_mean_[0])]
        stds = list(np.asarray(fe.u_std_, float)) + [float(fe.y_std_[0])]
        self.signal_ports = [PortFormat(FixedFormat(self.input_bits, fin, True, "half_up", "saturate"), SignalScaling(s, mu))
                             for mu, s in zip(means, stds)]

        # ---- float observers
        self._acl, self._b, self._l, self._d = [], [], [], []
        for g, lg in zip(fe.models_, fe.gains_):
            a_mat, b_mat, c_mat, d = canonical_form(g, m, nu)
            self._acl.append(a_mat - np.outer(lg, c_mat[0]))
            self._b.append(b_mat)
            self._l.append(np.asarray(lg, float))
            self._d.append(d)
        # l1 gains: residual error per unit state injection, state bound per unit input
        self.residual_gain = max(float(l1_gain(acl, np.eye(m))[0].sum()) for acl in self._acl)
        xmax = []
        for acl, b, lg, d in zip(self._acl, self._b, self._l, self._d):
            gin = l1_gain(acl, np.column_stack([b, lg, d]))
            xmax.append(gin[:, : nu + 1].sum(axis=1) * h_in + gin[:, nu + 1])
        self.state_bound = float(np.max(xmax))  # normalised units, every state of every observer

        # ---- budget -> F_s, F_c
        lsb_min = min(f.lsb for f in self.feature_inputs)
        self.budget = float(budget)
        target = self.budget * lsb_min
        x0 = self.state_bound + 1.0
        # 11b-sq: where the estimate can differ, some window lies in the domain (s <= hi), so each of
        # its residuals is <= sqrt(l hi); beyond hi both hw and float clamp to the domain
        e_max = math.sqrt(l_w * max(f.hi for f in self.feature_inputs)) if self.feature_map == "11b-sq" else x0 + h_in
        self.residual_max = e_max

        def feat_err(de: float) -> float:
            if self.feature_map == "11b":
                return math.sqrt((l_w + 1) / l_w) * de
            return (l_w + 1) / l_w * (2 * e_max * de + de * de)

        g_e = self.residual_gain
        if state_frac is None:
            fs = fin
            while feat_err(g_e * 2.0 ** -(fs + 1)) + (2.0**-fs / math.sqrt(l_w) if self.feature_map == "11b" else 0) > target and fs < 40:
                fs += 1
        else:
            fs = int(state_frac)
        if fs < fin:
            raise InputError(f"{option_text('state_frac')} = {fs} must be >= the input fraction bits {fin} "
                             f"(input bits {self.input_bits} - 1 - ceil(log2 input head room {self.input_headroom:g}); "
                             f"{option_text('input_bits')}, {option_text('input_headroom')})")
        if coef_frac is None:
            fc = 4
            while feat_err(g_e * 2.0 ** -(fc + 1) * (x0 + (nu + 1) * h_in + 1)) > target and fc < 40:
                fc += 1
        else:
            fc = int(coef_frac)
        if not 1 <= fc <= 40:
            raise InputError(f"{option_text('coef_frac')} must be in 1..40, got {fc}")  # the default is 4..40
        if fs > 40:
            raise InputError(f"{option_text('state_frac')} must be <= 40, got {fs}"
                             + ("" if state_frac is not None else " (the default, from the input fraction bits: give fewer "
                                f"{option_text('input_bits')} or --state-frac 40 or less)"))
        self.state_frac, self.coef_frac = fs, fc

        # ---- coefficient codes
        def q(v, f):
            return np.floor(np.asarray(v, float) * 2.0**f + 0.5).astype(np.int64)

        self.a0_codes = np.array([q(acl[:, 0], fc) for acl in self._acl])  # (N, M)
        self.b_codes = np.array([q(b, fc) for b in self._b]).reshape(self.n_models, m, nu)  # (N, M, nu)
        self.l_codes = np.array([q(lg, fc) for lg in self._l])  # (N, M)
        self.d_codes = np.array([q(d, fc + fs) for d in self._d])  # (N, M)
        self.coef_error = max(
            float(np.max(np.abs(self.a0_codes * 2.0**-fc - np.array([acl[:, 0] for acl in self._acl])))),
            float(np.max(np.abs(self.b_codes * 2.0**-fc - np.array(self._b).reshape(self.n_models, m, nu)), initial=0.0)),
            float(np.max(np.abs(self.l_codes * 2.0**-fc - np.array(self._l)))),
        )

        # ---- state width
        need = signed_bits_needed(np.array([math.ceil((self.state_bound + 1.0) * 2.0**fs)]))
        need = max(need, signed_bits_needed(np.array([-(math.ceil((self.state_bound + 1.0) * 2.0**fs))])))
        self.state_bits_needed = int(need)
        bs = int(state_bits) if state_bits is not None else int(need)
        if bs < 2:
            raise InputError(f"{option_text('state_bits')} must be >= 2, got {bs}")
        self.state_may_saturate = bs < need
        # residual x0 - y (exact in max(B_s, B_in + F_s - F_in) + 1 bits), widened so that the square
        # e * e (2 rb bits) also holds the window sum of l + 1 squares: the RTL sums at one width
        lgw = max(1, math.ceil(math.log2(l_w + 1)))
        rb = max(bs + 2, self.input_bits + fs - fin + 2) + (lgw + 1) // 2
        sqb = 2 * rb  # the square as the multiplier gives it (value < 2**(2 rb - 2 - lgw))
        sumb = 2 * rb  # window sum, < 2**(2 rb - 2)
        if self.feature_map == "11b":
            rootb = (sumb + 1) // 2
            r_max = (1 << rootb) - 1
        else:
            rootb = sumb
            r_max = (1 << sumb) - 1
        # scale constants: K_j >= 2**(B_in + 4) so that rounding K costs <= 1/16 code over the code range;
        # r is capped at r_cap_j (where q_j saturates anyway) so the product stays narrow
        creal = [(2.0**-fs / (math.sqrt(l_w) * f.lsb)) if self.feature_map == "11b" else (2.0 ** (-2 * fs) / (l_w * f.lsb))
                 for f in self.feature_inputs]  # codes per unit of r
        bcore = self.feature_inputs[0].bits
        # drop the low bits of r that are below 1/16 code of every feature (truncation, exact shift)
        tsh = max(0, math.floor(math.log2(1.0 / (16.0 * max(creal)))))
        self.root_shift = tsh
        r_max = r_max >> tsh
        self.truncation_codes = [(2.0**tsh - 1.0) * cr for cr in creal] if tsh else [0.0] * len(creal)
        creal = [cr * 2.0**tsh for cr in creal]
        shift = max(1, math.ceil(math.log2(2.0 ** (bcore + 4) / min(creal))))
        ks, cs, caps = [], [], []
        qmax = (1 << (bcore - 1)) - 1
        for f, cr in zip(self.feature_inputs, creal):
            k = int(math.floor(2.0**shift * cr + 0.5))
            c = int(math.floor(-(2.0**shift) * f.offset / f.lsb + 0.5)) + (1 << (shift - 1))
            cap = max(0, -((c - ((qmax + 1) << shift)) // k))  # ceil(((qmax+1) 2**R - c) / k): q(cap) > qmax
            cap = min(cap, r_max)
            ks.append(k)
            cs.append(c)
            caps.append(cap)
        self.scale_mul, self.scale_add, self.root_cap, self.scale_shift = ks, cs, caps, shift
        kb = max(int(v).bit_length() for v in ks) + 1
        capb = max(int(v).bit_length() for v in caps) + 1
        prodmax = max(k * cap for k, cap in zip(ks, caps))
        scaleb = signed_bits_needed(np.array([prodmax + max(cs), min(cs), prodmax + min(cs)])) + 1
        scaleb = max(scaleb, capb + kb, shift + bcore + 1)  # the RTL's product width; the code field wider than B_in
        r_max = max(caps)
        # acc_i = A0 x0 + (sum B qu + L qy) << (Fs-Fin) + D + (x_{i+1} << Fc): bound it from the codes
        amax = int(np.abs(self.a0_codes).max(initial=0)) * (1 << (bs - 1))
        # Python ints: the product exceeds int64 for wide inputs (numpy would wrap, under-sizing acc)
        bin_max = (int(np.abs(self.b_codes).sum(axis=2).max(initial=0)) + int(np.abs(self.l_codes).max(initial=0))) \
            * (1 << (self.input_bits - 1))
        accmax = int(amax) + (bin_max << (fs - fin)) + int(np.abs(self.d_codes).max(initial=0)) + ((1 << (bs - 1)) << fc)
        accb = accmax.bit_length() + 2  # + 1: the rounding term 2**(F_c-1) is added in it
        accb = max(accb, bs + fc + 2)  # x_{i+1} 2**F_c is a product of that width in the RTL
        self.formats = ObserverBankFormats(self.input_bits, fin, fc, bs, fs, rb, sqb, sumb, rootb, shift, kb, accb)
        self.cap_bits = capb
        self.widths = {"acc": accb, "state": bs, "residual": rb, "square": sqb, "window_sum": sumb, "root": rootb,
                       "scale_product": scaleb}
        for nm, w in self.widths.items():
            if w > MAX_DATAPATH_BITS:
                raise InputError(f"the observer bank's {nm} would need {w} bits (more than {MAX_DATAPATH_BITS}) with "
                                 f"state fraction bits F_s = {fs}, state bits B_s = {bs} and input head room "
                                 f"{self.input_headroom:g}; give a smaller {option_text('state_frac')}, at least the input "
                                 f"fraction bits {fin}, fewer {option_text('state_bits')} or a smaller "
                                 f"{option_text('input_headroom')}, or fit faster observers (fit --observer)")

        # ---- error bound of the features
        eta = 2.0 ** -(fs + 1) + self.coef_error * (x0 + (nu + 1) * h_in) + 2.0 ** -(fc + fs + 1)
        self.residual_error_bound = g_e * eta  # normalised units
        code_term = (r_max * 0.5 + 0.5) * 2.0**-shift + 0.5  # codes
        isq = 2.0**-fs / math.sqrt(l_w) if self.feature_map == "11b" else 0.0
        self.feature_error_bound = [feat_err(self.residual_error_bound) + isq + (code_term + tc) * f.lsb
                                    for f, tc in zip(self.feature_inputs, self.truncation_codes)]

    # ------------------------------------------------------------------ signals
    def quantize_signals(self, u: np.ndarray | None, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Input codes of one trajectory: columns ``u0 .. u{nu-1}, y0``.

        Parameters
        ----------
        u : ndarray, shape (T, nu), or None
            Physical inputs (None when ``nu = 0``).
        y : ndarray, shape (T,) or (T, 1)
            Physical output.

        Returns
        -------
        codes : ndarray of int64, shape (T, nu + 1)
            Signed ``B_in``-bit codes, columns ``u0 .. u{nu-1}, y0``.
        saturated : ndarray of bool, shape (T,)
            Some signal of the sample saturated.
        """
        y = np.asarray(y, float).reshape(-1, 1)
        cols = [np.zeros((y.shape[0], 0))] if u is None else [np.asarray(u, float).reshape(y.shape[0], -1)]
        x = np.hstack(cols + [y])
        if x.shape[1] != self.nu + 1:
            raise InputError(f"the observer bank takes {self.nu} input(s) and one output, got {x.shape[1] - 1} input column(s)")
        codes = np.empty(x.shape, dtype=np.int64)
        sat = np.zeros(x.shape, dtype=bool)
        for c, p in enumerate(self.signal_ports):
            codes[:, c], sat[:, c] = p.quantize(x[:, c], return_saturated=True)
        return codes, sat.any(axis=1)

    def represented_signals(self, codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Physical (u, y) the codes stand for: shapes (T, nu), (T, 1).

        Parameters
        ----------
        codes : ndarray of int, shape (T, nu + 1)
            Input codes (columns ``u0 .. u{nu-1}, y0``) inside the signed ``B_in``-bit range.

        Returns
        -------
        u : ndarray of float, shape (T, nu)
        y : ndarray of float, shape (T, 1)
            Physical units.

        Raises
        ------
        InputError
            ``codes`` is not an integer array of that shape, or a code is out of range.
        """
        codes = self._check(codes)
        phys = np.column_stack([p.to_physical(codes[:, c]) for c, p in enumerate(self.signal_ports)])
        return phys[:, : self.nu], phys[:, self.nu :]

    def _check(self, codes) -> np.ndarray:
        c = np.asarray(codes)
        if c.ndim != 2 or c.shape[1] != self.nu + 1 or c.dtype.kind not in "iu":
            raise InputError(f"input codes must be integers of shape (T, {self.nu + 1}), got {c.shape} {c.dtype}")
        lo, hi = -(1 << (self.input_bits - 1)), (1 << (self.input_bits - 1)) - 1
        if c.size and (c.min() < lo or c.max() > hi):
            raise InputError(f"input codes outside the signed {self.input_bits}-bit range")
        return c.astype(np.int64)

    # ------------------------------------------------------------------ datapath
    def trace(self, codes: np.ndarray) -> dict[str, np.ndarray]:
        """Run the bank from reset over one trajectory of codes (T, nu + 1).

        Parameters
        ----------
        codes : ndarray of int, shape (T, nu + 1)
            Input codes (columns ``u0 .. u{nu-1}, y0``) inside the signed ``B_in``-bit range.

        Returns
        -------
        dict of str to ndarray
            Keys :data:`BANK_TRACE_STAGES`: ``state`` (T, N, M) state *before* sample k,
            ``state_saturated`` (T,) some state saturated in the update with sample k, ``residual``,
            ``square``, ``window_sum``, ``root``, ``root_capped`` (T, N), ``feature_codes`` (T, N)
            (rows ``k < M + l`` are computed too; the sensor has no output for them); and
            ``codes``, the input codes (int64).

        Raises
        ------
        InputError
            ``codes`` is not an integer array of that shape, or a code is out of range.
        """
        codes = self._check(codes)
        t_len = codes.shape[0]
        n, m, fc, fs, fin = self.n_models, self.order, self.coef_frac, self.state_frac, self.input_frac
        bs = self.formats.state_bits
        smin, smax = -(1 << (bs - 1)), (1 << (bs - 1)) - 1
        sh_in = fs - fin
        x = np.zeros((n, m), dtype=np.int64)
        states = np.empty((t_len, n, m), dtype=np.int64)
        sat = np.zeros(t_len, dtype=bool)
        qu, qy = codes[:, : self.nu], codes[:, self.nu]
        half = np.int64(1 << (fc - 1))
        lim = 1 << (self.widths["acc"] - 1)
        for k in range(t_len):
            states[k] = x
            inj = (self.b_codes @ qu[k] if self.nu else 0) + self.l_codes * qy[k]  # (N, M)
            nxt = np.zeros_like(x)
            nxt[:, : m - 1] = x[:, 1:]
            acc = self.a0_codes * x[:, :1] + (inj << sh_in) + self.d_codes + (nxt << fc)
            assert np.all(np.abs(acc) < lim), "observer accumulator exceeds its declared width"
            r = (acc + half) >> fc
            xs = np.clip(r, smin, smax)
            sat[k] = bool(np.any(xs != r))
            x = xs
        res = states[:, :, 0] - (qy[:, None] << sh_in)
        sq = res * res
        c = np.concatenate([np.zeros((1, n), dtype=np.int64), np.cumsum(sq, axis=0)])
        lw = self.window
        start = np.maximum(np.arange(t_len) - lw, 0)
        wsum = c[1:] - c[start]
        root = isqrt_floor(wsum) if self.feature_map == "11b" else wsum
        k_mul = np.array(self.scale_mul, dtype=np.int64)
        c_add = np.array(self.scale_add, dtype=np.int64)
        capped = np.minimum(root >> self.root_shift, np.array(self.root_cap, dtype=np.int64))
        qf = (capped * k_mul + c_add) >> self.scale_shift
        lo, hi = -(1 << (self.input_bits_core - 1)), (1 << (self.input_bits_core - 1)) - 1
        qf = np.clip(qf, lo, hi)
        return {"codes": codes, "state": states, "state_saturated": sat, "residual": res, "square": sq,
                "window_sum": wsum, "root": root, "root_capped": capped, "feature_codes": qf}

    @property
    def input_bits_core(self) -> int:
        """``B_in`` of the PWAS core's feature codes."""
        return int(self.feature_inputs[0].bits)

    @property
    def first_output(self) -> int:
        """Sample index (0-based since reset) of the first estimate: ``M + l``."""
        return self.order + self.window

    def float_features(self, codes: np.ndarray) -> np.ndarray:
        """The float front end's features at the physical signals the codes represent, rows ``k >= M + l``.

        Parameters
        ----------
        codes : ndarray of int, shape (T, nu + 1)
            Input codes of one trajectory from reset.

        Returns
        -------
        ndarray of float, shape (T - M - l, N)
            Features (the front end's feature map), one row per sample with an estimate.
        """
        u, y = self.represented_signals(codes)
        feats, _ = self.front_end.transform([u], [y])
        return feats

    def to_dict(self) -> dict:
        """Formats, constants and bounds (the manifest's ``observer_bank`` block).

        Returns
        -------
        dict
            Sizes, feature map, signal formats, ``formats`` (:meth:`ObserverBankFormats.to_dict`),
            coefficient codes, the feature scale constants, widths, state bound, residual gain,
            ``error_bound`` (residual and per-feature, physical units of the normalised residual
            and of the features) and ``first_output_sample``.
        """
        return {
            "n_models": self.n_models, "order": self.order, "nu": self.nu, "window": self.window,
            "feature_map": self.feature_map, "observer": self.front_end.observer,
            "signals": [{"name": nm, **p.to_dict()} for nm, p in zip(self.signal_names, self.signal_ports)],
            "input_headroom": self.input_headroom,
            "formats": self.formats.to_dict(),
            "coefficients": {"frac": self.coef_frac, "a0": self.a0_codes.tolist(), "b": self.b_codes.tolist(),
                             "l": self.l_codes.tolist(), "d": self.d_codes.tolist(), "d_frac": self.coef_frac + self.state_frac},
            "feature_scale": {"mul": list(self.scale_mul), "add": list(self.scale_add), "shift": self.scale_shift,
                              "cap": list(self.root_cap), "root_shift": self.root_shift,
                              "rule": ("q_j = sat((min(r >> root_shift, cap_j) * mul_j + add_j) >> shift), "
                                       + ("r = isqrt(window_sum)" if self.feature_map == "11b" else "r = window_sum"))},
            "widths": dict(self.widths),
            "state_bound": self.state_bound, "state_bits_needed": self.state_bits_needed,
            "state_may_saturate": self.state_may_saturate,
            "residual_gain": self.residual_gain,
            "error_bound": {"residual": self.residual_error_bound, "features": list(self.feature_error_bound),
                            "holds_unless_state_saturates": True,
                            "against": "float front end at the physical signals the input codes represent"},
            "first_output_sample": self.first_output,
        }


def _edge_lipschitz(grid, weights: np.ndarray) -> np.ndarray:
    """``G_j``: the largest ``|w(v + e_j) - w(v)| / h`` over the grid edges along ``j`` (``h``: the
    edge's length, the cell width of its interval on a non-uniform grid), per target (nz, n).

    Every Kuhn simplex has one edge along each axis, and the PWAS function's slope along ``e_j``
    inside the simplex is that edge's difference over its length, so ``G_j`` bounds the slope."""
    shape = [p + 1 for p in grid.partitions]
    nz = weights.shape[1]
    out = np.zeros((nz, grid.n))
    cuts = getattr(grid, "breakpoints", None)
    # vertex order of the grid: the last coordinate fastest (Grid.strides): C order
    for z in range(nz):
        arr = np.asarray(weights[:, z], float).reshape(shape)
        for j in range(grid.n):
            if shape[j] < 2:
                continue
            width = np.diff(np.asarray(cuts[j], float)) if cuts is not None and cuts[j] is not None \
                else np.full(shape[j] - 1, float(grid.step[j]))
            across = [1] * grid.n
            across[j] = shape[j] - 1
            out[z, j] = float((np.abs(np.diff(arr, axis=j)) / width.reshape(across)).max())
    return out


class ObserverBankSensorModel:
    """Bit-true observer-bank sensor: :class:`FixedPointObserverBank` -> PWAS core (:class:`FixedPointModel`).

    Build with :meth:`from_sensor`.

    Parameters
    ----------
    bank : FixedPointObserverBank
        The bit-true bank (features).
    core : FixedPointModel or WarpedFixedPointModel
        The bit-true PWAS core on the bank's features; of a sensor fitted with power-of-two
        ``breakpoints`` the warp and the uniform core (:mod:`pwas_hdl.fixedpoint.warp`), the
        features' codes then being the warp's input codes (``s<B_in>.0``, :class:`WarpInputFormat
        <pwas_hdl.fixedpoint.warp.WarpInputFormat>`).
    sensor : PWASVirtualSensor, optional
        The float sensor both were built from (needed by :meth:`reference`).

    Attributes
    ----------
    lipschitz : ndarray, shape (nz, n)
        Per target and core input, a bound on the PWAS function's slope (physical target units per
        physical regressor unit), from its edges.
    error_bound : list of float
        Per target, physical units: the core's bound plus ``lipschitz`` times the features' bounds.
    """

    def __init__(self, bank: FixedPointObserverBank, core: FixedPointModel, sensor: Any = None):
        self.bank = bank
        self.core = core
        self.sensor = sensor
        self.lipschitz = _edge_lipschitz(core.grid, core.weights)
        fb = np.array(bank.feature_error_bound)
        self.error_bound = [float(core.error_bound + self.lipschitz[z] @ fb) for z in range(core.nz)]

    @classmethod
    def from_sensor(cls, sensor: PWASVirtualSensor, *, input_bits: int = 12, input_headroom: float | None = 8.0,
                    coef_frac: int | None = None, state_frac: int | None = None, state_bits: int | None = None,
                    **core_formats: Any) -> "ObserverBankSensorModel":
        """From a fitted :class:`~pwas_hdl.fit.virtual_sensor.PWASVirtualSensor` with an observer-bank front end.

        ``core_formats``: :class:`FixedPointModel` options (``input_bits`` of the core = the same
        ``input_bits``); the core's regressors are the bank features (lag taps are not supported
        in hardware yet).

        Parameters
        ----------
        sensor : PWASVirtualSensor
            Fitted, with an observer-bank front end and no u/y lag taps.
        input_bits : int
            ``B_in``, bits of the u / y codes and of the core's feature codes.
        input_headroom : float, optional
            ``H`` (None: 8).
        coef_frac, state_frac, state_bits : int, optional
            ``F_c``, ``F_s`` (fraction bits), ``B_s`` (bits) of :class:`FixedPointObserverBank`
            (default: from the noise budget and the state bound).
        **core_formats
            Options of :class:`FixedPointModel` (None means the default); ``reference_error``
            defaults to the largest finite positive training RMSE.

        Returns
        -------
        ObserverBankSensorModel

        Raises
        ------
        InputError
            No observer-bank front end, lag taps present (see
            :class:`~pwas_hdl.fixedpoint.bank_taps.TappedObserverBankSensorModel`), or impossible
            formats.
        """
        fe = getattr(sensor, "front_end_", None)
        if fe is None:
            raise InputError("the model has no observer-bank front end")
        if getattr(sensor, "lags_", None) is not None:
            raise InputError("this model has u/y lag taps (mu, my > 0): its bit-true model is "
                             "pwas_hdl.fixedpoint.bank_taps.TappedObserverBankSensorModel (observer_bank_model picks it)")
        names = fe.feature_names()
        given = {k: v for k, v in core_formats.items() if v is not None}
        if input_headroom is None:
            input_headroom = 8.0
        rmse = np.asarray(getattr(sensor, "train_rmse_", []), float).reshape(-1)
        rmse = rmse[np.isfinite(rmse) & (rmse > 0)]
        given.setdefault("reference_error", float(rmse.max()) if rmse.size else None)
        from pwas_hdl.fixedpoint.warp import WarpedFixedPointModel, is_warped

        # non-uniform partition: the warp, then the uniform core
        core_cls: Any = WarpedFixedPointModel if is_warped(sensor) else FixedPointModel
        core = core_cls(sensor.grid_, sensor.weights_, input_bits=input_bits, regressor_names=names,
                        regressor_signals=[(nm, 0) for nm in names], target_names=sensor.signal_names()[2], **given)
        bank = FixedPointObserverBank(fe, core.inputs, input_bits=input_bits, input_headroom=input_headroom,
                                      coef_frac=coef_frac, state_frac=state_frac, state_bits=state_bits)
        return cls(bank, core, sensor)

    @property
    def first_output(self) -> int:
        """Sample index (0-based since reset) of the first estimate: ``M + l`` (the bank's).

        The one alignment rule of an observer-bank sensor: :meth:`evaluate` returns the estimates
        of samples ``first_output .. T-1`` of a trajectory, the sensor top's warm-up is this many
        transfers (the manifest's ``lags.warmup.samples_without_output``) and ``simulate`` / ``explore``
        compare them with data rows ``first_output ..`` of each trajectory.
        :class:`~pwas_hdl.fixedpoint.bank_taps.TappedObserverBankSensorModel` overrides it.
        """
        return self.bank.first_output

    def quantize_signals(self, u: ArrayLike | None, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Input codes of one trajectory (:meth:`FixedPointObserverBank.quantize_signals`).

        Parameters
        ----------
        u : array_like, shape (T, nu), or None
            Physical inputs (None when ``nu = 0``).
        y : array_like, shape (T,) or (T, 1)
            Physical output.

        Returns
        -------
        codes : ndarray of int64, shape (T, nu + 1)
            Columns ``u0 .. u{nu-1}, y0``.
        saturated : ndarray of bool, shape (T,)
            Some signal of the sample saturated its code range.

        Raises
        ------
        InputError
            Another number of input columns than the bank has.
        """
        return self.bank.quantize_signals(u, y)

    def trace(self, codes: np.ndarray) -> dict[str, np.ndarray]:
        """Bank trace plus the core's ``out`` (T - M - l, nz) and ``out_of_range`` for rows ``k >= M + l``.

        Parameters
        ----------
        codes : ndarray of int, shape (T, nu + 1)
            Input codes of one trajectory from reset.

        Returns
        -------
        dict of str to ndarray
            :meth:`FixedPointObserverBank.trace` with ``out`` (T - M - l, nz) output codes and
            ``out_of_range`` (T - M - l,).
        """
        tr = self.bank.trace(codes)
        qf = tr["feature_codes"][self.first_output :]
        out, oor = self.core.evaluate(qf) if qf.shape[0] else (np.zeros((0, self.core.nz), np.int64), np.zeros(0, bool))
        tr["out"], tr["out_of_range"] = out, oor
        return tr

    def evaluate(self, codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Output codes (T - M - l, nz) and out-of-range flags of one trajectory from reset.

        Parameters
        ----------
        codes : ndarray of int, shape (T, nu + 1)
            Input codes.

        Returns
        -------
        out : ndarray of int64, shape (T - M - l, nz)
            Output codes of the core's output format.
        out_of_range : ndarray of bool, shape (T - M - l,)
            Some feature was outside the PWAS domain.
        """
        tr = self.trace(codes)
        return tr["out"], tr["out_of_range"]

    def predict(self, u: ArrayLike | None, y: ArrayLike) -> np.ndarray:
        """Physical estimates (T - M - l, nz) of one trajectory through the bit-true circuit.

        Parameters
        ----------
        u : array_like, shape (T, nu), or None
            Physical inputs (None when ``nu = 0``).
        y : array_like, shape (T,) or (T, 1)
            Physical output.

        Returns
        -------
        ndarray of float, shape (T - M - l, nz)
            Physical target units, one row per sample ``k >= M + l``.
        """
        codes, _ = self.quantize_signals(u, y)
        out, _ = self.evaluate(codes)
        return self.core.to_physical_output(out)

    def reference(self, codes: np.ndarray) -> np.ndarray:
        """The float sensor (front end + PWAS) at the physical signals the codes represent, (T - M - l, nz).

        Parameters
        ----------
        codes : ndarray of int, shape (T, nu + 1)
            Input codes of one trajectory from reset.

        Returns
        -------
        ndarray of float, shape (T - M - l, nz)
            Physical target units (needs the ``sensor`` the model was built from).
        """
        feats = self.bank.float_features(codes)
        return self.sensor.predict_regressors(feats)

    def to_dict(self) -> dict:
        """The manifest's description of the front end and of the sensor's error bound.

        Returns
        -------
        dict
            ``observer_bank`` (:meth:`FixedPointObserverBank.to_dict`), ``lipschitz`` (nz x n
            list) and ``error_bound`` (per target, physical units, with the core's and the
            features' parts and the rule).
        """
        return {"observer_bank": self.bank.to_dict(), "lipschitz": self.lipschitz.tolist(),
                "error_bound": {"physical": list(self.error_bound), "core": self.core.error_bound,
                                "features": list(self.bank.feature_error_bound),
                                "rule": "core bound + sum_j G_j * feature bound_j",
                                "holds_unless_state_saturates": True,
                                "against": "float sensor (front end + PWAS) at the physical signals the codes represent"}}


def observer_bank_model(sensor: PWASVirtualSensor, memory: str = "banked", **formats: Any) -> ObserverBankSensorModel:
    """The bit-true model ``generate`` builds for an observer-bank sensor.

    ``formats``: the core's format options (those of :class:`FixedPointModel`; ``input_bits`` is
    shared by the u / y codes and the feature codes) and :data:`BANK_FORMAT_OPTIONS`; None means
    the default. Raises :class:`InputError` for an option the bank design does not have.

    Parameters
    ----------
    sensor : PWASVirtualSensor
        Fitted, with an observer-bank front end.
    memory : {"banked", "replicated", "corner", "single"}
        Weight memory layout of the core (``"single"``: the serial core's, modelled by the
        replicated layout, :func:`~pwas_hdl.fixedpoint.memory_layout.model_layout`).
    **formats
        As above.

    Returns
    -------
    ObserverBankSensorModel
        A :class:`~pwas_hdl.fixedpoint.bank_taps.TappedObserverBankSensorModel` (a subclass)
        when the sensor also has u/y lag taps.

    Raises
    ------
    InputError
        An unknown option, an input scale other than ``pow2``, or impossible formats.
    """
    memory = model_layout(memory)
    given = {k: v for k, v in formats.items() if v is not None}
    bank = {k: given.pop(k) for k in BANK_FORMAT_OPTIONS if k in given}
    if "input_scale" in given and given["input_scale"] != "pow2":
        raise InputError(f"{option_text('input_scale')} {given['input_scale']!r} does not apply: observer-bank sensors use "
                         "the pow2 input scale of the core (their feature codes are scaled already); leave --input-scale out")
    try:
        if getattr(sensor, "lags_", None) is not None:  # u/y taps beside the features (pwas_hdl.fixedpoint.bank_taps)
            from pwas_hdl.fixedpoint.bank_taps import TappedObserverBankSensorModel

            return TappedObserverBankSensorModel.from_sensor(sensor, layout=memory, **bank, **given)
        return ObserverBankSensorModel.from_sensor(sensor, layout=memory, **bank, **given)
    except TypeError as exc:
        raise InputError(f"unknown format option for an observer-bank sensor: {exc}") from None


# ---------------------------------------------------------------------------------------------------
# Seed 003's estimator as a configuration of the bank: per-mode observers, argmin detector, switched observer
# ---------------------------------------------------------------------------------------------------
class FixedPointSwitchedEstimator:
    """Bit-true virtual estimator of seed 003 (Morales-Morales et al.; float: :func:`pwas_hdl.systems.switched_observer.run_switched_observer`).

    The same arithmetic as :class:`FixedPointObserverBank`, in general state-space form (``n``
    states per mode, ``F = A - K C``, ``G = B``, ``L = K``, ``H = C`` quantised with ``F_c``
    fraction bits, states ``s<B_s>.<F_s>`` saturating, inputs ``s<B_in>.<F_in>`` of the physical
    u, y with head room ``H``):

    * bank (8) with output injection: ``x_j' = sat((F_j x_j + (G_j qu + L_j qy) << (F_s - F_in) + 2**(F_c-1)) >> F_c)``;
    * residual ``r_j = ((qy << (F_s - F_in + F_c)) - H_j x_j + 2**(F_c-1)) >> F_c``, the window sum
      of ``r_j**2`` over ``window`` samples (running sum, exact), and the detector (9) ``theta =
      argmin_j`` by the compare tree of :mod:`pwas_hdl.fixedpoint.argmax` (``select="min"``, ties to
      the lowest mode: ``numpy.argmin`` as the float estimator);
    * the switched observer (10) with the coefficients of the detected mode; outputs per sample
      (before its update): ``x_hat`` codes, ``theta``, ``y_hat = (H_theta x + 2**(F_c-1)) >> F_c``.

    Bounds against the float estimator at the represented inputs: the residual error ``dr``
    (l1 gain of ``(F_j, I, H_j)`` times the per-step injection), the window-sum error
    ``dS = W (2 R dr + dr**2)`` (``R`` the largest residual); the detected mode equals the float one
    wherever the float detector's margin (runner-up minus best window sum) exceeds ``2 dS``; with
    the same modes, ``|x_hw - x_float| <= dx = eta / (1 - rho)`` (``rho = max_i ||F_i||_inf < 1``)
    and ``|y_hat_hw - y_hat| <= ||H||_1 dx + 2**-(F_s+1)``.

    State width: ``state_bound`` is the invariant box of :func:`switched_state_bound` over the
    quantised coefficients (every mode sequence, every input code, the rounding of each step), so
    the default ``B_s`` (the fewest bits holding ``+-ceil(state_bound * 2**F_s)``) cannot saturate the
    bank or the switched observer for inputs in the code range. The per-mode l1 gain
    (``bank_state_bound``) bounds the bank only: sized by it, a switched observer that alternates
    modes can saturate. When no box exists (the ``|F_i|`` have no common contraction),
    ``state_bound_proven`` is False, the width holds the per-mode bound and ``state_may_saturate``
    is True (manifest ``estimator.state_may_saturate``; the ``state_saturated`` output flags it).
    """

    def __init__(self, A, B, C, K, *, window: int = 1, input_bits: int = 12, input_headroom: float = 8.0,
                 coef_frac: int | None = None, state_frac: int | None = None, state_bits: int | None = None,
                 budget: float = FEATURE_BUDGET):
        self.A = [np.atleast_2d(np.asarray(a, float)) for a in A]
        self.B = [np.asarray(b, float).reshape(-1) for b in B]
        self.C = [np.asarray(c, float).reshape(-1) for c in C]
        self.K = [np.asarray(k, float).reshape(-1) for k in K]
        s, n = len(self.A), self.A[0].shape[0]
        if not (len(self.B) == len(self.C) == len(self.K) == s) or window < 1:
            raise InputError("A, B, C, K need one entry per mode and window >= 1")
        self.n_modes, self.n, self.window = s, n, int(window)
        self.input_bits = int(input_bits)
        fin = self.input_bits - 1 - max(0, math.ceil(math.log2(float(input_headroom))))
        self.input_frac = fin
        h_in = (2 ** (self.input_bits - 1)) * 2.0**-fin
        self.input_port = PortFormat(FixedFormat(self.input_bits, fin, True, "half_up", "saturate"))
        self.F = [a - np.outer(k, c) for a, k, c in zip(self.A, self.K, self.C)]
        # state bound (inputs within the code range), residual gain, switched contraction
        xb = [l1_gain(f, np.column_stack([b, k])).sum(axis=1) * h_in for f, b, k in zip(self.F, self.B, self.K)]
        self.bank_state_bound = float(np.max(xb))  # each bank observer runs one mode: its l1 gain bounds it
        self.residual_gain = max(float(np.abs(l1_gain(f.T, c[:, None])).sum()) for f, c in zip(self.F, self.C))
        self.rho = max(float(np.abs(f).sum(axis=1).max()) for f in self.F)
        # the switched observer changes mode: bound it over every mode sequence (float coefficients here,
        # to choose F_c; proven with the quantised ones below)
        inj = np.array([(np.abs(b) + np.abs(k)) * h_in for b, k in zip(self.B, self.K)])
        sw = switched_state_bound(np.array(self.F), inj)
        x0 = max(self.bank_state_bound, float(np.max(sw)) if sw is not None else 0.0) + 1.0
        target = budget * 2.0**-fin
        g = max(self.residual_gain, 1.0 / (1.0 - self.rho) if self.rho < 1 else self.residual_gain)
        fs = fin if state_frac is None else int(state_frac)
        while state_frac is None and g * 2.0 ** -(fs + 1) > target and fs < 40:
            fs += 1
        fc = 4 if coef_frac is None else int(coef_frac)
        while coef_frac is None and g * 2.0 ** -(fc + 1) * (n * x0 + 2 * h_in) > target and fc < 40:
            fc += 1
        self.state_frac, self.coef_frac = fs, fc
        q = lambda v: np.floor(np.asarray(v, float) * 2.0**fc + 0.5).astype(np.int64)  # noqa: E731
        self.f_codes = np.array([q(f) for f in self.F])  # (s, n, n)
        self.g_codes = np.array([q(b) for b in self.B])  # (s, n)
        self.l_codes = np.array([q(k) for k in self.K])
        self.h_codes = np.array([q(c) for c in self.C])
        eps = max(float(np.max(np.abs(self.f_codes * 2.0**-fc - np.array(self.F)))),
                  float(np.max(np.abs(self.g_codes * 2.0**-fc - np.array(self.B)))),
                  float(np.max(np.abs(self.l_codes * 2.0**-fc - np.array(self.K)))),
                  float(np.max(np.abs(self.h_codes * 2.0**-fc - np.array(self.C)))))
        # the state bound the width is derived from: the invariant box of the quantised arithmetic
        # (x' = F^ x + G^ u + L^ y rounded half up: |e| <= (|G^| + |L^|) h_in + 2**-(F_s+1)), which holds
        # for the bank and the switched observer whatever the detected modes, for every input code
        step = np.array([(np.abs(g) + np.abs(lc)) * 2.0**-fc * h_in + 2.0 ** -(fs + 1)
                         for g, lc in zip(self.g_codes, self.l_codes)])
        box = switched_state_bound(self.f_codes * 2.0**-fc, step)
        #: True when the box exists: the default state width then cannot saturate for inputs in range
        self.state_bound_proven = box is not None
        self.state_bound = float(np.max(box)) if box is not None else x0 - 1.0
        x0 = max(x0, self.state_bound)
        top = math.ceil(self.state_bound * 2.0**fs)
        need = signed_bits_needed(np.array([top, -top]))
        self.state_bits = int(state_bits) if state_bits is not None else int(need)
        # no proven box: the width holds the per-mode bound only and the switched observer may saturate
        self.state_may_saturate = self.state_bits < need or not self.state_bound_proven
        # bounds (normalised = physical here)
        eta = 2.0 ** -(fs + 1) + eps * (n * x0 + 2 * h_in)
        self.residual_error_bound = self.residual_gain * eta + 2.0 ** -(fs + 1) + eps * n * x0
        r_max = h_in + float(np.abs(np.array(self.C)).sum(axis=1).max()) * x0
        dr = self.residual_error_bound
        self.sum_error_bound = self.window * (2 * r_max * dr + dr * dr)
        self.state_error_bound = eta / (1.0 - self.rho) if self.rho < 1 else None
        hn = float(np.abs(np.array(self.C)).sum(axis=1).max())
        self.output_error_bound = (hn * self.state_error_bound + 2.0 ** -(fs + 1)) if self.state_error_bound is not None else None

    def quantize_signals(self, u, y) -> np.ndarray:
        """Codes (T, 2): columns u, y."""
        x = np.column_stack([np.asarray(u, float).reshape(-1), np.asarray(y, float).reshape(-1)])
        return self.input_port.quantize(x)

    def represented(self, codes) -> tuple[np.ndarray, np.ndarray]:
        p = self.input_port.to_physical(np.asarray(codes, np.int64))
        return p[:, 0], p[:, 1]

    def _step(self, fc, gc, lc, x, qu, qy, sh, lim):
        acc = x @ fc.T if x.ndim == 1 else np.einsum("jmk,jk->jm", fc, x)
        acc = acc + ((gc * qu + lc * qy) << sh) + (1 << (self.coef_frac - 1))
        r = acc >> self.coef_frac
        xs = np.clip(r, -lim, lim - 1)
        return xs, bool(np.any(xs != r))

    def trace(self, codes) -> dict[str, np.ndarray]:
        """Run from reset (all states 0): ``theta`` (T,) 1-based modes, ``x_hat`` (T, n) codes, ``y_hat`` (T,)
        codes (frac F_s), ``residual`` (T, s), ``window_sum`` (T, s), ``state_saturated`` (T,)."""
        from pwas_hdl.fixedpoint.argmax import argmax_index

        c = np.asarray(codes, np.int64)
        t_len, s, n, fc, sh = len(c), self.n_modes, self.n, self.coef_frac, self.state_frac - self.input_frac
        lim = 1 << (self.state_bits - 1)
        half = 1 << (fc - 1)
        xb = np.zeros((s, n), np.int64)
        xo = np.zeros(n, np.int64)
        res = np.empty((t_len, s), np.int64)
        xh = np.empty((t_len, n), np.int64)
        yh = np.empty(t_len, np.int64)
        th = np.empty(t_len, np.int64)
        wsum = np.empty((t_len, s), np.int64)
        sat = np.zeros(t_len, bool)
        sq_hist = np.zeros((self.window, s), np.int64)
        for k in range(t_len):
            qu, qy = c[k, 0], c[k, 1]
            yal = qy << (sh + fc)
            r = (yal - np.einsum("jm,jm->j", self.h_codes, xb) + half) >> fc
            res[k] = r
            sq_hist[k % self.window] = r * r
            wsum[k] = sq_hist.sum(axis=0)
            i = int(argmax_index(wsum[k][None, :], select="min")[0])
            th[k] = i + 1
            xh[k] = xo
            yh[k] = (int(self.h_codes[i] @ xo) + half) >> fc
            xo, s1 = self._step(self.f_codes[i], self.g_codes[i], self.l_codes[i], xo, qu, qy, sh, lim)
            xb, s2 = self._step(self.f_codes, self.g_codes, self.l_codes, xb, qu, qy, sh, lim)
            sat[k] = s1 or s2
        return {"theta": th, "x_hat": xh, "y_hat": yh, "residual": res, "window_sum": wsum, "state_saturated": sat}

    def to_physical_state(self, codes) -> np.ndarray:
        return np.asarray(codes, np.int64) * 2.0**-self.state_frac

    def reference(self, codes):
        """The float estimator (bank ``practical``) at the represented signals."""
        from pwas_hdl.systems.switched_observer import run_switched_observer

        u, y = self.represented(codes)
        return run_switched_observer(u, y, K=self.K, window=self.window, A=self.A, B=self.B, C=self.C)

    def to_dict(self) -> dict:
        return {"kind": "switched-observer", "modes": self.n_modes, "states": self.n, "window": self.window,
                "formats": {"input_bits": self.input_bits, "input_frac": self.input_frac, "coef_frac": self.coef_frac,
                            "state_bits": self.state_bits, "state_frac": self.state_frac},
                "state_bound": self.state_bound, "residual_gain": self.residual_gain, "contraction_inf_norm": self.rho,
                "error_bound": {"residual": self.residual_error_bound, "window_sum": self.sum_error_bound,
                                "state": self.state_error_bound, "y_hat": self.output_error_bound,
                                "modes": "equal to the float detector wherever its margin exceeds 2 * window_sum"}}
