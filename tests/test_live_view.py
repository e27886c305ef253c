"""``lamps foxglove``: the cell over Zenoh, served on Foxglove's WebSocket protocol, read by a real client.

A real Zenoh session publishes the cell's messages on loopback; the live view
(its own session and WebSocket server) serves them; a WebSocket client
speaking ``foxglove.websocket.v1`` (Lichtblick's) or ``foxglove.sdk.v1``
(current Foxglove apps') subscribes and checks every message it gets against
the schema the server advertised (JSON Schema, or Foxglove's protobuf types).

Who may watch: the view binds loopback unless told otherwise; beyond it, it
refuses to start without a token, and a client from another address (this
machine's own network address stands in for another machine) gets its
handshake answered 401 without the token in the URL's query, or with a
wrong one.
"""

from __future__ import annotations

import base64
import json
import os
import struct
import time

import jsonschema
import numpy as np
import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from interfaces.messages import CameraFrame, CameraIntrinsics, Capabilities, ControllerStatus, RobotState
from launch.live import LiveView, live_token
from launch.ws_server import FoxgloveWsServer, TokenRequired, check_token, is_loopback
from runtime.config import ZenohSettings
from runtime.session import ServiceNode

from .mcap_check import protobuf_class
from .test_scene import camera_message, stains_message
from .zenoh_helpers import free_port, wait_for, wait_subscribed


def state_message(i: int) -> RobotState:
    """The ``i``-th RobotState of a slowly moving 7-joint simulated arm (1 ms apart)."""
    return RobotState(seq=i, stamp_ns=i * 10**6, q_rad=[float(0.1 * np.sin(i * 1e-3))] * 7, dq_rad_s=[0.0] * 7,
                      tau_nm=[0.0] * 7, wrench_world=[0.0] * 6,
                      capabilities=Capabilities(True, [100.0] * 7, "sim", 1000.0), robot_time_ns=i * 10**6)


def _frame() -> CameraFrame:
    f = camera_message()
    k = CameraIntrinsics(fx=50.0, fy=50.0, cx=32.0, cy=24.0, width=64, height=48)
    return CameraFrame(seq=1, stamp_ns=1, camera="board", encoding="rgb8", data=bytes(64 * 48 * 3), intrinsics=k,
                       T_camera_to_world=f.T_camera_to_world, robot_time_ns=1)


class FoxgloveClient:
    """A Foxglove WebSocket protocol client: advertised channels by topic, subscriptions, message frames."""

    def __init__(self, port: int, subprotocol: str, host: str = "127.0.0.1", token: str | None = None) -> None:
        query = f"/?token={token}" if token is not None else ""
        self.ws = connect(f"ws://{host}:{port}{query}", subprotocols=[subprotocol], open_timeout=10)
        assert self.ws.subprotocol == subprotocol
        self.channels: dict[str, dict] = {}
        self.by_sub: dict[int, dict] = {}
        self.got: dict[str, list[bytes]] = {}
        self.server_info = None

    def pump(self, timeout_s: float = 0.2) -> None:
        end = time.monotonic() + timeout_s
        while (left := end - time.monotonic()) > 0:
            try:
                frame = self.ws.recv(timeout=left)
            except TimeoutError:
                return
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg["op"] == "serverInfo":
                    self.server_info = msg
                elif msg["op"] == "advertise":
                    for ch in msg["channels"]:
                        self.channels[ch["topic"]] = ch
            elif frame[0] == 0x01:  # message data: opcode, subscription id u32, log time u64, payload
                sub, _t = struct.unpack_from("<IQ", frame, 1)
                self.got.setdefault(self.by_sub[sub]["topic"], []).append(bytes(frame[13:]))

    def subscribe(self, topics: list[str]) -> None:
        subs = []
        for i, topic in enumerate(topics, start=len(self.by_sub) + 1):
            self.by_sub[i] = self.channels[topic]
            subs.append({"id": i, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))


def follow_live(port: int, topics: list[str], what: str) -> FoxgloveClient:
    """A ``foxglove.websocket.v1`` client of the live view on ``port`` once it serves (2 min), subscribed to
    ``topics`` once advertised, after a message on each, every message checked against its channel's schema."""
    def connected():
        try:
            return FoxgloveClient(port, "foxglove.websocket.v1")
        except OSError:
            return None
    client = wait_for(connected, 120.0, what, period_s=0.5)
    wait_for(lambda: client.pump(0.5) or all(t in client.channels for t in topics), 120.0, f"advertised {topics}")
    client.subscribe(topics)
    wait_for(lambda: client.pump(0.5) or all(client.got.get(t) for t in topics), 60.0, f"live messages on {topics}")
    for t in topics:
        check_payload(client.channels[t], client.got[t][-1])
    return client


