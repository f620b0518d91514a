"""The paper's gantry figures from experiment runs: the error over time per algorithm (Fig. 9
and 11) and the filtered velocity in x (Fig. 10)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from services.experiment.gantry import Run  # noqa: E402


def write_plots(runs: list[Run], scenario: str, out_dir: Path) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(len(runs), 1, figsize=(9, 2.2 * len(runs)), sharex=True,
                             layout="constrained", squeeze=False)
    for ax, run in zip(axes[:, 0], runs, strict=True):
        ax.plot(run.t_s, run.error_mm[:, 0], lw=0.8, label="x error")
        ax.plot(run.t_s, run.error_mm[:, 1], lw=0.8, label="y error")
        s = run.summary()
        ax.set_title(f"{run.algorithm}: std x {s['std_x_mm']:.1f} mm, y {s['std_y_mm']:.1f} mm",
                     fontsize=9)
        ax.set_ylabel("crane − robot (mm)")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time (s)")
    errors = out_dir / f"{scenario}-errors.png"
    fig.savefig(errors, dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(9, 3), layout="constrained")
    for run in runs:
        if run.velocity_mm_s:
            ax.plot(run.velocity_t_s, np.array(run.velocity_mm_s)[:, 0], lw=0.8,
                    label=run.algorithm)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("velocity x (mm/s)")
    ax.set_title("velocity in x as each algorithm sees it (paper Fig. 10)", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    velocity = out_dir / f"{scenario}-velocity.png"
    fig.savefig(velocity, dpi=110)
    plt.close(fig)
    return [errors, velocity]
