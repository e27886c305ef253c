"""Synthetic, human-like multi-periodic whiteboard-wiping demonstrations.

The embedded default input of ``lamps`` and the ground truth of the tests.
A demonstration is built piece by piece in the board frame (x along the
board, y up the board, z the outward normal, metres) and then placed in the
world (robot base) frame:

- a short rest, then an *approach* from off the board to the first stain,
- per stain a *periodic* stroke (circles or zig-zags) whose frequency and
  amplitude drift slowly, as a person's do (mean frequency exactly ``f0``),
- between stains a *transition* of varying shape (a minimum-jerk move of
  the stroke centre, into which the strokes fade out and in, plus a
  sideways bulge and a small lift that vanish to second order at the ends),
- a *retreat* off the board and a short rest.

With ``human=True`` it also does what real people do in one take (drawn
from a second random stream, so the plain demos stay as they were):

- *lift-offs*: the eraser leaves the board with the height profile of a real
  retract (the recordings rise 12-35 cm in about a second, fastest early:
  a beta(3, 6) velocity profile), hovers, and comes down again with the
  mirrored, slow-landing profile of a real approach;
- *revisits*: a spot wiped, the eraser lifted, the same spot wiped again;
- *pauses*: at rest in the air at the top of a lift-off, or on the board
  beside a stain, 0.6-2 s;
- *grip shifts*: inside a wipe the stroke shrinks for half a second while
  its centre moves 1.5-3 cm (one wiping phase, still periodic).

Every such demo holds at least one of each (a revisit from two stains on).

With ``hop=HopSpec(...)`` consecutive stains lie close together, one move
of ``move_pads`` pad lengths (:data:`PAD_LENGTH_M`) apart, and the eraser
goes from one to the next in a short *hop*: it rises ``lift_m`` off the
board, crosses while up and comes down again, all in ``duration_s``. With
``drift_m`` every stroke centre drifts that far, slowly, during its wipe
(one wiping phase each). Both come from a third random stream: the strokes
themselves stay those of the plain demo of that seed.

Everything is C2 in time, sampled at 100-200 Hz with timestamp jitter and
white position noise. The true per-sample labels come with it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from lampskit.core.rotations import quat_wxyz_from_matrix
from lampskit.errors import DemoError
from lampskit.learn.demo import Demonstration
from lampskit.learn.synth_human import HumanPlan, lift_off, pause_on_board
from lampskit.learn.synth_pieces import Rest, Stroke, StrokeSpec, Transition

#: Board area in which stains are placed, board frame [m] (x range, y range).
BOARD_AREA_M = ((0.10, 1.00), (0.10, 0.70))
#: The eraser pad's length [m], the unit of a hop's move (``arm.description.PAD_SIZE_M[0]``; the
#: offline learner does not import the cell's description, a test keeps the two equal).
PAD_LENGTH_M = 0.12


@dataclass(frozen=True)
class HopSpec:
    """A short hop between consecutive nearby wipes (see the module docstring).

    lift_m : peak height off the board [m] (0.005-0.3); move_pads : centre-to-centre move in pad lengths
    (0.25-4); duration_s : the hop's duration, strokes fading out and in included [s] (0.5-5).
    """

    lift_m: float
    move_pads: float
    duration_s: float

    def __post_init__(self) -> None:
        for name, value, (lo, hi) in (("lift_m", self.lift_m, (0.005, 0.3)), ("move_pads", self.move_pads, (0.25, 4.0)),
                                      ("duration_s", self.duration_s, (0.5, 5.0))):
            if not (isinstance(value, (int, float)) and lo <= value <= hi):
                raise DemoError(f"hop {name} must be between {lo} and {hi}, got {value!r}")


@dataclass(frozen=True)
class SyntheticDemo:
    """A synthetic demonstration with its ground truth.

    Attributes
    ----------
    demo : Demonstration
        Positions in the world frame [m], orientation constant (pad on board).
    true_periodic : array of bool, shape (T,)
        True where the sample belongs to a periodic stroke.
    true_stain : array of int, shape (T,)
        Stain index of each periodic sample, -1 on transitional samples.
    stain_centres_m : array, shape (K, 3)
        Stroke centres in the world frame [m], in wiping order.
    strokes : tuple of StrokeSpec
        The strokes, in the board frame.
    segments : tuple of (start, end, kind, stain)
        True ``[start, end)`` segments in time order.
    T_board_to_world : array, shape (4, 4)
        Pose of the board frame in the world frame.
    """

    demo: Demonstration
    true_periodic: np.ndarray
    true_stain: np.ndarray
    stain_centres_m: np.ndarray
    strokes: tuple[StrokeSpec, ...]
    segments: tuple[tuple[int, int, str, int], ...]
    T_board_to_world: np.ndarray = field(repr=False)


def synthesize_demo(
    n_stains: int = 3,
    seed: int = 0,
    rate_hz: float | None = None,
    noise_m: float = 0.0004,
    revisit_first: bool = False,
    human: bool = False,
    hop: HopSpec | None = None,
    drift_m: float = 0.0,
) -> SyntheticDemo:
    """A human-like wiping demonstration over ``n_stains`` stains.

    Parameters
    ----------
    n_stains : int
        Number of stains wiped, 1 to 8.
    seed : int
        Seed of every random choice; the same seed gives the same demo.
    rate_hz : float, optional
        Mean sample rate [Hz]; default drawn from [100, 200].
    noise_m : float
        Standard deviation of the white position noise [m].
    revisit_first : bool
        Wipe the first stain a second time at the end (same board region,
        two periodic segments at different times; its stain index repeats).
    human : bool
        Lift-offs, a revisit after a lift-off, pauses and a grip shift inside
        a wipe, as real people do (see the module docstring).
    hop : HopSpec, optional
        Consecutive stains one move apart, joined by short hops (see the module docstring).
    drift_m : float
        How far every stroke centre drifts, slowly, during its wipe [m] (0 to 0.15).
    """
    if not 1 <= int(n_stains) <= 8:
        raise DemoError(f"n_stains must be between 1 and 8, got {n_stains!r}")
    if rate_hz is not None and not 20.0 <= rate_hz <= 2000.0:
        raise DemoError(f"rate_hz must be between 20 and 2000 Hz, got {rate_hz!r}")
    if not 0.0 <= noise_m <= 0.01:
        raise DemoError(f"noise_m must be between 0 and 0.01 m, got {noise_m!r}")
    if not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise DemoError(f"seed must be a non-negative integer, got {seed!r}")
    if not 0.0 <= drift_m <= 0.15:
        raise DemoError(f"drift_m must be between 0 and 0.15 m, got {drift_m!r}")
    rng = np.random.default_rng(seed)
    rate = float(rate_hz) if rate_hz is not None else float(rng.uniform(100.0, 200.0))
    strokes = _draw_strokes(int(n_stains), rng)
    if hop is not None or drift_m > 0:
        strokes = _hops_and_drift(strokes, hop, drift_m, np.random.default_rng([seed, 2]))
    order = list(range(len(strokes))) + ([0] if revisit_first else [])
    plan = HumanPlan.draw(order, np.random.default_rng([seed, 1])) if human else None
    if plan is not None:
        order = plan.order
    wiped = [strokes[k] for k in order]
    if plan is not None:
        k = plan.shift_piece
        wiped[k] = replace(wiped[k], shift_m=plan.shift_m, shift_at=plan.shift_at)
    pieces = _build_pieces(wiped, rng, plan, hop)
    t_end = sum(p.duration_s for p in pieces)
    dt = 1.0 / rate
    n = int(np.floor(t_end / dt))
    t = np.arange(n) * dt + rng.uniform(-0.15, 0.15, n) * dt  # jitter, strictly increasing
    t[0] = 0.0
    t = np.clip(t, 0.0, t_end)
    pos_board = np.empty((n, 3))
    periodic = np.zeros(n, dtype=bool)
    stain = np.full(n, -1, dtype=int)
    segments: list[tuple[int, int, str, int]] = []
    t0 = 0.0
    for piece in pieces:
        t1 = t0 + piece.duration_s
        idx = np.flatnonzero((t >= t0) & (t < t1)) if piece is not pieces[-1] else np.flatnonzero(t >= t0)
        pos_board[idx] = piece.evaluate(t[idx] - t0)
        if piece.stain >= 0:
            periodic[idx] = True
            stain[idx] = piece.stain
        if idx.size:
            kind = "periodic" if piece.stain >= 0 else "transitional"
            if segments and segments[-1][2] == kind == "transitional":
                segments[-1] = (segments[-1][0], int(idx[-1]) + 1, kind, -1)
            else:
                segments.append((int(idx[0]), int(idx[-1]) + 1, kind, piece.stain))
        t0 = t1
    pos_board += rng.normal(0.0, noise_m, pos_board.shape)
    T = _board_pose(rng)
    pos_world = pos_board @ T[:3, :3].T + T[:3, 3]
    q = np.tile(_quat_wxyz_tool_on_board(T[:3, :3]), (n, 1))
    centres = np.array([[*s.centre_m, 0.0] for s in strokes]) @ T[:3, :3].T + T[:3, 3]
    index = np.array(order + [-1])  # a piece's stain is its place in the wiping order; -1 stays -1
    stain = index[stain]
    segments = [(a, b, k, int(index[s])) for a, b, k, s in segments]
    extra = (", human" if human else "") + (f", {hop}" if hop else "") + (f", drift_m={drift_m:g}" if drift_m else "")
    demo = Demonstration(t, pos_world, q, source=f"synthetic(n_stains={n_stains}, seed={seed}{extra})")
    return SyntheticDemo(demo, periodic, stain, centres, tuple(strokes), tuple(segments), T)


# --------------------------------------------------------------------------
# random scene


def _draw_strokes(n: int, rng: np.random.Generator) -> list[StrokeSpec]:
    strokes: list[StrokeSpec] = []
    for _k in range(n):
        kind = "circle" if rng.random() < 0.6 else "zigzag"
        amplitude = float(rng.uniform(0.025, 0.05))
        for _ in range(2000):
            c = np.array([rng.uniform(*BOARD_AREA_M[0]), rng.uniform(*BOARD_AREA_M[1])])
            # separation: two stroke envelopes apart plus a gap a person would leave
            if all(np.linalg.norm(c - s.centre_m) > amplitude + s.amplitude_m + 0.12 for s in strokes):
                break
        else:
            raise DemoError(f"could not place {n} separated stains on the board")
        strokes.append(
            StrokeSpec(
                centre_m=c,
                kind=kind,
                freq_hz=float(rng.uniform(1.0, 2.2)),
                amplitude_m=amplitude,
                angle_rad=float(rng.uniform(0, 2 * np.pi)),
                n_cycles=float(rng.uniform(4.0, 7.0)),
            )
        )
    return strokes


def _hops_and_drift(strokes: list[StrokeSpec], hop: HopSpec | None, drift_m: float,
                    rng: np.random.Generator) -> list[StrokeSpec]:
    """The strokes re-placed one hop apart (each next centre one move from where the last wipe ended, in a
    direction that keeps it on the board and at least a move from every earlier stain), and given their drift."""
    out: list[StrokeSpec] = []
    lo, hi = np.array(BOARD_AREA_M).T
    for s in strokes:
        angle = rng.uniform(0, 2 * np.pi)
        drift = drift_m * np.array([np.cos(angle), np.sin(angle)])
        centre = s.centre_m
        if hop is not None and out:
            move = hop.move_pads * PAD_LENGTH_M
            start = out[-1].centre_m + out[-1].drift_m
            for _ in range(2000):
                a = rng.uniform(0, 2 * np.pi)
                centre = start + move * np.array([np.cos(a), np.sin(a)])
                ends = (centre, centre + drift)
                if (all(np.all((lo <= c) & (c <= hi)) for c in ends)
                        and all(np.linalg.norm(e - (o.centre_m + w * o.drift_m)) >= 0.999 * move
                                for e in ends for o in out[:-1] for w in (0, 1))):
                    break
            else:
                raise DemoError(f"could not place {len(strokes)} stains one hop of {move:.3f} m apart on the board")
        out.append(replace(s, centre_m=centre, drift_m=drift))
    return out


def _board_pose(rng: np.random.Generator) -> np.ndarray:
    """A vertical board in front of the robot, slightly tilted at random."""
    tilt = rng.uniform(-0.08, 0.08, 2)
    # board x -> world -y ... chosen so the board faces the robot (normal -x)
    R = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    R = _rot_x(tilt[0]) @ _rot_z(tilt[1]) @ R
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = [0.75, -0.55, 0.25]
    return T


def _rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _quat_wxyz_tool_on_board(R_board: np.ndarray) -> np.ndarray:
    """Tool z axis into the board (along -normal), tool x along board x."""
    return quat_wxyz_from_matrix(np.column_stack([R_board[:, 0], -R_board[:, 1], -R_board[:, 2]]))


# --------------------------------------------------------------------------
# the pieces in time order (each maps local time (K,) -> board positions (K, 3), C2 in time: synth_pieces)


def _build_pieces(strokes: list[StrokeSpec], rng: np.random.Generator, plan: HumanPlan | None = None,
                  hop: HopSpec | None = None) -> list:
    zero = np.zeros(3)
    runs = [
        Stroke(
            s,
            k,  # a revisited stain gets index len(strokes) here; synthesize_demo maps it back
            np.array(
                [
                    rng.uniform(0.12, 0.3),  # frequency modulation rate [Hz]
                    rng.uniform(0, 2 * np.pi),
                    rng.uniform(0.1, 0.25),  # amplitude modulation rate [Hz]
                    rng.uniform(0, 2 * np.pi),
                    rng.uniform(0, 2 * np.pi),  # start phase
                    rng.uniform(0.02, 0.05),  # frequency modulation depth
                    rng.uniform(0.04, 0.10),  # amplitude modulation depth
                ]
            ),
        )
        for k, s in enumerate(strokes)
    ]
    home = np.array([*runs[0].spec.centre_m + rng.uniform(-0.1, 0.1, 2), rng.uniform(0.08, 0.15)])
    pieces: list = [Rest(home, float(rng.uniform(0.2, 0.4)))]
    duration = float(rng.uniform(1.0, 1.6))
    pieces.append(Transition(home, runs[0].centre3, duration, zero.copy(), None, runs[0], 0.35 / duration))
    for k, run in enumerate(runs):
        pieces.append(run)
        if plan is not None and k + 1 < len(runs) and (plan.lift[k] or plan.pause_at == k):
            pause = plan.pause_s if plan.pause_at == k else 0.0
            build = lift_off if plan.lift[k] else pause_on_board
            pieces.extend(build(run, runs[k + 1], pause, plan.rng))
        elif hop is not None and k + 1 < len(runs):
            fade = min(0.4, 0.35 / hop.duration_s)
            pieces.append(Transition(run.end_centre3, runs[k + 1].centre3, hop.duration_s,
                                      np.array([0.0, 0.0, hop.lift_m]), run, runs[k + 1], fade, profile="hop"))
        elif k + 1 < len(runs):
            nxt = runs[k + 1]
            delta = nxt.centre3 - run.end_centre3
            dist = float(np.linalg.norm(delta))
            duration = max(0.8, dist / rng.uniform(0.25, 0.4))
            side = np.cross([0.0, 0.0, 1.0], delta) / max(dist, 1e-9)
            bulge = side * rng.uniform(-0.2, 0.2) * dist + np.array([0, 0, rng.uniform(0.0, 0.01)])
            fade = min(0.4, 0.35 / duration)
            pieces.append(Transition(run.end_centre3, nxt.centre3, duration, bulge, run, nxt, fade))
        else:
            away = np.array([*run.spec.centre_m + rng.uniform(-0.1, 0.1, 2), rng.uniform(0.08, 0.15)])
            duration = float(rng.uniform(1.0, 1.6))
            pieces.append(Transition(run.end_centre3, away, duration, zero.copy(), run, None, 0.35 / duration))
            pieces.append(Rest(away, float(rng.uniform(0.2, 0.4))))
    return pieces
