"""The benchmarks' services as subprocesses (for ``bench_controller.py`` and ``bench_robot_port.py``, which put the
repository on ``sys.path`` before importing this): a service process with its output in a file, a free port, and
the robot side (``lamps sim``, or the simulated lbr stack behind ``lamps robot --backend lbr``) with a controller,
started, awaited until alive and stopped."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from lampskit.core.skill import save_skill
from lampskit.learn.learn import bundled_skill
from runtime.config import ZenohSettings
from runtime.ports import free_port
from runtime.session import ServiceNode

REPO = Path(__file__).resolve().parent.parent
#: The controller's start-up refusal of a rate its tick timing check says it cannot hold; retried this often.
RATE_REFUSED = "cannot be held on this machine"
MAX_REFUSALS = 3


class BenchError(RuntimeError):
    """A benchmark could not run (a subprocess died, a peer never came up)."""


# ---------------------------------------------------------------------------------------------- processes
class Proc:
    """A service subprocess with its output in a temporary file; ``stop()`` is SIGINT, then kill after 20 s."""

    def __init__(self, name: str, cmd: list[str], log_dir: Path, env: dict[str, str] | None = None,
                 cwd: Path = REPO) -> None:
        self.name = name
        self.log_path = log_dir / f"{name}.log"
        self._log = open(self.log_path, "w+")  # noqa: SIM115 (open for the process's life)
        # a bench's services run plain TCP on loopback on purpose unless given identities (runtime/service_security)
        env = dict(os.environ, PYTHONUNBUFFERED="1", **{"LAMPS_ZENOH_INSECURE": "true", **(env or {})})
        self.proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=self._log, stderr=subprocess.STDOUT, text=True)

    def output(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def check(self) -> None:
        """Raise BenchError (with the output) when the process has exited."""
        if self.proc.poll() is not None:
            raise BenchError(f"{self.name} exited early with code {self.proc.returncode}; its output:\n"
                             f"{self.output()}")

    def stop(self, timeout_s: float = 20.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                print(f"warning: {self.name} did not stop within {timeout_s:.0f} s of SIGINT: killed", file=sys.stderr)
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        return self.proc.returncode


#: The simulated stack set up as docs/real-robot.md has a user set the real one up for torque commands.
LBR_TORQUE_SETUP = {"LAMPS__LBR_PEER__CLIENT_COMMAND_MODE": "torque", "LAMPS__LBR_PEER__OPEN_LOOP": "false",
                    "LAMPS__LBR_PEER__UPDATE_RATE_HZ": "1000", "LAMPS__LBR__OPEN_LOOP": "false"}


def _robot_side(robot: str, mode: str, p1: int, rid: str, bridge: int) -> list[tuple[str, list[str], str]]:
    """(name, argv, liveliness name) of the robot side's processes: the sim, or the lbr peer and the adapter."""
    if robot == "sim":
        return [("sim", [sys.executable, "-m", "sim.cli", "--mode", mode, "--no-camera",
                         "--listen", f"tcp/127.0.0.1:{p1}", "--robot-id", rid], "sim")]
    return [("lbr-peer", [sys.executable, "-m", "sim.lbr_stack.cli", "--mode", mode,
                          "--listen", f"tcp/127.0.0.1:{bridge}", "--robot-id", rid], "lbr-peer"),
            ("robot", [sys.executable, "-m", "robot.cli", "--backend", "lbr", "--mode", mode, "--arm",
                       "--connect", f"tcp/127.0.0.1:{bridge}", "--listen", f"tcp/127.0.0.1:{p1}",
                       "--robot-id", rid], "robot")]


def _wait_listening(proc: Proc, port: int, timeout_s: float = 60.0) -> None:
    """Return once ``proc`` accepts TCP connections on ``port``; BenchError when it exits or times out."""
    end = time.monotonic() + timeout_s
    while True:
        proc.check()
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        if time.monotonic() > end:
            raise BenchError(f"{proc.name} did not listen on {port} within {timeout_s:.0f} s:\n{proc.output()}")
        time.sleep(0.1)


