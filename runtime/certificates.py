"""``lamps certificates DIR``: a cell's certificate authority and one TLS certificate per service, for mutual TLS.

For cells whose peers are on more than one machine. Writes, each
atomically (private keys mode 0600):

* ``DIR/ca.pem`` (the cell's CA certificate, every peer trusts it) and
  ``DIR/ca.key`` (its key: keep it off the robot cell's machines once the
  certificates are made; only ``--add`` needs it again);
* ``DIR/<name>.pem`` and ``DIR/<name>.key`` per service name (default: the
  cell's roles, :data:`interfaces.access.ROLES`), signed by the CA, usable
  as server *and* client certificate (a peer both listens and connects),
  with the host names and addresses it is reached at as subject
  alternative names (``--host NAME`` repeatable; default the service's
  name, ``localhost`` and ``127.0.0.1``: compose's service names and a
  one-machine cell).

Elliptic-curve keys (P-256), SHA-256 signatures, made with the maintained
``cryptography`` library. The CA may sign only end-entity certificates
(basic constraints ``CA:TRUE, pathlen:0``, key usage certificate and CRL
signing): to a verifier that reads the trust anchor's path length
(OpenSSL, ``cryptography``'s) a leaf issued by an intermediate under it is
no good; Zenoh's TLS (rustls / webpki) reads nothing of an anchor but its
name and key, so there only the CA's key guards against such a chain
(``tests/test_credential_lifetimes.py``). Each service's
certificate is no CA (``CA:FALSE``, which rustls enforces: a certificate
signed with a service's key gets no link), for TLS server and client
authentication (extended key usage), its key for signatures and key
agreement (key usage: the TLS handshake; the static ECDH of
:mod:`interfaces.arm_auth`). Everything is valid for ``--days``
(:data:`DEFAULT_DAYS`, 365) from the moment it is made (5 minutes earlier,
for clocks a little behind). Existing files are never overwritten;
``--if-missing`` keeps a complete set (exit 0), ``--add NAME`` signs one
more service's certificate with the existing CA.

A service then uses ``tls/<host>:<port>`` endpoints and
``LAMPS_ZENOH_TLS_CA=DIR/ca.pem LAMPS_ZENOH_TLS_CERTIFICATE=DIR/<name>.pem
LAMPS_ZENOH_TLS_PRIVATE_KEY=DIR/<name>.key``: Zenoh then requires a
certificate signed by the cell's CA from every peer on both sides of every
link (``enable_mtls``); a peer without one cannot join.
"""

from __future__ import annotations

import argparse
import datetime as dt
import ipaddress
import sys
from pathlib import Path

from interfaces.access import ROLES
from interfaces.errors import ConfigError
from lampskit.atomic import write_atomic

CA_CERT, CA_KEY = "ca.pem", "ca.key"
#: Validity of certificates made for a site, by ``lamps certificates`` and ``lamps credentials`` [days].
DEFAULT_DAYS = 365
#: The longest validity either command makes [days].
MAX_DAYS = 3650
#: Certificates are valid from this long before they are made (a peer whose clock is a little behind) [min].
BACKDATE_MIN = 5
#: Host names every certificate carries unless ``hosts`` is given.
DEFAULT_HOSTS = ("localhost", "127.0.0.1")


def _crypto():
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID
    except ImportError as exc:  # a dependency of the package: only a broken install gets here
        raise RuntimeError(f"the 'cryptography' package is needed to make certificates: {exc}") from None
    return x509, hashes, serialization, ec, ExtendedKeyUsageOID, NameOID


def cert_paths(directory: Path, name: str) -> tuple[Path, Path]:
    """(certificate, private key) of service ``name`` in ``directory``."""
    return directory / f"{name}.pem", directory / f"{name}.key"


def write_key_and_cert(cert_path: Path, key_path: Path, key, cert) -> None:
    _, _, serialization, *_ = _crypto()
    key_pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                serialization.NoEncryption())
    write_atomic(key_path, lambda f: f.write(key_pem), mode=0o600)
    cert_pem = cert.public_bytes(serialization.Encoding.PEM)
    write_atomic(cert_path, lambda f: f.write(cert_pem), mode=0o644)


