"""Thin Zenoh helpers: open a session from settings, publish and subscribe typed messages.

Every payload is checked here, once, for all services: a sample that is too large, not msgpack,
of the wrong shape, non-finite, or (on streams) older than ``max_age_s`` is counted per key,
logged at a bounded rate and dropped; it never reaches a handler. Stream subscribers get the
newest sample per key (a slow handler never holds back a producer and never sees a backlog).
"""

from __future__ import annotations

import contextlib
import json
import logging
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

import zenoh

from common import codec
from common.keys import Topic, alive_key, topic_for
from common.messages import KeyStats, Message
from common.settings import BusSettings, ZenohSettings

log = logging.getLogger(__name__)
M = TypeVar("M", bound=Message)

HANDLER_ERROR = "handler_error"
QUEUE_FULL = "queue_full"
SUPERSEDED = "superseded"  # a newer sample of the same key came before the handler was free
MAX_QUEUED_KEYS = 256
"""Keys with samples waiting in one ``per_key`` subscription at most."""


class BusUnreachable(ConnectionError):
    """No router (or peer) could be reached with the configured endpoints and credentials."""


def zenoh_config(z: ZenohSettings) -> zenoh.Config:
    """A zenoh.Config from our settings; the optional raw config file is applied first."""
    cfg = zenoh.Config.from_file(str(z.config_file)) if z.config_file else zenoh.Config()

    def put(path: str, value: Any) -> None:
        cfg.insert_json5(path, json.dumps(value))

    put("mode", z.mode)
    if z.connect:
        put("connect/endpoints", z.connect)
    if z.listen:
        put("listen/endpoints", z.listen)
    put("scouting/multicast/enabled", z.multicast_scouting)
    put("transport/shared_memory/transport_optimization/pool_size",
        int(z.shm_pool_mib * 1024 * 1024))
    put("transport/link/tx/lease", z.lease_ms)
    put("connect/retry", {"period_init_ms": z.retry_init_ms, "period_max_ms": z.retry_max_ms,
                          "period_increase_factor": 2})
    if z.mode == "client":
        put("connect/timeout_ms", z.connect_timeout_ms)
    usrpwd: dict[str, str] = {}
    if z.user is not None:
        usrpwd["user"] = z.user
    secret = z.secret()
    if secret is not None:
        usrpwd["password"] = secret
    if z.users_file is not None:
        usrpwd["dictionary_file"] = str(z.users_file)
    if usrpwd:
        put("transport/auth/usrpwd", usrpwd)
    tls = _tls_config(z)
    if tls:
        put("transport/link/tls", tls)
    return cfg


def _tls_config(z: ZenohSettings) -> dict[str, Any]:
    t = z.tls
    out: dict[str, Any] = {}
    if t.root_ca_certificate:
        out["root_ca_certificate"] = str(t.root_ca_certificate)
    side = "listen" if z.mode == "router" else "connect"
    if t.certificate:
        out[f"{side}_certificate"] = str(t.certificate)
    if t.private_key:
        out[f"{side}_private_key"] = str(t.private_key)
    if out:
        out["enable_mtls"] = t.enable_mtls
        out["verify_name_on_connect"] = t.verify_name_on_connect
    return out


SEND_LINGER_S = 0.5
"""Zenoh's session has no flush: what was put just before it closes may still be queued, and
is lost with it. A client that put 32 pictures of 60 kB and closed at once lost the last ones
in 6 of 20 runs on an idle machine (4 of 20 beside two busy cores); closed 0.2 s after its
last put, in none of 60 beside two busy cores. A tool that ends after putting waits for the
rest of this since its last put (``linger``)."""


def linger(last_put_s: float | None, clock: Callable[[], float] = time.monotonic) -> None:
    """Before a session that put something closes: until ``SEND_LINGER_S`` after the last put
    (``clock``'s time; None: nothing was put, no wait)."""
    if last_put_s is not None:
        time.sleep(max(0.0, last_put_s + SEND_LINGER_S - clock()))  # no flush to wait for


