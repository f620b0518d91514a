"""``stb monitor``'s table fits the terminal it is shown on (services/monitor/view.py)."""

from __future__ import annotations

from common import messages as m
from services.monitor.view import LabView


def _busy_lab() -> LabView:
    view = LabView()
    for service in ("router", "sim", "tracker", "calib", "gantry", "web"):
        view.on_alive(service, "main", True)
    for camera in ("ptz1", "ptz2"):
        view.on_alive("ptz", camera, True)
    for n in range(40):
        for t in (0.0, 0.5, 1.0):
            view.on_sample(f"stb/some/rather/long/key/expression/number/{n}",
                           m.RobotPosition(measured_s=t, label="robot", x_mm=1.0, y_mm=2.0,
                                           z_mm=3.0, vx_mm_s=4.0, vy_mm_s=5.0, vz_mm_s=6.0),
                           t)
    return view


def test_at_80_by_24_nothing_wraps_and_what_does_not_fit_is_counted() -> None:
    text = _busy_lab().render(1.0, 80, 24)
    lines = text.split("\n")
    assert len(lines) <= 23 and all(len(line) <= 80 for line in lines)
    assert lines[0].startswith("alive (8): calib/main gantry/main")
    assert "latest" in lines[2] and "rate Hz" in lines[2]
    assert lines[-1] == "… 21 more keys"


def test_a_narrow_terminal_drops_the_digest_before_the_rates() -> None:
    lines = _busy_lab().render(1.0, 50, None).split("\n")
    assert all(len(line) <= 50 for line in lines) and len(lines) == 3 + 40
    assert "latest" not in lines[2] and "rate Hz" in lines[2]
    assert lines[3].endswith("2.0     0.0")  # rate and age kept


def test_a_wide_terminal_shows_the_whole_key_and_a_digest() -> None:
    lines = _busy_lab().render(1.0, 160, None).split("\n")
    row = next(line for line in lines if "number/7 " in line)
    assert "stb/some/rather/long/key/expression/number/7" in row and "x_mm=1.0" in row
