"""Identities and access control over real Zenoh on loopback: each role writes only its own keys, whoever opened
the link.

Each node joins with a role's identity from ``lamps credentials`` (mutual TLS: a certificate whose common name is
the role) and applies the cell's default-deny access list. A forbidden put is proven dropped with a barrier: the
same session then puts an allowed message on the same link at the same priority, and once that arrives every
earlier sample from that session would have arrived too.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
import zenoh

from interfaces.access import IDENTITIES, RELAY, ROLE_SERVICES, ROLES, cell_acl, may_put, writers
from interfaces.errors import ConfigError
from interfaces.keys import Keys
from runtime.certificates import issue, write_key_and_cert
from runtime.config import ZenohSettings
from runtime.credentials import BRIDGE_CONFIG, CA_FOLDER, identity_files, identity_folder, make_credentials
from runtime.credentials import main as credentials_main
from runtime.session import ServiceNode, zenoh_config

from .zenoh_helpers import free_port, wait_for, wait_subscribed


@pytest.fixture(scope="module")
def creds(tmp_path_factory):
    d = tmp_path_factory.mktemp("credentials")
    make_credentials(d)
    return d


def _settings(folder: Path, rid: str, listen=(), connect=(), acl: bool = True) -> ZenohSettings:
    """A peer with the identity in ``folder``; ``acl=False``: one that does not apply the cell's list (an attacker)."""
    return ZenohSettings(listen=tuple(listen), connect=tuple(connect), robot_id=rid, identity=str(folder),
                         access_control=acl, gossip=False)


def _tls() -> str:
    return f"tls/127.0.0.1:{free_port()}"


def _attempts(keys: Keys) -> list[str]:
    """A concrete key under every row of the table, plus keys nobody may put."""
    p = keys.prefix
    return [keys.robot_command, keys.robot_state, keys.robot_status, keys.sim_truth, keys.camera_frame("scene"),
            "lbr/state", "lbr/command/torque", keys.robot_arm, keys.perception_stains, keys.controller_status,
            keys.controller_trace, keys.controller_estop, keys.controller_estop_release, f"{p}/other/thing"]


def _barrier_key(keys: Keys, role: str) -> str:
    return "lbr/state" if role == "bridge" else keys.controller_estop


def _put(sender: ServiceNode, key: str, payload: str) -> None:
    """A put that waits for room on a congested link: the default drops it (zenoh's CongestionControl.DROP), and a
    dropped put here would read as one the access list refused."""
    sender.session.put(key, payload.encode(), congestion_control=zenoh.CongestionControl.BLOCK)


def _until_heard(sender: ServiceNode, role: str, keys: Keys, got: dict[str, list], timeout_s: float = 10.0) -> None:
    """``sender`` puts a hello on every key its role may put until every receiver has one on each: from then on
    it knows every receiver's subscriptions (a put it sends is decided by the receiver's access list)."""
    allowed = [k for k in _attempts(keys) if may_put(keys, role, k)]
    tag = f"{role}-hello"
    deadline = time.monotonic() + timeout_s
    while True:
        for k in allowed:
            _put(sender, k, tag)
        time.sleep(0.05)
        if all({k for s, k in g if s == tag} >= set(allowed) for g in got.values()):
            return
        assert time.monotonic() < deadline, f"{role}'s hellos did not reach every receiver"


# ------------------------------------------------------------------------------------------------- identities

def test_lamps_credentials_gives_each_role_a_folder_of_its_own_and_never_overwrites(tmp_path, capsys):
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    d = tmp_path / "c"
    assert credentials_main([str(d), "--host", "cell-a.example"]) == 0
    keys = {}
    for role in ROLES:
        ca, cert, key = identity_files(identity_folder(d, role))
        assert ca.read_bytes() == (d / CA_FOLDER / "ca.pem").read_bytes()
        assert oct(key.stat().st_mode & 0o777) == "0o600", role
        c = x509.load_pem_x509_certificate(cert.read_bytes())
        assert c.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == role
        names = c.extensions.get_extension_for_class(x509.SubjectAlternativeName).value.get_values_for_type(
            x509.DNSName)
        assert "localhost" in names and "cell-a.example" in names, names
        keys[role] = key.read_bytes()
        assert sorted(p.name for p in identity_folder(d, role).iterdir()) == sorted(
            ["ca.pem", "cert.pem", "key.pem"] + ([BRIDGE_CONFIG] if role == "bridge" else []))
    assert len(set(keys.values())) == len(ROLES)
    assert credentials_main([str(d)]) == 1
    assert "not overwritten" in capsys.readouterr().err
    assert credentials_main([str(d), "--if-missing"]) == 0
    assert {r: identity_files(identity_folder(d, r))[2].read_bytes() for r in ROLES} == keys


