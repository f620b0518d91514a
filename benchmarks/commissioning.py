"""``stb gantry commission`` against a simulated lab whose geometry was drawn at random
(tests/geometry_truths.py): how long the crane moves, how long the whole command takes, and
how close each measured value comes to the sim's truth.

    .venv/bin/python -m benchmarks.commissioning [--seeds 7,8,9]

Each seed: the lab (router, sim with a parked robot and two targets, tracker) under ``stb up``
on free loopback ports, then the command as a lab runs it (``--yes``). Target (issue: the
lab's geometry): the crane's motion ≤ 3 min.
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common.tracking_camera import TrackingCameraModel
from services.args import Parser
from services.gantry.commissioning.geometry_fit import distortion_difference_px
from services.sim.lab import load_or_make_crater
from services.sim.settings import SimSettings
from tests.conftest import ROOT, client_settings, open_when_up, stb_process
from tests.geometry_truths import askew_lab_file, draw_truths
from tests.ports import free_port
from tests.services.test_processes import _stop


def one(seed: int, folder: Path) -> dict:
    crane, camera = draw_truths(seed)
    truth = folder / "truth.npz"
    load_or_make_crater(SimSettings(crater_file=truth, seed=seed))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    lab = askew_lab_file(folder, endpoint, truth, truth, crane, camera,
                         extra={"up": {"log_dir": str(folder / "logs"),
                                       "services": ["router", "sim", "tracker"]}})
    up = stb_process("up", "--lab", str(lab), "--no-view")
    try:
        open_when_up(client_settings(endpoint).zenoh).close()
        time.sleep(5)  # the sim's QTM and the tracker up
        started = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "services.cli", "gantry", "commission",
                               "--lab", str(lab), "--yes", "--json"], capture_output=True,
                              text=True, timeout=900, cwd=ROOT)
        wall = time.perf_counter() - started
    finally:
        _stop(up, signal.SIGINT, timeout=30)
    if done.returncode != 0:
        raise SystemExit(f"seed {seed}: {done.stderr[-3000:]}")
    found = json.loads(done.stdout)
    fitted = TrackingCameraModel(**{k: found["camera"][k]
                                    for k in TrackingCameraModel.model_fields})
    return {"motion_s": found["motion_s"], "wall_s": wall,
            "origin_mm": float(np.hypot(*np.subtract(found["frame"]["origin_mm"],
                                                     crane["origin_mm"]))),
            "yaw_deg": abs(found["frame"]["yaw_deg"] - crane["yaw_deg"]),
            "focal_pct": abs(fitted.focal_mm / camera["focal_mm"] - 1) * 100,
            "camera_yaw_deg": abs(fitted.yaw_deg - camera["yaw_deg"]),
            "offset_mm": float(np.hypot(*np.subtract(fitted.offset_mm, camera["offset_mm"]))),
            "distortion_px": distortion_difference_px(fitted, TrackingCameraModel(**camera))}


def main(argv: list[str] | None = None) -> int:
    parser = Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", default="7,8,9")
    args = parser.parse_args(argv)
    print("| seed | crane motion s | command s | origin mm | yaw ° | focal % | camera yaw ° |"
          " lens offset mm | distortion px |")
    print("|---|---|---|---|---|---|---|---|---|")
    for seed in (int(s) for s in args.seeds.split(",")):
        with tempfile.TemporaryDirectory(prefix="stb-commission-") as folder:
            r = one(seed, Path(folder))
        print(f"| {seed} | {r['motion_s']:.0f} | {r['wall_s']:.0f} | {r['origin_mm']:.1f} | "
              f"{r['yaw_deg']:.3f} | {r['focal_pct']:.3f} | {r['camera_yaw_deg']:.3f} | "
              f"{r['offset_mm']:.1f} | {r['distortion_px']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
