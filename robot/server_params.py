"""The robot side's settings: the ``robot/*`` protocol's timing and the robot side's own limits (``[robot]``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np

from arm.description import PAD_SIZE_M
from interfaces.errors import ConfigError
from runtime.config import In, check_declared

from .gate import DEFAULT_CONTACT_TAU_RATE_NM_S, DEFAULT_TAU_RATE_NM_S
from .guard import GuardLimits
from .port import RobotPort


@dataclass(frozen=True)
class ServerParams:
    """Timing of the protocol and the robot side's own limits (``[robot]``; docs/security.md states them).

    mode : ``"lockstep"`` or ``"realtime"`` (clocked ports are always driven by their own clock);
    rate_hz : the real-time rate [Hz]; stale_limit_s : a command older than this is not applied [s];
    republish_s : lock-step re-send period of an unanswered state [s]; max_steps : stop after this
    many written cycles (0: never); status_rate_hz : status publications per second (wall);
    tau_rate_nm_s : the gate's torque-rate limit [Nm/s]; contact_tau_rate_nm_s : the same while the pad touches
    (a contact force over ``contact_n``) [Nm/s]; rebind_after_s : another controller session is served only after
    the served one has sent nothing for this long [s].

    The limits (:mod:`robot.guard`; docs/security.md, "The robot side's limits"): speed_brake_share : brake
    while a joint moves faster than this share of its limit (ports declaring limits), or the pad faster than
    this share of ``tool_speed_limit_m_s`` or of ``press_speed_limit_m_s`` into the surface it last pressed on,
    or would by the next cycle (0: no speed brakes); speed_release_share : a speed brake lets go once all
    these are under this share; tool_speed_limit_m_s : the pad centre's speed limit [m/s] (ports declaring a
    ``limits_model``; 0: none); press_speed_limit_m_s : the speed limit [m/s] of the pad's fastest corner into
    the surface it last pressed on while within ``press_zone_m`` [m] of it (0: none); contact_n : a contact
    force over this [N] marks the surface (and makes a press too fast a yield, not a brake); force_cap_n : yield
    while the contact force is over this [N] (0: never); force_release_share : the yield lets go under this
    share of the cap; yield_damping_share : each joint's damping in a yield, as the share of its torque limit it
    gives at its speed limit; late_damping_rad_s : a command applied more than two states after the one it
    answers gets each joint's motion since damped as a mode of this frequency [rad/s] on its inertia
    (:mod:`robot.late_answer`; 0, the default: never); fault_episodes, fault_window_s : that many brake or yield
    episodes within that long [s] (robot time) latch the FAULT-hold until the operator's e-stop release (0
    episodes: never).
    """

    mode: str = "lockstep"
    rate_hz: float = 1000.0
    stale_limit_s: float = 0.02
    republish_s: float = 0.05
    max_steps: int = 0
    status_rate_hz: float = 10.0
    tau_rate_nm_s: float = DEFAULT_TAU_RATE_NM_S
    contact_tau_rate_nm_s: Annotated[float, In(10.0, 1e6)] = DEFAULT_CONTACT_TAU_RATE_NM_S
    rebind_after_s: float = 0.5
    speed_brake_share: Annotated[float, In(0.0, 1.0)] = 0.95
    speed_release_share: Annotated[float, In(0.0, 1.0)] = 0.8
    tool_speed_limit_m_s: Annotated[float, In(0.0, 5.0)] = 1.0
    press_speed_limit_m_s: Annotated[float, In(0.0, 1.0)] = 0.05
    press_zone_m: Annotated[float, In(0.0, 0.2)] = 0.01
    contact_n: Annotated[float, In(0.1, 100.0)] = 5.0
    force_cap_n: Annotated[float, In(0.0, 1000.0)] = 45.0
    force_release_share: Annotated[float, In(0.0, 1.0)] = 0.8
    yield_damping_share: Annotated[float, In(0.0, 1.0)] = 0.1
    late_damping_rad_s: Annotated[float, In(0.0, 500.0)] = 0.0
    fault_episodes: Annotated[int, In(0, 1000)] = 5
    fault_window_s: Annotated[float, In(0.0, 60.0)] = 1.0

    def __post_init__(self) -> None:
        check_declared(self, "robot")
        if self.speed_brake_share > 0 and self.speed_release_share > self.speed_brake_share:
            raise ConfigError(f"[robot] speed_release_share ({self.speed_release_share}) must not be above "
                              f"speed_brake_share ({self.speed_brake_share})")

    def guard_limits(self, port: RobotPort) -> GuardLimits:
        """The limits of :class:`~robot.guard.RobotGuard` for ``port`` (its declared speed limits and model)."""
        tau_max = np.asarray(port.capabilities.torque_limits_nm, float)
        speeds = port.velocity_limits_rad_s
        if speeds is None and port.limits_model is not None:
            speeds = port.limits_model.limits.dq_max
        brakes = self.speed_brake_share > 0
        damping = np.zeros_like(tau_max) if speeds is None else \
            self.yield_damping_share * tau_max / np.asarray(speeds, float)
        return GuardLimits(
            joint_speed_rad_s=None if port.velocity_limits_rad_s is None or not brakes else
            np.asarray(port.velocity_limits_rad_s, float),
            tool_speed_m_s=self.tool_speed_limit_m_s if brakes else 0.0,
            press_speed_m_s=self.press_speed_limit_m_s if brakes else 0.0, press_zone_m=self.press_zone_m,
            pad_half_m=(PAD_SIZE_M[0] / 2, PAD_SIZE_M[1] / 2),
            brake_share=self.speed_brake_share, release_share=self.speed_release_share, contact_n=self.contact_n,
            force_cap_n=self.force_cap_n, force_release_share=self.force_release_share,
            damping_nm_s_rad=damping, fault_episodes=self.fault_episodes, fault_window_s=self.fault_window_s)
