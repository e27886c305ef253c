"""What authentication, access control and mutual TLS cost the 1 kHz exchange: state -> command round trip.

Usage: .venv/bin/python bench/bench_zenoh_security.py [--quick] [--json OUT]

Two sessions on loopback play the robot side and the controller: the robot
side publishes a 7-joint ``RobotState``, the controller answers each with a
``TorqueCommand`` (``ServiceNode`` publishers and an ``Inbox`` on each side,
what the services use). The round trip (state published -> its answer
received) is timed with ``perf_counter_ns`` over N exchanges after a
warm-up, for each way a cell can join:

- baseline ``plain TCP``: no authentication (how the benchmarks of the
  real-time cell run);
- ``mutual TLS``: each side's role identity from ``lamps credentials``
  (the links encrypted and both ends checked);
- ``mutual TLS + access list``: the cell's default-deny list checked on
  every sample sent and received (the default under compose and
  ``lamps up``);
- ``through lamps router``: both sides clients of ``lamps router`` (a
  process of its own, the router identity, the access list checked at the
  router and at each client): one hop more.

The table gives p50, p99 and mean [us] and each p50 and mean over the baseline's,
measured in the same run, the cases interleaved in rounds (the machine's
speed drifts).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from interfaces.messages import Capabilities, RobotState, TorqueCommand  # noqa: E402
from runtime.config import ZenohSettings  # noqa: E402
from runtime.credentials import identity_folder, make_credentials  # noqa: E402
from runtime.ports import free_port  # noqa: E402
from runtime.session import ServiceNode  # noqa: E402


def _settings(role: str, rid: str, port: int, listen: bool, secrets: Path, acl: bool, tls: bool) -> ZenohSettings:
    ep = f"{'tls' if tls else 'tcp'}/127.0.0.1:{port}"
    kw: dict = {"listen": (ep,)} if listen else {"connect": (ep,)}
    if tls:
        kw.update(identity=str(identity_folder(secrets, role)), access_control=acl)
    return ZenohSettings(robot_id=rid, **kw)


def _router(rid: str, port: int, secrets: Path):
    """``lamps router`` as a process on ``port`` with the router identity and access list; once it listens."""
    import os
    import socket
    import subprocess

    env = {**os.environ, "LAMPS_ROBOT_ID": rid, "LAMPS_ZENOH_ACCESS_CONTROL": "true",
           "LAMPS_ZENOH_IDENTITY": str(identity_folder(secrets, "router"))}
    proc = subprocess.Popen([sys.executable, "-m", "runtime.cli", "router", "--listen", f"tls/127.0.0.1:{port}",
                             "--status-s", "0"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return proc
        time.sleep(0.1)
    proc.kill()
    raise RuntimeError("lamps router did not come up")


def _round_trips(n: int, warmup: int, secrets: Path, acl: bool, tls: bool, router: bool = False) -> np.ndarray:
    port = free_port()
    rid = f"b{port}"
    proc = None
    if router:
        proc = _router(rid, port, secrets)
        client = dict(mode="client", connect=(f"tls/127.0.0.1:{port}",), listen=())
        robot = ServiceNode("robot", replace(_settings("robot", rid, port, False, secrets, acl, tls), **client))
        ctl = ServiceNode("controller", replace(_settings("controller", rid, port, False, secrets, acl, tls),
                                                **client))
        robot.__enter__()
        ctl.__enter__()
    else:
        robot = ServiceNode("robot", _settings("robot", rid, port, True, secrets, acl, tls)).__enter__()
        ctl = ServiceNode("controller", _settings("controller", rid, port, False, secrets, acl, tls)).__enter__()
    try:
        keys = robot.keys
        answers = robot.inbox(keys.robot_command, TorqueCommand, maxlen=16)
        states = ctl.inbox(keys.robot_state, RobotState, maxlen=16)
        caps = Capabilities(True, [100.0] * 7)
        out = np.zeros(n)
        for i in range(-warmup - 200, n):  # the first 200 also wait for the subscriptions to propagate
            st = RobotState(seq=i + warmup + 200, stamp_ns=0, q_rad=[0.1] * 7, dq_rad_s=[0.0] * 7, tau_nm=[0.0] * 7,
                            wrench_world=[0.0] * 6, capabilities=caps)
            t0 = time.perf_counter_ns()
            robot.publish(keys.robot_state, st)
            got = states.get(0.05 if i < -warmup else 1.0)
            if got is None:
                if i < -warmup:
                    continue
                raise RuntimeError("a state was lost on loopback")
            ctl.publish(keys.robot_command, TorqueCommand(seq=got.seq, stamp_ns=0, tau_nm=[0.0] * 7,
                                                          session="bench"))
            ans = answers.get(1.0)
            if ans is None:
                raise RuntimeError("an answer was lost on loopback")
            if i >= 0:
                out[i] = (time.perf_counter_ns() - t0) / 1e3
        return out
    finally:
        ctl.close()
        robot.close()
        if proc is not None:
            proc.terminate()
            proc.wait(10)


#: Rounds over all cases; each measures N / ROUNDS exchanges per case with a fresh pair of sessions.
ROUNDS = 5
CASES = (("plain TCP (baseline)", False, False, False), ("mutual TLS", False, True, False),
         ("mutual TLS + access list (the default)", True, True, False),
         ("through lamps router (mutual TLS + access lists, both sides its clients)", True, True, True))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json")
    a = ap.parse_args()
    n, warmup = (500, 50) if a.quick else (5000, 200)
    with tempfile.TemporaryDirectory() as tmp:
        secrets = Path(tmp)
        make_credentials(secrets)
        samples: dict[str, list[np.ndarray]] = {c[0]: [] for c in CASES}
        rng = np.random.default_rng(0)
        for _ in range(ROUNDS):  # the cases interleaved, in a new order each round: drift hits them alike
            for k in rng.permutation(len(CASES)):
                name, acl, tls, router = CASES[k]
                samples[name].append(_round_trips(n // ROUNDS, warmup, secrets, acl, tls, router))
        rows = []
        for name, parts in samples.items():
            rt = np.concatenate(parts)
            rows.append((name, float(np.percentile(rt, 50)), float(np.percentile(rt, 99)), float(rt.mean())))
    base, base50 = rows[0][3], rows[0][1]
    print(f"state -> command round trip on loopback, two sessions in one process, {n} exchanges per case "
          f"in {ROUNDS} interleaved rounds, "
          f"{platform.machine()}, python {platform.python_version()}\n")
    print("| joining as | p50 [us] | p99 [us] | mean [us] | p50 / baseline p50 | mean / baseline mean |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, p50, p99, mean in rows:
        print(f"| {name} | {p50:.0f} | {p99:.0f} | {mean:.0f} | {p50 / base50:.2f} | {mean / base:.2f} |")
    if a.json:
        Path(a.json).write_text(json.dumps({"n": n, "cases": [
            {"name": r[0], "p50_us": r[1], "p99_us": r[2], "mean_us": r[3], "ratio": r[3] / base} for r in rows]}))


if __name__ == "__main__":
    main()
