"""Authentication and access control over real Zenoh on loopback: only the controller moves the arm.

Each node authenticates as a role of the cell (user-password, credentials
from ``lamps credentials``) and applies the cell's access-control list. A
forbidden put is proven dropped with a barrier: the same session then puts
an allowed message on the same link, and once that arrives every earlier
sample from that session would have arrived too.
"""

from __future__ import annotations

import time

import pytest

from interfaces.access import ROLES, cell_acl, writers
from interfaces.config import ZenohSettings
from interfaces.credentials import DICTIONARY, main as credentials_main, make_credentials, password_file
from interfaces.errors import ConfigError
from interfaces.keys import Keys
from interfaces.messages import Estop, TorqueCommand
from interfaces.session import ServiceNode, zenoh_config

from .zenoh_helpers import free_port, wait_alive, wait_for, wait_sample, wait_subscribed


@pytest.fixture(scope="module")
def creds(tmp_path_factory):
    d = tmp_path_factory.mktemp("credentials")
    make_credentials(d)
    return d


def _settings(creds, role: str, rid: str, listen=(), connect=(), password: str | None = None) -> ZenohSettings:
    pw = password_file(creds, role)
    if password is not None:
        pw = creds / f"wrong-{role}.password"
        pw.write_text(password + "\n")
    return ZenohSettings(listen=tuple(listen), connect=tuple(connect), robot_id=rid, user=role,
                         password_file=str(pw), credentials_file=str(creds / DICTIONARY), access_control=True)


def _robot_readers(robot: ServiceNode, *senders: ServiceNode):
    """(commands, e-stop engages, releases) inboxes on ``robot``, once every sender knows they are subscribed."""
    keys = robot.keys
    readers = (robot.inbox(keys.robot_command, TorqueCommand), robot.inbox(keys.controller_estop, Estop),
               robot.inbox(keys.controller_estop_release, Estop))
    for node in senders:
        for key in (keys.robot_command, keys.controller_estop, keys.controller_estop_release):
            wait_subscribed(node.session, key)
    return readers


def _cmd(seq: int) -> TorqueCommand:
    return TorqueCommand(seq=seq, stamp_ns=time.monotonic_ns(), tau_nm=[0.0] * 7)


def _estop(engaged: bool, source: str) -> Estop:
    return Estop(stamp_ns=time.monotonic_ns(), engaged=engaged, reason="test", source=source)


def test_the_acl_gives_each_protected_key_to_its_writers_only():
    keys = Keys.for_robot("acl")
    acl = cell_acl(keys)
    assert acl["enabled"] and acl["default_permission"] == "allow"
    rules = {r["id"]: r for r in acl["rules"]}
    denied: dict[str, set[str]] = {}
    for policy in acl["policies"]:
        for rule in policy["rules"]:
            for key in rules[rule]["key_exprs"]:
                denied.setdefault(key, set()).update(policy["subjects"])
    for key, allowed in writers(keys).items():
        assert denied[key] == set(ROLES) - set(allowed), key
    assert keys.controller_estop not in denied, "engaging the e-stop is never refused"
    assert denied[keys.robot_command] == set(ROLES) - {"controller"}
    assert denied[keys.controller_estop_release] == set(ROLES) - {"operator"}


def test_a_bad_security_setting_is_refused_with_its_name(creds, tmp_path):
    with pytest.raises(ConfigError, match="user must be one of the cell's roles"):
        ZenohSettings(user="intruder", password_file="x", credentials_file="y")
    with pytest.raises(ConfigError, match="needs password_file and credentials_file"):
        ZenohSettings(user="controller")
    with pytest.raises(ConfigError, match="access_control needs a user"):
        ZenohSettings(access_control=True)
    missing = ZenohSettings(user="controller", password_file=str(tmp_path / "nope"),
                            credentials_file=str(creds / DICTIONARY))
    with pytest.raises(ConfigError, match="password_file .*nope"):
        zenoh_config(missing)


