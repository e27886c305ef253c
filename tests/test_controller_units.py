"""The controller's pure parts: motions, limits, force regulator, parameters, and the executor's phase logic."""

from __future__ import annotations

import concurrent.futures
import os
import threading

import numpy as np
import pytest

from controller.control.force import NormalForceRegulator
from controller.control.limits import (
    SpeedOverride,
    TorqueShaper,
    jerk_limited_scale,
    joint_margin_torque,
    joint_speed_brake_torque,
    speed_excess_force,
)
from controller.executor import SkillExecutor
from controller.executor_stage import Stage
from controller.executor_types import BoardPose, ToolState
from controller.look_points import look_point
from controller.motion import OrientationBlend, Quintic, bounded_brake_to_rest, brake_peaks, brake_to_rest
from controller.params import ControllerParams, ExecutorParams
from controller.stain_book import StainBook
from interfaces.errors import ConfigError
from interfaces.transforms import tool_rotation_on_board
from lampskit.core.chain import ChainStep
from lampskit.core.planner_types import Stain
from lampskit.errors import PlanningError


def test_quintic_meets_position_velocity_acceleration_at_both_ends():
    start = (np.array([0.1, -0.2]), np.array([0.3, 0.0]), np.array([-1.0, 2.0]))
    goal = (np.array([0.5, 0.4]), np.array([0.0, -0.2]), np.array([0.5, 0.0]))
    q = Quintic(start, goal, 0.8)
    for x, want in zip((q.position, q.velocity, q.acceleration), start):
        np.testing.assert_allclose(x, want)
    dt = 1e-4
    pos, vel = [q.position.copy()], [q.velocity.copy()]
    for _ in range(8000):
        q.update(dt)
        pos.append(q.position.copy())
        vel.append(q.velocity.copy())
    for x, want in zip((q.position, q.velocity, q.acceleration), goal):
        np.testing.assert_allclose(x, want, atol=1e-9)
    # the reported velocity is the derivative of the position
    np.testing.assert_allclose(np.gradient(np.array(pos), dt, axis=0)[1:-1], np.array(vel)[1:-1], atol=1e-5)


def test_brake_to_rest_stops_a_moving_point_continuously():
    b = brake_to_rest(np.zeros(2), np.array([0.2, -0.1]), np.array([1.0, 0.0]), 0.3)
    np.testing.assert_allclose(b.acceleration, [1.0, 0.0])
    for _ in range(400):
        b.update(0.001)
    np.testing.assert_allclose(b.velocity, 0.0, atol=1e-12)
    np.testing.assert_allclose(b.acceleration, 0.0, atol=1e-12)


def test_orientation_blend_reaches_the_goal_with_consistent_rates():
    R0 = np.eye(3)
    R1 = tool_rotation_on_board(np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]]))
    blend = OrientationBlend(R0, R1, 1.0)
    prev = blend.R.copy()
    for _ in range(500):
        blend.update(0.001)
    # finite-difference angular velocity (world axes) equals the reported one
    import pinocchio as pin

    before = blend.R.copy()
    blend.update(0.001)
    w_fd = pin.log3(blend.R @ before.T) / 0.001
    np.testing.assert_allclose(w_fd, blend.omega, atol=1e-3)
    for _ in range(600):
        blend.update(0.001)
    np.testing.assert_allclose(blend.R, R1, atol=1e-9)
    assert blend.finished and not np.allclose(prev, R1)


def test_torque_shaper_limits_rate_and_magnitude_but_not_the_gravity_offset():
    shaper = TorqueShaper(np.array([10.0, 10.0]), rate_nm_s=1000.0)
    g = np.array([5.0, -3.0])
    out = shaper(np.array([8.0, -20.0]), 0.001, g)  # wants +3 / -17 beyond gravity: 1 Nm per ms allowed
    np.testing.assert_allclose(out, [6.0, -4.0])
    assert shaper.clipped_rate == 1
    for _ in range(50):
        out = shaper(np.array([8.0, -20.0]), 0.001, g)
    np.testing.assert_allclose(out, [8.0, -10.0])  # the absolute limit
    assert shaper.clipped_abs > 0


def test_joint_margin_pushes_back_only_inside_the_margin():
    lo, hi = np.array([-1.0]), np.array([1.0])
    assert joint_margin_torque(np.array([0.5]), np.zeros(1), lo, hi, 0.1, 300.0, 10.0)[0] == 0.0
    near_hi = joint_margin_torque(np.array([0.95]), np.array([0.2]), lo, hi, 0.1, 300.0, 10.0)[0]
    near_lo = joint_margin_torque(np.array([-0.95]), np.array([-0.2]), lo, hi, 0.1, 300.0, 10.0)[0]
    assert near_hi < 0 < near_lo
    edge = joint_margin_torque(np.array([0.9 + 1e-9]), np.array([0.2]), lo, hi, 0.1, 300.0, 10.0)[0]
    assert abs(edge) < 1e-5  # continuous at the margin's edge


def test_speed_limit_brakes_only_above_the_limit():
    assert np.all(speed_excess_force(np.array([0.3, 0.0, 0.0]), 0.5, 200.0) == 0.0)
    f = speed_excess_force(np.array([0.0, 0.8, 0.0]), 0.5, 200.0)
    np.testing.assert_allclose(f, [0.0, -60.0, 0.0])


def test_force_regulator_reaches_the_target_on_a_spring_and_respects_the_cap():
    reg = NormalForceRegulator(kp=0.3, ki=8.0, integral_limit_n=8.0, cap_n=40.0, filter_s=0.005)
    force = 0.0
    for _ in range(3000):  # a plant that delivers 80 % of the command with a 20 ms lag
        cmd = reg.command(10.0, force, 0.001, in_contact=True)
        force += (0.8 * cmd - force) * 0.05
    assert abs(force - 10.0) < 0.05
    assert reg.command(1000.0, 0.0, 0.001, True) == 40.0
    for _ in range(20):
        reg.measure(60.0, 0.001)
    assert reg.over_cap
    spike = NormalForceRegulator(0.3, 8.0, 8.0, 40.0, filter_s=0.005)
    spike.measure(100.0, 0.001)  # one tick of impact
    assert not spike.over_cap


@pytest.mark.parametrize("table, match", [
    ({"impedance": {"stiffness_n_m": -100.0}}, "stiffness_n_m"),
    ({"force": {"target_n": 50.0}}, r"target_n \(50.0 N\) must be below cap_n \(40.0 N\)"),
    ({"force": {"target_n": 20.0, "cap_n": 15.0}}, "must be below cap_n"),
    ({"rate_hz": 20000.0}, r"rate_hz must be a number in \[100.0, 10000.0\]"),
    ({"mode": "fast"}, "mode must be one of"),
    ({"stains_from": "camera"}, "stains_from must be one of"),
    ({"executor": {"standoff_m": 2.0}}, "standoff_m"),
    ({"limits": {"torque_rate_nm_per_ms": 0.0}}, "torque_rate_nm_per_ms"),
    ({"limits": {"overload_share": 0.0}}, "overload_share"),
    ({"planner": {"order": "random"}}, "order must be"),
    ({"force": {"gain": 1.0}}, r"unknown key\(s\) \['gain'\]"),
    ({"impedance": 3}, r"\[controller.impedance\] must be a table"),
    ({"robot_lost_s": 0.05}, r"robot_lost_s must be a number in \[0.15, 60.0\]"),
])
def test_bad_controller_config_is_refused_with_the_key_named(table, match):
    with pytest.raises(ConfigError, match=match):
        ControllerParams.from_table(table)


def test_the_robot_lost_watch_is_longer_in_lock_step_unless_set():
    """Lock-step: the sim waits for each answer, so a starved sim moves nothing; only a dead one is lost."""
    assert ControllerParams.from_table({}).robot_lost_or_default_s == 2.0
    assert ControllerParams.from_table({"mode": "realtime"}).robot_lost_or_default_s == 0.5
    assert ControllerParams.from_table({"robot_lost_s": 0.3}).robot_lost_or_default_s == 0.3


