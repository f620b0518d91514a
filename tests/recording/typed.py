"""Reading Foxglove's typed channels back as a client would: the schema's protobuf
descriptors from the file (or the server), the message decoded with them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mcap.reader import make_reader

from services.report.video import message_class

__all__ = ["decoded_typed", "message_class"]


def decoded_typed(path: Path, topic: str) -> list[Any]:
    """Every message of a typed channel of a recording, decoded by its own schema."""
    with open(path, "rb") as f:
        return [message_class(schema.name, schema.data).FromString(msg.data)
                for schema, _, msg in make_reader(f).iter_messages(topics=[topic])
                if schema is not None]
