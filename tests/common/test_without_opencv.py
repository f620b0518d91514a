"""OpenCV costs a process about 30 MB: the services that need it for nothing load it never
(docs/benchmarks.md, "Memory": the demo lab's sum). The observation service passes JPEGs on
undecoded; the page draws the crater's map (with OpenCV and matplotlib) only when first asked;
the gantry and the PTZ services decode their JPEGs with Pillow and detect with the compiled
loop; the sim's QTM process draws no picture."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import ROOT

JPEG_OF_A_PICTURE = (
    "from PIL import Image; import io, numpy as np; b = io.BytesIO(); "
    "Image.fromarray((np.arange(480 * 640) % 251).astype(np.uint8).reshape(480, 640))"
    ".save(b, 'JPEG'); data = b.getvalue()")

WORK = {
    "observation": "import services.observation.__main__, services.observation.service",
    "web": "import services.web.__main__, services.web.service, services.web.app",
    "gantry": ("import services.gantry.__main__, services.gantry.service; "
               "from services.gantry.frames import decode; from common import messages as m; "
               "from common.markers import detect, warm_up; warm_up(); "
               f"{JPEG_OF_A_PICTURE}; got = decode(m.CameraFrame(measured_s=1.0, "
               "camera='tracking', seq=1, width_px=640, height_px=480, encoding='jpeg', "
               "data=data)); assert got is not None; detect(got[1])"),
    "ptz": ("import services.ptz.__main__, services.ptz.service; "
            f"from common.jpeg import decode_gray; {JPEG_OF_A_PICTURE}; "
            "assert decode_gray(data).shape == (480, 640)"),
    "sim's QTM process": "import services.sim.device_process, services.sim.mocap_server",
}


def _loaded(code: str, module: str) -> bool:
    done = subprocess.run([sys.executable, "-c", f"{code}\nimport sys; print({module!r} in "
                           "sys.modules)"], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.split()[-1] == "True"


@pytest.mark.parametrize("process", list(WORK))
def test_a_service_that_needs_no_opencv_never_loads_it(process: str) -> None:
    assert not _loaded(WORK[process], "cv2"), f"{process} loaded OpenCV"


def test_the_observation_service_passes_pictures_on_without_numpy() -> None:
    assert not _loaded(WORK["observation"], "numpy")
