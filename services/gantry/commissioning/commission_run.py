"""``stb gantry commission`` once its flags are parsed (``commission_cli.py`` has the command and
its documentation): the frame, the camera, the dynamics, in that order, and the TOML."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from common.bus import Bus, BusUnreachable, open_session
from common.crane_frame import CraneFrame
from common.files import write_atomically
from common.heightmap import HeightMap
from common.tracking_camera import TrackingCameraModel
from services.gantry.commissioning.commission import (
    Stands,
    Watch,
    confirm,
    frame_pattern,
    heartbeat,
    survey_camera,
)
from services.gantry.commissioning.geometry_fit import CameraFit, FitRefused, FrameFit, fit_frame
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

EXIT_REFUSED, EXIT_NO_DEVICE = 1, 3


@dataclass
class Outcome:
    frame: FrameFit | None = None
    height_mm: float | None = None
    camera: CameraFit | None = None
    dynamics: Measurements | None = None
    motion_s: float = 0.0  # the crane moving, all steps
    notes: list[str] = field(default_factory=list)


def commission(args: argparse.Namespace) -> int:
    try:
        settings, heights = lab_of(args)
    except CommissioningError as err:
        print(f"stb gantry commission: {err}", file=sys.stderr)
        return err.code
    raw = ModbusCrane(settings.crane_host, settings.crane_port, settings.crane_timeout_s,
                      settings.crane)  # its own frame: the frame is what is measured
    session = None
    try:
        try:
            session = open_session(settings.zenoh_settings())
        except BusUnreachable as err:
            raise CommissioningError(str(err), EXIT_NO_DEVICE) from err
        bus = Bus(session, settings.bus)
        outcome = _run(args, settings, heights, raw, bus)
    except (CommissioningError, FitRefused) as err:
        print(f"stb gantry commission: {err}", file=sys.stderr)
        return getattr(err, "code", EXIT_REFUSED)
    finally:
        with contextlib.suppress(CraneError):
            raw.disable()
        raw.close()
        if session is not None:
            session.close()
    _report(args, settings, outcome)
    return 0


def _run(args: argparse.Namespace, settings: GantrySettings, heights: HeightMap,
         raw: ModbusCrane, bus: Bus) -> Outcome:
    watch = Watch(raw, bus)
    outcome = Outcome()
    steps = set(args.only)
    start = _ready(watch, settings, args.targets if "camera" in steps else [])
    with heartbeat(raw):
        if "frame" in steps:
            outcome.frame, outcome.height_mm = _frame(watch, settings, start, args, outcome)
        frame = outcome.frame.frame if outcome.frame else settings.crane.frame()
        height = outcome.height_mm or settings.tracking_camera.height_mm
        if "camera" in steps:
            outcome.camera = _camera(watch, settings, frame, height, start, args, outcome)
        watch.move(start)  # back where it stood: over the targets, for the dynamics
    if "dynamics" in steps:
        camera = outcome.camera.camera if outcome.camera else settings.tracking_camera
        outcome.dynamics = _dynamics(settings, heights, frame, camera, bus, args, outcome)
    return outcome


def _ready(watch: Watch, settings: GantrySettings, targets: list[str]) -> np.ndarray:
    """Where the crane stands (its own frame), once it is clear that moving it is safe and
    that the motion capture sees what the steps need."""
    try:
        reading = watch.crane.read()
    except CraneError as err:
        raise CommissioningError(str(err), EXIT_NO_DEVICE) from err
    if reading.enabled:
        raise CommissioningError("the crane is enabled: is the gantry service driving it? "
                                 "stop it (stb gantry disarm, then stop the service)")
    if not reading.safety_ok or reading.latched_faults:
        raise CommissioningError(f"the crane cannot move: faults {reading.fault_names} (reset "
                                 "them with stb gantry reset or at the controller)")
    needed = [settings.crane_marker, *targets]
    seen = watch.mocap(needed, seconds=1.0)
    missing = [label for label in needed if label not in seen]
    if missing:
        raise CommissioningError(f"the motion capture does not see {', '.join(missing)}: the "
                                 "crane's marker on its carriage and the targets below it must "
                                 "be labelled in QTM", EXIT_NO_DEVICE)
    with contextlib.suppress(CraneError):
        watch.crane.reset_faults()  # nothing latched (checked): clears a stale 'clamped'
    watch.crane.enable()
    return np.array([reading.x_mm, reading.y_mm])


def _frame(watch: Watch, settings: GantrySettings, start: np.ndarray, args: argparse.Namespace,
           outcome: Outcome) -> tuple[FrameFit, float]:
    half = min(args.box / 2, 600.0)
    stops = frame_pattern(start, half)
    confirm(args.yes, f"frame: move the crane through {len(stops)} stops within ±{half:.0f} mm "
                      f"of where it stands ({start[0]:.0f}, {start[1]:.0f}) in its own counts?")
    counted, seen, heights = [], [], []
    began = time.monotonic()
    for i, raw_xy in enumerate(stops):
        reading = watch.move(raw_xy)
        marker = watch.mocap([settings.crane_marker]).get(settings.crane_marker)
        if marker is None:
            raise CommissioningError(f"the motion capture lost {settings.crane_marker!r} at "
                                     f"stop {i + 1}")
        counted.append([reading.x_mm, reading.y_mm])
        seen.append(marker[:2])
        heights.append(marker[2])
        _progress(f"frame stop {i + 1}/{len(stops)}: crane ({reading.x_mm:.0f}, "
                  f"{reading.y_mm:.0f}), marker ({marker[0]:.0f}, {marker[1]:.0f}) mm")
    outcome.motion_s += time.monotonic() - began
    fit = fit_frame(np.array(counted), np.array(seen), max_residual_mm=args.max_frame_mm)
    height = float(np.mean(heights)) - args.marker_above_lens_mm
    return fit, height


def _camera(watch: Watch, settings: GantrySettings, frame: CraneFrame, height: float,
            start: np.ndarray, args: argparse.Namespace, outcome: Outcome) -> CameraFit:
    nominal = settings.tracking_camera.model_copy(update={
        "height_mm": height, "principal_px": None, "distortion": (0.0,) * 5, "yaw_deg": 0.0,
        "offset_mm": (0.0, 0.0)})
    targets = watch.mocap(args.targets, seconds=1.0)

    def visit(stops: list[np.ndarray]) -> Stands:
        inside = [s for s in stops if np.all(np.abs(frame.to_crane(s) - start) <= args.box / 2)]
        if len(inside) < len(stops):
            outcome.notes.append(f"camera: {len(stops) - len(inside)} of {len(stops)} stops "
                                 f"lay outside the ±{args.box / 2:.0f} mm box and were left out")
        confirm(args.yes, f"camera: move the crane through {len(inside)} stops above the "
                          f"targets {', '.join(targets)}?")
        stands: Stands = []
        began = time.monotonic()
        for i, world_xy in enumerate(inside):
            reading = watch.move(frame.to_crane(world_xy))
            stand = frame.to_world([reading.x_mm, reading.y_mm])
            stands.append((stand, watch.spots()))
            _progress(f"camera stop {i + 1}/{len(inside)}: {sum(map(len, stands[-1][1]))} spots")
        outcome.motion_s += time.monotonic() - began
        return stands

    return survey_camera(visit, targets, nominal, frame, height,
                         max_residual_px=args.max_camera_px, notes=outcome.notes)


def _dynamics(settings: GantrySettings, heights: HeightMap, frame: CraneFrame,
              camera: TrackingCameraModel, bus: Bus, args: argparse.Namespace,
              outcome: Outcome) -> Measurements:
    """What ``stb gantry identify`` measures, through the frame and camera just fitted."""
    measured = settings.model_copy(update={
        "crane": settings.crane.model_copy(update=frame.model_dump()),
        "tracking_camera": camera})
    crane = ModbusCrane(settings.crane_host, settings.crane_port, settings.crane_timeout_s,
                        settings.crane, frame)
    recorder = Recorder(measured, heights, crane, bus)
    recorder.start()
    try:
        start = recorder.ready_to_move()
        box = min(args.box, 400.0)
        confirm(args.yes, f"dynamics: steps, long moves and a ramp within ±{box / 2:.0f} mm "
                          "along x?")
        began = time.monotonic()
        with heartbeat(crane):
            plan = run_moves(recorder, start, box, args.steps, progress=_progress)
        outcome.motion_s += time.monotonic() - began
        return Measurements.of(recorder, plan, measured)
    finally:
        recorder.stop()
        with contextlib.suppress(CraneError):
            crane.disable()
        crane.close()


def _progress(what: str) -> None:
    print(f"  {time.strftime('%H:%M:%S')} {what}", file=sys.stderr, flush=True)


# --- what it found --------------------------------------------------------------------------


def _report(args: argparse.Namespace, settings: GantrySettings, outcome: Outcome) -> None:
    text = toml_fragment(outcome, settings.tracking_camera)
    if args.toml:
        write_atomically(args.toml, text.encode())
    out = sys.stderr if args.json else sys.stdout
    print(_table(outcome), file=out)
    for note in outcome.notes:
        print(f"note: {note}", file=out)
    print(f"\ncrane motion {outcome.motion_s:.0f} s"
          + (f"; written to {args.toml}" if args.toml else "") + "\n\n" + text, file=out)
    if args.json:
        print(json.dumps(_as_json(outcome)))


def _table(o: Outcome) -> str:
    rows = []
    if o.frame:
        f = o.frame
        rows += [f"frame: origin ({f.frame.origin_mm[0]:.1f} ± {f.origin_sd_mm[0]:.1f}, "
                 f"{f.frame.origin_mm[1]:.1f} ± {f.origin_sd_mm[1]:.1f}) mm, yaw "
                 f"{f.frame.yaw_deg:.3f} ± {f.yaw_sd_deg:.3f}°, flip_x {f.frame.flip_x}, flip_y "
                 f"{f.frame.flip_y}; residual {f.residual_rms_mm:.1f} mm rms "
                 f"({f.residual_max_mm:.1f} max) over {f.stops} stops; scale {f.scale:.4f}",
                 f"lens height {o.height_mm:.1f} mm (the crane's marker)"]
    if o.camera:
        c, sd = o.camera.camera, o.camera.spreads
        rows += [f"camera: focal {c.focal_mm:.4f} ± {sd['focal_mm']:.4f} mm, principal "
                 f"({c.principal[0]:.1f} ± {sd['cx_px']:.1f}, {c.principal[1]:.1f} ± "
                 f"{sd['cy_px']:.1f}) px, yaw {c.yaw_deg:.3f} ± {sd['yaw_deg']:.3f}°, lens offset"
                 f" ({c.offset_mm[0]:.1f} ± {sd['offset_x_mm']:.1f}, {c.offset_mm[1]:.1f} ± "
                 f"{sd['offset_y_mm']:.1f}) mm",
                 "        distortion " + ", ".join(
                     f"{name} {value:.4f} ± {sd[name]:.4f}" for name, value in
                     zip(("k1", "k2", "p1", "p2", "k3"), c.distortion, strict=True)),
                 f"        reprojection {o.camera.residual_rms_px:.2f} px rms "
                 f"({o.camera.residual_max_px:.2f} max) over {o.camera.observations} sightings"]
    if o.dynamics:
        rows.append("dynamics:\n" + o.dynamics.table())
    return "\n".join(rows)


def toml_fragment(o: Outcome, current: TrackingCameraModel) -> str:
    """The lab file's sections for what was measured, each value with its spread."""
    lines = ["# stb gantry commission, " + time.strftime("%Y-%m-%d %H:%M")]
    if o.dynamics:
        lines += ["", o.dynamics.toml().rstrip()]
    if o.frame:
        f = o.frame.frame
        lines += ["", "[gantry.crane]",
                  f"origin_mm = [{f.origin_mm[0]:.1f}, {f.origin_mm[1]:.1f}]  # ± "
                  f"{o.frame.origin_sd_mm[0]:.1f}, {o.frame.origin_sd_mm[1]:.1f}",
                  f"yaw_deg = {f.yaw_deg:.4f}  # ± {o.frame.yaw_sd_deg:.4f}",
                  f"flip_x = {str(f.flip_x).lower()}", f"flip_y = {str(f.flip_y).lower()}"]
    camera = o.camera.camera if o.camera else None
    if camera or o.height_mm is not None:
        c = camera or current.model_copy(update={"height_mm": o.height_mm})
        sd = o.camera.spreads if o.camera else {}
        lines += ["", "[gantry.tracking_camera]",
                  f"focal_mm = {c.focal_mm:.5f}  # ± {sd.get('focal_mm', 0):.5f}",
                  f"pixel_mm = {c.pixel_mm:g}", f"width_px = {c.width_px}",
                  f"height_px = {c.height_px}",
                  f"principal_px = [{c.principal[0]:.2f}, {c.principal[1]:.2f}]  # ± "
                  f"{sd.get('cx_px', 0):.2f}, {sd.get('cy_px', 0):.2f}",
                  "distortion = [" + ", ".join(f"{k:.6f}" for k in c.distortion) + "]",
                  f"yaw_deg = {c.yaw_deg:.4f}  # ± {sd.get('yaw_deg', 0):.4f}",
                  f"offset_mm = [{c.offset_mm[0]:.2f}, {c.offset_mm[1]:.2f}]  # ± "
                  f"{sd.get('offset_x_mm', 0):.2f}, {sd.get('offset_y_mm', 0):.2f}",
                  f"height_mm = {c.height_mm:.1f}  # the crane's marker"]
    return "\n".join(lines) + "\n"


def _as_json(o: Outcome) -> dict:
    import dataclasses

    out: dict = {"motion_s": o.motion_s, "notes": o.notes, "height_mm": o.height_mm}
    if o.frame:
        out["frame"] = {**o.frame.frame.model_dump(), "origin_sd_mm": o.frame.origin_sd_mm,
                        "yaw_sd_deg": o.frame.yaw_sd_deg, "residual_rms_mm":
                        o.frame.residual_rms_mm, "scale": o.frame.scale}
    if o.camera:
        out["camera"] = {**o.camera.camera.model_dump(), "spreads": o.camera.spreads,
                         "residual_rms_px": o.camera.residual_rms_px}
    if o.dynamics:
        out["dynamics"] = dataclasses.asdict(o.dynamics)
    return out
