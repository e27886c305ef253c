"""The whole cell for fault injection: the compose services started as ``lamps up`` does, and tools to hurt it.

:class:`Cell` plans the sim profile of ``docker-compose.yml`` with the
launcher's own code (credentials, access control, free local ports), starts
every service as a real process, watches the controller's status as the
operator, and lets a test SIGKILL, SIGSTOP/SIGCONT or restart any service,
stall or cut the controller's link to the robot side (:class:`TcpProxy`,
with gossip off so that link is the only one), or join as a rogue peer.
:meth:`Cell.finish` stops it the way ``lamps up`` does (``run.json``, then
the recorder writes ``report.json``) and returns the report.
"""

from __future__ import annotations

import json
import os
import selectors
import signal
import socket
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

from interfaces.keys import Keys
from interfaces.messages import ControllerStatus
from runtime.config import ZenohSettings
from runtime.credentials import identity_folder
from runtime.realtime import RealtimeRequest
from runtime.session import ServiceNode

from .conftest import REPO
from .zenoh_helpers import free_port

COMPOSE = REPO / "docker-compose.yml"


class TcpProxy:
    """A TCP relay from a local port to ``target_port`` whose traffic can be stalled (:meth:`stall`) or cut
    (:meth:`cut`: every connection closed, in-flight bytes lost; new connections are accepted again at once)."""

    def __init__(self, target_port: int) -> None:
        self.target = target_port
        self.port = free_port()
        self._server = socket.create_server(("127.0.0.1", self.port))
        self._open = threading.Event()
        self._open.set()
        self._lock = threading.Lock()
        self._pairs: list[tuple[socket.socket, socket.socket]] = []
        self._stop = threading.Event()
        self.forwarded = 0
        threading.Thread(target=self._accept, daemon=True, name="proxy-accept").start()

    def _accept(self) -> None:
        self._server.settimeout(0.2)
        while not self._stop.is_set():
            try:
                down, _ = self._server.accept()
            except (TimeoutError, OSError):
                continue
            try:
                up = socket.create_connection(("127.0.0.1", self.target), timeout=2.0)
            except OSError:
                down.close()
                continue
            for s in (down, up):
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._pairs.append((down, up))
            threading.Thread(target=self._pump, args=(down, up), daemon=True, name="proxy-pump").start()

    def _pump(self, a: socket.socket, b: socket.socket) -> None:
        self._as_a_link()
        sel = selectors.DefaultSelector()
        sel.register(a, selectors.EVENT_READ, b)
        sel.register(b, selectors.EVENT_READ, a)
        try:
            while not self._stop.is_set():
                self._open.wait()  # stalled: nothing read, the senders' buffers and queues fill up
                for key, _ in sel.select(0.05):
                    data = key.fileobj.recv(65536)
                    if not data:
                        return
                    key.data.sendall(data)
                    self.forwarded += len(data)
        except OSError:
            return
        finally:
            sel.close()
            for s in (a, b):
                try:
                    s.close()
                except OSError:
                    pass

    @staticmethod
    def _as_a_link() -> None:
        """The pump to SCHED_FIFO one below the loops (as ``lamps router``'s threads), when allowed: a network link
        is no thread the scheduler can starve. Left fair, it waited behind the cell's FIFO loops on 2 cores and
        forwarded the commands in bursts: each state's answer 17-18 periods late at the 99th percentile, the pad
        bouncing on the board."""
        priority = RealtimeRequest.from_env().priority
        if priority is None or not sys.platform.startswith("linux"):
            return
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(max(1, priority - 1)))  # 0: this thread
        except OSError:
            pass  # not permitted here: the relay stays fair

    def stall(self, seconds: float) -> None:
        """Forward nothing for ``seconds`` (blocking), then everything that waited."""
        self._open.clear()
        time.sleep(seconds)
        self._open.set()

    def cut(self) -> int:
        """Close every connection now; returns how many were cut."""
        with self._lock:
            pairs, self._pairs = self._pairs, []
        for pair in pairs:
            for s in pair:
                try:
                    s.shutdown(socket.SHUT_RDWR)
                    s.close()
                except OSError:
                    pass
        return len(pairs)

    def close(self) -> None:
        self._stop.set()
        self._open.set()
        self.cut()
        self._server.close()


