"""A server of Foxglove's WebSocket protocol (publishing side), for the live view.

The protocol (github.com/foxglove/ws-protocol, spec v1): the server sends
``serverInfo`` and ``advertise`` (channels: id, topic, message encoding,
schema name, schema, schema encoding) as JSON text, the client answers
``subscribe`` / ``unsubscribe`` (its subscription ids for channel ids), and
each message goes out as a binary frame: opcode 0x01, the subscription id
(u32), the log time (u64 ns) and the payload, all little-endian. Both
sub-protocol names are accepted: ``foxglove.websocket.v1`` (the open-source
Lichtblick, older Foxglove apps) and ``foxglove.sdk.v1`` (current Foxglove
apps): the messages are the same. (foxglove-sdk's own server speaks only the
second, which Lichtblick refuses.)

The server runs an asyncio loop on a thread of its own; :meth:`add_channel`
and :meth:`send` are called from any thread and never wait on a client:
each client has a bounded queue, and a client that falls behind loses its
oldest messages (counted in :attr:`dropped`), never the cell's time.

Who may connect: the server binds ``127.0.0.1`` unless told otherwise.
Bound to any other address (``0.0.0.0`` in a container) it reaches beyond
this machine and starts only with a token (:class:`TokenRequired`
otherwise); a client that connects from another machine must then present
it in the URL's query, ``ws://HOST:PORT/?token=TOKEN`` (a browser's
WebSocket can set no header, and the sub-protocol is fixed by Foxglove's
protocol), checked at the opening handshake in constant time; without it
the handshake is answered 401 and counted in :attr:`refused`. A client from
a loopback address is served without a token, as every client of a view
bound to loopback is (so a reverse proxy on the same machine must check
clients itself).
"""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import ipaddress
import json
import logging
import struct
import threading
import time
from dataclasses import dataclass, field
from http import HTTPStatus
from typing import TYPE_CHECKING
from urllib.parse import parse_qs, urlsplit

if TYPE_CHECKING:
    from websockets.asyncio.server import ServerConnection

log = logging.getLogger(__name__)

SUBPROTOCOLS = ("foxglove.websocket.v1", "foxglove.sdk.v1")
MESSAGE_DATA = 0x01
#: Frames queued per client before the oldest are dropped.
CLIENT_QUEUE = 2000
#: The shortest token accepted [characters] (``secrets.token_urlsafe(16)`` gives 22).
MIN_TOKEN_CHARS = 16


