"""Controller benchmarks: control-law time per tick, real-time loop against the sim, lock-step closed loop.

Usage: .venv/bin/python bench/bench_controller.py [--quick] [--json OUT] [--baseline COMMIT [--rounds N]]

With ``--baseline COMMIT``: items 1 and 2 only (the tick alone, the real-time loop as deployed), from this
checkout and from COMMIT (a temporary git worktree, :mod:`ab_trees`) taking turns ``--rounds`` times (3) in
one run; the medians of each and their ratio.

1. Control-law compute time per tick: ``ControllerCore.tick`` alone, timed
   with ``perf_counter_ns`` around each call, in-process against an
   in-process ``SimCore`` (no network, no camera) for a whole wipe of the
   bundled skill (approach, contact, wiping, retreat; until the executor
   reaches DONE, at most 20000 ticks). The stains come from the sim's truth
   every 100 ticks. p50 / p99 / max [us] over all ticks, and split into WIPE
   ticks and the rest. Baseline: the 1000 us period at 1 kHz. The same run
   also gives the in-process closed-loop speed (sim step + controller tick
   per wall second): the ceiling for item 3. Then the arm's terms and the impedance law alone on every
   5th state of that run: compiled (``Kinematics.update`` + ``impedance_torque`` into preallocated
   terms) against the numpy formulation it replaced (``tests/numpy_law.py``), interleaved; the ratio
   of the medians and the largest torque difference.
2. Real-time mode over Zenoh for 60 s (10 s with --quick): ``lamps sim`` and
   ``lamps controller`` each in their own process, both ``--mode realtime``,
   no camera, stains from the sim's truth. The controller's status is
   sampled every 0.5 s; its timing percentiles cover the last 2000 ticks, so
   the table gives the median of those windowed p50 periods, the largest
   windowed p99, the largest single period, and the overruns at the end
   (the controller's loop is driven by the robot's states: an overrun is a
   robot state it never answered), also per 10,000 ticks. Baseline: a 1000 us period
   with no overruns. Also the controller's final phase, its
   ``ticks_without_fresh_state`` counter, and the sim's own step period p99
   and ``stale_command_brakes`` (steps where no fresh command arrived).
   Run twice: the loops' threads SCHED_FIFO with locked memory (the default), then the baseline with
   both off (``LAMPS_RT_PRIORITY=off LAMPS_MLOCK=off``). Then the floor: the same sim against
   ``bench/minimal_controller.py`` (the controller's set-up, Zenoh path and loop with a tick that answers
   zeros at once), the same duration; the ratios say what the controller's tick adds. And a third time
   through ``lamps router`` (a process of its own; sim and controller its clients, no link between them):
   every state and command takes one hop more, the ratios to the mesh run are printed.
3. Lock-step real-time factor of the whole closed loop: the same two
   processes in ``--mode lockstep`` (each sim step waits for the command
   answering its state) until the controller reports DONE (at most 120 s).
   Simulated seconds per wall second (from ``sim/truth``'s robot clock),
   ticks per wall second, and the controller's loop period (one round trip)
   p50 / p99. Baseline: 1.0 is real time. Then the same through ``lamps router``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from service_procs import BenchError, Proc, free_port, sim_and_controller  # noqa: E402

from controller.control.impedance import (  # noqa: E402
    Kinematics,
    Reference,
    TaskShaping,
    impedance_torque,
    new_terms,
    task_modes,
    task_stiffness,
)
from controller.core import ControllerCore  # noqa: E402
from controller.executor_types import BoardPose  # noqa: E402
from controller.params import ControllerParams  # noqa: E402
from controller.tick_io import TickInput, TickOutput  # noqa: E402
from interfaces.messages import ControllerStatus, ServiceStatus, SimTruth  # noqa: E402
from lampskit.core.planner_types import Stain  # noqa: E402
from lampskit.learn.learn import bundled_skill  # noqa: E402
from runtime.config import ZenohSettings  # noqa: E402
from runtime.session import ServiceNode  # noqa: E402
from sim.core import SimCore  # noqa: E402
from sim.params import SimParams  # noqa: E402

MAX_TICKS = 20_000
#: Every this many ticks the in-process run keeps the state for the law-alone comparison.
LAW_STATE_EVERY = 5
STAINS_EVERY = 100
SAMPLE_S = 0.5


# ---------------------------------------------------------------------------------------------- 1. in process
def _feed_stains(core: ControllerCore, sim: SimCore) -> None:
    board = BoardPose.from_transform(sim.board.T_board_to_world, sim.board.size_m)
    stains = [Stain(s.id, np.array(s.centre_m), s.size_m, kappa=bool(r <= 0.03))
              for s, r in zip(sim.dirt.stains, sim.dirt.remaining())]
    core.executor.set_stains(board, stains)


def _stats_us(ns: np.ndarray) -> dict:
    if len(ns) == 0:
        return {"ticks": 0, "p50_us": float("nan"), "p99_us": float("nan"), "max_us": float("nan")}
    us = ns / 1e3
    return {"ticks": len(us), "p50_us": float(np.percentile(us, 50)), "p99_us": float(np.percentile(us, 99)),
            "max_us": float(us.max())}


def bench_tick(skill) -> dict:
    sim = SimCore(SimParams.from_table({"camera": {"enabled": False}}))
    core = ControllerCore(ControllerParams.from_table({}), skill)
    inp, out = TickInput.zeros(core.model.nq), TickOutput.zeros(core.model.nq)
    times = np.zeros(MAX_TICKS, np.int64)
    states: list[tuple[np.ndarray, np.ndarray]] = []
    phases: list[str] = []
    n = 0
    t_wall = time.perf_counter()
    try:
        while n < MAX_TICKS and core.executor.phase != "DONE":
            if n % STAINS_EVERY == 0:
                _feed_stains(core, sim)
            o = sim.out
            inp.set_state(o.q, o.dq, o.wrench, 0.001, False)
            t0 = time.perf_counter_ns()
            core.tick(inp, out)
            times[n] = time.perf_counter_ns() - t0
            tau = out.tau_nm
            phases.append(core.executor.phase)
            if n % LAW_STATE_EVERY == 0:
                states.append((o.q.copy(), o.dq.copy()))
            sim.step(tau.copy())
            n += 1
        wall = time.perf_counter() - t_wall
        remaining = [float(r) for r in sim.dirt.remaining()]
    finally:
        sim.close()
    times = times[:n]
    wipe = np.array([p == "WIPE" for p in phases], bool)
    per_phase = {}
    for name in dict.fromkeys(phases):
        per_phase[name] = _stats_us(times[np.array([p == name for p in phases], bool)])
    return {"all": _stats_us(times), "wipe": _stats_us(times[wipe]), "other": _stats_us(times[~wipe]),
            "per_phase": per_phase, "final_phase": core.executor.phase, "ticks": n, "wall_s": wall,
            "loop_ticks_per_s": n / wall, "loop_x_realtime": n / wall / 1000.0, "remaining": remaining,
            "law": bench_law(core, states)}


def bench_law(core: ControllerCore, states: list[tuple[np.ndarray, np.ndarray]]) -> dict:
    """The arm's terms and the impedance law alone on the run's states: compiled (the controller's
    ``Kinematics.update`` + ``impedance_torque`` into preallocated terms) against the numpy formulation it
    replaced (``tests/numpy_law.py``), interleaved state by state; the largest torque difference too."""
    from tests.numpy_law import numpy_kinematics, numpy_law

    model, imp = core.model, core.p.impedance
    kin = Kinematics(model)
    terms = new_terms(kin)
    shaping = TaskShaping(force_axis=np.array([0.0, 0.0, 1.0]), press_n=10.0, normal_damping_1_s=20.0)
    compiled, numpy_ns, worst = [], [], 0.0
    for q, dq in states:
        kin.update(q, dq)
        ref = Reference(kin.p + 0.005, kin.R.copy(), np.full(6, 0.05), np.full(6, 0.5))
        modes = task_modes(kin.Lambda, task_stiffness(imp), imp.damping_factor, imp.max_mode_frequency_rad_s)
        t0 = time.perf_counter_ns()
        kin.update(q, dq)
        impedance_torque(model, q, dq, ref, imp, q, False, shaping, kin, modes, terms)
        t1 = time.perf_counter_ns()
        tau = numpy_law(numpy_kinematics(model, q, dq), q, dq, ref, imp, q, False, shaping, modes)[0]
        t2 = time.perf_counter_ns()
        compiled.append(t1 - t0)
        numpy_ns.append(t2 - t1)
        worst = max(worst, float(np.max(np.abs(tau - terms.tau_nm))))
    c, b = _stats_us(np.array(compiled)), _stats_us(np.array(numpy_ns))
    return {"compiled": c, "numpy": b, "ratio_p50": b["p50_us"] / c["p50_us"], "max_tau_diff_nm": worst}


# ---------------------------------------------------------------------------------------------- 2. real time
#: The baseline of the real-time run: the loops' threads left under the fair scheduler (nice -10 still applies).
NO_RT = {"LAMPS_RT_PRIORITY": "off", "LAMPS_MLOCK": "off"}
NO_RT_LABEL = "LAMPS_RT_PRIORITY=off LAMPS_MLOCK=off"
#: The same two processes as clients of ``lamps router`` (one process more, plain TCP like the mesh runs).
ROUTER_LABEL = "through lamps router (sim and controller its clients)"


def bench_realtime(duration_s: float, robot: str = "sim", env: dict[str, str] | None = None,
                   router: bool = False) -> dict:
    with sim_and_controller("realtime", robot, env, router) as (node, sim, ctl, refusals):
        status = node.latest(node.keys.controller_status, ControllerStatus)
        sim_status = node.latest(node.keys.sim_status, ServiceStatus)
        robot_status = node.latest(node.keys.robot_status, ServiceStatus)
        last_robot: ServiceStatus | None = None
        samples: list[ControllerStatus] = []
        last_sim: ServiceStatus | None = None
        last: ControllerStatus | None = None
        timeline: list[tuple[float, str, str]] = []  # (s since start, phase, reason) at each change seen
        t0 = time.monotonic()
        next_sample = t0 + SAMPLE_S
        while time.monotonic() < t0 + duration_s:
            time.sleep(max(next_sample - time.monotonic(), 0.0))
            next_sample += SAMPLE_S
            sim.check()
            ctl.check()
            s = status.take()
            if s is not None:
                last = s
                if s.timing.ticks > 0:
                    samples.append(s)
                if not timeline or timeline[-1][1:3] != (s.phase, s.reason):
                    timeline.append((time.monotonic() - t0, s.phase, s.reason))
            ss = sim_status.take()
            if ss is not None:
                last_sim = ss
            last_robot = robot_status.take() or last_robot
        # the freshest statuses before stopping (controller at 20 Hz, sim at 2 Hz)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            s, ss = status.take(), sim_status.take()
            last = s or last
            last_sim = ss or last_sim
            last_robot = robot_status.take() or last_robot
            time.sleep(0.05)
        wall = time.monotonic() - t0
    if last is None or not samples:
        raise BenchError("no controller status received in real-time mode")
    t = last.timing
    return {"duration_s": wall, "samples": len(samples), "start_refusals": refusals,
            "timeline": timeline,
            "period_p50_us_median": float(np.median([s.timing.period_p50_us for s in samples])),
            "period_p99_us_max": float(max(s.timing.period_p99_us for s in samples)),
            "period_max_us": float(max(s.timing.period_max_us for s in samples)),
            "update_p99_us_max": float(max(s.timing.update_p99_us for s in samples)),
            "read_p99_us_max": float(max(s.timing.read_p99_us for s in samples)),
            "write_p99_us_max": float(max(s.timing.write_p99_us for s in samples)),
            "ticks": t.ticks, "overruns": t.overruns, "overruns_per_10k": 1e4 * t.overruns / max(t.ticks, 1),
            "phase": last.phase, "reason": last.reason, "counters": dict(last.counters),
            "ticks_without_fresh_state": last.counters.get("ticks_without_fresh_state"),
            "sim_period_p99_us": None if last_sim is None else last_sim.timing.period_p99_us,
            "sim_period_max_us": None if last_sim is None else last_sim.timing.period_max_us,
            "sim_overruns": None if last_sim is None else last_sim.timing.overruns,
            "sim_ticks": None if last_sim is None else last_sim.timing.ticks,
            "stale_command_brakes": None if last_sim is None else last_sim.counters.get("stale_command_brakes", 0),
            "robot_counters": None if last_robot is None else dict(last_robot.counters),
            "robot_detail": None if last_robot is None else last_robot.detail}


def bench_minimal(duration_s: float) -> dict:
    """The floor: ``lamps sim`` (real time, gravity compensated) against ``bench/minimal_controller.py``, the
    controller's loop, set-up and Zenoh path with a tick that only answers zeros (its figures over the whole
    run, from the first state; the sim's status at the end)."""
    p1 = free_port()
    rid = f"bench{p1}"
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        procs: list[Proc] = []
        stack.callback(lambda: [p.stop() for p in reversed(procs)])
        procs.append(Proc("sim", [sys.executable, "-m", "sim.cli", "--mode", "realtime", "--no-camera",
                                  "--gravity-compensated", "--listen", f"tcp/127.0.0.1:{p1}", "--robot-id", rid],
                          Path(tmp)))
        node = stack.enter_context(ServiceNode("bench", ZenohSettings(connect=(f"tcp/127.0.0.1:{p1}",),
                                                                      robot_id=rid)))
        end = time.monotonic() + 60.0
        while "sim" not in node.alive_services(0.5):
            procs[0].check()
            if time.monotonic() > end:
                raise BenchError("the sim was not alive after 60 s:\n" + procs[0].output())
        sim_status = node.latest(node.keys.sim_status, ServiceStatus)
        ctl = subprocess.run([sys.executable, str(REPO / "bench" / "minimal_controller.py"), "--connect",
                              f"tcp/127.0.0.1:{p1}", "--robot-id", rid, "--seconds", str(duration_s)],
                             cwd=REPO, capture_output=True, text=True, timeout=duration_s + 120)
        if ctl.returncode != 0:
            raise BenchError(f"the minimal controller failed:\n{ctl.stdout}{ctl.stderr}")
        res = json.loads(ctl.stdout.strip().splitlines()[-1])
        last_sim, end = None, time.monotonic() + 1.5  # the sim's status comes at 2 Hz
        while time.monotonic() < end:
            last_sim = sim_status.take() or last_sim
            time.sleep(0.05)
    res["sim_period_p99_us"] = None if last_sim is None else last_sim.timing.period_p99_us
    res["sim_overruns_per_10k"] = None if last_sim is None else \
        1e4 * last_sim.timing.overruns / max(last_sim.timing.ticks, 1)
    res["stale_command_brakes"] = None if last_sim is None else last_sim.counters.get("stale_command_brakes", 0)
    return res


