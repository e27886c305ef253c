"""``lamps router``: the cell through a Zenoh router with the peers' identities and access list, over real Zenoh.

The router is the real command (the eclipse-zenoh library in router mode) started as a process; every other
party is a Zenoh client of it with its role's identity from ``lamps credentials``: no link between clients, so
whatever reaches a client came through the router and its access list. A site of two cells (``lamps credentials
--cells``, ``lamps router --cells``): each cell's roles are kept to their own cell, and ``lamps up --cells 2`` runs
both cells side by side through one router.
"""

from __future__ import annotations

import base64
import json
import os
import subprocess
import sys
import threading
import time

import pytest
import zenoh

from interfaces.access import RELAY, ROLES, SITE_VIEWER, cell_acl, role_and_cell, site_acl
from interfaces.errors import ConfigError
from launch.health import accepts
from runtime.config import ZenohSettings
from runtime.credentials import identity_folder, make_credentials
from runtime.session import zenoh_config

from .conftest import REPO
from .mcap_check import protobuf_class
from .zenoh_helpers import free_port, wait_subscribed


def _accepts(port: int) -> bool:
    return accepts("127.0.0.1", port, 0.2) is None


#: Zenoh's access-control interceptor logs each message it refuses (and each it lets through) at trace level.
DENIALS_LOG = "zenoh::net::routing::interceptor::access_control=trace"


