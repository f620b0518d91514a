"""What ``stb report`` does once its flags are parsed (services/report/cli.py has the
command and its documentation): the figures, summary.json and index.html."""

from __future__ import annotations

import argparse
import errno
import html
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from common.errors import ConfigError
from common.files import write_atomically
from common.heightmap import HeightMap
from common.lab_views import GantryHeightMap
from common.mcap_file import RecordingError
from common.settings import load_settings
from services.args import EXIT_CONFIG, EXIT_DISK
from services.report import birdseye, plots
from services.report.data import Recording, crane_error, moments, read_recording, summary
from services.report.stills import Moment, write_stills

FIGURES = (("errors.png", "Crane-to-robot error over time"),
           ("tracks.png", "Tracks over the height map"),
           ("velocity.png", "Filtered velocity"),
           ("calibration.png", "Calibration residuals"),
           ("aim.png", "PTZ aim error"))


def write_report(rec: Recording, out_dir: Path, height_map: HeightMap | None,
                 marker_label: str = "wand", paths: Sequence[Path] = ()
                 ) -> dict[str, Path | None]:
    """Every figure (None where there is no data), stills of the run's moments from the
    videos in ``paths`` (the recording's files), ``summary.json`` and ``index.html``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = {
        "errors.png": plots.error_plot(rec, out_dir / "errors.png"),
        "tracks.png": plots.track_plot(rec, height_map, out_dir / "tracks.png"),
        "velocity.png": plots.velocity_plot(rec, out_dir / "velocity.png"),
        "calibration.png": plots.calibration_plot(rec, out_dir / "calibration.png",
                                                  marker_label),
        "aim.png": plots.aim_plot(rec, out_dir / "aim.png"),
    }
    figures = summary(rec)
    shots = write_stills(paths, moments(rec), out_dir, rec.first_s) if paths else []
    write_atomically(out_dir / "summary.json", (json.dumps(figures, indent=1) + "\n").encode())
    write_atomically(out_dir / "index.html", render_html(rec, figures, written, shots).encode())
    return written


def render_moments(shots: list[Moment], run_start_s: float) -> str:
    """The moments' section: when, what, and the pictures side by side."""
    if not shots:
        return ""
    parts = ["<h2>Moments</h2>"]
    for shot in shots:
        pictures = "".join(
            f'<figure class="still"><img src="{html.escape(name)}" alt="{html.escape(caption)}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>"
            for name, caption in shot.pictures) or "<p class='missing'>no video then</p>"
        parts.append(f"<h3>{shot.time_s - run_start_s:.1f} s: {html.escape(shot.what)}</h3>"
                     f'<div class="stills">{pictures}</div>')
    return "\n".join(parts)


def render_html(rec: Recording, figures: dict, written: dict[str, Path | None],
                shots: Sequence[Moment] = ()) -> str:
    rows = "\n".join(f"<tr><td>{html.escape(k)}</td><td>{html.escape(_fmt(v))}</td></tr>"
                     for k, v in figures.items())
    keys = "\n".join(f"<tr><td>{html.escape(k)}</td><td>{n}</td></tr>"
                     for k, n in sorted(rec.counts.items()))
    blocks = []
    for name, title in FIGURES:
        if written.get(name) is not None:
            blocks.append(f'<figure><img src="{name}" alt="{html.escape(title)}">'
                          f"<figcaption>{html.escape(title)}</figcaption></figure>")
        else:
            blocks.append(f'<p class="missing">{html.escape(title)}: no data in this '
                          "recording.</p>")
    unhealthy = [f"{name}: {h.status} {h.detail}" for name, h in sorted(rec.health.items())
                 if h.status != "ok"]
    health = ("<p>Last health of every service: ok.</p>" if rec.health and not unhealthy
              else "".join(f"<p class='missing'>{html.escape(u)}</p>" for u in unhealthy))
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>STB run {html.escape(rec.path.name)}</title>
<style>
body {{ font-family: sans-serif; margin: 1.5em; max-width: 1000px; }}
table {{ border-collapse: collapse; margin-bottom: 1em; }}
td {{ border-bottom: 1px solid #ddd; padding: 2px 12px 2px 0; font-size: 90%; }}
figure {{ margin: 0 0 1em 0; }} img {{ max-width: 100%; }}
.missing {{ color: #a40; }} .cols {{ display: flex; gap: 3em; flex-wrap: wrap; }}
.stills {{ display: flex; gap: 0.8em; flex-wrap: wrap; }} .still img {{ max-width: 320px; }}
</style></head><body>
<h1>Run {html.escape(rec.path.name)}</h1>
<div class="cols"><div><h2>Figures</h2><table id="figures">{rows}</table>{health}</div>
<div><h2>Samples per key</h2><table id="keys">{keys}</table></div></div>
{''.join(blocks)}
{render_moments(list(shots), rec.first_s)}
</body></html>
"""


def _fmt(value: object) -> str:
    return "—" if value is None else str(value)


def report(args: argparse.Namespace) -> int:
    try:
        height_map = _height_map(args)
        files = " ".join(str(p) for p in args.recording)
        print(f"stb report: reading {files} ...", file=sys.stderr, flush=True)
        rec = read_recording(args.recording, args.prefix)
    except (ConfigError, RecordingError, OSError, ValueError) as err:
        print(f"stb report: {err}", file=sys.stderr)
        return EXIT_CONFIG
    try:
        written = write_report(rec, args.out, height_map, args.calib_marker, args.recording)
        for name, path in written.items():
            print(f"  {path}" if path else f"  {name}: no data in this recording",
                  file=sys.stderr)
        if args.video:
            _video(args, rec)
    except OSError as err:  # the output's disk full, or a folder it may not write to
        full = err.errno == errno.ENOSPC
        print(f"stb report: cannot write the report to {args.out}: {err}"
              f"{' — free space, or give --out on another disk' if full else ''}",
              file=sys.stderr)
        return EXIT_DISK if full else EXIT_CONFIG
    print(f"stb report: {args.out / 'index.html'}", file=sys.stderr)
    return 0


def _video(args: argparse.Namespace, rec: Recording) -> None:
    """The bird's-eye MP4: ``--video-seconds`` around the largest crane error (0: all)."""
    t, error = crane_error(rec)
    distance = np.hypot(error[:, 0], error[:, 1]) if len(error) else np.empty(0)
    start = end = None
    if args.video_seconds > 0 and rec.last_s > rec.first_s:
        centre = float(t[np.argmax(distance)]) if len(t) else rec.first_s
        start = max(rec.first_s, centre - args.video_seconds / 2)
        end = min(rec.last_s, start + args.video_seconds)
        start = max(rec.first_s, end - args.video_seconds)
    out = args.out / "birdseye.mp4"
    frames = birdseye.export(args.recording, out, t, distance, rec.first_s, start, end)
    if frames:
        print(f"  {out} ({frames} frames)", file=sys.stderr)
    else:
        print(f"  birdseye.mp4: no bird's-eye video ({birdseye.BIRDSEYE}) in this recording "
              "(record with stb observation running)", file=sys.stderr)


def _height_map(args: argparse.Namespace) -> HeightMap | None:
    path = args.height_map
    if path is None:
        default = load_settings(GantryHeightMap, args.lab).height_map
        if not default.exists():
            return None
        path = default
    return HeightMap.load(path)
