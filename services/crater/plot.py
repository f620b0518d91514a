"""A picture of an imported height map: heights in colour, the cells filled by interpolation
in grey, the largest hole circled."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from services.crater.grid import Gridded


def plot_map(gridded: Gridded, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    heights = gridded.heights
    x0, x1, y0, y1 = heights.extent_mm
    fig, ax = plt.subplots(figsize=(7.5, 6.5), dpi=110)
    shown = ax.imshow(heights.heights_mm, origin="lower", extent=(x0, x1, y0, y1),
                      cmap="terrain")
    fig.colorbar(shown, ax=ax, label="height, mm")
    filled = np.ma.masked_where(~gridded.filled, np.ones_like(heights.heights_mm))
    ax.imshow(filled, origin="lower", extent=(x0, x1, y0, y1), cmap="Greys", alpha=0.55,
              vmin=0, vmax=1.5)
    if gridded.largest_hole_at_mm is not None:
        ax.plot(*gridded.largest_hole_at_mm, "o", mfc="none", mec="red", ms=16, mew=1.5,
                label=f"largest hole ({gridded.largest_hole_cells} cells)")
        ax.legend(loc="upper right", fontsize=8)
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_title(f"crater from {gridded.points} scan points: {gridded.filled_cells} cells "
                 "filled (grey)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
