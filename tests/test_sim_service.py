"""``lamps sim`` as a real process, driven over real Zenoh on loopback by scripted torque clients."""

from __future__ import annotations

import time

import cv2
import msgspec
import numpy as np
import pinocchio as pin
import pytest

from arm.robot_model import RobotModel
from interfaces.board_markers import marker_corners_board
from interfaces.codec import encode
from interfaces.messages import CameraFrame, RobotState, SimTruth, TorqueCommand
from interfaces.transforms import transform_from_pose
from sim.board import board_from_params
from sim.camera import project
from sim.params import BoardParams

from .zenoh_helpers import SimProcess, latest_status, run_lockstep, wait_for, wait_sample, wait_seq

pytestmark = pytest.mark.slow
NO_CAMERA = {"enabled": False}


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel()


def tcp_positions(model: RobotModel, states) -> np.ndarray:
    return np.array([model.tcp_pose(np.array(s.q_rad))[0] for s in states])


def test_gravity_compensation_from_pinocchio_holds_the_arm_within_1mm_for_2s(tmp_path, model):
    with SimProcess(tmp_path, {"mode": "lockstep", "camera": NO_CAMERA}) as sim:
        states = run_lockstep(sim, 2000, lambda s: model.gravity(np.array(s.q_rad)))
    p = tcp_positions(model, states)
    assert states[-1].robot_time_ns == 2_000_000_000
    assert np.linalg.norm(p - p[0], axis=1).max() < 1e-3
    assert not states[0].capabilities.gravity_compensated


def test_without_gravity_torques_the_arm_falls(tmp_path, model):
    """The control for the test above: the same client sending zeros sees the arm sag."""
    with SimProcess(tmp_path, {"mode": "lockstep", "camera": NO_CAMERA}) as sim:
        states = run_lockstep(sim, 300, lambda s: np.zeros(7))
    p = tcp_positions(model, states)
    assert np.linalg.norm(p[-1] - p[0]) > 0.01


def test_gravity_compensated_robot_holds_with_zero_torques(tmp_path, model):
    with SimProcess(tmp_path, {"mode": "lockstep", "gravity_compensated": True, "camera": NO_CAMERA}) as sim:
        states = run_lockstep(sim, 1000, lambda s: np.zeros(7))
    assert states[0].capabilities.gravity_compensated
    p = tcp_positions(model, states)
    assert np.linalg.norm(p - p[0], axis=1).max() < 1e-3
    # the reported torque is what the joints exert: the robot's own gravity torques
    np.testing.assert_allclose(states[-1].tau_nm, model.gravity(np.array(states[-2].q_rad)), atol=0.05)


class PressAndSlide:
    """A scripted operational-space client: press the pad on the board with ``force_n``, slide it along board x.

    tau = J^T (Lambda (K e + D de) - F n) + g(q) + N^T M (posture PD), with
    Lambda the task-space inertia, D = 2 sqrt(K) (critical damping), a
    sinusoid of ``amplitude_m`` at ``freq_hz`` about ``centre_board`` (2,)
    after 1 s, no position control along the normal (only damping), where
    a constant force presses, and a dynamically consistent nullspace
    projector N holding the elbow near its start posture.
    """

    def __init__(self, model: RobotModel, board, centre_board, force_n=10.0, amplitude_m=0.03, freq_hz=1.0):
        self.m, self.b = model, board
        self.centre = board.world_from_board(np.asarray(centre_board, float))
        self.force_n, self.amp, self.freq = force_n, amplitude_m, freq_hz
        self.R_goal = board.tool_rotation()
        self.n = board.normal_world
        self.K = np.diag([600.0] * 3 + [60.0] * 3)
        self.D = 2.0 * np.sqrt(self.K)
        self.q_rest: np.ndarray | None = None

    def __call__(self, s: RobotState) -> np.ndarray:
        q, dq, t = np.array(s.q_rad), np.array(s.dq_rad_s), s.robot_time_ns * 1e-9
        if self.q_rest is None:
            self.q_rest = q.copy()
        model, data, n = self.m.model, self.m.data, self.n
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        M_inv = np.linalg.inv(M)
        J = self.m.tcp_jacobian(q)
        p, R = self.m.tcp_pose(q)
        v = J @ dq
        Lam = np.linalg.inv(J @ M_inv @ J.T + 1e-6 * np.eye(6))
        phase = 2 * np.pi * self.freq * max(t - 1.0, 0.0)
        goal = self.centre + self.b.R[:, 0] * self.amp * np.sin(phase)
        goal_v = self.b.R[:, 0] * self.amp * 2 * np.pi * self.freq * np.cos(phase) * (t > 1.0)
        e = np.concatenate([goal - p, pin.log3(self.R_goal @ R.T)])
        de = np.concatenate([goal_v - v[:3], -v[3:]])
        e[:3] -= (e[:3] @ n) * n
        de[:3] -= (de[:3] @ n) * n
        a = self.K @ e + self.D @ de
        a[:3] -= 30.0 * (v[:3] @ n) * n
        f = Lam @ a
        f[:3] -= self.force_n * n
        N = np.eye(7) - J.T @ (M_inv @ J.T @ Lam).T
        posture = N @ (M @ (10.0 * (self.q_rest - q) - 2.0 * np.sqrt(10.0) * dq))
        return J.T @ f + self.m.gravity(q) + posture


