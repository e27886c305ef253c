"""Look points chosen off the 1 kHz tick (controller/off_tick.py, controller/free_motion.py): with the planner
thread the tick hands the 2-3 ms choice over and holds the setpoint until the answer is back, then flies where the
tick would have flown; a motion started meanwhile forgets it; without a thread it is the same as in the tick."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from arm.reach import arm_reach
from arm.robot_model import RobotModel
from controller.executor_types import BoardPose, ToolState
from controller.free_motion import FreeMotion
from controller.look_points import look_point, stain_targets, survey_point
from controller.off_tick import OffTick
from controller.params import ExecutorParams, ForceParams
from interfaces.messages import Pose
from interfaces.transforms import tool_rotation_on_board, transform_from_pose
from lampskit.core.planner_types import Stain
from sim.board_sampler import sample_board

DT_S = 1e-3
#: Where the sim's automatic camera stands for random board 248 (tests/test_silhouette.py: the case the camera-aware
#: look points are for), world [m].
CAMERA_M = np.array([0.55, 0.60, 1.35])


class Gated(ThreadPoolExecutor):
    """A one-thread executor whose jobs wait for :attr:`go` (a planner thread slower than any tick)."""

    def __init__(self) -> None:
        super().__init__(max_workers=1)
        self.go = threading.Event()
        self.threads: list[str] = []

    def submit(self, fn, /, *args, **kwargs):
        def gated():
            self.go.wait(10.0)
            self.threads.append(threading.current_thread().name)
            return fn(*args, **kwargs)

        return super().submit(gated)


@pytest.fixture(scope="module")
def board() -> BoardPose:
    t = sample_board(248).table
    return BoardPose.from_transform(transform_from_pose(Pose(t["origin_m"], t["quat_wxyz"])), t["size_m"], CAMERA_M)


def _motion(board: BoardPose, xy=(0.3, 0.2), h: float = 0.06) -> FreeMotion:
    m = FreeMotion(ExecutorParams(), ForceParams())
    m.arm = arm_reach(RobotModel())
    R = tool_rotation_on_board(board.R)
    m.hold_here(ToolState(np.array(xy, float), h, np.zeros(2), 0.0, R, 0.0))
    return m


def _fly(m: FreeMotion, limit_s: float = 20.0) -> int:
    """Ticks until the motion arrives; while a job is off the tick, each tick waits for the next period as the
    real-time loop does (a loop spinning without a pause would keep the job's thread off the interpreter)."""
    for k in range(int(limit_s / DT_S)):
        if m.move(DT_S):
            return k
        if m.aim.busy:
            time.sleep(DT_S)
    raise AssertionError("never arrived")


def test_the_survey_point_is_chosen_off_the_tick_and_flown_to_as_in_the_tick(board):
    inline, threaded = _motion(board), _motion(board)
    inline.fly_to_survey(board)
    _fly(inline)
    pool = threaded.aim.executor = Gated()
    try:
        start = threaded.setpoint.xyh().copy()
        threaded.fly_to_survey(board)
        assert threaded.aim.busy
        for _ in range(50):  # the answer is not back: the setpoint holds where it was, at rest
            assert not threaded.move(DT_S)
        assert np.array_equal(threaded.setpoint.xyh(), start) and not threaded.setpoint.v_xy.any()
        pool.go.set()
        _fly(threaded)
    finally:
        pool.shutdown()
    assert pool.threads and pool.threads[0] != threading.current_thread().name
    np.testing.assert_allclose(threaded.setpoint.xyh(), inline.setpoint.xyh(), atol=1e-12)
    want = survey_point(board, ExecutorParams().look_clearance_m, inline.arm, ExecutorParams().standoff_m)
    np.testing.assert_allclose(inline.setpoint.xy, want, atol=1e-12)


def test_a_motion_started_while_the_point_is_chosen_forgets_it(board):
    m = _motion(board, h=0.005)
    pool = m.aim.executor = Gated()
    try:
        m.fly_to_survey(board)
        tool = ToolState(m.setpoint.xy.copy(), m.setpoint.h, np.zeros(2), 0.0, m.setpoint.R.copy(), 0.0)
        m.hold_here(tool)  # a fault while waiting: hold, then lift
        assert not m.aim.busy
        m.lift(tool)
        pool.go.set()
        pool.shutdown(wait=True)
        _fly(m)
    finally:
        pool.shutdown()
    np.testing.assert_allclose(m.setpoint.xy, tool.xy)  # lifted straight up, never flown to the survey point
    assert m.setpoint.h > tool.h


def test_a_look_from_where_the_pad_already_is_stays_there(board):
    stain = Stain(1, np.array([0.345, 0.155]), 0.06)
    arm = arm_reach(RobotModel())
    h = 0.06
    goal = look_point(board, [stain.centre_m], [stain.size_m], ExecutorParams().look_clearance_m, arm, h, 0,
                      stain_targets([stain.centre_m], [stain.size_m]))
    inline = _motion(board, goal, h)
    assert not inline.fly_to_look(board, [stain])  # known at once: no move
    threaded = _motion(board, goal, h)
    pool = threaded.aim.executor = Gated()
    try:
        assert threaded.fly_to_look(board, [stain])  # not known yet
        assert not threaded.move(DT_S)
        pool.go.set()
        assert _fly(threaded) < 1000 and threaded.stayed
    finally:
        pool.shutdown()
    far = _motion(board, (0.5, 0.4), h)
    assert far.fly_to_look(board, [stain]) and not far.stayed
    _fly(far)
    np.testing.assert_allclose(far.setpoint.xy, goal, atol=1e-12)


def test_a_job_that_fails_off_the_tick_fails_in_the_tick_that_takes_its_answer():
    aim = OffTick()
    with ThreadPoolExecutor(1) as pool:
        aim.executor = pool
        answers: list = []

        def broken():
            raise ValueError("no look point (test)")

        aim.start(broken, answers.append)
        with pytest.raises(ValueError, match="no look point"):
            while not aim.poll():
                pass
        assert not aim.busy and answers == []
        aim.start(lambda: 7, answers.append)
        while not aim.poll():
            pass
    assert answers == [7]
    aim.executor = None
    aim.start(lambda: 8, answers.append)  # in the tick: at once
    assert answers == [7, 8] and not aim.busy and aim.poll()


def test_the_look_point_benchmark_prints_its_tables():
    """bench/bench_look_points.py --quick runs (a smoke test; its figures are the README's, not checked here)."""
    import subprocess
    import sys

    from .conftest import REPO

    r = subprocess.run([sys.executable, "bench/bench_look_points.py", "--quick"], cwd=REPO, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "| survey: the board's 5 cm grid in view |" in r.stdout and "point chosen on the planner thread" in r.stdout
    bad = subprocess.run([sys.executable, "bench/bench_look_points.py", "--boards", "0"], cwd=REPO,
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--boards must be at least 1" in bad.stderr
