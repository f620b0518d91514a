"""Reading Foxglove's typed channels back as a client would: the schema's protobuf
descriptors from the file (or the server), the message decoded with them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

_CLASSES: dict[tuple[str, bytes], Any] = {}


def message_class(name: str, descriptors: bytes) -> Any:
    """The protobuf class of ``name`` from a serialized FileDescriptorSet."""
    cls = _CLASSES.get((name, descriptors))
    if cls is None:
        pool = descriptor_pool.DescriptorPool()
        for file in descriptor_pb2.FileDescriptorSet.FromString(descriptors).file:
            pool.Add(file)
        cls = _CLASSES[(name, descriptors)] = message_factory.GetMessageClass(
            pool.FindMessageTypeByName(name))
    return cls


def decoded_typed(path: Path, topic: str) -> list[Any]:
    """Every message of a typed channel of a recording, decoded by its own schema."""
    with open(path, "rb") as f:
        return [message_class(schema.name, schema.data).FromString(msg.data)
                for schema, _, msg in make_reader(f).iter_messages(topics=[topic])]
