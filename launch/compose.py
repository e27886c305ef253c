"""docker-compose.yml as the one description of the cell, run as local processes.

:func:`load_compose` reads the services (command, environment, depends_on,
profiles, network aliases) and substitutes ``${VAR}`` / ``${VAR:-default}``
from a variables mapping, as ``docker compose`` does. :func:`localize` turns
them into :class:`LocalService` processes for this machine: service host
names and aliases become ``127.0.0.1``, every Zenoh port a service listens
on becomes a local port (free ones by default, so several cells and the
tests can run side by side), and ``lamps`` becomes this interpreter's entry
point. Nothing else changes: ``lamps up`` and the compose tests run exactly
the commands and environments the containers get.
"""

from __future__ import annotations

import os
import re
import socket
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import yaml

from interfaces.errors import ConfigError

#: The compose file next to the packages (a source checkout or the image's /opt/lamps).
DEFAULT_COMPOSE = Path(__file__).resolve().parent.parent / "docker-compose.yml"

_VAR = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?::?-([^}]*))?\}")
_ENDPOINT = re.compile(r"^(tcp|udp)/([^:/,]+):(\d+)$")


@dataclass(frozen=True)
class ComposeService:
    """One service as written in the compose file (variables substituted)."""

    name: str
    command: tuple[str, ...]
    environment: dict[str, str]
    depends_on: tuple[str, ...] = ()
    profiles: tuple[str, ...] = ()
    aliases: tuple[str, ...] = ()
    volumes: tuple[str, ...] = ()
    labels: dict[str, str] = field(default_factory=dict)
    cap_add: tuple[str, ...] = ()


@dataclass(frozen=True)
class LocalService:
    """A compose service as a local process: argv and the environment it adds to ours."""

    name: str
    argv: tuple[str, ...]
    environment: dict[str, str]
    listen_ports: tuple[int, ...] = field(default=())
    loop: bool = False  # a fixed-rate loop (granted SYS_NICE): it runs, and stops, ahead of the others


def substitute(text: str, variables: Mapping[str, str]) -> str:
    """``${VAR}``, ``${VAR-default}`` and ``${VAR:-default}`` as compose resolves them (unset -> default or "")."""

    def one(m: re.Match) -> str:
        name, default = m.group(1), m.group(2)
        value = variables.get(name)
        if value is None or (value == "" and ":-" in m.group(0)):
            return default if default is not None else ""
        return value

    return _VAR.sub(one, text)


def _strings(value, what: str) -> tuple[str, ...]:
    if value is None:
        return ()
    if isinstance(value, str):
        return (value,)
    if isinstance(value, list) and all(isinstance(v, (str, int, float)) for v in value):
        return tuple(str(v) for v in value)
    raise ConfigError(f"{what} must be a string or a list of strings, got {value!r}")


def load_compose(path: str | os.PathLike = DEFAULT_COMPOSE, variables: Mapping[str, str] | None = None
                 ) -> dict[str, ComposeService]:
    """The services of a compose file, in file order, with ``variables`` (default: ours) substituted.

    Raises ConfigError naming the file and the problem (missing, not YAML,
    no services, a command that is not a list, an unknown dependency).
    """
    p = Path(path)
    variables = dict(os.environ if variables is None else variables)
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such compose file") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("services"), dict) or not data["services"]:
        raise ConfigError(f"{p}: no services")
    out: dict[str, ComposeService] = {}
    for name, svc in data["services"].items():
        where = f"{p}: service {name!r}"
        if not isinstance(svc, dict):
            raise ConfigError(f"{where} must be a mapping")
        cmd = svc.get("command")
        if not isinstance(cmd, list) or not cmd or not all(isinstance(c, str) for c in cmd):
            raise ConfigError(f"{where}: command must be a non-empty list of strings (exec form), got {cmd!r}")
        env_raw = svc.get("environment") or {}
        if isinstance(env_raw, list):
            env_raw = dict(e.split("=", 1) if "=" in e else (e, variables.get(e, "")) for e in env_raw)
        if not isinstance(env_raw, dict):
            raise ConfigError(f"{where}: environment must be a mapping or a list")
        env = {str(k): substitute("" if v is None else str(v), variables) for k, v in env_raw.items()}
        deps = svc.get("depends_on") or []
        deps = tuple(deps) if isinstance(deps, (list, dict)) else _strings(deps, f"{where}: depends_on")
        nets = svc.get("networks") or {}
        aliases: tuple[str, ...] = ()
        if isinstance(nets, dict):
            for net in nets.values():
                if isinstance(net, dict):
                    aliases += _strings(net.get("aliases"), f"{where}: aliases")
        vols = tuple(substitute(str(v), variables) for v in (svc.get("volumes") or ()))
        labels_raw = svc.get("labels") or {}
        if isinstance(labels_raw, list):
            labels_raw = dict(e.split("=", 1) if "=" in e else (e, "") for e in labels_raw)
        if not isinstance(labels_raw, dict):
            raise ConfigError(f"{where}: labels must be a mapping or a list")
        labels = {str(k): substitute(str(v), variables) for k, v in labels_raw.items()}
        out[name] = ComposeService(name, tuple(substitute(c, variables) for c in cmd), env, deps,
                                   _strings(svc.get("profiles"), f"{where}: profiles"), aliases, vols, labels,
                                   _strings(svc.get("cap_add"), f"{where}: cap_add"))
    for s in out.values():
        for d in s.depends_on:
            if d not in out:
                raise ConfigError(f"{p}: service {s.name!r} depends on unknown service {d!r}")
    return out


