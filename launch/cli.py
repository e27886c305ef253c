"""``lamps up``: the whole cell from docker-compose.yml as local processes, recorded and reported.

``lamps up`` learns the skill (the bundled demo by default), starts every
service of the compose file as a local process with the compose command and
environment (:mod:`launch.compose`), shows progress, ends when the controller
stays DONE (or on a fault held 5 s, a dead service, ``--max-duration`` or
Ctrl-C), stops everything and prints the report the recorder wrote into the
run folder. The recorder's own command, ``lamps record``, and ``lamps report``
are in :mod:`launch.record_cli`.

``--router ENDPOINT --credentials DIR`` runs the cell's services as clients
of a Zenoh router with the cell's identities from ``DIR``; ``--cells N``
runs N such cells side by side through one router (:mod:`launch.site`).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
import threading
import time
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

from lampskit.errors import LampsError

from .run_end import RunEnd

#: ``--robot``: the compose profile of the robot side (``real`` needs a robot and is compose's alone).
ROBOTS = ("sim", "lbr-sim")
BOARDS = {"vertical": "wall", "wall": "wall", "horizontal": "table", "table": "table"}


class UpError(LampsError):
    """A clear, one-line reason why the cell could not run."""


def _print(line: str) -> None:
    print(line, flush=True)


def build_up_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lamps up", description=(
        "Run the whole cell (sim, controller, perception, recorder) as docker-compose.yml describes it, as local "
        "processes. Without options: the bundled demo is learned, a wall board gets 3 random stains, the robot "
        "cleans it; the run folder gets report.json, plots and an MCAP recording."))
    p.add_argument("--seed", type=int, default=0, help="stains: count, places, shapes (default 0)")
    p.add_argument("--stains", type=int, default=3, help="number of random stains (default 3)")
    p.add_argument("--board", default="vertical", metavar="vertical|horizontal|random:N|FILE.toml",
                   help="board preset, random:N (the reachable board drawn from seed N), or a TOML file with a [board] "
                        "table (preset = \"custom\", origin_m, quat_wxyz, size_m; see config/example.toml [sim.board])")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--skill", metavar="FILE", help="skill file from 'lamps learn' (default: learn the bundled demo)")
    src.add_argument("--demo", metavar="FILE", help="learn this demonstration first (CSV, NPZ, TSV, MAT#i)")
    p.add_argument("--robot", choices=ROBOTS, default=None,
                   help="the robot side: sim (PyBullet) or lbr-sim (the same arm behind lbr_fri_ros2_stack's "
                        "messages, driven by the real-robot adapter); default: COMPOSE_PROFILES of the environment "
                        "or the compose file's .env (sim)")
    p.add_argument("--foxglove", nargs="?", type=int, const=8765, default=None, metavar="PORT",
                   help="also serve the cell live to the Foxglove app on ws://127.0.0.1:PORT (default 8765; the "
                        "compose profile foxglove)")
    p.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep",
                   help="lockstep: deterministic, as fast as the machine goes (default); realtime: 1 kHz wall clock")
    p.add_argument("--max-duration", type=float, default=600.0, metavar="S",
                   help="give up after S s wall (default 600)")
    p.add_argument("--out", metavar="DIR", help="run folder (default runs/<time>)")
    p.add_argument("--compose", metavar="FILE", help="compose file (default: docker-compose.yml of this checkout)")
    p.add_argument("--port-base", type=int, metavar="N",
                   help="listen on N, N+1, ... (default: free ports); a busy port is refused before anything starts")
    p.add_argument("--robot-id", default=None,
                   help="key prefix lamps/<robot-id> (default iiwa; with --cells the cells are <robot-id>-1 ... -N)")
    p.add_argument("--cells", type=int, metavar="N", default=None,
                   help="N cells side by side through one lamps router, each with its own identities (one CA), "
                        "seed (SEED, SEED+1, ...) and run folder OUT/<robot id>/; --port-base: the router's port")
    p.add_argument("--router", metavar="ENDPOINT", default=None,
                   help="every service a client of the Zenoh router at ENDPOINT (tls/HOST:PORT), no peer links; "
                        "needs --credentials")
    p.add_argument("--credentials", metavar="DIR", default=None,
                   help="the cell's identities: a folder of 'lamps credentials DIR', or DIR/<robot id> of "
                        "'lamps credentials DIR --cells ...' (its robot id is the cell's); default: new ones in "
                        "the run folder")
    p.add_argument("--no-network", action="store_true",
                   help="lock-step, sim only: the same services in one process on an in-process bus, no Zenoh "
                        "(launch/local_cell.py; what lamps campaign --no-network runs)")
    p.add_argument("-q", "--quiet", action="store_true", help="do not echo the services' logs")
    p.add_argument("-v", "--verbose", action="store_true", help="log what the launcher does")
    return p


def board_env(board: str) -> dict[str, str]:
    """Compose variables and service environment for ``--board``."""
    if board in BOARDS:
        return {"LAMPS_BOARD": BOARDS[board]}
    if board.startswith("random:"):  # sim/board_sampler.py: the board of seed N over the reachable workspace
        from sim.board_sampler import random_board_table
        try:
            return {f"LAMPS__SIM__BOARD__{k.upper()}": json.dumps(v) for k, v in random_board_table(board).items()}
        except ValueError as exc:
            raise UpError(f"--board {board}: {exc}") from None
    path = Path(board)
    if not path.is_file():
        raise UpError(f"--board {board!r}: not one of {sorted(set(BOARDS))} and no such file")
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise UpError(f"--board {board}: not valid TOML ({exc})") from None
    table = table.get("sim", {}).get("board", table.get("board"))
    if not isinstance(table, dict) or not table:
        raise UpError(f"--board {board}: no [board] table")
    return {f"LAMPS__SIM__BOARD__{k.upper()}": json.dumps(v) for k, v in table.items()}


def _learn(a, out: Path, echo, stop_requested: threading.Event) -> Path:
    """The skill file to run: given, learned from --demo, or learned from the bundled demo."""
    from .procs import Child

    if a.skill:
        skill = Path(a.skill).resolve()
        if not skill.is_file():
            raise UpError(f"--skill {a.skill}: no such file")
        return skill
    learn = out / "learn"
    lamps = (sys.executable, "-m", "runtime.cli")
    if a.demo:
        if not Path(a.demo.split("#")[0]).is_file():
            raise UpError(f"--demo {a.demo}: no such file")
        argv: tuple[str, ...] = (*lamps, "learn", a.demo, "-o", str(learn / "skill.json"), "--plots", str(learn))
    else:  # the controller's own default: the bundled synthetic demonstration, 3 stains, seed 0
        argv = (*lamps, "demo", "--stains", "3", "--seed", "0", "--out", str(learn))
    child = Child("learn", argv, {"MPLBACKEND": "Agg"}, out / "logs", echo)
    while child.returncode is None:
        if stop_requested.is_set():
            child.stop()
            raise UpError("stopped by the user while learning the skill")
        time.sleep(0.1)
    code = child.stop()
    if code != 0 or not (learn / "skill.json").is_file():
        raise UpError(f"learning the skill failed (exit {code}): {child.last_words()}")
    return (learn / "skill.json").resolve()


def up_main(argv: list[str] | None = None) -> int:
    a = build_up_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING,
                        format="lamps up %(levelname)s: %(message)s")
    from runtime.stop_signals import on_stop_signals

    stop_requested = threading.Event()
    on_stop_signals(stop_requested)
    try:
        return _up(a, stop_requested)
    except LampsError as exc:
        print(f"lamps up: error: {exc}", file=sys.stderr)
        return 1


def _up(a, stop_requested: threading.Event) -> int:
    from .compose import DEFAULT_COMPOSE, compose_model

    _check_options(a)
    board_vars = board_env(a.board)
    out = _new_run_folder(a.out)
    echo = None if a.quiet else _print
    compose_path = Path(a.compose) if a.compose else DEFAULT_COMPOSE
    # read the compose file before learning: a broken one should not cost the learning time
    model = compose_model(compose_path, dict(os.environ))
    if a.verbose:
        _print(f"lamps up: {compose_path} read by {model.reader}")

    t_start = time.monotonic()
    skill = _learn(a, out, echo, stop_requested)
    if a.cells is not None:
        from .site import run_cells

        return run_cells(a, skill, out, stop_requested)
    cell = plan_cell(a, compose_path, board_vars, skill, out)
    if a.no_network:
        from .local_cell import run as run_local

        _print(f"lamps up: the cell in one process, no network; run folder {cell.out}")
        why = run_local(cell.services, cell.env, out, cell.robot_id, skill, dict(vars(a)), a.max_duration,
                        stop_requested, lambda *p: _print(_progress(*p)) if echo else None)
    else:
        why = _run_cell(cell, a, echo, stop_requested, t_start)
    return show_report(out, why)


def _check_options(a) -> None:
    """The numeric options in range (the others are checked where they are used)."""
    if a.no_network and (a.mode != "lockstep" or a.foxglove is not None or a.robot not in (None, "sim")
                         or a.cells is not None or a.router):
        raise UpError("--no-network runs one simulated cell in lock-step only (no --mode realtime, --foxglove, "
                      "--robot lbr-sim, --cells, --router: they need the network)")
    if a.stains < 0 or a.stains > 50:
        raise UpError(f"--stains must be in [0, 50], got {a.stains}")
    if not (a.max_duration > 0 and math.isfinite(a.max_duration)):
        raise UpError(f"--max-duration must be a positive number of seconds, got {a.max_duration}")
    if a.foxglove is not None:
        if not 0 < a.foxglove < 65536:
            raise UpError(f"--foxglove PORT must be in 1..65535, got {a.foxglove}")
        if _port_busy(a.foxglove):
            raise UpError(f"--foxglove {a.foxglove}: the port is already in use (give another)")
    if a.cells is not None:
        if not 1 <= a.cells <= 16:
            raise UpError(f"--cells must be in [1, 16], got {a.cells}")
        if a.router or a.credentials:
            raise UpError("--cells makes the router and the cells' credentials itself: not with --router or "
                          "--credentials")
        if a.robot == "lbr-sim":  # the lbr stack's ROS topics (lbr/**) are outside the cells' prefixes
            raise UpError("--cells runs --robot sim only: the lbr stack's ROS namespaces would be shared")
    if a.router and not (a.credentials and a.router.startswith("tls/")):
        raise UpError(f"--router {a.router}: a tls/HOST:PORT endpoint and --credentials DIR (the cell's identities)")


def _new_run_folder(out_option: str | None) -> Path:
    """The run folder (``--out``, default ``runs/<time>``), created; refused if it holds anything."""
    out = Path(out_option) if out_option else Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    if out.exists() and any(out.iterdir()):
        raise UpError(f"--out {out}: exists and is not empty (a run folder is never overwritten)")
    out.mkdir(parents=True, exist_ok=True)
    return out.resolve()


@dataclass(frozen=True)
class _Cell:
    """What ``lamps up`` runs: the services as local processes, in start order, and where they write."""

    services: list  # LocalService, localised from the compose file
    env: dict[str, str]  # added to every service's environment (the board table of a --board file)
    robot_id: str
    skill: Path
    out: Path
    credentials: Path  # the run's per-role identities (each container's /secrets is one role's folder)
    access_control: bool
    router: str | None = None  # every service a client of this router (--router)


def plan_cell(a, compose_path: Path, board_vars: dict[str, str], skill: Path, out: Path) -> _Cell:
    """The compose file read with the run's variables, its active services localised on their ports."""
    from .compose import compose_model, localize, run_locally
    from .site import cell_credentials

    credentials = cell_credentials(a, out)
    model = compose_model(compose_path, _compose_variables(a, board_vars, skill, out))
    if a.foxglove is not None:
        model = replace(model, profiles=(*model.profiles, "foxglove"))
    services = run_locally(model.active())
    sides = [s.name for s in services if "robot" in s.aliases]
    if len(sides) != 1:
        raise UpError(f"{compose_path}: profiles {','.join(model.profiles) or '(none)'} give "
                      f"{len(sides)} robot sides ({', '.join(sides) or 'none'}); choose one with --robot "
                      f"{'|'.join(ROBOTS)} or COMPOSE_PROFILES")
    router = getattr(a, "router", None)
    local = localize(services, None if router else _port_map(services, a.port_base), secrets=credentials)
    if router:
        from .site import clients_of_router

        local = clients_of_router(local, router)
    robot_id = next((rid for s in local if (rid := s.environment.get("LAMPS_ROBOT_ID"))), "iiwa")
    access = any(s.environment.get("LAMPS_ZENOH_ACCESS_CONTROL", "false").lower() == "true" for s in local)
    return _Cell(services=local, env={k: v for k, v in board_vars.items() if k.startswith("LAMPS__")},
                 robot_id=robot_id, skill=skill, out=out, credentials=credentials, access_control=access, router=router)


