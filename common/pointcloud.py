"""Point cloud files as laser scanners and their software write them, read and written by
well-kept libraries: PLY (ASCII and binary, ``plyfile``), LAS/LAZ (``laspy``, LAZ through
``lazrs``) and plain text — XYZ or CSV, three numbers a line (``numpy.loadtxt``).

``read_points`` gives (N, 3) float64 in the file's own units and says which; a file that is
not a point cloud is a ``PointCloudError`` naming the file and what is wrong.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

SUFFIXES = {".ply": "PLY", ".las": "LAS", ".laz": "LAZ", ".xyz": "XYZ", ".txt": "XYZ",
            ".csv": "CSV"}


class PointCloudError(ValueError):
    """A point cloud file that cannot be read; the message names it."""


def read_points(path: Path) -> np.ndarray:
    """Every point's (x, y, z) in the file's units, (N, 3) float64."""
    kind = SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise PointCloudError(f"{path}: unknown point cloud format {path.suffix!r} (known: "
                              f"{', '.join(sorted(SUFFIXES))})")
    if not path.is_file():
        raise PointCloudError(f"{path}: no such file")
    try:
        points = {"PLY": _read_ply, "LAS": _read_las, "LAZ": _read_las}.get(kind, _read_text)(
            path)
    except PointCloudError:
        raise
    except Exception as err:  # noqa: BLE001 - each library fails its own way on a bad file
        raise PointCloudError(f"{path}: not a readable {kind} point cloud ({err})") from err
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise PointCloudError(f"{path}: no points with x, y and z")
    finite = np.all(np.isfinite(points), axis=1)
    if not finite.all():
        points = points[finite]
        if len(points) == 0:
            raise PointCloudError(f"{path}: no finite points")
    return points


def write_points(path: Path, points: np.ndarray, *, ascii_ply: bool = False) -> None:
    """Write (N, 3) points as PLY (binary unless ``ascii_ply``) or XYZ/CSV by the suffix."""
    kind = SUFFIXES.get(path.suffix.lower())
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "PLY":
        from plyfile import PlyData, PlyElement

        vertex = np.empty(len(points), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
        vertex["x"], vertex["y"], vertex["z"] = points[:, 0], points[:, 1], points[:, 2]
        PlyData([PlyElement.describe(vertex, "vertex")], text=ascii_ply).write(str(path))
    elif kind in ("XYZ", "CSV"):
        np.savetxt(path, points, fmt="%.2f", delimiter="," if kind == "CSV" else " ",
                   header="x,y,z" if kind == "CSV" else "", comments="")
    else:
        raise PointCloudError(f"{path}: can write .ply, .xyz and .csv, not {path.suffix!r}")


def _read_ply(path: Path) -> np.ndarray:
    from plyfile import PlyData

    data = PlyData.read(str(path))
    if "vertex" not in data:
        raise PointCloudError(f"{path}: a PLY file without vertices")
    vertex = data["vertex"].data
    names = vertex.dtype.names or ()
    if not {"x", "y", "z"} <= set(names):
        raise PointCloudError(f"{path}: PLY vertices without x, y, z (has {', '.join(names)})")
    return np.column_stack([vertex["x"], vertex["y"], vertex["z"]]).astype(np.float64)


def _read_las(path: Path) -> np.ndarray:
    import laspy

    las = laspy.read(str(path))
    return np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])


def _read_text(path: Path) -> np.ndarray:
    with open(path, encoding="utf-8", errors="replace") as f:
        first = f.readline()
    delimiter = "," if "," in first else None
    try:
        float(first.replace(",", " ").split()[0])
        header = 0
    except (ValueError, IndexError):
        header = 1  # a header line: x,y,z
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # an empty file: said below, not warned
        return np.loadtxt(path, delimiter=delimiter, skiprows=header, usecols=(0, 1, 2),
                          dtype=np.float64, ndmin=2)
