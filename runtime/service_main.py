"""One skeleton for every service's ``main()``: its log on stderr, its errors as one line and exit 1, its node in a
``with``.

Every ``lamps <service>`` (sim, controller, perception, robot, the lbr peer, the watchdog, the preflight) runs the
same steps: parse, log to stderr, load and check its configuration (a bad one: ``lamps <service>: error: <what>``,
exit 1), open its Zenoh node, serve until a stop signal, close the node whatever happened. This module holds the
parts every one of them shares; what a service serves stays in its own ``cli.py``::

    def main(argv=None) -> int:
        a = build_parser().parse_args(argv)
        log_to_stderr("controller", a.verbose)
        try:
            settings, params = load(a)
        except LampsError as exc:
            return refuse("lamps controller", exc)
        return serve("lamps controller", SERVICE, settings, lambda node: ControllerService(params, node).run())

A node that cannot open (a bad or busy endpoint, a certificate the router refuses) is a configuration error of
the service, said as one: Zenoh raises its own error type for those, so any exception while opening is taken.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .config import ZenohSettings
    from .session import ServiceNode


def log_to_stderr(name: str, verbose: bool) -> None:
    """The service's log on stderr, each line stamped and naming ``name``; INFO with ``verbose``, else WARNING."""
    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING,
                        format=f"%(asctime)s {name} %(levelname)s %(name)s: %(message)s")


def refuse(program: str, problem: BaseException | str) -> int:
    """``<program>: error: <problem>`` on stderr; returns the exit code 1 (``return refuse(...)``)."""
    print(f"{program}: error: {problem}", file=sys.stderr)
    return 1


def serve(program: str, service: str, settings: ZenohSettings, body: Callable[[ServiceNode], int],
          max_message_bytes: int | None = None, on_open_failure: Callable[[], None] | None = None) -> int:
    """Open ``service``'s node with ``settings`` and return ``body(node)``'s exit code; the node is closed when
    ``body`` returns or raises. A node that does not open: ``on_open_failure()`` (release what was made before it,
    e.g. a simulator), the reason on stderr, exit 1."""
    from .session import ServiceNode

    with contextlib.ExitStack() as stack:
        try:
            node = stack.enter_context(ServiceNode(service, settings, max_message_bytes))
        except Exception as exc:  # zenoh raises its own error type for a bad or busy endpoint
            if on_open_failure is not None:
                on_open_failure()
            return refuse(program, f"cannot open the Zenoh session ({exc})")
        return body(node)