def _compose_variables(a, board_vars: dict[str, str], skill: Path, out: Path) -> dict[str, str]:
    """The environment plus the ``LAMPS_*`` variables docker-compose.yml substitutes, from the options."""
    variables = dict(os.environ)
    if a.robot:
        variables["COMPOSE_PROFILES"] = a.robot
    # the recorder runs until lamps up stops it (it writes the report after run.json)
    variables["LAMPS_RECORD_UNTIL"] = "stopped"
    variables.update(LAMPS_SEED=str(a.seed), LAMPS_STAINS=str(a.stains), LAMPS_MODE=a.mode, LAMPS_SKILL=str(skill),
                     LAMPS_OUT=str(out), **{k: v for k, v in board_vars.items() if k == "LAMPS_BOARD"})
    if a.robot_id:
        variables["LAMPS_ROBOT_ID"] = a.robot_id
    if a.foxglove is not None:
        variables["LAMPS_FOXGLOVE_PORT"] = str(a.foxglove)
    return variables


def _port_map(services, port_base: int | None) -> dict[tuple[str, int], int] | None:
    """(service, compose port) -> port_base, port_base + 1, ... in service order; None (free ports) without a base.

    Every port is checked before anything starts: a busy one is refused, naming its service.
    """
    from .compose import listen_ports

    if port_base is None:
        return None
    port_of, n = {}, port_base
    for s in services:
        for p in listen_ports(s):
            port_of[(s.name, p)] = n
            n += 1
    for (name, _), port in port_of.items():
        if _port_busy(port):
            raise UpError(f"service {name}: port {port} is already in use (choose another --port-base)")
    return port_of


