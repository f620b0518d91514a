"""A long synthetic recording at the demo lab's rates, written straight to MCAP parts (what
``stb record --split-time`` would write over that long, without waiting for it): the tracker's
marker frames and robot position (100 Hz), the gantry's state, estimate and offload (25 Hz),
two PTZ cameras' states (10 Hz) and previews (2 Hz, 40 kB JPEGs), eight services' health
(1 Hz), and the H.264 channels of the tracking camera (25 Hz) and the observation camera
(5 Hz) as incompressible bytes of a real encoder's size. The robot goes round an oval and the
crane follows it 40 mm behind, so the report has figures to compute."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from foxglove import messages as fm

from common import codec, keys
from common import messages as m
from common.mcap_file import RecordWriter
from services.recording.split import part_path

MOCAP_HZ, GANTRY_HZ, PTZ_HZ, PREVIEW_HZ, OBSERVATION_HZ = 100, 25, 10, 2, 5
VIDEO_BYTES = {"/gantry/image": 1_500, "/observation/video": 12_000}  # H.264 access units


def _robot_at(t: float) -> tuple[float, float]:
    a = 2 * math.pi * t / 40.0
    return 1500 * math.cos(a), 900 * math.sin(a)


def write_long_run(out: Path, minutes: float, parts: int, t0: float = 1.7e9) -> list[Path]:
    """The run's parts (``out``-001.mcap …), each ``minutes / parts`` long."""
    rng = np.random.default_rng(0)
    jpeg = bytes(rng.integers(0, 256, 40_000, dtype=np.uint8))
    video = {topic: fm.CompressedVideo(  # not H.264 inside: no keyframe, no still
        frame_id=topic, format="h264", data=bytes(rng.integers(0, 256, size, dtype=np.uint8))
    ).encode() for topic, size in VIDEO_BYTES.items()}
    part_s = minutes * 60 / parts
    paths = []
    for part in range(parts):
        paths.append(part_path(out, part + 1))
        with open(paths[-1], "wb") as f:
            writer = RecordWriter(f, {"prefix": "stb", "part": str(part + 1)})
            schema = fm.CompressedVideo.get_schema()
            schema_of = (schema.name, schema.encoding, bytes(schema.data))
            for i in range(int(part * part_s * MOCAP_HZ), int((part + 1) * part_s * MOCAP_HZ)):
                _tick(writer, i, t0 + i / MOCAP_HZ, jpeg, video, schema_of)
            writer.finish()
    return paths


def _put(writer: RecordWriter, topic: keys.Topic, msg: m.Message, t: float, **params: str
         ) -> None:
    writer.write(topic.key("stb", **params), codec.encode(msg, sent_s=t),
                 encoding=codec.CONTENT_TYPE, model=topic.model.__name__, received_s=t,
                 measured_s=msg.measured_s)


def _tick(writer: RecordWriter, i: int, t: float, jpeg: bytes, video: dict[str, bytes],
          schema: tuple[str, str, bytes]) -> None:
    x, y = _robot_at(t)
    markers = [m.Marker(label="robot", x_mm=x, y_mm=y, z_mm=300.0)] + [
        m.Marker(label=f"static_{k}", x_mm=3000.0 * k, y_mm=100.0, z_mm=0.0) for k in range(3)]
    _put(writer, keys.TRACKER_MARKERS, m.MarkerFrame(measured_s=t, frame=i, markers=markers), t)
    _put(writer, keys.TRACKER_ROBOT, m.RobotPosition(
        measured_s=t, label="robot", x_mm=x, y_mm=y, z_mm=300.0, vx_mm_s=0.0, vy_mm_s=0.0,
        vz_mm_s=0.0), t)
    if i % (MOCAP_HZ // GANTRY_HZ) == 0:
        _put(writer, keys.GANTRY_STATE, m.CraneState(
            measured_s=t, status="tracking", x_mm=x + 40.0, y_mm=y, target_x_mm=x,
            target_y_mm=y, enabled=True, moving=True, fault_bits=0, mode="armed"), t)
        _put(writer, keys.GANTRY_ESTIMATE, m.RobotEstimate(
            measured_s=t, algorithm="default", valid=True, x_mm=x, y_mm=y, z_mm=300.0,
            vx_mm_s=0.0, vy_mm_s=0.0), t)
        _put(writer, keys.GANTRY_OFFLOAD, m.GravityOffload(
            measured_s=t, horizontal_error_mm=40.0, cable_length_mm=3000.0,
            vertical_loss_pct=0.01, horizontal_share_pct=1.3, warning=False,
            warn_above_pct=5.0), t)
        writer.write_typed("/gantry/image", schema=schema, message_encoding="protobuf",
                           data=video["/gantry/image"], time_s=t)
    if i % (MOCAP_HZ // OBSERVATION_HZ) == 0:
        writer.write_typed("/observation/video", schema=schema, message_encoding="protobuf",
                           data=video["/observation/video"], time_s=t)
    for camera in ("ptz1", "ptz2"):
        if i % (MOCAP_HZ // PTZ_HZ) == 0:
            _put(writer, keys.PTZ_STATE, m.PtzState(
                measured_s=t, camera=camera, status="tracking", pan_deg=10.0, tilt_deg=-20.0,
                zoom=1, focal_px=684.4, aim_error_deg=0.3), t, camera=camera)
        if i % (MOCAP_HZ // PREVIEW_HZ) == 0:
            _put(writer, keys.PTZ_PREVIEW, m.PtzPreview(
                measured_s=t, camera=camera, seq=i, width_px=704, height_px=576, jpeg=jpeg,
                pan_deg=10.0, tilt_deg=-20.0, robot_px=[352.0, 288.0], markers=[]), t,
                camera=camera)
    if i % MOCAP_HZ == 0:
        for service in ("router", "sim", "tracker", "calib", "ptz", "gantry", "observation",
                        "web"):
            _put(writer, keys.HEALTH, m.ServiceHealth(
                measured_s=t, service=service, instance="main", host="lab", pid=1,
                started_s=t - t % 3600, status="ok", keys={}), t, service=service,
                instance="main")
