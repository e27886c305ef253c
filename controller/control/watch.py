"""Is the arm doing what it was told? Disturbance torque and contact-loss watches (pure numpy).

* :class:`DisturbanceWatch` estimates, each robot cycle, the joint torque
  that neither the command nor the measured contact explains:

      tau_d = M(q) (dq_k - dq_{k-1}) / dt + nle(q, dq) - tau_applied - J^T w

  (``nle`` = C dq + g; ``tau_applied`` the command the robot reports it
  applied over the cycle, plus gravity when the robot adds it; ``w`` the
  measured contact wrench on the pad, world axes). Low-pass filtered, it is
  the acceleration-based form of a momentum observer: near zero while the
  robot executes our torques, large when something else moves the arm (a
  peer's torques, a collision the force sensor does not see, a robot that
  brakes on its own). Cycles whose applied command is not ours or is
  unknown (holds, skipped states) are not evaluated and restart the
  persistence count.
* :class:`ContactWatch` times how long the measured normal force stays
  under the contact threshold while the setpoint presses with more than
  twice it: contact lost (board gone, pad torn off, sensor dead).

Neither allocates per call; the disturbance arithmetic is one compiled call (:mod:`.kernels`).
"""

from __future__ import annotations

import numpy as np

from .kernels import disturbance_into
from .records import disturbance_dtype, new_record, view


class DisturbanceWatch:
    """Filtered unexplained joint torque and whether it has exceeded its limit long enough.

    Parameters
    ----------
    limit_nm : (n,) per-joint limit on the filtered disturbance [Nm].
    filter_s : time constant of the first-order low-pass [s].
    persist_s : the limit must be exceeded this long (robot time) before :attr:`tripped` [s].
    """

    def __init__(self, limit_nm: np.ndarray, filter_s: float, persist_s: float) -> None:
        limit = np.asarray(limit_nm, float)
        #: the state the kernel keeps (:func:`~.records.disturbance_dtype`); ``limit``, ``tau_d`` view it
        self.rec = new_record(disturbance_dtype(len(limit)))
        self.limit = view(self.rec, "limit")
        self.limit[:] = limit
        self.tau_d = view(self.rec, "tau_d")
        self._dq_prev = view(self.rec, "dq_prev")
        self.filter_s = float(filter_s)
        self.persist_s = float(persist_s)
        self._have_prev = False
        self.over_s = 0.0
        self.peak_ratio = 0.0  # largest |tau_d| / limit since the last reset (status, tuning)
        self.tripped = False

    def reset(self) -> None:
        """Forget the history (a restart, a hold): the next cycle only stores its velocity."""
        self.tau_d[:] = 0.0
        self._have_prev = False
        self.over_s = 0.0
        self.tripped = False

    def skip(self, dq: np.ndarray) -> None:
        """A cycle whose applied torque is not known: keep its velocity as the next reference, evaluate nothing."""
        self._dq_prev[:] = dq
        self._have_prev = True
        self.over_s = 0.0

    def update(self, M: np.ndarray, nle: np.ndarray, J: np.ndarray, dq: np.ndarray, tau_applied: np.ndarray,
               wrench: np.ndarray, dt_s: float) -> bool:
        """One robot cycle of length ``dt_s`` [s] over which ``tau_applied`` (n,) [Nm] acted; True once tripped.

        M : (n, n) inertia; nle : (n,) C dq + g [Nm]; J : (6, n) pad Jacobian (world-aligned);
        dq : (n,) measured velocities at the cycle's end [rad/s]; wrench : (6,) contact wrench [N, Nm].
        """
        if not self._have_prev or dt_s <= 0.0:
            self.skip(dq)
            return self.tripped
        ratio = disturbance_into((M, nle, J), dq, tau_applied, wrench, float(dt_s),
                                 min(dt_s / (self.filter_s + dt_s), 1.0), self.rec)
        self.peak_ratio = max(self.peak_ratio, ratio)
        self.over_s = self.over_s + dt_s if ratio > 1.0 else 0.0
        if self.over_s >= self.persist_s:
            self.tripped = True
        return self.tripped

    def compile(self, kin) -> None:
        """Compile the kernel for the arrays a controller passes (its :class:`~.impedance.Kinematics` ``kin``,
        own (n,) and (6,) buffers) without touching the watch's state."""
        n = len(self.limit)
        rec = new_record(self.rec.dtype)
        rec["limit"] = 1.0
        disturbance_into((kin.M, kin.nle, kin.J), np.zeros(n), np.zeros(n), np.zeros(6), 0.001, 0.5, rec)

    def worst_joint(self) -> int:
        """Index of the joint with the largest disturbance relative to its limit."""
        return int(np.argmax(np.abs(self.tau_d) / self.limit))


