"""``stb gantry identify``: measure the crane that is there (docs/commissioning.md).

    stb gantry identify [--box MM] [--steps N] [--yes] [--lab FILE]

With the gantry service stopped and a marker standing still below the crane (the robot,
parked), it moves the crane within a box of --box mm around where it stands — steps, long
moves, a slow ramp — and measures from the controller's registers and the tracking camera:
the sampling period, the dead time and total reaction, how old the reported position is, the
top speed and the acceleration. It prints them with their spread and as [gantry] settings.
It asks before it moves the crane (--yes: do not ask). Exit status: 0 measured, 1 not safe to
start or cancelled, 2 bad arguments, 3 no crane controller or no camera frames.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import sys
import threading
import time
from collections.abc import Sequence

from common.bus import Bus, BusUnreachable, open_session
from common.heightmap import HeightMap
from common.markers import warm_up
from common.node import configure_logging
from common.settings import ConfigError, load_settings
from services.entry import EXIT_CONFIG, base_parser, overrides_from
from services.gantry.commissioning_run import (
    CommissioningError,
    Measurements,
    Recorder,
    run_moves,
)
from services.gantry.crane import CraneError, ModbusCrane
from services.gantry.settings import GantrySettings

EXIT_NOT_SAFE, EXIT_NO_DEVICE = 1, 3


def main(argv: Sequence[str]) -> int:
    parser = base_parser("stb gantry identify", __doc__ or "")
    parser.add_argument("--box", type=float, default=400.0, metavar="MM",
                        help="the crane moves at most ±MM/2 around where it stands (400)")
    parser.add_argument("--steps", type=int, default=12, help="step responses (12)")
    parser.add_argument("--yes", action="store_true", help="do not ask before moving")
    parser.add_argument("--json", action="store_true", help="the figures as JSON on stdout")
    args = parser.parse_args(argv)
    if not 50 <= args.box <= 2000 or not 2 <= args.steps <= 100:
        print("stb gantry identify: --box must be 50–2000 mm, --steps 2–100", file=sys.stderr)
        return EXIT_CONFIG
    try:
        settings = load_settings(GantrySettings, args.lab, overrides_from(args))
        heights = HeightMap.load(settings.height_map)
    except (ConfigError, ValueError) as err:
        print(f"stb gantry identify: {err}", file=sys.stderr)
        return EXIT_CONFIG
    configure_logging(settings.log_level)
    warm_up()
    try:
        return _identify(settings, heights, args)
    except CommissioningError as err:
        print(f"stb gantry identify: {err}", file=sys.stderr)
        return err.code


def _identify(settings: GantrySettings, heights: HeightMap, args: object) -> int:
    crane = ModbusCrane(settings.crane_host, settings.crane_port, settings.crane_timeout_s,
                        settings.crane)
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


def _measure(recorder: Recorder, settings: GantrySettings, args: object) -> int:
    box, steps, yes = args.box, args.steps, args.yes  # type: ignore[attr-defined]
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


