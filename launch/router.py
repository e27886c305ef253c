"""``lamps router``: a Zenoh router for a cell spread over several hosts, with the peers' identities and access list.

The eclipse-zenoh library opened in router mode (no router of our own):
it listens on ``--listen`` (``[zenoh] listen``; default
``tls/0.0.0.0:7447``), proves who it is with the ``router`` identity of
``lamps credentials`` (``LAMPS_ZENOH_IDENTITY`` or ``[zenoh] identity``;
mutual TLS, every endpoint ``tls/``) and applies the cell's access list
(:func:`interfaces.access.cell_acl`, default deny) to every client: a
client's puts pass only on its role's row, whichever host it runs on.
Services join it as clients (``LAMPS_ZENOH_MODE=client``,
``LAMPS_ZENOH_CONNECT=tls/<router host>:7447``, no listen endpoint) and keep
their own access list, which lets in the router's relayed puts.

With ``--cells ID,ID,...`` (``[zenoh] cells``) it routes a site of several
cells: their identities from ``lamps credentials DIR --cells ...``, the
site's access list (:func:`interfaces.access.site_acl`): each cell's roles
put their own row under their own prefix only and hear nothing of another
cell; the ``site-viewer`` reads them all. Each refusal is logged with
``RUST_LOG=zenoh::net::routing::interceptor::access_control=debug``.

A service that must not pay the extra hop (the controller and the robot
side at 1 kHz) can stay a peer with a direct link to its partner and a
link to the router for the rest. The router's threads run ``SCHED_FIFO``
one below the loops (as the services' I/O threads; ``LAMPS_RT_PRIORITY``,
``LAMPS_MLOCK``, :func:`runtime.realtime.apply_relay_realtime`): the
routed states and commands must not wait behind ordinary processes. Runs until SIGTERM or Ctrl-C; with ``-v`` logs
the sessions it routes every ``--status-s`` seconds (0: never).
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading

from interfaces.errors import ConfigError
from runtime.realtime import RealtimeRequest, apply_relay_realtime
from runtime.stop_signals import on_stop_signals, wait_for

log = logging.getLogger("lamps.router")

DEFAULT_LISTEN = "tls/0.0.0.0:7447"


def router_settings(settings, listen: tuple[str, ...]):
    """``settings`` as a router's: router mode, ``listen`` (or its own, or :data:`DEFAULT_LISTEN`), no connect
    unless given (routers may link to routers), multicast off, access control as configured."""
    from dataclasses import replace

    return replace(settings, mode="router", listen=listen or settings.listen or (DEFAULT_LISTEN,),
                   multicast_scouting=False)


def main(argv: list[str] | None = None) -> int:
    from dataclasses import replace

    from runtime.config import add_zenoh_options, load_config, zenoh_with_options

    ap = argparse.ArgumentParser(prog="lamps router", description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", help="TOML configuration ([zenoh]: identity, access_control, robot_id, ...)")
    ap.add_argument("--status-s", type=float, default=10.0,
                    help="with -v: log the sessions routed this often (0: never)")
    ap.add_argument("--cells", metavar="ID,ID,...",
                    help="route several cells (robot ids) with the site's access list ([zenoh] cells)")
    ap.add_argument("-v", "--verbose", action="store_true",
                    help="log what the router does (its sessions, its settings)")
    add_zenoh_options(ap)
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING,
                        format="%(asctime)s router %(levelname)s %(message)s")
    try:
        cfg = load_config(a.config)
        settings = zenoh_with_options(cfg.zenoh, a)
        if a.cells is not None:
            settings = replace(settings, cells=tuple(c.strip() for c in a.cells.split(",") if c.strip()))
        settings = router_settings(settings, tuple(a.listen or ()))
        if settings.tls_ca and not settings.access_control:
            log.warning("access control is off: every client with a cell certificate may put on every key")
        import zenoh

        from runtime.session import zenoh_config

        zenoh.try_init_log_from_env()  # RUST_LOG: Zenoh's own log on stderr (the refusals above); unset: quiet
        threads = RealtimeRequest.from_env()  # a bad LAMPS_RT_PRIORITY or LAMPS_MLOCK is refused before Zenoh starts
        session = zenoh.open(zenoh_config(settings))
        rt = apply_relay_realtime(threads)  # its threads as a loop's I/O threads: it relays the 1 kHz states, commands
    except ConfigError as exc:
        print(f"lamps router: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # zenoh cannot listen: the port is taken, a certificate unreadable
        print(f"lamps router: cannot start: {exc}", file=sys.stderr)
        return 1
    stop = threading.Event()
    on_stop_signals(stop)
    log.info("routing for robot id%s %s on %s (access control %s, identity %s)", "s" if settings.cells else "",
             ", ".join(settings.cells) or settings.robot_id,
             ", ".join(settings.listen), "on" if settings.access_control else "off",
             settings.tls_certificate or "none")
    print(f"lamps router: listening on {', '.join(settings.listen)}; threads {rt.report}", flush=True)
    try:
        while not wait_for(stop, a.status_s if a.status_s > 0 else None):
            info = session.info
            log.info("sessions: %d peers, %d routers", len(list(info.peers_zid())), len(list(info.routers_zid())))
    finally:
        session.close()
    return 0
