"""``lamps credentials DIR``: one identity per role of the cell, each in a folder of its own (mutual TLS).

Writes, each file atomically (private keys mode 0600):

* ``DIR/ca/ca.pem`` and ``DIR/ca/ca.key``: the cell's certificate
  authority. No service is given the CA's key (compose mounts no service
  ``DIR/ca``): it is needed only to add a host or remake an identity.
* ``DIR/<role>/`` for every role of :data:`interfaces.access.ROLES`, and
  ``DIR/ca/router/`` for the router (:data:`interfaces.access.RELAY`,
  ``lamps router``: kept with the CA, never beside a service's folder):
  ``ca.pem`` (the CA's certificate, to check peers), ``cert.pem`` (the
  role's certificate: common name = the role, which is what access control
  reads) and ``key.pem`` (its private key). A service is given its own
  folder only (compose mounts ``DIR/<role>`` at ``/secrets``), so it can
  prove who it is but never be anyone else.
* ``DIR/bridge/zenoh-bridge.json5``: a Zenoh configuration for
  zenoh-bridge-ros2dds (``-c``) that joins as the ``bridge`` role over mutual
  TLS with the cell's access list, only the lbr stack's topics crossing.

Each certificate names the hosts its role is reached at (the compose service
names and aliases of that role, ``localhost`` and ``127.0.0.1``, plus every
``--host``): Zenoh checks the listener's name on every TLS link a service
opens. Elliptic-curve keys (P-256) and SHA-256 signatures, as
:mod:`runtime.certificates` makes them (a CA that certifies end entities
only, ``pathlen:0``).

Lifetimes: ``lamps credentials DIR`` (a site's, compose's ``./secrets``)
are valid :data:`~runtime.certificates.DEFAULT_DAYS` (365) days, or
``--days N``; :func:`make_credentials` called without ``days`` (what
``lamps up`` makes in each run folder, ``<run>/credentials/``) makes
one-run credentials, valid :data:`RUN_DAYS` (24 hours). A complete set
whose CA or any certificate has expired is refused by ``--if-missing``,
naming the date: delete the folder and make new ones.

``--cells ID1,ID2,...`` makes a *site*: several cells behind one router
(:func:`interfaces.access.site_acl`), one CA. Each cell gets ``DIR/<robot
id>/<role>/`` for every role (and its bridge's configuration), the common
name ``<role>@<robot id>`` (``controller@iiwa-1``), so the router tells cell
A's controller from cell B's; ``DIR/<robot id>`` is laid out as a one-cell
``DIR``, so whatever takes a credentials folder takes a cell's. Beside them
``DIR/router/`` (``lamps router --cells ...``) and ``DIR/site-viewer/`` (one
recorder or live view reading every cell).

Existing files are never overwritten: a cell keeps its identities until they
are deleted on purpose (``--if-missing``: a complete set already there is
kept, exit 0; a set made before the router's identity existed gets it from
the same CA; compose's one-shot ``credentials`` service runs it so). A
service then runs with ``LAMPS_ZENOH_IDENTITY=DIR/<role>`` (inside compose:
``/secrets``), ``tls/`` endpoints and ``LAMPS_ZENOH_ACCESS_CONTROL=true``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from interfaces.access import (
    DEFAULT_ROS_NAMESPACES,
    IDENTITIES,
    RELAY,
    ROLES,
    SITE_VIEWER,
    cell_acl,
    check_cells,
    identity_name,
    role_and_cell,
)
from interfaces.keys import Keys
from lampskit.atomic import write_atomic, write_text_atomic

from .certificates import DEFAULT_DAYS, DEFAULT_HOSTS, MAX_DAYS, issue, new_ca, write_key_and_cert

CA_FOLDER = "ca"
#: The files of an identity folder: the CA's certificate, the role's certificate, its private key.
CA_FILE, CERT_FILE, KEY_FILE = "ca.pem", "cert.pem", "key.pem"
BRIDGE_CONFIG = "zenoh-bridge.json5"
#: Validity of one-run credentials (``lamps up``'s, in the run folder) [days]: 24 hours.
RUN_DAYS = 1.0
#: Where the bridge's container finds its identity (compose mounts ./secrets/bridge there).
BRIDGE_SECRETS = "/secrets"
#: The host names each role is reached at in docker-compose.yml (service names and network aliases).
ROLE_HOSTS = {
    "robot": ("robot", "camera", "sim", "lbr-peer", "robot-lbr-sim", "robot-lbr", "bridge"),
    "bridge": ("bridge",),
    "controller": ("controller",),
    "perception": ("perception",),
    "recorder": ("recorder", "foxglove"),
    "operator": ("operator",),
    "router": ("router",),
    SITE_VIEWER: (SITE_VIEWER,),
}
#: zenoh-plugin-ros2dds settings (its DEFAULT_CONFIG.json5, 09d68c0): only the lbr stack's topics the adapter
#: uses cross the bridge; the 1 kHz state goes first and unbatched (``pub_priorities`` ``1:express``, which the
#: plugin applies to the ROS -> Zenoh direction only: the adapter's own publisher sets the command's), and
#: a congested route drops a state rather than blocking the stack's writer (``reliable_routes_blocking``).
BRIDGE_ROS2DDS = {
    "allow": {"publishers": ["/lbr/state", "/lbr/joint_states", "/lbr/force_torque_broadcaster/wrench",
                             "/camera/.*/image_raw", "/camera/.*/image_raw/compressed", "/camera/.*/camera_info"],
              "subscribers": ["/lbr/command/torque"], "service_servers": [], "service_clients": [],
              "action_servers": [], "action_clients": []},
    "pub_priorities": ["/lbr/state=1:express"],
    "reliable_routes_blocking": False,
}


def identity_folder(directory: Path, role: str, cell: str | None = None) -> Path:
    """The folder of ``role``'s identity in a credentials folder ``directory`` (of cell ``cell`` in a site's). The
    router's (:data:`RELAY`) is kept with the CA, ``DIR/ca/router``, never beside a service's folder."""
    if role == RELAY:
        return directory / CA_FOLDER / RELAY
    return directory / role if cell is None else directory / cell / role


def identity_files(folder: Path) -> tuple[Path, Path, Path]:
    """(CA certificate, certificate, private key) of an identity folder."""
    return folder / CA_FILE, folder / CERT_FILE, folder / KEY_FILE


def identities(directory: Path, cells: tuple[str, ...] = ()) -> dict[str, tuple[Path, str]]:
    """Common name -> (folder, role) of every identity ``make_credentials`` puts in ``directory``."""
    if not cells:
        return {name: (identity_folder(directory, name), name) for name in IDENTITIES}
    site = {name: (identity_folder(directory, name), name) for name in (RELAY, SITE_VIEWER)}
    return {**site, **{identity_name(r, c): (identity_folder(directory, r, c), r) for c in cells for r in ROLES}}


def cell_of(folder: Path) -> str | None:
    """The robot id an identity folder's certificate names (``role@robot_id``), or None (a cell of its own)."""
    from .certificates import common_name

    return role_and_cell(common_name(identity_files(folder)[1]))[1]


