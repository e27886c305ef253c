"""The maths of turning a robot's recorded state into a pad path: joint order, time window, gaps, frame chains.

Pure numpy, no file I/O (:mod:`lampskit.learn.bags` reads the recordings and
calls these). Times are in seconds from the topic's first sample; poses are
a position ``p`` (T, 3) [m] and a rotation ``R`` (T, 3, 3) of a frame in its
parent. Every refusal is a :class:`~lampskit.errors.DemoError` whose one
line names what was found.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from lampskit.errors import DemoError

#: A gap between two samples longer than this many median sample periods is refused ...
GAP_PERIODS = 5
#: ... unless it is shorter than this [s] (at 100 Hz and slower, 5 periods are 50 ms or more anyway).
MIN_GAP_LIMIT_S = 0.05
#: Samples are thinned (every k-th kept) to at most this rate [Hz]: the learner is tuned for 100-200 Hz demos
#: and a 1 kHz robot state holds no more of a hand's motion.
MAX_RATE_HZ = 250.0


def joint_columns(names: Sequence[str], index_of: Callable[[str], int | None], n_joints: int,
                  expected: str) -> np.ndarray:
    """Column of each of the arm's joints in a message's ``names``: (n_joints,) indices, joint 1 first.

    ``index_of(name)`` is the joint's 0-based number along the arm, or None for a name that is not one of the
    arm's (another robot's, or a gripper's: those are ignored unless the arm's are missing). ``expected`` names
    the valid joint names for the message.
    """
    cols = np.full(n_joints, -1)
    for col, name in enumerate(names):
        k = index_of(name)
        if k is not None and 0 <= k < n_joints and cols[k] < 0:
            cols[k] = col
    if (cols < 0).any():
        shown = list(names[:10]) + (["..."] if len(names) > 10 else [])
        raise DemoError(f"joint names {shown} are not the arm's {n_joints} joints ({expected}): another robot?")
    return cols


def increasing(t_ns: np.ndarray) -> np.ndarray:
    """Indices that order the samples by time with repeated stamps dropped (the first kept): (K,) ints."""
    order = np.argsort(t_ns, kind="stable")
    ts = t_ns[order]
    keep = np.r_[True, np.diff(ts) > 0]
    return order[keep]


def in_window(t_s: np.ndarray, start_s: float | None, end_s: float | None) -> np.ndarray:
    """Mask (T,) of the samples with ``start_s <= t <= end_s`` (either bound optional); refused when empty."""
    lo = -np.inf if start_s is None else start_s
    hi = np.inf if end_s is None else end_s
    shown = f"{'start' if start_s is None else f'{start_s:g} s'}..{'end' if end_s is None else f'{end_s:g} s'}"
    if hi <= lo:
        raise DemoError(f"the time range {shown} is empty: the end must come after the start")
    mask = (t_s >= lo) & (t_s <= hi)
    if not mask.any():
        raise DemoError(f"no sample in the time range {shown}; the topic spans "
                        f"{t_s[0]:.3f}..{t_s[-1]:.3f} s from its first sample")
    return mask


def gap_limit_s(t_s: np.ndarray) -> float:
    """The longest step [s] accepted: :data:`GAP_PERIODS` median sample periods, at least :data:`MIN_GAP_LIMIT_S`."""
    if len(t_s) < 2:
        return MIN_GAP_LIMIT_S
    return max(GAP_PERIODS * float(np.median(np.diff(t_s))), MIN_GAP_LIMIT_S)


def check_gaps(t_s: np.ndarray, limit_s: float) -> None:
    """Refuse a step of ``t_s`` (T,) [s] longer than ``limit_s``, naming the first such gap and its time."""
    steps = np.diff(t_s)
    bad = np.flatnonzero(steps > limit_s)
    if bad.size:
        i = int(bad[0])
        raise DemoError(f"a gap of {steps[i]:.3f} s in the samples at t={t_s[i]:.3f} s (the limit is {limit_s:.3f} s, "
                        f"{GAP_PERIODS} sample periods or {MIN_GAP_LIMIT_S * 1000:.0f} ms; {bad.size} such gap(s)): "
                        "record again, or learn a part without it (--start/--end)")


def thin(t_s: np.ndarray, max_rate_hz: float = MAX_RATE_HZ) -> np.ndarray:
    """Indices keeping every k-th sample, k the smallest that brings the mean rate to ``max_rate_hz`` or below."""
    if len(t_s) < 2 or t_s[-1] <= t_s[0]:
        return np.arange(len(t_s))
    rate = (len(t_s) - 1) / (t_s[-1] - t_s[0])
    return np.arange(0, len(t_s), max(1, int(np.ceil(rate / max_rate_hz))))


def matrices_from_quat_xyzw(q: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotation matrices of ROS quaternions ``q`` (T, 4) = (x, y, z, w), normalised first."""
    q = np.asarray(q, float)
    n = np.linalg.norm(q, axis=1)
    if (n < 1e-9).any():
        raise DemoError(f"a zero quaternion at sample {int(np.argmax(n < 1e-9))}: not an orientation")
    x, y, z, w = (q / n[:, None]).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=1)


