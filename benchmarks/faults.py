"""Fault campaign: the whole simulated lab under the faults a lab meets, and what held.

    .venv/bin/python -m benchmarks.faults [--per-key 10000] [--churn 4000] [--json FILE]
    .venv/bin/python -m benchmarks.faults --short        # a few seconds per fault (make test)

Starts ``stb up`` with every service (router, sim, tracker, calib with both cameras' poses
stored, ptz1, ptz2, gantry, web) on free loopback ports, arms the gantry as an operator and
waits until the crane and both cameras follow the robot. Then, one after the other:

* fuzz: ``--per-key`` payloads on every key a service subscribes to (random bytes, broken
  msgpack, each key's message with fields missing, extra, mistyped or extreme);
* key churn: 8 garbage bytes on each of ``--churn`` distinct keys under subscribed wildcards;
* decode bombs: tracking frames whose JPEG header declares 24000×24000 pixels;
* spoofed frames: a bright spot far from the robot, 30 frames a second for a few seconds;
* a spoofed camera pose (ptz1 turned 40°, at the version PTZ services hold, measured now);
* SIGKILL of each service (the router last);
* SIGSTOP of the gantry for 0.3, 1 and 3 s and of the tracker for 2 s;
* a foreign Modbus client writing setpoints beside the gantry's.

Measured from outside, as a lab would: liveliness tokens and health messages on the bus, the
sim's true crane and robot (``stb/sim/truth/**``), the setpoints and estimates the gantry
publishes, the crane controller's status registers read over Modbus at 100 Hz (reads are not
activity for its watchdog), and each service's resident memory from /proc. The last lines
are the table of goals and figures; docs/reliability.md holds one run's.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import msgpack
import numpy as np
import zenoh
from pymodbus.client import ModbusTcpClient

from common import codec, keys
from common import messages as m
from common.bus import Bus, open_session
from common.crane_registers import DEFAULT_MAP, ENABLED, FAULTED
from common.settings import BusSettings, ZenohSettings
from common.wiredoc import EXAMPLES
from services.calib.store import PoseStore
from services.gantry.settings import GantrySettings
from tests.calib.test_demo_calibration import MOUNTS
from tests.ports import free_port
from tests.sim.test_sim_service import write_lab

ROOT = Path(__file__).resolve().parents[1]
SERVICES = ["router", "sim", "tracker", "calib", "ptz:ptz1", "ptz:ptz2", "gantry", "web"]
ALIVE = {"sim": "sim/main", "tracker": "tracker/main", "calib": "calib/main",
         "ptz:ptz1": "ptz/ptz1", "ptz:ptz2": "ptz/ptz2", "gantry": "gantry/main",
         "web": "web/main"}
# Keys our meters read and that a single service writes (the secured lab lets only it):
# fuzzing them would fool the meters, not the services.
MEASURED = {keys.TRUTH_CRANE, keys.TRUTH_ROBOT, keys.GANTRY_SETPOINT, keys.GANTRY_ESTIMATE,
            keys.GANTRY_STATE, keys.HEALTH}
# Commands are fuzzed with invalid payloads only: a valid one is obeyed, which is what it is for
# (a valid collect request starts a collection); in the secured lab only the operator sends them.
COMMANDS = {keys.GANTRY_COMMAND, keys.CALIB_COLLECT, keys.PTZ_CALIBRATION}
GOAL_ALIVE_S = 2.0
GOAL_WATCHDOG_S = 0.5
GOAL_MEMORY_MB = 20.0
GOAL_FLAT_MB = 5.0  # the same fault again: memory that grew once must not grow again
GOAL_POSE_REPORTED_S = 5.0
GOAL_FOREIGN_STOP_S = 1.0
POLL_S = 0.01


@dataclass
class Row:
    fault: str
    goal: str
    measured: str
    held: bool
    figures: dict = field(default_factory=dict)
    misses: list[str] = field(default_factory=list)  # which part of the goal did not hold

    def __post_init__(self) -> None:
        if not self.held and not self.misses:
            self.misses = ["goal"]


# --- the lab ---------------------------------------------------------------------------------


@contextmanager
def running_lab(folder: Path) -> Iterator[tuple[subprocess.Popen, Path, str]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    lab, _ = write_lab(folder, endpoint, folder / "crater.npz")
    services = ", ".join(f'"{s}"' for s in SERVICES)
    with open(lab, "a") as f:
        f.write(f'[router]\nlisten = ["{endpoint}"]\n[up]\nlog_dir = "{folder / "logs"}"\n'
                f'services = [{services}]\n[web]\nport = {free_port()}\n'
                f'height_map = "{folder / "crater.npz"}"\n')
    store = PoseStore(folder / "calib")
    for camera, mount in MOUNTS.items():  # as a finished calibration leaves them
        store.save(m.CameraPose(measured_s=time.time(), camera=camera, x_mm=mount.x_mm,
                                y_mm=mount.y_mm, z_mm=mount.z_mm, rx_deg=mount.rx_deg,
                                ry_deg=mount.ry_deg, rz_deg=mount.rz_deg, focal_mm=3.8,
                                mean_error_px=1.5, passpoints=100, version=1), {})
    with open(folder / "up.log", "w") as log:
        up = subprocess.Popen([sys.executable, "-m", "services.cli", "up", "--lab", str(lab),
                               "--no-view"], cwd=ROOT, stdout=log, stderr=subprocess.STDOUT,
                              env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        yield up, lab, endpoint
    finally:
        up.send_signal(signal.SIGINT)
        try:
            up.wait(30)
        except subprocess.TimeoutExpired:
            up.kill()
            up.wait()


def _children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(p) for p in text.split()]


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def _status(pid: int, field: str) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(f"{field}:"):
                return float(line.split()[1])
    except OSError:
        pass
    return float("nan")


def private_mb(pid: int) -> float:
    """A process's own resident memory (RssAnon): what it allocated. Not the shared memory it
    maps: Zenoh hands messages over 3 kB between processes on one host through each sender's
    16 MiB shared-memory pool, which every receiver maps once it gets such a message from that
    sender (it counts in each one's VmRSS, in 17 MiB steps, but exists once)."""
    return _status(pid, "RssAnon") / 1024


def shared_mb(pid: int) -> float:
    return _status(pid, "RssShmem") / 1024


def threads(pid: int) -> float:
    return _status(pid, "Threads")


def wait_until(predicate: Callable[[], object], timeout: float, period: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(period)
    return bool(predicate())


# --- what the campaign watches ---------------------------------------------------------------


class Meters:
    """Everything measured from outside: bus, liveliness, Modbus status, /proc."""

    def __init__(self, session: zenoh.Session, bus: Bus, crane_port: int) -> None:
        self.bus, self.lock = bus, threading.Lock()
        self.alive: list[tuple[float, str, str]] = []
        self._liveliness = session.liveliness().declare_subscriber(
            "stb/alive/**", self._on_alive, history=True)
        self.health: dict[str, tuple[float, m.ServiceHealth]] = {}
        self.crane: list[tuple[float, float, float, float]] = []  # t, x, y, distance to robot
        self.robot: m.RobotTruth | None = None
        self.setpoints: list[tuple[float, m.CraneSetpoint, float]] = []  # t, msg, estimate age
        self.estimate_s = 0.0
        self.robot_ages: list[tuple[float, float]] = []  # arrival, sent_s - measured_s
        self.poses: list[tuple[float, m.CameraPose]] = []
        self.modbus: list[tuple[float, int]] = []  # t, status bits
        self.states: list[m.CraneState] = []
        self.replies: list[m.GantryCommandReply] = []
        bus.subscribe(keys.HEALTH, self._on_health, latest=False)
        bus.subscribe(keys.TRUTH_ROBOT, self._on_robot, latest=False)
        bus.subscribe(keys.TRUTH_CRANE, self._on_crane, latest=False)
        # one subscription for both, so that they are seen in the order they were published:
        # each setpoint's estimate age is from the estimate that went out before it
        bus.subscribe_any(f"{bus.prefix}/gantry/*", self._on_gantry, latest=False)
        bus.subscribe(keys.TRACKER_ROBOT, self._on_tracked, latest=False, max_age_s=1e9)
        bus.subscribe(keys.CALIB_POSE, lambda p: self._add(self.poses, p), latest=False)
        self.stops: list[tuple[float, str]] = []  # when the gantry said it stopped, and why
        bus.subscribe(keys.GANTRY_STATE, self._on_state, latest=False)
        bus.subscribe(keys.GANTRY_COMMAND_REPLY, self.replies.append, latest=False)
        self.stop = threading.Event()
        self._modbus = threading.Thread(target=self._poll_modbus, args=(crane_port,),
                                        daemon=True)
        self._modbus.start()

    def _add(self, target: list, item: object) -> None:
        with self.lock:
            target.append((time.monotonic(), item))

    def _on_alive(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.alive.append((time.monotonic(), str(sample.key_expr), str(sample.kind)))

    def _on_state(self, msg: m.CraneState) -> None:
        if msg.mode == "stopped" and (not self.states or self.states[-1].mode != "stopped"):
            with self.lock:
                self.stops.append((time.monotonic(), msg.mode_reason))
        self.states.append(msg)

    def _on_health(self, msg: m.ServiceHealth) -> None:
        with self.lock:
            self.health[f"{msg.service}/{msg.instance}"] = (time.monotonic(), msg)

    def _on_robot(self, msg: m.RobotTruth) -> None:
        self.robot = msg

    def _on_crane(self, msg: m.CraneTruth) -> None:
        robot = self.robot
        gap = float(np.hypot(msg.x_mm - robot.x_mm, msg.y_mm - robot.y_mm)) if robot else 0.0
        with self.lock:
            self.crane.append((time.monotonic(), msg.x_mm, msg.y_mm, gap))

    def _on_gantry(self, item: tuple[str, m.Message | dict]) -> None:
        msg = item[1]
        if isinstance(msg, m.RobotEstimate):
            self.estimate_s = max(self.estimate_s, msg.measured_s)
        elif isinstance(msg, m.CraneSetpoint):
            with self.lock:
                self.setpoints.append((time.monotonic(), msg, msg.measured_s - self.estimate_s))

    def _on_tracked(self, msg: m.RobotPosition) -> None:
        with self.lock:
            self.robot_ages.append((time.monotonic(), msg.sent_s - msg.measured_s))

    def _poll_modbus(self, port: int) -> None:
        client = ModbusTcpClient("127.0.0.1", port=port, timeout=0.5, retries=0)
        while not self.stop.is_set():
            try:
                reply = client.read_input_registers(DEFAULT_MAP.status, count=1,
                                                    device_id=DEFAULT_MAP.unit_id)
                if not reply.isError():
                    with self.lock:
                        self.modbus.append((time.monotonic(), reply.registers[0]))
            except Exception:  # noqa: BLE001 - the sim restarting: try again
                client.close()
            time.sleep(POLL_S)
        client.close()

    # --- queries ---

    def pid(self, service: str) -> int | None:
        name = service.replace(":", "/") if ":" in service else f"{service}/main"
        with self.lock:
            entry = self.health.get(name)
        return entry[1].pid if entry else None

    def alive_again(self, key: str, after: float) -> float | None:
        with self.lock:
            return next((t - after for t, k, kind in self.alive if k == f"stb/alive/{key}"
                         and t > after and kind == str(zenoh.SampleKind.PUT)), None)

    def deaths(self, since: float) -> list[str]:
        with self.lock:
            return [k for t, k, kind in self.alive
                    if t > since and kind == str(zenoh.SampleKind.DELETE)]

    def health_heard_after(self, after: float) -> set[str]:
        with self.lock:
            return {name for name, (t, _) in self.health.items() if t > after}

    def crane_window(self, start: float, end: float | None = None) -> np.ndarray:
        end = end if end is not None else time.monotonic()
        with self.lock:
            rows = [row for row in self.crane if start <= row[0] <= end]
        return np.array(rows).reshape(-1, 4)

    def first_status(self, after: float, bit: int, present: bool) -> float | None:
        with self.lock:
            return next((t - after for t, bits in self.modbus
                         if t > after and bool(bits & bit) == present), None)

    def status_at(self, t: float) -> int:
        """The status bits read next after ``t`` (0 if none)."""
        with self.lock:
            return next((bits for at, bits in self.modbus if at >= t), 0)

    def setpoints_since(self, start: float) -> list[tuple[float, m.CraneSetpoint, float]]:
        with self.lock:
            return [row for row in self.setpoints if row[0] >= start]

    def close(self) -> None:
        self.stop.set()
        self._modbus.join(2)
        self._liveliness.undeclare()


# --- the campaign ----------------------------------------------------------------------------


class Campaign:
    def __init__(self, up: subprocess.Popen, meters: Meters, bus: Bus, session: zenoh.Session,
                 short: bool, crane_port: int) -> None:
        self.up, self.meters, self.bus, self.session = up, meters, bus, session
        self.short, self.crane_port = short, crane_port
        self.gantry = GantrySettings()
        self.max_age_s = BusSettings().max_age_s
        self.rows: list[Row] = []
        self.rng = random.Random(1)
        self.commands = 0
        self.threads_before: dict[str, float] = {}
        self.shared_before: dict[str, float] = {}

    def log(self, text: str) -> None:
        print(f"[{time.strftime('%H:%M:%S')}] {text}", flush=True)

    # --- the operator ---

    def operator(self, command: str) -> m.GantryCommandReply | None:
        self.commands += 1
        ident = f"campaign-{self.commands}"
        self.bus.publish(keys.GANTRY_COMMAND, m.GantryCommand(
            measured_s=time.time(), command=command, operator="fault campaign",  # type: ignore[arg-type]
            reason="fault campaign", id=ident))
        found: list[m.GantryCommandReply] = []
        wait_until(lambda: found.extend(r for r in self.meters.replies if r.id == ident)
                   or found, timeout=3)
        return found[0] if found else None

    def follow(self, timeout: float = 60.0) -> bool:
        """Reset a latched fault if there is one, arm, and wait until the crane tracks."""
        def tracking() -> bool:
            states = self.meters.states
            if states and states[-1].mode == "armed" and states[-1].status == "tracking":
                return True
            if states and states[-1].mode != "armed":
                self.operator("reset")
                reply = self.operator("arm")
                return False if reply is None else False
            return False
        return wait_until(tracking, timeout, period=0.5)

    def snapshot_memory(self) -> dict[str, float]:
        return {s: private_mb(self.meters.pid(s) or -1) for s in ALIVE}

    def shared_memory(self) -> dict[str, float]:
        return {s: shared_mb(self.meters.pid(s) or -1) for s in ALIVE}

    def settled_memory(self, timeout: float = 40.0) -> dict[str, float]:
        """Every service's own memory once none has changed by more than 2 MB in 3 s (1.5 s
        with ``--short``): a service that has just started still grows as it warms up, which
        is not the fault's doing."""
        history = [self.snapshot_memory()]
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            time.sleep(0.5 if self.short else 1.0)
            history.append(self.snapshot_memory())
            recent = history[-4:]
            if len(recent) == 4 and all(abs(r[s] - recent[0][s]) <= 2.0
                                        for r in recent for s in ALIVE):
                break
        self.threads_before, self.shared_before = self.threads(), self.shared_memory()
        return history[-1]

    def threads(self) -> dict[str, float]:
        return {s: threads(self.meters.pid(s) or -1) for s in ALIVE}

    def pids(self) -> dict[str, int | None]:
        return {s: self.meters.pid(s) for s in ALIVE}

    # --- steps ---

    def baseline(self) -> dict:
        # "tracking" comes while the crane still closes in on the robot
        time.sleep(3 if self.short else 5)
        start = time.monotonic()
        time.sleep(3 if self.short else 10)
        crane = self.meters.crane_window(start)
        return {"rms_mm": float(np.sqrt(np.mean(crane[:, 3] ** 2))),
                "max_mm": float(crane[:, 3].max())}

    def fuzz(self, per_key: int, again: bool = False) -> None:
        topics = [t for t in vars(keys).values() if isinstance(t, keys.Topic)
                  and t not in MEASURED]
        pids, memory, start = self.pids(), self.settled_memory(), time.monotonic()
        sent = 0
        for topic in topics:
            params = {name: "ptz1" for name in topic.params}
            key = topic.key(self.bus.prefix, **params)
            publisher = self.session.declare_publisher(key)
            for payload in fuzz_payloads(topic, per_key, self.rng):
                if topic in COMMANDS and _valid(topic, payload):
                    continue
                publisher.put(payload)
                sent += 1
                if sent % 2000 == 0:
                    time.sleep(0.01)  # the router's queues are bounded: a burst is dropped
            publisher.undeclare()
        time.sleep(2 if self.short else 3)
        for camera in MOUNTS:  # a fuzzed request may have started a collection: end it
            self.bus.publish(keys.CALIB_COLLECT, m.CollectRequest(
                measured_s=time.time(), camera=camera, action="cancel"), camera=camera)
        what = f"{per_key} payloads on each of {len(topics)} keys ({sent} in " \
            f"{time.monotonic() - start:.0f} s)"
        self._survived("fuzz" + " again" * again, what, start, pids, memory, again=again)

    def quiet(self) -> None:
        """The control: the same wait as a fault's, with no fault."""
        pids, memory, start = self.pids(), self.settled_memory(), time.monotonic()
        time.sleep(5)
        self._survived("nothing (control)", "5 s without a fault", start, pids, memory)

    def churn(self, count: int, again: bool = False) -> None:
        pids, memory, start = self.pids(), self.settled_memory(), time.monotonic()
        patterns = ["stb/ptz/churn{}/state", "stb/calib/churn{}/progress",
                    "stb/health/churn/{}", "stb/sim/truth/robot/churn{}"]
        for i in range(count):
            self.session.put(patterns[i % len(patterns)].format(i), os.urandom(8))
            if i % 1000 == 999:
                time.sleep(0.01)
        time.sleep(2 if self.short else 3)
        heard = self.meters.health_heard_after(time.monotonic() - 1.5)
        too_large = sum(s.dropped.get("too_large", 0) for k, s in self.bus.key_stats().items()
                        if k.startswith("stb/health/"))
        extra = {"health messages too large": too_large,
                 "services heard in the last 1.5 s": len(heard)}
        self._survived("key churn" + " again" * again, f"8 bytes on each of {count} distinct "
                       "keys", start, pids, memory, again=again, extra=extra,
                       ok=too_large == 0 and len(heard) >= len(ALIVE))

    def decode_bombs(self) -> None:
        pid = self.meters.pid("gantry")
        before, start = self.settled_memory()["gantry"], time.monotonic()
        bomb = jpeg_declaring(24000, 24000)
        for seq in range(20):
            self.bus.publish(keys.GANTRY_FRAME, m.CameraFrame(
                measured_s=time.time(), camera="tracking", seq=10**9 + seq, width_px=640,
                height_px=480, encoding="jpeg", data=bomb))
            time.sleep(0.05)
        time.sleep(2)
        after = private_mb(pid or -1)
        deaths = self.meters.deaths(start)
        held = not deaths and after - before <= GOAL_MEMORY_MB and self.meters.pid("gantry") == pid
        self.rows.append(Row("decode bombs", "no crash; the gantry's own memory ≤ +20 MB",
                             f"20 JPEGs declaring 24000×24000 in 640×480 frames: gantry "
                             f"{before:.0f} → {after:.0f} MB, restarts {len(deaths)}", held,
                             {"rss_before_mb": before, "rss_after_mb": after}))

    def spoofed_frames(self, baseline: dict) -> None:
        seconds = 3 if self.short else 8
        start = time.monotonic()
        frame = np.zeros((480, 640), np.uint8)
        cv2.circle(frame, (60, 60), 5, 255, -1)
        seq = 2 * 10**9
        while time.monotonic() - start < seconds:
            seq += 1
            self.bus.publish(keys.GANTRY_FRAME, m.CameraFrame(
                measured_s=time.time(), camera="tracking", seq=seq, width_px=640,
                height_px=480, encoding="mono8", data=frame.tobytes()))
            time.sleep(1 / 30)
        crane = self.meters.crane_window(start)
        worst = float(crane[:, 3].max()) if len(crane) else float("nan")
        bound = max(2 * baseline["max_mm"], baseline["max_mm"] + 100)
        self.rows.append(Row(
            "spoofed frames", "crane stays with the robot (max gap ≤ 2× the baseline's)",
            f"{seq - 2 * 10**9} frames with a spot 2 m off, over {seconds} s: crane–robot max "
            f"{worst:.0f} mm (baseline max {baseline['max_mm']:.0f} mm)", worst <= bound,
            {"max_gap_mm": worst}, [] if worst <= bound else ["gap"]))

    def spoofed_pose(self) -> None:
        held_version = max((p.version for _, p in self.meters.poses if p.camera == "ptz1"),
                           default=1)
        mount = MOUNTS["ptz1"]
        start = time.monotonic()
        self.bus.publish(keys.CALIB_POSE, m.CameraPose(
            measured_s=time.time(), camera="ptz1", x_mm=mount.x_mm, y_mm=mount.y_mm,
            z_mm=mount.z_mm, rx_deg=mount.rx_deg, ry_deg=mount.ry_deg,
            rz_deg=mount.rz_deg + 40.0, focal_mm=3.8, mean_error_px=0.5, passpoints=100,
            version=held_version), camera="ptz1")

        def answered() -> float | None:
            return next((t - start for t, p in list(self.meters.poses)
                         if t > start and p.version > held_version
                         and abs(p.rz_deg - mount.rz_deg) < 1e-6), None)

        def reported() -> float | None:
            with self.meters.lock:
                entry = self.meters.health.get("calib/main")
            ok = entry and entry[0] > start and "did not send" in entry[1].detail
            return entry[0] - start if ok else None

        wait_until(lambda: answered() is not None and reported() is not None, timeout=8)
        a, r = answered(), reported()
        held = a is not None and r is not None and max(a, r) <= GOAL_POSE_REPORTED_S
        self.rows.append(Row(
            "spoofed pose", "detected and reported ≤ 5 s",
            f"ptz1 turned 40° at the held version: true pose out-versioned after "
            f"{_s(a)}, calib health degraded after {_s(r)}", held,
            {"answered_s": a, "reported_s": r}))

    def kill_each(self) -> None:
        for service in [s for s in SERVICES if s != "router"]:
            pid = self.meters.pid(service)
            if pid is None:
                self.rows.append(Row(f"SIGKILL {service}", "alive ≤ 2 s", "no pid heard", False))
                continue
            at = time.monotonic()
            os.kill(pid, signal.SIGKILL)
            wait_until(lambda s=service, t=at: self.meters.alive_again(ALIVE[s], t) is not None,
                       20)
            back = self.meters.alive_again(ALIVE[service], at)
            figures = {"alive_again_s": back}
            text = f"alive again after {_s(back)}"
            held = back is not None and back <= GOAL_ALIVE_S
            if service == "gantry":
                trip = self.meters.first_status(at, ENABLED, present=False)
                figures["crane_disabled_s"] = trip
                text += f"; crane disabled after {_s(trip)}"
                held = held and trip is not None and trip <= GOAL_WATCHDOG_S + 2 * POLL_S
            if service in ("gantry", "sim"):  # it comes back disarmed; the crane disabled
                self.follow()
            self.rows.append(Row(f"SIGKILL {service}", "alive ≤ 2 s" + (
                "; crane disabled ≤ 0.5 s" if "crane_disabled_s" in figures else ""),
                text, held, figures))
            self.log(f"SIGKILL {service}: {text}")
            # the next kill once this one is up again (its health from the new process): each
            # restart measured alone, not while the one before still loads
            wait_until(lambda s=service, p=pid: self.meters.pid(s) not in (None, p), 10)
            time.sleep(0.3 if self.short else 1)
        self.router_restart()

    def router_restart(self) -> None:
        routers = [p for p in _children(self.up.pid) if "services.router" in _cmdline(p)]
        if not routers:
            self.rows.append(Row("router restart", "resumed ≤ 2 s", "no router process", False))
            return
        at = time.monotonic()
        os.kill(routers[0], signal.SIGKILL)
        names = {f"{s.replace(':', '/')}" if ":" in s else f"{s}/main" for s in ALIVE}
        wait_until(lambda: names <= self.meters.health_heard_after(at + 0.1), 30)
        heard = {}
        with self.meters.lock:
            for name in names:
                entry = self.meters.health.get(name)
                heard[name] = entry[0] - at if entry and entry[0] > at + 0.1 else None
        worst = max((v for v in heard.values() if v is not None), default=None)
        held = None not in heard.values() and worst is not None and worst <= GOAL_ALIVE_S + 1.0
        self.rows.append(Row(
            "router SIGKILL", "every service heard again ≤ 2 s after the router is back",
            f"router restarted by stb up; every service's health heard again after "
            f"{_s(worst)} (router restart included)", held, {"resumed_s": heard}))
        self.follow()

    def stall(self, service: str, seconds: float) -> None:
        pid = self.meters.pid(service)
        if pid is None:
            return
        at = time.monotonic()
        os.kill(pid, signal.SIGSTOP)
        time.sleep(seconds)
        os.kill(pid, signal.SIGCONT)
        resumed = time.monotonic()
        time.sleep(2)
        if service == "gantry":
            self._gantry_stall(seconds, at, resumed)
        else:
            ages = [age for t, age in self.meters.robot_ages if t > resumed]
            stale = sum(age > self.max_age_s for age in ages)
            self.rows.append(Row(
                f"SIGSTOP {service} {seconds:g} s",
                f"0 robot samples older than bus.max_age_s ({self.max_age_s} s) sent",
                f"{len(ages)} robot samples in 2 s after SIGCONT, {stale} older than "
                f"{self.max_age_s} s (oldest {max(ages, default=0):.2f} s)", stale == 0,
                {"stale_samples": stale, "samples": len(ages)}))

    def _gantry_stall(self, seconds: float, at: float, resumed: float) -> None:
        trip = self.meters.first_status(at, FAULTED, present=True)
        setpoints = self.meters.setpoints_since(resumed)
        stale = [age for t, sp, age in setpoints if not sp.hold and age > self.max_age_s
                 and self.meters.status_at(t) & ENABLED]
        expect_trip = seconds > GOAL_WATCHDOG_S
        tripped_in_time = trip is not None and trip <= GOAL_WATCHDOG_S + 2 * POLL_S
        held = (tripped_in_time if expect_trip else trip is None or trip > seconds) \
            and not stale
        ages = [age for _, sp, age in setpoints if not sp.hold]
        text = (f"watchdog tripped {_s(trip)} after SIGSTOP" if trip is not None and
                trip < seconds + 1 else "no watchdog trip") + \
            f"; {len(stale)} setpoints with an estimate older than {self.max_age_s} s " \
            "executed after SIGCONT"
        self.rows.append(Row(
            f"SIGSTOP gantry {seconds:g} s",
            "crane halted ≤ 0.5 s after the last write; 0 stale setpoints executed", text, held,
            {"watchdog_s": trip, "stale_setpoints": len(stale), "stale_ages_s": stale,
             "oldest_estimate_s": max(ages, default=None)}))
        self.log(f"SIGSTOP gantry {seconds:g} s: {text}")
        self.follow()

    def foreign_modbus(self, baseline: dict) -> None:
        """Another client writes setpoints 2 m outside the workspace at 10 Hz for 2 s."""
        client = ModbusTcpClient("127.0.0.1", port=self.crane_port, timeout=0.5, retries=0)
        start = time.monotonic()
        g = self.gantry
        written = 0
        for i in range(20):
            x = g.x_max_mm + 2000 if i % 2 else g.x_min_mm - 2000
            values = DEFAULT_MAP.encode("setpoint_x", x) + DEFAULT_MAP.encode("setpoint_y", 0)
            reply = client.write_registers(DEFAULT_MAP.setpoint_x, values,
                                           device_id=DEFAULT_MAP.unit_id)
            written += not reply.isError()
            time.sleep(0.1)
        client.close()
        time.sleep(1)
        crane = self.meters.crane_window(start)
        inside = bool(len(crane)) and bool(
            (crane[:, 1] >= g.x_min_mm).all() and (crane[:, 1] <= g.x_max_mm).all())
        worst = float(crane[:, 3].max()) if len(crane) else float("nan")
        with self.meters.lock:
            stopped = next((t - start for t, why in self.meters.stops
                            if t > start and "another Modbus client" in why), None)
        held = inside and stopped is not None and stopped <= GOAL_FOREIGN_STOP_S
        self.rows.append(Row(
            "foreign Modbus writer", "crane inside the workspace; the gantry stops it ≤ 1 s",
            f"{written} setpoint writes 2 m beyond the workspace over 2 s: the gantry stopped "
            f"the crane after {_s(stopped)}; crane x {crane[:, 1].min():.0f}…"
            f"{crane[:, 1].max():.0f} mm, max gap to the robot {worst:.0f} mm (baseline "
            f"{baseline['max_mm']:.0f})", held, {"stopped_s": stopped, "max_gap_mm": worst}))

    def totals(self, started: float) -> None:
        crane = self.meters.crane_window(started)
        g = self.gantry
        setpoints = self.meters.setpoints_since(started)
        outside = sum(not (g.x_min_mm <= sp.x_mm <= g.x_max_mm and
                           g.y_min_mm <= sp.y_mm <= g.y_max_mm) for _, sp, _ in setpoints)
        inside = bool(((crane[:, 1] >= g.x_min_mm) & (crane[:, 1] <= g.x_max_mm) &
                       (crane[:, 2] >= g.y_min_mm) & (crane[:, 2] <= g.y_max_mm)).all())
        self.rows.append(Row(
            "whole campaign", "0 setpoints outside the workspace; crane inside it",
            f"{len(setpoints)} setpoints, {outside} outside; crane x {crane[:, 1].min():.0f}…"
            f"{crane[:, 1].max():.0f}, y {crane[:, 2].min():.0f}…{crane[:, 2].max():.0f} mm",
            outside == 0 and inside, {"setpoints": len(setpoints), "outside": outside}))

    def _shared_text(self) -> str:
        if not self.shared_before:
            return ""
        service, grown = _largest(self.shared_before, self.shared_memory())
        return f"; shared memory mapped: {service} {grown:+.1f} MB" if grown > 1 else ""

    def _survived(self, fault: str, what: str, start: float, pids: dict, memory: dict,
                  extra: dict | None = None, ok: bool = True, again: bool = False) -> None:
        after = self.snapshot_memory()
        deaths = self.meters.deaths(start)
        grown = {s: after[s] - memory[s] for s in memory}
        worst = max(grown, key=lambda s: grown[s])
        bound = GOAL_FLAT_MB if again else GOAL_MEMORY_MB
        misses = ((["crash"] if deaths or self.pids() != pids else []) +
                  (["memory"] if grown[worst] > bound else []) + ([] if ok else ["check"]))
        extra_text = "".join(f"; {k} {v}" for k, v in (extra or {}).items())
        self.rows.append(Row(
            fault, f"0 crashes; every service's own memory ≤ +{bound:g} MB" +
            (" (no leak)" if again else ""),
            f"{what}: restarts {len(deaths)}, largest growth {worst} {grown[worst]:+.1f} MB"
            f"{extra_text}{self._shared_text()}", not misses,
            {"memory_before_mb": memory, "memory_after_mb": after,
             "threads_before": self.threads_before, "threads_after": self.threads(),
             "shared_before_mb": self.shared_before, "shared_after_mb": self.shared_memory(),
             **(extra or {})}, misses))
        self.log(f"{fault}: {self.rows[-1].measured}")


def _largest(before: dict[str, float], after: dict[str, float]) -> tuple[str, float]:
    grown = {s: after[s] - before[s] for s in before}
    worst = max(grown, key=lambda s: grown[s])
    return worst, grown[worst]


def _valid(topic: keys.Topic, payload: bytes) -> bool:
    try:
        codec.decode(topic.model, payload, max_bytes=topic.max_payload_bytes)
    except codec.DecodeError:
        return False
    return True


def _s(value: float | None) -> str:
    return "never" if value is None else f"{value:.2f} s"


# --- payloads --------------------------------------------------------------------------------


EXTREMES = [1e308, -1e308, 2**63, -(2**63), 0, -1, "", "x" * 70000, None, [], {}, True,
            b"\xff" * 100, [1.0] * 5000]


def fuzz_payloads(topic: keys.Topic, count: int, rng: random.Random) -> Iterator[bytes]:
    """Random bytes, broken msgpack, and the key's own message mutated field by field."""
    example = EXAMPLES.get(topic.model)
    base = example.model_dump(mode="python") if example is not None else {"measured_s": 1.0}
    names = list(base)
    for i in range(count):
        kind = i % 4
        if kind == 0:
            yield rng.randbytes(rng.randrange(1, 200))
        elif kind == 1:
            whole = msgpack.packb(base, use_bin_type=True)
            yield whole[:rng.randrange(0, len(whole))]
        else:
            doc = dict(base)
            name = rng.choice(names)
            if kind == 2:
                doc[name] = rng.choice(EXTREMES)
            elif rng.random() < 0.5:
                doc.pop(name, None)
            else:
                doc[f"extra{rng.randrange(100)}"] = 1
            doc["measured_s"] = time.time()
            yield msgpack.packb(doc, use_bin_type=True)


def jpeg_declaring(width: int, height: int) -> bytes:
    """A small JPEG whose frame header (SOF0) claims ``width``×``height`` pixels."""
    ok, data = cv2.imencode(".jpg", np.zeros((8, 8), np.uint8))
    raw = bytearray(data.tobytes())
    sof = raw.index(b"\xff\xc0")
    raw[sof + 5:sof + 7] = height.to_bytes(2, "big")
    raw[sof + 7:sof + 9] = width.to_bytes(2, "big")
    return bytes(raw)


# --- the command -----------------------------------------------------------------------------


STEPS = ["quiet", "fuzz", "churn", "bombs", "frames", "pose", "stalls", "tracker", "modbus", "kill"]


def run(short: bool, per_key: int, churn: int, folder: Path,
        only: list[str] | None = None) -> list[Row]:
    with running_lab(folder) as (up, lab, endpoint):
        ports = json.loads(json.dumps(_ports(lab)))
        settings = BusSettings(zenoh=ZenohSettings(mode="client", connect=[endpoint]))
        session = _open(settings.zenoh)
        bus = Bus(session, settings)
        meters = Meters(session, bus, ports["crane"])
        try:
            campaign = Campaign(up, meters, bus, session, short, ports["crane"])
            campaign.log("lab starting; waiting until every service is alive")
            if not wait_until(lambda: all(campaign.meters.pid(s) for s in ALIVE), 90, 0.5):
                raise SystemExit(f"the lab did not come up: see {folder / 'logs'}")
            if not campaign.follow(90):
                raise SystemExit(f"the crane never tracked: see {folder / 'logs'}")
            wait_until(lambda: any(p.camera == "ptz1" for _, p in meters.poses), 10)
            started = time.monotonic()
            baseline = campaign.baseline()
            campaign.log(f"baseline: crane–robot rms {baseline['rms_mm']:.0f} mm, "
                         f"max {baseline['max_mm']:.0f} mm")
            steps: dict[str, Callable[[], None]] = {
                "quiet": campaign.quiet,
                "fuzz": lambda: [campaign.fuzz(per_key, again) for again in (False, True)],
                "churn": lambda: [campaign.churn(churn, again) for again in (False, True)],
                "bombs": campaign.decode_bombs,
                "frames": lambda: campaign.spoofed_frames(baseline),
                "pose": campaign.spoofed_pose,
                "stalls": lambda: [campaign.stall("gantry", seconds) for seconds in
                                   ((0.3, 1.0) if short else (0.3, 1.0, 3.0))],
                "tracker": lambda: campaign.stall("tracker", 2.0),
                "modbus": lambda: campaign.foreign_modbus(baseline),
                "kill": campaign.kill_each}
            for name in only or list(steps):
                campaign.follow()  # each fault starts from a crane that follows the robot
                steps[name]()
            campaign.totals(started)
            return campaign.rows
        finally:
            meters.close()
            bus.close()
            session.close()


def _ports(lab: Path) -> dict:
    import tomllib

    doc = tomllib.loads(lab.read_text())
    return {"crane": doc["sim"]["crane"]["port"]}


def _open(settings: ZenohSettings) -> zenoh.Session:
    deadline = time.monotonic() + 30
    while True:
        try:
            return open_session(settings)
        except Exception:  # noqa: BLE001 - the router is still starting
            if time.monotonic() > deadline:
                raise
            time.sleep(0.3)


def table(rows: list[Row]) -> str:
    lines = ["| fault | goal | measured | held |", "|---|---|---|---|"]
    lines += [f"| {r.fault} | {r.goal} | {r.measured} | {'yes' if r.held else '**no**'} |"
              for r in rows]
    return "\n".join(lines)


IN_NAMESPACE = "STB_FAULTS_IN_NAMESPACE"


def in_own_namespace(argv: list[str]) -> int | None:
    """Run the campaign again inside a new network namespace (only its loopback, up), so
    that nothing it does reaches the host's network; None where that cannot be done (not
    root, no unshare or ip): the campaign then runs on free loopback ports."""
    if os.geteuid() != 0 or not shutil.which("unshare") or not shutil.which("ip"):
        return None
    probe = subprocess.run(["unshare", "--net", "true"], capture_output=True)
    if probe.returncode != 0:
        return None
    command = ["unshare", "--net", "sh", "-c", 'ip link set lo up && exec "$0" "$@"',
               sys.executable, "-m", "benchmarks.faults", *argv]
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    return subprocess.call(command, env={**os.environ, IN_NAMESPACE: "1", "PYTHONPATH": path})


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--short", action="store_true", help="a few seconds per fault")
    parser.add_argument("--per-key", type=int, default=None, help="fuzz payloads per key "
                        "(default 10000; --short: 300)")
    parser.add_argument("--churn", type=int, default=None, help="distinct keys (default 4000; "
                        "--short: 1000)")
    parser.add_argument("--only", nargs="+", choices=STEPS, help="these faults only")
    parser.add_argument("--json", type=Path, help="write the rows with their figures here")
    parser.add_argument("--keep", type=Path, help="the lab's folder (logs); default: a "
                        "temporary one, removed")
    parser.add_argument("--loopback", action="store_true", help="on this host's loopback "
                        "(default: in a network namespace of its own when run as root)")
    args = parser.parse_args(argv)
    argv = sys.argv[1:] if argv is None else argv
    if not args.loopback and os.environ.get(IN_NAMESPACE) != "1":
        code = in_own_namespace(argv)
        if code is not None:
            return code
    where = "in a network namespace of its own" if os.environ.get(IN_NAMESPACE) == "1" \
        else "on the host's loopback"
    print(f"fault campaign {where}", flush=True)
    per_key = args.per_key or (300 if args.short else 10_000)
    churn = args.churn or (1000 if args.short else 4000)
    began = time.monotonic()
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)
        rows = run(args.short, per_key, churn, args.keep, args.only)
    else:
        with tempfile.TemporaryDirectory(prefix="stb-faults-") as folder:
            rows = run(args.short, per_key, churn, Path(folder), args.only)
    print(table(rows))
    held = sum(r.held for r in rows)
    print(f"\n{held} of {len(rows)} held; campaign {time.monotonic() - began:.0f} s")
    if args.json:
        args.json.write_text(json.dumps([asdict(r) for r in rows], indent=1, default=str))
    return 0 if held == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
