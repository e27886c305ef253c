"""What the skill executor shares with its parts: one :class:`ExecutorState` record per
:class:`~controller.executor.SkillExecutor`, handed to its :class:`~controller.board_watch.BoardWatch` and
:class:`~controller.executor_stops.ExecutorStops` when it builds them."""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass

from interfaces.messages import Phase

from .executor_stage import Stage
from .executor_types import BoardPose, ToolState


@dataclass(eq=False, slots=True)
class ExecutorState:
    """The run's state that the executor and its parts read and write (the executor alone advances the clock and
    records the measured pad; a phase is entered through :meth:`set_phase`, except the executor's start over).

    Parameters
    ----------
    log : logging.Logger
        The executor's log: its parts' messages come under the executor's name.
    counters : Counter
        The executor's event counters (status), shared, never replaced.
    junction_ticks : list of int
        The executor's tick numbers at which one MP handed over to the next, shared, never replaced.

    Attributes
    ----------
    phase : Phase
        What the cell sees.
    reason : str
        Why the phase (set in PAUSED, FAULT, ESTOP).
    current_mp : str
        ``"periodic k"``, ``"approach"``, ``"lift"``, ... for status.
    stain_id : int
        The stain being wiped or approached (-1 none).
    stage : Stage
        The motion running inside the phase.
    board : BoardPose or None
        The adopted board (None until the first board report in reach).
    clock_s : float
        The skill's clock [s]: the sum of the steps' ``dt_s``.
    ticks : int
        Steps and waits so far.
    last_force_n : float
        The measured push of the board on the pad at the last step [N].
    last_h_m : float
        The measured pad's height above the board at the last step [m] (infinite before the first).
    last_tool : ToolState or None
        The pad measured at the last step (None before the first).
    """

    log: logging.Logger
    counters: Counter[str]
    junction_ticks: list[int]
    phase: Phase = Phase.INIT
    reason: str = ""
    current_mp: str = ""
    stain_id: int = -1
    stage: Stage = Stage.HOLD
    board: BoardPose | None = None
    clock_s: float = 0.0
    ticks: int = 0
    last_force_n: float = 0.0
    last_h_m: float = float("inf")
    last_tool: ToolState | None = None

    def set_phase(self, phase: Phase, reason: str) -> None:
        """Enter ``phase`` for ``reason`` ("" none); a change is logged and counted (``phase_<name>``)."""
        if phase != self.phase or reason != self.reason:
            self.log.info("phase %s -> %s%s", self.phase, phase, f" ({reason})" if reason else "")
            self.counters[f"phase_{phase.lower()}"] += 1
        self.phase, self.reason = phase, reason
