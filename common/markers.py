"""The paper's marker detector (§2.1): run lengths, union-find, inertia ellipses, roundness.

``detect(frame)`` finds the round bright regions of an 8-bit gray image:

1. run-length encoding: per row, runs of pixels at or above the threshold that are at least
   ``l_min`` long (shorter ones are stray bright pixels);
2. a union-find with path compression merges runs that overlap on consecutive rows into
   regions;
3. per region: area, centroid and the inertia ellipse from the second moments (long and short
   radius, angle of the long axis); roundness r = long / short;
4. a region is a marker if r < ``r_lim`` and its area is within bounds. With no marker the
   threshold is lowered step by step down to ``t_lim``; more than ``max_markers`` markers is
   "too_many" (the paper makes no passpoint of such an image).

Pixel ``[row, col]`` has its centre at ``(u, v) = (col, row)``. Angles are in degrees in
(−90, 90], measured from the +u axis towards +v (clockwise on screen).

Speed: one vectorised pass finds the brightest pixel of each band of 16 rows — a frame in
which nothing reaches the lowest threshold ends there; in the bands that do, each column's
brightest over the band gives the band's bright segments of columns and each row's brightest
pixel within them, and at each threshold only the rows that reach it are scanned, within
those segments, by the compiled loop in ``markers_kernel.py`` (run lengths,
union-find and moments in one go): built ahead of time by ``make`` and the Docker image
(``markers_aot.py``), or else compiled by numba's JIT at the first call (a few seconds, then
cached on disk). Services call ``warm_up()`` at start-up.
"""

from __future__ import annotations

import functools
import importlib
import os
import threading
import time
from collections.abc import Callable
from typing import Literal, NamedTuple

import numpy as np

from common.messages import DetectedMarker, MarkerDetections

Status = Literal["ok", "none", "too_many"]
BAND_ROWS = 16  # rows per band of the first pass over the frame
_SMALL_AREA = 30  # below this (radius ≲ 3 px) the binary shape is too coarse to judge


class Spot(NamedTuple):
    """One bright region of an image: centroid (px), inertia ellipse (px, deg), roundness, area
    (px); a marker when it passes the paper's filters (``DetectedMarker`` on the bus)."""

    u: float
    v: float
    radius_long: float
    radius_short: float
    angle_deg: float
    roundness: float
    area: int


class Detection(NamedTuple):
    """What ``detect`` found. ``regions`` are all regions at the final threshold (markers and
    rejected ones alike, for annotated images); ``markers`` are the valid ones. (A NamedTuple:
    it is made for every frame, and a frozen dataclass costs microseconds to make.)"""

    status: Status
    threshold: int
    markers: tuple[Spot, ...]
    regions: tuple[Spot, ...] = ()


def detect(frame: np.ndarray, *, threshold: int = 230, t_lim: int = 203, step: int = 5,
           r_lim: float = 1.21, l_min: int = 2, min_area: int = 3, max_area: int = 20000,
           max_markers: int = 1) -> Detection:
    """Find round bright markers in an 8-bit gray image (paper §2.1).

    Parameters
    ----------
    frame : (rows, cols) uint8 array
    threshold : first gray threshold (pixels ≥ threshold are bright)
    t_lim : lowest threshold tried when nothing is found (paper: 203)
    step : how much the threshold is lowered each time
    r_lim : a marker's roundness (long / short radius) must be below this (paper: 1.21)
    l_min : shortest run of bright pixels kept, in pixels
    min_area, max_area : a marker's area bounds, pixels
    max_markers : more valid markers than this → status "too_many"

    Raises ValueError for anything but a 2-D uint8 array, or inconsistent parameters.
    """
    threshold_kernel = _threshold_kernel()
    image = _checked(frame, threshold, t_lim, step, r_lim, l_min, min_area, max_area,
                     max_markers)
    if image.size == 0:
        return Detection("none", t_lim, ())
    bands = _band_maxima(image)
    if not bands.tobytes().translate(None, _darker_than(t_lim)):  # the common frame:
        return Detection("none", t_lim, ())  # nothing reaches even the lowest threshold
    out = _out_table(0)
    args = (image, bands, BAND_ROWS, _thresholds(threshold, t_lim, step), l_min, _SMALL_AREA,
            float(r_lim), min_area, max_area)
    t, count = threshold_kernel(*args, out)
    if count > out.shape[0]:  # more regions than the table has room for: again, with room
        out = _out_table(count)
        t, count = threshold_kernel(*args, out)
    rows = out[:count].tolist()
    regions = tuple([Spot(u, v, long_r, short_r, angle, roundness, int(area))
                     for u, v, long_r, short_r, angle, roundness, area, _ in rows])
    markers = tuple([spot for spot, row in zip(regions, rows, strict=True) if row[7]])
    if not markers:
        return Detection("none", t_lim, (), regions)
    return Detection("too_many" if len(markers) > max_markers else "ok", int(t), markers,
                     regions)