def test_defaults_are_valid_and_the_example_config_lists_them():
    import tomllib
    from pathlib import Path

    p = ControllerParams.from_table({})
    assert p.force.target_n == 10.0 and p.force.cap_n == 40.0 and p.rate_hz == 1000.0
    example = tomllib.loads((Path(__file__).resolve().parent.parent / "config" / "example.toml").read_text())
    assert ControllerParams.from_table(example["controller"]) == p


# --------------------------------------------------------------------------
# the executor against an ideal arm (the pad is where the setpoint says; a stiff board)

WALL = np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
BOARD = BoardPose(WALL, np.array([0.68, 0.4, 0.25]), np.array([0.8, 0.6]))


class IdealArm:
    """Follows the setpoint exactly; pressing into the board (h < 0) gives 2e4 N/m of force."""

    def __init__(self, xy=(0.4, 0.3), h=0.08):
        self.tool = ToolState(np.array(xy, float), h, np.zeros(2), 0.0, tool_rotation_on_board(WALL), 0.0)

    def follow(self, sp) -> ToolState:
        t = self.tool
        t.xy = sp.xy.copy()
        t.v_xy = sp.v_xy.copy()
        t.R = sp.R.copy()
        if sp.contact:
            t.h = -sp.force_n / 2e4
        else:
            t.h = sp.h
        t.force_n = max(0.0, -t.h * 2e4)
        return t


def stains(kappa=(False, False, False)):
    centres = [(0.2, 0.2), (0.55, 0.35), (0.3, 0.45)]
    return [Stain(i, np.array(c), 0.06, kappa=k) for i, (c, k) in enumerate(zip(centres, kappa))]


def run(ex: SkillExecutor, arm: IdealArm, seconds: float, on_tick=None) -> list[tuple]:
    log = []
    for k in range(int(seconds * 1000)):
        if on_tick is not None:
            on_tick(k, ex)
        sp = ex.step(0.001, arm.tool)
        arm.follow(sp)
        log.append((ex.phase, ex.stain_id, sp.xy.copy(), sp.v_xy.copy(), sp.a_xy.copy(), sp.contact, sp.force_n,
                    arm.tool.h))
    return log


def phases(log) -> list[str]:
    out = []
    for entry in log:
        if not out or out[-1] != entry[0]:
            out.append(entry[0])
    return out


def test_executor_chains_the_stains_until_kappa_then_retreats(learned_skill):
    ex = SkillExecutor(learned_skill, ExecutorParams(pass_cycles=1e6))  # kappa, 2 s in, ends each pass
    arm = IdealArm()
    ex.set_stains(BOARD, stains())
    wiped: dict[int, int] = {}

    def kappa_after_two_seconds(k, ex):
        if ex.phase == "WIPE":
            wiped[ex.stain_id] = wiped.get(ex.stain_id, 0) + 1
        if k % 100 == 0:
            ex.set_stains(BOARD, stains(tuple(wiped.get(i, 0) > 2000 for i in range(3))))

    log = run(ex, arm, 30.0, kappa_after_two_seconds)
    assert phases(log)[:2] == ["WAIT_PEERS", "APPROACH"] or phases(log)[0] == "APPROACH"
    seq = [p for p in phases(log) if p not in ("WAIT_PEERS",)]
    assert seq == ["APPROACH", "TRANSITION", "WIPE", "TRANSITION", "WIPE", "TRANSITION", "WIPE", "RETREAT", "DONE"]
    assert sorted(wiped) == [0, 1, 2] and all(n > 2000 for n in wiped.values())
    final = log[-1]
    assert not final[5] and final[7] >= ExecutorParams().standoff_m - 1e-6  # lifted off
    forces = np.array([e[6] for e in log if e[0] == "WIPE"])
    np.testing.assert_allclose(forces, 10.0)
    # the in-plane reference is continuous in acceleration at every MP junction
    a = np.array([e[4] for e in log])
    steps = np.linalg.norm(np.diff(a, axis=0), axis=1)
    for j in ex.junction_ticks:
        i = j - 1  # ticks count from 1, the log from 0
        around = np.concatenate([steps[i - 6 : i - 1], steps[i + 1 : i + 6]])
        assert steps[i - 1] <= 3.0 * around.max() + 1e-3, (j, steps[i - 1], around.max())


def test_stale_stains_pause_off_the_board_and_fresh_ones_resume(learned_skill):
    ex = SkillExecutor(learned_skill, ExecutorParams(survey_s=0.0))
    arm = IdealArm()
    ex.set_stains(BOARD, stains())
    run(ex, arm, 6.0)
    assert ex.phase in ("WIPE", "TRANSITION")
    ex.stains_stale("no stains update for 1.0 s")
    log = run(ex, arm, 2.0)
    assert ex.phase == "PAUSED" and ex.reason == "no stains update for 1.0 s"
    assert not log[-1][5] and log[-1][7] > 0.03  # off the board
    ex.set_stains(BOARD, stains())
    log = run(ex, arm, 8.0)
    assert "APPROACH" in phases(log) and ex.phase in ("WIPE", "TRANSITION")


def test_estop_lifts_off_and_holds_until_released(learned_skill):
    ex = SkillExecutor(learned_skill, ExecutorParams())
    arm = IdealArm()
    ex.set_stains(BOARD, stains())
    run(ex, arm, 6.0)
    ex.estop("button")
    log = run(ex, arm, 3.0)
    assert ex.phase == "ESTOP" and "button" in ex.reason
    assert not log[-1][5] and log[-1][7] > 0.03
    # the force ramps out within the e-stop ramp, then the pad rises
    lifted = next(i for i, e in enumerate(log) if not e[5])
    assert lifted <= 0.1 * 1000 + 5
    ex.set_stains(BOARD, stains())  # fresh stains alone do not release an e-stop
    run(ex, arm, 1.0)
    assert ex.phase == "ESTOP"
    ex.clear()
    log = run(ex, arm, 6.0)
    assert "APPROACH" in phases(log) and ex.phase in ("WIPE", "TRANSITION")


def test_a_fault_at_the_arm_stops_from_the_measured_pose_not_from_a_reference_ahead_of_it(learned_skill):
    """A joint torque nothing explains: the arm is not following. The stop starts from the pose last measured,
    at rest, and lifts from there; the ordinary fault brakes the reference on from where it ran."""
    for at_the_arm in (True, False):
        ex = SkillExecutor(learned_skill, ExecutorParams())
        arm = IdealArm()
        ex.set_stains(BOARD, stains())
        for _ in range(20_000):
            arm.follow(ex.step(0.001, arm.tool))
            if ex._sp.contact and np.linalg.norm(ex._sp.v_xy) > 0.1:
                break
        assert ex._sp.contact and np.linalg.norm(ex._sp.v_xy) > 0.1, "moving on the board"
        arm.tool.xy = arm.tool.xy - 0.03 * ex._sp.v_xy / np.linalg.norm(ex._sp.v_xy)  # 30 mm behind
        stuck = arm.tool.xy.copy()
        ex.step(0.001, arm.tool)
        ex.fault("unexplained joint torque", at_the_arm=at_the_arm)
        log = []
        for _ in range(3000):
            sp = ex.step(0.001, arm.tool)
            log.append(np.linalg.norm(sp.xy - stuck))
            arm.follow(sp)
        assert ex.phase == "FAULT" and not ex._sp.contact
        if at_the_arm:
            assert max(log) < 1e-9, f"the stop moved {max(log) * 1000:.1f} mm off the measured pose"
        else:
            assert max(log) > 0.03, "the ordinary fault brakes the reference on"


