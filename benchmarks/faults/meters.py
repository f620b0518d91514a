"""What the campaign watches, from outside as a lab would."""

from __future__ import annotations

import threading
import time

import numpy as np
import zenoh
from pymodbus.client import ModbusTcpClient

from benchmarks.faults.rows import POLL_S
from common import keys
from common import messages as m
from common.bus import Bus
from common.crane_registers import DEFAULT_MAP


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
        self.ptz: list[tuple[float, m.PtzTruth, m.RobotTruth]] = []  # t, camera, robot then
        bus.subscribe(keys.TRUTH_PTZ, self._on_ptz, latest=False)
        self.ptz_states: list[m.PtzState] = []  # what the PTZ services say (status manual)
        bus.subscribe(keys.PTZ_STATE, self.ptz_states.append, latest=False)
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

    def _on_ptz(self, msg: m.PtzTruth) -> None:
        if self.robot is not None:
            with self.lock:
                self.ptz.append((time.monotonic(), msg, self.robot))

    def ptz_window(self, camera: str, start: float,
                   end: float | None = None) -> list[tuple[m.PtzTruth, m.RobotTruth]]:
        end = end if end is not None else time.monotonic()
        with self.lock:
            return [(head, robot) for t, head, robot in self.ptz
                    if start <= t <= end and head.camera == camera]

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
