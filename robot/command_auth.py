"""The robot side's end of authenticated commands and releases (:mod:`interfaces.arm_auth`).

:class:`CommandAuth` introduces the robot side (its certificate and the
nonce of this start, on ``robot/introduction`` every half second), reads the
controllers' introductions, and keeps one MAC key per controller session
whose certificate proved the controller role of this cell. A command is
applied only when its MAC is that key's; a release of the e-stop only when
the operator signed it. Every refusal is counted by reason
(``commands_unauthenticated: <why>``, ``estop_releases_refused: <why>``) and
logged at most every few seconds.

Without an identity (an ``--insecure`` robot side), or in process (the
network-free cell), there is nothing to check with: every command and release is taken, as
before, and the status says the robot side is insecure.
"""

from __future__ import annotations

import logging
import time
from collections import Counter, OrderedDict

from interfaces.arm_auth import (
    AuthAccount,
    AuthError,
    CommandMac,
    LocalIdentity,
    command_key,
    load_identity,
    new_nonce,
    peer_public_key,
)
from interfaces.messages import Estop, Introduction, TorqueCommand
from runtime.service_security import IN_PROCESS

log = logging.getLogger(__name__)

#: The robot side introduces itself this often [s] (a controller that starts later learns its nonce within it).
INTRODUCE_EVERY_S = 0.5
#: Controller sessions whose keys are kept (the newest; a restarted controller is a new session).
MAX_SESSIONS = 8


class CommandAuth:
    """Authenticates commands and releases for one robot side. ``node``: its open ServiceNode; ``counters``: the
    server's."""

    def __init__(self, node, counters: Counter) -> None:
        s = node.settings
        # in process (the network-free cell) nothing travels between the services: nothing to authenticate
        self.identity: LocalIdentity | None = None if node.security == IN_PROCESS else \
            load_identity(s.tls_ca, s.tls_certificate, s.tls_private_key)
        self.node = node
        self.counters = counters
        self.nonce = new_nonce()
        self._keys: OrderedDict[str, CommandMac] = OrderedDict()
        self._next_intro = 0.0
        self._account = AuthAccount(self.identity, node.keys.prefix, counters, log)
        self._intros = None
        if self.identity is not None:
            self._intros = node.inbox(node.keys.controller_introduction, Introduction, maxlen=16)

    @property
    def enabled(self) -> bool:
        """Whether commands and releases are checked (the robot side has an identity)."""
        return self.identity is not None

    def housekeeping(self) -> None:
        """Introduce the robot side when due and take the controllers' introductions (off the 1 kHz path's
        critical part: at most a few per second, each an ECDH)."""
        identity, intros = self.identity, self._intros
        if identity is None or intros is None:
            return
        now = time.monotonic()
        if now >= self._next_intro:
            self._next_intro = now + INTRODUCE_EVERY_S
            self.node.publish(self.node.keys.robot_introduction, Introduction(
                stamp_ns=time.monotonic_ns(), role="robot", certificate=identity.certificate_pem,
                nonce=self.nonce))
        while (intro := intros.get(0.0)) is not None:
            self._take_introduction(intro, identity)

    def _take_introduction(self, intro: Introduction, identity: LocalIdentity) -> None:
        if intro.session in self._keys:
            return
        try:
            key = peer_public_key(intro.certificate, identity, "controller")
        except AuthError as exc:
            self._refuse("controller_introductions_refused", str(exc))
            return
        self._keys[intro.session] = CommandMac(command_key(identity, key, intro.session, self.nonce))
        while len(self._keys) > MAX_SESSIONS:
            self._keys.popitem(last=False)
        log.info("controller session %s introduced and proven", intro.session[:40] or "?")

    def command_ok(self, cmd: TorqueCommand) -> bool:
        """True when ``cmd`` may be applied: its MAC is its session's (always, without an identity)."""
        if self.identity is None:
            return True
        mac = self._keys.get(cmd.session)
        if mac is None:
            self.housekeeping()  # its introduction may be waiting
            mac = self._keys.get(cmd.session)
        if mac is None:
            return self._refuse("commands_unauthenticated", "no proven introduction of its session")
        if not mac.check(cmd.seq, cmd.mode, cmd.tau_nm, cmd.mac):
            return self._refuse("commands_unauthenticated", "MAC is not its session's")
        return True

    def release_ok(self, release: Estop) -> bool:
        """True when the e-stop release is the operator's, fresh and new (always, without an identity)."""
        return self._account.release_ok(release)

    def _refuse(self, counter: str, why: str) -> bool:
        return self._account.refuse(counter, why)
