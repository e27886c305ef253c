"""Cost of the transitional MP at 1 kHz, against ruckig joining the same states.

Measures, for n = 2 (board plane):

* ``TransitionalRunner.update`` per 1 kHz cycle (mean, p50, p99) over many
  realistic transitions (circles r 2-6 cm at 1-2.5 Hz, 0.05-0.6 m apart, T 0.5-3 s),
* building one transition (``TransitionalRunner(...)``, what happens when kappa flips),
* learning one MP from a demonstrated segment (offline, once per skill),
* ruckig between the same full states in the same time: ``Ruckig.calculate``
  (offline, into a ``Trajectory``) and ``Trajectory.at_time`` per sample,

and prints a markdown table with the ratios (ruckig / ours).

    .venv/bin/python bench/bench_transitional_step.py [--quick] [--json OUT]
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

from lampskit.core.transitional import TransitionStatus
from lampskit.core.transitional_plan import similarity_transform
from lampskit.core.transitional_runner import TransitionalRunner  # noqa: E402
from lampskit.learn.baselines import limits_from_states  # noqa: E402
from lampskit.learn.transitional_fit import learn_transitional  # noqa: E402

DT_S = 0.001


def circle_state(centre, radius_m, freq_hz, phase_rad, direction):
    w = 2 * np.pi * freq_hz * direction
    c, s = np.cos(phase_rad), np.sin(phase_rad)
    return np.array([centre + radius_m * np.array([c, s]), radius_m * w * np.array([-s, c]),
                     -w * w * radius_m * np.array([c, s])])


def demo_segment(rng):
    """A human-like move between two wiping circles (see tests/test_transitional.human_demo)."""
    T, r = 1.5, 0.04
    t = np.arange(0.0, T + 1e-9, 0.01)
    smooth = lambda u: 10 * u**3 - 15 * u**4 + 6 * u**5  # noqa: E731
    centre = np.array([0.3, 0.1]) * smooth(t / T)[:, None]
    a0, a1 = 1 - smooth(np.clip(t / 0.3, 0, 1)), smooth(np.clip(1 - (T - t) / 0.3, 0, 1))
    ring0 = r * np.stack([np.cos(1.0 + 9.4 * t), np.sin(1.0 + 9.4 * t)], 1)
    ring1 = r * np.stack([np.cos(2.0 - 11.3 * (t - T)), np.sin(2.0 - 11.3 * (t - T))], 1)
    return t, centre + a0[:, None] * ring0 + a1[:, None] * ring1 + 0.0002 * rng.standard_normal((len(t), 2))


def cases(rng, n):
    out = []
    for _ in range(n):
        c0 = rng.uniform(-0.3, 0.3, 2)
        d = rng.standard_normal(2)
        c1 = c0 + rng.uniform(0.05, 0.6) * d / np.linalg.norm(d)
        st = circle_state(c0, rng.uniform(0.02, 0.06), rng.uniform(1, 2.5), rng.uniform(0, 6.3), rng.choice([-1, 1]))
        gl = circle_state(c1, rng.uniform(0.02, 0.06), rng.uniform(1, 2.5), rng.uniform(0, 6.3), rng.choice([-1, 1]))
        out.append((st, gl, float(rng.uniform(0.5, 3.0))))
    return out


def stats_us(samples_ns) -> dict:
    a = np.asarray(samples_ns, dtype=float) / 1e3
    p50, p99 = np.percentile(a, [50, 99])
    return {"mean": float(a.mean()), "p50": float(p50), "p99": float(p99), "n": len(a)}


def time_ours(mp, todo, clock) -> tuple[list[int], list[int]]:
    """Nanoseconds per TransitionalRunner build (20 per case) and per 1 kHz update over every case."""
    build_ns, update_ns = [], []
    for st, gl, T in todo:
        M = similarity_transform(mp.demo_displacement_m, gl[0] - st[0])
        for _ in range(20):
            t0 = clock()
            runner = TransitionalRunner(mp, st, gl, T, forcing_transform=M)
            build_ns.append(clock() - t0)
        status = TransitionStatus.WORKING
        while status == TransitionStatus.WORKING:
            t0 = clock()
            status = runner.update(DT_S)
            update_ns.append(clock() - t0)
        if status != TransitionStatus.FINISHED:
            raise SystemExit(f"bench: a transition failed with {status.name}")
    return build_ns, update_ns


def time_ruckig(todo, clock) -> tuple[list[int], list[int]]:
    """Nanoseconds per ruckig calculate (20 per case, same boundary states and duration) and per at_time sample."""
    from ruckig import InputParameter, Ruckig, Trajectory

    calc_ns, at_ns = [], []
    otg, traj = Ruckig(2), Trajectory(2)
    for st, gl, T in todo:
        lim = limits_from_states(st, gl, T)
        inp = InputParameter(2)
        inp.current_position, inp.current_velocity, inp.current_acceleration = (r.tolist() for r in st)
        inp.target_position, inp.target_velocity, inp.target_acceleration = (r.tolist() for r in gl)
        inp.max_velocity, inp.max_acceleration = lim.max_velocity_m_s.tolist(), lim.max_acceleration_m_s2.tolist()
        inp.max_jerk, inp.minimum_duration = lim.max_jerk_m_s3.tolist(), T
        for _ in range(20):
            t0 = clock()
            otg.calculate(inp, traj)
            calc_ns.append(clock() - t0)
        for k in range(int(traj.duration / DT_S)):
            t0 = clock()
            traj.at_time(k * DT_S)
            at_ns.append(clock() - t0)
    return calc_ns, at_ns


def print_table(fig: dict, n_cases: int) -> None:
    print(f"# Transitional MP step cost (n = 2, dt = {DT_S * 1e3:g} ms, {n_cases} transitions)\n")
    print("| what | mean [us] | p50 [us] | p99 [us] | samples |")
    print("|---|---:|---:|---:|---:|")
    for key, label in (("update_us", "TransitionalRunner.update (per 1 kHz cycle)"),
                       ("build_us", "TransitionalRunner(...) build"),
                       ("ruckig_at_time_us", "ruckig Trajectory.at_time (per sample)"),
                       ("ruckig_calculate_us", "ruckig Ruckig.calculate (per transition)"),
                       ("learn_us", "learn_transitional (offline, per segment)")):
        s = fig[key]
        print(f"| {label} | {s['mean']:.1f} | {s['p50']:.1f} | {s['p99']:.1f} | {s['n']} |")
    print(f"\nruckig at_time / our update (p50): {fig['ratio_at_time_over_update_p50']:.2f}; "
          f"ruckig calculate / our build (p50): {fig['ratio_calculate_over_build_p50']:.2f}")
    print("Budget: update well under 50 us, build under 1 ms (one 1 kHz tick).")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer transitions (CI smoke run)")
    ap.add_argument("--json", type=Path, help="also write the figures here")
    args = ap.parse_args()
    n_cases = 5 if args.quick else 40
    rng = np.random.default_rng(0)
    clock = time.perf_counter_ns

    t_demo, y_demo = demo_segment(rng)
    learn_ns = []
    for _ in range(2 if args.quick else 5):
        t0 = clock()
        mp = learn_transitional(t_demo, y_demo)
        learn_ns.append(clock() - t0)
    todo = cases(rng, n_cases)
    build_ns, update_ns = time_ours(mp, todo, clock)
    calc_ns, at_ns = time_ruckig(todo, clock)
    fig = {
        "update_us": stats_us(update_ns),
        "build_us": stats_us(build_ns),
        "learn_us": stats_us(learn_ns),
        "ruckig_calculate_us": stats_us(calc_ns),
        "ruckig_at_time_us": stats_us(at_ns),
        "python": platform.python_version(),
        "machine": platform.machine(),
        "n_transitions": n_cases,
    }
    fig["ratio_at_time_over_update_p50"] = fig["ruckig_at_time_us"]["p50"] / fig["update_us"]["p50"]
    fig["ratio_calculate_over_build_p50"] = fig["ruckig_calculate_us"]["p50"] / fig["build_us"]["p50"]
    print_table(fig, n_cases)
    if args.json:
        args.json.write_text(json.dumps(fig, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
