"""The pieces a synthetic demonstration (:mod:`lampskit.learn.synth`) is built from: each maps local time (K,)
[s] to board-frame positions (K, 3) [m], C2 in time. A stain's periodic stroke (:class:`StrokeSpec`, with its
slow frequency and amplitude drift and an optional grip shift), a transition between strokes (a minimum-jerk move
of the centre into which the strokes fade out and in, or a real retract's or approach's height profile) and a
rest, with the smooth step and bump curves they use. Pure maths: no random draws (the builder draws)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: How long a grip shift inside a wipe takes [s].
GRIP_SHIFT_S = 0.5
#: Share of a lift-off's retract spent going up before moving along the board (mirrored for the approach).
LIFT_FIRST = 0.3
#: Share of a short hop spent rising (and, mirrored, coming down); it moves across from half of it to the mirror.
HOP_RISE = 0.3


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
    drift_m : array, shape (2,)
        A slow drift of the stroke centre over the whole wipe [m] (a smoothstep from start to end; zeros: none).
    """

    centre_m: np.ndarray
    kind: str
    freq_hz: float
    amplitude_m: float
    angle_rad: float
    n_cycles: float
    shift_m: np.ndarray = field(default_factory=lambda: np.zeros(2))
    shift_at: float = 0.5
    drift_m: np.ndarray = field(default_factory=lambda: np.zeros(2))


@dataclass
class Stroke:
    """One stroke of a synthetic demonstration as drawn: its spec, the stain it wipes and the random draws that
    vary it (frequency and amplitude modulation, phases); :meth:`evaluate` is the pad position (K, 3) [m] in the
    board frame at times ``t`` (K,) [s]."""

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
        if np.any(self.spec.drift_m):
            for k, w in enumerate(self._drift(t)):
                out[k][:, :2] += w[:, None] * self.spec.drift_m
        return out[0], out[1], out[2]

    def _drift(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The share of the centre's drift done (K,) with its two time derivatives: a smoothstep over the wipe."""
        d = self.duration_s
        g, dg, ddg = _smoothstep3(t / d)
        return g, dg / d, ddg / d**2

    @property
    def centre3(self) -> np.ndarray:
        """The stroke centre where the wipe starts (3,) [m]."""
        return np.array([*self.spec.centre_m, 0.0])

    @property
    def end_centre3(self) -> np.ndarray:
        """The stroke centre where the wipe ends (after any grip shift and drift) (3,) [m]."""
        return np.array([*(self.spec.centre_m + self.spec.shift_m + self.spec.drift_m), 0.0])

    def offset(self, t: np.ndarray) -> np.ndarray:
        """The stroke's offset from its (moving) centre (K, 3) [m], for fading it in and out of transitions."""
        p = self.evaluate(t)
        if np.any(self.spec.shift_m):
            p[:, :2] -= self._shift(np.asarray(t, float))[0][:, None] * self.spec.shift_m
        if np.any(self.spec.drift_m):
            p[:, :2] -= self._drift(np.asarray(t, float))[0][:, None] * self.spec.drift_m
        return p - self.centre3

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        return self.state(np.asarray(t, dtype=float))[0]


@dataclass
class Transition:
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
    prev: Stroke | None = None
    next: Stroke | None = None
    fade: float = 0.4
    stain: int = -1
    profile: str = "smooth"  # "retract": off the board as a person does; "approach": back onto it; "hop": see below

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        T = self.duration_s
        s = np.clip(t / T, 0.0, 1.0)[:, None]
        if self.profile == "smooth":
            p = self.start_m + _smoothstep(s) * (self.end_m - self.start_m)
        elif self.profile == "hop":  # up to bulge_m[2], across while up, down; flat top, C2 everywhere
            up = _smoothstep(np.clip(s / HOP_RISE, 0, 1)) * _smoothstep(np.clip((1 - s) / HOP_RISE, 0, 1))
            along = _smoothstep(np.clip((s - HOP_RISE / 2) / (1 - HOP_RISE), 0, 1))
            d = self.end_m - self.start_m
            return self._faded(self.start_m + along * d + up * np.array([0.0, 0.0, self.bulge_m[2]]), s, t)
        else:  # height with a real retract's (approach's) profile; along the board mostly while up
            rising = self.profile == "retract"
            h = _retract(s) if rising else 1.0 - _retract(1.0 - s)
            along = _smoothstep(np.clip((s - LIFT_FIRST) / (1 - LIFT_FIRST), 0, 1) if rising
                                else np.clip(s / (1 - LIFT_FIRST), 0, 1))
            d = self.end_m - self.start_m
            p = self.start_m + along * np.array([d[0], d[1], 0.0]) + h * np.array([0.0, 0.0, d[2]])
        return self._faded(p + 64.0 * s**3 * (1 - s) ** 3 * self.bulge_m, s, t)

    def _faded(self, p: np.ndarray, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """``p`` (K, 3) plus the previous stroke fading out and the next fading in."""
        T = self.duration_s
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
class Rest:
    """The pad held still at ``position_m`` (3,) [m] for ``duration_s`` [s] (on stain ``stain``, or -1 off any)."""

    position_m: np.ndarray
    duration_s: float
    stain: int = -1

    def evaluate(self, t: np.ndarray) -> np.ndarray:
        return np.tile(self.position_m, (len(t), 1))
