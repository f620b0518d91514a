"""What ``stb record`` does once its flags are parsed (services/recording/record_cli.py has
the command and its documentation): the bus to MCAP, and a JSON copy."""

from __future__ import annotations

import argparse
import logging
import os
import queue
import re
import socket
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import IO

import zenoh
from pydantic import Field

from common import codec, keys
from common import messages as m
from common.errors import ConfigError
from common.heightmap import HeightMap
from common.jpeg import jpeg_size
from common.lab_paths import DEFAULT_HEIGHT_MAP
from common.lab_views import CameraConnection, LabCameras
from common.mcap_file import RecordWriter
from common.mjpeg import CameraVideo
from common.node import stop_on_signals
from common.settings import LogLevel, ServiceSettings, load_settings
from services.args import EXIT_DISK
from services.entry import (
    ToolError,
    checked_key_exprs,
    tool_session,
    tool_settings,
)
from services.recording.disk import DiskReserve, DiskWatch
from services.recording.foxglove import json_copy
from services.recording.split import SplitRule, part_path
from services.recording.typed import VIDEO_TOPICS, LabScene

log = logging.getLogger(__name__)
DISK_CHECK_S = 0.5  # free space looked at this often
NO_SPLIT = SplitRule()


class RecordSettings(ServiceSettings):
    section = "record"
    borrowed = {"height_map": "gantry"}  # the lab's crater, named once

    log_level: LogLevel = "WARNING"
    progress_s: float = Field(5.0, gt=0, description="a progress line this often (stderr)")
    json_copy: bool = Field(True, description="also write the JSON copy Foxglove can show")
    typed: bool = Field(True, description="also write Foxglove's typed channels: the 3D "
                        "scene, camera transforms, images and their annotations")
    height_map: Path | None = Field(DEFAULT_HEIGHT_MAP, description="the crater in "
                                    "the 3D scene (.npz; [gantry] height_map unless set here); "
                                    "missing: a scene without it")
    video: list[str] = Field(default_factory=list, description="cameras of [ptz.cameras] whose "
                             "video (VAPIX MJPEG) goes into the recording on video/<camera>")
    video_fps: float = Field(5.0, gt=0, le=30, description="video frames a second per camera")
    video_resolution: str = Field("", pattern=r"^([1-9][0-9]{1,4}x[1-9][0-9]{1,4})?$",
                                  description="the video's size, as VAPIX names it (one the "
                                  "camera lists); empty: the camera's own, its full picture "
                                  "(an AXIS 215's 704x576)")
    min_free_mb: float = Field(64.0, ge=0, description="the recording stops (exit 5) when the "
                               "disk has less free than this, while the file can still be "
                               "finished with its summary")
    reserve_mb: float = Field(8.0, ge=0, description="room kept allocated inside the file, "
                              "just past its end, to finish it should another process fill "
                              "the disk; 0: none")
    split_mb: float | None = Field(None, gt=0, description="start a new file (each a complete "
                                   "MCAP: run-001.mcap, run-002.mcap, …) at this size")
    split_s: float | None = Field(None, gt=0, description="start a new file after this many "
                                  "seconds")
    raw_frames: bool = Field(False, description="also the camera frames as they crossed the bus "
                             "(stb/gantry/camera/frame, video/<camera>: about 8 MB/s for the "
                             "tracking camera), for a replay that feeds a gantry; without, "
                             "they are in the file as H.264 video only")


@dataclass
class Stats:
    samples: Counter = field(default_factory=Counter)
    invalid: Counter = field(default_factory=Counter)
    payload_bytes: int = 0
    lost: int = 0  # samples not written: the disk was full


def latest_samples(session: zenoh.Session, expr: zenoh.KeyExpr | str,
                   timeout_s: float) -> Iterator[zenoh.Sample]:
    """What the queryables under ``expr`` hold now (camera poses, published once at
    calibration), for a tool that joins the bus after they were published."""
    for reply in session.get(expr, timeout=timeout_s):
        if reply.ok is not None:
            yield reply.ok


