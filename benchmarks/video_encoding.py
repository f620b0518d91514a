"""What encoding the lab's cameras as H.264 costs ``stb record``: one core's share at the
cameras' rates, on the sim's own pictures, through the recorder's own path.

    .venv/bin/python -m benchmarks.video_encoding [--seconds 10]

The pictures are what each camera sends: the tracking camera's frames (640×480 grey, as the
sim renders them, raw on the bus), the PTZ cameras' MJPEG (704×576 colour JPEGs) and the
observation camera's MJPEG (640×480 colour JPEGs), ``--seconds`` of each at its rate, rendered
before the clock starts. Each goes through ``LabScene(video=True).on`` — JPEG decoding where
there is one, libx264 (PyAV), Foxglove's protobuf — as ``stb record`` writes it; the CPU time
of this process (``time.process_time``) per second of video is the share of one core. Beside
it, in the same run, the reference the issue sets: 25 % of one core.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from common import keys
from common import messages as m
from services.args import Parser
from services.recording.typed import LabScene
from services.sim.camera_server import SimCamera
from services.sim.lab import Lab
from services.sim.observation import observation_camera
from services.sim.scene import GroundView
from services.sim.settings import SimSettings

GOAL_CORE = 0.25


def _jpeg(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 85])
    assert ok
    return data.tobytes()


def streams(lab: Lab, settings: SimSettings, seconds: float
            ) -> dict[str, tuple[keys.Topic, float, list[m.CameraFrame]]]:
    """Each camera's frames over ``seconds``: (topic, frames a second, frames)."""
    t = [10.0]
    out: dict[str, tuple[keys.Topic, float, list[m.CameraFrame]]] = {}
    rng = np.random.default_rng(0)
    lab.start_robot(0.0)
    tracking = []
    for i in range(int(25 * seconds)):
        t[0] = 10.0 + i / 25
        lab.crane_state(t[0])
        image = lab.tracking_frame(t[0], rng)
        tracking.append(m.CameraFrame(measured_s=t[0], camera="tracking", seq=i + 1,
                                      width_px=640, height_px=480, encoding="mono8",
                                      data=image.tobytes()))
    out["tracking camera, 640×480 grey"] = (keys.GANTRY_FRAME, 25.0, tracking)
    for cam in settings.cameras:
        sim = SimCamera(cam.name, lab.heads[cam.name], lab.bright_points,
                        lab.ptz_glints, lambda: t[0], np.random.default_rng(1),
                        ground=GroundView.of(lab.crater), robots=lambda at: [lab.robot_pose(at)])
        frames = []
        for i in range(int(5 * seconds)):
            t[0] = 10.0 + i / 5
            frames.append(m.CameraFrame(measured_s=t[0], camera=cam.name, seq=i + 1,
                                        width_px=704, height_px=576, encoding="jpeg",
                                        data=_jpeg(sim.snapshot(704, 576))))
        out[f"{cam.name}, 704×576 colour JPEG"] = (keys.VIDEO, 5.0, frames)
    observation = observation_camera(lab, settings, lambda: t[0], lab.crane_world_at)
    frames = []
    for i in range(int(5 * seconds)):
        t[0] = 10.0 + i / 5
        frames.append(m.CameraFrame(measured_s=t[0], camera="observation", seq=i + 1,
                                    width_px=640, height_px=480, encoding="jpeg",
                                    data=_jpeg(observation.snapshot(640, 480))))
    out["observation, 640×480 colour JPEG"] = (keys.VIDEO, 5.0, frames)
    return out


def main() -> None:
    parser = Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        settings = SimSettings(crater_file=Path(tmp) / "crater.npz")
        lab = Lab.build(settings)
        cameras = streams(lab, settings, args.seconds)
    scene = LabScene(video=True)
    total = 0.0
    print("| camera | frames/s | CPU ms a frame | share of one core | H.264 kB/s |")
    print("|---|---|---|---|---|")
    for name, (topic, fps, frames) in cameras.items():
        started, size = time.process_time(), 0
        for frame in frames:
            size += sum(len(typed.data) for typed in scene.on(frame, topic))
        cpu = time.process_time() - started
        share = cpu / (len(frames) / fps)
        total += share
        print(f"| {name} | {fps:g} | {1e3 * cpu / len(frames):.1f} | {100 * share:.1f} % | "
              f"{size / 1e3 / (len(frames) / fps):.0f} |")
    print(f"| all four cameras | | | **{100 * total:.1f} %** (goal ≤ {100 * GOAL_CORE:.0f} %) | |")


if __name__ == "__main__":
    main()
