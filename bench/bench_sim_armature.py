"""What the simulated drives (rotor inertia and joint friction) cost per physics step.

Usage: .venv/bin/python bench/bench_sim_armature.py [--quick] [--json OUT]

``SimCore.step`` alone (no network), the arm approaching the board, then
pressing the pad on it with 10 N while sliding (the scripted client of the
sim tests, its torques computed outside the timed region), for four sets
of joint figures (:mod:`arm.joint_dynamics`):

* rigid: no armature, no friction; the motor torques go to PyBullet as they are.
* friction only: the drive path (mass matrix, inverse dynamics, contact
  Jacobian, a 7 x 7 solve) with the cited friction and no armature.
* cited: the defaults (friction and the A7 armature).
* FR3-size armature: the cited friction with Franka FR3's reflected inertias.

Each row gives the mean step time and, within it, the time of
``SimRobot.write`` (where the drive path runs), each with its increase
over the rigid arm (best of the repeats: the other figures of a loaded
machine only add noise), the normal force at the end and the time the pad
first touched the board (the scripted client damps its approach and does
not compensate friction, so friction and armature delay it).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from arm.joint_dynamics import FR3_REFLECTED_INERTIA_KG_M2, JointDynamics  # noqa: E402
from arm.robot_model import RobotModel  # noqa: E402
from sim.core import SimCore  # noqa: E402
from sim.params import SimParams  # noqa: E402

ZERO = (0.0,) * 7
CASES = {
    "rigid": JointDynamics(armature_kg_m2=ZERO, viscous_nm_s_rad=ZERO, coulomb_nm=ZERO),
    "friction only": JointDynamics(armature_kg_m2=ZERO),
    "cited (friction + A7 armature)": JointDynamics(),
    "FR3-size armature + friction": JointDynamics(armature_kg_m2=FR3_REFLECTED_INERTIA_KG_M2),
}


def bench_case(joints: JointDynamics, steps: int, repeats: int) -> dict:
    from types import SimpleNamespace

    from tests.test_sim_service import PressAndSlide

    best_step, best_write = np.inf, np.inf
    for _ in range(repeats):
        core = SimCore(SimParams.from_table({"camera": {"enabled": False}}), RobotModel(joints=joints))
        policy = PressAndSlide(RobotModel(joints=joints), core.board, core.board.size_m / 2)
        write, t_write = core.robot.write, [0.0]

        def timed_write(tau, write=write, t_write=t_write):
            t0 = time.perf_counter()
            write(tau)
            t_write[0] += time.perf_counter() - t0

        core.robot.write = timed_write  # the drive path's share of each step
        touched_s = None
        t_total = 0.0
        for k in range(steps):
            o = core.out
            tau = np.clip(policy(SimpleNamespace(q_rad=o.q.copy(), dq_rad_s=o.dq.copy(), robot_time_ns=core.time_ns)),
                          -core.tau_max, core.tau_max)
            t0 = time.perf_counter()
            core.step(tau)
            t_total += time.perf_counter() - t0
            if touched_s is None and core.out.normal_force_n > 1.0:
                touched_s = (k + 1) * core.params.dt_s
        best_step, best_write = min(best_step, t_total / steps), min(best_write, t_write[0] / steps)
        force_n = core.out.normal_force_n
        core.close()
    return {"us_per_step": best_step * 1e6, "us_write": best_write * 1e6, "contact_force_n": force_n,
            "touched_s": touched_s}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3000 steps once instead of 6000 steps, best of 3")
    ap.add_argument("--json", metavar="OUT", help="also write the figures as JSON")
    a = ap.parse_args()
    steps, repeats = (3000, 1) if a.quick else (6000, 3)
    res = {"machine": f"{platform.machine()}, {platform.python_version()}", "steps": steps, "cases": {}}
    for name, joints in CASES.items():
        res["cases"][name] = bench_case(joints, steps, repeats)
    base = res["cases"]["rigid"]
    print(f"Simulated drives: SimCore.step, pressing 10 N and sliding, {steps} steps "
          f"(best of {repeats}; {res['machine']})\n")
    print("| joints | us/step | + us over rigid | of it SimRobot.write us (+ over rigid) | normal force at the end [N] "
          "| pad touched at [s] |\n|---|---|---|---|---|---|")
    for name, r in res["cases"].items():
        touched = "-" if r["touched_s"] is None else f"{r['touched_s']:.2f}"
        print(f"| {name} | {r['us_per_step']:.1f} | {r['us_per_step'] - base['us_per_step']:+.1f} | "
              f"{r['us_write']:.1f} ({r['us_write'] - base['us_write']:+.1f}) | {r['contact_force_n']:.1f} | "
              f"{touched} |")
    if a.json:
        from lampskit.atomic import write_text_atomic

        write_text_atomic(Path(a.json), json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
