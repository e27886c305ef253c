"""One configuration loader for every service: a TOML file plus environment overrides.

The file has one table per concern (``[zenoh]``, ``[sim]``, ``[controller]``,
``[perception]``); each service turns its table into its own frozen
dataclass. Environment variables override single values without editing the
file (what compose and tests use):

* ``LAMPS__<SECTION>__<KEY>=<value>`` sets ``[section] key`` (lower-cased;
  ``LAMPS__SIM__BOARD__PRESET`` reaches into the sub-table ``[sim.board]``);
  the value is parsed as a TOML value (``500``, ``true``, ``"x"``,
  ``["tcp/127.0.0.1:7447"]``) and taken as a plain string if it is not one.
* Shorthands: ``LAMPS_ROBOT_ID``, ``LAMPS_KEY_PREFIX``, ``LAMPS_ZENOH_LISTEN``
  and ``LAMPS_ZENOH_CONNECT`` (comma-separated endpoints), ``LAMPS_ZENOH_MODE``,
  ``LAMPS_ZENOH_MULTICAST`` and ``LAMPS_ZENOH_GOSSIP`` (``true``/``false``).

``[zenoh]`` keys: ``mode`` (``peer`` | ``client`` | ``router``), ``listen``
and ``connect`` (lists of endpoints such as ``tcp/127.0.0.1:7447``),
``multicast_scouting`` (default false: it fails in containers and CI),
``gossip`` (default true: peers learn each other's endpoints from the
ones they connect to and link directly; false: only the configured links,
e.g. when a link must pass a particular network path),
``robot_id``, ``key_prefix`` (default ``lamps/<robot_id>``); identity and
access control (:mod:`interfaces.access`, :mod:`runtime.credentials`):
``identity`` (the service's folder from ``lamps credentials DIR``: its
role's certificate and key and the cell's CA; mutual TLS, every endpoint
then ``tls/...``), or ``tls_ca``, ``tls_certificate`` and ``tls_private_key``
given one by one (all three or none); ``access_control`` (true: apply the
cell's default-deny access list, subjects the certificates' common names;
unset: on whenever the service has an identity); ``insecure`` (shorthand
``LAMPS_ZENOH_INSECURE``, option ``--insecure``: a service started without
an identity, or with the access list off, runs only when told so, and says
so in every status, :mod:`runtime.service_security`; the robot role's
access list stays on whatever it says);
``ros_namespaces`` (default ``["lbr", "camera"]``: the ROS topic namespaces
zenoh-bridge-ros2dds carries, the keys the robot side and the bridge may put);
``cells`` (shorthand ``LAMPS_ZENOH_CELLS``, comma-separated robot ids; default
none): a router or site viewer serving several cells applies the site's
access list (:func:`interfaces.access.site_acl`) instead of one cell's.
Zenoh's user-password authentication is still there for a router-held
dictionary: ``user`` (the role), ``password_file``, ``credentials_file``.
Shorthands ``LAMPS_ZENOH_IDENTITY``, ``LAMPS_ZENOH_ACCESS_CONTROL``,
``LAMPS_ZENOH_USER``, ``LAMPS_ZENOH_PASSWORD_FILE``,
``LAMPS_ZENOH_CREDENTIALS_FILE``, ``LAMPS_ZENOH_TLS_CA``, ``LAMPS_ZENOH_TLS_CERTIFICATE``,
``LAMPS_ZENOH_TLS_PRIVATE_KEY``. ``config_file`` (shorthand
``LAMPS_ZENOH_CONFIG_FILE``): a Zenoh configuration file (JSON5, Zenoh's own
format) to start from, for what these settings do not cover (QoS, buffers,
interceptors such as ``downsampling``); the settings above are applied over
it, and a file that sets one of the fields they own is refused, naming it.
"""

from __future__ import annotations

import math
import os
import tomllib
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Annotated, Any

import msgspec

from interfaces.access import DEFAULT_ROS_NAMESPACES, ROLES, check_cells
from interfaces.errors import ConfigError
from interfaces.keys import DEFAULT_ROBOT_ID, Keys

