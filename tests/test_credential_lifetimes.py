"""How long a cell's identities last, what its CA may certify, and that Zenoh's TLS holds it to that.

One-run credentials (``lamps up``'s, in the run folder) last 24 hours; a
site's (``lamps credentials DIR``, ``lamps certificates DIR``) 365 days or
``--days``. The cell's CA is ``CA:TRUE, pathlen:0`` and every leaf ``CA:FALSE``, for
TLS client and server authentication, its key for signatures and key
agreement. Over real Zenoh TLS (rustls / webpki), whichever side opens the
link: a certificate signed with a role's key (a stolen leaf used as a CA)
gets no session; a path length is enforced on every CA of a chain but the
trust anchor. The anchor's own ``pathlen:0`` is not: a leaf issued by an
intermediate that the cell's CA certified does get a session (an expected
failure, strict: it shows when Zenoh starts enforcing it), while
``cryptography``'s RFC 5280 verifier refuses that chain.
"""

from __future__ import annotations

import datetime as dt
import json
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
import zenoh
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from interfaces.codec import encode
from interfaces.keys import Keys
from interfaces.messages import Estop
from runtime.certificates import CA_CERT, DEFAULT_DAYS, cert_paths
from runtime.certificates import main as certificates_main
from runtime.credentials import (
    CA_FILE,
    CA_FOLDER,
    RUN_DAYS,
    CredentialsExpired,
    check_not_expired,
    identity_files,
    identity_folder,
    make_credentials,
)
from runtime.credentials import main as credentials_main

from .zenoh_helpers import free_port

#: How long a peer that must not get in is given to try [s].
REFUSED_FOR_S = 3.0
#: A certificate's lifetime may be off its nominal one by this (made 5 min early, a slow test) [s].
SLACK_S = 5 * 60 + 60


def _cert(path: Path) -> x509.Certificate:
    return x509.load_pem_x509_certificate(path.read_bytes())


def _lifetime_s(cert: x509.Certificate) -> float:
    return (cert.not_valid_after_utc - dt.datetime.now(dt.UTC)).total_seconds()


def _all_certificates(directory: Path) -> list[Path]:
    return [directory / CA_FOLDER / CA_FILE] + sorted(p for p in directory.glob("*/cert.pem"))


def test_one_run_credentials_last_24_hours_and_a_sites_365_days_or_days(tmp_path, capsys):
    from launch.site import cell_credentials

    run = tmp_path / "run"
    made = cell_credentials(SimpleNamespace(credentials=None, robot_id=None), run)  # what lamps up makes
    assert RUN_DAYS * 24 == 24.0
    for path in _all_certificates(made):
        assert abs(_lifetime_s(_cert(path)) - 24 * 3600) < SLACK_S, path
    site = tmp_path / "site"
    assert credentials_main([str(site)]) == 0
    assert DEFAULT_DAYS == 365
    for path in _all_certificates(site):
        assert abs(_lifetime_s(_cert(path)) - 365 * 86400) < SLACK_S, path
    assert credentials_main([str(tmp_path / "month"), "--days", "30"]) == 0
    for path in _all_certificates(tmp_path / "month"):
        assert abs(_lifetime_s(_cert(path)) - 30 * 86400) < SLACK_S, path
    assert credentials_main([str(tmp_path / "x"), "--days", "4000"]) == 2
    assert "--days must be in [1, 3650]" in capsys.readouterr().err
    assert certificates_main([str(tmp_path / "certs")]) == 0
    assert abs(_lifetime_s(_cert(tmp_path / "certs" / CA_CERT)) - 365 * 86400) < SLACK_S
    assert abs(_lifetime_s(_cert(cert_paths(tmp_path / "certs", "robot")[0])) - 365 * 86400) < SLACK_S


def test_a_complete_set_that_expired_is_refused_by_if_missing_naming_the_date(tmp_path):
    d = tmp_path / "secrets"
    make_credentials(d)
    assert make_credentials(d, if_missing=True)  # still valid: kept
    later = dt.datetime.now(dt.UTC) + dt.timedelta(days=2)
    with pytest.raises(CredentialsExpired, match=r"expired on \d{4}-\d\d-\d\d .*delete .* and make new ones"):
        check_not_expired(d, _all_certificates(d), now=later)


def test_the_ca_certifies_end_entities_only_and_each_leaf_is_a_tls_client_and_server(tmp_path):
    d = tmp_path / "secrets"
    make_credentials(d)
    ca = _cert(d / CA_FOLDER / CA_FILE)
    bc = ca.extensions.get_extension_for_class(x509.BasicConstraints)
    assert bc.critical and bc.value.ca and bc.value.path_length == 0
    ku = ca.extensions.get_extension_for_class(x509.KeyUsage)
    assert ku.critical and ku.value.key_cert_sign and ku.value.crl_sign and not ku.value.digital_signature
    for path in _all_certificates(d)[1:]:
        leaf = _cert(path)
        leaf.verify_directly_issued_by(ca)
        bc = leaf.extensions.get_extension_for_class(x509.BasicConstraints)
        assert bc.critical and not bc.value.ca, path
        ku = leaf.extensions.get_extension_for_class(x509.KeyUsage)
        assert ku.critical and ku.value.digital_signature and ku.value.key_agreement, path
        assert not (ku.value.key_cert_sign or ku.value.crl_sign or ku.value.key_encipherment), path
        eku = leaf.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
        assert set(eku) == {ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH}, path
        assert leaf.not_valid_after_utc <= ca.not_valid_after_utc


