"""Long multi-wipe takes chained from real single-wipe demonstrations, with their true labels (a test set).

A *take* is what a person does in one recording: wipe a spot, lift the
eraser, come back to the same spot or go to another 5-30 cm away, pause,
shift the grip inside a wipe. The real recordings we have hold one wipe
each (approach, wiping, retract; :mod:`lampskit.learn.demo_io` reads them
with their hand labels); :func:`build_take` chains them as a person would:

* every piece is placed on one common board (the first piece's wiping plane):
  a demonstration is expressed in its own wiping plane (fitted to its
  labelled wiping samples), moved so its wiping centre lands on the recipe's
  spot, and mapped onto the board, orientations rotated alike;
* between two pieces the pad flies from where the retract ended to where the
  next approach starts along a quintic that matches position, velocity and
  acceleration at both ends (no jump in any of them), at a person's pace;
* a pause comes to rest smoothly and holds the pose, with the recording's own
  jitter (hundredths of a millimetre);
* a *move inside a wipe* splits a wiping phase in the middle and shifts the
  rest of that piece by a few centimetres along the board through a short
  in-contact quintic move (C2 at both ends): one wiping phase, still periodic;
* a *hop* to a nearby spot: the previous piece ends with its wiping phase and
  this one starts with its own (no retract, no approach); the pad goes from
  one to the other along a quintic matching position, velocity and
  acceleration at both ends, raised off the board by a flat-topped lift
  (C2, :func:`hop_lift`) of a few centimetres; transitional.

Labels: the recordings' wiping samples and the in-wipe moves are periodic;
approaches, retracts, flights and pauses transitional. :data:`REAL_TAKES`
names the test set; ``bench/build_real_takes.py`` writes it out.
Pure numpy; the labels are used to build the truth, never by a segmenter.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lampskit.core.rotations import matrix_from_quat_wxyz, quat_wxyz_from_matrix
from lampskit.core.surface import fit_surface_frame

from .demo import Demonstration

#: A person's flying speed between spots [m/s] and the bounds of a flight's duration [s].
FLIGHT_SPEED_M_S = 0.25
FLIGHT_S = (0.6, 3.0)
#: Duration of a move inside a wipe [s].
IN_WIPE_MOVE_S = 0.5
#: How long a person takes to come to rest before a pause [s].
SETTLE_S = 0.6
#: Pose jitter while paused [m] (the recordings' own noise level).
PAUSE_JITTER_M = 3e-5
#: Share of a hop spent rising to its lift (and, mirrored, coming down).
HOP_RISE = 0.3


@dataclass(frozen=True)
class Piece:
    """One wipe of a recording placed on the board.

    demo : index into the recordings; spot_m : (2,) where its wiping centre lands on the board [m];
    move_m : (2,) a move inside the wipe, at its middle [m] (zeros: none); pause_before_s : rest before it [s];
    hop_before : (lift [m], duration [s]) of a hop from the previous piece's wiping phase into this one's
    (duration 0: a retract, a flight and an approach instead).
    """

    demo: int
    spot_m: tuple[float, float]
    move_m: tuple[float, float] = (0.0, 0.0)
    pause_before_s: float = 0.0
    hop_before: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class TakeRecipe:
    name: str
    pieces: tuple[Piece, ...]
    what: str = ""


@dataclass
class Take:
    """A built take: the demonstration, its truth (T,) (True = periodic), and each wiping phase's sample span."""

    name: str
    demo: Demonstration
    true_periodic: np.ndarray
    wipes: list[tuple[int, int]] = field(default_factory=list)


