"""The robot side's e-stop (:class:`~robot.server.RobotServer`): engaged by any
:class:`~interfaces.messages.Estop` on ``controller/estop``, released only by one on ``controller/estop/release``
that the operator signed (:class:`~robot.command_auth.CommandAuth`); a release also ends the guard's FAULT-hold."""

from __future__ import annotations

import logging
from collections import Counter

from interfaces.messages import Estop

from .command_auth import CommandAuth
from .guard import RobotGuard


class RobotEstop:
    """The e-stop's two keys and whether it is engaged.

    Parameters
    ----------
    node : an open :class:`~runtime.session.ServiceNode` (the keys are its ``controller_estop`` and
        ``controller_estop_release``). auth : the server's command and release authentication.
    guard : the server's guard (a release releases its FAULT-hold). counters : the server's counters.
    log : the server's log (the messages come under its name).

    Attributes
    ----------
    reason : str or None
        Why it is engaged: the last engaging message's reason and source (``"<reason> (<source>)"``, at most 80 and
        40 characters of them); None while released.
    """

    def __init__(self, node, auth: CommandAuth, guard: RobotGuard, counters: Counter[str],
                 log: logging.Logger) -> None:
        self.reason: str | None = None
        self._engages = node.inbox(node.keys.controller_estop, Estop, maxlen=32)
        self._releases = node.inbox(node.keys.controller_estop_release, Estop, maxlen=32)
        self._auth = auth
        self._guard = guard
        self._counters = counters
        self._log = log

    def poll(self) -> None:
        """Take what came on both keys (without waiting): engage, release (signed ones only), count."""
        counters, log = self._counters, self._log
        for inbox, release_key in ((self._engages, False), (self._releases, True)):
            while (e := inbox.get(0.0)) is not None:
                if e.engaged:
                    if self.reason is None:
                        log.warning("e-stop from %s: %s; holding whatever is commanded", e.source or "?", e.reason)
                    counters["estops"] += 1
                    self.reason = f"{e.reason[:80]} ({e.source[:40] or '?'})"
                elif release_key and not self._auth.release_ok(e):
                    continue  # not signed by the operator, or a replay: counted and logged
                elif release_key:
                    if self.reason is not None:
                        log.warning("e-stop released by %s", e.source or "?")
                    if self._guard.release():
                        log.warning("FAULT-hold released by %s: serving commands again", e.source or "?")
                        counters["guard_fault_releases"] += 1
                    counters["estop_releases"] += 1
                    self.reason = None
                else:
                    counters["estop_releases_ignored_on_the_engage_key"] += 1

    def dropped_into(self, counters: dict[str, int]) -> None:
        """Add the undecodable messages of both keys to the status ``counters`` (``estop_dropped: <reason>``,
        ``estop_release_dropped: <reason>``)."""
        for name, source in (("estop", self._engages), ("estop_release", self._releases)):
            for reason, n in list(source.bad.items()):
                counters[f"{name}_dropped: {reason}"] = n
