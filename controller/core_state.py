"""What :class:`~controller.core.ControllerCore` keeps between ticks, grouped by purpose.

* :class:`TickBuffers`: the arrays the tick writes into, allocated once (no tick allocates);
* :class:`TickClock`: the controller's robot time, the periods and the skill steps cut short;
* :class:`ModesCache`: the task's modes (an eigen-decomposition refreshed every few ticks) and their cap;
* :class:`TickMemory`: what one tick leaves for the next (rest pose, hold pose, forces, the board in use).
"""

from __future__ import annotations

import numpy as np

from .control.impedance import ImpedanceTerms, Kinematics, TaskModes, new_terms
from .control.records import BOARD_DTYPE, new_record, view
from .executor_types import BoardPose, Setpoint


class TickBuffers:
    """The tick's preallocated arrays, for an arm of ``n`` joints (shapes below; units as named).

    q, dq (n,) [rad, rad/s] and wrench (6,) [N, Nm]: the state as the compiled law sees it (copied in, so the
    kernels always see the same array types); tau (n,) [Nm]: the answer; applied, last_applied (n,) [Nm]: the
    torques the robot applied last cycle and the newest it said it applied; clearance (n,) [Nm] (the shaping's
    posture view when the clearance is on); limits: the torque limits' settings and scratch, one record
    (:func:`~.control.limit_kernels.limits_dtype`); neutral (n,) [Nm]: what takes the limits' push along the
    board's normal out (:func:`~.control.limit_kernels.normal_neutral_into`); demand (n,) [rad/s], demand_work
    (4, 7): the override's joint speeds and scratch; extra_force (3,)
    [N]: the speed brake's force; xyh, v_board (3,): the pad in the board frame [m, m/s]; sp_v_xy (2,) [m/s]:
    the last setpoint's in-plane velocity at time scale 1; board: the board's pose as a record
    (:data:`~.control.records.BOARD_DTYPE`), board_R (3, 3) and board_origin (3,) [m] its views; terms: the
    law's output; no_setpoint: the trace's stand-in when there is none.
    """

    def __init__(self, kin: Kinematics, limits: np.ndarray) -> None:
        n = kin.model.nq
        self.q, self.dq, self.wrench, self.tau = np.zeros(n), np.zeros(n), np.zeros(6), np.zeros(n)
        self.applied, self.last_applied = np.zeros(n), np.zeros(n)
        self.clearance, self.limits, self.neutral = np.zeros(n), limits, np.zeros(n)
        self.demand, self.demand_work = np.zeros(n), np.zeros((4, 7))
        self.extra_force, self.xyh, self.v_board, self.sp_v_xy = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(2)
        self.board = new_record(BOARD_DTYPE)
        self.board_R, self.board_origin = view(self.board, "R"), view(self.board, "origin")
        self.board_R[:] = np.eye(3)
        self.terms: ImpedanceTerms = new_terms(kin)
        self.no_setpoint = Setpoint()


class TickClock:
    """time_s: the robot time the ticks covered [s]; since_start_s: since the last (re)start [s] (the gain
    ramp); period_s: the controller's own period [s]; robot_rate_hz: the robot's declared state rate (0 until a
    state says); skill_steps_capped: ticks whose skill step was cut to a few robot periods."""

    def __init__(self, rate_hz: float) -> None:
        self.time_s = 0.0
        self.since_start_s = 0.0
        self.period_s = 1.0 / rate_hz
        self.robot_rate_hz = 0.0
        self.skill_steps_capped = 0


class ModesCache:
    """The task's modes in use (``current``, None until computed or after a change of cap), their buffer
    ``out``, the ticks since they were computed (``age``), the stiffness scale they were computed at
    (``scale``) and the cap on their frequency ``cap_rad_s`` [rad/s]."""

    def __init__(self, cap_rad_s: float) -> None:
        self.current: TaskModes | None = None
        self.out = TaskModes()
        self.age = 0
        self.scale = -1.0
        self.cap_rad_s = cap_rad_s


class TickMemory:
    """What a tick leaves for the next: hold, the pad's pose (p (3,) [m], R (3, 3)) held while no board is
    known; normal_force_n [N], the measured force along the board's normal; press_n [N], the commanded press;
    last_terms, the law's last terms; override_used, the time scale the last skill step used; applied_known, whether
    ``last_applied`` holds torques the robot said it applied; board, the board whose pose the buffers hold;
    xy_prev (2,) [m], the pad's in-plane position at the last tick (None after a (re)start)."""

    def __init__(self) -> None:
        self.hold: tuple[np.ndarray, np.ndarray] | None = None
        self.normal_force_n = 0.0
        self.press_n = 0.0
        self.last_terms: ImpedanceTerms | None = None
        self.override_used = 1.0
        self.applied_known = False
        self.board: BoardPose | None = None
        self.xy_prev: np.ndarray | None = None
