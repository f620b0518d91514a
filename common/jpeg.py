"""JPEG to a gray image, with its size read from the header first: a small file that declares
a huge picture (a decode bomb: 6.75 MB declaring 24000 × 24000 took a service from 347 MB to
1.2 GB) is refused before anything is decoded.

Decoded by Pillow (libjpeg-turbo, as OpenCV's), straight to gray: the same pixels as OpenCV's
``imdecode`` as fast, and 30 MB less in a process that needs OpenCV for nothing else (each
PTZ service, the gantry: docs/benchmarks.md, "Memory")."""

from __future__ import annotations

import io
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

MAX_PIXELS = 4096 * 4096
"""Larger than any camera of the lab's (the PTZ cameras' 704 × 576, the tracking camera's
640 × 480) by far."""
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
_NO_LENGTH = {0x01, *range(0xD0, 0xD8)}


class JpegError(ValueError):
    """Not a JPEG this project decodes: says why."""


def jpeg_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from the frame header (SOF), without decoding; None if there is none
    before the scan."""
    if data[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in _NO_LENGTH:
            i += 2
            continue
        if marker == 0xDA:  # start of scan: no frame header before it
            return None
        if marker in _SOF and i + 9 <= len(data):
            height = int.from_bytes(data[i + 5:i + 7], "big")
            width = int.from_bytes(data[i + 7:i + 9], "big")
            return width, height
        i += 2 + int.from_bytes(data[i + 2:i + 4], "big")
    return None


def decode_gray(data: bytes, size: tuple[int, int] | None = None) -> np.ndarray:
    """The JPEG as a gray uint8 array. Its header's size must be ``size`` (width, height) when
    given, and at most ``MAX_PIXELS``; checked before decoding. JpegError otherwise."""
    found = jpeg_size(data)
    if found is None:
        raise JpegError("not a JPEG (no frame header)")
    if size is not None and found != size:
        raise JpegError(f"JPEG is {found[0]}×{found[1]}, not the {size[0]}×{size[1]} declared")
    if found[0] * found[1] > MAX_PIXELS or 0 in found:
        raise JpegError(f"JPEG of {found[0]}×{found[1]} pixels refused (at most {MAX_PIXELS})")
    # Here, not at the top: a process that only reads sizes (stb observation) loads neither.
    import numpy as np
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data), formats=["JPEG"]) as picture:
            picture.draft("L", picture.size)  # libjpeg's own colour conversion: no RGB first
            gray = picture.convert("L")
    except (OSError, ValueError, SyntaxError) as err:  # Pillow's ways of saying "corrupt"
        raise JpegError(f"JPEG does not decode: {err}") from None
    return np.asarray(gray)