#: The named long real test set (recordings 0-3 of the wiping-demos dataset).
REAL_TAKES: tuple[TakeRecipe, ...] = (
    TakeRecipe("revisit", (Piece(0, (0.0, 0.0)), Piece(1, (0.0, 0.0)), Piece(2, (0.25, 0.0))),
               "a spot wiped, the eraser lifted, the same spot wiped again; then a spot 25 cm away"),
    TakeRecipe("near-spots", (Piece(2, (0.0, 0.0)), Piece(3, (0.06, 0.0)), Piece(0, (0.30, 0.05))),
               "spots 6 cm and 30 cm apart"),
    TakeRecipe("move-in-wipe", (Piece(1, (0.0, 0.0), move_m=(0.04, 0.0)), Piece(2, (0.20, 0.0)),
                                Piece(3, (0.20, 0.0), pause_before_s=2.0)),
               "a 4 cm shift inside a wipe; a spot 20 cm away; a 2 s pause; that spot again"),
    TakeRecipe("four-spots", (Piece(3, (0.10, 0.10)), Piece(2, (-0.10, 0.05), pause_before_s=1.5),
                              Piece(1, (0.15, -0.05), move_m=(0.0, 0.03)), Piece(0, (0.15, -0.05))),
               "four wipes in another order, a pause, a shift inside a wipe, a revisit"),
    TakeRecipe("hops", (Piece(1, (0.0, 0.0)), Piece(0, (0.06, 0.0), hop_before=(0.02, 1.0)),
                        Piece(3, (0.06, 0.12), hop_before=(0.05, 3.0)), Piece(2, (0.30, 0.12), hop_before=(0.08, 2.0))),
               "hops of 2, 5 and 8 cm lifting the pad to a spot half, one and two pad lengths (12 cm) away"),
)


def _frame(demo: Demonstration, periodic: np.ndarray):
    frame = fit_surface_frame(demo.position_m[periodic], demo.position_m)
    local = frame.surface_from_world(demo.position_m)
    centre = local[periodic, :2].mean(axis=0)
    return frame, local, centre


def _rates(t: np.ndarray, x: np.ndarray, at_end: bool) -> tuple[np.ndarray, np.ndarray]:
    """Velocity (3,) [m/s] and acceleration (3,) [m/s^2] at the last (or first) sample, from three samples."""
    tt, xx = (t[-3:], x[-3:]) if at_end else (t[:3], x[:3])
    v01 = (xx[1] - xx[0]) / (tt[1] - tt[0])
    v12 = (xx[2] - xx[1]) / (tt[2] - tt[1])
    a = (v12 - v01) / (0.5 * (tt[2] - tt[0]))
    return (v12 + 0.5 * a * (tt[2] - tt[1]), a) if at_end else (v01 - 0.5 * a * (tt[1] - tt[0]), a)


def hermite_quintic(p0, v0, a0, p1, v1, a1, duration_s: float, dt_s: float) -> np.ndarray:
    """Samples (n, d) strictly inside (0, duration) of the quintic matching position, velocity and acceleration
    at both ends."""
    p0, v0, a0, p1, v1, a1 = (np.asarray(a, float) for a in (p0, v0, a0, p1, v1, a1))
    T = duration_s
    n = max(int(round(T / dt_s)) - 1, 1)
    tau = (np.arange(1, n + 1) * (T / (n + 1)))[:, None]
    c3 = (20 * (p1 - p0) - (8 * v1 + 12 * v0) * T - (3 * a0 - a1) * T**2) / (2 * T**3)
    c4 = (30 * (p0 - p1) + (14 * v1 + 16 * v0) * T + (3 * a0 - 2 * a1) * T**2) / (2 * T**4)
    c5 = (12 * (p1 - p0) - 6 * (v1 + v0) * T - (a0 - a1) * T**2) / (2 * T**5)
    return p0 + v0 * tau + 0.5 * a0 * tau**2 + c3 * tau**3 + c4 * tau**4 + c5 * tau**5


