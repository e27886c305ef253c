"""No joint runs away: the clearance posture in the task's nullspace, and stops and lifts that stay within the arm's
reach with the elbow off its stretched pose (controller/control/limits.py, controller/free_motion.py).

The cell: board 27 (:data:`BOARD_27`, a tilted board the simulator starts on, which the sampler refuses since a
point of its stain region is beyond the controller's reach test), where the retreat's in-plane stop coasted 7 cm up
the tilted board to the arm's full reach, the arm swung through its stretched pose (A4 at 0) and the robot side's
FAULT-hold ended the run.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from arm.reach import arm_reach
from arm.robot_model import RobotModel
from controller.control.impedance import Kinematics, Reference, TaskShaping, impedance_torque
from controller.control.limits import clearance_torque
from controller.control.params import ImpedanceParams
from controller.executor_types import BoardPose, ToolState
from controller.free_motion import MIN_LIFT_M, STRETCH_ROOM_RAD, FreeMotion
from controller.motion import bounded_brake_to_rest
from controller.params import ExecutorParams, ForceParams, LimitParams
from interfaces.errors import ConfigError
from interfaces.transforms import tool_rotation_on_board

from .conftest import REPO

LO, HI = -np.full(7, 2.0), np.full(7, 2.0)
SINGULAR = np.array([0, 1, 0, 1, 0, 1, 0], float)


def test_the_clearance_pushes_out_of_its_zones_only_and_is_continuous_at_their_edges():
    still = np.zeros(7)
    q = np.array([0.0, 1.0, 1.7, 0.1, -1.9, -0.05, 1.49])
    tau = clearance_torque(q, still, LO, HI, 0.5, SINGULAR, 0.3, 20.0, 2.0)
    # joint 1 free; 2 free; 3 0.2 deep before its upper limit; 4 0.2 deep around zero, pushed up; 5 0.4 deep
    # before its lower limit; 6 0.25 deep around zero on the negative side; 7 just outside its zone
    np.testing.assert_allclose(tau, [0.0, 0.0, -4.0, 4.0, 8.0, -5.0, 0.0], atol=1e-12)
    for i, edge in ((2, 1.5), (3, 0.3)):  # continuous at each zone's edge, in position and with speed
        for dq in (-1.0, 1.0):
            q_in, q_out = q.copy(), q.copy()
            q_in[i], q_out[i] = edge + (1e-9 if i == 2 else -1e-9), edge + (-1e-9 if i == 2 else 1e-9)
            v = np.full(7, dq)
            a = clearance_torque(q_in, v, LO, HI, 0.5, SINGULAR, 0.3, 20.0, 2.0)[i]
            b = clearance_torque(q_out, v, LO, HI, 0.5, SINGULAR, 0.3, 20.0, 2.0)[i]
            assert abs(a - b) < 1e-6, (i, dq, a, b)
    # damping only against motion deeper in
    deeper = clearance_torque(q, np.array([0, 0, 1.0, -1.0, -1.0, 1.0, 0]), LO, HI, 0.5, SINGULAR, 0.3, 20.0, 2.0)
    out = clearance_torque(q, np.array([0, 0, -1.0, 1.0, 1.0, -1.0, 0]), LO, HI, 0.5, SINGULAR, 0.3, 20.0, 2.0)
    assert np.all(np.abs(deeper[2:6]) > np.abs(tau[2:6])) and np.allclose(out, tau)


def test_the_clearance_acts_in_the_nullspace_only():
    """Through the law's posture, the clearance changes the joint torques but not what they do to the pad."""
    model = RobotModel()
    kin = Kinematics(model)
    rng = np.random.default_rng(7)
    for _ in range(10):
        q = rng.uniform(model.limits.q_min * 0.8, model.limits.q_max * 0.8)
        kin.update(q, np.zeros(7))
        ref = Reference(kin.p.copy(), kin.R.copy())
        plain = impedance_torque(model, q, np.zeros(7), ref, ImpedanceParams(), q, False, TaskShaping(), kin)
        push = rng.normal(0, 10, 7)
        cleared = impedance_torque(model, q, np.zeros(7), ref, ImpedanceParams(), q, False,
                                   TaskShaping(posture_nm=push), kin)
        diff = cleared.tau_nm - plain.tau_nm
        assert np.linalg.norm(diff) > 1e-3 * np.linalg.norm(push)  # one direction of 7 is the nullspace
        # the pad's acceleration from the difference: J M^-1 diff = 0 (dynamically consistent projection)
        # (to the task inertia's regularisation, LAMBDA_EPS: a few parts per million near a singular pose)
        assert np.linalg.norm(kin.J @ kin.M_inv @ diff) < 1e-4 * np.linalg.norm(kin.M_inv @ diff), q


