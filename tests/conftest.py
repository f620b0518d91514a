"""Shared fixtures: real Zenoh sessions on loopback, each test set on its own free ports."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
import time
from collections.abc import Awaitable, Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, TypeVar

import numpy as np
import pytest
import zenoh

from common.bus import Bus, BusUnreachable, open_session
from common.keys import Topic
from common.markers import warm_up
from common.messages import Message
from common.settings import BusSettings, ZenohSettings
from tests.ports import free_port
from tests.simlab import crater, crater_file, lab  # noqa: F401 - shared fixtures

pytest_plugins = ["tests.scheduling"]  # how make test-system shares its tests

ROOT = Path(__file__).resolve().parent.parent
T = TypeVar("T")
M = TypeVar("M", bound=Message)


def client_settings(endpoint: str, **bus: object) -> BusSettings:
    return BusSettings(zenoh=ZenohSettings(mode="client", connect=[endpoint]), **bus)


def poll(predicate: Callable[[], T | None], timeout: float = 5.0,
         period: float = 0.02) -> T | None:
    """Poll ``predicate`` until it returns something truthy, and return that; None on
    timeout."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(period)  # the poll's period: the condition is asked again
    return None


async def poll_async(step: Callable[[], Awaitable[T | None]], timeout: float = 5.0,
                     period: float = 0.02) -> T | None:
    """``poll`` on an event loop: await ``step()`` until it gives something truthy, and
    return that; None on timeout."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = await step()
        if value:
            return value
        await asyncio.sleep(period)  # the poll's period: the step is awaited again
    return None


def wait_for(predicate: Callable[[], T | None], timeout: float = 5.0, period: float = 0.02,
             why: Callable[[], str] | None = None) -> T:
    """Poll ``predicate`` until it returns something truthy; fail the test on timeout (saying
    ``why()``, what was seen, if given)."""
    value = poll(predicate, timeout, period)
    if not value:
        pytest.fail(f"condition not met within {timeout} s: {predicate}"
                    + (f": {why()}" if why else ""))
    return value


def publish_paced(publisher: Bus, topic: Topic[M], samples: Iterable[M], period_s: float,
                  **fmt: str) -> None:
    """Publish ``samples`` on ``topic`` one every ``period_s``, a device's pace: the bus may
    drop a burst of big samples that it would carry at the rate a camera sends them."""
    for sample in samples:
        publisher.publish(topic, sample, max_age_s=None, **fmt)
        time.sleep(period_s)  # a device's pace (the subject is the samples, not the burst)


def until_heard(publisher: Bus, key: str, timeout: float = 10.0) -> None:
    """Wait until a subscriber of ``key`` is known to ``publisher``'s session (Zenoh's
    matching status: the subscription has reached it through the router), so that what it
    puts next is delivered — instead of a fixed pause."""
    declared = publisher.session.declare_publisher(key)
    try:
        wait_for(lambda: declared.matching_status.matching,  # type: ignore[attr-defined]
                 timeout=timeout,
                 why=lambda: f"no subscriber of {key} reached the publisher")
    finally:
        declared.undeclare()


def open_when_up(settings: ZenohSettings, timeout: float = 15.0) -> zenoh.Session:
    """A session as soon as the router accepts it (it may still be starting)."""
    def attempt() -> zenoh.Session | None:
        try:
            return open_session(settings)
        except BusUnreachable:
            return None

    return wait_for(attempt, timeout=timeout, period=0.2)


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator: every test's randomness is reproducible."""
    return np.random.default_rng(1234)


@pytest.fixture(scope="session", autouse=True)
def compiled_detector() -> None:
    """Services compile the marker detector at start (about 10 s in a fresh checkout, in
    every process at once, before they act): every test session compiles it first, into the
    cache the services load (0.2 s), so that no test that times a service waits for the
    compiler (a demo-calibration test once missed its 30 s that way in a fresh clone)."""
    warm_up()


@pytest.fixture(scope="module")
def router_endpoint() -> Iterator[str]:
    """An in-process Zenoh router on a free loopback port (multicast scouting off)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session(ZenohSettings(mode="router", listen=[endpoint], connect=[]))
    try:
        yield endpoint
    finally:
        session.close()


@contextmanager
def buses(endpoint: str, opener: Callable[[ZenohSettings], zenoh.Session] = open_session
          ) -> Iterator[Callable[..., Bus]]:
    """Factory of client Buses on the router at ``endpoint`` (``opener``: how a session is
    opened, e.g. ``open_when_up`` for a router still starting); all closed on leaving."""
    opened: list[tuple[Bus, zenoh.Session]] = []

    def make(**bus_settings: object) -> Bus:
        settings = client_settings(endpoint, **bus_settings)
        session = opener(settings.zenoh)
        bus = Bus(session, settings)
        opened.append((bus, session))
        return bus

    try:
        yield make
    finally:
        for bus, session in opened:
            bus.close()
            session.close()


@pytest.fixture
def make_bus(router_endpoint: str) -> Iterator[Callable[..., Bus]]:
    """Factory of client Buses on the module's router; all closed after the test."""
    with buses(router_endpoint) as make:
        yield make


class StbProcess(subprocess.Popen[str]):
    """A command started by ``stb_process``: its output and errors are always pipes of text."""

    stdout: IO[str]
    stderr: IO[str]


def ahead_of_other_work() -> Callable[[], None] | None:
    """For ``preexec_fn``: the process scheduled ahead of the other worker's tests (nice -10,
    where the runner may raise priority: root), as a lab's own machine would run it. For the
    tests that measure how a live loop keeps time, not how it shares two cores with another
    test's lab (a CI run's live gantry followed at 19.3 mm where the experiment gave 11.8)."""
    if os.geteuid() != 0:
        return None

    def raise_priority() -> None:
        os.nice(-10)
    return raise_priority


def stb_process(*args: str, **popen: Any) -> StbProcess:
    """Start ``python -m services.cli ARGS`` with the project on the path."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1", **popen.pop("env", {})}
    cwd = popen.pop("cwd", ROOT)
    return StbProcess([sys.executable, "-m", "services.cli", *args], cwd=cwd, env=env,
                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)
