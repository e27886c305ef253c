"""``lamps controller``: the LAMPS skill executor and Cartesian impedance controller as a Zenoh service.

Configuration comes from ``--config FILE`` (TOML, ``[zenoh]`` and
``[controller]`` tables, see :mod:`controller.params`; ``[joints]``, the
arm's rotor inertia and friction, :mod:`arm.joint_dynamics`), then ``LAMPS_*``
environment variables, then the options below (highest priority). A bad
config, a skill file that does not load, or a rate this machine cannot
hold is a one-line error and exit code 1 before anything starts; Ctrl-C or
SIGTERM stops it cleanly (and ``--trace`` is written then).
"""

from __future__ import annotations

import argparse
import logging
import sys
import time

import numpy as np

from interfaces.errors import InterfaceError
from lampskit.errors import LampsError, SkillFileError
from runtime.config import add_zenoh_options, load_config, zenoh_with_options
from runtime.priority import REALTIME, set_service_priority, wanted_nice
from runtime.realtime import RealtimeRequest
from runtime.service_main import log_to_stderr, refuse, serve
from runtime.stop_signals import on_stop_signals

SERVICE = "controller"
PROG = "lamps controller"
#: A real-time rate is refused when the control law's median tick takes more than this share of the period.
MAX_TICK_SHARE = 0.5


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Runs a learned LAMPS skill on the robot over Zenoh: fixed-rate Cartesian impedance "
                    "(Pinocchio) with normal force regulation. Options override the config file.")
    p.add_argument("--config", metavar="FILE", help="TOML config with [zenoh] and [controller] tables")
    p.add_argument("--mode", choices=("lockstep", "realtime"),
                   help="lockstep: answer each robot state (deterministic); realtime: own fixed-rate clock")
    p.add_argument("--rate", type=float, metavar="HZ", help="control rate (default 1000)")
    p.add_argument("--skill", metavar="FILE",
                   help="skill file from 'lamps learn' or 'lamps demo' (required here or as [controller] skill)")
    p.add_argument("--stains-from", choices=("perception", "truth"),
                   help="where stains come from: perception/stains, or sim/truth (tests, no perception)")
    p.add_argument("--air", action="store_true", default=None, help="dry run: wipe in the air above the board")
    p.add_argument("--force", type=float, metavar="N", help="normal force to wipe with (default 10 N)")
    p.add_argument("--max-ticks", type=int, metavar="N", help="stop after N ticks (default: run until stopped)")
    p.add_argument("--trace", metavar="FILE.npz", help="record reference and measurement; written on exit")
    add_zenoh_options(p)
    p.add_argument("--check", action="store_true", help="validate config, skill and rate, then exit")
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens")
    return p


def load(a: argparse.Namespace):
    """(ZenohSettings, ControllerParams) from file, environment and options."""
    from .params import ControllerParams

    cfg = load_config(a.config)
    table = {k: (dict(v) if isinstance(v, dict) else v) for k, v in cfg.table("controller").items()}
    for key, value in (("mode", a.mode), ("rate_hz", a.rate), ("skill", a.skill), ("stains_from", a.stains_from),
                       ("max_ticks", a.max_ticks)):
        if value is not None:
            table[key] = value
    if a.trace and not table.get("trace_ticks"):
        table["trace_ticks"] = 600_000  # 10 min at 1 kHz
    if a.air is not None:
        table.setdefault("executor", {})["air"] = a.air
    if a.force is not None:
        table.setdefault("force", {})["target_n"] = a.force
    return zenoh_with_options(cfg.zenoh, a), ControllerParams.from_table(table)


def load_runnable_skill(path: str):
    """The skill file at ``path``, checked to hold what the executor needs (SkillFileError otherwise).

    The controller never learns: a skill comes from ``lamps learn`` or
    ``lamps demo`` (``lamps up`` runs the latter before it starts the cell).
    """
    from lampskit.core.skill import load_skill

    if not path:
        raise SkillFileError("no skill file: give --skill FILE or [controller] skill (LAMPS__CONTROLLER__SKILL); "
                             "make one with 'lamps demo --out DIR' (the bundled demo) or 'lamps learn DEMO -o FILE'")
    skill = load_skill(path)
    if not skill.transitional:
        raise SkillFileError(f"{path}: the skill has no transitional MP; the controller needs one to move "
                             "between stains (learn from a demonstration that wipes at least two stains)")
    return skill


