"""How a recording of the bus is laid out in an MCAP file, written and read in one place.

* One channel per concrete key (topic = the key, e.g. ``stb/tracker/robot``), message encoding
  ``msgpack``, no schema: the payload exactly as it crossed the bus, so that a replay puts back
  the same bytes. Channel metadata: the Zenoh encoding and the model name.
* Beside it a JSON copy for Foxglove (topic ``json/<key>``, encoding ``json``, a JSON Schema
  per model; see ``services.recording.foxglove``), and Foxglove's typed channels (``/scene``,
  ``/tf``, ``/CAMERA/image``, …, protobuf; see ``services.recording.typed``). Only the
  msgpack channels are the recording proper: replay and the report read those.
* ``log_time`` = when the recorder received the sample, ``publish_time`` = the message's own
  measurement time (``measured_s``; the receive time if the payload has none), ``sequence`` =
  the sample's number on its key, from 1.
"""

from __future__ import annotations

import json
import logging
import math
import struct
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from mcap.exceptions import EndOfFile, McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.summary import Summary
from mcap.writer import CompressionType, Writer

log = logging.getLogger(__name__)
JSON_PREFIX = "json/"
MCAP0_MAGIC = b"\x89MCAP0\r\n"
PROFILE = ""
LIBRARY = "stb-supervisor record"
NS = 1_000_000_000
READ_ERRORS = (McapError, EOFError, ValueError, KeyError, struct.error, OSError)
"""What the mcap reader raises for a missing, truncated or foreign file."""


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

    def write_json(self, key: str, data: bytes, *, schema: tuple[str, dict[str, Any]] | None,
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

    def write_typed(self, topic: str, *, schema: tuple[str, str, bytes], message_encoding: str,
                    data: bytes, time_s: float) -> None:
        """A typed message for Foxglove: ``schema`` = (name, encoding, data)."""
        channel = self._channels.get(topic)
        if channel is None:
            name, encoding, body = schema
            schema_id = self._schemas.get(name) or self._writer.register_schema(
                name, encoding, body)
            self._schemas[name] = schema_id
            channel = self._writer.register_channel(topic, message_encoding, schema_id)
            self._channels[topic] = channel
        sequence = self._sequence.get(topic, 0) + 1
        self._sequence[topic] = sequence
        self._writer.add_message(channel, log_time=_ns(time_s), data=data,
                                 publish_time=_ns(time_s), sequence=sequence)

    def finish(self) -> None:
        self._writer.finish()


def read_samples(path: Path, keys: Iterable[str] | None = None) -> Iterator[Sample]:
    """The recorded bus samples (not the JSON copies) in receive order; ``keys`` limits them
    to those concrete keys. A recording that was never finished (the recorder was killed) is
    read in file order up to where it breaks off. Raises RecordingError for a file that is not
    a recording."""
    wanted = None if keys is None else set(keys)
    if not _finished(path):
        yield from _salvage(path, wanted)
        return
    try:
        with open(path, "rb") as f:
            for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
                if _is_bus(channel) and (wanted is None or channel.topic in wanted):
                    yield _sample(channel, message)
    except READ_ERRORS as err:
        raise RecordingError(f"{path}: not a readable MCAP recording ({err})") from err


def read_run(paths: Path | Sequence[Path], keys: Iterable[str] | None = None
             ) -> Iterator[Sample]:
    """The samples of a run recorded as one file or as its parts (``stb record --split-*``),
    file after file, each in receive order. What a part writes again at its start (the camera
    poses heard before it) is left out: a sample no newer than its key's last one in the
    parts before."""
    last: dict[str, float] = {}
    for path in [paths] if isinstance(paths, Path) else paths:
        before = dict(last)
        for sample in read_samples(path, keys):
            if sample.received_s <= before.get(sample.key, -math.inf):
                continue
            last[sample.key] = sample.received_s
            yield sample


def run_keys(paths: Path | Sequence[Path]) -> dict[str, int]:
    """Every key recorded in any file of a run, and its number of samples (from each file's
    summary; a pose written again at a part's start counts again)."""
    counts: Counter[str] = Counter()
    for path in [paths] if isinstance(paths, Path) else paths:
        counts.update(recorded_keys(path))
    return dict(counts)


def recorded_keys(path: Path) -> dict[str, int]:
    """Every recorded key and its number of samples."""
    summary = _summary(path)
    if summary is None:
        return dict(Counter(s.key for s in _salvage(path, None)))
    assert summary.statistics is not None  # checked by _summary
    counts = summary.statistics.channel_message_counts
    return {c.topic: counts.get(cid, 0) for cid, c in summary.channels.items() if _is_bus(c)}


def topics_of(path: Path) -> dict[str, str]:
    """Every channel's topic and its schema's name ("" without one), from the summary or, in a
    recording that was never finished, from the channels written before it breaks off."""
    summary = _summary(path)
    if summary is None:
        schemas: dict[int, str] = {}
        found: dict[str, str] = {}
        for record in _records_until_broken(path):
            if isinstance(record, Schema):
                schemas[record.id] = record.name
            elif isinstance(record, Channel):
                found[record.topic] = schemas.get(record.schema_id, "")
        return found
    return {c.topic: (s.name if (s := summary.schemas.get(c.schema_id)) else "")
            for c in summary.channels.values()}


def messages_of(path: Path, topics: Iterable[str], start_ns: int | None = None,
                end_ns: int | None = None) -> Iterator[tuple[Schema | None, Channel, Message]]:
    """The messages on ``topics`` logged between two times, both included (None: from the
    start, to the end), in log time order; a recording that was never finished (the recorder
    was killed) in file order up to where it breaks off."""
    wanted = set(topics)
    if _finished(path):
        with open(path, "rb") as f:
            yield from make_reader(f).iter_messages(topics=sorted(wanted), starting_at=start_ns,
                                                    ending_at=end_ns, log_time_order=True)
        return
    for schema, channel, message in _salvaged_messages(path, wanted):
        if (start_ns is None or message.log_time >= start_ns) and \
                (end_ns is None or message.log_time <= end_ns):
            yield schema, channel, message


def _salvaged_messages(path: Path, wanted: set[str] | None
                       ) -> Iterator[tuple[Schema | None, Channel, Message]]:
    """An unfinished file's messages on ``wanted`` topics (None: all), in file order."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    for record in _records_until_broken(path):
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Message):
            channel = channels.get(record.channel_id)
            if channel is not None and (wanted is None or channel.topic in wanted):
                yield schemas.get(channel.schema_id), channel, record


def _records_until_broken(path: Path) -> Iterator[object]:
    """An unfinished file's records in file order, up to where it breaks off."""
    try:
        with open(path, "rb") as f:
            yield from StreamReader(f).records
    except (*READ_ERRORS, EndOfFile) as err:
        log.warning("%s was not finished: read up to where it breaks off (%s)", path,
                    type(err).__name__)


def _finished(path: Path) -> bool:
    return _summary(path) is not None


def _summary(path: Path) -> Summary | None:
    """The file's summary, with its statistics; None if it breaks off before them.
    RecordingError if it is no MCAP file at all."""
    try:
        with open(path, "rb") as f:
            header = f.read(len(MCAP0_MAGIC))
    except OSError as err:
        raise RecordingError(f"{path}: cannot read it ({err})") from err
    if header != MCAP0_MAGIC:
        raise RecordingError(f"{path}: not a readable MCAP recording (no MCAP header)")
    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except READ_ERRORS:
        return None
    return summary if summary is not None and summary.statistics is not None else None


def _salvage(path: Path, wanted: set[str] | None) -> Iterator[Sample]:
    for _, channel, message in _salvaged_messages(path, wanted):
        if _is_bus(channel):
            yield _sample(channel, message)


def _is_bus(channel: Channel) -> bool:
    return channel.message_encoding == "msgpack" and not channel.topic.startswith(JSON_PREFIX)


def _sample(channel: Channel, message: Message) -> Sample:
    return Sample(key=channel.topic, payload=message.data,
                  encoding=channel.metadata.get("zenoh_encoding", ""),
                  received_s=message.log_time / NS, measured_s=message.publish_time / NS,
                  sequence=message.sequence)


def _ns(seconds: float) -> int:
    return round(seconds * NS)
