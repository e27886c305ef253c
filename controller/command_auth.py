"""The controller's end of authenticated commands and releases (:mod:`interfaces.arm_auth`).

:class:`ControllerAuth` introduces the controller (its certificate and
session, on ``controller/introduction`` every half second, and at once when
a robot side it has not seen introduces itself), reads the robot side's
introduction, and once that certificate proved the robot role of this cell
derives the key the robot side derives: each command then carries its MAC
(:meth:`ControllerAuth.mac`, 2 us). Before that, commands go without one
and the robot side holds (counted here as
``commands_before_the_robot_side_introduced_itself``). A release of the
e-stop counts only when the operator signed it.

Without an identity (``--insecure``, the in-process cell) nothing is added
and every release is taken.
"""

from __future__ import annotations

import logging
import time
from collections import Counter

import msgspec

from interfaces.arm_auth import (
    AuthAccount,
    AuthError,
    CommandMac,
    LocalIdentity,
    command_key,
    load_identity,
    peer_public_key,
)
from interfaces.messages import Estop, Introduction, TorqueCommand
from runtime.service_security import IN_PROCESS

log = logging.getLogger(__name__)

#: The controller introduces itself this often [s].
INTRODUCE_EVERY_S = 0.5


class ControllerAuth:
    """Authentication of one controller session. ``node``: its open ServiceNode; ``session``: what its commands
    carry; ``counters``: the service's."""

    def __init__(self, node, session: str, counters: Counter) -> None:
        s = node.settings
        # in process (the network-free cell) nothing travels between the services: nothing to authenticate
        self.identity: LocalIdentity | None = None if node.security == IN_PROCESS else \
            load_identity(s.tls_ca, s.tls_certificate, s.tls_private_key)
        self.node = node
        self.session = session
        self.counters = counters
        self._mac: CommandMac | None = None
        self._nonce = b""
        self._next_intro = 0.0
        self._account = AuthAccount(self.identity, node.keys.prefix, counters, log)
        self._intros = None
        if self.identity is not None:
            self._intros = node.latest(node.keys.robot_introduction, Introduction)

    def housekeeping(self) -> None:
        """Introduce the controller when due; take a new robot side's introduction (an ECDH, a few per run)."""
        if self.identity is None or self._intros is None:  # (the introductions are read with an identity only)
            return
        intro = self._intros.take()
        if intro is not None and intro.nonce != self._nonce:
            try:
                key = peer_public_key(intro.certificate, self.identity, "robot")
            except AuthError as exc:
                self._refuse("robot_introductions_refused", str(exc))
            else:
                self._mac = CommandMac(command_key(self.identity, key, self.session, intro.nonce))
                self._nonce = intro.nonce
                self._next_intro = 0.0  # a robot side that just started hears of us at once
                log.info("robot side introduced and proven: commands authenticated from now on")
        now = time.monotonic()
        if now >= self._next_intro:
            self._next_intro = now + INTRODUCE_EVERY_S
            self.node.publish(self.node.keys.controller_introduction, Introduction(
                stamp_ns=time.monotonic_ns(), role="controller", certificate=self.identity.certificate_pem,
                session=self.session))

    def mac(self, seq: int, mode: str, tau_nm) -> bytes:
        """The MAC a command of ``seq``, ``mode`` and torques (n,) [Nm] carries (b"" without an identity, or
        before the robot side introduced itself)."""
        if self._mac is None:
            if self.identity is not None:
                self.counters["commands_before_the_robot_side_introduced_itself"] += 1
            return b""
        return self._mac.mac(seq, mode, tau_nm)

    def with_mac(self, cmd: TorqueCommand) -> TorqueCommand:
        """``cmd`` as sent again, its MAC made under the key proven now: it went without one before the robot side
        introduced itself, or under the key of a robot side that has since restarted (a lock-step robot side
        re-sends the state it waits for; the same answer must pass the robot side there is now)."""
        if self._mac is None:
            return cmd
        mac = self._mac.mac(cmd.seq, cmd.mode, cmd.tau_nm)
        return cmd if mac == cmd.mac else msgspec.structs.replace(cmd, mac=mac)

    def release_ok(self, release: Estop) -> bool:
        """True when the e-stop release is the operator's, fresh and new (always, without an identity)."""
        return self._account.release_ok(release)

    def _refuse(self, counter: str, why: str) -> bool:
        return self._account.refuse(counter, why)
