"""Real-time scheduling, locked memory and CPU affinity for the thread of a 1 kHz loop.

Nice values (:mod:`runtime.priority`) only weigh the fair scheduler's
shares: a nice -10 loop that wakes while another process runs still waits
for that process's slice to end. A thread under ``SCHED_FIFO`` preempts
every ordinary thread the moment it wakes, which is what a loop owing the
robot an answer every millisecond needs; it sleeps between periods, so the
others keep the CPU meanwhile (and the kernel's real-time throttling keeps
5 % for them should a loop ever spin).

The process's other threads are raised too, one priority below the loop
(``SCHED_FIFO`` 9 by default): Zenoh's runtime threads hand the loop its
states and commands, and they run our Python callbacks, holding the
interpreter's lock while they do. Left under the fair scheduler, such a
thread preempted by any busy process while it holds the lock stalls the
real-time loop behind it (a priority inversion the lock does not resolve).
Measured on the 2-core cell, ``--robot lbr-sim --mode realtime`` beside a
busy process: with the loop's thread alone raised the adapter's loop stood
still for up to 83 ms, 23 % of the FRI states went unanswered in time, 61
stale-command brakes, and the robot, repeating the last torque meanwhile as
the stack does, sped its wrist past the adapter's guard; with the others
raised, 4-5 % and 1-4 brakes, and 4 of 5 runs complete. Threads doing long
computations (the controller's planner) register with :func:`keep_fair`
and stay where they are: as ``SCHED_FIFO`` threads they would hold a core
against every ordinary process for a whole plan. Threads started later by
a raised thread inherit its scheduling.

:func:`apply_realtime` is called by :class:`~runtime.loop_hygiene.LoopHygiene`
on the loop's thread when the loop starts. What it asks for, from the
environment (one service at a time, like ``LAMPS_NICE``):

* ``LAMPS_RT_PRIORITY``: ``SCHED_FIFO`` priority 1-98 for the loop's thread
  (default :data:`DEFAULT_PRIORITY`), or ``off``. Needs ``CAP_SYS_NICE``
  (root, or ``cap_add: [SYS_NICE]`` under compose).
* ``LAMPS_RT_IO``: ``on`` (default) raises the process's other threads to
  ``SCHED_FIFO`` one below the loop's priority (see above), ``off`` leaves
  them under the fair scheduler.
* ``LAMPS_MLOCK``: ``on`` (default) locks the process's memory
  (``mlockall(MCL_CURRENT | MCL_FUTURE)``: no page fault in the loop waits
  for the disk), ``off`` does not. Needs ``CAP_IPC_LOCK`` or a memlock
  limit above the process's size (compose: ``ulimits: memlock: -1``).
* ``LAMPS_CPUS``: CPUs the loop's thread may run on, e.g. ``1`` or ``2,3``
  (default: any; on a machine with a core to spare, give each loop its own).

A refusal by the operating system is reported (the returned text goes into
the service's status), never raised; a malformed value is a ConfigError
naming the variable.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import os
import sys
import threading
from dataclasses import dataclass

from interfaces.errors import ConfigError

log = logging.getLogger(__name__)

#: SCHED_FIFO priority of a loop's thread: above ordinary threads, far below the kernel's own (50: IRQ threads).
DEFAULT_PRIORITY = 10
_MCL_CURRENT, _MCL_FUTURE = 1, 2
#: Native ids of threads that must stay under the fair scheduler (:func:`keep_fair`).
_FAIR: set[int] = set()
_FAIR_LOCK = threading.Lock()


def keep_fair() -> None:
    """Call on a thread that runs long computations (a planner): :func:`apply_realtime` will not raise it to
    ``SCHED_FIFO`` with the process's I/O threads."""
    with _FAIR_LOCK:
        _FAIR.add(threading.get_native_id())


