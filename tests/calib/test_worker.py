"""The calib service solves in a short-lived worker process (``services/calib/worker.py``): the
result and the errors come back as from a call, and the service itself never loads the solvers
(scipy, cma, matplotlib: about 100 MB that stayed once it had solved)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from common.passpoints import CalibrationError, Passpoints
from services.calib.options import Options
from services.calib.synthetic import PAPER_POSE, zoom_passpoints
from services.calib.worker import in_worker, solve_one_zoom
from tests.calib.test_zoom_fit import drawn_lens
from tests.conftest import ROOT

ZOOMS = [1, 5000, 9999]


def test_the_solvers_never_load_in_the_service_and_the_fit_comes_back(tmp_path: Path) -> None:
    """In a fresh interpreter that loads what the service loads, a collection session's zoom
    fit gives the pose with the lens and draws lens.png, and scipy, cma and matplotlib are
    still not loaded there."""
    rng = np.random.default_rng(3)
    truth = drawn_lens(rng)
    sets = zoom_passpoints(PAPER_POSE, truth, ZOOMS, rng, count=60)
    arrays: dict[str, Any] = {f"world{s.zoom}": s.world_mm for s in sets}
    arrays.update({f"pixels{s.zoom}": s.pixels for s in sets})
    np.savez(tmp_path / "points.npz", **arrays)
    script = textwrap.dedent(f"""
        import sys, threading
        from pathlib import Path
        from types import SimpleNamespace
        import numpy as np
        from common import messages as m
        from common.passpoints import Passpoints
        from services.calib.service import Session  # what the service loads
        from services.calib.settings import CalibSettings
        from services.calib.store import PoseStore
        data = np.load({str(tmp_path / "points.npz")!r})
        node = SimpleNamespace(stop=threading.Event(), bus=SimpleNamespace(
            publish=lambda key, msg, **where: print(msg.message, file=sys.stderr)))
        poses = []
        session = Session(node, CalibSettings(), PoseStore(Path({str(tmp_path)!r})), "ptz1",
                          60, 60.0, lambda pose, report: poses.append(pose), zooms={ZOOMS})
        for zoom, collector in zip({ZOOMS}, session.collection.collectors):
            collector.passpoints = lambda z=zoom: Passpoints(data[f"world{{z}}"],
                                                            data[f"pixels{{z}}"])
        # passpoints without times: no clock offset
        session.collection.collector.track = lambda: None
        session.store.save_inputs = lambda *args: None
        session._solve_zooms(m.PtzState(measured_s=0.0, camera="ptz1", status="calibrating",
                                        pan_deg=0.0, tilt_deg=0.0, zoom=1, focal_px=743.1,
                                        aim_error_deg=0.0))
        print(session.state, [(p.zoom, p.focal_px) for p in poses[0].lens][-1])
        print(sorted(m for m in ("scipy", "cma", "matplotlib") if m in sys.modules))
        """)
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True,
                          text=True, timeout=120, env=dict(os.environ))
    assert done.returncode == 0, done.stderr
    state, last = done.stdout.strip().splitlines()[-2].split(" ", 1)
    zoom, focal = last.strip("()").split(", ")
    assert state == "done" and int(zoom) == ZOOMS[-1]
    assert abs(float(focal) / truth.focal_px(ZOOMS[-1]) - 1) < 0.02
    assert done.stdout.strip().splitlines()[-1] == "[]"
    assert (tmp_path / "ptz1" / "lens.png").stat().st_size > 10_000


def test_a_solve_that_fails_raises_its_calibration_error_here() -> None:
    rng = np.random.default_rng(4)
    (few,) = zoom_passpoints(PAPER_POSE, drawn_lens(rng), [1], rng, count=3)
    with pytest.raises(CalibrationError, match="passpoints"):
        in_worker(solve_one_zoom, Passpoints(few.world_mm, few.pixels), Options())


def test_a_worker_that_dies_is_a_calibration_error_saying_so() -> None:
    with pytest.raises(CalibrationError, match="ended without a result"):
        in_worker(os._exit, 3)


def test_an_error_that_does_not_pickle_comes_back_as_its_text() -> None:
    with pytest.raises(CalibrationError, match="Error: Can.t pickle"):
        in_worker(_unpicklable)


def _unpicklable() -> object:
    return lambda: None  # a lambda does not pickle