@pytest.mark.parametrize("preset", ["wall", "table"])
def test_pressing_and_sliding_wipes_the_stain_under_the_pad_and_leaves_the_next_one(tmp_path, model, preset):
    board = board_from_params(BoardParams(preset=preset))
    cx, cy = (float(v) for v in board.size_m / 2)
    under = {"centre_m": [cx, cy], "size_m": 0.06, "aspect": 2.5, "angle_deg": 0.0}  # 6 x 2.4 cm on the path
    beside = {"centre_m": [cx, cy + 0.07], "size_m": 0.04, "aspect": 2.0, "angle_deg": 0.0}  # 2.5 cm off the pad
    sim_cfg = {"mode": "lockstep", "camera": NO_CAMERA, "board": {"preset": preset},
               "dirt": {"stain": [under, beside]}}
    client = PressAndSlide(model, board, (cx, cy), force_n=10.0)
    with SimProcess(tmp_path, sim_cfg) as sim:
        truth = sim.node.latest(sim.keys.sim_truth, SimTruth)
        states = run_lockstep(sim, 4000, client)
        final = wait_seq(truth, 4000, 5.0, "sim truth")
    forces = np.array([np.array(s.wrench_world[:3]) @ board.normal_world for s in states])
    # the client only damps its approach (and no friction compensation): the pad lands after 2-3 s
    touched = int(np.argmax(forces > 1.0))
    assert 0 < touched < 3200, f"the pad touched the board at step {touched}"
    sliding = forces[touched + 300:]
    assert 6.0 < sliding.mean() < 14.0, f"mean normal force {sliding.mean():.1f} N (10 N pressed)"
    assert final.seq == 4000 and final.stain_ids == [0, 1]
    assert final.remaining[0] < 0.2, final.remaining
    assert final.remaining[1] == 1.0
    assert final.contact_force_n > 2.0
    assert final.T_board_to_world is not None
    # the truth is what was drawn: the wobbly 6 x 2.4 cm ellipse's centre and long extent, not the nominal ones
    assert np.allclose(final.centres_board_m[0], [cx, cy], atol=0.004), final.centres_board_m
    assert 0.045 < final.sizes_m[0] < 0.07, final.sizes_m


def test_lockstep_runs_are_bit_identical_for_a_seed(tmp_path, model):
    """Contact, friction and dirt removal included: the pad lands on a seeded stain and slides."""
    board = board_from_params(BoardParams())
    runs, truths = [], []
    for i in range(2):
        cfg = {"mode": "lockstep", "seed": 7, "camera": NO_CAMERA,
               "dirt": {"stain": [{"centre_m": [0.4, 0.3], "size_m": 0.06, "aspect": 2.5}]}}
        client = PressAndSlide(model, board, (0.4, 0.3))
        with SimProcess(tmp_path, cfg, name=f"sim{i}") as sim:
            truth = sim.node.latest(sim.keys.sim_truth, SimTruth)
            states = run_lockstep(sim, 3000, client)  # the pad lands after about 2.2 s
            truths.append(_newest_truth(truth))
        runs.append(np.array([s.q_rad + s.dq_rad_s + s.tau_nm + s.wrench_world for s in states]))
    assert runs[0].shape == (3001, 27)
    assert np.abs(runs[0][:, 21:24]).max() > 5.0  # it pressed on the board
    assert truths[0][1][0] < 1.0  # and wiped
    assert runs[0].tobytes() == runs[1].tobytes()
    assert truths[0] == truths[1]


