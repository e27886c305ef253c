"""Which board points the arm hides from a camera, with the pad at a given pose (pure maths, vectorised).

The arm is drawn as four capsules along its centre line: the base column
(mounting plane to shoulder), the upper arm (shoulder to elbow), the
forearm (elbow to wrist) and the wrist with its tool (wrist to pad). The
shoulder, the wrist and the pad follow from the pad pose alone
(:class:`~arm.reach.ArmReach`); the elbow swings on a circle about the
shoulder-wrist line (the arm's self-motion) and is taken at the circle's
point furthest along A1's axis, elbow up, where the controller's posture
task holds it (on a recorded survey pose it was 8 cm from the elbow the arm
took; the wrist, which hides the most, is exact).

A board point is hidden when the ray from the camera to it passes within a
capsule's radius of the capsule's axis before it reaches the board. The
executor's look points, where the pad waits so the camera sees the stains,
are chosen by it (:func:`controller.look_points.look_point`).
"""

from __future__ import annotations

import numpy as np

from .reach import ArmReach

#: Radii [m] of the capsules: base column, upper arm, forearm, wrist and tool (the iiwa 14's links are 0.12-0.16
#: m across; a margin for the elbow's guessed swing and the pose error).
CAPSULE_RADII_M = (0.09, 0.08, 0.08, 0.07)


def arm_centre_lines(arm: ArmReach, p_m: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The arm's centre lines with the pad at each of ``p_m`` (m, 3) [m, world], turned ``R`` (3, 3): ``(lines
    (m, 5, 3), elbow (m,))``, each line the base under the shoulder, the shoulder, the elbow (up: module
    docstring), the wrist centre and the pad; ``elbow`` the elbow angle |q4| [rad] (inf beyond the stretched
    arm, where the line is nan)."""
    p = np.atleast_2d(np.asarray(p_m, float))
    wrist = p + R @ arm.wrist_in_pad_m
    sw = wrist - arm.shoulder_m
    d = np.linalg.norm(sw, axis=1)
    a, b = arm.upper_m, arm.fore_m
    reach = (d > 1e-9) & (d <= a + b)
    d_ok = np.where(reach, d, 1.0)
    u = sw / d_ok[:, None]
    along = (a * a - b * b + d_ok * d_ok) / (2.0 * d_ok)
    radius = np.sqrt(np.maximum(a * a - along * along, 0.0))
    up = arm.axis1 - (u @ arm.axis1)[:, None] * u
    n = np.linalg.norm(up, axis=1)
    up = np.where(n[:, None] > 1e-9, up / np.maximum(n, 1e-9)[:, None], np.array([1.0, 0.0, 0.0]))
    elbow = arm.shoulder_m + along[:, None] * u + radius[:, None] * up
    base = arm.shoulder_m - float(arm.shoulder_m @ arm.axis1) * arm.axis1
    lines = np.stack([np.broadcast_to(base, p.shape), np.broadcast_to(arm.shoulder_m, p.shape), elbow, wrist, p],
                     axis=1)
    lines[~reach] = np.nan
    cos_q4 = (d * d - a * a - b * b) / (2.0 * a * b)
    return lines, np.where(reach, np.arccos(np.clip(cos_q4, -1.0, 1.0)), np.inf)


def hidden(points_m: np.ndarray, camera_m: np.ndarray, lines_m: np.ndarray,
           radii_m: tuple[float, ...] = CAPSULE_RADII_M) -> np.ndarray:
    """(..., n) bool: which of the world points ``points_m`` (n, 3) [m] the capsules along each centre line of
    ``lines_m`` (..., k + 1, 3) (``radii_m``: k radii [m]) hide from a camera at ``camera_m`` (3,).

    A point is hidden when its sight line from the camera passes within a capsule's radius of the capsule's
    axis between the camera and the point (the closest approach of two segments, each clamped to its ends).
    """
    lines = np.asarray(lines_m, float)
    ray = np.asarray(points_m, float) - camera_m  # (n, 3) camera -> point
    rr = np.einsum("ij,ij->i", ray, ray)  # (n,)
    out = np.zeros((*lines.shape[:-2], len(ray)), bool)
    for k, radius in enumerate(radii_m):
        a = lines[..., k, :]  # (..., 3)
        seg = lines[..., k + 1, :] - a
        ss = np.einsum("...j,...j->...", seg, seg)[..., None]  # (..., 1)
        w0 = camera_m - a
        sw = np.einsum("...j,...j->...", seg, w0)[..., None]
        rs = seg @ ray.T  # (..., n)
        rw = w0 @ ray.T
        den = rr * ss - rs * rs
        ok = den > 1e-12
        # the closest parameters: t along the sight line (0 the camera, 1 the point), s along the capsule's axis
        s = np.clip(np.where(ok, (rr * sw - rs * rw) / np.where(ok, den, 1.0), 0.0), 0.0, 1.0)
        t = np.clip((s * rs - rw) / rr, 0.0, 1.0)
        s = np.clip((t * rs + sw) / np.maximum(ss, 1e-12), 0.0, 1.0)
        # |camera + t ray - a - s seg|^2, expanded in the dot products above
        gap2 = (np.einsum("...j,...j->...", w0, w0)[..., None] + t * t * rr + s * s * ss
                + 2.0 * t * rw - 2.0 * s * sw - 2.0 * t * s * rs)
        out |= gap2 < radius * radius
    return out
