"""The report's PNG plots (matplotlib, Agg, imported lazily): the board before and after, the eraser path by MP kind,
and force, acceleration and phase over robot time."""

from __future__ import annotations

import base64
from pathlib import Path

import numpy as np

from controller.core import PHASE_CODES
from interfaces.keys import Keys
from interfaces.messages import Phase

from .report_maths import WIPING, dirt_removed


def _frames(rec: dict, keys: Keys) -> list[np.ndarray]:
    import cv2
    cam = keys.camera_frame("x")[:-len("x/frame")]
    topic = next((t for t in rec if t.startswith(cam) and t.endswith("/frame")), None)
    if topic is None:
        return []
    msgs = rec[topic]
    out = []
    for _, m in (msgs[0], msgs[-1]):
        img = cv2.imdecode(np.frombuffer(base64.b64decode(m["data"]), np.uint8), cv2.IMREAD_COLOR)
        if img is not None:
            out.append(img[..., ::-1])
    return out


def write_plots(run_dir: Path, rec: dict, keys: Keys, tr: np.ndarray, col: dict[str, int], truth: list[dict],
                stains_msgs: list[dict]) -> list[str]:
    """PNGs: board before/after, eraser path by MP kind, force/acceleration/phase over time. Returns their names."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lampskit.atomic import write_atomic

    written = []

    def save(fig, name: str) -> None:
        write_atomic(Path(run_dir) / name, lambda f: fig.savefig(f, format="png", dpi=100))
        plt.close(fig)
        written.append(name)

    frames = _frames(rec, keys)
    if len(frames) == 2:
        save(_board_before_after_figure(frames, truth), "board_before_after.png")
    if len(tr):
        save(_eraser_path_figure(tr, col, truth, stains_msgs), "eraser_path.png")
        save(_timeseries_figure(tr, col), "timeseries.png")
    if (Path(run_dir) / "learn" / "fig4_reachability.png").is_file():
        written.append("learn/fig4_reachability.png")
    return written


def _board_before_after_figure(frames: list[np.ndarray], truth: list[dict]):
    """The first and last camera image side by side, the dirt removed in the title."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.8))
    for a, img, title in zip(ax, frames, ("before", f"after ({dirt_removed(truth):.1%} of the dirt removed)")):
        a.imshow(img)
        a.set_title(title)
        a.axis("off")
    return fig


def _eraser_path_figure(tr: np.ndarray, col: dict[str, int], truth: list[dict], stains_msgs: list[dict]):
    """The pad on the board coloured by MP kind, with the true stains as circles and the board's outline."""
    import matplotlib.pyplot as plt

    phase = tr[:, col["phase"]]
    fig, ax = plt.subplots(figsize=(8, 6))
    kinds = (("periodic MP (WIPE)", PHASE_CODES[Phase.WIPE], "tab:blue"),
             ("transitional MP", PHASE_CODES[Phase.TRANSITION], "tab:orange"))
    free = ~np.isin(phase, WIPING)
    ax.plot(tr[free, col["x"]], tr[free, col["y"]], ",", color="0.6", label="free moves (approach, retreat)")
    for label, code, colour in kinds:
        sel = phase == code
        ax.plot(tr[sel, col["x"]], tr[sel, col["y"]], ".", ms=1, color=colour, label=label)
    if truth and truth[-1]["centres_board_m"]:
        for c, s in zip(truth[-1]["centres_board_m"], truth[-1]["sizes_m"]):
            ax.add_patch(plt.Circle(c, s / 2, fill=False, color="k", lw=1))
    if stains_msgs:
        w, h = stains_msgs[-1]["board_size_m"]
        ax.add_patch(plt.Rectangle((0, 0), w, h, fill=False, color="0.3", lw=1.5))
    ax.set_aspect("equal")
    ax.set_xlabel("board x [m]")
    ax.set_ylabel("board y [m]")
    ax.set_title("eraser path on the board (true stains as circles)")
    ax.legend(loc="upper right", fontsize=8, markerscale=8)
    return fig


def _timeseries_figure(tr: np.ndarray, col: dict[str, int]):
    """Measured force and commanded press, |reference acceleration| and the phase over robot time."""
    import matplotlib.pyplot as plt

    t = tr[:, 0]
    fig, ax = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    ax[0].plot(t, tr[:, col["force_n"]], lw=0.7, label="measured normal force")
    ax[0].plot(t, tr[:, col["press_n"]], lw=0.7, label="commanded press")
    ax[0].set_ylabel("force [N]")
    ax[0].legend(fontsize=8)
    ax[1].plot(t, np.linalg.norm(tr[:, [col["ref_ax"], col["ref_ay"]]], axis=1), lw=0.7)
    ax[1].set_ylabel("|reference accel.| [m/s^2]")
    ax[2].step(t, tr[:, col["phase"]], where="post", lw=0.8)
    ax[2].set_yticks(list(PHASE_CODES.values()), list(PHASE_CODES), fontsize=7)
    ax[2].set_xlabel("robot time [s]")
    return fig