class TokenRequired(ValueError):
    """A server that reaches beyond this machine was given no token (or one too short); the message says how to
    give one."""


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (``127.0.0.0/8``, ``::1``, IPv4-mapped ``::ffff:127.x``);
    anything else (``0.0.0.0``, ``""``, another name or address) reaches beyond this machine."""
    if host == "localhost":
        return True
    try:
        ip = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return False
    mapped = getattr(ip, "ipv4_mapped", None)
    return (mapped or ip).is_loopback


def check_token(host: str, token: str | None) -> None:
    """TokenRequired unless serving on ``host`` is allowed with ``token``: any on loopback; beyond it, a token of
    :data:`MIN_TOKEN_CHARS` or more."""
    if is_loopback(host):
        return
    if not token:
        raise TokenRequired(f"serving on {host or 'every interface'} reaches beyond this machine and the live view "
                            "would be open to anyone on the network: give it a token (--token-file FILE, "
                            "LAMPS_LIVE_TOKEN or --token-from-identity), or serve on 127.0.0.1")
    if len(token) < MIN_TOKEN_CHARS:
        raise TokenRequired(f"the live view's token has {len(token)} characters: at least {MIN_TOKEN_CHARS} "
                            "(python -c 'import secrets; print(secrets.token_urlsafe(24))' makes one)")


def _digest(text: str) -> bytes:
    return hashlib.sha256(text.encode()).digest()


@dataclass(eq=False)  # hashed by identity: one per connection
class _Client:
    ws: ServerConnection
    subs: dict[int, int] = field(default_factory=dict)  # channel id -> the client's subscription id
    queue: asyncio.Queue[bytes | str] = field(default_factory=lambda: asyncio.Queue(CLIENT_QUEUE))


class FoxgloveWsServer:
    """Serves channels to Foxglove clients on ``ws://host:port`` (port 0: any free one; see :attr:`port`).

    token : what a client from another machine must present (``?token=``); needed when ``host`` is not loopback
    (:func:`check_token`). refused : handshakes answered 401 (no token, or a wrong one).
    """

    def __init__(self, name: str, host: str = "127.0.0.1", port: int = 8765, token: str | None = None) -> None:
        check_token(host, token)
        self.name = name
        self.dropped = 0
        self.refused = 0
        self._token_digest = _digest(token) if token else None
        self._channels: dict[int, dict] = {}
        self._clients: set[_Client] = set()
        self._lock = threading.Lock()
        self._next_id = 1
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(host, port), name="foxglove-ws", daemon=True)
        self._thread.start()
        self._ready.wait(30.0)
        if self._error is not None:
            raise RuntimeError(f"cannot serve on {host}:{port}: {self._error}") from self._error
        if not self._ready.is_set():
            raise RuntimeError(f"the WebSocket server on {host}:{port} did not start within 30 s")

    # ----------------------------------------------------------------------------------------- any thread

    def add_channel(self, topic: str, encoding: str, schema_name: str, schema: str, schema_encoding: str) -> int:
        """Advertise a channel to every client (now and later); returns its id."""
        with self._lock:
            cid = self._next_id
            self._next_id += 1
            ch = {"id": cid, "topic": topic, "encoding": encoding, "schemaName": schema_name, "schema": schema,
                  "schemaEncoding": schema_encoding}
            self._channels[cid] = ch
        self._loop.call_soon_threadsafe(self._broadcast, json.dumps({"op": "advertise", "channels": [ch]}))
        return cid

    def send(self, channel_id: int, log_time_ns: int, payload: bytes) -> None:
        """One message on a channel to each client subscribed to it."""
        self._loop.call_soon_threadsafe(self._fanout, channel_id, log_time_ns, payload)

    @property
    def clients(self) -> int:
        return len(self._clients)

    def stop(self) -> None:
        if self._loop.is_running():
            self._loop.call_soon_threadsafe(self._stop_event.set)
        self._thread.join(10.0)

    # ------------------------------------------------------------------------------------ the server's loop

    def _run(self, host: str, port: int) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._serve(host, port))
        except BaseException as exc:  # a bind failure reaches the constructor
            self._error = exc
            self._ready.set()

    async def _serve(self, host: str, port: int) -> None:
        from websockets.asyncio.server import serve
        from websockets.typing import Subprotocol

        self._stop_event = asyncio.Event()
        async with serve(self._handler, host, port, subprotocols=[Subprotocol(s) for s in SUBPROTOCOLS], max_size=2**20,
                         compression=None, process_request=self._admit) as server:
            self.port = server.sockets[0].getsockname()[1]
            self._ready.set()
            await self._stop_event.wait()

    def _admit(self, connection, request):
        """At the opening handshake: None (go on) for a client from loopback or one presenting the token in the
        query (constant-time comparison of digests); else a 401 response, counted and logged."""
        peer = connection.remote_address[0] if connection.remote_address else ""
        if is_loopback(str(peer)):
            return None
        given = parse_qs(urlsplit(request.path).query).get("token", [""])[-1]
        if self._token_digest is not None and hmac.compare_digest(_digest(given), self._token_digest):
            return None
        self.refused += 1
        log.warning("live view: refused %s (%s)", peer, "a wrong token" if given else "no token")
        return connection.respond(HTTPStatus.UNAUTHORIZED, "this live view needs its token: ws://HOST:PORT/?token=\n")

    def _broadcast(self, text: str) -> None:
        for c in self._clients:
            self._put(c, text)

    def _fanout(self, channel_id: int, log_time_ns: int, payload: bytes) -> None:
        head = None
        for c in self._clients:
            sub = c.subs.get(channel_id)
            if sub is None:
                continue
            head = head or bytes([MESSAGE_DATA])
            self._put(c, head + struct.pack("<IQ", sub, log_time_ns) + payload)

    def _put(self, c: _Client, frame) -> None:
        if c.queue.full():
            c.queue.get_nowait()
            self.dropped += 1
        c.queue.put_nowait(frame)

    async def _handler(self, ws) -> None:
        if ws.subprotocol not in SUBPROTOCOLS:
            await ws.close(1002, f"sub-protocol must be one of {', '.join(SUBPROTOCOLS)}")
            return
        c = _Client(ws)
        self._clients.add(c)
        writer = asyncio.ensure_future(self._write(c))
        try:
            await ws.send(json.dumps({"op": "serverInfo", "name": self.name, "capabilities": [],
                                      "supportedEncodings": [], "metadata": {},
                                      "sessionId": str(time.time_ns())}))
            with self._lock:
                channels = list(self._channels.values())
            if channels:
                await ws.send(json.dumps({"op": "advertise", "channels": channels}))
            async for text in ws:
                self._on_client(c, text)
        except Exception as exc:  # a client's error ends that client only
            log.info("foxglove client %s: %s", getattr(ws, "remote_address", "?"), exc)
        finally:
            self._clients.discard(c)
            writer.cancel()

    async def _write(self, c: _Client) -> None:
        while True:
            await c.ws.send(await c.queue.get())

    def _on_client(self, c: _Client, text) -> None:
        """A client's request: subscribe / unsubscribe; anything else is answered with a warning status."""
        try:
            msg = json.loads(text) if isinstance(text, str) else {}
            op = msg.get("op")
            if op == "subscribe":
                for s in msg["subscriptions"]:
                    if int(s["channelId"]) in self._channels:
                        c.subs[int(s["channelId"])] = int(s["id"])
                return
            if op == "unsubscribe":
                gone = {int(i) for i in msg["subscriptionIds"]}
                c.subs = {ch: sub for ch, sub in c.subs.items() if sub not in gone}
                return
            why = f"unsupported request {op!r}"
        except (ValueError, KeyError, TypeError) as exc:
            why = f"malformed request ({type(exc).__name__}: {exc})"
        self._put(c, json.dumps({"op": "status", "level": 1, "message": why}))