def test_a_bad_security_setting_is_refused_with_its_name(creds, tmp_path):
    with pytest.raises(ConfigError, match="user must be one of the cell's roles"):
        ZenohSettings(user="intruder", password_file="x", credentials_file="y")
    with pytest.raises(ConfigError, match="access_control needs an identity"):
        ZenohSettings(access_control=True)
    with pytest.raises(ConfigError, match="works on a router only"):
        ZenohSettings(user="controller", password_file="x", credentials_file="y", access_control=True)
    with pytest.raises(ConfigError, match="every endpoint must be tls"):
        ZenohSettings(identity=str(identity_folder(creds, "robot")), listen=("tcp/127.0.0.1:7447",))
    with pytest.raises(ConfigError, match="not both"):
        ZenohSettings(identity=str(identity_folder(creds, "robot")), tls_ca="x", tls_certificate="y",
                      tls_private_key="z")
    with pytest.raises(ConfigError, match="tls_ca .*nope.ca.pem.*No such file"):
        zenoh_config(ZenohSettings(identity=str(tmp_path / "nope")))
    with pytest.raises(ConfigError, match="ros_namespaces"):
        ZenohSettings(ros_namespaces=("lbr/**",))


def test_the_access_list_denies_by_default_and_lets_each_role_put_its_own_keys_only():
    keys = Keys.for_robot("acl")
    for relay in (False, True):
        acl = cell_acl(keys, relay=relay)
        assert acl["enabled"] and acl["default_permission"] == "deny"
        # a peer has no policy for the router's identity: the router relays, it does not vouch
        assert [s["cert_common_names"] for s in acl["subjects"]] == [[r] for r in (IDENTITIES if relay else ROLES)]
        rules = {r["id"]: r for r in acl["rules"]}
        for policy in acl["policies"]:
            (role,) = policy["subjects"]
            puts = [k for rule in policy["rules"] for k in rules[rule]["key_exprs"]
                    if "put" in rules[rule]["messages"] and "ingress" in rules[rule]["flows"]]
            tokens = [k for rule in policy["rules"] for k in rules[rule]["key_exprs"]
                      if "liveliness_token" in rules[rule]["messages"] and "ingress" in rules[rule]["flows"]]
            if role == RELAY:  # a router's client takes what it relays: every key of the cell, checked at the router
                assert set(puts) == {"lamps/acl/**", "lbr/**", "camera/**"}
                continue
            assert set(puts) == {k for k, allowed in writers(keys).items() if role in allowed}, role
            assert set(tokens) == {keys.alive(s) for s in ROLE_SERVICES[role]}, role
    assert may_put(keys, "operator", keys.controller_estop_release)
    assert not any(may_put(keys, r, keys.controller_estop_release) for r in ROLES if r != "operator")
    assert [r for r in ROLES if may_put(keys, r, keys.robot_command)] == ["controller"]
    assert all(may_put(keys, r, keys.controller_estop) for r in ROLES if r != "bridge"), "engaging is never refused"
    # the bridge carries the stack's states out, never a command in: lbr_fri_ros2_stack's command topics
    for topic in ("lbr/command/torque", "lbr/command/joint_position", "lbr/command/wrench", "lbr/command/twist"):
        assert [r for r in ROLES if may_put(keys, r, topic)] == ["robot"], topic
    for topic in ("lbr/state", "lbr/joint_states", "lbr/force_torque_broadcaster/wrench", "camera/color/image_raw",
                  "camera/color/image_raw/compressed", "camera/color/camera_info"):
        assert may_put(keys, "bridge", topic) and may_put(keys, "robot", topic), topic
    assert not any(may_put(keys, r, "lbr/forward_position_controller/commands") for r in ROLES)


