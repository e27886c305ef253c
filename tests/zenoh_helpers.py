"""Helpers for tests over real Zenoh on loopback: free ports, bounded waits, a real ``lamps sim`` process."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from interfaces.config import ZenohSettings
from interfaces.messages import RobotState, ServiceStatus, TorqueCommand
from interfaces.session import ServiceNode

REPO = Path(__file__).resolve().parent.parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(predicate, timeout_s: float = 5.0, what: str = "condition"):
    """Poll ``predicate`` until it returns something truthy (fails the test after the timeout)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.005)
    raise AssertionError(f"{what} not met within {timeout_s} s")


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + "}"
    return repr(v)


def write_config(path: Path, port: int, robot_id: str, sim: dict) -> Path:
    """A TOML config: the sim listens on ``port``; ``sim`` holds [sim] keys and sub-tables."""
    lines = ["[zenoh]", f'listen = ["tcp/127.0.0.1:{port}"]', f'robot_id = "{robot_id}"', "", "[sim]"]
    subs = {k: v for k, v in sim.items() if isinstance(v, dict)}
    lines += [f"{k} = {toml_value(v)}" for k, v in sim.items() if k not in subs]
    for name, table in subs.items():
        lines += ["", f"[sim.{name}]"] + [f"{k} = {toml_value(v)}" for k, v in table.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


class SimProcess:
    """``lamps sim`` in its own process with a client node connected to it.

    Use as ``with SimProcess(tmp_path, {"mode": "lockstep"}) as sim: sim.node ...``.
    """

    def __init__(self, tmp_path: Path, sim: dict, name: str = "sim", client: str = "test-client",
                 port: int | None = None) -> None:
        self.port = port or free_port()
        self.robot_id = f"t{self.port}"
        self.config = write_config(tmp_path / f"{name}.toml", self.port, self.robot_id, sim)
        self.client_name = client
        self.proc: subprocess.Popen | None = None
        self.node: ServiceNode | None = None

    def __enter__(self) -> "SimProcess":
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen([sys.executable, "-m", "sim.cli", "--config", str(self.config)], cwd=REPO,
                                     env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        settings = ZenohSettings(connect=(f"tcp/127.0.0.1:{self.port}",), robot_id=self.robot_id)
        self.node = ServiceNode(self.client_name, settings).__enter__()
        try:
            wait_for(lambda: self.proc.poll() is not None or "sim" in self.node.alive_services(0.5), 60.0,
                     "sim liveliness")
            if self.proc.poll() is not None:
                raise AssertionError(f"lamps sim exited with {self.proc.returncode}:\n{self.proc.stdout.read()}")
        except BaseException:
            self.__exit__()
            raise
        return self

    @property
    def keys(self):
        return self.node.keys

    def stop(self, timeout_s: float = 20.0) -> int:
        if self.proc is None or self.proc.poll() is not None:
            return self.proc.returncode if self.proc else 0
        self.proc.send_signal(signal.SIGINT)
        try:
            return self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            raise AssertionError("lamps sim did not stop on SIGINT")

    def output(self) -> str:
        return self.proc.stdout.read() if self.proc and self.proc.poll() is not None else ""

    def __exit__(self, *exc) -> None:
        try:
            self.stop()
        finally:
            if self.node is not None:
                self.node.close()


def run_lockstep(sim: SimProcess, steps: int, policy, timeout_s: float = 120.0) -> list[RobotState]:
    """Answer ``steps`` states with ``policy(state) -> tau (7,)``; returns the states seen (k = 0..steps)."""
    inbox = sim.node.inbox(sim.keys.robot_state, RobotState, maxlen=4)
    out: list[RobotState] = []
    end = time.monotonic() + timeout_s
    expected = None
    while len(out) <= steps:
        if time.monotonic() > end:
            raise AssertionError(f"lock-step stalled after {len(out)} states")
        state = inbox.get(1.0)
        if state is None or (expected is not None and state.seq != expected):
            continue  # a re-sent state we already answered, or one from before we joined
        out.append(state)
        expected = state.seq + 1
        if len(out) > steps:
            break
        tau = np.asarray(policy(state), float)
        sim.node.publish(sim.keys.robot_command, TorqueCommand(seq=state.seq, stamp_ns=time.monotonic_ns(),
                                                               tau_nm=tau.tolist()))
    inbox.close()
    return out


def latest_status(sim: SimProcess, timeout_s: float = 5.0) -> ServiceStatus:
    reader = sim.node.latest(sim.keys.sim_status, ServiceStatus)
    return wait_for(reader.take, timeout_s, "a sim status")
