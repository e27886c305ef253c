"""The report's fault lines: the controller's PAUSED / FAULT / ESTOP entries, services gone silent or restarted,
the robot side's safety actions, the recorder's stalls and restarts, and the launcher's ending of the cell."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from interfaces.messages import Phase

from .record import RECORDING, RESUMED_TOPIC
from .report_run import Run, cell_series
from .report_sources import budget_faults, deaf_from

#: A service whose status is not heard for this long [s], or four of its status periods if that is longer,
#: went silent: a fault.
SERVICE_SILENCE_S = 1.0


def recorder_stalls(run: Run) -> list[tuple[int, int]]:
    """(start, end) [wall ns] of every stretch longer than ``SERVICE_SILENCE_S`` in which nothing the cell sent was
    recorded (before the recording reached its whole disk budget: past it nothing is, on purpose)."""
    times = np.sort(np.fromiter((t for msgs in cell_series(run.rec) for t, _ in msgs), dtype=np.int64))
    if len(times) < 2:
        return []
    gaps = np.diff(times)
    full = deaf_from(run).get("*")
    return [(int(times[i]), int(times[i + 1])) for i in np.flatnonzero(gaps * 1e-9 > SERVICE_SILENCE_S)
            if full is None or times[i] < full]


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
    "tool_speed_brakes": "braked: the pad moved faster than its speed limit allows",
    "press_speed_brakes": "braked or yielded: the pad moved into the surface faster than its press limit allows",
    "contact_force_yields": "yielded: the contact force went over the robot side's cap",
    "guard_faults": "FAULT-hold: the controller kept running into the robot side's limits",
    "frozen_stamps": "disarmed: the robot's clock stood still while states kept coming (a lost FRI link)",
    "quality_disarms": "disarmed: the FRI connection quality fell",
    "connection_quality_warnings": "warned: the FRI connection quality fell to FAIR",
    "applied_stalls": "disarmed: nothing judged applied for a second (a robot that does not echo?)",
    "states_on_an_old_command": "held: the robot ran on an old message (ours did not reach it), reported as such",
    "disarms": "the real-robot adapter disarmed: no more commands to the robot",
}


#: Increases of one robot-side counter less than this apart [s] are one line of the faults (a burst).
ROBOT_BURST_S = 5.0


def robot_events(run: Run) -> list[dict[str, Any]]:
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


_NEVER = 2**63 - 1


def service_faults(run: Run, stalls: list[tuple[int, int]]) -> list[dict[str, Any]]:
    """Each silence of a service's status longer than ``SERVICE_SILENCE_S`` (not counting the recorder's own stalls,
    nor its thinning or stopping of a key past its share: :func:`.report_sources.deaf_from`) and each restart (its
    status seq going back), until the launcher began stopping the cell (services then stop one by one) or the
    recording ends."""
    k = run.keys
    last_ns = max((msgs[-1][0] for msgs in cell_series(run.rec) if msgs), default=0)
    end_ns = min(int(run.launcher.get("stopping_wall_ns", 0)) or last_ns, last_ns) or None
    deaf = deaf_from(run)
    out: list[dict[str, Any]] = []
    for name, topic in (("sim", k.sim_status), ("robot", k.robot_status), ("controller", k.controller_status),
                        ("perception", k.perception_status)):
        msgs = run.rec.get(topic, [])
        if len(msgs) < 2:
            continue
        # past its share the recorder keeps a status a second, then none: a gap from then is the recorder's doing
        partial = min(deaf.get(topic, _NEVER), deaf.get("*", _NEVER))
        # a service's own status period sets what counts as silent (the sim and perception report at 2 Hz)
        silence_s = max(SERVICE_SILENCE_S, 4.0 * float(np.median(np.diff([t for t, _ in msgs]))) * 1e-9)
        for (t0, m0), (t1, m1) in zip(msgs, msgs[1:]):
            if end_ns is not None and t0 >= end_ns:
                break
            gap = (t1 - t0) * 1e-9
            if gap > silence_s and t1 <= partial and _unheard_s(t0, t1, stalls) > silence_s:
                out.append({"wall_ns": t0, "phase": "SERVICE",
                            "reason": f"{name}: no status for {gap:.1f} s (frozen, stopped or dead)"})
            if m1.get("seq", 0) < m0.get("seq", 0):
                out.append({"wall_ns": t1, "phase": "SERVICE",
                            "reason": f"{name}: restarted (status count {m0.get('seq')} -> {m1.get('seq')})"})
        if end_ns is not None and end_ns <= partial and _unheard_s(msgs[-1][0], end_ns, stalls) > silence_s:
            out.append({"wall_ns": msgs[-1][0], "phase": "SERVICE", "reason": f"{name}: silent for the last "
                        f"{(end_ns - msgs[-1][0]) * 1e-9:.1f} s before the cell stopped (dead or frozen)"})
    return out


def recorder_faults(run: Run, run_dir: Path) -> list[dict[str, Any]]:
    """The recorder stalled (nothing recorded on any key for ``SERVICE_SILENCE_S``), thinned or stopped a key past
    its share of the disk budget or reached the whole budget, or died (recovered recording)."""
    out: list[dict[str, Any]] = [{"wall_ns": a, "phase": "RECORDER",
                                  "reason": f"nothing recorded for {(b - a) * 1e-9:.1f} s (the recorder stalled)"}
                                 for a, b in recorder_stalls(run)]
    out += budget_faults(run)
    for t_ns, m in run.rec.get(RESUMED_TOPIC, []):
        how = "had finished" if m.get("earlier_finished") else "had died"
        out.append({"wall_ns": t_ns, "phase": "RECORDER",
                    "reason": f"the recorder restarted {(t_ns - m.get('last_earlier_ns', t_ns)) * 1e-9:.1f} s after "
                              f"the last earlier message (its predecessor {how}); {m.get('carried_messages', 0)} "
                              f"earlier messages carried over from {m.get('earlier_file', '?')}"[:500]})
    if (run_dir / (RECORDING + ".partial")).is_file():
        last_ns = max((msgs[-1][0] for msgs in cell_series(run.rec) if msgs), default=0)
        out.append({"wall_ns": last_ns, "phase": "RECORDER",
                    "reason": "the recorder did not finish: the recording was recovered from its .partial file "
                              "and ends here"})
    return out


def cell_faults(launcher: dict) -> list[dict[str, Any]]:
    """The launcher's ending as a fault when it was one (a service died or failed, the run timed out)."""
    if launcher.get("outcome") not in ("failed", "timeout"):
        return []
    return [{"wall_ns": int(launcher.get("ended_wall_ns", 0)), "phase": "CELL",
             "reason": str(launcher.get("why", launcher["outcome"]))[:500]}]


def faults_section(status: list[dict]) -> list[dict[str, Any]]:
    """Every entry into PAUSED, FAULT or ESTOP in the controller's status."""
    faults, prev = [], None
    for s in status:
        if s["phase"] != prev and s["phase"] in (Phase.PAUSED, Phase.FAULT, Phase.ESTOP):
            faults.append({"wall_ns": s.get("wall_ns", 0), "phase": s["phase"], "reason": s["reason"]})
        prev = s["phase"]
    return faults
