"""Listening ports are drawn below the kernel's ephemeral range, from the worker's own slice, bindable and never
twice; a malformed range is named."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from runtime import ports
from runtime.ports import PortRangeError, bindable, free_port, port_range


def _ephemeral_low() -> int:
    path = Path("/proc/sys/net/ipv4/ip_local_port_range")
    return int(path.read_text().split()[0]) if path.is_file() else 32768


def test_free_ports_lie_in_the_range_below_the_ephemeral_one_and_are_never_given_twice():
    lo, hi = port_range()
    assert hi <= _ephemeral_low()  # the kernel never hands these out for an outgoing connection's source port
    assert lo > 19999  # above Ray's default worker ports (10002-19999): a Ray head refuses a port among them
    drawn = [free_port() for _ in range(100)]
    assert len(set(drawn)) == 100 and all(lo <= p < hi for p in drawn)
    base = free_port(5)
    assert all(bindable(p) for p in range(base, base + 5)) and not set(range(base, base + 5)) & set(drawn)


def test_a_port_someone_listens_on_is_not_bindable_and_is_skipped(monkeypatch):
    with socket.socket() as taken:
        lo, _ = port_range()
        for port in range(lo, lo + 200):
            try:
                taken.bind(("127.0.0.1", port))
                break
            except OSError:
                continue
        taken.listen()
        assert not bindable(port)
        monkeypatch.setenv(ports.PORT_RANGE_ENV, f"{port}-{port + 2}")
        monkeypatch.setattr(ports, "_given", set())
        assert free_port() == port + 1  # the only free one left in [port, port + 2)
        with pytest.raises(PortRangeError, match="no 1 free consecutive port"):
            free_port()


def test_the_workers_of_this_run_draw_from_disjoint_slices(monkeypatch):
    import os

    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    if worker.startswith("gw"):
        lo, hi = port_range()
        assert hi - lo == 625 and lo == ports.DEFAULT_RANGE[0] + int(worker[2:]) % 8 * 625
        assert hi <= ports.DEFAULT_RANGE[1]
    monkeypatch.delenv(ports.PORT_RANGE_ENV, raising=False)
    assert port_range() == ports.DEFAULT_RANGE


@pytest.mark.parametrize("value", ["7000", "a-b", "900-2000", "3000-3000", "60000-70000"])
def test_a_malformed_range_is_named(monkeypatch, value):
    monkeypatch.setenv(ports.PORT_RANGE_ENV, value)
    with pytest.raises(PortRangeError, match="LAMPS_PORT_RANGE"):
        port_range()
