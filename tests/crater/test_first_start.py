"""A simulated lab's first ``stb up`` makes the crater's height map from the sim's laser scan
(``stb sim scan`` → ``stb crater import``) before anything starts, and the gantry reads that,
not the sim's own crater; a lab that points the gantry at the sim's file, or has its map
already, is left alone; a step that fails stops ``stb up`` naming the command."""

from __future__ import annotations

import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from common.heightmap import HeightMap
from common.settings import load_settings
from services.crater.first_start import height_map_to_import
from services.recording.record import RecordSettings
from services.sim.world import CraterMap
from services.web.settings import WebSettings
from tests.conftest import ROOT, stb_process, wait_for
from tests.services.test_processes import _lab_for_up, _stop


def _fresh_lab(tmp_path: Path, services: list[str]) -> tuple[Path, Path, Path]:
    """``_lab_for_up``'s lab with the gantry's map apart from the sim's crater: (lab file,
    the gantry's map, the sim's crater)."""
    lab, _ = _lab_for_up(tmp_path)
    doc = tomllib.loads(lab.read_text())
    gantry_map = tmp_path / "lab" / "crater.npz"
    doc["gantry"]["height_map"] = str(gantry_map)
    doc["up"]["services"] = services
    lab.write_text(tomli_w.dumps(doc))
    return lab, gantry_map, Path(doc["sim"]["crater_file"])


def test_only_a_sim_lab_without_its_map_imports_one(tmp_path: Path) -> None:
    missing, sim = tmp_path / "crater.npz", tmp_path / "sim" / "crater.npz"
    assert height_map_to_import(["router", "sim", "gantry"], missing, sim)
    assert height_map_to_import(["sim:main", "web"], missing, sim)
    assert not height_map_to_import(["router", "tracker", "gantry"], missing, sim)  # real lab
    assert not height_map_to_import(["sim", "gantry"], sim, sim)  # the sim's own, on purpose
    missing.write_bytes(b"")
    assert not height_map_to_import(["sim", "gantry"], missing, sim)  # there already


def test_the_lab_names_the_crater_once(tmp_path: Path) -> None:
    """``[gantry] height_map`` is the page's and the recorders' too, unless theirs is set."""
    lab = tmp_path / "lab.toml"
    lab.write_text('[gantry]\nheight_map = "scan/crater.npz"\n')
    assert load_settings(WebSettings, lab).height_map == Path("scan/crater.npz")
    assert load_settings(RecordSettings, lab).height_map == Path("scan/crater.npz")
    lab.write_text('[gantry]\nheight_map = "scan/crater.npz"\n[web]\nheight_map = "other.npz"\n')
    assert load_settings(WebSettings, lab).height_map == Path("other.npz")
    assert load_settings(WebSettings, lab, {"height_map": "given.npz"}).height_map == \
        Path("given.npz")
    assert load_settings(WebSettings, lab, environ={"STB_WEB__HEIGHT_MAP": "env.npz"}
                         ).height_map == Path("env.npz")


def test_a_step_that_fails_stops_up_naming_the_command(tmp_path: Path) -> None:
    lab, gantry_map, sim_crater = _fresh_lab(tmp_path, ["router", "sim", "gantry"])
    sim_crater.write_bytes(b"not a height map")
    done = subprocess.run([sys.executable, "-m", "services.cli", "up", "--lab", str(lab),
                           "--no-view"], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 1, done.stderr
    assert "first start's height map: stb sim scan" in done.stderr, done.stderr
    assert str(sim_crater) in done.stderr, done.stderr  # the sim's file named
    assert not gantry_map.exists()


@pytest.mark.system
@pytest.mark.timeout(300)
def test_a_fresh_sim_lab_starts_on_an_imported_scan(tmp_path: Path) -> None:
    lab, gantry_map, sim_crater = _fresh_lab(tmp_path, ["router", "sim", "gantry"])
    up = stb_process("up", "--lab", str(lab), "--no-view")
    try:
        wait_for(lambda: gantry_map.exists(), timeout=180, period=0.5)
        gantry_log = tmp_path / "logs" / "gantry-main.log"
        wait_for(lambda: gantry_log.exists() and "disarmed" in gantry_log.read_text()
                 or up.poll() is not None, timeout=60, period=0.5)
        assert up.poll() is None, "stb up ended"
    finally:
        assert _stop(up, signal.SIGINT, timeout=30) == 0
    imported, truth = HeightMap.load(gantry_map), CraterMap.load(sim_crater)
    with np.load(gantry_map) as saved:
        assert saved["filled"].any(), "an import marks the cells it filled"
    rows, cols = imported.heights_mm.shape
    xs = imported.origin_x_mm + np.arange(cols) * imported.resolution_mm
    ys = imported.origin_y_mm + np.arange(rows) * imported.resolution_mm
    error = np.abs(imported.heights_mm - truth.height_at(*np.meshgrid(xs, ys)))
    assert np.percentile(error, 99) <= 5.0
    assert imported.resolution_mm != truth.resolution_mm, "the scan's cells, not the sim's grid"


def test_stb_crater_from_sim_does_what_stb_up_does_once(tmp_path: Path) -> None:
    """The compose sim lab's one-shot service: nothing to do when the map is there; a step
    that fails is named (exit 1)."""
    lab, gantry_map, sim_crater = _fresh_lab(tmp_path, ["sim"])

    def from_sim() -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "services.cli", "crater", "from-sim",
                               "--lab", str(lab)], capture_output=True, text=True, timeout=120,
                              cwd=ROOT)

    sim_crater.write_bytes(b"not a height map")
    failed = from_sim()
    assert failed.returncode == 1 and "stb sim scan" in failed.stderr, failed.stderr
    gantry_map.parent.mkdir(parents=True, exist_ok=True)
    gantry_map.write_bytes(b"")  # there already
    done = from_sim()
    assert done.returncode == 0 and "nothing to do" in done.stdout, done.stderr
