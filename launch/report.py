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
  ``kappa_s`` (robot time; null if never), ``kappa_latency_s``.
* ``max_normal_force_n``, ``normal_force_mean_n`` and ``normal_force_std_n``
  while wiping, ``time_above_cap_s`` (the measured force, low-passed as the
  controller's cap watch low-passes it (``ForceParams.filter_s``), above
  ``force_cap_n``: what would fault the controller; a single-tick spike of the
  measured wrench, e.g. around a robot-side brake, is not an overload).
* ``max_junction_accel_jump`` [m/s^2]: the largest change of the in-plane
  reference acceleration across one tick at an MP junction, and
  ``junction_step_ratio_max``: that change over the largest ordinary
  one-tick change in the 5 ticks around it (<= ~1: continuous).
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
* ``loop_timing``: the controller's last reported loop statistics.
* ``max_contact_force_n`` (the sim's truth: the physical contact force,
  whatever the controller measured) and ``max_joint_speed_ratio`` (the
  largest ``|dq| / dq_max`` of any joint in any recorded ``robot/state``):
  the cell's safety, across restarts of any service.
* ``faults``, in time order, each with a wall time, a phase and a reason: every entry into PAUSED, FAULT
  or ESTOP; every service that went silent (no status for ``SERVICE_SILENCE_S`` or four status periods:
  frozen, stopped or dead) or came back restarted (its status count starting again), phase ``SERVICE``;
  each safety action of the robot side (a brake on stale commands or after its own freeze, commands of
  another controller dropped, a change of the controller served, commands held while e-stopped:
  :data:`ROBOT_EVENTS`), phase ``ROBOT``; a recorder that stalled, restarted (carrying its predecessor's
  recording over) or did not finish (a recording recovered from its ``.partial`` file), phase ``RECORDER``; the launcher's end of the run when a service died, failed
  or the run timed out (phase ``CELL``, the reason ``lamps up`` gave).
* ``services``: exit codes from the launcher (if any); ``counters``: the
  last status counters of each service; ``plots``: the PNG files written.
