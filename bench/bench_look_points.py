"""Look points: what choosing one costs, and the worst 1 kHz tick while it is chosen in the tick or off it.

Usage: .venv/bin/python bench/bench_look_points.py [--boards N] [--quick] [--json OUT]

On random boards (``sim/board_sampler.py``, seeds 0..N-1) seen by the sim's
automatic camera, it times the executor's survey point
(:func:`controller.look_points.survey_point`: the arm's silhouette from
~50 pad positions against a 5 cm grid over the board) and a look at 1-3
stains (:func:`controller.look_points.look_point` with their centre and rim
points), against the baseline in the same run: the base-side point, which
ignores the camera (what a look costs without its position). Then a 1 kHz
loop of control-law ticks (the impedance law on the arm: Pinocchio and numpy,
as in the controller) starts a survey: the executor's
:class:`~controller.free_motion.FreeMotion` chooses its point in the tick
(lock-step) or on the real-time controller's planner thread; the worst tick,
from the start of its period to its end, over the choice and 20 more periods.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from arm.reach import arm_reach  # noqa: E402
from arm.robot_model import RobotModel  # noqa: E402
from controller.executor_types import BoardPose, ToolState  # noqa: E402
from controller.free_motion import FreeMotion  # noqa: E402
from controller.look_points import base_side_point, look_point, stain_targets, survey_point  # noqa: E402
from controller.params import ExecutorParams, ForceParams  # noqa: E402
from controller.planner_thread import PlannerThread  # noqa: E402
from interfaces.transforms import tool_rotation_on_board  # noqa: E402
from sim.board_sampler import sample_board  # noqa: E402
from sim.camera import camera_pose  # noqa: E402
from sim.core import SimCore  # noqa: E402
from sim.params import SimParams  # noqa: E402

REPEATS = 5


def seen_board(seed: int) -> BoardPose:
    """Random board ``seed`` as the controller takes it, with the sim's camera position."""
    params = SimParams.from_table({"board": sample_board(seed).table})
    b = SimCore(params).board
    return BoardPose.from_transform(b.T_board_to_world, b.size_m, camera_pose(params.camera, b)[:3, 3])


def _ms(f) -> float:
    t0 = time.perf_counter()
    f()
    return (time.perf_counter() - t0) * 1e3


def choice_costs(boards: list[BoardPose], arm) -> dict[str, list[float]]:
    """Per board, the median of :data:`REPEATS` calls [ms]: survey, look at stains, base-side point (baseline)."""
    p = ExecutorParams()
    out: dict[str, list[float]] = {"survey": [], "look": [], "base_side": []}
    for k, board in enumerate(boards):
        rng = np.random.default_rng(k)
        n = int(rng.integers(1, 4))
        centres = [rng.uniform(0.1, 0.9) * board.size_m for _ in range(n)]
        sizes = [float(rng.uniform(0.04, 0.1)) for _ in range(n)]
        targets = stain_targets(centres, sizes)
        runs = {"survey": lambda: survey_point(board, p.look_clearance_m, arm, p.standoff_m),
                "look": lambda: look_point(board, centres, sizes, p.look_clearance_m, arm, p.standoff_m, 0, targets),
                "base_side": lambda: base_side_point(board, centres, sizes, p.look_clearance_m, arm, p.standoff_m)}
        for name, f in runs.items():
            out[name].append(float(np.median([_ms(f) for _ in range(REPEATS)])))
    return out


