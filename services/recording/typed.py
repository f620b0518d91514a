"""The lab as Foxglove's typed messages (foxglove-sdk's schemas, protobuf): what ``stb foxglove``
serves live and ``stb record`` writes beside the raw channels, so that Foxglove's 3D, image
and plot panels show a run without any extension.

    /scene              SceneUpdate      robot, its track, the crane and its cable to the robot
                                         (red above the sideways-pull limit), each camera's
                                         view cone and name
    /crater             SceneUpdate      the crater's height map as a coloured triangle mesh
                                         (at the start and every ``crater_every_s``)
    /tf                 FrameTransforms  world → each camera's head (pose · pan · tilt), world →
                                         robot, world → crane
    /CAMERA/image       CompressedImage  each PTZ camera's preview (JPEG as the camera sent it)
    /CAMERA/annotations ImageAnnotations the markers the detector found (circles) and where the
                                         robot should be (a cross)
    /gantry/image       CompressedImage  the tracking camera's frames (mono8 JPEG-encoded), or
                        CompressedVideo  in a recording: H.264 (``encode.py``)
    /CAMERA/video       CompressedImage  a camera's video as ``stb record --video`` took it, or
                        CompressedVideo  in a recording: H.264
    /CAMERA/snapshot    CompressedImage  its snapshots in calibration mode (JPEG), or
                        CompressedVideo  in a recording: H.264

Positions in metres (Foxglove's unit), frame ``world`` = the mocap's frame. Each output is a
``Typed`` record of plain bytes (schema and payload), so that the MCAP writer and the live
server need nothing of the SDK's. The plot panel's numeric series are the JSON copies of the
bus messages (``services.recording.foxglove``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from foxglove import messages as fm
from matplotlib import colormaps
from scipy.spatial.transform import Rotation

from common import keys
from common import messages as m
from common.camera import Intrinsics, Pose, head_pose
from common.heightmap import HeightMap
from services.recording.encode import FORMAT as H264
from services.recording.encode import H264Stream

MM = 1e-3  # the lab's millimetres in Foxglove's metres
WORLD = "world"
SCENE, CRATER, TF, GANTRY_IMAGE = "/scene", "/crater", "/tf", "/gantry/image"
CONE_M = 1.5  # how far a camera's view cone reaches in the 3D scene
CRATER_CELLS = 80  # the mesh's cells per side at most (the height map is finer)
TRACK_S, TRACK_STEP_S = 30.0, 0.2
RED, BLUE, YELLOW, WHITE = ((1.0, 0.31, 0.31, 1.0), (0.3, 0.64, 1.0, 1.0),
                            (1.0, 0.85, 0.3, 1.0), (1.0, 1.0, 1.0, 1.0))
JPEG_QUALITY = 80
FRAME_TOPICS = {keys.GANTRY_FRAME: GANTRY_IMAGE, keys.VIDEO: "/{camera}/video",
                keys.PTZ_SNAPSHOT: "/{camera}/snapshot"}
"""Where each kind of camera frame goes (all are ``CameraFrame`` on the bus)."""
VIDEO_TOPICS = {keys.GANTRY_FRAME, keys.VIDEO, keys.PTZ_SNAPSHOT}
"""Camera streams that go as H.264 video where the scene encodes video (a recording): each
picture stored once, the bus samples too only with ``--raw-frames``. (The calibration
snapshots, about 52 kB of JPEG ten a second a camera, were stored twice — the bus sample and
a JPEG image —: 57 MB of the first minute of ``make demo``, docs/benchmarks.md.)"""


@dataclass(frozen=True)
class Typed:
    """One typed message: its topic, schema (name, encoding, data), payload and time."""

    topic: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes
    message_encoding: str
    data: bytes
    time_s: float


_SCHEMAS: dict[type, tuple[str, str, bytes]] = {}  # (name, encoding, descriptors), made once


def _typed(topic: str, msg: Any, time_s: float) -> Typed:
    schema = _SCHEMAS.get(type(msg))
    if schema is None:
        found = type(msg).get_schema()
        schema = _SCHEMAS[type(msg)] = (found.name, found.encoding, bytes(found.data))
    return Typed(topic, *schema, "protobuf", msg.encode(), time_s)


def _time(seconds: float) -> fm.Timestamp:
    sec, nsec = divmod(round(seconds * 1e9), 1_000_000_000)
    return fm.Timestamp(sec=int(sec), nsec=int(nsec))


def _vec(x_mm: float, y_mm: float, z_mm: float) -> fm.Vector3:
    return fm.Vector3(x=x_mm * MM, y=y_mm * MM, z=z_mm * MM)


def _point(x_mm: float, y_mm: float, z_mm: float) -> fm.Point3:
    return fm.Point3(x=x_mm * MM, y=y_mm * MM, z=z_mm * MM)


def _colour(rgba: tuple[float, ...]) -> fm.Color:
    return fm.Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _at(x_mm: float, y_mm: float, z_mm: float,
        rotation: fm.Quaternion | None = None) -> fm.Pose:
    return fm.Pose(position=_vec(x_mm, y_mm, z_mm),
                   orientation=rotation or fm.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))


def _quaternion(matrix: np.ndarray) -> fm.Quaternion:
    x, y, z, w = Rotation.from_matrix(matrix).as_quat()
    return fm.Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))


def crater_mesh(height_map: HeightMap, time_s: float) -> Typed:
    """The crater as one triangle-list entity, coloured by height as the page colours it."""
    h = height_map.heights_mm
    stride = max(1, math.ceil((max(h.shape) - 1) / CRATER_CELLS))
    rows, cols = np.arange(0, h.shape[0], stride), np.arange(0, h.shape[1], stride)
    grid = h[np.ix_(rows, cols)].astype(float)
    x0, _, y0, _ = height_map.extent_mm
    xs = x0 + cols * height_map.resolution_mm
    ys = y0 + rows * height_map.resolution_mm
    span = float(grid.max() - grid.min()) or 1.0
    rgba = colormaps["terrain"]((grid - grid.min()) / span)
    points, colours = [], []
    for r, y in enumerate(ys):
        for c, x in enumerate(xs):
            points.append(_point(float(x), float(y), float(grid[r, c])))
            colours.append(_colour(tuple(float(v) for v in rgba[r, c])))
    n_cols = len(xs)
    indices = []
    for r in range(len(ys) - 1):
        for c in range(n_cols - 1):
            a, b = r * n_cols + c, r * n_cols + c + 1
            d, e = a + n_cols, b + n_cols
            indices += [a, b, e, a, e, d]
    entity = fm.SceneEntity(
        timestamp=_time(time_s), frame_id=WORLD, id="crater", frame_locked=True,
        triangles=[fm.TriangleListPrimitive(pose=_at(0, 0, 0), points=points, colors=colours,
                                            indices=indices)])
    return _typed(CRATER, fm.SceneUpdate(entities=[entity]), time_s)


class LabScene:
    """Turns bus messages into typed ones (``on``); keeps what a scene needs of the latest
    robot, crane, offload, camera poses and states. The 3D scene is sent at most ``scene_hz``
    a second and each camera's transform at most that often; images go as they come."""

    def __init__(self, height_map: HeightMap | None = None, *, scene_hz: float = 10.0,
                 crater_every_s: float = 60.0, video: bool = False) -> None:
        self.height_map, self.scene_period_s = height_map, 1.0 / scene_hz
        self.video = video  # camera streams as H.264 (VIDEO_TOPICS), one stream per topic
        self._streams: dict[str, H264Stream] = {}
        self.crater_every_s = crater_every_s
        self.robot: m.RobotPosition | None = None
        self.crane: m.CraneState | None = None
        self.offload: m.GravityOffload | None = None
        self.poses: dict[str, m.CameraPose] = {}
        self.heads: dict[str, m.PtzState] = {}
        self.track: deque[tuple[float, float, float, float]] = deque()
        self._scene_at = -math.inf
        self._tf_at: dict[str, float] = {}
        self._crater_at = -math.inf

    def on(self, msg: m.Message, topic: keys.Topic | None = None) -> list[Typed]:
        """The typed messages ``msg`` (which came on ``topic``) gives; often none: it only
        updates the scene."""
        t = msg.measured_s
        out: list[Typed] = []
        if isinstance(msg, m.RobotPosition):
            self.robot = msg
            if not self.track or t - self.track[-1][0] >= TRACK_STEP_S:
                self.track.append((t, msg.x_mm, msg.y_mm, msg.z_mm))
            while self.track and t - self.track[0][0] > TRACK_S:
                self.track.popleft()
        elif isinstance(msg, m.CraneState):
            self.crane = msg
        elif isinstance(msg, m.GravityOffload):
            self.offload = msg
        elif isinstance(msg, m.CameraPose):
            old = self.poses.get(msg.camera)
            if old is None or msg.measured_s >= old.measured_s:
                self.poses[msg.camera] = msg
        elif isinstance(msg, m.PtzState):
            self.heads[msg.camera] = msg
            if t - self._tf_at.get(msg.camera, -math.inf) >= self.scene_period_s:
                self._tf_at[msg.camera] = t
                out += self._camera_transform(msg.camera, t)
        elif isinstance(msg, m.PtzPreview):
            out += _preview(msg)
        elif isinstance(msg, m.CameraFrame) and topic in FRAME_TOPICS:
            to = FRAME_TOPICS[topic].format(camera=msg.camera)
            if self.video and topic in VIDEO_TOPICS:
                stream = self._streams.get(to) or self._streams.setdefault(to, H264Stream())
                out += _video(msg, to, stream)
            else:
                out += _frame(msg, to)
        if self.height_map is not None and t - self._crater_at >= self.crater_every_s:
            self._crater_at = t
            out.append(crater_mesh(self.height_map, t))
        if isinstance(msg, m.RobotPosition | m.CraneState) and \
                t - self._scene_at >= self.scene_period_s:
            self._scene_at = t
            out += self.scene(t)
        return out

    def restart(self) -> None:
        """A new file begins: each video stream starts again with a keyframe, the crater and
        the scene go again with the next messages."""
        self._streams.clear()
        self.resend_crater()
        self._scene_at = -math.inf
        self._tf_at.clear()

    def resend_crater(self) -> None:
        """The crater goes with the next message (a client that just subscribed)."""
        self._crater_at = -math.inf

    def scene(self, t: float) -> list[Typed]:
        entities, transforms = [], []
        robot, crane = self.robot, self.crane
        if robot is not None:
            entities.append(fm.SceneEntity(
                timestamp=_time(t), frame_id=WORLD, id="robot",
                spheres=[fm.SpherePrimitive(pose=_at(robot.x_mm, robot.y_mm, robot.z_mm),
                                            size=_vec(150, 150, 150), color=_colour(RED))],
                lines=[fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineStrip, thickness=3,
                                        scale_invariant=True, color=_colour(RED),
                                        points=[_point(x, y, z) for _, x, y, z in self.track])]))
            rotation = None if robot.qw is None else fm.Quaternion(
                x=robot.qx or 0.0, y=robot.qy or 0.0, z=robot.qz or 0.0, w=robot.qw)
            transforms.append(fm.FrameTransform(
                timestamp=_time(t), parent_frame_id=WORLD, child_frame_id="robot",
                translation=_vec(robot.x_mm, robot.y_mm, robot.z_mm),
                rotation=rotation or fm.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)))
        if crane is not None and crane.status != "unreachable":
            cable = 2000.0 if self.offload is None else self.offload.cable_length_mm
            z = (robot.z_mm if robot is not None else 0.0) + cable
            warn = self.offload is not None and self.offload.warning
            lines = [] if robot is None else [fm.LinePrimitive(
                type=fm.LinePrimitiveLineType.LineStrip, thickness=4, scale_invariant=True,
                color=_colour(RED if warn else BLUE),
                points=[_point(crane.x_mm, crane.y_mm, z),
                        _point(robot.x_mm, robot.y_mm, robot.z_mm)])]
            label = f"crane {crane.mode}, {crane.status}"
            if self.offload is not None:
                label += (f"\n{self.offload.horizontal_error_mm:.0f} mm off, pull "
                          f"{self.offload.horizontal_share_pct:.1f} %")
            entities.append(fm.SceneEntity(
                timestamp=_time(t), frame_id=WORLD, id="crane",
                cubes=[fm.CubePrimitive(pose=_at(crane.x_mm, crane.y_mm, z),
                                        size=_vec(400, 400, 60), color=_colour(BLUE))],
                lines=lines,
                texts=[fm.TextPrimitive(pose=_at(crane.x_mm, crane.y_mm, z + 150),
                                        billboard=True, font_size=14, scale_invariant=True,
                                        color=_colour(WHITE), text=label)]))
            transforms.append(fm.FrameTransform(
                timestamp=_time(t), parent_frame_id=WORLD, child_frame_id="crane",
                translation=_vec(crane.x_mm, crane.y_mm, z),
                rotation=fm.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)))
        for camera in sorted(self.poses):
            cone = self._cone(camera, t)
            if cone is not None:
                entities.append(cone)
        out = [_typed(SCENE, fm.SceneUpdate(entities=entities), t)] if entities else []
        if transforms:
            out.append(_typed(TF, fm.FrameTransforms(transforms=transforms), t))
        return out

    def _head(self, camera: str) -> Pose | None:
        pose, state = self.poses.get(camera), self.heads.get(camera)
        if pose is None:
            return None
        pan, tilt = (0.0, 0.0) if state is None else (state.pan_deg, state.tilt_deg)
        return head_pose(Pose.of(pose), pan, tilt)

    def _camera_transform(self, camera: str, t: float) -> list[Typed]:
        head = self._head(camera)
        if head is None:
            return []
        transform = fm.FrameTransform(
            timestamp=_time(t), parent_frame_id=WORLD, child_frame_id=camera,
            translation=_vec(*head.position), rotation=_quaternion(head.rotation))
        return [_typed(TF, fm.FrameTransforms(transforms=[transform]), t)]

    def _cone(self, camera: str, t: float) -> fm.SceneEntity | None:
        """The camera's view cone in its own frame (x = optical axis, y right, z down in the
        image), as wide as its focal length shows."""
        if camera not in self.poses:
            return None
        state = self.heads.get(camera)
        pose = self.poses[camera]
        intr = Intrinsics(state.focal_px if state is not None else pose.focal_px,
                          pose.width_px, pose.height_px)
        d = CONE_M / MM
        half_w, half_h = d * intr.cy_px / intr.fy_px, d * intr.cz_px / intr.fz_px
        corners = [_point(d, sy * half_w, sz * half_h)
                   for sy, sz in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        origin = _point(0, 0, 0)
        edges = [p for c in corners for p in (origin, c)]
        edges += [p for i in range(4) for p in (corners[i], corners[(i + 1) % 4])]
        return fm.SceneEntity(
            timestamp=_time(t), frame_id=camera, id=f"camera/{camera}",
            lines=[fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineList, thickness=2,
                                    scale_invariant=True, color=_colour(YELLOW),
                                    points=edges)],
            texts=[fm.TextPrimitive(pose=_at(0, 0, -150), billboard=True, font_size=14,
                                    scale_invariant=True, color=_colour(YELLOW), text=camera)])


