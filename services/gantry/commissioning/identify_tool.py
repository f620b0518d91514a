"""What ``stb gantry identify`` does once its flags are parsed (``identify_cli.py`` beside it
has the command and its documentation)."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import sys
import threading
import time

from common.bus import Bus, BusUnreachable, open_session
from common.heightmap import HeightMap
from services.gantry.commissioning.identify_run import (
    CommissioningError,
    Measurements,
    Recorder,
    lab_of,
    run_moves,
)
from services.gantry.crane import ModbusCrane
from services.gantry.reading import CraneError
from services.gantry.settings import GantrySettings

EXIT_NOT_SAFE, EXIT_NO_DEVICE = 1, 3


def identify(args: argparse.Namespace) -> int:
    try:
        return _identify(*lab_of(args), args)
    except CommissioningError as err:
        print(f"stb gantry identify: {err}", file=sys.stderr)
        return err.code


def _identify(settings: GantrySettings, heights: HeightMap, args: argparse.Namespace) -> int:
    crane = ModbusCrane(settings.crane_host, settings.crane_port, settings.crane_timeout_s,
                        settings.crane, settings.crane.frame())
    session = bus = None
    try:
        if settings.frames == "bus":
            try:
                session = open_session(settings.zenoh_settings())
            except BusUnreachable as err:
                raise CommissioningError(str(err), EXIT_NO_DEVICE) from err
            bus = Bus(session, settings.bus)
        recorder = Recorder(settings, heights, crane, bus)
        recorder.start()
        try:
            return _measure(recorder, settings, args)
        finally:
            recorder.stop()
            with contextlib.suppress(CraneError):
                crane.disable()
    finally:
        crane.close()
        if bus is not None and session is not None:
            bus.close()
            session.close()


def _measure(recorder: Recorder, settings: GantrySettings, args: argparse.Namespace) -> int:
    box, steps, yes = args.box, args.steps, args.yes
    start = recorder.ready_to_move()  # the crane idle and fault-free, the marker still
    out = sys.stderr if getattr(args, "json", False) else sys.stdout
    print(f"the crane stands at ({start[0]:.0f}, {start[1]:.0f}) mm; it will move within "
          f"x {start[0] - box / 2:.0f}…{start[0] + box / 2:.0f} mm, y {start[1]:.0f} mm "
          f"(±{box / 2:.0f} mm) for about {recorder.duration_s(steps):.0f} s.\n"
          "The marker below it must stay where it is; keep the crane's path clear.", file=out)
    if not yes and input("move the crane now? [y/N] ").strip().lower() not in ("y", "yes"):
        print("cancelled: the crane did not move")
        return EXIT_NOT_SAFE
    stop = threading.Event()
    beats = threading.Thread(target=_heartbeat, args=(recorder, stop), daemon=True)
    beats.start()
    try:
        plan = run_moves(recorder, start, box, steps, progress=_progress)
    finally:
        stop.set()
        beats.join(2)
    result = Measurements.of(recorder, plan, settings)
    if getattr(args, "json", False):
        print(json.dumps(dataclasses.asdict(result)))
    else:
        print(result.table())
        print("\nas lab-file settings:\n" + result.toml())
    return 0


def _heartbeat(recorder: Recorder, stop: threading.Event) -> None:
    while not stop.wait(0.1):
        with contextlib.suppress(CraneError):
            recorder.crane.heartbeat()


def _progress(what: str) -> None:
    print(f"  {time.strftime('%H:%M:%S')} {what}", file=sys.stderr, flush=True)