def pad_from_frame(p_m: np.ndarray, R: np.ndarray, offset_m: np.ndarray) -> np.ndarray:
    """Pad centre (T, 3) [m] from a frame's poses ``p_m`` (T, 3), ``R`` (T, 3, 3): ``p + R offset``.

    ``offset_m`` (3,) is the pad centre in that frame (the tool offset).
    """
    return p_m + R @ np.asarray(offset_m, float)


@dataclass(frozen=True)
class FrameLink:
    """One transform of a frame chain: the child's pose in its parent, static or over time.

    t_ns : (K,) stamps [ns] of a moving link, or None for a static one (K = 1).
    p_m : (K, 3) [m]; R : (K, 3, 3).
    """

    parent: str
    child: str
    t_ns: np.ndarray | None
    p_m: np.ndarray
    R: np.ndarray


def chain_to(frame: str, links: dict[str, FrameLink], base: str | None) -> list[FrameLink]:
    """The links from ``frame`` up to ``base`` (or to the root of its tree), child first.

    ``links`` maps a child frame to its link. Refused when ``frame`` is not in the tree, when ``base`` is not
    above it, or when the chain loops.
    """
    if frame not in links:
        found = sorted(links)[:12]
        raise DemoError(f"no transform to the frame {frame!r}; the transforms' child frames are {found}")
    chain: list[FrameLink] = []
    at = frame
    while at in links and at != base:
        link = links[at]
        if any(c.child == link.parent for c in chain) or link.parent == frame:
            raise DemoError(f"the transforms above {frame!r} loop back at {link.parent!r}")
        chain.append(link)
        at = link.parent
    if base is not None and at != base:
        path = " <- ".join([frame] + [c.parent for c in chain])
        raise DemoError(f"the base frame {base!r} is not above {frame!r}: its chain is {path}")
    return chain


def compose_chain(chain: list[FrameLink]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses of the chain's first child in its last parent, at the stamps of the chain's lowest moving link.

    Each other moving link contributes its newest transform at or before a stamp; stamps before every link
    has been seen once are dropped. Returns ``t_ns`` (T,), ``p_m`` (T, 3), ``R`` (T, 3, 3).
    """
    moving = [c for c in chain if c.t_ns is not None]
    if not moving:
        raise DemoError(f"the frame {chain[0].child!r} never moves: every transform above it is static")
    t_ns = moving[0].t_ns
    assert t_ns is not None  # (a moving link has stamps)
    idx = [None if c.t_ns is None else np.searchsorted(c.t_ns, t_ns, side="right") - 1 for c in chain]
    keep = np.all([i >= 0 for i in idx if i is not None], axis=0)
    t_ns = t_ns[keep]
    p = np.zeros((len(t_ns), 3))
    R = np.tile(np.eye(3), (len(t_ns), 1, 1))
    for c, i in zip(chain, idx):  # child first: T = T_link @ T
        k = np.zeros(len(t_ns), dtype=int) if i is None else i[keep]
        p = np.einsum("tij,tj->ti", c.R[k], p) + c.p_m[k]
        R = c.R[k] @ R
    return t_ns, p, R
