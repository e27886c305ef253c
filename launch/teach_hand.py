"""The scripted operator for teaching in the simulator: a human-like wiping path for the hand, on the sim's board.

:func:`hand_path` takes the synthetic demonstration of :mod:`lampskit.learn.synth` (circular and zig-zag strokes
over ``n_stains`` stains with drifting frequency and amplitude, C2 transitions, a rest before and after), moves
its board-frame path onto the simulated board's stain region (scaled down if it does not fit), puts it
``press_n / stiffness`` behind the board's face where it wipes (the hand's spring presses the pad with about
``press_n``) and leads in from where the pad starts. :func:`write_hand_csv` writes it as ``[sim.hand] script``
reads it (:mod:`sim.hand`).
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: The hand's path runs ``press_n / stiffness`` behind the board's face where the synthetic path touches the board,
#: as drawn from this height up (the rests, a lift) [m], and in between pressed in gradually (smoothstep): the pad
#: lands softly, as a hand sets an eraser down.
LANDING_M = 0.02


@dataclass(frozen=True)
class HandPath:
    """t_s (T,) [s]; p_world_m (T, 3) the hand's path [m]; stain_centres_m (K, 2) where the strokes are centred,
    board frame [m] (the scaled synthetic strokes, in wiping order); lead_in_s : when the synthetic path starts."""

    t_s: np.ndarray
    p_world_m: np.ndarray
    stain_centres_m: np.ndarray
    lead_in_s: float


def hand_path(board, start_p_m: np.ndarray, region: tuple[np.ndarray, np.ndarray], n_stains: int = 3,
              seed: int = 0, press_n: float = 10.0, stiffness_n_m: float = 2000.0, rate_hz: float = 200.0,
              lead_in_s: float = 1.5, max_speed_m_s: float = 0.4) -> HandPath:
    """The hand's path over ``board`` (:class:`sim.board.Board`) from the pad's start ``start_p_m`` (3,) [m].

    region : (lo (2,), hi (2,)) board-frame corners the strokes must stay in [m] (the stain region).
    max_speed_m_s : the synthetic path is slowed down (time stretched) so its peak in-plane speed is at most this:
    the teach controller brakes the pad above ``[controller.limits] max_speed_m_s``.
    """
    from lampskit.learn.synth import synthesize_demo

    syn = synthesize_demo(n_stains, seed, rate_hz=rate_hz, noise_m=0.0)
    T = syn.T_board_to_world
    pb = (syn.demo.position_m - T[:3, 3]) @ T[:3, :3]  # the synthetic board frame
    t = syn.demo.t_s
    lo, hi = (np.asarray(v, float) for v in region)
    xy = pb[:, :2]
    span = xy.max(axis=0) - xy.min(axis=0)
    scale = float(min(1.0, *((hi - lo) / np.maximum(span, 1e-9))))
    mid_src = 0.5 * (xy.max(axis=0) + xy.min(axis=0))
    xy = (xy - mid_src) * scale + 0.5 * (lo + hi)
    centres = (syn.stain_centres_m - T[:3, 3]) @ T[:3, :3]
    centres = (centres[:, :2] - mid_src) * scale + 0.5 * (lo + hi)
    speed = np.linalg.norm(np.gradient(xy, t, axis=0), axis=1)
    stretch = max(1.0, float(np.percentile(speed, 99.5)) / max_speed_m_s)
    t = t * stretch
    u = np.clip(1.0 - pb[:, 2] / LANDING_M, 0.0, 1.0)
    h = pb[:, 2] - press_n / stiffness_n_m * u * u * (3.0 - 2.0 * u)
    path = board.world_from_board(xy) + h[:, None] * board.normal_world
    n_in = max(int(lead_in_s * rate_hz), 2)
    s = np.linspace(0.0, 1.0, n_in, endpoint=False)
    blend = s ** 3 * (10.0 - 15.0 * s + 6.0 * s ** 2)  # rest to rest (minimum jerk)
    lead = np.asarray(start_p_m, float) + blend[:, None] * (path[0] - np.asarray(start_p_m, float))
    t_all = np.concatenate([s * lead_in_s, lead_in_s + t - t[0]])
    return HandPath(t_all, np.vstack([lead, path]), centres, lead_in_s)


def write_hand_csv(path: str | Path, hand: HandPath) -> Path:
    """``t,x,y,z`` (world frame), atomically."""
    from lampskit.atomic import write_text_atomic

    buf = io.StringIO()
    np.savetxt(buf, np.column_stack([hand.t_s, hand.p_world_m]), delimiter=",", header="t,x,y,z", comments="",
               fmt="%.9g")
    return write_text_atomic(path, buf.getvalue())
