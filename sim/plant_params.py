"""The simulated arm as a setting: the ``[sim.plant]`` table, how the simulated iiwa differs from the description.

The controller loads the description (``arm/description/iiwa14_eraser.urdf``) and the ``[joints]``
table; the simulator builds its arm from the same description changed by this table (:mod:`sim.plant`), so a
controller meets an arm that is not its model, as on a real robot. Nothing here reaches the controller except
through the robot's states. Every key is optional; the defaults are the description itself::

    [sim.plant]
    profile = ""                  # "" (the description) or "stuerz2017" (identified link masses, see PROFILES)
    mass_scale = [1, 1, 1, 1, 1, 1, 1]      # per link A1..A7 (or one number for all), [0.2, 3]
    inertia_scale = [1, 1, 1, 1, 1, 1, 1]   # the rotational inertia about each link's centre of mass, [0.2, 3]
    com_offset_m = [[0, 0, 0], ...]         # 7 x 3, added to each link's centre of mass (link frame), |.| <= 0.1 m
    tool_mass_kg = 0.0            # load on the flange the description does not carry [kg], [0, 5]
    tool_com_m = [0, 0, 0.0175]   # where it sits, flange frame [m], each in [-0.3, 0.3]
    load_mass_kg, load_com_m      # the load data the robot is given (gravity_compensated = true); unset: the
                                  # tool as described (the eraser, 0.15 kg at [0, 0, 0.0175] m)
    armature_kg_m2, viscous_nm_s_rad, coulomb_nm   # the simulated drives' own (7 each); unset: the [joints] table's
    torque_bias_nm = [0, ...]     # added to the measured joint torques [Nm], [-50, 50]
    torque_noise_nm = [0, ...]    # standard deviation of white noise on them [Nm], [0, 20]
    state_delay_periods = 0       # the measured state is this many periods old, [0, 20]
    random_mass_error = 0.0       # per link mass and inertia factors uniform in [1 - e, 1 + e], e in [0, 0.5]
    random_com_error_m = 0.0      # per link centre-of-mass offsets up to this length [m], [0, 0.05]
    seed = 0                      # of the random link errors and the torque noise

Order: profile, then the random errors, then ``mass_scale`` / ``inertia_scale`` / ``com_offset_m`` on top.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

from interfaces.errors import ConfigError
from runtime.config import In, check_declared, check_int, check_range, check_vector

N_LINKS = 7

#: Stürz, Affolter, Smith, "Parameter identification of the KUKA LBR iiwa robot including constraints on physical
#: feasibility", IFAC-PapersOnLine 50(1), 6863-6868 (2017), doi:10.1016/j.ifacol.2017.08.1208: the physically
#: feasible link masses of links 1..7 [kg]. Read from a public transcription, not from the paper:
#: ESTEKI/iiwa14-control, file loadRobotmodel1.m lines 10-16, commit 0a6f28158773d4876e2e09cca08ccb538a6bde76
#: (a second public transcription found in the same search agrees on all seven). The table number was not
#: verified. The paper's centres of mass and inertias are given in its Denavit-Hartenberg frames, and the two
#: transcriptions disagree on how those columns line up, so they are not used: the profile keeps the
#: description's centres of mass and scales each link's inertia with its mass (the described shape, the
#: identified mass). The profile changes the link masses only; joint friction stays the [joints] table's
#: (Xu et al. 2020, Table 6, :mod:`arm.joint_dynamics`).
STUERZ_2017_LINK_MASS_KG: tuple[float, ...] = (3.94781, 4.50275, 2.45520, 2.61155, 3.41000, 3.38795, 0.35432)

#: Named plants: profile name -> link masses [kg] (links A1..A7).
PROFILES: dict[str, tuple[float, ...]] = {"stuerz2017": STUERZ_2017_LINK_MASS_KG}

#: The eraser of the description: its mass [kg] and centre of mass in the flange frame [m] (the default load data).
DESCRIBED_TOOL_MASS_KG = 0.15
DESCRIBED_TOOL_COM_M = (0.0, 0.0, 0.0175)


def _vector_in(section: str, name: str, value: Any, n: int, lo: float, hi: float) -> tuple[float, ...]:
    """``value`` as ``n`` floats each in [lo, hi] (a single number is taken for all ``n``), else ConfigError."""
    given = value
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = [value] * n
    try:
        out = check_vector(section, name, value, n)
    except ConfigError:
        out = ()
    if len(out) != n or not all(lo <= v <= hi for v in out):
        raise ConfigError(f"[{section}] {name} must be {n} numbers each in [{lo}, {hi}], got {given!r}")
    return out


@dataclass(frozen=True)
class PlantParams:
    """How the simulated arm differs from the description (module docstring for the keys, units and ranges)."""

    profile: str = ""
    mass_scale: Any = (1.0,) * N_LINKS
    inertia_scale: Any = (1.0,) * N_LINKS
    com_offset_m: Any = ((0.0, 0.0, 0.0),) * N_LINKS
    tool_mass_kg: Annotated[float, In(0.0, 5.0)] = 0.0
    tool_com_m: Any = DESCRIBED_TOOL_COM_M
    load_mass_kg: float | None = None
    load_com_m: Any = None
    armature_kg_m2: Any = None
    viscous_nm_s_rad: Any = None
    coulomb_nm: Any = None
    torque_bias_nm: Any = (0.0,) * N_LINKS
    torque_noise_nm: Any = (0.0,) * N_LINKS
    state_delay_periods: Annotated[int, In(0, 20)] = 0
    random_mass_error: Annotated[float, In(0.0, 0.5)] = 0.0
    random_com_error_m: Annotated[float, In(0.0, 0.05)] = 0.0
    seed: Annotated[int, In(0, 2**31 - 1)] = 0

    def __post_init__(self) -> None:
        s = "sim.plant"
        check_declared(self, s)
        if self.profile not in ("", *PROFILES):
            raise ConfigError(f"[{s}] profile must be one of {['', *PROFILES]}, got {self.profile!r}")
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        fix("mass_scale", _vector_in(s, "mass_scale", self.mass_scale, N_LINKS, 0.2, 3.0))
        fix("inertia_scale", _vector_in(s, "inertia_scale", self.inertia_scale, N_LINKS, 0.2, 3.0))
        rows = self.com_offset_m
        if not isinstance(rows, (list, tuple)) or len(rows) != N_LINKS:
            raise ConfigError(f"[{s}] com_offset_m must be {N_LINKS} rows [x, y, z] (one per link), got {rows!r}")
        fix("com_offset_m", tuple(_vector_in(s, "com_offset_m", r, 3, -0.1, 0.1) for r in rows))
        fix("tool_com_m", _vector_in(s, "tool_com_m", self.tool_com_m, 3, -0.3, 0.3))
        if self.load_mass_kg is not None:
            check_range(s, "load_mass_kg", self.load_mass_kg, 0.0, 10.0)
        if self.load_com_m is not None:
            fix("load_com_m", _vector_in(s, "load_com_m", self.load_com_m, 3, -0.3, 0.3))
        for name, hi in (("armature_kg_m2", 10.0), ("viscous_nm_s_rad", 50.0), ("coulomb_nm", 20.0)):
            if getattr(self, name) is not None:
                fix(name, _vector_in(s, name, getattr(self, name), N_LINKS, 0.0, hi))
        fix("torque_bias_nm", _vector_in(s, "torque_bias_nm", self.torque_bias_nm, N_LINKS, -50.0, 50.0))
        fix("torque_noise_nm", _vector_in(s, "torque_noise_nm", self.torque_noise_nm, N_LINKS, 0.0, 20.0))
        check_int(s, "state_delay_periods", self.state_delay_periods, 0, 20)

    # -- what differs --------------------------------------------------------------------------------
    @property
    def body_is_described(self) -> bool:
        """The links and the tool are the description's (no profile, scale, offset, random error or tool load)."""
        return (not self.profile and all(v == 1.0 for v in self.mass_scale + self.inertia_scale)
                and not any(any(r) for r in self.com_offset_m) and self.tool_mass_kg == 0.0
                and self.random_mass_error == 0.0 and self.random_com_error_m == 0.0)

    @property
    def load_is_true(self) -> bool:
        """The load data the robot compensates with is the tool it carries (the described eraser, no extra load)."""
        return self.tool_mass_kg == 0.0 and self.load_mass_kg is None and self.load_com_m is None

    @property
    def measurement_is_exact(self) -> bool:
        """The measured state is the simulated one: no torque bias or noise, no delay."""
        return not any(self.torque_bias_nm) and not any(self.torque_noise_nm) and self.state_delay_periods == 0

    def load_data(self) -> tuple[float, tuple[float, float, float]]:
        """(mass [kg], centre of mass in the flange frame [m]) the robot is told its tool has."""
        m = DESCRIBED_TOOL_MASS_KG if self.load_mass_kg is None else float(self.load_mass_kg)
        return m, tuple(DESCRIBED_TOOL_COM_M if self.load_com_m is None else self.load_com_m)

    def true_tool(self) -> tuple[float, tuple[float, float, float]]:
        """(mass [kg], centre of mass in the flange frame [m]) of the tool the arm really carries: the described
        eraser and the extra load together."""
        m0, c0 = DESCRIBED_TOOL_MASS_KG, DESCRIBED_TOOL_COM_M
        m = m0 + self.tool_mass_kg
        return m, tuple((m0 * a + self.tool_mass_kg * b) / m for a, b in zip(c0, self.tool_com_m))

