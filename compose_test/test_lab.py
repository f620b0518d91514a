"""`docker compose --profile sim up` for real, watched from the host as a remote client of the
containerised, secured router (TLS, passwords, access control). The tests run in file order on
one lab: up → healthy → calibrated and following → a crash → a router restart → access
control → down and up again."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from common import keys
from common import messages as m
from compose_test.conftest import FOLLOW_WINDOW_S, figure
from compose_test.lab import (
    ALIVE_BOUND_S,
    CAMERAS,
    HEALTHY_BOUND_S,
    ON_THE_BUS,
    RESTART_BOUND_S,
    RESUME_BOUND_S,
    FollowMeter,
    Watch,
    container,
    follow_bound_mm,
    up,
    wait_until,
)
from tests.uplab import OPERATOR, VIEWER
from tests.webpage import PageClient


def _expected(lab: dict) -> list[tuple[str, str]]:
    return list(ON_THE_BUS.values()) + ([("router", "main")] if lab["offline_router"] else [])


@pytest.fixture(scope="module")
def watch(lab: dict) -> Watch:
    return Watch(lab["client"].bus("monitor"))


def test_every_service_is_alive_and_healthy_on_the_bus(lab: dict, watch: Watch) -> None:
    expected = _expected(lab)
    wait_until(lambda: all(watch.alive(who) for who in expected), ALIVE_BOUND_S,
          f"every service alive ({expected})")
    figure("up -d -> every service alive on the bus, s", round(time.monotonic() - lab["up_at"], 1))
    wait_until(lambda: watch.ok_since(0.0, expected), HEALTHY_BOUND_S,
          "every service healthy: " + ", ".join(
              f"{s}/{i} {h.status if (h := watch.latest((s, i))) else 'unheard'}"
              f"{' (' + h.detail + ')' if h and h.detail else ''}" for s, i in expected))
    figure("up -d -> every service healthy (cameras calibrated), s",
           round(time.monotonic() - lab["up_at"], 1))


def test_the_services_that_detect_run_the_loop_built_in_the_image(lab: dict) -> None:
    """The image's build stage built the marker detector's loop ahead of time: the gantry
    and the PTZ services load it, not numba's JIT (docs/deployment.md §7)."""
    for service in ("gantry", "ptz-1", "ptz-2"):
        logs = lab["engine"].docker("logs", container(service))
        ready = [line for line in (logs.stdout + logs.stderr).splitlines()
                 if "detector ready" in line]
        assert ready and all("built ahead" in line for line in ready), (service, ready)


def test_the_cameras_are_calibrated_and_the_crane_follows_the_robot(
        lab: dict, reference_follow_mm: float) -> None:
    bus = lab["client"].bus("monitor")
    poses = {}
    for camera in CAMERAS:
        replies = bus.query_latest(keys.CALIB_POSE, timeout_s=5, camera=camera)
        assert replies, f"{camera}: no pose from the calib service"
        poses[camera] = replies[0]
        # compose-sim.toml's calib.count is 50; the pose counts its inliers
        assert replies[0].mean_error_px < 1.0 and replies[0].passpoints >= 45, replies[0]
    lab["poses"] = poses
    meter = FollowMeter(bus)
    lab["client"].operator("arm")
    figure("armed -> crane over the robot, s", round(meter.caught_up(), 1))
    follow = meter.over(FOLLOW_WINDOW_S)
    figure("compose: crane-to-robot RMS, mm", str(follow))
    bound = follow_bound_mm(reference_follow_mm)
    assert follow.rms_mm <= bound, (f"the crane is {follow} mm from the robot under compose; "
                                    f"stb up: {reference_follow_mm:.0f} mm")
    lab["follow_bound_mm"] = bound


def test_a_crashed_gantry_is_restarted_by_the_engine_disarmed_with_the_fault_latched(
        lab: dict, watch: Watch) -> None:
    engine, gantry = lab["engine"], container("gantry")
    before = watch.latest(("gantry", "main"))
    assert before is not None
    _, restarts = engine.container_starts(gantry)
    bus = lab["client"].bus("monitor")
    states: list[m.CraneState] = []
    bus.subscribe(keys.GANTRY_STATE, states.append, latest=False)
    pid = engine.container_pid(gantry)  # (`docker inspect`: 0.1 s in which it still runs)
    killed_at = time.monotonic()
    os.kill(pid, signal.SIGKILL)  # a crash: `docker kill` would disable the restart policy
    back_s = wait_until(
        lambda: (h := watch.latest(("gantry", "main"), killed_at)) is not None
        and h.started_s != before.started_s, RESTART_BOUND_S, "the killed gantry back")
    figure("SIGKILL gantry -> restarted, on the bus again, s", round(back_s, 1))
    assert engine.container_starts(gantry)[1] == restarts + 1
    restarted = watch.latest(("gantry", "main"), killed_at)
    assert restarted is not None

    def since_the_crash() -> list[m.CraneState]:
        """The restarted process's states: measured after it started (the killed one's
        armed states — up to its last moment — do not count)."""
        return [s for s in list(states) if s.measured_s >= restarted.started_s]

    wait_until(lambda: len(since_the_crash()) >= 8, 10, "the restarted gantry's state")
    modes = {s.mode for s in since_the_crash()}
    assert modes == {"disarmed"}, f"a restarted gantry arms itself: {modes}"
    # The crash stopped the crane's watchdog heartbeat: the controller latched the fault, and
    # only an operator clears it.
    status, said = lab["client"].answer("arm")
    assert status != 0 and "latched" in said, said
    lab["client"].operator("reset")
    lab["client"].operator("arm")