"""

from __future__ import annotations

import base64
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from controller.core import PHASE_CODES
from controller.control.force import NormalForceRegulator
from controller.params import ForceParams
from interfaces.keys import Keys
from interfaces.messages import Phase
from lampskit.atomic import write_text_atomic

from .record import RECORDING, RESUMED_TOPIC, read_recording, trace_array

SCHEMA = "lamps-run-report/1"
#: Fraction of the dirt that must be gone for the outcome ``cleaned``.
CLEANED_FRACTION = 0.95
#: A stain counts as wiped in the truth at or below this remaining fraction (perception's kappa level).
TRUTH_LEVEL = 0.03
_WIPING = (PHASE_CODES[Phase.WIPE], PHASE_CODES[Phase.TRANSITION])
_OUTCOME_RANK = {"cleaned": 0, "incomplete": 1, "timeout": 2, "stopped": 2, "fault": 3, "failed": 4}
#: A service whose status is not heard for this long [s], or four of its status periods if that is longer,
#: went silent: a fault.
SERVICE_SILENCE_S = 1.0


def _topic(rec: dict, key: str) -> list[dict]:
    return [m for _, m in rec.get(key, [])]


def _junction_steps(tr: np.ndarray, col: dict[str, int], window: int = 5) -> tuple[float, float]:
    """(largest one-tick reference-acceleration change at an MP junction [m/s^2], its ratio to the ticks around)."""
    if len(tr) < 3:
        return 0.0, 0.0
    phase = tr[:, col["phase"]]
    a = tr[:, [col["ref_ax"], col["ref_ay"]]]
    steps = np.linalg.norm(np.diff(a, axis=0), axis=1)  # steps[k] = a[k+1] - a[k]
    chain = set(_WIPING)
    js = [k for k in range(1, len(tr)) if phase[k] != phase[k - 1] and phase[k - 1] in chain
          and (phase[k] in chain or phase[k] == PHASE_CODES[Phase.RETREAT])]
    worst, ratio = 0.0, 0.0
    for j in js:
        at = steps[max(j - 2, 0): j + 1]  # the change lands within a tick of the phase flag
        around = np.concatenate([steps[max(j - 2 - window, 0): max(j - 2, 0)], steps[j + 1: j + 1 + window]])
        jump = float(at.max())
        worst = max(worst, jump)
        ratio = max(ratio, jump / max(float(around.max()) if around.size else 0.0, 1e-9))
    return worst, ratio


@dataclass(frozen=True)
class _Run:
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


def _read_run(run_dir: Path, keys: Keys | None = None, cap_n: float | None = None) -> _Run:
    """The recording of ``run_dir`` and its ``run.json``; ``keys`` and ``cap_n`` default to what the launcher ran."""
    rec = read_recording(run_dir / RECORDING)
    launcher = json.loads((run_dir / "run.json").read_text()) if (run_dir / "run.json").is_file() else {}
    keys = keys or Keys(launcher.get("key_prefix", Keys().prefix))
    cap_n = cap_n if cap_n is not None else launcher.get("force_cap_n", ForceParams().cap_n)
    cols, tr = trace_array(_topic(rec, keys.controller_trace))
    filter_s = float(launcher.get("force_filter_s", ForceParams().filter_s))
    return _Run(rec=rec, launcher=launcher, keys=keys, cap_n=cap_n, filter_s=filter_s, truth=_topic(rec, keys.sim_truth),
                status=_topic(rec, keys.controller_status),
                stains_msgs=[m for m in _topic(rec, keys.perception_stains) if m.get("board") != "lost"],
                tr=tr, col={c: i for i, c in enumerate(cols)})


def build_report(run_dir: Path, keys: Keys | None = None, cap_n: float | None = None) -> dict[str, Any]:
    """The report of ``run_dir`` from its ``recording.mcap`` (and ``run.json`` from the launcher, if there)."""
    run_dir = Path(run_dir)
    run = _read_run(run_dir, keys, cap_n)
    report: dict[str, Any] = {"schema": SCHEMA, "run_dir": run_dir.name}
    report.update(_progress_section(run))
    report["stains"] = _stains_section(run.truth, run.stains_msgs)
    report.update(_force_section(run.tr, run.col, run.truth, run.cap_n, run.filter_s))
    report["motion_peaks"] = _motion_peaks(run.tr, run.col)
    report["phase_time_s"] = phase_times(run.tr, run.col)
    report["skill_start_s"] = skill_start(run.tr, run.col)
    report["job_end_s"] = job_end(run.tr, run.col)
    report["final_retreat_s"] = final_retreat(run.tr, run.col)
    report["force_cap_n"] = run.cap_n
    report["loop_timing"] = run.status[-1]["timing"] if run.status else {}
    report.update(_safety_section(run))
    recorder = _recorder_faults(run, run_dir)
    faults = (_faults_section(run.status) + _service_faults(run, _recorder_stalls(run)) + _robot_events(run)
              + recorder + _cell_faults(run.launcher))
    report["faults"] = sorted(faults, key=lambda f: f["wall_ns"])
    report["final_phase"] = _final_phase(run)
    report["outcome"] = _outcome(report["final_phase"], report["dirt_removed_fraction"], run.launcher.get("outcome"))
    report["services"] = run.launcher.get("services", {})
    report["counters"] = _counters_section(run)
    report["plots"] = write_plots(run_dir, run.rec, run.keys, run.tr, run.col, run.truth, run.stains_msgs)
    return report


def _dirt_removed(truth: list[dict]) -> float:
    """1 - last / first total dirt of ``sim/truth`` (0 without truth or dirt)."""
    return (1.0 - truth[-1]["total_dirt"] / truth[0]["total_dirt"]) if truth and truth[0]["total_dirt"] > 0 else 0.0


def _progress_section(run: _Run) -> dict[str, float]:
    """``duration_s`` (the launcher's, else the recording's span), ``sim_time_s`` and ``dirt_removed_fraction``."""
    times = [t for msgs in run.rec.values() for t, _ in msgs[:1] + msgs[-1:]]
    truth, tr = run.truth, run.tr
    return {"duration_s": run.launcher.get("duration_s", (max(times) - min(times)) * 1e-9 if times else 0.0),
            "sim_time_s": truth[-1]["robot_time_ns"] * 1e-9 if truth else (float(tr[-1, 0]) if len(tr) else 0.0),
            "dirt_removed_fraction": float(_dirt_removed(truth))}


def _stains_section(truth: list[dict], stains_msgs: list[dict]) -> list[dict[str, Any]]:
    """Per true stain: where, how big, how much is left, and when the truth and perception saw it wiped."""
    if not truth:
        return []
    first, last = truth[0], truth[-1]
    centres = np.array(last["centres_board_m"]) if last["centres_board_m"] else np.zeros((0, 2))
    stains = []
    for k, sid in enumerate(last["stain_ids"]):
        below = next((t["robot_time_ns"] * 1e-9 for t in truth if t["remaining"][k] <= TRUTH_LEVEL), None)
        kappa = _first_kappa_s(stains_msgs, centres, k)
        stains.append({"id": sid, "centre_board_m": last["centres_board_m"][k] if len(centres) else None,
                       "size_m": last["sizes_m"][k] if last["sizes_m"] else None,
                       "initial_remaining": first["remaining"][k], "final_remaining": last["remaining"][k],
                       "truth_below_level_s": below, "kappa_s": kappa,
                       "kappa_latency_s": (kappa - below) if kappa is not None and below is not None else None})
    return stains


def _first_kappa_s(stains_msgs: list[dict], centres_board_m: np.ndarray, k: int) -> float | None:
    """Robot time [s] of the first perceived stain with kappa whose nearest true stain is ``k`` (None if never).

    centres_board_m : array, shape (n_stains, 2), the true stain centres on the board
    """
    for m in stains_msgs:
        for s in m["stains"]:
            if s["kappa"] and len(centres_board_m) and int(np.argmin(np.linalg.norm(
                    centres_board_m - np.array(s["centre_board_m"]), axis=1))) == k:
                return m["robot_time_ns"] * 1e-9
    return None


def cap_watch_force(t_s: np.ndarray, force_n: np.ndarray, filter_s: float) -> np.ndarray:
    """The measured normal force as the controller's cap watch sees it: low-passed tick by tick.

    t_s, force_n : arrays, shape (n_ticks,), robot time [s] and measured normal force [N] of the trace.
    Returns an array, shape (n_ticks,) [N]. The filter is the controller's own
    (:meth:`NormalForceRegulator.measure`); where the robot clock goes back (a restarted controller) it
    starts again from 0 N, as the new controller's does; a gap is bridged with its real length.
    """
    watch = NormalForceRegulator(0.0, 0.0, 0.0, 1.0, filter_s)
    out = np.empty(len(force_n))
    prev = -np.inf
    for k, (t, f) in enumerate(zip(t_s.tolist(), force_n.tolist())):
        if t < prev:
            watch.filtered_n = 0.0
        out[k] = watch.measure(f, t - prev if np.isfinite(prev) and t > prev else 0.0)
        prev = t
    return out


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
    wiping = np.isin(tr[:, col["phase"]], _WIPING) & (tr[:, col["contact"]] > 0.5)
    dt = float(np.median(np.diff(tr[:, 0]))) if len(tr) > 1 else 0.0
    jump, ratio = _junction_steps(tr, col)
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


def _motion_peaks(tr: np.ndarray, col: dict[str, int]) -> dict[str, dict[str, float]]:
    """Peak speed, acceleration and jerk of the executed in-plane reference per phase name and over ``all``."""
    if len(tr) < 2:
        return {}
    t, phase = tr[:, col["t_s"]], tr[:, col["phase"]]
    v = np.linalg.norm(tr[:, [col["ref_vx"], col["ref_vy"]]], axis=1)
    a_xy = tr[:, [col["ref_ax"], col["ref_ay"]]]
    a = np.linalg.norm(a_xy, axis=1)
    dt = np.diff(t)
    tick = float(np.median(dt[dt > 0])) if np.any(dt > 0) else 0.0
    consecutive = (dt > 0) & (dt <= 1.5 * tick) & (phase[1:] == phase[:-1])
    jerk = np.zeros(len(tr))
    jerk[1:][consecutive] = np.linalg.norm(np.diff(a_xy, axis=0)[consecutive], axis=1) / dt[consecutive]
    names = {code: name for name, code in PHASE_CODES.items()}
    out = {}
    for code in [None, *sorted(set(phase.astype(int).tolist()))]:
        sel = np.ones(len(tr), bool) if code is None else phase == code
        out["all" if code is None else names.get(code, str(code))] = {
            "speed_m_s": float(v[sel].max()), "accel_m_s2": float(a[sel].max()), "jerk_m_s3": float(jerk[sel].max()),
            "ticks": int(np.count_nonzero(sel))}
    return out


def phase_times(tr: np.ndarray, col: dict[str, int]) -> dict[str, float]:
    """Robot time [s] per phase name and ``all``: each interval between consecutive recorded ticks (at most 1.5
    ordinary ticks apart: a gap is nobody's) counts for the phase of its first tick."""
    if len(tr) < 2:
        return {}
    t, phase = tr[:, col["t_s"]], tr[:, col["phase"]].astype(int)
    dt = np.diff(t)
    tick = float(np.median(dt[dt > 0])) if np.any(dt > 0) else 0.0
    dt = np.where((dt > 0) & (dt <= 1.5 * tick), dt, 0.0)
    names = {code: name for name, code in PHASE_CODES.items()}
    out = {names.get(c, str(c)): float(dt[phase[:-1] == c].sum()) for c in sorted(set(phase[:-1].tolist()))}
    out["all"] = float(dt.sum())
    return out


def skill_start(tr: np.ndarray, col: dict[str, int]) -> float | None:
    """Robot time [s] of the first recorded TRANSITION or WIPE tick (None if there is none)."""
    if not len(tr):
        return None
    hit = np.flatnonzero(np.isin(tr[:, col["phase"]].astype(int), _WIPING))
    return float(tr[hit[0], col["t_s"]]) if hit.size else None


def job_end(tr: np.ndarray, col: dict[str, int]) -> float | None:
    """Robot time [s] of the first tick of the DONE the recording ends in (None if it does not end DONE)."""
    if not len(tr):
        return None
    done = tr[:, col["phase"]].astype(int) == PHASE_CODES[Phase.DONE]
    if not done[-1]:
        return None
    other = np.flatnonzero(~done)
    return float(tr[other[-1] + 1 if other.size else 0, col["t_s"]])


def final_retreat(tr: np.ndarray, col: dict[str, int]) -> float | None:
    """Robot time [s] of the RETREAT that ends in the DONE the recording ends in (from its first tick to that
    DONE; None if it does not end DONE after a RETREAT). Retreats before it (a look, then a re-pass) are not it."""
    end = job_end(tr, col)
    if end is None:
        return None
    t, phase = tr[:, col["t_s"]], tr[:, col["phase"]].astype(int)
    before = np.flatnonzero(t < end)
    if not before.size or phase[before[-1]] != PHASE_CODES[Phase.RETREAT]:
        return None
    other = np.flatnonzero(phase[: before[-1] + 1] != PHASE_CODES[Phase.RETREAT])
    return float(end - t[other[-1] + 1 if other.size else 0])


def _final_phase(run: _Run) -> str:
    """The controller's phase when the launcher began stopping the cell (what the stop itself does, e.g. the lift
    of a pad stopped mid-wipe, is in the faults, not the outcome); the last one without a launcher."""
    msgs = run.rec.get(run.keys.controller_status, [])
    stopping = int(run.launcher.get("stopping_wall_ns", 0))
    before = [m for t, m in msgs if t < stopping] if stopping else []
    last = before[-1] if before else (msgs[-1][1] if msgs else None)
    return last["phase"] if last else "none"


def _safety_section(run: _Run) -> dict[str, float]:
    """The physical contact force (sim truth) and the joint speeds (every robot state), over the whole run."""
    from interfaces.robot_model import RobotModel

    dq_max = RobotModel().limits.dq_max
    worst = 0.0
    for _, m in run.rec.get(run.keys.robot_state, []):
        dq = m.get("dq_rad_s") or []
        if len(dq) == len(dq_max):
            worst = max(worst, float(np.max(np.abs(np.asarray(dq, float)) / dq_max)))
    return {"max_contact_force_n": max((float(t["contact_force_n"]) for t in run.truth), default=0.0),
            "max_joint_speed_ratio": worst}


def _recorder_stalls(run: _Run) -> list[tuple[int, int]]:
    """(start, end) [wall ns] of every stretch longer than ``SERVICE_SILENCE_S`` in which nothing was recorded."""
    times = np.sort(np.fromiter((t for msgs in run.rec.values() for t, _ in msgs), dtype=np.int64))
    if len(times) < 2:
        return []
    gaps = np.diff(times)
    return [(int(times[i]), int(times[i + 1])) for i in np.flatnonzero(gaps * 1e-9 > SERVICE_SILENCE_S)]


def _unheard_s(t0: int, t1: int, stalls: list[tuple[int, int]]) -> float:
    """How much of (t0, t1) [wall ns] the recorder was listening [s] (a stalled recorder hears no one)."""
    deaf = sum(max(0, min(t1, b) - max(t0, a)) for a, b in stalls)
    return (t1 - t0 - deaf) * 1e-9


#: Robot-side counters whose every increase is a safety action worth a line in the faults: name -> what it means.
ROBOT_EVENTS = {
    "stale_command_brakes": "braked: no fresh command within its stale limit",
    "loop_freezes": "its own loop froze: braked until a fresh answer",
    "commands_from_another_controller": "dropped commands from a controller session it does not serve",
    "controller_changes": "now serves another controller session (the one it served fell silent)",
    "commands_held_for_estop": "held commands while e-stopped",
    "joint_speed_brakes": "braked: a joint moved faster than its speed brake allows",
    "disarms": "the real-robot adapter disarmed: no more commands to the robot",
}


#: Increases of one robot-side counter less than this apart [s] are one line of the faults (a burst).
ROBOT_BURST_S = 5.0


def _robot_events(run: _Run) -> list[dict[str, Any]]:
    """Each burst of increases of a :data:`ROBOT_EVENTS` counter in the robot side's statuses (phase ``ROBOT``),
    until the launcher began stopping the cell: increases less than ``ROBOT_BURST_S`` apart make one line, with
    how many and over how long."""
    out: list[dict[str, Any]] = []
    stopping = int(run.launcher.get("stopping_wall_ns", 0)) or None  # stopping the cell brakes and disarms it
    for name, topic in (("sim", run.keys.sim_status), ("robot", run.keys.robot_status)):
        prev: dict = {}
        bursts: dict[str, list] = {}  # key -> [first wall ns, last wall ns, increase, detail] of the open burst
        for t, m in run.rec.get(topic, []):
            if stopping is not None and t >= stopping:
                break
            counters = m.get("counters", {})
            if m.get("seq", 0) < prev.get("_seq", 0):
                prev = {}  # a restarted robot side counts from 0 again
            for key in ROBOT_EVENTS:
                n = int(counters.get(key, 0))
                if n <= prev.get(key, 0):
                    continue
                b = bursts.get(key)
                if b is not None and (t - b[1]) * 1e-9 < ROBOT_BURST_S:
                    b[1], b[2] = t, b[2] + n - prev.get(key, 0)
                else:
                    if b is not None:
                        out.append(_robot_line(name, key, b))
                    bursts[key] = [t, t, n - prev.get(key, 0), m.get("detail", "")]
            prev = {**{k: int(counters.get(k, 0)) for k in ROBOT_EVENTS}, "_seq": m.get("seq", 0)}
        out += [_robot_line(name, key, b) for key, b in bursts.items()]
    return out


def _robot_line(name: str, key: str, burst: list) -> dict[str, Any]:
    first, last, n, detail = burst
    span = f" over {(last - first) * 1e-9:.1f} s" if last > first else ""
    why = f"; {detail[detail.index('why='):][:160]}" if key == "disarms" and "why=" in detail else ""
    return {"wall_ns": first, "phase": "ROBOT", "reason": f"{name}: {ROBOT_EVENTS[key]} ({key} +{n}{span}){why}"}


def _service_faults(run: _Run, stalls: list[tuple[int, int]]) -> list[dict[str, Any]]:
    """Each silence of a service's status longer than ``SERVICE_SILENCE_S`` (not counting the recorder's own stalls)
    and each restart (its status seq going back), until the launcher began stopping the cell (services then stop
    one by one) or the recording ends."""
    k = run.keys
    last_ns = max((msgs[-1][0] for msgs in run.rec.values() if msgs), default=0)
    end_ns = min(int(run.launcher.get("stopping_wall_ns", 0)) or last_ns, last_ns) or None
    out: list[dict[str, Any]] = []
    for name, topic in (("sim", k.sim_status), ("robot", k.robot_status), ("controller", k.controller_status),
                        ("perception", k.perception_status)):
        msgs = run.rec.get(topic, [])
        if len(msgs) < 2:
            continue
        # a service's own status period sets what counts as silent (the sim and perception report at 2 Hz)
        silence_s = max(SERVICE_SILENCE_S, 4.0 * float(np.median(np.diff([t for t, _ in msgs]))) * 1e-9)
        for (t0, m0), (t1, m1) in zip(msgs, msgs[1:]):
            if end_ns is not None and t0 >= end_ns:
                break
            gap = (t1 - t0) * 1e-9
            if gap > silence_s and _unheard_s(t0, t1, stalls) > silence_s:
                out.append({"wall_ns": t0, "phase": "SERVICE",
                            "reason": f"{name}: no status for {gap:.1f} s (frozen, stopped or dead)"})
            if m1.get("seq", 0) < m0.get("seq", 0):
                out.append({"wall_ns": t1, "phase": "SERVICE",
                            "reason": f"{name}: restarted (status count {m0.get('seq')} -> {m1.get('seq')})"})
        if end_ns is not None and _unheard_s(msgs[-1][0], end_ns, stalls) > silence_s:
            out.append({"wall_ns": msgs[-1][0], "phase": "SERVICE", "reason": f"{name}: silent for the last "
                        f"{(end_ns - msgs[-1][0]) * 1e-9:.1f} s before the cell stopped (dead or frozen)"})
    return out


def _recorder_faults(run: _Run, run_dir: Path) -> list[dict[str, Any]]:
    """The recorder stalled (nothing recorded on any key for ``SERVICE_SILENCE_S``) or died (recovered recording)."""
    out: list[dict[str, Any]] = [{"wall_ns": a, "phase": "RECORDER",
                                  "reason": f"nothing recorded for {(b - a) * 1e-9:.1f} s (the recorder stalled)"}
                                 for a, b in _recorder_stalls(run)]
    for t_ns, m in run.rec.get(RESUMED_TOPIC, []):
        how = "had finished" if m.get("earlier_finished") else "had died"
        out.append({"wall_ns": t_ns, "phase": "RECORDER",
                    "reason": f"the recorder restarted {(t_ns - m.get('last_earlier_ns', t_ns)) * 1e-9:.1f} s after "
                              f"the last earlier message (its predecessor {how}); {m.get('carried_messages', 0)} "
                              f"earlier messages carried over from {m.get('earlier_file', '?')}"[:500]})
    if (run_dir / (RECORDING + ".partial")).is_file():
        last_ns = max((msgs[-1][0] for msgs in run.rec.values() if msgs), default=0)
        out.append({"wall_ns": last_ns, "phase": "RECORDER",
                    "reason": "the recorder did not finish: the recording was recovered from its .partial file "
                              "and ends here"})
    return out


def _cell_faults(launcher: dict) -> list[dict[str, Any]]:
    """The launcher's ending as a fault when it was one (a service died or failed, the run timed out)."""
    if launcher.get("outcome") not in ("failed", "timeout"):
        return []
    return [{"wall_ns": int(launcher.get("ended_wall_ns", 0)), "phase": "CELL",
             "reason": str(launcher.get("why", launcher["outcome"]))[:500]}]


def _faults_section(status: list[dict]) -> list[dict[str, Any]]:
    """Every entry into PAUSED, FAULT or ESTOP in the controller's status."""
    faults, prev = [], None
    for s in status:
        if s["phase"] != prev and s["phase"] in (Phase.PAUSED, Phase.FAULT, Phase.ESTOP):
            faults.append({"wall_ns": s.get("wall_ns", 0), "phase": s["phase"], "reason": s["reason"]})
        prev = s["phase"]
    return faults


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


def _counters_section(run: _Run) -> dict[str, dict]:
    """The last status counters of the controller, perception, the sim and the robot side (an adapter)."""
    counters = {"controller": run.status[-1]["counters"] if run.status else {}}
    for name, key in (("perception", run.keys.perception_status), ("sim", run.keys.sim_status),
                      ("robot", run.keys.robot_status)):
        msgs = _topic(run.rec, key)
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
    for a, img, title in zip(ax, frames, ("before", f"after ({_dirt_removed(truth):.1%} of the dirt removed)")):
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
    free = ~np.isin(phase, _WIPING)
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


def summary_lines(report: dict[str, Any]) -> list[str]:
    """A few lines for the terminal."""
    lines = [(f"outcome {report['outcome']}: {report['dirt_removed_fraction']:.1%} of the dirt removed in "
              f"{report['sim_time_s']:.1f} s robot time ({report['duration_s']:.1f} s wall)"),
             (f"force while wiping {report['normal_force_mean_n']:.1f} +- {report['normal_force_std_n']:.1f} N, "
              f"max {report['max_normal_force_n']:.1f} N; tracking RMS {report['tracking_rms_m'] * 1000:.2f} mm; "
              f"junction accel. step max {report['max_junction_accel_jump']:.3f} m/s^2 "
              f"({report['junction_step_ratio_max']:.2f}x an ordinary tick)")]
    for s in report["stains"]:
        k = "no kappa" if s["kappa_s"] is None else f"kappa at {s['kappa_s']:.1f} s"
        lines.append(f"  stain {s['id']}: {s['initial_remaining']:.0%} -> {s['final_remaining']:.1%}, {k}")
    peaks = report.get("motion_peaks", {})
    moving = [(name, m) for name, m in peaks.items() if name in ("APPROACH", "TRANSITION", "WIPE", "RETREAT")]
    if moving:
        lines.append("reference peaks (speed m/s, accel. m/s^2, jerk m/s^3): " + "; ".join(
            f"{name} {m['speed_m_s']:.2f} / {m['accel_m_s2']:.1f} / {m['jerk_m_s3']:.0f}" for name, m in moving))
    lines.append(f"safety: contact force max {report.get('max_contact_force_n', 0.0):.1f} N (cap "
                 f"{report['force_cap_n']:.0f} N), joint speed max {report.get('max_joint_speed_ratio', 0.0):.2f} "
                 "of the limit")
    for f in report["faults"]:
        lines.append(f"  {f['phase']}: {f['reason']}")
    return lines

