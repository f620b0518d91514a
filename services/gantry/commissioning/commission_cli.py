"""``stb gantry commission [--box MM] [--yes] [--toml OUT.toml]``: a crane's first day
(docs/commissioning.md): the geometry the gantry needs, measured, not assumed.

With the gantry service stopped, the motion capture seeing the marker on the crane's carriage
(``[gantry] crane_marker``, stuck at the tracking camera lens's height) and two targets
standing still below the crane (--targets, labelled in QTM: one on the floor, one raised by
0.5–1 m, a metre or less apart), it moves the crane, asking before each step unless --yes,
within --box mm around where it stands:

  frame     nine stops on a square; the crane's reports against its marker: [gantry.crane]
            origin_mm, yaw_deg, flip_x, flip_y (Umeyama's fit, its residual; a large residual
            or a scale off 1 is refused, saying why); the lens's height from the marker
  camera    a grid of stops that takes the targets across the whole image: focal_mm,
            principal_px, distortion, yaw_deg and offset_mm of [gantry.tracking_camera],
            fitted together (reprojection residual in pixels)
  dynamics  what stb gantry identify measures, through the frame and camera just fitted

It prints each value with its spread and writes them (--toml) with the lab file's section
names: copy them into the lab file. Exit status: 0 measured, 1 refused or cancelled (the
message says why), 2 bad arguments, 3 no crane controller, motion capture or camera frames.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from services.args import EXIT_CONFIG, base_parser

STEPS = ("frame", "camera", "dynamics")


def main(argv: Sequence[str]) -> int:
    parser = base_parser("stb gantry commission", __doc__ or "")
    parser.add_argument("--box", type=float, default=2500.0, metavar="MM",
                        help="the crane moves at most ±MM/2 around where it stands (2500)")
    parser.add_argument("--targets", default="target_1,target_2", metavar="LABEL,LABEL",
                        help="the motion capture's labels of the targets below the crane")
    parser.add_argument("--only", default=",".join(STEPS), metavar="STEP,...",
                        help="some of frame, camera, dynamics (others: as the lab file has "
                        "them)")
    parser.add_argument("--steps", type=int, default=8, help="dynamics: step responses (8)")
    parser.add_argument("--marker-above-lens-mm", type=float, default=0.0, metavar="MM",
                        help="the crane's marker above the lens, if not at its height")
    parser.add_argument("--max-frame-mm", type=float, default=10.0, metavar="MM",
                        help="refuse a frame fit whose residual is larger (10 mm rms)")
    parser.add_argument("--max-camera-px", type=float, default=1.0, metavar="PX",
                        help="refuse a camera fit whose residual is larger (1 px rms)")
    parser.add_argument("--yes", action="store_true", help="do not ask before moving")
    parser.add_argument("--toml", type=Path, metavar="OUT.toml", help="write the values here")
    parser.add_argument("--json", action="store_true", help="the figures as JSON on stdout")
    args = parser.parse_args(argv)
    args.targets = [t for t in args.targets.split(",") if t]
    args.only = [s for s in args.only.split(",") if s]
    unknown = sorted(set(args.only) - set(STEPS))
    if unknown or not args.only:
        parser.error(f"--only: steps are {', '.join(STEPS)} (got {', '.join(unknown) or '—'})")
    if not 200 <= args.box <= 10_000 or not 2 <= args.steps <= 100 or len(args.targets) < 1:
        print("stb gantry commission: --box must be 200–10000 mm, --steps 2–100, and at least "
              "one target", file=sys.stderr)
        return EXIT_CONFIG
    from services.gantry.commissioning.commission_run import commission

    return commission(args)