def open_session(z: ZenohSettings) -> zenoh.Session:
    """Open a Zenoh session; BusUnreachable (with the endpoints) if that fails."""
    try:
        return zenoh.open(zenoh_config(z))
    except zenoh.ZError as err:
        where = ", ".join(z.listen if z.mode == "router" else z.connect) or "(no endpoint)"
        raise BusUnreachable(f"cannot open a Zenoh {z.mode} session on {where}: {err}") from err


def declare_publisher(session: zenoh.Session, key: str, model: type) -> zenoh.Publisher:
    """A publisher as the bus declares one: the message's encoding named, and samples dropped,
    never blocking the sender, when the link is congested."""
    return session.declare_publisher(
        key, encoding=zenoh.Encoding(f"{codec.CONTENT_TYPE};{model.__name__}"),
        congestion_control=zenoh.CongestionControl.DROP)


OTHER_KEYS = "(other keys)"
"""Where the counts and log lines of keys beyond ``MAX_KEYS`` go: a flood of distinct keys
(4,000 garbage keys grew a health message to 131 KB, past the bus's limit) stays bounded."""
MAX_KEYS = 64


class _RateLimitedLog:
    """Logs the first event of a kind at once, then at most one summary per ``period_s``; at
    most ``MAX_KEYS`` keys have their own, the rest share one."""

    def __init__(self, period_s: float = 10.0) -> None:
        self._period_s = period_s
        self._last: dict[tuple[str, str], tuple[float, int]] = {}
        self._lock = threading.Lock()

    def warning(self, key: str, reason: str, detail: str, *, exc_info: bool = False) -> None:
        now = time.monotonic()
        with self._lock:
            if (key, reason) not in self._last and len(self._last) >= MAX_KEYS:
                key = OTHER_KEYS
            last, suppressed = self._last.get((key, reason), (-1e18, 0))
            if now - last < self._period_s:
                self._last[(key, reason)] = (last, suppressed + 1)
                return
            self._last[(key, reason)] = (now, 0)
        more = f" (+{suppressed} more since last report)" if suppressed else ""
        log.warning("dropped sample on %s: %s%s", key, detail, more, exc_info=exc_info)


@dataclass
class _Stats:
    received: int = 0
    published: int = 0
    dropped: dict[str, int] = field(default_factory=dict)

    @property
    def total(self) -> int:
        return self.received + self.published + sum(self.dropped.values())

    def merge(self, other: _Stats) -> None:
        self.received += other.received
        self.published += other.published
        for reason, n in other.dropped.items():
            self.dropped[reason] = self.dropped.get(reason, 0) + n


def _stats_of(table: dict[str, _Stats], key: str) -> _Stats:
    """``key``'s counters; when ``MAX_KEYS`` keys are kept already, the least busy of them
    is summed into ``OTHER_KEYS`` to make room (the busiest keep their own)."""
    stats = table.get(key)
    if stats is not None:
        return stats
    named = [k for k in table if k != OTHER_KEYS]
    if len(named) >= MAX_KEYS:
        quietest = min(named, key=lambda k: table[k].total)
        table.setdefault(OTHER_KEYS, _Stats()).merge(table.pop(quietest))
    return table.setdefault(key, _Stats())


