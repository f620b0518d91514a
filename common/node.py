"""What every service process does around its own work: connect, announce, report, stop cleanly.

``run_node`` opens the session, holds the liveliness token ``<prefix>/alive/<service>/<instance>``,
publishes ``ServiceHealth`` once per ``health_period_s`` (with the bus's per-key counters), turns
SIGINT/SIGTERM into ``node.stop`` and closes everything on the way out.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import threading
import time
from collections.abc import Callable
from types import FrameType
from typing import Any, Generic, TypeVar

from common import keys
from common.bus import Bus, BusUnreachable, open_session
from common.errors import StartupError
from common.messages import HealthStatus, ServiceHealth, text
from common.realtime import use_realtime_priority
from common.settings import ServiceSettings

log = logging.getLogger(__name__)

EXIT_OK = 0
EXIT_UNREACHABLE = 3
EXIT_STARTUP = 4


S = TypeVar("S", bound=ServiceSettings)


class Node(Generic[S]):
    """A running service as its own code sees it: its settings, the bus, a stop event and a
    status."""

    def __init__(self, service: str, settings: S, bus: Bus) -> None:
        self.service = service
        self.settings = settings
        self.bus = bus
        self.stop = threading.Event()
        self.started_s = time.time()
        self._status: tuple[HealthStatus, str] = ("ok", "")

    def set_status(self, status: HealthStatus, detail: str = "") -> None:
        """``ok`` or ``degraded`` (with a reason); shows in the published health."""
        if (status, detail) != self._status:
            log.info("status %s%s", status, f": {detail}" if detail else "")
        self._status = (status, detail)

    def health(self) -> ServiceHealth:
        status, detail = self._status
        if self.stop.is_set():
            status, detail = "stopping", ""
        return ServiceHealth(
            measured_s=time.time(), service=self.service, instance=self.settings.instance,
            host=socket.gethostname()[:255], pid=os.getpid(), started_s=self.started_s,
            status=status, detail=text(detail), keys=self.bus.key_stats())

    def publish_health(self) -> None:
        self.bus.publish(keys.HEALTH, self.health(), service=self.service,
                         instance=self.settings.instance)


class LogBudget(logging.Filter):
    """At most ``burst`` lines at once and ``per_s`` a second after that, whatever logs them (a
    flood of requests that each log a line cannot fill a disk); errors and above always pass.
    What it held back is counted in the next line that passes."""

    def __init__(self, per_s: float = 20.0, burst: float = 200.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self.per_s, self.burst, self.clock = per_s, burst, clock
        self.tokens, self.at, self.held_back = burst, clock(), 0
        self.lock = threading.Lock()

    def filter(self, record: logging.LogRecord) -> bool:
        with self.lock:
            now = self.clock()
            self.tokens = min(self.burst, self.tokens + (now - self.at) * self.per_s)
            self.at = now
            if self.tokens < 1 and record.levelno < logging.ERROR:
                self.held_back += 1
                return False
            self.tokens = max(self.tokens - 1, 0.0)
            held, self.held_back = self.held_back, 0
        if held:
            record.msg = f"[{held} log lines held back before this one] {record.msg}"
        return True


def configure_logging(level: str) -> None:
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    for handler in logging.getLogger().handlers:
        handler.addFilter(LogBudget())
    for chatty in ("httpx", "httpcore", "pymodbus", "qtm_rt"):  # one line per request/frame
        logging.getLogger(chatty).setLevel(max(logging.WARNING, logging.getLogger().level))


def run_node(service: str, settings: ServiceSettings, body: Callable[[Node[Any]], None]) -> int:
    """Run ``body(node)`` as service ``service`` until it returns or a signal stops it.

    ``body`` must return soon after ``node.stop`` is set. Returns the process exit code.
    """
    use_realtime_priority(settings.realtime_priority)  # before Zenoh's threads: they inherit it
    opening = time.monotonic()
    try:
        session = open_session(settings.zenoh_settings())
    except BusUnreachable as err:
        log.error("%s", err)
        return EXIT_UNREACHABLE
    bus = Bus(session, settings.bus)
    node = Node(service, settings, bus)
    restore = stop_on_signals(node.stop)
    health = threading.Thread(target=_health_loop, args=(node,), name="health", daemon=True)
    try:
        bus.declare_alive(service, settings.instance)
        health.start()
        log.info("%s/%s running (prefix %s; the bus took %.2f s)", service, settings.instance,
                 bus.prefix, time.monotonic() - opening)
        body(node)
    except StartupError as err:
        log.error("%s/%s cannot start: %s", service, settings.instance, err)
        return EXIT_STARTUP
    finally:
        node.stop.set()
        health.join(timeout=2)
        _try(node.publish_health)
        bus.close()
        session.close()
        restore()
        log.info("%s/%s stopped", service, settings.instance)
    return EXIT_OK


def _health_loop(node: Node[Any]) -> None:
    while not node.stop.wait(node.settings.bus.health_period_s):
        _try(node.publish_health)


def _try(action: Callable[[], None]) -> None:
    try:
        action()
    except Exception:  # noqa: BLE001 - health reporting must never kill the service
        log.debug("health publication failed", exc_info=True)


def stop_on_signals(stop: threading.Event) -> Callable[[], None]:
    """Set ``stop`` on SIGINT/SIGTERM (main thread only); returns a function that undoes it."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def handler(signum: int, _frame: FrameType | None) -> None:
        log.info("received %s, stopping", signal.Signals(signum).name)
        stop.set()

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}

    def restore() -> None:
        for signum, old in previous.items():
            signal.signal(signum, old)

    return restore


def run_every(period_s: float, stop: threading.Event, action: Callable[[], None],
              what: str = "periodic task") -> None:
    """Call ``action`` every ``period_s`` (no drift) until ``stop``; an exception is logged
    and the next tick comes anyway — one bad tick must not end a stream or a control loop."""
    run_scheduled(lambda at: at + period_s, stop, action, what)


def run_scheduled(next_at: Callable[[float], float], stop: threading.Event,
                  action: Callable[[], None], what: str = "periodic task") -> None:
    """Call ``action``, then again at ``next_at(when it was due)`` (monotonic seconds), until
    ``stop``; an exception is logged and the next call comes anyway."""
    due = time.monotonic()
    while not stop.is_set():
        try:
            action()
        except Exception:  # noqa: BLE001
            log.exception("%s failed", what)
        due = next_at(due)
        stop.wait(max(0.0, due - time.monotonic()))