# ---------------------------------------------------------------------------------------------- 3. lock step
def bench_lockstep(timeout_s: float, robot: str = "sim", router: bool = False) -> dict:
    with sim_and_controller("lockstep", robot, router=router) as (node, sim, ctl, refusals):
        status = node.latest(node.keys.controller_status, ControllerStatus)
        truth = node.latest(node.keys.sim_truth, SimTruth)
        samples: list[ControllerStatus] = []
        first: tuple[float, int, int] | None = None  # (wall, robot_time_ns, steps) of the first truth seen
        newest: tuple[float, int, int] | None = None
        last: ControllerStatus | None = None
        t0 = time.monotonic()
        next_sample = t0
        while time.monotonic() < t0 + timeout_s:
            time.sleep(0.02)
            now = time.monotonic()
            tr = truth.take()
            if tr is not None and tr.robot_time_ns > 0:
                newest = (now, tr.robot_time_ns, tr.seq)
                if first is None:
                    first = newest
            s = status.take()
            if s is not None:
                last = s
                if now >= next_sample and s.timing.ticks > 0:
                    samples.append(s)
                    next_sample = now + SAMPLE_S
                if s.phase == "DONE":
                    samples.append(s)
                    break
            sim.check()
            ctl.check()
        reached_done = last is not None and last.phase == "DONE"
    if first is None or newest is None or newest[0] <= first[0] or last is None:
        raise BenchError("no simulated time advanced in lock-step mode (no sim/truth or controller status)")
    wall = newest[0] - first[0]
    sim_s = (newest[1] - first[1]) / 1e9
    steps = newest[2] - first[2]
    with_ticks = [s for s in samples if s.timing.ticks > 0] or [last]
    return {"reached_done": reached_done, "start_refusals": refusals, "phase": last.phase, "reason": last.reason,
            "wall_s": wall, "sim_s": sim_s, "x_realtime": sim_s / wall, "ticks_per_s": steps / wall,
            "sim_time_total_s": newest[1] / 1e9, "controller_ticks": last.timing.ticks,
            "period_p50_us_median": float(np.median([s.timing.period_p50_us for s in with_ticks])),
            "period_p99_us_max": float(max(s.timing.period_p99_us for s in with_ticks)),
            "period_p50_us_final": last.timing.period_p50_us, "period_p99_us_final": last.timing.period_p99_us,
            "counters": dict(last.counters)}


