"""How the skill executor (:class:`~controller.executor.SkillExecutor`) starts: its start-over latches and the
survey of the board before its first approach. Its own state, not shared with its parts."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(slots=True)
class StartLatches:
    """What decides the executor's next start, held from tick to tick.

    Attributes
    ----------
    initialised : bool
        The first step has started the run over at the measured pose (WAIT_PEERS).
    restart_pending : bool
        The robot came back after a loss: the next step starts the run over at the measured pose.
    estop : str or None
        The e-stop's reason, latched until released (across restarts); None when none.
    """

    initialised: bool = False
    restart_pending: bool = False
    estop: str | None = None


@dataclass(slots=True)
class BoardSurvey:
    """The survey before the first approach after a start: the pad at the look point of the whole board, waiting
    for perception to see every stain.

    Attributes
    ----------
    done : bool
        The board has been surveyed (or the survey is under way) since the last start or adopted board jump.
    until_s : float
        The skill's clock at which the wait at the look point ends [s]; infinite while flying there.
    again : bool
        The survey has looked again (:func:`~controller.look_points.resurvey_point`): from its first point no stain
        was seen, and the arm hid part of the board there.
    """

    done: bool = False
    until_s: float = float("inf")
    again: bool = False

    def begin(self) -> None:
        """A survey starts: fly to the look point (the wait is timed on arrival)."""
        self.done = True
        self.until_s = float("inf")
        self.again = False

    def look_again(self) -> None:
        """Nothing seen from the first point: fly to the second (the wait is timed on arrival)."""
        self.again = True
        self.until_s = float("inf")

    def forget(self) -> None:
        """The board is to be surveyed again before the next approach (a restart, a new board pose)."""
        self.done = False