def test_singular_joints_are_checked():
    assert LimitParams(singular_joints=[4, 6]).singular_joints == (4, 6)
    for bad in ([0], [8], [4, 4], ["4"], 4):
        with pytest.raises(ConfigError, match="singular_joints"):
            LimitParams(singular_joints=bad)


def test_a_bounded_stop_that_would_coast_out_of_reach_ends_in_reach():
    """Within tight bounds the stop takes long and coasts far; where that end is out of reach, the first try that
    ends in reach is taken, even beyond the bounds (reach before smoothness)."""
    p0, v0, a0 = np.zeros(2), np.array([0.1, 0.0]), np.array([0.5, 0.0])
    long = bounded_brake_to_rest(p0, v0, a0, 0.2, 0.05, 0.5)
    short = bounded_brake_to_rest(p0, v0, a0, 0.2, 0.05, 0.5, reachable=lambda xy: xy[0] <= 0.02)
    assert long.goal[0][0] > 0.02 and short.goal[0][0] <= 0.02, (long.goal[0], short.goal[0])
    assert short.T < long.T
    never = bounded_brake_to_rest(p0, v0, a0, 0.2, 0.05, 0.5, reachable=lambda xy: False)
    assert never.T == pytest.approx(0.2)  # nowhere in reach: the shortest stop


#: Board 27: tilted, its far part near the arm's reach (near enough that the sampler refuses it: a point of its
#: stain region puts the elbow within 0.1 rad of stretched straight; the controller skips a stain there).
BOARD_27 = {"preset": "custom", "origin_m": [0.855801, 0.137946, 0.186604],
            "quat_wxyz": [0.312984393, 0.240603053, -0.418372536, -0.81799472], "size_m": [0.6902, 0.4863]}


def _board_27() -> BoardPose:
    """:data:`BOARD_27` as the controller takes it."""
    from interfaces.messages import Pose
    from interfaces.transforms import transform_from_pose

    t = BOARD_27
    return BoardPose.from_transform(transform_from_pose(Pose(t["origin_m"], t["quat_wxyz"])), t["size_m"])


def test_a_lift_ends_where_the_elbow_has_room():
    motion = FreeMotion(ExecutorParams(), ForceParams())
    motion.arm = arm_reach(RobotModel())
    board = _board_27()
    from interfaces.transforms import tool_rotation_on_board

    motion.setpoint.R[:] = tool_rotation_on_board(board.R)
    standoff = ExecutorParams().standoff_m
    grid = [np.array([x, y]) for x in np.linspace(0.0, board.size_m[0], 30)
            for y in np.linspace(0.0, board.size_m[1], 30)]
    edge = [xy for xy in grid if motion.roomy(board, xy, MIN_LIFT_M) and not motion.roomy(board, xy, standoff)]
    assert edge, "board 27 has points reachable on the board but stretched at the standoff"
    tool = ToolState(edge[0], 0.0, np.zeros(2), 0.0, motion.setpoint.R.copy(), 10.0)
    motion.setpoint.xy[:] = tool.xy
    motion.setpoint.contact = True
    assert not motion.lift(tool, board=board)
    h = float(motion._mover.goal[0][2])
    assert MIN_LIFT_M <= h < ExecutorParams().standoff_m
    p = board.to_world(np.array([*edge[0], h]))
    assert motion.arm.elbow_rad(p, motion.setpoint.R) >= STRETCH_ROOM_RAD
    assert motion.lift(tool)  # without the board: the full standoff, as before