def test_a_vanished_stain_is_not_visited_and_new_stains_after_done_are(learned_skill):
    ex = SkillExecutor(learned_skill, ExecutorParams(wipe_timeout_s=1.0, max_passes=1))
    arm = IdealArm()
    ex.set_stains(BOARD, stains()[:1])
    log = run(ex, arm, 14.0)  # the first touch of the board creeps from first_creep_height_m
    assert ex.phase == "DONE" and {e[1] for e in log if e[0] == "WIPE"} == {0}
    assert ex.counters["wipe_timeouts"] == 1
    assert ex.reason.startswith("1 stain(s) left: stain 0 at (") and ex.reason.endswith(") m given up after 1 passes")
    ex.set_stains(BOARD, stains()[:1] + [Stain(7, np.array([0.6, 0.2]), 0.05, kappa=False)])
    log = run(ex, arm, 10.0)
    assert 7 in {e[1] for e in log if e[0] == "WIPE"}
    assert 0 not in {e[1] for e in log if e[0] == "WIPE"}  # given up after its timeout, not retried


def test_no_contact_below_the_board_is_a_fault_not_a_crash(learned_skill):
    ex = SkillExecutor(learned_skill, ExecutorParams(survey_s=0.0))
    arm = IdealArm()
    arm.follow = lambda sp: _no_board(arm.tool, sp)
    ex.set_stains(BOARD, stains())
    run(ex, arm, 8.0)
    assert ex.phase == "FAULT" and "no contact found" in ex.reason


def _no_board(t: ToolState, sp) -> ToolState:
    t.xy, t.v_xy, t.R, t.h, t.force_n = sp.xy.copy(), sp.v_xy.copy(), sp.R.copy(), sp.h, 0.0
    return t


def test_the_first_approach_surveys_the_whole_board_so_a_stain_hidden_at_the_start_is_planned(learned_skill):
    """Before the first plan the pad flies to the look point of the whole board and waits ``survey_s``; a stain
    reported only then (the arm hid it at its start pose) is in the first plan: one approach, one retreat."""
    p = ExecutorParams(survey_s=1.0)
    ex = SkillExecutor(learned_skill, p)
    arm = IdealArm()
    ex.set_stains(BOARD, stains()[:2])  # the third is hidden by the arm
    log = run(ex, arm, 0.5)
    assert ex.phase == "APPROACH" and ex.current_mp.startswith("survey") and ex.counters["surveys"] == 1
    corners = [np.array(c) for c in ((0.0, 0.0), (0.8, 0.0), (0.0, 0.6), (0.8, 0.6))]
    goal = look_point(BOARD, corners, [0.0] * 4, p.look_clearance_m)
    seen = run(ex, arm, 3.0, on_tick=lambda k, e: e.set_stains(BOARD, stains()) if k == 0 else None)
    arrived = [e for e in log + seen if np.linalg.norm(e[2] - goal) < 1e-6 and abs(e[7] - p.standoff_m) < 1e-6]
    assert arrived, "the pad reached standoff above the whole board's look point"
    wiped: dict[int, int] = {}

    def judge(k: int, e: SkillExecutor) -> None:  # kappa once a stain had 2 s of wiping
        if e.phase == "WIPE":
            wiped[e.stain_id] = wiped.get(e.stain_id, 0) + 1
        if k % 50 == 0:
            e.set_stains(BOARD, stains(tuple(wiped.get(i, 0) > 2000 for i in range(3))))

    log += seen + run(ex, arm, 120.0, on_tick=judge)
    assert ex.counters["plans"] == 1 and ex.counters["phase_retreat"] == 1 and ex.phase == "DONE"
    assert {e[1] for e in log if e[0] == "WIPE"} == {0, 1, 2}, "the stain seen during the survey was wiped"
    # without the survey the plan is made at once over what is reported (and a restart surveys again)
    ex0 = SkillExecutor(learned_skill, ExecutorParams(survey_s=0.0))
    ex0.set_stains(BOARD, stains()[:2])
    run(ex0, IdealArm(), 0.01)
    assert ex0.current_mp == "approach" and ex0.counters["surveys"] == 0


def test_an_estop_engaged_again_while_lifting_after_a_release_holds(learned_skill):
    ex = SkillExecutor(learned_skill, ExecutorParams())
    arm = IdealArm()
    ex.set_stains(BOARD, stains())
    run(ex, arm, 6.0)
    ex.estop("first")
    run(ex, arm, 0.05)  # still braking / lifting
    ex.clear()
    ex.estop("second")
    log = run(ex, arm, 6.0)
    assert set(phases(log)) == {"ESTOP"} and ex.reason == "second"
    assert not log[-1][5] and log[-1][7] > 0.03


def test_an_estop_before_the_first_stains_is_kept(learned_skill):
    ex = SkillExecutor(learned_skill, ExecutorParams())
    arm = IdealArm()
    ex.estop("before start")
    ex.wait()
    assert ex.phase == "ESTOP"
    ex.set_stains(BOARD, stains())
    log = run(ex, arm, 3.0)
    assert set(phases(log)) == {"ESTOP"}
    ex.clear()
    log = run(ex, arm, 3.0)
    assert "APPROACH" in phases(log)


def test_a_release_with_stale_stains_waits_paused_instead_of_wiping_blind(learned_skill):
    ex = SkillExecutor(learned_skill, ExecutorParams())
    arm = IdealArm()
    ex.set_stains(BOARD, stains())
    run(ex, arm, 6.0)
    ex.estop("button")
    run(ex, arm, 2.0)
    ex.stains_stale("no stains update for 1.0 s")
    ex.clear()
    log = run(ex, arm, 2.0)
    assert set(phases(log)) <= {"ESTOP", "PAUSED"} and ex.phase == "PAUSED"
    ex.set_stains(BOARD, stains())
    log = run(ex, arm, 4.0)
    assert "APPROACH" in phases(log)


class RaisedBoardArm(IdealArm):
    """An :class:`IdealArm` whose board surface is ``surface_h`` [m] above where the executor expects it."""

    def __init__(self, surface_h: float):
        super().__init__()
        self.surface_h = surface_h

    def follow(self, sp) -> ToolState:
        t = super().follow(sp)
        if sp.contact:
            t.h = self.surface_h - sp.force_n / 2e4
        t.force_n = max(0.0, (self.surface_h - t.h) * 2e4)
        return t


@pytest.mark.parametrize("surface_h", [0.0, 0.011, -0.004])
def test_the_pad_touches_down_at_the_creep_speed_wherever_the_board_is_within_the_creep_height(learned_skill,
                                                                                                surface_h):
    """The tilted board met the pad up to 11 mm above the expected surface, at the end of the fast descent
    (0.075-0.09 m/s, 46-50 N). The descent now hands over at the creep speed at ``creep_height_m`` (16 mm),
    C1 across the hand-over, and the contact comes at that speed (with the surface where expected, 4 mm low or 11
    mm high)."""
    p = ExecutorParams()
    ex = SkillExecutor(learned_skill, p)
    arm = RaisedBoardArm(surface_h)
    ex.set_stains(BOARD, stains())
    v_h, touch, stages = [], None, []
    for _ in range(30000):
        sp = ex.step(0.001, arm.tool)
        if ex.current_mp == "descend":
            v_h.append(sp.v_h)
            stages.append(ex.state.stage)
        arm.follow(sp)
        if arm.tool.force_n >= ex.f.contact_threshold_n and touch is None:
            touch = v_h[-1]
            break
    assert touch is not None, "no contact"
    assert -p.descend_speed_m_s * 1.001 <= touch < 0.0, touch
    assert Stage.CREEP in stages, "the contact came while creeping"
    k = stages.index(Stage.CREEP)  # the hand-over: the creep goes on at the speed the descent arrived with
    assert abs(v_h[k] - v_h[k - 1]) < 1e-4 and abs(v_h[k] + p.descend_speed_m_s) < 1e-4, v_h[k - 2:k + 2]
    assert max(abs(np.diff(v_h))) < 0.004, "no step in the speed (the fast descent peaks at 3.5 m/s^2)"


