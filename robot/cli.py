"""``lamps robot``: a robot side of the cell as a Zenoh service: the real iiwa through lbr_fri_ros2_stack, or a mock.

``--backend lbr`` serves :class:`~robot.lbr.adapter.LbrPort` (the stack
behind zenoh-bridge-ros2dds; keys from the ``[lbr]`` table) with the
``robot/*`` protocol of :mod:`robot.server`: it monitors from the start
and commands only once armed (``--arm``, ``[lbr] arm``, or an ArmRequest on
``robot/arm``). ``--backend mock`` serves :class:`~robot.mock.MockArm`
(no physics engine) for trying a controller or the protocol.

``--backend lbr --watchdog`` runs, instead of the adapter, the watchdog
that sends the stack the release when the adapter's messages stop
(:mod:`robot.lbr.watchdog`; run it on the robot PC beside the stack).
``--backend lbr --preflight`` runs the checks that move nothing
(:mod:`robot.lbr.preflight`), prints each PASS or FAIL with the fix and
exits 0 only if all pass.

Configuration: ``--config FILE`` (``[zenoh]``, ``[lbr]``, ``[robot]``
tables), then ``LAMPS_*`` environment variables, then the options. A bad
configuration is one line and exit 1; Ctrl-C or SIGTERM disarms (one last
hold), says why and exits 0.
"""

from __future__ import annotations

import argparse
import logging
import sys

from interfaces.errors import ConfigError
from lampskit.errors import LampsError
from runtime.config import add_zenoh_options, check_range, load_config, zenoh_with_options
from runtime.priority import REALTIME, set_service_priority, wanted_nice
from runtime.realtime import RealtimeRequest
from runtime.service_main import log_to_stderr, refuse, serve
from runtime.stop_signals import on_stop_signals

SERVICE = "robot"
PROG = "lamps robot"
BACKENDS = ("lbr", "mock")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="lamps robot",
        description="A robot side of the cell over Zenoh: the KUKA LBR iiwa through lbr_fri_ros2_stack and "
                    "zenoh-bridge-ros2dds (--backend lbr), or a mock arm. Options override the config file.")
    p.add_argument("--backend", choices=BACKENDS, default="lbr", help="lbr: the real robot (default); mock: a mock arm")
    p.add_argument("--config", metavar="FILE", help="TOML config with [zenoh], [lbr] and [robot] tables")
    p.add_argument("--mode", choices=("lockstep", "realtime"),
                   help="lbr: realtime for a real robot (default), lockstep behind the lbr peer's lock-step; "
                        "mock: lockstep (default) or realtime")
    p.add_argument("--namespace", help="lbr: the stack's robot name (topics /NS/state, /NS/command/torque)")
    p.add_argument("--arm", action="store_true", default=None,
                   help="lbr: arm as soon as the robot's session allows commanding (else: an ArmRequest on robot/arm)")
    add_zenoh_options(p)
    p.add_argument("--watchdog", action="store_true",
                   help="lbr: run the watchdog beside the stack: the release when the adapter's messages stop")
    p.add_argument("--preflight", action="store_true",
                   help="lbr: check the stack, the robot and the bridge without moving anything; exit 0 if all pass")
    p.add_argument("--check", action="store_true", help="validate the configuration, then exit")
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens")
    return p