# ----------------------------------------------------------------------------------- an intermediate CA over TLS
def _sign(subject: str, key, issuer_name: x509.Name, issuer_key, ca: bool, path_length: int | None = None,
          hosts: tuple[str, ...] = ()) -> x509.Certificate:
    now = dt.datetime.now(dt.UTC)
    b = (x509.CertificateBuilder().subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, subject)]))
         .issuer_name(issuer_name).public_key(key.public_key()).serial_number(x509.random_serial_number())
         .not_valid_before(now - dt.timedelta(minutes=5)).not_valid_after(now + dt.timedelta(days=1))
         .add_extension(x509.BasicConstraints(ca=ca, path_length=path_length), critical=True)
         .add_extension(x509.KeyUsage(digital_signature=not ca, key_cert_sign=ca, crl_sign=ca,
                                      content_commitment=False, key_encipherment=False, data_encipherment=False,
                                      key_agreement=False, encipher_only=False, decipher_only=False), critical=True)
         .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
         .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(issuer_key.public_key()),
                        critical=False))
    if not ca:
        b = (b.add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH,
                                                    ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False)
             .add_extension(x509.SubjectAlternativeName([x509.DNSName("localhost")]), critical=False))
    return b.sign(issuer_key, hashes.SHA256())


def _pem(*certs: x509.Certificate) -> bytes:
    return b"".join(c.public_bytes(serialization.Encoding.PEM) for c in certs)


def _identity(folder: Path, ca_pem: bytes, key, chain: tuple[x509.Certificate, ...]) -> Path:
    """An identity folder: the CA to trust, the leaf and the CAs between it and the root (``chain``), its key."""
    folder.mkdir(parents=True)
    ca, cert, key_path = identity_files(folder)
    ca.write_bytes(ca_pem)
    cert.write_bytes(_pem(*chain))
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    return folder


def _config(folder: Path, listen: str | None = None, connect: str | None = None) -> zenoh.Config:
    """A plain Zenoh peer with mutual TLS from ``folder`` (no LAMPS access list: the link alone is tested)."""
    ca, cert, key = (str(p) for p in identity_files(folder))
    cfg = zenoh.Config()
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("scouting/gossip/enabled", "false")
    cfg.insert_json5("listen/endpoints", json.dumps([listen] if listen else []))
    cfg.insert_json5("connect/endpoints", json.dumps([connect] if connect else []))
    cfg.insert_json5("transport/link/tls", json.dumps({
        "root_ca_certificate": ca, "enable_mtls": True, "listen_certificate": cert, "listen_private_key": key,
        "connect_certificate": cert, "connect_private_key": key}))
    return cfg


def _joins(listener: Path, connector: Path, wait_s: float) -> bool:
    """True if a peer with ``connector``'s identity, connecting to one with ``listener``'s, gets a session: the
    listener sees its liveliness token and a sample it puts within ``wait_s``."""
    endpoint = f"tls/localhost:{free_port()}"
    key = Keys.for_robot("pathlen").controller_estop
    with zenoh.open(_config(listener, listen=endpoint)) as lis:
        got: list = []
        sub = lis.declare_subscriber(key, lambda s: got.append(s))
        time.sleep(0.3)
        with zenoh.open(_config(connector, connect=endpoint)) as con:
            token = con.liveliness().declare_token(f"{key}/alive")
            end = time.monotonic() + wait_s
            while time.monotonic() < end and not got:
                con.put(key, encode(Estop(stamp_ns=1, engaged=True, reason="pathlen", source="test")))
                time.sleep(0.1)
            alive = bool(list(lis.liveliness().get(f"{key}/alive", timeout=0.5)))
            token.undeclare()
        sub.undeclare()
    return bool(got) or alive


def _cell_ca(cell: Path):
    """(key, certificate) of the CA of credentials folder ``cell``."""
    key = serialization.load_pem_private_key((cell / CA_FOLDER / "ca.key").read_bytes(), password=None)
    return key, _cert(cell / CA_FOLDER / CA_FILE)


def test_a_verifier_that_reads_the_cas_path_length_refuses_a_leaf_of_an_intermediate(tmp_path):
    """``cryptography``'s RFC 5280 verifier (client certificates) takes the cell's own leaves and refuses one issued
    by an intermediate the cell's CA certified: ``pathlen:0`` says so."""
    from cryptography.x509 import verification

    cell = tmp_path / "cell"
    make_credentials(cell)
    ca_key, ca = _cell_ca(cell)
    inter_key, leaf_key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    inter = _sign("intermediate", inter_key, ca.subject, ca_key, ca=True)
    leaf = _sign("controller", leaf_key, inter.subject, inter_key, ca=False)
    verifier = (verification.PolicyBuilder().store(verification.Store([ca]))
                .time(dt.datetime.now(dt.UTC)).build_client_verifier())
    verifier.verify(_cert(identity_files(identity_folder(cell, "controller"))[1]), [])
    with pytest.raises(verification.VerificationError, match="path length constraint violated"):
        verifier.verify(leaf, [inter])


