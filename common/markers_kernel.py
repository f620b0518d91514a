"""The marker detector's hot loop, compiled with numba: runs → union-find → region moments.

Pure and allocation-light; ``common.markers`` is its only caller and documents the algorithm
(paper §2.1). Set ``NUMBA_DISABLE_JIT=1`` to run it as plain Python (slow, for debugging).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _find(parent: np.ndarray, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        following = parent[i]
        parent[i] = root
        i = following
    return root


@njit(cache=True, nogil=True)
def bright_segments(image: np.ndarray, band_max: np.ndarray, band_rows: int, floor: int
                    ) -> tuple[Any, ...]:
    """Where a threshold of at least ``floor`` can find anything: in each band whose brightest
    (``band_max``) reaches it, the segments of columns whose brightest over the band's rows
    (a vectorised pass) does — ``segments[band_start[b]:band_start[b + 1]]``, (first, end)
    each, left to right — and each row's brightest pixel within them (0 elsewhere, so that no
    threshold looks at the row) and its span: from its first to past its last pixel at or
    above ``floor``. A run of pixels at or above ``floor`` never leaves its segment or its
    row's span."""
    rows, cols = image.shape
    bands = band_max.shape[0]
    row_max = np.zeros(rows, np.uint8)
    row_span = np.empty((rows, 2), np.int64)  # read only where row_max reaches floor
    band_start = np.zeros(bands + 1, np.int64)
    segments = np.empty((cols // 2 + 1, 2), np.int64)  # a band has at most this many
    found = np.empty((0, 2), np.int64)
    column_max = np.empty(cols, np.uint8)
    n = 0
    for b in range(bands):
        band_start[b] = n
        if band_max[b] < floor:
            continue
        top_row = b * band_rows
        end_row = min(top_row + band_rows, rows)
        column_max[:] = image[top_row]
        for y in range(top_row + 1, end_row):
            np.maximum(column_max, image[y], column_max)  # vectorised
        first = n
        x = 0
        while x < cols:
            if column_max[x] < floor:
                x += 1
                continue
            begin = x
            while x < cols and column_max[x] >= floor:
                x += 1
            segments[n - first, 0], segments[n - first, 1] = begin, x
            n += 1
        found = np.concatenate((found, segments[:n - first]))
        for y in range(top_row, end_row):
            top, f, g = 0, -1, -1
            for k in range(n - first):
                for x in range(segments[k, 0], segments[k, 1]):
                    value = image[y, x]
                    top = max(top, value)
                    if value >= floor:
                        if f < 0:
                            f = x
                        g = x
            row_max[y] = top
            if f >= 0:
                row_span[y, 0], row_span[y, 1] = f, g + 1
    band_start[bands] = n
    return row_max, row_span, band_start, found


@njit(cache=True, nogil=True)
def _bright_rows(rows: int, band_rows: int, band_start: np.ndarray) -> np.ndarray:
    """The rows of the bands that have bright segments, top to bottom (the others have
    nothing at any threshold: not even looked at)."""
    out = np.empty(rows, np.int64)
    n = 0
    for b in range(band_start.shape[0] - 1):
        if band_start[b] < band_start[b + 1]:
            for y in range(b * band_rows, min((b + 1) * band_rows, rows)):
                out[n] = y
                n += 1
    return out[:n]


@njit(cache=True, nogil=True)
def run_capacity(row_max: np.ndarray, band_rows: int, band_start: np.ndarray,
                 segments: np.ndarray, bright: np.ndarray, threshold: int, l_min: int) -> int:
    """The most runs a threshold can give: one per l_min + 1 columns of each segment in each
    row that reaches it, and one more (the lowest threshold gives the most)."""
    capacity = 1
    for y in bright:
        if row_max[y] >= threshold:
            b = y // band_rows
            for k in range(band_start[b], band_start[b + 1]):
                capacity += (segments[k, 1] - segments[k, 0]) // (l_min + 1) + 1
    return capacity


@njit(cache=True, nogil=True)
def _scan_runs(image: np.ndarray, row_max: np.ndarray, row_span: np.ndarray, band_rows: int,
               band_start: np.ndarray, segments: np.ndarray, bright: np.ndarray,
               threshold: int, l_min: int, runs: np.ndarray, weights: np.ndarray
               ) -> tuple[Any, ...]:
    """Runs (row, start, end exclusive; Σw, Σw·x) with w = gray − threshold + 1, in the rows
    whose maximum reaches the threshold, within their band's segments and their span; sorted
    by row, then
    start; written into ``runs`` (n × 3) and ``weights`` (n × 2), which hold
    ``run_capacity`` of them."""
    run_row, run_start, run_end = runs[:, 0], runs[:, 1], runs[:, 2]
    run_w, run_wx = weights[:, 0], weights[:, 1]
    n = 0
    for y in bright:
        if row_max[y] < threshold:
            continue
        b = y // band_rows
        for k in range(band_start[b], band_start[b + 1]):
            x = max(segments[k, 0], row_span[y, 0])
            end = min(segments[k, 1], row_span[y, 1])
            while x < end:
                if image[y, x] < threshold:
                    x += 1
                    continue
                start, w, wx = x, 0.0, 0.0
                while x < end and image[y, x] >= threshold:
                    weight = image[y, x] - threshold + 1.0
                    w += weight
                    wx += weight * x
                    x += 1
                if x - start >= l_min:
                    run_row[n], run_start[n], run_end[n] = y, start, x
                    run_w[n], run_wx[n] = w, wx
                    n += 1
    return run_row[:n], run_start[:n], run_end[:n], run_w[:n], run_wx[:n]


@njit(cache=True, nogil=True)
def _label_runs(run_row: np.ndarray, run_start: np.ndarray, run_end: np.ndarray) -> tuple[Any, ...]:
    """Union-find over runs overlapping on consecutive rows; (label per run, region count)."""
    n = run_row.shape[0]
    parent = np.arange(n)
    prev_lo, prev_hi, i = 0, 0, 0
    while i < n:
        row = run_row[i]
        j = i + 1
        while j < n and run_row[j] == row:
            j += 1
        if i > 0 and run_row[i - 1] == row - 1:
            a = prev_lo
            for b in range(i, j):
                while a < prev_hi and run_end[a] <= run_start[b]:
                    a += 1
                k = a
                while k < prev_hi and run_start[k] < run_end[b]:
                    ra, rb = _find(parent, k), _find(parent, b)
                    if ra != rb:
                        parent[max(ra, rb)] = min(ra, rb)
                    k += 1
        prev_lo, prev_hi = i, j
        i = j
    label = np.full(n, -1, np.int64)
    count = 0
    for i in range(n):
        root = _find(parent, i)
        if label[root] < 0:
            label[root] = count
            count += 1
        label[i] = label[root]
    return label, count


@njit(cache=True, nogil=True)
def regions_kernel(image: np.ndarray, row_max: np.ndarray, row_span: np.ndarray, band_rows: int,
                   band_start: np.ndarray, segments: np.ndarray, bright: np.ndarray,
                   threshold: int, l_min: int, small_area: int, refine_from: int,
                   runs: np.ndarray, weights: np.ndarray) -> tuple[Any, ...]:
    """(table, seeds): one row per region, columns u, v, radius_long, radius_short,
    angle_deg, roundness, area: the brightness-weighted centroid, and the binary region's
    inertia ellipse (radius = 2·√eigenvalue, + 1/12 px² for a pixel's own extent, so a disc
    of radius R gives R), its angle, roundness and area; and a pixel (row, column) of each.

    A region smaller than ``small_area`` leaves too few pixels for its binary shape to say
    whether it is round (three pixels make an "L"); its centroid and ellipse come from the
    brightness-weighted moments of the blurred spot around it (``refine``) — here only for
    those of at least ``refine_from`` pixels (smaller ones cannot be markers: the threshold
    loop refines them only in the table it returns)."""
    run_row, run_start, run_end, run_w, run_wx = _scan_runs(
        image, row_max, row_span, band_rows, band_start, segments, bright, threshold, l_min,
        runs, weights)
    label, count = _label_runs(run_row, run_start, run_end)
    sums = np.zeros((count, 9))
    seed = np.full((count, 2), -1, np.int64)  # a pixel of each region: its first run's start
    for i in range(run_row.shape[0]):
        k = label[i]
        if seed[k, 0] < 0:
            seed[k, 0], seed[k, 1] = run_row[i], run_start[i]
        s, e, y = float(run_start[i]), float(run_end[i]), float(run_row[i])
        m = e - s
        sx = m * (s + e - 1) / 2
        sums[k, 0] += m
        sums[k, 1] += sx
        sums[k, 2] += ((e - 1) * e * (2 * e - 1) - (s - 1) * s * (2 * s - 1)) / 6
        sums[k, 3] += m * y
        sums[k, 4] += m * y * y
        sums[k, 5] += y * sx
        sums[k, 6] += run_w[i]
        sums[k, 7] += run_wx[i]
        sums[k, 8] += y * run_w[i]
    out = np.empty((count, 7))
    for k in range(count):
        area = sums[k, 0]
        mean_x, mean_y = sums[k, 1] / area, sums[k, 3] / area
        mu20 = sums[k, 2] / area - mean_x * mean_x + 1.0 / 12
        mu02 = sums[k, 4] / area - mean_y * mean_y + 1.0 / 12
        mu11 = sums[k, 5] / area - mean_x * mean_y
        spread = np.sqrt(((mu20 - mu02) / 2) ** 2 + mu11 * mu11)
        mean = (mu20 + mu02) / 2
        long_r = 2 * np.sqrt(mean + spread)
        short_r = 2 * np.sqrt(max(mean - spread, 1e-12))
        angle = np.degrees(0.5 * np.arctan2(2 * mu11, mu20 - mu02))
        if angle <= -90:
            angle += 180
        out[k, 0] = sums[k, 7] / sums[k, 6]
        out[k, 1] = sums[k, 8] / sums[k, 6]
        out[k, 2], out[k, 3], out[k, 4] = long_r, short_r, angle
        out[k, 5], out[k, 6] = long_r / short_r, area
    refine(image, out, seed, threshold, refine_from, small_area)
    return out, seed


@njit(cache=True, nogil=True)
def refine(image: np.ndarray, table: np.ndarray, seed: np.ndarray, threshold: int,
           from_area: int, below_area: int) -> None:
    """Regions of ``from_area`` to ``below_area`` pixels: centroid and ellipse (and so
    roundness) from the brightness-weighted moments of the spot around them, in place."""
    for k in range(table.shape[0]):
        if from_area <= table[k, 6] < below_area:
            refined = weighted_ellipse(image, table[k, 0], table[k, 1],
                                       int(np.ceil(table[k, 2])) + 3, threshold, seed[k, 0],
                                       seed[k, 1])
            if not np.isnan(refined[0]):
                table[k, :5] = refined
                table[k, 5] = refined[2] / refined[3]


@njit(cache=True, nogil=True)
def _border_median(image: np.ndarray, r0: int, r1: int, c0: int, c1: int) -> float:
    """The median gray of the window's border (its two rows and two columns, corners counted
    twice, as ``np.median`` of them would give), by counting: no copy, no sort."""
    counts = np.zeros(256, np.int64)
    for x in range(c0, c1):
        counts[image[r0, x]] += 1
        counts[image[r1 - 1, x]] += 1
    for y in range(r0, r1):
        counts[image[y, c0]] += 1
        counts[image[y, c1 - 1]] += 1
    total = 2 * (c1 - c0) + 2 * (r1 - r0)
    low_rank, high_rank = (total - 1) // 2, total // 2
    low = high = -1
    seen = 0
    for value in range(256):
        seen += counts[value]
        if low < 0 and seen > low_rank:
            low = value
        if seen > high_rank:
            high = value
            break
    return (low + high) / 2.0


@njit(cache=True, nogil=True)
def weighted_ellipse(image: np.ndarray, u: float, v: float, reach: int, threshold: int,
                     seed_y: int, seed_x: int) -> np.ndarray:
    """(u, v, radius_long, radius_short, angle_deg) from brightness-weighted moments of the
    spot that holds the pixel (seed_y, seed_x), within the window of ``reach`` pixels around
    (u, v): the 8-connected pixels brighter than the midpoint between the window border's
    median (the background) and the threshold, weighted by how much brighter. Only the spot
    itself: a reflection beside the marker must not stretch its ellipse. All NaN if the seed
    is not above that midpoint."""
    rows, cols = image.shape
    r0, r1 = max(int(v) - reach, 0), min(int(v) + reach + 1, rows)
    c0, c1 = max(int(u) - reach, 0), min(int(u) + reach + 1, cols)
    floor = (_border_median(image, r0, r1, c0, c1) + threshold) / 2
    out = np.full(5, np.nan)
    if not (r0 <= seed_y < r1 and c0 <= seed_x < c1) or image[seed_y, seed_x] <= floor:
        return out
    # seen: the window with a one-pixel frame marked seen, so that no neighbour needs a
    # bounds check (offset by r0 - 1, c0 - 1). Filled a row's run at a time (scanline); the
    # sums are exact in any order (weights are multiples of 1/4, far below 2^50).
    seen = np.zeros((r1 - r0 + 2, c1 - c0 + 2), np.bool_)
    seen[0, :] = seen[-1, :] = True
    seen[:, 0] = seen[:, -1] = True
    oy, ox = 1 - r0, 1 - c0
    # a run's start is pushed at most once from each run touching it (above, below)
    stack = np.empty((3 * (r1 - r0) * (c1 - c0) + 1, 2), np.int64)
    stack[0, 0], stack[0, 1] = seed_y, seed_x
    top = 1
    w = sx = sy = sxx = syy = sxy = 0.0
    while top > 0:
        top -= 1
        y, x = stack[top, 0], stack[top, 1]
        if seen[y + oy, x + ox]:
            continue
        left = x
        while not seen[y + oy, left - 1 + ox] and image[y, left - 1] > floor:
            left -= 1
        right = x
        while not seen[y + oy, right + 1 + ox] and image[y, right + 1] > floor:
            right += 1
        for col in range(left, right + 1):
            seen[y + oy, col + ox] = True
            weight = image[y, col] - floor
            w += weight
            sx += weight * col
            sy += weight * y
            sxx += weight * col * col
            syy += weight * y * y
            sxy += weight * col * y
        for ny in (y - 1, y + 1):  # 8-connected: the runs touching [left - 1, right + 1]
            col = left - 1
            while col <= right + 1:
                if not seen[ny + oy, col + ox] and image[ny, col] > floor:
                    stack[top, 0], stack[top, 1] = ny, col
                    top += 1
                    while col <= right + 1 and not seen[ny + oy, col + ox] \
                            and image[ny, col] > floor:
                        col += 1
                else:
                    col += 1
    if w <= 0:
        return out
    mean_x, mean_y = sx / w, sy / w
    mu20 = sxx / w - mean_x * mean_x + 1.0 / 12
    mu02 = syy / w - mean_y * mean_y + 1.0 / 12
    mu11 = sxy / w - mean_x * mean_y
    spread = np.sqrt(((mu20 - mu02) / 2) ** 2 + mu11 * mu11)
    mean = (mu20 + mu02) / 2
    angle = np.degrees(0.5 * np.arctan2(2 * mu11, mu20 - mu02))
    out[0], out[1] = mean_x, mean_y
    out[2] = 2 * np.sqrt(mean + spread)
    out[3] = 2 * np.sqrt(max(mean - spread, 1e-12))
    out[4] = angle + 180 if angle <= -90 else angle
    return out


@njit(cache=True, nogil=True)
def _is_marker(region: np.ndarray, r_lim: float, min_area: int, max_area: int) -> bool:
    """The paper's filters on a regions-table row: round enough, and of a marker's area."""
    return region[5] < r_lim and min_area <= region[6] <= max_area


@njit(cache=True, nogil=True)
def threshold_kernel(image: np.ndarray, band_max: np.ndarray, band_rows: int,
                     thresholds: np.ndarray, l_min: int, small_area: int, r_lim: float,
                     min_area: int, max_area: int, out: np.ndarray) -> tuple[Any, ...]:
    """The paper's threshold loop in one call (each call from Python costs microseconds, and
    an array handed back two more: the result goes into ``out``): the bright segments of the
    bands that reach the lowest threshold (``bright_segments``), then from the first
    threshold down, the regions at each threshold the frame reaches, until one has a marker
    (roundness below ``r_lim``, area within bounds).

    Returns (threshold, regions): the threshold, and how many regions it gave, whose rows
    (``regions_kernel``'s columns, then 1.0 for a marker, 0.0 for not) are written into
    ``out`` (n × 8) as far as it has room — a caller with less room than regions calls again
    with more. The last threshold with no marker when none has one, no regions when the frame
    reaches none."""
    row_max, row_span, band_start, segments = bright_segments(image, band_max, band_rows,
                                                              thresholds[-1])
    brightest = 0  # the frame's brightest pixel (where it reaches the floor: a band's)
    for value in band_max:
        brightest = max(brightest, value)
    bright = _bright_rows(image.shape[0], band_rows, band_start)
    table = np.empty((0, 7))
    seed = np.empty((0, 2), np.int64)
    capacity = run_capacity(row_max, band_rows, band_start, segments, bright, thresholds[-1],
                            l_min)
    runs = np.empty((capacity, 3), np.int64)  # one buffer for every threshold's runs
    weights = np.empty((capacity, 2), np.float64)
    chosen = thresholds[-1]
    found = False
    for t in thresholds:
        if t > brightest:
            continue
        table, seed = regions_kernel(image, row_max, row_span, band_rows, band_start,
                                     segments, bright, t, l_min, small_area, min_area, runs,
                                     weights)
        chosen = t
        for k in range(table.shape[0]):
            if _is_marker(table[k], r_lim, min_area, max_area):
                found = True
                break
        if found:
            break
    # regions too small to be markers were not refined while the loop went on: the table
    # handed back has them refined too (a frame without a marker tries every threshold)
    refine(image, table, seed, chosen, 0, min(min_area, small_area))
    for k in range(min(table.shape[0], out.shape[0])):
        out[k, :7] = table[k]
        out[k, 7] = 1.0 if _is_marker(table[k], r_lim, min_area, max_area) else 0.0
    return (chosen if found else thresholds[-1]), table.shape[0]
