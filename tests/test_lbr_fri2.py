"""FRI 2 (no commanded position in the state): the adapter's mirror of the stack's PID against the stack itself.

The stand-in's stack (sim/lbr_stack/stack.py) on the PyBullet arm, in process, one controller-manager cycle per
FRI cycle (2 ms): a message answers the state of the last FRI cycle and reaches the robot one cycle later. The
adapter's JointSpring (robot/lbr/compensation.py) runs the PID on the states with the target those cycles had.
A controller holding the start pose softly and pushing A2 with 3 Nm moves the arm as far as with FRI 1's
reported command, and the mirror stays on the stack's command (mirroring the newest target instead ran 13 mrad
ahead after 0.13 rad of A2, and the spring's 2.6 Nm held the arm back: the pad never reached the board).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from interfaces.robot_model import RobotModel
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
                spring.observe(st.q_rad, t_ns, T, None if fri2 else st.q_commanded_rad)
                if robot_cmd is not None:
                    err = max(err, float(np.max(np.abs(spring.c - robot_cmd.joint_position))))
                tau = -5.0 * (o.q - q0) - 1.0 * o.dq
                tau[1] += 3.0
                pending = spring.command(o.q.copy(), tau, o.dq.copy(), T)
            cmd = stack.fri_cycle(SessionState.COMMANDING_ACTIVE, o.q, o.q if robot_cmd is None else
                                  robot_cmd.joint_position, o.tau, np.zeros(7), ClientCommandMode.TORQUE, T)
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
