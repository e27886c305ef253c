"""Opening the Zenoh node of a background service (the recorder, the live view): shared start-up steps.

Stop on SIGTERM / Ctrl-C (an Event), background CPU priority, the settings
from ``--config`` and the Zenoh options, and the node; a failure is printed
with the command's name and None returned, so the command exits 1.
"""

from __future__ import annotations

import sys
import threading
from dataclasses import replace
from typing import TYPE_CHECKING

from lampskit.errors import LampsError

if TYPE_CHECKING:
    from runtime.config import ZenohSettings
    from runtime.session import ServiceNode


def open_background_node(prog: str, service: str, args, cells: tuple[str, ...] = ()
                         ) -> tuple[ServiceNode, ZenohSettings, threading.Event] | None:
    """(node, settings, stop event) for ``service``, or None after printing ``<prog>: error: ...``.

    args : parsed options with ``config`` and the options of ``runtime.config.add_zenoh_options``.
    cells : the robot ids of a site's cells the service follows (the site viewer: ``[zenoh] cells`` set to them,
    the node's own keys, its liveliness token, the first cell's); () keeps the configured ones.
    """
    from runtime.config import load_config, zenoh_with_options
    from runtime.priority import BACKGROUND, leave_background, set_service_priority
    from runtime.stop_signals import on_stop_signals

    stop = threading.Event()
    on_stop_signals(stop, background=True)
    try:
        settings = zenoh_with_options(load_config(args.config).zenoh, args)
        if cells or settings.cells:
            cells = tuple(cells or settings.cells)
            settings = replace(settings, cells=cells, robot_id=cells[0], key_prefix="")
        set_service_priority(BACKGROUND)
        if stop.is_set():  # stopped before it stepped back: its handler found nothing to leave
            leave_background()
        from runtime.session import ServiceNode

        node = ServiceNode(service, settings).__enter__()
    except LampsError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return None
    except Exception as exc:  # zenoh's own error type for a bad endpoint
        print(f"{prog}: error: cannot open the Zenoh session ({exc})", file=sys.stderr)
        return None
    return node, settings, stop


def cells_option(a) -> tuple[str, ...]:
    """The robot ids of ``--cells`` (none: one cell); ValueError naming a bad one."""
    if a.cells is None:
        return ()
    from interfaces.access import check_cells
    from interfaces.errors import ConfigError

    try:
        cells = check_cells([c.strip() for c in a.cells.split(",") if c.strip()])
    except (ConfigError, ValueError) as exc:
        raise ValueError(f"--cells {a.cells}: {exc}") from None
    if not cells:
        raise ValueError("--cells needs at least one robot id")
    if a.robot_id:
        raise ValueError("give --cells or --robot-id, not both")
    return cells