# --------------------------------------------------------------------------------------- the matrix, over Zenoh

@pytest.mark.attack("2", "every role's identity used by a peer that listens (the receivers open the links, as "
                         "gossip makes them) puts on every key of the cell",
                   "each receiver gets exactly the puts the table gives the sender's role")
def test_every_identity_puts_only_its_own_keys_on_links_the_receiver_opened(creds):
    _matrix(creds, receivers_connect=True)


@pytest.mark.attack("2", "every role's identity used by a peer that connects to each service puts on every key",
                   "each receiver gets exactly the puts the table gives the sender's role")
def test_every_identity_puts_only_its_own_keys_on_links_the_sender_opened(creds):
    _matrix(creds, receivers_connect=False)


def _matrix(creds: Path, receivers_connect: bool) -> None:
    """One sender per role and one receiver per role; every sender puts on every key; each receiver gets exactly
    the puts the table allows that sender."""
    rid = f"acl{free_port()}"
    keys = Keys.for_robot(rid)
    sender_eps = {r: _tls() for r in ROLES}
    receiver_eps = {r: _tls() for r in ROLES}
    got: dict[str, list[tuple[str, str]]] = {r: [] for r in ROLES}
    senders, receivers = {}, {}
    try:
        for r in ROLES:
            senders[r] = ServiceNode(f"sender-{r}", _settings(identity_folder(creds, r), rid, listen=[sender_eps[r]],
                                                              acl=False))
            senders[r].__enter__()
        for r in ROLES:
            connect = list(sender_eps.values()) if receivers_connect else []
            receivers[r] = ServiceNode(f"receiver-{r}", _settings(identity_folder(creds, r), rid,
                                                                  listen=[receiver_eps[r]], connect=connect))
            receivers[r].__enter__()
            for scope in (f"{keys.prefix}/**", "lbr/**"):
                receivers[r].session.declare_subscriber(
                    scope, lambda s, r=r: got[r].append((s.payload.to_bytes().decode(), str(s.key_expr))))
        if not receivers_connect:  # the senders open the links this time
            for r in ROLES:
                senders[r].close()
                senders[r] = ServiceNode(f"sender-{r}", _settings(identity_folder(creds, r), rid,
                                                                  connect=list(receiver_eps.values()), acl=False))
                senders[r].__enter__()
        for r in ROLES:
            wait_for(lambda r=r: len(list(senders[r].session.info.peers_zid())) == len(ROLES), 10.0,
                     f"{r}'s links to every receiver")
            _until_heard(senders[r], r, keys, got)
        for r in ROLES:
            for key in _attempts(keys):
                _put(senders[r], key, r)
            _put(senders[r], _barrier_key(keys, r), f"{r}-barrier")
        for q in ROLES:
            wait_for(lambda q=q: {s for s, _ in got[q] if s.endswith("-barrier")} == {f"{r}-barrier" for r in ROLES},
                     10.0, f"every sender's barrier at {q}")
        for q in ROLES:
            arrived = {(s, k) for s, k in got[q] if s in ROLES}
            allowed = {(r, k) for r in ROLES for k in _attempts(keys) if may_put(keys, r, k)}
            assert arrived == allowed, (q, sorted(arrived ^ allowed))
    finally:
        for node in (*senders.values(), *receivers.values()):
            node.close()


@pytest.mark.attack("2", "a peer with a certificate of the cell's CA for a name that is no role, and one with "
                         "another CA's certificate, put on the e-stop release and the torque command",
                   'nothing arrives, no presence; another CA opens no link')
