"""``lamps foxglove``: the running cell served live to the Foxglove app over its WebSocket protocol.

It subscribes every key of the cell as the recorder does and publishes what
the recording would hold (:func:`launch.record_json.json_records`: the cell's
messages as JSON with full schemas, camera frames as
``foxglove.CompressedImage``, the controller trace as plottable rows) and the
3D scene and image overlays of :mod:`launch.scene` (Foxglove's typed messages
from ``foxglove-sdk``), through :class:`launch.ws_server.FoxgloveWsServer`
(Foxglove's WebSocket protocol, for the Foxglove app and Lichtblick alike).
Open the app, "Open connection", ``ws://<host>:8765``, and load
``config/foxglove/lamps.json``.

The Zenoh thread only queues the raw sample; a worker thread decodes,
converts and logs. Each topic is thinned to at most ``--max-rate`` messages
per second (the 1 kHz states and commands; a viewer needs no more), and a
full queue drops the oldest samples (counted): a slow viewer never slows
the cell. Nothing is written to disk.

Who may watch: the view serves on ``127.0.0.1`` (``--host``). Served on
any other address (``--host 0.0.0.0``, as in its container) it reaches
beyond this machine and starts only with a token, which clients from other
machines present as ``ws://HOST:PORT/?token=TOKEN``
(:mod:`launch.ws_server`): ``--token-file FILE`` (its first line),
``LAMPS_LIVE_TOKEN``, or ``--token-from-identity``, a token derived from the
private key of the view's Zenoh identity (:func:`live_token`: the same for
every start with that identity, gone with it when credentials are made
anew), which ``--print-token`` prints. Without one it refuses to start,
naming the problem.

A site of several cells through one router (``lamps up --cells N``) is served by one view: ``lamps foxglove
--cells ID,...`` joins as the site viewer (the identity that reads every cell) and serves every cell's topics
(each under its own prefix) on one port, each cell's scene in a frame tree of its own (``<robot id>/world``);
``--write-layout`` then writes a layout with a tab per cell.
"""

from __future__ import annotations

import argparse
import base64
import json
import logging
import os
import sys
import threading
import time
from collections import Counter, deque
from pathlib import Path

log = logging.getLogger(__name__)

#: The WebSocket port Foxglove's app connects to by default.
DEFAULT_PORT = 8765
#: The environment variable that may carry the live view's token.
TOKEN_ENV = "LAMPS_LIVE_TOKEN"
#: HKDF's ``info`` for the token derived from an identity's key (:func:`live_token`).
_TOKEN_INFO = b"lamps live view token v1"


