"""``stb crater import SCAN --out crater.npz [--cell-mm N] [--units auto|mm|m] [--plot PNG]``:
the gantry's height map (paper §3.1's look-up table) from a laser scan of the crater.
``stb crater from-sim [--lab FILE]``: a simulated lab's first start — the sim's laser scan
imported to ``[gantry] height_map`` unless it is there (what ``stb up`` does; the compose
sim lab's one-shot service ``crater``).

SCAN is a point cloud in the world's (the motion capture's) frame: PLY (ASCII or binary),
LAS/LAZ, or XYZ/CSV text (three numbers a line, an optional header). Its points are binned to
cells of --cell-mm (15), a plane fitted in each cell; cells the scanner did not see are filled
by interpolation from their neighbours and reported (how many, and the largest hole), and
--plot draws the map with the filled cells marked. --units: the file's length unit (auto:
metres if the scan spans less than 50 units, else millimetres). The map is written with the
filled cells marked (``filled``, beside the heights). Then point [gantry] height_map at the
output (the page and the recorders read it too). Exit status: 0 written, 2 a bad file or
argument.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from services.args import EXIT_CONFIG, base_parser

METRES_BELOW = 50.0  # a scan spanning less than this many units is in metres


def main(argv: Sequence[str] | None = None) -> int:
    parser = base_parser("stb crater", __doc__ or "")
    parser.add_argument("action", choices=["import", "from-sim"])
    parser.add_argument("scan", type=Path, metavar="SCAN", nargs="?")
    parser.add_argument("--out", type=Path, metavar="crater.npz")
    parser.add_argument("--cell-mm", type=float, default=15.0, help="grid cell (15 mm)")
    parser.add_argument("--units", choices=["auto", "mm", "m"], default="auto")
    parser.add_argument("--plot", type=Path, metavar="PNG", help="a picture of the map")
    args = parser.parse_args(sys.argv[1:] if argv is None else list(argv))
    if args.action == "from-sim":
        return _from_sim(args.lab)
    if args.scan is None or args.out is None:
        parser.error("import needs SCAN and --out")
    if not 1.0 <= args.cell_mm <= 1000.0:
        print("stb crater import: --cell-mm must be 1–1000 mm", file=sys.stderr)
        return EXIT_CONFIG
    from services.entry import ToolError, tool_main

    def run() -> int:
        try:
            return _import(args)
        except ValueError as err:
            raise ToolError(str(err), EXIT_CONFIG) from err

    return tool_main("crater import", run)


def _from_sim(lab: Path | None) -> int:
    from common.errors import ConfigError
    from common.lab_views import GantryHeightMap, SimCraterFile
    from common.node import configure_logging
    from common.settings import load_settings
    from services.crater.first_start import (
        FirstStartError,
        height_map_to_import,
        import_sim_scan,
    )

    try:
        height_map = load_settings(GantryHeightMap, lab).height_map
        sim_crater = load_settings(SimCraterFile, lab).crater_file
    except ConfigError as err:
        print(f"stb crater from-sim: {err}", file=sys.stderr)
        return EXIT_CONFIG
    configure_logging("INFO")
    if not height_map_to_import(["sim"], height_map, sim_crater):
        print(f"{height_map}: there already (or the sim's own crater): nothing to do")
        return 0
    try:
        import_sim_scan(lab, height_map)
    except FirstStartError as err:
        print(f"stb crater from-sim: {err}", file=sys.stderr)
        return 1
    print(f"wrote {height_map} from the sim's laser scan")
    return 0


def _import(args: argparse.Namespace) -> int:
    import numpy as np

    from common.pointcloud import read_points
    from services.crater.grid import grid_points

    started = time.monotonic()
    points = read_points(args.scan)
    span = float(np.ptp(points[:, :2], axis=0).max())
    units = args.units
    if units == "auto":
        units = "m" if span < METRES_BELOW else "mm"
    if units == "m":
        points *= 1000.0
    try:
        gridded = grid_points(points, args.cell_mm)
    except ValueError as err:
        raise ValueError(f"{args.scan}: {err}") from err
    gridded.heights.save(args.out, filled=gridded.filled)
    print(f"{args.scan}: read in {units}; {gridded.report()}")
    if args.plot:
        from services.crater.plot import plot_map

        plot_map(gridded, args.plot)
        print(f"picture: {args.plot}")
    print(f"wrote {args.out} in {time.monotonic() - started:.1f} s: set [gantry] height_map "
          "to it")
    return 0
