"""Open a Zenoh session from :class:`~runtime.config.ZenohSettings`, announce the service, read newest samples.

* :func:`zenoh_config` builds the ``zenoh.Config`` (peer mode, explicit
  endpoints, multicast scouting off unless asked for; user-password
  authentication, access control and mutual TLS when configured).
* :class:`ServiceNode` is a context manager: the session plus the liveliness
  token ``<prefix>/alive/<service>``; closing it undeclares both. Its
  publishers carry the key's quality of service (:func:`publisher_qos`):
  the control path (robot states and commands) is sent at once (express,
  not batched), at Zenoh's real-time priority (ahead of camera frames on a
  shared link) and dropped rather than queued when a link is congested (a
  late state or command is worth nothing: the next one replaces it); the
  e-stop has the same priority but is never dropped; camera frames go at
  the lowest data priority.
* :class:`Latest` is a subscription that keeps only the newest sample (a
  one-slot ring channel): the Zenoh thread never waits for the loop, and
  :meth:`Latest.take` never blocks. Bad payloads are counted per reason,
  logged (rate-limited) and dropped; the caller never sees an exception.
* :class:`Inbox` keeps every sample in arrival order (bounded) and lets a
  loop *wait* for the next one with a timeout: what a lock-step peer needs;
  it can also set an event shared with other sources, so one loop waits on
  several at once.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections import Counter, deque
from pathlib import Path
from typing import Any, Generic, TypeVar

import msgspec
import zenoh

from interfaces.access import cell_acl, role_and_cell, site_acl
from interfaces.codec import Decoder, encode
from interfaces.errors import ConfigError, MessageDecodeError
from interfaces.keys import Keys
from interfaces.messages import ControllerStatus, Message, ServiceStatus

from .config import ZenohSettings

log = logging.getLogger(__name__)
M = TypeVar("M", bound=Message)

#: Zenoh's back-off between attempts on a ``connect`` endpoint that is down or was lost (``connect/retry``), unless
#: the ``config_file`` sets one: the first retry after 0.25 s, then doubling up to 1 s. Zenoh's own (1, 2, 4 s)
#: left a restarted service unheard by the peers that connect to it (the recorder, perception, an operator) for up
#: to 4 s after it listened again; a refused TCP connect on a dead endpoint once a second costs nothing.
CONNECT_RETRY = {"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2.0}
CONNECT_RETRY_PATH = "connect/retry"

#: At most one log line per key and this many seconds about bad samples.
BAD_SAMPLE_LOG_PERIOD_S = 5.0
#: At most this many distinct reasons are counted per key; the rest are "other reasons".
MAX_BAD_REASONS = 16


#: Zenoh configuration paths that :class:`ZenohSettings` owns -> the ``[zenoh]`` setting that sets them.
OWNED_PATHS = {
    "mode": "mode", "listen/endpoints": "listen", "connect/endpoints": "connect",
    "scouting/multicast/enabled": "multicast_scouting", "scouting/gossip/enabled": "gossip",
    "transport/auth/usrpwd": "user, password_file, credentials_file", "access_control": "access_control",
    "transport/link/tls": "tls_ca, tls_certificate, tls_private_key",
}


def _base_config(path: str) -> zenoh.Config:
    """Zenoh's defaults, or the Zenoh configuration file ``path`` (``[zenoh] config_file``).

    Raises ConfigError naming the file when it cannot be read or parsed, or when it sets a field that
    the ``[zenoh]`` settings own (:data:`OWNED_PATHS`): one place decides endpoints, identity and access.
    """
    if not path:
        return zenoh.Config()
    if not Path(path).is_file():
        raise ConfigError(f"[zenoh] config_file {path!r} is not a file")
    try:
        cfg = zenoh.Config.from_file(path)
    except zenoh.ZError as exc:
        why = " ".join(str(exc).split()).split(" at /")[0]  # one line, without the Rust source location
        why = "Zenoh refused a value in it" if why.startswith("Invalid configuration") else why[:300]
        raise ConfigError(f"[zenoh] config_file {path!r} is not a Zenoh configuration: {why}") from None
    default = zenoh.Config()
    owned = [f"{p} (set it with [zenoh] {name})" for p, name in OWNED_PATHS.items()
             if cfg.get_json(p) != default.get_json(p)]
    if owned:
        raise ConfigError(f"[zenoh] config_file {path!r} sets what the [zenoh] settings own: {'; '.join(owned)}")
    return cfg


def zenoh_config(settings: ZenohSettings, max_message_bytes: int | None = None) -> zenoh.Config:
    """The ``zenoh.Config`` for ``settings``: its ``config_file`` (or Zenoh's defaults) with the settings over it.

    max_message_bytes : Zenoh's limit on a whole message the session takes [bytes] (a larger one is dropped while
    reassembled, :mod:`interfaces.message_limits`); default the cell's largest message bound, unless the
    ``config_file`` sets one. The reconnect back-off is :data:`CONNECT_RETRY` unless the ``config_file`` sets one.
    """
    from interfaces.message_limits import MAX_MESSAGE_SIZE_PATH
    from interfaces.message_limits import max_message_bytes as cell_max

    cfg = _base_config(settings.config_file)
    if max_message_bytes is not None or cfg.get_json(MAX_MESSAGE_SIZE_PATH) == zenoh.Config().get_json(
            MAX_MESSAGE_SIZE_PATH):
        cfg.insert_json5(MAX_MESSAGE_SIZE_PATH, json.dumps(int(max_message_bytes or cell_max())))
    if cfg.get_json(CONNECT_RETRY_PATH) == zenoh.Config().get_json(CONNECT_RETRY_PATH):
        cfg.insert_json5(CONNECT_RETRY_PATH, json.dumps(CONNECT_RETRY))
    cfg.insert_json5("mode", json.dumps(settings.mode))
    cfg.insert_json5("scouting/multicast/enabled", json.dumps(settings.multicast_scouting))
    cfg.insert_json5("scouting/gossip/enabled", json.dumps(settings.gossip))
    cfg.insert_json5("listen/endpoints", json.dumps(list(settings.listen)))
    cfg.insert_json5("connect/endpoints", json.dumps(list(settings.connect)))
    if settings.user:
        password = _read_secret(settings.password_file, "password_file")
        _read_secret(settings.credentials_file, "credentials_file")
        cfg.insert_json5("transport/auth/usrpwd", json.dumps(
            {"user": settings.user, "password": password, "dictionary_file": settings.credentials_file}))
    if settings.tls_ca:  # first: a missing identity file is named as the setting that gives it
        for path, what in ((settings.tls_ca, "tls_ca"), (settings.tls_certificate, "tls_certificate"),
                           (settings.tls_private_key, "tls_private_key")):
            _read_secret(path, what)
    if settings.access_control:
        cfg.insert_json5("access_control", json.dumps(access_list(settings)))
    if settings.tls_ca:
        cfg.insert_json5("transport/link/tls", json.dumps({
            "root_ca_certificate": settings.tls_ca, "enable_mtls": True,
            "listen_certificate": settings.tls_certificate, "listen_private_key": settings.tls_private_key,
            "connect_certificate": settings.tls_certificate, "connect_private_key": settings.tls_private_key}))
    return cfg


def access_list(settings: ZenohSettings) -> dict:
    """The access list ``settings`` apply: the site's with ``cells``, else the cell's, its roles named as the
    service's own certificate names them (``controller`` or ``controller@<robot_id>``,
    :func:`interfaces.access.identity_name`). ConfigError when that certificate is another cell's."""
    subject = "cert_common_names" if settings.tls_ca else "usernames"
    if settings.cells:
        return site_acl(settings.cells, subject)
    cell = None
    if settings.tls_ca:
        from .certificates import common_name

        role, cell = role_and_cell(common_name(Path(settings.tls_certificate)))
        if cell is not None and Keys.for_robot(cell).prefix != settings.keys.prefix:
            raise ConfigError(f"[zenoh] identity {settings.identity or settings.tls_certificate!r} is {role} of cell "
                              f"{cell}, but the keys are under {settings.keys.prefix} (robot id {cell} expected)")
    # the router's identity is accepted only by its clients (their one link is the router they checked) and by
    # routers linked to it; a peer never accepts it (interfaces.access, "the router relays, it does not vouch")
    return cell_acl(settings.keys, subject, settings.ros_namespaces, cell, relay=settings.mode in ("client", "router"))


