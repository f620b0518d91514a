"""The lab on several hosts: router, sim (with the tracker, as on the mocap PC), gantry and a
ptz service each in its own network namespace, joined by veth links to a switch, behind the
lab's secured router (TLS, passwords, default-deny access control). Cables are pulled and the
router is restarted under the running chain."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from common import keys
from common import messages as m
from common.bus import Bus
from common.camera import Pose
from common.settings import BusSettings
from services.gantry.crane import ModbusCrane
from services.gantry.reading import CraneError
from services.sim.settings import SimSettings
from tests.conftest import ROOT, open_when_up, wait_for
from tests.deploy import netns
from tests.deploy.lab_secrets import ROUTER_CONFIG, identity, identity_env, make_secrets
from tests.gantry.rig import Operator

WHY_NOT = netns.why_not()
pytestmark = pytest.mark.skipif(WHY_NOT is not None, reason=f"no several hosts: {WHY_NOT}")

STALE_AFTER_S = 0.6  # the gantry's configured estimate age (lab file below)


class Host:
    def __init__(self, lan: netns.Lan, name: str, workdir: Path) -> None:
        self.lan, self.name, self.workdir = lan, name, workdir
        self.address = lan.host(name)
        self.procs: dict[str, subprocess.Popen] = {}

    def start(self, label: str, *args: str, env: dict[str, str]) -> None:
        log = open(self.workdir / f"{label}.log", "ab")  # noqa: SIM115 - the process owns it
        self.procs[label] = subprocess.Popen(
            ["ip", "netns", "exec", self.lan.namespace(self.name), sys.executable, "-m",
             "services.cli", *args], cwd=self.workdir, stdout=log, stderr=log,
            env={**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": str(ROOT), **env})

    def kill(self, label: str) -> None:
        proc = self.procs.pop(label)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)

    def stop_all(self) -> None:
        for proc in self.procs.values():
            proc.send_signal(signal.SIGINT)
        for proc in self.procs.values():
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()


def _lab_file(path: Path, router: str, sim: str, crater: Path) -> Path:
    path.write_text(f"""
