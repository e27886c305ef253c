"""A real camera's path end to end: a ROS 2 image topic at 30 frames/s into a running ``lamps perception``.

What a RealSense or UVC camera's ROS driver and zenoh-bridge-ros2dds put on
the cell's keys (``sensor_msgs/msg/Image`` rgb8, 1280x720, as CDR written by
rosbags, the header stamped with the wall clock at the put; its
``camera_info`` once a second) is put by a publisher session at the camera's
rate, each frame a photograph of a real board with fresh sensor noise.
``lamps perception --source ros:/camera/color/image_raw`` with the real-board
profile (``tests/fixtures/whiteboards/board.toml``) runs as its own process,
pinned to one core (``taskset``, when there is one to spare) while the
publisher has the other. Reported from perception's own status: frames
processed per second of the stream, the share of frames processed, the
arrival-to-stains latency p50/p99 (``frame_to_stains``: decoding and
processing) and the capture-to-stains latency p50/p99 (``capture_to_stains``:
the header's stamp to the stains message, transport included), and the
stains found against the photograph's hand-made labels.

``--baseline REV``: the same stream into that revision's perception (a
temporary git worktree), streams alternating, in one run.

Run: ``.venv/bin/python bench/bench_camera_path.py [--seconds 20] [--baseline REV] [--json OUT]``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from service_procs import BenchError, Proc, free_port  # noqa: E402

from interfaces.messages import ServiceStatus, Stains  # noqa: E402
from perception.ros_images import store  # noqa: E402
from runtime.config import ZenohSettings  # noqa: E402
from runtime.session import ServiceNode  # noqa: E402

TOPIC = "/camera/color/image_raw"
BOARD = REPO / "tests" / "fixtures" / "whiteboards" / "board.toml"
#: Distinct noisy frames made per stream (put in turn): the noise a sensor adds, without the cost of making it
#: at the camera's rate.
VARIANTS = 24


def image_cdr(rgb: np.ndarray) -> bytearray:
    """``sensor_msgs/msg/Image`` rgb8 of ``rgb`` (h, w, 3) as CDR; its stamp is set by :func:`stamp`."""
    ts = store()
    h, w = rgb.shape[:2]
    header = ts.types["std_msgs/msg/Header"](stamp=ts.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0),
                                            frame_id="camera_color_optical_frame")
    msg = ts.types["sensor_msgs/msg/Image"](header=header, height=h, width=w, encoding="rgb8", is_bigendian=0,
                                            step=3 * w, data=np.ascontiguousarray(rgb).ravel())
    return bytearray(ts.serialize_cdr(msg, "sensor_msgs/msg/Image"))


def stamp(cdr: bytearray, wall_ns: int) -> bytearray:
    """``cdr`` with its header stamped ``wall_ns`` [ns since the epoch]: after the 4-byte encapsulation, the
    header's ``builtin_interfaces/Time`` (int32 sec, uint32 nanosec, little-endian)."""
    struct.pack_into("<iI", cdr, 4, wall_ns // 1_000_000_000, wall_ns % 1_000_000_000)
    return cdr


def info_cdr(K: np.ndarray, w: int, h: int) -> bytes:
    """``sensor_msgs/msg/CameraInfo`` with ``K`` (3, 3) [px] and no distortion."""
    ts = store()
    header = ts.types["std_msgs/msg/Header"](stamp=ts.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0),
                                            frame_id="camera_color_optical_frame")
    roi = ts.types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    msg = ts.types["sensor_msgs/msg/CameraInfo"](
        header=header, height=h, width=w, distortion_model="plumb_bob", d=np.zeros(5), k=K.ravel().astype(float),
        r=np.eye(3).ravel(), p=np.hstack([K, np.zeros((3, 1))]).ravel(), binning_x=0, binning_y=0, roi=roi)
    return bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/CameraInfo"))


def noisy_frames(rgb: np.ndarray, n: int, seed: int = 0) -> list[bytearray]:
    """``n`` CDR images of ``rgb`` each with fresh sensor noise (sigma 2 grey levels)."""
    rng = np.random.default_rng(seed)
    return [image_cdr(np.clip(rgb + rng.normal(0.0, 2.0, rgb.shape), 0, 255).astype(np.uint8)) for _ in range(n)]


def _seen(msg: Stains | None) -> Stains | None:
    """``msg`` if it holds a board in view (after the stream perception says "lost": no frames)."""
    return msg if msg is not None and msg.board != "lost" else None


def _cores() -> list[str]:
    """``taskset -c 1`` for the perception process when this machine has a second core and taskset, else []."""
    return ["taskset", "-c", "1"] if (os.cpu_count() or 1) >= 2 and shutil.which("taskset") else []


