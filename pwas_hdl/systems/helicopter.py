"""A synthetic closed-loop 2-DOF helicopter: the stand-in for the CE150 plant of the seed paper.

The paper's Section VI-B estimates the elevation of a laboratory helicopter (Humusoft CE150) from
its references and its measured azimuth; that data is not available, so this module simulates a
plant of the same structure and size (Table VI: ``Mu = 2`` with ``nu = 2``, ``My = 2`` with
``ny = 1``). Only the structure matches the paper; the numbers are not the CE150's.

Plant (continuous time, integrated with RK4)
--------------------------------------------
Elevation ``psi`` and azimuth ``phi`` (rad); two propellers whose speeds ``w1``, ``w2`` follow
their commands with a first-order lag ``tm = 0.1 s``; main rotor torque ``tau1 = k1 w1^2``:

* ``I1 psi'' = tau1 + ml2 phi'^2 sin psi cos psi - c1 tanh(psi'/0.05) - b1 psi' - mgl sin psi
  - kG phi' tau1 cos psi`` (centrifugal term, Coulomb and viscous friction, gravity, gyroscopic
  coupling);
* ``I2 (0.4 + 0.6 cos^2 psi) phi'' = k2 w2 |w2| - c2 tanh(phi'/0.05) - b2 phi' - kr tau1``
  (tail rotor, friction, the main motor's reaction torque; the azimuth inertia depends on ``psi``).

Control: two PID loops (the elevation one with gravity feed-forward ``sqrt(mgl sin psi_d / k1)``),
commands clipped to ``[0, 3]`` and ``[-3, 3]``, tracking references ``psi_d``, ``phi_d`` that are
random steps (held 2-6 s and 2-8 s, in ``[0.05, 0.75]`` and ``[-1.2, 1.2]`` rad) through a 0.5 s
first-order prefilter.

Sampling: every ``dt = 10 ms`` (``substeps`` RK4 steps per sample); ``burn_in`` samples dropped.
Measurement noise: Gaussian, standard deviation 0.01 rad on ``phi`` and on ``psi``.
"""

from __future__ import annotations

import math

import numpy as np

from pwas_hdl.errors import InputError
from pwas_hdl.limits import check_seed
from pwas_hdl.systems.lorenz import PlantData

__all__ = ["helicopter", "HELICOPTER_PARAMS"]

#: Physical constants, controller gains and noise of the synthetic plant (SI units, rad).
HELICOPTER_PARAMS = {
    "i1": 0.05, "i2": 0.06, "mgl": 0.5, "ml2": 0.02, "k1": 1.0, "k2": 0.4, "kr": 0.08,
    "b1": 0.08, "b2": 0.05, "c1": 0.01, "c2": 0.01, "kg": 0.05, "tm": 0.1,
    "kp1": 4.0, "ki1": 2.0, "kd1": 1.2, "kp2": 2.5, "ki2": 0.8, "kd2": 1.0,
    "prefilter_s": 0.5, "noise_phi": 0.01, "noise_psi": 0.01,
}


