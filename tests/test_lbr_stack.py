"""The simulated lbr_fri_ros2_stack (sim/lbr_stack): its filters, PID, session, FRI and ros2_control sides.

Each test pins one behaviour of the stack's code (``rolling`` 218d723) as
sim/lbr_stack/stack.py cites it, so that a model that behaves differently
fails here: pure numpy, no network, no PyBullet.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from arm.robot_model import RobotModel
from robot.lbr.compensation import filter_alpha
from robot.lbr.msgs import ClientCommandMode, SessionState
from robot.lbr.tip import tip_jacobian, tip_pose
from sim.lbr_stack.params import LbrPeerParams
from sim.lbr_stack.stack import (
    ExponentialFilter,
    FriCommand,
    JointPid,
    RobotSession,
    StackClient,
    StackError,
    estimated_wrench,
    impedance_damping,
    joint_impedance_torque,
    soft_threshold,
)

READY, WAIT, ACTIVE = SessionState.MONITORING_READY, SessionState.COMMANDING_WAIT, SessionState.COMMANDING_ACTIVE
TORQUE = int(ClientCommandMode.TORQUE)
T_S = 0.001  # FRI sample time [s]
MS = 1_000_000  # [ns]
ZERO = np.zeros(7)
#: A joint configuration well inside the limits, tip rotated away from the base axes.
Q0 = np.array([0.1, 0.4, -0.2, -1.2, 0.3, 0.8, 0.0])


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel()


def make_client(model: RobotModel, **overrides) -> StackClient:
    """A stack configured as a torque-commanding cell must configure it (torque mode, open_loop off) + overrides."""
    kw = {"client_command_mode": "torque", "open_loop": False, **overrides}
    lim = model.limits
    return StackClient(LbrPeerParams(**kw), lim.q_min, lim.q_max, lim.dq_max)


def fri(client: StackClient, session: SessionState, q: np.ndarray, tau_measured: np.ndarray = ZERO,
        tau_external: np.ndarray = ZERO, mode: int = TORQUE) -> FriCommand | None:
    return client.fri_cycle(session, q, q, tau_measured, tau_external, mode, T_S)


def activate(client: StackClient, q: np.ndarray = Q0) -> None:
    """WAIT, then ACTIVE (FRI), then one controller-manager cycle that sees ACTIVE (no message yet)."""
    fri(client, WAIT, q)
    fri(client, ACTIVE, q)
    client.cm_cycle()


# -- the stack's defaults -------------------------------------------------------------------------------------
def test_params_defaults_are_the_stacks():
    p = LbrPeerParams()
    assert (p.pid_p, p.pid_i, p.pid_d) == (0.1, 0.0, 0.0)
    assert p.joint_stiffness_nm_rad == 200.0
    assert p.open_loop is True
    assert p.client_command_mode == "position"
    assert (p.measured_torque_cutoff_hz, p.external_torque_cutoff_hz) == (10.0, 10.0)


# -- filter_alpha and ExponentialFilter (filters.cpp:23-28, state.cpp) --------------------------------------------
def _alpha_reference(cutoff_hz: float, sample_time_s: float) -> float:
    c = math.cos(2.0 * math.pi * sample_time_s * cutoff_hz)
    return c - 1.0 + math.sqrt(c * c - 4.0 * c + 3.0)


@pytest.mark.parametrize("cutoff_hz, sample_time_s", [(10.0, 0.001), (1.0, 0.001), (100.0, 0.001), (50.0, 0.005),
                                                     (10.0, 0.01), (300.0, 0.001)])
def test_filter_alpha_is_the_stacks_formula(cutoff_hz, sample_time_s):
    assert filter_alpha(cutoff_hz, sample_time_s) == pytest.approx(_alpha_reference(cutoff_hz, sample_time_s),
                                                                   rel=1e-12)


def test_filter_alpha_values():
    assert filter_alpha(10.0, 0.001) == pytest.approx(0.0609, abs=5e-5)
    assert filter_alpha(0.0, 0.001) == 0.0  # cutoff 0: frozen
    assert filter_alpha(1000.0, 0.001) == 0.0  # cutoff exactly 1 / T: frozen too
    assert filter_alpha(100.0, 0.01) == pytest.approx(0.0, abs=1e-7)
    # below 1 / T it grows with the cutoff
    alphas = [filter_alpha(f, 0.001) for f in (1.0, 10.0, 100.0, 250.0)]
    assert all(0.0 < a < b < 1.0 for a, b in zip(alphas, alphas[1:]))


def test_exponential_filter_first_sample_zero_then_alpha_weighted():
    f = ExponentialFilter(10.0, n=3)
    a = filter_alpha(10.0, T_S)
    x = np.array([5.0, -2.0, 0.5])
    assert np.array_equal(f.update(x, T_S), np.zeros(3))  # the default filter (alpha 0) on the first sample
    assert f.alpha == a
    np.testing.assert_allclose(f.update(x, T_S), a * x, rtol=1e-15)
    y = a * x
    for n in range(3, 200):
        out = f.update(x, T_S)
        y = a * x + (1.0 - a) * y
        np.testing.assert_allclose(out, y, rtol=1e-12)
        np.testing.assert_allclose(out, x * (1.0 - (1.0 - a) ** (n - 1)), rtol=1e-9)
    for _ in range(300):
        out = f.update(x, T_S)
    np.testing.assert_allclose(out, x, rtol=1e-6)  # converges to a held input


@pytest.mark.parametrize("cutoff_hz", [0.0, 1000.0])
def test_exponential_filter_frozen_at_zero_and_sample_rate_cutoff(cutoff_hz):
    f = ExponentialFilter(cutoff_hz, n=2)
    for _ in range(100):
        out = f.update(np.array([3.0, -4.0]), T_S)
    assert np.array_equal(out, np.zeros(2))


# -- JointPid (filters.cpp:56-62, control_toolbox Pid) ----------------------------------------------------------
def test_pid_p_adds_p_times_error_to_the_command():
    pid = JointPid(0.1, 0.0, 0.0, 0.0, 0.0, n=2)
    command = np.array([1.0, -1.0])
    target, measured = np.array([1.5, 0.0]), np.array([1.0, -0.5])
    pid.step(target, measured, T_S, command)
    np.testing.assert_allclose(command, [1.0 + 0.05, -1.0 + 0.05], rtol=1e-15)
    pid.step(target, measured, T_S, command)  # accumulates: it is added to the command every cycle
    np.testing.assert_allclose(command, [1.1, -0.9], rtol=1e-15)


def test_pid_i_integrates_and_clamps():
    pid = JointPid(0.0, 2.0, 0.0, 0.005, -0.003, n=2)
    command = np.zeros(2)
    e = np.array([1.0, -1.0])  # i e dt = +-0.002 per step
    expected_integral = np.zeros(2)
    total = np.zeros(2)
    for _ in range(5):
        pid.step(e, np.zeros(2), T_S, command)
        expected_integral = np.clip(expected_integral + 2.0 * e * T_S, -0.003, 0.005)
        total += expected_integral
        np.testing.assert_allclose(command, total, rtol=1e-12)
    assert expected_integral.tolist() == [0.005, -0.003]  # both clamps reached
    before = command.copy()
    pid.step(e, np.zeros(2), T_S, command)
    np.testing.assert_allclose(command - before, [0.005, -0.003], rtol=1e-12)


def test_pid_default_i_limits_zero_disable_the_integral():
    pid = JointPid(0.0, 5.0, 0.0, 0.0, 0.0, n=1)
    command = np.zeros(1)
    for _ in range(10):
        pid.step(np.ones(1), np.zeros(1), T_S, command)
    assert command[0] == 0.0


def test_pid_d_is_d_times_error_rate():
    pid = JointPid(0.0, 0.0, 0.01, 0.0, 0.0, n=1)
    command = np.zeros(1)
    pid.step(np.array([0.2]), np.zeros(1), T_S, command)  # first step: previous error 0
    assert command[0] == pytest.approx(0.01 * 0.2 / T_S)
    before = command[0]
    pid.step(np.array([0.5]), np.zeros(1), T_S, command)
    assert command[0] - before == pytest.approx(0.01 * 0.3 / T_S)
    before = command[0]
    pid.step(np.array([0.5]), np.zeros(1), T_S, command)  # constant error: no D
    assert command[0] == pytest.approx(before, abs=1e-12)


# -- RobotSession -----------------------------------------------------------------------------------------------
def test_session_runs_ready_wait_active_ready_over_robot_time():
    s = RobotSession(LbrPeerParams(commanding_after_s=0.5, commanding_wait_s=0.1, stop_app_after_s=2.0))
    assert s.state == READY
    expected = [(0, READY), (500 * MS - 1, READY), (500 * MS, WAIT), (600 * MS - 1, WAIT), (600 * MS, ACTIVE),
                (2000 * MS - 1, ACTIVE), (2000 * MS, READY), (5000 * MS, READY)]
    for t_ns, state in expected:
        assert s.advance(t_ns) == state, t_ns
        assert s.state == state
    assert s.stopped


def test_session_stop_app_ends_commanding_for_good():
    s = RobotSession(LbrPeerParams(commanding_after_s=0.0, commanding_wait_s=0.05))
    assert s.advance(0) == WAIT
    assert s.advance(50 * MS) == ACTIVE
    assert s.advance(10**15) == ACTIVE  # stop_app_after_s = 0: never stops by itself
    s.stop_app()
    assert s.advance(10**15 + 1) == READY
    assert s.advance(10**16) == READY


def test_session_zero_wait_goes_active_at_commanding_after():
    s = RobotSession(LbrPeerParams(commanding_after_s=1.0, commanding_wait_s=0.0))
    assert s.advance(1000 * MS - 1) == READY
    assert s.advance(1000 * MS) == ACTIVE


# -- StackClient: the FRI side ------------------------------------------------------------------------------------
def test_monitoring_sends_nothing(model):
    c = make_client(model)
    assert fri(c, READY, Q0) is None
    assert np.array_equal(c.state.q_rad, Q0)


def test_wait_answers_with_measured_position_and_zero_torque(model):
    c = make_client(model)
    rng = np.random.default_rng(0)
    c.receive(Q0 + 0.3, np.full(7, 5.0))  # a message while WAIT changes nothing
    for k in range(20):
        q = Q0 + 1e-4 * k + 1e-5 * rng.standard_normal(7)
        cmd = fri(c, WAIT, q, tau_measured=np.ones(7))
        c.cm_cycle()
        assert np.array_equal(cmd.joint_position, q)
        assert np.array_equal(cmd.torque, ZERO)
        assert np.array_equal(c.target.joint_position, q)
        assert np.array_equal(c.target.torque, ZERO)


def test_active_without_message_command_follows_measured_position(model):
    """The NaN hw command reaches the target every cm cycle; the FRI side re-initialises it to the measured
    position (torque_command.cpp:20-25): with the manager at the FRI rate the command is the measured position."""
    c = make_client(model, update_rate_hz=1000.0)
    activate(c)
    assert np.isnan(c.target.joint_position).all()  # the NaN hw command reached the target
    for k in range(1, 30):
        q = Q0 + 1e-4 * k * np.arange(1, 8) / 7
        cmd = fri(c, ACTIVE, q)
        np.testing.assert_array_equal(cmd.joint_position, q)
        np.testing.assert_array_equal(cmd.torque, ZERO)
        np.testing.assert_array_equal(c.target.joint_position, q)
        c.cm_cycle()
        assert np.isnan(c.target.joint_position).all() and np.isnan(c.target.torque).all()


def test_active_without_message_between_cm_cycles_pid_pulls_to_the_reinitialised_target(model):
    """init_command replaces the NaN target (base_command.cpp:12-17) until write() brings the NaN back
    (system_interface.cpp:347-354): between cm cycles the PID pulls towards the position at the re-init."""
    c = make_client(model)  # update_rate_hz 100: one cm cycle per 10 FRI cycles
    activate(c)
    for i in range(3):
        q_init = Q0 + 1e-3 * i
        cmd = fri(c, ACTIVE, q_init)
        np.testing.assert_array_equal(cmd.joint_position, q_init)
        prev = cmd.joint_position
        for k in range(1, c.p.cm_every):
            q = q_init + 1e-4 * k
            cmd = fri(c, ACTIVE, q)
            np.testing.assert_array_equal(c.target.joint_position, q_init)
            np.testing.assert_allclose(cmd.joint_position, prev + 0.1 * (q_init - q), rtol=0, atol=1e-15)
            prev = cmd.joint_position
        c.cm_cycle()


def test_message_becomes_target_and_command_moves_by_p_times_error(model):
    c = make_client(model)
    activate(c)
    target, tau = Q0 + np.linspace(0.01, 0.07, 7), np.linspace(-3.0, 3.0, 7)
    c.receive(target, tau)
    c.cm_cycle()
    np.testing.assert_array_equal(c.target.joint_position, target)
    np.testing.assert_array_equal(c.target.torque, tau)
    prev = Q0.copy()  # the command the ACTIVE transition initialised
    for k in range(1, 20):
        q = Q0 + 2e-4 * k
        cmd = fri(c, ACTIVE, q)
        expected = prev + 0.1 * (target - q)
        np.testing.assert_allclose(cmd.joint_position, expected, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(cmd.torque, tau)
        prev = cmd.joint_position


def test_pid_p_from_params_is_used(model):
    c = make_client(model, pid_p=0.4)
    activate(c)
    c.receive(Q0 + 0.01, ZERO)
    c.cm_cycle()
    cmd = fri(c, ACTIVE, Q0)
    np.testing.assert_allclose(cmd.joint_position, Q0 + 0.004, atol=1e-15)


def test_last_message_is_reapplied_every_cm_cycle_forever(model):
    c = make_client(model, open_loop=True)  # the command converges on the target, so it stays within limits
    activate(c)
    target, tau = Q0 + 0.005, np.full(7, 1.5)  # first step 0.1 * 5 mrad per ms: under every speed limit
    c.receive(target, tau)
    for _ in range(1000):
        c.cm_cycle()
        cmd = fri(c, ACTIVE, Q0)
        np.testing.assert_array_equal(c.target.joint_position, target)
        np.testing.assert_array_equal(c.target.torque, tau)
        np.testing.assert_array_equal(cmd.torque, tau)
    np.testing.assert_allclose(cmd.joint_position, target, atol=1e-12)


def test_newest_message_wins(model):
    c = make_client(model)
    activate(c)
    c.receive(Q0 + 0.01, ZERO)
    c.receive(Q0 + 0.02, np.ones(7))
    c.cm_cycle()
    np.testing.assert_array_equal(c.target.joint_position, Q0 + 0.02)
    np.testing.assert_array_equal(c.target.torque, np.ones(7))


def test_message_received_while_wait_reaches_target_only_once_active(model):
    c = make_client(model)
    target, tau = Q0 + 0.05, np.full(7, 2.0)
    fri(c, WAIT, Q0)
    c.receive(target, tau)
    for _ in range(5):
        c.cm_cycle()  # write() only while COMMANDING_ACTIVE
        cmd = fri(c, WAIT, Q0)
        np.testing.assert_array_equal(c.target.joint_position, Q0)
        np.testing.assert_array_equal(cmd.torque, ZERO)
    cmd = fri(c, ACTIVE, Q0)  # active, but no cm_cycle has run yet: still the initialised command
    np.testing.assert_array_equal(c.target.joint_position, Q0)
    np.testing.assert_array_equal(cmd.joint_position, Q0)
    np.testing.assert_array_equal(cmd.torque, ZERO)
    c.cm_cycle()
    np.testing.assert_array_equal(c.target.joint_position, target)
    np.testing.assert_array_equal(c.target.torque, tau)
    cmd = fri(c, ACTIVE, Q0)
    np.testing.assert_allclose(cmd.joint_position, Q0 + 0.1 * 0.05, atol=1e-15)
    np.testing.assert_array_equal(cmd.torque, tau)


def test_open_loop_publishes_its_own_previous_command(model):
    c = make_client(model, open_loop=True)
    activate(c)
    c.receive(Q0 + 0.005, ZERO)
    c.cm_cycle()
    prev = Q0.copy()
    rng = np.random.default_rng(1)
    for k in range(1, 50):
        encoder = Q0 + 1e-4 * k + 1e-5 * rng.standard_normal(7)
        cmd = fri(c, ACTIVE, encoder)
        np.testing.assert_array_equal(c.state.q_rad, prev)  # not the encoder's
        np.testing.assert_allclose(cmd.joint_position, prev + 0.1 * (Q0 + 0.005 - prev), atol=1e-15)
        prev = cmd.joint_position


def test_open_loop_with_target_equal_to_command_freezes_the_published_position(model):
    c = make_client(model, open_loop=True)
    activate(c)
    c.receive(Q0 + 0.005, ZERO)
    c.cm_cycle()
    for _ in range(10):
        cmd = fri(c, ACTIVE, Q0)
    c.receive(cmd.joint_position, np.full(7, 4.0))
    c.cm_cycle()
    frozen = fri(c, ACTIVE, Q0).joint_position
    published = c.state.q_rad.copy()
    for k in range(1, 200):
        encoder = Q0 + 1e-4 * k  # the arm moves under the overlay
        cmd = fri(c, ACTIVE, encoder)
        assert np.array_equal(c.state.q_rad, published)
        assert np.array_equal(cmd.joint_position, frozen)
        if k % 10 == 0:
            c.cm_cycle()


def test_closed_loop_publishes_the_encoder(model):
    c = make_client(model, open_loop=False)
    activate(c)
    c.receive(Q0 + 0.01, ZERO)
    c.cm_cycle()
    for k in range(1, 20):
        encoder = Q0 + 1e-4 * k
        fri(c, ACTIVE, encoder)
        np.testing.assert_array_equal(c.state.q_rad, encoder)


@pytest.mark.parametrize("session", [WAIT, ACTIVE])
def test_stack_in_position_mode_throws_while_commanding(model, session):
    c = make_client(model, client_command_mode="position")
    assert fri(c, READY, Q0) is None
    with pytest.raises(StackError, match="torque_command.cpp"):
        fri(c, session, Q0)


@pytest.mark.parametrize("robot_mode", [int(ClientCommandMode.POSITION), int(ClientCommandMode.WRENCH),
                                        int(ClientCommandMode.NO_COMMAND_MODE), 7])
def test_robot_not_in_torque_mode_throws_when_active(model, robot_mode):
    c = make_client(model)
    fri(c, READY, Q0, mode=robot_mode)  # monitoring does not care
    with pytest.raises(StackError, match="TORQUE mode, the robot is in"):
        fri(c, ACTIVE, Q0, mode=robot_mode)


@pytest.mark.parametrize("after", [READY, WAIT, SessionState.IDLE])
def test_leaving_commanding_active_makes_cm_cycle_raise(model, after):
    c = make_client(model)
    activate(c)
    c.cm_cycle()  # still active: fine
    fri(c, after, Q0, mode=int(ClientCommandMode.NO_COMMAND_MODE) if after != WAIT else TORQUE)
    with pytest.raises(StackError, match="left COMMANDING_ACTIVE"):
        c.cm_cycle()


def test_cm_cycle_before_active_does_not_raise(model):
    c = make_client(model)
    fri(c, READY, Q0)
    c.cm_cycle()
    fri(c, WAIT, Q0)
    c.cm_cycle()
    fri(c, READY, Q0)  # WAIT back to READY never was COMMANDING_ACTIVE
    c.cm_cycle()


# -- the command guard (command_guard.cpp) ------------------------------------------------------------------------
def test_guard_rejects_a_commanded_position_outside_the_limits(model):
    q_max = model.limits.q_max
    q = Q0.copy()
    q[0] = q_max[0] - 0.01
    c = make_client(model)
    activate(c, q)
    inside = q.copy()
    inside[0] = q_max[0] - 0.001
    c.receive(inside, np.full(7, 1e6))  # the torque is not checked
    c.cm_cycle()
    fri(c, ACTIVE, q)  # q + 0.1 (0.009) stays inside
    outside = q.copy()
    outside[0] = q_max[0] + 0.5
    c.receive(outside, ZERO)
    c.cm_cycle()
    with pytest.raises(StackError, match="commanded A1 .* outside"):
        fri(c, ACTIVE, q)  # one step: c + 0.1 (0.51) > q_max


def test_guard_rejects_a_commanded_position_below_the_lower_limit(model):
    q = Q0.copy()
    q[3] = model.limits.q_min[3] + 0.002
    c = make_client(model)
    activate(c, q)
    target = q.copy()
    target[3] -= 0.1
    c.receive(target, ZERO)
    c.cm_cycle()
    with pytest.raises(StackError, match="commanded A4"):
        fri(c, ACTIVE, q)


def test_guard_rejects_a_measured_speed_over_the_limit(model):
    dq_max = model.limits.dq_max
    c = make_client(model)
    activate(c)
    q = Q0.copy()
    q[4] += 0.95 * dq_max[4] * T_S  # just under the limit: fine
    fri(c, ACTIVE, q)
    q = q.copy()
    q[4] += 1.05 * dq_max[4] * T_S
    with pytest.raises(StackError, match=r"A5 moved .* rad/s"):
        fri(c, ACTIVE, q)


# -- the torque filters in the state (state.cpp) ---------------------------------------------------------------
def test_state_torques_are_filtered_first_zero_then_alpha_weighted(model):
    c = make_client(model, measured_torque_cutoff_hz=10.0, external_torque_cutoff_hz=40.0)
    a_m, a_e = filter_alpha(10.0, T_S), filter_alpha(40.0, T_S)
    rng = np.random.default_rng(2)
    y_m, y_e = np.zeros(7), np.zeros(7)
    for k in range(100):
        tau_m, tau_e = rng.normal(0.0, 10.0, 7), rng.normal(0.0, 3.0, 7)
        fri(c, READY, Q0, tau_measured=tau_m, tau_external=tau_e)
        if k == 0:
            assert np.array_equal(c.state.tau_measured_nm, ZERO)
            assert np.array_equal(c.state.tau_external_nm, ZERO)
        else:
            y_m = a_m * tau_m + (1.0 - a_m) * y_m
            y_e = a_e * tau_e + (1.0 - a_e) * y_e
        np.testing.assert_allclose(c.state.tau_measured_nm, y_m, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(c.state.tau_external_nm, y_e, rtol=1e-12, atol=1e-12)
        if k == 1:
            np.testing.assert_allclose(c.state.tau_measured_nm, a_m * tau_m, rtol=1e-14)


def test_state_torque_with_cutoff_at_sample_rate_stays_zero(model):
    c = make_client(model, external_torque_cutoff_hz=1000.0)
    for _ in range(20):
        fri(c, READY, Q0, tau_external=np.full(7, 8.0))
    assert np.array_equal(c.state.tau_external_nm, ZERO)


# -- the force-torque estimate (ft_estimator.cpp) ---------------------------------------------------------------
def _damped_pinv(A: np.ndarray, damping: float) -> np.ndarray:
    """Damped least-squares inverse of A by its SVD: V diag(s / (s^2 + lambda^2)) U^T."""
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    return Vt.T @ np.diag(s / (s**2 + damping**2)) @ U.T


def _tip(model: RobotModel, q: np.ndarray = Q0) -> tuple[np.ndarray, np.ndarray]:
    _, R_base_tip = tip_pose(model, q)
    return tip_jacobian(model, q), R_base_tip


def test_soft_threshold():
    th = np.array([2.0, 2.0, 2.0])
    np.testing.assert_array_equal(soft_threshold(np.array([10.0, -10.0, 1.5]), th), [8.0, -8.0, 0.0])
    np.testing.assert_array_equal(soft_threshold(np.array([2.0, -2.0, 0.0]), th), [0.0, 0.0, 0.0])


def test_wrench_is_damped_pinv_of_jt_rotated_into_tip_axes(model):
    J, R = _tip(model)
    rng = np.random.default_rng(3)
    tau_ext = rng.normal(0.0, 5.0, 7)
    f_base = _damped_pinv(J.T, 0.2) @ tau_ext
    expected = np.concatenate([R.T @ f_base[:3], R.T @ f_base[3:]])
    for in_tip in (True, False):
        w = estimated_wrench(J, tau_ext, R, 0.2, 0.0, 0.0, in_tip)
        np.testing.assert_allclose(w, expected, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("force_n", [10.0, -10.0])
def test_pure_tip_force_comes_back_in_tip_axes_minus_threshold(model, force_n):
    J, R = _tip(model)
    assert not np.allclose(np.abs(R), np.eye(3), atol=0.3)  # the tip is rotated away from the base axes
    w_tip = np.array([force_n, 0.0, 0.0, 0.0, 0.0, 0.0])
    w_base = np.concatenate([R @ w_tip[:3], R @ w_tip[3:]])
    tau_ext = J.T @ w_base

    # humble: threshold the tip-axes components: exactly |F| - 2 N along tip x, nothing else
    humble = estimated_wrench(J, tau_ext, R, 0.0, 2.0, 0.5, threshold_in_tip=True)
    np.testing.assert_allclose(humble, [math.copysign(8.0, force_n), 0, 0, 0, 0, 0], atol=1e-9)

    # rolling: threshold the base-axes components, then rotate: the force leaks into the other tip axes
    rolling = estimated_wrench(J, tau_ext, R, 0.0, 2.0, 0.5, threshold_in_tip=False)
    f_base = soft_threshold(R @ w_tip[:3], np.full(3, 2.0))
    np.testing.assert_allclose(rolling[:3], R.T @ f_base, atol=1e-9)
    np.testing.assert_allclose(rolling[3:], 0.0, atol=1e-9)
    assert np.max(np.abs(rolling - humble)) > 1.0
    assert np.max(np.abs(rolling[1:3])) > 0.5


def test_force_below_threshold_reads_zero(model):
    J, R = _tip(model)
    tau_ext = J.T @ np.concatenate([R @ np.array([1.5, 0.0, 0.0]), np.zeros(3)])
    for in_tip in (True, False):
        np.testing.assert_allclose(estimated_wrench(J, tau_ext, R, 0.0, 2.0, 0.5, in_tip), ZERO[:6], atol=1e-12)


def test_thresholds_agree_when_the_tip_is_aligned_with_the_base(model):
    J, _ = _tip(model)
    w_base = np.array([10.0, -3.0, 1.0, 0.2, 0.0, -0.9])
    tau_ext = J.T @ w_base
    a = estimated_wrench(J, tau_ext, np.eye(3), 0.0, 2.0, 0.5, True)
    b = estimated_wrench(J, tau_ext, np.eye(3), 0.0, 2.0, 0.5, False)
    np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(a, [8.0, -1.0, 0.0, 0.0, 0.0, -0.4], atol=1e-9)


# -- the app's joint impedance (LBRServer.java) -----------------------------------------------------------------
def test_joint_impedance_torque_arithmetic():
    overlay = np.linspace(-1.0, 1.0, 7)
    K = np.full(7, 200.0)
    D = np.arange(1.0, 8.0)
    q = Q0
    q_cmd = Q0 + 0.01
    dq = np.full(7, 0.5)
    dq_cmd = np.zeros(7)
    tau = joint_impedance_torque(overlay, q_cmd, dq_cmd, q, dq, K, D)
    np.testing.assert_allclose(tau, overlay + 2.0 - 0.5 * D, rtol=0, atol=1e-12)
    # no spring deflection, no speed: the overlay alone
    np.testing.assert_array_equal(joint_impedance_torque(overlay, q, ZERO, q, ZERO, K, D), overlay)


def test_impedance_damping_is_two_ratio_sqrt_k_m():
    K = np.full(7, 200.0)
    m = np.array([0.5, 2.0, 0.0, -1.0, 8.0, 0.125, 1.0])
    d = impedance_damping(K, 0.7, m)
    np.testing.assert_allclose(d, [14.0, 28.0, 0.0, 0.0, 56.0, 7.0, 2 * 0.7 * math.sqrt(200.0)], rtol=1e-12)
