"""Generates docs/wire-format.md from the models and keys, so the page cannot drift.

``python -m common.wiredoc > docs/wire-format.md``; a test checks the committed page is current.
``EXAMPLES`` holds one valid instance of every model; the codec tests round-trip them.
"""

from __future__ import annotations

import json
import types
import typing
from pathlib import Path

from pydantic import BaseModel
from pydantic.fields import FieldInfo

from common import keys
from common import messages as m
from common.codec import CONTENT_TYPE

_T = 1795000000.25  # an example UNIX time

EXAMPLES: dict[type[m.Message], m.Message] = {
    m.MarkerFrame: m.MarkerFrame(measured_s=_T, frame=1042, markers=[
        m.Marker(label="robot", x_mm=3412.5, y_mm=1093.0, z_mm=212.4),
        m.Marker(id=7, x_mm=-120.0, y_mm=88.5, z_mm=40.0)], bodies=[
        m.RigidBody(name="robot", x_mm=3412.5, y_mm=1093.0, z_mm=212.4, qw=0.99993, qx=0.0,
                    qy=0.0, qz=-0.0121)]),
    m.RobotPosition: m.RobotPosition(measured_s=_T, x_mm=3412.5, y_mm=1093.0, z_mm=212.4,
                                     vx_mm_s=290.0, vy_mm_s=-3.5, vz_mm_s=0.4, body="robot",
                                     qw=0.99993, qx=0.0, qy=0.0, qz=-0.0121),
    m.MarkerDetections: m.MarkerDetections(
        measured_s=_T, camera="ptz1", status="ok", threshold=230, width_px=704, height_px=576,
        markers=[m.DetectedMarker(u_px=351.6, v_px=290.2, radius_long_px=3.1,
                                  radius_short_px=2.9, angle_deg=12.0, roundness=1.07,
                                  area_px=29)]),
    m.PtzState: m.PtzState(measured_s=_T, camera="ptz1", status="tracking", pan_deg=-35.2,
                           tilt_deg=-21.7, zoom=1, focal_px=743.1, aim_error_deg=0.4),
    m.CameraPose: m.CameraPose(measured_s=_T, camera="ptz1", x_mm=3413.0, y_mm=1093.0,
                               z_mm=2163.0, rx_deg=197.0, ry_deg=27.0, rz_deg=159.0,
                               focal_px=743.1, mean_error_px=6.79, passpoints=100),
    m.CalibrationMode: m.CalibrationMode(measured_s=_T, camera="ptz1", active=True, pan_deg=0.0,
                                         tilt_deg=0.0, zoom=1, lease_s=3.0),
    m.CollectRequest: m.CollectRequest(measured_s=_T, camera="ptz1", action="start", count=100),
    m.PtzHand: m.PtzHand(measured_s=_T, camera="ptz2", action="nudge", pan_deg=-5.0,
                         tilt_deg=0.0, zoom=0, operator="olga (web 10.0.0.5)"),
    m.CollectProgress: m.CollectProgress(
        measured_s=_T, camera="ptz1", state="collecting", passpoints=42, target=100,
        snapshots=97, skipped={"no marker": 30, "too many": 5, "not moved": 20}),
    m.CameraFrame: m.CameraFrame(measured_s=_T, camera="tracking", seq=88, width_px=4,
                                 height_px=2, encoding="mono8", data=bytes(8)),
    m.PtzPreview: m.PtzPreview(measured_s=_T, camera="ptz1", seq=12, width_px=704,
                               height_px=576, jpeg=bytes(4), pan_deg=-35.2,
                               tilt_deg=-21.7, markers=[], robot_px=[351.6, 290.2]),
    m.RobotEstimate: m.RobotEstimate(measured_s=_T, algorithm="default", valid=True,
                                     x_mm=3410.0, y_mm=1090.0, z_mm=210.0, vx_mm_s=288.0,
                                     vy_mm_s=-2.0),
    m.CraneSetpoint: m.CraneSetpoint(measured_s=_T, seq=17, x_mm=3480.0, y_mm=1088.0,
                                     hold=False),
    m.CraneState: m.CraneState(measured_s=_T, status="tracking", x_mm=3400.0, y_mm=1080.0,
                               target_x_mm=3480.0, target_y_mm=1088.0, enabled=True,
                               moving=True, fault_bits=0, safety_ok=True, mode="armed",
                               mode_by="operator", mode_reason="run 12 starts",
                               mode_since_s=_T - 30),
    m.GantryCommand: m.GantryCommand(measured_s=_T, command="arm", operator="operator",
                                     reason="run 12 starts", id="cli-4242-1"),
    m.GantryCommandReply: m.GantryCommandReply(measured_s=_T, id="cli-4242-1", command="arm",
                                               accepted=True, detail="run 12 starts",
                                               mode="armed"),
    m.GravityOffload: m.GravityOffload(measured_s=_T, horizontal_error_mm=100.0,
                                       cable_length_mm=2000.0, vertical_loss_pct=0.125,
                                       horizontal_share_pct=5.0, warning=False,
                                       warn_above_pct=5.0),
    m.RobotTruth: m.RobotTruth(measured_s=_T, robot="locomotive", x_mm=3412.0, y_mm=1093.0,
                               z_mm=212.0, vx_mm_s=290.0, vy_mm_s=0.0),
    m.CraneTruth: m.CraneTruth(measured_s=_T, x_mm=3400.0, y_mm=1080.0, vx_mm_s=120.0,
                               vy_mm_s=0.0),
    m.PtzTruth: m.PtzTruth(measured_s=_T, camera="ptz1", pan_deg=-35.0, tilt_deg=-21.5, zoom=1),
    m.ServiceHealth: m.ServiceHealth(
        measured_s=_T, service="gantry", instance="main", host="gantry-pc", pid=4242,
        started_s=_T - 60, status="ok",
        keys={"stb/gantry/camera/frame": m.KeyStats(received=1500, published=0,
                                                    dropped={"stale": 2})}),
}