class SaggingArm(IdealArm):
    """An ideal arm whose pad, in the air, hangs ``sag_m`` below the setpoint while :attr:`sagging` (random board
    899: near its stain the elbow at its limit, the pad 14 mm under its hover and on the board, 28 N)."""

    def __init__(self, sag_m: float):
        super().__init__()
        self.sag_m, self.sagging = sag_m, False

    def follow(self, sp) -> ToolState:
        t = super().follow(sp)
        if self.sagging and not sp.contact:
            t.h = sp.h - self.sag_m
            t.force_n = max(0.0, -t.h * 2e4)
        return t


def test_a_flight_that_meets_the_board_stops_there_and_takes_it_as_the_touch(learned_skill):
    """Board 899's approach: the pad met the board on its way to the hover and pressed 22-29 N for 4 s, the force
    not watched until the descent. A flight now ends where the force has stayed over the contact threshold for
    FLIGHT_TOUCH_S (a shorter spike is no touch) and presses from there, the reference brought back to the pad;
    the chain starts from that point."""
    from controller.free_motion import FLIGHT_TOUCH_S

    p = ExecutorParams()
    ex = SkillExecutor(learned_skill, p)
    arm = SaggingArm(sag_m=p.standoff_m + 0.01)  # 1 cm into the board at the hover, 200 N on this stiff board
    ex.set_stains(BOARD, stains())
    fly_force, touched_at, after, spiked = [], None, [], 0
    for _ in range(30000):
        flying = ex.state.stage == Stage.FLY
        if flying and spiked < 5:  # a 5 ms spike of the force estimate as the flight starts: no touch
            arm.tool.force_n, spiked = 8.0, spiked + 1
        elif flying:  # within 5 cm of its stain the pad sinks
            arm.sagging = np.linalg.norm(arm.tool.xy - stains()[ex.stain_id].centre_m) < 0.05
        sp = ex.step(0.001, arm.tool)
        if flying:
            fly_force.append(arm.tool.force_n)
        if ex.state.stage != Stage.FLY and touched_at is None and fly_force:
            touched_at = (ex.state.stage, sp.xy.copy(), arm.tool.xy.copy(), sp.contact, sp.force_n)
        arm.follow(sp)
        if touched_at is not None:
            after.append((ex.phase, arm.tool.force_n))
            if ex.phase == "WIPE":
                break
    assert touched_at is not None, "the flight never ended"
    stage, sp_xy, tool_xy, contact, force = touched_at
    assert stage == Stage.PRESS and contact, "the touch in flight starts the press"
    np.testing.assert_allclose(sp_xy, tool_xy, atol=1e-9)
    assert ex.counters["flights_touched"] == 1 and "descend" not in {e[0] for e in after}
    over = [f >= ex.f.contact_threshold_n for f in fly_force]
    n = round(FLIGHT_TOUCH_S / 0.001)
    assert spiked == 5 and sum(over[:-n]) == 5 and all(over[-n:]), "ended once the force had stayed over"
    assert max(f for _, f in after) < 1.2 * ex.f.target_n, "pressed with the target, not with the sag"
    assert after[-1][0] == "WIPE", "the chain goes on from the touch"


def test_a_pause_while_descending_fast_never_drives_the_pad_into_the_board(learned_skill):
    # the fast descent of a board whose surface is known (the first touch of one creeps from higher up: as low
    # as the later ones here)
    ex = SkillExecutor(learned_skill, ExecutorParams(first_creep_height_m=ExecutorParams().creep_height_m))
    arm = IdealArm()
    ex.set_stains(BOARD, stains())
    # run until the fast part of the descent is at full speed
    for _ in range(20000):
        sp = ex.step(0.001, arm.tool)
        arm.follow(sp)
        if ex.current_mp == "descend" and sp.v_h < -0.2:
            break
    else:
        pytest.fail("the descent never went faster than 0.2 m/s: nothing tested")
    h_at_pause = sp.h
    ex.stains_stale("no stains")
    log = run(ex, arm, 2.0)
    lowest = min(e[7] for e in log)
    assert lowest > h_at_pause - 0.006 and lowest > 0.0, (h_at_pause, lowest)
    assert ex.phase == "PAUSED" and log[-1][7] >= ExecutorParams().standoff_m - 1e-6


def test_a_moved_board_is_adopted_while_holding_without_moving_the_held_pose(learned_skill):
    ex = SkillExecutor(learned_skill, ExecutorParams(survey_s=0.0))
    arm = IdealArm()
    ex.set_stains(BOARD, [])
    run(ex, arm, 0.5)
    assert ex.phase == "DONE"
    held = BOARD.to_world(np.array([*ex.motion.setpoint.xy, ex.motion.setpoint.h]))
    moved = BoardPose(WALL, BOARD.origin_m + np.array([0.0, 0.01, 0.0]), BOARD.size_m)
    ex.set_stains(moved, [])
    np.testing.assert_allclose(moved.to_world(np.array([*ex.motion.setpoint.xy, ex.motion.setpoint.h])), held,
                               atol=1e-12)
    assert ex.board is moved


def test_a_stain_without_kappa_gets_another_pass_after_the_others_and_a_recheck(learned_skill):
    """The eraser hides the stain from the camera: after a pass it is left, judged, and wiped again if still open."""
    ex = SkillExecutor(learned_skill, ExecutorParams(wipe_timeout_s=1.5, recheck_s=1.0, max_passes=3, survey_s=0.0))
    arm = IdealArm()
    ex.set_stains(BOARD, stains()[:2])
    log = run(ex, arm, 30.0)
    visits = [sid for i, (phase, sid, *_rest) in enumerate(log)
              if phase == "WIPE" and (i == 0 or log[i - 1][0] != "WIPE" or log[i - 1][1] != sid)]
    # never two passes in a row on one stain, each stain three passes, then given up
    assert all(a != b for a, b in zip(visits, visits[1:])), visits
    assert sorted(visits) == [0, 0, 0, 1, 1, 1], visits
    assert ex.counters["wipe_timeouts"] == 6 and ex.phase == "DONE"
    ex2 = SkillExecutor(learned_skill, ExecutorParams(wipe_timeout_s=1.5, recheck_s=1.0, max_passes=3, survey_s=0.0))
    ex2.set_stains(BOARD, stains()[:1])
    log = run(ex2, arm, 6.0)
    # alone on the board: lifted off after the pass, a fresh view; kappa from it ends the job
    ex2.set_stains(BOARD, [Stain(0, stains()[0].centre_m, stains()[0].size_m, kappa=True)])
    run(ex2, arm, 6.0)
    assert ex2.phase == "DONE" and ex2.counters["wipe_timeouts"] >= 1


def test_a_stain_passed_without_kappa_waits_until_no_stain_has_fewer_passes():
    """kappa comes seconds after the pad has left (once the arm no longer hides the stain): a stain wiped once is
    not wiped again, however long ago, while a stain not yet wiped is open; then it is, after ``recheck_s``."""
    book = StainBook(recheck_s=1.0, max_passes=3)
    a, b, c = (Stain(i, np.array([0.1 + 0.2 * i, 0.2]), 0.05, kappa=False) for i in range(3))
    book.update([a, b, c], 0.0)
    assert book.open_ids(0.0) == {0, 1, 2}
    assert not book.end_pass(0, 1.0)
    assert book.open_ids(1.5) == {1, 2} and book.open_ids(30.0) == {1, 2}
    book.end_pass(1, 2.0)
    book.update([a, b, Stain(2, c.centre_m, c.size_m, kappa=True)], 3.0)  # c done: a and b have one pass each
    assert book.open_ids(3.0) == {0, 1} and book.open_ids(2.5) == {0}
    book.end_pass(0, 4.0)
    assert book.open_ids(10.0) == {1}
    done_c = Stain(2, c.centre_m, c.size_m, kappa=True)
    book.update([a, Stain(1, b.centre_m, b.size_m, kappa=True), done_c], 10.0)
    assert book.open_ids(10.0) == {0}
    # the stain just left does not count (recheck_s 0: it would be the only one open, and the chain would end)
    book = StainBook(recheck_s=0.0, max_passes=5)
    book.update([a, b], 0.0)
    book.end_pass(1, 1.0), book.end_pass(1, 2.0), book.end_pass(0, 3.0)
    assert {s.id for s in book.open_stains(3.0)} == {0}
    assert {s.id for s in book.open_stains(3.0, exclude=0)} == {1}


