"""From a demonstration to a skill: segment, fit the surface frame, learn every MP.

This is the offline pipeline behind ``lamps learn``; it only composes the
pure modules (segmentation, surface, periodic, transitional).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from lampskit.core.skill import PeriodicEntry, Skill, TransitionalEntry
from lampskit.core.surface import fit_surface_frame
from lampskit.errors import LearningError, SegmentationError
from lampskit.learn.demo import Demonstration
from lampskit.learn.periodic_fit import learn_periodic
from lampskit.learn.segmentation import Segmentation, segment
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


def learn_skill_from_demos(
    demos: list[Demonstration],
    *,
    method: str = "optics",
    progress: Callable[[str, int, int], None] | None = None,
) -> tuple[Skill, list[Segmentation]]:
    """One skill from several demonstrations of it (same board, same world frame, the same wiping phases in the
    same order): each is segmented; the surface frame is fitted to all their wiping samples; the k-th periodic
    and the k-th learned transitional MP of every demo are fused by GMM-GMR over all of them
    (:mod:`lampskit.learn.fusion`). The skill keeps the first demo's segmentation; its ``source`` lists every
    demo and, per MP, the spread between them (``source["spread"]``).

    Raises :class:`LearningError` naming the demos when they do not hold the same number of MPs.
    """
    from lampskit.learn.fusion import fuse_periodic, fuse_transitional

    if len(demos) == 1:
        skill, seg = learn_skill(demos[0], method=method, progress=progress)
        return skill, [seg]
    segs = []
    for i, demo in enumerate(demos):
        seg_progress = None if progress is None else (
            lambda done, total, i=i: progress(f"segmenting {i + 1}/{len(demos)}", done, total))
        segs.append(segment(demo, method=method, progress=seg_progress))
    per = [[s for s in seg.segments if s.kind == "periodic"] for seg in segs]
    trans = [[(k, s) for k, s in enumerate(seg.segments) if s.kind == "transitional"
              and demo.t_s[s.end - 1] - demo.t_s[s.start] >= MIN_TRANSITION_S] for demo, seg in zip(demos, segs)]
    for what, found in (("wiping phases (periodic MPs)", per), ("transitions of at least "
                                                                  f"{MIN_TRANSITION_S} s", trans)):
        counts = [len(f) for f in found]
        if len(set(counts)) != 1:
            listing = ", ".join(f"{d.source}: {n}" for d, n in zip(demos, counts))
            raise LearningError(f"the demonstrations do not hold the same number of {what} ({listing}): "
                                "demonstrations of one skill must show the same phases in the same order")
    plane = np.vstack([d.position_m[s.start:s.end] for d, p in zip(demos, per) for s in p])
    surface = fit_surface_frame(plane, np.vstack([d.position_m for d in demos]))
    in_plane = [surface.surface_from_world(d.position_m)[:, :2] for d in demos]
    total = len(per[0]) + len(trans[0])
    periodic: list[PeriodicEntry] = []
    transitional: list[TransitionalEntry] = []
    spread: dict[str, list] = {"periodic": [], "transitional": []}
    index = {s: k for k, s in enumerate(segs[0].segments)}
    for j in range(len(per[0])):
        if progress is not None:
            progress("fusing", j, total)
        parts = [(d.t_s[p[j].start:p[j].end], y[p[j].start:p[j].end]) for d, p, y in zip(demos, per, in_plane)]
        try:
            mp, sp = fuse_periodic(parts)
        except LearningError as exc:
            raise LearningError(f"wiping phase {j} of {len(per[0])}: {exc}") from None
        first = per[0][j]
        periodic.append(PeriodicEntry(index[first], int(first.cluster), mp.n_cycles, mp))
        spread["periodic"].append(sp)
    for j in range(len(trans[0])):
        if progress is not None:
            progress("fusing", len(per[0]) + j, total)
        parts = [(d.t_s[s.start:s.end], y[s.start:s.end]) for d, tr, y in zip(demos, trans, in_plane)
                 for _, s in [tr[j]]]
        try:
            t_mp, sp = fuse_transitional(parts)
        except LearningError as exc:
            log.warning("transition %d not learned: %s", j, exc)
            continue
        transitional.append(TransitionalEntry(trans[0][j][0], t_mp))
        spread["transitional"].append(sp)
    if progress is not None:
        progress("fusing", total, total)
    source = {
        "demo": " + ".join(d.source for d in demos),
        "n_samples": int(sum(d.n_samples for d in demos)),
        "rate_hz": round(float(np.mean([d.rate_hz for d in demos])), 6),
        "duration_s": round(float(sum(d.duration_s for d in demos)), 6),
        "demos": [{"demo": d.source, "n_samples": d.n_samples, "rate_hz": round(d.rate_hz, 6),
                   "duration_s": round(d.duration_s, 6)} for d in demos],
        "spread": spread,
    }
    skill = Skill(surface, tuple(periodic), tuple(transitional), segs[0].to_dict(summary=True), source)
    return skill, segs


def bundled_skill(n_stains: int = 3, seed: int = 0) -> Skill:
    """The skill learned from the bundled synthetic demonstration (what ``lamps demo`` and ``lamps up`` learn).

    ``n_stains`` wiped stains, ``seed`` of :func:`~lampskit.learn.synth.synthesize_demo`.
    """
    from lampskit.learn.synth import synthesize_demo

    skill, _ = learn_skill(synthesize_demo(n_stains, seed).demo)
    return skill