def _run_cell(cell: _Cell, a, echo, stop_requested: threading.Event, t_start: float) -> str:
    """Start the services, watch the run, stop everything and write ``run.json``; returns why the run ended."""
    children: list = []
    outcome, why = "stopped", "stopped by the user"
    node = None
    try:
        if cell.router:  # the services come up through the router: watched from the start, by their tokens
            try:
                node = _watcher(cell).__enter__()
            except Exception as exc:  # zenoh.ZError: no router there, or it refused the operator's certificate
                raise UpError(f"cannot join the router {cell.router}: {exc}") from None
        _start_services(cell, echo, children, node)
        _print(f"lamps up: {', '.join(c.name for c in children)} running; run folder {cell.out}")
        if a.foxglove is not None:
            _print(f"lamps up: live in Foxglove: Open connection ws://127.0.0.1:{a.foxglove} "
                   f"(layout config/foxglove/lamps.json)")
        outcome, why = _watch(cell, children, a.max_duration, stop_requested, node)
    except UpError as exc:
        outcome, why = "failed", str(exc)
        print(f"lamps up: error: {exc}", file=sys.stderr)
    finally:
        if node is not None:
            node.close()
        stop_services(children, cell, {"outcome": outcome, "why": why}, a, t_start)
    return why


def _start_services(cell: _Cell, echo, children: list, node=None) -> None:
    """Start the services in order, each listening on its ports (through a router: its liveliness token seen by
    ``node``, counted, as a service names its token itself: ``robot``, not ``robot-lbr-sim``) before the next
    one starts.

    ``children`` gets each child as it starts, so whatever started is stopped when a later one fails.
    """
    from .procs import Child, wait_port

    for svc in cell.services:
        child = Child(svc.name, svc.argv, {**svc.environment, **cell.env, "MPLBACKEND": "Agg"}, cell.out / "logs",
                      echo)
        children.append(child)
        deadline = time.monotonic() + 120.0
        while node is not None and len(node.alive_services(0.5) - {"launcher"}) < len(children):
            if child.returncode is not None or time.monotonic() > deadline:
                raise UpError(f"service {svc.name} did not come up through the router {cell.router}: "
                              f"{child.last_words()}")
        for port in svc.listen_ports:
            if not wait_port(port, child, 120.0):
                code = child.returncode
                raise UpError(f"service {svc.name} failed at start-up"
                              + (f" (exit {code})" if code is not None else " (not listening after 120 s)")
                              + f": {child.last_words()}")