ZENOH_MODES = ("peer", "client", "router")
_SHORTHANDS = {
    "LAMPS_ROBOT_ID": ("zenoh", "robot_id"),
    "LAMPS_KEY_PREFIX": ("zenoh", "key_prefix"),
    "LAMPS_ZENOH_LISTEN": ("zenoh", "listen"),
    "LAMPS_ZENOH_CONNECT": ("zenoh", "connect"),
    "LAMPS_ZENOH_MODE": ("zenoh", "mode"),
    "LAMPS_ZENOH_MULTICAST": ("zenoh", "multicast_scouting"),
    "LAMPS_ZENOH_GOSSIP": ("zenoh", "gossip"),
    "LAMPS_ZENOH_USER": ("zenoh", "user"),
    "LAMPS_ZENOH_PASSWORD_FILE": ("zenoh", "password_file"),
    "LAMPS_ZENOH_CREDENTIALS_FILE": ("zenoh", "credentials_file"),
    "LAMPS_ZENOH_ACCESS_CONTROL": ("zenoh", "access_control"),
    "LAMPS_ZENOH_INSECURE": ("zenoh", "insecure"),
    "LAMPS_ZENOH_IDENTITY": ("zenoh", "identity"),
    "LAMPS_ZENOH_TLS_CA": ("zenoh", "tls_ca"),
    "LAMPS_ZENOH_TLS_CERTIFICATE": ("zenoh", "tls_certificate"),
    "LAMPS_ZENOH_TLS_PRIVATE_KEY": ("zenoh", "tls_private_key"),
    "LAMPS_ZENOH_CONFIG_FILE": ("zenoh", "config_file"),
    "LAMPS_ZENOH_CELLS": ("zenoh", "cells"),
}


def _check_ros_namespace(ns: str) -> None:
    chunks = ns.strip("/").split("/")
    if not all(c and all(ch.isalnum() or ch == "_" for ch in c) for c in chunks):
        raise ConfigError(f"[zenoh] ros_namespaces must be ROS namespaces like 'lbr' or 'cell1/lbr', got {ns!r}")