def _san(hosts: tuple[str, ...]):
    x509 = _crypto()[0]
    names = []
    for h in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            names.append(x509.DNSName(h))
    return x509.SubjectAlternativeName(names)


def _validity(days: float):
    """(not valid before, not valid after) of a certificate made now and valid ``days`` (fractions: 1/24 is an
    hour)."""
    now = dt.datetime.now(dt.UTC)
    return now - dt.timedelta(minutes=BACKDATE_MIN), now + dt.timedelta(days=days)


def _make_ca(directory: Path, days: float):
    key, cert = new_ca(days)
    write_key_and_cert(directory / CA_CERT, directory / CA_KEY, key, cert)
    return key, cert


def new_ca(days: float = DEFAULT_DAYS):
    """A new self-signed CA valid ``days``: (private key, certificate) objects of ``cryptography``. It signs end
    entities only (``pathlen:0``; see the module docstring for who enforces it)."""
    x509, hashes, _, ec, _, NameOID = _crypto()
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "LAMPS cell CA")])
    start, end = _validity(days)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(start).not_valid_after(end)
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=False, key_cert_sign=True, crl_sign=True,
                                         content_commitment=False, key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, encipher_only=False, decipher_only=False),
                           critical=True)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
            .sign(key, hashes.SHA256()))
    return key, cert


def _load_ca(directory: Path):
    x509, _, serialization, *_ = _crypto()
    try:
        cert = x509.load_pem_x509_certificate((directory / CA_CERT).read_bytes())
        key = serialization.load_pem_private_key((directory / CA_KEY).read_bytes(), password=None)
    except OSError as exc:
        raise FileNotFoundError(f"no usable CA in {directory} ({exc.strerror or exc}): make one first") from None
    except ValueError as exc:
        raise ValueError(f"{directory}: the CA files are not a PEM certificate and key ({exc})") from None
    return key, cert


def _sign(directory: Path, name: str, hosts: tuple[str, ...], days: float, ca_key, ca_cert) -> Path:
    key, cert = issue(name, hosts, days, ca_key, ca_cert)
    cert_path, key_path = cert_paths(directory, name)
    write_key_and_cert(cert_path, key_path, key, cert)
    return cert_path


def issue(name: str, hosts: tuple[str, ...], days: float, ca_key, ca_cert):
    """A new key and a certificate for it signed by the CA, valid ``days`` (fractions: 1/24 is an hour; never past
    the CA's end): common name ``name`` (the role access control reads), subject alternative names ``hosts``, no
    CA, server and client use, the key for signatures and key agreement; (private key, certificate)."""
    x509, hashes, _, ec, EKU, NameOID = _crypto()
    key = ec.generate_private_key(ec.SECP256R1())
    start, end = _validity(days)
    end = min(end, ca_cert.not_valid_after_utc)  # never outlives its CA
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
            .issuer_name(ca_cert.subject).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(start).not_valid_after(end)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, key_encipherment=False, key_cert_sign=False,
                                         crl_sign=False, content_commitment=False, data_encipherment=False,
                                         key_agreement=True, encipher_only=False, decipher_only=False),
                           critical=True)
            .add_extension(x509.ExtendedKeyUsage([EKU.SERVER_AUTH, EKU.CLIENT_AUTH]), critical=False)
            .add_extension(_san(hosts), critical=False)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
            .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False)
            .sign(ca_key, hashes.SHA256()))
    return key, cert


def common_name(cert_path: Path) -> str:
    """The common name of the PEM certificate at ``cert_path`` (what access control reads);
    ConfigError naming the file when it cannot be read."""
    x509, *_, NameOID = _crypto()
    try:
        cert = x509.load_pem_x509_certificate(Path(cert_path).read_bytes())
    except (OSError, ValueError) as exc:
        raise ConfigError(f"certificate {str(cert_path)!r} cannot be read: {exc}") from None
    names = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    return str(names[0].value) if names else ""


