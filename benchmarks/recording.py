"""What a recording costs: its size per minute and the recorder's load, with and without the
tracking camera's raw frames, the cameras' video and Foxglove's typed channels.

    .venv/bin/python -m benchmarks.recording [--seconds 30] [--video-fps 5]

Runs the whole simulated lab under ``stb up`` (every service, the gantry armed), then
``stb record`` as a user runs it, once per variant, each for ``--seconds``:

* every key (the default: the tracking camera's frames as H.264 video, not raw);
* that, plus both PTZ cameras' video (``--video ptz1 --video ptz2``, VAPIX MJPEG at
  ``--video-fps``, 704×576, recorded as H.264);
* that, with the raw frames too (``--raw-frames``: what a replay into a gantry needs);
* both cameras' video without Foxglove's typed channels (``--set typed=false``, the tracking
  camera's frames left out) — what the typed channels cost;
* the first minute of a fresh demo lab (``--first-minute``, another lab started for it): the
  cameras calibrated as ``make demo`` does (``config/demo.toml``'s passpoint count, the wand,
  the calibration snapshots ten a second a camera), then the robot followed; every camera —
  both PTZ cameras' video, the tracking camera, the observation camera — recorded from the
  lab's start for ``--seconds`` (60 by default then). The issue's bound: ≤ 30 MB a minute.

Per variant: the file's size per minute; how it splits (the messages' bytes before the file's
zstd compression: bus samples, video — H.264 channels and raw video frames —, JSON copies,
the other typed channels); the recorder's CPU (user +
system of the process over its run, a share of one core, and its peak resident memory); the
sim's CPU over the same time (the MJPEG streams are rendered and encoded by the sim; a real
camera does that in hardware).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from mcap.reader import make_reader

from benchmarks.faults.lab import open_when_up, running_lab
from benchmarks.tracker import _cpu_s, _lab_processes
from common import keys
from common.bus import Bus
from common.settings import BusSettings, ZenohSettings, load_settings
from services.args import Parser
from services.calib.settings import CalibSettings
from services.recording.typed import GANTRY_IMAGE
from tests.gantry.rig import Operator
from tests.uplab import SERVICES

ROOT = Path(__file__).resolve().parent.parent
FRAMES = "stb/gantry/camera/frame"


def variants(video_fps: float) -> list[tuple[str, list[str]]]:
    video = ["--video", "ptz1", "--video", "ptz2", "--video-fps", f"{video_fps:g}"]
    return [("every key (camera streams as H.264)", []),
            (f"… plus both cameras' video at {video_fps:g} fps", video),
            ("… with the raw frames too (`--raw-frames`)", [*video, "--raw-frames"]),
            ("both cameras' video, no typed channels (`--set typed=false`), no tracking frames",
             ["--exclude", FRAMES, *video, "--set", "typed=false"])]


def _group(topic: str) -> str:
    if topic.startswith("stb/video/") or topic == GANTRY_IMAGE or topic.endswith("/video"):
        return "video"
    if topic.startswith("stb/"):
        return "bus"
    return "json" if topic.startswith("json/") else "typed"


def bytes_by_group(path: Path) -> Counter:
    """The messages' bytes (before compression) by group: bus, video, json, typed."""
    out: Counter = Counter()
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            out[_group(channel.topic)] += len(message.data)
    return out


def record(lab: Path, crater: Path, out: Path, seconds: float, extra: list[str],
           sim_pid: int) -> dict:
    sim_before = _cpu_s(sim_pid)
    started = time.monotonic()
    proc = subprocess.Popen(
        [sys.executable, "-m", "services.cli", "record", str(out), "--lab", str(lab),
         "--duration", str(seconds), "--set", f"height_map={crater}", *extra],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.monotonic() - started
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"stb record failed: {proc.stderr.read() if proc.stderr else ''}")
    size = out.stat().st_size
    groups = bytes_by_group(out)
    return {"seconds": seconds, "file_mb": size / 1e6,
            "mb_per_min": size / 1e6 / seconds * 60,
            "raw_mb_by_group": {k: round(v / 1e6, 2) for k, v in groups.items()},
            "recorder_cpu": (usage.ru_utime + usage.ru_stime) / wall,
            "recorder_max_rss_mb": usage.ru_maxrss / 1024,
            "sim_cpu": (_cpu_s(sim_pid) - sim_before) / wall}