def _read_secret(path: str, what: str) -> str:
    """The first line of a credentials file; ConfigError naming the file when it cannot be used."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"[zenoh] {what} {path!r}: {exc.strerror or exc}") from None
    first = text.strip().splitlines()[0].strip() if text.strip() else ""
    if not first:
        raise ConfigError(f"[zenoh] {what} {path!r} is empty")
    return first


class Latest(Generic[M]):
    """Newest decoded sample of one key; :meth:`take` returns it once, or None. With ``depth`` > 1 the newest
    ``depth`` samples are held: :meth:`take` gives the oldest of them, :meth:`take_all` all, oldest first.

    Attributes
    ----------
    received : int
        Payloads taken from the channel (good or bad).
    bad : collections.Counter
        Dropped payloads by reason (the decode error's first words).
    """

    def __init__(self, session: zenoh.Session, key: str, msg_type: type[M], depth: int = 1) -> None:
        self.key = key
        self._decode = Decoder(msg_type)
        # Zenoh keeps the newest ``depth`` samples itself: no Python runs per sample (a 1 kHz stream read at
        # 10 Hz costs a decode per sample only when taken)
        self._sub: zenoh.Subscriber | None = session.declare_subscriber(key, zenoh.handlers.RingChannel(depth))
        self.received = 0
        self._bad = _BadSamples(key)
        self.bad = self._bad.bad

    def take(self) -> M | None:
        """The newest valid message not yet taken, or None (also once closed); never blocks, never raises on bad
        data."""
        sample = None if self._sub is None else self._sub.try_recv()
        return None if sample is None else self._decoded(sample)

    def take_all(self) -> list[M]:
        """Every valid sample held (at most ``depth``, the newest), oldest first; never blocks."""
        out: list[M] = []
        while self._sub is not None and (sample := self._sub.try_recv()) is not None:
            if (msg := self._decoded(sample)) is not None:
                out.append(msg)
        return out

    def _decoded(self, sample) -> M | None:
        """The sample's message, or None (counted in :attr:`bad`)."""
        self.received += 1
        try:
            return _message(self._decode, sample)
        except MessageDecodeError as exc:
            self._bad.count(str(exc))
            return None

    def close(self) -> None:
        if self._sub is not None:
            self._sub.undeclare()
            self._sub = None


def _message(decode: Decoder, sample):
    """The message of ``sample`` (raises MessageDecodeError). The size is checked before the payload is copied
    out (a huge one is never parsed). A payload of the in-process bus (:mod:`runtime.local_bus`) is the
    published message itself, or decoded once for all its readers of one type (``decoded``: the messages are
    frozen); Zenoh's is decoded by each reader."""
    payload = sample.payload
    shared = getattr(payload, "decoded", None)
    if shared is not None:
        return shared(decode)
    decode.check_size(len(payload))
    return decode(payload.to_bytes())


class _BadSamples:
    """Counts dropped payloads by reason and logs at most every few seconds."""

    def __init__(self, key: str) -> None:
        self.key = key
        self.bad: Counter[str] = Counter()
        self._last_log = -float("inf")

    def count(self, reason: str) -> None:
        reason = reason.split(":")[0][:60]
        if reason not in self.bad and len(self.bad) >= MAX_BAD_REASONS:  # a sender cannot grow the status
            reason = "other reasons"
        self.bad[reason] += 1
        now = time.monotonic()
        if now - self._last_log >= BAD_SAMPLE_LOG_PERIOD_S:
            self._last_log = now
            log.warning("dropped a bad sample on %s (%d so far): %s", self.key, sum(self.bad.values()), reason)


class Inbox(Generic[M]):
    """Decoded samples of one key in arrival order (the oldest dropped beyond ``maxlen``); :meth:`get` waits.

    Decoding happens in Zenoh's callback thread; bad payloads are counted in
    :attr:`bad` and dropped there.
    """

    def __init__(self, session: zenoh.Session, key: str, msg_type: type[M], maxlen: int = 64,
                 wake: threading.Event | None = None) -> None:
        self.key = key
        self._decode = Decoder(msg_type)
        self._wake = wake
        self._queue: deque[M] = deque(maxlen=maxlen)
        self._ready = threading.Condition()
        self._bad = _BadSamples(key)
        self.bad = self._bad.bad
        self.received = 0
        self.replaced = 0  #: samples pushed out unread by newer ones (the reader did not keep up)
        self._sub: zenoh.Subscriber | None = session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            msg = _message(self._decode, sample)
        except MessageDecodeError as exc:
            with self._ready:
                self.received += 1
            self._bad.count(str(exc))
            return
        with self._ready:
            self.received += 1
            if len(self._queue) == self._queue.maxlen:
                self.replaced += 1  # the oldest waiting sample goes unread
            self._queue.append(msg)
            self._ready.notify()
        if self._wake is not None:
            self._wake.set()

    def get(self, timeout_s: float) -> M | None:
        """The oldest sample not yet taken, waiting up to ``timeout_s``; None on timeout."""
        with self._ready:
            if not self._queue:
                # a poll (timeout 0, every cycle of a 1 kHz loop) must not pay for a waiter: ~1 us, not 3
                if timeout_s <= 0.0 or not self._ready.wait_for(lambda: bool(self._queue), timeout_s):
                    return None
            return self._queue.popleft()

    def close(self) -> None:
        if self._sub is not None:
            self._sub.undeclare()
            self._sub = None


#: Zenoh publisher options of the 1 kHz control path: at once, first, never queued behind a congested link.
CONTROL_QOS: dict[str, Any] = {"express": True, "priority": zenoh.Priority.REAL_TIME,
               "congestion_control": zenoh.CongestionControl.DROP}


def publisher_qos(keys: Keys, key: str) -> dict:
    """Zenoh ``declare_publisher`` options for ``key`` of the cell (see the module docstring); {} by default."""
    if key in (keys.robot_state, keys.robot_command):
        return CONTROL_QOS
    if key in (keys.controller_estop, keys.controller_estop_release):
        return {"express": True, "priority": zenoh.Priority.REAL_TIME,
                "congestion_control": zenoh.CongestionControl.BLOCK}
    if zenoh.KeyExpr(keys.camera_frames).intersects(zenoh.KeyExpr(key)):
        return {"priority": zenoh.Priority.DATA_LOW}
    return {}


class ServiceNode:
    """A service's presence on the network: session, liveliness token, publishers, newest-sample readers.

    Use as ``with ServiceNode("sim", settings) as node: ...``.
    """

    def __init__(self, service: str, settings: ZenohSettings, max_message_bytes: int | None = None) -> None:
        self.service = service
        self.settings = settings
        self.max_message_bytes = max_message_bytes  # None: the cell's (interfaces.message_limits)
        self.keys: Keys = settings.keys
        self._session: zenoh.Session | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._readers: list[Latest | Inbox] = []
        #: how this node joined, carried by every status it publishes (:mod:`runtime.service_security`)
        self.security = ""

    def __enter__(self) -> ServiceNode:
        from .service_security import security_summary

        zenoh.try_init_log_from_env()  # RUST_LOG (e.g. zenoh=info) shows Zenoh's own log on stderr; unset: quiet
        self.security = security_summary(self.settings)
        if self.security.startswith("INSECURE"):
            log.warning("%s: %s (--insecure); every status says so", self.service, self.security)
        self._session = zenoh.open(zenoh_config(self.settings, self.max_message_bytes))
        self._token = self._session.liveliness().declare_token(self.keys.alive(self.service))
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def session(self) -> zenoh.Session:
        if self._session is None:
            raise RuntimeError(f"ServiceNode {self.service!r} is not open (use it as a context manager)")
        return self._session

    def publish(self, key: str, msg: Message) -> None:
        """Encode and put ``msg`` on ``key`` (publisher declared on first use with the key's QoS, then reused).
        A status (:class:`ServiceStatus`, :class:`ControllerStatus`) goes out saying how this node joined."""
        msg = self._with_security(msg)
        pub = self._publishers.get(key)
        if pub is None:
            pub = self._publishers[key] = self.session.declare_publisher(key, **publisher_qos(self.keys, key))
        pub.put(encode(msg))

    def _with_security(self, msg: Message) -> Message:
        if isinstance(msg, (ServiceStatus, ControllerStatus)) and not msg.security:
            return msgspec.structs.replace(msg, security=self.security)
        return msg

    def latest(self, key: str, msg_type: type[M], depth: int = 1) -> Latest[M]:
        """A newest-sample reader of ``key`` decoding ``msg_type`` (``depth``: the newest samples kept, for
        :meth:`Latest.take_all`)."""
        reader = Latest(self.session, key, msg_type, depth)
        self._readers.append(reader)
        return reader

    def inbox(self, key: str, msg_type: type[M], maxlen: int = 64, wake: threading.Event | None = None) -> Inbox[M]:
        """An in-order reader of ``key`` that can wait for the next sample (and sets ``wake`` on each one)."""
        reader = Inbox(self.session, key, msg_type, maxlen, wake)
        self._readers.append(reader)
        return reader

    def alive_services(self, timeout_s: float = 1.0) -> set[str]:
        """Names of the services whose liveliness tokens are visible now."""
        prefix = self.keys.alive("x")[:-1]
        replies = self.session.liveliness().get(self.keys.alive_any, timeout=timeout_s)
        return {str(r.ok.key_expr)[len(prefix):] for r in replies if r.ok is not None}

    def close(self) -> None:
        if self._session is None:
            return
        for reader in self._readers:
            reader.close()
        for pub in self._publishers.values():
            pub.undeclare()
        if self._token is not None:
            self._token.undeclare()
        self._session.close()
        self._session = None
