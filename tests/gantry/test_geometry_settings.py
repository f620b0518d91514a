"""The lab's geometry in the lab file: bad values and moved fields stop start-up naming the
field; the crane's frame maps both ways and has one canonical form."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from common.crane_frame import CraneFrame
from common.errors import ConfigError
from common.settings import load_settings
from services.gantry.settings import GantrySettings
from services.sim.settings import SimSettings


@pytest.mark.parametrize(("text", "names"), [
    ("[gantry.tracking_camera]\nprincipal_px = [900.0, 10.0]\n", "gantry.tracking_camera"),
    ("[gantry.tracking_camera]\ndistortion = [0.1, 0.2]\n", "gantry.tracking_camera.distortion"),
    ("[gantry.crane]\nyaw_deg = 270.0\n", "gantry.crane.yaw_deg"),
    ("[gantry]\nlens_height_mm = 3400.0\n", "[gantry.tracking_camera] now"),
    ("[gantry]\nfix_check_mm = -1.0\n", "gantry.fix_check_mm"),
])
def test_a_bad_geometry_value_names_its_field(tmp_path: Path, text: str, names: str) -> None:
    lab = tmp_path / "lab.toml"
    lab.write_text(text)
    with pytest.raises(ConfigError, match=names.replace("[", r"\[").replace("]", r"\]")):
        load_settings(GantrySettings, lab, environ={})


def test_the_sims_truths_are_its_own_sections(tmp_path: Path) -> None:
    lab = tmp_path / "lab.toml"
    lab.write_text("[sim.crane]\norigin_mm = [-3600.0, 3300.0]\nflip_y = true\n"
                   "[sim.tracking_camera]\noffset_mm = [40.0, -30.0]\n"
                   "[sim]\ntargets = [[300.0, 200.0, 0.0]]\n")
    sim = load_settings(SimSettings, lab, environ={})
    gantry = load_settings(GantrySettings, lab, environ={})
    assert sim.crane.frame() == CraneFrame(origin_mm=(-3600.0, 3300.0), flip_y=True)
    assert gantry.crane.frame().is_identity, "the gantry never reads [sim]"
    assert gantry.tracking_camera.offset_mm == (0.0, 0.0)


def test_a_frame_maps_both_ways_and_has_one_canonical_form(rng: np.random.Generator) -> None:
    points = rng.uniform(-3000, 3000, (20, 2))
    for frame in (CraneFrame(origin_mm=(-3600.0, 3300.0), yaw_deg=1.5, flip_y=True),
                  CraneFrame(origin_mm=(10.0, 20.0), yaw_deg=-170.0, flip_x=True)):
        np.testing.assert_allclose(frame.to_crane(frame.to_world(points)), points, atol=1e-9)
        np.testing.assert_allclose(frame.canonical().to_world(points), frame.to_world(points),
                                   atol=1e-9)
        assert abs(frame.canonical().yaw_deg) <= 90
        again = CraneFrame.from_linear(np.array(frame.origin_mm), frame.linear)
        np.testing.assert_allclose(again.to_world(points), frame.to_world(points), atol=1e-9)


def test_a_frame_copied_with_new_values_maps_with_them(rng: np.random.Generator) -> None:
    """Commissioning copies the lab's crane settings with the frame it measured
    (``model_copy(update=…)``); the copy maps with the measured frame even when the old one
    had been used before (a cached rotation once travelled with the copy)."""
    points = rng.uniform(-3000, 3000, (5, 2))
    old = CraneFrame()
    old.to_world(points)
    measured = CraneFrame(origin_mm=(-3600.0, 3300.0), yaw_deg=91.0, flip_y=True)
    copied = old.model_copy(update=measured.model_dump())
    np.testing.assert_allclose(copied.to_world(points), measured.to_world(points), atol=1e-9)
    np.testing.assert_allclose(copied.to_crane(points), measured.to_crane(points), atol=1e-9)
