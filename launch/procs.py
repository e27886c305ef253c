"""Child processes of the launcher: started in their own process group, logs prefixed, stopped without orphans.

Each child runs in a new session (its own process group, so a stop reaches
whatever it started) and, on Linux, gets SIGTERM if the launcher dies
(``PR_SET_PDEATHSIG``). Its output is read line by line on a thread,
printed as ``[name] line`` and appended to ``logs/<name>.log``.
"""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:  # runs in the child between fork and exec
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except OSError:
        pass


#: Switches that weaken a service's security: a launcher never passes them on from its own environment, only
#: when it sets them itself (runtime/service_security.py: no silent insecurity).
SECURITY_SWITCHES = ("LAMPS_ZENOH_INSECURE", "LAMPS_ZENOH_ACCESS_CONTROL", "LAMPS_ACCESS_CONTROL",
                     "LAMPS__ZENOH__INSECURE", "LAMPS__ZENOH__ACCESS_CONTROL")


def inherited_environment() -> dict[str, str]:
    """Our environment less :data:`SECURITY_SWITCHES`: what a service started by a launcher inherits."""
    return {k: v for k, v in os.environ.items() if k not in SECURITY_SWITCHES}


class Child:
    """One running service. ``tail`` keeps its last output lines (for error messages)."""

    def __init__(self, name: str, argv: tuple[str, ...], env: dict[str, str], log_dir: Path,
                 echo: Callable[[str], None] | None = None) -> None:
        self.name = name
        self.argv = argv
        self.tail: deque[str] = deque(maxlen=20)
        log_dir.mkdir(parents=True, exist_ok=True)
        self._log: TextIO = open(log_dir / f"{name}.log", "a", encoding="utf-8")
        self._echo = echo
        self._terminated = False  # SIGTERM sent: a second one would find Python's default handler back at its exit
        self.proc = subprocess.Popen(argv, env={**inherited_environment(), **env}, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True, bufsize=1,
                                     start_new_session=True,
                                     preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None)
        self._reader = threading.Thread(target=self._read, name=f"log-{name}", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            line = line.rstrip("\n")
            self.tail.append(line)
            self._log.write(line + "\n")
            self._log.flush()
            if self._echo is not None:
                self._echo(f"[{self.name}] {line}")

    @property
    def returncode(self) -> int | None:
        return self.proc.poll()

    def last_words(self) -> str:
        """The most telling recent output line (an error if there is one)."""
        for line in reversed(self.tail):
            if any(w in line for w in ("Error", "error", "refused", "failed", "cannot", "FAULT")):
                return line.strip()
        return self.tail[-1].strip() if self.tail else "(no output)"

    def terminate(self) -> None:
        """SIGTERM to the group, once, without waiting (:meth:`stop` waits, and kills). Once only: a service that
        took the first is on its way out, and while Python finalizes it has restored the default handlers, so a
        second SIGTERM kills it (exit -15) instead of letting it end cleanly."""
        if self.proc.poll() is None and not self._terminated:
            self._terminated = True
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass

    def stop(self, timeout_s: float = 10.0) -> int:
        """SIGTERM to the group, SIGKILL after ``timeout_s``; returns the exit code."""
        if self.proc.poll() is None:
            self.terminate()
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                self.proc.wait(5.0)
        else:  # the leader is gone; take anything it left in its group with it
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
        self._reader.join(2.0)
        self._log.close()
        return int(self.proc.returncode)


def wait_port(port: int, child: Child, timeout_s: float) -> bool:
    """True once 127.0.0.1:``port`` accepts connections; False if ``child`` exits or time runs out."""
    import socket

    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if child.returncode is not None:
            return False
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.settimeout(0.2)
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return True
        time.sleep(0.1)
    return False