def build_take(recipe: TakeRecipe, demos: list[Demonstration], labels: list[np.ndarray],
               seed: int = 0) -> Take:
    """Chain ``recipe``'s pieces of ``demos`` (with their periodic ``labels``) into one take (module docstring)."""
    rng = np.random.default_rng(seed)
    board = None
    parts_t: list[np.ndarray] = []
    parts_p: list[np.ndarray] = []
    parts_q: list[np.ndarray] = []
    parts_l: list[np.ndarray] = []
    wipes: list[tuple[int, int]] = []
    t_end = -np.inf
    n_total = 0

    def add(t: np.ndarray, p: np.ndarray, q: np.ndarray, lab: np.ndarray) -> None:
        nonlocal t_end, n_total
        parts_t.append(t)
        parts_p.append(p)
        parts_q.append(q)
        parts_l.append(lab)
        t_end = float(t[-1])
        n_total += len(t)

    for piece in recipe.pieces:
        demo, per = demos[piece.demo], np.asarray(labels[piece.demo], bool)
        frame, local, centre = _frame(demo, per)
        if board is None:
            board = frame
        dt = float(np.median(np.diff(demo.t_s)))
        xy = local[:, :2] - centre + np.asarray(piece.spot_m)
        local = np.column_stack([xy, local[:, 2]])
        R_map = board.T_surface_to_world[:3, :3] @ frame.T_surface_to_world[:3, :3].T
        quats = _rotated(demo.orientation_wxyz, R_map, len(local))
        t = demo.t_s - demo.t_s[0]
        move = np.asarray(piece.move_m, float)
        if np.any(move):
            t, local, quats, per = _move_inside_wipe(t, local, quats, per, move, dt)
        world = board.world_from_surface(local)
        if parts_t and piece.hop_before[1] > 0:
            first = int(np.flatnonzero(per)[0])
            t, world, quats, per = t[first:] - t[first], world[first:], quats[first:], per[first:]
            n_total -= _end_at_wipe(parts_t, parts_p, parts_q, parts_l)
            t_end = float(parts_t[-1][-1])
            hop = _hop(parts_t[-1], parts_p[-1], t, world, board, piece.hop_before, dt)
            add(t_end + piece.hop_before[1] * np.arange(1, len(hop) + 1) / (len(hop) + 1), hop,
                _slerp(parts_q[-1][-1], quats[0], len(hop)), np.zeros(len(hop), bool))
            start = t_end + piece.hop_before[1] / (len(hop) + 1)
        elif parts_t:
            prev_t, prev_p, prev_q = parts_t[-1], parts_p[-1], parts_q[-1]
            if piece.pause_before_s > 0:  # come to rest smoothly, then hold with the recording's jitter
                v_end, a_end = _rates(prev_t, prev_p, True)
                rest_at = prev_p[-1] + v_end * SETTLE_S / 2
                settle = hermite_quintic(prev_p[-1], v_end, a_end, rest_at, np.zeros(3), np.zeros(3), SETTLE_S, dt)
                add(t_end + SETTLE_S * np.arange(1, len(settle) + 1) / (len(settle) + 1), settle,
                    np.repeat(prev_q[-1:], len(settle), 0), np.zeros(len(settle), bool))
                n = int(round(piece.pause_before_s / dt))
                add(t_end + dt * np.arange(1, n + 1), rest_at + rng.normal(0.0, PAUSE_JITTER_M, (n, 3)),
                    np.repeat(prev_q[-1:], n, 0), np.zeros(n, bool))
                prev_t, prev_p = parts_t[-1], parts_p[-1]
            v0, a0 = _rates(prev_t, prev_p, True) if not piece.pause_before_s else (np.zeros(3), np.zeros(3))
            v1, a1 = _rates(t, world, False)
            dist = float(np.linalg.norm(world[0] - prev_p[-1]))
            dur = float(np.clip(dist / FLIGHT_SPEED_M_S, *FLIGHT_S))
            fly = hermite_quintic(prev_p[-1], v0, a0, world[0], v1, a1, dur, dt)
            qs = _slerp(prev_q[-1], quats[0], len(fly))
            add(t_end + dur * np.arange(1, len(fly) + 1) / (len(fly) + 1), fly, qs, np.zeros(len(fly), bool))
            start = t_end + dur / (len(fly) + 1)
        else:
            start = 0.0
        idx = np.flatnonzero(per)
        wipes.append((n_total + int(idx[0]), n_total + int(idx[-1]) + 1))
        add(start + t, world, quats, per)
    demo = Demonstration(np.concatenate(parts_t), np.vstack(parts_p), np.vstack(parts_q),
                         source=f"take {recipe.name}")
    return Take(recipe.name, demo, np.concatenate(parts_l), wipes)


def hop_lift(s: np.ndarray) -> np.ndarray:
    """Flat-topped 0 -> 1 -> 0 over ``s`` in [0, 1], flat to second order at both ends: up in the first
    :data:`HOP_RISE` of the hop, down in the last."""
    def step(x):
        x = np.clip(x, 0.0, 1.0)
        return 10 * x**3 - 15 * x**4 + 6 * x**5
    return step(s / HOP_RISE) * step((1 - s) / HOP_RISE)


