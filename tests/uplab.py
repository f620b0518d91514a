"""The whole simulated lab for ``stb up`` on free loopback ports, with both cameras' poses
stored as a finished calibration leaves them (the operator tests and the fault campaign)."""

from __future__ import annotations

import time
from pathlib import Path

from common import messages as m
from services.calib.store import PoseStore
from tests.calib.test_demo_calibration import MOUNTS
from tests.ports import free_port
from tests.sim.test_sim_service import write_lab

SERVICES = ["router", "sim", "tracker", "calib", "ptz:ptz1", "ptz:ptz2", "gantry", "web"]
"""Every service: the whole lab."""


def store_poses(data_dir: Path, version: int = 0) -> None:
    """The cameras' poses as a finished calibration leaves them on disk."""
    store = PoseStore(data_dir)
    for camera, mount in MOUNTS.items():
        store.save(m.CameraPose(measured_s=time.time(), camera=camera, **mount.fields(),
                                focal_px=743.1, mean_error_px=1.5, passpoints=100,
                                version=version),
                   {"method": "stored"})


OPERATOR = ("olga", "olga-operator-pw")
VIEWER = ("victor", "victor-viewer-pw")
"""The page's users in a lab written with ``users=True``: (name, password)."""


def write_users(path: Path) -> Path:
    """A users file with ``OPERATOR`` and ``VIEWER``."""
    from services.web.users import Role, Users

    users = Users.load(path)
    users.add(OPERATOR[0], Role.OPERATOR, OPERATOR[1])
    users.add(VIEWER[0], Role.VIEWER, VIEWER[1])
    return path


def write_up_lab(folder: Path, services: list[str], pose_version: int = 0,
                 users: bool = False) -> tuple[Path, str, int]:
    """A lab file in ``folder`` running ``services`` under ``stb up``, the poses stored:
    (the lab file, the router's endpoint, the web page's port). With ``users`` the page needs
    a sign-in (``OPERATOR``, ``VIEWER``); without, it is open on loopback."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    lab, _ = write_lab(folder, endpoint, folder / "crater.npz")
    web_port = free_port()
    listed = ", ".join(f'"{s}"' for s in services)
    with open(lab, "a") as f:
        f.write(f'\n[router]\nlisten = ["{endpoint}"]\n[up]\nlog_dir = "{folder / "logs"}"\n'
                f'services = [{listed}]\n[web]\nport = {web_port}\n'
                f'height_map = "{folder / "crater.npz"}"\n'
                f'recordings_dir = "{folder / "recordings"}"\n')
        if users:
            f.write(f'users_file = "{write_users(folder / "users.json")}"\n')
    store_poses(folder / "calib", pose_version)
    return lab, endpoint, web_port
