"""A service dies mid-wipe and the cell stops as ``lamps up`` stops it: the pad is off the board before the
controller exits, and the run has its report.

The compose cell's sim profile as local processes (:mod:`tests.cell_harness`), lock-step. Perception is killed
while the pad presses; the cell is then stopped the way ``lamps up`` stops it when a service exits (the
controller first, which lifts off before it goes). The sim's truth, recorded to the end, says what the pad
pressed when the controller was gone.
"""

from __future__ import annotations

import signal
import time

import pytest

from launch.record import read_recording

from .cell_harness import Cell

pytestmark = pytest.mark.slow


@pytest.mark.attack('5', 'perception killed (SIGKILL) under lamps up mid-wipe',
                    'the controller exits only with contact below 0.5 N')
def test_perception_killed_mid_wipe_the_controller_lifts_the_pad_before_it_exits(tmp_path, learned_skill_file):
    out = tmp_path / "run"
    with Cell(out, learned_skill_file, "lockstep") as cell:
        cell.wait_phase(("WIPE",), 120.0)
        time.sleep(0.5)
        assert cell.status.normal_force_n > 5.0, cell.status
        cell.signal("perception", signal.SIGKILL)
        report = cell.finish(outcome="failed", why="service perception exited")
    rec = read_recording(out / "recording.mcap")
    truth = next(msgs for topic, msgs in rec.items() if topic.endswith("/sim/truth"))
    assert truth[-1][1]["contact_force_n"] < 0.5, truth[-5:]
    assert report["peak_contact_force_n"] <= report["force_cap_n"], report["peak_contact_force_n"]
