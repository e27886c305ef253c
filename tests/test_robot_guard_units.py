"""The robot side's own limits without a network: the pure parts (robot.guard_bands), the gate's ramp after a hold,
the description's prediction (robot.guard_model), the guard's decisions (robot.guard) and the sim's yield."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pinocchio as pin
import pytest

from arm.description import PAD_SIZE_M
from arm.robot_model import RobotModel
from interfaces.errors import ConfigError
from interfaces.messages import HOLD, TorqueCommand
from robot.command import CommandKind
from robot.gate import CommandGate
from robot.guard import Action, GuardLimits, RobotGuard
from robot.guard_bands import Band, ContactPlane, FaultLatch, Trend, ahead_of, look_ahead_into
from robot.guard_model import ToolMotion
from robot.mock import MockArm
from robot.server import ServerParams

Q0 = np.array([0.558, 0.301, -0.66, -1.896, -0.143, -0.586, -1.268])  # the sim's start pose facing the wall board


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel()


def cmd(tau, mode: str = "torque") -> TorqueCommand:
    return TorqueCommand(seq=0, stamp_ns=0, tau_nm=[float(v) for v in tau], mode=mode)


# ------------------------------------------------------------------------------------------ look-ahead, bands, latch

@pytest.mark.parametrize("x, d, ahead", [
    (0.5, 0.1, 0.6),   # gaining: one more such gain
    (0.5, -0.1, 0.5),  # falling: no risk, the magnitude itself
    (0.5, 0.0, 0.5),
])
def test_the_look_ahead_extrapolates_a_gain_never_a_fall(x, d, ahead):
    assert look_ahead_into(np.array([x]), np.array([d]), np.zeros(1))[0] == pytest.approx(ahead)


def test_a_trend_looks_one_gain_ahead_of_each_magnitude():
    t = Trend(2)
    np.testing.assert_allclose(t.update(np.array([0.3, 0.0])), [0.3, 0.0]), "the first sample: itself"
    np.testing.assert_allclose(t.update(np.array([0.4, 0.1])), [0.5, 0.2])
    np.testing.assert_allclose(t.update(np.array([0.35, 0.1])), [0.35, 0.1])
    assert ahead_of(0.4, 0.3) == pytest.approx(0.5) and ahead_of(0.3, 0.4) == 0.3


def test_a_band_engages_above_its_brake_share_and_lets_go_only_under_its_release():
    band = Band(0.95, 0.8)
    shares = [0.5, 0.9, 0.96, 0.99, 0.9, 0.85, 0.81, 0.79, 0.9, 0.94, 0.96]
    entered, engaged = [], []
    for s in shares:
        entered.append(band.update(s, s))
        engaged.append(band.engaged)
    assert engaged == [False, False, True, True, True, True, True, False, False, False, True]
    assert entered == [False, False, True, False, False, False, False, False, False, False, True], "one entry each"
    assert not Band(0.95, 0.8).update(0.9, 0.9) and Band(0.95, 0.8).update(0.96, 0.5), "the look-ahead engages"


def test_the_fault_latches_on_the_nth_entry_within_the_window_and_the_release_starts_afresh():
    latch = FaultLatch(3, 1.0)
    assert [latch.note(t) for t in (0.0, 0.6, 1.2, 1.7)] == [False, False, False, False], "never 3 within 1 s"
    assert latch.note(2.1) and latch.latched, "1.2, 1.7, 2.1: three within 1 s"
    assert not latch.note(2.2), "latched once"
    latch.release()
    assert not latch.latched and not latch.note(2.3) and not latch.note(2.4) and latch.note(2.5)


def test_the_press_speed_of_the_pad_is_its_fastest_corner_into_the_surface_by_finite_differences():
    rng = np.random.default_rng(3)
    plane = ContactPlane(0.01)
    R = pin.exp3(rng.normal(size=3) * 0.2)
    plane.touch(np.zeros(3), R[:, 2])
    half = (PAD_SIZE_M[0] / 2, PAD_SIZE_M[1] / 2)
    for _ in range(20):
        v, w = rng.normal(size=3) * 0.05, rng.normal(size=3) * 0.5
        dt = 1e-6
        corners = [R @ np.array([sx * half[0], sy * half[1], 0.0]) for sx in (-1, 1) for sy in (-1, 1)]
        moved = [(dt * v + pin.exp3(w * dt) @ r - r) @ plane.axis / dt for r in corners]
        assert plane.approach(v, w, R, half) == pytest.approx(max(moved), abs=1e-6)
    assert plane.near(-0.005 * plane.axis) and not plane.near(-0.02 * plane.axis) and plane.near(0.01 * plane.axis)


# ------------------------------------------------------------------------------------------ the gate's ramp

def test_after_a_hold_the_gate_ramps_from_what_the_arm_held_not_from_nothing_and_not_to_the_command():
    counters = Counter()
    gate = CommandGate(np.full(2, 100.0), counters, tau_rate_nm_s=5000.0, dt_s=0.001)  # 5 Nm a cycle
    gate.ran(np.array([30.0, -10.0]))  # the brakes held 30 and -10 Nm before the first command
    np.testing.assert_array_equal(gate.accept(cmd([100.0, 100.0])).tau_nm, [35.0, -5.0])
    assert gate.accept(cmd([0.0, 0.0], HOLD)).kind is CommandKind.HOLD
    gate.ran(np.array([20.0, 0.0]))  # what the hold applied
    np.testing.assert_array_equal(gate.accept(cmd([100.0, 100.0]), elapsed_s=0.05).tau_nm, [25.0, 5.0]), \
        "however long the hold, one cycle's step from it"
    np.testing.assert_array_equal(gate.accept(cmd([100.0, 100.0]), elapsed_s=0.003).tau_nm, [40.0, 20.0]), \
        "a late command after applied ones: the cycles between ran on the last"
    # real time: the newest command is applied again each cycle; after a brake it climbs from the brakes' torque
    gate.ran(np.array([0.0, 0.0]))
    target = gate.check(cmd([12.0, -12.0])).tau_nm.copy()
    assert [gate.limit_rate(target).tolist() for _ in range(4)] == [[5.0, -5.0], [10.0, -10.0], [12.0, -12.0],
                                                                  [12.0, -12.0]]
    assert counters["commands_rate_limited"] == 5 and counters["commands_applied"] == 4


def test_while_the_pad_touches_the_gate_ramps_at_the_contact_rate():
    gate = CommandGate(np.full(1, 100.0), Counter(), tau_rate_nm_s=10_000.0, dt_s=0.001, contact_tau_rate_nm_s=2000.0)
    gate.ran(np.zeros(1))
    assert gate.accept(cmd([50.0])).tau_nm[0] == 10.0
    gate.touching = True
    assert gate.accept(cmd([50.0])).tau_nm[0] == 12.0
    gate.touching = False
    assert gate.accept(cmd([50.0])).tau_nm[0] == 22.0


# ------------------------------------------------------------------------------------------ the description's view

def test_the_pad_velocity_is_the_derivative_of_its_pose_and_the_prediction_is_the_forward_dynamics(model):
    rng = np.random.default_rng(0)
    tool = ToolMotion(model, gravity_compensated=False)
    q, dq = Q0 + rng.normal(size=7) * 0.1, rng.normal(size=7) * 0.3
    tool.update(q, dq)
    h = 1e-7
    p1, R1 = model.tcp_pose(q + h * dq)
    np.testing.assert_allclose(tool.v, (p1 - tool.p) / h, atol=1e-5)
    np.testing.assert_allclose(tool.w, pin.log3(R1 @ tool.R.T) / h, atol=1e-5)
    tau = rng.normal(size=7) * 5.0
    M = pin.crba(model.model, model.model.createData(), q)
    M = np.triu(M) + np.triu(M, 1).T
    h_nle = pin.rnea(model.model, model.model.createData(), q, dq, np.zeros(7))
    dt = 0.001
    np.testing.assert_allclose(tool.predict(q, dq, tau, dt), dq + dt * np.linalg.solve(M, tau - h_nle), atol=1e-9)
    compensated = ToolMotion(model, gravity_compensated=True)
    np.testing.assert_allclose(compensated.predict(q, dq, tau - model.gravity(q), dt),
                               dq + dt * np.linalg.solve(M, tau - h_nle), atol=1e-9)


def limits(**kw) -> GuardLimits:
    base = dict(joint_speed_rad_s=np.full(7, 1.0), tool_speed_m_s=1.0, press_speed_m_s=0.05, press_zone_m=0.01,
                pad_half_m=(0.06, 0.025), brake_share=0.95, release_share=0.8, contact_n=5.0, force_cap_n=45.0,
                force_release_share=0.8, damping_nm_s_rad=np.full(7, 2.0), fault_episodes=5, fault_window_s=1.0)
    return GuardLimits(**{**base, **kw})


def test_a_command_that_would_spin_a_wrist_past_its_brake_within_a_cycle_is_braked_before_it_is_applied(model):
    """A7 gains a third of its limit from a 10 Nm step in one cycle: no trend of its past speeds foresees that."""
    guard = RobotGuard(limits(joint_speed_rad_s=model.limits.dq_max), model)
    g = model.gravity(Q0)
    assert guard.observe(Q0, np.zeros(7), np.zeros(6), 0.0) == () and guard.action == Action.APPLY
    assert guard.check_command(Q0, np.zeros(7), g + [0, 0, 0, 0, 0, 0, 1.0], 0.001, 0.0) == ()
    step = g + [0, 0, 0, 0, 0, 0, 30.0]
    assert guard.check_command(Q0, np.zeros(7), step, 0.001, 0.0) == ("joint_speed",)
    assert guard.worst_joint == 6 and guard.entry_value["joint_speed"] > 0.95 * model.limits.dq_max[6]
    assert guard.action == Action.BRAKE
    dq = np.zeros(7)
    dq[6] = 0.85 * model.limits.dq_max[6]  # braking: still over the release share
    guard.observe(Q0, dq, np.zeros(6), 0.001)
    assert guard.action == Action.BRAKE
    dq[6] = 0.75 * model.limits.dq_max[6]
    guard.observe(Q0, dq, np.zeros(6), 0.002)
    assert guard.action == Action.APPLY, "let go under 0.8"


def test_a_force_over_the_cap_yields_until_under_its_release_and_the_yield_is_damping_only():
    guard = RobotGuard(limits(), None)
    f = np.zeros(6)
    for t, fx, action in ((0.0, 10.0, Action.APPLY), (0.001, 20.0, Action.APPLY), (0.002, 30.0, Action.APPLY),
                          (0.003, 38.0, Action.YIELD),  # 46 N by the next cycle at its last gain
                          (0.004, 40.0, Action.YIELD), (0.005, 37.0, Action.YIELD), (0.006, 35.0, Action.APPLY)):
        f[0] = fx
        guard.observe(Q0, np.zeros(7), f, t)
        assert guard.action == action, (fx, guard.action)
    dq = np.linspace(-1.0, 1.0, 7)
    np.testing.assert_allclose(guard.damping_into(dq, np.zeros(7)), -2.0 * dq)


def test_five_episodes_within_a_second_latch_the_fault_which_yields_while_pressing_and_brakes_otherwise():
    guard = RobotGuard(limits(), None)
    f, t = np.zeros(6), 0.0
    for _ in range(5):
        for fx in (10.0, 50.0):  # into the band and out again
            f[0], t = fx, t + 0.01
            entered = guard.observe(Q0, np.zeros(7), f, t)
    assert entered == ("contact_force", "fault") and "5 limit episodes within 1 s" in guard.fault_reason
    assert guard.action == Action.YIELD, "a held pad presses on: the force first"
    f[0] = 10.0
    guard.observe(Q0, np.zeros(7), f, t + 0.01)
    assert guard.action == Action.FAULT
    assert guard.release() and guard.action == Action.APPLY and guard.fault_reason is None


def test_episodes_that_begin_while_the_arm_is_already_held_do_not_latch_the_fault_but_are_counted():
    """A wiping pad braked on a stale command rocks on its edge: its bands flicker while nothing of the controller's
    runs. Those entries are the hold's doing; the same entries on the controller's torques latch."""
    guard = RobotGuard(limits(), None)
    f, t = np.zeros(6), 0.0
    for _ in range(8):
        for fx in (10.0, 50.0):
            f[0], t = fx, t + 0.01
            guard.observe(Q0, np.zeros(7), f, t, held=True)
    assert not guard.latch.latched and guard.episodes_in_hold == 8 and guard.fault_reason is None
    for k in range(5):
        for fx in (10.0, 50.0):
            f[0], t = fx, t + 0.01
            entered = guard.observe(Q0, np.zeros(7), f, t, held=False)
        assert guard.latch.latched == (k == 4), k
    assert entered == ("contact_force", "fault") and guard.episodes_in_hold == 8


def test_a_pad_pressing_into_the_surface_it_touched_too_fast_yields_and_one_near_it_brakes(model):
    guard = RobotGuard(limits(joint_speed_rad_s=model.limits.dq_max), model)
    p, R = model.tcp_pose(Q0)
    J = model.tcp_jacobian(Q0)
    into = np.linalg.pinv(J) @ np.concatenate([R[:, 2], np.zeros(3)])  # joint speeds moving the pad along its axis
    touching = np.concatenate([-12.0 * R[:, 2], np.zeros(3)])  # the board pushing the pad back
    guard.observe(Q0, 0.01 * into, touching, 0.0)
    assert guard.touching and guard.plane.known and guard.action == Action.APPLY
    guard.observe(Q0, 0.06 * into, touching, 0.001)
    assert guard.bands["press_speed"].engaged and guard.action == Action.YIELD
    guard.observe(Q0, 0.03 * into, touching, 0.002)
    assert guard.action == Action.APPLY
    guard.observe(Q0, 0.06 * into, np.zeros(6), 0.003)  # lifted a hair, rushing back: a brake, not a yield
    assert guard.action == Action.BRAKE


def test_server_params_state_their_ranges_and_the_brake_bands_order():
    with pytest.raises(ConfigError, match=r"\[robot\] force_cap_n must be a number in \[0.0, 1000.0\], got -1"):
        ServerParams(force_cap_n=-1.0)
    with pytest.raises(ConfigError, match="speed_release_share .* must not be above speed_brake_share"):
        ServerParams(speed_release_share=0.96)
    lim = ServerParams(speed_brake_share=0.0).guard_limits(MockArm(dq_max_rad_s=np.ones(7)))
    assert lim.joint_speed_rad_s is None and lim.tool_speed_m_s == 0.0 and lim.press_speed_m_s == 0.0, \
        "no speed brakes at all: the force cap and the latch stay"
    assert lim.force_cap_n == 45.0


# ------------------------------------------------------------------------------------------ the sim's yield

def pressed_sim(model: RobotModel, force_n: float):
    """A sim (wall board, the pad 1 cm off it) whose pad a scripted client pressed onto the board at ``force_n``;
    returns the port (:class:`sim.service.SimPort` on an in-process bus)."""
    from runtime.local_bus import LocalBus, LocalNode
    from sim.core import SimCore
    from sim.params import SimParams
    from sim.service import SimPort

    params = SimParams.from_table({"camera": {"enabled": False}, "start_standoff_m": 0.01})
    core = SimCore(params)
    port = SimPort(params, LocalNode("sim", LocalBus()).__enter__(), core)
    n = core.board.normal_world
    p0, R0 = model.tcp_pose(core.out.q)
    for k in range(1500):  # approach at 2 cm/s, then press
        q, dq = core.out.q.copy(), core.out.dq.copy()
        J = model.tcp_jacobian(q)
        p, R = model.tcp_pose(q)
        v = J @ dq
        e = p0 - p
        e -= (e @ n) * n
        vn = v[:3] @ n
        push = force_n * min(k / 500, 1.0) if core.out.normal_force_n > 1.0 or k > 700 else \
            float(np.clip(400.0 * (vn + 0.02), -10.0, 10.0))
        f = 600.0 * e - 50.0 * (v[:3] - vn * n) - push * n - 40.0 * vn * n
        w = 60.0 * pin.log3(R0 @ R.T) - 8.0 * v[3:]
        port.write(model.gravity(q) + J.T @ np.concatenate([f, w]) - dq)
    return port


def test_a_brake_holds_a_pressed_pad_at_its_force_and_the_yield_lets_the_board_push_it_back(model):
    """Why the robot side yields, not brakes, when the contact force is over its cap: the sim's brake holds the
    pose, and with it the felt's compression; the yield (gravity compensated, damped, no task torque) leaves the
    pad nothing to press with."""
    outcomes = {}
    for response in ("brake", "yield"):
        port = pressed_sim(model, 60.0)
        start = port.core.out.normal_force_n
        damping = 0.1 * port.core.tau_max / port.core.dq_max  # ServerParams' yield_damping_share
        forces = []
        for _ in range(100):
            if response == "brake":
                port.speed_hold()
            else:
                port.yield_hold(-damping * port.core.out.dq)
            forces.append(port.core.out.normal_force_n)
        outcomes[response] = (start, forces, port.held_torque_nm(), model.gravity(port.core.out.q))
        port.core.close()
    start, forces, _, _ = outcomes["brake"]
    assert start > 50.0 and min(forces[20:]) > 0.8 * start, (start, min(forces[20:]))
    start, forces, held, gravity = outcomes["yield"]
    assert start > 50.0 and max(forces[30:]) < 5.0, (start, max(forces[30:]))
    np.testing.assert_allclose(held, gravity, atol=0.5), "what the yield ran on (the rate limit's next reference)"
