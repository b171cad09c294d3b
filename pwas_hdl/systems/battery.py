"""Seed 004's Li-ion battery (E3): state of charge from current and terminal voltage.

Masti, Bernardini, Bemporad (EJC 2021), eq. (19)-(20), after Ali et al. [4]; assumption ids refer
to ``shared/design/seed-specs/seed_004.md``. Model (19)::

    dx1/dt = -i / C_c
    dx2/dt = -x2 / (R_ts(x1) C_ts(x1)) + i / C_ts(x1)
    dx3/dt = -x3 / (R_tl(x1) C_tl(x1)) + i / C_tl(x1)
    y      = E0(x1) - x2 - x3 - i R_s(x1)

    E0(s)  = -a1 exp(-a2 s) + a3 + a4 s - a5 s^2 + a6 s^3
    R_ts(s) = a7 exp(-a8 s) + a9,     R_tl(s) = a10 exp(-a11 s) + a12,
    C_ts(s) = -a13 exp(-a14 s) + a15, C_tl(s) = -a16 exp(-a17 s) + a18,
    R_s(s)  = a19 exp(-a20 s) + a21

x1 = SoC in [0, 1], x2, x3 [V] the RC voltages, i [A] (positive = discharge), y [V].

**The coefficients are a substitute (C1).** The paper takes a1..a21 from Tables 1-3 of [4],
which it does not print, and does not give C_c. :data:`SUBSTITUTE_COEFFS` holds the Chen &
Rincon-Mora (IEEE Trans. Energy Convers. 21(2), 2006) values, whose functional forms and signs
are those of (19), with ``C_c = 3060 A s`` (850 mAh). They are *not* the values of [4].

Sampling ``T_s = 5 s`` with one explicit RK4 step per sample (C2), the current constant within the
step: ``i_k = 0.2 max{0, cos(k/100) + cos(k/37)} + u_k``, ``u_k ~ U(0, 0.4)`` (20);
``x(0) = [1, 0, 0]``, and the whole state is reset to ``x(0)`` whenever the SoC falls below 0.05.

:class:`BatteryEKF` is the baseline of Section 4.10: an extended Kalman filter on the same
model with the analytic Jacobian of the RK4 step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from pwas_hdl.errors import InputError, ResourceLimit
from pwas_hdl.limits import check_seed
from pwas_hdl.systems.lorenz import PlantData

if TYPE_CHECKING:
    from pwas_hdl.systems.normalization import Normalization

__all__ = ["SUBSTITUTE_COEFFS", "TS", "X0", "battery", "battery_current", "BatteryModel", "BatteryEKF", "make_battery_dataset"]

#: a1..a21 and C_c [A s]: Chen & Rincon-Mora 2006, a SUBSTITUTE for [4]'s (unprinted) values (C1).
SUBSTITUTE_COEFFS = {
    "a1": 1.031, "a2": 35.0, "a3": 3.685, "a4": 0.2156, "a5": 0.1178, "a6": 0.3201,
    "a7": 0.3208, "a8": 29.14, "a9": 0.04669,
    "a10": 6.603, "a11": 155.2, "a12": 0.04984,
    "a13": 752.9, "a14": 13.51, "a15": 703.6,
    "a16": 6056.0, "a17": 27.12, "a18": 4475.0,
    "a19": 0.1562, "a20": 24.37, "a21": 0.07446,
    "Cc": 3060.0,
}
TS = 5.0  #: sampling period [s] (f_s = 1/5 Hz)
X0 = np.array([1.0, 0.0, 0.0])  #: initial (and reset) state
RESET_SOC = 0.05
MAX_SAMPLES = 2_000_000


class BatteryModel:
    """Model (19) with its analytic derivatives, for the simulator and the EKF.

    Parameters
    ----------
    coeffs : dict, optional
        ``a1 .. a21`` and ``Cc``; default :data:`SUBSTITUTE_COEFFS`.
    """

    def __init__(self, coeffs: dict | None = None):
        self.c = dict(SUBSTITUTE_COEFFS if coeffs is None else coeffs)

    # each element function returns (value, d value / d x1)
    def _exp_term(self, s, amp, rate, off, sign=1.0):
        e = np.exp(-rate * s)
        return sign * amp * e + off, -sign * amp * rate * e

    def e0(self, s: float | np.ndarray) -> tuple[float | np.ndarray, float | np.ndarray]:
        """Open-circuit voltage ``E0(s) = -a1 exp(-a2 s) + a3 + a4 s - a5 s^2 + a6 s^3`` and its derivative.

        Parameters
        ----------
        s : float or ndarray
            State of charge ``x1`` (nominally in [0, 1], dimensionless): a scalar or an array of any shape.

        Returns
        -------
        value : float or ndarray, shape of ``s``
            The value [V].
        derivative : float or ndarray, shape of ``s``
            ``d value / d s`` [V per unit SoC].
        """
        c = self.c
        e = np.exp(-c["a2"] * s)
        val = -c["a1"] * e + c["a3"] + c["a4"] * s - c["a5"] * s**2 + c["a6"] * s**3
        der = c["a1"] * c["a2"] * e + c["a4"] - 2 * c["a5"] * s + 3 * c["a6"] * s**2
        return val, der

    def rts(self, s: float | np.ndarray) -> tuple[float | np.ndarray, float | np.ndarray]:
        """Short transient resistance ``R_ts(s) = a7 exp(-a8 s) + a9`` and its derivative.

        Parameters
        ----------
        s : float or ndarray
            State of charge ``x1`` (nominally in [0, 1], dimensionless): a scalar or an array of any shape.

        Returns
        -------
        value : float or ndarray, shape of ``s``
            The value [Ohm].
        derivative : float or ndarray, shape of ``s``
            ``d value / d s`` [Ohm per unit SoC].
        """
        return self._exp_term(s, self.c["a7"], self.c["a8"], self.c["a9"])

    def rtl(self, s: float | np.ndarray) -> tuple[float | np.ndarray, float | np.ndarray]:
        """Long transient resistance ``R_tl(s) = a10 exp(-a11 s) + a12`` and its derivative.

        Parameters
        ----------
        s : float or ndarray
            State of charge ``x1`` (nominally in [0, 1], dimensionless): a scalar or an array of any shape.

        Returns
        -------
        value : float or ndarray, shape of ``s``
            The value [Ohm].
        derivative : float or ndarray, shape of ``s``
            ``d value / d s`` [Ohm per unit SoC].
        """
        return self._exp_term(s, self.c["a10"], self.c["a11"], self.c["a12"])

    def cts(self, s: float | np.ndarray) -> tuple[float | np.ndarray, float | np.ndarray]:
        """Short transient capacitance ``C_ts(s) = -a13 exp(-a14 s) + a15`` and its derivative.

        Parameters
        ----------
        s : float or ndarray
            State of charge ``x1`` (nominally in [0, 1], dimensionless): a scalar or an array of any shape.

        Returns
        -------
        value : float or ndarray, shape of ``s``
            The value [F].
        derivative : float or ndarray, shape of ``s``
            ``d value / d s`` [F per unit SoC].
        """
        return self._exp_term(s, self.c["a13"], self.c["a14"], self.c["a15"], -1.0)

    def ctl(self, s: float | np.ndarray) -> tuple[float | np.ndarray, float | np.ndarray]:
        """Long transient capacitance ``C_tl(s) = -a16 exp(-a17 s) + a18`` and its derivative.

        Parameters
        ----------
        s : float or ndarray
            State of charge ``x1`` (nominally in [0, 1], dimensionless): a scalar or an array of any shape.

        Returns
        -------
        value : float or ndarray, shape of ``s``
            The value [F].
        derivative : float or ndarray, shape of ``s``
            ``d value / d s`` [F per unit SoC].
        """
        return self._exp_term(s, self.c["a16"], self.c["a17"], self.c["a18"], -1.0)

    def rs(self, s: float | np.ndarray) -> tuple[float | np.ndarray, float | np.ndarray]:
        """Series resistance ``R_s(s) = a19 exp(-a20 s) + a21`` and its derivative.

        Parameters
        ----------
        s : float or ndarray
            State of charge ``x1`` (nominally in [0, 1], dimensionless): a scalar or an array of any shape.

        Returns
        -------
        value : float or ndarray, shape of ``s``
            The value [Ohm].
        derivative : float or ndarray, shape of ``s``
            ``d value / d s`` [Ohm per unit SoC].
        """
        return self._exp_term(s, self.c["a19"], self.c["a20"], self.c["a21"])

    def f(self, x: np.ndarray, i: float) -> tuple[np.ndarray, np.ndarray]:
        """Right-hand side of (19) and its Jacobian d f / d x, shapes (3,) and (3, 3).

        Parameters
        ----------
        x : ndarray, shape (3,)
            State ``(SoC, v_ts [V], v_tl [V])``.
        i : float
            Current [A] (positive = discharge).

        Returns
        -------
        f : ndarray, shape (3,)
            ``dx/dt``: [1/s], [V/s], [V/s].
        jac : ndarray, shape (3, 3)
            ``d f / d x``: entry (r, c) in units of ``f_r`` per unit of ``x_c`` (row 0 is zero).
        """
        s, x2, x3 = x
        rts, drts = self.rts(s)
        cts, dcts = self.cts(s)
        rtl, drtl = self.rtl(s)
        ctl, dctl = self.ctl(s)
        f = np.array([-i / self.c["Cc"], -x2 / (rts * cts) + i / cts, -x3 / (rtl * ctl) + i / ctl])
        jac = np.zeros((3, 3))
        jac[1, 0] = x2 * (drts * cts + rts * dcts) / (rts * cts) ** 2 - i * dcts / cts**2
        jac[1, 1] = -1.0 / (rts * cts)
        jac[2, 0] = x3 * (drtl * ctl + rtl * dctl) / (rtl * ctl) ** 2 - i * dctl / ctl**2
        jac[2, 2] = -1.0 / (rtl * ctl)
        return f, jac

    def rk4(self, x: np.ndarray, i: float, h: float = TS) -> tuple[np.ndarray, np.ndarray]:
        """One explicit RK4 step and its exact Jacobian (chain rule through the four stages).

        Parameters
        ----------
        x : ndarray, shape (3,)
            State ``(SoC, v_ts [V], v_tl [V])``.
        i : float
            Current [A], constant over the step.
        h : float
            Step [s].

        Returns
        -------
        x_next : ndarray, shape (3,)
            The next state.
        jac : ndarray, shape (3, 3)
            ``d x_next / d x``: entry (r, c) in units of ``x_r`` per unit of ``x_c``.
        """
        k1, j1 = self.f(x, i)
        k2, j2 = self.f(x + 0.5 * h * k1, i)
        k3, j3 = self.f(x + 0.5 * h * k2, i)
        k4, j4 = self.f(x + h * k3, i)
        eye = np.eye(3)
        d1 = j1
        d2 = j2 @ (eye + 0.5 * h * d1)
        d3 = j3 @ (eye + 0.5 * h * d2)
        d4 = j4 @ (eye + h * d3)
        return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), eye + h / 6 * (d1 + 2 * d2 + 2 * d3 + d4)

    def step(self, x: np.ndarray, i: float, h: float = TS) -> np.ndarray:
        """One explicit RK4 step without the Jacobian (the simulator's): the same floating-point
        operations in the same order as :meth:`rk4`'s state, element by element on scalars (bitwise
        the same result; about 5x faster than building the Jacobians it does not need).

        Parameters
        ----------
        x : ndarray, shape (3,)
            State ``(SoC, v_ts [V], v_tl [V])``.
        i : float
            Current [A], constant over the step.
        h : float
            Step [s].

        Returns
        -------
        ndarray, shape (3,)
            The next state.
        """
        c = self.c
        cc, exp = c["Cc"], np.exp
        a7, a8, a9, a10, a11, a12 = c["a7"], c["a8"], c["a9"], c["a10"], c["a11"], c["a12"]
        m13, a14, a15, m16, a17, a18 = -1.0 * c["a13"], c["a14"], c["a15"], -1.0 * c["a16"], c["a17"], c["a18"]
        k0 = -i / cc  # f's first component does not depend on the state

        def rhs(s, x2, x3):
            rts = a7 * exp(-a8 * s) + a9
            cts = m13 * exp(-a14 * s) + a15
            rtl = a10 * exp(-a11 * s) + a12
            ctl = m16 * exp(-a17 * s) + a18
            return -x2 / (rts * cts) + i / cts, -x3 / (rtl * ctl) + i / ctl

        s, x2, x3 = x
        hh = 0.5 * h
        k2a, k3a = rhs(s, x2, x3)
        k2b, k3b = rhs(s + hh * k0, x2 + hh * k2a, x3 + hh * k3a)
        k2c, k3c = rhs(s + hh * k0, x2 + hh * k2b, x3 + hh * k3b)
        k2d, k3d = rhs(s + h * k0, x2 + h * k2c, x3 + h * k3c)
        w = h / 6
        return np.array([s + w * (k0 + 2 * k0 + 2 * k0 + k0), x2 + w * (k2a + 2 * k2b + 2 * k2c + k2d),
                         x3 + w * (k3a + 2 * k3b + 2 * k3c + k3d)])

    def output(self, x: np.ndarray, i: float) -> tuple[float, np.ndarray]:
        """Terminal voltage y [V] and its gradient d y / d x, shape (3,).

        Parameters
        ----------
        x : ndarray, shape (3,)
            State ``(SoC, v_ts [V], v_tl [V])``.
        i : float
            Current [A] (positive = discharge).

        Returns
        -------
        y : float
            ``E0(x1) - x2 - x3 - i R_s(x1)`` [V].
        grad : ndarray, shape (3,)
            ``d y / d x``: [V per unit SoC], -1, -1.
        """
        e0, de0 = self.e0(x[0])
        rs, drs = self.rs(x[0])
        return float(e0 - x[1] - x[2] - i * rs), np.array([de0 - i * drs, -1.0, -1.0])


def battery_current(n_samples: int, rng: np.random.Generator) -> np.ndarray:
    """Eq. (20): ``i_k = 0.2 max{0, cos(k/100) + cos(k/37)} + u_k``, ``u_k ~ U(0, 0.4)`` [A].

    Parameters
    ----------
    n_samples : int
        Samples T (``k = 0 .. T-1``, ``T_s = 5 s`` apart).
    rng : numpy.random.Generator
        Draws the T values ``u_k``.

    Returns
    -------
    ndarray, shape (n_samples,)
        The current ``i_k`` [A] (positive = discharge).
    """
    k = np.arange(n_samples)
    return 0.2 * np.maximum(0.0, np.cos(k / 100.0) + np.cos(k / 37.0)) + rng.uniform(0.0, 0.4, n_samples)


def battery(n_samples: int, seed: int = 0, coeffs: dict | None = None) -> PlantData:
    """Noise-free battery data: current ``i``, terminal voltage ``v``, state of charge ``soc``.

    Parameters
    ----------
    n_samples : int
        Samples, ``T_s = 5 s`` apart.
    seed : int
        Seed of the random part of the current (20).
    coeffs : dict, optional
        Model coefficients (default: the substitute :data:`SUBSTITUTE_COEFFS`, C1).

    Returns
    -------
    PlantData
        ``u`` (T, 1) named ``i`` [A]; ``y`` (T, 1) named ``v`` [V]; ``z = z_true`` (T, 1) named
        ``soc`` (SoC at the sample instant, before the step). ``reset`` is not a column: a reset is
        visible as a jump of ``soc`` back to 1.
    """
    if not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise InputError(f"the number of samples must be an integer >= 1, got {n_samples!r}")
    if n_samples > MAX_SAMPLES:
        raise ResourceLimit(f"{n_samples} samples requested; the limit is {MAX_SAMPLES}")
    model = BatteryModel(coeffs)
    cur = battery_current(n_samples, np.random.default_rng(seed))
    x = X0.copy()
    v = np.empty(n_samples)
    soc = np.empty(n_samples)
    for k in range(n_samples):
        soc[k] = x[0]
        v[k], _ = model.output(x, cur[k])
        x = model.step(x, cur[k])  # rk4's state, without the Jacobian
        if x[0] < RESET_SOC:
            x = X0.copy()
    return PlantData(cur[:, None], v[:, None], soc[:, None].copy(), soc[:, None].copy(), {"u": ["i"], "y": ["v"], "z": ["soc"]})


def make_battery_dataset(n_train: int, n_test: int, seed: int = 0,
                         noise: float = 0.03) -> tuple[PlantData, PlantData, Normalization]:
    """Training and test sets as in Section 4.10 / 4.2: independent runs, normalised, noisy (C3).

    Parameters
    ----------
    n_train, n_test : int
        Samples of each set (``T_s = 5 s`` apart).
    seed : int
        One run: the battery seeds of both sets and the noise are drawn from it.
    noise : float
        Noise std after normalisation (normalised units; paper 0.03), on ``u``, ``y`` and ``z``.

    Returns
    -------
    train, test : PlantData
        ``u`` (T, 1) current, ``y`` (T, 1) voltage, ``z`` (T, 1) SoC, normalised with the training
        statistics and noisy; ``z_true`` normalised and noise-free.
    norm : Normalization
        The training statistics (physical units: [A], [V], SoC).
    """
    from pwas_hdl.systems.normalization import normalize_with_noise

    check_seed(seed)
    ss = np.random.SeedSequence(seed)
    s_train, s_test, s_noise = (int(s.generate_state(1)[0]) for s in ss.spawn(3))
    tr = battery(n_train, s_train)
    te = battery(n_test, s_test)
    trn, (ten,), norm = normalize_with_noise(tr, [te], noise, np.random.default_rng(s_noise), True)
    return trn, ten, norm


@dataclass
class EKFSetting:
    """One tuning of the EKF: process noise ``Q = diag(q)`` (state units^2 per step) and ``R`` [V^2]."""

    name: str
    q: tuple[float, float, float]
    r: float


class BatteryEKF:
    """Extended Kalman filter on model (19) (the baseline of Section 4.10).

    Discrete model: ``x_{k+1} = RK4(x_k, i_k) + w_k``, ``w_k ~ N(0, Q)``;
    ``y_k = g(x_k, i_k) + v_k``, ``v_k ~ N(0, R)``. The Jacobians are analytic
    (:meth:`BatteryModel.rk4`, :meth:`BatteryModel.output`). The filter knows nothing of the
    resets of the simulated battery: it has to track the jump of SoC back to 1 through its gain.

    Parameters
    ----------
    q : sequence of 3 float
        Diagonal of Q.
    r : float
        Measurement noise variance R [V^2].
    x0 : ndarray (3,), optional
        Initial estimate (default ``x(0) = [1, 0, 0]``).
    p0 : sequence of 3 float
        Diagonal of the initial covariance.
    coeffs : dict, optional
        Model coefficients (default the substitute of C1, the same as the simulator).
    """

    def __init__(self, q: Sequence[float], r: float, x0: np.ndarray | None = None,
                 p0: Sequence[float] = (1e-2, 1e-4, 1e-4), coeffs: dict | None = None):
        self.q = np.diag(np.asarray(q, dtype=float))
        self.r = float(r)
        if self.r <= 0 or np.any(np.diag(self.q) < 0):
            raise InputError("EKF: R must be > 0 and Q's diagonal >= 0")
        self.x0 = X0.copy() if x0 is None else np.asarray(x0, dtype=float)
        self.p0 = np.diag(np.asarray(p0, dtype=float))
        self.model = BatteryModel(coeffs)

    def run(self, current: np.ndarray, voltage: np.ndarray) -> np.ndarray:
        """Filtered state estimates for every sample.

        Parameters
        ----------
        current : ndarray (T,) [A]
            Measured current (the model input).
        voltage : ndarray (T,) [V]
            Measured terminal voltage.

        Returns
        -------
        ndarray, shape (T, 3)
            ``x_hat_{k|k}``; column 0 is the SoC estimate.
        """
        current = np.asarray(current, dtype=float).reshape(-1)
        voltage = np.asarray(voltage, dtype=float).reshape(-1)
        x = self.x0.copy()
        p = self.p0.copy()
        out = np.empty((current.size, 3))
        for k in range(current.size):
            yh, g = self.model.output(x, current[k])
            s = g @ p @ g + self.r
            kg = p @ g / s
            x = x + kg * (voltage[k] - yh)
            p = p - np.outer(kg, g @ p)
            out[k] = x
            x, fj = self.model.rk4(x, current[k])
            p = fj @ p @ fj.T + self.q
        return out
