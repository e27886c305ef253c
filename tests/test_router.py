"""``lamps router``: the cell through a Zenoh router with the peers' identities and access list, over real Zenoh.

The router is the real command (the eclipse-zenoh library in router mode) started as a process; every other
party is a Zenoh client of it with its role's identity from ``lamps credentials``: no link between clients, so
whatever reaches a client came through the router and its access list.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time

import pytest
import zenoh

from interfaces.access import RELAY, cell_acl
from interfaces.config import ZenohSettings
from interfaces.credentials import identity_folder, make_credentials
from interfaces.session import zenoh_config
from launch.health import accepts

from .conftest import REPO
from .zenoh_helpers import free_port


def _accepts(port: int) -> bool:
    return accepts("127.0.0.1", port, 0.2) is None


class _Router:
    def __init__(self, tmp, robot_id: str, credentials, access: bool = True) -> None:
        self.port = free_port()
        self.endpoint = f"tls/127.0.0.1:{self.port}"
        env = {"LAMPS_ROBOT_ID": robot_id, "LAMPS_ZENOH_ACCESS_CONTROL": "true" if access else "false",
               "LAMPS_ZENOH_IDENTITY": str(identity_folder(credentials, RELAY)), "PATH": "/usr/bin:/bin",
               "PYTHONPATH": str(REPO)}
        self.proc = subprocess.Popen([sys.executable, "-m", "interfaces.cli", "router", "--listen", self.endpoint,
                                      "--status-s", "0"], env=env, cwd=tmp, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
        deadline = time.monotonic() + 60.0
        while not _accepts(self.port):
            assert self.proc.poll() is None and time.monotonic() < deadline, self.proc.communicate(timeout=5)[0]
            time.sleep(0.1)

    def close(self) -> str:
        self.proc.terminate()
        out, _ = self.proc.communicate(timeout=20)
        return out


def _client(router: _Router, robot_id: str, folder) -> zenoh.Session:
    return zenoh.open(zenoh_config(ZenohSettings(mode="client", connect=(router.endpoint,), robot_id=robot_id,
                                                 access_control=True, identity=str(folder))))


@pytest.fixture
def cell(tmp_path):
    creds = tmp_path / "credentials"
    make_credentials(creds)
    robot_id = f"r{free_port()}"
    router = _Router(tmp_path, robot_id, creds)
    yield router, robot_id, creds
    router.close()


@pytest.mark.attack("router: a client puts another role's keys through the router",
                    "perception's identity, a client of the router, puts 100 Nm on robot/command and releases "
                    "the e-stop", "refused at the router: the robot and the controller get only their writers'")
def test_the_router_lets_each_client_put_its_own_row_only(cell):
    router, robot_id, creds = cell
    from interfaces.keys import Keys

    keys = Keys.for_robot(robot_id)
    got: dict[str, list[bytes]] = {"command": [], "release": []}
    lock = threading.Lock()
    robot = _client(router, robot_id, identity_folder(creds, "robot"))
    ctl = _client(router, robot_id, identity_folder(creds, "controller"))
    thief = _client(router, robot_id, identity_folder(creds, "perception"))
    operator = _client(router, robot_id, identity_folder(creds, "operator"))
    try:
        def keep(name):
            def cb(sample):
                with lock:
                    got[name].append(bytes(sample.payload.to_bytes()))
            return cb

        subs = [robot.declare_subscriber(keys.robot_command, keep("command")),
                ctl.declare_subscriber(keys.controller_estop_release, keep("release"))]
        time.sleep(1.0)  # the declarations reach the router and the publishers' sessions
        for _ in range(20):
            thief.put(keys.robot_command, b"forged by perception")
            thief.put(keys.controller_estop_release, b"released by perception")
            ctl.put(keys.robot_command, b"from the controller")
            operator.put(keys.controller_estop_release, b"from the operator")
            time.sleep(0.02)
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and (len(got["command"]) < 20 or len(got["release"]) < 20):
            time.sleep(0.05)
        time.sleep(0.3)
        with lock:
            assert set(got["command"]) == {b"from the controller"} and len(got["command"]) == 20, got["command"][:3]
            assert set(got["release"]) == {b"from the operator"} and len(got["release"]) == 20
        for s in subs:
            s.undeclare()
    finally:
        for s in (robot, ctl, thief, operator):
            s.close()


@pytest.mark.attack("router: a client from another CA joins the router",
                    "a client with a certificate of its own CA (common name controller) connects",
                    "no session: the TLS handshake fails at the router")
def test_a_client_with_another_cas_certificate_gets_no_session(cell, tmp_path):
    router, robot_id, _ = cell
    other = tmp_path / "other"
    make_credentials(other)
    with pytest.raises(zenoh.ZError):
        _client(router, robot_id, identity_folder(other, "controller"))


def test_clients_access_list_lets_the_routers_relayed_puts_in_and_nothing_else_unnamed():
    from interfaces.keys import Keys

    acl = cell_acl(Keys.for_robot("x"))
    relay = next(p for p in acl["policies"] if p["subjects"] == [RELAY])
    rule = next(r for r in acl["rules"] if r["id"] == "relay")
    assert "relay" in relay["rules"] and rule["flows"] == ["ingress"] and "lamps/x/**" in rule["key_exprs"]
    assert acl["default_permission"] == "deny"


def test_credentials_made_before_the_router_get_its_identity_from_the_same_ca(tmp_path):
    import shutil

    creds = tmp_path / "c"
    make_credentials(creds)
    ca = (creds / "ca" / "ca.pem").read_bytes()
    shutil.rmtree(creds / RELAY)
    make_credentials(creds, if_missing=True)
    assert (creds / RELAY / "cert.pem").is_file() and (creds / RELAY / "ca.pem").read_bytes() == ca


@pytest.mark.slow
def test_a_lockstep_cell_runs_through_the_router_and_cleans_its_board(tmp_path, learned_skill_file):
    from .cell_harness import Cell

    with Cell(tmp_path / "run", learned_skill_file, "lockstep", router=True) as c:
        c.wait_phase(("DONE",), 600.0)
        report = c.finish("done", "the cell through the router is DONE")
        router_log = (tmp_path / "run" / "logs" / "router.log").read_text()
    assert report["final_phase"] == "DONE" and report["dirt_removed_fraction"] > 0.95, report["dirt_removed_fraction"]
    assert "listening on" in router_log


def test_health_alive_sees_a_clients_token_through_the_router_and_names_a_missing_one(cell):
    """``lamps health --alive``: compose's probe of a router's client (no port of its own to probe)."""
    import os

    from launch.health import alive

    router, robot_id, creds = cell
    env = {"LAMPS_ROBOT_ID": robot_id, "LAMPS_ZENOH_MODE": "client", "LAMPS_ZENOH_CONNECT": router.endpoint,
           "LAMPS_ZENOH_ACCESS_CONTROL": "true", "LAMPS_ZENOH_IDENTITY": str(identity_folder(creds, "robot"))}
    from interfaces.session import ServiceNode

    settings = ZenohSettings(mode="client", connect=(router.endpoint,), robot_id=robot_id, access_control=True,
                             identity=str(identity_folder(creds, "robot")))
    with ServiceNode("sim", settings):
        r = subprocess.run([sys.executable, "-m", "interfaces.cli", "health", "--alive", "sim", "--timeout", "3",
                            "-v"],
                           env={**os.environ, **env, "PYTHONPATH": str(REPO)}, capture_output=True, text=True,
                           timeout=60)
        assert r.returncode == 0 and "sim is alive" in r.stdout, r.stderr
        why = alive("perception", 1.0, env)
    assert why is not None and f"lamps/{robot_id}/alive/perception" in why and router.endpoint in why, why
    assert "no Zenoh session" in alive("sim", 1.0, {**env, "LAMPS_ZENOH_CONNECT": "tls/127.0.0.1:1"})
