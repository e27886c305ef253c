"""Cost per cycle of what the real-time loops do besides their work: the robot side's guard on one reading,
the loop hygiene's end of period (collection check, deadline) and the controller's speed override (its jerk limit
on the scale's changes), against an empty call in the same run.

Usage: .venv/bin/python bench/bench_loop_additions.py [--quick] [--json OUT]

Each call is timed on its own with ``perf_counter_ns`` (about 0.1 us of it is the timer), 20,000 times
(5,000 with --quick): ``RobotGuard.observe`` on a 7-joint state (the sim's speed limits, joint speeds only; and
with the described arm: the pad's speeds and press speed by Pinocchio too); the collection
check of ``LoopHygiene.collect_due`` with nothing due; ``LoopHygiene.next_period`` with a 1 ns period (its
deadline is due at once: the cost of ending a period, not its wait); ``SpeedOverride.update`` without the
skill's acceleration (no jerk limit: as before it), with it and a steady scale, and with it while the scale
changes (the joints' demand switched every 0.2 s: the limit's arithmetic runs). Baseline: a Python call that does
nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from arm.robot_model import RobotModel  # noqa: E402
from controller.control.limits import SpeedOverride  # noqa: E402
from robot.guard import RobotGuard  # noqa: E402
from robot.mock import MockArm  # noqa: E402
from robot.server_params import ServerParams  # noqa: E402
from runtime.loop_hygiene import LoopHygiene  # noqa: E402
from runtime.loop_stats import LoopStats  # noqa: E402


def _time(fn, n: int) -> np.ndarray:
    out = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter_ns()
        fn()
        out[i] = (time.perf_counter_ns() - t0) / 1e3
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    n = 5000 if a.quick else 20000
    model = RobotModel()
    arm = MockArm(dq_max_rad_s=model.limits.dq_max)
    limits = ServerParams(mode="realtime").guard_limits(arm)
    joints_only, described = RobotGuard(limits), RobotGuard(limits, model)
    rng = np.random.default_rng(0)
    qs = np.array([0.0, 0.6, 0.0, -1.4, 0.0, 0.8, 0.0]) + rng.uniform(-0.3, 0.3, (64, 7))  # near a wiping pose
    dqs = rng.uniform(-0.5, 0.5, (64, 7))
    wrench = np.zeros(6)
    k = [0]

    def watch(guard: RobotGuard):
        k[0] += 1
        guard.observe(qs[k[0] & 63], dqs[k[0] & 63], wrench, k[0] * 1e-3)

    accel = np.array([3.0, -1.0])
    demands = (np.full(7, 0.2), np.full(7, 1.0))

    def override(with_accel: bool, switching: bool):
        ov = SpeedOverride(np.ones(7), 0.5, jerk_bound_m_s3=100.0)
        j = [0]

        def tick():
            j[0] += 1
            ov.update(demands[(j[0] // 200) & 1] if switching else demands[0], 0.001, accel if with_accel else None)
        return tick

    h = LoopHygiene(counts=Counter())
    h.start()
    stats = LoopStats()
    try:
        rows = {"empty call (baseline)": _time(lambda: None, n),
                "RobotGuard.observe, joint speeds (7 joints)": _time(lambda: watch(joints_only), n),
                "RobotGuard.observe, the described arm (pad speeds too)": _time(lambda: watch(described), n),
                "LoopHygiene.collect_due, nothing due": _time(lambda: h.collect_due(500_000), n),
                "LoopHygiene.next_period, no wait": _time(lambda: h.next_period(stats, 0, 1), n),
                "SpeedOverride.update, scale changing, no jerk limit": _time(override(False, True), n),
                "SpeedOverride.update, jerk limit, scale steady": _time(override(True, False), n),
                "SpeedOverride.update, jerk limit, scale changing": _time(override(True, True), n)}
    finally:
        h.stop()
    print("| per cycle | p50 [us] | p99 [us] | max [us] |")
    print("|---|---:|---:|---:|")
    out = {}
    for name, v in rows.items():
        p50, p99 = np.percentile(v, [50, 99])
        out[name] = {"p50_us": float(p50), "p99_us": float(p99), "max_us": float(v.max())}
        print(f"| {name} | {p50:.2f} | {p99:.2f} | {v.max():.1f} |")
    print(f"\n{n} calls each; gc collections meanwhile: {dict(h.counts)}")
    if a.json:
        a.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