def live_token(private_key_pem: Path) -> str:
    """The live view's token of the identity whose private key (PEM, an elliptic-curve key as ``lamps
    credentials`` makes) is at ``private_key_pem``: HKDF-SHA256 of the key's secret scalar, ``info``
    :data:`_TOKEN_INFO`, 18 bytes, URL-safe base64 (24 characters, 144 bits). Whoever can read the key can compute
    it; nobody else can."""
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.hazmat.primitives.kdf.hkdf import HKDF

    key = serialization.load_pem_private_key(Path(private_key_pem).read_bytes(), password=None)
    if not isinstance(key, ec.EllipticCurvePrivateKey):
        raise ValueError(f"{private_key_pem}: not an elliptic-curve private key")
    scalar = key.private_numbers().private_value.to_bytes((key.curve.key_size + 7) // 8, "big")
    raw = HKDF(algorithm=hashes.SHA256(), length=18, salt=None, info=_TOKEN_INFO).derive(scalar)
    return base64.urlsafe_b64encode(raw).decode("ascii")


def token_of(a, settings=None) -> str | None:
    """The token the options give: ``--token-file`` (its first line), ``--token-from-identity`` (of
    ``settings``' identity), else ``LAMPS_LIVE_TOKEN``; None if none. ValueError naming what cannot be read."""
    if a.token_file:
        try:
            lines = Path(a.token_file).read_text().splitlines()
        except OSError as exc:
            raise ValueError(f"--token-file {a.token_file}: {exc.strerror or exc}") from None
        return lines[0].strip() if lines else ""
    if a.token_from_identity:
        key = getattr(settings, "tls_private_key", "")
        if not key:
            raise ValueError("--token-from-identity: the live view has no identity (LAMPS_ZENOH_IDENTITY, [zenoh] "
                             "identity: a folder of 'lamps credentials')")
        try:
            return live_token(Path(key))
        except (OSError, ValueError) as exc:
            raise ValueError(f"--token-from-identity: {key}: {exc}") from None
    return os.environ.get(TOKEN_ENV) or None


class LiveView:
    """Subscribes ``<prefix>/**`` of each cell on ``session`` and serves it on a Foxglove WebSocket server until
    :meth:`close`.

    keys : the cell's :class:`~interfaces.keys.Keys`, or a sequence of them (a site: each cell's scene frames then
    carry its robot id, :func:`launch.scene.cell_frames`).
    counters : samples logged per topic kind (the key after the cell's prefix), ``thinned`` (above the rate),
    ``undecodable``, ``unknown_key``, ``dropped_queue_full``.
    """

    def __init__(self, session, keys, host: str = "127.0.0.1", port: int = DEFAULT_PORT, max_rate_hz: float = 100.0,
                 max_queue: int = 20_000, token: str | None = None) -> None:
        from .scene import cells_of, scenes_of
        from .ws_server import FoxgloveWsServer

        if not max_rate_hz > 0:
            raise ValueError(f"max_rate_hz must be positive, got {max_rate_hz}")
        self.cells = cells = cells_of(keys)
        self.keys = cells[0]
        self.counters: Counter[str] = Counter()
        self._min_gap_ns = int(1e9 / max_rate_hz)
        self._last_ns: dict[str, int] = {}
        self._channels: dict[str, int] = {}  # topic -> channel id
        self.scenes = scenes_of(cells)
        self.scene = self.scenes[self.keys.prefix]
        self._decoders: dict = {}
        self._queue: deque = deque(maxlen=max_queue)
        self._wake = threading.Event()
        self._stop = threading.Event()
        many = len(cells) > 1
        name = f"LAMPS site {', '.join(k.prefix for k in cells)}" if many else f"LAMPS cell {self.keys.prefix}"
        self.server = FoxgloveWsServer(name, host, port, token)  # before anything: it refuses a host without token
        self.port = self.server.port
        self._thread = threading.Thread(target=self._run, name="foxglove-live", daemon=True)
        self._thread.start()
        self._subs = [session.declare_subscriber(f"{k.prefix}/**", self._on_sample) for k in cells]

    def _on_sample(self, sample) -> None:  # Zenoh thread: never waits
        if len(self._queue) == self._queue.maxlen:
            self.counters["dropped_queue_full"] += 1
        self._queue.append((str(sample.key_expr), sample.payload.to_bytes(), time.time_ns()))
        self._wake.set()

    def _channel(self, topic: str, make) -> int:
        """The id of ``topic``'s channel; ``make()`` -> (encoding, schema name, schema text, schema encoding)."""
        cid = self._channels.get(topic)
        if cid is None:
            cid = self._channels[topic] = self.server.add_channel(topic, *make())
        return cid

    def _thin(self, topic: str, t_ns: int) -> bool:
        """Whether ``topic`` already had a message within the rate's gap (then this one is left out)."""
        last = self._last_ns.get(topic)
        if last is not None and 0 <= t_ns - last < self._min_gap_ns:
            self.counters["thinned"] += 1
            return True
        self._last_ns[topic] = t_ns
        return False

    def _publish(self, key: str, data: bytes, t_ns: int) -> None:
        import msgspec

        from interfaces.codec import Decoder
        from interfaces.errors import MessageDecodeError

        from .record_json import json_records, message_type_of
        from .scene import cell_of_key

        if key not in self._decoders:
            cell = cell_of_key(self.cells, key)
            t = message_type_of(cell, key) if cell is not None else None
            self._decoders[key] = (Decoder(t), self.scenes[cell.prefix], len(cell.prefix) + 1) \
                if cell is not None and t is not None else None
        entry = self._decoders[key]
        if entry is None:
            self.counters["unknown_key"] += 1
            return
        dec, scene, after_prefix = entry
        try:
            msg = dec(data)
        except MessageDecodeError:
            self.counters["undecodable"] += 1
            return
        for topic, scene_msg in scene.on_message(key, msg, t_ns):  # thinned by the builder itself
            def typed(m=scene_msg):
                schema = type(m).get_schema()
                return "protobuf", schema.name, base64.b64encode(bytes(schema.data)).decode("ascii"), "protobuf"
            self.server.send(self._channel(topic, typed), t_ns, scene_msg.encode())
        if self._thin(key, t_ns):
            return
        for topic, name, schema, payload, t in json_records(key, msg, t_ns):
            cid = self._channel(topic,
                                lambda name=name, schema=schema: ("json", name, json.dumps(schema()), "jsonschema"))
            self.server.send(cid, t, msgspec.json.encode(payload))
        self.counters[key[after_prefix:]] += 1

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(0.1)
            self._wake.clear()
            while self._queue:
                key, data, t_ns = self._queue.popleft()
                try:
                    self._publish(key, data, t_ns)
                except Exception:  # a bad message never ends the view: counted and logged
                    self.counters["failed"] += 1
                    log.exception("live view: cannot publish a sample of %s", key)

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self._stop.set()
        self._wake.set()
        self._thread.join(10.0)
        self.server.stop()


def main(argv: list[str] | None = None) -> int:
    from runtime.config import add_zenoh_options

    p = argparse.ArgumentParser(prog="lamps foxglove", description=(
        "Serve the running cell to the Foxglove app over its WebSocket protocol (open ws://HOST:PORT in the app; "
        "layout: config/foxglove/lamps.json) until stopped (SIGTERM or Ctrl-C)."))
    p.add_argument("--host", default="127.0.0.1",
                   help="address to serve on (default 127.0.0.1: this machine only; any other, e.g. 0.0.0.0 in a "
                        "container, needs a token)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"WebSocket port (default {DEFAULT_PORT})")
    token_source = p.add_mutually_exclusive_group()
    token_source.add_argument("--token-file", metavar="FILE",
                              help=f"the token clients from other machines present (ws://HOST:PORT/?token=...): the "
                                   f"file's first line (default: ${TOKEN_ENV})")
    token_source.add_argument("--token-from-identity", action="store_true",
                              help="the token derived from the private key of the view's Zenoh identity (the same at "
                                   "every start with it; --print-token shows it)")
    p.add_argument("--print-token", action="store_true", help="print the token and the URL clients open, then exit")
    p.add_argument("--max-rate", type=float, default=100.0, metavar="HZ",
                   help="at most this many messages per second per topic (default 100)")
    p.add_argument("--write-layout", metavar="FILE",
                   help="only write the cell's Foxglove layout (3D scene, camera with stains, force, tracking, "
                        "phase, joints) for this --robot-id and --camera to FILE, then exit")
    p.add_argument("--camera", default="board", help="the camera the layout's image panel shows (default board)")
    p.add_argument("--cells", metavar="ID,...", help="serve every one of these cells (robot ids) of a site, as the "
                   "site viewer through the site's router ([zenoh] cells; --write-layout: a tab per cell)")
    p.add_argument("--config", metavar="FILE", help="TOML config with a [zenoh] table")
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens")
    add_zenoh_options(p)
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING,
                        format="lamps foxglove %(levelname)s: %(message)s")
    from .background_node import cells_option

    try:
        cells = cells_option(a)
    except ValueError as exc:
        p.error(str(exc))
    if a.write_layout:
        return _write_layout(a, cells)
    if not 0 < a.port < 65536:
        p.error(f"--port must be in 1..65535, got {a.port}")
    if not a.max_rate > 0:
        p.error(f"--max-rate must be positive, got {a.max_rate}")
    try:
        token = _checked_token(a)
    except ValueError as exc:
        print(f"lamps foxglove: error: {exc}", file=sys.stderr)
        return 1
    if a.print_token:
        return _print_token(a, token)
    from runtime.stop_signals import wait_for

    from .background_node import open_background_node

    opened = open_background_node("lamps foxglove", "foxglove", a, cells)
    if opened is None:
        return 1
    node, settings, stop = opened
    from interfaces.keys import Keys

    try:
        try:
            view = LiveView(node.session, [Keys.for_robot(c) for c in settings.cells] or settings.keys, a.host,
                            a.port, a.max_rate, token=token)
        except RuntimeError as exc:  # the port is taken, or the address is not ours
            print(f"lamps foxglove: error: cannot serve on {a.host}:{a.port} ({exc})", file=sys.stderr)
            return 1
        what = f"the cells {', '.join(settings.cells)}" if settings.cells else "the cell"
        print(f"lamps foxglove: serving {what} on ws://{a.host}:{view.port} (Foxglove: Open connection"
              f"{'; from another machine with ?token=, --print-token shows it' if token else ''})", flush=True)
        wait_for(stop)  # in slices: a signal another thread took still reaches this one
        view.close()
    finally:
        node.close()
    log.info("live view counters: %s", dict(view.counters))
    return 0


def _checked_token(a) -> str | None:
    """The token of the options (None: none) if the view may serve on ``--host`` with it; ValueError saying why
    not (no token beyond loopback, a short one, an identity or a file that cannot be read)."""
    from lampskit.errors import LampsError
    from runtime.config import load_config, zenoh_with_options

    from .ws_server import check_token

    try:
        settings = zenoh_with_options(load_config(a.config).zenoh, a) if a.token_from_identity else None
    except LampsError as exc:
        raise ValueError(str(exc)) from None
    token = token_of(a, settings)
    if a.print_token and not token:
        raise ValueError(f"no token to print: give --token-file FILE, {TOKEN_ENV} or --token-from-identity")
    check_token(a.host, token)  # TokenRequired is a ValueError
    return token


def _print_token(a, token: str | None) -> int:
    host = "HOST" if a.host in ("0.0.0.0", "::", "") else a.host
    print(token)
    print(f"clients from other machines open ws://{host}:{a.port}/?token={token}", file=sys.stderr)
    return 0


def _write_layout(a, cells: tuple[str, ...]) -> int:
    from pathlib import Path

    from interfaces.keys import Keys
    from lampskit.atomic import write_text_atomic

    from .layout import cell_layout, site_layout

    try:
        if cells:
            layout, what = site_layout([Keys.for_robot(c) for c in cells], a.camera), f"the cells {', '.join(cells)}"
        else:
            keys = Keys.for_robot(a.robot_id) if a.robot_id else Keys()
            layout, what = cell_layout(keys, a.camera), keys.prefix
        write_text_atomic(Path(a.write_layout), json.dumps(layout, indent=1) + "\n")
    except (OSError, ValueError) as exc:
        print(f"lamps foxglove: error: cannot write the layout: {exc}", file=sys.stderr)
        return 1
    print(f"wrote the Foxglove layout of {what} to {a.write_layout} (Foxglove / Lichtblick: Import layout)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
