"""The robot server's cycles (:class:`~robot.server.RobotServer`): the torque buffers it reuses and the record of
what the port did with the last cycle, which the next state reports."""

from __future__ import annotations

import numpy as np

from .command import Command
from .port import Applied


class TorqueBuffers:
    """The server's torques, allocated once for ``n`` joints and reused every cycle.

    Attributes
    ----------
    hold : Command
        A hold, for the cycles the server holds by itself.
    held : Command
        Real time: the newest command accepted, kept over the cycles.
    damping : ndarray, shape (n,)
        The guard's yield torques [Nm].
    written : ndarray, shape (n,)
        The torques last applied [Nm].
    """

    __slots__ = ("hold", "held", "damping", "written")

    def __init__(self, n: int) -> None:
        self.hold = Command(n)
        self.held = Command(n)
        self.damping = np.zeros(n)
        self.written = np.zeros(n)


class CycleRecord:
    """What the port did with the last cycle, and the holds the states have reported.

    Attributes
    ----------
    outcome : Applied
        What the port did with the last cycle.
    braked : bool
        The last cycle held (any outcome but the controller's command: :attr:`Applied.took_command`).
    applied_seq : int
        The seq of the controller's command written in the last cycle; -1: none (a hold).
    held_cycles : int
        States published saying -1, each seq once (:attr:`RobotState.held_cycles`).
    """

    __slots__ = ("outcome", "braked", "applied_seq", "held_cycles", "_held_counted_seq")

    def __init__(self) -> None:
        self.outcome = Applied.HELD
        self.braked = True
        self.applied_seq = -1
        self.held_cycles = 0
        self._held_counted_seq = -1  # the last state counted in held_cycles

    def took(self, done: Applied, seq: int) -> None:
        """The port did ``done`` with the cycle answering state ``seq``."""
        self.outcome, self.braked = done, not done.took_command
        self.applied_seq = -1 if self.braked else seq

    def command_seq(self, applying: bool, seq: int) -> int:
        """The command state ``seq`` reports as applied (-1 a hold, or ``applying`` False: the robot runs on an old
        command); a hold is counted once per state (a state said again in lock-step is one cycle)."""
        applied = self.applied_seq if applying else -1
        if applied < 0 and seq != self._held_counted_seq:
            self.held_cycles += 1
            self._held_counted_seq = seq
        return applied