def run(seconds: float, video_fps: float, workdir: Path) -> list[dict]:
    results = []
    with running_lab(workdir) as (up, lab, endpoint):
        session = open_when_up(ZenohSettings(connect=[endpoint], connect_timeout_ms=0))
        try:
            bus = Bus(session, BusSettings(zenoh=ZenohSettings(connect=[endpoint])))
            previews: list[object] = []
            bus.subscribe(keys.PTZ_PREVIEW, previews.append, latest=False, camera="ptz1")
            operator = Operator(bus)
            deadline = time.monotonic() + 120
            while not (previews and _armed(operator)):
                if time.monotonic() > deadline:
                    raise RuntimeError("the lab did not start following within 120 s")
                time.sleep(1.0)
            time.sleep(5.0)
            sim_pid = _lab_processes(up.pid)["sim"]
            for index, (name, extra) in enumerate(variants(video_fps)):
                result = record(lab, workdir / "crater.npz", workdir / f"run{index}.mcap",
                                seconds, extra, sim_pid)
                result["variant"] = name
                results.append(result)
                print(json.dumps(result), file=sys.stderr, flush=True)
            bus.close()
        finally:
            session.close()
    return results


def first_minute(seconds: float, video_fps: float, workdir: Path) -> dict:
    """A fresh demo lab (no stored poses, the observation camera on) recorded from its start
    with every camera: calibration included."""
    folder = workdir / "first-minute"
    folder.mkdir()
    count = load_settings(CalibSettings, ROOT / "config" / "demo.toml").count
    env = {"STB_CALIB__COLLECT_MISSING": "true", "STB_SIM__CALIBRATE_FIRST": '["ptz1", "ptz2"]',
           "STB_CALIB__COUNT": str(count)}
    with running_lab(folder, services=[*SERVICES, "observation"], poses=False, env=env) as (
            up, lab, endpoint):
        open_when_up(ZenohSettings(connect=[endpoint], connect_timeout_ms=0)).close()
        deadline = time.monotonic() + 30
        while "sim" not in (processes := _lab_processes(up.pid)):
            if time.monotonic() > deadline:
                raise RuntimeError("the sim did not start within 30 s")
            time.sleep(0.2)
        video = ["--video", "ptz1", "--video", "ptz2", "--video-fps", f"{video_fps:g}"]
        result = record(lab, folder / "crater.npz", workdir / "first-minute.mcap", seconds,
                        video, processes["sim"])
        poses = sorted(path.parent.name for path in (folder / "calib").glob("*/pose.json"))
        result["variant"] = (f"the first minute of a fresh demo lab: {', '.join(poses) or 'no'}"
                             f" camera calibrated, all four cameras")
        return result


def _armed(operator: Operator) -> bool:
    import pytest

    try:
        return operator.send("arm").accepted
    except (Exception, pytest.fail.Exception):  # the rig's waits fail as tests do: not yet
        return False


def table(results: list[dict]) -> str:
    lines = ["| recording | MB/min | bus / video / JSON / typed, MB before compression "
             "| stb record, share of a core | its peak memory, MB | sim, share of a core |",
             "|---|---|---|---|---|---|"]
    for r in results:
        g = r["raw_mb_by_group"]
        split = " / ".join(f"{g.get(k, 0):.1f}" for k in ("bus", "video", "json", "typed"))
        lines.append(f"| {r['variant']} | {r['mb_per_min']:.1f} | {split} | "
                     f"{r['recorder_cpu'] * 100:.0f} % | {r['recorder_max_rss_mb']:.0f} | "
                     f"{r['sim_cpu'] * 100:.0f} % |")
    return "\n".join(lines)


def main() -> None:
    parser = Parser(description=__doc__,
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=None,
                        help="per variant; 30 s, or 60 s with --first-minute")
    parser.add_argument("--video-fps", type=float, default=5.0)
    parser.add_argument("--first-minute", action="store_true",
                        help="only the first minute of a fresh demo lab, calibration included")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="stb-bench-rec-") as tmp:
        if args.first_minute:
            results = [first_minute(args.seconds or 60.0, args.video_fps, Path(tmp))]
        else:
            results = run(args.seconds or 30.0, args.video_fps, Path(tmp))
    print(table(results))


if __name__ == "__main__":
    main()