@dataclass(frozen=True)
class RealtimeRequest:
    """What a loop's thread asks for. priority : SCHED_FIFO priority (None: stay SCHED_OTHER); lock_memory :
    mlockall; cpus : allowed CPUs (None: any); io_threads : the process's other threads to SCHED_FIFO one
    below ``priority`` (those not kept fair)."""

    priority: int | None = DEFAULT_PRIORITY
    lock_memory: bool = True
    cpus: frozenset[int] | None = None
    io_threads: bool = True

    @classmethod
    def from_env(cls, env: dict | os._Environ | None = None) -> RealtimeRequest:
        """Read ``LAMPS_RT_PRIORITY``, ``LAMPS_RT_IO``, ``LAMPS_MLOCK`` and ``LAMPS_CPUS``; ConfigError names a
        bad one."""
        env = os.environ if env is None else env
        text = env.get("LAMPS_RT_PRIORITY", "").strip().lower()
        priority: int | None = DEFAULT_PRIORITY
        if text == "off":
            priority = None
        elif text:
            try:
                priority = int(text)
            except ValueError:
                priority = -1
            if not 1 <= priority <= 98:
                raise ConfigError(f"LAMPS_RT_PRIORITY must be an integer from 1 to 98 or 'off', got {text!r}")
        mlock = env.get("LAMPS_MLOCK", "").strip().lower() or "on"
        if mlock not in ("on", "off"):
            raise ConfigError(f"LAMPS_MLOCK must be 'on' or 'off', got {mlock!r}")
        io = env.get("LAMPS_RT_IO", "").strip().lower() or "on"
        if io not in ("on", "off"):
            raise ConfigError(f"LAMPS_RT_IO must be 'on' or 'off', got {io!r}")
        cpus_text = env.get("LAMPS_CPUS", "").strip()
        cpus = None
        if cpus_text:
            try:
                cpus = frozenset(int(c) for c in cpus_text.split(","))
            except ValueError:
                cpus = frozenset({-1})
            if not cpus or min(cpus) < 0:
                raise ConfigError(f"LAMPS_CPUS must be CPU numbers separated by commas (e.g. 1 or 2,3), "
                                  f"got {cpus_text!r}")
        return cls(priority, mlock == "on", cpus, io == "on")


def _libc():
    return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)


@dataclass(frozen=True)
class RealtimeResult:
    """What :func:`apply_realtime` got. fifo_priority : the thread's SCHED_FIFO priority (0: SCHED_OTHER);
    memory_locked : mlockall succeeded; report : one line saying it all, refusals with their reason;
    io_threads_fifo : the process's other threads raised to SCHED_FIFO."""

    fifo_priority: int
    memory_locked: bool
    report: str
    io_threads_fifo: int = 0

    def counters(self) -> dict[str, int]:
        """For a service's status counters."""
        return {"loop_sched_fifo_priority": self.fifo_priority, "loop_memory_locked": int(self.memory_locked),
                "io_threads_sched_fifo": self.io_threads_fifo}


def apply_realtime(request: RealtimeRequest | None = None) -> RealtimeResult:
    """Apply ``request`` (default: from the environment) to the calling thread and process; the report reads
    e.g. ``"SCHED_FIFO 10; memory locked"`` or ``"SCHED_OTHER (asked FIFO 10: refused, needs CAP_SYS_NICE);
    ..."``. Not on Linux: nothing applied, and said."""
    request = RealtimeRequest.from_env() if request is None else request
    if not sys.platform.startswith("linux"):
        return RealtimeResult(0, False, f"real-time scheduling: not on Linux ({sys.platform})")
    fifo = _fifo(request.priority)
    parts = [fifo]
    raised = 0
    if fifo.startswith("SCHED_FIFO") and request.priority is not None:
        if request.io_threads:
            raised, text = _raise_others(max(1, request.priority - 1))
        else:
            text = "other threads fair (LAMPS_RT_IO=off)"
        parts.append(text)
    mlock = _mlock(request.lock_memory)
    parts.append(mlock)
    if request.cpus is not None:
        parts.append(_affinity(request.cpus))
    report = "; ".join(parts)
    log.info("loop thread: %s", report)
    fifo_priority = request.priority if request.priority is not None and fifo.startswith("SCHED_FIFO") else 0
    return RealtimeResult(fifo_priority, mlock == "memory locked",
                          report, raised)


