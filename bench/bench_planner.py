"""Planning time: ordering the stains and planning the wipes for 5, 7, 10, 30 and 100 stains.

Usage: .venv/bin/python bench/bench_planner.py [--quick] [--json OUT]

``plan()`` runs inside a controller tick when kappa flips (the executor
re-plans over the stains still open), so its time is time taken from one
1 kHz period. Per board size (stains uniform on a 1 m x 1 m board, start at
a corner, 5 boards each) it prints the median and worst time of
``order_stains`` and of the whole ``plan()``, against the baseline in the
same run: the previous search, pure Python over ``itertools.permutations``
(exhaustive up to 7 stains) and a first-improvement 2-opt recomputing whole
path lengths, with the path length each finds.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller.planner_thread import SWITCH_INTERVAL_S, PlannerThread  # noqa: E402
from lampskit.core.planner import adapted_wipe, plan, plan_transition  # noqa: E402
from lampskit.core.planner_types import Plan, PlannerParams, Stain  # noqa: E402
from lampskit.core.stain_order import EXACT_ORDER_MAX, order_stains  # noqa: E402
from lampskit.learn.learn import bundled_skill  # noqa: E402

SIZES = (5, 7, 10, 30, 100)


def baseline_order(stains, start_m):
    """The search ``order_stains`` used before: Python loops over whole path lengths."""
    pts = np.array([s.centre_m for s in stains])
    n = len(pts)

    def length(order):
        path = np.vstack([start_m, pts[list(order)]])
        return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())

    if n <= EXACT_ORDER_MAX:
        return [stains[i] for i in min(itertools.permutations(range(n)), key=length)]
    left, order, here = set(range(n)), [], start_m
    while left:
        nxt = min(left, key=lambda i: (np.linalg.norm(pts[i] - here), i))
        order.append(nxt)
        left.remove(nxt)
        here = pts[nxt]
    improved = True
    while improved:
        improved = False
        for i in range(n - 1):
            for j in range(i + 1, n):
                cand = order[:i] + order[i: j + 1][::-1] + order[j + 1:]
                if length(cand) < length(order) - 1e-12:
                    order, improved = cand, True
    return [stains[i] for i in order]


def _length(order, start) -> float:
    p = np.vstack([start] + [s.centre_m for s in order])
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def _timed(f) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = f()
    return (time.perf_counter() - t0) * 1e3, out


def ticks_during_replan(skill, stains, start, threaded: bool, ticks_after: int = 20) -> dict:
    """A 1 kHz loop of control-law ticks (the impedance law on the arm: Pinocchio and numpy, as in the
    controller) while ``plan()`` runs: in the tick (the tick that re-plans takes the whole plan), or
    ``threaded`` on the real-time controller's :class:`~controller.planner_thread.PlannerThread`.
    Returns the worst tick [ms] (from its deadline to its end: what the robot waits for) over the plan and
    ``ticks_after`` more periods, and the periods the plan took."""
    from arm.robot_model import RobotModel
    from controller.control.impedance import Reference, impedance_torque
    from controller.control.params import ImpedanceParams

    model, imp = RobotModel(), ImpedanceParams()
    q = np.array([0.2, 0.5, -0.3, -1.3, 0.4, 0.8, -0.2])
    dq, q_rest = np.zeros(7), q.copy()
    ref = Reference(model.tcp_pose(q)[0] + 0.01, model.tcp_pose(q)[1])

    def tick() -> None:
        impedance_torque(model, q, dq, ref, imp, q_rest, False)

    for _ in range(50):
        tick()
    pool = PlannerThread()
    worst, periods = 0.0, 0
    try:
        deadline = time.perf_counter()
        future = None
        left = ticks_after
        while left > 0:
            deadline += 1e-3
            time.sleep(max(deadline - time.perf_counter(), 0.0))
            if periods == 0:
                if not threaded:
                    plan(skill, stains, start)  # the re-plan inside the tick
                else:
                    future = pool.submit(plan, skill, stains, start)
            tick()
            worst = max(worst, time.perf_counter() - deadline)  # from the period's start to the tick's end
            periods += 1
            if future is None or future.done():
                left -= 1
    finally:
        pool.shutdown()
    return {"worst_tick_ms": worst * 1e3, "periods": periods - ticks_after}


def transition_costs(skill, boards: int) -> dict[str, list[float]]:
    """Wall time [ms] of planning each transition of random plans: bounded search, given duration, no bounds."""
    loose = PlannerParams(max_speed_m_s=2.0, max_accel_m_s2=50.0, max_jerk_m_s3=5000.0)
    rest = (np.zeros(2),) * 3
    out: dict[str, list[float]] = {"search": [], "given": [], "unbounded": [], "adapt": []}
    for b in range(boards):
        rng = np.random.default_rng(7000 + b)
        stains = [Stain(i, rng.uniform([0.05, 0.05], [0.65, 0.4]), float(rng.uniform(0.03, 0.22)))
                  for i in range(int(rng.integers(1, 7)))]
        p = plan(skill, stains, np.zeros(2))
        for w in p.wipes:  # adaptive wiping's re-target at an elongated ink left of the stain
            ink = Stain(w.stain.id, w.stain.centre_m + 0.01, 0.5 * w.stain.size_m, 0.2 * w.stain.size_m,
                        float(rng.uniform(-1.5, 1.5)))
            out["adapt"].append(_timed(lambda: adapted_wipe(skill, w, w, ink, p.params))[0])
        for w in p.wipes:
            dt, spec = _timed(lambda: plan_transition(skill, p, w, rest))
            out["search"].append(dt)
            out["given"].append(_timed(lambda: plan_transition(skill, p, w, rest, spec.duration_s))[0])
            out["unbounded"].append(_timed(lambda: plan_transition(skill, Plan(p.wipes, loose), w, rest))[0])
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 boards per size, no baseline at 100 stains")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    skill = bundled_skill()
    boards = 2 if a.quick else 5
    start = np.zeros(2)
    rows = []
    order_stains([Stain(i, np.array([0.1 * i, 0.0]), 0.05) for i in range(7)], start)  # warm the caches
    for n in SIZES:
        t_order, t_plan, t_base, gain = [], [], [], []
        for b in range(boards):
            rng = np.random.default_rng(1000 * n + b)
            stains = [Stain(i, rng.uniform(0.0, 1.0, 2), 0.05) for i in range(n)]
            dt, order = _timed(lambda: order_stains(stains, start))
            t_order.append(dt)
            t_plan.append(_timed(lambda: plan(skill, stains, start))[0])
            if not (a.quick and n >= 100):
                dt_b, base = _timed(lambda: baseline_order(stains, start))
                t_base.append(dt_b)
                gain.append(_length(base, start) - _length(order, start))
        rows.append({"stains": n, "order_ms_p50": float(np.median(t_order)), "order_ms_max": float(np.max(t_order)),
                     "plan_ms_p50": float(np.median(t_plan)), "plan_ms_max": float(np.max(t_plan)),
                     "baseline_ms_p50": float(np.median(t_base)) if t_base else None,
                     "shorter_than_baseline_m": float(np.mean(gain)) if gain else None})
    print("| stains | order_stains p50 / max [ms] | plan() p50 / max [ms] | baseline (previous search) p50 [ms] | "
          "baseline / ours | path vs baseline [mm] |")
    print("|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        base = "skipped (--quick)" if r["baseline_ms_p50"] is None else f"{r['baseline_ms_p50']:.1f}"
        ratio = "-" if r["baseline_ms_p50"] is None else f"{r['baseline_ms_p50'] / r['order_ms_p50']:.0f}x"
        gain = "-" if r["shorter_than_baseline_m"] is None else f"{-r['shorter_than_baseline_m'] * 1000:+.1f}"
        print(f"| {r['stains']} | {r['order_ms_p50']:.2f} / {r['order_ms_max']:.2f} | {r['plan_ms_p50']:.2f} / "
              f"{r['plan_ms_max']:.2f} | {base} | {ratio} | {gain} |")
    print(f"\n{boards} boards per size; up to {EXACT_ORDER_MAX} stains both search every order (same length).")

    replan = []
    for n in (7, 30, 100):
        rng = np.random.default_rng(1000 * n)
        stains = [Stain(i, rng.uniform(0.0, 1.0, 2), 0.05) for i in range(n)]
        rounds = [(ticks_during_replan(skill, stains, start, False),
                   ticks_during_replan(skill, stains, start, True)) for _ in range(boards)]
        inline = [r[0]["worst_tick_ms"] for r in rounds]
        thread = [r[1]["worst_tick_ms"] for r in rounds]
        replan.append({"stains": n, "inline_ms": inline, "thread_ms": thread,
                       "thread_periods": [r[1]["periods"] for r in rounds]})
    print(f"\n| re-plan during a 1 kHz loop of control-law ticks ({boards} rounds) | worst tick, plan in the tick: "
          f"median / max [ms] | plan on the planner thread (GIL switch {SWITCH_INTERVAL_S * 1e3:.1f} ms): median "
          f"/ max [ms] | periods the plan took there |\n|---:|---:|---:|---:|")
    for r in replan:
        print(f"| {r['stains']} stains | {np.median(r['inline_ms']):.2f} / {max(r['inline_ms']):.2f} | "
              f"{np.median(r['thread_ms']):.2f} / {max(r['thread_ms']):.2f} | {int(np.median(r['thread_periods']))} |")
    print("\nworst tick: from the start of its 1 ms period to the end of its control law (budget 1 ms)")

    transitions = transition_costs(skill, 8 if a.quick else 40)
    print("\n| planning one transition into a stain (random boards of 1-6 stains of 3-22 cm, from rest) | p50 / max "
          "[ms] |\n|---|---:|")
    for name, label in (("search", "with the search for a duration within the kinematic bounds (lock-step: in the "
                                   "tick; real time: on the planner thread)"),
                        ("given", "with the duration given (real time: the exit tick)"),
                        ("unbounded", "baseline: the duration as demonstrated, no bounds (the previous planner)"),
                        ("adapt", "adaptive wiping: re-targeting a wipe at the ink left (in the tick that takes a "
                                  "perception message, at most every 0.5 s)")):
        t = transitions[name]
        print(f"| {label} | {np.median(t):.2f} / {max(t):.2f} |")
    if a.json:
        a.json.write_text(json.dumps({"rows": rows, "boards": boards, "replan": replan,
                                      "transitions_ms": transitions}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
