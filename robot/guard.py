"""The robot side's own limits: joint speeds, the pad's speed, its press speed and the contact force.

The robot side is the last line: a stolen or broken controller may send any
torques the :class:`~robot.gate.CommandGate` lets through (within the limits,
each step within the torque-rate limit). :class:`RobotGuard` watches what the
arm does and what each command is about to do, and decides for every cycle
whether the command is applied (:class:`Action`). Four bands, each with
hysteresis (:class:`~robot.guard_bands.Band`: engaged above ``brake_share`` of
its limit, released only under ``release_share``; a brake that lets go where it
engaged hands the arm straight back to the command that sped it up):

* **joint speed**: a joint faster than ``brake_share`` of its limit brakes every
  joint;
* **tool speed**: the pad centre's linear speed ``|J(q) dq|`` [m/s];
* **press speed**: the speed of the pad's fastest corner into the surface it
  last pressed on (along the pad's axis there,
  :class:`~robot.guard_bands.ContactPlane`), while it is within
  ``press_zone_m`` of it. A contact force follows the pad's speed into the
  board within a step (the felt's damping: 0.2 m/s into a pressed board is 50
  N more at once), faster than any force limit can answer, so the speed into
  the board is what must be held (as ISO/TS 15066 bounds a transient contact
  by the speed);
* **contact force**: the measured ``|f|`` (the port's wrench: sim truth, the
  stack's estimate on a real arm) over ``force_cap_n``.

Each band is checked twice: on each reading, with the magnitude's trend one
cycle ahead (:func:`~robot.guard_bands.look_ahead_into`), and, for the speeds
of a port that declares its description (``RobotPort.limits_model``), on each
command before it is applied, with the description's dynamics
(:meth:`~robot.guard_model.ToolMotion.predict`): a wrist joint gains a third of
its speed limit from one 10 Nm step within a cycle, which no trend of past
speeds foresees.

The answers: a speed over brakes (the port's speed hold); a contact force over,
or a press speed over while touching, *yields*: no task torque, gravity
compensated and each joint damped (``tau = g(q) - D dq``,
:meth:`RobotPort.yield_hold`), so whatever presses on the pad pushes the arm
back. A brake would not do there: it holds the pose, and a pad held where it
was pressed into a board presses on at the force it had. ``fault_episodes``
entries into any band within ``fault_window_s`` of robot time latch a FAULT:
the e-stop hold, whatever is commanded (a yield while the force is over),
until the operator's e-stop release (:meth:`RobotGuard.release`). Only an
entry while the arm runs on the controller's torques counts towards it: one
that begins while the robot side already holds the arm (a brake on a stale
command, another band's brake or yield, the controller's own hold) is what the
hold does to the arm, not a command's offence (a wiping pad braked at once
rocks on its edge, and its press speed flickers over the band for a few
cycles), and is counted apart (``episodes_in_hold``).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from .guard_bands import Band, ContactPlane, FaultLatch, Trend, ahead_of
from .guard_model import ToolMotion


class Action(IntEnum):
    """What the next cycle does. ``APPLY``: the command; ``BRAKE``: the port's speed hold; ``YIELD``: the port's
    yield (gravity compensated, damped, no task torque); ``FAULT``: latched, the port's e-stop hold."""

    APPLY = 0
    BRAKE = 1
    YIELD = 2
    FAULT = 3


@dataclass(frozen=True)
class GuardLimits:
    """What :class:`RobotGuard` holds the arm to (``ServerParams`` documents each default).

    joint_speed_rad_s : (n,) joint speed limits [rad/s], or None (no joint-speed brake); tool_speed_m_s : the pad
    centre's speed limit [m/s] (0: none); press_speed_m_s : the speed limit of the pad's fastest corner into the
    surface it last pressed on while within ``press_zone_m`` [m] of it (0: none); pad_half_m : the pad's half
    extents along its x and y axes [m]; brake_share, release_share : a speed band engages above
    the first share of its limit and lets go under the second; contact_n : a force over this [N] is a contact
    (where the surface is); force_cap_n : the contact force cap [N] (0: none), released under
    ``force_release_share`` of it; damping_nm_s_rad : (n,) the yield's joint damping [Nm s/rad]; fault_episodes,
    fault_window_s : that many entries within that long [s] latch the FAULT (0 episodes: never).
    """

    joint_speed_rad_s: np.ndarray | None
    tool_speed_m_s: float
    press_speed_m_s: float
    press_zone_m: float
    pad_half_m: tuple[float, float]
    brake_share: float
    release_share: float
    contact_n: float
    force_cap_n: float
    force_release_share: float
    damping_nm_s_rad: np.ndarray
    fault_episodes: int
    fault_window_s: float


