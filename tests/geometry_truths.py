"""A lab whose geometry differs from every default the code has, drawn from a seed: the crane
counting from its home corner with a flipped axis and a small yaw, the tracking camera
askew, off-centre, offset on the carriage and bending the image's corners by tens of pixels.

Where the ranges come from: a crane's home corner is its travel's end (here beyond the
crater's rim); gantry axes are aligned to a room by eye and tape to a degree or so (1–3°);
a camera mounted by hand sits 2–4° askew and a few centimetres off the carriage's reference
(30–60 mm); the lens bends as the 640 × 480 camera of OpenCV's calibration tutorial does (its
sample chessboard images give k1 −0.29, k2 0.11, p1 0.001, p2 −0.0002, k3 0.04), scaled by
0.7–1.1 (its corners move 20–35 px behind an 8 mm lens, 5–10 px behind 11 mm); a principal
point within 10 px of the image's centre; the lens 3.38–3.48 m up; its focal length 6–12 mm
(the code's default is 8 mm; C-mount lenses for a 1/3-inch chip are sold from 2.8 to 50 mm,
and 6–12 mm see 2.7–1.4 m of ground across the 4.8 mm chip from 3.4 m: the robot and the
targets stay in view)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import tomli_w

OPENCV_SAMPLE = np.array([-0.29, 0.11, 0.001, -0.0002, 0.04])
TARGETS = [[350.0, 250.0, 0.0], [-300.0, -250.0, 700.0]]
"""Commissioning targets near the parked robot (0, 0): one on the floor, one raised 0.7 m."""


def draw_truths(seed: int) -> tuple[dict, dict]:
    """(the sim's [sim.crane] frame and travel, its [sim.tracking_camera] lens and mount)."""
    rng = np.random.default_rng((seed, 34))
    sign = rng.choice([-1.0, 1.0])
    origin = (-3600.0 + rng.uniform(-300, 300), 3300.0 + rng.uniform(-300, 300))
    crane = {"origin_mm": origin, "yaw_deg": float(sign * rng.uniform(1.0, 3.0)),
             "flip_y": True, "x_min_mm": 0.0, "x_max_mm": 7600.0, "y_min_mm": 0.0,
             "y_max_mm": 7000.0}
    angle = rng.uniform(0, 2 * np.pi)
    reach = rng.uniform(30.0, 60.0)
    camera = {"principal_px": tuple(float(c) for c in (320.0, 240.0) + rng.uniform(-10, 10, 2)),
              "distortion": tuple(float(k) for k in OPENCV_SAMPLE * rng.uniform(0.7, 1.1)),
              "yaw_deg": float(rng.choice([-1.0, 1.0]) * rng.uniform(2.0, 4.0)),
              "offset_mm": (float(reach * np.cos(angle)), float(reach * np.sin(angle))),
              "height_mm": float(rng.uniform(3380.0, 3480.0))}
    camera["focal_mm"] = float(rng.uniform(6.0, 12.0))
    return crane, camera


def askew_lab_file(folder: Path, endpoint: str, truth_map: Path, gantry_map: Path, crane: dict,
              camera: dict, extra: dict | None = None) -> Path:
    """The lab: the sim's truths (parked robot, two targets) and the gantry's own view."""
    folder.mkdir(parents=True, exist_ok=True)
    from tests.sim.test_sim_service import write_lab

    lab, _ = write_lab(folder, endpoint, truth_map)
    doc = tomllib.loads(lab.read_text())
    doc["sim"].update(scenario="parked", targets=TARGETS)
    doc["sim"]["crane"].update(crane)
    doc["sim"]["tracking_camera"] = dict(camera)
    doc["gantry"]["height_map"] = str(gantry_map)
    doc["router"] = {"listen": [endpoint]}
    doc["up"] = {"log_dir": str(folder / "logs"),
                 "services": ["router", "sim", "tracker", "gantry"]}
    for section, values in (extra or {}).items():
        doc.setdefault(section, {}).update(values)
    lab.write_text(tomli_w.dumps(doc))
    return lab
