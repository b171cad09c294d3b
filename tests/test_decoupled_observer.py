"""Seed 001: the Section 3 design procedure reproduces the paper's sensors (27) and (28)."""

import numpy as np
import pytest

from pwas_hdl.errors import InputError
from pwas_hdl.systems.decoupled_observer import (
    LogicDynamicSystem, design_virtual_sensor, paper_sensors, simulate_design, three_tank_logic_dynamic,
)
from pwas_hdl.systems.three_tank import THREE_TANK_PARAMS, three_tank_paper_run

a1, a2, a3, a4 = (THREE_TANK_PARAMS[k] for k in ("a1", "a2", "a3", "a4"))


def test_design_reproduces_the_printed_matrices():
    d = design_virtual_sensor(three_tank_logic_dynamic())
    np.testing.assert_allclose(d.C0, [[0, 1, 0]])                      # (14): N2 = 1, C0 = C
    np.testing.assert_allclose(d.psi_solutions, [[0, 0, 1]])           # (21), k = 1: Psi = (0 0 1)
    np.testing.assert_allclose(d.J_star, [[a2, 0, 1 - a2 - a3]])       # J* = (a2 0 1-a2-a3)
    assert d.cond18 and d.cond20 == [False, True]                      # "(18) is satisfied, whilst (20) is not"
    np.testing.assert_allclose(d.V_bar, [[0, 0, 1]])
    np.testing.assert_allclose(d.V0, [[1, 0, 0]])
    first, second = d.subsystems
    assert first.insensitive and not second.insensitive
    np.testing.assert_allclose(first.B_star, [0, 0])                   # B* = (0 0)
    np.testing.assert_allclose(first.G_star, [0, a2, -a3])             # G* = (0 a2 -a3)
    # F* = [[-1 1 0 0], [1 0 0 0]] over [z; y; x1; x3]: ours is over [z; y] (the v columns are zero)
    np.testing.assert_allclose(np.vstack([first.F_star[1], first.F_star[2]]), [[-1, 1], [1, 0]])
    # linear part of (28): z2(t+1) = a2 y + (1 - a2 - a3) z2
    assert first.a == pytest.approx(1 - a2 - a3) and first.J == pytest.approx([a2])
    # second subsystem: Psi0 = (1 0 0), B* = (a4 0), G0 = (-a1 0 0), F0 over [z1; y] = (1 -1)
    np.testing.assert_allclose(second.psi, [1, 0, 0])
    np.testing.assert_allclose(second.B_star, [a4, 0])
    np.testing.assert_allclose(second.G_star, [-a1, 0, 0])
    np.testing.assert_allclose(second.F_star[0][:2], [1, -1])
    assert second.a == pytest.approx(1 - a1) and second.J[0] == pytest.approx(a1)


def test_designed_sensor_equals_eqs_27_and_28_on_the_paper_run():
    r = three_tank_paper_run(600, seed=2)
    sys_ = three_tank_logic_dynamic()
    d = design_virtual_sensor(sys_)
    designed = simulate_design(d, sys_, r.u, r.y, [2.0, 5.0])   # states: (x3 sensor, x1 sensor)
    printed = paper_sensors(r.u[:, 0], r.y, (5.0, 2.0))
    np.testing.assert_allclose(designed, printed, rtol=0, atol=1e-10)
    err = printed - r.z_true
    # (28) is decoupled from rho, (27) is not (the paper's qualitative claim, Fig. 2)
    rms = np.sqrt(np.mean(err[100:] ** 2, axis=0))
    assert rms[1] < 2e-3 and rms[0] > 0.1


def test_design_refuses_what_k1_cannot_do():
    s = three_tank_logic_dynamic()
    # disturbance on every state: no decoupled combination besides nothing
    with pytest.raises(InputError):
        design_virtual_sensor(LogicDynamicSystem(s.A, s.B, s.C, np.eye(3), s.G, s.F, s.V))
    with pytest.raises(InputError, match="shape"):
        LogicDynamicSystem(s.A, s.B, s.C, s.D, s.G, s.F, [[1, 0]])