def test_a_peer_that_is_no_role_may_do_nothing(creds, tmp_path):
    rid = f"acl{free_port()}"
    keys = Keys.for_robot(rid)
    # a certificate signed by the cell's own CA (whoever holds ca/ca.key) for a name that is not a role
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    ca_key = serialization.load_pem_private_key((creds / CA_FOLDER / "ca.key").read_bytes(), password=None)
    ca_cert = x509.load_pem_x509_certificate((creds / CA_FOLDER / "ca.pem").read_bytes())
    stranger = tmp_path / "stranger"
    stranger.mkdir()
    key, cert = issue("intruder", ("localhost", "127.0.0.1"), 1, ca_key, ca_cert)
    ca_path, cert_path, key_path = identity_files(stranger)
    write_key_and_cert(cert_path, key_path, key, cert)
    ca_path.write_bytes((creds / CA_FOLDER / "ca.pem").read_bytes())
    # and a whole other cell's identity
    foreign = tmp_path / "foreign"
    make_credentials(foreign)
    ep = _tls()
    robot_settings = _settings(identity_folder(creds, "robot"), rid, listen=[ep])
    got = []
    with ServiceNode("robot", robot_settings) as robot, \
            ServiceNode("stranger", _settings(stranger, rid, connect=[ep], acl=False)) as intruder, \
            ServiceNode("foreign", _settings(identity_folder(foreign, "controller"), rid, connect=[ep],
                                             acl=False)) as other, \
            ServiceNode("controller", _settings(identity_folder(creds, "controller"), rid, connect=[ep])) as ctl:
        robot.session.declare_subscriber(f"{keys.prefix}/**", lambda s: got.append(s.payload.to_bytes()))
        wait_subscribed(ctl.session, keys.robot_command)
        for node in (intruder, other):
            for key in (keys.robot_command, keys.controller_estop_release, keys.controller_estop):
                node.session.put(key, node.service.encode())
        ctl.session.put(keys.robot_command, b"controller")
        wait_for(lambda: b"controller" in got, 5.0, "the controller's command")
        time.sleep(0.3)
        assert got == [b"controller"]
        assert not list(other.session.info.peers_zid()), "another CA's certificate opens no link"
        assert "stranger" not in robot.alive_services(0.5), "a non-role cannot even declare its presence"


def test_the_bridge_config_joins_as_the_bridge_over_mutual_tls_with_the_cells_access_list(creds):
    """zenoh-bridge-ros2dds is not ours: compose starts it with ``-c /secrets/zenoh-bridge.json5`` and its own
    identity folder at /secrets. A Zenoh session opened from that very file (its paths pointed at this test's
    folder) stands for the bridge: the adapter's command reaches it, a perception identity's does not."""
    import json

    rid = f"acl{free_port()}"
    ep = _tls()
    folder = identity_folder(creds, "bridge")
    text = (folder / BRIDGE_CONFIG).read_text().replace('"/secrets/', f'"{folder}/')
    cfg = json.loads(text)
    ros2dds = cfg["plugins"]["ros2dds"]  # only the stack's topics cross; the state express and first
    assert ros2dds["pub_priorities"] == ["/lbr/state=1:express"] and ros2dds["reliable_routes_blocking"] is False
    assert ros2dds["allow"]["subscribers"] == ["/lbr/command/torque"] and "/lbr/state" in ros2dds["allow"]["publishers"]
    assert cfg["access_control"]["default_permission"] == "deny"
    conf = zenoh.Config.from_json5(text)
    conf.insert_json5("listen/endpoints", json.dumps([ep]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(conf) as bridge, \
            ServiceNode("robot", _settings(identity_folder(creds, "robot"), rid, connect=[ep])) as adapter, \
            ServiceNode("perception", _settings(identity_folder(creds, "perception"), rid, connect=[ep],
                                                acl=False)) as rogue:
        got = []
        sub = bridge.declare_subscriber("lbr/command/torque", lambda s: got.append(s.payload.to_bytes()))
        wait_subscribed(adapter.session, "lbr/command/torque")
        wait_subscribed(rogue.session, "lbr/command/torque")
        rogue.session.put("lbr/command/torque", b"rogue")
        adapter.session.put("lbr/command/torque", b"cdr")
        wait_for(lambda: b"cdr" in got, 5.0, "the adapter's command at the bridge")
        time.sleep(0.2)
        assert got == [b"cdr"]
        sub.undeclare()
