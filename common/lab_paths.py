"""Where a lab's files are by default (light: imported by commands before ``--help``)."""

from __future__ import annotations

from pathlib import Path

DEFAULT_HEIGHT_MAP = Path("run/crater.npz")
"""The lab's height map of the crater (``[gantry] height_map``, which the page, the recorders
and ``stb report`` read too): what ``stb crater import`` makes of a laser scan. On a simulated
lab's first start ``stb up`` makes it from the sim's scan (``services/crater/first_start.py``)."""

SIM_CRATER_FILE = Path("run/sim/crater.npz")
"""The sim's own crater, its truth (``[sim] crater_file``, made from the seed if missing): what
the sim's laser scanner and cameras see, never read by the gantry unless a lab file says so."""