def test_lamps_credentials_never_overwrites(tmp_path, capsys):
    assert credentials_main([str(tmp_path / "c")]) == 0
    words = {r: password_file(tmp_path / "c", r).read_text() for r in ROLES}
    assert len(set(words.values())) == len(ROLES) and all(len(w.strip()) == 64 for w in words.values())
    assert oct(password_file(tmp_path / "c", "controller").stat().st_mode & 0o777) == "0o600"
    assert credentials_main([str(tmp_path / "c")]) == 1
    assert "not overwritten" in capsys.readouterr().err
    assert {r: password_file(tmp_path / "c", r).read_text() for r in ROLES} == words


def test_only_the_controller_moves_the_arm_and_only_the_operator_releases_the_estop(creds):
    rid = f"acl{free_port()}"
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    with ServiceNode("robot", _settings(creds, "robot", rid, listen=[ep])) as robot, \
            ServiceNode("controller", _settings(creds, "controller", rid, connect=[ep])) as ctl, \
            ServiceNode("perception", _settings(creds, "perception", rid, connect=[ep])) as rogue, \
            ServiceNode("operator", _settings(creds, "operator", rid, connect=[ep])) as op:
        keys = robot.keys
        commands, engages, releases = _robot_readers(robot, ctl, rogue, op)
        # a perception peer commands torques and releases the e-stop: both dropped at the robot's ingress
        for seq in range(100, 120):
            rogue.publish(keys.robot_command, _cmd(seq))
        rogue.publish(keys.controller_estop_release, _estop(False, "rogue"))
        rogue.publish(keys.controller_estop, _estop(True, "rogue barrier"))  # allowed: the barrier
        assert wait_sample(engages, lambda e: e.source == "rogue barrier", what="the rogue's allowed e-stop")
        assert commands.get(0.0) is None and releases.get(0.0) is None
        assert commands.received == 0 and releases.received == 0
        # the controller's commands and the operator's release arrive
        ctl.publish(keys.robot_command, _cmd(1))
        assert wait_sample(commands, lambda c: c.seq == 1, what="the controller's command").seq == 1
        op.publish(keys.controller_estop_release, _estop(False, "operator"))
        assert wait_sample(releases, what="the operator's release").source == "operator"
        assert commands.received == 1 and releases.received == 1


def test_a_peer_without_valid_credentials_cannot_join(creds):
    rid = f"acl{free_port()}"
    ep = f"tcp/127.0.0.1:{free_port()}"
    anonymous = ZenohSettings(connect=(ep,), robot_id=rid)
    with ServiceNode("robot", _settings(creds, "robot", rid, listen=[ep])) as robot, \
            ServiceNode("impostor", _settings(creds, "controller", rid, connect=[ep], password="guessed")) as bad, \
            ServiceNode("anonymous", anonymous) as anon, \
            ServiceNode("controller", _settings(creds, "controller", rid, connect=[ep])) as ctl:
        wait_alive(robot, "controller")
        commands = robot.inbox(robot.keys.robot_command, TorqueCommand)
        wait_subscribed(ctl.session, robot.keys.robot_command)
        for node, seq in ((bad, 7), (anon, 8)):
            node.publish(robot.keys.robot_command, _cmd(seq))
        ctl.publish(robot.keys.robot_command, _cmd(1))
        assert wait_sample(commands, what="the controller's command").seq == 1
        time.sleep(0.3)  # the refused peers have no link at all: nothing of theirs can be in flight
        assert commands.get(0.0) is None
        assert not bad.session.info.peers_zid() and not anon.session.info.peers_zid(), "no transport was opened"
        alive = robot.alive_services(0.5)
        assert "impostor" not in alive and "anonymous" not in alive and "controller" in alive
        assert wait_for(lambda: len(list(robot.session.info.peers_zid())) == 1, 2.0, "one peer: the controller")


