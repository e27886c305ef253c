"""A run's report and plots, rebuilt from its recording alone (``lamps report RUN_DIR``).

``report.json`` (schema ``lamps-run-report/1``; every quantity in SI units):

* ``outcome``: ``cleaned`` (controller DONE and >= 95 % of the dirt gone),
  ``incomplete``, ``fault`` (ended in FAULT or ESTOP; the phase is the
  controller's when the launcher began stopping the cell), or what the launcher
  recorded in ``run.json`` (``failed``: a service died; ``timeout``;
  ``stopped``: Ctrl-C) when that is worse.
* ``duration_s`` (wall), ``sim_time_s`` (robot clock), ``dirt_removed_fraction``
  (1 - final / first total dirt of ``sim/truth``).
* ``stains``: per true stain ``id``, ``centre_board_m``, ``size_m``,
  ``initial_remaining``, ``final_remaining``, ``truth_below_level_s`` and
  ``kappa_s`` (robot time; null if never), ``kappa_latency_s``, ``smeared``
  (perception's first report of it smeared: ``at_s`` robot time,
  ``remaining`` and ``passes``; null if never).
* ``max_normal_force_n``, ``normal_force_mean_n`` and ``normal_force_std_n``
  while wiping, ``time_above_cap_s`` (the measured force, low-passed as the
  controller's cap watch low-passes it (``ForceParams.filter_s``), above
  ``force_cap_n``: what would fault the controller; a single-tick spike of the
  measured wrench, e.g. around a robot-side brake, is not an overload).
* ``max_junction_accel_jump`` [m/s^2]: the largest change of the in-plane
  reference acceleration across one tick at an MP junction, and
  ``junction_step_ratio_max``: that change over the largest ordinary
  one-tick change in the 5 ticks around it (<= ~1: continuous); junctions
  with a tick the robot held nearby are left out (its scale follows the arm).
* ``tracking_rms_m``: in-plane reference vs measured pad while wiping.
* ``motion_peaks``: per phase (and ``all``), the peak speed [m/s],
  acceleration [m/s^2] and jerk [m/s^3] of the in-plane reference as
  executed (time-scaled), over every recorded tick of the whole run; jerk from
  consecutive ticks only (a gap, a restart or a skipped state is not one).
* ``phase_time_s``: robot time [s] spent in each controller phase (and
  ``all``), summed over consecutive recorded ticks: where a run's time goes
  (APPROACH holds the survey's flight and look); ``skill_start_s``: the
  robot time of the first TRANSITION or WIPE tick (the start of the skill,
  after waiting for the peers, the survey and the approach; null if never),
  exact even when the recording began late; ``job_end_s``: the robot time
  of the first tick of the DONE the run ended in (the skill's end: the
  launcher keeps the cell running ``SETTLE_S`` longer to see that it stays
  DONE; null if the run did not end DONE); ``final_retreat_s``: the RETREAT
  that led into that DONE, its first tick to the DONE (a re-pass's retreat
  and look before it are not counted; null without one).
* ``final_phase`` and ``final_reason``: the controller's phase and its reason in the status the outcome is judged
  on (a DONE that leaves stains without kappa names each and why: out of the arm's reach, smeared, given up).
* ``loop_timing``: the controller's last reported loop statistics.
* ``max_contact_force_n`` (the sim's truth: the physical contact force,
  whatever the controller measured, at each truth, 10 Hz),
  ``peak_contact_force_n`` (its peak over every physics step: impacts of a
  few ms that the 10 Hz samples miss) and ``max_joint_speed_ratio`` (the
  largest ``|dq| / dq_max`` of any joint in any recorded ``robot/state``):
  the cell's safety, across restarts of any service.
* ``faults``, in time order, each with a wall time, a phase and a reason: every entry into PAUSED, FAULT
  or ESTOP; every service that went silent (no status for ``SERVICE_SILENCE_S`` or four status periods:
  frozen, stopped or dead) or came back restarted (its status count starting again), phase ``SERVICE``;
  each safety action of the robot side (a brake on stale commands or after its own freeze, commands of
  another controller dropped, a change of the controller served, commands held while e-stopped:
  :data:`.report_faults.ROBOT_EVENTS`), phase ``ROBOT``; a recorder that stalled, restarted (carrying its predecessor's
  recording over), thinned or stopped a key past its share of the disk budget or did not finish (a recording
  recovered from its ``.partial`` file), phase ``RECORDER``; the launcher's end of the run when a service died, failed
  or the run timed out (phase ``CELL``, the reason ``lamps up`` gave).
* ``services``: exit codes from the launcher (if any); ``counters``: the
  last status counters of each service, and the recorder's of each key
  (received, recorded, dropped and why); ``recording`` and ``sources``: which
  keys the recorder thinned or stopped past their share of its disk budget and, per
  figure, whether it comes from the recording (whole or not) or from the
  services' own last statuses and truth, which the recorder writes at its
  close when the recording of their key had stopped
  (:mod:`.report_sources`); ``plots``: the PNG files written
  (none when :data:`~launch.report_options.PLOTS_ENV` is ``0``: a campaign's cells, ``lamps report``
  draws them later).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from interfaces.keys import Keys
from interfaces.messages import Phase
from lampskit.atomic import write_text_atomic

from .report_faults import (
    cell_faults,
    faults_section,
    recorder_faults,
    recorder_stalls,
    robot_events,
    service_faults,
)
from .report_maths import (
    WIPING,
    cap_watch_force,
    dirt_removed,
    final_retreat,
    job_end,
    junction_steps,
    motion_peaks,
    phase_times,
    skill_start,
)
from .report_options import plots_from_env
from .report_plots import write_plots
from .report_run import Run, cell_series, read_run, topic_messages
from .report_sources import recording_section, sources_section

SCHEMA = "lamps-run-report/1"
#: Fraction of the dirt that must be gone for the outcome ``cleaned``.
CLEANED_FRACTION = 0.95
#: A stain counts as wiped in the truth at or below this remaining fraction (perception's kappa level).
TRUTH_LEVEL = 0.03
_OUTCOME_RANK = {"cleaned": 0, "incomplete": 1, "timeout": 2, "stopped": 2, "fault": 3, "failed": 4}


def build_report(run_dir: Path, keys: Keys | None = None, cap_n: float | None = None,
                 plots: bool | None = None) -> dict[str, Any]:
    """The report of ``run_dir`` from its ``recording.mcap`` (and ``run.json`` from the launcher, if there);
    ``plots``: draw the PNG plots too (None: as :data:`~launch.report_options.PLOTS_ENV` says)."""
    run_dir = Path(run_dir)
    if plots is None:
        plots = plots_from_env()
    run = read_run(run_dir, keys, cap_n)
    report: dict[str, Any] = {"schema": SCHEMA, "run_dir": run_dir.name}
    report.update(_progress_section(run))
    report["stains"] = stains_section(run.truth, run.stains_msgs)
    report.update(_force_section(run.tr, run.col, run.truth, run.cap_n, run.filter_s))
    report["motion_peaks"] = motion_peaks(run.tr, run.col)
    report["phase_time_s"] = phase_times(run.tr, run.col)
    report["skill_start_s"] = skill_start(run.tr, run.col)
    report["job_end_s"] = job_end(run.tr, run.col)
    report["final_retreat_s"] = final_retreat(run.tr, run.col)
    report["force_cap_n"] = run.cap_n
    report["loop_timing"] = run.status[-1]["timing"] if run.status else {}
    report.update(_safety_section(run))
    recorder = recorder_faults(run, run_dir)
    faults = (faults_section(run.status) + service_faults(run, recorder_stalls(run)) + robot_events(run)
              + recorder + cell_faults(run.launcher))
    report["faults"] = sorted(faults, key=lambda f: f["wall_ns"])
    final_ns, final_status = _final_status(run)
    report["final_phase"] = final_status["phase"] if final_status else "none"
    report["final_reason"] = final_status.get("reason", "") if final_status else ""
    # what the controller estimated of the arm (its flange load, model error, a model_mismatch warning)
    report["arm_model"] = (final_status or {}).get("arm", {})
    report["outcome"] = _outcome(report["final_phase"], report["dirt_removed_fraction"], run.launcher.get("outcome"))
    report["services"] = run.launcher.get("services", {})
    report["recording"], recorder_counts = recording_section(run)
    report["counters"] = {**_counters_section(run), "recorder": recorder_counts}
    report["sources"] = sources_section(run, report["recording"], recorder_counts, final_ns)
    report["plots"] = write_plots(run_dir, run.rec, run.keys, run.tr, run.col, run.truth, run.stains_msgs) \
        if plots else []
    return report


def _progress_section(run: Run) -> dict[str, float]:
    """``duration_s`` (the launcher's, else the recording's span), ``sim_time_s`` and ``dirt_removed_fraction``."""
    times = [t for msgs in cell_series(run.rec) for t, _ in msgs[:1] + msgs[-1:]]
    truth, tr = run.truth, run.tr
    return {"duration_s": run.launcher.get("duration_s", (max(times) - min(times)) * 1e-9 if times else 0.0),
            "sim_time_s": truth[-1]["robot_time_ns"] * 1e-9 if truth else (float(tr[-1, 0]) if len(tr) else 0.0),
            "dirt_removed_fraction": float(dirt_removed(truth))}


def stains_section(truth: list[dict], stains_msgs: list[dict]) -> list[dict[str, Any]]:
    """Per true stain: where, how big, how much is left, and when the truth and perception saw it wiped."""
    if not truth:
        return []
    first, last = truth[0], truth[-1]
    centres = np.array(last["centres_board_m"]) if last["centres_board_m"] else np.zeros((0, 2))
    stains = []
    for k, sid in enumerate(last["stain_ids"]):
        below = next((t["robot_time_ns"] * 1e-9 for t in truth if t["remaining"][k] <= TRUTH_LEVEL), None)
        kappa = _first_kappa_s(stains_msgs, centres, k)
        smeared = _first_smear(stains_msgs, centres, k)
        stains.append({"id": sid, "centre_board_m": last["centres_board_m"][k] if len(centres) else None,
                       "size_m": last["sizes_m"][k] if last["sizes_m"] else None,
                       "initial_remaining": first["remaining"][k], "final_remaining": last["remaining"][k],
                       "truth_below_level_s": below, "kappa_s": kappa,
                       "kappa_latency_s": (kappa - below) if kappa is not None and below is not None else None,
                       "smeared": smeared})
    return stains


def _nearest(centres_board_m: np.ndarray, s: dict) -> int:
    """Index of the true stain nearest to perceived stain ``s`` (-1 without true stains)."""
    if not len(centres_board_m):
        return -1
    return int(np.argmin(np.linalg.norm(centres_board_m - np.array(s["centre_board_m"]), axis=1)))


def _first_kappa_s(stains_msgs: list[dict], centres_board_m: np.ndarray, k: int) -> float | None:
    """Robot time [s] of the first perceived stain with kappa whose nearest true stain is ``k`` (None if never).

    centres_board_m : array, shape (n_stains, 2), the true stain centres on the board
    """
    for m in stains_msgs:
        for s in m["stains"]:
            if s["kappa"] and _nearest(centres_board_m, s) == k:
                return m["robot_time_ns"] * 1e-9
    return None


def _first_smear(stains_msgs: list[dict], centres_board_m: np.ndarray, k: int) -> dict[str, float] | None:
    """Perception's first report of a smear on true stain ``k``: robot time [s], remaining fraction and passes
    (None if never; a recording from a perception without smears has no ``smeared`` field)."""
    for m in stains_msgs:
        for s in m["stains"]:
            if s.get("smeared") and _nearest(centres_board_m, s) == k:
                return {"at_s": m["robot_time_ns"] * 1e-9, "remaining": s["remaining"], "passes": s["passes"]}
    return None


def _force_section(tr: np.ndarray, col: dict[str, int], truth: list[dict], cap_n: float,
                   filter_s: float) -> dict[str, Any]:
    """Normal force while wiping, time above the cap, MP junction steps and tracking, from the controller trace.

    Without a trace only the peak contact force of the sim truth is known; the rest is 0.
    """
    if not len(tr):
        return {"max_normal_force_n": max((t["contact_force_n"] for t in truth), default=0.0),
                "normal_force_mean_n": 0.0, "normal_force_std_n": 0.0, "time_above_cap_s": 0.0,
                "max_junction_accel_jump": 0.0, "junction_step_ratio_max": 0.0, "tracking_rms_m": 0.0,
                "trace_ticks": 0}
    force = tr[:, col["force_n"]]
    wiping = np.isin(tr[:, col["phase"]], WIPING) & (tr[:, col["contact"]] > 0.5)
    dt = float(np.median(np.diff(tr[:, 0]))) if len(tr) > 1 else 0.0
    jump, ratio = junction_steps(tr, col)
    err = tr[wiping][:, [col["ref_x"], col["ref_y"]]] - tr[wiping][:, [col["x"], col["y"]]]
    return {"max_normal_force_n": float(force.max()),
            "normal_force_mean_n": float(force[wiping].mean()) if wiping.any() else 0.0,
            "normal_force_std_n": float(force[wiping].std()) if wiping.any() else 0.0,
            "time_above_cap_s": float(np.count_nonzero(cap_watch_force(tr[:, col["t_s"]], force, filter_s) > cap_n)
                                      * dt),
            "max_junction_accel_jump": jump,
            "junction_step_ratio_max": ratio,
            "tracking_rms_m": float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) if len(err) else 0.0,
            "trace_ticks": len(tr)}


def _final_status(run: Run) -> tuple[int | None, dict | None]:
    """(its log time [ns], the controller's status) when the launcher began stopping the cell (what the stop itself
    does, e.g. the lift of a pad stopped mid-wipe, is in the faults, not the outcome); the last one without a
    launcher; (None, None) without a status.

    "Before" is by the status's own ``wall_ns`` (the controller's clock when it published it) where the cell's
    services share the launcher's wall clock: the recorder, a background process, may receive a status seconds
    after it was said (16 s behind a routed real-time cell on 2 cores: its last status before the stop read
    RETREAT while the controller had been DONE for 14 s). The network-free cell logs on the robot's clock, as its
    ``stopping_wall_ns`` is, so there the log time decides."""
    msgs = run.rec.get(run.keys.controller_status, [])
    stopping = int(run.launcher.get("stopping_wall_ns", 0))
    own_clock = run.launcher.get("network") != "none"
    before = [(t, m) for t, m in msgs if (int(m.get("wall_ns") or t) if own_clock else t) < stopping] \
        if stopping else []
    return before[-1] if before else (msgs[-1] if msgs else (None, None))


def _safety_section(run: Run) -> dict[str, float]:
    """The physical contact force (sim truth) and the joint speeds (every robot state), over the whole run."""
    from arm.robot_model import RobotModel

    dq_max = RobotModel().limits.dq_max
    worst = 0.0
    for _, m in run.rec.get(run.keys.robot_state, []):
        dq = m.get("dq_rad_s") or []
        if len(dq) == len(dq_max):
            worst = max(worst, float(np.max(np.abs(np.asarray(dq, float)) / dq_max)))
    return {"max_contact_force_n": max((float(t["contact_force_n"]) for t in run.truth), default=0.0),
            "peak_contact_force_n": max((float(t.get("peak_force_n", t["contact_force_n"])) for t in run.truth),
                                        default=0.0),
            "max_joint_speed_ratio": worst}


def _outcome(final_phase: str, removed: float, told: str | None) -> str:
    """``fault``, ``cleaned`` or ``incomplete`` from the recording, or the launcher's ``told`` when that is worse."""
    if final_phase in (Phase.FAULT, Phase.ESTOP):
        outcome = "fault"
    elif final_phase == Phase.DONE and removed >= CLEANED_FRACTION:
        outcome = "cleaned"
    else:
        outcome = "incomplete"
    if told and _OUTCOME_RANK.get(told, 0) > _OUTCOME_RANK[outcome]:
        outcome = told
    return outcome


