"""``stb foxglove [KEYEXPR ...]``: the bus, live, in Foxglove.

Serves Foxglove's WebSocket protocol (foxglove-sdk's server) on ``[foxglove] host:port``
(127.0.0.1:8765; 0.0.0.0 for the lab LAN). In Foxglove: Open connection → Foxglove
WebSocket → ws://HOST:8765, then import the layout docs/foxglove-layout.json. Channels:
/scene and /crater (3D: the crater's mesh, robot and its track, crane and its cable, each
camera's view cone), /tf (world → cameras, robot, crane), /ptz1/image and /ptz1/annotations
(previews with the markers found and where the robot should be), /gantry/image, and every
bus key's JSON copy with its schema (json/<key>) for plots. The same channels as in a
recording of ``stb record``. Ctrl-C or SIGTERM ends it.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.args import base_parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = base_parser("stb foxglove", __doc__ or "")
    parser.add_argument("key_exprs", nargs="*", metavar="KEYEXPR",
                        help="what to serve (default: <prefix>/**)")
    args = parser.parse_args(argv)
    from services.entry import tool_main
    from services.recording.live import serve

    return tool_main("foxglove", lambda: serve(args))


if __name__ == "__main__":
    sys.exit(main())