def _end_at_wipe(parts_t: list, parts_p: list, parts_q: list, parts_l: list) -> int:
    """Cut the last part after its last wiping sample (its retract goes: a hop follows); samples removed."""
    keep = int(np.flatnonzero(parts_l[-1])[-1]) + 1
    removed = len(parts_t[-1]) - keep
    for parts in (parts_t, parts_p, parts_q, parts_l):
        parts[-1] = parts[-1][:keep]
    return removed


def _hop(prev_t, prev_p, t, world, board, lift_duration: tuple[float, float], dt: float) -> np.ndarray:
    """The hop's samples (n, 3) in the world frame from the end of ``prev_p`` to ``world[0]`` (module docstring)."""
    lift, duration = lift_duration
    a = board.surface_from_world(prev_p[-3:])
    b = board.surface_from_world(world[:3])
    v0, a0 = _rates(prev_t[-3:], a, True)
    v1, a1 = _rates(t[:3], b, False)
    path = hermite_quintic(a[-1], v0, a0, b[0], v1, a1, duration, dt)
    s = np.arange(1, len(path) + 1) / (len(path) + 1)
    path[:, 2] += lift * hop_lift(s)
    return board.world_from_surface(path)


def _rotated(q_wxyz: np.ndarray | None, R: np.ndarray, n: int) -> np.ndarray:
    if q_wxyz is None:
        return np.tile(quat_wxyz_from_matrix(R), (n, 1))
    out = np.array([quat_wxyz_from_matrix(R @ matrix_from_quat_wxyz(q)) for q in q_wxyz])
    flip = np.sum(out[1:] * out[:-1], axis=1) < 0  # one hemisphere along the take
    signs = np.r_[1.0, np.cumprod(np.where(flip, -1.0, 1.0))]
    return out * signs[:, None]


def _slerp(q0: np.ndarray, q1: np.ndarray, n: int) -> np.ndarray:
    q1 = q1 if float(q0 @ q1) >= 0 else -q1
    s = np.arange(1, n + 1)[:, None] / (n + 1)
    dot = float(np.clip(q0 @ q1, -1.0, 1.0))
    theta = np.arccos(dot)
    if theta < 1e-9:
        out = np.repeat(q0[None], n, 0)
    else:
        out = (np.sin((1 - s) * theta) * q0 + np.sin(s * theta) * q1) / np.sin(theta)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _move_inside_wipe(t, local, quats, per, move, dt):
    """Split the wiping phase at its middle; shift the rest by ``move`` (2,) through a short in-contact move."""
    idx = np.flatnonzero(per)
    k = int(idx[len(idx) // 2])
    v_end, a_end = _rates(t[: k + 1], local[: k + 1], True)
    v_start, a_start = _rates(t[k + 1:], local[k + 1:], False)
    rest = local[k + 1:].copy()
    rest[:, :2] += move
    bridge = hermite_quintic(local[k], v_end, a_end, rest[0], v_start, a_start, IN_WIPE_MOVE_S, dt)
    nb = len(bridge)
    t_bridge = t[k] + IN_WIPE_MOVE_S * np.arange(1, nb + 1) / (nb + 1)
    t_rest = t[k + 1:] - t[k + 1] + t[k] + IN_WIPE_MOVE_S
    return (np.concatenate([t[: k + 1], t_bridge, t_rest]), np.vstack([local[: k + 1], bridge, rest]),
            np.vstack([quats[: k + 1], np.repeat(quats[k: k + 1], nb, 0), quats[k + 1:]]),
            np.concatenate([per[: k + 1], np.ones(nb, bool), per[k + 1:]]))


def build_real_takes(mat_path: str) -> list[Take]:
    """:data:`REAL_TAKES` built from the wiping-demos recordings at ``mat_path`` (read there, never copied)."""
    from .demo_io import read_demo, read_labels

    demos = [read_demo(f"{mat_path}#{i}") for i in range(4)]
    labels = [read_labels(f"{mat_path}#{i}", d.n_samples) for i, d in enumerate(demos)]
    return [build_take(r, demos, labels, seed=i) for i, r in enumerate(REAL_TAKES)]
