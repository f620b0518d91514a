"""JPEG sizes read from the header before decoding; a frame whose JPEG is not the size its
message declares is refused without being decoded (a decode bomb)."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
import pytest

from common import messages as m
from common.jpeg import MAX_PIXELS, JpegError, decode_gray, jpeg_size
from services.gantry.frames import decode


def _jpeg(width: int, height: int, **params: int) -> bytes:
    image = np.zeros((height, width), np.uint8)
    image[height // 3, width // 3] = 255
    flags = [v for kv in params.items() for v in (getattr(cv2, kv[0]), kv[1])]
    ok, data = cv2.imencode(".jpg", image, flags)
    assert ok
    return data.tobytes()


@pytest.mark.parametrize("size", [(64, 48), (640, 480), (704, 576), (3000, 17)])
@pytest.mark.parametrize("progressive", [0, 1])
def test_the_size_is_read_from_the_header(size: tuple[int, int], progressive: int) -> None:
    data = _jpeg(*size, IMWRITE_JPEG_PROGRESSIVE=progressive)
    assert jpeg_size(data) == size
    assert decode_gray(data, size).shape == (size[1], size[0])


def test_not_a_jpeg_or_a_wrong_or_huge_size_is_refused_before_decoding(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from PIL import Image

    decoded: list[int] = []
    real = Image.open
    def counted(*a: Any, **k: Any) -> Any:
        decoded.append(1)
        return real(*a, **k)

    monkeypatch.setattr(Image, "open", counted)
    big = _jpeg(2000, 2000)  # a black 2000 × 2000 picture: a few kB
    assert len(big) < 100_000
    with pytest.raises(JpegError, match="2000×2000, not the 640×480 declared"):
        decode_gray(big, (640, 480))
    with pytest.raises(JpegError, match="no frame header"):
        decode_gray(b"\x89PNG\r\n\x1a\n" + bytes(100))
    bomb = bytearray(_jpeg(64, 48))  # the header patched to declare 24000 × 24000
    sof = next(i for i in range(len(bomb) - 1) if bomb[i] == 0xFF and bomb[i + 1] == 0xC0)
    bomb[sof + 5:sof + 9] = (24000).to_bytes(2, "big") * 2
    assert jpeg_size(bytes(bomb)) == (24000, 24000) and MAX_PIXELS < 24000 ** 2
    with pytest.raises(JpegError, match="refused"):
        decode_gray(bytes(bomb))
    assert decoded == [], "nothing was decoded"


@pytest.mark.parametrize("colour", [False, True])
def test_decoded_as_opencv_decodes_it_and_a_broken_one_is_refused(colour: bool) -> None:
    rng = np.random.default_rng(5)
    picture = (rng.random((576, 704, 3) if colour else (576, 704)) * 255).astype(np.uint8)
    ok, encoded = cv2.imencode(".jpg", picture, [cv2.IMWRITE_JPEG_QUALITY, 85])
    assert ok
    data = encoded.tobytes()
    ours = decode_gray(data, (704, 576))
    theirs = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert ours.dtype == np.uint8 and ours.shape == (576, 704)
    assert int(np.abs(ours.astype(int) - theirs).max()) <= 1
    with pytest.raises(JpegError, match="does not decode"):
        decode_gray(data[:len(data) // 2], (704, 576))


def test_the_gantry_drops_a_frame_whose_jpeg_is_not_its_declared_size() -> None:
    def frame(data: bytes) -> m.CameraFrame:
        return m.CameraFrame(measured_s=1.0, camera="tracking", seq=3, width_px=640,
                             height_px=480, encoding="jpeg", data=data)

    assert decode(frame(_jpeg(2000, 2000))) is None
    got = decode(frame(_jpeg(640, 480)))
    assert got is not None and got[1].shape == (480, 640)
