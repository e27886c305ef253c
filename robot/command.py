"""What the robot side makes of a controller command: joint torques or a hold, tagged.

A :class:`~interfaces.messages.TorqueCommand` names its mode on the wire as
a string; the :class:`~robot.gate.CommandGate` turns a decoded one into a
:class:`Command`: joint torques or a hold, tagged by :class:`CommandKind`.
A :class:`Command` is a record reused cycle after cycle (the 1 kHz path
allocates nothing): whoever keeps one past the next gate call copies it
(:meth:`Command.assign`). What a port then did with the cycle is its
:class:`~robot.port.Applied`.
"""

from __future__ import annotations

from enum import Enum, auto

import numpy as np


class CommandKind(Enum):
    """The two kinds of command the robot side applies."""

    TORQUE = auto()  #: apply the joint torques (:attr:`Command.tau_nm`) for one cycle
    HOLD = auto()  #: brake and hold the position; no torques


class Command:
    """One cycle's command on the robot side: :attr:`kind`, and for ``TORQUE`` the torques :attr:`tau_nm` (n,) [Nm].

    A mutable record with a buffer of its own, filled in place (no allocation per cycle). For a ``HOLD`` the buffer
    keeps whatever it held last: it is not read.
    """

    __slots__ = ("kind", "tau_nm")

    def __init__(self, n_joints: int, kind: CommandKind = CommandKind.HOLD) -> None:
        self.kind = kind
        self.tau_nm = np.zeros(n_joints)

    @property
    def is_hold(self) -> bool:
        return self.kind is CommandKind.HOLD

    def set_torques(self, tau_nm: np.ndarray) -> Command:
        """Make this a ``TORQUE`` command of ``tau_nm`` (n,) [Nm], copied into the buffer; returns self."""
        self.kind = CommandKind.TORQUE
        self.tau_nm[:] = tau_nm
        return self

    def set_hold(self) -> Command:
        """Make this a ``HOLD``; returns self."""
        self.kind = CommandKind.HOLD
        return self

    def assign(self, other: Command) -> Command:
        """Make this a copy of ``other`` (its kind, and its torques when it has any); returns self."""
        if other.kind is CommandKind.TORQUE:
            return self.set_torques(other.tau_nm)
        return self.set_hold()

    def __repr__(self) -> str:
        return "Command(HOLD)" if self.is_hold else f"Command(TORQUE, {self.tau_nm.tolist()})"