[bus.zenoh]
connect = ["tls/{router}:7447"]
lease_ms = 1000
[sim]
scenario = "walker"  # slow: still in the tracking camera's view when the cable is back
crater_file = "{crater}"
bind = "0.0.0.0"
[tracker]
qtm_host = "127.0.0.1"
[ptz.cameras.ptz1]
url = "http://{sim}:8081"
user = "root"
password = "pass"
[gantry]
crane_host = "{sim}"
height_map = "{crater}"
marker_height_mm = 350.0
stale_after_s = {STALE_AFTER_S}
""")
    return path


@pytest.fixture
def lab(tmp_path: Path, crater_file: Path) -> Iterator[dict]:
    lan = netns.Lan()
    hosts: dict[str, Host] = {}
    sessions = []
    try:
        for name in ("router", "sim", "gantry", "ptz"):
            hosts[name] = Host(lan, name, tmp_path)
        router_ip = hosts["router"].address
        secrets = make_secrets(tmp_path, router_ip)
        endpoint = f"tls/{router_ip}:7447"
        lab_file = _lab_file(tmp_path / "lab.toml", router_ip, hosts["sim"].address,
                             crater_file)

        def start_router() -> None:
            hosts["router"].start("router", "router", "--config", str(ROUTER_CONFIG),
                                  "--listen", "tls/0.0.0.0:7447", env={})

        def service(host: str, user: str, *args: str) -> None:
            hosts[host].start(f"{args[0]}-{user}", *args, "--lab", str(lab_file),
                              env=identity_env(secrets, user, endpoint))

        start_router()
        service("sim", "sim", "sim")
        service("sim", "tracker", "tracker")
        service("gantry", "gantry", "gantry")
        service("ptz", "ptz1", "ptz", "--instance", "ptz1")

        def bus(user: str) -> Bus:
            settings = identity(secrets, user, endpoint)
            sessions.append(open_when_up(settings, timeout=20))
            return Bus(sessions[-1], BusSettings(zenoh=settings))

        yield {"lan": lan, "hosts": hosts, "bus": bus, "start_router": start_router,
               "crane": ModbusCrane(hosts["sim"].address, 5020, timeout_s=0.2),
               "logs": tmp_path}
    finally:
        for host in hosts.values():
            host.stop_all()
        for session in sessions:
            session.close()
        lan.close()


def _serve_true_pose(calib: Bus) -> None:
    """Play the calibration service: answer the PTZ service's question with the camera's true
    pose, and publish it (a PTZ service takes a pose only from such an answer)."""
    cam = SimSettings().cameras[0]
    pose = m.CameraPose(measured_s=time.time(), camera=cam.name, **Pose.of(cam).fields(),
                        focal_px=743.1, mean_error_px=0.5, passpoints=100)
    calib.serve_latest(keys.CALIB_POSE, lambda: pose, camera=cam.name)
    calib.publish(keys.CALIB_POSE, pose, camera=cam.name)


def _read(crane: ModbusCrane):
    try:
        return crane.read()
    except CraneError:
        return None


@pytest.mark.system
@pytest.mark.timeout(240)
def test_the_chain_across_hosts_survives_cut_links_and_a_router_restart(lab: dict) -> None:
    monitor, calib = lab["bus"]("monitor"), lab["bus"]("calib")
    states: list[m.CraneState] = []
    setpoints: list[m.CraneSetpoint] = []
    ptz: list[m.PtzState] = []
    health: list[m.ServiceHealth] = []
    monitor.subscribe(keys.GANTRY_STATE, states.append, latest=False)
    monitor.subscribe(keys.GANTRY_SETPOINT, setpoints.append, latest=False)
    monitor.subscribe(keys.PTZ_STATE, ptz.append, latest=False)
    monitor.subscribe(keys.HEALTH, health.append, latest=False)
    operator = Operator(lab["bus"]("operator"))  # the crane moves once an operator arms it
    operator.arm_within(60)
    wait_for(lambda: any(s.status == "tracking" for s in states), timeout=60, period=0.2)
    _serve_true_pose(calib)
    wait_for(lambda: ptz and ptz[-1].status == "tracking" and ptz[-1].aim_error_deg < 3.0,
             timeout=30, period=0.2)
    crane = lab["crane"]
    wait_for(lambda: (r := _read(crane)) is not None and r.moving and r.enabled, timeout=10)

    # --- the gantry's cable is pulled: the crane's watchdog stops it ----------------------------
    lab["lan"].cut("gantry")
    cut_at = time.time()
    tripped = wait_for(lambda: (r := _read(crane)) is not None and r.watchdog_tripped
                       and time.time(), timeout=3, period=0.01)
    print(f"watchdog tripped {tripped - cut_at:.3f} s after the cut")
    assert tripped - cut_at <= 0.55
    wait_for(lambda: (r := _read(crane)) is not None and not r.moving, timeout=3)
    time.sleep(1.5)  # the subject: it stays stopped
    reading = _read(crane)
    assert reading is not None and not reading.enabled and not reading.moving

    # --- plugged back in: the gantry is stopped (the watchdog's fault is latched) and leaves
    # the crane alone until an operator resets and arms; then tracking resumes, never with a
    # setpoint from before
    before = _read(crane)
    assert before is not None
    lab["lan"].plug("gantry")
    wait_for(lambda: any(s.mode == "stopped" and "watchdog" in s.mode_reason
                         for s in states), timeout=5, period=0.1)
    time.sleep(1.0)  # the subject: a second in which the gantry leaves the crane alone
    reading = _read(crane)
    assert reading is not None and not reading.enabled and reading.watchdog_tripped
    assert operator.send("reset").accepted
    assert operator.arm_within(10).accepted
    plugged_at = time.time()
    targets: list[tuple[float, float, float]] = []  # each new target the crane took, and when
    last = [(before.target_x_mm, before.target_y_mm)]

    def watched_for_six_seconds() -> bool:
        r = _read(crane)
        if r is not None and (r.target_x_mm, r.target_y_mm) != last[-1]:
            last.append((r.target_x_mm, r.target_y_mm))
            targets.append((time.time(), *last[-1]))
        return time.time() >= plugged_at + 6
    wait_for(watched_for_six_seconds, timeout=10, period=0.02)
    tracking = [s.measured_s for s in states
                if s.status == "tracking" and s.measured_s > plugged_at]
    assert tracking, "tracking did not resume"
    resumed_at = min(tracking)
    print(f"tracking again {resumed_at - plugged_at:.2f} s after the operator armed it")
    assert resumed_at - plugged_at <= 3.0
    assert targets, "the crane took no setpoint after the link came back"
    for seen_at, x, y in targets:
        match = [s for s in setpoints if abs(s.x_mm - x) <= 1.0 and abs(s.y_mm - y) <= 1.0]
        assert match, f"target ({x:.0f}, {y:.0f}) is no setpoint the gantry published"
        newest = max(s.measured_s for s in match)
        assert newest >= plugged_at - STALE_AFTER_S, (
            f"the crane executed a setpoint {seen_at - newest:.2f} s old after the link came back")

    # --- the router restarts: every service carries on without a restart of its own -----------
    pids = {h.service + "/" + h.instance: h.pid for h in health}
    lab["hosts"]["router"].kill("router")
    time.sleep(1.0)  # the router stays away a second: the outage is the subject
    restarted_at = time.time()
    lab["start_router"]()
    for name in ("sim/main", "tracker/main", "gantry/main", "ptz/ptz1"):
        service, instance = name.split("/")

        def heard_again(s: str = service, i: str = instance) -> bool:
            return any((h.service, h.instance) == (s, i) and h.measured_s > restarted_at
                       for h in health)

        wait_for(heard_again, timeout=20, period=0.2)
    after = {f"{h.service}/{h.instance}": h.pid for h in health if h.measured_s > restarted_at}
    for name in ("sim/main", "tracker/main", "gantry/main", "ptz/ptz1"):
        assert after[name] == pids[name], f"{name} was restarted"
    wait_for(lambda: any(s.status == "tracking" and s.measured_s > restarted_at + 0.5
                         for s in states), timeout=15, period=0.2)
    wait_for(lambda: any(p.status == "tracking" and p.measured_s > restarted_at for p in ptz),
             timeout=15, period=0.2)
    for label, proc in [(k, p) for h in lab["hosts"].values() for k, p in h.procs.items()]:
        assert proc.poll() is None, f"{label} exited; see {lab['logs']}/{label}.log"
