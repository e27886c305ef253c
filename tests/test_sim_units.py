"""The simulator's parts without networking: parameters, board, dirt law, commands, camera model, description."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
import pybullet as pb
import pytest
from matplotlib.path import Path as MplPath

from arm.robot_model import RobotModel
from interfaces.errors import ConfigError
from interfaces.messages import TorqueCommand
from interfaces.transforms import matrix_from_quat_wxyz, quat_wxyz_from_matrix
from robot.command import CommandKind
from robot.gate import CommandGate
from sim import cli
from sim.board import board_from_params, check_board, start_configuration
from sim.camera import camera_pose, intrinsics_of, look_at, project
from sim.dirt import DirtGrid, StainShape, random_stains, stains_from_specs
from sim.params import BoardParams, CameraParams, SimParams
from sim.world import build_world

from .zenoh_helpers import wait_for


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel()


# -- parameters ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("table, match", [
    ({"mode": "fast"}, r"mode must be one of \('lockstep', 'realtime'\)"),
    ({"rate_hz": 10}, r"rate_hz must be a number in \[100.0, 5000.0\]"),
    ({"board": {"preset": "ceiling"}}, "preset must be one of"),
    ({"board": {"preset": "custom", "origin_m": [1, 0, 0]}}, "needs origin_m, quat_wxyz and size_m"),
    ({"board": {"preset": "custom", "origin_m": [1, 0, 0], "quat_wxyz": [1, 1, 0, 0], "size_m": [0.8, 0.6]}},
     "unit quaternion"),
    ({"dirt": {"cell_m": 0.005}}, r"cell_m must be a number in \[0.0005, 0.002\]"),
    ({"dirt": {"stains": -1}}, r"stains must be an integer count in \[0, 12\]"),
    ({"camera": {"width": 10}}, r"width must be an integer in \[64, 1920\]"),
    ({"camera": {"position_m": [1, 0, 1]}}, "give both position_m and look_at_m"),
    ({"colour": "red"}, r"\[sim\] unknown key\(s\) \['colour'\]"),
    ({"contact": {"friction": "high"}}, "friction must be a number"),
])
def test_bad_parameters_name_the_key_and_the_valid_range(table, match):
    with pytest.raises(ConfigError, match=match):
        SimParams.from_table(table)


def test_camera_defaults_are_a_d435i_colour_stream_scaled_to_the_resolution():
    cam = CameraParams(width=320, height=240)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (307.5, 307.5, 160.0, 120.0)


# -- board ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("preset", ["wall", "table"])
def test_board_presets_are_wipeable_and_frames_round_trip(preset, model):
    board = board_from_params(BoardParams(preset=preset))
    check_board(board, 0.12, model)
    xy = np.array([[0.1, 0.2], [0.5, 0.4]])
    back = board.board_from_world(board.world_from_board(xy))
    np.testing.assert_allclose(back[:, :2], xy, atol=1e-12)
    np.testing.assert_allclose(back[:, 2], 0.0, atol=1e-12)
    q = start_configuration(board, 0.08, model)
    p, R = model.tcp_pose(q)
    np.testing.assert_allclose(p, board.centre_world_m + 0.08 * board.normal_world, atol=2e-4)
    assert R[:, 2] @ board.normal_world == pytest.approx(-1.0, abs=1e-3)  # the pad faces the board


@pytest.mark.parametrize("origin, quat, match", [
    # board behind the robot
    ((-0.5, 0.4, 0.25), (0.5, -0.5, -0.5, 0.5), "the robot.s shoulder is .* in front of the board"),
    ((1.6, 0.4, 0.25), (0.5, 0.5, -0.5, -0.5), "the eraser cannot reach"),  # a wall board 1.6 m away
])
def test_impossible_board_poses_are_refused_with_a_reason(origin, quat, match, model):
    board = board_from_params(BoardParams(preset="custom", origin_m=origin, quat_wxyz=quat, size_m=(0.8, 0.6)))
    with pytest.raises(ConfigError, match="impossible board pose: " + match):
        check_board(board, 0.12, model)


# -- dirt ----------------------------------------------------------------------------------------------

def _grid_full_of_dirt() -> DirtGrid:
    g = DirtGrid(np.array([0.4, 0.3]), 0.002, [], 0)
    g.dirt[:] = 1.0
    return g


def test_wiping_removes_dirt_only_under_the_pad():
    g = _grid_full_of_dirt()
    centre, axis = np.array([0.2, 0.15]), np.array([math.cos(0.5), math.sin(0.5)])
    n = g.wipe(centre, axis, (0.06, 0.025), np.array([0.2, 0.0]), 0.0, 10.0, 0.01, 2.0, 2.0)
    # the pad: a 12 x 5 cm rectangle turned by 0.5 rad; cells inside it by matplotlib's point-in-polygon test
    across = np.array([-axis[1], axis[0]])
    corners = [centre + sa * 0.06 * axis + sb * 0.025 * across for sa, sb in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
    xs, ys = np.meshgrid((np.arange(g.nx) + 0.5) * 0.002, (np.arange(g.ny) + 0.5) * 0.002)
    under = MplPath(corners).contains_points(np.column_stack([xs.ravel(), ys.ravel()])).reshape(g.dirt.shape)
    assert n == under.sum() == np.count_nonzero(g.dirt < 1.0)
    assert np.all(g.dirt[~under] == 1.0)
    assert n * 0.002**2 == pytest.approx(0.12 * 0.05, rel=0.02)  # the pad's area, up to its edge cells
    wiped = g.dirt[under]
    assert 0.0 < wiped.min() and wiped.max() < 1.0 and np.ptp(wiped) == 0.0  # a pure slide: the same everywhere


def test_the_removal_law_is_exponential_in_the_excess_force_times_the_distance_slid():
    """d <- d exp(-k (F - F0) ds), checked by its properties and one e-fold rather than by evaluating it."""
    def left(force=10.0, speed=0.2, dt=0.01, steps=1):
        g = _grid_full_of_dirt()
        for _ in range(steps):
            g.wipe(np.array([0.2, 0.15]), np.array([1.0, 0.0]), (0.06, 0.025), np.array([speed, 0.0]), 0.0,
                   force, dt, 2.0, 2.0)
        return float(g.dirt[int(0.15 / 0.002), int(0.2 / 0.002)])  # the cell under the pad's centre

    assert left(steps=2) == pytest.approx(left(dt=0.02), rel=1e-6)  # two steps are one step twice as long
    assert left(speed=0.4) == pytest.approx(left(dt=0.02), rel=1e-6)  # only the distance slid counts
    assert math.log(left(force=18.0)) == pytest.approx(2 * math.log(left(force=10.0)), rel=1e-5)  # 16 N vs 8 N over
    assert math.log(left(speed=0.4)) == pytest.approx(2 * math.log(left(speed=0.2)), rel=1e-5)
    # the units of rate_per_n_m: 2 / (N m) with 8 N over the threshold, over 1/16 m of sliding, is one e-fold
    assert left(force=10.0, speed=0.25, dt=0.25) == pytest.approx(math.exp(-1.0), rel=1e-6)


def test_removal_needs_force_above_the_threshold_and_sliding_and_grows_with_both():
    def left(force, speed):
        g = _grid_full_of_dirt()
        g.wipe(np.array([0.2, 0.15]), np.array([1.0, 0.0]), (0.06, 0.025), np.array([speed, 0.0]), 0.0,
               force, 0.01, 2.0, 2.0)
        return g.dirt.min()

    assert left(1.9, 0.2) == 1.0 and left(10.0, 0.0) == 1.0
    assert left(20.0, 0.2) < left(10.0, 0.2) < 1.0
    assert left(10.0, 0.4) < left(10.0, 0.2)


def test_spinning_in_place_wipes_the_ends_of_the_pad_more_than_its_middle():
    g = _grid_full_of_dirt()
    g.wipe(np.array([0.2, 0.15]), np.array([1.0, 0.0]), (0.06, 0.025), np.zeros(2), 5.0, 10.0, 0.01, 2.0, 2.0)
    row = g.dirt[int(0.15 / 0.002)]
    assert row[int(0.255 / 0.002)] < row[int(0.205 / 0.002)] < 1.0


def test_random_stains_are_seeded_separate_and_inside_the_region():
    lo, hi = np.array([0.12, 0.12]), np.array([0.68, 0.48])
    a = random_stains(np.random.default_rng(3), 5, (0.04, 0.08), lo, hi)
    b = random_stains(np.random.default_rng(3), 5, (0.04, 0.08), lo, hi)
    assert a == b and len(a) == 5
    for s in a:
        assert np.all(np.array(s.centre_m) - s.size_m / 2 >= lo) and np.all(np.array(s.centre_m) + s.size_m / 2 <= hi)
    for i, s in enumerate(a):
        for t in a[i + 1:]:
            assert math.dist(s.centre_m, t.centre_m) > (s.size_m + t.size_m) / 2 + 0.03
    with pytest.raises(ConfigError, match="do not fit"):
        random_stains(np.random.default_rng(0), 12, (0.2, 0.3), lo, hi)


def test_stains_have_their_size_and_remaining_dirt_is_tracked():
    shape = StainShape(0, (0.2, 0.15), 0.08, aspect=2.0, angle_rad=0.0, wobble_seed=1)
    g = DirtGrid(np.array([0.4, 0.3]), 0.002, [shape], 0)
    ys, xs = np.nonzero(g.labels == 0)
    extent_x = (xs.max() - xs.min() + 1) * 0.002
    assert 0.06 < extent_x <= 0.09  # the wobbly edge stays within about 10 % of the nominal size
    assert g.remaining().tolist() == [1.0]
    # the truth reports the drawn stain: its centre and the extent along its long axis (here board x)
    truth = g.shapes()[0]
    assert truth.size_m == pytest.approx(extent_x, abs=0.003)
    assert np.allclose(truth.centre_m, (0.2, 0.15), atol=0.004)
    assert truth.extent_m[0] == pytest.approx(extent_x) and truth.extent_m[1] < 0.06
    g.dirt[g.labels == 0] *= 0.5
    assert g.remaining()[0] == pytest.approx(0.5)


def test_stain_specs_are_checked():
    lo, hi = np.array([0.1, 0.1]), np.array([0.7, 0.5])
    assert stains_from_specs([{"centre_m": [0.3, 0.3], "size_m": 0.05}], lo, hi)[0].centre_m == (0.3, 0.3)
    with pytest.raises(ConfigError, match="outside the stain region"):
        stains_from_specs([{"centre_m": [0.05, 0.3], "size_m": 0.05}], lo, hi)
    with pytest.raises(ConfigError, match="unknown key"):
        stains_from_specs([{"centre_m": [0.3, 0.3], "size_m": 0.05, "colour": 1}], lo, hi)
    with pytest.raises(ConfigError, match="needs centre_m"):
        stains_from_specs([{"size_m": 0.05}], lo, hi)


# -- commands ---------------------------------------------------------------------------------------------

def test_command_gate_clips_drops_and_counts():
    counters: Counter = Counter()
    gate = CommandGate(np.array([10.0, 5.0]), counters)
    torques = gate.accept(TorqueCommand(seq=0, stamp_ns=0, tau_nm=[20.0, -1.0]))
    assert torques.kind is CommandKind.TORQUE
    np.testing.assert_array_equal(torques.tau_nm, [10.0, -1.0])
    assert gate.accept(TorqueCommand(seq=0, stamp_ns=0, tau_nm=[1.0])) is None
    assert gate.accept(TorqueCommand(seq=0, stamp_ns=0, tau_nm=[], mode="hold")).kind is CommandKind.HOLD, \
        "the wire's mode string becomes the tagged kind"
    assert counters == Counter(commands_clipped=1, commands_applied=1, commands_dropped_wrong_length=1,
                               commands_hold=1)


# -- camera model ------------------------------------------------------------------------------------------

def test_look_at_gives_an_optical_frame_looking_at_the_target():
    T = look_at(np.array([0.0, 0.0, 2.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    R = T[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R[:, 2], np.array([1.0, 0.0, -2.0]) / math.sqrt(5.0))
    assert R[:, 1] @ np.array([0.0, 0.0, 1.0]) < 0  # image y (down) points away from "up"


@pytest.mark.parametrize("preset", ["wall", "table"])
def test_automatic_camera_sees_the_whole_board(preset):
    cam = CameraParams()
    board = board_from_params(BoardParams(preset=preset))
    k, T = intrinsics_of(cam), camera_pose(cam, board)
    corners = board.world_from_board(np.array([[0, 0], [0.8, 0], [0.8, 0.6], [0, 0.6]]) * board.size_m / [0.8, 0.6])
    px = project(k, T, corners)
    assert np.all(px > 0) and np.all(px[:, 0] < cam.width) and np.all(px[:, 1] < cam.height)
    np.testing.assert_allclose(project(k, T, board.centre_world_m), [cam.cx, cam.cy], atol=1e-6)


def test_quaternion_matrix_round_trip():
    rng = np.random.default_rng(0)
    for q in rng.normal(size=(50, 4)):
        q /= np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        np.testing.assert_allclose(quat_wxyz_from_matrix(matrix_from_quat_wxyz(q)), q, atol=1e-12)


# -- one description for PyBullet and Pinocchio ----------------------------------------------------------

def test_pybullet_and_pinocchio_agree_on_the_description(model):
    board = board_from_params(BoardParams())
    client = pb.connect(pb.DIRECT)
    try:
        q = np.array([0.3, 0.5, -0.2, -1.2, 0.4, 0.8, 0.1])
        world = build_world(client, board, SimParams().contact, q)
        tcp = pb.getLinkState(world.robot, world.tcp_link, computeForwardKinematics=1, physicsClientId=client)
        np.testing.assert_allclose(tcp[4], model.tcp_pose(q)[0], atol=1e-6)
        g = pb.calculateInverseDynamics(world.robot, q.tolist(), [0.0] * 7, [0.0] * 7, physicsClientId=client)
        np.testing.assert_allclose(g, model.gravity(q), atol=1e-6)
        limits = [pb.getJointInfo(world.robot, j, physicsClientId=client)[10] for j in world.joints]
        np.testing.assert_allclose(limits, model.limits.tau_max)
    finally:
        pb.disconnect(client)
    np.testing.assert_allclose(model.limits.tau_max, [320, 320, 176, 176, 110, 40, 40])
    np.testing.assert_allclose(np.degrees(model.limits.q_max), [170, 120, 170, 120, 170, 120, 175], atol=1e-3)
    assert model.tcp_pose(np.zeros(7))[0][2] == pytest.approx(0.36 + 0.42 + 0.40 + 0.126 + 0.035)


def test_tcp_jacobian_matches_finite_differences(model):
    q = np.array([0.2, 0.4, -0.3, -1.1, 0.5, 0.7, -0.2])
    J = model.tcp_jacobian(q)
    eps = 1e-7
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = eps
        dp = (model.tcp_pose(q + dq)[0] - model.tcp_pose(q - dq)[0]) / (2 * eps)
        np.testing.assert_allclose(J[:3, i], dp, atol=1e-6)


# -- the command line ---------------------------------------------------------------------------------------

def test_sim_cli_checks_config_and_board_at_start(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[sim\nmode = 1")
    assert cli.main(["--config", str(bad)]) == 1
    assert "not valid TOML" in capsys.readouterr().err
    behind = tmp_path / "behind.toml"
    behind.write_text('[sim.board]\npreset = "custom"\norigin_m = [-0.5, 0.4, 0.25]\n'
                      'quat_wxyz = [0.5, -0.5, -0.5, 0.5]\nsize_m = [0.8, 0.6]\n')
    assert cli.main(["--config", str(behind), "--check"]) == 1
    assert "impossible board pose" in capsys.readouterr().err
    assert cli.main(["--board", "table", "--stains", "4", "--check"]) == 0
    assert "table board" in capsys.readouterr().out
    assert cli.main(["--camera-size", "big", "--check"]) == 1
    for name, text, message in (
            ("cam", "[sim.camera]\nelevation_deg = 70.0\nazimuth_deg = 70.0\nmargin = 1.0\n", "no camera distance"),
            ("camname", '[sim.camera]\nname = "a*b"\n', "name must be letters"),
            ("camup", "[sim.camera]\nposition_m = [0.68, 0.0, 1.5]\nlook_at_m = [0.68, 0.0, 0.5]\n", "parallel"),
            ("q", "[sim]\nstart_q_rad = [10.0, 0.6, 0.0, -1.4, 0.0, 0.8, 0.0]\n", "outside the description's limits"),
            ("angle", "[sim.dirt]\nstain = [{centre_m = [0.3, 0.3], size_m = 0.05, angle_deg = inf}]\n",
             "angle_deg finite")):
        path = tmp_path / f"{name}.toml"
        path.write_text(text)
        assert cli.main(["--config", str(path), "--check"]) == 1, name
        assert message in capsys.readouterr().err, name
    with pytest.raises(SystemExit) as exc:
        cli.main(["--mode", "warp"])
    assert exc.value.code == 2


def test_the_example_config_loads_and_says_the_defaults():
    from runtime.config import load_config

    cfg = load_config(Path(__file__).resolve().parent.parent / "config" / "example.toml", env={})
    assert SimParams.from_table(cfg.table("sim")) == SimParams()
    assert cfg.zenoh.listen == ("tcp/127.0.0.1:7447",)


# -- the renderer process ---------------------------------------------------------------------------------

@pytest.mark.slow
def test_renderer_shows_wiped_dirt_and_survives_its_own_death():
    import threading

    from sim.core import SimCore
    from sim.renderer import CameraProcess

    params = SimParams.from_table({"camera": {"width": 320, "height": 240}, "dirt": {"stain": [
        {"centre_m": [0.62, 0.42], "size_m": 0.1, "aspect": 1.0}]}})  # upper right: clear of the arm
    core = SimCore(params)
    cam = CameraProcess(params, core.board, core.q_start, core.dirt.dirt.shape)
    frames = []
    stop = threading.Event()
    try:
        cam.start()
        thread = threading.Thread(target=cam.serve, args=(frames.append, stop), daemon=True)
        thread.start()
        pixel = np.round(project(intrinsics_of(params.camera), core.T_camera_to_world,
                                 core.board.world_from_board(np.array([0.62, 0.42])))).astype(int)
        for version, dirt in ((1, core.dirt.dirt), (2, np.zeros_like(core.dirt.dirt))):
            assert cam.request(version, 0, 0, core.q_start, dirt, version)
            assert cam.wait_idle(30.0)
        assert [f.seq for f in frames] == [1, 2]
        images = [np.frombuffer(f.data, np.uint8).reshape(240, 320, 3).astype(int) for f in frames]
        stained, clean = (img[pixel[1], pixel[0]] for img in images)
        assert stained[2] > stained[0] + 30 and clean.min() > 150, (stained, clean)  # blue ink, then white board
        cam._proc.kill()
        cam._proc.join(5.0)
        assert cam.wait_idle(5.0)

        def noticed() -> bool:  # a request to the dead renderer (or its publisher thread) finds it gone
            cam.request(3, 0, 0, core.q_start, core.dirt.dirt, 3)
            return cam.dead

        wait_for(noticed, 5.0, "the camera noticing that its renderer died", period_s=0.05)
        assert cam.dead and not cam.request(4, 0, 0, core.q_start, core.dirt.dirt, 4)
    finally:
        stop.set()
        cam.close()
        cam.close()  # idempotent
        core.close()


# -- the brakes ------------------------------------------------------------------------------------------

def test_a_stop_once_begun_ends_with_the_arm_standing_before_torques_apply_again():
    """A brake stops the arm over BRAKE_STOP_S; a command that comes meanwhile is held until the arm has stood a
    step, so what the gate climbs from (held_torque_nm) is the brakes' hold, not their deceleration. Released a
    step into standing, that deceleration carried on and swung the wrist (80 rad/s^2 on A6, the pad at 46 N)."""
    from robot.port import Applied
    from runtime.config import ZenohSettings
    from runtime.local_bus import LocalBus, LocalNode
    from sim.core import SimCore
    from sim.robot import BRAKE_STOP_S
    from sim.service import SimPort

    params = SimParams.from_table({"camera": {"enabled": False}, "gravity_compensated": True})
    core = SimCore(params)
    with LocalNode("sim", LocalBus(), ZenohSettings(robot_id="brakes")) as node:
        port = SimPort(params, node, core, publish_frames=False)
        push = np.zeros(7)
        push[5] = 2.0  # A6 [Nm] on top of the gravity compensation
        for _ in range(100):
            assert port.write(push) == Applied.TORQUES
        dq0 = core.out.dq[5]
        assert dq0 > 0.3, dq0
        assert port.hold() == Applied.HELD  # the brake engages
        ramp = int(round(BRAKE_STOP_S * params.rate_hz))
        decelerating = port.held_torque_nm()[5]
        outcomes = [port.write(push) for _ in range(ramp + 3)]
        held = outcomes.count(Applied.HELD)
        assert held == ramp and outcomes[held:] == [Applied.TORQUES] * 3, outcomes  # the ramp's rest and a step
        assert port.counters()["commands_held_to_finish_a_stop"] == ramp
    assert decelerating < -5.0, decelerating  # the brakes' torque while they stop A6
    with LocalNode("sim", LocalBus(), ZenohSettings(robot_id="brakes")) as node:  # what they hold it with: ~0
        core2 = SimCore(params)
        port2 = SimPort(params, node, core2, publish_frames=False)
        for _ in range(100):
            port2.write(push)
        for _ in range(ramp + 2):
            port2.hold()
        assert abs(core2.out.dq[5]) < 1e-3 and abs(port2.held_torque_nm()[5]) < 0.2 * abs(decelerating), \
            port2.held_torque_nm()
