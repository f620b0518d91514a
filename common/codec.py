"""The only module that knows the wire encoding: msgpack maps of plain values.

``encode(msg)`` packs ``msg.model_dump()``; ``decode(Model, payload)`` checks the size first, then
unpacks and validates strictly. Every rejection raises ``DecodeError`` with a short ``reason``
that the bus counts per key.
"""

from __future__ import annotations

import base64
import math
from typing import Any, TypeVar

import msgpack
from pydantic import BaseModel, ValidationError

from common.messages import Message

M = TypeVar("M", bound=Message)

CONTENT_TYPE = "application/msgpack"
DEFAULT_MAX_BYTES = 1024 * 1024

# Reasons a payload is dropped, as counted in ServiceHealth.keys[...].dropped.
TOO_LARGE = "too_large"
NOT_MSGPACK = "not_msgpack"
NOT_A_MAP = "not_a_map"
MISSING_FIELD = "missing_field"
EXTRA_FIELD = "extra_field"
NON_FINITE = "non_finite"
WRONG_TYPE = "wrong_type"
OUT_OF_RANGE = "out_of_range"
STALE = "stale"
FROM_FUTURE = "from_future"

_REASON_BY_ERROR = {
    "missing": MISSING_FIELD,
    "extra_forbidden": EXTRA_FIELD,
    "finite_number": NON_FINITE,
    "greater_than": OUT_OF_RANGE,
    "greater_than_equal": OUT_OF_RANGE,
    "less_than": OUT_OF_RANGE,
    "less_than_equal": OUT_OF_RANGE,
    "too_long": OUT_OF_RANGE,
    "too_short": OUT_OF_RANGE,
}


class DecodeError(ValueError):
    """A payload that is not a valid message; ``reason`` is one of the constants above."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


def encode(msg: Message, *, sent_s: float | None = None) -> bytes:
    """Pack a message; ``sent_s`` (if given) replaces the message's own send time."""
    data = msg.model_dump()
    if sent_s is not None:
        data["sent_s"] = sent_s
    return msgpack.packb(data, use_bin_type=True)


def unpack(payload: bytes, *, max_bytes: int) -> dict[str, Any]:
    """Unpack a msgpack map without validating it against a model (for generic tools)."""
    if len(payload) > max_bytes:
        raise DecodeError(TOO_LARGE, f"{len(payload)} bytes > limit {max_bytes}")
    try:
        data = msgpack.unpackb(payload, raw=False, strict_map_key=True)
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError) as err:
        raise DecodeError(NOT_MSGPACK, str(err) or type(err).__name__) from err
    if not isinstance(data, dict):
        raise DecodeError(NOT_A_MAP, f"top level is {type(data).__name__}, not a map")
    return data


def decode(model: type[M], payload: bytes, *, max_bytes: int = DEFAULT_MAX_BYTES) -> M:
    """Unpack and validate ``payload`` as ``model``; raise DecodeError on anything wrong."""
    data = unpack(payload, max_bytes=max_bytes)
    try:
        return model.model_validate(data)
    except ValidationError as err:
        first = err.errors()[0]
        reason = _REASON_BY_ERROR.get(first["type"], WRONG_TYPE)
        if reason == WRONG_TYPE and _has_non_finite(first.get("input")):
            reason = NON_FINITE
        where = ".".join(str(p) for p in first["loc"]) or "<message>"
        raise DecodeError(reason, f"{where}: {first['msg']}") from err


def _has_non_finite(value: object) -> bool:
    return isinstance(value, float) and not math.isfinite(value)


def to_plain(msg: BaseModel | dict[str, Any]) -> dict[str, Any]:
    """A JSON-ready dict of a message; bytes become base64 strings (monitor, recordings)."""
    data = msg.model_dump() if isinstance(msg, BaseModel) else dict(msg)
    return _plain(data)


def _plain(value: Any) -> Any:
    if isinstance(value, bytes):
        return base64.b64encode(value).decode("ascii")
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value