def ticks_during_survey(board: BoardPose, arm, threaded: bool, ticks_after: int = 20, survey: bool = True) -> dict:
    """A 1 kHz loop of control-law ticks; in the first, the executor's motion starts a survey (its point chosen in
    the tick, or ``threaded`` on a :class:`PlannerThread`) and every tick moves it on (``survey`` False: the loop
    alone, the baseline). Returns the worst tick [ms] (from its period's start to its end: what the robot waits
    for) and the periods until the flight began."""
    from controller.control.impedance import Reference, impedance_torque
    from controller.control.params import ImpedanceParams

    model, imp = RobotModel(), ImpedanceParams()
    q = np.array([0.2, 0.5, -0.3, -1.3, 0.4, 0.8, -0.2])
    dq, q_rest = np.zeros(7), q.copy()
    ref = Reference(model.tcp_pose(q)[0] + 0.01, model.tcp_pose(q)[1])
    motion = FreeMotion(ExecutorParams(), ForceParams())
    motion.arm = arm
    motion.hold_here(ToolState(0.5 * board.size_m, 0.06, np.zeros(2), 0.0, tool_rotation_on_board(board.R), 0.0))
    for _ in range(50):
        impedance_torque(model, q, dq, ref, imp, q_rest, False)
    pool = PlannerThread()
    motion.aim.executor = pool if threaded else None
    worst, periods, waited = 0.0, 0, 0
    try:
        deadline = time.perf_counter()
        left = ticks_after
        while left > 0:
            deadline += 1e-3
            time.sleep(max(deadline - time.perf_counter(), 0.0))
            if not survey:
                pass
            elif periods == 0:
                motion.fly_to_survey(board)
            else:
                motion.move(1e-3)
            impedance_torque(model, q, dq, ref, imp, q_rest, False)
            worst = max(worst, time.perf_counter() - deadline)
            periods += 1
            if motion.aim.busy:
                waited += 1
            else:
                left -= 1
    finally:
        pool.shutdown()
    return {"worst_tick_ms": worst * 1e3, "periods": waited}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--boards", type=int, default=20, help="random boards 0..N-1 (default 20)")
    ap.add_argument("--quick", action="store_true", help="3 boards (a smoke test)")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    if a.boards < 1:
        ap.error(f"--boards must be at least 1, not {a.boards}")
    n_boards = 3 if a.quick else a.boards
    arm = arm_reach(RobotModel())
    boards = [seen_board(s) for s in range(n_boards)]
    costs = choice_costs(boards, arm)
    base = np.median(costs["base_side"])
    print(f"| choosing a look point ({n_boards} random boards, median of {REPEATS} calls each) | p50 / max [ms] | "
          "/ baseline p50 |\n|---|---:|---:|")
    for name, label in (("survey", "survey: the board's 5 cm grid in view"),
                        ("look", "look at 1-3 stains: their centre and rim in view"),
                        ("base_side", "baseline: the base-side point, camera ignored")):
        t = costs[name]
        print(f"| {label} | {np.median(t):.2f} / {max(t):.2f} | {np.median(t) / base:.1f}x |")
    rounds = [(ticks_during_survey(b, arm, False), ticks_during_survey(b, arm, True),
               ticks_during_survey(b, arm, True, survey=False)) for b in boards[:5]]
    inline = [r[0]["worst_tick_ms"] for r in rounds]
    thread = [r[1]["worst_tick_ms"] for r in rounds]
    alone = [r[2]["worst_tick_ms"] for r in rounds]
    periods = [r[1]["periods"] for r in rounds]
    print(f"\n| a survey starting in a 1 kHz loop of control-law ticks ({len(rounds)} boards) | worst tick: median / "
          "max [ms] |\n|---|---:|")
    print(f"| point chosen in the tick (lock-step) | {np.median(inline):.2f} / {max(inline):.2f} |")
    print(f"| point chosen on the planner thread (real time; the flight starts {int(np.median(periods))} periods "
          f"later, median) | {np.median(thread):.2f} / {max(thread):.2f} |")
    print(f"| baseline: the same loop, no survey | {np.median(alone):.2f} / {max(alone):.2f} |")
    print("\nworst tick: from the start of its 1 ms period to the end of its control law (budget 1 ms)")
    if a.json:
        a.json.write_text(json.dumps({"choice_ms": costs, "inline_ms": inline, "thread_ms": thread, "alone_ms": alone,
                                      "thread_periods": periods}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