def check_payload(channel: dict, payload: bytes) -> None:
    """The payload is what the advertised schema says (JSON Schema with properties, or a protobuf type)."""
    if channel["encoding"] == "json":
        schema = json.loads(channel["schema"])
        assert schema.get("properties"), channel["topic"]
        jsonschema.validate(json.loads(payload), schema)
    else:
        assert channel["encoding"] == "protobuf" and channel["schemaEncoding"] == "protobuf"
        cls = protobuf_class(channel["schemaName"], base64.b64decode(channel["schema"]))
        assert cls.FromString(payload).ListFields(), channel["topic"]


@pytest.mark.slow
@pytest.mark.parametrize("subprotocol", ["foxglove.websocket.v1", "foxglove.sdk.v1"])
def test_the_live_view_serves_the_cell_and_its_scene_to_a_foxglove_client(subprotocol):
    zport, wport = free_port(), free_port()
    pub = ServiceNode("sim", ZenohSettings(listen=(f"tcp/127.0.0.1:{zport}",))).__enter__()
    view_node = ServiceNode("foxglove", ZenohSettings(connect=(f"tcp/127.0.0.1:{zport}",))).__enter__()
    view = LiveView(view_node.session, view_node.keys, port=wport, max_rate_hz=100.0)
    client = None
    try:
        keys = pub.keys
        wait_subscribed(pub.session, keys.robot_state, what="the live view's subscription")
        camera_key = keys.camera_frame("board")
        status = ControllerStatus(seq=1, stamp_ns=1, phase="WIPE", current_mp="periodic 0")

        bursts = iter(range(10**6))

        def publish_all() -> None:
            """A camera frame, 50 states 1 ms apart (robot time goes on), the stains, a status."""
            i0 = next(bursts) * 500
            pub.publish(camera_key, _frame())
            for i in range(i0, i0 + 50):
                pub.publish(keys.robot_state, state_message(i))
            pub.publish(keys.perception_stains, stains_message())
            pub.publish(keys.controller_status, status)

        client = FoxgloveClient(view.port, subprotocol)
        wanted = [keys.robot_state, keys.controller_status, keys.perception_stains, camera_key,
                  f"{keys.prefix}/scene/tf", f"{keys.prefix}/scene/robot", f"{keys.prefix}/scene/board",
                  f"{camera_key}/calibration", f"{camera_key}/annotations"]

        def advertised():
            publish_all()
            client.pump()
            return all(t in client.channels for t in wanted)
        try:
            wait_for(advertised, 15.0, f"advertisements of {wanted}")
        except AssertionError as exc:
            raise AssertionError(f"{exc}: got {sorted(client.channels)}, server info {client.server_info}; view "
                                 f"{dict(view.counters)}, clients {view.server.clients}") from None
        assert client.server_info is not None and "LAMPS" in client.server_info["name"]
        client.subscribe(wanted)

        def received():
            publish_all()
            client.pump(0.3)
            return all(client.got.get(t) for t in wanted)
        try:
            wait_for(received, 20.0, "a message on every subscribed topic", period_s=0.0)
        except AssertionError as exc:
            raise AssertionError(f"{exc}: got {sorted(client.got)}; view {dict(view.counters)}") from None
        for topic in wanted:
            for payload in client.got[topic][:3]:
                check_payload(client.channels[topic], payload)
        names = {t: client.channels[t]["schemaName"] for t in wanted}
        assert names[f"{keys.prefix}/scene/tf"] == "foxglove.FrameTransforms"
        assert names[camera_key] == "foxglove.CompressedImage"
        assert names[f"{camera_key}/annotations"] == "foxglove.ImageAnnotations"
        # the 1 kHz states are thinned to the rate asked for: 50 states in 50 ms give about 5
        per_burst = len(client.got[keys.robot_state])
        assert view.counters["thinned"] > 0 and per_burst < 0.3 * 50 * len(client.got[keys.controller_status])
        assert view.counters["failed"] == 0 and view.server.clients == 1
    finally:
        if client is not None:
            client.ws.close()
        view.close()
        view_node.close()
        pub.close()