class Recorder:
    """Subscribes to key expressions and writes what arrives from a thread of its own; the
    Zenoh callback only queues (key, payload, encoding, receive time).

    With a ``split`` rule and ``next_part`` (opens the next file), a full part is finished and
    the next begun: each part is a complete recording — its own summary, the camera poses
    heard so far written again, the crater and each video stream starting afresh (a
    keyframe)."""

    def __init__(self, session: zenoh.Session, prefix: str, key_exprs: Sequence[str],
                 out: IO[bytes], *, exclude: Sequence[str] = (), with_json: bool = True,
                 scene: LabScene | None = None, raw_frames: bool = True,
                 metadata: dict[str, str] | None = None, split: SplitRule = NO_SPLIT,
                 next_part: Callable[[], IO[bytes]] | None = None,
                 clock: Callable[[], float] = time.time,
                 out_of_room: Callable[[], bool] = lambda: False) -> None:
        """``clock``: the receive time stamped on every sample (UNIX seconds), by which the
        parts are cut; ``out_of_room``: the disk filled up from outside, what room is left
        is for finishing the file (no more samples are written)."""
        self.prefix, self.with_json, self._session = prefix, with_json, session
        self._clock, self._out_of_room = clock, out_of_room
        self.raw_frames = raw_frames  # False: camera streams as the scene's video only
        self.write_error: OSError | None = None  # the disk is full: nothing more is written
        self.scene = scene
        self._video_seq: dict[str, int] = {}
        self.stats = Stats()
        self.out, self.parts = out, 1
        self._split, self._next_part = split, next_part
        self._part_started_s: float | None = None
        self._latched: dict[str, tuple] = {}  # the camera poses: written again in every part
        self._metadata = metadata or {}
        self._writer = RecordWriter(out, self._metadata)
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._exprs = [zenoh.KeyExpr(k) for k in key_exprs]
        self._exclude = [zenoh.KeyExpr(k) for k in exclude]
        self._thread = threading.Thread(target=self._run, name="record-writer", daemon=True)
        self._thread.start()
        self._subs = [session.declare_subscriber(
            expr, zenoh.handlers.Callback(partial(self._on_sample, i), indirect=False))
            for i, expr in enumerate(self._exprs)]

    def ask_latest(self, timeout_s: float = 1.0) -> int:
        """Query the recorded key expressions once, so that values published before the
        recording started and kept by a queryable (camera poses) are in it too. Returns how
        many replies were queued."""
        replies = 0
        for index, expr in enumerate(self._exprs):
            for sample in latest_samples(self._session, expr, timeout_s):
                self._on_sample(index, sample)
                replies += 1
        return replies

    def _on_sample(self, index: int, sample: zenoh.Sample) -> None:
        received = self._clock()
        key = sample.key_expr
        if sample.kind != zenoh.SampleKind.PUT or any(x.includes(key) for x in self._exclude):
            return
        if any(e.includes(key) for e in self._exprs[:index]):  # an earlier expression has it
            return
        self._queue.put((str(key), sample.payload.to_bytes(), str(sample.encoding), received,
                         None))

    def _run(self) -> None:
        while (item := self._queue.get()) is not None:
            if self.write_error is not None or self._out_of_room():
                self.stats.lost += 1  # the disk is full: the rest is counted, not written
                continue
            try:
                self._next_part_if_due(item[3])
                self._write(*item)
            except OSError as err:  # a full disk (FULL) or a failing one
                self.write_error = err
                self.stats.lost += 1
                log.error("cannot write the recording: %s; it stops", err)
            except Exception:  # noqa: BLE001 - one bad sample must not end the recording
                log.exception("cannot record a sample of %s", item[0])

    def _next_part_if_due(self, received_s: float) -> None:
        if self._part_started_s is None:
            self._part_started_s = received_s
        if self._next_part is None or not self._split.due(self.out.tell(), self._part_started_s,
                                                          received_s):
            return
        self._writer.finish()
        self.out.close()
        self.out = self._next_part()
        self.parts += 1
        self._part_started_s = received_s
        self._writer = RecordWriter(self.out, {**self._metadata, "part": str(self.parts)})
        if self.scene is not None:
            self.scene.restart()
        for item in list(self._latched.values()):
            self._write(*item, again=True)

    def _write(self, key: str, payload: bytes, encoding: str, received: float,
               made: m.Message | None, *, again: bool = False) -> None:
        """One sample; ``made``: the message itself when the recorder made it (video);
        ``again``: a camera pose written again at the start of a part (not counted)."""
        msg, topic = (made, keys.VIDEO) if made is not None else self._decode(key, payload)
        if topic is keys.CALIB_POSE and msg is not None and not again:
            self._latched[key] = (key, payload, encoding, received, made)
        model = topic.model.__name__ if topic is not None else ""
        measured = (msg.measured_s if isinstance(msg, m.Message)
                    else _float_or_none(msg.get("measured_s")) if isinstance(msg, dict) else None)
        if not again:
            self.stats.samples[key] += 1
            self.stats.payload_bytes += len(payload)
        raw = self.raw_frames or self.scene is None or not self.scene.video \
            or topic not in VIDEO_TOPICS or msg is None
        sequence = self._writer.write(key, payload, encoding=encoding, model=model,
                                      received_s=received, measured_s=measured) if raw else 0
        if raw and self.with_json and msg is not None and (copy := json_copy(msg)) is not None:
            data, schema = copy
            self._writer.write_json(key, data, schema=schema, received_s=received,
                                    measured_s=measured, sequence=sequence)
        if self.scene is not None and isinstance(msg, m.Message):
            for typed in self.scene.on(msg, topic):
                self._writer.write_typed(
                    typed.topic, schema=(typed.schema_name, typed.schema_encoding,
                                         typed.schema_data),
                    message_encoding=typed.message_encoding, data=typed.data,
                    time_s=typed.time_s)

    def _decode(self, key: str, payload: bytes
                ) -> tuple[m.Message | dict | None, keys.Topic | None]:
        msg, topic, error = decode(self.prefix, key, payload)
        if error:
            self.stats.invalid[f"{key}: {error}"] += 1
        return msg, topic

    def add_video(self, camera: str, jpeg: bytes, received_s: float) -> None:
        """A camera's video frame, recorded as if it had crossed the bus on ``video/CAMERA``
        (so that replay puts it there), stamped when it arrived."""
        size = jpeg_size(jpeg)
        if size is None or 0 in size:
            self.stats.invalid[f"video {camera}: not a JPEG"] += 1
            return
        seq = self._video_seq[camera] = self._video_seq.get(camera, 0) + 1
        frame = m.CameraFrame(measured_s=received_s, camera=camera, seq=seq, width_px=size[0],
                              height_px=size[1], encoding="jpeg", data=jpeg)
        self._queue.put((keys.VIDEO.key(self.prefix, camera=camera),
                         codec.encode(frame, sent_s=received_s),
                         f"{codec.CONTENT_TYPE};CameraFrame", received_s, frame))

    def close(self) -> None:
        """Stop listening, write what is queued, and finish the file (its summary; a disk
        that filled up leaves the file readable up to its last whole chunk)."""
        for sub in self._subs:
            sub.undeclare()
        self._queue.put(None)
        self._thread.join()
        if self.write_error is None:
            try:
                self._writer.finish()
            except OSError as err:  # the disk filled up (from outside) while it finished
                self.write_error = err
                log.error("cannot finish the recording: %s", err)


