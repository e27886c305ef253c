"""The real-robot path against the plain simulator, in one run: the adapter's added latency and the controller's loop.

Usage: .venv/bin/python bench/bench_robot_port.py [--quick] [--json OUT]

1. The adapter's added latency, in-process over loopback Zenoh: a "stack"
   session puts a CDR ``LBRState`` on ``lbr/state`` every millisecond and
   times until the ``LBRTorqueCommand`` answering it comes back on
   ``lbr/command/torque``, through ``lamps robot``'s server and LbrPort
   (armed) and an "echo controller" session that answers each RobotState
   at once. Baseline in the same run: the same stack talking to an echo
   that answers the CDR state with a CDR command directly (the transport's
   own floor for the extra hop). Added latency = the difference, p50 / p99.
2. The controller's loop through each path, real time over Zenoh (20 s,
   10 s with --quick): ``lamps sim`` + ``lamps controller`` against
   ``lamps lbr-peer`` + ``lamps robot --backend lbr --arm`` + the same
   controller, both ``--mode realtime``, stains from the truth, no camera:
   the controller's period p50 / p99 / max, overruns per 10,000 ticks, the
   robot side's round trip as the adapter sees it (state published -> its
   answer forwarded) and its late cycles.
3. Lock-step through each path: simulated seconds per wall second.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import zenoh  # noqa: E402
from bench_controller import bench_lockstep, bench_realtime  # noqa: E402
from service_procs import BenchError, free_port  # noqa: E402

from interfaces.messages import RobotState, TorqueCommand  # noqa: E402
from robot.lbr.adapter import LbrPort  # noqa: E402
from robot.lbr.msgs import LbrState, decode_state, encode_state, encode_torque_command  # noqa: E402
from robot.lbr.params import LbrParams  # noqa: E402
from robot.server import RobotServer, ServerParams  # noqa: E402
from runtime.config import ZenohSettings  # noqa: E402
from runtime.session import ServiceNode, zenoh_config  # noqa: E402

Q0 = np.array([0.0, 0.6, 0.0, -1.4, 0.0, 0.8, 0.0])


def _state(k: int) -> bytes:
    return encode_state(LbrState(0.001, 4, 0, 0, 2, 3, 2, 1_000_000_000 + k * 1_000_000, Q0, np.zeros(7),
                                 np.zeros(7)))


def _round_trips(stack: zenoh.Session, n: int) -> np.ndarray:
    """(n,) microseconds from putting state k on lbr/state to the command coming back, one state per ms."""
    got = threading.Event()
    out = np.full(n, np.nan)
    sent = [0]
    sub = stack.declare_subscriber("lbr/command/torque", lambda s: got.set())
    pub = stack.declare_publisher("lbr/state")
    time.sleep(0.5)  # the matching routes are declared by now on loopback; the first samples are warm-up
    for k in range(n + 50):
        got.clear()
        sent[0] = time.perf_counter_ns()
        pub.put(_state(k))
        if got.wait(0.05) and k >= 50:
            out[k - 50] = (time.perf_counter_ns() - sent[0]) / 1e3
        time.sleep(max(0.0, 0.001 - (time.perf_counter_ns() - sent[0]) / 1e9))
    sub.undeclare()
    pub.undeclare()
    return out


def bench_adapter_latency(n: int) -> dict:
    p_adapter, p_floor = free_port(), free_port()
    rid = f"bench{p_adapter}"
    # through the adapter: stack -> LbrPort/RobotServer -> echo controller -> adapter -> stack
    node = ServiceNode("robot", ZenohSettings(listen=(f"tcp/127.0.0.1:{p_adapter}",), robot_id=rid)).__enter__()
    port = LbrPort(LbrParams(arm=True, hold_timeout_s=5.0), node)
    server = RobotServer(port, node, ServerParams(mode="realtime", stale_limit_s=0.02), "robot",
                         node.keys.robot_status)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    ctl = ServiceNode("controller", ZenohSettings(connect=(f"tcp/127.0.0.1:{p_adapter}",), robot_id=rid)).__enter__()
    ctl_pub = ctl.session.declare_publisher(ctl.keys.robot_command)
    from interfaces.codec import Decoder, encode

    decode = Decoder(RobotState)
    zero = [0.0] * 7
    echo_sub = ctl.session.declare_subscriber(ctl.keys.robot_state, lambda s: ctl_pub.put(encode(TorqueCommand(
        seq=decode(s.payload.to_bytes()).seq, stamp_ns=0, tau_nm=zero))))
    stack = zenoh.open(zenoh_config(ZenohSettings(connect=(f"tcp/127.0.0.1:{p_adapter}",))))
    try:
        via_adapter = _round_trips(stack, n)
    finally:
        stack.close()
        server.stop.set()
        thread.join(5.0)
        echo_sub.undeclare()
        ctl.close()
        port.close()
        node.close()
    # the floor: stack -> CDR echo -> stack, one Zenoh hop each way, the same encode / decode work
    echo = zenoh.open(zenoh_config(ZenohSettings(listen=(f"tcp/127.0.0.1:{p_floor}",))))
    cmd_pub = echo.declare_publisher("lbr/command/torque")
    zeros = np.zeros(7)
    floor_sub = echo.declare_subscriber("lbr/state", lambda s: cmd_pub.put(encode_torque_command(
        decode_state(s.payload.to_bytes()).q_rad, zeros)))
    stack = zenoh.open(zenoh_config(ZenohSettings(connect=(f"tcp/127.0.0.1:{p_floor}",))))
    try:
        floor = _round_trips(stack, n)
    finally:
        stack.close()
        floor_sub.undeclare()
        echo.close()
    a, f = via_adapter[np.isfinite(via_adapter)], floor[np.isfinite(floor)]
    if len(a) < n // 2 or len(f) < n // 2:
        raise BenchError(f"too few round trips came back (adapter {len(a)}, floor {len(f)} of {n})")
    pa, pf = np.percentile(a, [50, 99]), np.percentile(f, [50, 99])
    return {"n": n, "adapter_p50_us": float(pa[0]), "adapter_p99_us": float(pa[1]), "floor_p50_us": float(pf[0]),
            "floor_p99_us": float(pf[1]), "added_p50_us": float(pa[0] - pf[0]), "added_p99_us": float(pa[1] - pf[1]),
            "lost_adapter": int(n - len(a)), "lost_floor": int(n - len(f))}


def print_report(res: dict, cmd: str) -> None:
    lat = res["latency"]
    print(f"Real-robot path vs plain sim ({res['machine']})\n")
    print(f"| adapter round trip (stack state in -> torque command out, echo controller), {lat['n']} cycles "
          "| p50 us | p99 us |\n|---|---:|---:|")
    print(f"| through lamps robot --backend lbr (decode, velocity, wrench, RobotState, gate, guards, encode) | "
          f"{lat['adapter_p50_us']:.0f} | {lat['adapter_p99_us']:.0f} |")
    print(f"| baseline: a direct CDR echo (the transport's floor) | {lat['floor_p50_us']:.0f} | "
          f"{lat['floor_p99_us']:.0f} |")
    print(f"| **added by the adapter** | **{lat['added_p50_us']:.0f}** | **{lat['added_p99_us']:.0f}** |")
    rt = res["realtime"]
    print(f"\n| real time over Zenoh, {rt['sim']['duration_s']:.0f} s each | plain sim | lbr peer + adapter |"
          "\n|---|---:|---:|")
    rows = [("controller period p50 us", "period_p50_us_median", ".0f"),
            ("controller period p99 us (max of windows)", "period_p99_us_max", ".0f"),
            ("controller period max us", "period_max_us", ".0f"),
            ("controller overruns per 10,000 ticks", "overruns_per_10k", ".1f")]
    for label, key, spec in rows:
        print(f"| {label} | {format(rt['sim'][key], spec)} | {format(rt['lbr'][key], spec)} |")
    print(f"| controller final phase | {rt['sim']['phase']} | {rt['lbr']['phase']} |")
    c = rt["lbr"]["robot_counters"] or {}
    print(f"| robot side: state -> answer forwarded p50 / p99 us | - | {c.get('answer_latency_p50_us', 'n/a')} / "
          f"{c.get('answer_latency_p99_us', 'n/a')} |")
    print(f"| robot side: late cycles (held) / answers forwarded | {rt['sim']['stale_command_brakes']} stale brakes | "
          f"{c.get('commands_late', 0)} / {c.get('commands_sent', 0)} |")
    lk = res["lockstep"]
    print("\n| lock-step over Zenoh | plain sim | lbr peer + adapter |\n|---|---:|---:|")
    print(f"| simulated s per wall s | {lk['sim']['x_realtime']:.2f} | {lk['lbr']['x_realtime']:.2f} |")
    print(f"| controller period (round trip) p50 us | {lk['sim']['period_p50_us_median']:.0f} | "
          f"{lk['lbr']['period_p50_us_median']:.0f} |")
    print(f"\ncpu count {os.cpu_count()}, Python {platform.python_version()}, {platform.machine()}")
    print(f"reproduce: {cmd}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="shorter runs")
    ap.add_argument("--json", metavar="OUT", help="also write the figures as JSON")
    a = ap.parse_args()
    cmd = ".venv/bin/python bench/bench_robot_port.py" + (" --quick" if a.quick else "")
    res = {"machine": f"{platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"}
    duration = 10.0 if a.quick else 20.0
    try:
        res["latency"] = bench_adapter_latency(1000 if a.quick else 3000)
        res["realtime"] = {robot: bench_realtime(duration, robot) for robot in ("sim", "lbr")}
        res["lockstep"] = {robot: bench_lockstep(duration, robot) for robot in ("sim", "lbr")}
    except BenchError as exc:
        print(f"bench_robot_port: {exc}", file=sys.stderr)
        return 1
    print_report(res, cmd)
    if a.json:
        from lampskit.atomic import write_text_atomic

        write_text_atomic(Path(a.json), json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
