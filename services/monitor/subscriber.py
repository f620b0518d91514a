"""What ``stb monitor`` does once its flags are parsed (services/monitor/__main__.py has the
command and its documentation): the table, or raw JSON lines."""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import threading
import time

import zenoh

from common import keys
from common.bus import Bus
from common.messages import Message
from common.node import stop_on_signals
from services.entry import checked_key_exprs, tool_session, tool_settings
from services.monitor.settings import MonitorSettings
from services.monitor.view import LabView, json_line


def monitor(args: argparse.Namespace) -> int:
    settings = tool_settings(MonitorSettings, args)
    if args.raw:
        checked_key_exprs([args.raw])
    session = tool_session(settings)
    stop = threading.Event()
    restore = stop_on_signals(stop)
    bus = Bus(session, settings.bus)
    try:
        if args.raw:
            _raw(bus, args.raw, stop, args.duration)
        else:
            _table(bus, settings, stop, args.duration)
    finally:
        bus.close()
        session.close()
        restore()
    return 0


def _raw(bus: Bus, key_expr: str, stop: threading.Event, duration: float | None) -> None:
    def show(item: tuple[str, Message | dict]) -> None:
        if stop.is_set():
            return
        try:
            print(json_line(*item), flush=True)
        except BrokenPipeError:  # the reader went away (| head): stop quietly
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            stop.set()

    bus.subscribe_any(key_expr, show)
    stop.wait(duration)


def _table(bus: Bus, settings: MonitorSettings, stop: threading.Event,
           duration: float | None) -> None:
    view = LabView()
    lock = threading.Lock()

    def on_sample(item: tuple[str, Message | dict]) -> None:
        with lock:
            view.on_sample(item[0], item[1], time.time())

    def on_alive(sample: zenoh.Sample) -> None:
        parsed = keys.parse_alive(bus.prefix, str(sample.key_expr))
        if parsed:
            with lock:
                view.on_alive(*parsed, alive=sample.kind == zenoh.SampleKind.PUT)

    bus.subscribe_any(f"{bus.prefix}/**", on_sample, latest=True)
    token_sub = bus.session.liveliness().declare_subscriber(
        keys.alive_pattern(bus.prefix), on_alive, history=True)
    deadline = None if duration is None else time.monotonic() + duration
    tty = sys.stdout.isatty()
    try:
        while not stop.wait(settings.refresh_s):
            size = shutil.get_terminal_size() if tty else None
            with lock:
                text = view.render(time.time(), *(size if size else (120, None)))
            print(("\x1b[H\x1b[2J" if tty else "") + text + ("" if tty else "\n---"), flush=True)
            if deadline is not None and time.monotonic() > deadline:
                break
    finally:
        token_sub.undeclare()