def helicopter(n_samples: int, seed: int = 0, dt: float = 0.01, substeps: int = 10, burn_in: int = 500) -> PlantData:
    """Simulate the synthetic closed-loop helicopter (see the module docstring).

    Parameters
    ----------
    n_samples : int
        Samples returned (after the burn-in), ``>= 1``.
    seed : int
        Seed of the reference steps and of the measurement noise (``numpy.random.default_rng``).
    dt : float
        Sample time in seconds (default 0.01).
    substeps : int
        RK4 steps per sample (default 10).
    burn_in : int
        Samples simulated and dropped first (default 500).

    Returns
    -------
    PlantData
        ``u`` (T, 2) the references ``psi_d``, ``phi_d`` (rad); ``y`` (T, 1) the measured azimuth
        ``phi`` (+ noise); ``z`` (T, 1) the measured elevation ``psi`` (+ noise), the quantity to
        estimate; ``z_true`` (T, 1) the noise-free ``psi``. Column names ``psi_d``, ``phi_d``,
        ``phi``, ``psi``.
    """
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise InputError(f"n_samples must be an integer >= 1, got {n_samples!r}")
    if not (dt > 0 and substeps >= 1 and burn_in >= 0):
        raise InputError(f"need dt > 0, substeps >= 1 and burn_in >= 0, got dt={dt!r}, substeps={substeps!r}, burn_in={burn_in!r}")
    check_seed(seed)
    prm = HELICOPTER_PARAMS
    rng = np.random.default_rng(seed)
    total = int(n_samples) + int(burn_in)

    def steps(lo, hi, tmin, tmax):
        r = np.empty(total)
        t = 0
        while t < total:
            k = int(rng.uniform(tmin, tmax) / dt)
            r[t : t + k] = rng.uniform(lo, hi)
            t += k
        return r

    psi_r, phi_r = steps(0.05, 0.75, 2.0, 6.0), steps(-1.2, 1.2, 2.0, 8.0)
    a = dt / prm["prefilter_s"]
    psi_d, phi_d = np.empty(total), np.empty(total)
    pd, fd = psi_r[0], phi_r[0]
    for t in range(total):
        pd += a * (psi_r[t] - pd)
        fd += a * (phi_r[t] - fd)
        psi_d[t], phi_d[t] = pd, fd
    i1, i2, mgl, ml2, k1, k2, kr = (prm[k] for k in ("i1", "i2", "mgl", "ml2", "k1", "k2", "kr"))
    b1, b2, c1, c2, kg, tm = (prm[k] for k in ("b1", "b2", "c1", "c2", "kg", "tm"))
    kp1, ki1, kd1, kp2, ki2, kd2 = (prm[k] for k in ("kp1", "ki1", "kd1", "kp2", "ki2", "kd2"))

    def f(x, pd, fd):
        psi, dpsi, phi, dphi, w1, w2, e1i, e2i = x
        e1, e2 = pd - psi, fd - phi
        v1 = math.sqrt(max(mgl * math.sin(pd), 0.0) / k1) + kp1 * e1 + ki1 * e1i - kd1 * dpsi
        v2 = kp2 * e2 + ki2 * e2i - kd2 * dphi
        v1, v2 = min(max(v1, 0.0), 3.0), min(max(v2, -3.0), 3.0)
        tau1 = k1 * w1 * w1
        ddpsi = (tau1 + ml2 * dphi**2 * math.sin(psi) * math.cos(psi) - c1 * math.tanh(dpsi / 0.05) - b1 * dpsi
                 - mgl * math.sin(psi) - kg * dphi * tau1 * math.cos(psi)) / i1
        ddphi = (k2 * w2 * abs(w2) - c2 * math.tanh(dphi / 0.05) - b2 * dphi - kr * tau1) / (i2 * (0.4 + 0.6 * math.cos(psi) ** 2))
        return np.array([dpsi, ddpsi, dphi, ddphi, (v1 - w1) / tm, (v2 - w2) / tm, e1, e2])

    x = np.zeros(8)
    x[0] = psi_d[0]
    x[4] = math.sqrt(mgl * math.sin(psi_d[0]) / k1)
    out = np.empty((total, 2))
    h = dt / substeps
    for t in range(total):
        out[t] = x[0], x[2]
        pd, fd = psi_d[t], phi_d[t]
        for _ in range(substeps):
            s1 = f(x, pd, fd)
            s2 = f(x + h / 2 * s1, pd, fd)
            s3 = f(x + h / 2 * s2, pd, fd)
            s4 = f(x + h * s3, pd, fd)
            x = x + h / 6 * (s1 + 2 * s2 + 2 * s3 + s4)
    s = slice(burn_in, None)
    u = np.stack([psi_d, phi_d], 1)[s]
    psi, phi = out[s, 0:1], out[s, 1:2]
    y = phi + rng.normal(0, prm["noise_phi"], phi.shape)
    z = psi + rng.normal(0, prm["noise_psi"], psi.shape)
    return PlantData(u, y, z, psi.copy(), {"u": ["psi_d", "phi_d"], "y": ["phi"], "z": ["psi"]})
