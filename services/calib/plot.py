"""Plots of a calibration: fitness over evaluations (paper Fig. 6) and every passpoint's
residual, drawn over the image so that wrong passpoints stand out."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from common.camera import project, project_camera  # noqa: E402
from common.passpoints import Passpoints  # noqa: E402
from common.ptz_lens import PtzLens  # noqa: E402
from services.calib.solve import Solution  # noqa: E402
from services.calib.zoom_fit import ZoomFit  # noqa: E402


def write_plots(solution: Solution, points: Passpoints, out_dir: Path) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    written = [_residual_plot(solution, points, out_dir / "residuals.png")]
    if solution.fitness_curve:
        written.append(_fitness_plot(solution, out_dir / "fitness.png"))
    return written


def _fitness_plot(solution: Solution, path: Path) -> Path:
    evaluations, best = np.array(solution.fitness_curve).T
    fig, ax = plt.subplots(figsize=(6.4, 4.0), layout="constrained")
    ax.semilogy(evaluations, best, color="tab:blue")
    ax.set_xlabel("evaluations")
    ax.set_ylabel("best fitness (mean pixel deviation, px)")
    ax.set_title(f"{solution.method}: {best[0]:.1f} px → {best[-1]:.2f} px "
                 f"in {int(evaluations[-1])} evaluations")
    ax.grid(True, which="both", alpha=0.3)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _residual_plot(solution: Solution, points: Passpoints, path: Path) -> Path:
    intr = solution.intrinsics()
    world = solution.world_mm
    predicted = project(world, solution.pose, intr)
    inlier = np.zeros(len(points), dtype=bool)
    inlier[solution.inliers] = True
    fig, (image, bars) = plt.subplots(1, 2, figsize=(12.0, 4.6), layout="constrained",
                                      gridspec_kw={"width_ratios": [1.3, 1.0]})
    image.set_xlim(0, intr.width_px)
    image.set_ylim(intr.height_px, 0)
    image.set_aspect("equal")
    image.scatter(*points.pixels[inlier].T, s=10, color="tab:blue", label="detected (inlier)")
    image.scatter(*points.pixels[~inlier].T, s=24, marker="x", color="tab:red",
                  label="rejected")
    ok = np.all(np.isfinite(predicted), axis=1)
    for (u, v), (pu, pv) in zip(points.pixels[ok], predicted[ok], strict=True):
        image.plot([u, pu], [v, pv], color="0.4", lw=0.8)
    image.set_title("passpoints: detected pixel → reprojected (lines)")
    image.set_xlabel("u (px)")
    image.set_ylabel("v (px)")
    image.legend(loc="lower right", fontsize=8)
    residuals = np.minimum(solution.residuals_px, 1e3)
    bars.bar(np.arange(len(points)), residuals,
             color=np.where(inlier, "tab:blue", "tab:red"))
    bars.set_yscale("log")
    bars.set_xlabel("passpoint")
    bars.set_ylabel("residual (px)")
    bars.set_title(f"mean over inliers {solution.mean_error_px:.2f} px, "
                   f"{len(solution.inliers)}/{len(points)} kept")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_lens_plot(fit: ZoomFit, path: Path) -> Path:
    """The lens as measured: the zoom → focal curve through the fitted points, how the
    distortion at the widest zoom bends a grid of straight lines, and every passpoint's
    residual per zoom."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lens = fit.lens()
    fig, (curve, grid, spread) = plt.subplots(1, 3, figsize=(15.0, 4.4), layout="constrained")
    steps = np.linspace(fit.zooms[0], fit.zooms[-1], 400)
    curve.plot(steps, [lens.focal_px(z) for z in steps], color="tab:blue", label="PCHIP curve")
    line = PtzLens()
    curve.plot(steps, [line.intrinsics(z, *fit.picture_px).focal_px for z in steps],
               color="tab:gray", ls="--", label="the AXIS 215 data sheet's straight line")
    curve.plot(fit.zooms, fit.focals_px, "o", color="tab:red", label="fitted at the step")
    curve.set_xlabel("zoom step (VAPIX)")
    curve.set_ylabel(f"focal length, px of the {fit.picture_px[0]} × {fit.picture_px[1]} "
                     "picture")
    curve.set_yscale("log")
    curve.legend()
    curve.grid(True, which="both", alpha=0.3)
    curve.set_title("zoom → focal length")
    intr = lens.intrinsics(fit.zooms[0])
    for along in np.linspace(0, 1, 9):
        for horizontal in (True, False):
            t = np.linspace(-0.1, 1.1, 60)
            u = (t if horizontal else np.full_like(t, along)) * intr.width_px
            v = (np.full_like(t, along) if horizontal else t) * intr.height_px
            rays = np.column_stack([np.ones(len(t)), (u - intr.cy_px) / intr.fy_px,
                                    (v - intr.cz_px) / intr.fz_px])
            bent = project_camera(rays, intr)
            grid.plot(u, v, color="tab:gray", lw=0.6)
            grid.plot(bent[:, 0], bent[:, 1], color="tab:blue", lw=1.0)
    grid.set_xlim(0, intr.width_px)
    grid.set_ylim(intr.height_px, 0)
    grid.set_aspect("equal")
    k1, k2, p1, p2, k3 = intr.distortion
    grid.set_title(f"zoom {fit.zooms[0]}: straight lines (gray) as the lens shows them\n"
                   f"k1 {k1:+.3f}, k2 {k2:+.3f}, p1 {p1:+.4f}, p2 {p2:+.4f}, k3 {k3:+.3f}",
                   fontsize=9)
    for i in range(len(fit.zooms)):
        errors = fit.residuals_px[i]
        kept = np.zeros(len(errors), bool)
        kept[fit.inliers[i]] = True
        spread.plot(np.full(kept.sum(), i), errors[kept], ".", color="tab:blue", alpha=0.5)
        spread.plot(np.full((~kept).sum(), i), np.minimum(errors[~kept], 50), "x",
                    color="tab:red")
    spread.set_xticks(range(len(fit.zooms)), [str(z) for z in fit.zooms])
    spread.set_xlabel("zoom step")
    spread.set_ylabel("reprojection error, px (× rejected)")
    spread.set_title(f"passpoints: {fit.mean_error_px():.2f} px mean over the inliers")
    spread.grid(True, alpha=0.3)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