class ContactWatch:
    """Time under the contact threshold while pressing; ``tripped`` after ``persist_s`` of it.

    threshold_n : contact force [N]; persist_s : how long a loss may last [s].
    """

    def __init__(self, threshold_n: float, persist_s: float) -> None:
        self.threshold_n = float(threshold_n)
        self.persist_s = float(persist_s)
        self.lost_s = 0.0

    def update(self, pressing_n: float, measured_n: float, dt_s: float) -> bool:
        """``pressing_n``: the setpoint's press force (0 when not in contact) [N]; True when contact is lost."""
        if pressing_n > 2.0 * self.threshold_n and measured_n < self.threshold_n:
            self.lost_s += dt_s
        else:
            self.lost_s = 0.0
        return self.lost_s >= self.persist_s


class OverloadWatch:
    """The share of the robot's states a real-time loop left unanswered, low-passed over robot time, and whether
    it has stayed above its limit long enough.

    A loop that misses more and more periods (a starved CPU, a slow tick) answers with ever staler torques;
    past this watch it should stop wiping and lift off under control, which it still can at a reduced rate.

    Parameters
    ----------
    max_share : limit on the filtered share (0-1; 1 never trips). filter_s : time constant of the first-order
    low-pass [s]. persist_s : above the limit this long (robot time) before :attr:`tripped` [s].
    calm_share, calm_s : after a trip that faulted (:meth:`faulted`), the share below calm_share for calm_s
    [s] of robot time means the load has passed (:meth:`calm_again`); calm_s 0: never.
    """

    def __init__(self, max_share: float, filter_s: float, persist_s: float, calm_share: float = 0.0,
                 calm_s: float = 0.0) -> None:
        self.max_share = float(max_share)
        self.filter_s = float(filter_s)
        self.persist_s = float(persist_s)
        self.calm_share = float(calm_share)
        self.calm_s = float(calm_s)
        self.share = 0.0
        self.over_s = 0.0
        self.peak_share = 0.0
        self.tripped = False
        self._after_fault = False
        self._calm_for_s = 0.0

    def faulted(self) -> None:
        """The trip ended in a FAULT: from now on :meth:`calm_again` watches for the load to pass."""
        self._after_fault = self.calm_s > 0.0
        self._calm_for_s = 0.0

    def calm_again(self, dt_s: float) -> bool:
        """After a fault, True once (then forgotten) when the share has stayed below calm_share for calm_s."""
        if not self._after_fault:
            return False
        self._calm_for_s = self._calm_for_s + dt_s if self.share < self.calm_share else 0.0
        if self._calm_for_s >= self.calm_s:
            self._after_fault = False
            return True
        return False

    def reset(self) -> None:
        """Forget the history (a restart of the robot, a new loop)."""
        self.share = self.over_s = 0.0
        self.tripped = False

    def update(self, missed: int, dt_s: float) -> bool:
        """One answered state after ``missed`` unanswered ones, ``dt_s`` [s] of robot time since the last answered
        one; True once tripped (it stays so until :meth:`reset`)."""
        if dt_s <= 0.0:
            return self.tripped
        x = missed / (missed + 1.0)
        self.share += min(1.0, dt_s / self.filter_s) * (x - self.share)
        self.peak_share = max(self.peak_share, self.share)
        if self.share > self.max_share and self.max_share < 1.0:
            self.over_s += dt_s
            if self.over_s >= self.persist_s:
                self.tripped = True
        else:
            self.over_s = 0.0
        return self.tripped

    def reason(self) -> str:
        return (f"overload: {self.share:.0%} of the robot's states left unanswered (limit {self.max_share:.0%} for "
                f"{self.persist_s:g} s): the controller cannot keep up with the robot; lifted off")