class Subscription:
    """Samples of one key expression, checked by ``accept`` and handed to ``handler`` on a
    worker thread of their own, so a slow handler never blocks Zenoh or other subscriptions.

    Queued (not ``latest``) samples are kept in arrival order, at most ``queue_size``; with
    ``per_key`` each key has a queue of its own of that size and the keys take turns, so that
    a flood on one key (one sender's commands) can neither push another key's samples out nor
    hold them back (at most ``MAX_QUEUED_KEYS`` keys wait at once)."""

    def __init__(self, bus: Bus, key_expr: str, accept: Callable[[str, bytes], Any | None],
                 handler: Callable[[Any], None], *, latest: bool, queue_size: int,
                 per_key: bool = False) -> None:
        self._bus, self._accept, self._handler, self._latest = bus, accept, handler, latest
        self._pending: dict[str, bytes] = {}
        self._queue_size, self._per_key = queue_size, per_key
        self._queues: OrderedDict[str, deque[tuple[str, bytes]]] = OrderedDict()
        self._wake = threading.Condition()
        self._closed = False
        self._worker = threading.Thread(target=self._run, name=f"sub:{key_expr}", daemon=True)
        self._worker.start()
        self._zsub = bus.session.declare_subscriber(
            key_expr, zenoh.handlers.Callback(self._on_sample, indirect=False))

    def _on_sample(self, sample: zenoh.Sample) -> None:
        # Runs on Zenoh's network thread: store and return, nothing else.
        key, payload = str(sample.key_expr), sample.payload.to_bytes()
        self._bus.count_received(key)
        with self._wake:
            if self._latest:
                if self._pending.pop(key, None) is not None:  # re-inserted: oldest key first
                    self._bus.count_drop(key, SUPERSEDED, "", log_it=False)
                self._pending[key] = payload
            else:
                self._enqueue(key, payload)
            self._wake.notify()

    def _enqueue(self, key: str, payload: bytes) -> None:
        turn = key if self._per_key else ""
        queue = self._queues.get(turn)
        if queue is None:
            if len(self._queues) >= MAX_QUEUED_KEYS:
                self._bus.count_drop(key, QUEUE_FULL, "too many keys waiting: dropped")
                return
            queue = self._queues[turn] = deque(maxlen=self._queue_size)
        if len(queue) == queue.maxlen:
            self._bus.count_drop(key, QUEUE_FULL, "subscriber queue full, oldest dropped")
        queue.append((key, payload))

    def _next(self) -> tuple[str, bytes] | None:
        with self._wake:
            while not self._closed and not self._pending and not self._queues:
                self._wake.wait()
            if self._closed:
                return None
            if self._latest:
                key = next(iter(self._pending))
                return key, self._pending.pop(key)
            turn, queue = next(iter(self._queues.items()))
            item = queue.popleft()
            if queue:
                self._queues.move_to_end(turn)  # the next key's turn
            else:
                del self._queues[turn]
            return item

    def _run(self) -> None:
        while (item := self._next()) is not None:
            msg = self._accept(*item)
            if msg is None:
                continue
            try:
                self._handler(msg)
            except Exception:  # noqa: BLE001 - a handler bug must not stop the subscription
                self._bus.count_drop(item[0], HANDLER_ERROR, "handler raised", exc_info=True)

    def close(self) -> None:
        with self._wake:
            self._closed = True
            self._wake.notify_all()
        with contextlib.suppress(zenoh.ZError):  # session already closed
            self._zsub.undeclare()


