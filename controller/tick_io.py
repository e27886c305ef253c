"""The control tick's records: what goes in, what comes out, and what it says.

``ControllerCore.tick(inp, out) -> TickStatus`` (:mod:`controller.core`), as
ruckig's ``update(input, output) -> Result``: the caller owns one
:class:`TickInput` and one :class:`TickOutput`, made once with the robot's
joint count and refilled every tick (no allocation on the 1 kHz path); the
tick reads the first, writes the second and returns its status.

All arrays are float64, contiguous, ``n`` the robot's joints (7 for the iiwa);
SI units; the wrench in world axes, force first.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from enum import IntEnum

import numpy as np


class LastCommand(IntEnum):
    """What the robot did with this controller's commands over the cycle that led to the state.

    ``APPLIED``: one known command of ours ran over the whole cycle (:attr:`TickInput.applied_nm`): the
    disturbance watch checks the motion against it. ``UNKNOWN``: not one known command (a hold answered, a state in
    between not seen, an answer no longer kept); :attr:`TickInput.running_nm` says what it ran on when known.
    ``HELD``: the robot held over the cycle instead of applying a command (braked on a stale or missing answer, a
    robot found running an old command): the skill's clock runs only as far as the arm went along the path, the
    force integral stands, the rate limit counts from the torques last applied (``running_nm`` when known).
    """

    APPLIED = 0
    UNKNOWN = 1
    HELD = 2


class TickStatus(IntEnum):
    """What the tick's torques are. ``TORQUE``: they answer the state, the skill going (or done, holding its last
    pose); ``HALTED``: the executor is in FAULT or E-STOP and they hold the arm; ``NON_FINITE``: the law gave a
    non-finite torque (an absurd state): the executor faulted, :attr:`TickOutput.tau_nm` is not to be sent (answer
    with the robot's hold)."""

    TORQUE = 0
    HALTED = 1
    NON_FINITE = 2


@dataclass(slots=True)
class TickInput:
    """One robot state for the tick, and what became of the last command.

    q_rad, dq_rad_s : (n,) joint positions [rad] and speeds [rad/s]; wrench : (6,) the contact wrench on the pad
    [N, Nm]; dt_s : robot time since the last tick [s]; gravity_compensated : the robot adds gravity itself (the
    torques then leave it out); tau_max_nm : (n,) the robot's declared torque limits [Nm] (the tighter of these and
    the description's apply; ``inf`` where it declares none); last : :class:`LastCommand`; applied_nm : (n,) with
    ``APPLIED``, the torques applied [Nm] (without gravity when the robot adds it); running_nm : (n,) the torques of
    the command the robot ran on, when ``running_known`` (read with ``UNKNOWN`` or ``HELD``).
    """

    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    wrench: np.ndarray
    tau_max_nm: np.ndarray
    applied_nm: np.ndarray
    running_nm: np.ndarray
    dt_s: float = 0.0
    gravity_compensated: bool = False
    last: LastCommand = LastCommand.UNKNOWN
    running_known: bool = False

    @classmethod
    def zeros(cls, n: int) -> TickInput:
        """A record for ``n`` joints: all zero, no torque limit declared, the last command unknown."""
        return cls(np.zeros(n), np.zeros(n), np.zeros(6), np.full(n, np.inf), np.zeros(n), np.zeros(n))

    def set_state(self, q_rad, dq_rad_s, wrench, dt_s: float, gravity_compensated: bool) -> TickInput:
        """Copy one state in (sequences of floats or arrays of the record's shapes); returns the record."""
        self.q_rad[:] = q_rad
        self.dq_rad_s[:] = dq_rad_s
        self.wrench[:] = wrench
        self.dt_s = dt_s
        self.gravity_compensated = gravity_compensated
        return self

    def set_last(self, last: LastCommand, applied_nm=None, running_nm=None) -> TickInput:
        """What became of the last command: ``applied_nm`` (n,) with ``APPLIED``; ``running_nm`` (n,) or None (not
        known). Returns the record."""
        self.last = last
        if applied_nm is not None:
            self.applied_nm[:] = applied_nm
        self.running_known = running_nm is not None
        if running_nm is not None:
            self.running_nm[:] = running_nm
        return self


@dataclass(slots=True)
class TickOutput:
    """What the tick gives: ``tau_nm`` (n,) joint torques [Nm] to send (without gravity when the robot adds it),
    ``status`` (:class:`TickStatus`), ``compute_ns`` the tick's own compute time [ns]."""

    tau_nm: np.ndarray
    status: TickStatus = TickStatus.TORQUE
    compute_ns: int = 0

    @classmethod
    def zeros(cls, n: int) -> TickOutput:
        return cls(np.zeros(n))


def conclude(out: TickOutput, tau_nm: np.ndarray, halted: bool, t0_ns: int) -> TickStatus:
    """A tick's end: ``tau_nm`` (n,) [Nm] into ``out`` with its status (``NON_FINITE`` when any torque is not
    finite, the caller then faults; ``HALTED`` when ``halted``; else ``TORQUE``) and the compute time since
    ``t0_ns`` (``time.perf_counter_ns``)."""
    out.tau_nm[:] = tau_nm
    status = TickStatus.TORQUE
    if not np.isfinite(out.tau_nm).all():
        status = TickStatus.NON_FINITE
    elif halted:
        status = TickStatus.HALTED
    out.status = status
    out.compute_ns = time.perf_counter_ns() - t0_ns
    return status
