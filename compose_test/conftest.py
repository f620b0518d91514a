"""Fixtures of the compose test (`make compose-test`): its own Docker engine, the project's
image, the lab brought up by compose with the sim profile and the secured router, and the
same chain under ``stb up`` on the host for reference. Every figure measured is printed at
the end of the run (and kept in run/compose-test/figures.json)."""

from __future__ import annotations

import json
import signal
import subprocess
import time
from collections.abc import Iterator

import pytest

from compose_test.engine import (
    ENGINE_HOME,
    IMAGE,
    OUT,
    Engine,
    EngineError,
    install_when_missing,
    why_no_engine,
)
from compose_test.lab import EVERY_PROFILE, PROJECT, Client, FollowMeter, lab_folder, up
from tests.conftest import stb_process
from tests.ports import free_port
from tests.sim.test_sim_service import write_lab

UPSTREAM_ROUTER = "eclipse/zenoh:1.10.2"  # docker-compose.yml's
FIGURES: dict[str, object] = {}
FOLLOW_WINDOW_S = 30.0  # more than one lap of the locomotive's railway (about 24 s)
MEASURED_POSES = "stb-compose-test-measured-poses"
"""A volume with what the one-host lab's calib measured (its poses, passpoints and pictures),
kept when that lab goes down: the three-host lab (test_hosts.py), the same sim lab file and so
the same camera mounts, starts its calib with it instead of calibrating the cameras again."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The one-host lab's tests first: the three-host lab starts with the poses they measured
    (``MEASURED_POSES``; without them it calibrates at its first start)."""
    items.sort(key=lambda item: item.path.name != "test_lab.py")


def figure(name: str, value: object) -> None:
    FIGURES[name] = value
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "figures.json").write_text(json.dumps(FIGURES, indent=1) + "\n")


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    if FIGURES:
        terminalreporter.section("compose test: measured")
        for name, value in FIGURES.items():
            terminalreporter.write_line(f"{name:<46} {value}")


def _timed(name: str, started: float) -> float:
    took = round(time.monotonic() - started, 1)
    figure(name, took)
    return took


@pytest.fixture(scope="session")
def engine() -> Iterator[Engine]:
    why = why_no_engine()
    if why is not None:
        pytest.skip(f"no Docker engine can run here: {why}")
    OUT.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    install_when_missing(OUT / "install.log")
    _timed("engine installed when missing, s", started)
    started = time.monotonic()
    engine = Engine(ENGINE_HOME)
    try:
        engine.start()
    except EngineError as err:
        pytest.skip(f"no Docker engine can run here: {err}")
    _timed("dockerd answering, s", started)
    try:
        yield engine
    finally:
        engine.stop()


@pytest.fixture(scope="session")
def images(engine: Engine) -> dict[str, object]:
    started = time.monotonic()
    base = engine.base_image()
    figure("base image", base)
    _timed("base image ready (pulled or made), s", started)
    started = time.monotonic()
    engine.build(base)
    _timed("project image built, s", started)
    figure("project image size, MB", round(engine.image_size_mb(IMAGE)))
    offline_router = not engine.pulled(UPSTREAM_ROUTER)
    figure("router image", IMAGE + " (stb router)" if offline_router else UPSTREAM_ROUTER)
    return {"base": base, "offline_router": offline_router}


@pytest.fixture(scope="module")
def lab(engine: Engine, images: dict, reference_follow_mm: float) -> Iterator[dict]:
    """The lab under compose (after the reference, which must not share the cores with it);
    down after its module, its calib's data kept in ``MEASURED_POSES``."""
    with lab_folder(offline_router=bool(images["offline_router"])) as (folder, files, client):
        try:
            started = up(engine, folder, files)
            yield {"engine": engine, "folder": folder, "files": files, "client": client,
                   "up_at": started, "offline_router": images["offline_router"]}
        finally:
            logs = engine.compose(folder, files, "--profile", "sim", "logs", "--no-color",
                                  check=False, timeout=60)
            (OUT / "containers.log").write_text(logs.stdout + logs.stderr)
            keep_calib_data(engine, f"{PROJECT}_calib-data")
            engine.compose(folder, files, *EVERY_PROFILE, "down", "-v", "--remove-orphans",
                           "-t", "5", check=False, timeout=180)


def keep_calib_data(engine: Engine, volume: str) -> None:
    """``volume``'s files copied into ``MEASURED_POSES`` (made afresh), owners kept; no such
    volume when the copy failed (the three-host lab then calibrates, and its figure says so)."""
    engine.docker("volume", "rm", "-f", MEASURED_POSES, check=False)
    engine.docker("volume", "create", MEASURED_POSES)
    copied = engine.docker("run", "--rm", "--user", "root", "--entrypoint", "cp",
                           "-v", f"{volume}:/from:ro", "-v", f"{MEASURED_POSES}:/to", IMAGE,
                           "-a", "/from/.", "/to/", check=False)
    if copied.returncode != 0:
        engine.docker("volume", "rm", "-f", MEASURED_POSES, check=False)


@pytest.fixture(scope="session")
def reference_follow_mm(tmp_path_factory: pytest.TempPathFactory) -> Iterator[float]:
    """The crane-to-robot RMS distance that ``stb up`` gives on the host: same sim scenario,
    same gantry defaults, plain local bus."""
    workdir = tmp_path_factory.mktemp("reference")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    lab_file, _ = write_lab(workdir, endpoint, workdir / "crater.npz")
    with open(lab_file, "a") as f:
        f.write(f'[router]\nlisten = ["{endpoint}"]\n[up]\nservices = ["router", "sim", '
                f'"tracker", "gantry"]\nlog_dir = "{workdir / "logs"}"\n')
    proc = stb_process("up", "--lab", str(lab_file), "--no-view", cwd=workdir)
    client = Client(endpoint)
    try:
        meter = FollowMeter(client.bus("monitor"))
        client.operator("arm", timeout_s=90)
        meter.caught_up()
        follow = meter.over(FOLLOW_WINDOW_S)
        figure("stb up: crane-to-robot RMS, mm", str(follow))
        yield follow.rms_mm
    finally:
        client.close()
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()