def _counters_section(run: Run) -> dict[str, dict]:
    """The last status counters of the controller, perception, the sim and the robot side (an adapter)."""
    counters = {"controller": run.status[-1]["counters"] if run.status else {}}
    for name, key in (("perception", run.keys.perception_status), ("sim", run.keys.sim_status),
                      ("robot", run.keys.robot_status)):
        msgs = topic_messages(run.rec, key)
        counters[name] = msgs[-1]["counters"] if msgs else {}
    return counters


def write_report(run_dir: Path, **kwargs) -> dict[str, Any]:
    """Build the report and write ``report.json`` atomically; returns it."""
    report = build_report(run_dir, **kwargs)
    write_text_atomic(Path(run_dir) / "report.json", json.dumps(report, indent=1, default=_json_default) + "\n")
    return report


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    raise TypeError(f"not JSON: {type(o).__name__}")


def summary_lines(report: dict[str, Any]) -> list[str]:
    """A few lines for the terminal."""
    lines = [(f"outcome {report['outcome']}: {report['dirt_removed_fraction']:.1%} of the dirt removed in "
              f"{report['sim_time_s']:.1f} s robot time ({report['duration_s']:.1f} s wall)"),
             (f"force while wiping {report['normal_force_mean_n']:.1f} +- {report['normal_force_std_n']:.1f} N, "
              f"max {report['max_normal_force_n']:.1f} N; tracking RMS {report['tracking_rms_m'] * 1000:.2f} mm; "
              f"junction accel. step max {report['max_junction_accel_jump']:.3f} m/s^2 "
              f"({report['junction_step_ratio_max']:.2f}x an ordinary tick)")]
    if report.get("final_reason"):
        lines.append(f"  {report['final_phase']}: {report['final_reason']}")
    for s in report["stains"]:
        k = "no kappa" if s["kappa_s"] is None else f"kappa at {s['kappa_s']:.1f} s"
        if s.get("smeared"):
            m = s["smeared"]
            k += f", smeared at {m['at_s']:.1f} s ({m['remaining']:.0%} left after {m['passes']} passes)"
        lines.append(f"  stain {s['id']}: {s['initial_remaining']:.0%} -> {s['final_remaining']:.1%}, {k}")
    peaks = report.get("motion_peaks", {})
    moving = [(name, m) for name, m in peaks.items() if name in ("APPROACH", "TRANSITION", "WIPE", "RETREAT")]
    if moving:
        lines.append("reference peaks (speed m/s, accel. m/s^2, jerk m/s^3): " + "; ".join(
            f"{name} {m['speed_m_s']:.2f} / {m['accel_m_s2']:.1f} / {m['jerk_m_s3']:.0f}" for name, m in moving))
    lines.append(f"safety: contact force max {report.get('max_contact_force_n', 0.0):.1f} N at 10 Hz, "
                 f"{report.get('peak_contact_force_n', 0.0):.1f} N over every step (cap "
                 f"{report['force_cap_n']:.0f} N), joint speed max {report.get('max_joint_speed_ratio', 0.0):.2f} "
                 "of the limit")
    for f in report["faults"]:
        lines.append(f"  {f['phase']}: {f['reason']}")
    return lines
