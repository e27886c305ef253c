"""A stolen controller against the robot side's own limits: ``lamps sim`` (real PyBullet, lock-step) over real Zenoh.

The test client is first an ordinary controller that lands the pad on the board and presses it at 10 N (no limit
of the robot side may trip meanwhile), then a thief with the same session (a holder of the controller's key can
copy it): bursts of +-1e9 Nm for 0.3 s, each with a sign pattern chosen to press the pad into the board, spin the
joints, tip an edge of the pad in or lift it, between 0.2 s of ordinary gravity-holding commands. Each burst must
latch the robot side's FAULT-hold; the operator then releases it (as a fooled operator would) and the next burst
tries again. Every state and every physics step (sim truth's peak) must show the joints within 1.1x their speed
limits and the contact force within the robot side's cap + 10 %.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from arm.robot_model import RobotModel
from interfaces.messages import Estop, RobotState, ServiceStatus, SimTruth
from robot.server import ServerParams
from sim.board import board_from_params
from sim.params import BoardParams

from .zenoh_helpers import SimProcess, run_lockstep, wait_for, wait_sample, wait_subscribed

PRESS_S = 1.0  # the honest controller's part [s of robot time]
SLOT_S, BURST_S = 0.5, 0.3  # each burst and the gravity-holding commands after it [s]
PATTERNS = ("press", "alternate", "press", "tip", "all", "lift", "press", "alternate_negated")
BIG_NM = 1e9


class PressThenSteal:
    """``policy(state) -> tau (7,)`` for :func:`run_lockstep`: press the pad on the board at ``force_n`` until
    ``PRESS_S``, then the thief's bursts (``PATTERNS``); releases the robot side's FAULT-hold (the operator's key)
    late in each slot once it is latched, so that the next burst finds the robot side serving again."""

    def __init__(self, model: RobotModel, normal: np.ndarray, operator, status, force_n: float = 10.0) -> None:
        self.m, self.n, self.op, self.status, self.force_n = model, normal, operator, status, force_n
        self.hold: tuple[np.ndarray, np.ndarray] | None = None
        self.touched = False
        self.released = set()

    def __call__(self, s: RobotState) -> np.ndarray:
        q, dq, t = np.array(s.q_rad), np.array(s.dq_rad_s), s.robot_time_ns * 1e-9
        if t < PRESS_S:
            return self._press(q, dq, np.linalg.norm(s.wrench_world[:3]))
        slot = int((t - PRESS_S) / SLOT_S)
        within = t - PRESS_S - slot * SLOT_S
        if within < BURST_S and slot < len(PATTERNS):
            return BIG_NM * self._signs(PATTERNS[slot], q)
        if s.estop and within > SLOT_S - 0.05 and slot not in self.released:
            self.released.add(slot)
            self.op.publish(self.op.keys.controller_estop_release,
                            Estop(stamp_ns=s.stamp_ns, engaged=False, reason="fooled", source="operator"))
            # lock-step: the robot side waits for this answer and reads the release meanwhile
            wait_sample(self.status, lambda m: m.counters.get("guard_fault_releases", 0) == len(self.released), 5.0,
                        "the release seen by the robot side")
        return self.m.gravity(q)

    def _press(self, q: np.ndarray, dq: np.ndarray, force_n: float) -> np.ndarray:
        """Impedance in the board's plane and in orientation; along the normal a 2 cm/s approach, then the force."""
        m, n = self.m, self.n
        J = m.tcp_jacobian(q)
        p, R = m.tcp_pose(q)
        if self.hold is None:
            self.hold = (p, R)
        v = J @ dq
        vn = float(v[:3] @ n)  # negative: towards the board
        e = self.hold[0] - p
        e -= (e @ n) * n
        self.touched = self.touched or force_n > 2.0
        push = self.force_n if self.touched else float(np.clip(400.0 * (vn + 0.02), -self.force_n, self.force_n))
        f = 600.0 * e - 50.0 * (v[:3] - vn * n) - push * n - 40.0 * vn * n
        w = 60.0 * pin.log3(self.hold[1] @ R.T) - 8.0 * v[3:]
        return m.gravity(q) + J.T @ np.concatenate([f, w]) - dq

    def _signs(self, pattern: str, q: np.ndarray) -> np.ndarray:
        J = self.m.tcp_jacobian(q)
        _, R = self.m.tcp_pose(q)
        alternate = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0])
        return {"press": np.sign(J[:3].T @ -self.n), "lift": np.sign(J[:3].T @ self.n),
                "tip": np.sign(J[3:].T @ R[:, 0] + 0.3 * J[:3].T @ -self.n),  # roll about the pad's long side
                "alternate": alternate, "alternate_negated": -alternate, "all": np.ones(7)}[pattern]