def _as_clients(side: list[tuple[str, list[str], str]], ctl_cmd: list[str], router: str):
    """The robot side and the controller as clients of the router at ``router`` (each ``--listen``/``--connect``
    pair replaced by one ``--connect`` to it): no link between them, every sample goes through it."""
    def client(cmd: list[str]) -> list[str]:
        out, i = [], 0
        while i < len(cmd):
            if cmd[i] in ("--listen", "--connect"):
                i += 2
                continue
            out.append(cmd[i])
            i += 1
        return [*out, "--connect", router]

    return [(n, client(c), a) for n, c, a in side], client(ctl_cmd)


@contextlib.contextmanager
def sim_and_controller(mode: str, robot: str = "sim", env: dict[str, str] | None = None, router: bool = False):
    """(node, robot-side Proc, controller Proc, refusals) once all are alive; all stopped on exit. env : added
    to every process's environment.

    robot ``"sim"``: ``lamps sim``; ``"lbr"``: ``lamps lbr-peer`` (the arm behind lbr_fri_ros2_stack's
    CDR keys) and ``lamps robot --backend lbr --arm`` in front of it. The controller sees ``robot/*`` alike.
    router : ``lamps router`` as a process of its own (plain TCP, as the peers here), the robot side and the
    controller its clients (``LAMPS_ZENOH_MODE=client``, no listen endpoint): every state and command one hop more.
    """
    p1, p2, bridge = free_port(), free_port(), free_port()
    rid = f"bench{p1}"
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        skill = save_skill(Path(tmp) / "skill.json", bundled_skill())
        ctl_cmd = [sys.executable, "-m", "controller.cli", "--mode", mode, "--stains-from", "truth", "--skill",
                   str(skill), "--connect", f"tcp/127.0.0.1:{p1}", "--listen", f"tcp/127.0.0.1:{p2}",
                   "--robot-id", rid]
        procs = []
        stack.callback(lambda: [p.stop() for p in reversed(procs)])
        side = _robot_side(robot, mode, p1, rid, bridge)
        if router:
            if robot != "sim":
                raise BenchError("through the router: the sim only (the lbr peer's link to its adapter is direct)")
            ends = (free_port(),)
            side, ctl_cmd = _as_clients(side, ctl_cmd, f"tcp/127.0.0.1:{ends[0]}")
            env = dict(env or {}, LAMPS_ZENOH_MODE="client")
            procs.append(Proc("router", [sys.executable, "-m", "runtime.cli", "router", "--listen",
                                         f"tcp/127.0.0.1:{ends[0]}", "--status-s", "0", "--robot-id", rid],
                              Path(tmp)))
            _wait_listening(procs[-1], ends[0])
        side_env = dict(env or {}, **(LBR_TORQUE_SETUP if robot != "sim" else {}))
        for name, cmd, _ in side:
            procs.append(Proc(name, cmd, Path(tmp), side_env))
            time.sleep(0.5)  # let each listener come up before the next one dials it
        n_side = len(procs)
        procs.append(Proc("controller", ctl_cmd, Path(tmp), env))
        if not router:
            ends = (p1, p2) if robot == "sim" else (p1, p2, bridge)  # the peer has the truth and the sim status
        settings = ZenohSettings(connect=tuple(f"tcp/127.0.0.1:{p}" for p in ends), robot_id=rid,
                                 mode="client" if router else "peer")
        node = stack.enter_context(ServiceNode("bench", settings))
        want = {alive for _, _, alive in side} | {"controller"}
        end = time.monotonic() + 60.0
        refusals: list[str] = []
        while True:
            ctl = procs[-1]
            if ctl.proc.poll() is not None and RATE_REFUSED in ctl.output() and len(refusals) < MAX_REFUSALS:
                # the controller's start-up timing check (300 ticks) is noisy on a loaded machine: try again
                refusals.append(ctl.output().strip().splitlines()[-1])
                print(f"note: controller refused to start ({refusals[-1]}); starting it again", file=sys.stderr)
                ctl.stop()
                procs.append(Proc(f"controller{len(refusals)}", ctl_cmd, Path(tmp), env))
                continue
            for p in (*procs[:n_side], procs[-1]):  # the router too
                p.check()
            if want <= node.alive_services(0.5):
                break
            if time.monotonic() > end:
                raise BenchError(f"{sorted(want)} not all alive after 60 s; outputs:\n"
                                 + "\n".join(f"--- {p.name}\n{p.output()}" for p in procs))
            time.sleep(0.2)
        yield node, procs[n_side - 1], procs[-1], refusals