def test_the_book_names_each_stain_it_closed_without_kappa_and_why():
    """What a DONE leaves (its reason): out of the arm's reach with the reach test's words, smeared after its
    passes, given up after ``max_passes``; a stain with kappa is not named."""
    book = StainBook(recheck_s=0.0, max_passes=2)
    far, smear, stubborn, clean = (Stain(i, np.array([0.1 + 0.2 * i, 0.2]), 0.05, kappa=False) for i in range(4))
    book.update([far, smear, stubborn, clean], 0.0)
    assert book.left_undone() == ""
    book.close_out_of_reach(0, "beyond the stretched arm (1.21 m from the base)")
    book.end_pass(1, 1.0)
    book.update([far, Stain(1, smear.centre_m, smear.size_m, kappa=False, smeared=True, passes=1), stubborn,
                 Stain(3, clean.centre_m, clean.size_m, kappa=True)], 1.5)
    book.end_pass(2, 2.0), book.end_pass(2, 3.0)
    assert book.left_undone() == ("3 stain(s) left: stain 0 at (0.10, 0.20) m out of the arm's reach (beyond the "
                                  "stretched arm (1.21 m from the base)); stain 1 at (0.30, 0.20) m smeared after 1 "
                                  "passes; stain 2 at (0.50, 0.20) m given up after 2 passes")


def test_a_pass_ends_after_pass_cycles_of_the_periodic_mp(learned_skill):
    """Without kappa a pass lasts ``pass_cycles`` cycles (or ``wipe_timeout_s``, whichever comes first)."""
    for cycles in (1.5, 3.0):
        ex = SkillExecutor(learned_skill, ExecutorParams(wipe_timeout_s=60.0, pass_cycles=cycles, max_passes=1,
                                                         survey_s=0.0))
        arm = IdealArm()
        ex.set_stains(BOARD, stains()[:1])
        ended = []
        run(ex, arm, 15.0, on_tick=lambda k, e: ended.append(e.chain.cycles_wiped)
            if not ended and e.counters["wipe_timeouts"] else None)
        assert ex.counters["wipe_timeouts"] == 1 and ex.phase == "DONE"
        assert ended and cycles <= ended[0] < cycles + 0.05, (cycles, ended)
    with pytest.raises(ConfigError, match="pass_cycles"):
        ExecutorParams(pass_cycles=0.0)


def test_the_retreat_brake_takes_as_long_as_the_kinematic_bounds_need():
    """A wiping stroke stopped at 0.3 m/s turning at 3.4 m/s^2: over 0.3 s the quintic stop peaks above 100 m/s^3;
    the bounded stop stretches until its jerk and acceleration fit, C2 from the stroke's state, to rest."""
    p0, v0, a0 = np.array([0.3, 0.2]), np.array([0.3, 0.0]), np.array([0.0, 3.4])
    plain = brake_to_rest(p0, v0, a0, 0.3)
    assert plain.peaks()[1] > 100.0
    q = bounded_brake_to_rest(p0, v0, a0, 0.3, 4.0, 100.0)
    acc, jerk = q.peaks()
    assert q.T > 0.3 and jerk <= 100.0 and acc <= 4.0
    dt = 1e-4  # the peaks hold on a fine grid too
    ts = np.arange(0.0, q.T + dt, dt)
    a = []
    for _ in ts:
        a.append(q.acceleration.copy())
        q.update(dt)
    j = np.linalg.norm(np.diff(np.array(a), axis=0), axis=1) / dt
    assert j.max() <= 100.0 * 1.01 and np.allclose(q.velocity, 0.0) and np.allclose(q.acceleration, 0.0)
    np.testing.assert_allclose(a[0], a0)
    easy = bounded_brake_to_rest(p0, 0.1 * v0, 0.0 * a0, 0.3, 4.0, 100.0)  # already within: as asked
    assert easy.T == 0.3


def test_the_brakes_closed_form_peaks_are_the_quintics_sampled_ones():
    rng = np.random.default_rng(7)
    for _ in range(50):
        n = int(rng.integers(2, 4))
        p0, v0, a0 = rng.normal(size=n), rng.normal(size=n) * 0.3, rng.normal(size=n) * 3.0
        durations = rng.uniform(0.05, 2.0, size=4)
        acc, jerk = brake_peaks(v0, a0, durations)
        for T, a, j in zip(durations, acc, jerk):
            np.testing.assert_allclose((a, j), brake_to_rest(p0, v0, a0, T).peaks(), rtol=1e-9, atol=1e-9)
    # the bounded stop is the first stretched try within both bounds, as trying them one by one would find
    p0, v0, a0 = np.zeros(2), np.array([0.3, 0.0]), np.array([0.0, 3.4])
    T = 0.3
    while brake_to_rest(p0, v0, a0, T).peaks()[1] > 60.0:
        T *= 1.2
    assert bounded_brake_to_rest(p0, v0, a0, 0.3, 4.0, 60.0).T == pytest.approx(T, rel=1e-12)


def test_the_retreat_leaves_room_in_the_jerk_bound_for_the_speed_override(learned_skill):
    """The retreat's stop is planned to the jerk bound less ``2 x 8/s x |a|`` (the override's scale may fall at 8/s
    while the stroke accelerates at ``a``: the executed jerk gains ``2 s (ds/dt) a``)."""
    ex = SkillExecutor(learned_skill, ExecutorParams(max_passes=1, survey_s=0.0))
    arm = IdealArm()
    ex.set_stains(BOARD, stains()[:1])
    seen = []
    run(ex, arm, 12.0, on_tick=lambda k, e: seen.append(e.motion.setpoint.a_xy.copy())
        if e.phase in ("WIPE", "TRANSITION") else None)
    assert ex.counters["phase_retreat"] == 1
    a0 = float(np.linalg.norm(seen[-1]))
    acc, jerk = ex.motion._xy_brake.peaks()
    assert a0 > 1.0 and jerk <= max(100.0 - 16.0 * a0, 25.0) + 1e-9 and acc <= 4.0


def test_the_last_stroke_heads_away_from_the_robot_base_before_the_retreat(learned_skill):
    """The retreat's stop runs on a few cm the way the stroke goes: towards the base, on a board near it, the elbow
    folds to its limit. The chain finishes when the stroke heads away from the base."""
    ex = SkillExecutor(learned_skill, ExecutorParams(max_passes=1, survey_s=0.0))
    arm = IdealArm()
    ex.set_stains(BOARD, stains()[:1])
    seen = []
    run(ex, arm, 12.0, on_tick=lambda k, e: seen.append((e.phase, e.motion.setpoint.v_xy.copy(),
                                                         e.motion.setpoint.xy.copy())))
    assert ex.counters["phase_retreat"] == 1
    k = next(i for i, (phase, _, _) in enumerate(seen) if phase == "RETREAT")
    v = seen[k - 1][1]
    away = 0.5 * BOARD.size_m - BOARD.to_board(np.zeros(3))[:2]
    away /= np.linalg.norm(away)
    assert v @ away > 0.8 * np.linalg.norm(v) > 0.0, "the last stroke heads away from the base"
    rest = [xy for phase, _, xy in seen[k:] if phase == "RETREAT"][-1]
    assert (rest - seen[k - 1][2]) @ away > 0.0, "and the stop runs on that way"


def test_look_point_is_beyond_the_stains_towards_the_robot_base_and_on_the_board():
    base_xy = BOARD.to_board(np.zeros(3))[:2]
    c = np.array([0.5, 0.3])
    p = look_point(BOARD, [c], [0.06], 0.1)
    toward = (base_xy - c) / np.linalg.norm(base_xy - c)
    np.testing.assert_allclose(p - c, 0.13 * toward, atol=1e-9)  # 3 cm stain radius + 10 cm clearance
    # clipped into the board when the stain is near the base's edge
    q = look_point(BOARD, [base_xy.clip(0.02, BOARD.size_m - 0.02)], [0.06], 0.5)
    assert np.all(q >= 0.0) and np.all(q <= BOARD.size_m)


