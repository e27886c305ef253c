"""Messy synthetic takes: what a person's real wiping looks like to a segmenter, with the truth it must find.

:mod:`lampskit.learn.synth` draws clean strokes; a person's are not. :func:`messy_take` builds one take of
``len(phases)`` wiping phases on a tilted board, each a :class:`PhaseSpec`:

* strokes (zig-zag or circle) whose **period, amplitude and centre wander** from stroke to stroke (a random
  walk of the period by ``period_jitter``, of the amplitude by ``amp_jitter``, a centre **drift** over the whole
  phase, as when the stain shrinks);
* **slow strokes** (a stroke at 2-3 times the period) and **pauses** (the pad stands still, pressed, for a few
  tenths of a second at a turning point) inside a phase: still one periodic MP;
* between phases a :class:`HopSpec`-like **hop** (``"hop"``): it leaves mid-stroke (wherever the last stroke
  is), rises ``lift_m`` along a normal **tilted** by ``tilt_rad``, crosses ``move_m`` and **lands inside the
  next patch** (on its first stroke, not at its centre), all in ``duration_s``; or a **lift-off** (``"lift"``,
  12-25 cm up and down, 2-3 s) or a **slide** along the board to a far spot (``"slide"``);
* an approach from above at the start and a retract at the end;
* **sensor noise** (``noise_m``, Gaussian per axis) and **dropped samples** (``drop_share`` of them, single and
  in bursts of up to 5) at any rate (100-1000 Hz).

Truth: the wiping phases are periodic (pauses and slow strokes included), everything else transitional; the
count a segmenter must find is ``len(phases)``. Pure numpy, one ``numpy.random.Generator`` per take.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lampskit.learn.demo import Demonstration

#: Lift-off heights [m] and durations [s] of a ``"lift"`` transition; the speed of a ``"slide"`` [m/s].
LIFT_OFF_M, LIFT_OFF_S, SLIDE_SPEED_M_S = (0.12, 0.25), (2.0, 3.0), 0.2
#: Approach and retract: height [m] and duration [s].
APPROACH_M, APPROACH_S = 0.15, 1.5


@dataclass(frozen=True)
class PhaseSpec:
    """One wiping phase (board frame, metres, seconds).

    centre_m : (2,) centre of its first stroke; kind ``"zigzag"`` or ``"circle"``; period_s mean stroke period;
    amplitude_m half stroke length (zig-zag) or radius (circle); angle_rad the zig-zag's direction; n_strokes;
    drift_m (2,) how far the centre moves over the phase; period_jitter, amp_jitter the relative random walk per
    stroke; slow_strokes how many strokes take 2-3 periods; pauses how many still stretches of pause_s.
    """

    centre_m: tuple[float, float]
    kind: str = "zigzag"
    period_s: float = 1.0
    amplitude_m: float = 0.05
    angle_rad: float = 0.0
    n_strokes: int = 10
    drift_m: tuple[float, float] = (0.0, 0.0)
    period_jitter: float = 0.08
    amp_jitter: float = 0.08
    slow_strokes: int = 0
    pauses: int = 0
    pause_s: float = 0.5


@dataclass(frozen=True)
class Move:
    """The transition after a phase: ``kind`` ``"hop"``, ``"lift"`` or ``"slide"``; a hop's lift [m] along a
    normal tilted by ``tilt_rad`` and its ``duration_s`` (a lift-off's and a slide's are drawn / from the
    distance)."""

    kind: str = "hop"
    lift_m: float = 0.05
    duration_s: float = 1.5
    tilt_rad: float = 0.3


@dataclass(frozen=True)
class MessyTake:
    """demo (world frame); true_periodic (T,) bool; n_periodic the wiping phases; phases the sample spans
    ``(start, end)`` of each; T_board_to_world (4, 4)."""

    demo: Demonstration
    true_periodic: np.ndarray
    n_periodic: int
    phases: tuple[tuple[int, int], ...]
    T_board_to_world: np.ndarray


def _quintic(s: np.ndarray) -> np.ndarray:
    return s ** 3 * (10 - 15 * s + 6 * s ** 2)


def _hermite(p0, v0, p1, v1, tau: np.ndarray, dur: float) -> np.ndarray:
    """Cubic Hermite from (p0, v0) to (p1, v1) over ``dur`` [s] at ``tau`` in [0, 1], shape (K, 3)."""
    t = tau[:, None]
    h00, h10 = 2 * t ** 3 - 3 * t ** 2 + 1, t ** 3 - 2 * t ** 2 + t
    h01, h11 = -2 * t ** 3 + 3 * t ** 2, t ** 3 - t ** 2
    return h00 * p0 + h10 * dur * v0 + h01 * p1 + h11 * dur * v1


def _ease_out(u: np.ndarray) -> np.ndarray:
    """0 -> 1 on u in [0, 1], slope 1 at 0 and 0 at 1: a stroke slowing to a stop."""
    return u + u ** 2 - u ** 3


def _phase_curve(spec: PhaseSpec, dt: float, rng: np.random.Generator) -> np.ndarray:
    """Board positions (K, 3) of one wiping phase sampled every ``dt`` [s]."""
    n = spec.n_strokes
    periods = spec.period_s * np.exp(np.cumsum(rng.normal(0, spec.period_jitter, n)) * 0.5)
    periods = np.clip(periods, 0.6 * spec.period_s, 1.6 * spec.period_s)
    inner = np.arange(1, max(n - 1, 2))
    for i in rng.choice(inner, size=min(spec.slow_strokes, max(n - 2, 0)), replace=False):
        periods[i] *= rng.uniform(2.0, 3.0)
    amps = spec.amplitude_m * np.clip(np.exp(np.cumsum(rng.normal(0, spec.amp_jitter, n)) * 0.5), 0.7, 1.4)
    # the stroke phase [cycles] runs through stroke i in periods[i]
    knots_t = np.r_[0.0, np.cumsum(periods)]
    t = np.arange(0.0, knots_t[-1], dt)
    phi = np.interp(t, knots_t, np.arange(n + 1.0))
    # a pause: the stroke slows to a stop at a turning point (phase k + 1/4), rests, and speeds up again
    for k in sorted(rng.choice(inner, size=min(spec.pauses, max(n - 2, 0)), replace=False).tolist(), reverse=True):
        p_stop, q = k + 0.25, 0.25 * periods[k]
        j0, j1 = np.searchsorted(phi, [p_stop - 0.25, p_stop + 0.25])
        u = np.arange(0.0, q, dt) / q
        middle = np.concatenate([p_stop - 0.25 + 0.25 * _ease_out(u), np.full(int(spec.pause_s / dt), p_stop),
                                 p_stop + 0.25 * (1 - _ease_out(1 - u))])
        phi = np.concatenate([phi[:j0], middle, phi[j1:]])
    t = np.arange(len(phi)) * dt
    amp = np.interp(phi, np.arange(n) + 0.5, amps)
    share = t / max(t[-1], dt)
    centre = np.asarray(spec.centre_m) + np.asarray(spec.drift_m) * _quintic(share)[:, None]
    sway_s, sway_phase = rng.uniform(5.0, 10.0), rng.uniform(0, 2 * np.pi, 2)
    centre = centre + 0.004 * np.sin(2 * np.pi * t[:, None] / sway_s + sway_phase)  # a hand's slow sway [m]
    w = 2 * np.pi * phi
    if spec.kind == "circle":
        rel = amp[:, None] * np.column_stack([np.cos(w + spec.angle_rad) - np.cos(spec.angle_rad),
                                              np.sin(w + spec.angle_rad) - np.sin(spec.angle_rad)])
    elif spec.kind == "zigzag":
        d = np.array([np.cos(spec.angle_rad), np.sin(spec.angle_rad)])
        perp = np.array([-d[1], d[0]])
        rel = amp[:, None] * (np.sin(w)[:, None] * d + 0.08 * np.sin(2 * w)[:, None] * perp)
    else:
        raise ValueError(f"stroke kind must be 'zigzag' or 'circle', got {spec.kind!r}")
    press = 0.0008 * np.sin(2 * w + 1.0)  # the pad's give under a varying press [m]
    return np.column_stack([centre + rel, press])


def _velocity(p: np.ndarray, dt: float, end: bool) -> np.ndarray:
    return (p[-1] - p[-2]) / dt if end else (p[1] - p[0]) / dt


def _transition(a: np.ndarray, b: np.ndarray, move: Move, dt: float, rng: np.random.Generator) -> np.ndarray:
    """Board positions (K, 3) from the end of one phase ``a`` (K_a, 3) to the start of the next ``b``."""
    p0, p1 = a[-1], b[0]
    v0, v1 = _velocity(a, dt, True), _velocity(b, dt, False)
    dist = float(np.linalg.norm(p1[:2] - p0[:2]))
    if move.kind == "hop":
        dur, lift = move.duration_s, move.lift_m
    elif move.kind == "lift":
        dur, lift = float(rng.uniform(*LIFT_OFF_S)), float(rng.uniform(*LIFT_OFF_M))
    elif move.kind == "slide":
        dur, lift = max(1.0, dist / SLIDE_SPEED_M_S), 0.0
    else:
        raise ValueError(f"move kind must be 'hop', 'lift' or 'slide', got {move.kind!r}")
    tau = np.arange(1, int(round(dur / dt))) * dt / dur
    base = _hermite(p0, v0, p1, v1, tau, dur)
    az = rng.uniform(0, 2 * np.pi)
    normal = np.array([np.sin(move.tilt_rad) * np.cos(az), np.sin(move.tilt_rad) * np.sin(az), np.cos(move.tilt_rad)])
    rise = 0.3
    bump = np.where(tau < rise, _quintic(np.clip(tau / rise, 0, 1)),
                    np.where(tau > 1 - rise, _quintic(np.clip((1 - tau) / rise, 0, 1)), 1.0))
    return base + lift * bump[:, None] * normal


def _vertical(p: np.ndarray, height: float, dur: float, dt: float, down: bool) -> np.ndarray:
    tau = np.arange(1, int(round(dur / dt))) * dt / dur
    z = height * (1 - _quintic(tau)) if down else height * _quintic(tau)
    out = np.repeat(p[None], len(tau), axis=0)
    out[:, 2] = p[2] + z
    return out


def messy_take(phases: list[PhaseSpec], moves: list[Move], seed: int, *, rate_hz: float = 100.0,
               noise_m: float = 3e-4, drop_share: float = 0.02) -> MessyTake:
    """One messy take (module docstring): ``phases`` joined by ``moves`` (one fewer), sampled at ``rate_hz``
    [Hz] with sensor noise ``noise_m`` [m] and ``drop_share`` of the samples dropped."""
    if len(moves) != len(phases) - 1:
        raise ValueError(f"{len(phases)} phases need {len(phases) - 1} moves, got {len(moves)}")
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    curves = [_phase_curve(p, dt, rng) for p in phases]
    parts, periodic = [_vertical(curves[0][0], APPROACH_M, APPROACH_S, dt, down=True)], [False]
    for i, c in enumerate(curves):
        parts.append(c)
        periodic.append(True)
        if i < len(moves):
            parts.append(_transition(c, curves[i + 1], moves[i], dt, rng))
            periodic.append(False)
    parts.append(_vertical(curves[-1][-1], APPROACH_M, APPROACH_S, dt, down=False))
    periodic.append(False)
    board = np.vstack(parts)
    truth = np.concatenate([np.full(len(p), f) for p, f in zip(parts, periodic)])
    keep = np.ones(len(board), dtype=bool)
    n_drop = int(drop_share * len(board))
    starts = rng.choice(np.arange(1, len(board) - 6), size=max(n_drop // 2, 0), replace=False)
    for s in starts:
        keep[s:s + int(rng.integers(1, 6))] = False
    keep[[0, -1]] = True
    t = np.arange(len(board)) * dt
    R = _tilted_board(rng)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, np.array([0.55, 0.0, 0.35])
    world = board @ R.T + T[:3, 3] + rng.normal(0, noise_m, board.shape)
    idx = np.flatnonzero(keep)
    truth_kept = truth[idx]
    edges = np.flatnonzero(np.diff(np.r_[0, truth_kept.astype(int), 0]))
    spans = tuple(zip(edges[::2].tolist(), edges[1::2].tolist()))
    demo = Demonstration(t[idx], world[idx], None, f"messy-take(seed={seed}, {rate_hz:g} Hz)")
    return MessyTake(demo, truth_kept, len(phases), spans, T)


def _tilted_board(rng: np.random.Generator) -> np.ndarray:
    """A board rotation (3, 3): tilted 0-90 deg about x (a table to a wall), turned about z."""
    a, b = float(rng.uniform(0, np.pi / 2)), float(rng.uniform(-np.pi, np.pi))
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    rz = np.array([[cb, -sb, 0], [sb, cb, 0], [0, 0, 1]])
    return rx @ rz


#: Rates a random take is sampled at [Hz].
RATES_HZ = (100.0, 200.0, 500.0, 1000.0)
#: Hops of a random take: lift [m], move [pad lengths], duration [s].
HOP_LIFT_M, HOP_MOVE_PADS, HOP_S = (0.02, 0.08), (0.5, 2.0), (1.0, 2.5)
#: A slide of a random take goes this far [m].
SLIDE_M = (0.18, 0.30)


def draw_messy_take(seed: int, n_phases: int | None = None, rate_hz: float | None = None) -> MessyTake:
    """A random messy take: 1-4 wiping phases (unless ``n_phases``) of 8-16 strokes, each wandering, drifting,
    with up to two slow strokes or pauses (at most one slow stroke), joined by hops (the most), lift-offs or slides,
    at one of :data:`RATES_HZ` (unless ``rate_hz``) with 0.1-0.5 mm noise and up to 3 % of the samples dropped."""
    from lampskit.learn.synth import PAD_LENGTH_M

    rng = np.random.default_rng([seed, 50])
    n = int(rng.integers(1, 5)) if n_phases is None else n_phases
    phases: list[PhaseSpec] = []
    moves: list[Move] = []
    centre = np.zeros(2)
    for i in range(n):
        amp = float(rng.uniform(0.03, 0.06))
        drift = rng.uniform(0, 0.05) * _unit(rng)
        slow = int(rng.integers(0, 2))
        phases.append(PhaseSpec((float(centre[0]), float(centre[1])), str(rng.choice(["zigzag", "circle"])),
                                float(rng.uniform(0.7, 1.5)), amp, float(rng.uniform(0, np.pi)),
                                int(rng.integers(8, 17)), (float(drift[0]), float(drift[1])),
                                slow_strokes=slow, pauses=int(rng.integers(0, 3 - slow)),
                                pause_s=float(rng.uniform(0.3, 0.8))))
        if i == n - 1:
            break
        kind = str(rng.choice(["hop", "hop", "lift", "slide"]))
        dist = (rng.uniform(*HOP_MOVE_PADS) * PAD_LENGTH_M if kind == "hop" else rng.uniform(*SLIDE_M))
        moves.append(Move(kind, float(rng.uniform(*HOP_LIFT_M)), float(rng.uniform(*HOP_S)),
                          float(rng.uniform(0, 0.5))))
        centre = centre + drift + dist * _unit(rng)
    rate = float(rng.choice(RATES_HZ)) if rate_hz is None else rate_hz
    return messy_take(phases, moves, seed, rate_hz=rate, noise_m=float(rng.uniform(1e-4, 5e-4)),
                      drop_share=float(rng.uniform(0, 0.03)))


def _unit(rng: np.random.Generator) -> np.ndarray:
    a = rng.uniform(0, 2 * np.pi)
    return np.array([np.cos(a), np.sin(a)])
