"""``lamps sim``: the simulated robot side of the cell as a Zenoh service.

Configuration comes from ``--config FILE`` (TOML, ``[zenoh]`` and ``[sim]``
tables, see :mod:`sim.params`; ``[joints]``, the drives' rotor inertia and
friction, :mod:`arm.joint_dynamics`), then ``LAMPS_*`` environment variables
(:mod:`runtime.config`), then the options below (highest priority).
A broken config file or an impossible board pose is a one-line error and
exit code 1 before anything starts; Ctrl-C or SIGTERM stops it cleanly.
"""

from __future__ import annotations

import argparse
import logging
import sys

from interfaces.errors import InterfaceError
from lampskit.errors import LampsError
from runtime.config import add_zenoh_options, load_config, zenoh_with_options
from runtime.priority import REALTIME, set_service_priority, wanted_nice
from runtime.realtime import RealtimeRequest
from runtime.service_main import log_to_stderr, refuse, serve
from runtime.stop_signals import on_stop_signals

SERVICE = "sim"
PROG = "lamps sim"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="PyBullet iiwa 14 with an eraser, a whiteboard with dirt and a camera, served over Zenoh. "
                    "Options override the config file, which overrides the defaults.")
    p.add_argument("--config", metavar="FILE", help="TOML config with [zenoh], [sim] and [joints] tables")
    p.add_argument("--mode", choices=("lockstep", "realtime"),
                   help="lockstep: step after each answering command (deterministic); realtime: 1 kHz wall clock")
    p.add_argument("--seed", type=int, help="seed of the stains (count, places, shapes)")
    p.add_argument("--stains", type=int, metavar="K", help="number of random stains")
    p.add_argument("--board", choices=("wall", "table"), help="board preset: vertical wall or horizontal table")
    p.add_argument("--gravity-compensated", action="store_true", default=None,
                   help="the robot adds gravity torques itself (like the real iiwa); declared in robot/state")
    p.add_argument("--stale-limit", type=float, metavar="S",
                   help="realtime: brake when the newest command is older than this [s] (default 0.02)")
    p.add_argument("--max-steps", type=int, metavar="N", help="stop after N physics steps (default: run until stopped)")
    p.add_argument("--no-camera", action="store_true", help="do not render camera frames")
    p.add_argument("--camera-size", metavar="WxH", help="camera resolution, e.g. 320x240 (default 640x480)")
    p.add_argument("--camera-rate", type=float, metavar="HZ", help="camera frame rate (default 10)")
    add_zenoh_options(p)
    p.add_argument("--check", action="store_true", help="validate the configuration and the board pose, then exit")
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens")
    return p


def _overrides(a: argparse.Namespace) -> tuple[dict, dict]:
    sim: dict = {}
    camera: dict = {}
    for key, value in (("mode", a.mode), ("seed", a.seed), ("gravity_compensated", a.gravity_compensated),
                       ("stale_limit_s", a.stale_limit), ("max_steps", a.max_steps)):
        if value is not None:
            sim[key] = value
    if a.stains is not None:
        sim.setdefault("dirt", {})["stains"] = a.stains
    if a.board is not None:
        sim["board"] = {"preset": a.board}
    if a.no_camera:
        camera["enabled"] = False
    if a.camera_size is not None:
        try:
            w, h = (int(v) for v in a.camera_size.lower().split("x"))
        except ValueError:
            raise InterfaceError(f"--camera-size must look like 640x480, got {a.camera_size!r}") from None
        camera.update(width=w, height=h)
    if a.camera_rate is not None:
        camera["rate_hz"] = a.camera_rate
    return sim, camera


def _merge(base: dict, extra: dict) -> dict:
    out = dict(base)
    for k, v in extra.items():
        out[k] = _merge(out.get(k, {}), v) if isinstance(v, dict) and isinstance(out.get(k, {}), dict) else v
    return out


def load(a: argparse.Namespace):
    """(ZenohSettings, SimParams) from file, environment and options."""
    from .params import SimParams

    cfg = load_config(a.config)
    sim_over, cam_over = _overrides(a)
    table = _merge(dict(cfg.table("sim")), sim_over)
    if cam_over:
        table = _merge(table, {"camera": cam_over})
    return zenoh_with_options(cfg.zenoh, a), SimParams.from_table(table)


def load_joints(a: argparse.Namespace):
    """The drives' rotor inertia and friction: the ``[joints]`` table of the file, with environment overrides."""
    from arm.joint_dynamics import joint_dynamics_from_config

    return joint_dynamics_from_config(a.config)


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    log_to_stderr("sim", a.verbose)
    try:
        zenoh_settings, params = load(a)
        wanted_nice(REALTIME)  # a bad LAMPS_NICE is refused with the rest of the configuration
        RealtimeRequest.from_env()  # and a bad LAMPS_RT_PRIORITY, LAMPS_MLOCK or LAMPS_CPUS
        from arm.robot_model import RobotModel

        from .core import SimCore

        core = SimCore(params, RobotModel(joints=load_joints(a)))
    except LampsError as exc:
        return refuse(PROG, exc)
    if a.check:
        d = core.dirt
        print(f"ok: {params.board.preset} board {core.board.size_m.tolist()} m, {len(d.stains)} stains, "
              f"mode {params.mode}, keys under {zenoh_settings.keys.prefix}")
        core.close()
        return 0
    set_service_priority(REALTIME)  # before the Zenoh session starts its threads: they inherit it
    return serve(PROG, SERVICE, zenoh_settings, lambda node: _serve(node, params, core), on_open_failure=core.close)


def _serve(node, params, core) -> int:
    """Run the simulator on its open ``node`` until a stop signal."""
    from .service import SimService

    service = SimService(params, node, core)
    on_stop_signals(service.stop)
    try:
        steps = service.run()
    except (RuntimeError, OSError) as exc:
        if service.stop.is_set():  # stopped while starting: the signal reached the renderer too, not a fault
            logging.getLogger("sim").info("stopped during start-up (%s)", exc)
            return 0
        return refuse(PROG, exc)
    logging.getLogger("sim").info("stopped after %d steps", steps)
    return 0


if __name__ == "__main__":
    sys.exit(main())
