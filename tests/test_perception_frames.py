"""Perception on frames the simulator renders with known stains (``lamps sim`` over real Zenoh, lock-step).

The frames come from a real ``lamps sim`` process; :class:`Perception` runs
on them in this process so each test can look at every frame. The sim's
truth (drawn stain centres and long extents, the board pose) is the
reference.
"""

from __future__ import annotations

import msgspec
import numpy as np
import pytest

from arm.robot_model import RobotModel
from interfaces.messages import CameraFrame, SimTruth
from interfaces.transforms import transform_from_pose
from perception.board import pose_distance
from perception.frames import frame_from_message
from perception.params import KappaParams, PerceptionParams
from perception.pipeline import Perception

from .zenoh_helpers import SimProcess, run_lockstep, wait_for

pytestmark = pytest.mark.slow
#: The arm turned away from the board, out of the camera's view of it.
PARKED_Q = [2.6, 0.3, 0.0, -1.2, 0.0, 0.8, 0.0]
CAMERA = {"rate_hz": 10.0}


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel()


def render(tmp_path, model, sim_cfg: dict, steps: int = 1500) -> tuple[list[CameraFrame], SimTruth]:
    """Frames of a lock-step sim holding its arm still for ``steps`` ms, and its truth."""
    with SimProcess(tmp_path, {"mode": "lockstep", "camera": CAMERA, **sim_cfg}) as sim:
        frames = sim.node.inbox(sim.keys.camera_frame("board"), CameraFrame, maxlen=1000)
        truth = sim.node.latest(sim.keys.sim_truth, SimTruth)
        run_lockstep(sim, steps, lambda s: model.gravity(np.array(s.q_rad)) - 5.0 * np.array(s.dq_rad_s))
        wait_for(lambda: frames.received >= steps // 100 - 1, 20.0, "the camera frames")
        final = wait_for(truth.take, 5.0, "sim truth")
        out = []
        while (f := frames.get(0.0)) is not None:
            out.append(f)
    return out, final


def run_perception(frames: list[CameraFrame], params: PerceptionParams | None = None):
    p = Perception(params or PerceptionParams())
    results = [p.process(frame_from_message(f)) for f in frames]
    return p, results


def match(stains, truth: SimTruth) -> list[tuple[int, int]]:
    """(perception index, truth index) pairs by nearest centre."""
    centres = np.array(truth.centres_board_m)
    return [(i, int(np.argmin(np.linalg.norm(centres - s.centre_board_m, axis=1)))) for i, s in enumerate(stains)]


def check_against_truth(msg, truth: SimTruth) -> list[str]:
    lines = []
    assert len(msg.stains) == len(truth.stain_ids), (len(msg.stains), len(truth.stain_ids))
    pairs = match(msg.stains, truth)
    assert sorted(t for _, t in pairs) == list(range(len(truth.stain_ids)))  # one to one
    T_true = transform_from_pose(truth.T_board_to_world)
    for i, t in pairs:
        s = msg.stains[i]
        err = float(np.linalg.norm(np.array(s.centre_board_m) - truth.centres_board_m[t]))
        size_err = abs(s.size_m - truth.sizes_m[t]) / truth.sizes_m[t]
        world = T_true[:3, :3] @ np.array([*truth.centres_board_m[t], 0.0]) + T_true[:3, 3]
        world_err = float(np.linalg.norm(np.array(s.centre_world_m) - world))
        lines.append(f"stain {t}: centre error {err * 1000:.1f} mm (world {world_err * 1000:.1f} mm), size "
                     f"{s.size_m * 100:.1f} cm vs {truth.sizes_m[t] * 100:.1f} cm ({size_err:.0%})")
        assert err <= 0.01 and world_err <= 0.012, lines[-1]
        assert size_err <= 0.2, lines[-1]
        assert not s.kappa and s.remaining > 0.95 and s.visible > 0.95, s
    return lines


@pytest.mark.parametrize("preset,seed", [("wall", 0), ("table", 3)])
def test_stain_count_centres_and_sizes_match_the_truth(tmp_path, model, preset, seed):
    frames, truth = render(tmp_path, model, {"seed": seed, "start_q_rad": PARKED_Q, "board": {"preset": preset},
                                             "dirt": {"stains": 4}})
    assert len(frames) >= 12
    p, results = run_perception(frames)
    msg = results[-1].stains
    assert msg is not None and msg.board == "seen"
    lines = check_against_truth(msg, truth)
    dist, angle = pose_distance(transform_from_pose(msg.T_board_to_world), transform_from_pose(truth.T_board_to_world))
    size = np.array(msg.board_size_m)
    print(f"{preset}: board pose error {dist * 1000:.1f} mm {angle:.2f} deg, size {size.round(4).tolist()}; "
          + "; ".join(lines))
    assert dist < 0.01 and angle < 1.0
    ids = [[s.id for s in r.stains.stains] for r in results if r.stains is not None]
    assert all(i == ids[-1] for i in ids), "stain ids must be stable from frame to frame"
    timing = np.array([sum(r.timing_ms.values()) for r in results[3:]])
    print(f"processing {np.median(timing):.1f} ms per frame (median)")


def test_a_board_moved_between_runs_is_found_and_its_stains_start_afresh(tmp_path, model):
    moved = {"preset": "custom", "size_m": [0.8, 0.6], "origin_m": [0.62, 0.45, 0.2],
             "quat_wxyz": [0.5609855, 0.5609855, -0.4304593, -0.4304593]}  # the wall board turned 15 deg, shifted
    first, truth1 = render(tmp_path, model, {"seed": 1, "start_q_rad": PARKED_Q, "dirt": {"stains": 2}})
    second, truth2 = render(tmp_path, model, {"seed": 2, "start_q_rad": PARKED_Q, "board": moved,
                                              "dirt": {"stains": 3}}, steps=1000)
    p, results = run_perception(first + second)  # one perception process across both runs
    assert p.resets >= 1, "the sim's clock restarted and the board moved: perception must start afresh"
    msg = results[-1].stains
    lines = check_against_truth(msg, truth2)
    dist, angle = pose_distance(transform_from_pose(msg.T_board_to_world), transform_from_pose(truth2.T_board_to_world))
    print(f"moved board: pose error {dist * 1000:.1f} mm {angle:.2f} deg; " + "; ".join(lines))
    assert dist < 0.01 and angle < 1.0


def test_the_arm_covering_a_stain_never_makes_it_clean(tmp_path, model):
    """First the stains in full view; then the same board with the arm over the board (its default start pose)."""
    clear, truth = render(tmp_path, model, {"seed": 0, "start_q_rad": PARKED_Q}, steps=800)
    covered, _ = render(tmp_path, model, {"seed": 0}, steps=3000)
    params = PerceptionParams(kappa=KappaParams(memory_s=0.5))
    p = Perception(params)
    offset = clear[-1].robot_time_ns + 100_000_000  # one continuous clock for the two runs
    for f in clear + [msgspec.structs.replace(f, robot_time_ns=f.robot_time_ns + offset) for f in covered]:
        r = p.process(frame_from_message(f))
    msg = r.stains
    assert len(msg.stains) == 3
    hidden = [s for s in msg.stains if s.visible < 0.5]
    assert hidden, [(s.id, s.visible) for s in msg.stains]  # the arm does cover a stain
    for s in msg.stains:
        assert not s.kappa, s
        assert s.remaining > 0.9, s  # hidden ink is still ink
    print("with the arm over the board: " + ", ".join(f"stain {s.id} visible {s.visible:.0%} remaining "
                                                      f"{s.remaining:.0%}" for s in msg.stains))
