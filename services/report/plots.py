"""The report's figures as PNG: the paper's (crane error over time, Fig. 9/11; filtered
velocity, Fig. 10; calibration residuals) plus the tracks over the height map and the PTZ aim
error. Each function returns the file it wrote, or None when the recording has no data for it."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from common.heightmap import HeightMap  # noqa: E402
from services.report.data import Recording, calibration_residuals, crane_error  # noqa: E402

DPI = 100


def _save(fig: plt.Figure, path: Path) -> Path:
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def error_plot(rec: Recording, path: Path) -> Path | None:
    t, error = crane_error(rec)
    if len(t) == 0:
        return None
    distance = np.hypot(error[:, 0], error[:, 1])
    fig, ax = plt.subplots(figsize=(9, 3.2), layout="constrained")
    ax.plot(t - rec.first_s, error[:, 0], lw=0.8, label="x error")
    ax.plot(t - rec.first_s, error[:, 1], lw=0.8, label="y error")
    ax.plot(t - rec.first_s, distance, lw=0.8, color="0.3", label="distance")
    ax.set_xlabel("time since the recording started (s)")
    ax.set_ylabel("crane − robot (mm)")
    ax.set_title(f"crane-to-robot error (paper Fig. 9/11): mean {distance.mean():.0f} mm, "
                 f"std x {error[:, 0].std():.0f} mm, y {error[:, 1].std():.0f} mm", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, path)


def track_plot(rec: Recording, height_map: HeightMap | None, path: Path) -> Path | None:
    if len(rec.robot) == 0 and len(rec.crane) == 0:
        return None
    fig, ax = plt.subplots(figsize=(7.5, 6.5), layout="constrained")
    if height_map is not None:
        x0, x1, y0, y1 = height_map.extent_mm
        shown = ax.imshow(height_map.heights_mm, origin="lower", extent=(x0, x1, y0, y1),
                          cmap="terrain", alpha=0.8)
        fig.colorbar(shown, ax=ax, shrink=0.7, label="height (mm)")
    for series, label, style in ((rec.truth, "robot (sim truth)", dict(color="0.5", ls="--")),
                                 (rec.robot, "robot (mocap)", dict(color="tab:red")),
                                 (rec.crane, "crane", dict(color="tab:blue"))):
        if len(series):
            _, values = series.arrays()
            ax.plot(values[:, 0], values[:, 1], lw=1.0, label=label, **style)
            ax.plot(*values[0, :2], "o", color=style["color"], ms=4)
    for camera, pose in sorted(rec.poses.items()):
        ax.plot(pose.x_mm, pose.y_mm, "k^", ms=8)
        ax.annotate(camera, (pose.x_mm, pose.y_mm), textcoords="offset points", xytext=(5, 5))
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title("tracks over the crater (dots: start)", fontsize=9)
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
    ax.set_xlabel("time since the recording started (s)")
    ax.set_ylabel("velocity x (mm/s)")
    ax.set_title("filtered velocity in x (paper Fig. 10)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, path)


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
    ax.set_xlabel("time since the recording started (s)")
    ax.set_ylabel("aim error (deg)")
    ax.set_title("PTZ cameras: angle between the optical axis and the robot", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, path)