def _newest_truth(reader) -> tuple[int, list[float]]:
    """(robot time [ns], remaining) of the last truth the sim published: the newest once none has come for 1 s
    (the first one taken may still be an earlier truth, the last one on its way)."""
    last = wait_for(reader.take, 5.0, "sim truth")
    quiet_until = time.monotonic() + 1.0
    while time.monotonic() < quiet_until:
        if (m := reader.take()) is not None:
            last, quiet_until = m, time.monotonic() + 1.0
        time.sleep(0.02)
    return last.robot_time_ns, last.remaining


@pytest.mark.alone
@pytest.mark.parametrize("stale_limit_s, should_brake", [(0.02, True), (1.0, False)])
def test_realtime_stale_command_makes_the_arm_brake_and_hold(tmp_path, model, stale_limit_s, should_brake):
    cfg = {"mode": "realtime", "stale_limit_s": stale_limit_s, "camera": NO_CAMERA,  # the control case: no speed
           "speed_brake_share": 0.95 if should_brake else 0.0,  # brake and no late-answer damping either (held,
           "late_damping_rad_s": 120.0 if should_brake else 0.0}  # the push moves joint 1 0.2 rad in 0.4 s with it)
    with SimProcess(tmp_path, cfg) as sim:
        states = sim.node.latest(sim.keys.robot_state, RobotState)
        first = wait_for(states.take, 10.0, "a robot state")
        end = time.monotonic() + 0.5
        last = first
        while time.monotonic() < end:  # hold the arm with gravity torques, answering each state
            s = states.take()
            if s is None:
                time.sleep(0.0005)  # polling the one-slot reader between 1 kHz states, not waiting for Zenoh
                continue
            last = s
            sim.node.publish(sim.keys.robot_command, TorqueCommand(seq=s.seq, stamp_ns=time.monotonic_ns(),
                                                                   tau_nm=model.gravity(np.array(s.q_rad)).tolist()))
        # the last command would spin joint 1 if it were held for long (about 30 rad/s^2 here)
        push = model.gravity(np.array(last.q_rad)) + np.array([5.0, 0, 0, 0, 0, 0, 0])
        sim.node.publish(sim.keys.robot_command, TorqueCommand(seq=last.seq, stamp_ns=time.monotonic_ns(),
                                                               tau_nm=push.tolist()))
        q_push = np.array(last.q_rad)
        # no command after the push: 0.4 s and then 0.3 s more on the sim's own clock (real time, but a
        # loaded machine may run it slower than the wall clock)
        after = wait_sample(states, lambda s: s.robot_time_ns >= last.robot_time_ns + 400_000_000, 10.0,
                            "a robot state 0.4 s (robot time) after the push")
        later = wait_sample(states, lambda s: s.robot_time_ns >= after.robot_time_ns + 300_000_000, 10.0,
                            "a robot state 0.3 s (robot time) later")
        status = latest_status(sim)
    moved = abs(after.q_rad[0] - q_push[0])
    if should_brake:
        # 20 ms of the push moves joint 1 by about 6 mrad; held for 0.4 s it would move radians
        assert moved < 0.05, f"joint 1 moved {moved:.4f} rad after the commands stopped"
        assert max(abs(v) for v in later.dq_rad_s) < 0.01
        assert np.abs(np.subtract(later.q_rad, after.q_rad)).max() < 1e-3, "brakes hold the pose"
        assert status.counters.get("stale_command_brakes", 0) >= 1
        assert "braked=True" in status.detail
    else:
        assert moved > 0.5, "the control case: a held command keeps driving the arm"
    assert status.timing.ticks > 400


def _raw_command(seq: int, tau) -> bytes:
    """A TorqueCommand's bytes with any values (bypassing the constructor's checks)."""
    wire = msgspec.msgpack.decode(encode(TorqueCommand(seq=seq, stamp_ns=1, tau_nm=[0.0] * 7)))
    wire[3] = list(tau)
    return msgspec.msgpack.encode(wire)


