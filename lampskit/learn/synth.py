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

Everything is C2 in time, sampled at 100-200 Hz with timestamp jitter and
white position noise. The true per-sample labels come with it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from lampskit.core.rotations import quat_wxyz_from_matrix

from lampskit.learn.demo import Demonstration
from lampskit.errors import DemoError

#: Board area in which stains are placed, board frame [m] (x range, y range).
BOARD_AREA_M = ((0.10, 1.00), (0.10, 0.70))
#: How long a grip shift inside a wipe takes [s].
GRIP_SHIFT_S = 0.5
#: Share of a lift-off's retract spent going up before moving along the board (mirrored for the approach).
LIFT_FIRST = 0.3
#: Lift-off heights [m] (the recordings' retracts reach 12-35 cm) and how likely a transition is one.
LIFT_HEIGHT_M = (0.12, 0.30)
LIFT_SHARE = 0.35
#: A pause's duration [s].
PAUSE_S = (0.6, 2.0)


@dataclass(frozen=True)
class StrokeSpec:
    """One stain's periodic stroke, in the board frame.

    Attributes
    ----------
    centre_m : array, shape (2,)
        Stroke centre on the board [m].
    kind : str
        ``"circle"`` or ``"zigzag"``.
    freq_hz : float
        Mean stroke frequency [Hz].
    amplitude_m : float
        Stroke amplitude [m] (circle radius, zig-zag half length).
    angle_rad : float
        Direction of the zig-zag stroke / start angle of the circle [rad].
    n_cycles : float
        Number of cycles wiped.
    shift_m : array, shape (2,)
        A grip shift inside the wipe: how far the stroke centre moves [m] (zeros: none).
    shift_at : float
        Where in the wipe the shift starts, as a share of its duration.
    """

    centre_m: np.ndarray
    kind: str
    freq_hz: float
    amplitude_m: float
    angle_rad: float
    n_cycles: float
    shift_m: np.ndarray = field(default_factory=lambda: np.zeros(2))
    shift_at: float = 0.5


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
    """
    if not 1 <= int(n_stains) <= 8:
        raise DemoError(f"n_stains must be between 1 and 8, got {n_stains!r}")
    if rate_hz is not None and not 20.0 <= rate_hz <= 2000.0:
        raise DemoError(f"rate_hz must be between 20 and 2000 Hz, got {rate_hz!r}")
    if not 0.0 <= noise_m <= 0.01:
        raise DemoError(f"noise_m must be between 0 and 0.01 m, got {noise_m!r}")
    if not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise DemoError(f"seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng(seed)
    rate = float(rate_hz) if rate_hz is not None else float(rng.uniform(100.0, 200.0))
    strokes = _draw_strokes(int(n_stains), rng)
    order = list(range(len(strokes))) + ([0] if revisit_first else [])
    plan = _HumanPlan.draw(order, np.random.default_rng([seed, 1])) if human else None
    if plan is not None:
        order = plan.order
    wiped = [strokes[k] for k in order]
    if plan is not None:
        k = plan.shift_piece
        wiped[k] = replace(wiped[k], shift_m=plan.shift_m, shift_at=plan.shift_at)
    pieces = _build_pieces(wiped, rng, plan)
    t_end = sum(p.duration_s for p in pieces)
    dt = 1.0 / rate
    n = int(np.floor(t_end / dt))
    t = np.arange(n) * dt + rng.uniform(-0.15, 0.15, n) * dt  # jitter, strictly increasing
    t[0] = 0.0
    t = np.clip(t, 0.0, t_end)
    pos_board = np.empty((n, 3))
    periodic = np.zeros(n, dtype=bool)
    stain = np.full(n, -1, dtype=int)
    segments = []
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
    extra = ", human" if human else ""
    demo = Demonstration(t, pos_world, q, source=f"synthetic(n_stains={n_stains}, seed={seed}{extra})")
    return SyntheticDemo(demo, periodic, stain, centres, tuple(strokes), tuple(segments), T)


# --------------------------------------------------------------------------
# random scene


def _draw_strokes(n: int, rng: np.random.Generator) -> list[StrokeSpec]:
    strokes: list[StrokeSpec] = []
    for k in range(n):
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
# pieces: each maps local time (K,) -> board positions (K, 3), C2 in time


@dataclass
class _Stroke:
    spec: StrokeSpec
    stain: int
    rng_values: np.ndarray  # fm, phase_m, am_freq, phase_a, phase0, fm_depth, am_depth

    @property
    def duration_s(self) -> float:
        return self.spec.n_cycles / self.spec.freq_hz

    def _phase(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f0 = self.spec.freq_hz
        fm, pm, _, _, p0, depth, _ = self.rng_values
        w0, wm = 2 * np.pi * f0, 2 * np.pi * fm
        phi = p0 + w0 * t + depth * w0 / wm * (np.sin(wm * t + pm) - np.sin(pm))
        dphi = w0 * (1 + depth * np.cos(wm * t + pm))
        ddphi = -w0 * depth * wm * np.sin(wm * t + pm)
        return phi, dphi, ddphi

    def _amp(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        _, _, fa, pa, _, _, depth = self.rng_values
        wa = 2 * np.pi * fa
        a0 = self.spec.amplitude_m
        return (
            a0 * (1 + depth * np.sin(wa * t + pa)),
            a0 * depth * wa * np.cos(wa * t + pa),
            -a0 * depth * wa**2 * np.sin(wa * t + pa),
        )

    def _shift(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple]:
        """The grip shift: the share of the centre's move done (K,) with its two time derivatives, and the
        stroke's amplitude factor (1 - a half-depth bump while the hand moves) with its two derivatives."""
        d = GRIP_SHIFT_S
        u = (t - self.spec.shift_at * self.duration_s) / d
        g, dg, ddg = _smoothstep3(u)
        b, db, ddb = _bump3(u)
        return g, dg / d, ddg / d**2, (1.0 - 0.5 * b, -0.5 * db / d, -0.5 * ddb / d**2)

    def state(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration (K, 3) in the board frame."""
        phi, dphi, ddphi = self._phase(t)
        a, da, dda = self._amp(t)
        shifting = bool(np.any(self.spec.shift_m))
        if shifting:
            g, dg, ddg, (m, dm, ddm) = self._shift(t)
            a, da, dda = a * m, da * m + a * dm, dda * m + 2 * da * dm + a * ddm
        # unit shape u(phi) and its phase derivatives, in the stroke's own axes
        if self.spec.kind == "circle":
            u = np.stack([np.cos(phi), np.sin(phi)], -1)
            u1 = np.stack([-np.sin(phi), np.cos(phi)], -1)
            u2 = -u
        else:  # zig-zag: fast back and forth with a slight loop at the turns
            k = 1.0 / 1.12
            u = np.stack([k * (np.sin(phi) + 0.12 * np.sin(3 * phi)), 0.25 * np.sin(2 * phi)], -1)
            u1 = np.stack([k * (np.cos(phi) + 0.36 * np.cos(3 * phi)), 0.5 * np.cos(2 * phi)], -1)
            u2 = np.stack([k * (-np.sin(phi) - 1.08 * np.sin(3 * phi)), -np.sin(2 * phi)], -1)
        a, da, dda = a[:, None], da[:, None], dda[:, None]
        dphi, ddphi = dphi[:, None], ddphi[:, None]
        p = a * u
        v = da * u + a * u1 * dphi
        acc = dda * u + 2 * da * u1 * dphi + a * (u2 * dphi**2 + u1 * ddphi)
        c, s = np.cos(self.spec.angle_rad), np.sin(self.spec.angle_rad)
        R = np.array([[c, -s], [s, c]])
        out = []
        for arr, offset in ((p, self.spec.centre_m), (v, 0.0), (acc, 0.0)):
            xy = arr @ R.T + offset
            out.append(np.column_stack([xy, np.zeros(len(xy))]))
        if shifting:
            for k, w in enumerate((g, dg, ddg)):
                out[k][:, :2] += w[:, None] * self.spec.shift_m
        return out[0], out[1], out[2]

    @property
    def centre3(self) -> np.ndarray:
        """The stroke centre where the wipe starts (3,) [m]."""
        return np.array([*self.spec.centre_m, 0.0])

    @property
    def end_centre3(self) -> np.ndarray:
        """The stroke centre where the wipe ends (after any grip shift) (3,) [m]."""
        return np.array([*(self.spec.centre_m + self.spec.shift_m), 0.0])

    def offset(self, t: np.ndarray) -> np.ndarray:
        """The stroke's offset from its (moving) centre (K, 3) [m], for fading it in and out of transitions."""
        p = self.evaluate(t)
        if np.any(self.spec.shift_m):
            p[:, :2] -= self._shift(np.asarray(t, float))[0][:, None] * self.spec.shift_m
        return p - self.centre3

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        return self.state(np.asarray(t, dtype=float))[0]


@dataclass
class _Transition:
    """A move between strokes: a minimum-jerk path of the stroke centre plus fading stroke offsets.

    ``p(t) = c(s) + (1 - w(s/rho)) * o_prev(t) + w((s - 1 + rho)/rho) * o_next(t - T) + bump(s) * bulge``
    with ``s = t / T``, ``c`` the quintic (rest-to-rest) path between the stroke centres, ``o_prev`` the
    previous stroke's offset from its centre continued past its end, ``o_next`` the next stroke's offset
    run back before its start, ``w`` the quintic smoothstep and ``bump = 64 s^3 (1 - s)^3``. Every term
    other than the stroke offsets has zero velocity and acceleration at both ends, and the fades are flat
    to second order there, so the demonstration is C2 across each junction, and the eraser spirals out of
    one stroke and into the next as a person's hand does.
    """

    start_m: np.ndarray  # (3,) centre (or rest point) at t = 0
    end_m: np.ndarray  # (3,) centre (or rest point) at t = T
    duration_s: float
    bulge_m: np.ndarray  # (3,) peak sideways / lift offset
    prev: "_Stroke | None" = None
    next: "_Stroke | None" = None
    fade: float = 0.4
    stain: int = -1
    profile: str = "smooth"  # "retract": off the board as a person does; "approach": back onto it

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        T = self.duration_s
        s = np.clip(t / T, 0.0, 1.0)[:, None]
        if self.profile == "smooth":
            p = self.start_m + _smoothstep(s) * (self.end_m - self.start_m)
        else:  # height with a real retract's (approach's) profile; along the board mostly while up
            rising = self.profile == "retract"
            h = _retract(s) if rising else 1.0 - _retract(1.0 - s)
            along = _smoothstep(np.clip((s - LIFT_FIRST) / (1 - LIFT_FIRST), 0, 1) if rising
                                else np.clip(s / (1 - LIFT_FIRST), 0, 1))
            d = self.end_m - self.start_m
            p = self.start_m + along * np.array([d[0], d[1], 0.0]) + h * np.array([0.0, 0.0, d[2]])
        p = p + 64.0 * s**3 * (1 - s) ** 3 * self.bulge_m
        if self.prev is not None:
            w = 1.0 - _smoothstep(np.clip(s / self.fade, 0.0, 1.0))
            p = p + w * self.prev.offset(self.prev.duration_s + t)
        if self.next is not None:
            w = _smoothstep(np.clip((s - 1.0 + self.fade) / self.fade, 0.0, 1.0))
            p = p + w * self.next.offset(t - T)
        return p


def _smoothstep(s: np.ndarray) -> np.ndarray:
    """Quintic smoothstep: 0 -> 1 with zero first and second derivatives at both ends."""
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def _smoothstep3(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The smoothstep of ``u`` clipped to [0, 1] with its first and second derivatives in ``u``."""
    s = np.clip(u, 0.0, 1.0)
    inside = (u > 0.0) & (u < 1.0)
    return (10 * s**3 - 15 * s**4 + 6 * s**5, np.where(inside, 30 * s**2 * (1 - s) ** 2, 0.0),
            np.where(inside, 60 * s * (1 - s) * (1 - 2 * s), 0.0))


def _bump3(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``64 u^3 (1-u)^3`` on [0, 1] (peak 1 at the middle, flat to second order at the ends), 0 outside, with
    its first and second derivatives in ``u``."""
    s = np.clip(u, 0.0, 1.0)
    inside = (u > 0.0) & (u < 1.0)
    return (64 * s**3 * (1 - s) ** 3, np.where(inside, 192 * s**2 * (1 - s) ** 2 * (1 - 2 * s), 0.0),
            np.where(inside, 192 * s * (1 - s) * (2 - 10 * s + 10 * s**2), 0.0))


def _retract(s: np.ndarray) -> np.ndarray:
    """0 -> 1 with a beta(3, 6) velocity profile (peak at 2/7 of the move, flat to second order at both ends):
    a real retract's height, fast off the board, slow at the top (the recordings rise half way in a third of
    the time to the top)."""
    return s**3 * (56 - 210 * s + 336 * s**2 - 280 * s**3 + 120 * s**4 - 21 * s**5)


@dataclass
class _Rest:
    position_m: np.ndarray
    duration_s: float
    stain: int = -1

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        return np.tile(self.position_m, (len(t), 1))


@dataclass
class _HumanPlan:
    """What a person does in one take beyond wiping (see the module docstring), drawn from its own stream.

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
    def draw(cls, order: list[int], rng: np.random.Generator) -> "_HumanPlan":
        r = int(rng.integers(0, len(order)))
        order = order[: r + 1] + [order[r]] + order[r + 1:]  # the spot again, after a lift-off
        lift = [bool(rng.random() < LIFT_SHARE) or i == r for i in range(len(order) - 1)]
        angle = rng.uniform(0, 2 * np.pi)
        return cls(order, lift, int(rng.integers(0, len(lift))), float(rng.uniform(*PAUSE_S)),
                   int(rng.integers(0, len(order))),
                   rng.uniform(0.015, 0.03) * np.array([np.cos(angle), np.sin(angle)]),
                   float(rng.uniform(0.35, 0.5)), rng)


def _lift_off(run: "_Stroke", nxt: "_Stroke", pause_s: float, rng: np.random.Generator) -> list:
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
    pieces: list = [_Transition(a, top, t_up, np.zeros(3), run, None, min(0.4, 0.35 / t_up), profile="retract")]
    if pause_s > 0:
        pieces.append(_Rest(top, pause_s))
    pieces.append(_Transition(top, b, t_down, np.zeros(3), None, nxt, min(0.4, 0.35 / t_down), profile="approach"))
    return pieces


def _pause_on_board(run: "_Stroke", nxt: "_Stroke", pause_s: float, rng: np.random.Generator) -> list:
    """Out of ``run`` to rest on the board beside it for ``pause_s``, then on into ``nxt``."""
    a, b = run.end_centre3, nxt.centre3
    side = rng.uniform(-1, 1, 2)
    stop = np.array([*(a[:2] + 0.03 * side / max(np.linalg.norm(side), 1e-9)), 0.0])
    t_out = float(rng.uniform(0.6, 0.9))
    t_on = max(0.8, float(np.linalg.norm(b - stop)) / rng.uniform(0.25, 0.4))
    return [_Transition(a, stop, t_out, np.zeros(3), run, None, min(0.4, 0.35 / t_out)), _Rest(stop, pause_s),
            _Transition(stop, b, t_on, np.zeros(3), None, nxt, min(0.4, 0.35 / t_on))]


def _build_pieces(strokes: list[StrokeSpec], rng: np.random.Generator, plan: _HumanPlan | None = None) -> list:
    zero = np.zeros(3)
    runs = [
        _Stroke(
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
    pieces: list = [_Rest(home, float(rng.uniform(0.2, 0.4)))]
    duration = float(rng.uniform(1.0, 1.6))
    pieces.append(_Transition(home, runs[0].centre3, duration, zero.copy(), None, runs[0], 0.35 / duration))
    for k, run in enumerate(runs):
        pieces.append(run)
        if plan is not None and k + 1 < len(runs) and (plan.lift[k] or plan.pause_at == k):
            pause = plan.pause_s if plan.pause_at == k else 0.0
            build = _lift_off if plan.lift[k] else _pause_on_board
            pieces.extend(build(run, runs[k + 1], pause, plan.rng))
        elif k + 1 < len(runs):
            nxt = runs[k + 1]
            delta = nxt.centre3 - run.end_centre3
            dist = float(np.linalg.norm(delta))
            duration = max(0.8, dist / rng.uniform(0.25, 0.4))
            side = np.cross([0.0, 0.0, 1.0], delta) / max(dist, 1e-9)
            bulge = side * rng.uniform(-0.2, 0.2) * dist + np.array([0, 0, rng.uniform(0.0, 0.01)])
            fade = min(0.4, 0.35 / duration)
            pieces.append(_Transition(run.end_centre3, nxt.centre3, duration, bulge, run, nxt, fade))
        else:
            away = np.array([*run.spec.centre_m + rng.uniform(-0.1, 0.1, 2), rng.uniform(0.08, 0.15)])
            duration = float(rng.uniform(1.0, 1.6))
            pieces.append(_Transition(run.end_centre3, away, duration, zero.copy(), run, None, 0.35 / duration))
            pieces.append(_Rest(away, float(rng.uniform(0.2, 0.4))))
    return pieces