@pytest.mark.slow
@pytest.mark.attack("identity", "a certificate for the controller signed with perception's stolen key (a leaf used "
                                "as a CA) opens a link, either side",
                   "no TLS session")
def test_a_certificate_signed_with_a_stolen_role_key_gets_no_tls_session(tmp_path):
    """Every leaf is ``CA:FALSE``, which Zenoh's TLS (rustls / webpki) enforces on every certificate between the
    leaf and the CA: a thief of perception's key who signs a ``controller`` certificate with it gets no session,
    whichever side opens the link; the cell's own controller does."""
    cell = tmp_path / "cell"
    make_credentials(cell)
    ca_pem = (cell / CA_FOLDER / CA_FILE).read_bytes()
    perception = identity_folder(cell, "perception")
    stolen_key = serialization.load_pem_private_key(identity_files(perception)[2].read_bytes(), password=None)
    stolen = _cert(identity_files(perception)[1])
    key = ec.generate_private_key(ec.SECP256R1())
    forged = _identity(tmp_path / "forged", ca_pem, key,
                       (_sign("controller", key, stolen.subject, stolen_key, ca=False), stolen))
    robot = identity_folder(cell, "robot")
    assert _joins(robot, identity_folder(cell, "controller"), 10.0), "the cell's own controller gets in"
    assert not _joins(robot, forged, REFUSED_FOR_S), "a certificate signed by a role's key got a session"
    assert not _joins(forged, robot, REFUSED_FOR_S), "a service linked to a certificate signed by a role's key"


@pytest.mark.slow
def test_zenoh_tls_enforces_a_path_length_below_the_trust_anchor(tmp_path):
    """The same chain as below, but the CA with ``pathlen:0`` certified by a root above it (the root the trust
    anchor): rustls refuses the intermediate's leaf, and takes the leaf the pathlen:0 CA issued itself. So the
    chains are presented and verified, and the path length is read on every CA but the anchor."""
    root_key, ca_key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    root_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "root")])
    root = _sign("root", root_key, root_name, root_key, ca=True)
    ca = _sign("cell CA", ca_key, root.subject, root_key, ca=True, path_length=0)
    own_key = ec.generate_private_key(ec.SECP256R1())
    own = _identity(tmp_path / "own", _pem(root), own_key, (_sign("robot", own_key, ca.subject, ca_key, ca=False), ca))
    other_key = ec.generate_private_key(ec.SECP256R1())
    other = _identity(tmp_path / "other", _pem(root), other_key,
                      (_sign("controller", other_key, ca.subject, ca_key, ca=False), ca))
    inter_key, leaf_key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    inter = _sign("intermediate", inter_key, ca.subject, ca_key, ca=True)
    rogue = _identity(tmp_path / "rogue", _pem(root), leaf_key,
                      (_sign("controller", leaf_key, inter.subject, inter_key, ca=False), inter, ca))
    assert _joins(own, other, 10.0)
    assert not _joins(own, rogue, REFUSED_FOR_S)
    assert not _joins(rogue, own, REFUSED_FOR_S)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="rustls-webpki (Zenoh 1.10) reads nothing of the trust anchor but its name and key: the "
                          "cell CA's pathlen:0 is not enforced on TLS links")
def test_a_leaf_issued_by_an_intermediate_under_the_cell_ca_gets_no_tls_session(tmp_path):
    """Known gap, kept as a test so that a Zenoh whose TLS enforces the anchor's path length shows (XPASS fails
    the run: then say so in docs/security.md). The cell's CA is the trust anchor, and webpki enforces no
    constraint of an anchor: a leaf issued by an intermediate CA that the cell's CA certified gets a session.
    Only the holder of the CA's key can make such an intermediate (our CA never issues one), and it could issue
    any leaf directly anyway."""
    cell = tmp_path / "cell"
    make_credentials(cell)
    ca_key, ca = _cell_ca(cell)
    inter_key, leaf_key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    inter = _sign("intermediate", inter_key, ca.subject, ca_key, ca=True)
    rogue = _identity(tmp_path / "rogue", (cell / CA_FOLDER / CA_FILE).read_bytes(), leaf_key,
                      (_sign("controller", leaf_key, inter.subject, inter_key, ca=False), inter))
    robot = identity_folder(cell, "robot")
    assert not _joins(robot, rogue, REFUSED_FOR_S), "an intermediate's leaf under the cell's CA got a session"
    assert not _joins(rogue, robot, REFUSED_FOR_S), "a service linked to an intermediate's leaf listening"