def test_after_the_last_pass_without_kappa_the_pad_waits_off_the_stain_for_the_camera(learned_skill):
    """The arm hovering over the stain it just wiped hides it: the pad moves off it, on the base's side, and waits."""
    ex = SkillExecutor(learned_skill, ExecutorParams(wipe_timeout_s=1.5, recheck_s=1.0, max_passes=3))
    arm = IdealArm()
    s0 = stains()[0]
    ex.set_stains(BOARD, [s0])
    log = []
    t_done = None
    for k in range(20_000):
        sp = ex.step(0.001, arm.tool)
        arm.follow(sp)
        log.append((ex.phase, ex.current_mp, sp.xy.copy(), sp.h))
        if ex.phase == "DONE" and t_done is None:
            t_done = k
            break
    assert t_done is not None and ex.counters["looks"] == 1
    look = [e for e in log if e[1] == "look"]
    assert look and all(e[0] == "RETREAT" and e[3] >= ExecutorParams().standoff_m - 1e-9 for e in look)
    expected = look_point(BOARD, [s0.centre_m], [s0.size_m], ExecutorParams().look_clearance_m)
    np.testing.assert_allclose(log[-1][2], expected, atol=1e-6)
    # it waits there a full recheck_s (perception's time to look) before another pass
    log2 = run(ex, arm, 0.9)
    assert all(e[0] == "DONE" for e in log2)
    ex.set_stains(BOARD, [Stain(0, s0.centre_m, s0.size_m, kappa=True)])  # kappa from the fresh view
    log3 = run(ex, arm, 2.0)
    assert all(e[0] == "DONE" for e in log3) and ex.counters["wipe_timeouts"] == 1
    # without a clearance it holds where the pass ended, as before
    ex0 = SkillExecutor(learned_skill, ExecutorParams(wipe_timeout_s=1.5, look_clearance_m=0.0))
    ex0.set_stains(BOARD, [s0])
    run(ex0, IdealArm(), 8.0)
    assert ex0.counters["looks"] == 0


@pytest.mark.parametrize("phase, dt_s, mp", [("TRANSITION", float("nan"), "transitional"),
                                             ("WIPE", 0.5, "periodic")])
def test_a_runner_step_error_is_a_fault_naming_the_mp_and_the_status(learned_skill, phase, dt_s, mp):
    """A runner refuses the step (the transitional MP needs a finite dt, the periodic one dt <= 0.1 s): FAULT, no
    raise. (dt 0 is no error: the skill's clock stands still while the robot brakes.)"""
    ex = SkillExecutor(learned_skill, ExecutorParams())
    arm = IdealArm()
    ex.set_stains(BOARD, stains())
    for _ in range(20_000):
        arm.follow(ex.step(0.001, arm.tool))
        if ex.phase == phase:
            break
    running = ex.current_mp
    assert ex.phase == phase and running.startswith(mp)
    held = ex.step(0.0, arm.tool).xy.copy()
    assert ex.phase == phase and np.array_equal(ex.step(0.0, arm.tool).xy, held), "dt 0: the setpoint stands"
    ex.step(dt_s, arm.tool)
    assert ex.phase == "FAULT" and ex.reason == f"{running} MP step failed: ERROR_INVALID_INPUT"
    log = run(ex, arm, 2.0)
    assert ex.phase == "FAULT" and not log[-1][5] and log[-1][7] > 0.03  # lifted off and holding


def test_the_trace_phase_codes_follow_the_one_phase_list():
    from controller.core import PHASE_CODES
    from interfaces.messages import Phase

    assert list(PHASE_CODES) == [p.value for p in Phase] and PHASE_CODES[Phase.WIPE] == PHASE_CODES["WIPE"] == 3


def test_joint_speed_brake_acts_only_above_the_onset_against_the_motion_on_the_joint_inertia():
    onset = np.array([1.0, 1.0, 2.0])
    out = np.zeros(3)
    tau = joint_speed_brake_torque(np.array([0.5, -1.5, 2.5]), onset, 100.0, np.array([1.0, 2.0, 0.1]), out)
    assert tau is out
    np.testing.assert_allclose(tau, [0.0, 100.0 * 2.0 * 0.5, -100.0 * 0.1 * 0.5])


def test_speed_override_slows_to_the_share_holds_the_peak_and_recovers_slowly():
    dq_max = np.array([2.0, 1.0])
    ov = SpeedOverride(dq_max, share=0.5, min_scale=0.1, down_rate_1_s=8.0, up_rate_1_s=0.5, release_1_s=0.5)
    assert ov.update(np.array([0.9, 0.4]), 0.001) == 1.0, "0.45 of the limit: within the share"
    for _ in range(1000):  # the reference asks joint 2 for its full speed: half the speed is allowed
        s = ov.update(np.array([0.0, 1.0]), 0.001)
    assert s == pytest.approx(0.5) and ov.slowed_ticks > 0
    s_before = s
    for _ in range(100):  # a stroke turns round: the demand drops for 0.1 s, the held peak barely moves
        s = ov.update(np.array([0.0, 0.0]), 0.001)
    assert s == pytest.approx(s_before, abs=0.06)
    for _ in range(3000):
        s = ov.update(np.zeros(2), 0.001)
    assert s == 1.0, "back to full speed once the demand has gone"
    for _ in range(2000):  # an absurd demand (a singularity): never slower than min_scale
        s = ov.update(np.array([0.0, 1e6]), 0.001)
    assert s == pytest.approx(0.1)



def test_speed_override_lets_go_of_a_singular_spike_in_seconds():
    """A wrist passing a singularity asks, for a tick or two, a thousand times a joint's limit; the held peak must
    not keep the skill at its slowest for the half hour a fixed 0.5 limit/s release would take (board 96 of the
    random campaign crawled 200 s at the floor that way)."""
    dq_max = np.array([2.0, 1.0])
    ov = SpeedOverride(dq_max, share=0.5, min_scale=0.1, down_rate_1_s=8.0, up_rate_1_s=0.5, release_1_s=0.5)
    ov.update(np.array([0.0, 1000.0]), 0.001)
    assert ov.demand_share == pytest.approx(5.0), "held no higher than where the scale reaches its floor"
    s, t = ov.scale, 0.0
    while s < 1.0 and t < 30.0:
        s = ov.update(np.array([0.0, 0.3]), 0.001)
        t += 0.001
    assert s == 1.0 and 4.0 < t < 10.0, f"back at full speed after {t:.1f} s"
    ov.reset()
    for _ in range(200):  # a steady demand of twice the limits holds the scale where it belongs
        s = ov.update(np.array([0.0, 2.0]), 0.001)
    assert s == pytest.approx(0.25)


def _override_run(ov: SpeedOverride, j_along_m_s3: float, with_accel: bool, ticks: int = 400, dt: float = 0.001):
    """A skill accelerating at ``4 exp(-k sigma)`` m/s^2 along x, its planned jerk ``j_along`` at first (against
    the acceleration: the case where a falling scale adds to it); the joints ask for twice the override's share
    from tick 2. Returns the scales used and the executed in-plane acceleration ``s^2 a(sigma)`` per tick."""
    sigma, scales, executed = 0.0, [], []
    for k in range(ticks):
        s = ov.scale
        sigma += s * dt
        a = np.array([4.0 * np.exp(-j_along_m_s3 / 4.0 * sigma), 0.0])
        scales.append(s)
        executed.append(s * s * a)
        ov.update(np.array([0.0, 1.0 if k >= 2 else 0.2]), dt, a if with_accel else None)
    return np.array(scales), np.array(executed)


