"""``stb record OUT.mcap [KEYEXPR ...]``: every sample of the chosen keys into an MCAP file.

Default key expression: everything under the bus prefix (``stb/**``); what queryables hold
for those keys at the start (the camera poses) is asked for once and recorded too. Each sample
is written as it crossed the bus (msgpack) with its receive and measurement times, plus a JSON
copy with its schema (Foxglove's plots) and Foxglove's typed channels (a 3D scene of the
crater, robot, crane and camera cones; the previews with their detections); see
``common.mcap_file`` for the layout and docs/operator.md for the channels. Invalid payloads
are recorded too (as bytes, without a JSON copy) and counted. Ctrl-C, SIGTERM or
``--duration`` end the recording cleanly.

``--video ptz1 --video ptz2`` takes each camera's video straight from the camera (VAPIX
``mjpg/video.cgi`` at ``--video-fps``, 5 by default, at the camera's own size unless
``[record] video_resolution`` names one), stamped when each frame arrived,
into ``video/<camera>`` — beside the mocap and gantry channels on the same clock; replay puts
it on the bus, Foxglove shows it on ``/<camera>/video``.

Camera streams — the tracking camera's frames (``stb/gantry/camera/frame``) and the
``--video`` cameras — go into the file as H.264 video (libx264 through PyAV) on Foxglove's
``CompressedVideo`` channels ``/gantry/image`` and ``/<camera>/video``, each frame stamped with
its capture time. Their raw frames (about 8 MB/s for the tracking camera) only with
``--raw-frames``: what ``stb replay`` needs to feed a gantry again. The observation camera's
bird's-eye view (``stb observation``, on ``stb/video/observation``) is recorded the same way,
on ``/observation/video``, and so are a PTZ camera's snapshots in calibration mode
(``stb/ptz/<camera>/snapshot``) on ``/<camera>/snapshot``.

Long runs: ``--split-size MB`` and ``--split-time S`` start a new file when the current one is
that large or long — ``OUT-001.mcap``, ``OUT-002.mcap``, …, each a complete recording (its
summary, the camera poses again, every video starting with a keyframe); ``stb report`` and
``stb replay`` take the parts as one run. The progress line shows the elapsed time, the size
so far and the free space; below ``[record] min_free_mb`` free (or when a write fails) the
recording stops with exit 5, its file readable.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path

from services.args import base_parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = base_parser("stb record", __doc__ or "")
    parser.add_argument("out", type=Path, metavar="OUT.mcap")
    parser.add_argument("key_exprs", nargs="*", metavar="KEYEXPR",
                        help="what to record (default: <prefix>/**)")
    parser.add_argument("--exclude", action="append", default=[], metavar="KEYEXPR",
                        help="leave these keys out (repeatable)")
    parser.add_argument("--duration", type=float, help="stop after this many seconds")
    parser.add_argument("--video", action="append", default=None, metavar="CAMERA",
                        help="also record this camera's video (VAPIX MJPEG; a camera of "
                        "[ptz.cameras]; repeatable)")
    parser.add_argument("--video-fps", type=float, metavar="FPS",
                        help="video frames a second per camera (default 5)")
    parser.add_argument("--split-size", type=float, metavar="MB",
                        help="start a new file at this size (OUT-001.mcap, OUT-002.mcap, …; "
                        "each a complete recording)")
    parser.add_argument("--split-time", type=float, metavar="S",
                        help="start a new file after this many seconds")
    parser.add_argument("--raw-frames", action="store_true",
                        help="also the camera frames as they crossed the bus (large)")
    args = parser.parse_args(argv)
    if args.raw_frames:
        args.set[:0] = ["raw_frames=true"]
    if args.split_size is not None:
        args.set[:0] = [f"split_mb={args.split_size}"]
    if args.split_time is not None:
        args.set[:0] = [f"split_s={args.split_time}"]
    if args.video:  # the flags are settings of [record]: --set has the last word
        args.set[:0] = [f"video={json.dumps(args.video)}"]
    if args.video_fps is not None:
        args.set[:0] = [f"video_fps={args.video_fps}"]
    from services.entry import tool_main
    from services.recording.record import record

    return tool_main("record", lambda: record(args))


if __name__ == "__main__":
    sys.exit(main())
