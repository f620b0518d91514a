"""Faults in the files the lab writes and reads: a recording's disk filled by another process;
crater scans with NaN points, coordinates a world away, and a sparse scan quantised to a
millimetre."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.faults.base import CampaignBase
from benchmarks.faults.lab import ROOT
from benchmarks.faults.rows import Row
from common.heightmap import HeightMap
from services.args import EXIT_CONFIG, EXIT_DISK
from tests.crater.scans import BROKEN_XYZ, sparse_cells_off, sparse_quantised_scan
from tests.smalldisk import NO_TMPFS, record_on_small_disk, summary_messages

GOAL_CELL_MM = 20.0  # a cell of an imported scan this far off its ground counts as wrong


class FileFaults(CampaignBase):
    """As a part of ``Campaign`` (``self.lab``: the lab file)."""

    def disk_filled(self) -> None:
        """``stb record`` of the lab onto a 20 MB disk of its own that another process
        (``dd``) fills once the recording is 1 MB: exit 5 with the file finished (it ended in
        a traceback, the file rejected by the mcap reader)."""
        with tempfile.TemporaryDirectory(dir=self.folder) as folder:
            code, err, kept = record_on_small_disk(self.lab, Path(folder), "--set",
                                                   "min_free_mb=2", fill_at_bytes=1_000_000)
            messages = summary_messages(kept) if kept.exists() else None
        if code == NO_TMPFS:
            self.rows.append(Row("disk filled from outside", "exit 5, the file finished",
                                 f"no tmpfs could be mounted: {err.strip()[:200]}", False,
                                 misses=["not measured"]))
            return
        traceback = "Traceback" in err
        held = code == EXIT_DISK and messages is not None and not traceback
        self.rows.append(Row(
            "disk filled from outside", "exit 5, no traceback; the mcap reader reads the "
            "file's summary", f"a 20 MB disk filled by dd once the recording was 1 MB: exit "
            f"{code}{', a traceback' if traceback else ''}; the file "
            f"{f'finished, {messages} messages' if messages is not None else 'NOT finished'}",
            held, {"exit": code, "messages": messages},
            [] if held else ["exit" if code != EXIT_DISK else "file"]))
        self.log(f"disk filled: {self.rows[-1].measured}")

    def crater_imports(self) -> None:
        """``stb crater import`` of a scan with a NaN point and one 10³⁰⁰ mm away (exit 2
        naming the file; it ended in a traceback), and of a sparse LAS scan quantised to
        1 mm (70 cells 20–301 mm off its ground once, with a singular plane per cell)."""
        with tempfile.TemporaryDirectory(dir=self.folder) as name:
            folder = Path(name)
            broken = folder / "broken.xyz"
            broken.write_text(BROKEN_XYZ)
            bad = _crater_import(broken, folder / "broken.npz")
            sparse = folder / "sparse.las"
            sparse_quantised_scan(sparse)
            good = _crater_import(sparse, folder / "sparse.npz")
            off = _cells_off(folder / "sparse.npz") if good.returncode == 0 else None
        named = bad.returncode == EXIT_CONFIG and str(broken) in bad.stderr \
            and "Traceback" not in bad.stderr
        wrong = None if off is None else int((off > GOAL_CELL_MM).sum())
        held = named and wrong == 0
        worst = "not imported" if off is None else f"worst cell {off.max():.1f} mm off"
        self.rows.append(Row(
            "crater imports", f"exit 2 naming the file for NaN and 10³⁰⁰ points; no cell of "
            f"a sparse 1 mm LAS scan more than {GOAL_CELL_MM:g} mm off",
            f"NaN + 10³⁰⁰: exit {bad.returncode}"
            f"{', the file named' if named else ', NOT as asked'}; sparse LAS: "
            f"{wrong} cells > {GOAL_CELL_MM:g} mm off ({worst})", held,
            {"broken_exit": bad.returncode, "cells_off": wrong,
             "worst_mm": None if off is None else float(off.max())},
            ([] if named else ["broken file"]) + ([] if wrong == 0 else ["cells off"])))
        self.log(f"crater imports: {self.rows[-1].measured}")


def _crater_import(scan: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "services.cli", "crater", "import", str(scan),
                           "--out", str(out)], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)


def _cells_off(path: Path) -> np.ndarray:
    """How far each cell of the imported map inside the scanned square is off its ground."""
    off, inside = sparse_cells_off(HeightMap.load(path))
    return off[inside]
