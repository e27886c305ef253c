"""A plan executed offline at a fixed rate: the reference the robot would follow, sample by sample.

:func:`rollout` steps the executor's own MP chain (:class:`~lampskit.core.chain.MpChain`,
the one implementation of chaining) through the plan with a stand-in for kappa
(a number of cycles per stain), for ``lamps plan``, the figures and the tests;
:func:`junction_step_ratios` measures how continuous the hand-overs are.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from lampskit.core.chain import ChainResult, ChainStep, MpChain
from lampskit.core.planner_types import Plan, Stain, TransitionSpec, Wipe
from lampskit.core.skill import Skill
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


#: A rollout gives up after this many samples (a stand-in for kappa that never says done).
MAX_SAMPLES = 5_000_000


def rollout(
    skill: Skill,
    plan_: Plan,
    start: tuple[np.ndarray, np.ndarray, np.ndarray],
    *,
    dt_s: float = 0.001,
    cycles_per_stain: float | None = None,
    is_done: Callable[[Wipe, float], bool] | None = None,
) -> Rollout:
    """Execute ``plan_`` from ``start`` at ``1/dt_s`` Hz with the executor's MP chain.

    Each stain is wiped until ``is_done(wipe, cycles_done)`` (kappa's stand-in)
    is true; by default after ``cycles_per_stain`` cycles (default: the mean
    demonstrated count, at least 2); then, unless it is the last, until the
    phase heads for the next stain of the plan. The first sample is ``start``
    at t = 0; the rollout ends on the last stain's periodic MP (lifting off and
    retreating are the controller's). As in the executor, the tick in which a
    transition starts holds the reference it starts from.
    """
    if not 1e-4 <= dt_s <= 0.02:
        raise PlanningError(f"dt_s must be in [0.0001, 0.02] s, got {dt_s}")
    if is_done is None:
        is_done = _after_cycles(_cycles_per_stain(skill, cycles_per_stain))
    chain = MpChain(skill, plan_.params, math.inf, Counter(), follow_plan=True)
    book = _PlanBook(plan_, chain, is_done)
    ref = _Reference(*(np.asarray(x, dtype=float).reshape(2).copy() for x in start))
    rec = _Recorder()
    rec.record(0.0, ref, "transitional", plan_.wipes[0].stain.id)
    if chain.start(plan_, ref) == ChainResult.ERROR:
        raise PlanningError(chain.error)
    assert chain.entry is not None and chain.wipe is not None  # set by a start that did not fail
    specs, clock = [chain.entry], 0.0
    for k in range(1, MAX_SAMPLES):
        result = chain.update(dt_s, ref, book, clock)
        clock = k * dt_s
        if result == ChainResult.ERROR:
            raise PlanningError(chain.error)
        if result == ChainResult.FINISHED:
            break
        if result == ChainResult.TRANSITION:
            specs.append(chain.entry)
        if result in (ChainResult.TRANSITION, ChainResult.WIPE):
            rec.junctions.append(len(rec.t_s))
        kind = "transitional" if chain.step == ChainStep.TRANSIT else "periodic"
        rec.record(clock, ref, kind, chain.wipe.stain.id)
    else:
        raise PlanningError(f"the rollout did not end within {MAX_SAMPLES} samples: is_done never said done")
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


@dataclass
class _Reference:
    """The rollout's in-plane reference (what the executor's setpoint is to the chain)."""

    xy: np.ndarray
    v_xy: np.ndarray
    a_xy: np.ndarray


class _PlanBook:
    """The plan's stains for the chain, with ``is_done(wipe, cycles)`` standing in for kappa: a stain is done once
    the chain has wiped it long enough (and stays done)."""

    max_passes = 1

    def __init__(self, plan_: Plan, chain: MpChain, is_done: Callable[[Wipe, float], bool]) -> None:
        self._plan, self._chain, self._is_done = plan_, chain, is_done
        self.stains = {w.stain.id: w.stain for w in plan_.wipes}
        self._done: set[int] = set()

    def is_done(self, stain_id: int) -> bool:
        chain = self._chain
        if stain_id not in self._done and chain.wipe is not None and chain.wipe.stain.id == stain_id \
                and chain.step != ChainStep.TRANSIT and self._is_done(chain.wipe, chain.cycles_wiped):
            self._done.add(stain_id)
        return stain_id in self._done

    def end_pass(self, stain_id: int, clock_s: float) -> bool:  # no timeout offline: never called
        self._done.add(stain_id)
        return True

    def open_stains(self, clock_s: float, by_ink: bool = False, exclude: int | None = None) -> list[Stain]:
        return [w.stain for w in self._plan.wipes if w.stain.id not in self._done and w.stain.id != exclude]


class _Recorder:
    """The rollout's samples as they are produced, and where one MP handed over to the next."""

    def __init__(self) -> None:
        self.t_s: list[float] = []
        self.p: list[np.ndarray] = []
        self.v: list[np.ndarray] = []
        self.a: list[np.ndarray] = []
        self.kind: list[str] = []
        self.stain: list[int] = []
        self.junctions: list[int] = []

    def record(self, t: float, ref: _Reference, kind: str, stain_id: int) -> None:
        self.t_s.append(t)
        self.p.append(ref.xy.copy())
        self.v.append(ref.v_xy.copy())
        self.a.append(ref.a_xy.copy())
        self.kind.append(kind)
        self.stain.append(stain_id)

    def result(self, specs: tuple[TransitionSpec, ...]) -> Rollout:
        return Rollout(np.array(self.t_s), np.array(self.p), np.array(self.v), np.array(self.a),
                       np.array(self.kind), np.array(self.stain), tuple(self.junctions), specs)


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
