"""What moves the arm, authenticated end to end: the router relays, it does not vouch.

Zenoh's access list names the peer at the other end of a *link*. Behind a
router that peer is the router, whatever client put the sample, so a
router whose list is off, or a stolen router key, could pass anyone's
torque command or e-stop release on. The robot side therefore checks the
original sender itself, with the keys of the identities ``lamps
credentials`` already gave each role (P-256, signed by the cell's CA):

* **Torque commands** carry a MAC (HMAC-SHA256, 16 bytes) under a key only
  the controller and the robot side can compute: static-static ECDH between
  the controller's and the robot's certificate keys, through HKDF-SHA256
  with the controller's session and a nonce the robot side draws at each
  start (``info``), so a command is good for one controller session against
  one start of the robot side only. Each side introduces itself
  (:class:`~interfaces.messages.Introduction`: its certificate, its
  session or nonce) on its own key; the other checks the certificate
  against the cell's CA, its validity and its common name (the role, and
  the cell in a site). 2 us a command on either side, against 40 us to
  sign and 90 us to verify an ECDSA signature per command at 1 kHz.
* **An e-stop release** carries the operator's certificate and an ECDSA
  signature over the cell's prefix, its wall-clock stamp, reason and source;
  a release older than :data:`RELEASE_MAX_AGE_S`, or not newer than the
  last one taken, is a replay and refused.

A receiver without an identity (``--insecure``, the in-process cell) checks
nothing: there is nothing to check with. Everything here is pure: no
Zenoh, no threads.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import hmac
import os
import struct
from array import array
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from .access import role_and_cell
from .errors import InterfaceError

if TYPE_CHECKING:
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric import ec

#: Bytes of a command's MAC (HMAC-SHA256 truncated: 128 bits).
MAC_BYTES = 16
#: Bytes of the robot side's per-start nonce.
NONCE_BYTES = 16
#: A signed release older than this, by the receiver's wall clock, is refused [s] (clocks of a cell's hosts are
#: assumed synchronised to well within it: NTP on a LAN keeps them to milliseconds).
RELEASE_MAX_AGE_S = 30.0
_INFO = b"lamps robot command v1"


class AuthError(InterfaceError):
    """A certificate, MAC or signature that does not prove what it claims; the message names why."""


@dataclass(frozen=True)
class LocalIdentity:
    """This service's own identity: role and cell of its certificate, its private key, its certificate (PEM), the
    cell's CA certificate."""

    role: str
    cell: str | None
    private_key: ec.EllipticCurvePrivateKey
    certificate_pem: bytes
    ca_certificate: x509.Certificate


def load_identity(tls_ca: str, tls_certificate: str, tls_private_key: str) -> LocalIdentity | None:
    """The identity in these files (a ZenohSettings' ``tls_*``), or None when there is none (``tls_ca`` empty)."""
    if not tls_ca:
        return None
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    try:
        pem = Path(tls_certificate).read_bytes()
        cert = x509.load_pem_x509_certificate(pem)
        key = serialization.load_pem_private_key(Path(tls_private_key).read_bytes(), password=None)
        ca = x509.load_pem_x509_certificate(Path(tls_ca).read_bytes())
    except (OSError, ValueError) as exc:
        raise AuthError(f"identity files cannot be read: {exc}") from None
    if not isinstance(key, ec.EllipticCurvePrivateKey):
        raise AuthError(f"identity key {tls_private_key} is not an elliptic-curve key")
    cn = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    role, cell = role_and_cell(str(cn[0].value) if cn else "")
    return LocalIdentity(role, cell, key, pem, ca)


def peer_public_key(certificate_pem: bytes, identity: LocalIdentity, role: str, now: dt.datetime | None = None):
    """The public key of a peer's certificate that proves ``role`` of ``identity``'s cell: signed by the cell's CA,
    valid now, common name the role (``role@cell`` in a site). AuthError naming what fails."""
    from cryptography import x509
    from cryptography.exceptions import InvalidSignature
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    try:
        cert = x509.load_pem_x509_certificate(certificate_pem)
    except ValueError as exc:
        raise AuthError(f"not a certificate: {exc}") from None
    ca = identity.ca_certificate
    if cert.issuer != ca.subject:
        raise AuthError(f"certificate issued by {cert.issuer.rfc4514_string()}, not the cell's CA")
    ca_key, algorithm = ca.public_key(), cert.signature_hash_algorithm
    if not isinstance(ca_key, ec.EllipticCurvePublicKey) or algorithm is None:
        raise AuthError("the cell's CA key is not an elliptic-curve key, or the certificate names no hash")
    try:
        ca_key.verify(cert.signature, cert.tbs_certificate_bytes, ec.ECDSA(algorithm))
    except InvalidSignature:
        raise AuthError("certificate not signed by the cell's CA") from None
    now = now or dt.datetime.now(dt.UTC)
    if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
        raise AuthError(f"certificate not valid now (valid {cert.not_valid_before_utc:%Y-%m-%d %H:%M} to "
                        f"{cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC)")
    cn = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    name = str(cn[0].value) if cn else ""
    if role_and_cell(name) != (role, identity.cell):
        want = role if identity.cell is None else f"{role}@{identity.cell}"
        raise AuthError(f"certificate of {name!r}, not of {want!r}")
    key = cert.public_key()
    if not isinstance(key, ec.EllipticCurvePublicKey):
        raise AuthError("certificate key is not an elliptic-curve key")
    return key


def new_nonce() -> bytes:
    """A fresh random nonce (the robot side draws one at each start)."""
    return os.urandom(NONCE_BYTES)


