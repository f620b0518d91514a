"""Entry points as real processes: liveliness, clean stop, config errors, stb up, stb monitor."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time
from pathlib import Path
from typing import cast

import pytest
import zenoh

from common import keys
from common import messages as m
from common.bus import Bus
from common.wiredoc import EXAMPLES
from tests.conftest import (
    StbProcess,
    client_settings,
    free_port,
    open_when_up,
    stb_process,
    wait_for,
)


class AliveWatcher:
    """Records liveliness PUT/DELETE events under stb/alive/** with their arrival times."""

    def __init__(self, session: zenoh.Session) -> None:
        self.events: list[tuple[float, str, str]] = []
        self._lock = threading.Lock()
        self._sub = session.liveliness().declare_subscriber("stb/alive/**", self._on,
                                                            history=True)

    def _on(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self.events.append((time.monotonic(), str(sample.key_expr), str(sample.kind)))

    def alive(self, key: str) -> bool:
        with self._lock:
            kinds = [k for _, key_, k in self.events if key_ == key]
        return bool(kinds) and kinds[-1] == str(zenoh.SampleKind.PUT)

    def first_put_after(self, key: str, t: float) -> float | None:
        with self._lock:
            return next((at for at, key_, kind in self.events
                         if key_ == key and at > t and kind == str(zenoh.SampleKind.PUT)), None)


def _stop(proc: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 5.0) -> int:
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        return proc.wait(timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _linked_router(router_endpoint: str, instance: str) -> StbProcess:
    """A second router process that links to the test's router (a two-router lab)."""
    return stb_process("router", "--instance", instance, "--listen",
                       f"tcp/127.0.0.1:{free_port()}", "--set",
                       f'connect=["{router_endpoint}"]')


def test_liveliness_token_appears_and_goes_when_the_process_is_killed(
        router_endpoint: str, observer: tuple[Bus, AliveWatcher]) -> None:
    _, alive = observer
    proc = _linked_router(router_endpoint, "r2")
    try:
        wait_for(lambda: alive.alive("stb/alive/router/r2"), timeout=10)
        proc.kill()
        proc.wait()
        wait_for(lambda: not alive.alive("stb/alive/router/r2"), timeout=5)
    finally:
        _stop(proc)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_stops_a_service_cleanly_and_quickly(
        router_endpoint: str, observer: tuple[Bus, AliveWatcher], sig: int) -> None:
    _, alive = observer
    proc = _linked_router(router_endpoint, "r3")
    wait_for(lambda: alive.alive("stb/alive/router/r3"), timeout=10)
    start = time.monotonic()
    assert _stop(proc, sig) == 0
    assert time.monotonic() - start < 3.0
    assert "router/r3 stopped" in proc.stderr.read()
    wait_for(lambda: not alive.alive("stb/alive/router/r3"))


def test_service_health_is_published(router_endpoint: str,
                                     observer: tuple[Bus, AliveWatcher]) -> None:
    bus, _ = observer
    got: list[m.ServiceHealth] = []
    bus.subscribe(keys.HEALTH, got.append, latest=False, instance="r4")
    proc = _linked_router(router_endpoint, "r4")
    try:
        wait_for(lambda: got, timeout=10)
        assert got[0].service == "router" and got[0].pid == proc.pid and got[0].status == "ok"
    finally:
        _stop(proc)


def test_bad_config_stops_start_up_naming_the_field(tmp_path: Path) -> None:
    lab = tmp_path / "lab.toml"
    lab.write_text('[bus.zenoh]\nmode = "clinet"\n')
    proc = stb_process("router", "--lab", str(lab))
    assert proc.wait(10) == 2
    assert "router.bus.zenoh.mode" in proc.stderr.read()


def test_unreachable_router_is_a_clear_error() -> None:
    proc = stb_process("monitor", "--connect", f"tcp/127.0.0.1:{free_port()}",
                       "--set", "bus.zenoh.connect_timeout_ms=0")
    assert proc.wait(10) == 3
    assert "cannot open a Zenoh client session on tcp/127.0.0.1:" in proc.stderr.read()


def test_monitor_raw_prints_what_is_published(router_endpoint: str,
                                              observer: tuple[Bus, AliveWatcher]) -> None:
    bus, _ = observer
    proc = stb_process("monitor", "--connect", router_endpoint, "--raw", "stb/tracker/**",
                       "--duration", "20")
    try:
        robot = cast(m.RobotPosition, EXAMPLES[m.RobotPosition])
        line = ""

        def published_and_printed() -> bool:
            nonlocal line
            bus.publish(keys.TRACKER_ROBOT, robot.model_copy(update={"measured_s": time.time()}))
            os.set_blocking(proc.stdout.fileno(), False)
            line = proc.stdout.readline()
            return bool(line)

        wait_for(published_and_printed, timeout=10, period=0.2)
        data = json.loads(line)
        assert data["key"] == "stb/tracker/robot" and data["type"] == "RobotPosition"
        assert data["x_mm"] == robot.x_mm and data["sent_s"] > 0
    finally:
        assert _stop(proc, signal.SIGINT) == 0


def test_monitor_table_shows_alive_services_and_keys(router_endpoint: str,
                                                     observer: tuple[Bus, AliveWatcher]) -> None:
    _, alive = observer
    router = _linked_router(router_endpoint, "r5")
    try:
        wait_for(lambda: alive.alive("stb/alive/router/r5"), timeout=10)
        proc = stb_process("monitor", "--connect", router_endpoint, "--duration", "2.5")
        stdout, _ = proc.communicate(timeout=20)
        assert proc.returncode == 0
        last = stdout.strip().split("---")[-2]
        assert "router/r5" in last
        assert "stb/health/router/r5" in last
    finally:
        _stop(router)


def _lab_for_up(tmp_path: Path) -> tuple[Path, str]:
    """A lab file for ``stb up`` with every service (the sim too) on free ports."""
    from tests.sim.test_sim_service import write_lab

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    lab, _ = write_lab(tmp_path, endpoint, tmp_path / "crater.npz")
    with open(lab, "a") as f:
        f.write(f"""
[router]
listen = ["{endpoint}"]
[up]
log_dir = "{tmp_path / 'logs'}"
[web]
port = {free_port()}
""")
    return lab, endpoint


def _open_when_up(endpoint: str) -> zenoh.Session:
    return open_when_up(client_settings(endpoint).zenoh)


# A killed service under ``stb up`` is back within 2 s: the fault campaign kills each in turn
# (tests/reliability, docs/reliability.md).


def test_up_stops_every_child_on_ctrl_c(tmp_path: Path) -> None:
    lab, endpoint = _lab_for_up(tmp_path)
    up = stb_process("up", "--lab", str(lab), "--no-view")
    session = _open_when_up(endpoint)
    try:
        alive = AliveWatcher(session)
        wait_for(lambda: alive.alive("stb/alive/router/main"), timeout=15)
    finally:
        session.close()
    assert _stop(up, signal.SIGINT, timeout=15) == 0
    log_text = (tmp_path / "logs" / "router-main.log").read_text()
    assert "router/main stopped" in log_text


def test_up_says_where_the_page_is_once_the_web_service_is_up_and_reports_health_changes(
        ) -> None:
    from common.messages import ServiceHealth
    from services.supervisor import Supervisor, UpSettings, page_url, runs_web

    settings = UpSettings(services=["router", "web"])
    assert runs_web(settings) and not runs_web(UpSettings(services=["router", "sim"]))
    supervisor = Supervisor(settings, None, page_url("127.0.0.1", 8080))
    assert supervisor.page() == "the page: waiting for the web service"
    supervisor.set_alive("web", "main", True)
    assert supervisor.page() == "the page: http://127.0.0.1:8080/"
    before = supervisor.state()

    def health(status: m.HealthStatus, detail: str = "") -> ServiceHealth:
        return ServiceHealth(measured_s=1.0, service="web", instance="main", host="h", pid=1,
                             started_s=0.0, status=status, detail=detail, keys={})

    supervisor.set_health(health("ok", "serving"))
    changed = supervisor.state()
    assert changed != before
    supervisor.set_health(health("ok", "serving more"))  # the detail alone: no new report
    assert supervisor.state() == changed
    supervisor.set_health(health("degraded", "no crater"))
    assert supervisor.state() != changed
    assert [c.health for c in supervisor.children if c.service == "web"] == [
        "degraded (no crater)"]
