"""The real-time loops run the garbage collector themselves, in the slack before a deadline."""

from __future__ import annotations

import gc
import sys
import time
import weakref

import pytest

from runtime.loop_hygiene import GC_FORCE_FACTOR, LoopHygiene


class _Node:
    def __init__(self) -> None:
        self.me = self  # a reference cycle: only the collector frees it


def _garbage(n: int) -> weakref.ref:
    """``n`` cyclic objects dropped at once; a weak reference to one of them."""
    nodes = [_Node() for _ in range(n)]
    probe = weakref.ref(nodes[0])
    del nodes
    return probe


@pytest.fixture()
def hygiene():
    h = LoopHygiene()
    h.start()
    yield h
    h.stop()


def test_start_freezes_what_exists_and_takes_the_collector_over(hygiene):
    assert not gc.isenabled() and gc.get_freeze_count() > 0
    if sys.platform.startswith("linux"):
        assert "timer slack 1000 ns" in hygiene.report, hygiene.report


def test_garbage_is_collected_in_the_slack_not_when_the_deadline_is_near(hygiene):
    probe = _garbage(2 * gc.get_threshold()[0])
    hygiene.wait_until(time.monotonic_ns() + 50_000)  # 50 us left: no time to collect
    assert probe() is not None and hygiene.counts["gc_in_slack"] == 0
    hygiene.wait_until(time.monotonic_ns() + 2_000_000)  # 2 ms left
    assert probe() is None and hygiene.counts["gc_in_slack"] == 1


def test_a_pile_of_garbage_is_collected_even_without_slack(hygiene):
    probe = _garbage(GC_FORCE_FACTOR * gc.get_threshold()[0] + 10)
    hygiene.wait_until(time.monotonic_ns())
    assert probe() is None and hygiene.counts["gc_forced"] == 1


def test_the_wait_ends_at_the_deadline_sleeping_or_spinning():
    for spin in (0, 200_000):
        h = LoopHygiene(spin_ns=spin)
        h.start()
        try:
            deadline = time.monotonic_ns() + 3_000_000
            h.wait_until(deadline)
            assert time.monotonic_ns() >= deadline
        finally:
            h.stop()
    assert gc.isenabled(), "stop gives the collector back"