class _Router:
    def __init__(self, tmp, robot_id: str, credentials, access: bool = True, cells: tuple[str, ...] = (),
                 extra_env: dict | None = None) -> None:
        self.port = free_port()
        self.endpoint = f"tls/127.0.0.1:{self.port}"
        env = {"LAMPS_ROBOT_ID": robot_id, "LAMPS_ZENOH_ACCESS_CONTROL": "true" if access else "false",
               "LAMPS_ZENOH_IDENTITY": str(identity_folder(credentials, RELAY)), "PATH": "/usr/bin:/bin",
               "PYTHONPATH": str(REPO), "RUST_LOG": DENIALS_LOG, "NO_COLOR": "1",
               **({"LAMPS_ZENOH_CELLS": ",".join(cells)} if cells else {}), **(extra_env or {})}
        self.proc = subprocess.Popen([sys.executable, "-m", "runtime.cli", "router", "--listen", self.endpoint,
                                      "--status-s", "0"], env=env, cwd=tmp, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
        deadline = time.monotonic() + 60.0
        while not _accepts(self.port):
            assert self.proc.poll() is None and time.monotonic() < deadline, self.proc.communicate(timeout=5)[0]
            time.sleep(0.1)

    def close(self) -> str:
        self.proc.terminate()
        out, _ = self.proc.communicate(timeout=60)  # a loaded machine: its TLS links close first
        return out


def _client(router: _Router, robot_id: str, folder, acl: bool = True) -> zenoh.Session:
    """A client of ``router`` with the identity in ``folder``; ``acl=False``: one that does not apply its own access
    list (a stolen identity in a program of the thief's)."""
    return zenoh.open(zenoh_config(ZenohSettings(mode="client", connect=(router.endpoint,), robot_id=robot_id,
                                                 access_control=acl, identity=str(folder))))


@pytest.fixture
def cell(tmp_path):
    creds = tmp_path / "credentials"
    make_credentials(creds)
    robot_id = f"r{free_port()}"
    router = _Router(tmp_path, robot_id, creds)
    yield router, robot_id, creds
    router.close()


@pytest.mark.attack("router: a client puts another role's keys through the router",
                    "perception's identity, a client of the router, puts 100 Nm on robot/command and releases "
                    "the e-stop", "refused at the router: the robot and the controller get only their writers'")
def test_the_router_lets_each_client_put_its_own_row_only(cell):
    router, robot_id, creds = cell
    from interfaces.keys import Keys

    keys = Keys.for_robot(robot_id)
    got: dict[str, list[bytes]] = {"command": [], "release": []}
    lock = threading.Lock()
    robot = _client(router, robot_id, identity_folder(creds, "robot"))
    ctl = _client(router, robot_id, identity_folder(creds, "controller"))
    thief = _client(router, robot_id, identity_folder(creds, "perception"))
    operator = _client(router, robot_id, identity_folder(creds, "operator"))
    try:
        def keep(name):
            def cb(sample):
                with lock:
                    got[name].append(bytes(sample.payload.to_bytes()))
            return cb

        subs = [robot.declare_subscriber(keys.robot_command, keep("command")),
                ctl.declare_subscriber(keys.controller_estop_release, keep("release"))]
        time.sleep(1.0)  # the declarations reach the router and the publishers' sessions
        for _ in range(20):
            thief.put(keys.robot_command, b"forged by perception")
            thief.put(keys.controller_estop_release, b"released by perception")
            ctl.put(keys.robot_command, b"from the controller")
            operator.put(keys.controller_estop_release, b"from the operator")
            time.sleep(0.02)
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and (len(got["command"]) < 20 or len(got["release"]) < 20):
            time.sleep(0.05)
        time.sleep(0.3)
        with lock:
            assert set(got["command"]) == {b"from the controller"} and len(got["command"]) == 20, got["command"][:3]
            assert set(got["release"]) == {b"from the operator"} and len(got["release"]) == 20
        for s in subs:
            s.undeclare()
    finally:
        for s in (robot, ctl, thief, operator):
            s.close()


@pytest.mark.attack("router: a client from another CA joins the router",
                    "a client with a certificate of its own CA (common name controller) connects",
                    "no session: the TLS handshake fails at the router")
def test_a_client_with_another_cas_certificate_gets_no_session(cell, tmp_path):
    router, robot_id, _ = cell
    other = tmp_path / "other"
    make_credentials(other)
    with pytest.raises(zenoh.ZError):
        _client(router, robot_id, identity_folder(other, "controller"))


def test_clients_access_list_lets_the_routers_relayed_puts_in_and_nothing_else_unnamed():
    from interfaces.keys import Keys

    assert not [p for p in cell_acl(Keys.for_robot("x"))["policies"] if p["subjects"] == [RELAY]], \
        "a peer never accepts the router's identity"
    acl = cell_acl(Keys.for_robot("x"), relay=True)  # a router's client does
    relay = next(p for p in acl["policies"] if p["subjects"] == [RELAY])
    rule = next(r for r in acl["rules"] if r["id"] == "relay")
    assert "relay" in relay["rules"] and rule["flows"] == ["ingress"] and "lamps/x/**" in rule["key_exprs"]
    assert acl["default_permission"] == "deny"


def test_credentials_made_before_the_router_get_its_identity_from_the_same_ca(tmp_path):
    import shutil

    creds = tmp_path / "c"
    make_credentials(creds)
    ca = (creds / "ca" / "ca.pem").read_bytes()
    shutil.rmtree(identity_folder(creds, RELAY))
    make_credentials(creds, if_missing=True)
    router = identity_folder(creds, RELAY)
    assert router == creds / "ca" / RELAY, "the router's key is kept with the CA, never beside a service's"
    assert (router / "cert.pem").is_file() and (router / "ca.pem").read_bytes() == ca


# ------------------------------------------------------------------------------------ a site: two cells, one router
CELLS = ("cell-a", "cell-b")


@pytest.fixture
def site(tmp_path):
    """Two cells' identities (``lamps credentials --cells``) and a router with the site's access list."""
    creds = tmp_path / "credentials"
    make_credentials(creds, cells=CELLS)
    router = _Router(tmp_path, CELLS[0], creds, cells=CELLS)
    yield router, creds
    router.close()


def _cross_cell_attack(site, role: str, key_of, legit_role: str, victim_role: str) -> tuple[dict, int]:
    """Cell A's ``role`` (not applying its own list) and cell B's ``legit_role`` each put 20 times on cell B's key
    ``key_of(keys)``, heard by cell B's ``victim_role`` and recorder (all of cell B); a second session of the
    thief's subscribes to all of cell B. Returns (payloads per listener, the router's refusals of the thief's puts
    logged)."""
    from interfaces.keys import Keys

    router, creds = site
    a, b = CELLS
    key = key_of(Keys.for_robot(b))
    got: dict[str, list[bytes]] = {"victim": [], "recorder": [], "thief": []}
    lock = threading.Lock()

    def keep(name):
        def cb(sample):
            with lock:
                got[name].append(bytes(sample.payload.to_bytes()))
        return cb

    victim = _client(router, b, identity_folder(creds, victim_role, b))
    recorder = _client(router, b, identity_folder(creds, "recorder", b))
    legit = _client(router, b, identity_folder(creds, legit_role, b))
    thief = _client(router, a, identity_folder(creds, role, a), acl=False)
    eavesdropper = _client(router, a, identity_folder(creds, role, a), acl=False)
    sessions = (victim, recorder, legit, thief, eavesdropper)
    try:
        subs = [victim.declare_subscriber(key, keep("victim")),
                recorder.declare_subscriber(f"{Keys.for_robot(b).prefix}/**", keep("recorder")),
                eavesdropper.declare_subscriber(f"{Keys.for_robot(b).prefix}/**", keep("thief"))]
        wait_subscribed(legit, key)
        for _i in range(20):
            thief.put(key, f"forged by {role}@{a}".encode())
            legit.put(key, f"from {legit_role}@{b}".encode())
            time.sleep(0.02)
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and (len(got["victim"]) < 20 or len(got["recorder"]) < 20):
            time.sleep(0.05)
        time.sleep(0.3)  # anything forged would have come with the legitimate puts interleaved with it
        for sub in subs:
            sub.undeclare()
    finally:
        for sess in sessions:
            sess.close()
    refused = sum(f"CertCommonName({role}@{a})" in line and f"unauthorized to Put (ingress) on {key}" in line
                  for line in router.close().splitlines())
    return got, refused


@pytest.mark.attack("router, several cells: cell A's controller commands cell B's robot",
                    "cell A's controller identity (its program not applying the list), a client of the site's router, "
                    "puts 20 torque commands on cell B's robot/command and subscribes to all of cell B",
                    "refused at the router, each refusal logged: cell B's robot and recorder get only cell B's "
                    "controller's commands, the thief hears nothing of cell B")
def test_a_cells_controller_cannot_command_another_cells_robot(site):
    got, refused = _cross_cell_attack(site, "controller", lambda k: k.robot_command, "controller", "robot")
    assert got["victim"] == [f"from controller@{CELLS[1]}".encode()] * 20, got["victim"][:3]
    assert set(got["recorder"]) == {f"from controller@{CELLS[1]}".encode()} and len(got["recorder"]) == 20
    assert got["thief"] == [], got["thief"][:3]
    assert refused == 20, refused


@pytest.mark.attack("router, several cells: cell A's operator releases cell B's e-stop",
                    "cell A's operator identity (its program not applying the list), a client of the site's router, "
                    "puts 20 releases on cell B's controller/estop/release",
                    "refused at the router, each refusal logged: cell B's controller and recorder get only cell B's "
                    "operator's releases")
def test_a_cells_operator_cannot_release_another_cells_estop(site):
    got, refused = _cross_cell_attack(site, "operator", lambda k: k.controller_estop_release, "operator",
                                      "controller")
    assert got["victim"] == [f"from operator@{CELLS[1]}".encode()] * 20, got["victim"][:3]
    assert set(got["recorder"]) == {f"from operator@{CELLS[1]}".encode()} and len(got["recorder"]) == 20
    assert refused == 20, refused


def test_the_site_viewer_reads_every_cell_and_may_only_engage_their_estops(site):
    from interfaces.keys import Keys

    router, creds = site
    heard: list[str] = []
    viewer = zenoh.open(zenoh_config(ZenohSettings(mode="client", connect=(router.endpoint,), cells=CELLS,
                                                   access_control=True, identity=str(creds / SITE_VIEWER))))
    controllers = [_client(router, c, identity_folder(creds, "controller", c)) for c in CELLS]
    robot = _client(router, CELLS[1], identity_folder(creds, "robot", CELLS[1]))
    commands: list[bytes] = []
    estops: list[bytes] = []
    try:
        subs = [viewer.declare_subscriber(Keys.for_robot(c).controller_status, lambda s: heard.append(str(s.key_expr)))
                for c in CELLS]
        robot_subs = [robot.declare_subscriber(Keys.for_robot(CELLS[1]).robot_command,
                                               lambda s: commands.append(bytes(s.payload.to_bytes()))),
                      robot.declare_subscriber(Keys.for_robot(CELLS[1]).controller_estop,
                                               lambda s: estops.append(bytes(s.payload.to_bytes())))]
        for c, ctl in zip(CELLS, controllers):
            wait_subscribed(ctl, Keys.for_robot(c).controller_status)
        wait_subscribed(viewer, Keys.for_robot(CELLS[1]).controller_estop)
        for c, ctl in zip(CELLS, controllers):
            ctl.put(Keys.for_robot(c).controller_status, b"status")
        viewer.put(Keys.for_robot(CELLS[1]).robot_command, b"forged by the site viewer")
        viewer.put(Keys.for_robot(CELLS[1]).controller_estop, b"engaged by the site viewer")
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and (len(heard) < 2 or not estops):
            time.sleep(0.05)
        time.sleep(0.3)
        assert sorted(heard) == [Keys.for_robot(c).controller_status for c in CELLS], heard
        assert estops == [b"engaged by the site viewer"] and commands == [], commands
        for s in (*subs, *robot_subs):
            s.undeclare()
    finally:
        for s in (viewer, *controllers, robot):
            s.close()


def test_one_recording_of_every_cell_through_the_router_as_the_site_viewer(site, tmp_path):
    """``lamps record --cells A,B``: the site viewer's one recording holds both cells' states, each cell's scene in
    its own frame tree (``<robot id>/world``)."""
    import signal

    from interfaces.codec import encode
    from interfaces.keys import Keys
    from launch.record import read_recording

    from .test_live_view import state_message

    router, creds = site
    out = tmp_path / "site-recording"
    env = {**os.environ, "PYTHONPATH": str(REPO), "LAMPS_ZENOH_MODE": "client", "LAMPS_ZENOH_CONNECT": router.endpoint,
           "LAMPS_ZENOH_ACCESS_CONTROL": "true", "LAMPS_ZENOH_IDENTITY": str(creds / SITE_VIEWER)}
    rec = subprocess.Popen([sys.executable, "-m", "runtime.cli", "record", "--cells", ",".join(CELLS), "--out",
                            str(out)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    robots = [_client(router, c, identity_folder(creds, "robot", c)) for c in CELLS]
    try:
        for c, robot in zip(CELLS, robots):
            wait_subscribed(robot, Keys.for_robot(c).robot_state, what=f"the site recorder's subscription of {c}")
        for i in range(60):
            for c, robot in zip(CELLS, robots):
                robot.put(Keys.for_robot(c).robot_state, encode(state_message(i)))
            time.sleep(0.005)
        time.sleep(1.0)
        rec.send_signal(signal.SIGTERM)
        stdout, stderr = rec.communicate(timeout=60)
    finally:
        if rec.poll() is None:
            rec.kill()
        for s in robots:
            s.close()
    assert rec.returncode == 0, stderr[-2000:]
    assert not (out / "report.json").exists()  # each cell's own recorder reports; the site's only records
    msgs = read_recording(out / "recording.mcap")
    from mcap.reader import make_reader

    frames: dict[str, set[str]] = {}
    with open(out / "recording.mcap", "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(topics=[f"lamps/{c}/scene/tf" for c in CELLS]):
            tf = protobuf_class(schema.name, schema.data).FromString(message.data)
            frames.setdefault(channel.topic, set()).update(x.parent_frame_id for x in tf.transforms)
    for c in CELLS:
        assert len(msgs[Keys.for_robot(c).robot_state]) >= 10, (c, sorted(msgs))  # the states may drop on the way
        assert frames[f"lamps/{c}/scene/tf"] == {f"{c}/world"}, frames


def test_the_site_list_confines_each_cells_roles_to_its_own_prefix():
    acl = site_acl(CELLS)
    rules = {r["id"]: r for r in acl["rules"]}
    for policy in acl["policies"]:
        name = policy["subjects"][0]
        role, cell = role_and_cell(name)
        exprs = [e for r in policy["rules"] for e in rules[r]["key_exprs"]]
        if cell is not None:
            assert role in ROLES and all(e.startswith(f"lamps/{cell}/") for e in exprs), (name, exprs)
        else:
            assert name in (SITE_VIEWER, RELAY), name
    viewer = next(p for p in acl["policies"] if p["subjects"] == [SITE_VIEWER])
    puts = [e for r in viewer["rules"] if r.startswith("put-") for e in rules[r]["key_exprs"]]
    assert puts == [f"lamps/{c}/controller/estop" for c in CELLS]
    assert acl["default_permission"] == "deny"


def test_site_credentials_name_each_cells_roles_and_a_service_refuses_another_cells_identity(tmp_path):
    from runtime.credentials import cell_of

    creds = tmp_path / "c"
    folders = make_credentials(creds, cells=CELLS)
    assert set(folders) == {RELAY, SITE_VIEWER, *(f"{r}@{c}" for r in ROLES for c in CELLS)}
    assert cell_of(identity_folder(creds, "controller", CELLS[1])) == CELLS[1]
    assert cell_of(identity_folder(creds, RELAY)) is None
    assert (identity_folder(creds, "bridge", CELLS[0]) / "zenoh-bridge.json5").is_file()
    with pytest.raises(ConfigError, match="cell cell-b"):
        zenoh_config(ZenohSettings(robot_id=CELLS[0], access_control=True,
                                   identity=str(identity_folder(creds, "controller", CELLS[1]))))
    with pytest.raises(ConfigError, match="credentials folder"):
        make_credentials(tmp_path / "d", cells=("router",))


@pytest.mark.slow
def test_two_lockstep_cells_clean_their_boards_side_by_side_through_one_router(tmp_path, learned_skill_file):
    """``lamps up --cells 2 --foxglove PORT``: one router, two cells each a client of it with its own identities,
    one stain each; one live view (the site viewer through the router) serves both cells to a Foxglove client."""
    from .test_live_view import follow_live

    out, ws_port = tmp_path / "site", free_port()
    proc = subprocess.Popen([sys.executable, "-m", "runtime.cli", "up", "--cells", "2", "--stains", "1", "--seed",
                             "3", "--skill", str(learned_skill_file), "--out", str(out), "--max-duration", "400", "-q",
                             "--foxglove", str(ws_port)], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONPATH": str(REPO), "MPLBACKEND": "Agg"})
    try:
        live = [f"lamps/{cell}/{what}" for cell in ("iiwa-1", "iiwa-2") for what in ("controller/status", "scene/tf")]
        client = follow_live(ws_port, live, "the site's live view")
        assert "LAMPS site lamps/iiwa-1, lamps/iiwa-2" in client.server_info["name"], client.server_info
        for cell in ("iiwa-1", "iiwa-2"):  # each cell's scene in a frame tree of its own
            topic = f"lamps/{cell}/scene/tf"
            tf = protobuf_class("foxglove.FrameTransforms", base64.b64decode(client.channels[topic]["schema"]))
            tf = tf.FromString(client.got[topic][-1])
            assert {x.parent_frame_id for x in tf.transforms} == {f"{cell}/world"}, tf.transforms[0]
        client.ws.close()
        stdout, stderr = proc.communicate(timeout=900)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stdout[-3000:] + stderr[-3000:]
    for cell in ("iiwa-1", "iiwa-2"):
        report = json.loads((out / cell / "report.json").read_text())
        assert report["final_phase"] == "DONE" and report["dirt_removed_fraction"] > 0.95, (cell, report)
        assert json.loads((out / cell / "run.json").read_text())["key_prefix"] == f"lamps/{cell}"
        assert any(line.startswith(f"{cell}: cleaned") for line in stdout.splitlines()), stdout[-2000:]
    # the site viewer, one session through the router, saw both cells to the end
    assert "seen through the router: iiwa-1 DONE, iiwa-2 DONE" in stdout, stdout[-2000:]
    assert "listening on" in (out / "logs" / "router.log").read_text()
    assert "serving the cells iiwa-1, iiwa-2" in (out / "logs" / "foxglove.log").read_text()


def _schedulers(pid: int) -> set[tuple[int, int]]:
    """(policy, priority) of every thread of process ``pid``."""
    out = set()
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            out.add((os.sched_getscheduler(int(tid)), os.sched_getparam(int(tid)).sched_priority))
        except ProcessLookupError:
            continue
    return out


@pytest.mark.skipif(os.geteuid() != 0, reason="granting SCHED_FIFO needs root here")
def test_the_routers_threads_run_fifo_just_below_the_loops_it_relays_for(tmp_path):
    """Every routed state and command passes the router: its threads run as the loops' I/O threads do (SCHED_FIFO
    one below ``LAMPS_RT_PRIORITY``), not behind every ordinary process; ``off`` leaves them all fair."""
    creds = tmp_path / "credentials"
    make_credentials(creds)
    for env, expected in (({}, {(os.SCHED_FIFO, 9)}), ({"LAMPS_RT_PRIORITY": "21"}, {(os.SCHED_FIFO, 20)}),
                          ({"LAMPS_RT_PRIORITY": "off"}, {(os.SCHED_OTHER, 0)})):
        router = _Router(tmp_path, "iiwa-1", creds, extra_env=env)
        try:  # raised once the session is open: a moment after its port accepts
            deadline = time.monotonic() + 20.0
            while (threads := _schedulers(router.proc.pid)) != expected and time.monotonic() < deadline:
                time.sleep(0.1)
        finally:
            out = router.close()
        assert threads == expected, (env, threads, out)
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "router", "--listen", "tls/127.0.0.1:1"], cwd=tmp_path,
                       env={"PYTHONPATH": str(REPO), "LAMPS_RT_PRIORITY": "high",
                            "LAMPS_ZENOH_IDENTITY": str(identity_folder(creds, RELAY))},
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "LAMPS_RT_PRIORITY must be an integer" in r.stderr, r.stderr


#: Cores the whole routed real-time cell needs: one per 1 kHz loop (the sim, the controller, the router) and one
#: for perception and the recorder. On 2 cores the three FIFO loops leave perception about a ninth of a core while
#: it works (18.6 ms of CPU a frame in 163 ms of wall clock, p50): its stains pause the skill again and again, and
#: a controller late for its robot meets the robot side's stale-command brake in contact (docs/benchmarks.md,
#: "The real-time cell through lamps router").
ROUTED_CELL_CORES = 4


def _routed_realtime_cell(tmp_path, skill_file, *args: str, env_extra: dict | None = None) -> dict:
    """``lamps up --cells 1 --mode realtime --seed 0`` on the identified real-iiwa plant (``[sim.plant] profile =
    "stuerz2017"``, a 0.3 kg heavier tool; the controller keeps the description): the sim and the controller at
    1 kHz, each a client of the router, every state and command routed; checks what every such cell must show
    and returns its report: the board cleaned, no FAULT (the robot side's FAULT-hold neither), no joint-speed
    brake, no joint over 0.8 of its speed limit, the contact force under the controller's cap."""
    from .test_sim_plant_cell import PLANT_ENV

    out = tmp_path / "site"
    env = {k: v for k, v in os.environ.items() if not k.startswith("LAMPS__SIM__PLANT__")}
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "up", "--cells", "1", "--mode", "realtime", "--seed", "0",
                        "--skill", str(skill_file), "--out", str(out), "--max-duration", "300", "-q", *args],
                       cwd=tmp_path, capture_output=True, text=True, timeout=600,
                       env={**env, **PLANT_ENV, **(env_extra or {}), "PYTHONPATH": str(REPO), "MPLBACKEND": "Agg"})
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    report = json.loads((out / "iiwa-1" / "report.json").read_text())
    sim = report["counters"]["sim"]
    assert report["final_phase"] == "DONE" and report["dirt_removed_fraction"] > 0.98, report["faults"]
    assert not [f for f in report["faults"] if f["phase"] in ("FAULT", "ESTOP")], report["faults"]
    brakes = {k: sim.get(k, 0) for k in ("joint_speed_brakes", "tool_speed_brakes", "press_speed_brakes",
                                        "contact_force_yields", "guard_faults")}
    # no FAULT-hold, no joint run away, no force over the robot side's cap; a pad's press-speed yield may happen
    # on a loaded machine (one in a run beside a two-cell campaign), and is the robot side doing its job
    assert brakes["guard_faults"] == brakes["joint_speed_brakes"] == brakes["contact_force_yields"] == 0, brakes
    assert report["max_joint_speed_ratio"] < 0.8 and report["peak_contact_force_n"] < report["force_cap_n"], report
    if os.geteuid() == 0:  # the router's threads as the loops' I/O threads
        assert "threads SCHED_FIFO 9" in (out / "logs" / "router.log").read_text()
    return report


@pytest.mark.slow
@pytest.mark.alone
@pytest.mark.skipif((os.cpu_count() or 1) < ROUTED_CELL_CORES,
                    reason=f"the whole routed real-time cell needs {ROUTED_CELL_CORES} cores (ROUTED_CELL_CORES)")
def test_a_realtime_cell_on_the_identified_arm_through_the_router_cleans_its_board(tmp_path, learned_skill_file):
    """The whole cell, three stains, camera and perception, every state and command routed."""
    _routed_realtime_cell(tmp_path, learned_skill_file)


@pytest.mark.slow
@pytest.mark.alone
def test_a_realtime_cell_through_the_router_on_two_cores_cleans_a_stain_from_the_sims_truth(tmp_path,
                                                                                           learned_skill_file):
    """What 2 cores carry of the routed real-time cell: one stain, no camera, the controller's stains from the sim's
    truth (``stains_from = "truth"``: no wait for a starved perception; perception through the router is the
    lock-step cells' test above), every state and command still routed at 1 kHz, the same checks."""
    report = _routed_realtime_cell(tmp_path, learned_skill_file, "--stains", "1",
                                   env_extra={"LAMPS__CONTROLLER__STAINS_FROM": '"truth"',
                                              "LAMPS__SIM__CAMERA__ENABLED": "false"})
    assert report["counters"]["controller"].get("stains_stale", 0) == 0, report["counters"]["controller"]


def test_health_alive_sees_a_clients_token_through_the_router_and_names_a_missing_one(cell):
    """``lamps health --alive``: compose's probe of a router's client (no port of its own to probe)."""
    from launch.health import alive

    router, robot_id, creds = cell
    env = {"LAMPS_ROBOT_ID": robot_id, "LAMPS_ZENOH_MODE": "client", "LAMPS_ZENOH_CONNECT": router.endpoint,
           "LAMPS_ZENOH_ACCESS_CONTROL": "true", "LAMPS_ZENOH_IDENTITY": str(identity_folder(creds, "robot"))}
    from runtime.session import ServiceNode

    settings = ZenohSettings(mode="client", connect=(router.endpoint,), robot_id=robot_id, access_control=True,
                             identity=str(identity_folder(creds, "robot")))
    with ServiceNode("sim", settings):
        r = subprocess.run([sys.executable, "-m", "runtime.cli", "health", "--alive", "sim", "--timeout", "3",
                            "-v"],
                           env={**os.environ, **env, "PYTHONPATH": str(REPO)}, capture_output=True, text=True,
                           timeout=60)
        assert r.returncode == 0 and "sim is alive" in r.stdout, r.stderr
        why = alive("perception", 1.0, env)
    assert why is not None and f"lamps/{robot_id}/alive/perception" in why and router.endpoint in why, why
    assert "no Zenoh session" in alive("sim", 1.0, {**env, "LAMPS_ZENOH_CONNECT": "tls/127.0.0.1:1"})