def stop_services(children: list, cell: _Cell, ended: dict[str, str], a, t_start: float) -> None:
    """Stop the services (the loops in reverse start order), write ``run.json``, then stop the recorder (its report
    reads it).

    ended : ``outcome`` and ``why`` of the run, the first fields of ``run.json``
    """
    from lampskit.atomic import write_text_atomic

    codes = {}
    stopping_ns = time.time_ns()  # services go silent one by one from here on: not a fault
    services = [c for c in children if c.name != "recorder"]
    loops = {s.name for s in cell.services if s.loop}
    # the background services (nice +10) get almost no CPU while the loops (nice -10) spin, as a lock-step cell
    # does to the end: they are asked first and waited for last, once the loops are gone (a starved perception
    # once took over the 10 s before SIGKILL); the loops stop in reverse start order (the controller lifts the
    # pad before its robot goes)
    background = [c for c in services if c.name not in loops]
    for c in background:
        c.terminate()
    for c in reversed([c for c in services if c.name in loops]):
        codes[c.name] = c.stop()
    for c in background:
        codes[c.name] = c.stop()
    run = {**ended, "stopping_wall_ns": stopping_ns, "ended_wall_ns": time.time_ns(),
           "duration_s": time.monotonic() - t_start, "services": codes,
           "key_prefix": f"lamps/{cell.robot_id}", "skill": str(cell.skill),
           "options": {k: v for k, v in vars(a).items()}}
    write_text_atomic(cell.out / "run.json", json.dumps(run, indent=1) + "\n")
    for c in children:
        if c.name == "recorder":
            c.stop(timeout_s=120.0)


