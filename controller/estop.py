"""The controller's e-stop (:class:`~controller.service.ControllerService`): its own, engaged on
``controller/estop`` and released only from ``controller/estop/release`` (the operator's key under access control),
and the robot side's, which each robot state reports; the executor is in ESTOP while either is engaged."""

from __future__ import annotations

import logging
from collections import Counter

from interfaces.messages import Estop

from .command_auth import ControllerAuth
from .core import ControllerCore


class ControllerEstop:
    """Both e-stops and the keys of ours.

    Parameters
    ----------
    node : an open :class:`~runtime.session.ServiceNode`. core : the controller's core (its executor is told).
    auth : the controller's authentication (releases must carry the operator's signature). counters : the
    service's counters. log : the service's log (the messages come under its name).

    Attributes
    ----------
    engages, releases : Inbox of Estop
        The engage and release keys' readers (their counters go in the status).
    robot_engaged : bool
        The last robot state said the robot side's e-stop is engaged.
    ours : bool
        Our own e-stop is latched (an engage on ``controller/estop``, not yet released).
    """

    def __init__(self, node, core: ControllerCore, auth: ControllerAuth, counters: Counter[str],
                 log: logging.Logger) -> None:
        self.engages = node.inbox(node.keys.controller_estop, Estop, maxlen=32)
        self.releases = node.inbox(node.keys.controller_estop_release, Estop, maxlen=32)
        self.robot_engaged = False
        self.ours = False
        self._release_key = node.keys.controller_estop_release
        self._core = core
        self._auth = auth
        self._counters = counters
        self._log = log

    def follow_robot(self, engaged: bool) -> None:
        """The robot side's e-stop and ours agree: while its e-stop is engaged (it holds whatever we send) we are
        in ESTOP too, also when the engage never reached us (a lost sample, a controller started afterwards); when
        the operator's release reaches it, we resume unless our own e-stop is still latched."""
        self.robot_engaged = engaged
        if engaged:
            self._counters["robot_estops_seen"] += 1
            self._log.warning("the robot side reports its e-stop engaged: ESTOP until it is released")
            if not self.ours:
                self._core.executor.estop("e-stop engaged on the robot side")
        elif not self.ours:
            self._log.warning("the robot side's e-stop released")
            self._core.executor.clear()

    def poll(self) -> None:
        """Engage on ``controller/estop``; release only from ``controller/estop/release``: a release on the engage
        key is ignored and counted. A release while the robot side still reports its e-stop engaged waits for it
        (:meth:`follow_robot`)."""
        log, executor = self._log, self._core.executor
        for inbox, release_key in ((self.engages, False), (self.releases, True)):
            while True:
                e = inbox.get(0.0)
                if e is None:
                    break
                if e.engaged:
                    log.warning("e-stop from %s: %s", e.source or "?", e.reason)
                    self.ours = True
                    executor.estop(f"e-stop: {e.reason}" + (f" ({e.source})" if e.source else ""))
                elif release_key and not self._auth.release_ok(e):
                    continue  # not the operator's signature, or a replay: counted and logged
                elif release_key:
                    log.warning("e-stop released by %s", e.source or "?")
                    self._counters["estop_releases"] += 1
                    self.ours = False
                    if self.robot_engaged:
                        executor.estop("released here; waiting for the robot side's e-stop release")
                    else:
                        executor.clear()
                else:
                    self._counters["estop_releases_ignored_on_the_engage_key"] += 1
                    log.warning("e-stop release from %s on the engage key ignored (releases go to %s)",
                                e.source or "?", self._release_key)
