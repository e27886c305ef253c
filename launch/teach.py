"""``lamps teach``: hand-guide the arm through a wiping, record the pad's path, write a demonstration.

The controller runs in teach mode (:mod:`controller.teach`: no stiffness, light damping, gravity compensated
unless the robot adds it, the speed brakes, joint-limit repulsion, torque limits and a contact-force cap on);
the pad's path is the forward kinematics of the robot's own joint states, sampled at ``--rate`` (200 Hz, what
the learner is tuned for), from start until Enter, Ctrl-C or ``--duration``; the file (CSV ``t,x,y,z,qx,qy,qz,qw``
or NPZ, as ``lamps learn`` reads them) is written atomically, and only when teaching ended without a halt.

- ``--no-network``: the simulator, in one process (:func:`launch.teach_cell.run_local`). The operator's hand is a
  script (``--hand FILE``, see :mod:`sim.hand`) or, by default, a synthetic person wiping ``--stains`` stains
  (:mod:`launch.teach_hand`, the generator of ``lamps demo-data`` placed on the sim's board), written beside the
  output as ``<name>-hand.csv`` so the run can be replayed.
- otherwise: a teach controller on the cell's network (``--config``, ``--connect``), the robot side running
  apart (``lamps robot --backend lbr`` armed, or ``lamps sim``); docs/real-robot.md#teaching-on-the-robot.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from pathlib import Path

from lampskit.errors import LampsError

from .teach_cell import PathRecorder, TeachError

#: After the hand script ends, the sim runs on this long [s] (the pad settles where the hand left it).
SETTLE_S = 0.5


def build_parser() -> argparse.ArgumentParser:
    from runtime.config import add_zenoh_options

    p = argparse.ArgumentParser(prog="lamps teach", description=(
        "Teach mode: the arm is hand-guided (no stiffness, light damping, gravity compensated, the force and "
        "speed guards on) and the pad's path is recorded into a demonstration file for 'lamps learn'. Stops on "
        "Enter, Ctrl-C or --duration. --no-network: in the simulator, the operator's hand a script."))
    p.add_argument("--out", required=True, metavar="FILE", help="the demonstration to write (.csv or .npz)")
    p.add_argument("--duration", type=float, metavar="S",
                   help="stop after S s of robot time (default: the sim's hand script; on a robot: Enter/Ctrl-C)")
    p.add_argument("--rate", type=float, default=200.0, metavar="HZ", help="recording rate (default 200)")
    p.add_argument("--config", metavar="FILE", help="TOML config: [zenoh], [controller] (its [controller.teach] "
                                                   "table), and with --no-network [sim] and [joints]")
    p.add_argument("--no-network", action="store_true",
                   help="the simulated cell in one process, the operator's hand a script (lock-step)")
    p.add_argument("--hand", metavar="FILE",
                   help="--no-network: the hand's script, CSV t,x,y,z (a path, world frame) or t,fx,fy,fz (a force); "
                        "default: a synthetic person wiping --stains stains, written to <out>-hand.csv")
    p.add_argument("--stains", type=int, default=3, help="the synthetic hand: stains it wipes (default 3)")
    p.add_argument("--seed", type=int, default=0, help="the synthetic hand: its seed (default 0)")
    p.add_argument("--press", type=float, default=10.0, metavar="N",
                   help="the synthetic hand: how hard it presses the pad on the board (default 10 N)")
    p.add_argument("--board", default="vertical", metavar="vertical|horizontal|FILE.toml",
                   help="--no-network: the sim's board (as lamps up --board)")
    add_zenoh_options(p)
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens")
    return p


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING,
                        format="lamps teach %(levelname)s: %(message)s")
    from runtime.stop_signals import on_stop_signals

    stop = threading.Event()
    on_stop_signals(stop)
    try:
        return _teach(a, stop)
    except (LampsError, OSError) as exc:
        print(f"lamps teach: error: {exc}", file=sys.stderr)
        return 1


def _check(a) -> Path:
    out = Path(a.out)
    if out.suffix.lower() not in (".csv", ".npz"):
        raise TeachError(f"--out {a.out}: write a .csv or a .npz (what lamps learn reads)")
    if not out.parent.is_dir():
        raise TeachError(f"--out {a.out}: no folder {out.parent}")
    if a.duration is not None and not 0.5 <= a.duration <= 3600.0:
        raise TeachError(f"--duration must be in [0.5, 3600] s, got {a.duration:g}")
    if not 20.0 <= a.rate <= 1000.0:
        raise TeachError(f"--rate must be in [20, 1000] Hz, got {a.rate:g}")
    if not a.no_network and a.hand:
        raise TeachError("--hand is the simulator's (--no-network): on the network the hand is the operator's own")
    if not 1 <= a.stains <= 8 or a.seed < 0 or not 1.0 <= a.press <= 30.0:
        raise TeachError(f"the synthetic hand: --stains in [1, 8], --seed >= 0, --press in [1, 30] N; got "
                         f"{a.stains}, {a.seed}, {a.press:g}")
    return out


def _teach(a, stop: threading.Event) -> int:
    from arm.joint_dynamics import joint_dynamics_from_config
    from arm.robot_model import RobotModel
    from controller.params import ControllerParams
    from runtime.config import load_config

    out = _check(a)
    cfg = load_config(a.config)
    ctrl_table = {k: (dict(v) if isinstance(v, dict) else v) for k, v in cfg.table("controller").items()}
    joints = joint_dynamics_from_config(a.config)
    model = RobotModel(joints=joints)
    recorder = PathRecorder(a.rate)
    if a.no_network:
        from .teach_cell import run_local

        ctrl_table["mode"] = "lockstep"
        ctrl_p = ControllerParams.from_table(ctrl_table)
        sim_p, duration = _sim_with_hand(a, cfg, out, model)
        print(f"lamps teach: the simulated cell, the hand {sim_p.hand.script}; {duration:.1f} s of robot time",
              flush=True)
        why = run_local(sim_p, ctrl_p, joints, recorder, duration, stop, _note)
    else:
        from runtime.config import zenoh_with_options

        from .teach_cell import run_network

        ctrl_p = ControllerParams.from_table(ctrl_table)
        settings = zenoh_with_options(cfg.zenoh, a)
        _enter_stops(stop)
        print(f"lamps teach: teach mode on {settings.keys.prefix} ({ctrl_p.mode}); guide the arm, Enter or "
              "Ctrl-C stops", flush=True)
        why = run_network(settings, ctrl_p, model, recorder, a.duration, stop, _note)
    return _write(out, recorder, model, why)


def _note(line: str) -> None:
    print(line, flush=True)


def _enter_stops(stop: threading.Event) -> None:
    """Enter on a terminal stops teaching (a daemon thread waits for the line)."""
    if not sys.stdin.isatty():
        return

    def wait() -> None:
        sys.stdin.readline()
        stop.set()

    threading.Thread(target=wait, name="teach-enter", daemon=True).start()


def _sim_with_hand(a, cfg, out: Path, model):
    """The sim's parameters with the hand (``--hand``, or a synthetic one written beside ``out``), no camera,
    lock-step; and the robot time to teach for."""
    from sim.board import board_from_params, start_configuration, wipe_region
    from sim.hand import HandScript
    from sim.params import SimParams

    from .cli import board_env

    table = {k: (dict(v) if isinstance(v, dict) else v) for k, v in cfg.table("sim").items()}
    env = board_env(a.board)
    board_table = dict(table.get("board", {}))
    if "LAMPS_BOARD" in env:
        board_table = {"preset": env["LAMPS_BOARD"]}
    else:
        import json

        board_table = {k.removeprefix("LAMPS__SIM__BOARD__").lower(): json.loads(v) for k, v in env.items()}
    table.update(mode="lockstep", board=board_table, camera={**table.get("camera", {}), "enabled": False})
    base = SimParams.from_table(table)
    if a.hand:
        script = HandScript.read(a.hand)
        hand_file = Path(a.hand)
    else:
        from .teach_hand import hand_path, write_hand_csv

        board = board_from_params(base.board)
        q0 = (base.start_q_rad if base.start_q_rad is not None
              else start_configuration(board, base.start_standoff_m, model))
        start_p, _ = model.tcp_pose(q0)
        path = hand_path(board, start_p, wipe_region(board, base.dirt.margin_m), n_stains=a.stains, seed=a.seed,
                         press_n=a.press, stiffness_n_m=base.hand.stiffness_n_m)
        hand_file = write_hand_csv(out.with_name(out.stem + "-hand.csv"), path)
        script = HandScript.read(hand_file)
    table["hand"] = {**table.get("hand", {}), "script": str(hand_file)}
    duration = a.duration if a.duration is not None else script.duration_s + SETTLE_S
    return SimParams.from_table(table), duration


def _write(out: Path, recorder: PathRecorder, model, why: str) -> int:
    from lampskit.learn.demo import Demonstration
    from lampskit.learn.demo_io import write_demo_csv, write_demo_npz

    if len(recorder.t_ns) < 50:
        raise TeachError(f"teaching ended ({why}) after {len(recorder.t_ns)} samples: too short to learn from; "
                         "nothing written")
    t, p, quat = recorder.pad_path(model)
    demo = Demonstration(t, p, quat, source=f"lamps teach ({why})")
    (write_demo_npz if out.suffix.lower() == ".npz" else write_demo_csv)(out, demo)
    length = float(sum(((p[1:] - p[:-1]) ** 2).sum(axis=1) ** 0.5))
    print(f"lamps teach: {why}; wrote {out}: {len(t)} samples over {t[-1]:.1f} s, the pad moved {length:.2f} m; "
          f"next: lamps learn {out} -o skill.json", flush=True)
    return 0
