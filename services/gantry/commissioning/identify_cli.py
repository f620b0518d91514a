"""``stb gantry identify``: measure the crane that is there (docs/commissioning.md).

    stb gantry identify [--box MM] [--steps N] [--yes] [--lab FILE]

With the gantry service stopped and a marker standing still below the crane (the robot,
parked), it moves the crane within a box of --box mm around where it stands — steps, long
moves, a slow ramp — and measures from the controller's registers and the tracking camera:
the sampling period, the dead time and total reaction, how old the reported position is, the
top speed and the acceleration. It prints them with their spread and as [gantry] settings.
It asks before it moves the crane (--yes: do not ask). Exit status: 0 measured, 1 not safe to
start or cancelled, 2 bad arguments, 3 no crane controller or no camera frames.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.args import EXIT_CONFIG, base_parser


def main(argv: Sequence[str]) -> int:
    parser = base_parser("stb gantry identify", __doc__ or "")
    parser.add_argument("--box", type=float, default=400.0, metavar="MM",
                        help="the crane moves at most ±MM/2 around where it stands (400)")
    parser.add_argument("--steps", type=int, default=12, help="step responses (12)")
    parser.add_argument("--yes", action="store_true", help="do not ask before moving")
    parser.add_argument("--json", action="store_true", help="the figures as JSON on stdout")
    args = parser.parse_args(argv)
    if not 50 <= args.box <= 2000 or not 2 <= args.steps <= 100:
        print("stb gantry identify: --box must be 50–2000 mm, --steps 2–100", file=sys.stderr)
        return EXIT_CONFIG
    from services.gantry.commissioning.identify_tool import identify

    return identify(args)
