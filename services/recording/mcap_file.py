"""How a recording of the bus is laid out in an MCAP file, written and read in one place.

* One channel per concrete key (topic = the key, e.g. ``stb/tracker/robot``), message encoding
  ``msgpack``, no schema: the payload exactly as it crossed the bus, so that a replay puts back
  the same bytes. Channel metadata: the Zenoh encoding and the model name.
* Beside it a JSON copy for Foxglove (topic ``json/<key>``, encoding ``json``): the message as
  JSON, camera images as ``foxglove.CompressedImage`` (see ``services.recording.foxglove``).
* ``log_time`` = when the recorder received the sample, ``publish_time`` = the message's own
  measurement time (``measured_s``; the receive time if the payload has none), ``sequence`` =
  the sample's number on its key, from 1.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

JSON_PREFIX = "json/"
PROFILE = ""
LIBRARY = "stb-supervisor record"
NS = 1_000_000_000


class RecordingError(ValueError):
    """A file that is not a readable recording."""


@dataclass(frozen=True)
class Sample:
    """One recorded sample of the bus."""

    key: str
    payload: bytes
    encoding: str
    received_s: float
    measured_s: float
    sequence: int


class RecordWriter:
    """Writes samples (and their JSON copies) to an open binary file; ``finish()`` at the end."""

    def __init__(self, out: IO[bytes], metadata: dict[str, str] | None = None) -> None:
        self._writer = Writer(out, compression=CompressionType.ZSTD, chunk_size=256 * 1024)
        self._writer.start(profile=PROFILE, library=LIBRARY)
        if metadata:
            self._writer.add_metadata("stb", metadata)
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self.messages = 0

    def write(self, key: str, payload: bytes, *, encoding: str, model: str,
              received_s: float, measured_s: float | None) -> int:
        """Write one sample; returns its sequence number on its key."""
        channel = self._channels.get(key)
        if channel is None:
            channel = self._writer.register_channel(
                key, "msgpack", 0, metadata={"zenoh_encoding": encoding, "model": model})
            self._channels[key] = channel
        sequence = self._sequence.get(key, 0) + 1
        self._sequence[key] = sequence
        self._writer.add_message(channel, log_time=_ns(received_s), data=payload,
                                 publish_time=_ns(received_s if measured_s is None
                                                  else measured_s), sequence=sequence)
        self.messages += 1
        return sequence

    def write_json(self, key: str, data: bytes, *, schema: tuple[str, dict] | None,
                   received_s: float, measured_s: float | None, sequence: int) -> None:
        """The JSON copy of a sample written with ``write`` (same times and sequence)."""
        topic = JSON_PREFIX + key
        channel = self._channels.get(topic)
        if channel is None:
            schema_id = 0
            if schema is not None:
                name, body = schema
                schema_id = self._schemas.get(name) or self._writer.register_schema(
                    name, "jsonschema", json.dumps(body).encode())
                self._schemas[name] = schema_id
            channel = self._writer.register_channel(topic, "json", schema_id)
            self._channels[topic] = channel
        self._writer.add_message(channel, log_time=_ns(received_s), data=data,
                                 publish_time=_ns(received_s if measured_s is None
                                                  else measured_s), sequence=sequence)

    def finish(self) -> None:
        self._writer.finish()


def read_samples(path: Path, keys: Iterable[str] | None = None) -> Iterator[Sample]:
    """The recorded bus samples (not the JSON copies) in receive order; ``keys`` limits them
    to those concrete keys. Raises RecordingError for a file that is not a recording."""
    wanted = None if keys is None else set(keys)
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            for _, channel, message in reader.iter_messages(log_time_order=True):
                if channel.message_encoding != "msgpack" or channel.topic.startswith(JSON_PREFIX):
                    continue
                if wanted is not None and channel.topic not in wanted:
                    continue
                yield Sample(key=channel.topic, payload=message.data,
                             encoding=channel.metadata.get("zenoh_encoding", ""),
                             received_s=message.log_time / NS,
                             measured_s=message.publish_time / NS, sequence=message.sequence)
    except (McapError, EOFError, ValueError, KeyError) as err:
        raise RecordingError(f"{path}: not a readable MCAP recording ({err})") from err


def recorded_keys(path: Path) -> dict[str, int]:
    """Every recorded key and its number of samples (from the file's summary)."""
    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except (McapError, EOFError, ValueError) as err:
        raise RecordingError(f"{path}: not a readable MCAP recording ({err})") from err
    if summary is None or summary.statistics is None:
        raise RecordingError(f"{path}: no summary (was the recording stopped cleanly?)")
    counts = summary.statistics.channel_message_counts
    return {c.topic: counts.get(cid, 0) for cid, c in summary.channels.items()
            if c.message_encoding == "msgpack" and not c.topic.startswith(JSON_PREFIX)}


def _ns(seconds: float) -> int:
    return round(seconds * NS)
