"""The report's figures as PNG: the paper's (crane error over time, Fig. 9/11; filtered
velocity, Fig. 10; calibration residuals) plus the tracks over the height map and the PTZ aim
error. Each function returns the file it wrote, or None when the recording has no data for it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.patheffects as effects  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from common.heightmap import HeightMap  # noqa: E402
from services.report.data import (  # noqa: E402
    Recording,
    Series,
    calibration_residuals,
    crane_error,
)

DPI = 100


def _save(fig: plt.Figure, path: Path) -> Path:
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def _save_time_plot(fig: plt.Figure, ax: plt.Axes, ylabel: str, title: str, path: Path) -> Path:
    """A plot over the recording's time: its labels, grid and legend, then saved."""
    ax.set_xlabel("time since the recording started (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, path)


def error_plot(rec: Recording, path: Path) -> Path | None:
    t, error = crane_error(rec)
    if len(t) == 0:
        return None
    distance = np.hypot(error[:, 0], error[:, 1])
    fig, ax = plt.subplots(figsize=(9, 3.2), layout="constrained")
    ax.plot(t - rec.first_s, error[:, 0], lw=0.8, label="x error")
    ax.plot(t - rec.first_s, error[:, 1], lw=0.8, label="y error")
    ax.plot(t - rec.first_s, distance, lw=0.8, color="0.3", label="distance")
    return _save_time_plot(
        fig, ax, "crane − robot (mm)",
        f"crane-to-robot error (paper Fig. 9/11): mean {distance.mean():.0f} mm, "
        f"std x {error[:, 0].std():.0f} mm, y {error[:, 1].std():.0f} mm", path)


def track_view(rec: Recording, margin_mm: float = 400.0
               ) -> tuple[float, float, float, float] | None:
    """The part of the crater the run used: every track's extent and ``margin_mm`` around it
    (x0, x1, y0, y1), or None without a track."""
    tracks = [series.arrays()[1][:, :2] for series in (rec.truth, rec.robot, rec.crane)
              if len(series)]
    xy = np.vstack(tracks) if tracks else np.zeros((0, 2))
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    if len(xy) == 0:
        return None
    (x0, y0), (x1, y1) = xy.min(axis=0) - margin_mm, xy.max(axis=0) + margin_mm
    return float(x0), float(x1), float(y0), float(y1)


def track_plot(rec: Recording, height_map: HeightMap | None, path: Path) -> Path | None:
    """The tracks over the crater in grey (the lines' colours stand out), zoomed to where the
    run went; the crane's line wide and outlined in white, the robot's thin on top of it."""
    view = track_view(rec)
    if view is None:
        return None
    fig, ax = plt.subplots(figsize=(7.5, 6.5), layout="constrained")
    if height_map is not None:
        x0, x1, y0, y1 = height_map.extent_mm
        shown = ax.imshow(height_map.heights_mm, origin="lower", extent=(x0, x1, y0, y1),
                          cmap="gray", alpha=0.7)
        fig.colorbar(shown, ax=ax, shrink=0.7, label="height (mm)")
    outline = [effects.Stroke(linewidth=3.6, foreground="white"), effects.Normal()]
    lines: list[tuple[Series, str, dict[str, Any]]] = [
        (rec.truth, "robot (sim truth)", dict(color="0.3", ls="--", lw=1.0)),
        (rec.crane, "crane", dict(color="tab:blue", lw=2.4, path_effects=outline)),
        (rec.robot, "robot (mocap)", dict(color="tab:red", lw=0.9))]
    for series, label, style in lines:  # the crane's wide line under the robot's thin one
        if len(series):
            _, values = series.arrays()
            ax.plot(values[:, 0], values[:, 1], label=label, **style)
            ax.plot(*values[0, :2], "o", color=style["color"], ms=5)
    x0, x1, y0, y1 = view
    outside = []
    for camera, pose in sorted(rec.poses.items()):
        if x0 <= pose.x_mm <= x1 and y0 <= pose.y_mm <= y1:
            ax.plot(pose.x_mm, pose.y_mm, "k^", ms=8)
            ax.annotate(camera, (pose.x_mm, pose.y_mm), textcoords="offset points",
                        xytext=(5, 5))
        else:
            outside.append(f"{camera} ({pose.x_mm:.0f}, {pose.y_mm:.0f})")
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title("tracks over the crater (dots: start)" + (
        f"\ncameras outside the view: {', '.join(outside)} mm" if outside else ""), fontsize=9)
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, path)


def velocity_plot(rec: Recording, path: Path) -> Path | None:
    if len(rec.estimate) == 0:
        return None
    fig, ax = plt.subplots(figsize=(9, 3.2), layout="constrained")
    if len(rec.robot):
        t, robot = rec.robot.arrays()
        ax.plot(t - rec.first_s, robot[:, 3], lw=0.6, color="0.6", label="mocap velocity x")
    t, estimate = rec.estimate.arrays()
    valid = estimate[:, 4] > 0
    algorithm = rec.algorithms.most_common(1)[0][0]
    ax.plot(t[valid] - rec.first_s, estimate[valid, 2], lw=0.9, color="tab:blue",
            label=f"gantry filter ({algorithm}) velocity x")
    return _save_time_plot(fig, ax, "velocity x (mm/s)",
                           "filtered velocity in x (paper Fig. 10)", path)


def calibration_plot(rec: Recording, path: Path, marker_label: str = "wand") -> Path | None:
    if not rec.poses:
        return None
    residuals = calibration_residuals(rec, marker_label)
    cameras = sorted(rec.poses)
    fig, axes = plt.subplots(1, len(cameras), figsize=(4.5 * len(cameras), 3.4),
                             layout="constrained", squeeze=False)
    for ax, camera in zip(axes[0], cameras, strict=True):
        pose = rec.poses[camera]
        if camera in residuals:
            values = np.minimum(residuals[camera], 1e3)
            ax.bar(np.arange(len(values)), values, color="tab:blue")
            ax.axhline(pose.mean_error_px, color="tab:red", lw=1,
                       label=f"pose fit: {pose.mean_error_px:.2f} px")
            ax.set_xlabel("passpoint in this recording")
            ax.set_title(f"{camera}: {len(values)} passpoints, median "
                         f"{np.median(values):.2f} px", fontsize=9)
            ax.legend(fontsize=8)
        else:
            ax.bar([0], [pose.mean_error_px], color="tab:blue")
            ax.set_xticks([])
            ax.set_title(f"{camera}: fit {pose.mean_error_px:.2f} px over {pose.passpoints} "
                         "passpoints\n(collected before this recording)", fontsize=9)
        ax.set_ylabel("reprojection residual (px)")
        ax.grid(alpha=0.3, axis="y")
    return _save(fig, path)


def aim_plot(rec: Recording, path: Path) -> Path | None:
    if not rec.aim:
        return None
    fig, ax = plt.subplots(figsize=(9, 3.0), layout="constrained")
    for camera, series in sorted(rec.aim.items()):
        t, aim = series.arrays()
        ax.plot(t - rec.first_s, aim[:, 0], lw=0.8, label=camera)
    return _save_time_plot(fig, ax, "aim error (deg)",
                           "PTZ cameras: angle between the optical axis and the robot", path)
