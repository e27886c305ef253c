"""The answers a controller sent to the robot (:class:`~controller.service.ControllerService`): the torques of the
last :data:`SENT_RING` states, to look up the command a robot state says it ran on, and the last command."""

from __future__ import annotations

import numpy as np

from interfaces.messages import TorqueCommand

#: How many answers are kept to look up the one a robot state says it applied (>= the states a real-time
#: robot may run ahead of its answers).
SENT_RING = 64


class SentAnswers:
    """The answers sent, allocated once for ``nq`` joints.

    Attributes
    ----------
    tau : ndarray, shape (SENT_RING, nq)
        The torques sent [Nm], row ``seq % SENT_RING``.
    seq : ndarray of int64, shape (SENT_RING,)
        The state each row answered; -1: a hold, or none since the robot's start.
    last : TorqueCommand or None
        The last command sent (a state said again gets it again); None since the robot's start.
    """

    __slots__ = ("tau", "seq", "last")

    def __init__(self, nq: int) -> None:
        self.tau = np.zeros((SENT_RING, nq))
        self.seq = np.full(SENT_RING, -1, dtype=np.int64)
        self.last: TorqueCommand | None = None

    def running(self, command_seq: int) -> np.ndarray | None:
        """The torques (nq,) [Nm] of the answer to state ``command_seq`` if it is still kept; None for a hold (-1)
        or an answer no longer kept."""
        if command_seq < 0:
            return None
        row = command_seq % SENT_RING
        return self.tau[row] if self.seq[row] == command_seq else None

    def forget(self) -> None:
        """A new robot: it counts its states from 0 again, and nothing sent is re-sent."""
        self.last = None
        self.seq[:] = -1
