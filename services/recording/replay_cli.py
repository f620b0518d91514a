"""``stb replay IN.mcap [MORE.mcap ...] [--speed X]``: put a recording back on the bus with its
timing. The parts of a split recording (``stb record --split-size``) are given in order and go
out as one run; the files are read as they are sent (memory does not grow with their length).

Samples go out in the order they were received, spaced as they were (divided by ``--speed``).
By default every message's clock fields (``measured_s``, ``sent_s``, ``started_s``) are moved
to the replay's own time, so that services which drop stale samples take them as live: the
first sample is "now", later ones keep their offsets (scaled by the speed). ``--as-recorded``
sends the recorded bytes unchanged instead. ``--keys`` and ``--exclude`` choose what goes out;
replaying onto a lab bus whose services publish the same keys mixes two sources, so replay onto
a bus of its own (``stb router``) or leave those keys out.

On a lab router with access control, replay needs an identity allowed to put the keys.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from services.args import base_parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = base_parser("stb replay", __doc__ or "")
    parser.add_argument("recording", type=Path, nargs="+", metavar="IN.mcap",
                        help="the recording, or its parts in order")
    parser.add_argument("--speed", type=float, default=1.0, help="1 = as recorded, 2 = twice "
                        "as fast (default 1)")
    parser.add_argument("--keys", action="append", default=[], metavar="KEYEXPR",
                        help="replay only these keys (repeatable; default: all)")
    parser.add_argument("--exclude", action="append", default=[], metavar="KEYEXPR",
                        help="leave these keys out (repeatable)")
    parser.add_argument("--as-recorded", action="store_true",
                        help="send the recorded bytes unchanged (old time stamps)")
    args = parser.parse_args(argv)
    from services.entry import tool_main
    from services.recording.replay import replay_file

    return tool_main("replay", lambda: replay_file(args))


if __name__ == "__main__":
    sys.exit(main())
