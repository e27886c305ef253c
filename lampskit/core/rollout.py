"""A plan executed offline at a fixed rate: the reference the robot would follow, sample by sample.

:func:`rollout` chains the plan's transitional and periodic MPs with the same
runners the executor steps at 1 kHz (:mod:`lampskit.core.transitional_runner`,
:mod:`lampskit.core.periodic_runner`), for ``lamps plan``, the figures and the
tests; :func:`junction_step_ratios` measures how continuous the hand-overs are.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from lampskit.core.periodic_runner import PeriodicRunner
from lampskit.core.planner import Plan, TransitionSpec, Wipe, exit_phase_delay, plan_transition
from lampskit.core.skill import Skill
from lampskit.core.transitional import TransitionStatus
from lampskit.core.transitional_runner import TransitionalRunner
from lampskit.errors import PlanningError


@dataclass(frozen=True)
class Rollout:
    """A plan executed at a fixed rate.

    Attributes
    ----------
    t_s : array, shape (N,)
    position_m, velocity_m_s, acceleration_m_s2 : arrays, shape (N, 2)
        Reference in the board plane.
    kind : array of str, shape (N,)
        ``"periodic"`` or ``"transitional"`` per sample.
    stain : array of int, shape (N,)
        Stain id being wiped or approached.
    junctions : tuple of int
        Sample indices where one MP hands over to the next (first sample of the new MP).
    transitions : tuple of TransitionSpec
    """

    t_s: np.ndarray
    position_m: np.ndarray
    velocity_m_s: np.ndarray
    acceleration_m_s2: np.ndarray
    kind: np.ndarray
    stain: np.ndarray
    junctions: tuple[int, ...]
    transitions: tuple[TransitionSpec, ...]


def rollout(
    skill: Skill,
    plan_: Plan,
    start: tuple[np.ndarray, np.ndarray, np.ndarray],
    *,
    dt_s: float = 0.001,
    cycles_per_stain: float | None = None,
    is_done: Callable[[Wipe, float], bool] | None = None,
) -> Rollout:
    """Execute ``plan_`` from ``start`` at ``1/dt_s`` Hz.

    Each stain is wiped until ``is_done(wipe, cycles_done)`` (kappa's stand-in)
    is true; by default after ``cycles_per_stain`` cycles (default: the mean
    demonstrated count, at least 2); then, unless it is the last, until the
    phase heads for the next stain (:func:`exit_phase_delay`). The first
    sample is ``start`` at t = 0; the rollout ends on the last stain's
    periodic MP (lifting off and retreating are the controller's).
    """
    if not 1e-4 <= dt_s <= 0.02:
        raise PlanningError(f"dt_s must be in [0.0001, 0.02] s, got {dt_s}")
    if is_done is None:
        is_done = _after_cycles(_cycles_per_stain(skill, cycles_per_stain))
    rec = _Recorder(dt_s)
    specs = []
    state = tuple(np.asarray(x, dtype=float).reshape(2) for x in start)
    next_centres = {a.stain.id: b.stain.centre_m for a, b in zip(plan_.wipes, plan_.wipes[1:])}
    for wipe in plan_.wipes:
        spec = plan_transition(skill, plan_, wipe, state)
        specs.append(spec)
        overrun_s = _run_transition(rec, skill, spec, wipe.stain.id)
        periodic = _run_wipe(rec, skill, wipe, spec, overrun_s, is_done, next_centres.get(wipe.stain.id))
        state = (periodic.position_m.copy(), periodic.velocity_m_s.copy(), periodic.acceleration_m_s2.copy())
    return rec.result(tuple(specs))


def _cycles_per_stain(skill: Skill, cycles_per_stain: float | None) -> float:
    """The wiping cycles per stain: given, or the mean demonstrated count (at least 2)."""
    if cycles_per_stain is None:
        return max(2.0, float(np.mean([e.n_cycles for e in skill.periodic])))
    if np.isfinite(cycles_per_stain) and 0 < cycles_per_stain <= 1000:
        return float(cycles_per_stain)
    raise PlanningError(f"cycles_per_stain must be in (0, 1000], got {cycles_per_stain!r}")


def _after_cycles(n: float) -> Callable[[Wipe, float], bool]:
    return lambda wipe, cycles: cycles >= n


class _Recorder:
    """The rollout's samples as they are produced, and where one MP handed over to the next."""

    def __init__(self, dt_s: float) -> None:
        self.dt_s, self.t = dt_s, 0.0
        self.t_s: list[float] = []
        self.p: list[np.ndarray] = []
        self.v: list[np.ndarray] = []
        self.a: list[np.ndarray] = []
        self.kind: list[str] = []
        self.stain: list[int] = []
        self.junctions: list[int] = []

    def record(self, runner, kind: str, stain_id: int) -> None:
        self.t_s.append(self.t)
        self.p.append(runner.position_m.copy())
        self.v.append(runner.velocity_m_s.copy())
        self.a.append(runner.acceleration_m_s2.copy())
        self.kind.append(kind)
        self.stain.append(stain_id)

    def junction(self) -> None:
        self.junctions.append(len(self.t_s))

    def result(self, specs: tuple[TransitionSpec, ...]) -> Rollout:
        return Rollout(np.array(self.t_s), np.array(self.p), np.array(self.v), np.array(self.a),
                       np.array(self.kind), np.array(self.stain), tuple(self.junctions[1:]), specs)


def _run_transition(rec: _Recorder, skill: Skill, spec: TransitionSpec, stain_id: int) -> float:
    """Run one transitional MP to its end; returns how far [s] the last tick went past its duration."""
    trans = TransitionalRunner(skill.transitional[spec.transitional_index].mp, spec.start, spec.goal,
                               spec.duration_s, forcing_transform=spec.forcing_transform)
    rec.junction()
    if not rec.t_s:
        rec.record(trans, "transitional", stain_id)  # the start state, t = 0
    while (status := trans.update(rec.dt_s)) == TransitionStatus.WORKING:
        rec.t += rec.dt_s
        rec.record(trans, "transitional", stain_id)
    if status != TransitionStatus.FINISHED:
        raise PlanningError(f"the transition into stain {stain_id} failed: {status.name}")
    rec.t += rec.dt_s
    return trans.overrun_s


def _run_wipe(rec: _Recorder, skill: Skill, wipe: Wipe, spec: TransitionSpec, overrun_s: float,
              is_done: Callable[[Wipe, float], bool], towards_m: np.ndarray | None) -> PeriodicRunner:
    """Wipe one stain until ``is_done``, then on until the phase heads for ``towards_m`` (None: the last)."""
    # hand over at the goal (g1, g2) and entry phase, then advance by the time the last tick went past T
    periodic = PeriodicRunner(skill.periodic[wipe.periodic_index].mp, wipe.anchor_m, wipe.amplitude_m,
                              wipe.omega_rad_s, spec.entry_phase_rad, start_position_m=spec.goal[0],
                              start_velocity_m_s=spec.goal[1])
    phase0 = periodic.phase_unwrapped_rad
    if overrun_s > 0.0:
        periodic.update(overrun_s)
    rec.junction()
    rec.record(periodic, "periodic", wipe.stain.id)
    while not is_done(wipe, (periodic.phase_unwrapped_rad - phase0) / (2 * np.pi)):
        _periodic_tick(rec, periodic, wipe.stain.id)
    delay = 0.0 if towards_m is None else exit_phase_delay(skill, wipe, periodic.phase_rad, towards_m)
    leave_at = periodic.phase_unwrapped_rad + delay
    while periodic.phase_unwrapped_rad < leave_at:
        _periodic_tick(rec, periodic, wipe.stain.id)
    return periodic


def _periodic_tick(rec: _Recorder, periodic: PeriodicRunner, stain_id: int) -> None:
    status = periodic.update(rec.dt_s)
    if status < 0:
        raise PlanningError(f"the periodic MP of stain {stain_id} failed: {status.name}")
    rec.t += rec.dt_s
    rec.record(periodic, "periodic", stain_id)


def junction_step_ratios(ro: Rollout, window: int = 5) -> np.ndarray:
    """How much each MP junction steps compared with the ordinary ticks around it.

    For every junction ``j`` and each of position, velocity, acceleration:
    ``|x[j] - x[j-1]|`` divided by the largest ``|x[k] - x[k-1]|`` over the
    ``window`` ticks before and after (junction excluded). A continuous
    reference gives ratios near 1 or below; a jump shows as a ratio far
    above 1 (for a jump of ``J``, ``J / (rate of change * dt)``).

    Returns
    -------
    array, shape (n_junctions, 3)
    """
    out = np.empty((len(ro.junctions), 3))
    for col, x in enumerate((ro.position_m, ro.velocity_m_s, ro.acceleration_m_s2)):
        steps = np.linalg.norm(np.diff(x, axis=0), axis=1)  # steps[k] = x[k+1] - x[k]
        for row, j in enumerate(ro.junctions):
            around = np.concatenate([steps[max(j - 1 - window, 0) : j - 1], steps[j : j + window]])
            out[row, col] = steps[j - 1] / max(float(around.max()) if around.size else 0.0, 1e-12)
    return out