class RobotGuard:
    """The bands and the FAULT latch of one robot side (see the module docstring).

    limits : GuardLimits. model : a RobotModel (the pad's speeds, the commands' prediction), or None (joint
    speeds and the contact force only, by their trends). gravity_compensated : the robot adds gravity itself.
    """

    def __init__(self, limits: GuardLimits, model=None, gravity_compensated: bool = False) -> None:
        self.limits = lim = limits
        self.joint_cap = None if lim.joint_speed_rad_s is None else np.asarray(lim.joint_speed_rad_s, float)
        self.tool = ToolMotion(model, gravity_compensated) if model is not None else None
        self._predicts = self.joint_cap is not None or lim.tool_speed_m_s > 0 or lim.press_speed_m_s > 0
        self.bands = {name: Band(lim.brake_share, lim.release_share) for name in ("joint_speed", "tool_speed",
                                                                                    "press_speed")}
        self.bands["contact_force"] = Band(1.0, lim.force_release_share)
        self.plane = ContactPlane(lim.press_zone_m)
        self.latch = FaultLatch(lim.fault_episodes, lim.fault_window_s)
        self.fault_reason: str | None = None
        n = len(lim.damping_nm_s_rad)
        self._joints, self._speed, self._share = Trend(n), np.zeros(n), np.zeros(n)
        self._last = {"tool_speed": 0.0, "press_speed": 0.0, "contact_force": 0.0}  # the last readings' values
        self.touching = False
        self._near = False  # the pad within press_zone_m of the surface at the last reading
        # the last measurements and, at each band's last entry, what engaged it (for the status and the log)
        self.force_n = self.tool_speed_m_s = self.press_speed_m_s = 0.0
        self.entry_value = dict.fromkeys(self.bands, 0.0)
        self.worst_joint = 0
        self.episodes_in_hold = 0  # entries while the arm was already held: not the FAULT latch's

    @property
    def action(self) -> Action:
        """What the next cycle does: a yield whenever the force is over (a held pad presses on), else the FAULT, a
        yield for a press too fast while touching, a brake for any other speed, or the command."""
        b = self.bands
        if b["contact_force"].engaged:
            return Action.YIELD
        if self.latch.latched:
            return Action.FAULT
        if b["press_speed"].engaged:
            return Action.YIELD if self.touching else Action.BRAKE
        if b["joint_speed"].engaged or b["tool_speed"].engaged:
            return Action.BRAKE
        return Action.APPLY

    def observe(self, q: np.ndarray, dq: np.ndarray, wrench: np.ndarray, t_s: float,
                held: bool = False) -> tuple[str, ...]:
        """Take one reading: ``q``, ``dq`` (n,) [rad, rad/s], ``wrench`` (6,) contact force then torque [N, Nm],
        robot time ``t_s`` [s]; ``held``: the cycle that led to it held the arm (no command of the controller's
        applied), so what it engages does not count towards the FAULT latch. Returns the bands it engaged (usually
        none), ``"fault"`` last if that latched."""
        lim, b = self.limits, self.bands
        entered: tuple[str, ...] = ()
        f = wrench[:3]
        self.force_n = float(np.sqrt(f @ f))
        self.touching = self.force_n > lim.contact_n
        if self.joint_cap is not None:
            np.abs(dq, out=self._speed)
            ahead = self._joints.update(self._speed)
            np.divide(ahead, self.joint_cap, out=self._share)
            j = int(np.argmax(self._share))
            ahead_share = float(self._share[j])
            np.divide(self._speed, self.joint_cap, out=self._share)
            if b["joint_speed"].update(ahead_share, float(self._share.max())):
                self.worst_joint, self.entry_value["joint_speed"] = j, float(ahead[j])
                entered += ("joint_speed",)
        if self.tool is not None:
            tool = self.tool
            tool.update(q, dq)
            if self.touching:
                self.plane.touch(tool.p, tool.R[:, 2])
            near, self._near = self._near, self.plane.near(tool.p)
            self.tool_speed_m_s = v = float(np.sqrt(tool.v @ tool.v))
            self.press_speed_m_s = press = self._press(tool.v, tool.w)
            if near != self._near:  # into the zone or out of it: the press speed starts or stops, it did not jump
                self._last["press_speed"] = press
            entered += self._pad_bands(self._ahead("tool_speed", v), self._ahead("press_speed", press), v, press)
        if lim.force_cap_n > 0:
            force_ahead = self._ahead("contact_force", self.force_n)
            if b["contact_force"].update(force_ahead / lim.force_cap_n, self.force_n / lim.force_cap_n):
                self.entry_value["contact_force"] = force_ahead
                entered += ("contact_force",)
        return self._count(entered, t_s, held)

    def check_command(self, q: np.ndarray, dq: np.ndarray, tau_nm: np.ndarray, dt_s: float,
                      t_s: float) -> tuple[str, ...]:
        """Before ``tau_nm`` (n,) [Nm] is applied for ``dt_s`` [s] at ``q``, ``dq`` (n,): engage each speed band
        one cycle of it would take over ``brake_share`` of its limit, so that this cycle brakes (or yields)
        instead. Returns what it engaged, as :meth:`observe` does (nothing without a model)."""
        if self.tool is None or not self._predicts:
            return ()
        tool = self.tool
        entered: tuple[str, ...] = ()
        dq_next = tool.predict(q, dq, tau_nm, dt_s)
        if self.joint_cap is not None:
            np.abs(dq_next, out=self._speed)
            np.divide(self._speed, self.joint_cap, out=self._share)
            j = int(np.argmax(self._share))
            if self.bands["joint_speed"].update(float(self._share[j]), 1.0):
                self.worst_joint, self.entry_value["joint_speed"] = j, float(self._speed[j])
                entered += ("joint_speed",)
        v, w = tool.twist(q, dq_next)
        entered += self._pad_bands(float(np.sqrt(v @ v)), self._press(v, w), np.inf, np.inf)  # never releases
        return self._count(entered, t_s)

    def _ahead(self, name: str, x: float) -> float:
        """``x`` one cycle ahead at its last gain (:func:`~robot.guard_bands.ahead_of`); ``x`` becomes the last."""
        ahead = ahead_of(x, self._last[name])
        self._last[name] = x
        return ahead

    def _press(self, v: np.ndarray, w: np.ndarray) -> float:
        """The press speed [m/s] of a pad (at its last update's pose) moving at ``v``, ``w`` (3,): its fastest corner
        into the surface while near it, else 0 (and 0 for a pad moving away: only a press is a risk)."""
        tool = self.tool
        if tool is None or not self._near:
            return 0.0
        return max(self.plane.approach(v, w, tool.R, self.limits.pad_half_m), 0.0)

    def _pad_bands(self, tool_ahead: float, press_ahead: float, tool_now: float, press_now: float) -> tuple[str, ...]:
        """Move the tool- and press-speed bands (speeds [m/s] ahead and now); the names of those engaged."""
        lim = self.limits
        entered: tuple[str, ...] = ()
        for name, limit, ahead, now in (("tool_speed", lim.tool_speed_m_s, tool_ahead, tool_now),
                                        ("press_speed", lim.press_speed_m_s, press_ahead, press_now)):
            if limit > 0 and self.bands[name].update(ahead / limit, now / limit):
                self.entry_value[name] = ahead
                entered += (name,)
        return entered

    def _count(self, entered: tuple[str, ...], t_s: float, held: bool = False) -> tuple[str, ...]:
        lim = self.limits
        if entered and held:
            self.episodes_in_hold += len(entered)
            return entered
        if entered and lim.fault_episodes > 0 and self.latch.note(t_s):
            self.fault_reason = (f"{lim.fault_episodes} limit episodes within {lim.fault_window_s:g} s, the last "
                                 f"{', '.join(entered)}")
            entered += ("fault",)
        return entered

    def damping_into(self, dq: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The yield's damping torques ``out = -D dq`` (n,) [Nm] for joint speeds ``dq`` (n,) [rad/s]."""
        np.multiply(self.limits.damping_nm_s_rad, dq, out=out)
        np.negative(out, out=out)
        return out

    def release(self) -> bool:
        """The operator's release: unlatch the FAULT. True if it was latched."""
        was = self.latch.latched
        self.latch.release()
        self.fault_reason = None
        return was