def test_the_speed_override_changes_its_scale_within_the_jerk_bound():
    """The executed acceleration is ``s^2 a``: its jerk is ``s^3 j + 2 s (ds/dt) a``. Falling at its full 8/s the
    scale would add 64 m/s^3 to a planned 80 m/s^3; with the skill's acceleration the override falls only as fast
    as keeps the executed jerk within the 100 m/s^3 bound, still well above its 1/s floor."""
    def run(with_accel, j):
        ov = SpeedOverride(np.ones(2), share=0.5, min_scale=0.1, jerk_bound_m_s3=100.0)
        scales, executed = _override_run(ov, j, with_accel)
        return ov, scales, np.linalg.norm(np.diff(executed, axis=0), axis=1) / 0.001

    ov, scales, jerk = run(False, 80.0)
    assert jerk.max() > 125.0 and ov.jerk_limited_ticks == 0, "the baseline: the scale's fall adds ~55 m/s^3"
    ov, scales, jerk = run(True, 80.0)
    assert jerk.max() <= 100.0 and ov.jerk_limited_ticks > 0
    rate = -np.diff(scales)[3:13] / 0.001
    assert np.all(rate >= 1.0 - 1e-9) and rate[:3].max() < 8.0, "slower than 8/s at first, at least the floor"
    assert scales[-1] == pytest.approx(0.5, abs=0.01), "the scale still reaches the speed share"
    # a planned jerk at the bound leaves no room: the floor wins (the joints' speed first), the excess is small
    ov, scales, jerk = run(True, 99.0)
    assert -np.diff(scales)[2] / 0.001 == pytest.approx(1.0, abs=0.05) and jerk.max() < 99.0 + 2 * 1.0 * 4.0 + 1.0


def test_the_jerk_limited_scale_is_the_nearest_to_the_wanted_within_the_step():
    # no acceleration: the scale does not change the jerk
    assert jerk_limited_scale(1.0, 0.99, 0.0, 0.0, 0.0, 0.0, 0.1) == 0.99
    # constant a = 4 along x: |s^2 - 1| 4 <= 0.05 -> s >= sqrt(1 - 0.0125)
    s = jerk_limited_scale(1.0, 0.9, 4.0, 0.0, 4.0, 0.0, 0.05)
    assert s == pytest.approx(np.sqrt(1.0 - 0.0125))
    # the wanted scale within the step: unchanged; rising works alike
    assert jerk_limited_scale(1.0, 0.999, 4.0, 0.0, 4.0, 0.0, 0.05) == 0.999
    assert jerk_limited_scale(0.5, 0.6, 4.0, 0.0, 4.0, 0.0, 0.05) == pytest.approx(np.sqrt(0.25 + 0.0125))
    # a planned acceleration that changes by more than the step: a rising one (4 -> 4.5 next tick) is met by a
    # lower scale, the one nearest the wanted; against a falling one (4 -> 3.5) no fall helps: the least jerk, stay
    assert jerk_limited_scale(1.0, 0.9, 4.0, 0.0, 4.5, 0.0, 0.01) == pytest.approx(np.sqrt(3.99 / 4.5))
    assert jerk_limited_scale(1.0, 0.9, 4.0, 0.0, 3.5, 0.0, 0.01) == 1.0


def test_a_loop_that_cannot_keep_up_slows_the_motion_smoothly_before_the_overload_ends_it():
    from controller.control.limits import load_scale

    assert load_scale(0.0, 0.05, 0.3, 0.4) == 1.0 and load_scale(0.05, 0.05, 0.3, 0.4) == 1.0
    assert load_scale(0.175, 0.05, 0.3, 0.4) == pytest.approx(0.7)  # half-way: half-way down
    assert load_scale(0.3, 0.05, 0.3, 0.4) == pytest.approx(0.4) and load_scale(0.9, 0.05, 0.3, 0.4) == 0.4
    shares = np.linspace(0.0, 0.5, 51)
    assert np.all(np.diff([load_scale(x, 0.05, 0.3, 0.4) for x in shares]) <= 0.0)  # never faster with more load
    ov = SpeedOverride(np.ones(2), share=0.5, min_scale=0.1, down_rate_1_s=8.0, up_rate_1_s=0.5)
    ov.load_cap = 0.4
    scales = [ov.update(np.zeros(2), 0.001) for _ in range(200)]
    assert scales[-1] == pytest.approx(0.4) and ov.load_limited_ticks == 200
    assert max(abs(np.diff(scales))) <= 8.0 * 0.001 + 1e-12, "the scale moves at the override's rate, no jump"
    ov.load_cap = 1.0  # the load is gone: back up at the slow rate
    scales = [ov.update(np.zeros(2), 0.001) for _ in range(2000)]
    assert scales[0] == pytest.approx(0.4005) and scales[-1] == 1.0
    # a demand that asks for less than the load allows: the demand sets the pace, not the load
    ov.load_cap = 0.8
    for _ in range(3000):
        s = ov.update(np.array([0.0, 2.0]), 0.001)
    assert s == pytest.approx(0.25) and ov.load_limited_ticks == 200


def test_the_slowing_starts_below_the_overload_limit():
    from controller.params import ControllerParams

    with pytest.raises(ConfigError, match="overload_slow_share must be below overload_share"):
        ControllerParams.from_table({"limits": {"overload_slow_share": 0.3, "overload_share": 0.3}})


def test_the_controller_caps_its_task_modes_for_the_robot_state_rate(learned_skill):
    """A robot declaring 500 Hz (FRI at 2 ms) gets half the configured cap on every task mode, at once; 1 kHz
    and an undeclared rate keep the configured one."""
    import scipy.linalg

    from controller.control.impedance import Kinematics
    from controller.core import ControllerCore

    core = ControllerCore(ControllerParams(), learned_skill)
    kin = Kinematics(core.model).update(np.array([0.2, 0.5, -0.3, -1.3, 0.4, 0.8, -0.2]), np.zeros(7))

    def fastest_mode_rad_s() -> float:
        modes = core._task_modes(kin)
        return float(np.sqrt(scipy.linalg.eigh(modes.stiffness(), kin.Lambda, eigvals_only=True).max()))

    configured = core.p.impedance.max_mode_frequency_rad_s
    assert fastest_mode_rad_s() == pytest.approx(configured, rel=1e-6)  # the wrist's spin is capped
    core.follow_robot_rate(500.0)
    assert core.mode_cap_rad_s == pytest.approx(configured / 2)
    assert fastest_mode_rad_s() == pytest.approx(configured / 2, rel=1e-6)
    for rate in (1000.0, 0.0):
        core.follow_robot_rate(rate)
        assert fastest_mode_rad_s() == pytest.approx(configured, rel=1e-6)


class _SlowPlans(concurrent.futures.ThreadPoolExecutor):
    """The planner thread, slowed: each plan is handed back only after the loop ran ``ticks`` more ticks (a
    long re-plan on a loaded machine), and the plans made are kept."""

    def __init__(self, ticks: int) -> None:
        super().__init__(max_workers=1)
        self.ticks, self.plans, self.release = ticks, [], threading.Event()

    def submit(self, fn, *args, **kwargs):
        if fn.__name__ != "plan":  # the next transition's duration search: done at once, so the test is exact
            done = concurrent.futures.Future()
            done.set_result(fn(*args, **kwargs))
            self.durations = getattr(self, "durations", 0) + 1
            return done

        def slow():
            result = fn(*args, **kwargs)
            self.release.wait(10.0)
            self.release.clear()
            self.plans.append([w.stain.id for w in result.wipes])
            return result
        return super().submit(slow)


