"""The lab split over three "hosts" as a lab would run it: one compose project per host (the
router PC with the sim, the tracker, calib and the page; a camera host with both PTZ services;
the gantry PC), all from the same docker-compose.yml, joined only by one network — the lab's
LAN — and the containerised, secured router. Its calib starts with what the one-host lab's
calibration measured (``MEASURED_POSES``, when test_lab.py ran before: the same sim lab file,
the same camera mounts); the cameras' calibration itself is test_lab.py's."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from compose_test.conftest import FOLLOW_WINDOW_S, MEASURED_POSES, figure
from compose_test.engine import Engine
from compose_test.lab import (
    EVERY_PROFILE,
    HEALTHY_BOUND_S,
    ON_THE_BUS,
    FollowMeter,
    Watch,
    follow_bound_mm,
    lab_folder,
    up,
    wait_until,
)

HOSTS = {"router-pc": ["router", "sim", "crater", "tracker", "calib", "web"],
         "camera-pc": ["ptz-1", "ptz-2"],
         "gantry-pc": ["gantry", "observation"]}  # the observation camera hangs on the crane
# (a service named on the command line starts whatever its profile)
ONE_SHOT = ("crater",)  # the sim's scan imported at the first start, then it has exited
LAN = "stb-compose-lan"
# On one engine the sim's crater reaches the gantry PC through a shared volume; on real hosts
# the gantry PC has its own copy (its lab file's [gantry] height_map).
CRATER_VOLUME = "stb-compose-lan-sim-data"
ROUTER_HOST = "stb-router-pc-router-1"  # the router PC's router container, by its name on the LAN


def _project(host: str) -> str:
    return f"stb-{host}"


@pytest.fixture(scope="module")
def hosts(engine: Engine, images: dict, reference_follow_mm: float) -> Iterator[dict]:
    with lab_folder(offline_router=bool(images["offline_router"]),
                    router_names=(ROUTER_HOST,)) as (folder, files, client):
        (folder / "compose.lan.yml").write_text(f"""# every project on the one network, the LAN
networks:
  default:
    name: {LAN}
    external: true
volumes:
  sim-data:
    name: {CRATER_VOLUME}
  calib-data:
    name: {MEASURED_POSES}
    external: true
""")
        files.append("compose.lan.yml")
        _take_down(engine, folder, files)  # what a run killed before its teardown left behind
        engine.docker("network", "create", LAN)
        measured = engine.docker("volume", "inspect", MEASURED_POSES, check=False).returncode == 0
        figure("3 hosts: calib starts with the one-host lab's poses", measured)
        engine.docker("volume", "create", MEASURED_POSES)  # empty: calibrated at the first start
        try:
            started = time.monotonic()
            for host, services in HOSTS.items():  # the others name the router PC's router
                up(engine, folder, files, *services, project=_project(host),
                   router="router" if host == "router-pc" else ROUTER_HOST)
            yield {"engine": engine, "folder": folder, "files": files, "client": client,
                   "up_at": started, "reference_mm": reference_follow_mm}
        finally:
            _take_down(engine, folder, files)
            engine.docker("volume", "rm", "-f", MEASURED_POSES, check=False)


def _take_down(engine: Engine, folder: Path, files: list[str]) -> None:
    """Every host's project, the shared volume and the LAN gone, whether or not they exist."""
    for host in reversed(HOSTS):
        engine.compose(folder, files, *EVERY_PROFILE, "down", "-v", "--remove-orphans", "-t",
                       "5", project=_project(host), check=False, timeout=180)
    engine.docker("volume", "rm", "-f", CRATER_VOLUME, check=False)
    engine.docker("network", "rm", "--force", LAN, check=False)


def test_each_host_runs_only_its_own_services_on_the_lan(hosts: dict) -> None:
    engine = hosts["engine"]
    for host, services in HOSTS.items():
        running = engine.compose(hosts["folder"], hosts["files"], "ps", "--services",
                                 "--status", "running", project=_project(host)).stdout.split()
        staying = [s for s in services if s not in ONE_SHOT]  # the import may still run
        assert sorted(set(running) - set(ONE_SHOT)) == sorted(staying), host
        for service in staying:
            networks = engine.docker("inspect", "-f", "{{range $k, $v := .NetworkSettings."
                                     "Networks}}{{$k}} {{end}}",
                                     f"{_project(host)}-{service}-1").stdout.split()
            assert networks == [LAN], (host, service, networks)
    importer = f"{_project('router-pc')}-crater-1"  # the sim's scan imported, then it ends
    wait_until(lambda: engine.docker("inspect", "-f", "{{.State.Status}} {{.State.ExitCode}}",
                                     importer).stdout.split() == ["exited", "0"], 180,
               "the crater's import done")
    env = engine.docker("inspect", "-f", "{{range .Config.Env}}{{println .}}{{end}}",
                        f"{_project('gantry-pc')}-gantry-1").stdout.splitlines()
    assert f'STB_BUS__ZENOH__CONNECT=["tls/{ROUTER_HOST}:7447"]' in env


def test_across_hosts_every_service_is_healthy_and_the_crane_follows(hosts: dict) -> None:
    client = hosts["client"]
    watch = Watch(client.bus("monitor"))
    expected = [*ON_THE_BUS.values(), ("observation", "main")]  # named: its profile
    wait_until(lambda: watch.ok_since(0.0, expected), HEALTHY_BOUND_S,
               "every service healthy across the hosts")
    figure("3 hosts: up -> every service healthy, s", round(time.monotonic() - hosts["up_at"], 1))
    meter = FollowMeter(client.bus("monitor"))
    client.operator("arm")
    meter.caught_up()
    follow = meter.over(FOLLOW_WINDOW_S / 2)
    figure("3 hosts: crane-to-robot RMS, mm", str(follow))
    assert follow.rms_mm <= follow_bound_mm(hosts["reference_mm"]), str(follow)
