"""Cost of one PeriodicRunner.update() at 1 kHz, and of the closed form.

Usage: .venv/bin/python bench/bench_periodic_step.py [--quick] [--json OUT]

Measures, for a periodic DMP learned from a synthetic wiping segment in 2-D
and in 3-D (N = 50 basis functions):

- ``PeriodicRunner.update(1e-3)``: exponential integrator, preallocated
  buffers (steady parameters, and while ``set_targets`` ramps y_m, r, Omega);
- baseline ``naive RK4``: textbook fourth-order Runge-Kutta on eqs. (1)-(3)
  with fresh arrays at every stage and eq. (4) through the public
  ``forcing()`` (four basis evaluations per step);
- ``periodic_state`` (closed form, one scalar phase).

Each call is timed on its own with ``perf_counter_ns`` (adds ~0.1 us). The
table gives mean, p50, p99 in microseconds, the ratio of the baseline's mean
to the runner's, and each integrator's position error against the closed
form after the run (so the speed-up is not bought with accuracy).
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

from lampskit.core.periodic import forcing, periodic_state  # noqa: E402
from lampskit.core.periodic_runner import PeriodicRunner  # noqa: E402
from lampskit.learn.periodic_fit import learn_periodic  # noqa: E402

DT_S = 1e-3


class NaiveRK4Runner:
    """Baseline: RK4 on eqs. (1)-(3), allocating at every stage."""

    def __init__(self, mp, phase_rad: float) -> None:
        self.mp = mp
        pos, vel, _ = periodic_state(mp, phase_rad)
        self.y1, self.y2, self.phase = pos.copy(), vel / mp.omega_rad_s, phase_rad

    def _rhs(self, y1, y2, phase):
        mp = self.mp
        f = forcing(phase, mp.centres_rad, mp.widths, mp.weights, mp.amplitude_m)
        om = mp.omega_rad_s
        return om * y2, om * (mp.alpha * (mp.beta * (mp.anchor_m - y1) - y2) + f)

    def update(self, dt: float) -> None:
        om, y1, y2, p = self.mp.omega_rad_s, self.y1, self.y2, self.phase
        a1, b1 = self._rhs(y1, y2, p)
        a2, b2 = self._rhs(y1 + 0.5 * dt * a1, y2 + 0.5 * dt * b1, p + 0.5 * dt * om)
        a3, b3 = self._rhs(y1 + 0.5 * dt * a2, y2 + 0.5 * dt * b2, p + 0.5 * dt * om)
        a4, b4 = self._rhs(y1 + dt * a3, y2 + dt * b3, p + dt * om)
        self.y1 = y1 + dt / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4)
        self.y2 = y2 + dt / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
        self.phase = p + dt * om


def synthetic_mp(n_dims: int):
    t = np.arange(0.0, 5.0, 0.01)
    th = 2 * np.pi * 1.2 * t
    cols = [0.05 * np.cos(th), 0.04 * (np.sin(th) + 0.2 * np.sin(2 * th)), 0.01 * np.sin(2 * th + 0.5)][:n_dims]
    y = np.column_stack(cols) + np.random.default_rng(0).normal(0, 5e-4, (len(t), n_dims))
    return learn_periodic(t, y, n_basis=50)


def time_calls(fn, n_calls: int) -> np.ndarray:
    """Per-call durations [us], shape (n_calls,)."""
    out = np.empty(n_calls)
    clock = time.perf_counter_ns
    for i in range(n_calls):
        t0 = clock()
        fn()
        out[i] = clock() - t0
    return out * 1e-3


def stats(samples_us: np.ndarray) -> dict:
    return {
        "mean_us": float(samples_us.mean()),
        "p50_us": float(np.percentile(samples_us, 50)),
        "p99_us": float(np.percentile(samples_us, 99)),
    }


def run(quick: bool) -> list[dict]:
    n_calls = 3000 if quick else 30000
    rows = []
    for n_dims in (2, 3):
        mp = synthetic_mp(n_dims)
        phase0 = 0.3
        duration_s = n_calls * DT_S

        runner = PeriodicRunner(mp, start_phase_rad=phase0)
        for _ in range(200):  # warm-up
            runner.update(DT_S)
        runner = PeriodicRunner(mp, start_phase_rad=phase0)
        fast = time_calls(lambda: runner.update(DT_S), n_calls)
        ref, _, _ = periodic_state(mp, phase0 + duration_s * mp.omega_rad_s)
        fast_err = float(np.abs(runner.position_m - ref).max())

        naive = NaiveRK4Runner(mp, phase0)
        slow = time_calls(lambda: naive.update(DT_S), n_calls)
        slow_err = float(np.abs(naive.y1 - ref).max())

        ramping = PeriodicRunner(mp, start_phase_rad=phase0, ramp_time_constant_s=10.0)
        ramping.set_targets(
            anchor_m=mp.anchor_m + 0.05, amplitude_m=1.5 * mp.amplitude_m, omega_rad_s=1.3 * mp.omega_rad_s
        )
        ramp = time_calls(lambda: ramping.update(DT_S), n_calls)

        phases = iter(np.random.default_rng(1).uniform(0, 2 * np.pi, n_calls))
        closed = time_calls(lambda: periodic_state(mp, next(phases)), n_calls)

        base = dict(n_dims=n_dims, n_basis=mp.n_basis, n_harmonics=int(mp.limit_cycle.shape[0]), calls=n_calls)
        for what, samples, err in (
            ("PeriodicRunner.update", fast, fast_err),
            ("PeriodicRunner.update (ramping)", ramp, None),
            ("baseline: naive RK4", slow, slow_err),
            ("periodic_state (closed form)", closed, 0.0),
        ):
            ratio = float(slow.mean() / samples.mean())
            rows.append({**base, "what": what, **stats(samples), "ratio_vs_naive": ratio, "pos_err_m": err})
    return rows


def print_table(rows: list[dict]) -> None:
    print("| n | what | mean [us] | p50 [us] | p99 [us] | naive RK4 mean / this mean | pos. error vs closed form [m] |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for r in rows:
        err = "-" if r["pos_err_m"] is None else f"{r['pos_err_m']:.1e}"
        print(
            f"| {r['n_dims']} | {r['what']} | {r['mean_us']:.2f} | {r['p50_us']:.2f} | {r['p99_us']:.2f} "
            f"| {r['ratio_vs_naive']:.2f} | {err} |"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="3k calls per row instead of 30k")
    parser.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    args = parser.parse_args(argv)
    rows = run(args.quick)
    versions = f"python {platform.python_version()}, numpy {np.__version__}"
    print(f"periodic DMP step cost, dt = {DT_S * 1e3:.0f} ms, {versions}")
    print()
    print_table(rows)
    if args.json:
        args.json.write_text(json.dumps({"benchmark": "periodic_step", "quick": args.quick, "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