def stream(frames: list[bytearray], K: np.ndarray, size: tuple[int, int], seconds: float, rate_hz: float = 30.0,
           tree: Path = REPO, log_dir: Path | None = None) -> dict:
    """Put ``frames`` in turn at ``rate_hz`` for ``seconds`` into ``tree``'s ``lamps perception`` (ros source, the
    real-board profile); its figures (module docstring) and the last stains message."""
    port = free_port()
    rid = f"cam{port}"
    ep = f"tcp/127.0.0.1:{port}"
    log_dir = log_dir or Path(tempfile.mkdtemp(prefix="camera-path-"))
    env = {"PYTHONPATH": str(tree), "LAMPS__PERCEPTION__STATUS_RATE_HZ": "4"}
    proc = Proc(f"perception-{tree.name}", _cores() + [
        sys.executable, "-m", "perception.cli", "--config", str(tree / BOARD.relative_to(REPO)),
        "--source", f"ros:{TOPIC}", "--listen", ep, "--robot-id", rid], log_dir, env, cwd=tree)
    node = ServiceNode("bridge", ZenohSettings(connect=(ep,), robot_id=rid, insecure=True))
    node.__enter__()
    try:
        status = node.latest(node.keys.perception_status, ServiceStatus)
        stains = node.latest(node.keys.perception_stains, Stains)
        info = info_cdr(K, *size)
        t_end = time.monotonic() + 60.0
        while status.take() is None:  # perception up and subscribed (its first status)
            proc.check()
            if time.monotonic() > t_end:
                raise BenchError("perception sent no status within 60 s")
            node.session.put("camera/color/camera_info", info)
            time.sleep(0.1)
        for _ in range(5):
            node.session.put("camera/color/camera_info", info)
            time.sleep(0.05)
        period, sent, last = 1.0 / rate_hz, 0, None
        t0 = time.monotonic()
        next_t = t0
        while (now := time.monotonic()) < t0 + seconds:
            if now < next_t:
                time.sleep(next_t - now)
            node.session.put("camera/color/image_raw", stamp(frames[sent % len(frames)], time.time_ns()))
            sent += 1
            next_t += period
            if sent % int(rate_hz) == 0:
                node.session.put("camera/color/camera_info", info)
            last = _seen(stains.take()) or last
        wall = time.monotonic() - t0
        time.sleep(1.0)  # the last frames processed, a status after them
        s = None
        t_end = time.monotonic() + 10.0
        while time.monotonic() < t_end:
            s = status.take() or s
            last = _seen(stains.take()) or last
            time.sleep(0.05)
        proc.check()
        if s is None:
            raise BenchError("no perception status after the stream")
        c = s.counters
        bad = {k: v for k, v in c.items() if k.startswith("frames_bad")}
        return {"sent": sent, "stream_s": wall, "camera_fps": sent / wall,
                "processed": c.get("frames_processed", 0), "processed_fps": c.get("frames_processed", 0) / wall,
                "processed_share": c.get("frames_processed", 0) / max(sent, 1),
                "frame_to_stains_p50_ms": c.get("frame_to_stains_p50_us", 0) / 1e3,
                "frame_to_stains_p99_ms": c.get("frame_to_stains_p99_us", 0) / 1e3,
                "capture_to_stains_p50_ms": c.get("capture_to_stains_p50_us", 0) / 1e3,
                "capture_to_stains_p99_ms": c.get("capture_to_stains_p99_us", 0) / 1e3,
                "process_p50_ms": c.get("process_p50_us", 0) / 1e3, "frames_bad": bad,
                "stains": None if last is None else [{"id": st.id, "colour": st.colour, "size_m": st.size_m,
                                                      "centre_board_m": st.centre_board_m} for st in last.stains],
                "board": None if last is None else last.board}
    finally:
        node.close()
        proc.stop()


def photograph(name: str = "straight"):
    """(rgb (720, 1280, 3), K (3, 3)) of a photograph as a 1280x720 camera sends it (bench_ink_model's framing)."""
    from bench_ink_model import photo_frames

    frames, _, _ = photo_frames(1280, 720)
    rgb, K, _ = frames[("straight", "sideangle", "highangle").index(name)]
    return rgb, K


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="each stream's length [s] (default 20)")
    ap.add_argument("--rate", type=float, default=30.0, help="the camera's frames/s (default 30)")
    ap.add_argument("--photos", default="straight,sideangle,highangle", help="photographs streamed, one stream each")
    ap.add_argument("--baseline", metavar="REV", help="also stream into this revision's perception, alternating")
    ap.add_argument("--json", metavar="OUT", help="write the figures as JSON")
    a = ap.parse_args()
    trees = {"this": REPO}
    tmp = Path(tempfile.mkdtemp(prefix="camera-path-"))
    if a.baseline:
        trees = {"baseline": tmp / "baseline", "this": REPO}
        subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(trees["baseline"]), a.baseline],
                       check=True, capture_output=True)
    out: dict = {}
    try:
        for name in a.photos.split(","):
            rgb, K = photograph(name)
            frames = noisy_frames(rgb, VARIANTS)
            for which, tree in trees.items():
                r = stream(frames, K, (1280, 720), a.seconds, a.rate, tree, tmp)
                out.setdefault(name, {})[which] = r
                print(f"{name} {which}: {json.dumps({k: v for k, v in r.items() if k != 'stains'})}", flush=True)
    finally:
        if a.baseline:
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(trees["baseline"])],
                           check=False)
    print("\n| photograph | tree | camera frames/s | processed frames/s (share) | arrival to stains p50 / p99 [ms] "
          "| capture to stains p50 / p99 [ms] | stains |")
    print("|---|---|---|---|---|---|---|")
    for name, runs in out.items():
        for which, r in runs.items():
            cap = (f"{r['capture_to_stains_p50_ms']:.1f} / {r['capture_to_stains_p99_ms']:.1f}"
                   if r["capture_to_stains_p50_ms"] else "not reported")
            arrival = (f"{r['frame_to_stains_p50_ms']:.1f} / {r['frame_to_stains_p99_ms']:.1f}"
                       if r["frame_to_stains_p50_ms"] else "not reported")
            print(f"| {name} | {which} | {r['camera_fps']:.1f} | {r['processed_fps']:.1f} "
                  f"({r['processed_share']:.0%}) | {arrival} | {cap} | {len(r['stains'] or [])} |")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