def load(a: argparse.Namespace):
    """(ZenohSettings, LbrParams, ServerParams) from file, environment and options."""
    from robot.lbr.params import LbrParams
    from robot.server import ServerParams

    cfg = load_config(a.config)
    lbr = dict(cfg.table("lbr"))
    if a.namespace is not None:
        lbr["namespace"] = a.namespace
    if a.arm is not None:
        lbr["arm"] = a.arm
    lbr_params = LbrParams.from_table(lbr)
    robot = dict(cfg.table("robot"))
    unknown = sorted(set(robot) - {"mode", "rate_hz", "status_rate_hz", "republish_s"})
    if unknown:
        raise ConfigError(f"[robot] unknown key(s) {unknown}; valid: mode, rate_hz, status_rate_hz, republish_s")
    mode = a.mode or robot.get("mode", "realtime" if a.backend == "lbr" else "lockstep")
    if mode not in ("lockstep", "realtime"):
        raise ConfigError(f"[robot] mode must be lockstep or realtime, got {mode!r}")
    rate = robot.get("rate_hz", 1000.0)
    check_range("robot", "rate_hz", rate, 1.0, 10_000.0)
    status = robot.get("status_rate_hz", 10.0)
    check_range("robot", "status_rate_hz", status, 0.1, 100.0)
    republish = robot.get("republish_s", 0.05)
    check_range("robot", "republish_s", republish, 0.001, 10.0)
    server = ServerParams(mode=mode, rate_hz=float(rate), stale_limit_s=lbr_params.stale_limit_s,
                          republish_s=float(republish), status_rate_hz=float(status),
                          speed_brake_share=lbr_params.speed_brake_share)
    return zenoh_with_options(cfg.zenoh, a), lbr_params, server


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    log_to_stderr("robot", a.verbose)
    try:
        zenoh_settings, lbr_params, server_params = load(a)
        wanted_nice(REALTIME)  # a bad LAMPS_NICE is refused with the rest of the configuration
        RealtimeRequest.from_env()  # and a bad LAMPS_RT_PRIORITY, LAMPS_MLOCK or LAMPS_CPUS
    except LampsError as exc:
        return refuse(PROG, exc)
    if a.check:
        where = (f"topics under /{lbr_params.namespace}, {lbr_params.branch} joint names, FRI "
                 f"{lbr_params.fri_major} states" if a.backend == "lbr" else "a mock arm")
        print(f"ok: backend {a.backend} ({where}), mode {server_params.mode}, keys under {zenoh_settings.keys.prefix}")
        if a.backend == "lbr" and lbr_params.open_loop:
            print("note: [lbr] open_loop = true (the stack's default): arming will be refused until the stack runs "
                  "with open_loop: false and [lbr] open_loop = false (docs/real-robot.md)")
        return 0
    if (a.watchdog or a.preflight) and a.backend != "lbr":
        return refuse(PROG, "--watchdog and --preflight need --backend lbr")
    if a.watchdog:
        from .lbr.watchdog import WATCHDOG_SERVICE

        return serve(PROG, WATCHDOG_SERVICE, zenoh_settings, lambda node: _watchdog(node, lbr_params))
    if a.preflight:
        from .lbr.preflight import run_preflight

        return serve(PROG, "lbr-preflight", zenoh_settings, lambda node: run_preflight(lbr_params, node))
    set_service_priority(REALTIME)  # before the Zenoh session starts its threads: they inherit it
    return serve(PROG, SERVICE, zenoh_settings, lambda node: _serve(node, a.backend, lbr_params, server_params))


def _serve(node, backend: str, lbr_params, server_params) -> int:
    """Serve the robot side on its open ``node`` until a stop signal."""
    from .server import RobotServer

    port = _port(backend, lbr_params, node, server_params.mode == "lockstep")
    server = RobotServer(port, node, server_params, SERVICE, node.keys.robot_status)
    on_stop_signals(server.stop)
    server.run()
    port.close()
    reason = getattr(port, "disarm_reason", "")
    logging.getLogger("robot").warning("stopped after %d cycles%s", server.steps, f" ({reason})" if reason else "")
    return 0


def _watchdog(node, lbr_params) -> int:
    """Watch the stack for a controller gone silent, on its open ``node``, until a stop signal."""
    import threading

    from .lbr.watchdog import Watchdog

    stop = threading.Event()
    on_stop_signals(stop)
    dog = Watchdog(lbr_params, node.session, lbr_params.watchdog_after_s)
    try:
        dog.run(stop)
    finally:
        dog.close()
    logging.getLogger("robot").warning("watchdog stopped: %s", dict(dog.watch.counts))
    return 0


def _port(backend: str, lbr_params, node, lockstep: bool):
    if backend == "mock":
        from .mock import MockArm

        return MockArm()
    from .lbr.adapter import LbrPort

    return LbrPort(lbr_params, node, lockstep=lockstep)


if __name__ == "__main__":
    sys.exit(main())
