"""What a PTZ head whose axes do not meet at the lens leaves of the aim, through the PTZ
service's model (the axes meet at the optical centre: ``common.camera.head_pose``).

    .venv/bin/python -m benchmarks.head_offsets [--seeds 1-20] [--passpoints 150]

Per seed, the sim's head (``services.sim.ptz.PtzHead``, its own geometry) gets a tilt axis
off the pan axis and a lens in front of it, drawn at random within ±60 mm (the scale of a
compact PTZ head; no data sheet gives these offsets). The camera is calibrated as
``stb calib collect`` does at one hold (pan = tilt = 0 at ptz1's mount in the demo lab, the
data sheet's 3.8 mm, passpoints 2–7 m away with 0.5 px of noise), through the calib service's
solver; the pose is turned back into the mount at pan = tilt = 0 as the PTZ service does.
Then the PTZ service's aim (``services.ptz.aim.aim_at``) is pointed at 400 robot positions
over the crater (x, y within ±2 m, the marker 0.3 m above the floor) and the true head turned
there: the angle between where the true lens looks and the robot — and at zoom 9999 (46 mm),
where the robot is in the picture (its share of the picture's half-width from the centre;
the system test asks for the central 40 %, a share ≤ 0.4). The same without offsets, in the
same run, is the reference: what the calibration's noise alone leaves.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from benchmarks.gantry_table import seeds_of
from common.camera import Pose, mount_pose, project
from common.passpoints import Passpoints
from common.ptz_lens import axis_215
from services.calib.options import Options
from services.calib.solve import solve
from services.calib.synthetic import points_in_view
from services.ptz.aim import aim_at
from services.sim.ptz import PtzHead

MOUNT = Pose(3550, 1090, 2190, 180, 30, 165)  # ptz1 in the demo lab (services/sim/settings.py)
WIDE, LONG = axis_215(3.8), axis_215(46.0)
OFFSET_MM = 60.0


def drawn(seed: int) -> tuple[np.ndarray, PtzHead]:
    """Seed ``seed``'s robot positions (400, over the crater) and its head."""
    rng = np.random.default_rng(seed)
    robots = np.column_stack([rng.uniform(-2000, 2000, (400, 2)), np.full(400, 300.0)])
    tilt_axis = rng.uniform(-OFFSET_MM, OFFSET_MM, 3)
    centre = rng.uniform(-OFFSET_MM, OFFSET_MM, 3)
    return robots, PtzHead(MOUNT, tilt_axis_mm=(float(tilt_axis[0]), float(tilt_axis[1]),
                                                float(tilt_axis[2])),
                           optical_centre_mm=(float(centre[0]), float(centre[1]),
                                              float(centre[2])))


def calibrated_mount(head: PtzHead, rng: np.random.Generator, count: int) -> Pose:
    """The mount the PTZ service would use after a collection at pan = tilt = 0."""
    seen_from = head.pose_at(0.0, 0.0)
    world = points_in_view(seen_from, WIDE, rng, count)
    pixels = project(world, seen_from, WIDE) + rng.normal(0.0, 0.5, (count, 2))
    solution = solve(Passpoints(world, pixels), Options(focal_px=WIDE.focal_px))
    return mount_pose(solution.pose, 0.0, 0.0)


def aims(head: PtzHead, mount: Pose, robots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per robot position: the true angle (°) between the lens's view and the robot, and the
    robot's distance from the picture's centre at zoom 9999 as a share of the half-width."""
    angles, shares = [], []
    for robot in robots:
        pan, tilt = aim_at(robot, mount)
        true = head.pose_at(pan, tilt)
        seen = true.to_camera(robot[None, :])[0]
        angles.append(math.degrees(math.atan2(math.hypot(seen[1], seen[2]), seen[0])))
        u, _ = project(robot[None, :], true, LONG)[0]
        shares.append(abs(u - LONG.cy_px) / (LONG.width_px / 2))
    return np.array(angles), np.array(shares)


def run(seeds: list[int], count: int) -> list[dict]:
    rows = []
    for seed in seeds:
        robots, offset = drawn(seed)
        row: dict = {"seed": seed, "tilt_axis_mm": [round(v, 1) for v in offset.tilt_axis_mm],
                     "optical_centre_mm": [round(v, 1) for v in offset.optical_centre_mm]}
        for name, head in (("axes meet", PtzHead(MOUNT)), ("offsets", offset)):
            angle, share = aims(head, calibrated_mount(head, np.random.default_rng(
                (seed, 1)), count), robots)
            row[name] = {"angle_deg_p95": round(float(np.percentile(angle, 95)), 3),
                         "angle_deg_max": round(float(angle.max()), 3),
                         "share_p95": round(float(np.percentile(share, 95)), 3),
                         "share_max": round(float(share.max()), 3)}
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=seeds_of, default=seeds_of("1-20"))
    parser.add_argument("--passpoints", type=int, default=150)
    args = parser.parse_args()
    rows = run(args.seeds, args.passpoints)
    for name in ("axes meet", "offsets"):
        print(f"{name}: angle p95 worst {max(r[name]['angle_deg_p95'] for r in rows):.3f}°, "
              f"largest {max(r[name]['angle_deg_max'] for r in rows):.3f}°; share of the "
              f"half-width at zoom 9999: p95 worst "
              f"{max(r[name]['share_p95'] for r in rows):.3f}, largest "
              f"{max(r[name]['share_max'] for r in rows):.3f}")


if __name__ == "__main__":
    main()