class Bus:
    """A Zenoh session with our keys, codec, input checks and per-key statistics."""

    def __init__(self, session: zenoh.Session, settings: BusSettings,
                 clock: Callable[[], float] = time.time) -> None:
        self.session = session
        self.settings = settings
        self.prefix = settings.prefix
        self._clock = clock
        self._stats: dict[str, _Stats] = {}
        self._stats_lock = threading.Lock()
        self._publishers: dict[str, zenoh.Publisher] = {}
        # A publisher is put to by the threads that publish and undeclared by close: Zenoh
        # refuses both at once ("Already borrowed"), so they take turns (a put is microseconds)
        self._publishing = threading.Lock()
        self._closed = False
        self._subscriptions: list[Subscription] = []
        self._declared: list[Any] = []
        self._log = _RateLimitedLog()

    # --- publishing -------------------------------------------------------------------------

    def publish(self, topic: Topic[M], msg: M, *, max_age_s: float | None = None,
                **params: str) -> bool:
        """Stamp ``sent_s`` and put ``msg`` on the topic's key (drop, never block, if congested).

        With ``max_age_s``, a message measured longer than that before its ``sent_s`` stamp is
        not sent but counted as stale (the age is judged at the stamp receivers judge it by).
        True if it was put."""
        if not isinstance(msg, topic.model):
            raise TypeError(
                f"{topic.path} carries {topic.model.__name__}, not {type(msg).__name__}")
        key = topic.key(self.prefix, **params)
        sent_s = self._clock()
        if max_age_s is not None and sent_s - msg.measured_s > max_age_s:
            self.count_drop(key, codec.STALE, f"measured {sent_s - msg.measured_s:.3f} s "
                            f"before sending > {max_age_s} s: not sent")
            return False
        payload = codec.encode(msg, sent_s=sent_s)
        with self._publishing:
            if self._closed:
                return False
            publisher = self._publishers.get(key)
            if publisher is None:
                publisher = declare_publisher(self.session, key, topic.model)
                self._publishers[key] = publisher
            publisher.put(payload)
        with self._stats_lock:
            _stats_of(self._stats, key).published += 1
        return True

    # --- subscribing ------------------------------------------------------------------------

    def subscribe(self, topic: Topic[M], handler: Callable[[M], None], *,
                  latest: bool | None = None, max_age_s: float | None = None,
                  queue_size: int = 1000, **params: str) -> Subscription:
        """Call ``handler(msg)`` for every valid sample; parameters left out match any value.

        ``latest`` (default: the topic is a stream) delivers only the newest sample per key and
        drops samples older than ``max_age_s`` (default: the bus setting). Otherwise samples
        are queued in order, at most ``queue_size``, and never dropped for age.
        """
        latest = topic.stream if latest is None else latest
        if latest and max_age_s is None:
            max_age_s = self.settings.max_age_s
        return self._add_subscription(
            topic.pattern(self.prefix, **params),
            lambda key, payload: self.accept(topic, key, payload, max_age_s=max_age_s),
            handler, latest=latest, queue_size=queue_size)

    def subscribe_keyed(self, topic: Topic[M], handler: Callable[[dict[str, str], M], None], *,
                        queue_size: int = 1000) -> Subscription:
        """Call ``handler(params, msg)`` for every valid sample, in order per key, ``params``
        the key's parameters (who sent it, where the key names the sender: the router's access
        control lets each identity put only on its own key). Each key has a queue of its own
        and the keys take turns: a flood from one sender neither drops nor delays another's."""
        def accept(key: str, payload: bytes) -> tuple[dict[str, str], M] | None:
            params = topic.match(self.prefix, key)
            msg = self.accept(topic, key, payload)
            return None if msg is None or params is None else (params, msg)

        sub = Subscription(self, topic.pattern(self.prefix), accept,
                           lambda item: handler(*item), latest=False, queue_size=queue_size,
                           per_key=True)
        self._subscriptions.append(sub)
        return sub

    def subscribe_any(self, key_expr: str,
                      handler: Callable[[tuple[str, Message | dict[str, Any]]], None],
                      *, latest: bool = False, queue_size: int = 1000) -> Subscription:
        """Every valid sample under ``key_expr`` as ``(key, message)``, for generic tools.

        Keys of our topics are decoded with their model (invalid ones are counted and dropped);
        other keys are handed over as plain dicts if they are msgpack maps.
        """
        def accept(key: str, payload: bytes) -> tuple[str, Message | dict[str, Any]] | None:
            topic = topic_for(self.prefix, key)
            if topic is not None:
                msg = self.accept(topic, key, payload)
                return None if msg is None else (key, msg)
            try:
                return key, codec.unpack(payload, max_bytes=codec.DEFAULT_MAX_BYTES)
            except codec.DecodeError as err:
                self.count_drop(key, err.reason, str(err))
                return None

        return self._add_subscription(key_expr, accept, handler, latest=latest,
                                      queue_size=queue_size)

    def _add_subscription(self, key_expr: str, accept: Callable[[str, bytes], Any | None],
                          handler: Callable[[Any], None], *, latest: bool,
                          queue_size: int) -> Subscription:
        sub = Subscription(self, key_expr, accept, handler, latest=latest, queue_size=queue_size)
        self._subscriptions.append(sub)
        return sub

    def accept(self, topic: Topic[M], key: str, payload: bytes,
               *, max_age_s: float | None = None) -> M | None:
        """Decode and check one received payload; None (and counted) if it was dropped."""
        try:
            msg = codec.decode(topic.model, payload, max_bytes=topic.max_payload_bytes)
        except codec.DecodeError as err:
            self.count_drop(key, err.reason, str(err))
            return None
        if max_age_s is not None:
            age = self._clock() - msg.sent_s
            if age > max_age_s:
                self.count_drop(key, codec.STALE, f"stale: sent {age:.3f} s ago > {max_age_s} s")
                return None
            if -age > self.settings.max_future_s:
                self.count_drop(key, codec.FROM_FUTURE, f"sent {-age:.3f} s in the future "
                                "(clock skew between hosts?)")
                return None
        return msg

    def count_received(self, key: str) -> None:
        with self._stats_lock:
            _stats_of(self._stats, key).received += 1

    def count_drop(self, key: str, reason: str, detail: str, *, exc_info: bool = False,
                   log_it: bool = True) -> None:
        with self._stats_lock:
            dropped = _stats_of(self._stats, key).dropped
            dropped[reason] = dropped.get(reason, 0) + 1
        if log_it:
            self._log.warning(key, reason, detail, exc_info=exc_info)

    # --- latest-value queries and liveliness ------------------------------------------------

    def serve_latest(self, topic: Topic[M], latest: Callable[[], M | None], **params: str) -> None:
        """Answer queries on the topic's key with ``latest()`` (for late joiners)."""
        key = topic.key(self.prefix, **params)

        def reply(query: zenoh.Query) -> None:
            msg = latest()
            if msg is not None:
                query.reply(key, codec.encode(msg, sent_s=self._clock()),
                            encoding=zenoh.Encoding(codec.CONTENT_TYPE))

        self._declared.append(self.session.declare_queryable(key, reply))

    def query_latest(self, topic: Topic[M], timeout_s: float = 2.0, *, every_answer: bool = False,
                     **params: str) -> list[M]:
        """Ask every queryable of the topic for its latest value; invalid replies are dropped.
        ``every_answer``: all replies, also several on one key (Zenoh keeps the latest of them
        by default), to see whether two queryables answer one key."""
        consolidation = zenoh.ConsolidationMode.NONE if every_answer else None
        out: list[M] = []
        for reply in self.session.get(topic.pattern(self.prefix, **params), timeout=timeout_s,
                                      consolidation=consolidation):
            if reply.ok is not None:
                key = str(reply.ok.key_expr)
                self.count_received(key)
                msg = self.accept(topic, key, reply.ok.payload.to_bytes())
                if msg is not None:
                    out.append(msg)
        return out

    def declare_alive(self, service: str, instance: str) -> None:
        """Hold the liveliness token ``<prefix>/alive/<service>/<instance>`` until close()."""
        token = self.session.liveliness().declare_token(alive_key(self.prefix, service, instance))
        self._declared.append(token)

    # --- health and shutdown ----------------------------------------------------------------

    def key_stats(self) -> dict[str, KeyStats]:
        with self._stats_lock:
            return {k: KeyStats(received=s.received, published=s.published, dropped=dict(s.dropped))
                    for k, s in self._stats.items()}

    def close(self) -> None:
        """Undeclare everything this bus declared (the session stays open)."""
        for sub in self._subscriptions:
            sub.close()
        with self._publishing:
            self._closed = True  # a publish from a thread still running is not sent
            for entity in [*self._declared, *self._publishers.values()]:
                with contextlib.suppress(zenoh.ZError):  # session already closed
                    entity.undeclare()
            self._subscriptions.clear()
            self._declared.clear()
            self._publishers.clear()
