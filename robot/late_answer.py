"""A late answer damped on the robot side: the arm's motion since the state a command answers.

Each torque command answers one state (its ``seq``). On a slow link it is
applied at a later one (a real-time cell through a router: the applied
command answers a state 2 periods old at the median, bursts of 30), and in
real time it is held over the cycles until the next answer comes. The
controller's damping acted on the velocity it saw; whatever velocity the arm
gained since is undamped for as long as the answer is late. That is a
delayed damping loop, and on a light wrist it winds up: a damped mode of
frequency w keeps its margin only while w times the round trip stays under
about 0.35 (``ImpedanceParams.max_mode_frequency_rad_s``), and the wrist's
modes sit at the cap. The robot side knows the state each command answers
and the state it applies it at, so it damps the difference itself:

    tau = tau_cmd - 2 w_l diag(M(q_n)) (dq_n - dq_(k+m))

state k the one answered, n the newest, m the answer's lag the controller is
tuned for (its mode cap assumes a round trip of about two periods: a prompt
real-time answer is applied one or two states on); each joint a critically damped mode
of frequency ``w_l`` [rad/s] on its own inertia (the diagonal of the
description's joint-space inertia with the rotor inertia), about what the
controller's damping at its mode cap adds per rad/s, for the motion it has
not seen. An answer at most m states old (every lock-step cycle, a prompt
real-time one) is applied as it came. While late the term resists the
arm's acceleration (it adds 2 w_l (n - k - m) dt of each joint's inertia),
so a burst of late answers slows the arm rather than letting it wind up. It is the robot's own joint damping
on the difference, as the real iiwa's joint impedance runs beside its FRI
torque overlay: explicit at 1 kHz, stable while ``2 w_l dt < 2``.
"""

from __future__ import annotations

import numpy as np

#: States remembered [periods]: more than any answer the robot side still applies (``stale_limit_s``).
RING = 256


class LateAnswerDamping:
    """The late-answer damping of one robot side (see the module docstring).

    model : a :class:`~arm.robot_model.RobotModel` (the description's inertia), or None (no damping: a port
    that declares no model). rate_rad_s : ``w_l`` [rad/s] (0: off). tau_max_nm : (n,) the torque limits [Nm]
    the damped torques are clipped to. on_time : ``m``, an answer this many states old is applied as it came.
    """

    def __init__(self, model, rate_rad_s: float, tau_max_nm: np.ndarray, on_time: int = 2) -> None:
        self.on_time = int(on_time)
        self.on = model is not None and rate_rad_s > 0
        self._w = float(rate_rad_s)
        self._tau_max = np.asarray(tau_max_nm, float)
        n = len(self._tau_max)
        self._seq = np.full(RING, -1, dtype=np.int64)  # which state each slot holds
        self._dq = np.zeros((RING, n))  # its joint speeds (RING, n) [rad/s]
        self.newest = -1  # the newest state's seq
        self._q = np.zeros(n)  # its joint positions (n,) [rad]
        self._gain = np.zeros(n)  # 2 w_l diag M (n,) [Nm s/rad], per call
        self.tau = np.zeros(n)  # the damped torques (n,) [Nm], reused
        self.damped_nm = 0.0  # the largest joint torque the last damping added [Nm]
        if self.on:
            import pinocchio as pin  # only a robot side with a description pays for the import

            self._pin, self._model = pin, model.model
            self._data = self._model.createData()

    def record(self, seq: int, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> None:
        """State ``seq`` was published with ``q_rad``, ``dq_rad_s`` (n,) [rad, rad/s]."""
        if not self.on:
            return
        slot = seq % RING
        self._seq[slot] = seq
        self._dq[slot] = dq_rad_s
        if seq >= self.newest:
            self.newest = seq
            self._q[:] = q_rad

    def late_by(self, seq: int) -> int:
        """How many states newer than ``seq`` have been published (0: it answers the newest; -1: not known)."""
        if not self.on or seq < 0 or self._seq[seq % RING] != seq:
            return -1
        return self.newest - seq

    def apply(self, tau_nm: np.ndarray, seq: int) -> np.ndarray:
        """The torques (n,) [Nm] to apply for ``tau_nm`` answering state ``seq``: ``tau_nm`` itself when it
        is on time (or the state is not remembered), else damped as the module says and clipped to
        the limits (:attr:`tau`, reused)."""
        if self.late_by(seq) <= self.on_time:
            self.damped_nm = 0.0
            return tau_nm
        pin, model, data = self._pin, self._model, self._data
        pin.crba(model, data, self._q)
        np.multiply(data.M.diagonal(), 2.0 * self._w, out=self._gain)
        new = self.newest % RING
        np.subtract(self._dq[new], self._dq[(seq + self.on_time) % RING], out=self.tau)
        self.tau *= self._gain
        self.damped_nm = float(np.abs(self.tau).max())
        np.subtract(tau_nm, self.tau, out=self.tau)
        np.clip(self.tau, -self._tau_max, self._tau_max, out=self.tau)
        return self.tau