M = typing.TypeVar("M", bound=m.Message)


def example(model: type[M]) -> M:
    """The wire format's example of ``model`` (``EXAMPLES``), typed as that model."""
    found = EXAMPLES[model]
    if not isinstance(found, model):
        raise TypeError(f"EXAMPLES[{model.__name__}] is a {type(found).__name__}")
    return found


EXAMPLE_SUBSCRIBER = '''\
"""Print every STB message as a dict: needs only `pip install eclipse-zenoh==1.10.2 msgpack`."""
import os
import sys
import time

import msgpack
import zenoh

router = os.environ.get("STB_ROUTER", "tcp/127.0.0.1:7447")
key_expr = sys.argv[1] if len(sys.argv) > 1 else "stb/**"

config = zenoh.Config()
config.insert_json5("mode", '"client"')
config.insert_json5("connect/endpoints", f'["{router}"]')
config.insert_json5("scouting/multicast/enabled", "false")


def on_sample(sample):
    try:
        msg = msgpack.unpackb(sample.payload.to_bytes())
    except ValueError:
        return  # not msgpack: not one of ours
    age = time.time() - msg.get("sent_s", 0.0)
    print(sample.key_expr, f"age={age:.3f}s", msg, flush=True)


with zenoh.open(config) as session:
    session.declare_subscriber(key_expr, on_sample)
    session.liveliness().declare_subscriber(
        "stb/alive/**", lambda s: print("alive" if s.kind == zenoh.SampleKind.PUT else "gone",
                                        s.key_expr, flush=True), history=True)
    try:
        time.sleep(float(os.environ.get("STB_SECONDS", "1e9")))
    except KeyboardInterrupt:
        pass
'''


def _type_name(annotation: object) -> str:
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is typing.Annotated:
        return _type_name(args[0])
    if origin is typing.Literal:
        return " \\| ".join(f'"{a}"' for a in args)
    if origin in (list,):
        return f"list of {_type_name(args[0])}"
    if origin in (dict,):
        return f"map {_type_name(args[0])} → {_type_name(args[1])}"
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in args)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation.__name__
    names: dict[object, str] = {float: "float", int: "int", str: "str", bool: "bool",
                                bytes: "bin", type(None): "nil"}
    return names.get(annotation, str(annotation))


def _constraints(info: FieldInfo) -> str:
    parts = []
    for meta in info.metadata:
        for attr, sym in (("ge", "≥"), ("gt", ">"), ("le", "≤"), ("lt", "<"),
                          ("min_length", "min length"), ("max_length", "max length"),
                          ("pattern", "pattern")):
            value = getattr(meta, attr, None)
            if value is not None:
                parts.append(f"{sym} {value}")
    return ", ".join(parts)


def _summary(model: type[BaseModel]) -> str:
    """The docstring's first paragraph, on one line."""
    return " ".join((model.__doc__ or "").strip().split("\n\n")[0].split())


