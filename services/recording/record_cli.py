"""``stb record OUT.mcap [KEYEXPR ...]``: every sample of the chosen keys into an MCAP file.

Default key expression: everything under the bus prefix (``stb/**``); what queryables hold
for those keys at the start (the camera poses) is asked for once and recorded too. Each sample
is written as it crossed the bus (msgpack) with its receive and measurement times, plus a JSON
copy with its schema (Foxglove's plots) and Foxglove's typed channels (a 3D scene of the
crater, robot, crane and camera cones; the previews with their detections); see
``common.mcap_file`` for the layout and docs/operator.md for the channels. Invalid payloads
are recorded too (as bytes, without a JSON copy) and counted. Ctrl-C, SIGTERM or
``--duration`` end the recording cleanly.

The tracking camera's raw frames (``stb/gantry/camera/frame``) are about 8 MB/s before
compression; leave them out with ``--exclude stb/gantry/camera/frame`` when they are not needed.
"""

from __future__ import annotations

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
    args = parser.parse_args(argv)
    from services.entry import tool_main
    from services.recording.record import record

    return tool_main("record", lambda: record(args))


if __name__ == "__main__":
    sys.exit(main())
