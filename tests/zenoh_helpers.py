"""Helpers for tests over real Zenoh on loopback: free ports, bounded waits, a real ``lamps sim`` process.

Tests never sleep to let Zenoh settle: they wait, with a timeout that fails
the test naming what did not happen, for a peer's liveliness token
(:func:`wait_alive`), for a subscriber to be known to the publishing
session (:func:`wait_subscribed`) or for a received sample
(:func:`wait_sample`).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import zenoh

from interfaces.messages import RobotState, ServiceStatus, TorqueCommand
from runtime.config import ZenohSettings
from runtime.ports import free_port
from runtime.session import ServiceNode

REPO = Path(__file__).resolve().parent.parent


def wait_for(predicate, timeout_s: float = 5.0, what: str = "condition", period_s: float = 0.005):
    """Poll ``predicate`` every ``period_s`` until it returns something truthy and return that.

    Fails the test (AssertionError naming ``what``) after ``timeout_s``.
    """
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(period_s)
    raise AssertionError(f"{what} not met within {timeout_s} s")


def wait_seq(sub, seq: int, timeout_s: float = 5.0, what: str = "message"):
    """The first message taken from ``sub`` (a :class:`runtime.session.Latest`) whose ``seq`` is at least ``seq``.

    A lock-step peer publishes its last periodic message while the test has
    already stopped stepping: the newest one taken may still be the one
    before it, so a test that wants the state after its last step waits for it.
    """
    held = []

    def newest():
        msg = sub.take()
        if msg is not None:
            held[:] = [msg]
        return msg if msg is not None and msg.seq >= seq else None

    try:
        return wait_for(newest, timeout_s, f"{what} of seq {seq}")
    except AssertionError as exc:
        last = held[0].seq if held else None
        raise AssertionError(f"{exc}; the newest taken had seq {last}") from None


def wait_alive(node: ServiceNode, service: str, timeout_s: float = 10.0) -> None:
    """Wait until ``node`` sees the liveliness token ``alive/<service>`` (the peer's session is up)."""
    wait_for(lambda: service in node.alive_services(0.5), timeout_s, f"the liveliness token of {service!r}")


def wait_gone(node: ServiceNode, service: str, timeout_s: float = 10.0) -> None:
    """Wait until the liveliness token ``alive/<service>`` has gone from ``node``'s view."""
    wait_for(lambda: service not in node.alive_services(0.5), timeout_s,
             f"the liveliness token of {service!r} to go")


def wait_subscribed(session: zenoh.Session, key: str, timeout_s: float = 10.0, what: str | None = None) -> None:
    """Wait until ``session`` knows a subscriber on ``key``, so a put from it is delivered.

    The matching status of a publisher declared for the purpose. A
    subscriber of ``session`` itself matches too: call it on a session that
    does not subscribe to ``key``.
    """
    pub = session.declare_publisher(key)
    try:
        wait_for(lambda: pub.matching_status.matching, timeout_s, what or f"a subscriber on {key}")
    finally:
        pub.undeclare()


def wait_sample(reader, accept=None, timeout_s: float = 5.0, what: str = "a sample"):
    """The first message ``reader`` (a ``Latest`` or an ``Inbox``) receives for which ``accept(msg)`` holds.

    Messages before it are taken and dropped; ``accept`` None takes any.
    """
    take = reader.take if hasattr(reader, "take") else (lambda: reader.get(0.0))

    def accepted():
        msg = take()
        return msg if msg is not None and (accept is None or accept(msg)) else None

    return wait_for(accepted, timeout_s, what)


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
                 port: int | None = None, env: dict[str, str] | None = None) -> None:
        self.port = port or free_port()
        self.env = env or {}  # on top of ours (e.g. LAMPS_RT_PRIORITY)
        self.robot_id = f"t{self.port}"
        self.config = write_config(tmp_path / f"{name}.toml", self.port, self.robot_id, sim)
        self.log_path = tmp_path / f"{name}.log"  # a file, not a pipe: a pipe nobody reads blocks the sim when full
        self.client_name = client
        self.proc: subprocess.Popen | None = None
        self.node: ServiceNode | None = None

    def __enter__(self) -> SimProcess:
        env = dict(os.environ, PYTHONUNBUFFERED="1", **self.env)
        with self.log_path.open("w") as log:
            self.proc = subprocess.Popen([sys.executable, "-m", "sim.cli", "--config", str(self.config)], cwd=REPO,
                                         env=env, stdout=log, stderr=subprocess.STDOUT)
        settings = ZenohSettings(connect=(f"tcp/127.0.0.1:{self.port}",), robot_id=self.robot_id)
        self.node = ServiceNode(self.client_name, settings).__enter__()
        try:
            self._wait_started()
        except BaseException:
            self.__exit__()
            raise
        return self

    def _wait_started(self) -> None:
        """Until the sim's liveliness token is seen and it subscribes to commands (after its camera started)."""
        wait_for(lambda: self.proc.poll() is not None or "sim" in self.node.alive_services(0.5), 60.0,
                 "sim liveliness")
        self._check_running()
        commands = self.node.session.declare_publisher(self.keys.robot_command)
        try:
            wait_for(lambda: self.proc.poll() is not None or commands.matching_status.matching, 60.0,
                     "lamps sim subscribing to robot/command")
        finally:
            commands.undeclare()
        self._check_running()

    def _check_running(self) -> None:
        if self.proc.poll() is not None:
            raise AssertionError(f"lamps sim exited with {self.proc.returncode}:\n{self.log_path.read_text()}")

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
            raise AssertionError("lamps sim did not stop on SIGINT") from None

    def output(self) -> str:
        return self.log_path.read_text() if self.proc and self.proc.poll() is not None else ""

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


def latest_status(sim: SimProcess, timeout_s: float = 5.0, accept=None, what: str = "a sim status") -> ServiceStatus:
    """The next sim status (published after this call) for which ``accept(status)`` holds (default: any)."""
    reader = sim.node.latest(sim.keys.sim_status, ServiceStatus)
    try:
        return wait_sample(reader, accept, timeout_s, what)
    finally:
        reader.close()
