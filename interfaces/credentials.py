"""``lamps credentials DIR``: one password per role of the cell and the dictionary that checks them.

Writes ``DIR/<role>.password`` (a random 256-bit secret, one line) for
every role of :data:`interfaces.access.ROLES` and ``DIR/credentials.txt``
(``role:password`` per line: what each service checks connecting peers
against), each atomically with mode 0600, and ``DIR/zenoh-bridge.json5``:
a Zenoh configuration for zenoh-bridge-ros2dds (``-c``) that authenticates
it as the robot side (an authenticated adapter cannot open a link to an
unauthenticated bridge), its dictionary at the containers' ``/secrets``. Existing files are never
overwritten: a cell keeps its credentials until they are deleted on
purpose (``--if-missing``: a complete set already there is kept, exit 0;
compose's one-shot ``credentials`` service runs it so).
 A service then runs with ``LAMPS_ZENOH_USER=<role>``,
``LAMPS_ZENOH_PASSWORD_FILE=DIR/<role>.password``,
``LAMPS_ZENOH_CREDENTIALS_FILE=DIR/credentials.txt`` and
``LAMPS_ZENOH_ACCESS_CONTROL=true``.

Zenoh's user-password authentication is a challenge-response: a service
that checks others needs their passwords, so this keeps a cell on one
trusted host (or one compose project) honest, not a hostile network; cells
that leave one machine need mutual TLS with per-service certificates.
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import sys
from pathlib import Path

from lampskit.atomic import write_text_atomic

from .access import ROLES

DICTIONARY = "credentials.txt"
BRIDGE_CONFIG = "zenoh-bridge.json5"
#: Where the bridge's container finds the dictionary (compose mounts ./secrets there).
BRIDGE_DICTIONARY = "/secrets/credentials.txt"
#: zenoh-plugin-ros2dds settings (its DEFAULT_CONFIG.json5, 09d68c0): only the lbr stack's topics the adapter
#: uses cross the bridge; the 1 kHz state goes first and unbatched (``pub_priorities`` ``1:express``, which the
#: plugin applies to the ROS -> Zenoh direction only: the adapter's own publisher sets the command's), and
#: a congested route drops a state rather than blocking the stack's writer (``reliable_routes_blocking``).
BRIDGE_ROS2DDS = {
    "allow": {"publishers": ["/lbr/state", "/lbr/joint_states", "/lbr/force_torque_broadcaster/wrench"],
              "subscribers": ["/lbr/command/torque"], "service_servers": [], "service_clients": [],
              "action_servers": [], "action_clients": []},
    "pub_priorities": ["/lbr/state=1:express"],
    "reliable_routes_blocking": False,
}


def password_file(directory: Path, role: str) -> Path:
    return directory / f"{role}.password"


def make_credentials(directory: Path, if_missing: bool = False) -> dict[str, Path]:
    """Create the files (see the module docstring); role -> its password file. FileExistsError if any exists
    (with ``if_missing``: only if some but not all exist; a complete set is kept as it is)."""
    directory.mkdir(parents=True, exist_ok=True)
    targets = [password_file(directory, r) for r in ROLES] + [directory / DICTIONARY]
    present = [str(p) for p in targets if p.exists()]
    if if_missing and len(present) == len(targets):
        _write_bridge_config(directory, if_missing=True)
        return {role: password_file(directory, role) for role in ROLES}
    if present:
        raise FileExistsError(f"credentials already exist, not overwritten: {', '.join(present)}")
    words = {role: secrets.token_hex(32) for role in ROLES}
    for role, word in words.items():
        write_text_atomic(password_file(directory, role), word + "\n", mode=0o600)
    write_text_atomic(directory / DICTIONARY, "".join(f"{r}:{w}\n" for r, w in words.items()), mode=0o600)
    _write_bridge_config(directory)
    return {role: password_file(directory, role) for role in ROLES}


def _write_bridge_config(directory: Path, if_missing: bool = False) -> None:
    path = directory / BRIDGE_CONFIG
    if if_missing and path.exists():
        return
    word = password_file(directory, "robot").read_text(encoding="utf-8").strip()
    config = {"transport": {"auth": {"usrpwd": {"user": "robot", "password": word,
                                               "dictionary_file": BRIDGE_DICTIONARY}}},
              "plugins": {"ros2dds": BRIDGE_ROS2DDS}}
    write_text_atomic(path, json.dumps(config, indent=2) + "\n", mode=0o600)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="lamps credentials", description=__doc__.split("\n\n")[0])
    ap.add_argument("directory", type=Path, help="where the password files and credentials.txt go")
    ap.add_argument("--if-missing", action="store_true",
                    help="keep a complete set that is already there (exit 0); a partial one is still an error")
    args = ap.parse_args(argv)
    try:
        files = make_credentials(args.directory, args.if_missing)
    except (FileExistsError, OSError) as exc:
        print(f"lamps credentials: {exc}", file=sys.stderr)
        return 1
    d = args.directory
    print(f"wrote {len(files)} password files and {d / DICTIONARY} (mode 0600); a service runs as a role with")
    print(f"  LAMPS_ZENOH_USER=<role> LAMPS_ZENOH_PASSWORD_FILE={d}{os.sep}<role>.password "
          f"LAMPS_ZENOH_CREDENTIALS_FILE={d / DICTIONARY} LAMPS_ZENOH_ACCESS_CONTROL=true")
    print(f"roles: {', '.join(ROLES)}")
    return 0