def show_report(out: Path, why: str) -> int:
    """Print the summary of the report the recorder wrote, or build it from the recording, recovering a recording
    the recorder left unfinished (it died: ``recording.mcap.partial``); 0 if cleaned."""
    from .record import RECORDING, recover_recording

    final, partial = out / RECORDING, out / (RECORDING + ".partial")
    if not (out / "report.json").is_file() and not final.is_file() and partial.is_file():
        try:
            n = recover_recording(partial, final)
        except OSError as exc:
            print(f"lamps up: the recorder did not finish and {partial} cannot be recovered: {exc}", file=sys.stderr)
            return 1
        _print(f"the recorder did not finish: recovered {n} messages from {partial.name}")
    if not (out / "report.json").is_file() and not final.is_file():
        print(f"lamps up: no recording in {out}: {why}", file=sys.stderr)
        return 1
    from .report import summary_lines, write_report

    report = json.loads((out / "report.json").read_text()) if (out / "report.json").is_file() else write_report(out)
    for line in summary_lines(report):
        _print(line)
    _print(f"report: {out / 'report.json'}; recording: {out / 'recording.mcap'} (opens in Foxglove)")
    if report["outcome"] != "cleaned":
        print(f"lamps up: the board was not cleaned ({report['outcome']}: {why})", file=sys.stderr)
        return 1
    return 0


