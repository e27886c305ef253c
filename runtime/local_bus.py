"""The cell's keys without a network: an in-process bus behind the same :class:`~runtime.session.ServiceNode`.

A :class:`LocalNode` is a :class:`~runtime.session.ServiceNode` whose
session is a :class:`LocalSession` on a shared :class:`LocalBus` instead of
a Zenoh session: the services publish, read (through the same
:class:`~runtime.session.Latest` and :class:`~runtime.session.Inbox`,
bad payloads counted alike) and declare liveliness exactly as on Zenoh, but a
put is handed to every matching subscriber in the putting thread, at once, in
order, never lost. A published message travels as itself (messages are
frozen; built through their checks): a reader of its type gets the object, a
reader of another type or an old schema version gets the codec's bytes and
its refusal, and ``to_bytes`` encodes on demand (the codec's path itself is
what the Zenoh cell and the codec's tests run). Key expressions match as Zenoh
matches them (``zenoh.KeyExpr.intersects``). There is no access control
and no other process: one process holds every service of a cell
(:mod:`launch.local_cell`, a campaign's network-free cell).
"""

from __future__ import annotations

import itertools
import threading
from collections import deque
from collections.abc import Callable
from typing import cast

import zenoh

from interfaces.codec import encode
from interfaces.messages import SCHEMA_VERSION, Message

from .config import ZenohSettings
from .session import Latest, ServiceNode


class _Payload:
    """What a subscriber reads of a sample's payload (``len``, ``to_bytes``), as Zenoh's ``ZBytes``; and
    :meth:`decoded`, the message for a reader of one type: the published message itself when it is of that type
    and schema version, else the bytes decoded once for every reader of that type (raising, for each reader,
    what the codec raises)."""

    __slots__ = ("_data", "_msg", "_msgs")

    def __init__(self, data: bytes | None, msg=None) -> None:
        self._data = data
        self._msg = msg
        self._msgs: dict | None = None

    def __len__(self) -> int:
        return len(self.to_bytes())

    def to_bytes(self) -> bytes:
        if self._data is None:
            self._data = encode(self._msg)
        return self._data

    def decoded(self, decode):
        """The message as ``decode`` (a :class:`~interfaces.codec.Decoder`) reads it; a payload that does not
        decode raises for each reader, which each count it, as on Zenoh."""
        msg = self._msg
        t = decode.msg_type
        if msg is not None and type(msg) is t and msg.version == SCHEMA_VERSION:
            return msg
        msgs = self._msgs
        if msgs is None:
            msgs = self._msgs = {}
        out = msgs.get(t)
        if out is None:
            out = msgs[t] = decode(self.to_bytes())
        return out


class _Sample:
    __slots__ = ("key_expr", "payload")

    def __init__(self, key: str, data: bytes | None, msg=None) -> None:
        self.key_expr = key
        self.payload = _Payload(data, msg)


class _Subscriber:
    """A callback subscriber, or (``depth``) a ring of the newest samples read with :meth:`try_recv`."""

    def __init__(self, bus: LocalBus, expr: str, callback: Callable | None, depth: int) -> None:
        self.bus, self.expr, self.callback = bus, zenoh.KeyExpr(expr), callback
        self._ring: deque[_Sample] | None = None if callback is not None else deque(maxlen=max(depth, 1))

    def deliver(self, sample: _Sample) -> None:
        if self._ring is not None:
            self._ring.append(sample)
        elif self.callback is not None:
            self.callback(sample)

    def try_recv(self) -> _Sample | None:
        if self._ring is None:
            return None
        try:
            return self._ring.popleft()
        except IndexError:
            return None

    def undeclare(self) -> None:
        self.bus._remove(self)


class _Publisher:
    __slots__ = ("bus", "key")

    def __init__(self, bus: LocalBus, key: str) -> None:
        self.bus, self.key = bus, key

    def put(self, data: bytes) -> None:
        self.bus.put(self.key, data)

    def put_message(self, msg: Message) -> None:
        self.bus.put(self.key, None, msg)

    def undeclare(self) -> None:
        pass


