"""The JSON copy of a recorded sample, so that Foxglove (which cannot decode msgpack) shows it
and its plot panel finds each numeric field: the message as JSON with its JSON Schema
(``stb.<Model>``, from the message's definition). Images have no JSON copy: they are in the
typed channels (``services.recording.typed``: ``/CAMERA/image``, ``/CAMERA/video``,
``/gantry/image``)."""

from __future__ import annotations

import json
from functools import cache
from typing import Any

from common import codec
from common import messages as m

IMAGES = (m.PtzPreview, m.CameraFrame)


def json_copy(msg: m.Message | dict) -> tuple[bytes, tuple[str, dict] | None] | None:
    """(JSON bytes, (schema name, JSON Schema) or None for a message of no known model), or
    None for an image."""
    if isinstance(msg, IMAGES):
        return None
    data = json.dumps(codec.to_plain(msg), allow_nan=False).encode()
    if isinstance(msg, dict):
        return data, None
    return data, (f"stb.{type(msg).__name__}", json_schema(type(msg)))


@cache
def json_schema(model: type[m.Message]) -> dict[str, Any]:
    """The model's JSON Schema with its ``$defs`` written in place (Foxglove reads the fields
    of a plain schema for its message paths)."""
    schema = model.model_json_schema()
    defs = schema.pop("$defs", {})

    def inline(node: Any) -> Any:
        if isinstance(node, dict):
            ref = node.get("$ref")
            if isinstance(ref, str) and ref.startswith("#/$defs/"):
                return inline(defs[ref.removeprefix("#/$defs/")])
            return {k: inline(v) for k, v in node.items()}
        if isinstance(node, list):
            return [inline(v) for v in node]
        return node

    return inline(schema)
