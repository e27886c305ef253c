"""The run a report is built from: a run folder's recording split by topic, and the launcher's ``run.json``."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from controller.params import ForceParams
from interfaces.keys import Keys

from .record import RECORDING, read_recording, trace_array


def topic_messages(rec: dict, key: str) -> list[dict]:
    """The recorded messages of topic ``key`` (JSON objects in log order, without their log times)."""
    return [m for _, m in rec.get(key, [])]


def cell_series(rec: dict) -> list[list[tuple[int, dict]]]:
    """The recorded messages of every topic but the recorder's own (``recorder/...``: its status once a second
    from its start, its notes): what the cell sent."""
    return [msgs for topic, msgs in rec.items() if not topic.startswith("recorder/")]


@dataclass(frozen=True)
class Run:
    """What a report is built from: a run folder's recording, split by topic, and the launcher's ``run.json``.

    rec : every recorded message by topic, [(log_time_ns, JSON object)]
    launcher : ``run.json`` ({} when the recorder ran without the launcher)
    truth, status : ``sim/truth`` and ``controller/status`` messages in order
    stains_msgs : ``perception/stains`` messages with a board in view
    tr : array, shape (n_ticks, n_columns), the controller trace; col : its column name -> index
    cap_n : force cap [N] for ``time_above_cap_s``; filter_s : the cap watch's filter time constant [s]
    """

    rec: dict
    launcher: dict
    keys: Keys
    cap_n: float
    filter_s: float
    truth: list[dict]
    status: list[dict]
    stains_msgs: list[dict]
    tr: np.ndarray
    col: dict[str, int]


def read_run(run_dir: Path, keys: Keys | None = None, cap_n: float | None = None) -> Run:
    """The recording of ``run_dir`` and its ``run.json``; ``keys`` and ``cap_n`` default to what the launcher ran."""
    rec = read_recording(run_dir / RECORDING)
    launcher = json.loads((run_dir / "run.json").read_text()) if (run_dir / "run.json").is_file() else {}
    keys = keys or Keys(launcher.get("key_prefix", Keys().prefix))
    cap_n = cap_n if cap_n is not None else launcher.get("force_cap_n", ForceParams().cap_n)
    cols, tr = trace_array(topic_messages(rec, keys.controller_trace))
    filter_s = float(launcher.get("force_filter_s", ForceParams().filter_s))
    return Run(rec=rec, launcher=launcher, keys=keys, cap_n=cap_n, filter_s=filter_s,
                truth=topic_messages(rec, keys.sim_truth), status=topic_messages(rec, keys.controller_status),
                stains_msgs=[m for m in topic_messages(rec, keys.perception_stains) if m.get("board") != "lost"],
                tr=tr, col={c: i for i, c in enumerate(cols)})
