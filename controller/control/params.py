"""Gains and limits of the Cartesian impedance law, checked at construction."""

from __future__ import annotations

from dataclasses import dataclass

from interfaces.errors import ConfigError


class ControlConfigError(ConfigError):
    """An impedance parameter is out of its valid range."""


def _positive(name: str, value: float, hi: float = float("inf"), zero_ok: bool = False) -> None:
    ok = (value >= 0 if zero_ok else value > 0) and value <= hi
    if not ok:
        lo = "0 <=" if zero_ok else "0 <"
        raise ControlConfigError(f"{name} must satisfy {lo} {name} <= {hi}, got {value!r}")


#: The robot state period [s] for which ``ImpedanceParams.max_mode_frequency_rad_s`` is set.
REFERENCE_PERIOD_S = 1e-3


def mode_frequency_cap(max_mode_frequency_rad_s: float, robot_rate_hz: float) -> float:
    """The cap on the task modes' natural frequency [rad/s] for a robot sending states at ``robot_rate_hz``.

    The loop's round trip (state -> command applied) is about a robot period plus the tick; the delay margin
    of a damped mode depends on the frequency times that delay, so a slower robot gets a proportionally lower
    cap (500 Hz: half). A faster robot keeps the configured cap (the tick does not get faster); an unknown
    rate (0) too.
    """
    if robot_rate_hz <= 0:
        return max_mode_frequency_rad_s
    return max_mode_frequency_rad_s * min(1.0, robot_rate_hz * REFERENCE_PERIOD_S)


@dataclass(frozen=True)
class ImpedanceParams:
    """Cartesian impedance at the pad centre (world axes).

    stiffness_n_m : translational stiffness K_t [N/m]; stiffness_nm_rad :
    rotational K_r [Nm/rad]. damping_factor : zeta, the damping ratio of
    every mode of the task-space mass Lambda on K (1 = critical; the damping
    matrix comes from the modes, not from Lambda's diagonal).
    max_mode_frequency_rad_s : no mode of Lambda on K is stiffer than this
    natural frequency [rad/s]: a mode above it (the spin of a light wrist on
    K_r) gets the stiffness that puts it there. The loop's delay sets it:
    keep it times the round trip (state -> command applied) below ~0.35.
    It holds for a robot that sends a state every ``REFERENCE_PERIOD_S``
    (1 ms); a robot with a longer period T gets it times 1 ms / T
    (:func:`mode_frequency_cap`), since its round trip is that much longer.
    nullspace_stiffness_nm_rad : posture spring K_n [Nm/rad] (its damping
    is critical for a unit inertia, scaled by M) pulling towards the rest posture.
    """

    stiffness_n_m: float = 1500.0
    stiffness_nm_rad: float = 150.0
    damping_factor: float = 1.0
    max_mode_frequency_rad_s: float = 120.0
    nullspace_stiffness_nm_rad: float = 10.0

    def __post_init__(self) -> None:
        _positive("stiffness_n_m", self.stiffness_n_m, 1e5)
        _positive("stiffness_nm_rad", self.stiffness_nm_rad, 1e4)
        _positive("damping_factor", self.damping_factor, 5.0)
        _positive("max_mode_frequency_rad_s", self.max_mode_frequency_rad_s, 2000.0)
        _positive("nullspace_stiffness_nm_rad", self.nullspace_stiffness_nm_rad, 1e3, zero_ok=True)