def test_the_hover_over_a_stain_near_the_shoulder_is_lowered_to_where_the_elbow_has_room():
    """Random board 279: 40 mm above its stain at (0.15, 0.22) m the elbow would fold past its limit (the pad waited
    30 mm off that hover and sped into the board as the descent came back in reach). The hover is lowered to where
    the elbow keeps HOVER_ELBOW_ROOM_RAD (over a point nearby where no height above the creep height has it);
    where the standoff has room it stays."""
    from controller.free_motion import HOVER_ELBOW_ROOM_RAD
    from interfaces.messages import Pose
    from interfaces.transforms import transform_from_pose
    from sim.board_sampler import sample_board

    t = sample_board(279).table
    board = BoardPose.from_transform(transform_from_pose(Pose(t["origin_m"], t["quat_wxyz"])), t["size_m"])
    motion = FreeMotion(ExecutorParams(), ForceParams())
    motion.arm = arm_reach(RobotModel())
    R, p = tool_rotation_on_board(board.R), ExecutorParams()
    cramped, roomy = np.array([0.15, 0.22]), np.array([0.3, 0.3])
    assert motion.arm.elbow_room_rad(board.to_world(np.array([*cramped, p.standoff_m])), R) < 0.0
    assert not motion.fly_to_hover(cramped, board)
    goal = motion._mover.goal[0]
    h = float(goal[2])
    room = motion.arm.elbow_room_rad(board.to_world(np.array([*goal[:2], h])), R)
    assert h < p.standoff_m and room >= HOVER_ELBOW_ROOM_RAD, (goal, room)  # (moved along the board: below)
    assert motion.fly_to_hover(roomy, board) and float(motion._mover.goal[0][2]) == pytest.approx(p.standoff_m)


def test_a_hover_no_height_of_which_has_elbow_room_moves_along_the_board_to_one_that_has():
    """Random board 899: over its stain at (0.598, 0.149) m no height down to the creep height leaves the elbow
    HOVER_ELBOW_ROOM_RAD (it folds against its limit; the pad sank 14 mm under its hover onto the board at 22-29 N).
    The hover moves along the board, away from the shoulder, to the nearest point that has the room, within
    HOVER_SHIFT_MAX_M; a hover that has it stays over its stain."""
    from controller.free_motion import HOVER_ELBOW_ROOM_RAD, HOVER_SHIFT_MAX_M
    from interfaces.messages import Pose
    from interfaces.transforms import transform_from_pose
    from sim.board_sampler import sample_board

    t = sample_board(899).table
    board = BoardPose.from_transform(transform_from_pose(Pose(t["origin_m"], t["quat_wxyz"])), t["size_m"])
    p = ExecutorParams()
    motion = FreeMotion(p, ForceParams())
    motion.arm = arm_reach(RobotModel())
    R = tool_rotation_on_board(board.R)
    stain = np.array([0.598, 0.149])
    for h in np.arange(p.creep_height_m, p.standoff_m + 1e-9, 0.005):  # the case: no height has the room
        assert motion.arm.elbow_room_rad(board.to_world(np.array([*stain, h])), R) < HOVER_ELBOW_ROOM_RAD, h
    assert not motion.fly_to_hover(stain, board)
    goal = motion._mover.goal[0]
    xy, h = goal[:2], float(goal[2])
    room = motion.arm.elbow_room_rad(board.to_world(np.array([*xy, h])), R)
    assert room >= HOVER_ELBOW_ROOM_RAD and h >= p.creep_height_m - 1e-9, (xy, h, room)
    assert 0.0 < np.linalg.norm(xy - stain) <= HOVER_SHIFT_MAX_M + 1e-9 and np.all((xy >= 0) & (xy <= board.size_m))
    assert motion.counters["hovers_shifted"] == 1
    # the nearest such point along that line: one step back has no room at any height
    back = xy + 0.01 * (stain - xy) / np.linalg.norm(stain - xy)
    assert not any(motion.roomy(board, back, hb, R, HOVER_ELBOW_ROOM_RAD)
                   for hb in np.arange(p.creep_height_m, p.standoff_m + 1e-9, 0.005))
    motion.fly_to_hover(np.array([0.4, 0.3]), board)  # a stain with room: the hover over it
    np.testing.assert_allclose(motion._mover.goal[0][:2], [0.4, 0.3])
    assert motion.counters["hovers_shifted"] == 1