def _port_busy(port: int) -> bool:
    from runtime.ports import bindable

    return not bindable(port)


def _watcher(cell: _Cell):
    """The launcher's session, as the operator (its identity is in the run's credentials whether or not the list is
    on): linked to every service, or a client of the router."""
    from runtime.config import ZenohSettings
    from runtime.credentials import identity_folder
    from runtime.session import ServiceNode

    endpoints = tuple(e for s in cell.services for e in s.listen_endpoints)
    settings = ZenohSettings(connect=(cell.router,) if cell.router else endpoints,
                             mode="client" if cell.router else "peer", robot_id=cell.robot_id,
                             access_control=cell.access_control,
                             identity=str(identity_folder(cell.credentials, "operator")))
    return ServiceNode("launcher", settings)


def _watch(cell: _Cell, children, max_duration_s: float, stop_requested, node=None) -> tuple[str, str]:
    """Progress on the terminal until the run ends (``node``: the launcher's session if open); returns (outcome
    for run.json, why)."""
    from contextlib import nullcontext

    from interfaces.messages import ControllerStatus, SimTruth, Stains

    t0 = time.monotonic()
    with nullcontext(node) if node is not None else _watcher(cell) as node:
        keys = node.keys
        status = node.latest(keys.controller_status, ControllerStatus)
        truth = node.latest(keys.sim_truth, SimTruth)
        stains = node.latest(keys.perception_stains, Stains)
        st = tr = sn = None
        end = RunEnd()
        first_dirt = None
        next_print = 0.0
        while True:
            now = time.monotonic()
            if stop_requested.is_set():
                return "stopped", "stopped by the user (Ctrl-C)"
            for c in children:
                if c.returncode is not None:
                    raise UpError(f"service {c.name} exited with code {c.returncode}: {c.last_words()}")
            if now - t0 > max_duration_s:
                return "timeout", f"not finished after --max-duration {max_duration_s:g} s"
            st = status.take() or st
            tr = truth.take() or tr
            if first_dirt is None and tr is not None and tr.total_dirt > 0:
                first_dirt = tr.total_dirt
            sn = stains.take() or sn
            if st is not None:
                ended = end.update(st.phase, st.reason, now, st.robot_time_ns * 1e-9)
                if ended is not None:
                    return ended
            if now >= next_print:
                next_print = now + 2.0
                _print(_progress(now - t0, st, tr, sn, first_dirt))
            time.sleep(0.05)


def _progress(t: float, st, tr, sn, first_dirt: float | None) -> str:
    parts = [f"[up {t:5.1f} s]"]
    if tr is not None:
        parts.append(f"robot {tr.robot_time_ns * 1e-9:5.1f} s")
    if st is not None:
        mp = f" {st.current_mp}" if st.current_mp else ""
        parts.append(f"phase {st.phase}{mp}" + (f" ({st.reason})" if st.reason else ""))
        parts.append(f"force {st.normal_force_n:4.1f} N")
    if sn is not None:
        parts.append(f"stains clean {sum(s.kappa for s in sn.stains)}/{len(sn.stains)} (board {sn.board})")
    if tr is not None and first_dirt:
        parts.append(f"dirt removed {1.0 - tr.total_dirt / first_dirt:.0%} (sim truth)")
    return " | ".join(parts)
