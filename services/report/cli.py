"""``stb report IN.mcap [MORE.mcap ...] --out DIR``: the paper's plots of a recorded run as PNG
and a one-page HTML summary (``DIR/index.html``) with the run's figures. A split recording's
parts (``stb record --split-size``) are given in order and reported as one run; the files are
read once, as a stream (memory grows with the series the plots need, not with the video).

The tracks are drawn over the crater's height map (``--height-map``, default: the gantry's
``height_map`` from the lab file, if the file exists). Calibration residuals are computed again
from the passpoints found in the recording (the calib collector over its mocap frames and
detections, marker ``--calib-marker``); without a calibration in the recording the plot shows
each recorded pose's own fit error.

Moments of the run — the largest crane error and where alarms began (the crane reacquiring,
stale, at fault, stopped or unreachable; the sideways pull above its limit) — get stills from
every video in the recording (the observation camera's bird's-eye view, the PTZ cameras' videos
and previews, the tracking camera), under "Moments" in the page. ``--video`` also exports
``DIR/birdseye.mp4``: the bird's-eye view with the crane's error written over it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from services.args import Parser, plain


def main(argv: Sequence[str] | None = None) -> int:
    parser = Parser(prog="stb report", description=plain(__doc__ or ""),
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", type=Path, nargs="+", metavar="IN.mcap",
                        help="the recording, or its parts in order")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR")
    parser.add_argument("--lab", type=Path, metavar="FILE", help="lab config (height map path)")
    parser.add_argument("--height-map", type=Path, metavar="FILE.npz")
    parser.add_argument("--calib-marker", default="wand",
                        help="label of the calibration marker (default: wand)")
    parser.add_argument("--prefix", default="stb", help="key prefix of the recording")
    parser.add_argument("--video", action="store_true",
                        help="also DIR/birdseye.mp4: the observation camera's bird's-eye view "
                        "with the crane's error written over it")
    parser.add_argument("--video-seconds", type=float, default=60.0, metavar="S",
                        help="the MP4's length, around the largest crane error (default 60; "
                        "0: the whole run)")
    args = parser.parse_args(argv)
    from services.report.page import report

    return report(args)


if __name__ == "__main__":
    sys.exit(main())
