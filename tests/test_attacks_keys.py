"""The keys that used to open everything, tried as a thief would: the router's key as a peer and through a router
whose list is off, a service started without an identity, the robot role's access list turned off, a role
declaring another's presence. Real services, real Zenoh with mutual TLS on loopback, real PyBullet."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pytest

from interfaces.codec import encode
from interfaces.messages import Estop, RobotState, ServiceStatus, TorqueCommand
from runtime.config import ZenohSettings
from runtime.credentials import identity_folder, make_credentials
from runtime.session import ServiceNode

from .cell_harness import Cell
from .conftest import REPO
from .zenoh_helpers import free_port, wait_for, wait_sample

FORGED_NM = 100.0


def _forge_while_estopped(cell: Cell, thief: ServiceNode, hold_s: float = 3.0) -> tuple[float, int]:
    """With the operator's e-stop engaged, ``thief`` replays the controller's commands, forges 100 Nm with its
    session and puts unsigned releases for ``hold_s``; (largest joint motion [rad], puts sent)."""
    keys = cell.node.keys
    stolen: list[TorqueCommand] = []
    # what a thief of any role could read (every role reads the cell), captured by the operator's node: the
    # router's key used as a peer is denied even that
    cell.node.session.declare_subscriber(keys.robot_command, lambda s: _keep(stolen, s))
    states = cell.node.latest(keys.robot_state, RobotState)
    cell.wait_phase(("WIPE",), 180.0)
    wait_for(lambda: len(stolen) > 50, 30.0, "the thief hearing the controller's commands")
    t = time.monotonic()
    cell.node.publish(keys.controller_estop, Estop(stamp_ns=time.monotonic_ns(), engaged=True, reason="test hold",
                                                   source="operator"))
    cell.wait_phase(("ESTOP",), 10.0, since=t)
    time.sleep(0.5)  # the pad settles in the hold
    q0 = np.asarray(wait_sample(states, None, 10.0, "a state in the hold").q_rad)
    moved, sent = 0.0, 0
    t_end = time.monotonic() + hold_s
    while time.monotonic() < t_end:
        last = stolen[-1]
        for c in stolen[-20:]:
            thief.session.put(keys.robot_command, encode(c))
        for i in range(1, 6):
            thief.session.put(keys.robot_command, encode(TorqueCommand(
                seq=last.seq + i, stamp_ns=time.monotonic_ns(), tau_nm=[FORGED_NM] * 7, session=last.session,
                mac=last.mac)))
        thief.session.put(keys.controller_estop_release, encode(Estop(
            stamp_ns=time.monotonic_ns(), engaged=False, reason="forged", source="operator", wall_ns=time.time_ns())))
        sent += 26
        if (st := states.take()) is not None:
            moved = max(moved, float(np.abs(np.asarray(st.q_rad) - q0).max()))
        time.sleep(0.01)
    assert cell.phases[-1][1] == "ESTOP", cell.phases[-4:]
    return moved, sent


def _keep(out: list, sample) -> None:
    from interfaces.codec import Decoder

    out.append(Decoder(TorqueCommand)(sample.payload.to_bytes()))


@pytest.mark.slow
@pytest.mark.attack("2", "the router's key used as a plain peer (linked to every service, its program not applying "
                         "the list) replays the controller's commands, forges 100 Nm with its session and MAC and "
                         "puts e-stop releases for 3 s while the operator's e-stop holds",
                   "nothing applied: the arm within 1 mrad, ESTOP held, no release taken")
def test_the_routers_key_as_a_peer_moves_nothing(tmp_path, learned_skill_file):
    with Cell(tmp_path / "run", learned_skill_file) as cell:
        thief = ServiceNode("thief", cell.operator_settings("router", access_control=False)).__enter__()
        ear = ServiceNode("ear", cell.operator_settings("router", access_control=False)).__enter__()
        heard: list = []
        ear.session.declare_subscriber(f"{cell.node.keys.prefix}/**", heard.append)
        try:
            moved, sent = _forge_while_estopped(cell, thief)
        finally:
            thief.close()
            ear.close()
        assert not heard, "a peer with the router's key is sent nothing"
        sim = cell.node.latest(cell.node.keys.sim_status, ServiceStatus)
        st = wait_sample(sim, None, 10.0, "a sim status")
        cell.finish()
    assert sent > 1000
    assert moved < 1e-3, f"the arm moved {moved:.4f} rad"
    assert st.counters.get("estop_engaged") == 1, st.counters


@pytest.mark.slow
@pytest.mark.attack("2", "through a router whose access list is off (--insecure), perception's identity replays "
                         "the controller's commands, forges 100 Nm with its session and MAC and puts e-stop "
                         "releases for 3 s while the operator's e-stop holds",
                   "relayed, and refused by the robot side and the controller: the arm within 1 mrad, ESTOP held")
def test_through_a_router_whose_list_is_off_nothing_moves_the_arm(tmp_path, learned_skill_file):
    with Cell(tmp_path / "run", learned_skill_file, router=True, router_acl=False) as cell:
        thief = ServiceNode("thief", cell.operator_settings("perception", access_control=False)).__enter__()
        try:
            moved, sent = _forge_while_estopped(cell, thief)
        finally:
            thief.close()
        sim = cell.node.latest(cell.node.keys.sim_status, ServiceStatus)
        st = wait_sample(sim, None, 10.0, "a sim status")
        cell.finish()
    assert sent > 1000
    assert moved < 1e-3, f"the arm moved {moved:.4f} rad"
    refused = {k: v for k, v in st.counters.items() if k.startswith(("commands_unauthenticated",
                                                                      "estop_releases_refused"))}
    # the router relayed them (its list is off): the robot side's own check refused them
    assert sum(v for k, v in refused.items() if k.startswith("estop_releases_refused")) > 50, st.counters
    assert st.counters.get("estop_engaged") == 1, st.counters


def _service(argv: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    base = {k: v for k, v in os.environ.items() if not k.startswith("LAMPS_ZENOH_")}
    return subprocess.run([sys.executable, "-m", "runtime.cli", *argv], cwd=REPO, capture_output=True, text=True,
                          timeout=120, env={**base, **env})


@pytest.mark.attack("3", "each service started without an identity, and the robot side with its identity and "
                         "LAMPS_ZENOH_ACCESS_CONTROL=false (also with --insecure)",
                   "refused, exit 1, the reason named; with --insecure the service says INSECURE")
def test_a_service_without_an_identity_or_a_robot_without_its_list_refuses_to_start(tmp_path, learned_skill_file):
    creds = tmp_path / "c"
    make_credentials(creds)
    controller = ["controller", "--check", "--skill", str(learned_skill_file)]
    for argv in (["sim", "--check"], controller, ["perception", "--check"],
                 ["robot", "--backend", "mock", "--check"], ["robot", "--backend", "lbr", "--check"]):
        r = _service(argv, {})
        assert r.returncode == 1 and "no identity" in r.stderr and "--insecure" in r.stderr, (argv, r.stderr)
        assert _service([*argv, "--insecure"], {}).returncode == 0, argv
    robot = {"LAMPS_ZENOH_IDENTITY": str(identity_folder(creds, "robot")), "LAMPS_ZENOH_LISTEN": "tls/127.0.0.1:1"}
    for extra, env in (([], {"LAMPS_ZENOH_ACCESS_CONTROL": "false"}),
                       (["--insecure"], {"LAMPS_ZENOH_ACCESS_CONTROL": "false"}),
                       ([], {"LAMPS__ZENOH__ACCESS_CONTROL": "false", "LAMPS_ZENOH_INSECURE": "true"})):
        for argv in (["sim", "--check"], ["robot", "--backend", "lbr", "--check"]):
            r = _service([*argv, *extra], {**robot, **env})
            assert r.returncode == 1 and "cannot be turned off for the robot role" in r.stderr, (argv, env, r.stderr)
    ctl = {"LAMPS_ZENOH_IDENTITY": str(identity_folder(creds, "controller")), "LAMPS_ZENOH_LISTEN": "tls/127.0.0.1:1",
           "LAMPS_ZENOH_ACCESS_CONTROL": "false"}
    r = _service(controller, ctl)
    assert r.returncode == 1 and "access_control is off for the controller role" in r.stderr, r.stderr
    assert _service([*controller, "--insecure"], ctl).returncode == 0


def test_an_insecure_service_says_so_in_every_status(tmp_path):
    from runtime.service_security import security_summary

    creds = tmp_path / "c"
    make_credentials(creds)
    assert security_summary(ZenohSettings(insecure=True)).startswith("INSECURE: no identity")
    assert security_summary(ZenohSettings(identity=str(identity_folder(creds, "controller")),
                                          access_control=False, insecure=True)) == \
        "INSECURE: mtls as controller, access list off"
    assert security_summary(ZenohSettings(identity=str(identity_folder(creds, "robot")))) == "mtls+acl as robot"
    port = free_port()
    got: list[ServiceStatus] = []
    with ServiceNode("sim", ZenohSettings(listen=(f"tcp/127.0.0.1:{port}",), robot_id=f"s{port}")) as a, \
            ServiceNode("reader", ZenohSettings(connect=(f"tcp/127.0.0.1:{port}",), robot_id=f"s{port}")) as b:
        reader = b.latest(a.keys.sim_status, ServiceStatus)
        wait_for(lambda: (a.publish(a.keys.sim_status, ServiceStatus(service="sim", seq=1, stamp_ns=1)),
                          got.append(reader.take()), got[-1] is not None)[-1], 10.0, "a status")
    assert got[-1].security.startswith("INSECURE"), got[-1]


def test_a_role_cannot_declare_another_roles_presence(tmp_path):
    creds = tmp_path / "c"
    make_credentials(creds)
    port = free_port()
    rid = f"lv{port}"

    def settings(role: str, **kw) -> ZenohSettings:
        return ZenohSettings(robot_id=rid, identity=str(identity_folder(creds, role)), gossip=False, **kw)

    with ServiceNode("robot", settings("robot", listen=(f"tls/127.0.0.1:{port}",))) as robot, \
            ServiceNode("controller", settings("perception", connect=(f"tls/127.0.0.1:{port}",),
                                               access_control=False)), \
            ServiceNode("perception", settings("perception", connect=(f"tls/127.0.0.1:{port}",))):
        wait_for(lambda: "perception" in robot.alive_services(0.5), 10.0, "perception's own token")
        time.sleep(0.3)
        assert "controller" not in robot.alive_services(0.5), "perception's identity declared the controller"


@pytest.mark.slow
@pytest.mark.attack("1", "in an lbr-sim cell with the operator's e-stop engaged, the bridge's identity (its program "
                         "not applying the list, linked to every service and the stack) puts 30 Nm torque commands "
                         "on lbr/command/torque and e-stop releases for 3 s",
                   "nothing applied: the arm within 1 mrad, ESTOP held")
def test_the_bridges_identity_cannot_command_the_stack_nor_release_the_estop(tmp_path, learned_skill_file):
    from robot.lbr import msgs

    with Cell(tmp_path / "run", learned_skill_file, robot="lbr-sim") as cell:
        keys = cell.node.keys
        joints: list[np.ndarray] = []
        cell.node.session.declare_subscriber("lbr/state", lambda s: joints.append(
            msgs.decode_state(s.payload.to_bytes()).q_rad.copy()))
        cell.wait_phase(("WIPE",), 240.0)
        t = time.monotonic()
        cell.node.publish(keys.controller_estop, Estop(stamp_ns=time.monotonic_ns(), engaged=True, reason="test hold",
                                                       source="operator"))
        cell.wait_phase(("ESTOP",), 10.0, since=t)
        # the stack's hold lets the pressed pad settle: 9 mrad over the first 3 s, 0.3 mrad over 3 s after 4 s
        time.sleep(4.0)
        wait_for(lambda: bool(joints), 10.0, "the stack's states")
        q0 = joints[-1].copy()
        n0 = len(joints)
        thief = ServiceNode("bridge", cell.operator_settings("bridge", access_control=False)).__enter__()
        try:
            sent = 0
            t_end = time.monotonic() + 3.0
            while time.monotonic() < t_end:
                thief.session.put("lbr/command/torque", msgs.encode_torque_command(q0, np.full(7, 30.0)))
                thief.session.put(keys.controller_estop_release, encode(Estop(
                    stamp_ns=time.monotonic_ns(), engaged=False, reason="forged", source="operator",
                    wall_ns=time.time_ns())))
                sent += 2
                time.sleep(0.002)
        finally:
            thief.close()
        moved = max(float(np.abs(q - q0).max()) for q in joints[n0:])
        assert cell.phases[-1][1] == "ESTOP", cell.phases[-4:]
        cell.finish()
    assert sent > 1000 and len(joints) - n0 > 100
    assert moved < 1e-3, f"the arm moved {moved:.4f} rad"