@pytest.mark.slow
def test_one_view_serves_two_cells_each_in_a_frame_tree_of_its_own():
    """``lamps foxglove --cells``: two cells' states on one port, each cell's scene rooted at ``<robot id>/world``
    (two arms in one ``world`` would be one tree), a key of neither cell left unsubscribed."""
    from interfaces.keys import Keys

    zport, wport = free_port(), free_port()
    cells = [Keys.for_robot("iiwa-1"), Keys.for_robot("iiwa-2")]
    pub = ServiceNode("sim", ZenohSettings(listen=(f"tcp/127.0.0.1:{zport}",))).__enter__()
    view_node = ServiceNode("foxglove", ZenohSettings(connect=(f"tcp/127.0.0.1:{zport}",))).__enter__()
    view = LiveView(view_node.session, cells, port=wport, max_rate_hz=100.0)
    client = None
    try:
        for keys in cells:
            wait_subscribed(pub.session, keys.robot_state, what=f"the live view's subscription of {keys.prefix}")
        client = FoxgloveClient(view.port, "foxglove.websocket.v1")
        wanted = [f"{k.prefix}/{what}" for k in cells for what in ("robot/state", "scene/tf")]
        bursts = iter(range(10**6))

        def publish() -> None:
            i0 = next(bursts) * 100
            for k in cells:
                for i in range(i0, i0 + 30):
                    pub.publish(k.robot_state, state_message(i))
            pub.publish(Keys.for_robot("iiwa-3").robot_state, state_message(i0))  # not a cell of this view

        wait_for(lambda: publish() or client.pump() or all(t in client.channels for t in wanted), 15.0,
                 f"advertisements of {wanted}")
        client.subscribe(wanted)
        wait_for(lambda: publish() or client.pump(0.3) or all(client.got.get(t) for t in wanted), 20.0,
                 "a message on every topic of both cells", period_s=0.0)
        assert client.server_info["name"] == "LAMPS site lamps/iiwa-1, lamps/iiwa-2"
        assert not any(t.startswith("lamps/iiwa-3/") for t in client.channels), sorted(client.channels)
        for k in cells:
            topic, robot = f"{k.prefix}/scene/tf", k.prefix.rsplit("/", 1)[1]
            cls = protobuf_class("foxglove.FrameTransforms", base64.b64decode(client.channels[topic]["schema"]))
            tf = cls.FromString(client.got[topic][-1])
            assert {x.parent_frame_id for x in tf.transforms} == {f"{robot}/world"}
            assert all(x.child_frame_id.startswith(f"{robot}/") for x in tf.transforms)
        assert view.counters["robot/state"] > 0 and view.counters["failed"] == 0
    finally:
        if client is not None:
            client.ws.close()
        view.close()
        view_node.close()
        pub.close()