def make_credentials(directory: Path, if_missing: bool = False, hosts: tuple[str, ...] = (),
                     days: float = RUN_DAYS, cells: tuple[str, ...] = ()) -> dict[str, Path]:
    """Create the files (see the module docstring); common name -> its identity folder. FileExistsError if any
    exists (with ``if_missing``: only if some but not all exist; a complete set is kept as it is unless a
    certificate of it has expired: :class:`CredentialsExpired`).

    days : validity (default :data:`RUN_DAYS`, one run's; ``lamps credentials`` passes ``--days``, default
    365). cells : the robot ids of a site (per-cell identities ``<role>@<robot id>``); empty: one cell, bare roles.
    """
    cells = check_cells(cells)
    plan = identities(directory, cells)
    bridges = [f for f, role in plan.values() if role == "bridge"]
    targets = [directory / CA_FOLDER / n for n in (CA_FILE, "ca.key")]
    targets += [p for f, _ in plan.values() for p in identity_files(f)]
    targets += [f / BRIDGE_CONFIG for f in bridges]
    present = [str(p) for p in targets if p.exists()]
    folders = {name: f for name, (f, _) in plan.items()}
    if if_missing and len(present) == len(targets):
        certificates = [identity_files(f)[1] for f in folders.values()]
        check_not_expired(directory, [directory / CA_FOLDER / CA_FILE, *certificates])
        return folders
    missing = {r: f for r, f in folders.items() if not any(p.exists() for p in identity_files(f))}
    ca_there = all((directory / CA_FOLDER / n).exists() for n in (CA_FILE, "ca.key"))
    if if_missing and not cells and ca_there and missing and len(present) == len(targets) - 3 * len(missing):
        # a set made before an identity was added (the router): issue the missing ones with the same CA
        ca_key, ca_cert = _load_ca(directory / CA_FOLDER)
        _issue_all(directory, {n: plan[n] for n in missing}, ca_key, ca_cert, hosts, days)
        return folders
    if present:
        raise FileExistsError(f"credentials already exist, not overwritten: {', '.join(present[:4])}"
                              f"{' ...' if len(present) > 4 else ''}")
    ca_key, ca_cert = new_ca(days)
    (directory / CA_FOLDER).mkdir(parents=True, exist_ok=True)
    write_key_and_cert(directory / CA_FOLDER / CA_FILE, directory / CA_FOLDER / "ca.key", ca_key, ca_cert)
    _issue_all(directory, plan, ca_key, ca_cert, hosts, days)
    for c in cells or (None,):
        write_bridge_config(identity_folder(directory, "bridge", c), c)
    return folders


class CredentialsExpired(FileExistsError):
    """A complete set of credentials is there but a certificate of it has expired; the message names it."""


