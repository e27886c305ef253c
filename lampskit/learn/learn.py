"""From a demonstration to a skill: segment, fit the surface frame, learn every MP.

This is the offline pipeline behind ``lamps learn``; it only composes the
pure modules (segmentation, surface, periodic, transitional).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from lampskit.learn.demo import Demonstration
from lampskit.errors import LearningError, SegmentationError
from lampskit.learn.periodic_fit import learn_periodic
from lampskit.learn.segmentation import Segmentation, segment
from lampskit.core.skill import PeriodicEntry, Skill, TransitionalEntry
from lampskit.core.surface import fit_surface_frame
from lampskit.learn.transitional_fit import learn_transitional

log = logging.getLogger(__name__)

#: Transitional segments shorter than this [s] are not learned (too little shape to learn).
MIN_TRANSITION_S = 0.3


def learn_skill(
    demo: Demonstration,
    segmentation: Segmentation | None = None,
    *,
    method: str = "optics",
    progress: Callable[[str, int, int], None] | None = None,
) -> tuple[Skill, Segmentation]:
    """Segment ``demo`` (unless given) and learn every MP in the surface frame.

    Parameters
    ----------
    demo : Demonstration
        The recorded demonstration (world frame).
    segmentation : Segmentation, optional
        A precomputed segmentation of ``demo``.
    method : str
        Segmentation method when ``segmentation`` is not given.
    progress : callable, optional
        ``progress(stage, done, total)`` for a terminal progress line.

    Returns
    -------
    skill, segmentation
    """
    if segmentation is None:
        seg_progress = None if progress is None else (lambda done, total: progress("segmenting", done, total))
        segmentation = segment(demo, method=method, progress=seg_progress)
    periodic_segs = [(i, s) for i, s in enumerate(segmentation.segments) if s.kind == "periodic"]
    if not periodic_segs:
        raise SegmentationError(f"{demo.source}: the segmentation found no periodic part; nothing to learn")
    plane_idx = np.concatenate([np.arange(s.start, s.end) for _, s in periodic_segs])
    surface = fit_surface_frame(demo.position_m[plane_idx], demo.position_m)
    in_plane = surface.surface_from_world(demo.position_m)[:, :2]
    total = len(segmentation.segments)
    periodic: list[PeriodicEntry] = []
    transitional: list[TransitionalEntry] = []
    for k, s in enumerate(segmentation.segments):
        if progress is not None:
            progress("learning", k, total)
        t, y = demo.t_s[s.start : s.end], in_plane[s.start : s.end]
        if s.kind == "periodic":
            try:
                mp = learn_periodic(t, y)
            except LearningError as exc:
                raise LearningError(f"periodic segment {k} (samples {s.start}-{s.end}): {exc}") from None
            n_cycles = float((t[-1] - t[0]) * mp.omega_rad_s / (2 * np.pi))
            periodic.append(PeriodicEntry(k, int(s.cluster), n_cycles, mp))
        elif t[-1] - t[0] >= MIN_TRANSITION_S:
            try:
                transitional.append(TransitionalEntry(k, learn_transitional(t, y)))
            except LearningError as exc:
                log.warning("transitional segment %d (samples %d-%d) not learned: %s", k, s.start, s.end, exc)
    if progress is not None:
        progress("learning", total, total)
    source = {
        "demo": demo.source,
        "n_samples": demo.n_samples,
        "rate_hz": round(demo.rate_hz, 6),
        "duration_s": round(demo.duration_s, 6),
    }
    skill = Skill(surface, tuple(periodic), tuple(transitional), segmentation.to_dict(summary=True), source)
    return skill, segmentation


def bundled_skill(n_stains: int = 3, seed: int = 0) -> Skill:
    """The skill learned from the bundled synthetic demonstration (what ``lamps demo`` and ``lamps up`` learn).

    ``n_stains`` wiped stains, ``seed`` of :func:`~lampskit.learn.synth.synthesize_demo`.
    """
    from lampskit.learn.synth import synthesize_demo

    skill, _ = learn_skill(synthesize_demo(n_stains, seed).demo)
    return skill
