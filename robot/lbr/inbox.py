"""What the bridge delivers to the adapter, handed from Zenoh's thread to the server's loop.

Three of the stack's topics (zenoh-bridge-ros2dds, CDR): ``state`` (``LBRState``, in the FRI layout of ``[lbr]
fri_major``), ``joint_states`` (only the joint names are read: arming needs the configured ones) and, with
``wrench_source = "stack"``, the stack's wrench estimate. The callbacks decode, count what they drop under the
adapter's counter names, and keep the newest of each; the loop takes the newest state with :meth:`StateInbox.wait`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter

import numpy as np

from .msgs import LbrState, LbrWireError, decode_joint_names, decode_state, decode_wrench
from .params import LbrParams


class StateInbox:
    """The subscriptions to the stack's topics and the newest of what came on each.

    layout_error : the other FRI layout's message when states came in it (empty: none); names_ok : whether the
    joint names on ``joint_states`` are the configured ones (None: none seen); stack_wrench : (6,) the stack's
    newest wrench estimate [N, Nm], tip frame (None: none yet, or ``wrench_source`` is not ``"stack"``). counts and
    log are the adapter's (its counters, its logger).
    """

    def __init__(self, params: LbrParams, session, counts: Counter[str], log: logging.Logger) -> None:
        self.p = params
        self.counts = counts
        self.log = log
        self.layout_error = ""
        self.names_ok: bool | None = None
        self.stack_wrench: np.ndarray | None = None
        self._cond = threading.Condition()
        self._wake: threading.Event | None = None
        self._newest: tuple[LbrState, int] | None = None  # the newest state and its arrival [monotonic ns]
        topics = params.topics
        self._subs = [session.declare_subscriber(topics.key(topics.state), self._on_state),
                      session.declare_subscriber(topics.key(topics.joint_states), self._on_joint_states)]
        if params.wrench_source == "stack":
            self._subs.append(session.declare_subscriber(topics.key(topics.wrench), self._on_wrench))

    def set_wake(self, wake: threading.Event) -> None:
        """Set ``wake`` whenever a state arrives."""
        self._wake = wake

    def wait(self, timeout_s: float) -> tuple[LbrState, int] | None:
        """The newest state not yet taken and its arrival [monotonic ns], waiting up to ``timeout_s`` for one (None:
        none came)."""
        with self._cond:
            if self._newest is None and not self._cond.wait_for(lambda: self._newest is not None, timeout_s):
                return None
            newest, self._newest = self._newest, None
        return newest

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self._subs = []

    # -- network callbacks (Zenoh's thread: decode, count, hand over) ------------------------------
    def _on_state(self, sample) -> None:
        try:
            st = decode_state(sample.payload.to_bytes(), self.p.fri_major)
        except LbrWireError as exc:
            text = str(exc)
            if "set [lbr] fri_major" in text:
                if not self.layout_error:
                    self.log.error("lbr: %s", text)
                self.layout_error = text
            self.counts[f"states_dropped: {text[:60]}"] += 1
            return
        with self._cond:
            self.counts["states_received"] += 1
            self._newest = (st, time.monotonic_ns())
            self._cond.notify()
        if self._wake is not None:
            self._wake.set()

    def _on_joint_states(self, sample) -> None:
        try:
            names = decode_joint_names(sample.payload.to_bytes())
        except LbrWireError:
            self.counts["joint_states_dropped: not a JointState"] += 1
            return
        ok = tuple(names) == self.p.joint_names
        if not ok:
            self.counts[f"joint_states_dropped: names {list(names)[:8]}"] += 1
        self.names_ok = ok

    def _on_wrench(self, sample) -> None:
        try:
            _, w = decode_wrench(sample.payload.to_bytes())
        except LbrWireError as exc:
            self.counts[f"wrench_dropped: {str(exc)[:60]}"] += 1
            return
        self.stack_wrench = w
