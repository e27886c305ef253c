"""``docker compose up`` for real: the image built, the cell run in containers on a seeded board, then down.

The recorder runs with ``LAMPS_RECORD_UNTIL=done``: it ends the job once the
controller is DONE and exits 0 only if its report says cleaned. The run
folder it leaves on the host is checked (report, a readable recording, the
folders' owner), and so is the start order the healthchecks gave.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import uuid
from datetime import datetime

import pytest

from interfaces.keys import Keys

from .conftest import REPO
from .docker_helpers import base_image, ensure_docker, why_not_cleaned
from .test_live_view import FoxgloveClient, check_payload
from .zenoh_helpers import free_port, wait_for

pytestmark = [pytest.mark.slow, pytest.mark.docker, pytest.mark.xdist_group("docker")]


def _compose(project: str, env: dict, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(["docker", "compose", "-f", str(REPO / "docker-compose.yml"), "-p", project, *args],
                          capture_output=True, text=True, env=env, timeout=timeout, cwd=REPO)


def hard_limit(which: int) -> str:
    """This host's hard limit as compose wants it (-1 = unlimited): the engine cannot raise it above that."""
    hard = resource.getrlimit(which)[1]
    return "-1" if hard == resource.RLIM_INFINITY else str(hard)


def _connect(port: int, token: str | None = None):
    """A client that got the server's hello, or None (docker's port proxy accepts before the service listens).
    ``token``: the live view's (a client through docker's port proxy is not on the container's loopback)."""
    from websockets.exceptions import WebSocketException

    try:
        client = FoxgloveClient(port, "foxglove.sdk.v1", token=token)
        client.pump(2.0)
    except (OSError, EOFError, WebSocketException):
        return None
    return client if client.server_info is not None else None


def started_at(container: str) -> datetime:
    """When the container started (its engine's clock; nanosecond text cut to microseconds)."""
    out = subprocess.run(["docker", "inspect", "-f", "{{.State.StartedAt}}", container], capture_output=True,
                         text=True, check=True).stdout.strip().rstrip("Z")
    head, _, frac = out.partition(".")
    return datetime.fromisoformat(f"{head}.{(frac + '000000')[:6]}")


def test_docker_compose_up_cleans_a_seeded_board_and_leaves_the_run_on_the_host(tmp_path):
    ensure_docker()
    host = tmp_path / "cell"
    host.mkdir()
    project = f"lampstest{uuid.uuid4().hex[:8]}"
    ws_port = free_port()
    env = {**os.environ, "LAMPS_BASE_IMAGE": base_image(), "LAMPS_HOST_DIR": str(host),
           "LAMPS_RECORD_UNTIL": "done", "LAMPS_SEED": "3", "LAMPS_STAINS": "1", "COMPOSE_PROFILES": "sim,foxglove",
           "LAMPS_FOXGLOVE_PORT": str(ws_port),
           "LAMPS_MEMLOCK_BYTES": hard_limit(resource.RLIMIT_MEMLOCK),
           "LAMPS_RTPRIO_MAX": hard_limit(resource.RLIMIT_RTPRIO)}
    env.pop("COMPOSE_FILE", None)
    try:
        built = _compose(project, env, "build", timeout=1800)
        assert built.returncode == 0, f"docker compose build failed:\n{built.stderr[-4000:]}"
        up = _compose(project, env, "up", "-d", timeout=900)
        assert up.returncode == 0, f"docker compose up failed:\n{up.stderr[-4000:]}"
        # the live view (profile foxglove) serves the running cell on the host's port
        from launch.live import live_token
        from runtime.credentials import identity_files, identity_folder

        token = live_token(identity_files(identity_folder(host / "secrets", "recorder"))[2])
        client = wait_for(lambda: _connect(ws_port, token), 120.0, "the foxglove service's WebSocket port",
                          period_s=1.0)
        tf = f"{Keys().prefix}/scene/tf"
        wait_for(lambda: client.pump(0.5) or tf in client.channels, 120.0, f"{tf} advertised")
        client.subscribe([tf])
        wait_for(lambda: client.pump(0.5) or client.got.get(tf), 60.0, f"live {tf}")
        check_payload(client.channels[tf], client.got[tf][0])
        client.ws.close()
        waited = _compose(project, env, "wait", "recorder", timeout=900)
        if not (waited.returncode == 0 and waited.stdout.strip().endswith("0")):
            seen = why_not_cleaned(lambda s: _compose(project, env, "logs", "--no-color", "--tail", "30", s).stdout,
                                   host / "runs" / "latest")
            pytest.fail(f"the recorder did not end with the board cleaned ({waited.stdout.strip()}):\n{seen}")

        run = host / "runs" / "latest"
        report = json.loads((run / "report.json").read_text())
        assert report["outcome"] == "cleaned", report
        # on a loaded host a service's status may come late (SERVICE: no status for ...): recorded, not unsafe;
        # nothing may have faulted, stopped or lifted the arm
        unsafe = [f for f in report["faults"] if f["phase"] != "SERVICE"]
        assert report["dirt_removed_fraction"] >= 0.98 and not unsafe, report
        assert report["peak_contact_force_n"] <= report["force_cap_n"], report
        from mcap.reader import make_reader

        with open(run / "recording.mcap", "rb") as f:
            reader = make_reader(f)
            topics = {ch.topic for ch in reader.get_summary().channels.values()}
            n = sum(1 for _ in reader.iter_messages())
        assert n > 1000 and any(t.endswith("controller/status") for t in topics), (n, sorted(topics))
        # the host folders were made and handed to the services' user by the one-shot `folders` service
        for d in ("runs", "skills", "secrets"):
            assert (host / d).stat().st_uid == 1000, d
        assert (host / "skills" / "bundled" / "skill.json").is_file()

        # Docker's start order is lamps up's: each after the one it needs was healthy
        names = {s: f"{project}-{s}-1" for s in ("sim", "controller", "perception", "recorder", "foxglove")}
        started = {s: started_at(c) for s, c in names.items()}
        assert started["sim"] < started["controller"] < started["perception"], started
        assert started["recorder"] < started["controller"], started  # recording before the robot can move
        assert started["perception"] < started["foxglove"], started
    finally:
        down = _compose(project, env, "down", "--volumes", "--remove-orphans", "--timeout", "30", timeout=300)
        assert down.returncode == 0, down.stderr
