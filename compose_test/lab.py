"""The lab as compose brings it up, seen from the host as a remote client of its router: the
project folder a lab would have (compose file, config, router config, secrets), the services'
health and liveliness, and how closely the crane follows the robot (the sim's truth)."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh

from common import keys
from common import messages as m
from common.bus import Bus
from common.settings import BusSettings, ZenohSettings
from compose_test.engine import ROOT, Engine, may_raise_limits
from tests.conftest import open_when_up
from tests.deploy.lab_secrets import identity, identity_env, make_secrets
from tests.ports import free_port
from tests.services.test_processes import AliveWatcher
from tests.uplab import write_users

PROJECT = "stb-compose-test"
LAB_FILE_IN_CONTAINERS = "/config/compose-sim.toml"
# `down` leaves a profile's containers (and so their network) unless the profile is named
EVERY_PROFILE = ("--profile", "sim", "--profile", "observation")
# compose service -> (service, instance) on the bus; the router only when it is ours (stb
# router publishes health, upstream eclipse/zenoh does not).
ON_THE_BUS = {"tracker": ("tracker", "main"), "ptz-1": ("ptz", "ptz1"),
              "ptz-2": ("ptz", "ptz2"), "calib": ("calib", "main"),
              "gantry": ("gantry", "main"), "web": ("web", "main"), "sim": ("sim", "main")}
REALTIME_SERVICES = ("tracker", "ptz-1", "ptz-2")  # compose gives them ulimits: {rtprio: 10}
CAMERAS = ("ptz1", "ptz2")
ROBOT = "locomotive"  # config/compose-sim.toml's scenario (the sim's default)
CAUGHT_UP_MM = 300.0  # the crane is over the robot: it is well inside the tracking camera's view

# Bounds, well above what our runs on 2 cores measured (docs/deployment.md §7): every service
# alive 5.0-6.3 s after `up -d`, healthy once the wand has calibrated both cameras 31-33 s
# after it; a killed gantry back in 2.6-3.6 s; every service heard again 2.3-6.3 s after
# `compose restart router` began; calib healthy with its stored poses 4.7-6.7 s after `up -d`.
ALIVE_BOUND_S = 60.0
HEALTHY_BOUND_S = 150.0
RESTART_BOUND_S = 30.0
RESUME_BOUND_S = 45.0
# The crane's RMS distance to the robot under compose against stb up's on the host, measured in
# the same run once the crane is over the robot: the same code and scenario, so the same up to
# the spread of 30 s windows (stb up 44.9-48.0 mm, compose 45.2-47.6 mm in our runs) and the
# containers' and TLS's share of two cores.
FOLLOW_FACTOR, FOLLOW_SLACK_MM = 1.25, 15.0


def follow_bound_mm(reference_mm: float) -> float:
    return max(FOLLOW_FACTOR * reference_mm, reference_mm + FOLLOW_SLACK_MM)


def wait_until(predicate: Callable[[], object], bound_s: float, what: str) -> float:
    """Seconds until ``predicate()`` holds; the test fails after ``bound_s``."""
    started = time.monotonic()
    while time.monotonic() - started < bound_s:
        if predicate():
            return time.monotonic() - started
        time.sleep(0.2)
    pytest.fail(f"{what}: not within {bound_s:.0f} s")


@contextmanager
def lab_folder(*, offline_router: bool, router_names: tuple[str, ...] = ()
               ) -> Iterator[tuple[Path, list[str], Client]]:
    """A lab's folder in a temporary directory (``project_folder``), its compose files, and
    the host's client of the router it will run; the folder (secrets included) goes after."""
    folder = Path(tempfile.mkdtemp(prefix="stb-compose-"))
    try:
        files, ports = project_folder(folder, offline_router=offline_router,
                                      raise_limits=may_raise_limits(),
                                      router_names=router_names)
        client = Client(f"tls/localhost:{ports['router']}",
                        folder / "deploy" / "zenoh" / "secrets",
                        web_url=f"https://127.0.0.1:{ports['web']}")
        try:
            yield folder, files, client
        finally:
            client.close()
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def project_folder(folder: Path, *, offline_router: bool, raise_limits: bool,
                   router_names: tuple[str, ...] = ()) -> tuple[list[str], dict[str, int]]:
    """Lay out what a lab's checkout has (docker-compose.yml, config/, the router config,
    secrets from make-secrets, the router's certificate naming ``router_names`` too) plus this
    test's override: loopback-only, free host ports.
    Returns the compose files to use, in order, and the host ports."""
    shutil.copy(ROOT / "docker-compose.yml", folder)
    shutil.copytree(ROOT / "config", folder / "config")
    (folder / "deploy" / "zenoh").mkdir(parents=True)
    shutil.copy(ROOT / "deploy" / "zenoh" / "router.json5", folder / "deploy" / "zenoh")
    write_users(make_secrets(folder, *router_names) / "web-users.json")  # the page's users
    files = ["docker-compose.yml"]
    if offline_router:
        shutil.copy(ROOT / "deploy" / "docker" / "compose.offline.yml", folder)
        files.append("compose.offline.yml")
    ports = {name: free_port() for name in ("router", "web", "qtm", "ptz1", "ptz2")}
    text = f"""# the compose test's: host ports on loopback only, free ones
services:
  router:
    ports: !override ["127.0.0.1:{ports['router']}:7447"]
  web:
    ports: !override ["127.0.0.1:{ports['web']}:8080"]
  sim:
    ports: !override ["127.0.0.1:{ports['qtm']}:22223", "127.0.0.1:{ports['ptz1']}:8081",
                      "127.0.0.1:{ports['ptz2']}:8082"]
"""
    if not raise_limits:  # an engine without CAP_SYS_RESOURCE cannot grant rtprio 10
        text += "".join(f"  {name}:\n    ulimits: !reset {{}}\n" for name in REALTIME_SERVICES)
    (folder / "compose.test.yml").write_text(text)
    files.append("compose.test.yml")
    return files, ports