@dataclass(frozen=True)
class ZenohSettings:
    """How a service joins the Zenoh network and which keys it uses."""

    mode: str = "peer"
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    gossip: bool = True
    robot_id: str = DEFAULT_ROBOT_ID
    key_prefix: str = ""
    user: str = ""
    password_file: str = ""
    credentials_file: str = ""
    access_control: bool | None = None
    insecure: bool = False
    identity: str = ""
    tls_ca: str = ""
    tls_certificate: str = ""
    tls_private_key: str = ""
    config_file: str = ""
    ros_namespaces: tuple[str, ...] = DEFAULT_ROS_NAMESPACES
    cells: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name in ("mode", "robot_id", "key_prefix"):
            if not isinstance(getattr(self, name), str):
                raise ConfigError(f"[zenoh] {name} must be a string, got {getattr(self, name)!r}")
        for name in ("user", "password_file", "credentials_file", "identity", "tls_ca", "tls_certificate",
                     "tls_private_key", "config_file"):
            if not isinstance(getattr(self, name), str):
                raise ConfigError(f"[zenoh] {name} must be a string, got {getattr(self, name)!r}")
        if self.access_control is not None and not isinstance(self.access_control, bool):
            raise ConfigError(f"[zenoh] access_control must be true or false, got {self.access_control!r}")
        if not isinstance(self.insecure, bool):
            raise ConfigError(f"[zenoh] insecure must be true or false, got {self.insecure!r}")
        if self.user and self.user not in ROLES:
            raise ConfigError(f"[zenoh] user must be one of the cell's roles {ROLES}, got {self.user!r}")
        if self.user and not (self.password_file and self.credentials_file):
            raise ConfigError("[zenoh] user needs password_file and credentials_file (make them with "
                              "'lamps credentials DIR')")
        if self.identity:
            from .credentials import identity_files

            files = [str(p) for p in identity_files(Path(self.identity))]
            given = (self.tls_ca, self.tls_certificate, self.tls_private_key)
            if any(given) and list(given) != files:  # a copy of settings made from an identity carries its files
                raise ConfigError("[zenoh] identity (a folder from 'lamps credentials') or tls_ca, tls_certificate "
                                  "and tls_private_key, not both")
            for name, path in zip(("tls_ca", "tls_certificate", "tls_private_key"), files):
                object.__setattr__(self, name, path)
        if self.access_control is None:  # an identity brings its cell's access list unless turned off on purpose
            object.__setattr__(self, "access_control", bool(self.tls_ca))
        if self.access_control and not (self.user or self.tls_ca):
            raise ConfigError("[zenoh] access_control needs an identity (LAMPS_ZENOH_IDENTITY: the service's folder "
                              "from 'lamps credentials DIR') or a user and its password")
        if self.access_control and self.user and not self.tls_ca and self.mode != "router":
            raise ConfigError("[zenoh] access_control with a user-password identity works on a router only: Zenoh's "
                              "user-password authentication names the side that connects, so a peer cannot tell who "
                              "it connected to (and would deny it everything); give the service an identity folder "
                              "(mutual TLS: 'lamps credentials DIR')")
        if (not isinstance(self.ros_namespaces, (list, tuple))
                or not all(isinstance(n, str) for n in self.ros_namespaces)):
            raise ConfigError(f"[zenoh] ros_namespaces must be a list of ROS namespaces, got {self.ros_namespaces!r}")
        for ns in self.ros_namespaces:
            _check_ros_namespace(ns)
        object.__setattr__(self, "ros_namespaces", tuple(self.ros_namespaces))
        if not isinstance(self.cells, (list, tuple)) or not all(isinstance(c, str) for c in self.cells):
            raise ConfigError(f"[zenoh] cells must be a list of robot ids, got {self.cells!r}")
        object.__setattr__(self, "cells", check_cells(self.cells))
        if self.mode not in ZENOH_MODES:
            raise ConfigError(f"[zenoh] mode must be one of {ZENOH_MODES}, got {self.mode!r}")
        for name in ("listen", "connect"):
            value = getattr(self, name)
            if not isinstance(value, (list, tuple)) or not all(isinstance(e, str) and "/" in e for e in value):
                raise ConfigError(f"[zenoh] {name} must be a list of endpoints like 'tcp/127.0.0.1:7447', "
                                  f"got {value!r}")
            object.__setattr__(self, name, tuple(value))
        tls = (self.tls_ca, self.tls_certificate, self.tls_private_key)
        if any(tls) and not all(tls):
            raise ConfigError("[zenoh] mutual TLS needs all of tls_ca, tls_certificate and tls_private_key (make them "
                              "with 'lamps certificates DIR')")
        if all(tls):
            plain = [e for e in (*self.listen, *self.connect) if not e.startswith("tls/")]
            if plain:
                raise ConfigError(f"[zenoh] with mutual TLS every endpoint must be tls/...: {plain} would let peers "
                                  "without a certificate in")
        for name in ("multicast_scouting", "gossip"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"[zenoh] {name} must be true or false, got {getattr(self, name)!r}")
        _ = self.keys  # validates robot_id and key_prefix

    @property
    def keys(self) -> Keys:
        return Keys(self.key_prefix) if self.key_prefix else Keys.for_robot(self.robot_id)

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> ZenohSettings:
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(table) - known)
        if unknown:
            raise ConfigError(f"[zenoh] unknown key(s) {unknown}; valid: {sorted(known)}")
        return cls(**dict(table))


@dataclass(frozen=True)
class Config:
    """The whole configuration: ``zenoh`` parsed, every other table raw for its service."""

    zenoh: ZenohSettings = field(default_factory=ZenohSettings)
    tables: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    source: str = "defaults"

    def table(self, name: str) -> Mapping[str, Any]:
        """The ``[name]`` table (empty if absent)."""
        return self.tables.get(name, {})