def _model_table(model: type[BaseModel]) -> list[str]:
    lines = ["| field | type | limits | meaning |", "|---|---|---|---|"]
    for name, info in model.model_fields.items():
        meaning = (info.description or "").replace("|", "\\|")
        if not info.is_required():
            default = info.get_default(call_default_factory=True, validated_data={})
            meaning = f"{meaning} (default {default!r})".strip()
        lines.append(f"| `{name}` | {_type_name(info.annotation)} | {_constraints(info)} "
                     f"| {meaning} |")
    return lines


def _nested_models() -> list[type[BaseModel]]:
    return [m.Marker, m.RigidBody, m.DetectedMarker, m.KeyStats]


def render() -> str:
    out = [
        "# Wire format",
        "",
        "<!-- generated by `python -m common.wiredoc > docs/wire-format.md`; do not edit -->",
        "",
        "Everything STB services publish travels over Zenoh as **msgpack maps of plain values**",
        "(str, int, float, bool, bin, lists, maps), one map per sample, with the Zenoh encoding",
        f"`{CONTENT_TYPE};<Model>`. Any language with a msgpack library can read it.",
        "",
        "Rules every message follows:",
        "",
        "- Keys start with a prefix, `stb` by default (lab setting `[bus] prefix`).",
        "- Units are in the field names: `_mm` millimetres, `_deg` degrees, `_px` pixels,",
        "  `_s` seconds, `_mm_s` mm/s. World frame: x, y horizontal, z up (the mocap's frame).",
        "- `measured_s`: when the value was measured (UNIX seconds, wall clock);",
        "  `sent_s`: when it was published. Hosts must keep their clocks in sync (chrony/PTP):",
        "  receivers drop stream samples whose `sent_s` is older than `bus.max_age_s`",
        "  (0.5 s by default) or further than `bus.max_future_s` in the future.",
        "- No NaN or infinity ever: data that is missing is left out (a lost marker is absent).",
        "- Receivers are strict: a map with a missing, extra or mistyped field is dropped and",
        "  counted in the receiver's health (`stb/health/...`), as is anything larger than the",
        "  key's size limit or not msgpack at all.",
        "- Streams are sent with congestion control *drop*: a slow subscriber loses samples, it",
        "  never slows the producer. Take the newest sample, not every sample.",
        "",
        "## Keys",
        "",
        "| key expression | message | size limit | what |",
        "|---|---|---|---|",
    ]
    for t in keys.ALL_TOPICS:
        out.append(f"| `stb/{t.path}` | [{t.model.__name__}](#{t.model.__name__.lower()}) | "
                   f"{t.max_payload_bytes // 1024} KiB | {t.description} |")
    out += [
        f"| `stb/{keys.ALIVE}` | liveliness token, no payload | — | present while the service "
        "runs and reaches the router |",
        "",
        "`{camera}`, `{robot}`, `{service}` and `{instance}` are names of letters, digits, `_`,",
        "`.` and `-`. Subscribe with `*` in their place (`stb/ptz/*/state`) or `stb/**` for",
        "everything. `stb/calib/{camera}/pose` is also a queryable: `get` it to receive the",
        "current pose of every calibrated camera, e.g. after a restart.",
        "",
        "## Messages",
        "",
    ]
    for model, example in EXAMPLES.items():
        out += [f"### {model.__name__}", "", _summary(model), ""] + _model_table(model) + [
            "", "Example (as JSON; on the wire it is msgpack):", "", "```json",
            json.dumps(example.model_dump(mode="json"), indent=None)[:600], "```", ""]
    out += ["## Nested maps", ""]
    for nested in _nested_models():
        out += [f"### {nested.__name__}", "", _summary(nested), ""] + _model_table(nested) + [""]
    out += [
        "## A subscriber in plain Python",
        "",
        "Needs nothing from this project: `pip install eclipse-zenoh==1.10.2 msgpack` (the",
        "Zenoh version must match the lab's). It prints every message and every service",
        "that appears or goes away. With a secured lab router add the user and password:",
        "`config.insert_json5(\"transport/auth/usrpwd\", '{\"user\": \"monitor\", "
        "\"password\": \"...\"}')`.",
        "",
        "```python",
        EXAMPLE_SUBSCRIBER.rstrip(),
        "```",
        "",
        "Run it as `STB_ROUTER=tcp/<router-host>:7447 python subscriber.py 'stb/gantry/**'`.",
        "",
    ]
    return "\n".join(out)


def main() -> None:
    print(render(), end="")


DOC_PATH = Path(__file__).resolve().parent.parent / "docs" / "wire-format.md"

if __name__ == "__main__":
    main()
