"""The supervisor behind ``stb up`` (services/up_cli.py has the command): each service a
process of its own, restarted with back-off when it dies; the live table or log lines."""

from __future__ import annotations

import logging
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import zenoh
from pydantic import Field, field_validator

from common import keys
from common.backoff import doubled
from common.bus import SUPERSEDED, Bus, BusUnreachable, open_session
from common.messages import ServiceHealth
from common.settings import ServiceSettings
from services.registry import DEFAULT_UP, SERVICES

log = logging.getLogger(__name__)


class UpSettings(ServiceSettings):
    section = "up"

    services: list[str] = Field(
        default_factory=lambda: list(DEFAULT_UP),
        description="'name' or 'name:instance'; include 'router' for the embedded router")
    log_dir: Path = Path("run/logs")
    restart_initial_s: float = Field(0.2, gt=0)
    restart_max_s: float = Field(10.0, gt=0)
    stable_after_s: float = Field(10.0, gt=0)
    stop_timeout_s: float = Field(5.0, gt=0)

    @field_validator("services")
    @classmethod
    def _known(cls, specs: list[str]) -> list[str]:
        for spec in specs:
            if spec.partition(":")[0] not in SERVICES:
                raise ValueError(f"unknown service {spec!r}; known: {', '.join(SERVICES)}")
        return specs


def next_delay(previous_s: float | None, ran_for_s: float, settings: UpSettings) -> float:
    """Restart delay after a process that ran ``ran_for_s`` exited (pure)."""
    if previous_s is None or ran_for_s >= settings.stable_after_s:
        return settings.restart_initial_s
    return doubled(previous_s, settings.restart_max_s)


@dataclass
class Child:
    service: str
    instance: str
    process: subprocess.Popen | None = None
    started_at: float = 0.0
    restart_at: float | None = 0.0
    delay_s: float | None = None
    restarts: int = 0
    last_exit: int | None = None
    alive: bool = False
    health: str = ""  # as shown: status, detail, drops
    status: str = ""  # ok, degraded, stopping: a change of it is worth reporting
    log_file: BinaryIO | None = field(default=None, repr=False)

    @property
    def name(self) -> str:
        return f"{self.service}/{self.instance}"

    def close_log(self) -> None:
        if self.log_file is not None:
            self.log_file.close()
            self.log_file = None


