"""What ``lamps segment --plot`` writes so a person can check a segmentation: a PNG of the OPTICS reachability
plot, the tool speed and its height above the stroke surface, each coloured by segment, and an MCAP of the
take (Foxglove / Lichtblick load it) with the segments as a channel.

The stroke surface is the least-squares plane of every periodic segment's samples, its normal pointing to the
side most of the take lies on (approaches and retracts). Heights [m], speeds [m/s], times [s] from the first
sample.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from lampskit.atomic import write_atomic
from lampskit.learn.demo import Demonstration
from lampskit.learn.reachability import smooth_positions
from lampskit.learn.segmentation import Segmentation

#: MCAP topics: the tool's path sample by sample, and one message per segment at its start.
TAKE_TOPIC, SEGMENTS_TOPIC = "/take/tool", "/take/segments"

_TOOL_SCHEMA = {"type": "object", "title": "lamps.TakeSample", "properties": {
    "t_s": {"type": "number"}, "x_m": {"type": "number"}, "y_m": {"type": "number"}, "z_m": {"type": "number"},
    "speed_m_s": {"type": "number"}, "height_m": {"type": "number"}, "segment": {"type": "integer"},
    "periodic": {"type": "boolean"}}}
_SEGMENT_SCHEMA = {"type": "object", "title": "lamps.Segment", "properties": {
    "index": {"type": "integer"}, "kind": {"type": "string"}, "cluster": {"type": "integer"},
    "start": {"type": "integer"}, "end": {"type": "integer"}, "t0_s": {"type": "number"},
    "t1_s": {"type": "number"}, "margin": {"type": "number"}, "evidence": {"type": "string"}}}


def speed_and_height(demo: Demonstration, seg: Segmentation) -> tuple[np.ndarray, np.ndarray]:
    """Speed (T,) [m/s] and height above the stroke surface (T,) [m] of every sample (module docstring)."""
    smooth = smooth_positions(demo.position_m, demo.rate_hz)
    speed = np.linalg.norm(smooth_positions(smooth, demo.rate_hz, deriv=1), axis=1)
    per = seg.periodic_mask
    strokes = smooth[per] if per.sum() >= 3 else smooth
    centre = strokes.mean(axis=0)
    normal = np.linalg.svd(strokes - centre, full_matrices=False)[2][2]
    h = (smooth - centre) @ normal
    if float(np.mean(h)) < 0:
        h = -h
    return speed, h


def write_segment_png(demo: Demonstration, seg: Segmentation, path: Path) -> Path:
    """Three panels, coloured by segment (periodic by cluster, transitional grey), written atomically."""
    import matplotlib

    matplotlib.use("Agg")  # headless, as lampskit.figures draws (learn/ may not import figures/)
    import matplotlib.pyplot as plt

    t = demo.t_s - demo.t_s[0]
    speed, h = speed_and_height(demo, seg)
    colours = plt.get_cmap("tab10")
    fig, axes = plt.subplots(3, 1, figsize=(10, 8))
    reach = seg.reachability_plot
    if reach.size:
        labels = seg.ordering_labels
        x = np.arange(len(reach))
        finite = np.isfinite(reach)
        axes[0].bar(x[finite], reach[finite], width=1.0,
                    color=[colours(c % 10) if c >= 0 else "0.7" for c in labels[finite]])
        if seg.threshold is not None:
            axes[0].axhline(seg.threshold, color="k", lw=0.8, ls="--", label=f"threshold {seg.threshold:.3g} m")
            axes[0].legend(loc="upper right")
    axes[0].set(title=f"{demo.source}: OPTICS reachability plot", xlabel="points in OPTICS order",
                ylabel="reachability [m]")
    for ax, y, label in ((axes[1], speed, "speed [m/s]"), (axes[2], h, "height above the stroke surface [m]")):
        ax.plot(t, y, color="k", lw=0.6)
        for k, s in enumerate(seg.segments):
            colour = colours(s.cluster % 10) if s.kind == "periodic" else "0.85"
            ax.axvspan(t[s.start], t[min(s.end, len(t) - 1)], color=colour, alpha=0.35, lw=0)
            if ax is axes[1]:
                ax.text(t[s.start], 0.98, str(k), transform=ax.get_xaxis_transform(), va="top", fontsize=7)
        ax.set(xlabel="time [s]", ylabel=label)
    for cut in seg.cuts:
        if cut.get("margin") is not None:
            axes[2].text(cut["t_s"] - demo.t_s[0], 0.02, f"{cut['margin']:+.1f}", fontsize=6, rotation=90,
                         transform=axes[2].get_xaxis_transform())
    fig.tight_layout()
    png = io.BytesIO()
    fig.savefig(png, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return write_atomic(path, lambda f: f.write(png.getvalue()))


def write_segment_mcap(demo: Demonstration, seg: Segmentation, path: Path) -> Path:
    """The take on :data:`TAKE_TOPIC` (every sample) and the segments on :data:`SEGMENTS_TOPIC` (one message at
    each segment's start, with the margin of the cut that starts it), JSON with JSON Schemas, atomically."""
    from mcap.writer import Writer

    t = demo.t_s - demo.t_s[0]
    speed, h = speed_and_height(demo, seg)
    seg_of = np.empty(demo.n_samples, dtype=int)
    for k, s in enumerate(seg.segments):
        seg_of[s.start:s.end] = k
    margins = {c["sample"]: c for c in seg.cuts}
    buf = io.BytesIO()
    w = Writer(buf)
    w.start(profile="", library="lamps")
    tool = w.register_channel(TAKE_TOPIC, "json", w.register_schema(
        str(_TOOL_SCHEMA["title"]), "jsonschema", json.dumps(_TOOL_SCHEMA).encode()))
    segs = w.register_channel(SEGMENTS_TOPIC, "json", w.register_schema(
        str(_SEGMENT_SCHEMA["title"]), "jsonschema", json.dumps(_SEGMENT_SCHEMA).encode()))
    events = [(int(round(t[s.start] * 1e9)), 0, k) for k, s in enumerate(seg.segments)]
    events += [(int(round(t[i] * 1e9)), 1, i) for i in range(demo.n_samples)]
    for log_time, what, i in sorted(events):
        if what == 0:
            s = seg.segments[i]
            cut = margins.get(s.start, {})
            msg = {"index": i, "kind": s.kind, "cluster": s.cluster, "start": s.start, "end": s.end,
                   "t0_s": float(t[s.start]), "t1_s": float(t[s.end - 1]),
                   "margin": float(cut["margin"]) if cut.get("margin") is not None else 0.0,
                   "evidence": str(cut.get("evidence", "start"))}
            channel = segs
        else:
            p = demo.position_m[i]
            msg = {"t_s": float(t[i]), "x_m": float(p[0]), "y_m": float(p[1]), "z_m": float(p[2]),
                   "speed_m_s": float(speed[i]), "height_m": float(h[i]), "segment": int(seg_of[i]),
                   "periodic": bool(seg.labels[i] >= 0)}
            channel = tool
        w.add_message(channel, log_time=log_time, data=json.dumps(msg).encode(), publish_time=log_time)
    w.finish()
    return write_atomic(path, lambda f: f.write(buf.getvalue()))