# ---------------------------------------------------------------------------------------------- report
def _fmt(v, spec: str = ".0f") -> str:
    return "n/a" if v is None else format(v, spec)


def _ratio(a: dict, b: dict, key: str | None) -> str:
    """``a[key] / b[key]`` as ``1.23x`` ("-" without a key, "n/a" when b's is 0)."""
    if key is None:
        return "-"
    return f"{a[key] / b[key]:.2f}x" if b[key] else "n/a"


def _lockstep_rows(lk: dict) -> list[tuple[str, str]]:
    return [("ended in phase", lk["phase"] + ("" if lk["reached_done"] else " (120 s cap, not DONE)")
             + (f" ({lk['reason']})" if lk["reason"] else "")),
            ("simulated s / wall s (first truth seen to the end)", f"{lk['sim_s']:.1f} / {lk['wall_s']:.1f}"),
            ("real-time factor", f"{lk['x_realtime']:.2f}"),
            ("ticks per wall second", f"{lk['ticks_per_s']:.0f}"),
            ("controller period (round trip) p50, median of windows us", f"{lk['period_p50_us_median']:.0f}"),
            ("controller period (round trip) p99, max of windows us", f"{lk['period_p99_us_max']:.0f}"),
            ("controller period p50 / p99 at the end us",
             f"{lk['period_p50_us_final']:.0f} / {lk['period_p99_us_final']:.0f}")]


