"""What the adapter sends the stack: its messages (:class:`CommandSender`) and the hold of a silent controller
(:class:`HeldCommand`).

Each message is an ``LBRTorqueCommand`` (:func:`~robot.lbr.msgs.encode_torque_command`): ``joint_position`` (7,)
[rad] the target the stack's PID steers its command to, ``torque`` (7,) [Nm] the overlay added to the robot's joint
impedance. The stack re-applies the last one for as long as it runs, so the adapter's last message is the release
(:mod:`robot.lbr.release`). A controller that falls silent gets :class:`HeldCommand`'s torque instead of its own:
its last command again while that is younger than ``stale_limit_s``, then the contact brake
(:mod:`robot.lbr.brake`), and after ``hold_timeout_s`` of braking the adapter disarms.
"""

from __future__ import annotations

import numpy as np

from robot.port import Reading

from .brake import ContactBrake
from .msgs import N_JOINTS, encode_torque_command
from .release import RELEASE_BYTES


class CommandSender:
    """The publisher on the stack's torque command key and what went out on it.

    overlay : (7,) the overlay [Nm] last sent (zeros before the first message); has_sent : whether any message
    went out (then a disarmed adapter keeps answering with its hold, and its last message is the release);
    zeros : (7,) a zero overlay [Nm], the hold's (read only).
    """

    def __init__(self, publisher) -> None:
        self._publisher = publisher
        self.overlay = np.zeros(N_JOINTS)
        self.has_sent = False
        self.zeros = np.zeros(N_JOINTS)

    def send(self, joint_position: np.ndarray, overlay: np.ndarray) -> None:
        """One message: ``joint_position`` (7,) [rad], ``overlay`` (7,) [Nm]."""
        self._publisher.put(encode_torque_command(joint_position, overlay))
        self.overlay = np.asarray(overlay, float)
        self.has_sent = True

    def release(self) -> None:
        """The release (:mod:`robot.lbr.release`): the stack re-initialises its command at the measured pose."""
        self._publisher.put(RELEASE_BYTES)

    def undeclare(self) -> None:
        self._publisher.undeclare()


class HeldCommand:
    """The controller's last command and the hold that follows it when the controller's answers stop.

    brake : the :class:`~robot.lbr.brake.ContactBrake` started at the hold's first cycle past the repeats;
    stale_limit_s : how old [s, robot time] the last command may be and still be repeated; hold_timeout_s : how
    long [s, monotonic] the brake holds before the adapter disarms; tau_nm : (7,) the controller's last torque
    sent [Nm] (None: none since arming); t_ns : its robot time [ns]; holding_since_ns : when [monotonic ns] the
    brake began (None: not braking); repeated : whether the last :meth:`torque` repeated the last command.
    """

    def __init__(self, brake: ContactBrake, stale_limit_s: float, hold_timeout_s: float) -> None:
        self.brake = brake
        self.stale_limit_s = stale_limit_s
        self.hold_timeout_s = hold_timeout_s
        self.tau_nm: np.ndarray | None = None
        self.t_ns = 0
        self.holding_since_ns: int | None = None
        self.repeated = False

    def reset(self) -> None:
        """At arming: no last command, no hold."""
        self.tau_nm, self.holding_since_ns = None, None

    def commanded(self, tau_nm: np.ndarray, t_ns: int) -> None:
        """The controller's torque ``tau_nm`` (7,) [Nm] went out at robot time ``t_ns``: the hold ends."""
        self.tau_nm, self.t_ns = np.array(tau_nm, float), t_ns
        self.holding_since_ns = None

    def since_s(self, t_ns: int) -> float | None:
        """The robot time [s] from the last command to ``t_ns`` (None: no command since arming)."""
        return (t_ns - self.t_ns) * 1e-9 if self.tau_nm is not None else None

    def torque(self, r: Reading, now_ns: int) -> np.ndarray | None:
        """The hold's torque (7,) [Nm] for the reading ``r`` at ``now_ns`` [monotonic ns]: the last command while
        it is fresh (:attr:`repeated`), else the brake's (started here at the first such cycle); None once the
        brake has held for ``hold_timeout_s`` (:meth:`held_ms` says how long)."""
        prev, since = self.tau_nm, self.holding_since_ns
        repeat = prev is not None and (r.robot_time_ns - self.t_ns) * 1e-9 <= self.stale_limit_s
        self.repeated = repeat
        if not repeat and since is None:
            self.holding_since_ns = now_ns
            self.brake.start(r.q_rad, r.wrench_world, r.robot_time_ns)
        elif not repeat and since is not None and (now_ns - since) * 1e-9 > self.hold_timeout_s:
            return None
        return prev if repeat and prev is not None else self.brake.torque(r.dq_rad_s, r.robot_time_ns)

    def held_ms(self, now_ns: int) -> float:
        """How long [ms] the brake has held at ``now_ns`` [monotonic ns]."""
        since = self.holding_since_ns
        return (now_ns - since) / 1e6 if since is not None else 0.0
