"""The calib service loads no marker detector: it only draws the markers the cameras found, and
loading numba (a third of its start-up, more on a loaded machine) would delay its restart after
a crash (the fault campaign's "SIGKILL calib" row, docs/reliability.md)."""

from __future__ import annotations

import subprocess
import sys


def test_the_calib_service_starts_without_numba() -> None:
    probe = ("import sys, services.calib.service, services.calib.__main__; "
             "print(sorted(m for m in sys.modules if m.split('.')[0] in ('numba', 'llvmlite')))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         timeout=60, check=True).stdout.strip()
    assert out == "[]", out


def test_detection_still_loads_its_compiled_loop() -> None:
    """The loop (built ahead of time, or numba's JIT) loads at the first detection."""
    probe = ("import sys, numpy as np; from common.markers import detect; "
             "loops = lambda: [m for m in sys.modules if m.startswith(('common._markers_kernel', "
             "'common.markers_kernel'))]; before = loops(); "
             "f = np.zeros((16, 16), np.uint8); f[6:10, 6:10] = 255; "
             "print(detect(f).status, before, len(loops()))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         timeout=120, check=True).stdout.strip()
    assert out == "ok [] 1", out
