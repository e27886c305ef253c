"""Simulator benchmarks: physics alone, lock-step round trips over Zenoh, rendering, real-time jitter.

Usage: .venv/bin/python bench/bench_sim.py [--quick] [--only PART ...] [--json OUT]

1. Physics steps per second of ``SimCore.step`` alone (no network): the arm
   holding still in free space, and pressing the pad on the board while
   sliding (contacts + dirt removal). Baseline: the 1 kHz real-time budget;
   the ratio is the real-time factor the physics alone could reach.
2. Lock-step round trips per second: ``lamps sim`` in its own process, a
   minimal client (zero torques on a gravity-compensated arm) answering
   each state over Zenoh on loopback. Baseline: 1 kHz.
3. Rendering time per frame on the mirrored scene, then the dirt drawn in
   image space, at 320x240 and 640x480, for both renderers on the same poses:
   TinyRenderer, and the analytic camera (``sim/analytic_camera.py``; its
   once-per-scene board image is timed apart). Baseline: the 100 ms period of
   a 10 Hz camera.
4. Real-time mode: step-period jitter (p50, p99, max) from the stamps of
   every ``robot/state`` received over 30 s (10 s with --quick) while the
   camera renders 640x480 at 10 Hz, plus overruns and lost states.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from arm.robot_model import RobotModel  # noqa: E402
from interfaces.messages import RobotState, TorqueCommand  # noqa: E402
from sim.core import SimCore  # noqa: E402
from sim.params import SimParams  # noqa: E402
from tests.zenoh_helpers import SimProcess, latest_status, run_lockstep  # noqa: E402


def bench_physics(steps: int) -> list[dict]:
    from tests.test_sim_service import PressAndSlide

    model = RobotModel()
    rows = []
    for case in ("free space, hold", "pressing 10 N and sliding"):
        core = SimCore(SimParams.from_table({"camera": {"enabled": False}}))
        policy = PressAndSlide(model, core.board, core.board.size_m / 2) if "press" in case else None
        taus = []
        # precompute the client's torques outside the timed region: time the sim only
        for _ in range(1500 if policy else 0):
            s = _fake_state(core)
            core.step(policy(s))
        t_total, n = 0.0, 0
        for _ in range(steps):
            tau = policy(_fake_state(core)) if policy else core.robot.gravity()
            t0 = time.perf_counter()
            core.step(tau)
            t_total += time.perf_counter() - t0
            n += 1
        del taus
        rate = n / t_total
        rows.append({"case": case, "steps_per_s": rate, "us_per_step": 1e6 / rate, "x_realtime": rate / 1000.0,
                     "contact_force_n": core.out.normal_force_n})
        core.close()
    return rows


def _fake_state(core: SimCore) -> RobotState:
    from interfaces.messages import Capabilities

    o = core.out
    return RobotState(seq=core.steps, stamp_ns=0, q_rad=o.q.tolist(), dq_rad_s=o.dq.tolist(), tau_nm=o.tau.tolist(),
                      wrench_world=o.wrench.tolist(), capabilities=Capabilities(False, core.tau_max.tolist()),
                      robot_time_ns=core.time_ns)


def bench_lockstep(steps: int) -> dict:
    zeros = np.zeros(7)
    with tempfile.TemporaryDirectory() as tmp:
        with SimProcess(Path(tmp), {"mode": "lockstep", "gravity_compensated": True,
                                    "camera": {"enabled": False}}) as sim:
            run_lockstep(sim, 200, lambda s: zeros)  # warm up
            t0 = time.perf_counter()
            run_lockstep(sim, steps, lambda s: zeros)
            dt = time.perf_counter() - t0
    return {"round_trips_per_s": steps / dt, "us_per_round_trip": dt / steps * 1e6, "x_realtime": steps / dt / 1000.0}


def bench_render(frames: int) -> list[dict]:
    """Both renderers on the same scene and poses (the start, then joints moved by up to 0.2 rad, seeded)."""
    import pybullet as pb

    from sim.analytic_camera import AnalyticCamera
    from sim.camera import (
        DirtCompositor,
        board_cell_index,
        board_texture,
        camera_pose,
        intrinsics_of,
        light_towards,
        marker_layer,
        projection_matrix,
        view_matrix,
    )
    from sim.world import build_world

    rows = []
    for w, h in ((320, 240), (640, 480)):
        params = SimParams.from_table({"camera": {"width": w, "height": h}})
        core = SimCore(params)
        client = pb.connect(pb.DIRECT)
        world = build_world(client, core.board, params.contact, core.q_start, visual=True)
        markers = marker_layer(core.board.size_m)
        tex = board_texture(np.zeros_like(core.dirt.dirt), params.dirt.cell_m, markers, core.board.size_m)
        with tempfile.TemporaryDirectory() as tmp:
            import cv2

            path = str(Path(tmp) / "b.png")
            cv2.imwrite(path, tex[..., ::-1])
            tex_id = pb.loadTexture(path, physicsClientId=client)
        pb.changeVisualShape(world.board, -1, textureUniqueId=tex_id, physicsClientId=client)
        k = intrinsics_of(params.camera)
        T_cam = camera_pose(params.camera, core.board)
        view, proj = view_matrix(T_cam), projection_matrix(k)
        light = light_towards(params.camera, core.board)
        composite_dirt = DirtCompositor(board_cell_index(k, T_cam, core.board, params.dirt.cell_m,
                                                         core.dirt.dirt.shape))  # as the renderer process draws it
        t0 = time.perf_counter()
        analytic = AnalyticCamera(world, params.camera, k, T_cam, np.asarray(light), core.board.origin_m,
                                  core.board.normal_world)
        setup_ms = 1e3 * (time.perf_counter() - t0)
        rng = np.random.default_rng(0)
        poses = [core.q_start + (0.0 if i == 0 else rng.uniform(-0.2, 0.2, 7)) for i in range(frames)]
        rgb = np.zeros((h, w, 3), np.uint8)
        for name in ("tiny", "analytic"):
            render, texture = [], []
            for q in poses:
                t1 = time.perf_counter()
                if name == "tiny":
                    for j, qj in zip(world.joints, q):
                        pb.resetJointState(world.robot, j, float(qj), physicsClientId=client)
                    out = pb.getCameraImage(w, h, view, proj, renderer=pb.ER_TINY_RENDERER, shadow=1,
                                            lightDirection=light, physicsClientId=client)
                    rgb[...] = np.asarray(out[2], np.uint8).reshape(h, w, 4)[..., :3]
                    visible = np.asarray(out[4]).reshape(-1) == world.board
                else:
                    visible = analytic.render(rgb, q)
                t2 = time.perf_counter()
                composite_dirt(rgb, visible, core.dirt.dirt)
                t3 = time.perf_counter()
                texture.append(t3 - t2)
                render.append(t2 - t1)
            total = np.array(render) + np.array(texture)
            rows.append({"size": f"{w}x{h}", "renderer": name, "render_ms_p50": 1e3 * np.median(render),
                         "dirt_ms_p50": 1e3 * np.median(texture), "total_ms_p50": 1e3 * np.median(total),
                         "total_ms_max": 1e3 * total.max(), "max_fps": 1.0 / np.median(total),
                         "setup_ms": setup_ms if name == "analytic" else 0.0})
        pb.disconnect(client)
        core.close()
    return rows


def bench_realtime(duration_s: float) -> dict:
    zeros = [0.0] * 7
    with tempfile.TemporaryDirectory() as tmp:
        cfg = {"mode": "realtime", "gravity_compensated": True, "stale_limit_s": 0.05,
               "camera": {"width": 640, "height": 480, "rate_hz": 10.0}}
        with SimProcess(Path(tmp), cfg) as sim:
            inbox = sim.node.inbox(sim.keys.robot_state, RobotState, maxlen=100_000)
            stamps, seqs = [], []
            end = time.monotonic() + duration_s + 1.0
            while time.monotonic() < end:
                s = inbox.get(0.1)
                if s is None:
                    continue
                stamps.append(s.stamp_ns)
                seqs.append(s.seq)
                sim.node.publish(sim.keys.robot_command, TorqueCommand(seq=s.seq, stamp_ns=time.monotonic_ns(),
                                                                       tau_nm=zeros))
            status = latest_status(sim)
    stamps, seqs = np.array(stamps), np.array(seqs)
    keep = stamps >= stamps[0] + 1e9  # drop the first second (start-up)
    stamps, seqs = stamps[keep], seqs[keep]
    gaps = np.diff(seqs)
    periods_us = np.diff(stamps)[gaps == 1] / 1e3
    return {"duration_s": (stamps[-1] - stamps[0]) / 1e9, "states": int(len(stamps)),
            "lost_states": int((gaps - 1).clip(min=0).sum()), "period_p50_us": float(np.percentile(periods_us, 50)),
            "period_p99_us": float(np.percentile(periods_us, 99)), "period_max_us": float(periods_us.max()),
            "sim_overruns": status.timing.overruns, "sim_ticks": status.timing.ticks,
            "camera_frames": status.counters.get("camera_frames", 0),
            "camera_ticks_skipped": status.counters.get("camera_ticks_skipped", 0)}


PARTS = ("physics", "lockstep", "render", "realtime")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer steps, 10 s real-time run")
    ap.add_argument("--json", metavar="OUT", help="also write the figures as JSON")
    ap.add_argument("--only", choices=PARTS, action="append",
                    help="run only this part (repeatable); default: all of " + ", ".join(PARTS))
    a = ap.parse_args()
    q, parts = a.quick, a.only or PARTS
    res = {"machine": f"{platform.machine()}, {platform.python_version()}"}
    if "physics" in parts:
        res["physics"] = bench_physics(1000 if q else 5000)
    if "lockstep" in parts:
        res["lockstep"] = bench_lockstep(1000 if q else 5000)
    if "render" in parts:
        res["render"] = bench_render(5 if q else 20)
    if "realtime" in parts:
        res["realtime"] = bench_realtime(10.0 if q else 30.0)
    print(f"Simulator benchmarks ({res['machine']})")
    if "physics" in res:
        print("\n| physics alone | steps/s | us/step | x real time (1 kHz) |\n|---|---|---|---|")
        for r in res["physics"]:
            print(f"| {r['case']} | {r['steps_per_s']:.0f} | {r['us_per_step']:.0f} | {r['x_realtime']:.1f} |")
    if "lockstep" in res:
        lk = res["lockstep"]
        print("\n| lock-step over Zenoh, minimal client | round trips/s | us each | x real time |\n|---|---|---|---|")
        print(f"| sim process + client process | {lk['round_trips_per_s']:.0f} | {lk['us_per_round_trip']:.0f} | "
              f"{lk['x_realtime']:.2f} |")
    if "render" in res:
        print("\n| camera frame | renderer | render ms (p50) | dirt drawing ms (p50) | total ms (p50 / max) | "
              "frames/s possible | once per scene ms |\n|---|---|---|---|---|---|---|")
        for r in res["render"]:
            setup = f"{r['setup_ms']:.0f}" if r["renderer"] == "analytic" else "-"
            print(f"| {r['size']} | {r['renderer']} | {r['render_ms_p50']:.1f} | {r['dirt_ms_p50']:.1f} | "
                  f"{r['total_ms_p50']:.1f} / {r['total_ms_max']:.1f} | {r['max_fps']:.1f} | {setup} |")
    if "realtime" in res:
        rt = res["realtime"]
        print(f"\n| real-time mode, camera 640x480 @ 10 Hz, {rt['duration_s']:.0f} s | p50 us | p99 us | max us | "
              f"overruns | lost states | frames |\n|---|---|---|---|---|---|---|")
        print(f"| step period from robot/state stamps | {rt['period_p50_us']:.0f} | {rt['period_p99_us']:.0f} | "
              f"{rt['period_max_us']:.0f} | {rt['sim_overruns']} / {rt['sim_ticks']} | {rt['lost_states']} | "
              f"{rt['camera_frames']} (skipped {rt['camera_ticks_skipped']}) |")
    if a.json:
        from lampskit.atomic import write_text_atomic

        write_text_atomic(Path(a.json), json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