def _check_name(name: str) -> None:
    if not name or not all(c.isalnum() or c in "-_." for c in name) or name.startswith("."):
        raise ValueError(f"service name {name!r}: use letters, digits, '-', '_' and '.' (it names files)")


def make_certificates(directory: Path, names: tuple[str, ...] = ROLES, hosts: tuple[str, ...] = (),
                      days: float = DEFAULT_DAYS, if_missing: bool = False) -> dict[str, Path]:
    """A new CA and one certificate per name (SANs: ``hosts``, default the name plus :data:`DEFAULT_HOSTS`);
    name -> certificate path. FileExistsError if any target exists (``if_missing``: unless all do)."""
    for n in names:
        _check_name(n)
    directory.mkdir(parents=True, exist_ok=True)
    targets = [directory / CA_CERT, directory / CA_KEY] + [p for n in names for p in cert_paths(directory, n)]
    present = [str(p) for p in targets if p.exists()]
    if if_missing and len(present) == len(targets):
        return {n: cert_paths(directory, n)[0] for n in names}
    if present:
        raise FileExistsError(f"certificates already exist, not overwritten: {', '.join(present)}")
    ca_key, ca_cert = _make_ca(directory, days)
    return {n: _sign(directory, n, hosts or (n, *DEFAULT_HOSTS), days, ca_key, ca_cert) for n in names}


def add_certificate(directory: Path, name: str, hosts: tuple[str, ...] = (), days: float = DEFAULT_DAYS) -> Path:
    """One more service's certificate signed by the CA already in ``directory``."""
    _check_name(name)
    existing = [str(p) for p in cert_paths(directory, name) if p.exists()]
    if existing:
        raise FileExistsError(f"certificates already exist, not overwritten: {', '.join(existing)}")
    ca_key, ca_cert = _load_ca(directory)
    return _sign(directory, name, hosts or (name, *DEFAULT_HOSTS), days, ca_key, ca_cert)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="lamps certificates", description=__doc__.split("\n\n")[0])
    ap.add_argument("directory", type=Path, help="where ca.pem, ca.key and <name>.pem/.key go")
    ap.add_argument("--name", action="append", help=f"a service to certify (repeatable; default: {', '.join(ROLES)})")
    ap.add_argument("--host", action="append", default=[],
                    help="a host name or address the services are reached at (repeatable; default: the service's "
                         f"name, {', '.join(DEFAULT_HOSTS)})")
    ap.add_argument("--days", type=int, default=DEFAULT_DAYS, help=f"validity [days] (default {DEFAULT_DAYS})")
    ap.add_argument("--add", metavar="NAME", help="sign one more service's certificate with the existing CA")
    ap.add_argument("--if-missing", action="store_true", help="keep a complete set that is already there (exit 0)")
    args = ap.parse_args(argv)
    if not 1 <= args.days <= MAX_DAYS:
        print(f"lamps certificates: --days must be in [1, {MAX_DAYS}], got {args.days}", file=sys.stderr)
        return 2
    try:
        if args.add:
            made = {args.add: add_certificate(args.directory, args.add, tuple(args.host), args.days)}
        else:
            names = tuple(args.name) if args.name else ROLES
            made = make_certificates(args.directory, names, tuple(args.host), args.days, args.if_missing)
    except (FileExistsError, FileNotFoundError, ValueError, OSError, RuntimeError) as exc:
        print(f"lamps certificates: {exc}", file=sys.stderr)
        return 1
    d = args.directory
    print(f"CA {d / CA_CERT}; certificates: {', '.join(str(p) for p in made.values())}")
    print(f"a service <name> runs with tls/ endpoints and LAMPS_ZENOH_TLS_CA={d / CA_CERT} "
          f"LAMPS_ZENOH_TLS_CERTIFICATE={d}/<name>.pem LAMPS_ZENOH_TLS_PRIVATE_KEY={d}/<name>.key")
    return 0
