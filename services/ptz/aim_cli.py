"""``stb ptz aim``: pan and tilt that point a calibrated camera at a world point (eq. 4)."""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from services.args import Parser, plain

if TYPE_CHECKING:  # imported once the flags are parsed: --help answers at once
    from common.camera import Pose


def main(argv: Sequence[str] | None = None) -> int:
    parser = Parser(prog="stb ptz aim", description=plain(__doc__ or ""))
    parser.add_argument("--pose", type=Path, required=True,
                        help="the pose: as stb calib solve --json prints it (position_mm, "
                             "orientation_deg) or as the calib service stores it "
                             "(run/calib/<camera>/pose.json)")
    parser.add_argument("--target", required=True,
                        help="X,Y,Z in mm (world frame), e.g. -1200,300,0")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(sys.argv[1:] if argv is None else list(argv))
    import numpy as np

    from common.camera import PtzLimits
    from services.ptz.aim import aim_at

    try:
        pose = _read_pose(args.pose)
        target = np.array([float(v) for v in args.target.split(",")])
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise ValueError("--target needs three finite numbers X,Y,Z")
    except (OSError, ValueError, KeyError, TypeError) as err:
        print(f"stb ptz aim: {err}", file=sys.stderr)
        return 2
    pan, tilt = aim_at(target, pose, PtzLimits(-180.0, 180.0, -90.0, 90.0))
    out = {"pan_deg": pan, "tilt_deg": tilt}
    print(json.dumps(out) if args.json else f"pan {pan:.3f}°  tilt {tilt:.3f}°")
    return 0


def _read_pose(path: Path) -> Pose:
    from common.camera import Pose

    data = json.loads(path.read_text())
    if "pose" in data:  # the calib service's pose.json: the CameraPose message's fields
        p = data["pose"]
        return Pose(*(float(p[k]) for k in ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg",
                                             "rz_deg")))
    position, orientation = data["position_mm"], data["orientation_deg"]
    if len(position) != 3 or len(orientation) != 3:
        raise ValueError(f"{path}: position_mm and orientation_deg need three numbers each")
    return Pose(*map(float, position), *map(float, orientation))
