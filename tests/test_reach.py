"""The elbow's reach (arm/reach.py) against Pinocchio, and look points the arm can take."""

from __future__ import annotations

import numpy as np
import pytest

from arm.reach import arm_reach
from arm.robot_model import IkError, RobotModel
from controller.executor_types import BoardPose
from controller.look_points import LOOK_ELBOW_ROOM_RAD, look_point
from interfaces.transforms import tool_rotation_on_board
from sim.board import board_from_params, start_configuration
from sim.params import BoardParams

TILTED = BoardParams(preset="custom", origin_m=(0.45, 0.35, 0.25), quat_wxyz=(0.664463, 0.241845, -0.241845, -0.664463),
                     size_m=(0.7, 0.45))  # config/boards/tilted.toml


@pytest.fixture(scope="module")
def model():
    return RobotModel()


def test_the_elbow_angle_follows_from_the_pad_pose_alone(model):
    """Any configuration: |q4| from the shoulder-wrist distance equals the joint's own (a spherical shoulder and
    wrist; the wrist centre is rigid in the pad frame)."""
    arm = arm_reach(model)
    rng = np.random.default_rng(0)
    for _ in range(200):
        q = rng.uniform(model.limits.q_min, model.limits.q_max)
        p, R = model.tcp_pose(q)
        assert arm.elbow_rad(p, R) == pytest.approx(abs(q[3]), abs=1e-9)
    assert arm.elbow_room_rad(np.array([5.0, 0.0, 0.0]), np.eye(3)) == -np.inf, "beyond the stretched arm"


@pytest.mark.parametrize("name, params, moved", [("table", BoardParams(preset="table"), True),
                                                 ("tilted", TILTED, True),
                                                 ("wall", BoardParams(preset="wall"), False)])
def test_the_survey_look_point_is_one_the_arm_can_reach(model, name, params, moved):
    """The survey's look point (4 cm above the board's edge nearest the base) was out of reach on the table and the
    tilted board (the elbow folded past its limit; the pad dipped into the board at 30 N): with the arm's reach it
    moves in until the elbow has room; on the wall board it stays on the edge."""
    board = board_from_params(params)
    pose = BoardPose(board.R, board.origin_m, np.array(board.size_m, float))
    w, h = board.size_m
    corners = [np.array(c, float) for c in ((0, 0), (w, 0), (0, h), (w, h))]
    R = tool_rotation_on_board(board.R)
    q0 = start_configuration(board, 0.04, model)
    plain = look_point(pose, corners, [0.0] * 4, 0.1)
    xy = look_point(pose, corners, [0.0] * 4, 0.1, arm_reach(model), 0.04)
    p = pose.to_world(np.array([*xy, 0.04]))
    q = model.solve_ik(p, R, q0, tol_m=1e-3)
    assert model.limits.q_max[3] - abs(q[3]) >= LOOK_ELBOW_ROOM_RAD - 0.01  # the IK to 1 mm
    if moved:
        with pytest.raises(IkError):
            model.solve_ik(pose.to_world(np.array([*plain, 0.04])), R, q0, tol_m=1e-3)
        assert xy[1] > plain[1] and xy[0] == pytest.approx(plain[0]), "moved in towards the board centre"
    else:
        np.testing.assert_allclose(xy, plain)


def test_a_look_point_out_of_reach_towards_the_base_turns_aside_clear_of_the_stain(model):
    """A stain near the tilted board's near edge: the point beyond it towards the base is out of reach; the one
    the bisection would give hovers over the stain (the camera never saw it clean: six passes, 2x the run's time in
    a campaign cell). The look point turns off that line, clear of the stain, where the elbow has room."""
    board = board_from_params(TILTED)
    pose = BoardPose(board.R, board.origin_m, np.array(board.size_m, float))
    arm = arm_reach(model)
    c, size = np.array([0.238, 0.157]), 0.06
    xy = look_point(pose, [c], [size], 0.1, arm, 0.04)
    assert np.linalg.norm(xy - c) >= 0.5 * size + 0.05, "clear of the stain"
    R = tool_rotation_on_board(board.R)
    assert arm.elbow_room_rad(pose.to_world(np.array([*xy, 0.04])), R) >= LOOK_ELBOW_ROOM_RAD
    towards_base = pose.to_board(np.zeros(3))[:2] - c
    assert (xy - c) @ towards_base >= 0.0, "never beyond the stain, where the arm would reach over it"


