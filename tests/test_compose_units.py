"""The pieces compose's services use: the health probe, the host folders, the run's end, the image's lock file."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import tomllib

import pytest
from packaging.requirements import Requirement

from interfaces.messages import Phase
from launch.folders import owner_can_write, parse_owner, prepare
from launch.health import main as health_main
from launch.health import probe_targets
from launch.run_end import RunEnd

from .conftest import REPO

# -------------------------------------------------------------------------------------------------- health

def test_probe_targets_parse_endpoints_and_probe_wildcards_on_loopback():
    assert probe_targets("tcp/0.0.0.0:7447, tcp/robot:7448,") == [("127.0.0.1", 7447), ("robot", 7448)]
    assert probe_targets("tcp/[::]:7447") == [("::1", 7447)]
    with pytest.raises(ValueError, match="udp/0.0.0.0:7447"):
        probe_targets("udp/0.0.0.0:7447")


def test_health_is_ready_only_when_every_endpoint_accepts(capsys):
    with socket.socket() as listening, socket.socket() as closed:
        listening.bind(("127.0.0.1", 0))
        listening.listen()
        closed.bind(("127.0.0.1", 0))  # bound, not listening: refuses
        up, down = listening.getsockname()[1], closed.getsockname()[1]
        assert health_main(["--endpoint", f"tcp/0.0.0.0:{up}", "-v"]) == 0
        assert f"127.0.0.1:{up}" in capsys.readouterr().out
        assert health_main(["--endpoint", f"tcp/127.0.0.1:{up}", "--endpoint", f"tcp/127.0.0.1:{down}"]) == 1
        assert f"127.0.0.1:{down} does not accept connections" in capsys.readouterr().err


def test_health_reads_the_services_own_listen_endpoints_and_refuses_nothing_to_probe():
    env = {**os.environ, "LAMPS_ZENOH_LISTEN": ""}
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "health"], env=env, capture_output=True, text=True)
    assert r.returncode == 2 and "nothing to probe" in r.stderr
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        env["LAMPS_ZENOH_LISTEN"] = f"tcp/0.0.0.0:{s.getsockname()[1]}"
        r = subprocess.run([sys.executable, "-m", "runtime.cli", "health"], env=env, capture_output=True,
                           text=True)
        assert r.returncode == 0, r.stderr


# ------------------------------------------------------------------------------------------------- folders

def test_folders_are_made_and_root_owned_ones_handed_over(tmp_path):
    if os.geteuid() != 0:
        pytest.skip("handing a folder over needs root (compose runs it as root)")
    made = tmp_path / "runs"
    assert "now owned by 1000:1000" in prepare(made, 1000, 1000)
    assert made.stat().st_uid == 1000 and made.stat().st_gid == 1000
    assert "ok" in prepare(made, 1000, 1000)  # twice: nothing more to do
    theirs = tmp_path / "theirs"
    theirs.mkdir(mode=0o755)
    os.chown(theirs, 1234, 1234)
    os.chmod(theirs, 0o755)
    with pytest.raises(PermissionError, match="LAMPS_UID=1234 LAMPS_GID=1234"):
        prepare(theirs, 1000, 1000)
    assert theirs.stat().st_uid == 1234  # somebody else's folder is never taken
    (tmp_path / "file").write_text("x")
    with pytest.raises(NotADirectoryError, match="not a folder"):
        prepare(tmp_path / "file", 1000, 1000)


def test_owner_parsing_and_write_rights():
    assert parse_owner("1000:1001") == (1000, 1001)
    for bad in ("1000", "a:b", "1000:", ":1"):
        with pytest.raises(ValueError, match="UID:GID"):
            parse_owner(bad)
    st = os.stat_result((0o40755, 0, 0, 0, 1234, 50, 0, 0, 0, 0))
    assert owner_can_write(st, 1234, 1) and not owner_can_write(st, 1000, 50) and owner_can_write(st, 0, 0)
    st = os.stat_result((0o40775, 0, 0, 0, 1234, 50, 0, 0, 0, 0))
    assert owner_can_write(st, 1000, 50) and not owner_can_write(st, 1000, 51)


# ------------------------------------------------------------------------------------------------- run end

def test_the_run_ends_after_done_or_a_fault_is_held():
    end = RunEnd(settle_s=2.5, fault_hold_s=5.0)
    assert end.update(Phase.WIPE, "", 0.0) is None
    assert end.update(Phase.DONE, "", 1.0) is None
    assert end.update(Phase.WIPE, "", 2.0) is None  # a new stain: DONE again starts over
    assert end.update(Phase.DONE, "", 3.0) is None
    assert end.update(Phase.DONE, "", 5.4) is None
    assert end.update(Phase.DONE, "", 5.5) == ("done", "the controller is DONE")
    left = RunEnd(settle_s=1.0)
    assert left.update(Phase.DONE, "1 stain(s) left: stain 2 smeared after 3 passes", 0.0) is None
    assert left.update(Phase.DONE, "1 stain(s) left: stain 2 smeared after 3 passes", 1.0) == (
        "done", "the controller is DONE: 1 stain(s) left: stain 2 smeared after 3 passes")
    end = RunEnd()
    assert end.update(Phase.ESTOP, "stop pressed", 0.0) is None
    assert end.update(Phase.ESTOP, "stop pressed", 4.9) is None
    assert end.update(Phase.ESTOP, "stop pressed", 5.0) == ("fault", f"controller {Phase.ESTOP}: stop pressed")


def test_done_is_held_on_the_robot_clock_when_the_controller_reports_it():
    """A lock-step cell on a loaded machine runs slower than the wall: 2.5 s of wall time in DONE may be 1 s of the
    executor's time (its recheck may still bring it back); the robot clock is what the executor waits on."""
    end = RunEnd(settle_s=2.5, fault_hold_s=5.0)
    assert end.update(Phase.DONE, "", 0.0, robot_s=10.0) is None
    assert end.update(Phase.DONE, "", 6.0, robot_s=12.0) is None, "6 s of wall, 2 s of robot time"
    assert end.update(Phase.DONE, "", 7.0, robot_s=12.5) == ("done", "the controller is DONE")
    # a fault is held on the wall (a lost robot has no clock)
    assert end.update(Phase.FAULT, "no robot state", 8.0, robot_s=12.5) is None
    assert end.update(Phase.FAULT, "no robot state", 13.0, robot_s=12.5) == (
        "fault", f"controller {Phase.FAULT}: no robot state")


