"""The checks at rest (robot/lbr/rest_checks.py) and arming on them (robot/lbr/arming.py), as pure functions."""

from __future__ import annotations

import numpy as np

from arm.robot_model import RobotModel
from robot.lbr.arming import arming_refusal
from robot.lbr.msgs import LbrState, SessionState
from robot.lbr.params import LbrParams
from robot.lbr.rest_checks import (
    GRAVITY_M_S2,
    implied_tool_mass_kg,
    load_note,
    pad_wrench,
    preload_refusal,
    spring_preload_nm,
)
from robot.lbr.watches import ClockWatch

Q = np.array([0.0, 0.6, 0.0, -1.4, 0.0, 0.9, 0.0])


def test_the_pad_wrench_explains_the_external_torque_of_a_press():
    model = RobotModel()
    w = np.array([-10.0, 1.0, 0.5, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(pad_wrench(model, Q, model.tcp_jacobian(Q).T @ w), w, atol=0.05)  # damped: 0.2 %


def test_a_missing_load_weighs_as_a_force_down_and_implies_the_tool_mass():
    w = np.array([0.0, 0.0, -0.15 * GRAVITY_M_S2, 0.0, 0.0, 0.0])
    assert abs(implied_tool_mass_kg(w, 0.15) - 0.30) < 1e-12
    assert load_note(w, 0.15, 0.05).startswith("the external torque at rest implies a tool of 0.30 kg, [lbr] "
                                               "tool_mass_kg says 0.15 kg: set the tool's load data on the smartPAD")
    assert load_note(w * 0.3, 0.15, 0.05) is None  # 45 g off: within the tolerance


def test_a_press_over_the_limit_refuses_naming_the_force_and_the_fix():
    assert preload_refusal(np.array([-2.9, 0, 0, 0, 0, 0]), 3.0, 0.15) is None
    why = preload_refusal(np.array([-14.6, 0.3, 2.0, 0, 0, 0]), 3.0, 0.15)
    assert why.startswith("the pad presses 14.7 N at rest (force [-14.6, +0.3, +2.0] N): restart the LBRServer "
                          "app and relaunch the stack"), why
    assert "implies a tool of" in why


def test_the_spring_preload_needs_the_commanded_position():
    K = np.full(7, 200.0)
    assert spring_preload_nm(np.zeros(7), None, K) is None
    assert abs(spring_preload_nm(np.zeros(7), np.full(7, 0.01), K) - 2.0) < 1e-12


def test_arming_is_refused_at_rest_on_a_press_and_not_judged_while_moving():
    z = np.zeros(7)
    st = LbrState(0.001, int(SessionState.COMMANDING_ACTIVE), 0, 0, 2, 3, 2, 5_000_000, z, z, z, z, z)
    p, kw = LbrParams(open_loop=False), dict(layout_error="", names_ok=True, clock=ClockWatch(20))
    press = np.array([-10.0, 0, 0, 0, 0, 0])
    assert arming_refusal(st, p, dq_rad_s=z, wrench=press, **kw).startswith("the pad presses 10.0 N")
    assert arming_refusal(st, p, dq_rad_s=z + 0.1, wrench=press, **kw) is None  # FRI 1, moving: no rest to judge
    assert arming_refusal(st, p, dq_rad_s=z, wrench=np.zeros(6), **kw) is None