def apply_relay_realtime(request: RealtimeRequest | None = None) -> RealtimeResult:
    """For a process with no loop of its own that relays the loops' messages (``lamps router``): every thread of
    the process, the calling one too, to ``SCHED_FIFO`` one below the loop's priority, as a service's I/O threads
    (``LAMPS_RT_PRIORITY``; ``off``: all stay fair), and memory locked (``LAMPS_MLOCK``). Each state and command
    of a routed cell passes through it: left fair, it waits behind every ordinary process while the loops it
    serves run ``SCHED_FIFO``, and on a 2-core cell the routed round trip reached 29-64 periods at its 99th
    percentile and 144 at its worst (docs/benchmarks.md). Call after the Zenoh session is open (its threads
    exist)."""
    request = RealtimeRequest.from_env() if request is None else request
    if not sys.platform.startswith("linux"):
        return RealtimeResult(0, False, f"real-time scheduling: not on Linux ({sys.platform})")
    if request.priority is None:
        parts = ["threads fair (LAMPS_RT_PRIORITY=off)"]
        raised = 0
    else:
        priority = max(1, request.priority - 1)
        fifo = _fifo(priority)
        raised, text = _raise_others(priority) if fifo.startswith("SCHED_FIFO") else (0, fifo)
        raised += fifo.startswith("SCHED_FIFO")
        parts = [text if raised else fifo]
    parts.append(_mlock(request.lock_memory))
    report = "; ".join(parts)
    log.info("relay threads: %s", report)
    return RealtimeResult(0, parts[-1] == "memory locked", report, raised)


def _raise_others(priority: int) -> tuple[int, str]:
    """Every thread of this process but the calling one and those kept fair to ``SCHED_FIFO`` ``priority``;
    (how many, the report's words)."""
    me = threading.get_native_id()
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError as exc:
        return 0, f"other threads fair (/proc/self/task: {exc.strerror or exc})"
    with _FAIR_LOCK:
        fair = set(_FAIR)
    raised, failed = 0, []
    for tid in tids:
        if tid == me or tid in fair:
            continue
        try:
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
            raised += 1
        except ProcessLookupError:
            continue  # ended meanwhile
        except OSError as exc:
            failed.append(exc.strerror or str(exc))
    kept = len(fair & set(tids))
    text = f"other threads SCHED_FIFO {priority}: {raised}" + (f", {kept} kept fair" if kept else "")
    if failed:
        text += f", {len(failed)} refused ({failed[0]})"
        log.warning("loop thread: %s", text)
    return raised, text


def _fifo(priority: int | None) -> str:
    if priority is None:
        return "SCHED_OTHER (LAMPS_RT_PRIORITY=off)"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))  # 0: the calling thread (Linux)
    except PermissionError:
        text = f"SCHED_OTHER (asked FIFO {priority}: refused, needs CAP_SYS_NICE)"
        log.warning("loop thread: %s", text)
        return text
    except OSError as exc:
        text = f"SCHED_OTHER (asked FIFO {priority}: {exc.strerror or exc})"
        log.warning("loop thread: %s", text)
        return text
    return f"SCHED_FIFO {priority}"


def _mlock(lock: bool) -> str:
    if not lock:
        return "memory not locked (LAMPS_MLOCK=off)"
    try:
        libc = _libc()
        if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE) != 0:
            errno = ctypes.get_errno()
            text = f"memory not locked (mlockall: {os.strerror(errno)}; needs CAP_IPC_LOCK or ulimit -l unlimited)"
            log.warning("loop thread: %s", text)
            return text
    except (OSError, AttributeError) as exc:
        return f"memory not locked (mlockall unavailable: {exc})"
    return "memory locked"


def _affinity(cpus: frozenset[int]) -> str:
    try:
        os.sched_setaffinity(0, cpus)
    except OSError as exc:
        text = f"CPUs any (asked {sorted(cpus)}: {exc.strerror or exc})"
        log.warning("loop thread: %s", text)
        return text
    return f"CPUs {','.join(str(c) for c in sorted(cpus))}"