# ------------------------------------------------------------------------------------------------ the lock

def test_the_image_lock_pins_every_dependency_inside_its_range_with_hashes():
    deps = [Requirement(d) for d in tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]]
    text = (REPO / "requirements.lock").read_text()
    pins: dict[str, list[str]] = {}
    for m in re.finditer(r"^([A-Za-z0-9_.\-]+)==([^ ;\\]+)(?: ; ([^\\]+))? \\\n((?:    --hash=sha256:[0-9a-f]{64}"
                         r"(?: \\)?\n)+)", text, re.M):
        marker = m.group(3)
        if marker is None or Requirement(f"x ; {marker}").marker.evaluate({"python_full_version": "3.11.2",
                                                                            "python_version": "3.11"}):
            pins.setdefault(m.group(1).lower().replace("_", "-"), []).append(m.group(2))
    for d in deps:
        name = d.name.lower().replace("_", "-")
        assert name in pins, f"{d.name} is not in requirements.lock: run scripts/lock.sh"
        assert all(d.specifier.contains(v) for v in pins[name]), f"{d.name} {pins[name]} outside {d.specifier}"
    assert {"setuptools", "wheel"} <= set(pins)  # the image installs the package without build isolation
    blocks = [b for b in re.split(r"\n(?=[A-Za-z])", text) if re.match(r"[A-Za-z]", b)]
    assert all("--hash=sha256:" in b for b in blocks), "every locked package carries its hashes"