def check_not_expired(directory: Path, certificates: list[Path], now=None) -> None:
    """CredentialsExpired naming the first of ``certificates`` (PEM files) no longer valid at ``now`` (UTC)."""
    import datetime as dt

    from cryptography import x509

    now = now or dt.datetime.now(dt.UTC)
    for path in certificates:
        end = x509.load_pem_x509_certificate(path.read_bytes()).not_valid_after_utc
        if end < now:
            raise CredentialsExpired(f"credentials in {directory} expired on {end:%Y-%m-%d %H:%M} UTC ({path}): "
                                     f"delete {directory} and make new ones")


def _load_ca(folder: Path):
    """(key, certificate) of the CA in ``folder``."""
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    cert = x509.load_pem_x509_certificate((folder / CA_FILE).read_bytes())
    key = serialization.load_pem_private_key((folder / "ca.key").read_bytes(), password=None)
    return key, cert


def _issue_all(directory: Path, plan: dict[str, tuple[Path, str]], ca_key, ca_cert, hosts: tuple[str, ...],
               days: float) -> None:
    """Issue each common name of ``plan`` (name -> (folder, role)) into its folder, with the CA's certificate."""
    ca_pem = (directory / CA_FOLDER / CA_FILE).read_bytes()
    for name, (folder, role) in plan.items():
        folder.mkdir(parents=True, exist_ok=True)
        key, cert = issue(name, (*ROLE_HOSTS[role], *DEFAULT_HOSTS, *hosts), days, ca_key, ca_cert)
        ca_path, cert_path, key_path = identity_files(folder)
        write_key_and_cert(cert_path, key_path, key, cert)
        write_atomic(ca_path, lambda f: f.write(ca_pem), mode=0o644)


def bridge_config(secrets: str = BRIDGE_SECRETS, keys: Keys | None = None,
                  ros_namespaces: tuple[str, ...] = DEFAULT_ROS_NAMESPACES, cell: str | None = None) -> dict:
    """zenoh-bridge-ros2dds's configuration: the bridge identity at ``secrets``, the cell's access list (of
    cell ``cell`` of a site: its keys and its identities' names)."""
    ca, cert, key = (f"{secrets}/{n}" for n in (CA_FILE, CERT_FILE, KEY_FILE))
    return {"transport": {"link": {"tls": {"root_ca_certificate": ca, "enable_mtls": True,
                                           "listen_certificate": cert, "listen_private_key": key,
                                           "connect_certificate": cert, "connect_private_key": key}}},
            "access_control": cell_acl(keys or (Keys.for_robot(cell) if cell else Keys()), "cert_common_names",
                                       ros_namespaces, cell),
            "plugins": {"ros2dds": BRIDGE_ROS2DDS}}


def write_bridge_config(folder: Path, cell: str | None = None) -> Path:
    path = folder / BRIDGE_CONFIG
    write_text_atomic(path, json.dumps(bridge_config(cell=cell), indent=2) + "\n", mode=0o644)
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="lamps credentials", description=__doc__.split("\n\n")[0])
    ap.add_argument("directory", type=Path, help="where ca/ and one folder per role go")
    ap.add_argument("--host", action="append", default=[],
                    help="one more host name or address every role may be reached at (repeatable; a cell on "
                         "several machines)")
    ap.add_argument("--days", type=int, default=DEFAULT_DAYS,
                    help=f"validity of the CA and every certificate [days] (default {DEFAULT_DAYS}; lamps up's "
                         f"one-run credentials: {RUN_DAYS * 24:g} hours)")
    ap.add_argument("--if-missing", action="store_true",
                    help="keep a complete set that is already there (exit 0); a partial one is still an error")
    ap.add_argument("--cells", metavar="ID,ID,...", default="",
                    help="a site of several cells behind one router: per robot id DIR/<id>/<role>/ with common "
                         "names <role>@<id>, plus DIR/ca/router/ and DIR/site-viewer/ (default: one cell, DIR/<role>/)")
    args = ap.parse_args(argv)
    if not 1 <= args.days <= MAX_DAYS:
        print(f"lamps credentials: --days must be in [1, {MAX_DAYS}], got {args.days}", file=sys.stderr)
        return 2
    cells = tuple(c.strip() for c in args.cells.split(",") if c.strip())
    try:
        make_credentials(args.directory, args.if_missing, tuple(args.host), args.days, cells)
    except (FileExistsError, OSError, ValueError) as exc:
        print(f"lamps credentials: {exc}", file=sys.stderr)
        return 1
    d = args.directory
    if cells:
        print(f"identities of cells {', '.join(cells)} in {d}/<robot id>/<role>/ (common names <role>@<robot id>), "
              f"of {SITE_VIEWER} in {d}/{SITE_VIEWER}/, of {RELAY} with the CA in {identity_folder(d, RELAY)} (the "
              f"CA's key in {d / CA_FOLDER}: give it to no service)")
    else:
        print(f"identities of the roles in {d}{'/'}<role>/, of {RELAY} with the CA in {identity_folder(d, RELAY)} "
              f"(the CA's key in {d / CA_FOLDER}: give it to no service)")
    print("a service runs as a role with  LAMPS_ZENOH_IDENTITY=<that role's folder>  tls/ endpoints and "
          "LAMPS_ZENOH_ACCESS_CONTROL=true")
    return 0