def command_key(identity: LocalIdentity, peer_key, session: str, nonce: bytes) -> bytes:
    """The 32-byte MAC key of ``session``'s commands to the robot start ``nonce``: HKDF-SHA256 of the static ECDH
    secret of this side's key and the peer's (the same on both sides)."""
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.hazmat.primitives.kdf.hkdf import HKDF

    secret = identity.private_key.exchange(ec.ECDH(), peer_key)
    info = _INFO + b"|" + session.encode() + b"|" + nonce
    return HKDF(algorithm=hashes.SHA256(), length=32, salt=None, info=info).derive(secret)


class CommandMac:
    """MACs of one session's torque commands under :func:`command_key`'s key."""

    def __init__(self, key: bytes) -> None:
        self._key = key
        self._head = struct.Struct("<q")

    def mac(self, seq: int, mode: str, tau_nm) -> bytes:
        """MAC_BYTES over ``seq``, ``mode`` and the torques (n,) [Nm] as little-endian doubles."""
        data = self._head.pack(seq) + mode.encode() + b"|" + array("d", tau_nm).tobytes()
        return hmac.digest(self._key, data, hashlib.sha256)[:MAC_BYTES]

    def check(self, seq: int, mode: str, tau_nm, mac: bytes) -> bool:
        """True when ``mac`` is this key's for the command (constant time)."""
        return hmac.compare_digest(self.mac(seq, mode, tau_nm), mac)


def _release_payload(prefix: str, wall_ns: int, reason: str, source: str) -> bytes:
    return "|".join(("lamps estop release v1", prefix, str(wall_ns), reason, source)).encode()


def sign_release(identity: LocalIdentity, prefix: str, wall_ns: int, reason: str, source: str) -> bytes:
    """The operator's ECDSA (SHA-256) signature of a release of the cell under ``prefix``."""
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec

    return identity.private_key.sign(_release_payload(prefix, wall_ns, reason, source), ec.ECDSA(hashes.SHA256()))


def check_release(identity: LocalIdentity, prefix: str, certificate_pem: bytes, signature: bytes, wall_ns: int,
                  reason: str, source: str, last_wall_ns: int, now_ns: int | None = None) -> None:
    """Nothing when the release is the operator's, fresh and newer than ``last_wall_ns``; AuthError naming why not."""
    from cryptography.exceptions import InvalidSignature
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec

    if not certificate_pem or not signature:
        raise AuthError("unsigned (a release must carry the operator's certificate and signature)")
    key = peer_public_key(certificate_pem, identity, "operator")
    try:
        key.verify(signature, _release_payload(prefix, wall_ns, reason, source), ec.ECDSA(hashes.SHA256()))
    except InvalidSignature:
        raise AuthError("signature does not match the operator's certificate") from None
    now = dt.datetime.now(dt.UTC).timestamp() * 1e9 if now_ns is None else now_ns
    if abs(now - wall_ns) > RELEASE_MAX_AGE_S * 1e9:
        raise AuthError(f"stamped {abs(now - wall_ns) / 1e9:.0f} s from now (a replay, or clocks apart)")
    if wall_ns <= last_wall_ns:
        raise AuthError("not newer than the last release taken (a replay)")


def release_estop(settings, reason: str, source: str):
    """An e-stop release (:class:`~interfaces.messages.Estop`, ``engaged=False``) for the cell of ``settings``
    (a ZenohSettings), signed with its identity when it has one (it must be the operator's to be taken)."""
    import time

    from .messages import Estop

    wall_ns = time.time_ns()
    identity = load_identity(settings.tls_ca, settings.tls_certificate, settings.tls_private_key)
    if identity is None:
        return Estop(stamp_ns=time.monotonic_ns(), engaged=False, reason=reason, source=source, wall_ns=wall_ns)
    return Estop(stamp_ns=time.monotonic_ns(), engaged=False, reason=reason, source=source, wall_ns=wall_ns,
                 certificate=identity.certificate_pem,
                 signature=sign_release(identity, settings.keys.prefix, wall_ns, reason, source))


class AuthAccount:
    """One receiver's account of what it refused, and its check of e-stop releases (shared by the robot side and the
    controller): each refusal counted by reason in ``counters`` (``<counter>: <why>``) and logged at most every
    :data:`LOG_EVERY_S`; releases taken only as :func:`check_release` allows, each newer than the last."""

    LOG_EVERY_S = 5.0

    def __init__(self, identity: LocalIdentity | None, prefix: str, counters, logger) -> None:
        self.identity = identity
        self.prefix = prefix
        self.counters = counters
        self._log = logger
        self._last_log = -float("inf")
        self._last_release_wall_ns = 0

    def refuse(self, counter: str, why: str) -> bool:
        """Count and (rate-limited) log a refusal; False, for ``return account.refuse(...)``."""
        import time

        self.counters[f"{counter}: {why.split(':')[0][:60]}"] += 1
        now = time.monotonic()
        if now - self._last_log >= self.LOG_EVERY_S:
            self._last_log = now
            self._log.warning("%s: %s", counter.replace("_", " "), why)
        return False

    def release_ok(self, release) -> bool:
        """True when the e-stop release (an :class:`~interfaces.messages.Estop`) is the operator's, fresh and new
        (always, without an identity)."""
        if self.identity is None:
            return True
        try:
            check_release(self.identity, self.prefix, release.certificate, release.signature, release.wall_ns,
                          release.reason, release.source, self._last_release_wall_ns)
        except AuthError as exc:
            return self.refuse("estop_releases_refused", str(exc))
        self._last_release_wall_ns = release.wall_ns
        return True
