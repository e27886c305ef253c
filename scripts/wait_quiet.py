"""Wait until the machine is quiet before the tests that need it to themselves (``./run-tests``' alone run).

The alone tests run 1 kHz loops on the wall clock; started straight after the 2-worker run, the first of them can
meet a machine still busy with what that run left behind (containers stopping, processes exiting, caches written),
and a starved real-time controller faults on overload before any test has loaded it. This waits until the CPUs
are idle for a few seconds in a row (``/proc/stat``), at most ``--timeout`` seconds, and says what it waited for;
if the machine does not settle it names the busiest processes and lets the tests run anyway (exit 0): a busy
machine is worth knowing, not a failure of the code under test.

Usage: ``python scripts/wait_quiet.py [--idle 0.8] [--seconds 3] [--timeout 120]``. Linux only (elsewhere it
returns at once).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time


def cpu_times() -> tuple[int, int]:
    """(idle, total) jiffies of all CPUs since boot, from the first line of /proc/stat."""
    with open("/proc/stat") as f:
        fields = [int(v) for v in f.readline().split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
    return idle, sum(fields)


def idle_share(window_s: float) -> float:
    """The share of CPU time idle over the next ``window_s`` seconds (0-1)."""
    i0, t0 = cpu_times()
    time.sleep(window_s)
    i1, t1 = cpu_times()
    return (i1 - i0) / max(1, t1 - t0)


def busiest(n: int = 8) -> str:
    """The ``n`` processes using the most CPU, as ``ps`` prints them."""
    try:
        out = subprocess.run(["ps", "-eo", "pid,pcpu,etimes,args", "--sort=-pcpu"], capture_output=True,
                             text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        return f"(ps failed: {exc})"
    return "\n".join(line[:200] for line in out.splitlines()[: n + 1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--idle", type=float, default=0.8, help="idle share that counts as quiet (0-1)")
    ap.add_argument("--seconds", type=int, default=3, help="quiet seconds in a row needed")
    ap.add_argument("--timeout", type=float, default=120.0, help="give up after this many seconds")
    a = ap.parse_args(argv)
    if not sys.platform.startswith("linux"):
        return 0
    start, quiet, shares, at_start = time.monotonic(), 0, [], ""
    while quiet < a.seconds:
        share = idle_share(1.0)
        shares.append(share)
        quiet = quiet + 1 if share >= a.idle else 0
        if len(shares) == 1 and share < a.idle:
            at_start = busiest()
        if time.monotonic() - start > a.timeout:
            print(f"wait_quiet: the CPUs did not settle in {a.timeout:.0f} s (idle {share:.0%} over the last second, "
                  f"{a.idle:.0%} asked); the busiest processes:\n{busiest()}", file=sys.stderr)
            return 0
    print(f"wait_quiet: {len(shares)} s until {a.seconds} s in a row at >= {a.idle:.0%} idle "
          f"(first second {shares[0]:.0%} idle)" + (f"; busy at the start:\n{at_start}" if at_start else ""),
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