@pytest.mark.slow
@pytest.mark.attack("torques", "a stolen controller (the served session copied) sends 0.3 s bursts of +-1e9 Nm "
                    "pressing the pad into the board, spinning the joints, tipping the pad's edge in and lifting it, "
                    "between gravity-holding commands; the operator releases each FAULT-hold",
                    "joints within 1.1x their speed limits, contact force within the robot side's 45 N cap + 10 % "
                    "at every step; every burst latches the FAULT-hold; the honest press before trips nothing")
def test_a_stolen_controllers_bursts_are_held_within_the_robot_sides_limits_and_latch_its_fault_hold(tmp_path):
    model = RobotModel()
    board = board_from_params(BoardParams())
    limit_n = ServerParams().force_cap_n * 1.1
    cfg = {"mode": "lockstep", "camera": {"enabled": False}, "start_standoff_m": 0.01, "status_rate_hz": 20.0}
    with SimProcess(tmp_path, cfg) as sim:
        status = sim.node.latest(sim.keys.sim_status, ServiceStatus)
        truths = sim.node.inbox(sim.keys.sim_truth, SimTruth, maxlen=10_000)
        wait_subscribed(sim.node.session, sim.keys.controller_estop_release, what="the sim reading the release")
        policy = PressThenSteal(model, board.normal_world, sim.node, status)
        steps = int((PRESS_S + SLOT_S * len(PATTERNS)) * 1000)
        states = run_lockstep(sim, steps, policy, timeout_s=50.0)
        last = wait_sample(status, lambda m: m.seq >= steps, 10.0, "the status after the last step")
        peaks: list[SimTruth] = []

        def truth_of_the_last_steps() -> bool:
            while (m := truths.get(0.0)) is not None:
                peaks.append(m)
            return bool(peaks) and peaks[-1].seq >= steps - 100

        wait_for(truth_of_the_last_steps, 5.0, "the sim truth of the last steps")
    t = np.array([s.robot_time_ns * 1e-9 for s in states])
    share = np.array([np.abs(s.dq_rad_s) / model.limits.dq_max for s in states]).max(axis=1)
    force = np.array([np.linalg.norm(s.wrench_world[:3]) for s in states])
    estop = np.array([s.estop for s in states])
    honest = t < PRESS_S
    assert 8.0 < force[honest][-1] < 12.0, f"the honest controller pressed {force[honest][-1]:.1f} N"
    assert not estop[honest].any() and all(s.command_seq >= 0 for s in states[1:int(honest.sum())]), \
        "the honest press: every command applied, nothing braked, yielded or latched"
    print(f"stolen controller: joints max {share.max():.3f} of their speed limits, contact force max "
          f"{force.max():.1f} N (states), {max(p.peak_force_n for p in peaks):.1f} N normal (every step); "
          f"counters {dict((k, v) for k, v in last.counters.items() if 'brake' in k or 'yield' in k or 'fault' in k)}")
    assert share.max() <= 1.1, f"a joint at {share.max():.2f} of its speed limit"
    assert force.max() <= limit_n, f"contact force {force.max():.1f} N over {limit_n:.1f} N"
    assert max(p.peak_force_n for p in peaks) <= limit_n, "the normal force at some physics step"
    latched_ms = []
    for k in range(len(PATTERNS)):  # every burst latched the FAULT-hold, and it held while latched
        burst = (t >= PRESS_S + k * SLOT_S) & (t < PRESS_S + k * SLOT_S + BURST_S)
        assert estop[burst].any(), f"burst {k} ({PATTERNS[k]}) did not latch the FAULT-hold"
        latched_ms.append(round((t[burst][np.argmax(estop[burst])] - t[burst][0]) * 1000))
        held = [s for s, b, e in zip(states[1:], burst[:-1], estop[:-1]) if b and e]
        assert held and all(s.command_seq == -1 for s in held), f"burst {k}: a command applied while latched"
    print(f"latched {latched_ms} ms into the bursts {PATTERNS}")
    c = last.counters
    assert c["guard_faults"] == len(PATTERNS) and c["guard_fault_releases"] == len(PATTERNS), c
    assert c["commands_held_for_guard_fault"] > 0.5 * BURST_S * 1000 * len(PATTERNS), c
    assert "guard=FAULT" not in last.detail, "released at the end"