def test_the_rules_hold_for_peers_that_connect_through_another_service(creds):
    """The robot listens, the controller connects to it and listens too, perception and the operator connect only to
    the controller's endpoint (as in compose). Zenoh's gossip links them to the robot directly, so the robot sees
    each origin's own identity: the rogue's command is dropped, the operator's release arrives."""
    rid = f"acl{free_port()}"
    ep1, ep2 = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    with ServiceNode("robot", _settings(creds, "robot", rid, listen=[ep1])) as robot, \
            ServiceNode("controller", _settings(creds, "controller", rid, listen=[ep2], connect=[ep1])) as ctl, \
            ServiceNode("perception", _settings(creds, "perception", rid, connect=[ep2])) as rogue, \
            ServiceNode("operator", _settings(creds, "operator", rid, connect=[ep2])) as op:
        keys = robot.keys
        commands, engages, releases = _robot_readers(robot, ctl, rogue, op)
        rogue.publish(keys.robot_command, _cmd(100))
        rogue.publish(keys.controller_estop, _estop(True, "rogue barrier"))
        wait_sample(engages, lambda e: e.source == "rogue barrier", what="the rogue's allowed e-stop")
        op.publish(keys.controller_estop_release, _estop(False, "operator"))
        release = wait_sample(releases, what="the operator's release, through the controller's endpoint")
        assert release.source == "operator"
        assert commands.received == 0


def test_the_bridge_config_lets_the_authenticated_adapter_connect_and_an_unauthenticated_bridge_does_not(creds):
    """zenoh-bridge-ros2dds is not ours: compose starts it with ``-c /secrets/zenoh-bridge.json5`` so that the
    adapter (authenticated as the robot side) can open a link to it. Here a Zenoh session opened from that very
    file (its dictionary path pointed at this test's folder) stands for the bridge."""
    import json

    import zenoh

    from interfaces.credentials import BRIDGE_CONFIG

    rid = f"acl{free_port()}"
    ep = f"tcp/127.0.0.1:{free_port()}"
    cfg = json.loads((creds / BRIDGE_CONFIG).read_text())
    assert cfg["transport"]["auth"]["usrpwd"]["user"] == "robot"
    ros2dds = cfg["plugins"]["ros2dds"]  # only the stack's topics cross; the state express and first
    assert ros2dds["pub_priorities"] == ["/lbr/state=1:express"] and ros2dds["reliable_routes_blocking"] is False
    assert ros2dds["allow"]["subscribers"] == ["/lbr/command/torque"] and "/lbr/state" in ros2dds["allow"]["publishers"]
    cfg["transport"]["auth"]["usrpwd"]["dictionary_file"] = str(creds / DICTIONARY)
    local = creds / "bridge-local.json5"
    local.write_text(json.dumps(cfg))
    conf = zenoh.Config.from_file(str(local))
    conf.insert_json5("listen/endpoints", json.dumps([ep]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(conf) as bridge, ServiceNode("robot", _settings(creds, "robot", rid, connect=[ep])) as adapter:
        wait_for(lambda: list(adapter.session.info.peers_zid()), 5.0, "the adapter's link to the bridge")
        got = []
        sub = bridge.declare_subscriber("lbr/command/torque", lambda s: got.append(s))
        wait_subscribed(adapter.session, "lbr/command/torque")
        adapter.session.put("lbr/command/torque", b"cdr")
        wait_for(lambda: got, 5.0, "the adapter's command at the bridge")
        sub.undeclare()
    plain = ZenohSettings(listen=(f"tcp/127.0.0.1:{free_port()}",), robot_id=rid)
    with ServiceNode("bridge", plain) as b2, \
            ServiceNode("robot", _settings(creds, "robot", rid, connect=list(plain.listen))) as a2:
        time.sleep(1.0)
        assert not list(a2.session.info.peers_zid()), "without credentials on the bridge there is no link"
        assert not list(b2.session.info.peers_zid())
