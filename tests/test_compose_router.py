"""docker-compose.router.yml: the cell through ``lamps router``, each "host" a network of its own.

The override as Compose resolves it (every service a client of the router, on one network, its healthcheck
its own liveliness token), and, for real in Docker (slow), the cell cleaning a seeded board through the router
while perception has no route to the sim.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import uuid

import pytest

from .conftest import REPO
from .docker_helpers import base_image, ensure_docker, why_not_cleaned
from .test_compose_docker import hard_limit, started_at
from .zenoh_helpers import free_port

FILES = ("-f", str(REPO / "docker-compose.yml"), "-f", str(REPO / "docker-compose.router.yml"))
#: The services that talk Zenoh, and the network ("host") each is on.
NETWORK = {"sim": "robot_net", "controller": "robot_net", "perception": "vision_net", "recorder": "operator_net",
           "foxglove": "operator_net"}


def _compose(project: str, env: dict, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(["docker", "compose", *FILES, "-p", project, *args], capture_output=True, text=True,
                          env=env, timeout=timeout, cwd=REPO)


def test_every_service_is_a_client_of_the_router_on_its_own_network():
    ensure_docker()
    env = {**os.environ, "COMPOSE_PROFILES": "sim,foxglove"}
    env.pop("COMPOSE_FILE", None)
    r = _compose("lampsconfig", env, "config", "--format", "json", timeout=60)
    assert r.returncode == 0, r.stderr
    services = json.loads(r.stdout)["services"]
    router = services["router"]
    assert set(router["networks"]) == set(NETWORK.values())
    assert router["environment"]["LAMPS_ZENOH_LISTEN"] == "tls/0.0.0.0:7447"
    assert router["volumes"][0]["target"] == "/secrets" and router["volumes"][0]["source"].endswith("secrets/ca/router")
    for name, net in NETWORK.items():
        s = services[name]
        env_ = s["environment"]
        assert (env_["LAMPS_ZENOH_MODE"], env_["LAMPS_ZENOH_CONNECT"], env_["LAMPS_ZENOH_LISTEN"]) == \
            ("client", "tls/router:7447", ""), name
        assert list(s["networks"]) == [net], name
        assert s["depends_on"]["router"]["condition"] == "service_healthy", name
        if name in ("sim", "controller", "perception"):
            assert s["healthcheck"]["test"][:5] == ["CMD", "lamps", "health", "--alive", name], name


@pytest.mark.slow
@pytest.mark.docker
@pytest.mark.xdist_group("docker")
def test_docker_compose_through_the_router_cleans_a_board_and_perception_cannot_reach_the_sim(tmp_path):
    ensure_docker()
    host = tmp_path / "cell"
    host.mkdir()
    project = f"lampsrouter{uuid.uuid4().hex[:8]}"
    env = {**os.environ, "LAMPS_BASE_IMAGE": base_image(), "LAMPS_HOST_DIR": str(host),
           "LAMPS_RECORD_UNTIL": "done", "LAMPS_SEED": "3", "LAMPS_STAINS": "1", "COMPOSE_PROFILES": "sim",
           "LAMPS_ROUTER_PORT": str(free_port()),
           "LAMPS_MEMLOCK_BYTES": hard_limit(resource.RLIMIT_MEMLOCK),
           "LAMPS_RTPRIO_MAX": hard_limit(resource.RLIMIT_RTPRIO)}
    env.pop("COMPOSE_FILE", None)
    try:
        built = _compose(project, env, "build", timeout=1800)  # the compose test's image: cached when it ran first
        assert built.returncode == 0, f"docker compose build failed:\n{built.stderr[-4000:]}"
        up = _compose(project, env, "up", "-d", timeout=900)
        assert up.returncode == 0, f"docker compose up failed:\n{up.stderr[-4000:]}"
        # from the vision box's network: the router answers, the sim's address has no route, its name no answer
        sim_ip = subprocess.run(["docker", "inspect", "-f", "{{range .NetworkSettings.Networks}}{{.IPAddress}}{{end}}",
                                 f"{project}-sim-1"], capture_output=True, text=True, check=True).stdout.strip()
        probe = ("import json, socket\n"
                 "def tcp(h):\n"
                 "    try:\n"
                 "        socket.create_connection((h, 7447), timeout=3).close(); return 'connected'\n"
                 "    except OSError as e: return type(e).__name__ + ' ' + str(e.errno)\n"
                 f"print(json.dumps({{'router': tcp('router'), 'sim_ip': tcp('{sim_ip}'), 'sim': tcp('sim')}}))\n")
        seen = _compose(project, env, "exec", "-T", "perception", "python", "-c", probe, timeout=60)
        assert seen.returncode == 0, seen.stderr
        reach = json.loads(seen.stdout.strip().splitlines()[-1])
        assert reach["router"] == "connected", reach
        # no answer at all from the robot PC's network (a reachable closed port would refuse at once, errno 111):
        # dropped (a timeout) or unreachable (101, 113)
        assert reach["sim_ip"].startswith("TimeoutError") or reach["sim_ip"].split()[-1] in ("101", "113"), reach
        assert reach["sim"].startswith("gaierror"), reach  # and no name for it

        waited = _compose(project, env, "wait", "recorder", timeout=900)
        if not (waited.returncode == 0 and waited.stdout.strip().endswith("0")):
            seen = why_not_cleaned(lambda s: _compose(project, env, "logs", "--no-color", "--tail", "30", s).stdout,
                                   host / "runs" / "latest")
            pytest.fail(f"the recorder did not end with the board cleaned ({waited.stdout.strip()}):\n{seen}")
        report = json.loads((host / "runs" / "latest" / "report.json").read_text())
        assert report["outcome"] == "cleaned" and report["dirt_removed_fraction"] >= 0.98, report
        assert "listening on tls/0.0.0.0:7447" in _compose(project, env, "logs", "router").stdout
        # the liveliness healthchecks gave the start order
        started = {s: started_at(f"{project}-{s}-1") for s in ("router", "sim", "controller", "perception", "recorder")}
        assert started["router"] < started["sim"] < started["controller"] < started["perception"], started
        assert started["router"] < started["recorder"] < started["controller"], started  # recording before motion
    finally:
        down = _compose(project, env, "down", "--volumes", "--remove-orphans", "--timeout", "30", timeout=300)
        assert down.returncode == 0, down.stderr
