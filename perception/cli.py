"""``lamps perception``: stains and kappa from camera images, as a Zenoh service or over files.

Configuration comes from ``--config FILE`` (TOML, ``[zenoh]`` and
``[perception]`` tables, see :mod:`perception.params`), then ``LAMPS_*``
environment variables, then the options below. The source is the camera on
Zenoh (default), or ``--source folder:DIR`` / ``video:FILE`` for offline
checks, or ``device:N`` for a live UVC camera (a RealSense colour stream);
offline sources can write every stains message as a JSON line with
``--jsonl FILE`` and run without Zenoh (``--no-zenoh``). A bad config or
source is a one-line error and exit code 1; Ctrl-C or SIGTERM stops it.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys

import msgspec

from interfaces.errors import InterfaceError
from lampskit.errors import LampsError
from runtime.config import add_zenoh_options, load_config, zenoh_with_options
from runtime.priority import BACKGROUND, set_service_priority, wanted_nice
from runtime.service_main import log_to_stderr, refuse, serve
from runtime.stop_signals import on_stop_signals

from .params import PerceptionParams, parse_source

PROG = "lamps perception"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Finds the board from its ArUco markers, the stains on it and when each is wiped (kappa); "
                    "publishes perception/stains over Zenoh. Options override the config file.")
    p.add_argument("--config", metavar="FILE", help="TOML config with [zenoh] and [perception] tables")
    p.add_argument("--camera", metavar="NAME", help="camera name: frames from camera/<NAME>/frame (default board)")
    p.add_argument("--source", metavar="SPEC",
                   help="zenoh (default), folder:DIR, video:FILE, device:N or ros:TOPIC (a ROS 2 image topic through "
                        "zenoh-bridge-ros2dds)")
    p.add_argument("--debug-images", action="store_true", default=None,
                   help="publish the rectified board with stains drawn on perception/debug")
    p.add_argument("--debug-dir", metavar="DIR",
                   help="with --debug-images: also write every frame's debug image there (frame-<seq>.jpg); offline "
                        "runs default to ./perception-debug")
    p.add_argument("--jsonl", metavar="FILE", help="also write every stains message as a JSON line (offline checks)")
    p.add_argument("--no-zenoh", action="store_true", help="offline sources only: do not open a Zenoh session")
    add_zenoh_options(p)
    p.add_argument("--check", action="store_true", help="validate config and source, then exit")
    p.add_argument("--check-board", metavar="IMAGE",
                   help="report which corner markers IMAGE shows, the board's size and pose, and draw them; exit 1 "
                        "if the board is not found")
    p.add_argument("--board-image", metavar="FILE", help="where --check-board draws (default IMAGE.board.png)")
    p.add_argument("--fit-inks", metavar="IMAGE", nargs="+",
                   help="fit each ink's colour from photographs of the board whose drawings --masks outlines; print "
                        "the [perception.ink] inks line and exit")
    p.add_argument("--masks", metavar="FILE",
                   help="for --fit-inks: a TOML of [<image stem>] stains = [{ ink, polygon_m }] (the format of "
                        "tests/fixtures/whiteboards/stains.toml)")
    p.add_argument("--calibrate", metavar="DIR",
                   help="calibrate the camera from the images of a chessboard in DIR (OpenCV's calibration), write "
                        "a ROS camera_info YAML (--calibration-out) and exit")
    p.add_argument("--pattern", metavar="SPEC", default="chessboard:9x6:0.025",
                   help="the target of --calibrate: chessboard:COLSxROWS:SQUARE_M, inner corners (default %(default)s)")
    p.add_argument("--calibration-out", metavar="FILE", default="camera_info.yaml",
                   help="where --calibrate writes (default %(default)s); use it as [perception.camera_model] "
                        "calibration")
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens")
    return p


def load(a: argparse.Namespace):
    """(ZenohSettings, PerceptionParams) from file, environment and options."""
    cfg = load_config(a.config)
    table = {k: (dict(v) if isinstance(v, dict) else v) for k, v in cfg.table("perception").items()}
    for key, value in (("camera", a.camera), ("source", a.source), ("debug_images", a.debug_images)):
        if value is not None:
            table[key] = value
    return zenoh_with_options(cfg.zenoh, a), PerceptionParams.from_table(table)


def as_dict(value):
    """A message as plain JSON-able dicts and lists, field names kept (messages travel as arrays)."""
    if isinstance(value, msgspec.Struct):
        return {f: as_dict(getattr(value, f)) for f in value.__struct_fields__}
    if isinstance(value, (list, tuple)):
        return [as_dict(v) for v in value]
    return value


def open_source(params: PerceptionParams, node):
    kind, arg = parse_source(params.source)
    if kind == "zenoh":
        from .sources import ZenohSource

        return ZenohSource(node, params.camera)
    if kind == "ros":
        from .ros_images import RosImageSource

        return RosImageSource(node, arg, params)
    from .sources import OpenCVSource

    return OpenCVSource(params.source, params)


def calibrate_main(a: argparse.Namespace) -> int:
    """``--calibrate DIR``: OpenCV's calibration from chessboard images, written as a ROS camera_info YAML."""
    from pathlib import Path

    from .calibration import CalibrationError, calibrate, write_camera_info
    from .sources import IMAGE_SUFFIXES

    folder = Path(a.calibrate)
    images = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES) if folder.is_dir() else []
    if not images:
        return refuse(PROG, f"--calibrate {folder}: no {'/'.join(IMAGE_SUFFIXES)} images there")
    try:
        result = calibrate(images, a.pattern)
        write_camera_info(a.calibration_out, result.calibration)
    except (CalibrationError, OSError) as exc:
        return refuse(PROG, exc)
    K, d = result.calibration.K, result.calibration.dist
    print(f"calibrated from {len(result.used)} of {len(images)} images ({result.calibration.width} x "
          f"{result.calibration.height} px): fx {K[0, 0]:.1f} fy {K[1, 1]:.1f} cx {K[0, 2]:.1f} cy {K[1, 2]:.1f} px, "
          f"distortion {' '.join(f'{v:.4f}' for v in d)}; corners reproject to {result.rms_px:.3f} px RMS")
    for why in result.skipped:
        print(f"  skipped {why}")
    print(f"wrote {a.calibration_out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    if a.calibrate:
        return calibrate_main(a)
    log_to_stderr("perception", a.verbose)
    try:
        zenoh_settings, params = load(a)
        wanted_nice(BACKGROUND)  # a bad LAMPS_NICE is refused with the rest of the configuration
        kind, _ = parse_source(params.source)
        if a.no_zenoh and kind in ("zenoh", "ros"):
            raise InterfaceError("--no-zenoh needs an offline source (--source folder:DIR, video:FILE or device:N)")
        source = None if kind in ("zenoh", "ros") else open_source(params, None)
    except (LampsError, OSError) as exc:
        return refuse(PROG, exc)
    if a.fit_inks:
        from .fit_inks import main_fit_inks

        if source is not None:
            source.close()
        if not a.masks:
            return refuse(PROG, "--fit-inks needs --masks FILE (the drawings' outlines and inks)")
        return main_fit_inks(a.fit_inks, a.masks, params)
    if a.check_board:
        from .check_board import main_check_board

        if source is not None:
            source.close()
        return main_check_board(a.check_board, params, a.board_image)
    if a.check:
        print(f"ok: source {params.source}, camera {params.camera}, keys under {zenoh_settings.keys.prefix}")
        if source is not None:
            source.close()
        return 0
    from interfaces.message_limits import max_message_bytes

    from .service import SERVICE

    set_service_priority(BACKGROUND)  # before the Zenoh session starts its threads: they inherit it
    if a.no_zenoh:
        return _serve(None, a, params, kind, source)
    # ROS images through the bridge may be larger than the cell's own frames (message_limits)
    return serve(PROG, SERVICE, zenoh_settings, lambda node: _serve(node, a, params, kind, source),
                 max_message_bytes(ros_images=kind == "ros"), on_open_failure=source.close if source else None)


def _serve(node, a: argparse.Namespace, params, kind: str, source) -> int:
    """Serve frames from ``source`` (None: the camera's key on ``node``) until a stop signal or the source's end;
    ``node`` None: offline, the stains to ``--jsonl`` only."""
    from .service import PerceptionService

    if source is None:
        source = open_source(params, node)
    partial = f"{a.jsonl}.partial" if a.jsonl else None
    out = open(partial, "w") if partial else None  # renamed into place when complete
    sink = (lambda msg: out.write(json.dumps(as_dict(msg)) + "\n")) if out else None
    debug_dir = a.debug_dir or ("perception-debug" if params.debug_images and kind not in ("zenoh", "ros") else None)
    if debug_dir and params.debug_images:
        os.makedirs(debug_dir, exist_ok=True)
    service = PerceptionService(params, node, source, sink, debug_dir if params.debug_images else None)
    on_stop_signals(service.stop, background=True)
    try:
        frames = service.run()
    finally:
        source.close()
        if out is not None and partial is not None:
            out.close()
            os.replace(partial, a.jsonl)
    status = service.status()
    logging.getLogger("perception").info("stopped after %d frames: %s", frames, status.detail)
    if kind not in ("zenoh", "ros"):
        print(f"{frames} frames: {status.detail}; counters {dict(sorted(status.counters.items()))}")
        if service.debug_dir:
            print(f"debug images: {service.debug_dir}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