class Cell:
    """The sim profile of the compose file as local processes (see the module docstring).

    mode : ``lockstep`` or ``realtime``; proxy : route the controller's link to the sim through a
    :class:`TcpProxy` (:attr:`proxy`); router : run ``lamps router`` (the router identity, the cell's access
    list; ``router_acl=False``: its list off, ``--insecure``) and every service as its client; robot : ``sim``
    or ``lbr-sim`` (the arm behind the simulated lbr stack, as ``lamps up --robot``) (no listen endpoint, no link
    between services); thin : service name -> {key suffix (``robot/state``): samples per second}: Zenoh's own
    downsampling on that service's egress drops the samples of that key that come sooner than 1 / rate after the last
    one let through (given to the service as a Zenoh configuration file, ``LAMPS_ZENOH_CONFIG_FILE``).
    """

    def __init__(self, out: Path, skill: Path, mode: str = "lockstep", proxy: bool = False,
                 thin: dict[str, dict[str, float]] | None = None, router: bool = False,
                 router_acl: bool = True, robot: str = "sim") -> None:
        from launch.cli import plan_cell

        self.out = out
        self.a = SimpleNamespace(robot=robot, foxglove=None, seed=0, stains=3, mode=mode, robot_id=f"f{free_port()}",
                                 port_base=None, skill=str(skill), max_duration=0.0, quiet=True)
        self.cell = plan_cell(self.a, COMPOSE, {}, Path(skill), out)
        self.services = {s.name: s for s in self.cell.services}
        self.children: dict = {}
        self.proxy: TcpProxy | None = None
        if proxy:
            self.cell.env["LAMPS_ZENOH_GOSSIP"] = "false"  # the proxied link must be the only one
            sim_port = self.services["sim"].listen_ports[0]
            self.proxy = TcpProxy(sim_port)
            ctl = self.services["controller"]
            ctl.environment["LAMPS_ZENOH_CONNECT"] = ctl.environment["LAMPS_ZENOH_CONNECT"].replace(
                f":{sim_port}", f":{self.proxy.port}")
        self.router_endpoint = f"tls/127.0.0.1:{free_port()}" if router else None
        self.router_acl = router_acl  # False: the router relays everything (--insecure, its list off)
        if router:
            for svc in self.services.values():
                svc.environment.update(LAMPS_ZENOH_MODE="client", LAMPS_ZENOH_CONNECT=self.router_endpoint,
                                       LAMPS_ZENOH_LISTEN="")
        for name, rates in (thin or {}).items():
            self.services[name].environment["LAMPS_ZENOH_CONFIG_FILE"] = str(self._thinning_file(name, rates))
        self.phases: list[tuple[float, str, str]] = []  # (monotonic time, phase, reason) at each change
        self.status: ControllerStatus | None = None
        self._t0 = time.monotonic()
        self._watching = threading.Event()

    def _thinning_file(self, service: str, rates: dict[str, float]) -> Path:
        prefix = Keys.for_robot(self.cell.robot_id).prefix
        rules = [{"key_expr": f"{prefix}/{suffix}", "freq": float(hz)} for suffix, hz in rates.items()]
        path = self.out / f"zenoh-{service}.json5"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"downsampling": [{"messages": ["put"], "flows": ["egress"], "rules": rules}]}))
        return path

    # -- life ------------------------------------------------------------------------------------------
    def __enter__(self) -> Cell:
        try:
            if self.router_endpoint:
                self._start_router()
                self.node = ServiceNode("operator", self.operator_settings()).__enter__()
            for name in self.services:
                self.start(name)
            if not self.router_endpoint:
                self.node = ServiceNode("operator", self.operator_settings()).__enter__()
            self._watching.set()
            self._watcher = threading.Thread(target=self._watch, daemon=True)
            self._watcher.start()
        except BaseException:
            self._stop_all()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self._stop_all()

    def _start_router(self) -> None:
        from launch.procs import Child, wait_port

        env = {**self.cell.env, "LAMPS_ROBOT_ID": self.cell.robot_id,
               "LAMPS_ZENOH_ACCESS_CONTROL": "true" if self.router_acl else "false",
               "LAMPS_ZENOH_INSECURE": "false" if self.router_acl else "true",
               "LAMPS_ZENOH_IDENTITY": str(identity_folder(self.cell.credentials, "router"))}
        child = Child("router", (sys.executable, "-m", "runtime.cli", "router", "--listen", self.router_endpoint,
                                 "--status-s", "0"), env,
                      self.out / "logs")
        self.children["router"] = child
        if not wait_port(int(self.router_endpoint.rsplit(":", 1)[1]), child, 60.0):
            raise AssertionError(f"the router did not come up: {child.last_words()}")

    def operator_settings(self, role: str = "operator", **over) -> ZenohSettings:
        """Settings of a peer joining the cell with ``role``'s identity (connected to every service; through the
        router, its client)."""
        endpoints = tuple(e for s in self.services.values() for e in s.listen_endpoints)
        kw = dict(connect=endpoints, robot_id=self.cell.robot_id, access_control=True,
                  identity=str(identity_folder(self.cell.credentials, role)))
        if self.router_endpoint:
            kw.update(mode="client", connect=(self.router_endpoint,))
        return ZenohSettings(**{**kw, **over})

    def start(self, name: str) -> None:
        """Start (or start again) service ``name``; returns once it listens."""
        from launch.procs import Child, wait_port

        svc = self.services[name]
        child = Child(name, svc.argv, {**svc.environment, **self.cell.env, "MPLBACKEND": "Agg"},
                      self.out / "logs")
        self.children[name] = child
        if self.router_endpoint:  # no port of its own: up once its liveliness token shows through the router
            deadline = time.monotonic() + 120.0
            while name not in self.node.alive_services(0.5):
                if child.proc.poll() is not None or time.monotonic() > deadline:
                    raise AssertionError(f"{name} did not come up through the router: {child.last_words()}")
                time.sleep(0.2)
            return
        for port in svc.listen_ports:
            if not wait_port(port, child, 120.0):
                raise AssertionError(f"{name} did not come up: {child.last_words()}")

    def signal(self, name: str, sig: int) -> None:
        os.killpg(self.children[name].proc.pid, sig)

    def kill(self, name: str) -> int:
        """SIGKILL service ``name``; returns its exit code."""
        self.signal(name, signal.SIGKILL)
        return self.children[name].proc.wait(10.0)

    def freeze(self, name: str, seconds: float) -> None:
        """SIGSTOP service ``name`` for ``seconds``, then SIGCONT."""
        self.signal(name, signal.SIGSTOP)
        try:
            time.sleep(seconds)
        finally:
            self.signal(name, signal.SIGCONT)

    def restart(self, name: str, down_s: float = 0.0) -> None:
        """SIGKILL service ``name``, wait ``down_s``, start it again; the watching session starts afresh (its
        link to the killed service may take Zenoh's reconnect back-off to come back; the services' own links
        are what the test is about, and the recorder's show in the report)."""
        self.kill(name)
        self.children[name].stop()
        time.sleep(down_s)
        if name == "router":  # on the same endpoint: its clients reconnect to what they were given
            self._start_router()
        else:
            self.start(name)
        self._watching.clear()
        self._watcher.join(5.0)
        self.node.close()
        self.node = ServiceNode("operator", self.operator_settings()).__enter__()
        self._watching.set()
        self._watcher = threading.Thread(target=self._watch, daemon=True)
        self._watcher.start()

    # -- watching ----------------------------------------------------------------------------------------
    def _watch(self) -> None:
        status = self.node.latest(self.node.keys.controller_status, ControllerStatus)
        while self._watching.is_set():
            st = status.take()
            if st is not None:
                self.status = st
                if not self.phases or self.phases[-1][1:] != (st.phase, st.reason):
                    self.phases.append((time.monotonic(), st.phase, st.reason))
            time.sleep(0.02)

    def wait_phase(self, phases: tuple[str, ...], timeout_s: float, since: float | None = None) -> tuple:
        """The first change into one of ``phases`` (after ``since``, monotonic) within ``timeout_s``."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            for entry in self.phases:
                if entry[1] in phases and (since is None or entry[0] >= since):
                    return entry
            for name, child in self.children.items():
                if child.returncode is not None and name != "recorder":
                    raise AssertionError(f"{name} exited ({child.returncode}): {child.last_words()}")
            time.sleep(0.05)
        raise AssertionError(f"no phase in {phases} within {timeout_s} s; phases seen: {self.phases[-8:]}; "
                             f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")

    def alive(self) -> dict[str, int | None]:
        return {name: c.returncode for name, c in self.children.items()}

    # -- the end -------------------------------------------------------------------------------------------
    def finish(self, outcome: str = "stopped", why: str = "fault-injection test ended") -> dict:
        """Stop the cell as ``lamps up`` does and return ``report.json`` (rebuilt by ``lamps report`` when the
        recorder did not write it)."""
        from launch.cli import stop_services
        from launch.record_cli import report_main

        self._watching.clear()
        self.node.close()
        stop_services(list(self.children.values()), self.cell, {"outcome": outcome, "why": why}, self.a,
                       self._t0)
        self.children = {}
        if self.proxy is not None:
            self.proxy.close()
        if not (self.out / "report.json").is_file():
            assert report_main([str(self.out)]) == 0, "lamps report could not rebuild the report"
        return json.loads((self.out / "report.json").read_text())

    def _stop_all(self) -> None:
        self._watching.clear()
        node = getattr(self, "node", None)
        if node is not None:
            node.close()
        for c in self.children.values():
            c.stop(5.0)
        self.children = {}
        if self.proxy is not None:
            self.proxy.close()
