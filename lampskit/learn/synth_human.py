"""What a person does in one take beyond wiping, for a synthetic demonstration with ``human=True``
(:mod:`lampskit.learn.synth`): the plan of lift-offs, a revisit, a pause and a grip shift, drawn from its own
random stream, and the pieces of a lift-off and of a pause on the board."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lampskit.learn.synth_pieces import Rest, Stroke, Transition

#: Lift-off heights [m] (the recordings' retracts reach 12-35 cm) and how likely a transition is one.
LIFT_HEIGHT_M = (0.12, 0.30)
LIFT_SHARE = 0.35
#: A pause's duration [s].
PAUSE_S = (0.6, 2.0)


@dataclass
class HumanPlan:
    """What a person does in one take beyond wiping (see :mod:`lampskit.learn.synth`), drawn from its own stream.

    order : stain of each wipe, in time order (a revisit repeats one); lift : per transition between wipes,
    whether the eraser leaves the board; pause_at : the transition with a pause, pause_s its length [s];
    shift_piece : the wipe with a grip shift, shift_m (2,) its move [m], shift_at where it starts (share).
    """

    order: list[int]
    lift: list[bool]
    pause_at: int
    pause_s: float
    shift_piece: int
    shift_m: np.ndarray
    shift_at: float
    rng: np.random.Generator

    @classmethod
    def draw(cls, order: list[int], rng: np.random.Generator) -> HumanPlan:
        r = int(rng.integers(0, len(order)))
        order = order[: r + 1] + [order[r]] + order[r + 1:]  # the spot again, after a lift-off
        lift = [bool(rng.random() < LIFT_SHARE) or i == r for i in range(len(order) - 1)]
        angle = rng.uniform(0, 2 * np.pi)
        return cls(order, lift, int(rng.integers(0, len(lift))), float(rng.uniform(*PAUSE_S)),
                   int(rng.integers(0, len(order))),
                   rng.uniform(0.015, 0.03) * np.array([np.cos(angle), np.sin(angle)]),
                   float(rng.uniform(0.35, 0.5)), rng)


def lift_off(run: Stroke, nxt: Stroke, pause_s: float, rng: np.random.Generator) -> list:
    """Retract off the board from ``run``, hover (and pause ``pause_s``), approach ``nxt``: rest-to-rest at the top."""
    height = rng.uniform(*LIFT_HEIGHT_M)
    a, b = run.end_centre3, nxt.centre3
    if np.linalg.norm(b - a) < 0.02:  # the same spot again: the hand drifts a little while up
        top_xy = a[:2] + rng.uniform(-0.04, 0.04, 2)
    else:
        top_xy = 0.5 * (a[:2] + b[:2])
    top = np.array([*top_xy, height])
    slow = np.sqrt(height / 0.2)
    t_up = max(rng.uniform(0.9, 1.4) * slow, np.linalg.norm(top_xy - a[:2]) / 0.3)
    t_down = max(rng.uniform(1.1, 1.7) * slow, np.linalg.norm(b[:2] - top_xy) / 0.3)
    pieces: list = [Transition(a, top, t_up, np.zeros(3), run, None, min(0.4, 0.35 / t_up), profile="retract")]
    if pause_s > 0:
        pieces.append(Rest(top, pause_s))
    pieces.append(Transition(top, b, t_down, np.zeros(3), None, nxt, min(0.4, 0.35 / t_down), profile="approach"))
    return pieces


def pause_on_board(run: Stroke, nxt: Stroke, pause_s: float, rng: np.random.Generator) -> list:
    """Out of ``run`` to rest on the board beside it for ``pause_s``, then on into ``nxt``."""
    a, b = run.end_centre3, nxt.centre3
    side = rng.uniform(-1, 1, 2)
    stop = np.array([*(a[:2] + 0.03 * side / max(float(np.linalg.norm(side)), 1e-9)), 0.0])
    t_out = float(rng.uniform(0.6, 0.9))
    t_on = max(0.8, float(np.linalg.norm(b - stop)) / rng.uniform(0.25, 0.4))
    return [Transition(a, stop, t_out, np.zeros(3), run, None, min(0.4, 0.35 / t_out)), Rest(stop, pause_s),
            Transition(stop, b, t_on, np.zeros(3), None, nxt, min(0.4, 0.35 / t_on))]
