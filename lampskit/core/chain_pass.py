"""The chain's pass over the stain it wipes (:class:`WipePass`): the wipe as planned, how long and how far the
periodic MP has run on it, when it last adapted and at which phase it leaves."""

from __future__ import annotations

import math
from dataclasses import dataclass

from lampskit.core.planner_types import Wipe


@dataclass(slots=True)
class WipePass:
    """One pass of :class:`~lampskit.core.chain.MpChain` over a stain, from the end of the transition into it.

    Attributes
    ----------
    planned : Wipe or None
        The wipe as planned (adaptive wiping never exceeds its r); None before the first pass.
    phase0_rad : float
        The periodic MP's unwrapped phase when the pass began [rad].
    t_s : float
        Time the periodic MP has wiped the stain in this pass [s].
    adapted_at_s : float
        Clock of the last adaptation of the periodic MP to the ink [s] (-inf: none in this pass).
    leave_at_rad : float
        Unwrapped phase [rad] at which the periodic MP leaves the stain (inf until the next stain is chosen).
    """

    planned: Wipe | None = None
    phase0_rad: float = 0.0
    t_s: float = 0.0
    adapted_at_s: float = -math.inf
    leave_at_rad: float = 0.0

    def begin(self, planned: Wipe, phase0_rad: float) -> None:
        """A new pass of the wipe ``planned``, its periodic MP at the unwrapped phase ``phase0_rad`` [rad]."""
        self.planned = planned
        self.phase0_rad = phase0_rad
        self.adapted_at_s = -math.inf
        self.t_s = 0.0
        self.leave_at_rad = math.inf