def run_random_board(tmp_path, seed: int, stains: int, table: dict | None = None,
                     first_start: bool = False) -> tuple[dict, str, dict]:
    """``lamps up --no-network`` on the random board ``seed`` (or the ``[board]`` ``table``, from a TOML file) with
    ``stains`` stains (seed ``seed``): its report, its output and the simulator's counters. ``first_start``: the
    arm starts where the inverse kinematics' first answer puts it (``[sim] start_q_rad``), not in the configuration
    the simulator chooses for the whole board (``sim.board.start_configuration``): the hard start a test of the
    controller needs."""
    import os

    from sim.board import board_from_params, start_configuration
    from sim.board_sampler import sample_board
    from sim.params import SimParams

    out = tmp_path / "run"
    board = f"random:{seed}"
    if table is not None:
        board = str(tmp_path / "board.toml")
        lines = "".join(f"{k} = {json.dumps(v)}\n" for k, v in table.items())
        (tmp_path / "board.toml").write_text("[board]\n" + lines)
    env = dict(os.environ)
    if first_start:
        params = SimParams.from_table({"board": table or sample_board(seed).table})
        q0 = start_configuration(board_from_params(params.board), params.start_standoff_m)
        env["LAMPS__SIM__START_Q_RAD"] = json.dumps([round(float(v), 9) for v in q0])
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "up", "--no-network", "--board", board,
                        "--stains", str(stains), "--seed", str(seed), "--out", str(out), "-q"], cwd=REPO,
                       capture_output=True, text=True, timeout=900, env=env)
    report = json.loads((out / "report.json").read_text())
    print(r.stdout[-2000:])
    return report, r.stdout, report["counters"]["sim"]


@pytest.mark.slow
def test_board_27_cleans_without_the_robot_side_braking(tmp_path):
    report, stdout, sim = run_random_board(tmp_path, 27, 4, BOARD_27, first_start=True)
    assert report["outcome"] == "cleaned", (report["outcome"], report["faults"], stdout[-3000:])
    assert not {k: v for k, v in sim.items() if ("brake" in k or "yield" in k or "fault" in k) and v}, sim
    assert report["max_joint_speed_ratio"] < 0.8


def test_a_stain_beyond_the_arm_is_skipped_with_the_reason_never_attempted(learned_skill):
    """A wall board 1.6 m wide: its far end is beyond the stretched arm. That stain is closed as out of reach,
    named and counted; the others are planned as before."""
    from controller.executor import SkillExecutor
    from lampskit.core.planner_types import Stain

    from .test_controller_units import BOARD

    ex = SkillExecutor(learned_skill, ExecutorParams(survey_s=0.0))
    ex.motion.arm = arm_reach(RobotModel())
    big = BoardPose(BOARD.R, BOARD.origin_m, np.array([1.6, 0.6]))
    near, far = Stain(0, np.array([0.3, 0.3]), 0.06, kappa=False), Stain(1, np.array([1.4, 0.3]), 0.06, kappa=False)
    ex.set_stains(big, [near, far])
    assert set(ex.book.out_of_reach) == {1} and "beyond the stretched arm" in ex.book.out_of_reach[1]
    assert ex.counters["stains_out_of_reach"] == 1 and ex.book.is_done(1)
    assert [s.id for s in ex.book.open_stains(0.0)] == [0]
    ex.set_stains(big, [near, far])  # looked at once per board
    assert ex.counters["stains_out_of_reach"] == 1
    ex.stops.done()  # a DONE names the stain it leaves and why
    assert ex.reason.startswith("1 stain(s) left: stain 1 at (1.40, 0.30) m out of the arm's reach (beyond the "
                                "stretched arm"), ex.reason


