"""``stb sim scan --out FILE [--spacing-mm N] [--noise-mm N] [--ascii] [--seed N]``: the sim's
crater as a laser scanner would deliver it — a point cloud in world coordinates (mm) with its
own density, a few millimetres of noise, and holes where the scanner's two stations could not
see the ground (services/sim/scan.py). FILE: .ply (binary; --ascii for text), .xyz or .csv.
The crater is the sim's own (``[sim] crater_file``, made from the seed if missing), the truth
the gantry does not see: ``stb crater import FILE --out crater.npz`` makes its height map.
Exit status: 0 written, 2 bad arguments.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from services.args import base_parser


def main(argv: Sequence[str]) -> int:
    parser = base_parser("stb sim scan", __doc__ or "")
    parser.add_argument("--out", type=Path, required=True, metavar="FILE")
    parser.add_argument("--spacing-mm", type=float, default=3.0,
                        help="one point per spacing² of ground, on average (3)")
    parser.add_argument("--noise-mm", type=float, default=2.0, help="scatter, 1σ (2)")
    parser.add_argument("--ascii", action="store_true", help="PLY as text")
    parser.add_argument("--seed", type=int, default=0, help="the scanner's own randomness")
    args = parser.parse_args(argv)
    if not 1.0 <= args.spacing_mm <= 500.0 or not 0.0 <= args.noise_mm <= 100.0:
        parser.error("--spacing-mm must be 1–500 and --noise-mm 0–100")
    from services.entry import tool_main

    return tool_main("sim scan", lambda: _scan(args))


def _scan(args: argparse.Namespace) -> int:
    import numpy as np

    from common.pointcloud import SUFFIXES, write_points
    from services.entry import ToolError, tool_settings
    from services.sim.lab import load_or_make_crater
    from services.sim.scan import ScanOptions, scan
    from services.sim.settings import SimSettings

    if SUFFIXES.get(args.out.suffix.lower()) not in ("PLY", "XYZ", "CSV"):
        raise ToolError(f"{args.out}: write .ply, .xyz or .csv")
    crater = load_or_make_crater(tool_settings(SimSettings, args))
    points = scan(crater, np.random.default_rng(args.seed),
                  ScanOptions(spacing_mm=args.spacing_mm, noise_mm=args.noise_mm))
    write_points(args.out, points, ascii_ply=args.ascii)
    print(f"wrote {args.out}: {len(points)} points")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
