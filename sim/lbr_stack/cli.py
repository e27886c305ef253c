"""``lamps lbr-peer``: the simulated iiwa behind lbr_fri_ros2_stack's keys, as zenoh-bridge-ros2dds shows them.

Configuration comes from ``--config FILE`` (TOML: ``[zenoh]``, ``[lbr_peer]``
and ``[sim]`` for the arm, board, dirt and camera; see
:mod:`sim.lbr_stack.params` and :mod:`sim.lbr_stack.peer`), then ``LAMPS_*`` environment variables
(:mod:`runtime.config`), then the options below (highest priority).
A broken config file or an impossible board pose is a one-line error and
exit code 1 before anything starts; Ctrl-C or SIGTERM stops it cleanly.
"""

from __future__ import annotations

import argparse
import logging
import sys

from lampskit.errors import LampsError
from runtime.config import add_zenoh_options, load_config, zenoh_with_options
from runtime.priority import REALTIME, set_service_priority, wanted_nice
from runtime.realtime import RealtimeRequest
from runtime.service_main import log_to_stderr, refuse, serve
from runtime.stop_signals import on_stop_signals

PROG = "lamps lbr-peer"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="A robot to test the real-robot adapter against: the PyBullet iiwa behind lbr_fri_ros2_stack's "
                    "CDR messages on the bridge keys (<namespace>/state, <namespace>/command/torque, ...), behaving "
                    "as the stack's code does (the last command re-applied, the app's joint spring, the PID, "
                    "open_loop, filtered torques, FRI 1 or 2). Options override the config file, which overrides "
                    "the defaults.")
    p.add_argument("--config", metavar="FILE", help="TOML config with [zenoh], [lbr_peer], [sim] and [joints] tables")
    p.add_argument("--mode", choices=("lockstep", "realtime"),
                   help="lockstep: step once per received torque command (deterministic); "
                        "realtime: the FRI period on the wall clock, newest command held")
    p.add_argument("--namespace", metavar="NS", help="the stack's robot namespace (default lbr: keys lbr/...)")
    add_zenoh_options(p)
    p.add_argument("--check", action="store_true", help="validate the configuration and the board pose, then exit")
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens")
    return p


def load(a: argparse.Namespace):
    """(ZenohSettings, LbrPeerParams, SimParams) from file, environment and options."""
    from .params import LbrPeerParams
    from .peer import sim_params_for_peer

    cfg = load_config(a.config)
    table = dict(cfg.table("lbr_peer"))
    for key, value in (("mode", a.mode), ("namespace", a.namespace)):
        if value is not None:
            table[key] = value
    params = LbrPeerParams.from_table(table)
    return zenoh_with_options(cfg.zenoh, a), params, sim_params_for_peer(cfg.table("sim"), params)


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    log_to_stderr("lbr-peer", a.verbose)
    try:
        zenoh_settings, params, sim_params = load(a)
        wanted_nice(REALTIME)  # a bad LAMPS_NICE is refused with the rest of the configuration
        RealtimeRequest.from_env()  # and a bad LAMPS_RT_PRIORITY, LAMPS_MLOCK or LAMPS_CPUS
        from arm.joint_dynamics import joint_dynamics_from_config
        from arm.robot_model import RobotModel
        from sim.core import SimCore

        core = SimCore(sim_params, RobotModel(joints=joint_dynamics_from_config(a.config)))
    except LampsError as exc:
        return refuse(PROG, exc)
    if a.check:
        t = params.topics
        print(f"ok: keys {t.key(t.state)}, {t.key(t.torque_command)}, {t.key(t.wrench)}, {t.key(t.joint_states)}; "
              f"mode {params.mode}, sample time {params.sample_time_s * 1e3:g} ms, update rate "
              f"{params.update_rate_hz:g} Hz, FRI {params.fri_major}, {params.branch} joint names, client command "
              f"mode {params.client_command_mode}, open_loop {str(params.open_loop).lower()}, "
              f"{sim_params.board.preset} board, "
              f"{len(core.dirt.stains)} stains, sim keys under {zenoh_settings.keys.prefix}")
        core.close()
        return 0
    from .peer import SERVICE

    set_service_priority(REALTIME)  # before the Zenoh session starts its threads: they inherit it
    return serve(PROG, SERVICE, zenoh_settings, lambda node: _serve(node, params, sim_params, core),
                 on_open_failure=core.close)


def _serve(node, params, sim_params, core) -> int:
    """Play the lbr stack on its open ``node`` until a stop signal or the stack's exit."""
    from .peer import LbrPeer

    log = logging.getLogger("sim.lbr_stack.peer")
    try:
        peer = LbrPeer(params, sim_params, node, core)
    except Exception:
        core.close()
        raise
    on_stop_signals(peer.stop)
    try:
        steps = peer.run()
    except (RuntimeError, OSError) as exc:
        if peer.stop.is_set():  # stopped while the camera renderer started: the signal reached it too
            log.info("stopped during start-up (%s)", exc)
            return 0
        return refuse(PROG, exc)
    log.info("stopped after %d steps%s", steps, f"; the stack had exited: {peer.stack_exit}" if peer.stack_exit else "")
    return 0


if __name__ == "__main__":
    sys.exit(main())
