"""The virtual sensors of seed 001 (Sergiyenko et al. 2023): eqs. (27), (28) and the Section 3 design.

The plant is written in the logic-dynamic form (12) of Section 3::

    x(t+1) = A x(t) + B u(t) + G Phi(x(t)) + D rho(t),   y(t) = C x(t),
    Phi(x) = [phi(F_1 x), ..., phi(F_q x)],  phi(s) = sq(s) - s   (sq: signed root, A1)

and the quantity to estimate is ``v = V x``. :func:`design_virtual_sensor` follows the paper's
procedure for ``k = 1`` (one state per subsystem, ``A* = 0`` in the canonical form):

1. ``D0`` of maximal rank with ``D0 D = 0``; ``(N1 N2) [D0; C] = 0`` (14) gives the measured
   combination insensitive to the disturbance, ``C0 = N2 C``.
2. Eq. (21) with ``k = 1``: ``(Psi, -J*) [[A, D], [C*, 0]] = 0`` with ``C* = [C; V]``, i.e.
   ``Psi A = J* C*`` and ``Psi D = 0``. The solutions form the left null space; a canonical basis
   (reduced row echelon form) is taken and the rows in the row space of ``C`` (already measured)
   are dropped. The condition of solvability is (22): ``rank < n + (l + p) k``.
3. Conditions (18) ``rank [Psi; C*] = rank [Psi; C*; F_bar]`` (``F_bar``: the ``F_j`` of the
   nonzero columns of ``G* = Psi G``) and (20) ``rank [Psi; C0] = rank [Psi; C0; V_i]`` for each
   row ``V_i``. Rows that satisfy (20) form ``V_bar`` (estimated by the disturbance-insensitive
   *first subsystem*); the others ``V0`` (Section 3.2, the *second subsystem*, sensitive to rho).
4. Each subsystem is ``z(t+1) = a z(t) + J s(t) + B* u(t) + G* Phi(F* [z; s])`` where ``s`` holds
   the signals the subsystem may use: the measured ``y`` and, for a second subsystem, the states
   of the first ones. ``(a, J)`` solve ``Psi A = a Psi + J S`` (with ``a = 0`` when ``J`` alone
   suffices, as (15)), ``B* = Psi B``, ``G* = Psi G`` and ``F*_j`` solves
   ``F_j = F*_j [Psi; S]`` (17)/(23), preferring the measured signals.

For the three-tank matrices of Section 5 this reproduces the paper: ``Psi = (0 0 1)``,
``J* = (a2, 0, 1 - a2 - a3)``, (18) holds and (20) does not, ``V_bar = (0 0 1)``,
``V0 = (1 0 0)``, ``G* = (0, a2, -a3)``, ``F_bar = [[0, 1, -1], [0, 0, 1]]``,
``F* = [[-1, 1, 0, 0], [1, 0, 0, 0]]`` and the nonlinear models (28) and (27) (tested).
Only ``k = 1`` is implemented: a system that needs ``k > 1`` is refused with an error.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import null_space

from pwas_hdl.errors import InputError
from pwas_hdl.systems.three_tank import THREE_TANK_PARAMS, signed_sqrt

__all__ = [
    "LogicDynamicSystem",
    "Subsystem",
    "SensorDesign",
    "three_tank_logic_dynamic",
    "design_virtual_sensor",
    "simulate_design",
    "paper_sensors",
    "observer_map_27",
    "observer_map_28",
]

_TOL = 1e-9


def _phi(s: ArrayLike) -> np.ndarray:
    """The nonlinearity of the three-tank rewrite: ``sq(s) - s`` (signed root, A1).

    Parameters
    ----------
    s : array_like, any shape (a scalar too)
        Values ``F_j x`` (level differences or levels, the plant's level unit).

    Returns
    -------
    numpy.ndarray
        Float array of the shape of ``s`` (0-d for a scalar).
    """
    return signed_sqrt(s) - np.asarray(s, dtype=float)


@dataclass
class LogicDynamicSystem:
    """Matrices of form (12) of the paper.

    Given as nested lists or arrays; stored as float arrays of at least two dimensions (a shape
    mismatch with ``n = A.shape[0]`` raises :class:`~pwas_hdl.errors.InputError`).

    Attributes
    ----------
    A : numpy.ndarray, shape (n, n)
        State matrix.
    B : numpy.ndarray, shape (n, m)
        Input matrix.
    C : numpy.ndarray, shape (l, n)
        Output matrix: ``y = C x``.
    D : numpy.ndarray, shape (n, d)
        Disturbance matrix (``rho`` of dimension d).
    G : numpy.ndarray, shape (n, q)
        Weights of the nonlinear terms ``Phi(x)``.
    F : numpy.ndarray, shape (q, n)
        Row ``j`` is ``F_j``: the argument ``F_j x`` of the j-th nonlinear term.
    V : numpy.ndarray, shape (p, n)
        The estimated quantity ``v = V x``.
    phi : callable
        Elementwise nonlinearity applied to ``F_j x`` (:func:`simulate_design` calls it on one scalar
        at a time and takes ``float`` of the result; default ``sq(s) - s``).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    G: np.ndarray
    F: np.ndarray
    V: np.ndarray
    phi: Callable[[ArrayLike], np.ndarray] = _phi

    def __post_init__(self) -> None:
        for k in ("A", "B", "C", "D", "G", "F", "V"):
            setattr(self, k, np.atleast_2d(np.asarray(getattr(self, k), dtype=float)))
        n = self.A.shape[0]
        shapes = {"A": (n, n), "B": (n, None), "C": (None, n), "D": (n, None), "G": (n, self.F.shape[0]),
                  "F": (None, n), "V": (None, n)}
        for k, (r, c) in shapes.items():
            a = getattr(self, k)
            if (r is not None and a.shape[0] != r) or (c is not None and a.shape[1] != c):
                raise InputError(f"matrix {k} has shape {a.shape}; expected ({r or '*'}, {c or '*'}) for n = {n}")


@dataclass
class Subsystem:
    """One scalar model ``z(t+1) = a z + J s + B* u + G* Phi(F* [z; s])`` (``k = 1``).

    Attributes
    ----------
    psi : numpy.ndarray, shape (n,)
        The estimated combination: ``z = psi x``.
    a : float
        Coefficient of the own state.
    J : numpy.ndarray, shape (ns,)
        Coefficients of the signals ``s``.
    signals : list of str
        What ``s`` holds: ``"y0"``, ``"y1"``... (measured) and ``"z:i"`` (state of subsystem ``i``).
    B_star : numpy.ndarray, shape (m,)
        ``psi B``.
    G_star : numpy.ndarray, shape (q,)
        ``psi G``.
    F_star : dict of int to numpy.ndarray
        ``j`` -> row ``F*_j``, shape (1 + ns,), over ``[z; s]``, for the nonzero columns j of ``G*``.
    insensitive : bool
        ``psi D = 0`` (first subsystem) or not (second subsystem, Section 3.2).
    """

    psi: np.ndarray
    a: float
    J: np.ndarray
    signals: list
    B_star: np.ndarray
    G_star: np.ndarray
    F_star: dict
    insensitive: bool


@dataclass
class SensorDesign:
    """The result of :func:`design_virtual_sensor`.

    Attributes
    ----------
    subsystems : list of Subsystem
        First the insensitive ones, then the sensitive ones.
    C0 : numpy.ndarray, shape (l0, n)
        The measured combination insensitive to rho (14).
    psi_solutions : numpy.ndarray, shape (r, n)
        Canonical basis of the ``Psi`` of (21) (k = 1), measured rows dropped.
    J_star : numpy.ndarray, shape (r, l + p)
        The ``J*`` of each such ``Psi`` (``Psi A = J* C*``).
    cond18 : bool
        Condition (18) holds.
    cond20 : list of bool
        Condition (20), one per row of V.
    V_bar, V0 : numpy.ndarray, shape (p_bar, n) and (p - p_bar, n)
        The rows of V that satisfy (20) / that do not.
    estimates : list of int
        Per row of V, the index of the subsystem whose state estimates it.
    """

    subsystems: list
    C0: np.ndarray
    psi_solutions: np.ndarray
    J_star: np.ndarray
    cond18: bool
    cond20: list
    V_bar: np.ndarray
    V0: np.ndarray
    estimates: list = field(default_factory=list)


def _rank(M: np.ndarray) -> int:
    return int(np.linalg.matrix_rank(M, tol=_TOL)) if M.size else 0


def _rref(M: np.ndarray) -> np.ndarray:
    """Reduced row echelon form (numerical), zero rows dropped."""
    R = np.array(M, dtype=float)
    rows, cols = R.shape
    r = 0
    for c in range(cols):
        if r >= rows:
            break
        p = r + int(np.argmax(np.abs(R[r:, c])))
        if abs(R[p, c]) < _TOL:
            continue
        R[[r, p]] = R[[p, r]]
        R[r] /= R[r, c]
        for i in range(rows):
            if i != r:
                R[i] -= R[i, c] * R[r]
        r += 1
    R[np.abs(R) < _TOL] = 0.0
    return R[:r]


def _exact_solve(target: np.ndarray, basis: np.ndarray) -> np.ndarray | None:
    """``x`` with ``x @ basis = target`` exactly (least squares, then checked), or None."""
    if basis.size == 0:
        return None
    x, *_ = np.linalg.lstsq(basis.T, target, rcond=None)
    return x if np.allclose(x @ basis, target, atol=1e-9) else None


def _in_rowspace(v: np.ndarray, M: np.ndarray) -> bool:
    return _rank(np.vstack([M, v])) == _rank(M)


def _subsystem(sys_: LogicDynamicSystem, psi: np.ndarray, S: np.ndarray, names: list, insensitive: bool) -> Subsystem:
    """Coefficients of one scalar model over the signals ``S`` (rows = signal as a row of x)."""
    target = psi @ sys_.A
    J = _exact_solve(target, S)
    a = 0.0
    if J is None:  # keep the own state (A* != 0): Psi A = a Psi + J S
        sol = _exact_solve(target, np.vstack([psi, S]))
        if sol is None:
            raise InputError(f"no model of z = {psi.tolist()} x over the available signals: Psi A is not a combination of "
                             "Psi and the measured/estimated signals (k = 1); this system needs k > 1, which is not implemented")
        a, J = float(sol[0]), sol[1:]
    G_star = psi @ sys_.G
    F_star = {}
    for j in np.flatnonzero(np.abs(G_star) > _TOL):
        basis = np.vstack([psi, S])
        # prefer the measured signals: try [psi; measured] first, then everything (17)/(23)
        meas = [i for i, nm in enumerate(names) if nm.startswith("y")]
        f = _exact_solve(sys_.F[j], np.vstack([psi, S[meas]])) if meas else None
        if f is not None:
            full = np.zeros(1 + S.shape[0])
            full[0] = f[0]
            full[1 + np.array(meas)] = f[1:]
            f = full
        else:
            f = _exact_solve(sys_.F[j], basis)
        if f is None:
            raise InputError(f"condition (18) fails for F_{j + 1} = {sys_.F[j].tolist()}: it is not a combination of Psi and the signals")
        F_star[int(j)] = f
    return Subsystem(psi, a, J, names, psi @ sys_.B, G_star, F_star, insensitive)


def design_virtual_sensor(sys_: LogicDynamicSystem) -> SensorDesign:
    """The Section 3 design procedure (k = 1): see the module docstring.

    Parameters
    ----------
    sys_ : LogicDynamicSystem
        The plant in form (12), with the estimated rows ``V``.

    Returns
    -------
    SensorDesign
        The subsystems, the conditions (18)/(20) and which subsystem estimates each row of ``V``.

    Raises
    ------
    InputError
        (21) has no solution with k = 1 outside the measured rows, or a model cannot be formed.
    """
    A, C, D, V = sys_.A, sys_.C, sys_.D, sys_.V
    n, l, p = A.shape[0], C.shape[0], V.shape[0]
    D0 = null_space(D.T).T  # rows with D0 D = 0, maximal rank
    N = null_space(np.vstack([D0, C]).T).T  # (N1 N2) [D0; C] = 0  (14)
    N2 = N[:, D0.shape[0]:]
    C0 = _rref(N2 @ C) if N2.size else np.zeros((0, n))
    Cs = np.vstack([C, V])
    M = np.block([[A, D], [Cs, np.zeros((l + p, D.shape[1]))]])  # W(1), D(1) of (21)
    if not _rank(M) < n + (l + p):  # (22)
        raise InputError("condition (22) fails: (21) has no solution with k = 1 (k > 1 is not implemented)")
    sol = null_space(M.T).T
    psis = [r for r in _rref(sol[:, :n]) if not _in_rowspace(r, C)]
    if not psis:
        raise InputError("(21) has no disturbance-decoupled solution with k = 1 beyond the measured outputs")
    psis = np.array(psis)
    J_star = np.array([_exact_solve(ps @ A, Cs) for ps in psis])
    Fbar_rows = sorted({int(j) for ps in psis for j in np.flatnonzero(np.abs(ps @ sys_.G) > _TOL)})
    Fbar = sys_.F[Fbar_rows]
    cond18 = _rank(np.vstack([psis, Cs])) == _rank(np.vstack([psis, Cs, Fbar]))
    cond20 = [_rank(np.vstack([psis, C0])) == _rank(np.vstack([psis, C0, vi])) for vi in V]
    V_bar, V0 = V[np.array(cond20, dtype=bool)], V[~np.array(cond20, dtype=bool)]
    meas_names = [f"y{i}" for i in range(l)]
    subs: list[Subsystem] = []
    for ps in psis:  # first subsystems: insensitive to rho, over the measured outputs
        if not any(_in_rowspace(vb, np.vstack([ps, C0])) for vb in V_bar):
            continue  # a decoupled combination that no wanted row needs
        subs.append(_subsystem(sys_, ps, C, meas_names, True))
    n_first = len(subs)
    first_rows = np.array([s.psi for s in subs]).reshape(-1, n)
    for v0 in V0:  # second subsystems (Section 3.2): z0 = V0_i x, over y and the first subsystems' states
        S = np.vstack([C, first_rows])
        names = meas_names + [f"z:{i}" for i in range(n_first)]
        subs.append(_subsystem(sys_, v0, S, names, bool(np.allclose(v0 @ D, 0))))
    estimates = []
    for vi in V:
        idx = next((i for i, s in enumerate(subs) if np.allclose(s.psi, vi)), None)
        if idx is None:
            raise InputError(f"row {vi.tolist()} of V is not estimated by any subsystem (only Psi = V_i is supported)")
        estimates.append(idx)
    return SensorDesign(subs, C0, psis, J_star, cond18, cond20, V_bar, V0, estimates)


def simulate_design(design: SensorDesign, sys_: LogicDynamicSystem, u: np.ndarray, y: np.ndarray,
                    z0: ArrayLike) -> np.ndarray:
    """Run the designed sensor: returns ``v_hat`` (T, p), sample ``t`` = the state ``z(t)``.

    Parameters
    ----------
    design : SensorDesign
        The result of :func:`design_virtual_sensor` for ``sys_``.
    sys_ : LogicDynamicSystem
        The plant (its ``phi`` evaluates the nonlinear terms).
    u : numpy.ndarray, shape (T, m)
        Inputs, one row per step (a (T,) vector for m = 1).
    y : numpy.ndarray, shape (T, l)
        Measured outputs (a (T,) vector for l = 1).
    z0 : array_like, shape (n_subsystems,)
        Initial states, in the order of ``design.subsystems``.

    Returns
    -------
    numpy.ndarray
        Shape (T, p): ``v_hat``, row ``t`` the subsystem states ``z(t)`` picked by ``design.estimates``.
    """
    u = np.atleast_2d(np.asarray(u, dtype=float).reshape(len(u), -1))
    y = np.atleast_2d(np.asarray(y, dtype=float).reshape(len(y), -1))
    T, subs = len(y), design.subsystems
    z = np.array(z0, dtype=float).reshape(len(subs))
    out = np.empty((T, len(subs)))
    for t in range(T):
        out[t] = z
        nxt = np.empty_like(z)
        for i, s in enumerate(subs):
            sig = np.array([y[t, int(nm[1:])] if nm.startswith("y") else z[int(nm[2:])] for nm in s.signals])
            w = np.concatenate([[z[i]], sig])
            nl = sum(s.G_star[j] * float(sys_.phi(f @ w)) for j, f in s.F_star.items())
            nxt[i] = s.a * z[i] + s.J @ sig + s.B_star @ u[t] + nl
        z = nxt
    return out[:, design.estimates]


def three_tank_logic_dynamic(prm: dict = THREE_TANK_PARAMS) -> LogicDynamicSystem:
    """Section 5 matrices (seed_001.md §2.1, with B of assumption A3); ``V`` selects x1 and x3.

    Parameters
    ----------
    prm : dict
        Coefficients ``a1``..``a5`` (keys as in :data:`~pwas_hdl.systems.three_tank.THREE_TANK_PARAMS`).

    Returns
    -------
    LogicDynamicSystem
        n = 3, m = 2, l = 1 (``y = x2``), d = 1 (rho on x1), q = 3, p = 2.
    """
    a1, a2, a3, a4, a5 = (prm[k] for k in ("a1", "a2", "a3", "a4", "a5"))
    return LogicDynamicSystem(
        A=[[1 - a1, a1, 0], [a1, 1 - a1 - a2, a2], [0, a2, 1 - a2 - a3]],
        B=[[a4, 0], [0, a5], [0, 0]],
        C=[[0, 1, 0]],
        D=[[1], [0], [0]],
        G=[[-a1, 0, 0], [a1, -a2, 0], [0, a2, -a3]],
        F=[[1, -1, 0], [0, 1, -1], [0, 0, 1]],
        V=[[1, 0, 0], [0, 0, 1]],
    )


def observer_map_27(u1: ArrayLike, y: ArrayLike, z1: ArrayLike, prm: dict = THREE_TANK_PARAMS) -> np.ndarray | float:
    """One step of sensor (27): ``z1(t+1) = a4 u1(t) - a1 sq(z1(t) - y(t)) + z1(t)`` (elementwise).

    Arguments in the order of a recurrent PWAS regressor (input, output, state); see
    :func:`pwas_hdl.fit.map_approximation.recurrent_sensor_from_map`.

    Parameters
    ----------
    u1 : array_like, shape (N,) or scalar
        Inflow into tank 1 at step t.
    y : array_like, shape (N,) or scalar
        Measured level ``x2(t)``.
    z1 : array_like, shape (N,) or scalar
        Sensor state ``z1(t)`` (estimate of ``x1(t)``, level units).
    prm : dict
        Coefficients ``a1`` and ``a4`` (keys as in :data:`~pwas_hdl.systems.three_tank.THREE_TANK_PARAMS`).

    Returns
    -------
    numpy.ndarray or float
        ``z1(t+1)``, the broadcast shape of the arguments (a numpy float for scalars).
    """
    a1, a4 = prm["a1"], prm["a4"]
    return a4 * u1 - a1 * signed_sqrt(z1 - y) + z1


def observer_map_28(y: ArrayLike, z2: ArrayLike, prm: dict = THREE_TANK_PARAMS) -> np.ndarray | float:
    """One step of sensor (28): ``z2(t+1) = a2 sq(y(t) - z2(t)) - a3 sq(z2(t)) + z2(t)`` (elementwise).

    Parameters
    ----------
    y : array_like, shape (N,) or scalar
        Measured level ``x2(t)``.
    z2 : array_like, shape (N,) or scalar
        Sensor state ``z2(t)`` (estimate of ``x3(t)``, level units).
    prm : dict
        Coefficients ``a2`` and ``a3`` (keys as in :data:`~pwas_hdl.systems.three_tank.THREE_TANK_PARAMS`).

    Returns
    -------
    numpy.ndarray or float
        ``z2(t+1)``, the broadcast shape of the arguments (a numpy float for scalars).
    """
    a2, a3 = prm["a2"], prm["a3"]
    return a2 * signed_sqrt(y - z2) - a3 * signed_sqrt(z2) + z2


def paper_sensors(u1: np.ndarray, y: np.ndarray, z0: Sequence[float] = (5.0, 2.0),
                  prm: dict = THREE_TANK_PARAMS) -> np.ndarray:
    """The printed sensors (27) and (28): ``[x1_hat, x3_hat]`` (T, 2), sample ``t`` = ``z(t)``.

    ``z1(t+1) = a4 u1(t) - a1 sq(z1(t) - y(t)) + z1(t)`` (27),
    ``z2(t+1) = a2 sq(y(t) - z2(t)) - a3 sq(z2(t)) + z2(t)`` (28); ``sq`` the signed root (A1),
    ``z(0) = (5, 2)`` (A4).

    Parameters
    ----------
    u1 : numpy.ndarray, shape (T,) (any shape, flattened)
        Inflow into tank 1, one value per step.
    y : numpy.ndarray, shape (T,) (any shape, flattened)
        Measured level ``x2``.
    z0 : sequence of float, length 2
        Initial sensor states ``(z1(0), z2(0))`` (level units).
    prm : dict
        Coefficients ``a1``..``a4`` (keys as in :data:`~pwas_hdl.systems.three_tank.THREE_TANK_PARAMS`).

    Returns
    -------
    numpy.ndarray
        Shape (T, 2): ``[x1_hat, x3_hat]``, row ``t`` the states ``z(t)`` (row 0 is ``z0``).
    """
    u1 = np.asarray(u1, dtype=float).reshape(-1)
    y = np.asarray(y, dtype=float).reshape(-1)
    z1, z2 = float(z0[0]), float(z0[1])
    out = np.empty((y.size, 2))
    for t in range(y.size):
        out[t] = z1, z2
        z1, z2 = float(observer_map_27(u1[t], y[t], z1, prm)), float(observer_map_28(y[t], z2, prm))
    return out
