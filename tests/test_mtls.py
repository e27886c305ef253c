"""Mutual TLS between the cell's peers over real Zenoh on loopback, with certificates from ``lamps certificates``.

A peer with a certificate signed by the cell's CA joins; one signed by another CA, one with no client
certificate, and one speaking plain TCP to the TLS port never join: the listening service never sees their
liveliness tokens nor any sample they put, over a few seconds of trying.
"""

from __future__ import annotations

import json
import stat
import time

import pytest
import zenoh
from cryptography import x509
from cryptography.hazmat.primitives.asymmetric import ec

from interfaces.codec import encode
from interfaces.errors import ConfigError
from interfaces.messages import Estop
from runtime.certificates import CA_CERT, CA_KEY, add_certificate, cert_paths
from runtime.certificates import main as certificates_main
from runtime.config import ZenohSettings
from runtime.session import ServiceNode, zenoh_config

from .zenoh_helpers import free_port, wait_alive

#: How long a peer that must not get in is given to try [s].
REFUSED_FOR_S = 3.0


@pytest.fixture(scope="module")
def pki(tmp_path_factory):
    cell, other = tmp_path_factory.mktemp("cell"), tmp_path_factory.mktemp("other")
    assert certificates_main([str(cell)]) == 0
    assert certificates_main([str(other), "--name", "controller"]) == 0  # a controller of someone else's cell
    return cell, other


def _tls(d, name: str, rid: str, listen=(), connect=()) -> ZenohSettings:
    cert, key = cert_paths(d, name)
    return ZenohSettings(listen=tuple(listen), connect=tuple(connect), robot_id=rid, tls_ca=str(d / CA_CERT),
                         tls_certificate=str(cert), tls_private_key=str(key))


def test_certificates_are_signed_by_the_cell_ca_with_private_keys_readable_by_their_owner_only(pki, tmp_path, capsys):
    cell, _ = pki
    ca = x509.load_pem_x509_certificate((cell / CA_CERT).read_bytes())
    robot = x509.load_pem_x509_certificate(cert_paths(cell, "robot")[0].read_bytes())
    robot.verify_directly_issued_by(ca)
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    names = robot.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "robot" in names.get_values_for_type(x509.DNSName)
    assert [str(a) for a in names.get_values_for_type(x509.IPAddress)] == ["127.0.0.1"]
    assert isinstance(robot.public_key(), ec.EllipticCurvePublicKey)
    for path in (cell / CA_KEY, cert_paths(cell, "robot")[1]):
        assert stat.S_IMODE(path.stat().st_mode) == 0o600, path
    assert certificates_main([str(cell)]) == 1 and "not overwritten" in capsys.readouterr().err
    assert certificates_main([str(cell), "--if-missing"]) == 0
    laptop = add_certificate(cell, "laptop", hosts=("10.0.0.7", "cell-laptop.local"))
    x509.load_pem_x509_certificate(laptop.read_bytes()).verify_directly_issued_by(ca)
    assert certificates_main([str(tmp_path / "empty"), "--add", "x"]) == 1
    assert "no usable CA" in capsys.readouterr().err
    assert certificates_main([str(tmp_path / "bad"), "--name", "../etc"]) == 1


def test_tls_settings_are_all_or_nothing_and_refuse_plain_endpoints(pki):
    cell, _ = pki
    with pytest.raises(ConfigError, match="all of tls_ca"):
        ZenohSettings(tls_ca=str(cell / CA_CERT))
    with pytest.raises(ConfigError, match="every endpoint must be tls"):
        _tls(cell, "robot", "x", listen=("tcp/127.0.0.1:7447",))
    with pytest.raises(ConfigError, match="tls_certificate"):
        zenoh_config(ZenohSettings(listen=("tls/127.0.0.1:1",), tls_ca=str(cell / CA_CERT),
                                   tls_certificate=str(cell / "nobody.pem"), tls_private_key=str(cell / "x.key")))


def _raw_config(connect: str, tls: dict | None) -> zenoh.Config:
    cfg = zenoh.Config()
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("connect/endpoints", json.dumps([connect]))
    if tls is not None:
        cfg.insert_json5("transport/link/tls", json.dumps(tls))
    return cfg


@pytest.mark.attack('identity', "a peer with another CA's certificate, without one, or plain TCP to a TLS port",
                    'no link, no token, no sample')
@pytest.mark.slow
def test_only_peers_with_a_certificate_from_the_cell_ca_join(pki):
    cell, other = pki
    port = free_port()
    rid = f"tls{port}"
    endpoint = f"tls/127.0.0.1:{port}"
    with ServiceNode("robot", _tls(cell, "robot", rid, listen=(endpoint,))) as robot:
        keys = robot.keys
        estops = robot.inbox(keys.controller_estop, Estop)
        with ServiceNode("controller", _tls(cell, "controller", rid, connect=(endpoint,))) as ctl:
            wait_alive(robot, "controller")
            deadline = time.monotonic() + 5.0
            while estops.get(0.05) is None:  # until the subscription has propagated: then one arrives
                assert time.monotonic() < deadline, "the certified controller's e-stop never arrived"
                ctl.publish(keys.controller_estop, Estop(stamp_ns=1, engaged=True, reason="cell", source="ctl"))
        # someone else's CA; no client certificate (server authentication only); plain TCP on the TLS port
        foreign = ServiceNode("controller", _tls(other, "controller", rid, connect=(endpoint,)))
        no_cert = zenoh.open(_raw_config(endpoint, {"root_ca_certificate": str(cell / CA_CERT)}))
        plain = zenoh.open(_raw_config(f"tcp/127.0.0.1:{port}", None))
        with foreign:
            others = (foreign.session, no_cert, plain)
            tokens = [s.liveliness().declare_token(keys.alive(f"intruder{i}")) for i, s in enumerate(others)]
            pubs = [s.declare_publisher(keys.controller_estop) for s in others]
            end = time.monotonic() + REFUSED_FOR_S
            while time.monotonic() < end:
                for i, pub in enumerate(pubs):
                    pub.put(encode(Estop(stamp_ns=2, engaged=True, reason=f"intruder{i}", source="x")))
                assert estops.get(0.1) is None, "a peer without a cell certificate delivered a sample"
            assert not any(n.startswith("intruder") for n in robot.alive_services(0.5))
            for t in tokens:
                t.undeclare()
        no_cert.close()
        plain.close()