def video_cameras(names: list[str], args: argparse.Namespace
                  ) -> list[tuple[str, CameraConnection]]:
    """The cameras to take video from, with how to reach them (the lab file's [ptz.cameras]);
    a ToolError names one it does not know."""
    if not names:
        return []
    try:
        known = load_settings(LabCameras, args.lab).cameras
    except ConfigError as err:
        raise ToolError(str(err)) from err
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ToolError(f"no camera {', '.join(unknown)} in [ptz.cameras] (there: "
                        f"{', '.join(sorted(known)) or 'none'})")
    return [(n, known[n]) for n in dict.fromkeys(names)]


def decode(prefix: str, key: str, payload: bytes
           ) -> tuple[m.Message | dict | None, keys.Topic | None, str]:
    """(the message — a plain dict on a key of no known topic — or None, its topic, why it is
    invalid or "") of a sample."""
    topic = keys.topic_for(prefix, key)
    try:
        if topic is not None:
            return codec.decode(topic.model, payload, max_bytes=topic.max_payload_bytes), topic, ""
        return codec.unpack(payload, max_bytes=codec.DEFAULT_MAX_BYTES), topic, ""
    except codec.DecodeError as err:
        return None, topic, err.reason


def crater(path: Path | None) -> HeightMap | None:
    """The height map for the 3D scene, or None (said why) when there is none to read."""
    if path is None:
        return None
    try:
        return HeightMap.load(path)
    except (OSError, ValueError) as err:
        log.warning("no crater in the 3D scene: %s", err)
        return None


def _float_or_none(value: object) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None