def test_each_further_look_at_a_waiting_stain_is_from_another_point(model):
    """A stain at the table board's near edge stayed without kappa after six passes: the links hid part of it from
    the camera at the one look point (59 % of it seen; kappa wants 90 %). Each further look (``attempt``) takes the
    next point that qualifies (reachable, clear of the stain, not beyond it), in turn."""
    board = board_from_params(BoardParams(preset="table"))
    pose = BoardPose(board.R, board.origin_m, np.array(board.size_m, float))
    arm = arm_reach(model)
    R = tool_rotation_on_board(board.R)
    c, size = np.array([0.211, 0.167]), 0.085
    points = [look_point(pose, [c], [size], 0.1, arm, 0.04, attempt=k) for k in range(8)]
    np.testing.assert_allclose(points[0], look_point(pose, [c], [size], 0.1, arm, 0.04))
    distinct = {tuple(np.round(p, 6)) for p in points}
    assert len(distinct) >= 2, points  # here: beside it on the right (the first look), then on the left
    towards_base = pose.to_board(np.zeros(3))[:2] - c
    for xy in points:
        assert np.linalg.norm(xy - c) >= 0.5 * size + 0.05
        assert arm.elbow_room_rad(pose.to_world(np.array([*xy, 0.04])), R) >= LOOK_ELBOW_ROOM_RAD
        assert (xy - c) @ towards_base >= -1e-9
    np.testing.assert_allclose(points[len(distinct)], points[0])  # round again after the last


def test_the_shoulder_and_wrist_ranges_hold_for_every_configuration(model):
    """Whatever the joints, |q2| is at most the shoulder's largest tilt and |q6| within the wrist's range at the pad
    pose they make: the ranges span the elbow's whole swing (closed form, arm/reach.py)."""
    arm = arm_reach(model)
    rng = np.random.default_rng(1)
    for _ in range(500):
        q = rng.uniform(model.limits.q_min, model.limits.q_max)
        p, R = model.tcp_pose(q)
        assert abs(q[1]) <= arm.shoulder_tilt_max_rad(p, R) + 1e-9
        least, most = arm.wrist_bend_range_rad(p, R)
        assert least - 1e-9 <= abs(q[5]) <= most + 1e-9
    assert np.isnan(arm.shoulder_tilt_max_rad(np.array([5.0, 0.0, 0.0]), np.eye(3))), "beyond the stretched arm"


def _ik_solutions(model, p, R, n=30):
    rng, found = np.random.default_rng(2), []
    for _ in range(n):
        try:
            found.append(model.solve_ik(p, R, rng.uniform(model.limits.q_min, model.limits.q_max), tol_m=1e-3))
        except IkError:
            pass
    return found


def _motion(model):
    from controller.free_motion import FreeMotion
    from controller.params import ExecutorParams, ForceParams

    motion = FreeMotion(ExecutorParams(), ForceParams())
    motion.arm = arm_reach(model)
    return motion


