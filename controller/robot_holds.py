"""Whether the robot held over the cycles before a state: its own flag, or its count of held cycles.

A state says whether the robot applied one of our commands over the cycle that
ended in it (``RobotState.command_seq``, -1: it held, braked, was e-stopped or
ran on an old message) and how many cycles it has held since it started
(``RobotState.held_cycles``). A controller answers the newest state and may
skip some (states arriving in a burst after a stalled link); the count tells it
of a hold in those, which the newest state's own flag does not. A released arm
whose controller missed its hold would be asked for full speed at once
(:meth:`controller.control.limits.SpeedOverride.held`).
"""

from __future__ import annotations


class RobotHolds:
    """Follows ``held_cycles`` from state to state (pure; no clock, no I/O).

    Attributes
    ----------
    missed : int
        Held cycles learnt of only through the count (in states the controller did not answer).
    held : int
        States after which the robot had held (:meth:`held_since_last` True).
    """

    def __init__(self) -> None:
        self._seen: int | None = None
        self.missed = 0
        self.held = 0

    def reset(self) -> None:
        """A robot side back after a loss or a restart: its next state sets the count afresh."""
        self._seen = None

    def held_since_last(self, command_seq: int, held_cycles: int) -> bool:
        """True if the robot held over any cycle since the last state passed here: this state's (``command_seq``
        < 0) or one in between (``held_cycles`` grew by more than this state accounts for). The first state and a
        restarted robot side (its count starts again, lower) set the count without a hold of their own."""
        seen, self._seen = self._seen, held_cycles
        own = 1 if command_seq < 0 else 0
        if seen is None or held_cycles < seen:
            between = 0
        else:
            between = held_cycles - seen - own
            if between > 0:
                self.missed += between
        if own > 0 or between > 0:
            self.held += 1
            return True
        return False
