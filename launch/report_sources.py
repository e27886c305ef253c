"""Where a report's figures come from: the recording, whole or not, or the services' own last reports.

The recorder says what it did with every key (:data:`launch.record.STATUS_TOPIC`: received, recorded, dropped
and why, once a second and when it closes) and when it thinned or stopped one past its share of the disk budget
(``recorder/budget``, :mod:`launch.record_budget`). At its close it writes, whatever its budget, the services'
newest statuses and truth that the recording of their key had missed (:data:`launch.record.SELF_REPORTS_TOPIC`
names them): what the controller, the sim and perception last said of themselves. A report read from such a
recording is right about the end of the run (the phase, the dirt left, the counters) even when the recording
of a key stopped early, and says so:

* ``recording``: ``account`` (``final``: the recorder's account at its close; ``unfinished``: its last one
  before it died; null: the recording has none), ``over_budget``, ``incomplete`` (the keys, under the cell's
  prefix, the recorder did not record every accepted sample of: thinned, past their share, a full queue, past
  the whole budget; a sample the cell's receivers refuse too, oversized or undecodable, does not count) and
  ``self_reports`` (per key, how many of the services' own messages were written at the close). What it
  ``received``, ``recorded`` and ``dropped`` (by reason) of each key is in ``counters.recorder`` (counts
  follow the wall clock, as the services' counters do).
* ``sources``: per figure of the report, ``from`` (``recording``; ``self-reports``: the newest message it is
  read from is one of those written at the close), ``complete`` (every sample of its keys recorded; null
  without a final account) and ``missing`` (its incomplete keys, samples not recorded).
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from .record import RESUMED_TOPIC, SELF_REPORTS_TOPIC, STATUS_TOPIC
from .report_run import Run

#: Figures read from the newest message of their keys (the controller's phase: the newest before the cell began
#: stopping) -> those keys, under the prefix.
FINAL_FIGURES: dict[str, tuple[str, ...]] = {
    "outcome": ("controller/status", "sim/truth"), "final_phase": ("controller/status",),
    "dirt_removed_fraction": ("sim/truth",), "sim_time_s": ("sim/truth",), "stains": ("sim/truth", "perception/stains"),
    "loop_timing": ("controller/status",),
    "counters": ("controller/status", "sim/status", "robot/status", "perception/status"),
}
_TRACE = ("controller/trace",)
#: Figures computed from every recorded message of their keys -> those keys.
SERIES_FIGURES: dict[str, tuple[str, ...]] = {
    **{f: _TRACE for f in ("max_normal_force_n", "normal_force_mean_n", "normal_force_std_n", "time_above_cap_s",
                           "max_junction_accel_jump", "junction_step_ratio_max", "tracking_rms_m", "motion_peaks",
                           "phase_time_s", "skill_start_s", "job_end_s", "final_retreat_s")},
    "max_contact_force_n": ("sim/truth",), "peak_contact_force_n": ("sim/truth",),
    "max_joint_speed_ratio": ("robot/state",),
    "faults": ("controller/status", "sim/status", "robot/status", "perception/status"),
}
#: Reasons a sample was not recorded that leave the recording of its key incomplete (the rest, oversized and
#: undecodable, the cell's receivers refuse too).
LOST = ("thinned", "over_share", "queue_full", "over_budget")


def _lives(run: Run) -> list[dict]:
    """The last account of each recorder that wrote this recording (a restarted one carries its predecessor's
    recording over: :data:`~launch.record.RESUMED_TOPIC` marks where it began)."""
    starts = sorted(t for t, _ in run.rec.get(RESUMED_TOPIC, []))
    last: dict[int, dict] = {}
    for t, m in run.rec.get(STATUS_TOPIC, []):
        last[sum(1 for s in starts if s <= t)] = m
    return [last[k] for k in sorted(last)]


def recording_section(run: Run) -> tuple[dict[str, Any], dict[str, dict]]:
    """What the recorder did with the run's cell's keys, and its counts of each (see the module docstring)."""
    lives = _lives(run)
    prefix = run.keys.prefix + "/"
    keys: dict[str, dict] = {}
    for account in lives:
        for a in account.get("keys", []):
            if not a["key"].startswith(prefix):
                continue
            k = keys.setdefault(a["key"][len(prefix):], {"received": 0, "recorded": 0, "dropped": Counter()})
            k["received"] += a["received"]
            k["recorded"] += a["recorded"]
            k["dropped"].update(a["dropped"])
    copies = Counter(c["key"][len(prefix):] for _, m in run.rec.get(SELF_REPORTS_TOPIC, [])
                     for c in m["messages"] if c["key"].startswith(prefix))
    recording = {"account": None if not lives else "final" if lives[-1].get("final") else "unfinished",
                 "over_budget": any(a.get("over_budget") for a in lives),
                 "incomplete": sorted(k for k, v in keys.items() if any(v["dropped"][r] for r in LOST)),
                 "self_reports": dict(sorted(copies.items()))}
    return recording, {k: {**v, "dropped": dict(v["dropped"])} for k, v in sorted(keys.items())}


def sources_section(run: Run, recording: dict[str, Any], counts: dict[str, dict],
                    final_status_ns: int | None) -> dict[str, dict]:
    """Per figure: from the recording or from the services' own reports, and whether its keys are whole."""
    prefix = run.keys.prefix + "/"
    copies = {(c["key"], c["log_time_ns"]) for _, m in run.rec.get(SELF_REPORTS_TOPIC, []) for c in m["messages"]}

    def newest_is_a_copy(suffix: str) -> bool:
        msgs = run.rec.get(prefix + suffix, [])
        t = final_status_ns if suffix == "controller/status" and final_status_ns is not None else \
            (msgs[-1][0] if msgs else None)
        return (prefix + suffix, t) in copies

    out: dict[str, dict] = {}
    for figure, suffixes in {**FINAL_FIGURES, **SERIES_FIGURES}.items():
        missing = {s: sum(counts[s]["dropped"].get(r, 0) for r in LOST)
                   for s in suffixes if s in recording["incomplete"]}
        copied = figure in FINAL_FIGURES and any(newest_is_a_copy(s) for s in suffixes)
        entry: dict[str, Any] = {"from": "self-reports" if copied else "recording",
                                 "complete": None if recording["account"] != "final" else not missing}
        if missing:
            entry["missing"] = missing
        out[figure] = entry
    return out


def deaf_from(run: Run) -> dict[str, int]:
    """Topic -> the wall time [ns] from which the recorder recorded it only in part (thinned, or stopped past its
    share); every topic (``"*"``) from when the recording reached its whole budget. A service's status missing
    after then is the recorder's doing, not a silence of the service."""
    out: dict[str, int] = {}
    for t, m in run.rec.get("recorder/budget", []):
        key = m.get("key") or "*"
        out[key] = min(out.get(key, t), t)
    return out


def budget_faults(run: Run) -> list[dict[str, Any]]:
    """A ``RECORDER`` line for each key the recorder thinned or stopped, and for the whole budget reached."""
    prefix = run.keys.prefix + "/"
    return [{"wall_ns": t, "phase": "RECORDER", "reason": str(m.get("message", ""))[:500]}
            for t, m in run.rec.get("recorder/budget", []) if not m.get("key") or m["key"].startswith(prefix)]
