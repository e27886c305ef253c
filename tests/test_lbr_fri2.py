"""FRI 2 (no commanded position in the state): the adapter's mirror of the stack's PID against the stack itself.

The stand-in's stack (sim/lbr_stack/stack.py) on the PyBullet arm, in process, one controller-manager cycle per
FRI cycle (2 ms): a message answers the state of the last FRI cycle and reaches the robot one cycle later. The
adapter's JointSpring (robot/lbr/compensation.py) runs the PID on the states with the target those cycles had.
A controller holding the start pose softly and pushing A2 with 3 Nm moves the arm as far as with FRI 1's
reported command, and the mirror stays on the stack's command (mirroring the newest target instead ran 13 mrad
ahead after 0.13 rad of A2, and the spring's 2.6 Nm held the arm back: the pad never reached the board).

A controller manager on its own clock (the real one, and the real-time stand-in: two manager cycles per FRI cycle,
half a period out of phase) takes an answer at whichever of its cycles comes after the answer arrives, so the FRI
cycle that applies it varies with the answer's latency, and the adapter misses states when its loop is late. The
mirror then settles each cycle with the target the robot's echo (the state's commanded torque) names; a fixed guess
instead integrated the wrong target whenever the latency differed from it, and the mirror walked off the stack's
command for good (1.5 mrad on A4 in the real-time FRI 2 cell under load: 1.8 N off the 10 N press).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from arm.robot_model import RobotModel
from robot.lbr.compensation import JointSpring
from robot.lbr.msgs import ClientCommandMode, SessionState
from sim.core import SimCore
from sim.lbr_stack.params import LbrPeerParams
from sim.lbr_stack.stack import StackClient, impedance_damping, joint_impedance_torque
from sim.params import SimParams

T = 0.002


def _push(fri2: bool, cycles: int = 1500) -> tuple[float, float]:
    """(A2's travel [rad], the mirror's largest distance from the stack's command [rad])."""
    sim = SimCore(SimParams.from_table({"camera": {"enabled": False}, "gravity_compensated": True}))
    model = RobotModel(joints=sim.joints)
    lim = model.limits
    stack = StackClient(LbrPeerParams.from_table({"sample_time_s": T, "client_command_mode": "torque",
                                                  "open_loop": False, "update_rate_hz": 500}),
                        lim.q_min, lim.q_max, lim.dq_max)
    K = np.full(7, 200.0)
    spring = JointSpring(K, 0.1, 0.3, 0.5)
    robot_cmd = pending = None
    err = 0.0
    q0 = sim.out.q.copy()
    try:
        for k in range(cycles):
            o = sim.out
            if pending is not None:
                stack.receive(*pending)
            if k > 0:
                st = stack.cm_cycle()
                t_ns = round(k * T * 1e9)
                if k == 1:
                    spring.reset(st.q_rad if fri2 else st.q_commanded_rad, t_ns)
                spring.observe(st.q_rad, t_ns, T, None if fri2 else st.q_commanded_rad, st.tau_commanded_nm)
                if robot_cmd is not None:
                    err = max(err, float(np.max(np.abs(spring.c - robot_cmd.joint_position))))
                tau = -5.0 * (o.q - q0) - 1.0 * o.dq
                tau[1] += 3.0
                pending = spring.command(o.q.copy(), tau, o.dq.copy(), T)
            cmd = stack.fri_cycle(SessionState.COMMANDING_ACTIVE, o.q, o.q if robot_cmd is None else
                                  robot_cmd.joint_position, o.tau, np.zeros(7), ClientCommandMode.TORQUE, T,
                                  tau_commanded=None if robot_cmd is None else robot_cmd.torque)
            dq_cmd = np.zeros(7) if robot_cmd is None else (cmd.joint_position - robot_cmd.joint_position) / T
            robot_cmd = cmd
            D = impedance_damping(K, 0.7, np.diag(pin.crba(model.model, model.data, o.q)).copy())
            for _ in range(2):
                sim.step(joint_impedance_torque(cmd.torque, cmd.joint_position, dq_cmd, o.q, o.dq, K, D))
        return float(sim.out.q[1] - q0[1]), err
    finally:
        sim.close()


def test_the_fri2_mirror_stays_on_the_stacks_command_and_the_arm_goes_as_far_as_with_fri1():
    travel1, _ = _push(fri2=False)
    travel2, err2 = _push(fri2=True)
    print(f"\nA2 travel: FRI 1 {travel1:.3f} rad, FRI 2 {travel2:.3f} rad; FRI 2 mirror off by {err2 * 1e3:.2f} mrad")
    assert err2 < 1e-3, err2
    assert travel1 > 0.5 and abs(travel2 - travel1) < 0.1 * travel1, (travel1, travel2)


def _free_running(echo: bool, seed: int, cycles: int = 1500, skip: float = 0.1,
                  latency: tuple[float, ...] = (0.55, 0.3, 0.1, 0.05)) -> tuple[float, float]:
    """(the mirror's largest distance from the stack's command [rad], its mean over the last 100 states [rad]) with
    two manager cycles per FRI cycle: an answer reaches the manager ``d`` of its cycles after the one that published
    the state (``d`` drawn from ``latency``, seeded), and a share ``skip`` of the states is never seen. The arm under
    absolute joint damping, A2 pushed back and forth (3 Nm at 0.3 Hz)."""
    rng = np.random.default_rng(seed)
    sim = SimCore(SimParams.from_table({"camera": {"enabled": False}, "gravity_compensated": True}))
    model = RobotModel(joints=sim.joints)
    lim = model.limits
    stack = StackClient(LbrPeerParams.from_table({"sample_time_s": T, "client_command_mode": "torque",
                                                  "open_loop": False, "update_rate_hz": 1000}),
                        lim.q_min, lim.q_max, lim.dq_max)
    K = np.full(7, 200.0)
    spring = JointSpring(K, 0.1, 0.3, 0.5)
    robot_cmd, in_flight, errors = None, [], []
    q0 = sim.out.q.copy()
    try:
        for k in range(cycles):
            o = sim.out
            for slot in (2 * k, 2 * k + 1):  # the manager's two cycles in this FRI period
                arrived = [m for s, m in in_flight if s <= slot]
                in_flight = [(s, m) for s, m in in_flight if s > slot]
                if arrived:
                    stack.receive(*arrived[-1])
                st = stack.cm_cycle()
                if slot != 2 * k or k == 0:
                    continue
                t_ns = round(k * T * 1e9)
                if k == 1:
                    spring.reset(st.q_rad, t_ns)
                elif rng.random() < skip:
                    continue
                spring.observe(st.q_rad.copy(), t_ns, T, None, st.tau_commanded_nm if echo else None)
                if robot_cmd is not None:
                    errors.append(np.max(np.abs(spring.c - robot_cmd.joint_position)))
                tau = -5.0 * (st.q_rad - q0) - 1.0 * o.dq
                tau[1] += 3.0 * np.sin(2.0 * k * T)
                in_flight.append((slot + 1 + rng.choice(len(latency), p=latency),
                                  spring.command(st.q_rad.copy(), tau, o.dq.copy(), T)))
            cmd = stack.fri_cycle(SessionState.COMMANDING_ACTIVE, o.q, o.q if robot_cmd is None else
                                  robot_cmd.joint_position, o.tau, np.zeros(7), ClientCommandMode.TORQUE, T,
                                  tau_commanded=None if robot_cmd is None else robot_cmd.torque)
            robot_cmd = cmd
            D = impedance_damping(K, 0.7, np.diag(pin.crba(model.model, model.data, o.q)).copy())
            for _ in range(2):
                sim.step(joint_impedance_torque(cmd.torque, cmd.joint_position, np.zeros(7), o.q, o.dq, K, D))
        return float(np.max(errors)), float(np.mean(errors[-100:]))
    finally:
        sim.close()


def test_under_a_free_running_manager_the_echo_keeps_the_fri2_mirror_on_the_stacks_command():
    """The robot's echo of the overlay names the target of each settled cycle: the mirror stays within a cycle's
    guess of the stack's command (0.24-0.29 mrad at worst, 0.09-0.15 mrad at the end); the fixed guess alone walked
    off (6 mrad at worst, 2.3-2.8 mrad at the end: 0.5 Nm of the spring on a joint, for good)."""
    for seed in (1, 2):
        worst, end = _free_running(echo=True, seed=seed)
        worst_guess, end_guess = _free_running(echo=False, seed=seed)
        print(f"\nseed {seed}: mirror off by {worst * 1e3:.2f} mrad at worst, {end * 1e3:.3f} mrad at the end; "
              f"the fixed guess {worst_guess * 1e3:.2f}, {end_guess * 1e3:.2f} mrad")
        assert end_guess > 1e-3, end_guess  # the mechanism: a fixed guess accumulates
        assert worst < 1.5e-3 and end < 0.3e-3, (worst, end)


def test_an_echo_that_names_none_of_ours_leaves_the_mirror_on_its_guess():
    """A robot that does not echo the overlay (0.3 Nm off): the echo names nothing, the guess (the target sent
    before the newest) settles the cycles as without an echo, and the misses are counted."""
    q0 = np.linspace(-0.3, 0.3, 7)
    runs = []
    for echo_off in (None, 0.3):
        spring = JointSpring(np.full(7, 200.0), 0.1, 0.3, 0.0)
        spring.reset(q0, 0)
        overlay = np.zeros(7)
        for k in range(1, 6):
            q = q0 + 1e-3 * k
            tau_cmd = None if echo_off is None else overlay + echo_off
            spring.observe(q, round(k * T * 1e9), T, None, tau_cmd)
            _, overlay = spring.command(q, np.full(7, 1.0), None, T)
        runs.append((spring.c.copy(), spring.echoes_named, spring.echoes_missed))
    np.testing.assert_allclose(runs[1][0], runs[0][0], atol=1e-15)
    assert runs[1][1] == 0 and runs[1][2] == 3, runs[1]
