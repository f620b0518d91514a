"""``stb crater import`` of a large laser scan: wall time and peak memory of the command a lab
runs, beside the floor of reading the same file with plyfile alone, in the same run.

    .venv/bin/python -m benchmarks.crater_import [--points 10000000] [--runs 3]

The scan is ``stb sim scan`` of the sim's crater at the spacing that gives about --points
points, as binary PLY; each run is a fresh process started from this small one (its peak
resident memory from ``wait4``: a child's high-water mark counts what it inherited at the
fork, so the parent holds no points). Targets (issue: the lab's geometry): ≤ 30 s, ≤ 2 GB.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common.heightmap import HeightMap
from services.args import Parser

ROOT = Path(__file__).resolve().parents[1]
FLOOR = ("import sys, numpy as np; from plyfile import PlyData; "
         "v = PlyData.read(sys.argv[1])['vertex'].data; np.column_stack([v['x'], v['y'], v['z']])")
"""The floor: the file's points read into one array, nothing else."""


def timed(command: list[str]) -> tuple[float, float]:
    """(wall seconds, peak resident MB) of one process."""
    started = time.perf_counter()
    process = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - started
    if os.waitstatus_to_exitcode(status) != 0:
        said = process.stderr.read().decode() if process.stderr else ""
        raise SystemExit(f"{' '.join(command)} failed: {said[-2000:]}")
    return wall, usage.ru_maxrss / 1024


def accuracy(truth: Path, imported: Path) -> str:
    """The imported map against the sim's own surface, at every cell outside the holes."""
    heights, surface = HeightMap.load(imported), HeightMap.load(truth)
    with np.load(imported) as data:
        filled = np.asarray(data["filled"], dtype=bool)
    rows, cols = heights.heights_mm.shape
    xs = heights.origin_x_mm + np.arange(cols) * heights.resolution_mm
    ys = heights.origin_y_mm + np.arange(rows) * heights.resolution_mm
    error = np.abs(heights.heights_mm - surface.height_at(*np.meshgrid(xs, ys)))[~filled]
    median, p999, worst = np.percentile(error, [50, 99.9, 100])
    return (f"against the sim's surface outside the holes ({heights.resolution_mm:g} mm cells): "
            f"median {median:.2f} mm, 99.9 % {p999:.2f} mm, worst {worst:.2f} mm; "
            f"{100 * filled.mean():.1f} % of the cells filled")


def main(argv: list[str] | None = None) -> int:
    parser = Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--points", type=int, default=10_000_000)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--cell-mm", type=float, default=15.0)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="stb-crater-") as folder:
        truth, path = Path(folder) / "truth.npz", Path(folder) / "scan.ply"
        sim = [sys.executable, "-m", "services.cli", "sim", "scan", "--set",
               f"crater_file={truth}"]
        timed([*sim, "--out", str(Path(folder) / "small.ply"), "--spacing-mm", "100"])
        x0, x1, y0, y1 = HeightMap.load(truth).extent_mm  # the crater, made by the first scan
        spacing = float(np.sqrt((x1 - x0) * (y1 - y0) / args.points))
        made, made_peak = timed([*sim, "--out", str(path), "--spacing-mm", f"{spacing:.4f}"])
        size_mb = path.stat().st_size / 1e6
        print(f"stb sim scan: {size_mb / 24:.0f} M points (spacing {spacing:.2f} mm), "
              f"{size_mb:.0f} MB binary PLY in {made:.0f} s, peak {made_peak:.0f} MB")
        print("| run | stb crater import s | its peak MB | plyfile read alone s | its peak MB |")
        print("|---|---|---|---|---|")
        for run in range(args.runs):
            out = Path(folder) / f"map{run}.npz"
            wall, peak = timed([sys.executable, "-m", "services.cli", "crater", "import",
                                str(path), "--out", str(out), "--cell-mm", str(args.cell_mm)])
            floor, floor_peak = timed([sys.executable, "-c", FLOOR, str(path)])
            print(f"| {run + 1} | {wall:.1f} | {peak:.0f} | {floor:.1f} | {floor_peak:.0f} |",
                  flush=True)
        print(accuracy(truth, out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
