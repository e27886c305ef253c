"""docker-compose.yml as the one description of the cell, run as local processes.

:func:`compose_model` reads the services (command, environment, depends_on,
profiles, network aliases) the way ``docker compose`` itself does: from
``docker compose config --format json`` when Compose v2 is installed, and
otherwise from :func:`load_compose`, a reader that implements compose's
variable interpolation (``$VAR``, ``${VAR}``, ``${VAR:-d}``, ``${VAR-d}``,
``${VAR:?err}``, ``${VAR?err}``, ``${VAR:+x}``, ``${VAR+x}``, nesting,
``$$``) and its ``.env`` file (beside the compose file; the environment
wins), and refuses what it does not implement, naming it. The active
profiles come from ``COMPOSE_PROFILES`` (environment, then ``.env``).
The variables are :mod:`.compose_interp`'s.

:func:`localize` turns the services into :class:`LocalService` processes for
this machine: service host names and aliases become ``127.0.0.1``, every
Zenoh port a service listens on becomes a local port (free ones by default,
so several cells and the tests can run side by side), and ``lamps`` becomes
this interpreter's entry point, and a ``--host 0.0.0.0`` (the live view's
in its container) binds ``127.0.0.1``. Nothing else changes: ``lamps up``
and the compose tests run the commands and environments the containers get.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from interfaces.errors import ConfigError
from runtime.ports import free_port

from .compose_interp import active_profiles, compose_variables, interpolate_tree

#: The compose file next to the packages (a source checkout or the image's /opt/lamps).
DEFAULT_COMPOSE = Path(__file__).resolve().parent.parent / "docker-compose.yml"
#: ``LAMPS_COMPOSE_READER``: auto (docker compose when installed), docker (required) or builtin.
READERS = ("auto", "docker", "builtin")

_ENDPOINT = re.compile(r"^(tcp|udp|tls)/([^:/,]+):(\d+)$")


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
class ComposeModel:
    """Every service of the file (all profiles), the active profiles, and who read it."""

    services: dict[str, ComposeService]
    profiles: tuple[str, ...]
    reader: str  # "docker compose <version>" or "builtin"

    def active(self) -> list[ComposeService]:
        """The services compose starts with :attr:`profiles`, dependencies first."""
        return active(self.services, self.profiles)


@dataclass(frozen=True)
class LocalService:
    """A compose service as a local process: argv and the environment it adds to ours."""

    name: str
    argv: tuple[str, ...]
    environment: dict[str, str]
    listen_ports: tuple[int, ...] = field(default=())
    loop: bool = False  # a fixed-rate loop (granted SYS_NICE): it runs, and stops, ahead of the others

    @property
    def listen_endpoints(self) -> tuple[str, ...]:
        """Where it listens, as endpoints another local process connects to (``tls/127.0.0.1:<port>``...)."""
        return tuple(e.strip() for e in self.environment.get("LAMPS_ZENOH_LISTEN", "").split(",") if e.strip())


# --------------------------------------------------------------------------------------------------- readers

def _strings(value, what: str) -> tuple[str, ...]:
    if value is None:
        return ()
    if isinstance(value, str):
        return (value,)
    if isinstance(value, list) and all(isinstance(v, (str, int, float)) for v in value):
        return tuple(str(v) for v in value)
    raise ConfigError(f"{what} must be a string or a list of strings, got {value!r}")


def _volume_text(v) -> str:
    """A volume as its short form ``source:target[:ro]`` (compose's JSON gives mappings)."""
    if isinstance(v, dict):
        return f"{v.get('source', '')}:{v.get('target', '')}" + (":ro" if v.get("read_only") else "")
    return str(v)


def _service(name: str, svc, where: str, variables: Mapping[str, str]) -> ComposeService:
    """One service mapping (already interpolated) as a ComposeService."""
    if not isinstance(svc, dict):
        raise ConfigError(f"{where} must be a mapping")
    cmd = svc.get("command")
    if not isinstance(cmd, list) or not cmd or not all(isinstance(c, str) for c in cmd):
        raise ConfigError(f"{where}: command must be a non-empty list of strings (exec form), got {cmd!r}")
    env_raw = svc.get("environment") or {}
    if isinstance(env_raw, list):
        env_raw = dict(e.split("=", 1) if "=" in e else (e, variables.get(e)) for e in env_raw)
    if not isinstance(env_raw, dict):
        raise ConfigError(f"{where}: environment must be a mapping or a list")
    # KEY with no value takes the variable's value, or is left out when unset (as compose)
    env = {str(k): str(v if v is not None else variables.get(str(k)))
           for k, v in env_raw.items() if v is not None or str(k) in variables}
    deps_raw = svc.get("depends_on") or []
    # sorted, as compose's own model has them (the start order is the same whichever reader read the file)
    if isinstance(deps_raw, dict):
        deps = tuple(sorted(str(d) for d in deps_raw))
    else:
        deps = tuple(sorted(_strings(deps_raw, f"{where}: depends_on")))
    nets = svc.get("networks") or {}
    aliases: tuple[str, ...] = ()
    if isinstance(nets, dict):
        for net in nets.values():
            if isinstance(net, dict):
                aliases += _strings(net.get("aliases"), f"{where}: aliases")
    labels_raw = svc.get("labels") or {}
    if isinstance(labels_raw, list):
        labels_raw = dict(e.split("=", 1) if "=" in e else (e, "") for e in labels_raw)
    if not isinstance(labels_raw, dict):
        raise ConfigError(f"{where}: labels must be a mapping or a list")
    return ComposeService(name, tuple(cmd), env, deps, _strings(svc.get("profiles"), f"{where}: profiles"),
                          aliases, tuple(_volume_text(v) for v in (svc.get("volumes") or ())),
                          {str(k): str(v) for k, v in labels_raw.items()},
                          _strings(svc.get("cap_add"), f"{where}: cap_add"))


def _check_dependencies(services: dict[str, ComposeService], raw: Mapping[str, Any], p: Path) -> None:
    """Every required dependency names a service of the file (``required: false`` ones may be absent)."""
    for s in services.values():
        deps = (raw.get(s.name) or {}).get("depends_on") or {}
        for d in s.depends_on:
            optional = isinstance(deps, dict) and isinstance(deps.get(d), dict) and deps[d].get("required") is False
            if d not in services and not optional:
                raise ConfigError(f"{p}: service {s.name!r} depends on unknown service {d!r}")


def load_compose(path: str | os.PathLike = DEFAULT_COMPOSE, variables: Mapping[str, str] | None = None
                 ) -> dict[str, ComposeService]:
    """Every service of a compose file (all profiles), in file order, interpolated: the built-in reader.

    variables : what interpolation sees (default: :func:`compose_variables`
    of this environment, i.e. ``.env`` beside the file overridden by ours).
    Raises ConfigError naming the file and the problem (missing, not YAML,
    no services, a command that is not a list, an unknown dependency, an
    interpolation compose would refuse or that this reader does not implement).
    """
    p = Path(path)
    variables = compose_variables(p, os.environ) if variables is None else dict(variables)
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{p}: no such compose file") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("services"), dict) or not data["services"]:
        raise ConfigError(f"{p}: no services")
    raw = interpolate_tree(data["services"], variables, f"{p}: services")
    out = {name: _service(name, svc, f"{p}: service {name!r}", variables) for name, svc in raw.items()}
    _check_dependencies(out, raw, p)
    return out


def docker_compose_version() -> str | None:
    """``docker compose version --short`` when Compose v2 is installed, else None."""
    if shutil.which("docker") is None:
        return None
    try:
        r = subprocess.run(["docker", "compose", "version", "--short"], capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return r.stdout.strip() if r.returncode == 0 and r.stdout.strip() else None


def load_with_docker(path: Path, variables: Mapping[str, str]) -> dict[str, ComposeService]:
    """Every service (all profiles) as ``docker compose config --format json`` resolves them.

    variables : the environment compose runs with (it reads ``.env`` itself).
    Raises ConfigError with compose's own message when it refuses the file.
    """
    env = {**variables, "COMPOSE_PROFILES": "*"}
    env.pop("COMPOSE_FILE", None)
    r = subprocess.run(["docker", "compose", "-f", str(path), "--project-directory", str(path.parent), "config",
                        "--format", "json", "--no-path-resolution"], capture_output=True, text=True, env=env,
                       timeout=60)
    if r.returncode != 0:
        raise ConfigError(f"{path}: docker compose config refused it: {r.stderr.strip() or r.stdout.strip()}")
    data = _unescape(json.loads(r.stdout))  # compose writes every "$" of a resolved value as "$$"
    raw = data.get("services") or {}
    if not raw:
        raise ConfigError(f"{path}: no services")
    # compose sorts the services by name: keep the file's order (start order breaks ties by it)
    try:
        order = list((yaml.safe_load(path.read_text(encoding="utf-8")) or {}).get("services") or {})
    except yaml.YAMLError:
        order = []
    names = [n for n in order if n in raw] + sorted(n for n in raw if n not in order)
    out = {n: _service(n, raw[n], f"{path}: service {n!r}", env) for n in names}
    _check_dependencies(out, raw, path)
    return out


def _unescape(node: Any) -> Any:
    if isinstance(node, str):
        return node.replace("$$", "$")
    if isinstance(node, dict):
        return {k: _unescape(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_unescape(v) for v in node]
    return node


def compose_model(path: str | os.PathLike = DEFAULT_COMPOSE, environment: Mapping[str, str] | None = None,
                  reader: str | None = None) -> ComposeModel:
    """The cell's compose model: services from Compose itself when installed, else the built-in reader.

    environment : the shell environment compose would see (default: ours);
    COMPOSE_PROFILES there, or in ``.env``, picks the active profiles.
    reader : one of :data:`READERS` (default ``$LAMPS_COMPOSE_READER`` or auto).
    """
    p = Path(path)
    environment = dict(os.environ if environment is None else environment)
    reader = reader or environment.get("LAMPS_COMPOSE_READER") or "auto"
    if reader not in READERS:
        raise ConfigError(f"LAMPS_COMPOSE_READER must be one of {', '.join(READERS)}, got {reader!r}")
    if not p.is_file():
        raise ConfigError(f"{p}: no such compose file")
    variables = compose_variables(p, environment)
    profiles = active_profiles(variables)
    version = docker_compose_version() if reader != "builtin" else None
    if reader == "docker" and version is None:
        raise ConfigError("LAMPS_COMPOSE_READER=docker, but `docker compose version` does not answer "
                          "(install Compose v2 as a docker CLI plugin)")
    if version is not None:
        return ComposeModel(load_with_docker(p, environment), profiles, f"docker compose {version}")
    return ComposeModel(load_compose(p, variables), profiles, "builtin")


#: Where a container finds its role's identity (a folder of ``lamps credentials``); ``lamps up`` maps it to that
#: role's local folder.
SECRETS_MOUNT = "/secrets"
#: A service labelled ``lamps.up: skip`` is compose's alone: ``lamps up`` does its job itself (learning the skill).
SKIP_LABEL = "lamps.up"


def run_locally(services: list[ComposeService]) -> list[ComposeService]:
    """The services ``lamps up`` starts as processes: all but those labelled ``lamps.up: skip``."""
    return [s for s in services if s.labels.get(SKIP_LABEL) != "skip"]


def active(services: Mapping[str, ComposeService], profiles: tuple[str, ...]) -> list[ComposeService]:
    """Services compose starts with ``profiles`` enabled, dependencies first (file order otherwise)."""
    on = [s for s in services.values() if not s.profiles or "*" in profiles or set(s.profiles) & set(profiles)]
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


def listen_ports(s: ComposeService) -> list[int]:
    ports = []
    for ep in s.environment.get("LAMPS_ZENOH_LISTEN", "").split(","):
        m = _ENDPOINT.match(ep.strip())
        if m:
            ports.append(int(m.group(3)))
    return ports


def secrets_role(s: ComposeService) -> str | None:
    """The folder of ``./secrets`` a service mounts at ``/secrets`` (its role), or None."""
    for v in s.volumes:
        parts = v.split(":")
        if len(parts) >= 2 and parts[1].rstrip("/") == SECRETS_MOUNT and "/secrets/" in parts[0] + "/":
            name = Path(parts[0]).name
            return None if name == "secrets" else name
    return None


def _on_loopback(argv: tuple[str, ...]) -> tuple[str, ...]:
    """``argv`` with a ``--host 0.0.0.0`` (what a container binds to be reached through its published port) made
    ``--host 127.0.0.1``: on this machine a service is reached from here only, like the Zenoh endpoints."""
    out = list(argv)
    for i, a in enumerate(out[:-1]):
        if a == "--host" and out[i + 1] == "0.0.0.0":
            out[i + 1] = "127.0.0.1"
    return tuple(out)


def localize(services: list[ComposeService], port_of: Mapping[tuple[str, int], int] | None = None,
             lamps_argv0: tuple[str, ...] | None = None, secrets: Path | None = None) -> list[LocalService]:
    """The services as local processes (see the module docstring).

    port_of : (service, container port) -> local port; missing ones get
    :func:`free_port`. lamps_argv0 : what replaces ``lamps`` in commands
    (default: this interpreter running the console script's module).
    secrets : the local credentials folder (``lamps credentials``): a
    service's ``/secrets`` in environment values becomes the folder of the
    role its compose volume mounts there (``./secrets/<role>:/secrets``).
    """
    lamps = lamps_argv0 or (sys.executable, "-m", "runtime.cli")
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
        if secrets is not None and (role := secrets_role(s)) is not None:
            local = secrets / role
            env = {k: (str(local / v[len(SECRETS_MOUNT):].lstrip("/"))
                       if v == SECRETS_MOUNT or v.startswith(SECRETS_MOUNT + "/") else v) for k, v in env.items()}
        for key in ("LAMPS_ZENOH_LISTEN", "LAMPS_ZENOH_CONNECT"):
            if env.get(key):
                # two names of one service (robot, camera) become one endpoint, once
                env[key] = ",".join(dict.fromkeys(endpoint(e, s.name) for e in env[key].split(",") if e.strip()))
        argv = (*lamps, *s.command[1:]) if s.command[0] == "lamps" else s.command
        argv = _on_loopback(argv)
        out.append(LocalService(s.name, tuple(argv), env, tuple(ports[(s.name, p)] for p in listen_ports(s)),
                                "SYS_NICE" in s.cap_add))
    return out
