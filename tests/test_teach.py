"""Teach mode: the hand-guiding law, the simulated hand, the recorder, ``lamps teach``; and the whole loop: taught in
the sim by a scripted hand wiping three stains -> ``lamps learn`` -> ``lamps up --skill`` cleans seeded boards."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from arm.robot_model import RobotModel
from controller.params import ControllerParams
from controller.teach import TeachCore
from interfaces.errors import ConfigError
from interfaces.messages import Phase
from launch.teach_cell import PathRecorder
from sim.hand import Hand, HandScript, rotation_vector
from sim.params import HandParams

from .conftest import REPO
from .core_ticks import tick

LAMPS = (sys.executable, "-m", "runtime.cli")
Q = np.array([0.1, 0.6, -0.1, -1.4, 0.1, 0.8, 0.2])


def _core(**teach) -> TeachCore:
    return TeachCore(ControllerParams.from_table({"teach": teach, "limits": {"torque_rate_nm_per_ms": 50.0}}))


def test_at_rest_the_arm_gets_its_gravity_and_nothing_else():
    """No stiffness: wherever it is, the arm at rest is only held up (or, when the robot adds gravity, left alone)."""
    core, model = _core(), RobotModel()
    for q in (Q, Q + 0.3):
        tau = tick(core, q, np.zeros(7), np.zeros(6), False, 1e-3).copy()
        np.testing.assert_allclose(tau, model.gravity(q), atol=1e-9)
        np.testing.assert_allclose(tick(core, q, np.zeros(7), np.zeros(6), True, 1e-3), 0.0, atol=1e-9)
    assert core.executor.phase == Phase.TEACH


def test_moving_the_arm_meets_only_damping():
    """Beyond C dq (no power), the torque takes power out of every motion: dq . (tau - C dq) < 0, and it is the
    Cartesian damping on the pad's twist plus the joint damping."""
    core, model = _core(), RobotModel()
    rng = np.random.default_rng(0)
    for _ in range(5):
        dq = rng.normal(0.0, 0.2, 7)
        tau = tick(core, Q, dq, np.zeros(6), True, 1e-3).copy()
        coriolis = core.kin.nle - core.kin.g
        J = model.tcp_jacobian(Q)
        D = np.diag([25.0] * 3 + [1.0] * 3)
        np.testing.assert_allclose(tau - coriolis, -J.T @ D @ J @ dq - 0.5 * dq, atol=1e-6)
        assert dq @ (tau - coriolis) < 0.0


def test_a_contact_force_over_the_cap_halts_into_a_hold_of_that_pose():
    core = _core(force_cap_n=20.0)
    for _ in range(30):
        tick(core, Q, np.zeros(7), np.array([0.0, 0.0, 30.0, 0, 0, 0]), True, 1e-3)
    assert core.executor.phase == Phase.FAULT and "above the teach cap 20 N" in core.executor.reason
    pushed = Q + np.r_[0.05, np.zeros(6)]
    tau = tick(core, pushed, np.zeros(7), np.zeros(6), True, 1e-3)
    assert tau[0] < -1.0  # pulled back towards the pose of the halt
    core.executor.clear()  # a fault stays latched; an e-stop released does not
    assert core.executor.phase == Phase.FAULT
    fresh = _core()
    fresh.executor.estop("test")
    fresh.executor.clear()
    assert fresh.executor.phase == Phase.TEACH


def test_the_hand_script_interpolates_holds_its_ends_and_refuses_bad_files(tmp_path):
    s = HandScript(np.array([0.0, 1.0, 2.0]), np.array([[0, 0, 0], [1, 0, 0], [1, 2, 0.0]]), False)
    v, r = np.zeros(3), np.zeros(3)
    s.at(0.5, v, r)
    np.testing.assert_allclose(v, [0.5, 0, 0])
    s.at(1.5, v, r)
    np.testing.assert_allclose(v, [1.0, 1.0, 0])
    s.at(9.0, v, r)
    np.testing.assert_allclose(v, [1, 2, 0]) and np.testing.assert_allclose(r, 0.0)
    bad = tmp_path / "bad.csv"
    bad.write_text("t,a,b\n0,1,2\n1,2,3\n")
    with pytest.raises(ConfigError, match="has neither t,x,y,z nor t,fx,fy,fz"):
        HandScript.read(bad)
    bad.write_text("t,x,y,z\n0,1,2,3\n0,2,3,4\n")
    with pytest.raises(ConfigError, match="strictly increasing"):
        HandScript.read(bad)


