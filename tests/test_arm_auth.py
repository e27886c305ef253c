"""End-to-end authentication of what moves the arm (interfaces/arm_auth.py): the pure parts, on real identities from
``lamps credentials``."""

from __future__ import annotations

import datetime as dt
import time

import pytest

from interfaces.arm_auth import (
    AuthError,
    CommandMac,
    check_release,
    command_key,
    load_identity,
    new_nonce,
    peer_public_key,
    release_estop,
    sign_release,
)
from runtime.config import ZenohSettings
from runtime.credentials import identity_files, identity_folder, make_credentials


@pytest.fixture(scope="module")
def cells(tmp_path_factory):
    """Two cells' credentials (each its own CA) and a site's."""
    root = tmp_path_factory.mktemp("auth")
    make_credentials(root / "a")
    make_credentials(root / "b")
    make_credentials(root / "site", cells=("iiwa-1", "iiwa-2"))
    return root


def _identity(folder):
    return load_identity(*(str(p) for p in identity_files(folder)))


def _pem(folder) -> bytes:
    return identity_files(folder)[1].read_bytes()


def test_the_controller_and_the_robot_side_derive_the_same_key_and_nobody_else_does(cells):
    ctl, robot, perception = (_identity(identity_folder(cells / "a", r)) for r in ("controller", "robot", "perception"))
    nonce = new_nonce()
    at_ctl = command_key(ctl, peer_public_key(_pem(identity_folder(cells / "a", "robot")), ctl, "robot"), "s1", nonce)
    at_robot = command_key(robot, peer_public_key(_pem(identity_folder(cells / "a", "controller")), robot,
                                                  "controller"), "s1", nonce)
    assert at_ctl == at_robot and len(at_ctl) == 32
    # perception's key with the controller's public certificate: not the key
    forged = command_key(perception, peer_public_key(_pem(identity_folder(cells / "a", "robot")), perception, "robot"),
                         "s1", nonce)
    assert forged != at_robot
    # another session, another start of the robot side: other keys
    assert command_key(ctl, robot.private_key.public_key(), "s2", nonce) != at_ctl
    assert command_key(ctl, robot.private_key.public_key(), "s1", new_nonce()) != at_ctl


def test_a_mac_holds_only_for_the_command_it_was_made_for():
    mac = CommandMac(b"k" * 32)
    tau = [0.5, -1.0, 2.0, 0.0, 0.1, 0.2, 0.3]
    m = mac.mac(7, "torque", tau)
    assert len(m) == 16 and mac.check(7, "torque", tau, m)
    assert not mac.check(8, "torque", tau, m)
    assert not mac.check(7, "hold", tau, m)
    assert not mac.check(7, "torque", [*tau[:-1], 0.30000001], m)
    assert not mac.check(7, "torque", tau, b"")
    assert not CommandMac(b"j" * 32).check(7, "torque", tau, m)


def test_a_certificate_proves_only_its_own_role_of_its_own_cell(cells):
    robot = _identity(identity_folder(cells / "a", "robot"))
    peer_public_key(_pem(identity_folder(cells / "a", "controller")), robot, "controller")
    with pytest.raises(AuthError, match="not of 'controller'"):
        peer_public_key(_pem(identity_folder(cells / "a", "perception")), robot, "controller")
    with pytest.raises(AuthError, match="the cell's CA"):
        peer_public_key(_pem(identity_folder(cells / "b", "controller")), robot, "controller")
    with pytest.raises(AuthError, match="not a certificate"):
        peer_public_key(b"garbage", robot, "controller")
    with pytest.raises(AuthError, match="not valid now"):
        peer_public_key(_pem(identity_folder(cells / "a", "controller")), robot, "controller",
                        now=dt.datetime.now(dt.UTC) + dt.timedelta(days=4000))
    # a site: cell iiwa-1's robot side takes iiwa-1's controller, not iiwa-2's
    site_robot = _identity(identity_folder(cells / "site", "robot", "iiwa-1"))
    peer_public_key(_pem(identity_folder(cells / "site", "controller", "iiwa-1")), site_robot, "controller")
    with pytest.raises(AuthError, match="controller@iiwa-2"):
        peer_public_key(_pem(identity_folder(cells / "site", "controller", "iiwa-2")), site_robot, "controller")


def test_a_release_is_taken_only_signed_by_the_operator_fresh_and_once(cells):
    robot = _identity(identity_folder(cells / "a", "robot"))
    op = _identity(identity_folder(cells / "a", "operator"))
    ctl = _identity(identity_folder(cells / "a", "controller"))
    prefix, now = "lamps/iiwa", time.time_ns()
    sig = sign_release(op, prefix, now, "ok", "operator")
    check_release(robot, prefix, op.certificate_pem, sig, now, "ok", "operator", last_wall_ns=0)
    with pytest.raises(AuthError, match="replay"):
        check_release(robot, prefix, op.certificate_pem, sig, now, "ok", "operator", last_wall_ns=now)
    with pytest.raises(AuthError, match="from now"):
        check_release(robot, prefix, op.certificate_pem, sig, now, "ok", "operator", 0, now_ns=now + int(60e9))
    with pytest.raises(AuthError, match="does not match"):
        check_release(robot, prefix, op.certificate_pem, sig, now, "other reason", "operator", 0)
    with pytest.raises(AuthError, match="does not match"):
        check_release(robot, "lamps/other", op.certificate_pem, sig, now, "ok", "operator", 0)
    with pytest.raises(AuthError, match="not of 'operator'"):
        check_release(robot, prefix, ctl.certificate_pem, sign_release(ctl, prefix, now, "ok", "x"), now, "ok", "x", 0)
    with pytest.raises(AuthError, match="unsigned"):
        check_release(robot, prefix, b"", b"", now, "ok", "operator", 0)
    settings = ZenohSettings(identity=str(identity_folder(cells / "a", "operator")), listen=("tls/127.0.0.1:1",))
    e = release_estop(settings, "test", "pytest")
    check_release(robot, settings.keys.prefix, e.certificate, e.signature, e.wall_ns, e.reason, e.source, 0)
    assert not release_estop(ZenohSettings(), "test", "pytest").signature
