"""``stb calib collect --camera ptz1 [--count 100] [--zooms 1,3000,6000,8000,9999]``: collect
passpoints for a camera, solve and publish its pose — done by the calib service; this command
starts it and shows progress. With ``--zooms``, ``--count`` passpoints at the widest zoom step
and ``--step-count`` at each other (wave the wand through the view at each) and one fit of
the pose and the lens: the zoom → focal length curve and the distortion (docs/calibration.md,
"The lens across the zoom range").

Ctrl-C cancels the collection. Exit status: 0 solved, 2 bad arguments, 3 no calib service or
no router (at the start, or silent for 30 s on the way), 4 the collection failed or was
cancelled.
"""

from __future__ import annotations

import argparse
import queue
import sys
import threading
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

from common.errors import ConfigError
from services.args import EXIT_CONFIG, base_parser, overrides_from

if TYPE_CHECKING:  # imported once the flags are parsed: --help answers at once
    from common import messages as m
    from common.bus import Bus

EXIT_NO_SERVICE = 3
EXIT_FAILED = 4
SILENT_S = 30.0  # the service says how it goes twice a second; this long silent: it is gone
FINAL = ("done", "failed", "cancelled")


def main(argv: Sequence[str] | None = None) -> int:
    parser = base_parser("stb calib collect", __doc__ or "")
    parser.add_argument("--camera", required=True)
    parser.add_argument("--count", type=int, help="passpoints (default: calib.count; with "
                        "--zooms: at the widest step)")
    parser.add_argument("--step-count", type=int, help="with --zooms: passpoints at each "
                        "other step, at most --count (default: calib.step_count)")
    parser.add_argument("--timeout", type=float, help="seconds (default: calib.timeout_s; "
                        "with --zooms, that many times the number of zooms)")
    parser.add_argument("--zooms", type=_zoom_list, default=[],
                        help="comma-separated zoom steps, two or more, e.g. 1,3000,6000,9999")
    args = parser.parse_args(argv)
    from common import messages as m
    from common.bus import Bus, BusUnreachable, open_session
    from common.node import configure_logging, stop_on_signals
    from common.settings import load_settings
    from services.calib.settings import CalibSettings

    try:
        settings = load_settings(CalibSettings, args.lab, overrides_from(args))
        request = m.CollectRequest(measured_s=time.time(), camera=args.camera,
                                   count=args.count or settings.count,
                                   step_count=args.step_count,  # None: the service's
                                   timeout_s=args.timeout or settings.timeout_s
                                   * max(len(args.zooms), 1), zooms=args.zooms)
    except (ConfigError, ValueError) as err:
        print(f"stb calib collect: {err}", file=sys.stderr)
        return EXIT_CONFIG
    configure_logging("WARNING")
    try:
        session = open_session(settings.zenoh_settings())
    except BusUnreachable as err:
        print(f"stb calib collect: {err}", file=sys.stderr)
        return EXIT_NO_SERVICE
    bus = Bus(session, settings.bus)
    stop = threading.Event()
    restore = stop_on_signals(stop)
    try:
        return _collect(bus, request, stop)
    finally:
        restore()
        bus.close()
        session.close()


def _collect(bus: Bus, request: m.CollectRequest, stop: threading.Event) -> int:
    from common import keys

    updates: queue.Queue[m.CollectProgress] = queue.Queue()
    bus.subscribe(keys.CALIB_PROGRESS, updates.put, latest=False, camera=request.camera)
    # the query's answer comes back over the same link as the subscription went out, after
    # it: the router holds the subscription before the request goes out
    alive = list(bus.session.liveliness().get(
        keys.alive_key(bus.prefix, "calib", "*"), timeout=2.0))
    if not any(r.ok is not None for r in alive):
        print("stb calib collect: no calib service is running (start it: stb calib, or stb up)",
              file=sys.stderr)
        return EXIT_NO_SERVICE
    bus.publish(keys.CALIB_COLLECT, request, camera=request.camera)
    interactive = sys.stdout.isatty()
    last = None
    heard = time.monotonic()
    while True:
        if stop.is_set():
            bus.publish(keys.CALIB_COLLECT, request.model_copy(
                update={"action": "cancel", "measured_s": time.time()}), camera=request.camera)
            stop.clear()
        try:
            progress = updates.get(timeout=0.5)
        except queue.Empty:
            if time.monotonic() - heard > SILENT_S:
                print(f"\nstb calib collect: no word from the calib service for {SILENT_S:g} s "
                      "(stopped? the router gone?)", file=sys.stderr)
                return EXIT_NO_SERVICE
            continue
        heard = time.monotonic()
        line = _line(progress)
        if line != last:
            print(("\r" + line + "\x1b[K") if interactive else line, end="" if interactive
                  and progress.state not in FINAL else "\n", flush=True)
            last = line
        if progress.state in FINAL:
            return 0 if progress.state == "done" else EXIT_FAILED


def _zoom_list(text: str) -> list[int]:
    try:
        zooms = [int(z) for z in text.split(",") if z.strip()]
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"not zoom steps: {text!r} (e.g. 1,3000,9999)"
                                         ) from err
    if len(zooms) < 2 or len(set(zooms)) != len(zooms) or not all(1 <= z <= 19999
                                                                  for z in zooms):
        raise argparse.ArgumentTypeError(f"two or more distinct zoom steps 1–19999, not {text!r}")
    return sorted(zooms)


def _line(p: m.CollectProgress) -> str:
    if p.state == "collecting" and p.zoom is not None:
        return (f"{p.camera}: zoom {p.zoom} ({p.zooms_done + 1} of {p.zooms}): "
                + _bar(p))
    if p.state == "collecting":
        return f"{p.camera}: " + _bar(p)
    if p.state == "solving":
        return f"{p.camera}: solving from {p.passpoints} passpoints…"
    if p.state == "done":
        return f"{p.camera}: done — {p.mean_error_px:.2f} px mean error; {p.message}"
    return f"{p.camera}: {p.state} — {p.message}"


def _bar(p: m.CollectProgress) -> str:
    width = 30
    filled = int(width * p.passpoints / max(p.target, 1))
    skipped = ", ".join(f"{n} {why}" for why, n in sorted(p.skipped.items())) or "none"
    return (f"[{'#' * filled}{'.' * (width - filled)}] {p.passpoints}/{p.target} passpoints "
            f"from {p.snapshots} snapshots (skipped: {skipped})"
            + (f" — {p.message}" if p.message else ""))
