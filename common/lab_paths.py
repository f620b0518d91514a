"""Where a lab's files are by default (light: imported by commands before ``--help``)."""

from __future__ import annotations

from pathlib import Path

DEFAULT_HEIGHT_MAP = Path("run/sim/crater.npz")
"""Where the sim writes the crater as it starts (a real lab: ``stb crater import``)."""