#: Where the containers find the cell's credentials (``lamps credentials``); ``lamps up`` maps it to a local folder.
SECRETS_MOUNT = "/secrets/"
#: A service labelled ``lamps.up: skip`` is compose's alone: ``lamps up`` does its job itself (learning the skill).
SKIP_LABEL = "lamps.up"


def run_locally(services: list[ComposeService]) -> list[ComposeService]:
    """The services ``lamps up`` starts as processes: all but those labelled ``lamps.up: skip``."""
    return [s for s in services if s.labels.get(SKIP_LABEL) != "skip"]


def active(services: Mapping[str, ComposeService], profiles: tuple[str, ...]) -> list[ComposeService]:
    """Services compose starts with ``profiles`` enabled, dependencies first (file order otherwise)."""
    on = [s for s in services.values() if not s.profiles or set(s.profiles) & set(profiles)]
    names = {s.name for s in on}
    ordered: list[ComposeService] = []
    seen: set[str] = set()

    def visit(s: ComposeService, stack: tuple[str, ...]) -> None:
        if s.name in seen:
            return
        if s.name in stack:
            raise ConfigError(f"compose: dependency cycle {' -> '.join(stack + (s.name,))}")
        for d in s.depends_on:
            if d in names:
                visit(services[d], stack + (s.name,))
        seen.add(s.name)
        ordered.append(s)

    for s in on:
        visit(s, ())
    return ordered


def free_port() -> int:
    """A TCP port on 127.0.0.1 nobody listens on now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listen_ports(s: ComposeService) -> list[int]:
    ports = []
    for ep in s.environment.get("LAMPS_ZENOH_LISTEN", "").split(","):
        m = _ENDPOINT.match(ep.strip())
        if m:
            ports.append(int(m.group(3)))
    return ports


def localize(services: list[ComposeService], port_of: Mapping[tuple[str, int], int] | None = None,
             lamps_argv0: tuple[str, ...] | None = None, secrets: Path | None = None) -> list[LocalService]:
    """The services as local processes (see the module docstring).

    port_of : (service, container port) -> local port; missing ones get
    :func:`free_port`. lamps_argv0 : what replaces ``lamps`` in commands
    (default: this interpreter running the console script's module).
    secrets : the local folder that stands for the containers' ``/secrets``
    (the cell's credentials) in environment values.
    """
    lamps = lamps_argv0 or (sys.executable, "-m", "interfaces.cli")
    host_of: dict[str, str] = {}
    for s in services:
        for h in (s.name, *s.aliases):
            host_of[h] = s.name
    ports = dict(port_of or {})
    for s in services:
        for p in listen_ports(s):
            ports.setdefault((s.name, p), free_port())

    def endpoint(ep: str, own: str) -> str:
        m = _ENDPOINT.match(ep.strip())
        if not m:
            return ep.strip()
        proto, host, port = m.group(1), m.group(2), int(m.group(3))
        target = own if host in ("0.0.0.0", "localhost", "127.0.0.1") else host_of.get(host)
        if target is None:
            raise ConfigError(f"compose: service {own!r} connects to {ep.strip()!r}, but no active service "
                              f"is called {host!r}")
        if (target, port) not in ports:
            raise ConfigError(f"compose: service {own!r} connects to {ep.strip()!r}, but {target!r} does not "
                              f"listen on {port}")
        return f"{proto}/127.0.0.1:{ports[(target, port)]}"

    out = []
    for s in services:
        env = dict(s.environment)
        if secrets is not None:
            env = {k: (str(secrets / v[len(SECRETS_MOUNT):]) if v.startswith(SECRETS_MOUNT) else v)
                   for k, v in env.items()}
        for key in ("LAMPS_ZENOH_LISTEN", "LAMPS_ZENOH_CONNECT"):
            if env.get(key):
                # two names of one service (robot, camera) become one endpoint, once
                env[key] = ",".join(dict.fromkeys(endpoint(e, s.name) for e in env[key].split(",") if e.strip()))
        argv = (*lamps, *s.command[1:]) if s.command[0] == "lamps" else s.command
        out.append(LocalService(s.name, tuple(argv), env, tuple(ports[(s.name, p)] for p in listen_ports(s)),
                                "SYS_NICE" in s.cap_add))
    return out
