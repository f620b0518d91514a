"""The doctor's round: the lab file's sections read as each service reads them (a section that
does not validate is a failed row, and its checks are left out), then every check in turn,
each said as it starts (``say``: progress on stderr)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from common.bus import Bus, BusUnreachable, open_session
from common.errors import ConfigError
from common.lab_views import LabCameras
from common.settings import ServiceSettings, load_settings
from services.doctor import devices
from services.doctor import lab as on_bus
from services.doctor.settings import DoctorSettings
from services.doctor.table import Check, failed
from services.registry import SERVICES, settings_class


def examine(lab: Path | None, settings: DoctorSettings, say: Callable[[str], None]
            ) -> list[Check]:
    checks: list[Check] = []
    sections: dict[str, Any] = {}
    for name in ("tracker", "gantry", "calib", "observation", "web", "router"):
        sections[name] = _section(lab, settings_class(SERVICES[name]), checks)
    cameras = _section(lab, LabCameras, checks)
    timeout = settings.timeout_s
    tracker, gantry, calib = sections["tracker"], sections["gantry"], sections["calib"]
    if tracker is not None:
        say(f"motion capture at {tracker.qtm_host}:{tracker.qtm_port} ...")
        checks.append(devices.mocap(tracker.qtm_host, tracker.qtm_port,
                                    _labels(tracker, gantry, calib, settings), timeout))
    for name, connection in (cameras.cameras.items() if cameras is not None else []):
        say(f"PTZ camera {name} at {connection.url} ...")
        checks.append(devices.ptz_camera(name, connection, timeout))
    if gantry is not None:
        say(f"crane controller at {gantry.crane_host}:{gantry.crane_port} ...")
        checks.append(devices.crane(gantry.crane_host, gantry.crane_port, gantry.crane,
                                    (gantry.x_min_mm, gantry.x_max_mm, gantry.y_min_mm,
                                     gantry.y_max_mm), timeout))
    if sections["observation"] is not None:
        say("observation camera ...")
        checks.append(devices.observation_camera(sections["observation"].connection(),
                                                 timeout))
    checks += _bus_checks(settings, list(cameras.cameras) if cameras is not None else [], say)
    if sections["web"] is not None:
        checks.append(on_bus.disk(sections["web"].recordings_dir, settings.min_free_gb))
    router = sections["router"]
    config = settings.router_config or (router.config_file if router is not None else None)
    checks.append(on_bus.access_control(config, lab))
    return checks


def _section(lab: Path | None, cls: type[ServiceSettings], checks: list[Check]) -> Any:
    try:
        return load_settings(cls, lab)
    except ConfigError as err:
        checks.append(failed(f"lab file [{cls.section}]", str(err)[:300],
                             "correct the field it names (stb config check --lab FILE)"))
        return None


def _labels(tracker: Any, gantry: Any, calib: Any, settings: DoctorSettings) -> dict[str, str]:
    """The motion-capture labels the lab uses, and what for."""
    needed = {tracker.robot_label: "the robot, [tracker] robot_label"} \
        if tracker.robot_label else {}
    if gantry is not None and gantry.crane_check_mm > 0:
        needed[gantry.crane_marker] = "the crane's carriage, [gantry] crane_marker"
    if calib is not None and calib.marker_label:
        needed[calib.marker_label] = "the calibration wand, [calib] marker_label"
    needed |= {t: "[doctor] targets" for t in settings.targets}
    return needed


def _bus_checks(settings: DoctorSettings, cameras: list[str], say: Callable[[str], None]
                ) -> list[Check]:
    say(f"the bus: listening for {settings.listen_s:g} s ...")
    try:
        session = open_session(settings.zenoh_settings())
    except BusUnreachable as err:
        why = str(err).split(" at /", 1)[0][:200]  # Zenoh's source location left out
        fix = "start the lab's router (stb up), or set --connect / [bus.zenoh] connect"
        return [failed(row, f"the bus: {why}", fix)
                for row in ("tracking camera", "clocks", *(f"pose of {c}" for c in cameras))]
    bus = Bus(session, settings.bus)
    try:
        frames, offsets = on_bus.listen(bus, settings.listen_s)
        checks = [on_bus.tracking_frames(frames, settings.listen_s, settings.min_frame_hz),
                  on_bus.clocks(offsets, settings.clock_tolerance_s)]
        checks += [on_bus.pose(bus, camera, settings.timeout_s) for camera in cameras]
        return checks
    finally:
        bus.close()
        session.close()
