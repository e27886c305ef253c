"""The transport's floor for the real-time controller loop: the controller's loop with a minimal tick.

Usage (started by ``bench/bench_controller.py``): ``python bench/minimal_controller.py --connect EP
--robot-id ID --seconds S``; prints one JSON line of figures at the end.

The same process set-up as ``lamps controller --mode realtime`` (nice -10, the loop thread under
:class:`~runtime.loop_hygiene.LoopHygiene`: SCHED_FIFO, locked memory, the collector in the slack),
the same Zenoh readers and writers (an ``Inbox`` of the newest ``RobotState``, ``TorqueCommand`` with the
control path's QoS), the same answer-each-state-as-it-comes loop; the tick only copies zeros into the
command (the robot side must compensate gravity: ``lamps sim --gravity-compensated``). What the real
controller adds over this is its tick.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from interfaces.messages import RobotState, TorqueCommand  # noqa: E402
from runtime.config import ZenohSettings  # noqa: E402
from runtime.loop_hygiene import LoopHygiene  # noqa: E402
from runtime.priority import REALTIME, set_service_priority  # noqa: E402
from runtime.session import ServiceNode  # noqa: E402
from runtime.stop_signals import on_stop_signals  # noqa: E402


def run(connect: str, robot_id: str, seconds: float) -> dict:
    set_service_priority(REALTIME)
    stop = threading.Event()
    on_stop_signals(stop, signals=(signal.SIGTERM,))
    with ServiceNode("controller", ZenohSettings(connect=(connect,), robot_id=robot_id)) as node:
        states = node.inbox(node.keys.robot_state, RobotState, maxlen=1)
        periods_us = np.zeros(int(seconds * 1200) + 100)  # every period of the run (1 kHz, margin)
        n = overruns = 0
        counts: dict[str, int] = {}
        hygiene = LoopHygiene(counts=counts)
        hygiene.start(realtime=True)
        zeros = [0.0] * 7
        answered, t_prev, t_end = -1, None, None
        try:
            while not stop.is_set():
                state = states.get(0.001)
                t0 = time.monotonic_ns()
                if state is None:
                    continue
                if t_end is None:
                    t_end = t0 + int(seconds * 1e9)  # from the first state on
                elif t0 > t_end:
                    break
                if answered >= 0 and state.seq > answered + 1:
                    overruns += state.seq - answered - 1  # robot states never answered
                node.publish(node.keys.robot_command, TorqueCommand(seq=state.seq, stamp_ns=state.stamp_ns,
                                                                    tau_nm=zeros))
                answered = state.seq
                if t_prev is not None and n < len(periods_us):
                    periods_us[n] = (t0 - t_prev) / 1e3
                    n += 1
                t_prev = t0
                hygiene.collect_due(int(1e6) - (time.monotonic_ns() - t0))
        finally:
            hygiene.stop()
    p = periods_us[:n]
    return {"period_p50_us": float(np.percentile(p, 50)), "period_p99_us": float(np.percentile(p, 99)),
            "period_max_us": float(p.max()), "ticks": n + 1, "overruns": overruns,
            "overruns_per_10k": 1e4 * overruns / max(n + 1, 1), "counters": counts}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--connect", required=True)
    ap.add_argument("--robot-id", required=True)
    ap.add_argument("--seconds", type=float, default=60.0)
    a = ap.parse_args()
    print(json.dumps(run(a.connect, a.robot_id, a.seconds)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