def test_bad_commands_are_counted_and_never_reach_the_physics(tmp_path, model):
    with SimProcess(tmp_path, {"mode": "lockstep", "camera": NO_CAMERA}) as sim:
        states = sim.node.inbox(sim.keys.robot_state, RobotState)
        s0 = wait_for(lambda: states.get(1.0), 10.0, "state 0")
        pub = sim.node.session.declare_publisher(sim.keys.robot_command)
        for payload in (b"\x00garbage", encode(TorqueCommand(seq=0, stamp_ns=1, tau_nm=[0.0] * 7))[:-3],
                        _raw_command(0, [float("nan")] * 7), _raw_command(0, [float("inf")] + [0.0] * 6)):
            pub.put(payload)
        sim.node.publish(sim.keys.robot_command, TorqueCommand(seq=0, stamp_ns=1, tau_nm=[0.0] * 6))  # wrong length
        for _ in range(25):  # out-of-sequence chatter every 20 ms must not stop state 0 being re-sent
            sim.node.publish(sim.keys.robot_command, TorqueCommand(seq=5, stamp_ns=1, tau_nm=[0.0] * 7))
            time.sleep(0.02)  # the chatter's pace over 0.5 s is the scenario, not a wait for Zenoh
        status = latest_status(sim, 10.0, lambda m: m.counters.get("commands_out_of_sequence", 0) >= 25,
                               "a sim status counting the 25 out-of-sequence commands")
        assert status.seq == 0, "no bad command may step the physics"
        assert status.counters["states_republished"] >= 3 and status.counters["commands_out_of_sequence"] == 25
        over = model.gravity(np.array(s0.q_rad)) + np.array([0, 0, 0, 0, 0, 500.0, 0])
        sim.node.publish(sim.keys.robot_command, TorqueCommand(seq=0, stamp_ns=1, tau_nm=over.tolist()))
        s1 = wait_for(lambda: (lambda s: s if s is not None and s.seq == 1 else None)(states.get(1.0)), 10.0, "state 1")
        status = latest_status(sim, 10.0, lambda m: m.seq >= 1, "a sim status after step 1")
        pub.undeclare()
    assert s1.tau_nm[5] == pytest.approx(40.0)  # clipped to joint 6's limit
    c = status.counters
    bad = sum(v for k, v in c.items() if k.startswith("commands_dropped_bad_payload"))
    assert bad == 4, c
    assert c["commands_dropped_wrong_length"] == 1
    assert c["commands_clipped"] == 1 and c["commands_applied"] == 1


def test_camera_frames_show_the_board_markers_where_the_camera_model_says(tmp_path, model):
    cfg = {"mode": "lockstep", "camera": {"width": 320, "height": 240, "rate_hz": 10.0}}
    with SimProcess(tmp_path, cfg) as sim:
        frames = sim.node.latest(sim.keys.camera_frame("board"), CameraFrame)
        truth = sim.node.latest(sim.keys.sim_truth, SimTruth)
        run_lockstep(sim, 250, lambda s: model.gravity(np.array(s.q_rad)))
        frame = wait_for(frames.take, 20.0, "a camera frame")
        board_truth = wait_for(truth.take, 5.0, "sim truth")
    assert frame.encoding == "rgb8" and frame.intrinsics.width == 320
    assert frame.robot_time_ns % 100_000_000 == 0 and frame.robot_time_ns > 0
    rgb = np.frombuffer(frame.data, np.uint8).reshape(240, 320, 3)
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    corners, ids, _ = detector.detectMarkers(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))
    assert ids is not None and len(ids) >= 3, "the arm may hide one marker, not more"
    T_board = transform_from_pose(board_truth.T_board_to_world)
    T_cam = transform_from_pose(frame.T_camera_to_world)
    expected = marker_corners_board((0.8, 0.6))
    for c, i in zip(corners, ids.ravel()):
        world = expected[int(i)] @ T_board[:3, :2].T + T_board[:3, 3]
        assert np.abs(c[0] - project(frame.intrinsics, T_cam, world)).max() < 2.0