def _started_s(watch: Watch, who: tuple[str, str]) -> float:
    """When the service ``who`` (service, instance) last heard says it started."""
    health = watch.latest(who)
    assert health is not None, f"{who} is heard"
    return health.started_s


def test_every_service_resumes_after_the_router_restarts(lab: dict, watch: Watch) -> None:
    lab["client"].armed()
    engine, services = lab["engine"], list(ON_THE_BUS)
    starts = {s: engine.container_starts(container(s)) for s in services}
    started_s = {who: _started_s(watch, who) for who in ON_THE_BUS.values()}
    restarted_at = time.monotonic()
    engine.compose(lab["folder"], lab["files"], "--profile", "sim", "restart", "-t", "5",
                   "router")
    back_at = time.monotonic()
    resumed_s = wait_until(lambda: all(watch.latest(who, back_at) for who in ON_THE_BUS.values()),
                      RESUME_BOUND_S, "every service heard again")
    figure("compose restart router -> every service heard again, s",
           round(back_at - restarted_at + resumed_s, 1))
    assert {s: engine.container_starts(container(s)) for s in services} == starts, \
        "a service's container was restarted with the router"
    assert {who: _started_s(watch, who) for who in ON_THE_BUS.values()} == started_s
    meter = FollowMeter(lab["client"].bus("monitor"))
    meter.caught_up()
    follow = meter.over(FOLLOW_WINDOW_S / 2)
    figure("after the router restart: crane-to-robot RMS, mm", str(follow))
    assert follow.rms_mm <= lab["follow_bound_mm"], str(follow)


def test_the_monitor_cannot_put_a_setpoint_through_the_router(lab: dict) -> None:
    lab["client"].armed()
    listener = lab["client"].bus("monitor").session
    got: list[bytes] = []
    lock = threading.Lock()

    def on_sample(sample) -> None:
        with lock:
            got.append(sample.payload.to_bytes())

    _sub = listener.declare_subscriber("stb/gantry/setpoint", on_sample)
    intruder = lab["client"].bus("monitor").session
    time.sleep(1.0)
    for _ in range(5):
        intruder.put("stb/gantry/setpoint", b"from the monitor")
        time.sleep(0.2)
    time.sleep(1.0)
    with lock:
        assert len(got) >= 4, "the gantry's own setpoints (4 Hz, armed) must arrive"
        assert b"from the monitor" not in got


def test_the_page_needs_a_sign_in_over_tls_and_names_the_operator(lab: dict) -> None:
    """The operator's page from outside the containers, as a browser on the lab's LAN sees it:
    HTTPS with the lab CA's certificate, nothing before a sign-in, a viewer refused, an
    operator's command in the gantry's own state under their name."""
    page = PageClient(lab["client"].web_url, lab["client"].secrets / "ca.pem")
    status, _, form = page.request("GET", "/")
    assert status == 200 and b'id="signin"' in form and b"canvas" not in form
    for path in ("/state.json", "/events", "/map.png", "/preview/ptz1.jpg"):
        assert page.request("GET", path)[0] == 401, path
    assert page.request("POST", "/gantry/stop")[0] == 401
    assert page.request("GET", "/state.json", auth=VIEWER)[0] == 200
    assert page.request("POST", "/gantry/stop", auth=VIEWER)[0] == 403
    cookie, csrf, set_cookie = page.sign_in(OPERATOR)
    assert {"secure", "httponly", "samesite=strict"} <= {
        part.strip().lower() for part in set_cookie.split(";")}
    states: list[m.CraneState] = []
    lab["client"].bus("monitor").subscribe(keys.GANTRY_STATE, states.append, latest=False)
    status, answer = page.command("disarm", cookie, csrf)
    assert status == 200 and answer["accepted"], answer
    wait_until(lambda: states and states[-1].mode == "disarmed"
               and states[-1].mode_by.startswith("olga (web "), 10,
               "the gantry's state names the page's operator")
    deadline = time.monotonic() + 60
    while not (answer := page.command("arm", cookie, csrf)[1])["accepted"]:
        assert time.monotonic() < deadline, f"arm from the page: {answer}"
        time.sleep(1.0)


def test_the_calibration_survives_down_and_up(lab: dict, watch: Watch) -> None:
    engine, folder, files = lab["engine"], lab["folder"], lab["files"]
    engine.compose(folder, files, "--profile", "sim", "down", "-t", "5")
    assert "calib-data" in engine.docker("volume", "ls", "--format", "{{.Name}}").stdout
    started = up(engine, folder, files)
    wait_until(lambda: watch.ok_since(started, [("calib", "main")]), HEALTHY_BOUND_S,
                 "calib healthy again")
    figure("down, up -d -> calib healthy with its stored poses, s",
           round(time.monotonic() - started, 1))
    bus = lab["client"].bus("monitor")
    for camera, before in lab["poses"].items():
        after = bus.query_latest(keys.CALIB_POSE, timeout_s=5, camera=camera)
        assert after, f"{camera}: no pose after down/up"
        assert after[0].measured_s == before.measured_s, f"{camera} was calibrated again"
        assert (after[0].x_mm, after[0].rz_deg) == (before.x_mm, before.rz_deg)