def test_a_ceiling_over_the_shoulder_is_refused_for_the_shoulders_singularity(model):
    """A board facing down 0.81 m straight over the shoulder's centre: the elbow is bent 0.31 rad (the stretch check
    passes it) but at any swing the upper arm stays within 0.2 rad of A1's axis, A1 and A3 lined up. Refused with
    that reason; every joint solution the IK finds agrees; 10 cm aside the shoulder has room again."""
    motion = _motion(model)
    arm = motion.arm
    down = np.column_stack([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # board axes: normal down
    wrist_z = arm.shoulder_m[2] + 0.81
    face = wrist_z - float(arm.wrist_in_pad_m[2])  # the pad's z axis points up, into the ceiling
    board = BoardPose(down, np.array([-0.3, 0.3, face]), np.array([0.6, 0.6]))
    p, R = board.to_world(np.array([0.3, 0.3, 0.0])), tool_rotation_on_board(down)
    assert 0.1 < arm.elbow_rad(p, R) < 0.4 and arm.shoulder_tilt_max_rad(p, R) < 0.2
    why = motion.reach_problem(board, np.array([0.3, 0.3]))
    assert why is not None and why.startswith("over the shoulder: A2 within 0.1"), why
    solutions = _ik_solutions(model, p, R)  # the IK reaches it (5 of 30 starts here), every time near A2 = 0
    assert solutions and all(abs(q[1]) < 0.2 for q in solutions), [round(float(q[1]), 3) for q in solutions]
    aside = np.array([0.3 + 0.1, 0.3])
    assert arm.shoulder_tilt_max_rad(board.to_world(np.array([*aside, 0.0])), R) > 0.2


def test_a_table_over_the_robot_is_refused_for_the_wrists_limit_and_the_ik_agrees(model):
    """A board facing up 0.7 m over the base, the pad pressing down on it straight above the base: the forearm rises
    to the wrist centre and the pad points down, so A6 must bend at least 2.2 rad (its limit: 2.09) at any swing of
    the elbow. Refused with that reason, and no start of the IK finds a solution; 10 cm aside it is reachable."""
    motion = _motion(model)
    board = BoardPose(np.eye(3), np.array([-0.3, -0.3, 0.7]), np.array([0.6, 0.6]))
    why = motion.reach_problem(board, np.array([0.3, 0.3]))
    assert why is not None and why.startswith("where the wrist would bend past its limit: A6 at least 2.2"), why
    p, R = board.to_world(np.array([0.3, 0.3, 0.0])), tool_rotation_on_board(np.eye(3))
    assert _ik_solutions(model, p, R) == []
    assert motion.reach_problem(board, np.array([0.4, 0.3])) is None
    assert _ik_solutions(model, board.to_world(np.array([0.4, 0.3, 0.0])), R)


def test_no_random_board_loses_a_place_to_the_shoulder_or_wrist_checks(model):
    """On the sampler's reachable boards (the first ten seeds) the elbow's best swing keeps A2 and A6 clear of zero
    and A6 inside its limit everywhere on the board: the checks refuse what no joint solution can wipe, not the
    boards the campaign runs."""
    from sim.board_sampler import sample_board

    motion = _motion(model)
    for seed in range(10):
        board = board_from_params(BoardParams(**{k: tuple(v) if isinstance(v, list) else v
                                                 for k, v in sample_board(seed, model).table.items()}))
        pose = BoardPose(board.R, board.origin_m, np.array(board.size_m, float))
        w, h = board.size_m
        for x in np.linspace(0.05, w - 0.05, 7):
            for y in np.linspace(0.05, h - 0.05, 5):
                why = motion.reach_problem(pose, np.array([x, y]))
                assert why is None or not why.startswith(("over the shoulder", "where the wrist")), (seed, x, y, why)


def test_a_stain_over_the_wrists_limit_is_skipped_with_its_reason_and_the_other_planned(model, learned_skill):
    """Through the executor: on the table over the robot a stain straight above the base is closed as out of reach
    before any MP starts, the reason named; one 20 cm aside is planned."""
    from controller.executor import SkillExecutor
    from controller.params import ExecutorParams
    from lampskit.core.planner_types import Stain

    ex = SkillExecutor(learned_skill, ExecutorParams(survey_s=0.0))
    ex.motion.arm = arm_reach(model)
    board = BoardPose(np.eye(3), np.array([-0.3, -0.3, 0.7]), np.array([0.6, 0.6]))
    over, aside = Stain(0, np.array([0.3, 0.3]), 0.04), Stain(1, np.array([0.5, 0.3]), 0.04)
    ex.set_stains(board, [over, aside])
    assert set(ex.book.out_of_reach) == {0}, ex.book.out_of_reach
    assert "the wrist would bend past its limit" in ex.book.out_of_reach[0], ex.book.out_of_reach[0]