def _preview(msg: m.PtzPreview) -> list[Typed]:
    t = msg.measured_s
    stamp = _time(t)
    image = fm.CompressedImage(timestamp=stamp, frame_id=msg.camera, data=msg.jpeg,
                               format="jpeg")
    green = _colour((0.56, 0.82, 0.56, 1.0))
    circles = [fm.CircleAnnotation(timestamp=stamp, position=fm.Point2(x=d.u_px, y=d.v_px),
                                   diameter=max(12.0, 4 * d.radius_long_px), thickness=2,
                                   outline_color=green, fill_color=_colour((0, 0, 0, 0)))
               for d in msg.markers]
    points = []
    if msg.robot_px is not None:
        u, v = msg.robot_px
        points.append(fm.PointsAnnotation(
            timestamp=stamp, type=fm.PointsAnnotationType.LineList, thickness=2,
            outline_color=_colour(RED), fill_color=_colour((0, 0, 0, 0)),
            points=[fm.Point2(x=u - 12, y=v - 12), fm.Point2(x=u + 12, y=v + 12),
                    fm.Point2(x=u + 12, y=v - 12), fm.Point2(x=u - 12, y=v + 12)]))
    return [_typed(f"/{msg.camera}/image", image, t),
            _typed(f"/{msg.camera}/annotations",
                   fm.ImageAnnotations(circles=circles, points=points), t)]


def _video(msg: m.CameraFrame, to: str, stream: H264Stream) -> list[Typed]:
    if msg.encoding == "jpeg":
        image = cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            return []
    else:
        pixels = np.frombuffer(msg.data, np.uint8)
        if pixels.size != msg.width_px * msg.height_px:
            return []
        image = pixels.reshape(msg.height_px, msg.width_px)
    return [_typed(to, fm.CompressedVideo(timestamp=_time(unit.time_s), frame_id=msg.camera,
                                          data=unit.data, format=H264), unit.time_s)
            for unit in stream.encode(image, msg.measured_s)]


def _frame(msg: m.CameraFrame, to: str) -> list[Typed]:
    if msg.encoding == "jpeg":
        jpeg = msg.data
    else:
        pixels = np.frombuffer(msg.data, np.uint8)
        if pixels.size != msg.width_px * msg.height_px:
            return []
        ok, encoded = cv2.imencode(".jpg", pixels.reshape(msg.height_px, msg.width_px),
                                   [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if not ok:
            return []
        jpeg = encoded.tobytes()
    image = fm.CompressedImage(timestamp=_time(msg.measured_s), frame_id=msg.camera,
                               data=jpeg, format="jpeg")
    return [_typed(to, image, msg.measured_s)]