def tick_cost_us(params, skill, model, n: int = 300) -> np.ndarray:
    """(n,) cost [us] of the control tick on a representative posture (holding, no board): the CPU time of this
    thread, not the wall clock, so the time it waits for a core is not counted. At start-up the cell's other loops
    already run SCHED_FIFO while this thread is not yet raised: timed on the wall clock through the router on 2
    cores, the law's median read 765 us (it is about 100) and a cell was refused its 1 kHz."""
    import dataclasses

    from .core import ControllerCore
    from .tick_io import TickInput, TickOutput

    core = ControllerCore(dataclasses.replace(params, trace_ticks=0), skill, model)
    inp, out = TickInput.zeros(7), TickOutput.zeros(7)
    inp.set_state([0.0, 0.6, 0.0, -1.4, 0.0, 0.8, 0.0], np.full(7, 0.05), np.zeros(6), params.dt_s, False)
    costs = np.empty(n)
    for i in range(n):
        t0 = time.thread_time_ns()
        core.tick(inp, out)
        costs[i] = (time.thread_time_ns() - t0) / 1e3
    return costs


def check_rate(params, skill, model) -> str:
    """Refuse a real-time rate whose period the control law cannot fit on this machine (ConfigError)."""
    costs = tick_cost_us(params, skill, model)
    p50, p99 = (float(v) for v in np.percentile(costs[50:], [50, 99]))
    period_us = 1e6 / params.rate_hz
    text = f"control tick p50 {p50:.0f} us, p99 {p99:.0f} us; period {period_us:.0f} us"
    # the median, not the tail: a busy moment at start-up must not refuse a rate the machine holds
    if params.mode == "realtime" and p50 > MAX_TICK_SHARE * period_us:
        raise InterfaceError(
            f"[controller] rate_hz = {params.rate_hz:g} cannot be held on this machine: a tick must fit in "
            f"{period_us:.0f} us but the control law alone takes {p50:.0f} us (median; limit "
            f"{MAX_TICK_SHARE:.0%} of the period, leaving the rest for the network). Lower rate_hz.")
    return text


def write_trace(path: str, core) -> None:
    from controller.core import TRACE_COLUMNS
    from lampskit.atomic import write_atomic

    write_atomic(path, lambda f: np.savez(f, trace=core.trace.array(), columns=np.array(TRACE_COLUMNS),
                                          junction_ticks=np.array(core.executor.junction_ticks)))


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    log_to_stderr("controller", a.verbose)
    try:
        zenoh_settings, params = load(a)
        wanted_nice(REALTIME)  # a bad LAMPS_NICE is refused with the rest of the configuration
        RealtimeRequest.from_env()  # and a bad LAMPS_RT_PRIORITY, LAMPS_MLOCK or LAMPS_CPUS
        from arm.joint_dynamics import joint_dynamics_from_config
        from arm.robot_model import RobotModel

        skill = load_runnable_skill(params.skill)
        model = RobotModel(joints=joint_dynamics_from_config(a.config))  # the [joints] table the sim reads too
        timing = check_rate(params, skill, model)
    except (LampsError, OSError) as exc:
        return refuse(PROG, exc)
    if a.check:
        print(f"ok: skill with {len(skill.periodic)} periodic and {len(skill.transitional)} transitional MPs, "
              f"mode {params.mode} at {params.rate_hz:g} Hz ({timing}), stains from {params.stains_from}, "
              f"keys under {zenoh_settings.keys.prefix}")
        return 0
    set_service_priority(REALTIME)  # before the Zenoh session starts its threads: they inherit it
    return serve(PROG, SERVICE, zenoh_settings, lambda node: _serve(node, a, params, skill, model))


def _serve(node, a: argparse.Namespace, params, skill, model) -> int:
    """Run the controller on its open ``node`` until a stop signal; its trace written on the way out."""
    from .core import ControllerCore
    from .service import ControllerService

    core = ControllerCore(params, skill, model)
    service = ControllerService(params, node, core)
    on_stop_signals(service.stop)
    try:
        ticks = service.run()
    finally:
        if a.trace and core.trace is not None:
            write_trace(a.trace, core)
    logging.getLogger("controller").info("stopped after %d ticks in phase %s", ticks, core.executor.phase)
    return 0


if __name__ == "__main__":
    sys.exit(main())
