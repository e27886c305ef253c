"""The robot port: what a robot side (simulator, mock arm, real-robot adapter) implements, nothing more.

In the spirit of a ros2_control hardware interface: a lifecycle
(:meth:`RobotPort.activate` / :meth:`RobotPort.deactivate`), one
:meth:`RobotPort.read` of the measured state and one
:meth:`RobotPort.write` of joint torques (or :meth:`RobotPort.hold`) per
cycle, each saying what it did (:class:`Applied`), and declared
:class:`~interfaces.messages.Capabilities`. The
``robot/*`` protocol (timing modes, sequence matching, re-sends, stale
commands, the command gate, counters) belongs to
:class:`robot.server.RobotServer` alone; a port never sees a message.

Two kinds of port:

* stepped (``clocked = False``): time advances when the server writes (the
  simulator, the mock arm). The server sets the pace: one step per answered
  state in lock-step, its own wall clock in real time.
* clocked (``clocked = True``): the robot has its own clock (FRI). The
  server publishes each new reading as it comes and forwards each answer as
  soon as it arrives; :meth:`RobotPort.wait_reading` blocks for the next one.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np

from interfaces.messages import Capabilities

if TYPE_CHECKING:
    from arm.robot_model import RobotModel


class Applied(Enum):
    """What a port did with one cycle: what :meth:`RobotPort.write` and its holds return."""

    TORQUES = "torques"  #: the command's torques went to the robot
    #: the port's hold (:meth:`RobotPort.hold`): the brakes; the lbr adapter's repeats a fresh last command first
    HELD = "held"
    BRAKED = "braked"  #: the hold at once, no repeat of the last command (:meth:`RobotPort.speed_hold`)
    YIELDED = "yielded"  #: damping on top of gravity compensation, no task torque (:meth:`RobotPort.yield_hold`)
    ESTOP_HELD = "estop_held"  #: the e-stop's hold, at once (:meth:`RobotPort.estop_hold`)
    #: :meth:`RobotPort.write` on a port that is not commanding the robot (the lbr adapter disarmed, or disarming on
    #: a guard trip): the torques were not sent, only the port's stop hold. The server serves on as after torques.
    DISARMED = "disarmed"

    @property
    def took_command(self) -> bool:
        """Whether the cycle was the controller's command (:attr:`TORQUES`, or :attr:`DISARMED`: taken, not sent);
        every other outcome is a hold of some kind."""
        return self is Applied.TORQUES or self is Applied.DISARMED


@dataclass
class Reading:
    """One measurement of the robot side (SI units, joint order of the robot model).

    q_rad, dq_rad_s, tau_nm : (n,) joint positions [rad], velocities [rad/s]
    and applied torques [Nm]; wrench_world : (6,) contact force [N] then
    torque [Nm] on the tool, world axes; robot_time_ns : the robot side's own
    clock [ns]; dq_estimated : True when the velocity is estimated (filtered
    positions), not measured.
    """

    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    tau_nm: np.ndarray
    wrench_world: np.ndarray = field(default_factory=lambda: np.zeros(6))
    robot_time_ns: int = 0
    dq_estimated: bool = False


class RobotPort(ABC):
    """A robot side behind the ``robot/*`` keys. Subclasses implement only their own hardware's side.

    Attributes
    ----------
    capabilities : Capabilities
        What the robot does by itself (gravity compensation, torque limits, backend name).
    clocked : bool
        True when the robot has its own clock (see the module docstring).
    velocity_limits_rad_s : array, shape (n,), or None
        The joints' speed limits [rad/s] the server's speed brake watches (None: the port has its own).
    limits_model : RobotModel or None
        The description the joints follow, for the server's limits on the pad (its speed, its press speed) and its
        prediction of each command (None: joint speeds and the contact force only, by their trends). Used on the
        server's loop thread only. The lbr adapter does not declare it yet: its joint speeds are a filtered
        estimate, with which the pad limits are untried on the arm.
    """

    capabilities: Capabilities
    clocked: bool = False
    velocity_limits_rad_s: np.ndarray | None = None
    limits_model: RobotModel | None = None

    @property
    def n_joints(self) -> int:
        return len(self.capabilities.torque_limits_nm)

    def activate(self) -> None:
        """Commands may be applied from now on (default: nothing to do)."""

    def deactivate(self) -> None:
        """Leave the outputs safe (holding position) and stop applying commands."""
        self.hold()

    @abstractmethod
    def read(self) -> Reading:
        """The state now: after the last write for a stepped port, the newest measurement for a clocked one."""

    def wait_reading(self, timeout_s: float) -> bool:
        """Clocked ports: wait up to ``timeout_s`` for a new measurement (True when one came). Stepped: True."""
        return True

    def set_wake(self, wake) -> None:
        """Clocked ports: set ``wake`` (a threading.Event) whenever a new measurement arrives. Default: nothing."""

    @abstractmethod
    def write(self, tau_nm: np.ndarray) -> Applied:
        """Apply joint torques (n,) [Nm] for one cycle (already gated: finite, within limits): :attr:`Applied.TORQUES`
        (:attr:`Applied.DISARMED` from a port that is not commanding the robot)."""

    @abstractmethod
    def hold(self) -> Applied:
        """Brake and hold the current position for one cycle, whatever was commanded before: :attr:`Applied.HELD`."""

    def estop_hold(self) -> Applied:
        """Hold for one cycle because the e-stop is engaged: at once, no grace (default: :meth:`hold`, and what it
        did); :attr:`Applied.ESTOP_HELD` from a port with a hold of its own for it."""
        return self.hold()

    def speed_hold(self) -> Applied:
        """Hold for one cycle because a joint is too fast: at once, no repeat of the last command (which is
        what sped it up). Default: :meth:`hold`, and what it did; :attr:`Applied.BRAKED` from a port with a hold
        of its own for it."""
        return self.hold()

    def yield_hold(self, tau_nm: np.ndarray) -> Applied:
        """Yield for one cycle because the contact force is over the robot side's cap: apply ``tau_nm`` (n,) [Nm]
        (the server's joint damping) on top of gravity compensation and nothing else, so whatever presses on the
        tool pushes the arm back (:attr:`Applied.YIELDED`). Default: :meth:`speed_hold`, and what it did (a port
        whose hold does not press, such as the lbr adapter's joint spring at the measured pose, needs nothing
        more)."""
        return self.speed_hold()

    def held_torque_nm(self) -> np.ndarray | None:
        """The torques (n,) [Nm] the arm ran on over the last cycle, a hold, in command terms (without the gravity a
        compensating robot adds): where the gate's rate limit counts from after it. None: the port cannot tell, and
        the gate counts from the torques last applied (the lbr adapter: its hold repeats the last command while it
        is fresh, then sends its zero overlay). Default: the measured torques for a robot that does not compensate
        gravity (they are what the brakes hold), None for one that does."""
        if self.capabilities.gravity_compensated:
            return None
        return np.array(self.read().tau_nm, float)

    def applying(self) -> bool:
        """Whether the robot ran on the commands sent up to the newest reading (a clocked robot that re-applies an
        old message while ours do not reach it did not; the server then reports no command applied). Default:
        True."""
        return True

    def after_cycle(self, lockstep: bool) -> None:
        """Called after each written cycle (a simulator publishes its extras here). Default: nothing."""

    def counters(self) -> dict[str, int]:
        """The port's own counters for the status (merged with the server's)."""
        return {}

    def detail(self) -> str:
        """A short line for the status (mode, state)."""
        return ""

    def close(self) -> None:
        """Release what the port holds (connections, processes)."""
