"""Validation of torque commands at the robot side's edge: nothing bad reaches the physics.

A command is dropped if it has the wrong number of joints (NaN and inf are
already rejected when the message is decoded); torques beyond the joint
limits are clipped to them. Every outcome is counted by reason.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from interfaces.messages import TorqueCommand

HOLD = "hold"


class CommandGate:
    """Turns a decoded :class:`TorqueCommand` into torques for the physics, or into a brake request.

    Parameters
    ----------
    tau_max : (n,) joint torque limits [Nm].
    counters : shared counters (``commands_applied``, ``commands_clipped``,
        ``commands_dropped_wrong_length``, ``commands_hold``).
    """

    def __init__(self, tau_max: np.ndarray, counters: Counter) -> None:
        self.tau_max = np.asarray(tau_max, float)
        self.counters = counters
        self.tau = np.zeros_like(self.tau_max)

    def accept(self, cmd: TorqueCommand) -> np.ndarray | str | None:
        """Clipped torques (n,) [Nm] (a buffer reused by the next call), ``"hold"``, or None if dropped."""
        if cmd.mode == HOLD:
            self.counters["commands_hold"] += 1
            return HOLD
        if len(cmd.tau_nm) != len(self.tau_max):
            self.counters["commands_dropped_wrong_length"] += 1
            return None
        self.tau[:] = cmd.tau_nm
        if np.any(np.abs(self.tau) > self.tau_max):
            self.counters["commands_clipped"] += 1
            np.clip(self.tau, -self.tau_max, self.tau_max, out=self.tau)
        self.counters["commands_applied"] += 1
        return self.tau
