"""The sim's PTZ camera pictures: how long a snapshot takes on the path the PTZ service uses.

    .venv/bin/python -m benchmarks.pictures [--snapshots 60]

One simulated camera (ptz1 of the default lab, its crater made from the seed) served over
HTTP with Digest, exactly as ``stb sim`` serves it; this process asks for
``image.cgi?resolution=704x576`` as the PTZ service does and times each reply:

* following: the camera turns 0.5° before every snapshot (a new view each time: the crater
  is ray-cast again), as previews while it follows (2 a second per camera);
* still: the camera stands (the crater view is reused), as in calibration mode (10 a
  second);

each with the IR cut filter on (day view) and off (IR view). The reference in the same run
is the plain field the sim drew before (markers on a uniform gray, no crater): what the
crater costs on top. The figures are the milliseconds per snapshot, p50 and p95, and the
snapshots a second one camera could deliver on one core.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

from services.args import Parser
from services.sim.camera_server import CameraServer, SimCamera
from services.sim.lab import Lab
from services.sim.scene import GroundView
from services.sim.settings import SimSettings


def _serve(lab: Lab, picture: bool) -> CameraServer:
    cam = lab.settings.cameras[0]
    t0 = time.monotonic()

    def clock() -> float:
        return time.monotonic() - t0

    sim = SimCamera(cam.name, lab.heads[cam.name], lab.bright_points,
                    lab.ptz_glints, clock, np.random.default_rng(0), cam.user, cam.password,
                    ground=GroundView.of(lab.crater, lab.settings.seed) if picture else None,
                    robots=lambda t: [lab.robot_pose(t)])
    return CameraServer(sim, "127.0.0.1", 0).start()


def _times(client: httpx.Client, snapshots: int, moving: bool, infrared: bool) -> np.ndarray:
    ptz, image = "/axis-cgi/com/ptz.cgi", "/axis-cgi/jpg/image.cgi"
    client.get(ptz, params={"ircutfilter": "off" if infrared else "auto"})
    out = []
    for k in range(snapshots):
        if moving:
            client.get(ptz, params={"rpan": "0.5" if k % 40 < 20 else "-0.5"})
            time.sleep(0.13)  # past the camera's command latency: a new view
        started = time.perf_counter()
        reply = client.get(image, params={"resolution": "704x576"})
        out.append(time.perf_counter() - started)
        assert reply.status_code == 200 and reply.headers["content-type"] == "image/jpeg"
    return 1e3 * np.array(out)


def main() -> None:
    parser = Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--snapshots", type=int, default=60)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        lab = Lab.build(SimSettings(crater_file=Path(tmp) / "crater.npz"))
        print(f"{'picture':<14}{'camera':<11}{'filter':<8}{'p50 ms':>8}{'p95 ms':>8}"
              f"{'per s':>8}")
        for picture in (True, False):
            server = _serve(lab, picture)
            cam = lab.settings.cameras[0]
            with httpx.Client(base_url=f"http://127.0.0.1:{server.port}", timeout=5,
                              auth=httpx.DigestAuth(cam.user, cam.password)) as client:
                for moving in (True, False):
                    for infrared in (False, True):
                        ms = _times(client, args.snapshots, moving, infrared)
                        p50, p95 = np.percentile(ms, [50, 95])
                        print(f"{'crater' if picture else 'plain (before)':<14}"
                              f"{'following' if moving else 'still':<11}"
                              f"{'off (IR)' if infrared else 'on':<8}{p50:8.1f}{p95:8.1f}"
                              f"{1e3 / p50:8.0f}")
            server.close()


if __name__ == "__main__":
    main()
