"""The doctor's checks of the running lab on the bus and of this host: the tracking camera's
frames, each PTZ camera's stored pose, the hosts' clocks (the services' own health messages,
stamped by each host's clock), room for recordings, and the router's access control against
what the lab file renders."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from common import keys
from common import messages as m
from common.bus import Bus
from services.doctor.table import Check, failed, passed, skipped


def listen(bus: Bus, seconds: float) -> tuple[list[m.CameraFrame], dict[str, float]]:
    """What comes on the bus in ``seconds``: the tracking camera's frames, and per host the
    least (arrival − sent) of its services' health messages: its clock's offset from this
    host's (plus the bus's least delay, milliseconds)."""
    frames: list[m.CameraFrame] = []
    offsets: dict[str, float] = {}
    lock = threading.Lock()

    def on_health(msg: m.ServiceHealth) -> None:
        offset = time.time() - msg.sent_s
        with lock:
            offsets[msg.host] = min(offset, offsets.get(msg.host, offset))

    bus.subscribe(keys.GANTRY_FRAME, frames.append, latest=False)
    bus.subscribe(keys.HEALTH, on_health, latest=False)
    time.sleep(seconds)  # the listening window itself
    with lock:
        return list(frames), dict(offsets)


def tracking_frames(frames: list[m.CameraFrame], seconds: float, min_hz: float) -> Check:
    row = "tracking camera"
    rate = len(frames) / seconds
    if rate < min_hz:
        return failed(row, f"{len(frames)} frames on {keys.GANTRY_FRAME.key('stb')} in "
                      f"{seconds:g} s ({rate:.1f}/s, at least {min_hz:g}/s needed)",
                      "start stb camera on the tracking camera's host ([camera] source), "
                      "or the sim")
    last = frames[-1]
    return passed(row, f"{rate:.1f} frames/s from {last.camera!r}, {last.width_px}×"
                       f"{last.height_px} {last.encoding}")


def clocks(offsets: dict[str, float], tolerance_s: float) -> Check:
    row = "clocks"
    if not offsets:
        return failed(row, "no service's health message came", "start the lab (stb up), or "
                      "point --connect / [bus.zenoh] connect at its router")
    said = ", ".join(f"{host} {offset * 1000:+.0f} ms" for host, offset in sorted(offsets.items()))
    off = {h: o for h, o in offsets.items() if abs(o) > tolerance_s}
    if off:
        return failed(row, f"against this host: {said}",
                      f"set {', '.join(sorted(off))} to the lab's time server (chrony/NTP): "
                      f"more than {tolerance_s * 1000:.0f} ms off")
    return passed(row, f"within {tolerance_s * 1000:.0f} ms of this host: {said}")


def pose(bus: Bus, camera: str, timeout_s: float) -> Check:
    row = f"pose of {camera}"
    answers = bus.query_latest(keys.CALIB_POSE, timeout_s=timeout_s, camera=camera)
    if not answers:
        return failed(row, "the calibration service has none (or is not running)",
                      f"start calib and calibrate: stb calib collect --camera {camera}")
    p = max(answers, key=lambda a: a.measured_s)
    return passed(row, f"solved {_ago(time.time() - p.measured_s)}: ({p.x_mm:.0f}, "
                       f"{p.y_mm:.0f}, {p.z_mm:.0f}) mm, {p.mean_error_px:.2f} px from "
                       f"{p.passpoints} passpoints")


def _ago(seconds: float) -> str:
    minutes = seconds / 60
    if minutes < 1:
        return "just now"
    if minutes < 120:
        return f"{minutes:.0f} min ago"
    hours = minutes / 60
    return f"{hours:.0f} h ago" if hours < 48 else f"{hours / 24:.0f} days ago"


def disk(folder: Path, min_free_gb: float) -> Check:
    row = "disk for recordings"
    existing = next(p for p in [folder.resolve(), *folder.resolve().parents] if p.exists())
    free_gb = shutil.disk_usage(existing).free / 1e9
    if free_gb < min_free_gb:
        return failed(row, f"{folder}: {free_gb:.2f} GB free (at least {min_free_gb:g} GB: an "
                      "hour of the lab's recording)", "free space there, or set [web] "
                      "recordings_dir to a larger disk")
    return passed(row, f"{folder}: {free_gb:.1f} GB free")


def access_control(config: Path | None, lab: Path | None) -> Check:
    """The router's configuration against what ``stb deploy render`` makes of the lab file
    (run as the command, into a folder of its own)."""
    row = "router access control"
    if config is None:
        return skipped(row, "no router configuration: an open bus (stb up without "
                       "[router] config_file), nothing to check")
    try:
        text = config.read_text()
    except OSError as err:
        return failed(row, f"{config}: {err.strerror}", "name the router's configuration "
                      "(--router-config or [router] config_file)")
    if "access_control" not in text:
        return skipped(row, f"{config} has no access control: an open bus")
    with tempfile.TemporaryDirectory(prefix="stb-doctor-") as folder:
        done = subprocess.run([sys.executable, "-m", "services.cli", "deploy", "render",
                               "--out", folder, *(["--lab", str(lab)] if lab else [])],
                              capture_output=True, text=True, timeout=60)
        if done.returncode != 0:
            said = (done.stderr.strip().splitlines() or ["no answer"])[-1]
            return failed(row, f"stb deploy render: {said}", "correct the lab file's "
                          "[ptz.cameras] (a camera's name is its bus identity)")
        rendered = (Path(folder) / "deploy" / "zenoh" / "router.json5").read_text()
    if text != rendered:
        return failed(row, f"{config} is not what stb deploy render makes of the lab file: "
                      f"{_first_difference(rendered, text)}", "stb deploy render --lab LAB, "
                      "then restart the router (docs/deployment.md)")
    return passed(row, f"{config}: each identity's rules as the lab file renders them")


def _first_difference(expected: str, actual: str) -> str:
    lines = set(actual.splitlines())
    missing = [line.strip() for line in expected.splitlines()
               if line.strip() and line not in lines]
    if missing:
        return f"{len(missing)} line(s) missing, the first: {missing[0][:80]}"
    return "lines added or moved"
