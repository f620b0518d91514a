"""Where calibrations live on disk, so that a pose survives a restart of any service.

``<data_dir>/<camera>/pose.json`` — the CameraPose message fields plus the solver's report;
``passpoints.csv`` and ``track.csv`` — what it was solved from (``stb calib solve`` reads
them back); ``images/NNN.jpg`` — each passpoint's snapshot with the detected marker drawn
(the paper keeps these to sort out wrong passpoints by eye).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from common import messages as m
from common.files import write_atomically
from common.passpoints import Passpoints, Track, write_passpoints

log = logging.getLogger(__name__)


class PoseStore:
    def __init__(self, data_dir: Path) -> None:
        self.data_dir = data_dir

    def camera_dir(self, camera: str) -> Path:
        return self.data_dir / camera

    def load(self, camera: str) -> m.CameraPose | None:
        """The stored pose, or None if there is none or it cannot be read (logged)."""
        path = self.camera_dir(camera) / "pose.json"
        if not path.exists():
            return None
        try:
            data = json.loads(path.read_text())
            return m.CameraPose.model_validate(data["pose"], strict=False)
        except (OSError, ValueError, KeyError, TypeError, ValidationError) as err:
            log.error("cannot read %s (%s); %s needs calibrating again", path, err, camera)
            return None

    def save(self, pose: m.CameraPose, report: dict) -> Path:
        path = self.camera_dir(pose.camera) / "pose.json"
        text = json.dumps({"pose": pose.model_dump(mode="json"), "report": report}, indent=1)
        write_atomically(path, text.encode())  # a crash never leaves half a pose behind
        return path

    def save_inputs(self, camera: str, points: Passpoints, track: Track) -> None:
        folder = self.camera_dir(camera)
        write_passpoints(folder / "passpoints.csv", points)
        rows = np.column_stack([track.times_s, track.xyz_mm])
        np.savetxt(folder / "track.csv", rows, delimiter=",", header="t,X,Y,Z", comments="",
                   fmt=["%.6f", "%.3f", "%.3f", "%.3f"])

    def image_dir(self, camera: str) -> Path:
        folder = self.camera_dir(camera) / "images"
        folder.mkdir(parents=True, exist_ok=True)
        return folder