@pytest.mark.slow
def test_a_sites_layout_has_a_tab_per_cell_with_its_own_panels_and_frames(tmp_path):
    """``lamps foxglove --cells A,B --write-layout``: each tab is the cell's layout on its own topics."""
    import subprocess
    import sys

    from interfaces.keys import Keys
    from launch.layout import cell_layout, layout_paths

    from .conftest import REPO

    out = tmp_path / "site.json"
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "foxglove", "--cells", "iiwa-1,iiwa-2",
                        "--write-layout", str(out)], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "the cells iiwa-1, iiwa-2" in r.stdout, r.stderr
    site = json.loads(out.read_text())
    tab = site["configById"][site["layout"]]
    assert [t["title"] for t in tab["tabs"]] == ["iiwa-1", "iiwa-2"]
    topics, _ = layout_paths(site)
    for robot in ("iiwa-1", "iiwa-2"):
        one_topics, _ = layout_paths(cell_layout(Keys.for_robot(robot)))
        assert one_topics <= topics
        assert site["configById"][f"3D!scene-{robot}"]["followTf"] == f"{robot}/world"
    assert len(site["configById"]) == 2 * len(cell_layout()["configById"]) + 1
    bad = subprocess.run([sys.executable, "-m", "runtime.cli", "foxglove", "--cells", "iiwa-1,site-viewer",
                          "--write-layout", str(tmp_path / "x.json")], cwd=REPO, capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "--cells iiwa-1,site-viewer" in bad.stderr and not (tmp_path / "x.json").exists()


# ------------------------------------------------------------------------------------------------- who may watch
def _own_address() -> str | None:
    """This machine's address on its default route (no packet is sent), or None without one."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("10.255.255.255", 1))
        except OSError:
            return None
        address = s.getsockname()[0]
    return None if is_loopback(address) else address


@pytest.mark.parametrize("host, loopback", [("127.0.0.1", True), ("127.3.0.1", True), ("::1", True),
                                            ("localhost", True), ("::ffff:127.0.0.1", True), ("0.0.0.0", False),
                                            ("::", False), ("", False), ("192.0.2.7", False),
                                            ("cell-laptop.local", False)])
def test_only_loopback_counts_as_this_machine(host, loopback):
    assert is_loopback(host) == loopback
    if loopback:
        check_token(host, None)  # no token needed
    else:
        with pytest.raises(TokenRequired, match="reaches beyond this machine.*--token-file FILE, LAMPS_LIVE_TOKEN"):
            check_token(host, None)
        with pytest.raises(TokenRequired, match="7 characters: at least 16"):
            check_token(host, "short12")
        check_token(host, "a" * 16)


def test_a_view_beyond_loopback_without_a_token_refuses_to_start_and_says_why(tmp_path):
    import subprocess
    import sys

    from .conftest import REPO

    with pytest.raises(TokenRequired, match="0.0.0.0 reaches beyond this machine"):
        FoxgloveWsServer("x", "0.0.0.0", free_port())
    env = {k: v for k, v in os.environ.items() if k != "LAMPS_LIVE_TOKEN"}
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "foxglove", "--host", "0.0.0.0", "--port",
                        str(free_port()), "--insecure"], cwd=REPO, capture_output=True, text=True, timeout=60, env=env)
    assert r.returncode == 1, r.stderr
    assert "error: serving on 0.0.0.0 reaches beyond this machine" in r.stderr and "--token-from-identity" in r.stderr
    short = tmp_path / "token"
    short.write_text("abc\n")
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "foxglove", "--host", "0.0.0.0", "--token-file",
                        str(short), "--insecure"], cwd=REPO, capture_output=True, text=True, timeout=60, env=env)
    assert r.returncode == 1 and "3 characters: at least 16" in r.stderr, r.stderr


def test_the_identity_token_is_its_keys_own_and_printed_for_the_clients(tmp_path):
    import subprocess
    import sys

    from runtime.credentials import identity_files, identity_folder, make_credentials

    from .conftest import REPO

    make_credentials(tmp_path / "a")
    make_credentials(tmp_path / "b")
    key_a = identity_files(identity_folder(tmp_path / "a", "recorder"))[2]
    token = live_token(key_a)
    assert len(token) == 24 and token == live_token(key_a)
    assert token != live_token(identity_files(identity_folder(tmp_path / "b", "recorder"))[2])
    assert token != live_token(identity_files(identity_folder(tmp_path / "a", "perception"))[2])
    env = {**os.environ, "LAMPS_ZENOH_IDENTITY": str(identity_folder(tmp_path / "a", "recorder"))}
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "foxglove", "--host", "0.0.0.0", "--port", "8765",
                        "--token-from-identity", "--print-token"], cwd=REPO, capture_output=True, text=True,
                       timeout=60, env=env)
    assert r.returncode == 0 and r.stdout.strip() == token, r.stderr
    assert f"ws://HOST:8765/?token={token}" in r.stderr
    env.pop("LAMPS_ZENOH_IDENTITY")
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "foxglove", "--token-from-identity", "--print-token",
                        "--insecure"], cwd=REPO, capture_output=True, text=True, timeout=60, env=env)
    assert r.returncode == 1 and "--token-from-identity: the live view has no identity" in r.stderr, r.stderr


@pytest.mark.attack("live view", "clients from another address open the live view served beyond loopback without a "
                                 "token and with wrong ones",
                   "answered 401 and counted; only the token in the URL is served")
def test_a_client_from_another_address_needs_the_token_in_the_url_one_from_loopback_does_not():
    """Bound to every interface with a token: from this machine's network address (another machine, to the
    server), no token and a wrong one are answered 401 and counted; the token in the query is let in; a client from
    127.0.0.1 is let in without one."""
    address = _own_address()
    if address is None:
        pytest.skip("no network address besides loopback")
    token = "correct-horse-battery-staple"
    server = FoxgloveWsServer("LAMPS test", "0.0.0.0", 0, token)
    try:
        for given in (None, "", "correct-horse-battery-stapl", "correct-horse-battery-staplf", token + "x"):
            with pytest.raises(InvalidStatus, match="401"):
                FoxgloveClient(server.port, "foxglove.websocket.v1", host=address, token=given)
        assert server.refused == 5
        for host, given in ((address, token), ("127.0.0.1", None)):
            client = FoxgloveClient(server.port, "foxglove.sdk.v1", host=host, token=given)
            client.pump(1.0)
            assert client.server_info is not None and client.server_info["name"] == "LAMPS test", host
            client.ws.close()
        assert server.refused == 5
    finally:
        server.stop()
