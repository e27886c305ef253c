"""``lamps robot --backend lbr --preflight``: the checks that move nothing, each PASS or FAIL with the fix.

With the robot in T1, the LBRServer app started and the stack running,
the preflight listens to the stack's keys through the bridge for
``LISTEN_S`` and judges what arming needs and more
(:func:`~robot.lbr.arming.arming_refusal` has the stack's lines behind each;
docs/real-robot.md the bring-up checklist): the bridge reachable, states
in the configured FRI layout, the robot's clock advancing at a steady
sample time, a watchdog beside the stack (:mod:`robot.lbr.watchdog`), the
session, modes and drives, T1, ``open_loop``, the torque
filters, the connection quality, the joint names, the tool's load data and
the spring's preload at rest (:mod:`robot.lbr.rest_checks`). It sends
nothing. Exit 0 only if every check passes.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np

from arm.robot_model import RobotModel

from .arming import REST_SPEED_RAD_S
from .compensation import filter_alpha
from .msgs import (
    ClientCommandMode,
    ConnectionQuality,
    ControlMode,
    DriveState,
    LbrState,
    LbrWireError,
    OperationMode,
    SafetyState,
    SessionState,
    decode_joint_names,
    decode_state,
    enum_name,
)
from .params import LbrParams
from .rest_checks import load_note, pad_wrench, preload_refusal, spring_preload_nm
from .watchdog import WATCHDOG_SERVICE

#: How long the preflight listens to the states [s], and how long it waits for the first [s].
LISTEN_S = 1.0
FIRST_STATE_S = 5.0
#: The largest joint spring torque [Nm] at rest (FRI 1) the preflight passes.
SPRING_PRELOAD_MAX_NM = 2.0


@dataclass
class Check:
    """One line of the preflight: its name, whether it passed, what was seen, and the fix when it failed."""

    name: str
    ok: bool
    seen: str
    fix: str = ""

    def line(self) -> str:
        return f"{'PASS' if self.ok else 'FAIL'} {self.name}: {self.seen}" + ("" if self.ok else f"; fix: {self.fix}")


@dataclass
class Heard:
    """What the preflight heard: decoded states (arrival [monotonic ns], state), the first layout error, the
    joint names seen, whether the session reached a router or peer, and whether a watchdog's liveliness token
    (``alive/lbr-watchdog``) is there."""

    states: list[tuple[int, LbrState]]
    layout_error: str
    names: list[str] | None
    connected: bool
    watchdog: bool = False


def listen(p: LbrParams, session, listen_s: float = LISTEN_S, first_s: float = FIRST_STATE_S) -> Heard:
    """Subscribe to the stack's state and joint-state keys; wait up to ``first_s`` for a first state, then
    ``listen_s`` more."""
    lock = threading.Lock()
    heard = Heard([], "", None, False)
    first = threading.Event()

    def on_state(sample) -> None:
        try:
            st = decode_state(sample.payload.to_bytes(), p.fri_major)
        except LbrWireError as exc:
            with lock:
                heard.layout_error = heard.layout_error or str(exc)
            first.set()
            return
        with lock:
            heard.states.append((time.monotonic_ns(), st))
        first.set()

    def on_names(sample) -> None:
        try:
            names = decode_joint_names(sample.payload.to_bytes())
        except LbrWireError:
            return
        with lock:
            heard.names = list(names)

    t = p.topics
    subs = [session.declare_subscriber(t.key(t.state), on_state),
            session.declare_subscriber(t.key(t.joint_states), on_names)]
    try:
        if first.wait(first_s):
            time.sleep(listen_s)
        info = session.info
        heard.connected = bool(list(info.routers_zid()) or list(info.peers_zid()))
    finally:
        for sub in subs:
            sub.undeclare()
    with lock:
        return Heard(list(heard.states), heard.layout_error, heard.names, heard.connected)


def judge(p: LbrParams, heard: Heard, model: RobotModel | None = None) -> list[Check]:
    """The checks on what was heard, in order; later ones are left out when there is no state to judge."""
    key = p.topics.key(p.topics.state)
    out = [Check("bridge", heard.connected, "a Zenoh router or peer reached" if heard.connected else
                 "no Zenoh router or peer reached",
                 "run zenoh-bridge-ros2dds on the robot PC with its identity (secrets/bridge) and give this "
                 "--connect tls/<robot-pc>:7447 and LAMPS_ZENOH_IDENTITY=secrets/robot"),
           Check("watchdog", heard.watchdog, "lbr-watchdog is alive" if heard.watchdog else
                 "no lbr-watchdog liveliness token", "run lamps robot --backend lbr --watchdog on the robot PC "
                 "beside the bridge, with this robot id: it releases the arm if the adapter dies")]
    if heard.layout_error and not heard.states:
        out.append(Check("FRI layout", False, heard.layout_error, "set [lbr] fri_major to the stack's FRI SDK major"))
        return out
    if not heard.states:
        out.append(Check("states", False, f"no LBRState on {key}",
                         "launch the stack with ctrl:=lbr_torque_command_controller and start the LBRServer app "
                         "(the stack publishes from COMMANDING_WAIT on); check the bridge sees its DDS traffic "
                         "(same host, ROS_DOMAIN_ID, RMW_IMPLEMENTATION=rmw_cyclonedds_cpp)"))
        return out
    out.append(Check("FRI layout", True, f"FRI {p.fri_major} states on {key}"))
    states = [st for _, st in heard.states]
    st = states[-1]
    stamps = np.array([s.stamp_ns for s in states], dtype=np.int64)
    advanced = int(np.count_nonzero(np.diff(stamps) > 0))
    span_s = (heard.states[-1][0] - heard.states[0][0]) * 1e-9
    steady = len({s.sample_time_s for s in states}) == 1
    clock_ok = advanced >= max(2, len(states) // 4) and steady and bool(np.all(np.diff(stamps) >= 0))
    out.append(Check("robot clock", clock_ok,
                     f"{len(states)} states in {span_s:.2f} s, the time stamp advanced {advanced} times, sample "
                     f"time {sorted({s.sample_time_s * 1e3 for s in states})} ms",
                     "the states' time stamp stands or jumps: the FRI link is lost or unsteady (check the cable "
                     "and the robot PC's network; the stack's FRI socket waits for ever)"))
    modes = []
    if st.session_state != SessionState.COMMANDING_ACTIVE:
        modes.append((f"session {enum_name(SessionState, st.session_state)}", "start the LBRServer app"))
    if st.client_command_mode != ClientCommandMode.TORQUE:
        modes.append((f"client command mode {enum_name(ClientCommandMode, st.client_command_mode)}",
                      "choose TORQUE in the LBRServer app and client_command_mode: torque in the stack's config"))
    if st.control_mode != ControlMode.JOINT_IMP_CONTROL_MODE:
        modes.append((f"control mode {enum_name(ControlMode, st.control_mode)}",
                      "choose JOINT_IMPEDANCE_CONTROL in the LBRServer app"))
    if st.safety_state != SafetyState.NORMAL_OPERATION or st.drive_state != DriveState.ACTIVE:
        modes.append((f"safety {enum_name(SafetyState, st.safety_state)}, drives "
                      f"{enum_name(DriveState, st.drive_state)}", "clear the safety stop, enable the drives"))
    out.append(Check("modes", not modes, "; ".join(m for m, _ in modes) or
                     "COMMANDING_ACTIVE, TORQUE, JOINT_IMPEDANCE_CONTROL, drives active",
                     "; ".join(f for _, f in modes)))
    out.append(Check("T1", st.operation_mode == OperationMode.TEST_MODE_1,
                     f"operation mode {enum_name(OperationMode, st.operation_mode)}",
                     "turn the smartPAD's mode key to T1 for the bring-up (reduced speed, enabling switch)"))
    # (the stack's own open_loop is not in its state: before any message it re-initialises its command at the
    # measured position every cycle, so measured and commanded agree either way; the adapter's FreezeWatch judges
    # it once commanding)
    out.append(Check("open_loop", not p.open_loop, f"[lbr] open_loop = {str(p.open_loop).lower()}",
                     "set open_loop: false in the stack's config and [lbr] open_loop = false"))
    bad = [f"{n} {c:g} Hz" for n, c in (("measured_torque_cutoff_hz", p.measured_torque_cutoff_hz),
                                         ("external_torque_cutoff_hz", p.external_torque_cutoff_hz))
           if filter_alpha(c, st.sample_time_s) <= 1e-9]
    out.append(Check("torque filter", not bad, ", ".join(bad) + " give alpha 0 at this sample time" if bad else
                     f"alpha > 0 at {st.sample_time_s * 1e3:g} ms",
                     "set the stack's *_torque_cutoff_frequency below the sample rate and tell [lbr] the same"))
    q = st.connection_quality
    out.append(Check("connection quality", q >= ConnectionQuality.GOOD, enum_name(ConnectionQuality, q),
                     "GOOD or better is needed for commanding: a direct cable, no switch, the robot PC's network "
                     "card to itself, a real-time kernel"))
    names_ok = heard.names is not None and tuple(heard.names) == p.joint_names
    out.append(Check("joint names", names_ok, (f"{heard.names}" if heard.names is not None else "no joint_states") +
                     ("" if names_ok else f", [lbr] expects {list(p.joint_names)}"),
                     f"set [lbr] branch (or joint_names) to the stack's: {heard.names}"))
    out.extend(_rest_checks(p, heard, model or RobotModel()))
    return out


def _rest_checks(p: LbrParams, heard: Heard, model: RobotModel) -> list[Check]:
    """The tool's load data and the spring's preload, on the newest state, if the arm is at rest."""
    st, st0 = heard.states[-1][1], heard.states[0][1]
    dt = max((st.stamp_ns - st0.stamp_ns) * 1e-9, st.sample_time_s)
    speed = float(np.max(np.abs(st.q_rad - st0.q_rad))) / dt
    if speed > REST_SPEED_RAD_S:
        why = f"the arm moves ({speed:.2f} rad/s)"
        return [Check(n, False, why, "bring the arm to rest and run the preflight again")
                for n in ("load data", "spring preload")]
    w = pad_wrench(model, st.q_rad, st.tau_external_nm)
    note = load_note(w, p.tool_mass_kg, p.tool_mass_tolerance_kg)
    out = [Check("load data", note is None, (note or "").split(": set")[0] or "the external torque at rest agrees "
                 f"with [lbr] tool_mass_kg = {p.tool_mass_kg:g} kg",
                 "set the tool's load data on the smartPAD (mass, centre of mass) to the tool the arm carries, and "
                 "[lbr] tool_mass_kg to its mass")]
    spring = spring_preload_nm(st.q_rad, st.q_commanded_rad, np.array(p.joint_stiffness_nm_rad))
    press = preload_refusal(w, p.arm_preload_max_n, p.tool_mass_kg)
    spring_ok = spring is None or spring <= SPRING_PRELOAD_MAX_NM
    seen = press or (f"pad force {np.linalg.norm(w[:3]):.1f} N" +
                     (f", joint spring {spring:.2f} Nm" if spring is not None else " (FRI 2: no commanded position)"))
    out.append(Check("spring preload", press is None and spring_ok, seen if spring_ok or press else
                     f"joint spring {spring:.2f} Nm at rest (over {SPRING_PRELOAD_MAX_NM:g})",
                     "stop and start the LBRServer app and relaunch the stack (its command starts at the measured "
                     "pose)"))
    return out


def run_preflight(p: LbrParams, node) -> int:
    """Listen, judge, print each check; 0 if all pass, else 1."""
    heard = listen(p, node.session)
    heard.watchdog = WATCHDOG_SERVICE in node.alive_services(0.5)
    checks = judge(p, heard)
    for c in checks:
        print(c.line(), flush=True)
    failed = [c.name for c in checks if not c.ok]
    print(f"preflight: {len(checks) - len(failed)} of {len(checks)} passed" +
          (f"; failed: {', '.join(failed)}" if failed else ""), flush=True)
    return 1 if failed else 0