def _parse_value(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _env_overrides(env: Mapping[str, str]) -> list[tuple[tuple[str, ...], Any]]:
    """(table path, value) per override: shorthands first, then ``LAMPS__A__B[__C...]`` in name order."""
    out: list[tuple[tuple[str, ...], Any]] = []
    for name, (section, key) in _SHORTHANDS.items():
        if name in env:
            raw = env[name]
            if key in ("listen", "connect", "cells"):
                value: Any = [e.strip() for e in raw.split(",") if e.strip()]
            else:
                value = _parse_value(raw)
            out.append(((section, key), value))
    for name in sorted(env):
        if name.startswith("LAMPS__"):
            parts = name[len("LAMPS__"):].lower().split("__")
            if len(parts) < 2 or not all(parts):
                raise ConfigError(f"environment variable {name}: expected LAMPS__<SECTION>__<KEY> "
                                  "(or LAMPS__<SECTION>__<TABLE>__<KEY>)")
            out.append((tuple(parts), _parse_value(env[name])))
    return out


def load_config(path: str | os.PathLike | None = None, env: Mapping[str, str] | None = None) -> Config:
    """Read ``path`` (TOML; None = defaults only), apply ``env`` overrides (default ``os.environ``).

    Raises
    ------
    ConfigError
        Missing or unreadable file, invalid TOML, a table that is not a
        table, an invalid ``[zenoh]`` value, a malformed override.
    """
    env = os.environ if env is None else env
    data: dict[str, Any] = {}
    source = "defaults"
    if path is not None:
        p = Path(path)
        if not p.is_file():
            raise ConfigError(f"{p}: no such config file")
        try:
            data = tomllib.loads(p.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{p}: not valid TOML ({exc})") from None
        source = str(p)
    for name, table in data.items():
        if not isinstance(table, dict):
            raise ConfigError(f"{source}: top-level key {name!r} must be a [table], got {type(table).__name__}")
    for path_keys, value in _env_overrides(env):
        table = data
        for part in path_keys[:-1]:
            table = table.setdefault(part, {})
            if not isinstance(table, dict):
                raise ConfigError(f"environment override {'.'.join(path_keys)}: {part!r} is not a table")
        table[path_keys[-1]] = value
    zenoh = ZenohSettings.from_table(data.pop("zenoh", {}))
    return Config(zenoh, data, source)


# --------------------------------------------------------------------------
# checks every service's parameter dataclasses share


def In(lo: float, hi: float) -> msgspec.Meta:
    """A setting's allowed closed range, declared on its field: ``x: Annotated[float, In(0.0, 1.0)] = 0.5``
    (an ``int`` field takes whole numbers only). :func:`check_declared` checks it."""
    return msgspec.Meta(ge=lo, le=hi)


_DECLARED: dict[type, list[tuple[str, type, float, float]]] = {}


def declared_bounds(cls: type) -> list[tuple[str, type, float, float]]:
    """(field, int or float, lo, hi) of every field of dataclass ``cls`` declared with :func:`In`."""
    if cls not in _DECLARED:
        hints = typing.get_type_hints(cls, include_extras=True)
        out: list[tuple[str, type, float, float]] = []
        for f in fields(cls):
            hint = hints.get(f.name)
            if typing.get_origin(hint) is not Annotated:
                continue
            base, *extras = typing.get_args(hint)
            for meta in extras:
                if isinstance(meta, msgspec.Meta) and meta.ge is not None and meta.le is not None:
                    out.append((f.name, int if base is int else float, meta.ge, meta.le))
        _DECLARED[cls] = out
    return _DECLARED[cls]


def check_declared(obj: Any, section: str) -> None:
    """Check every field of dataclass ``obj`` against its declared range (:func:`In`); ConfigError naming the
    section, the key, the value and the range. Cross-field rules stay in the dataclass's ``__post_init__``."""
    for name, kind, lo, hi in declared_bounds(type(obj)):
        if kind is int:
            check_int(section, name, getattr(obj, name), int(lo), int(hi))
        else:
            check_range(section, name, getattr(obj, name), lo, hi)


def check_range(section: str, name: str, value: Any, lo: float, hi: float) -> None:
    """Raise ConfigError unless ``value`` is a number (not a bool) in ``[lo, hi]``."""
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not (lo <= value <= hi):
        raise ConfigError(f"[{section}] {name} must be a number in [{lo}, {hi}], got {value!r}")


def check_int(section: str, name: str, value: Any, lo: int, hi: int | None = None, what: str = "an integer") -> None:
    """Raise ConfigError unless ``value`` is an int (not a bool) in ``[lo, hi]`` (no upper bound if ``hi`` is None)."""
    if not isinstance(value, int) or isinstance(value, bool) or value < lo or (hi is not None and value > hi):
        if hi is not None:
            text = f"{what} in [{lo}, {hi}]"
        else:
            text = "a non-negative integer" if lo == 0 else f"{what} >= {lo}"
        raise ConfigError(f"[{section}] {name} must be {text}, got {value!r}")


def check_vector(section: str, name: str, value: Any, n: int) -> tuple[float, ...]:
    """``value`` as a tuple of ``n`` finite floats, or ConfigError."""
    ok = (isinstance(value, (list, tuple)) and len(value) == n
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value))
    if not ok:
        raise ConfigError(f"[{section}] {name} must be a list of {n} finite numbers, got {value!r}")
    return tuple(float(v) for v in value)


def dataclass_from_table(cls, section: str, table: Mapping[str, Any], **extra):
    """``cls(**table, **extra)``, refusing a non-table or an unknown key with the valid ones named."""
    if not isinstance(table, Mapping):
        raise ConfigError(f"[{section}] must be a table, got {type(table).__name__}")
    known = {f.name for f in fields(cls)} - set(extra)
    unknown = sorted(set(table) - known)
    if unknown:
        raise ConfigError(f"[{section}] unknown key(s) {unknown}; valid: {sorted(known)}")
    return cls(**dict(table), **extra)


# --------------------------------------------------------------------------
# the Zenoh options every service's command line has


def add_zenoh_options(parser) -> None:
    """``--listen``, ``--connect`` (repeatable endpoints), ``--robot-id`` and ``--zenoh-config`` on an argparse
    parser."""
    parser.add_argument("--listen", metavar="ENDPOINT", action="append",
                        help="Zenoh endpoint to listen on (repeatable)")
    parser.add_argument("--connect", metavar="ENDPOINT", action="append",
                        help="Zenoh endpoint to connect to (repeatable)")
    parser.add_argument("--robot-id", help="key prefix becomes lamps/<robot-id>")
    parser.add_argument("--zenoh-config", metavar="FILE",
                        help="a Zenoh configuration file (JSON5) to start from: QoS, buffers, interceptors "
                             "([zenoh] config_file)")
    parser.add_argument("--insecure", action="store_true", default=None,
                        help="run without an identity (plain TCP, no access list) or with the access list off, on "
                             "purpose; every status says so ([zenoh] insecure; the robot role's list stays on)")


def zenoh_with_options(settings: ZenohSettings, args) -> ZenohSettings:
    """``settings`` with the options of :func:`add_zenoh_options` that were given (they win over the file).

    These are the settings a service starts with: ConfigError when they would run it without an identity or
    without its access list unasked (:func:`runtime.service_security.check_service_security`)."""
    from .service_security import check_service_security

    over = {k: v for k, v in (("listen", args.listen), ("connect", args.connect), ("robot_id", args.robot_id),
                              ("config_file", getattr(args, "zenoh_config", None)),
                              ("insecure", getattr(args, "insecure", None))) if v is not None}
    if over:
        settings = ZenohSettings(**{**{f: getattr(settings, f) for f in settings.__dataclass_fields__}, **over})
    check_service_security(settings)
    return settings
