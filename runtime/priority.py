"""CPU priority per kind of service: the 1 kHz loops first, the background work after them.

A cell runs several 1 kHz services (the controller, the robot side: the
sim, or the lbr peer and the real-robot adapter) beside services whose work
can wait a few milliseconds (perception, the recorder, the sim's camera
renderer). On a machine with fewer cores than busy services, the kernel's
fair scheduler shares the CPU by *nice* value: a thread at nice -10 gets
about 87 times the share of one at nice +10 when both want to run. So:

* :data:`REALTIME` services ask for nice :data:`REALTIME_NICE` (-10). That
  needs ``CAP_SYS_NICE`` (root, or ``cap_add: [SYS_NICE]`` under compose);
  refused, the service runs at its inherited nice and says so.
* :data:`BACKGROUND` services take nice :data:`BACKGROUND_NICE` (+10);
  lowering one's own priority is always permitted.

Call :func:`set_service_priority` first thing in a service's process,
before its Zenoh session starts threads: on Linux the nice value belongs
to each thread, and new threads inherit their creator's (threads a library
started at import, e.g. a BLAS pool, are set too). The environment
variable ``LAMPS_NICE`` overrides the value for one service (an integer
from -20 to 19), ``LAMPS_NICE=keep`` leaves the inherited one. The report
it returns goes into the service's status (:data:`REPORT`).

A background service told to stop leaves its low priority
(:func:`leave_background`, from its signal handler:
:func:`runtime.stop_signals.on_stop_signals`): its exit now holds up the
launcher, and on a shared machine another cell's loops at nice -10 would
leave it about 1 % of a core for it (a perception once took more than the
launcher's 10 s to close its session so, and was killed).
"""

from __future__ import annotations

import logging
import os
import threading

from interfaces.errors import ConfigError

log = logging.getLogger(__name__)

REALTIME = "realtime"
BACKGROUND = "background"
#: nice value [-20, 19] by kind of service
REALTIME_NICE = -10
BACKGROUND_NICE = 10
KINDS = {REALTIME: REALTIME_NICE, BACKGROUND: BACKGROUND_NICE}

#: The nice value a background service takes when told to stop (:func:`leave_background`).
STOPPING_NICE = 0

#: What :func:`set_service_priority` did in this process (for status), "" before it ran.
REPORT = ""
#: The kind of service this process was set up as by :func:`set_service_priority` ("" before: a test, a tool).
KIND = ""
#: :func:`set_service_priority` stepped this process back to :data:`BACKGROUND_NICE` by default (not by
#: ``LAMPS_NICE``, whose value is the user's): what :func:`leave_background` may undo.
_STEPPED_BACK = False


def wanted_nice(kind: str, env: dict | os._Environ | None = None) -> int | None:
    """The nice value a service of ``kind`` asks for (None: keep the inherited one); ConfigError for a bad
    ``LAMPS_NICE`` (a service checks it with the rest of its configuration, before it serves)."""
    env = os.environ if env is None else env
    if kind not in KINDS:
        raise ConfigError(f"service priority kind must be one of {sorted(KINDS)}, got {kind!r}")
    text = env.get("LAMPS_NICE", "").strip()
    if not text:
        return KINDS[kind]
    if text == "keep":
        return None
    try:
        value = int(text)
    except ValueError:
        raise ConfigError(f"LAMPS_NICE must be an integer from -20 to 19 or 'keep', got {text!r}") from None
    if not -20 <= value <= 19:
        raise ConfigError(f"LAMPS_NICE must be an integer from -20 to 19 or 'keep', got {value}")
    return value


def _threads() -> list[int]:
    """The ids of this process's threads, the calling one first (0); Linux lists them in /proc."""
    try:
        others = sorted(int(t) for t in os.listdir("/proc/self/task") if int(t) != threading.get_native_id())
    except OSError:
        others = []
    return [0, *others]


def set_service_priority(kind: str, env: dict | os._Environ | None = None) -> str:
    """Set the calling thread's nice value for a service of ``kind`` (:data:`REALTIME` or :data:`BACKGROUND`);
    returns what was done, e.g. ``"nice -10"`` or ``"nice 0 (asked -10: refused, needs CAP_SYS_NICE)"``.

    Raises ConfigError for a bad ``LAMPS_NICE``; a refusal by the operating system is reported, not raised.
    """
    global REPORT, KIND, _STEPPED_BACK
    wanted = wanted_nice(kind, env)
    _STEPPED_BACK = False
    KIND = kind
    now = os.getpriority(os.PRIO_PROCESS, 0)
    if wanted is None or wanted == now:
        REPORT = f"nice {now}"
    else:
        try:
            for tid in _threads():  # the calling thread first; then any a library started at import
                try:
                    os.setpriority(os.PRIO_PROCESS, tid, wanted)
                except ProcessLookupError:
                    pass  # a thread that ended meanwhile
            REPORT = f"nice {wanted}"
            given = (os.environ if env is None else env).get("LAMPS_NICE", "").strip()
            _STEPPED_BACK = kind == BACKGROUND and not given
        except PermissionError:
            REPORT = f"nice {now} (asked {wanted}: refused, needs CAP_SYS_NICE)"
            log.warning("%s priority: %s", kind, REPORT)
        except OSError as exc:
            REPORT = f"nice {now} (asked {wanted}: {exc.strerror or exc})"
            log.warning("%s priority: %s", kind, REPORT)
    log.info("%s priority: %s", kind, REPORT)
    return REPORT


def leave_background() -> bool:
    """Every thread of a :data:`BACKGROUND` process that :func:`set_service_priority` stepped back by default
    (not by ``LAMPS_NICE``) to :data:`STOPPING_NICE` (a stop is due: its exit holds up the others); True if done,
    False if there was nothing to do or the system refused it (without ``CAP_SYS_NICE``: then the loops did not
    get -10 either). Safe in a signal handler: no logging, no lock."""
    global REPORT
    if not _STEPPED_BACK or os.getpriority(os.PRIO_PROCESS, 0) <= STOPPING_NICE:
        return False
    try:
        for tid in _threads():
            try:
                os.setpriority(os.PRIO_PROCESS, tid, STOPPING_NICE)
            except ProcessLookupError:
                pass
    except OSError:
        return False
    REPORT = f"nice {STOPPING_NICE} (stopping)"
    return True