class Supervisor:
    def __init__(self, settings: UpSettings, lab: Path | None, page_url: str | None = None
                 ) -> None:
        """``page_url``: where the web service's page is, when it is one of the services."""
        self.settings = settings
        self.lab = lab
        self.page_url = page_url
        self.children = [Child(*_split(spec)) for spec in settings.services]
        # The router goes first and stops last.
        self.children.sort(key=lambda c: c.service != "router")
        self._lock = threading.Lock()

    def argv(self, child: Child) -> list[str]:
        argv = [sys.executable, "-m", f"services.{child.service}", "--instance", child.instance]
        return argv + (["--lab", str(self.lab)] if self.lab else [])

    def poll(self, now: float) -> None:
        """Start what is due, notice what has exited; call every few tens of ms."""
        for child in self.children:
            if child.process is not None and child.process.poll() is not None:
                self._exited(child, now)
            if child.process is None and child.restart_at is not None and now >= child.restart_at:
                self._start(child, now)

    def _start(self, child: Child, now: float) -> None:
        self.settings.log_dir.mkdir(parents=True, exist_ok=True)
        path = self.settings.log_dir / f"{child.service}-{child.instance}.log"
        log_file = child.log_file = open(path, "ab")  # noqa: SIM115 - open while it runs
        child.process = subprocess.Popen(self.argv(child), stdout=log_file,
                                         stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        child.started_at, child.restart_at = now, None
        log.info("started %s (pid %d), log %s", child.name, child.process.pid, path)

    def _exited(self, child: Child, now: float) -> None:
        assert child.process is not None
        child.last_exit = child.process.returncode
        child.process = None
        child.close_log()
        child.delay_s = next_delay(child.delay_s, now - child.started_at, self.settings)
        child.restart_at = now + child.delay_s
        child.restarts += 1
        log.warning("%s exited with %s; restarting in %.1f s", child.name, child.last_exit,
                    child.delay_s)

    def stop_all(self) -> None:
        """SIGTERM the services, then the router; SIGKILL what is still there after the timeout."""
        for group in ([c for c in self.children if c.service != "router"],
                      [c for c in self.children if c.service == "router"]):
            running = [(c, c.process) for c in group if c.process is not None]
            for child, process in running:
                child.restart_at = None
                process.send_signal(signal.SIGTERM)
            for child, process in running:
                try:
                    process.wait(self.settings.stop_timeout_s)
                except subprocess.TimeoutExpired:
                    log.warning("%s did not stop in time, killing it", child.name)
                    process.kill()
                    process.wait()
                child.close_log()
                child.process = None

    def set_alive(self, service: str, instance: str, alive: bool) -> None:
        with self._lock:
            for child in self.children:
                if (child.service, child.instance) == (service, instance):
                    child.alive = alive

    def state(self) -> tuple:
        """What changes when something worth reporting happens (a service's health too)."""
        return tuple((c.name, c.process is not None and c.process.pid, c.alive, c.restarts,
                      c.status) for c in self.children)

    def page(self) -> str:
        """Where the operator's page is, once the web service is up."""
        web = [c for c in self.children if c.service == "web"]
        if not web or self.page_url is None:
            return ""
        if any(c.alive for c in web):
            return f"the page: {self.page_url}"
        return "the page: waiting for the web service"

    def set_health(self, health: ServiceHealth) -> None:
        # "superseded" is latest-value delivery doing its job, not bad input.
        dropped = sum(n for k in health.keys.values() for reason, n in k.dropped.items()
                      if reason != SUPERSEDED)
        text = health.status + (f" ({health.detail})" if health.detail else "")
        text += f", {dropped} dropped" if dropped else ""
        with self._lock:
            for child in self.children:
                if (child.service, child.instance) == (health.service, health.instance):
                    child.health, child.status = text, health.status

    def render(self, now: float) -> str:
        lines = [f"{'service':<24} {'pid':>7}  {'state':<22} {'restarts':>8}  {'last exit':>9}"
                 "  health"]
        for c in self.children:
            if c.process is None:
                wait = max(0.0, (c.restart_at or now) - now)
                state = "stopped" if c.restart_at is None else f"restarting in {wait:.1f} s"
            else:
                state = "alive" if c.alive else "starting"
            pid = str(c.process.pid) if c.process else "-"
            exit_code = "-" if c.last_exit is None else str(c.last_exit)
            health = (c.health if c.process else "")[:60]
            lines.append(f"{c.name:<24} {pid:>7}  {state:<22} {c.restarts:>8}  {exit_code:>9}"
                         f"  {health}")
        return "\n".join(lines)


def _split(spec: str) -> tuple[str, str]:
    service, _, instance = spec.partition(":")
    return service, instance or "main"


def watch_alive(supervisor: Supervisor, settings: UpSettings, stop: threading.Event) -> None:
    """Follow liveliness tokens and health (retrying until the router is up) until ``stop``."""
    session = None
    while session is None and not stop.is_set():
        try:
            session = open_session(settings.zenoh_settings())
        except BusUnreachable:
            stop.wait(0.5)
    if session is None:
        return
    prefix = settings.bus.prefix

    def on_token(sample: zenoh.Sample) -> None:
        parsed = keys.parse_alive(prefix, str(sample.key_expr))
        if parsed:
            supervisor.set_alive(*parsed, alive=sample.kind == zenoh.SampleKind.PUT)

    bus = Bus(session, settings.bus)
    try:
        session.liveliness().declare_subscriber(keys.alive_pattern(prefix), on_token, history=True)
        bus.subscribe(keys.HEALTH, supervisor.set_health, latest=True, max_age_s=5.0)
        stop.wait()
    finally:
        bus.close()
        session.close()


def runs_web(settings: UpSettings) -> bool:
    return any(_split(spec)[0] == "web" for spec in settings.services)


def page_url(host: str, port: int) -> str:
    """The web page's address from ``[web] host`` and ``port``."""
    host = socket.gethostname() if host in ("0.0.0.0", "::") else host
    return f"http://{host}:{port}/"


def run(settings: UpSettings, lab: Path | None, stop: threading.Event, *, view: bool,
        page: str | None = None) -> int:
    supervisor = Supervisor(settings, lab, page)
    watcher = threading.Thread(target=watch_alive, args=(supervisor, settings, stop), daemon=True)
    watcher.start()
    last_view, last_state, last_page = 0.0, None, ""
    try:
        while not stop.wait(0.05):
            now = time.monotonic()
            supervisor.poll(now)
            page = supervisor.page()
            changed = supervisor.state() != last_state
            if view and (now - last_view >= 1.0 or (changed and now - last_view >= 0.2)):
                last_state = supervisor.state()
                header = "stb up — " + (f"{page} — " if page else "") + "Ctrl-C stops everything"
                print("\x1b[H\x1b[2J" + header + "\n\n" + supervisor.render(now), flush=True)
                last_view = now
            elif not view and changed:
                last_state = supervisor.state()
                log.info("status\n%s", supervisor.render(now))
            if not view and page != last_page and page.startswith("the page: http"):
                log.info("%s", page)
            last_page = page
    finally:
        log.info("stopping all services")
        supervisor.stop_all()
        stop.set()
        watcher.join(timeout=3)
    return 0