class LocalBus:
    """Subscriptions by key expression; :meth:`put` delivers to each matching one in the caller's thread."""

    def __init__(self) -> None:
        self._subs: list[_Subscriber] = []
        self._routes: dict[str, tuple[_Subscriber, ...]] = {}  # concrete key -> its subscribers (cleared on change)
        self._tokens: set[str] = set()
        self._lock = threading.Lock()
        self.puts = 0
        self._ids = itertools.count(1)  # session ids, per bus: a cell's are the same whatever ran before it

    def next_id(self) -> int:
        """A new session id on this bus (1, 2, ...)."""
        return next(self._ids)

    def put(self, key: str, data: bytes | None, msg: Message | None = None) -> None:
        """Hand ``data`` (bytes), or the message ``msg`` (``data`` None), to every subscriber matching ``key``."""
        subs = self._routes.get(key)
        if subs is None:
            k = zenoh.KeyExpr(key)
            with self._lock:
                subs = self._routes[key] = tuple(s for s in self._subs if s.expr.intersects(k))
        self.puts += 1
        sample = _Sample(key, data, msg)
        for s in subs:
            s.deliver(sample)

    def subscribe(self, expr: str, callback: Callable | None, depth: int = 1) -> _Subscriber:
        sub = _Subscriber(self, expr, callback, depth)
        with self._lock:
            self._subs.append(sub)
            self._routes.clear()
        return sub

    def _remove(self, sub: _Subscriber) -> None:
        with self._lock:
            if sub in self._subs:
                self._subs.remove(sub)
                self._routes.clear()

    def tokens(self, expr: str) -> list[str]:
        k = zenoh.KeyExpr(expr)
        with self._lock:
            return [t for t in self._tokens if zenoh.KeyExpr(t).intersects(k)]


class _Token:
    def __init__(self, bus: LocalBus, key: str) -> None:
        self.bus, self.key = bus, key
        with bus._lock:
            bus._tokens.add(key)

    def undeclare(self) -> None:
        with self.bus._lock:
            self.bus._tokens.discard(self.key)


class _Reply:
    class _Ok:
        def __init__(self, key: str) -> None:
            self.key_expr = key

    def __init__(self, key: str) -> None:
        self.ok = self._Ok(key)


class _Liveliness:
    def __init__(self, bus: LocalBus) -> None:
        self.bus = bus

    def declare_token(self, key: str) -> _Token:
        return _Token(self.bus, key)

    def get(self, expr: str, timeout: float = 1.0) -> list[_Reply]:
        return [_Reply(t) for t in self.bus.tokens(expr)]


class LocalSession:
    """The part of ``zenoh.Session`` the services use, on a :class:`LocalBus`.

    ``declare_subscriber(key, handler)``: a callable gets each sample in the putting thread; any other handler
    (Zenoh's ``RingChannel``) makes a ring of :attr:`ring_depth` read by ``try_recv``.
    """

    def __init__(self, bus: LocalBus, ring_depth: int = 1) -> None:
        self.bus = bus
        self.ring_depth = ring_depth
        self._zid = f"{bus.next_id():032x}"

    def zid(self) -> str:
        return self._zid

    def declare_subscriber(self, key: str, handler) -> _Subscriber:
        return self.bus.subscribe(key, handler if callable(handler) else None, self.ring_depth)

    def declare_publisher(self, key: str, **_qos) -> _Publisher:
        return _Publisher(self.bus, key)

    def liveliness(self) -> _Liveliness:
        return _Liveliness(self.bus)

    def with_ring(self, depth: int) -> LocalSession:
        """A view of the same bus and id whose ring subscribers keep ``depth`` samples (how :class:`Latest` gets
        its depth)."""
        view = LocalSession.__new__(LocalSession)
        view.bus, view.ring_depth, view._zid = self.bus, depth, self._zid
        return view

    def close(self) -> None:
        pass


class LocalNode(ServiceNode):
    """A :class:`ServiceNode` on a :class:`LocalBus`: same publishing, readers and liveliness, no network."""

    def __init__(self, service: str, bus: LocalBus, settings: ZenohSettings | None = None) -> None:
        super().__init__(service, settings or ZenohSettings())
        self.bus = bus

    def __enter__(self) -> LocalNode:
        from .service_security import IN_PROCESS

        self.security = IN_PROCESS
        session = LocalSession(self.bus)
        # a stand-in for zenoh.Session and its token: the part ServiceNode's readers and liveliness use
        self._session = cast(zenoh.Session, session)
        self._token = cast(zenoh.LivelinessToken, session.liveliness().declare_token(self.keys.alive(self.service)))
        return self

    def _local(self) -> LocalSession:
        return cast(LocalSession, self.session)

    def publish(self, key: str, msg: Message) -> None:
        """Put ``msg`` on ``key`` as itself (see the module's notes)."""
        msg = self._with_security(msg)
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._publishers[key] = cast(zenoh.Publisher, self._local().declare_publisher(key))
        cast(_Publisher, pub).put_message(msg)

    def latest(self, key: str, msg_type, depth: int = 1) -> Latest:
        reader = Latest(cast(zenoh.Session, self._local().with_ring(depth)), key, msg_type, depth)
        self._readers.append(reader)
        return reader