def test_a_stain_whose_far_end_would_stretch_the_elbow_straight_is_skipped_naming_the_end(learned_skill):
    """Its centre is in reach, but wiping it whole would take the pad past where the elbow comes within
    UNREACHABLE_STRETCH_RAD of stretched straight (the arm's singular pose): skipped, the end and why named; a
    stain as large beside it, clear of that edge, is planned."""
    from arm.reach import UNREACHABLE_STRETCH_RAD
    from controller.executor import SkillExecutor
    from lampskit.core.planner_types import Stain

    from .test_controller_units import BOARD

    ex = SkillExecutor(learned_skill, ExecutorParams(survey_s=0.0))
    arm = ex.motion.arm = arm_reach(RobotModel())
    big = BoardPose(BOARD.R, BOARD.origin_m, np.array([1.6, 0.6]))
    R = tool_rotation_on_board(big.R)

    def roomy(x: float) -> bool:  # the elbow bent more than UNREACHABLE_STRETCH_RAD (inf: beyond the arm)
        return UNREACHABLE_STRETCH_RAD < arm.elbow_rad(big.to_world(np.array([x, 0.3, 0.0])), R) < np.inf

    lo, hi = 0.3, 1.6  # where along board x the elbow comes to stretched (it stretches outwards)
    assert roomy(lo) and not roomy(hi)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if roomy(mid) else (lo, mid)
    edge = lo
    reaching = Stain(0, np.array([edge - 0.03, 0.3]), 0.12, width_m=0.02)  # main axis along x: its end 3 cm past
    clear = Stain(1, np.array([edge - 0.2, 0.3]), 0.12, width_m=0.02)
    assert ex.motion.reach_problem(big, reaching.centre_m) is None  # its centre alone would pass
    ex.set_stains(big, [reaching, clear])
    assert set(ex.book.out_of_reach) == {0}, ex.book.out_of_reach
    why = ex.book.out_of_reach[0]
    # the band where the elbow is bent less than 0.1 rad is a millimetre wide: past it, the arm does not reach
    assert why.startswith(f"its end at ({edge + 0.03:.2f}, 0.30) m is ") and "stretched" in why, why
    assert [s.id for s in ex.book.open_stains(0.0)] == [1]


def test_the_clearance_fades_out_while_a_joint_runs_fast():
    """Near a singular pose a small push spins the wrist: the clearance never drives a joint past 0.6 of its
    speed limit (full below 0.4, none at 0.6)."""
    q = np.array([0.0, 1.0, 1.7, 0.1, -1.9, -0.05, 1.49])
    limit = np.full(7, 2.0)
    full = clearance_torque(q, np.zeros(7), LO, HI, 0.5, SINGULAR, 0.3, 20.0, 0.0, limit, 0.6)
    for share, gain in ((0.3, 1.0), (0.4, 1.0), (0.5, 0.5), (0.6, 0.0), (0.9, 0.0)):
        dq = np.zeros(7)
        dq[0] = share * 2.0  # joint 1, outside every zone: only the speed matters
        got = clearance_torque(q, dq, LO, HI, 0.5, SINGULAR, 0.3, 20.0, 0.0, limit, 0.6)
        np.testing.assert_allclose(got, gain * full, atol=1e-12, err_msg=str(share))


#: Random board 120 as the sampler draws it: its first touch was the highest force of 347 random cells (19.8 N).
BOARD_120 = {"preset": "custom", "origin_m": [0.719452, 0.193526, 0.519292],
             "quat_wxyz": [0.259261134, 0.53414588, -0.449375088, -0.667483238], "size_m": [0.8994, 0.5864]}


@pytest.mark.slow
def test_board_120_first_touch_stays_well_under_20_n(tmp_path):
    """The felt meets the board at the creep speed and the force climbs for a few ticks before the force loop
    answers; the peak grows with the speed (19.8 N here at 0.02 m/s). At the default creep speed the cell's
    highest force over every step stays under 15 N."""
    from sim.board_sampler import sample_board

    assert sample_board(120).table == BOARD_120
    report, stdout, sim = run_random_board(tmp_path, 120, 1, BOARD_120)
    assert report["outcome"] == "cleaned", (report["outcome"], report["faults"], stdout[-3000:])
    assert report["peak_contact_force_n"] < 15.0, report["peak_contact_force_n"]