def test_the_hand_pulls_the_pad_towards_its_path_clamped_and_holds_the_tool_upright():
    script = HandScript(np.array([0.0, 1.0]), np.array([[0.5, 0.0, 0.5]] * 2), False)
    hand = Hand(HandParams(stiffness_n_m=1000.0, damping_n_s_m=0.0, max_force_n=30.0), script, np.eye(3))
    w = hand.update(0.5, np.array([0.49, 0.0, 0.5]), np.zeros(3), np.eye(3), np.zeros(3))
    np.testing.assert_allclose(w[:3], [10.0, 0, 0])
    w = hand.update(0.5, np.array([0.0, 0.0, 0.5]), np.zeros(3), np.eye(3), np.zeros(3))
    np.testing.assert_allclose(w[:3], [30.0, 0, 0])  # 500 N asked, the hand gives at most 30
    c, s = np.cos(0.1), np.sin(0.1)
    tilted = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    w = hand.update(0.5, np.array([0.5, 0.0, 0.5]), np.zeros(3), tilted, np.zeros(3))
    np.testing.assert_allclose(w[3:], [0, 0, -0.1 * 30.0], atol=1e-9)  # turned back
    np.testing.assert_allclose(rotation_vector(tilted), [0, 0, 0.1], atol=1e-12)


def test_the_recorder_keeps_the_rate_on_the_robot_clock_and_gives_the_pad_path():
    rec = PathRecorder(200.0)
    for k in range(1001):  # 1 s of states at 1 kHz
        rec.add(k * 1_000_000, Q)
    assert len(rec.t_ns) == 201 and rec.duration_s == pytest.approx(1.0)
    t, p, quat = rec.pad_path(RobotModel())
    np.testing.assert_allclose(np.diff(t), 0.005)
    np.testing.assert_allclose(p[0], RobotModel().tcp_pose(Q)[0])
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0)


@pytest.mark.parametrize("args, match", [
    (["--out", "demo.txt", "--no-network"], "write a .csv or a .npz"),
    (["--out", "demo.csv", "--hand", "h.csv"], "--hand is the simulator's"),
    (["--out", "demo.csv", "--no-network", "--duration", "0.1"], "--duration must be in"),
])
def test_teach_refuses_bad_options_before_anything_runs(tmp_path, args, match):
    r = subprocess.run([*LAMPS, "teach", *args], capture_output=True, text=True, timeout=120, cwd=tmp_path,
                       env={**os.environ, "PYTHONPATH": str(REPO)})
    assert r.returncode == 1 and match in r.stderr, r.stderr
    assert not list(tmp_path.iterdir())


def test_a_hand_that_holds_the_pad_off_its_start_moves_it_there(tmp_path):
    """Hand and teach law together in the sim: the hand's spring alone carries the free arm to where it holds."""
    from sim.core import SimCore
    from sim.params import SimParams

    base = SimCore(SimParams.from_table({"camera": {"enabled": False}}))
    p0 = base.out.tcp_p.copy()
    base.close()
    goal = p0 + np.array([0.0, 0.05, 0.03])
    script = tmp_path / "hand.csv"
    script.write_text("t,x,y,z\n" + f"0,{p0[0]},{p0[1]},{p0[2]}\n0.5,{goal[0]},{goal[1]},{goal[2]}\n")
    sim = SimCore(SimParams.from_table({"camera": {"enabled": False}, "hand": {"script": str(script)}}))
    core = _core()
    try:
        for _ in range(2000):
            o = sim.out
            sim.step(tick(core, o.q, o.dq, o.wrench, False, 1e-3).copy())
        assert np.linalg.norm(sim.out.tcp_p - goal) < 0.004, sim.out.tcp_p - goal
        assert np.linalg.norm(sim.out.tcp_v) < 0.01 and core.executor.phase == Phase.TEACH
    finally:
        sim.close()


@pytest.mark.slow
def test_taught_in_the_sim_learned_and_run_it_cleans_seeded_boards(tmp_path):
    """The whole loop: `lamps teach --no-network` (the scripted hand wiping three stains) -> `lamps learn` finds
    three periodic MPs -> `lamps up --skill --no-network` removes >= 98 % on two seeded boards."""
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": str(REPO)}
    t0 = time.monotonic()
    demo = tmp_path / "demo.csv"
    r = subprocess.run([*LAMPS, "teach", "--no-network", "--out", str(demo)], capture_output=True, text=True,
                       timeout=300, env=env, cwd=tmp_path)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert (tmp_path / "demo-hand.csv").is_file() and "wrote" in r.stdout
    t_teach = time.monotonic() - t0
    skill = tmp_path / "skill.json"
    r = subprocess.run([*LAMPS, "learn", str(demo), "-o", str(skill)], capture_output=True, text=True, timeout=300,
                       env=env, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    learned = json.loads(skill.read_text())
    assert len(learned["periodic"]) == 3, r.stdout
    removed = []
    for seed in (1, 2):
        out = tmp_path / f"up{seed}"
        r = subprocess.run([*LAMPS, "up", "-q", "--no-network", "--skill", str(skill), "--seed", str(seed),
                            "--out", str(out), "--max-duration", "300"], capture_output=True, text=True, timeout=400,
                           env=env, cwd=REPO)
        assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
        removed.append(json.loads((out / "report.json").read_text())["dirt_removed_fraction"])
    assert min(removed) >= 0.98, removed
    print(f"taught in {t_teach:.0f} s wall; removed {[f'{v:.1%}' for v in removed]}; "
          f"{time.monotonic() - t0:.0f} s wall in all")
