"""``lamps health``: is this service ready? The probe of a compose healthcheck.

A service is ready when every Zenoh endpoint it listens on accepts a TCP
connection: that is what ``lamps up`` waits for before it starts the next
service (:func:`launch.procs.wait_port`), so compose's ``depends_on:
condition: service_healthy`` gives the containers the same start order.
The endpoints come from ``--endpoint`` or the service's own
``LAMPS_ZENOH_LISTEN`` (the probe runs in the service's container, with its
environment); ``0.0.0.0`` is probed on ``127.0.0.1``.

A client of a router (``LAMPS_ZENOH_MODE=client``, no listen endpoint, the
compose router override ``docker-compose.router.yml``) has no port to probe:
``--alive NAME`` asks Zenoh instead whether NAME's liveliness token
(``<prefix>/alive/NAME``, what each service declares once its session is up)
is visible, with the service's own Zenoh settings (its environment: the
router as the only endpoint, its identity, its access list) but no listen
endpoint: the answer comes through the router, as every other sample does.

Exit 0 ready, 1 not ready (naming the endpoint, or the token, and why), 2
nothing to probe. The port probe is pure standard library (it runs every
few seconds in every container); ``--alive`` imports Zenoh only when asked.
"""

from __future__ import annotations

import argparse
import os
import re
import socket
import sys

_ENDPOINT = re.compile(r"^(?:tcp|tls)/(\[[0-9a-fA-F:]+\]|[^:/,\[\]]+):(\d+)$")


def probe_targets(endpoints: str) -> list[tuple[str, int]]:
    """(host, port) of each ``tcp/<host>:<port>`` in a comma-separated list; wildcard hosts -> loopback.

    Raises ValueError naming an endpoint that is not TCP (the probe cannot open UDP, TLS needs its config).
    """
    out = []
    for ep in (e.strip() for e in endpoints.split(",")):
        if not ep:
            continue
        m = _ENDPOINT.match(ep.split("#", 1)[0])
        if not m:
            raise ValueError(
                f"cannot probe endpoint {ep!r}: only tcp/ and tls/<host>:<port> are probed (a TCP connect)")
        host = m.group(1).strip("[]")
        host = {"0.0.0.0": "127.0.0.1", "::": "::1", "": "127.0.0.1"}.get(host, host)
        out.append((host, int(m.group(2))))
    return out


def accepts(host: str, port: int, timeout_s: float) -> str | None:
    """None when ``host:port`` accepts a TCP connection within ``timeout_s``, else why not."""
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return None
    except OSError as exc:
        return exc.strerror or type(exc).__name__


def alive(service: str, timeout_s: float, env: dict[str, str] | None = None) -> str | None:
    """None when ``service``'s liveliness token is visible to a session with this environment's Zenoh settings
    (no listen endpoint of its own) within ``timeout_s``, else why not."""
    from dataclasses import replace

    from interfaces.errors import ConfigError
    from runtime.config import load_config

    try:
        settings = replace(load_config(None, env).zenoh, listen=())
        import zenoh

        from runtime.session import zenoh_config

        with zenoh.open(zenoh_config(settings)) as session:
            key = settings.keys.alive(service)
            replies = session.liveliness().get(key, timeout=timeout_s)
            if any(r.ok is not None for r in replies):
                return None
            through = ", ".join(settings.connect) or "no endpoint"
            return f"no liveliness token {key} within {timeout_s:g} s (through {through})"
    except ConfigError as exc:
        return f"its Zenoh settings: {exc}"
    except Exception as exc:  # zenoh could not open a session: no route, a refused certificate
        return f"no Zenoh session ({' '.join(str(exc).split()).split(' at /')[0][:200]})"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="lamps health", description=__doc__.split("\n\n")[0])
    p.add_argument("--endpoint", action="append", default=[],
                   help="tcp/<host>:<port> to probe (repeatable; default: $LAMPS_ZENOH_LISTEN)")
    p.add_argument("--alive", metavar="SERVICE",
                   help="instead: ready when SERVICE's liveliness token is visible over Zenoh (a router's client)")
    p.add_argument("--timeout", type=float, default=1.0, help="seconds per endpoint, or for the token (default 1)")
    p.add_argument("-v", "--verbose", action="store_true", help="say what was probed when ready too")
    a = p.parse_args(argv)
    if a.alive:
        why = alive(a.alive, a.timeout)
        if why is not None:
            print(f"lamps health: not ready: {a.alive}: {why}", file=sys.stderr)
            return 1
        if a.verbose:
            print(f"lamps health: ready: {a.alive} is alive")
        return 0
    spec = ",".join(a.endpoint) or os.environ.get("LAMPS_ZENOH_LISTEN", "")
    try:
        targets = probe_targets(spec)
    except ValueError as exc:
        print(f"lamps health: {exc}", file=sys.stderr)
        return 2
    if not targets:
        print("lamps health: nothing to probe (no --endpoint and LAMPS_ZENOH_LISTEN is empty)", file=sys.stderr)
        return 2
    for host, port in targets:
        why = accepts(host, port, a.timeout)
        if why is not None:
            print(f"lamps health: not ready: {host}:{port} does not accept connections ({why})", file=sys.stderr)
            return 1
    if a.verbose:
        print("lamps health: ready: " + ", ".join(f"{h}:{p}" for h, p in targets))
    return 0


if __name__ == "__main__":
    sys.exit(main())