def print_report(res: dict, cmd: str) -> None:
    print(f"Controller benchmarks ({res['machine']})\n")
    tk = res["tick"]
    print(f"| control law, in-process whole wipe ({tk['ticks']} ticks, ended {tk['final_phase']}) | ticks | "
          f"p50 us | p99 us | max us |\n|---|---|---|---|---|")
    for label, key in (("ControllerCore.tick, all ticks", "all"), ("  WIPE ticks", "wipe"),
                       ("  other phases", "other")):
        r = tk[key]
        print(f"| {label} | {r['ticks']} | {r['p50_us']:.0f} | {r['p99_us']:.0f} | {r['max_us']:.0f} |")
    for name, r in tk["per_phase"].items():
        print(f"| &nbsp;&nbsp;phase {name} | {r['ticks']} | {r['p50_us']:.0f} | {r['p99_us']:.0f} | "
              f"{r['max_us']:.0f} |")
    law = tk["law"]
    print(f"\n| the arm's terms + impedance law alone, {law['compiled']['ticks']} states of the run | p50 us | p99 us "
          f"| max us |\n|---|---|---|---|")
    for label, key in (("compiled (Kinematics.update + impedance_torque)", "compiled"),
                       ("baseline: the numpy formulation (tests/numpy_law.py)", "numpy")):
        r = law[key]
        print(f"| {label} | {r['p50_us']:.1f} | {r['p99_us']:.1f} | {r['max_us']:.0f} |")
    print(f"| numpy / compiled (p50); largest torque difference | {law['ratio_p50']:.1f}x | "
          f"{law['max_tau_diff_nm']:.1e} Nm | |")
    print("\n| in-process closed loop (SimCore.step + tick) | ticks/s | x real time (1 kHz) | stains left |"
          "\n|---|---|---|---|")
    print(f"| whole wipe, {tk['wall_s']:.1f} s wall | {tk['loop_ticks_per_s']:.0f} | {tk['loop_x_realtime']:.2f} | "
          f"{', '.join(f'{r:.1%}' for r in tk['remaining'])} |")
    rt, base, via = res["realtime"], res["realtime_no_rt"], res["realtime_router"]
    print(f"\n| real-time mode over Zenoh, {rt['duration_s']:.0f} s each ({rt['samples']} / {base['samples']} / "
          f"{via['samples']} status samples) | loop threads SCHED_FIFO, memory locked (default) | baseline: "
          f"{NO_RT_LABEL} | {ROUTER_LABEL} |\n|---|---|---|---|")

    def rows(rt: dict) -> list[tuple[str, str]]:
        c = rt["counters"]
        return [("controller loop thread", f"FIFO {c.get('loop_sched_fifo_priority', 0)}, memory "
                 + ("locked" if c.get("loop_memory_locked") else "not locked")
                 if c.get("loop_sched_fifo_priority") else "SCHED_OTHER, nice -10"),
                ("controller period p50 (median of windows) us", _fmt(rt["period_p50_us_median"])),
                ("controller period p99 (max of windows) us", _fmt(rt["period_p99_us_max"])),
                ("controller period max us", _fmt(rt["period_max_us"])),
                ("controller read / update / write p99 (max of windows) us",
                 f"{rt['read_p99_us_max']:.0f} / {rt['update_p99_us_max']:.0f} / {rt['write_p99_us_max']:.0f}"),
                ("controller overruns / ticks", f"{rt['overruns']} / {rt['ticks']}"),
                ("controller overruns per 10,000 ticks", f"{rt['overruns_per_10k']:.1f}"),
                ("controller ticks_without_fresh_state", "0 (never counted)"
                 if rt["ticks_without_fresh_state"] is None else str(rt["ticks_without_fresh_state"])),
                ("controller start-up refusals (rate check, retried)", str(len(rt["start_refusals"]))),
                ("controller final phase", rt["phase"] + (f" ({rt['reason']})" if rt["reason"] else "")),
                ("sim period p99 / max us", f"{_fmt(rt['sim_period_p99_us'])} / {_fmt(rt['sim_period_max_us'])}"),
                ("sim overruns / steps", f"{_fmt(rt['sim_overruns'], 'd')} / {_fmt(rt['sim_ticks'], 'd')}"),
                ("sim stale_command_brakes", _fmt(rt["stale_command_brakes"], "d"))]

    for (label, v), (_, b), (_, r) in zip(rows(rt), rows(base), rows(via)):
        print(f"| {label} | {v} | {b} | {r} |")
    print("\n| through lamps router / the mesh (first column), same run | real time | lock-step |\n|---|---|---|")
    for label, rk, lk in (("period (round trip) p50", "period_p50_us_median", "period_p50_us_median"),
                          ("period p99", "period_p99_us_max", "period_p99_us_max"),
                          ("states unanswered per 10,000", "overruns_per_10k", None),
                          ("ticks per wall second", None, "ticks_per_s")):
        print(f"| {label} | {_ratio(via, rt, rk)} | {_ratio(res['lockstep_router'], res['lockstep'], lk)} |")
    mn = res["minimal"]
    print(f"\n| the floor: the same loop with a minimal tick (bench/minimal_controller.py, zeros answered at once), "
          f"{mn['ticks']} states | value | the controller above / floor |\n|---|---|---|")
    for label, key, fmt in (("period p99 us", "period_p99_us", ".0f"), ("period max us", "period_max_us", ".0f"),
                            ("states unanswered per 10,000", "overruns_per_10k", ".1f")):
        ref = {"period_p99_us": rt["period_p99_us_max"], "period_max_us": rt["period_max_us"],
               "overruns_per_10k": rt["overruns_per_10k"]}[key]
        ratio = "n/a" if not mn[key] else f"{ref / mn[key]:.2f}x"
        print(f"| {label} | {format(mn[key], fmt)} | {ratio} |")
    print(f"| loop thread | FIFO {mn['counters'].get('loop_sched_fifo_priority', 0)} | - |")
    print(f"| sim period p99 us / overruns per 10,000 / stale brakes | {_fmt(mn['sim_period_p99_us'])} / "
          f"{_fmt(mn['sim_overruns_per_10k'], '.1f')} / {_fmt(mn['stale_command_brakes'], 'd')} | - |")
    print("\nreal-time phases (s since start): " + ", ".join(
        f"{t:.1f} {ph}" + (f" ({why})" if why else "") for t, ph, why in rt["timeline"]))
    print(f"\n| lock-step closed loop over Zenoh | the mesh | {ROUTER_LABEL} |\n|---|---|---|")
    for (label, v), (_, r) in zip(_lockstep_rows(res["lockstep"]), _lockstep_rows(res["lockstep_router"])):
        print(f"| {label} | {v} | {r} |")
    print(f"\ncpu count {os.cpu_count()}, Python {platform.python_version()}, {platform.machine()}")
    print(f"reproduce: {cmd}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10 s real-time run instead of 60 s")
    ap.add_argument("--json", metavar="OUT", help="also write the figures as JSON")
    ap.add_argument("--baseline", metavar="COMMIT", help="only the tick and the real-time loop, against COMMIT")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of each tree with --baseline (3)")
    a = ap.parse_args()
    if a.baseline:
        import ab_trees

        return ab_trees.compare_with(REPO, a.baseline, max(a.rounds, 1), a.quick)
    cmd = ".venv/bin/python bench/bench_controller.py" + (" --quick" if a.quick else "")
    res = {"machine": f"{platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"}
    try:
        skill = bundled_skill()
        res["tick"] = bench_tick(skill)
        res["realtime"] = bench_realtime(10.0 if a.quick else 60.0)
        res["realtime_no_rt"] = bench_realtime(10.0 if a.quick else 60.0, env=NO_RT)
        res["realtime_router"] = bench_realtime(10.0 if a.quick else 60.0, router=True)
        res["minimal"] = bench_minimal(10.0 if a.quick else 60.0)
        res["lockstep"] = bench_lockstep(120.0)
        res["lockstep_router"] = bench_lockstep(120.0, router=True)
    except BenchError as exc:
        print(f"bench_controller: {exc}", file=sys.stderr)
        return 1
    print_report(res, cmd)
    if a.json:
        from lampskit.atomic import write_text_atomic

        write_text_atomic(Path(a.json), json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
