"""What the fuzz sends, and a decode bomb."""

from __future__ import annotations

import random
import time
from collections.abc import Iterator

import cv2
import msgpack
import numpy as np

from common import codec, keys
from common.wiredoc import EXAMPLES


def valid(topic: keys.Topic, payload: bytes) -> bool:
    try:
        codec.decode(topic.model, payload, max_bytes=topic.max_payload_bytes)
    except codec.DecodeError:
        return False
    return True


EXTREMES = [1e308, -1e308, 2**63, -(2**63), 2**53, 2**53 - 1, float(2**53), float("inf"),
            float("-inf"), float("nan"), 0, -1, "", "x" * 70000, None, [], {}, True,
            b"\xff" * 100, [1.0] * 5000]


def fuzz_payloads(topic: keys.Topic, count: int, rng: random.Random) -> Iterator[bytes]:
    """Random bytes, broken msgpack, and the key's own message mutated field by field."""
    example = EXAMPLES.get(topic.model)
    base = example.model_dump(mode="python") if example is not None else {"measured_s": 1.0}
    names = list(base)
    for i in range(count):
        kind = i % 4
        if kind == 0:
            yield rng.randbytes(rng.randrange(1, 200))
        elif kind == 1:
            whole = msgpack.packb(base, use_bin_type=True)
            yield whole[:rng.randrange(0, len(whole))]
        else:
            doc = dict(base)
            name = rng.choice(names)
            if kind == 2:
                doc[name] = rng.choice(EXTREMES)
            elif rng.random() < 0.5:
                doc.pop(name, None)
            else:
                doc[f"extra{rng.randrange(100)}"] = 1
            doc["measured_s"] = time.time()
            yield msgpack.packb(doc, use_bin_type=True)


def jpeg_declaring(width: int, height: int) -> bytes:
    """A small JPEG whose frame header (SOF0) claims ``width``×``height`` pixels."""
    ok, data = cv2.imencode(".jpg", np.zeros((8, 8), np.uint8))
    raw = bytearray(data.tobytes())
    sof = raw.index(b"\xff\xc0")
    raw[sof + 5:sof + 7] = height.to_bytes(2, "big")
    raw[sof + 7:sof + 9] = width.to_bytes(2, "big")
    return bytes(raw)
