"""A recording's report files are served from inside its folder only: a link that leads out
(a symlink to /etc/shadow once was served to any signed-in user) is refused."""

from __future__ import annotations

from pathlib import Path

from services.web.recordings import RecordingDesk


def _desk(tmp_path: Path) -> tuple[RecordingDesk, Path]:
    folder = tmp_path / "recordings"
    report = folder / "20261204-101500.report"
    report.mkdir(parents=True)
    (report / "index.html").write_text("<html></html>")
    return RecordingDesk(folder, {}), report


def test_a_report_file_is_served(tmp_path: Path) -> None:
    desk, report = _desk(tmp_path)
    assert desk.report_file("20261204-101500", "index.html") == (report / "index.html").resolve()
    assert desk.report_file("20261204-101500", "missing.html") is None


def test_a_link_out_of_the_report_is_refused(tmp_path: Path) -> None:
    desk, report = _desk(tmp_path)
    secret = tmp_path / "secret.txt"
    secret.write_text("root:x")
    (report / "leak.txt").symlink_to(secret)
    (report / "inner.html").symlink_to(report / "index.html")  # a link inside stays fine
    assert desk.report_file("20261204-101500", "leak.txt") is None
    assert desk.report_file("20261204-101500", "inner.html") == (report / "index.html").resolve()


def test_a_report_folder_that_is_a_link_out_is_refused(tmp_path: Path) -> None:
    desk, _ = _desk(tmp_path)
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "index.html").write_text("<html>not ours</html>")
    (tmp_path / "recordings" / "20261204-101600.report").symlink_to(outside)
    assert desk.report_file("20261204-101600", "index.html") is None
