"""Local TCP ports to listen on, chosen where the kernel never hands one out by itself.

A port the kernel gives for ``bind(port 0)`` lies in its ephemeral range
(``/proc/sys/net/ipv4/ip_local_port_range``, 32768-60999 on Linux), the same
range it takes the source port of every outgoing connection from. Between the
moment a launcher picks such a port and the moment its service binds it, any
connection on the machine (another cell's Zenoh link, a test's client) may
take it as its source port, and the service fails with "Address already in
use". Ports chosen here lie below that range, so only another explicit choice
can collide with them: they are drawn at random from ``LAMPS_PORT_RANGE``
(``LO-HI``, default :data:`DEFAULT_RANGE`), never twice by one process, and
checked bindable on 127.0.0.1. Processes that run side by side (pytest's
workers) are given disjoint ranges through that variable; children inherit it.
"""

from __future__ import annotations

import os
import random
import socket

__all__ = ["DEFAULT_RANGE", "PORT_RANGE_ENV", "PortRangeError", "free_port", "port_range", "bindable"]

#: Where free ports are drawn from: under the kernel's ephemeral range (32768), above the campaign's fixed bases
#: (launch/campaign_run.py: up to 26999) and clear of Ray's default worker ports (10002-19999), which a Ray head
#: refuses to share with its own GCS port.
DEFAULT_RANGE = (27000, 32000)
PORT_RANGE_ENV = "LAMPS_PORT_RANGE"
_TRIES = 200
_given: set[int] = set()


class PortRangeError(ValueError):
    """``LAMPS_PORT_RANGE`` is not ``LO-HI`` with 1024 <= LO < HI <= 65536, or no port in it is free."""


def port_range() -> tuple[int, int]:
    """[lo, hi) from ``LAMPS_PORT_RANGE`` or :data:`DEFAULT_RANGE`; PortRangeError names a malformed value."""
    text = os.environ.get(PORT_RANGE_ENV, "").strip()
    if not text:
        return DEFAULT_RANGE
    try:
        lo, hi = (int(v) for v in text.split("-"))
    except ValueError:
        raise PortRangeError(f"{PORT_RANGE_ENV}={text!r}: expected LO-HI, two port numbers") from None
    if not 1024 <= lo < hi <= 65536:
        raise PortRangeError(f"{PORT_RANGE_ENV}={text!r}: expected 1024 <= LO < HI <= 65536")
    return lo, hi


def bindable(port: int, host: str = "127.0.0.1") -> bool:
    """Whether a TCP socket can bind ``host:port`` now (nobody listens there, no connection holds it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def free_port(count: int = 1) -> int:
    """The first of ``count`` consecutive ports, each bindable now and not given before by this process.

    Raises PortRangeError when :func:`port_range` has no such run after a few hundred draws.
    """
    lo, hi = port_range()
    if count < 1 or hi - lo < count:
        raise PortRangeError(f"no run of {count} ports in [{lo}, {hi})")
    for _ in range(_TRIES):
        base = random.randrange(lo, hi - count + 1)
        run = range(base, base + count)
        if any(p in _given for p in run) or not all(bindable(p) for p in run):
            continue
        _given.update(run)
        return base
    raise PortRangeError(f"no {count} free consecutive port(s) in [{lo}, {hi}) after {_TRIES} draws")
