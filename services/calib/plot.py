"""Plots of a calibration: fitness over evaluations (paper Fig. 6) and every passpoint's
residual, drawn over the image so that wrong passpoints stand out."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from common.camera import Intrinsics, project  # noqa: E402
from common.passpoints import Passpoints  # noqa: E402
from services.calib.solve import Solution  # noqa: E402


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
    intr = Intrinsics(solution.focal_mm)
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