def test_the_real_time_chain_re_plans_on_the_planner_thread_and_wipes_on_meanwhile(learned_skill):
    """With a planner thread (the real-time loop's), a re-plan never runs in the tick: the stain's periodic MP
    goes on until the plan comes back, then the chain leaves towards the plan's first stain as in the tick,
    the junctions as continuous. A failed plan is a FAULT naming it, not an exception in the loop."""
    def wipe(ex: SkillExecutor, release_after: int | None) -> tuple[list, dict, int]:
        arm = IdealArm()
        ex.set_stains(BOARD, stains())
        wiped: dict[int, int] = {}
        waiting = [0]

        def tick(k, ex):
            if ex.phase == "WIPE":
                wiped[ex.stain_id] = wiped.get(ex.stain_id, 0) + 1
            if k % 100 == 0:
                ex.set_stains(BOARD, stains(tuple(wiped.get(i, 0) > 2000 for i in range(3))))
            release = getattr(ex.chain.background, "release", None)
            if ex.chain.step == ChainStep.REPLAN:
                waiting[0] += 1
                if release is not None and waiting[0] % release_after == 0:
                    release.set()

        return run(ex, arm, 30.0, tick), ex.counters, waiting[0]

    params = ExecutorParams(pass_cycles=1e6)  # kappa, 2 s in, ends each pass
    inline = SkillExecutor(learned_skill, params)
    log_inline, _, _ = wipe(inline, None)
    threaded = SkillExecutor(learned_skill, params)
    threaded.chain.background = pool = _SlowPlans(0)
    try:
        log_threaded, counters, waited = wipe(threaded, 25)
    finally:
        pool.shutdown()
    seq = [p for p in phases(log_threaded) if p != "WAIT_PEERS"]
    assert seq == ["APPROACH", "TRANSITION", "WIPE", "TRANSITION", "WIPE", "TRANSITION", "WIPE", "RETREAT", "DONE"]
    # the same stains in the same order as the re-plans in the tick; each waited for ~25 ticks, wiping
    def visits(log):
        return [s for i, (p, s, *_) in enumerate(log) if p == "TRANSITION" and log[i - 1][0] != p]

    assert visits(log_threaded) == visits(log_inline)
    assert pool.plans and counters["replans"] == len(pool.plans) == inline.counters["replans"]
    assert counters["ticks_waiting_for_a_plan"] >= 24 * len(pool.plans) and waited >= 24 * len(pool.plans)
    # each transition's duration was searched off the tick (for the exit state), none in it
    assert pool.durations == 2 and counters["transitions_searched_in_tick"] == 0
    a = np.array([e[4] for e in log_threaded])
    steps = np.linalg.norm(np.diff(a, axis=0), axis=1)
    for j in threaded.junction_ticks:
        around = np.concatenate([steps[j - 7 : j - 2], steps[j : j + 5]])
        assert steps[j - 2] <= 3.0 * around.max() + 1e-3, (j, steps[j - 2], around.max())

    # a plan that fails on the planner thread
    failing = SkillExecutor(learned_skill, ExecutorParams())
    failing.chain.background = broken = concurrent.futures.ThreadPoolExecutor(max_workers=1)
    try:
        import lampskit.core.chain as chain_module

        def bad_plan(*args, **kwargs):
            raise PlanningError("no order found (test)")

        real_plan, chain_module.plan = chain_module.plan, bad_plan
        try:
            log_failing, _, _ = wipe(failing, 1)
        finally:
            chain_module.plan = real_plan
    finally:
        broken.shutdown()
    assert "FAULT" in phases(log_failing) and "planning failed: no order found (test)" in failing.reason


def test_the_planner_thread_exists_at_once_and_shortens_the_switch_interval_only_while_planning():
    import sys

    from controller.planner_thread import SWITCH_INTERVAL_S, PlannerThread

    normal = sys.getswitchinterval()
    pool = PlannerThread()
    try:
        assert any(t.name.startswith("lamps-planner") for t in threading.enumerate())  # before any plan
        go = threading.Event()
        future = pool.submit(lambda: go.wait(5.0) and sys.getswitchinterval())
        assert sys.getswitchinterval() == pytest.approx(SWITCH_INTERVAL_S)
        go.set()
        assert future.result(5.0) == pytest.approx(SWITCH_INTERVAL_S)
        for _ in range(100):  # the done callback runs right after the result is set
            if sys.getswitchinterval() == normal:
                break
            threading.Event().wait(0.01)
        assert sys.getswitchinterval() == normal
    finally:
        pool.shutdown()
        sys.setswitchinterval(normal)


@pytest.mark.skipif(not hasattr(os, "sched_setscheduler"), reason="Linux scheduling")
def test_the_planner_runs_its_jobs_at_the_lowest_fifo_priority_while_its_loop_runs_fifo():
    """A fair planner thread holding the interpreter waits for a core behind every FIFO thread while the loop
    waits for the interpreter; while the loop runs SCHED_FIFO, each job runs at SCHED_FIFO 1."""
    from controller.planner_thread import PLAN_PRIORITY, PlannerThread

    def policy() -> tuple[int, int]:
        return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority

    loop = {}

    def loop_thread() -> None:  # a loop's thread makes the planner, then turns real-time, as the service does
        pool = PlannerThread()
        try:
            loop["fair"] = pool.submit(policy).result(5.0)
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
            except PermissionError:
                loop["skip"] = True
                return
            loop["fifo"] = pool.submit(policy).result(5.0)
            loop["said"] = pool.policy
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
            loop["back"] = pool.submit(policy).result(5.0)
        finally:
            pool.shutdown()

    t = threading.Thread(target=loop_thread)
    t.start()
    t.join(20.0)
    if loop.get("skip"):
        pytest.skip("no permission for SCHED_FIFO here")
    assert loop["fair"] == (os.SCHED_OTHER, 0)
    assert loop["fifo"] == (os.SCHED_FIFO, PLAN_PRIORITY) and loop["said"] == f"FIFO {PLAN_PRIORITY}"
    assert loop["back"] == (os.SCHED_OTHER, 0)


def test_the_overload_watch_trips_on_a_sustained_share_of_unanswered_states_only():
    from controller.control.watch import OverloadWatch

    w = OverloadWatch(max_share=0.3, filter_s=0.5, persist_s=1.0)
    for _ in range(5000):  # 5 s at 1 kHz with one state in 20 unanswered (5 %): never
        assert not w.update(0, 0.001) or False
        if _ % 20 == 0:
            assert not w.update(1, 0.002)
    assert w.share < 0.1 and not w.tripped
    for _ in range(300):  # a 0.6 s burst of every other state unanswered: over the limit, but not for 1 s
        w.update(1, 0.002)
    assert w.share > 0.3 and not w.tripped
    for _ in range(1000):  # back to normal
        w.update(0, 0.001)
    assert w.share < 0.05 and w.over_s == 0.0
    t = 0.0
    while not w.update(1, 0.002):  # sustained: half the states unanswered
        t += 0.002
        assert t < 3.0
    assert 1.0 <= t <= 2.0, t  # the filter's rise, then the 1 s persistence
    assert "overload: " in w.reason() and "limit 30% for 1 s" in w.reason()
    w.reset()
    assert not w.tripped and w.share == 0.0
    off = OverloadWatch(max_share=1.0, filter_s=0.5, persist_s=0.0)
    assert not any(off.update(10, 0.011) for _ in range(1000))  # 1 = off


def test_after_an_overload_fault_the_watch_says_when_the_load_has_passed():
    from controller.control.watch import OverloadWatch

    w = OverloadWatch(max_share=0.3, filter_s=0.5, persist_s=1.0, calm_share=0.05, calm_s=3.0)
    assert not w.calm_again(10.0), "nothing to recover from before a fault"
    while not w.update(1, 0.002):
        pass
    w.reset()
    w.faulted()
    t = 0.0
    for _ in range(1000):  # still loaded: every other state unanswered for 2 s
        w.update(1, 0.002)
        assert not w.calm_again(0.002)
    w.share = 0.5
    while True:  # the load passes: the share decays below 5 %, then 3 s of calm
        w.update(0, 0.001)
        t += 0.001
        if w.calm_again(0.001):
            break
        assert t < 10.0
    assert 3.0 <= t <= 5.5, t
    assert not w.calm_again(10.0), "once"
    never = OverloadWatch(0.3, 0.5, 1.0, 0.05, calm_s=0.0)
    never.faulted()
    assert not never.calm_again(100.0)

