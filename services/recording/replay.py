"""What ``stb replay`` does once its flags are parsed (services/recording/replay_cli.py has
the command and its documentation): a recording back on the bus with its timing."""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path

import msgpack
import zenoh

from common import codec
from common.bus import linger
from common.mcap_file import RecordingError, Sample, read_run, run_keys
from common.node import stop_on_signals
from common.settings import LogLevel, ServiceSettings
from services.entry import (
    ToolError,
    checked_key_exprs,
    tool_session,
    tool_settings,
)

CLOCK_FIELDS = ("measured_s", "sent_s", "started_s")


class ReplaySettings(ServiceSettings):
    section = "replay"

    log_level: LogLevel = "WARNING"


def retimed(payload: bytes, *, origin_s: float, start_s: float, speed: float,
            sent_s: float) -> bytes:
    """The payload with its clock fields moved to replay time (pure).

    A recorded time ``t`` becomes ``start_s + (t - origin_s) / speed``: the recording's first
    receive time ``origin_s`` maps to when the replay started. ``sent_s`` is when this copy
    goes out. Payloads that are not msgpack maps go out unchanged.
    """
    try:
        data = codec.unpack(payload, max_bytes=len(payload))
    except codec.DecodeError:
        return payload
    for name in CLOCK_FIELDS:
        value = data.get(name)
        if isinstance(value, float):
            data[name] = start_s + (value - origin_s) / speed
    if isinstance(data.get("sent_s"), float):
        data["sent_s"] = sent_s
    return msgpack.packb(data, use_bin_type=True)


def pace(samples: Iterable[Sample], speed: float, stop: threading.Event,
         clock: Callable[[], float] = time.time) -> Iterator[tuple[Sample, float, float]]:
    """Each sample when its time has come, as (sample, origin_s, start_s): the first sample's
    receive time and when the replay started. Ends early when ``stop`` is set."""
    start = origin = None
    for sample in samples:
        if start is None or origin is None:
            start, origin = clock(), sample.received_s
        due = start + (sample.received_s - origin) / speed
        if stop.wait(max(0.0, due - clock())):
            return
        yield sample, origin, start


def replay(session: zenoh.Session, paths: Path | Sequence[Path], *, speed: float = 1.0,
           keys: Sequence[str] = (), exclude: Sequence[str] = (), as_recorded: bool = False,
           stop: threading.Event | None = None) -> Counter:
    """Put the recording (one file, or the parts of a split one in order) on the bus, one
    sample at a time as it is read; returns how many samples went out per key."""
    stop = stop or threading.Event()
    wanted = [zenoh.KeyExpr(k) for k in keys]
    unwanted = [zenoh.KeyExpr(k) for k in exclude]
    chosen = [k for k in run_keys(paths)
              if (not wanted or any(w.includes(zenoh.KeyExpr(k)) for w in wanted))
              and not any(u.includes(zenoh.KeyExpr(k)) for u in unwanted)]
    publishers: dict[str, zenoh.Publisher] = {}
    sent: Counter = Counter()
    last_put: float | None = None
    try:
        for sample, origin, start in pace(read_run(paths, chosen), speed, stop):
            publisher = publishers.get(sample.key)
            if publisher is None:
                publisher = session.declare_publisher(  # a replay waits rather than drops
                    sample.key, encoding=zenoh.Encoding(sample.encoding or codec.CONTENT_TYPE),
                    congestion_control=zenoh.CongestionControl.BLOCK)
                publishers[sample.key] = publisher
            payload = sample.payload if as_recorded else retimed(
                sample.payload, origin_s=origin, start_s=start, speed=speed,
                sent_s=time.time())
            publisher.put(payload)
            last_put = time.monotonic()
            sent[sample.key] += 1
    finally:
        linger(last_put)  # the last samples leave before the caller closes the session
        for publisher in publishers.values():
            publisher.undeclare()
    return sent


def replay_file(args: argparse.Namespace) -> int:
    if not args.speed > 0:
        raise ToolError("--speed must be > 0")
    settings = tool_settings(ReplaySettings, args)
    keys, exclude = checked_key_exprs(args.keys), checked_key_exprs(args.exclude)
    try:
        counts = run_keys(args.recording)
    except RecordingError as err:
        raise ToolError(str(err)) from err
    session = tool_session(settings)
    stop = threading.Event()
    restore = stop_on_signals(stop)
    files = " ".join(str(p) for p in args.recording)
    print(f"stb replay: {sum(counts.values())} samples on {len(counts)} keys from "
          f"{files} at speed {args.speed:g}", file=sys.stderr, flush=True)
    try:
        sent = replay(session, args.recording, speed=args.speed, keys=keys, exclude=exclude,
                      as_recorded=args.as_recorded, stop=stop)
    except RecordingError as err:
        raise ToolError(str(err)) from err
    finally:
        session.close()
        restore()
    print(f"stb replay: sent {sum(sent.values())} samples on {len(sent)} keys"
          f"{' (stopped early)' if stop.is_set() else ''}", file=sys.stderr)
    return 0