def record(args: argparse.Namespace) -> int:
    settings = tool_settings(RecordSettings, args)
    exprs = checked_key_exprs(args.key_exprs or [f"{settings.bus.prefix}/**"])
    exclude = checked_key_exprs(args.exclude)
    cameras = video_cameras(settings.video, args)
    split = SplitRule(None if settings.split_mb is None else int(settings.split_mb * 1e6),
                      settings.split_s)
    paths = [part_path(args.out, 1) if split.splits else args.out]

    def next_part() -> IO[bytes]:
        paths.append(part_path(args.out, len(paths) + 1))
        log.info("recording: part %d, %s", len(paths), paths[-1])
        return reserve.open(paths[-1])

    reserve = DiskReserve(settings.reserve_mb)
    try:
        out = reserve.open(paths[0])
    except OSError as err:
        raise ToolError(f"cannot write {paths[0]}: {err}") from err
    try:
        session = tool_session(settings)
    except ToolError:
        out.close()
        paths[0].unlink(missing_ok=True)
        raise
    # while it records, the PTZ cameras leave their IR-cut filter alone (keys.RECORDING)
    token = session.liveliness().declare_token(
        keys.recording_key(settings.bus.prefix, _recorder_id()))  # held: dropped, it goes
    stop = threading.Event()
    restore = stop_on_signals(stop)
    metadata = {"prefix": settings.bus.prefix, "key_exprs": " ".join(exprs),
                "exclude": " ".join(exclude), "started_s": f"{time.time():.6f}"}
    recorder = Recorder(session, settings.bus.prefix, exprs, out, exclude=exclude,
                        with_json=settings.json_copy, metadata=metadata,
                        raw_frames=settings.raw_frames or not settings.typed,
                        scene=LabScene(crater(settings.height_map), video=True)
                        if settings.typed else None, split=split, next_part=next_part,
                        out_of_room=lambda: reserve.spent is not None)
    print(f"stb record: recording {' '.join(exprs)} to {paths[0]}"
          f"{' (and parts after it)' if split.splits else ''} (Ctrl-C ends)", file=sys.stderr)
    recorder.ask_latest()
    videos = [CameraVideo(name, connection, settings.video_fps, settings.video_resolution,
                          recorder.add_video).start() for name, connection in cameras]
    disk = DiskWatch(paths, settings.min_free_mb, lambda: recorder.write_error, reserve)
    try:
        _wait(recorder, stop, args.duration, settings.progress_s, disk)
    finally:
        for video in videos:
            video.stop()
        recorder.close()  # into the room kept in the file, however full the disk is now
        token.undeclare()
        try:
            recorder.out.close()
        except OSError as err:  # the rest of a full disk's buffer
            recorder.write_error = recorder.write_error or err
        session.close()
        restore()
    _summary(recorder.stats, paths)
    if disk.why:
        readable = "up to its last whole chunk" if recorder.write_error else "and finished"
        raise ToolError(f"stopped: {disk.why}; {paths[-1]} is readable {readable}"
                        f"{' (the parts before it are complete)' if len(paths) > 1 else ''}"
                        " — free space, or record to another disk", EXIT_DISK)
    return 0


def _recorder_id() -> str:
    """This recording's name on the bus: the host's and the process's."""
    host = re.sub(r"[^A-Za-z0-9_.-]", "-", socket.gethostname())[:48] or "host"
    return f"{host}-{os.getpid()}"


def _wait(recorder: Recorder, stop: threading.Event, duration: float | None,
          progress_s: float, disk: DiskWatch) -> None:
    started = time.monotonic()
    deadline = None if duration is None else started + duration
    before, progress_at = 0, started + progress_s
    while not disk.full() and not stop.wait(
            DISK_CHECK_S if deadline is None
            else max(0.0, min(DISK_CHECK_S, deadline - time.monotonic()))):
        now = time.monotonic()
        if deadline is not None and now >= deadline:
            return
        if now < progress_at:
            continue
        progress_at = now + progress_s
        total = sum(recorder.stats.samples.values())
        parts = f" in {len(disk.paths)} files" if len(disk.paths) > 1 else ""
        print(f"stb record: {now - started:.0f} s, {total} samples on "
              f"{len(recorder.stats.samples)} keys ({(total - before) / progress_s:.0f}/s), "
              f"{disk.size_mb():.1f} MB{parts}, {disk.free_mb() / 1e3:.1f} GB free",
              file=sys.stderr, flush=True)
        before = total


def _summary(stats: Stats, paths: list[Path]) -> None:
    total = sum(stats.samples.values())
    size = sum(p.stat().st_size for p in paths if p.exists()) / 1e6
    where = paths[0] if len(paths) == 1 else f"{len(paths)} files, {paths[0]} … {paths[-1]}"
    print(f"stb record: wrote {total} samples on {len(stats.samples)} keys to {where} "
          f"({size:.1f} MB)", file=sys.stderr)
    for key, count in sorted(stats.samples.items()):
        print(f"  {key}: {count}", file=sys.stderr)
    for what, count in sorted(stats.invalid.items()):
        print(f"  invalid (recorded as bytes only) {what}: {count}", file=sys.stderr)
    if stats.lost:
        print(f"  not written (the disk was full): {stats.lost}", file=sys.stderr)

