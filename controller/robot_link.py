"""The controller's watch on the robot side's states (:class:`~controller.service.ControllerService`): the last
state answered, the robot's clock, and whether the robot is lost."""

from __future__ import annotations

from interfaces.messages import RobotState

from .robot_holds import RobotHolds


class RobotLink:
    """What the controller knows of the robot's states since it (re)started.

    Parameters
    ----------
    nominal_s : float
        The controller's nominal period [s]: the tick's time step when the robot's clock gives none.

    Attributes
    ----------
    last_seq : int
        The seq of the last state ticked (-1: none since the robot's start).
    last_robot_ns : int or None
        The robot's clock at the last state ticked [ns] (None since the robot's start).
    ever_state : bool
        A state has been ticked since the controller started.
    lost : bool
        No state for ``robot_lost_s``: FAULT until states come back.
    holds : RobotHolds
        The robot's held cycles, followed from state to state.
    """

    __slots__ = ("nominal_s", "last_seq", "last_robot_ns", "ever_state", "lost", "holds")

    def __init__(self, nominal_s: float) -> None:
        self.nominal_s = nominal_s
        self.last_seq = -1
        self.last_robot_ns: int | None = None
        self.ever_state = False
        self.lost = False
        self.holds = RobotHolds()  # a hold in the states skipped, from the robot's count

    def dt_s(self, state: RobotState) -> float:
        """Time since the last state ticked on the robot's clock [s]; the nominal period when that is unusable."""
        dt = self.nominal_s
        if self.last_robot_ns is not None and state.robot_time_ns > self.last_robot_ns:
            measured = (state.robot_time_ns - self.last_robot_ns) * 1e-9
            if measured <= 0.1:
                dt = measured
        self.last_robot_ns = state.robot_time_ns
        return dt

    def back(self) -> None:
        """States came back (a new or restarted robot): the robot's seq, clock and held count start afresh."""
        self.lost = False
        self.last_robot_ns = None
        self.last_seq = -1
        self.holds.reset()
