"""The command gate at the robot side's edge: nothing bad reaches the hardware.

A :class:`~interfaces.messages.TorqueCommand` is dropped when it has the
wrong number of joints (NaN and inf are already refused when the message is
decoded; checked again here for commands built in-process); torques beyond
the joint limits are clipped to them, and so is a step larger than the
torque-rate limit allows from the torques the arm last ran on. Every outcome
is counted by reason.

The rate reference is never dropped. After a cycle that applied none of the
gate's torques (a brake, a hold, a yield, an e-stop) the robot side tells the
gate what the arm ran on instead (:meth:`CommandGate.ran`: what the brakes
held, in command terms), and the next command is ramped from there at the
rate limit: a brake ends with the torque climbing back from what the arm
holds, never with a jump to the command that had to be braked.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from interfaces.messages import HOLD, TorqueCommand

from .command import Command, CommandKind

#: Default torque-rate limit at the robot side [Nm/s]: 10 Nm per ms, for gross errors only (the
#: controller limits its own rate to about 1 Nm/ms).
DEFAULT_TAU_RATE_NM_S = 10_000.0
#: Default torque-rate limit while the pad touches something [Nm/s]: 2 Nm per ms, twice the controller's own
#: rate. A pressed pad turns a torque step into force within a step (in the sim, a 10 Nm step on every joint
#: pressed 33 N more one cycle later); at 2 Nm/ms the force climbs slowly enough for the robot side's force
#: limit to see it coming. The lbr adapter's own guard refuses steps over the same rate.
DEFAULT_CONTACT_TAU_RATE_NM_S = 2_000.0


class CommandGate:
    """Turns a decoded :class:`TorqueCommand` into a :class:`~robot.command.Command` for the hardware (torques or a
    hold), or None (dropped). The wire's mode string is read here and nowhere else on the robot side.

    Parameters
    ----------
    tau_max : (n,) joint torque limits [Nm].
    counters : shared counters (``commands_applied``, ``commands_clipped``, ``commands_rate_limited``,
        ``commands_dropped_wrong_length``, ``commands_dropped_non_finite``, ``commands_hold``).
    tau_rate_nm_s : torque-rate limit [Nm/s] between two applied commands; ``dt_s`` the cycle [s];
    contact_tau_rate_nm_s : the limit while :attr:`touching` (the robot side sets it from the contact force).
    """

    def __init__(self, tau_max: np.ndarray, counters: Counter, tau_rate_nm_s: float = DEFAULT_TAU_RATE_NM_S,
                 dt_s: float = 0.001, contact_tau_rate_nm_s: float | None = None) -> None:
        self.tau_max = np.asarray(tau_max, float)
        self.counters = counters
        self.command = Command(len(self.tau_max))  # what check and accept return, reused by the next call
        self.tau = self.command.tau_nm  # (n,) [Nm]: its torques, also limit_rate's output
        self._prev = np.zeros_like(self.tau_max)
        self._step = np.zeros_like(self.tau_max)  # scratch: the 1 kHz path allocates nothing here
        self._have_prev = False  # the first command of a lock-step run, before anything held the arm, has none
        free = float(tau_rate_nm_s)
        self._rates = (free, min(free, float(contact_tau_rate_nm_s or free)))  # free, touching
        self._dt_s = float(dt_s)
        self.touching = False
        self._held = False  # the reference is what a hold applied: one cycle's step from it, however late
        self.rated = False  # the last output was rate-limited, or a hold set the reference (False: no reference yet)

    def ran(self, tau_nm: np.ndarray) -> None:
        """The arm ran on ``tau_nm`` (n,) [Nm] (command terms: without the gravity a compensating robot adds) over
        the last cycle instead of the gate's last output: the next step counts from it."""
        self._prev[:] = tau_nm
        self._have_prev = self.rated = True
        self._held = True

    def limit_rate(self, tau_nm: np.ndarray, elapsed_s: float | None = None) -> np.ndarray:
        """``tau_nm`` (n,) [Nm] (within the limits) moved at most the rate limit from the reference: a buffer reused
        by the next call, which becomes the reference. For a command applied again, e.g. after a brake."""
        self.tau[:] = tau_nm
        self._limit_rate(elapsed_s)
        return self.tau

    def _limit_rate(self, elapsed_s: float | None) -> None:
        self.rated = self._have_prev
        rate = self._rates[self.touching]
        if elapsed_s is not None and not self._held:  # late: the cycles in between ran on the last command
            max_step = rate * max(self._dt_s, elapsed_s)
        else:
            max_step = rate * self._dt_s
        step = self._step
        np.subtract(self.tau, self._prev, out=step)
        if self._have_prev and np.abs(step, out=step).max() > max_step:
            self.counters["commands_rate_limited"] += 1
            np.subtract(self.tau, self._prev, out=step)
            np.clip(step, -max_step, max_step, out=step)
            np.add(self._prev, step, out=self.tau)
        self._prev[:] = self.tau
        self._have_prev = True
        self._held = False

    def check(self, cmd: TorqueCommand) -> Command | None:
        """The command as :attr:`command` (reused by the next call): its torques (n,) [Nm] clipped to the limits, or
        a hold; None if dropped. No rate limit (:meth:`limit_rate` applies it cycle by cycle)."""
        if cmd.mode == HOLD:
            self.counters["commands_hold"] += 1
            return self.command.set_hold()  # the reference stays: the robot side sets it to what the hold applied
        if len(cmd.tau_nm) != len(self.tau_max):
            self.counters["commands_dropped_wrong_length"] += 1
            return None
        self.tau[:] = cmd.tau_nm
        if not np.isfinite(self.tau).all():
            self.counters["commands_dropped_non_finite"] += 1
            return None
        if (np.abs(self.tau) > self.tau_max).any():
            self.counters["commands_clipped"] += 1
            np.clip(self.tau, -self.tau_max, self.tau_max, out=self.tau)
        self.counters["commands_applied"] += 1
        self.command.kind = CommandKind.TORQUE
        return self.command

    def accept(self, cmd: TorqueCommand, elapsed_s: float | None = None) -> Command | None:
        """:meth:`check`, then the rate limit on torques: :attr:`command` (reused by the next call), torques (n,) [Nm]
        or a hold, or None if dropped.

        ``elapsed_s`` : time since the last applied command [s] (default one cycle): the rate limit allows
        ``tau_rate_nm_s`` times that, so commands that come late or after skipped periods are not clipped (the
        arm ran on the last one meanwhile); after a hold (:meth:`ran`) one cycle's step only.
        """
        command = self.check(cmd)
        if command is not None and not command.is_hold:
            self._limit_rate(elapsed_s)
        return command
