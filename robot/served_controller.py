"""The controller session a robot side serves (:class:`~robot.server.RobotServer`): commands are bound to one
session (``TorqueCommand.session``); another is served only after the served one fell silent."""

from __future__ import annotations

import logging
import time
from collections import Counter

from interfaces.messages import TorqueCommand

from .command_auth import CommandAuth


class ServedController:
    """Which controller session is served, and since when it has been silent.

    Parameters
    ----------
    auth : the server's command authentication (a command whose MAC is not its session's is refused first).
    counters : the server's counters. rebind_after_s : silence of the served session after which another is served
        [s]. log : the server's log (the messages come under its name).

    Attributes
    ----------
    session : str or None
        The session served (None before the first command).
    """

    def __init__(self, auth: CommandAuth, counters: Counter[str], rebind_after_s: float,
                 log: logging.Logger) -> None:
        self.session: str | None = None
        self._seen_ns = 0  # when the served session's last command came (monotonic) [ns]
        self._auth = auth
        self._counters = counters
        self._rebind_after_ns = rebind_after_s * 1e9
        self._log = log

    def accepts(self, cmd: TorqueCommand) -> bool:
        """True for a command of the session served (binding the first; re-binding to a newcomer only after the
        served one has been silent for ``rebind_after_s``); another session's command is counted. A command whose
        MAC is not its session's (:mod:`robot.command_auth`) is refused first, counted."""
        if not self._auth.command_ok(cmd):
            return False
        now = time.monotonic_ns()
        if cmd.session != self.session:
            if self.session is not None and now - self._seen_ns < self._rebind_after_ns:
                self._counters["commands_from_another_controller"] += 1
                return False
            if self.session is not None:
                self._counters["controller_changes"] += 1
            self._log.warning("serving controller session %s%s", cmd.session[:40] or "?",
                              "" if self.session is None else f" (after {self.session[:40] or '?'} fell silent)")
            self.session = cmd.session
        self._seen_ns = now
        return True