def warm_up() -> float:
    """Load the detector's loop now, not on the first frame: the module built ahead of time
    (``common/markers_aot.py``), or else numba's JIT, whose first compile in a fresh checkout
    or container takes seconds, holding the interpreter. Services that detect call this at
    start-up. Returns the seconds it took."""
    started = time.perf_counter()
    frame = np.zeros((16, 16), np.uint8)
    frame[6:10, 6:10] = 255  # a spot, so that every compiled step runs
    detect(frame)
    return time.perf_counter() - started


def kernel_origin() -> str:
    """Which build of the loop the detector runs, for the services' start-up log."""
    kernel = _threshold_kernel()
    return "numba's JIT" if hasattr(kernel, "py_func") else f"built ahead ({kernel.__module__})"


@functools.cache
def _threshold_kernel() -> Callable[..., tuple[int, int]]:
    """The loop: the module ``common/markers_aot.py`` built from this very kernel source if it
    is there (no numba, no LLVM in the process), numba's JIT otherwise. Loaded on the first
    detection, not where this module is imported: the calib service only draws markers, and
    loading numba (0.35 s, seconds on a loaded machine) would delay its restart
    (docs/reliability.md)."""
    from common.markers_aot import module_name

    try:
        if os.environ.get("NUMBA_DISABLE_JIT") == "1":  # the loop as plain Python, to debug
            raise ImportError("NUMBA_DISABLE_JIT")
        module = importlib.import_module(f"common.{module_name()}")
    except ImportError:
        from common.markers_kernel import threshold_kernel

        return threshold_kernel
    return module.threshold_kernel


def closest(markers: tuple[Spot, ...] | list[Spot], u: float, v: float,
            max_distance_px: float = float("inf")) -> Spot | None:
    """The marker nearest to a last known position (the gantry's choice, §3.1), or None."""
    best = min(markers, key=lambda m: (m.u - u) ** 2 + (m.v - v) ** 2, default=None)
    if best is None or np.hypot(best.u - u, best.v - v) > max_distance_px:
        return None
    return best


# --- the pipeline's steps --------------------------------------------------------------------


def _checked(frame: np.ndarray, threshold: int, t_lim: int, step: int, r_lim: float,
             l_min: int, min_area: int, max_area: int, max_markers: int) -> np.ndarray:
    if not isinstance(frame, np.ndarray):
        raise ValueError(f"expected a numpy array, got {type(frame).__name__}")
    if frame.ndim != 2:
        raise ValueError(f"expected a 2-D gray image (rows × cols), got shape {frame.shape}; "
                         "convert colour images to gray first")
    if frame.dtype != np.uint8:
        raise ValueError(f"expected 8-bit pixels (uint8), got {frame.dtype}")
    if not 0 <= t_lim <= threshold <= 255:
        raise ValueError(f"need 0 ≤ t_lim ≤ threshold ≤ 255, got t_lim={t_lim}, "
                         f"threshold={threshold}")
    if step < 1 or l_min < 1 or r_lim < 1 or max_markers < 1 or not 0 <= min_area <= max_area:
        raise ValueError("need step ≥ 1, l_min ≥ 1, r_lim ≥ 1, max_markers ≥ 1 and "
                         "0 ≤ min_area ≤ max_area")
    return frame if frame.flags.c_contiguous else np.ascontiguousarray(frame)


