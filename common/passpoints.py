"""Passpoints (a marker's world position and its pixel, paper §2.1) and mocap tracks, as CSV.

PASSPOINTS.csv: header ``X,Y,Z,u,v`` (mm, px), optionally ``t`` (the image's time, s, camera
clock) and ``zoom`` (the VAPIX zoom step the image was taken at: a multi-zoom collection).
TRACK.csv: header ``t,X,Y,Z`` (s on the mocap clock, mm). Every problem is reported
with the file and the row, and nothing is guessed.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from common.files import write_atomically

PASSPOINT_COLUMNS = ("X", "Y", "Z", "u", "v")
TRACK_COLUMNS = ("t", "X", "Y", "Z")


class CalibrationError(ValueError):
    """Input or result that cannot give a trustworthy pose; the message says why."""


@dataclass(frozen=True)
class Passpoints:
    world_mm: np.ndarray  # (N, 3)
    pixels: np.ndarray  # (N, 2) u, v
    times_s: np.ndarray | None = None  # (N,) image times on the camera clock
    zooms: np.ndarray | None = None  # (N,) zoom steps, for passpoints taken at several

    def __len__(self) -> int:
        return len(self.world_mm)

    def subset(self, index: np.ndarray) -> Passpoints:
        times = None if self.times_s is None else self.times_s[index]
        zooms = None if self.zooms is None else self.zooms[index]
        return Passpoints(self.world_mm[index], self.pixels[index], times, zooms)

    def with_world(self, world_mm: np.ndarray) -> Passpoints:
        return Passpoints(np.asarray(world_mm, dtype=float), self.pixels, self.times_s,
                          self.zooms)

    def by_zoom(self) -> dict[int, Passpoints]:
        """The passpoints of each zoom step (one entry, zoom 0, without a zoom column)."""
        if self.zooms is None:
            return {0: self}
        return {int(z): self.subset(np.flatnonzero(self.zooms == z))
                for z in np.unique(self.zooms)}

    @classmethod
    def joined(cls, by_zoom: dict[int, Passpoints]) -> Passpoints:
        """The passpoints of several zoom steps in one, each row with its zoom."""
        parts = list(by_zoom.items())
        times = [p.times_s for _, p in parts if p.times_s is not None]
        return cls(np.vstack([p.world_mm for _, p in parts]).reshape(-1, 3),
                   np.vstack([p.pixels for _, p in parts]).reshape(-1, 2),
                   np.concatenate(times) if len(times) == len(parts) else None,
                   np.concatenate([np.full(len(p), z, dtype=float) for z, p in parts]))


@dataclass(frozen=True)
class AtZoom:
    """The passpoints taken at one zoom step, their markers where the mocap saw them."""

    zoom: int
    world_mm: np.ndarray  # (N, 3)
    pixels: np.ndarray  # (N, 2)


@dataclass(frozen=True)
class Track:
    """A marker's mocap track; ``at`` interpolates linearly between samples."""

    times_s: np.ndarray  # (M,), strictly increasing
    xyz_mm: np.ndarray  # (M, 3)

    def at(self, times_s: np.ndarray) -> np.ndarray:
        t = np.asarray(times_s, dtype=float)
        return np.column_stack([np.interp(t, self.times_s, self.xyz_mm[:, i]) for i in range(3)])

    def covers(self, times_s: np.ndarray) -> bool:
        t = np.asarray(times_s, dtype=float)
        return bool(t.min() >= self.times_s[0] and t.max() <= self.times_s[-1])


def read_passpoints(path: Path) -> Passpoints:
    rows = _read_table(path, PASSPOINT_COLUMNS, optional=("t", "zoom"))
    data, present = rows["values"], rows["optional"]
    times = data[:, 5 + present.index("t")] if "t" in present else None
    zooms = data[:, 5 + present.index("zoom")] if "zoom" in present else None
    if zooms is not None and np.any((zooms < 1) | (zooms != np.round(zooms))):
        bad = np.flatnonzero((zooms < 1) | (zooms != np.round(zooms)))
        raise CalibrationError(f"{path}: rows {', '.join(str(i + 2) for i in bad[:10])} have "
                               "a zoom that is not a whole step ≥ 1")
    return Passpoints(data[:, 0:3], data[:, 3:5], times, zooms)


def read_track(path: Path) -> Track:
    data = _read_table(path, TRACK_COLUMNS)["values"]
    if len(data) < 2:
        raise CalibrationError(f"{path}: a track needs at least two samples, got {len(data)}")
    order = np.argsort(data[:, 0], kind="stable")
    data = data[order]
    if np.any(np.diff(data[:, 0]) <= 0):
        raise CalibrationError(f"{path}: two samples share a time")
    return Track(data[:, 0], data[:, 1:4])


def write_passpoints(path: Path, points: Passpoints) -> None:
    write_atomically(path, format_passpoints(points).encode())  # calib solve may read it


def format_passpoints(points: Passpoints) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    header = [*PASSPOINT_COLUMNS] + (["t"] if points.times_s is not None else []) + (
        ["zoom"] if points.zooms is not None else [])
    writer.writerow(header)
    for i in range(len(points)):
        row = [*(f"{v:.3f}" for v in points.world_mm[i]), *(f"{v:.3f}" for v in points.pixels[i])]
        if points.times_s is not None:
            row.append(f"{points.times_s[i]:.6f}")
        if points.zooms is not None:
            row.append(f"{int(points.zooms[i])}")
        writer.writerow(row)
    return out.getvalue()


def _read_table(path: Path, columns: tuple[str, ...], optional: tuple[str, ...] = ()
                ) -> dict[str, Any]:
    try:
        text = path.read_text()
    except OSError as err:
        raise CalibrationError(f"cannot read {path}: {err.strerror or err}") from err
    except UnicodeDecodeError as err:
        raise CalibrationError(f"{path}: not a CSV text file (byte {err.start} is not UTF-8)"
                               ) from err
    reader = csv.reader(io.StringIO(text))
    header = [h.strip() for h in next(reader, [])]
    missing = [c for c in columns if c not in header]
    if missing:
        raise CalibrationError(f"{path}: header {','.join(header) or '(empty)'} lacks "
                               f"{','.join(missing)}; expected {','.join(columns + optional)}")
    present_optional = [c for c in optional if c in header]
    wanted = [header.index(c) for c in (*columns, *present_optional)]
    values = []
    for line, row in enumerate(reader, start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        try:
            values.append([float(row[i]) for i in wanted])
        except (ValueError, IndexError) as err:
            raise CalibrationError(f"{path}, row {line}: {row!r} is not "
                                   f"{len(wanted)} numbers") from err
    array = np.array(values, dtype=float).reshape(-1, len(wanted))
    bad = np.flatnonzero(~np.all(np.isfinite(array), axis=1))
    if len(bad):
        raise CalibrationError(f"{path}: rows {', '.join(str(i + 2) for i in bad[:10])} hold NaN "
                               "or infinite values")
    return {"values": array, "optional": present_optional}