@dataclass
class Sighting:
    at: float  # monotonic arrival time on the host
    health: m.ServiceHealth


class Watch:
    """One client session of the host: the services' health and liveliness, as they arrive."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self._lock = threading.Lock()
        self.healths: list[Sighting] = []
        bus.subscribe(keys.HEALTH, self._on_health, latest=False)
        self._alive = AliveWatcher(bus.session)

    def _on_health(self, health: m.ServiceHealth) -> None:
        with self._lock:
            self.healths.append(Sighting(time.monotonic(), health))

    def latest(self, who: tuple[str, str], since: float = 0.0) -> m.ServiceHealth | None:
        with self._lock:
            return next((s.health for s in reversed(self.healths)
                         if s.at >= since and (s.health.service, s.health.instance) == who),
                        None)

    def ok_since(self, since: float, expected: list[tuple[str, str]]) -> bool:
        return all((h := self.latest(who, since)) is not None and h.status == "ok"
                   for who in expected)

    def alive(self, who: tuple[str, str]) -> bool:
        return self._alive.alive(keys.alive_key(self.bus.prefix, *who))


@dataclass
class Follow:
    rms_mm: float        # RMS horizontal crane-to-robot distance over the window
    samples: int         # crane/robot truth pairs in it
    tracking_share: float  # of the gantry's states in it, the share "tracking"

    def __str__(self) -> str:
        return f"{self.rms_mm:.1f} ({self.samples} samples, {self.tracking_share:.0%} tracking)"


class FollowMeter:
    """The horizontal distance from the crane to the robot, from the sim's truth (20 Hz), and
    what the gantry said it was doing meanwhile."""

    def __init__(self, bus: Bus) -> None:
        self._robot: m.RobotTruth | None = None
        self._errors: list[tuple[float, float]] = []
        self._statuses: list[tuple[float, str]] = []
        self._lock = threading.Lock()
        bus.subscribe(keys.TRUTH_ROBOT, self._on_robot, latest=False, robot=ROBOT)
        bus.subscribe(keys.TRUTH_CRANE, self._on_crane, latest=False)
        bus.subscribe(keys.GANTRY_STATE, self._on_state, latest=False)

    def _on_robot(self, robot: m.RobotTruth) -> None:
        self._robot = robot

    def _on_crane(self, crane: m.CraneTruth) -> None:
        robot = self._robot
        if robot is not None and abs(robot.measured_s - crane.measured_s) < 0.1:
            with self._lock:
                self._errors.append((time.monotonic(), math.hypot(
                    crane.x_mm - robot.x_mm, crane.y_mm - robot.y_mm)))

    def _on_state(self, state: m.CraneState) -> None:
        with self._lock:
            self._statuses.append((time.monotonic(), state.status))

    def caught_up(self, within_mm: float = CAUGHT_UP_MM, for_s: float = 2.0,
                  timeout_s: float = 60.0) -> float:
        """Seconds until the crane has stayed within ``within_mm`` of the robot for ``for_s``
        (armed after the robot left the tracking camera's view, the gantry first goes to the
        motion capture's fix at its reacquire speed: that is not following yet)."""
        start = time.monotonic()
        while time.monotonic() - start < timeout_s:
            now = time.monotonic()
            with self._lock:
                recent = [e for at, e in self._errors if at >= now - for_s]
            if now - start >= for_s and len(recent) > 10 * for_s and max(recent) <= within_mm:
                return now - start
            time.sleep(0.2)
        raise AssertionError(f"the crane did not come within {within_mm:.0f} mm of the robot "
                             f"in {timeout_s:.0f} s")

    def over(self, seconds: float) -> Follow:
        """How the crane follows over the next ``seconds``."""
        start = time.monotonic()
        time.sleep(seconds)
        with self._lock:
            window = [e for at, e in self._errors if start <= at <= start + seconds]
            statuses = [s for at, s in self._statuses if start <= at <= start + seconds]
        assert len(window) > 10 * seconds, f"only {len(window)} crane/robot pairs in {seconds} s"
        return Follow(math.sqrt(sum(e * e for e in window) / len(window)), len(window),
                      statuses.count("tracking") / max(1, len(statuses)))


class Client:
    """The host's side of the bus: sessions as the lab's identities through the router's
    port (TLS and passwords from ``secrets``; without, plain TCP as ``stb up`` has it)."""

    def __init__(self, endpoint: str, secrets: Path | None = None, web_url: str = "") -> None:
        self.endpoint, self.secrets, self.web_url = endpoint, secrets, web_url
        self._sessions: list[zenoh.Session] = []

    def settings(self, user: str) -> ZenohSettings:
        if self.secrets is None:
            return ZenohSettings(mode="client", connect=[self.endpoint])
        return identity(self.secrets, user, self.endpoint)

    def bus(self, user: str, timeout_s: float = 60.0) -> Bus:
        settings = self.settings(user)
        self._sessions.append(open_when_up(settings, timeout=timeout_s))
        return Bus(self._sessions[-1], BusSettings(zenoh=settings))

    def operator_once(self, command: str) -> tuple[int, str]:
        """``stb gantry COMMAND`` as the operator: its exit status and what it printed."""
        if self.secrets is None:
            bus_env = {"STB_BUS__ZENOH__CONNECT": f'["{self.endpoint}"]'}
        else:
            bus_env = identity_env(self.secrets, "operator", self.endpoint)
        done = subprocess.run(
            [sys.executable, "-m", "services.cli", "gantry", command, "--reason",
             "compose test"], capture_output=True, text=True, timeout=60, check=False,
            env={**os.environ, "PYTHONPATH": str(ROOT), "STB_BUS__ZENOH__MODE": "client",
                 **bus_env})
        return done.returncode, (done.stdout + done.stderr).strip()

    def answer(self, command: str, *, timeout_s: float = 30.0) -> tuple[int, str]:
        """``operator_once`` again while the gantry does not answer at all (just restarted on
        a loaded machine, its command path may still be coming up): its first answer,
        accepted or refused."""
        deadline = time.monotonic() + timeout_s
        while True:
            status, said = self.operator_once(command)
            if "no answer within" not in said or time.monotonic() > deadline:
                return status, said
            time.sleep(1.0)

    def operator(self, command: str, *, timeout_s: float = 60.0) -> str:
        """``stb gantry COMMAND`` as the operator, again until the gantry accepts it (arming
        waits for the robot in the tracking camera's view)."""
        deadline = time.monotonic() + timeout_s
        while True:
            status, said = self.operator_once(command)
            if status == 0:
                return said
            if time.monotonic() > deadline:
                raise AssertionError(f"stb gantry {command} not accepted within "
                                     f"{timeout_s:.0f} s: {said}")
            time.sleep(1.0)

    def armed(self) -> None:
        """The gantry armed whatever an earlier test left: a latched fault reset first."""
        status, said = self.operator_once("arm")
        if status != 0 and "reset first" in said:
            self.operator("reset")
        if status != 0:
            self.operator("arm")

    def close(self) -> None:
        for session in self._sessions:
            session.close()


def container(service: str) -> str:
    return f"{PROJECT}-{service}-1"


def up(engine: Engine, folder: Path, files: list[str], *services: str,
       project: str = PROJECT, router: str = "router") -> float:
    """``docker compose --profile sim up -d [--no-deps SERVICE...]`` with the sim's lab file,
    the services connecting to ``router`` (STB_ROUTER); its monotonic start."""
    started = time.monotonic()
    only = ["--no-deps", *services] if services else []
    engine.compose(folder, files, "--profile", "sim", "up", "-d", "--no-build", *only,
                   project=project, STB_LAB_FILE=LAB_FILE_IN_CONTAINERS, STB_ROUTER=router)
    return started