def _band_maxima(image: np.ndarray) -> np.ndarray:
    """The brightest pixel of every band of ``BAND_ROWS`` rows: the one full pass over the
    frame, as numpy's vectorised reduction over contiguous bands (several times faster than
    a compiled per-row loop, and than a maximum per column of each band)."""
    rows = image.shape[0]
    full = rows - rows % BAND_ROWS
    if full == 0:
        return np.array([image.max()], np.uint8)
    bands = image[:full].reshape(full // BAND_ROWS, -1).max(axis=1)
    return bands if full == rows else np.append(bands, image[full:].max())


_tables = threading.local()  # each thread's table for the kernel's result (detect is nogil)


def _out_table(regions: int) -> np.ndarray:
    """This thread's table for ``threshold_kernel``'s regions, with room for ``regions``
    (made once per thread, grown when a frame has more: an array made by the compiled code
    costs microseconds to hand over, one passed in almost nothing)."""
    table = getattr(_tables, "table", None)
    if table is None or table.shape[0] < regions:
        table = np.empty((max(256, 2 * regions), 8))
        _tables.table = table
    return table


@functools.lru_cache(maxsize=256)
def _darker_than(level: int) -> bytes:
    """Every byte value below ``level``: what ``bytes.translate`` deletes from the band maxima
    to leave those that reach it (a C loop over 36 bytes; Python's ``max`` took 1 µs)."""
    return bytes(range(level))


@functools.lru_cache(maxsize=64)
def _thresholds(threshold: int, t_lim: int, step: int) -> np.ndarray:
    """The paper's thresholds, highest first, down to ``t_lim`` (made once per parameters)."""
    out = np.array([*range(threshold, t_lim, -step), t_lim], np.int64)
    out.flags.writeable = False
    return out


# --- annotated images ----------------------------------------------------------------------------


def annotate(frame: np.ndarray, result: Detection) -> np.ndarray:
    """A colour copy of ``frame`` with every region drawn: its ellipse (green for markers,
    red for rejected regions), centroid, both radii along their axes, and the status."""
    import cv2

    image = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    chosen = set(result.markers)
    for region in result.regions:
        colour = (0, 200, 0) if region in chosen else (0, 0, 255)
        centre = (region.u, region.v)
        axes = (max(region.radius_long, 0.5), max(region.radius_short, 0.5))
        cv2.ellipse(image, (centre, (2 * axes[0], 2 * axes[1]), region.angle_deg), colour, 1,
                    cv2.LINE_AA)
        a = np.radians(region.angle_deg)
        for radius, direction in ((region.radius_long, (np.cos(a), np.sin(a))),
                                  (region.radius_short, (-np.sin(a), np.cos(a)))):
            tip = (int(round(region.u + radius * direction[0])),
                   int(round(region.v + radius * direction[1])))
            cv2.line(image, (int(round(region.u)), int(round(region.v))), tip, colour, 1)
        cv2.drawMarker(image, (int(round(region.u)), int(round(region.v))), (255, 200, 0),
                       cv2.MARKER_CROSS, 6, 1)
    text = f"{result.status} t={result.threshold} markers={len(result.markers)}"
    cv2.putText(image, text, (5, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 0), 1)
    return image


def to_message(result: Detection, camera: str, measured_s: float, width_px: int,
               height_px: int, answered_after_s: float = 0.0) -> MarkerDetections:
    """The bus message of a detection (``measured_s`` = when the image was captured, or when
    it was asked for and ``answered_after_s`` later it came)."""
    return MarkerDetections(
        measured_s=measured_s, camera=camera, status=result.status, threshold=result.threshold,
        width_px=width_px, height_px=height_px,
        answered_after_s=min(max(answered_after_s, 0.0), 60.0),
        markers=[DetectedMarker(u_px=mk.u, v_px=mk.v, radius_long_px=mk.radius_long,
                                radius_short_px=mk.radius_short,
                                angle_deg=min(max(mk.angle_deg, -180.0), 180.0),
                                roundness=max(mk.roundness, 1.0), area_px=mk.area)
                 for mk in result.markers[:256]])


def marker_of(d: DetectedMarker) -> Spot:
    """A detected marker from the bus back as the detector's own tuple (to annotate, say)."""
    return Spot(d.u_px, d.v_px, d.radius_long_px, d.radius_short_px, d.angle_deg,
                  d.roundness, d.area_px)
