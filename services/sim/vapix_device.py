"""Who the simulated camera is, as VAPIX tells it (pure): ``param.cgi``, ``basicdeviceinfo.cgi``,
``apidiscovery.cgi``, ``pwdgrp.cgi``, ``usergroup.cgi``.

The parameter groups (Brand, Properties, PTZ, ImageSource, IOPort, StreamProfile) follow the
layout real AXIS cameras list; the values are this camera's: its limits, presets, IR cut filter
and the configured user. The product is the paper's AXIS 215 PTZ; its I/O ports (one input,
one output) are listed, not wired; the firmware version says it is simulated. The serial
number is derived from the camera's name, so it is the same at every start.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field

from services.sim.ptz import PtzHead
from services.sim.vapix import JSON, RESOLUTIONS, TEXT, Reply, error, text
from services.sim.vapix_ptz import CameraMemory

BRAND = {"Brand": "AXIS", "ProdFullName": "AXIS 215 PTZ Network Camera", "ProdNbr": "215 PTZ",
         "ProdShortName": "AXIS 215 PTZ", "ProdType": "PTZ Network Camera", "ProdVariant": "",
         "WebURL": "http://www.axis.com"}
FIRMWARE = {"Version": "0.1.0-sim", "BuildDate": "Dec 01 2026 00:00", "BuildNumber": "1"}
API_LIST = [{"id": "api-discovery", "version": "1.0", "name": "API Discovery Service",
             "docLink": "https://www.axis.com/vapix-library/", "status": "official"},
            {"id": "basic-device-info", "version": "1.1", "name": "Basic Device Information",
             "docLink": "https://www.axis.com/vapix-library/", "status": "official"},
            {"id": "param-cgi", "version": "1.0", "name": "Legacy Parameter Handling",
             "docLink": "https://www.axis.com/vapix-library/", "status": "official"}]
JSON_ERRORS = {2004: "Method not supported", 4000: "Invalid JSON",
               2003: "Requested API version is not supported"}


def serial_of(name: str) -> str:
    return "ACCC8E" + hashlib.sha256(name.encode()).hexdigest()[:6].upper()


@dataclass
class Device:
    """One simulated camera as its VAPIX identity sees it."""

    name: str
    head: PtzHead
    memory: CameraMemory
    user: str
    resolutions: Mapping[str, tuple[int, int]] = field(default_factory=lambda: RESOLUTIONS)
    """the picture sizes it offers, its full picture first"""

    @property
    def serial(self) -> str:
        return serial_of(self.name)

    def parameters(self, now: float) -> list[tuple[str, str]]:
        """Every parameter as ``("root.Group.Key", value)``, in the cameras' order."""
        return [*self._brand(), *self._image_source(), *_io_ports(), *self._properties(),
                *self._ptz(now), *_stream_profiles(list(self.resolutions))]

    def _brand(self) -> list[tuple[str, str]]:
        return [(f"root.Brand.{k}", v) for k, v in BRAND.items()]

    def _image_source(self) -> list[tuple[str, str]]:
        return [("root.ImageSource.I0.Name", self.name),
                ("root.ImageSource.I0.DayNight.IrCutFilter", self.head.ir_cut_filter)]

    def _properties(self) -> list[tuple[str, str]]:
        p = "root.Properties"
        return [(f"{p}.API.HTTP.AdminPath", "/"), (f"{p}.API.HTTP.Version", "3"),
                (f"{p}.API.Metadata.Metadata", "no"), (f"{p}.API.Metadata.Version", "1.0"),
                (f"{p}.API.PTZ.Presets.Version", "2.00"),
                (f"{p}.ApiDiscovery.ApiDiscovery", "yes"),
                *((f"{p}.Firmware.{k}", v) for k, v in FIRMWARE.items()),
                (f"{p}.Image.Format", "jpeg,mjpeg"), (f"{p}.Image.NbrOfViews", "1"),
                (f"{p}.Image.Resolution", ",".join(self.resolutions)),
                (f"{p}.Image.Rotation", "0,180"),
                (f"{p}.Image.ShowSuboptimalResolutions", "false"),
                (f"{p}.PTZ.PTZ", "yes"), (f"{p}.PTZ.DigitalPTZ", "no"),
                (f"{p}.PTZ.DriverManagement", "no"),
                (f"{p}.System.SerialNumber", self.serial)]

    def _ptz(self, now: float) -> list[tuple[str, str]]:
        p, lim, mem = "root.PTZ", self.head.limits, self.memory
        out = [(f"{p}.BoaProtPTZOperator", "password"), (f"{p}.CameraDefault", "1"),
               (f"{p}.NbrOfCameras", "1"), (f"{p}.NbrOfSerPorts", "1"),
               (f"{p}.CamPorts.Cam1Port", "1"), (f"{p}.ImageSource.I0.PTZEnabled", "true")]
        limits = {"MaxFieldAngle": "508", "MaxFocus": "9999", "MaxIris": "9999",
                  "MaxPan": f"{lim.max_pan:g}", "MaxTilt": f"{lim.max_tilt:g}",
                  "MaxZoom": f"{lim.max_zoom}", "MinFieldAngle": "44", "MinFocus": "1",
                  "MinIris": "1", "MinPan": f"{lim.min_pan:g}", "MinTilt": f"{lim.min_tilt:g}",
                  "MinZoom": f"{lim.min_zoom}"}
        out += [(f"{p}.Limit.L1.{k}", v) for k, v in limits.items()]
        out += [(f"{p}.Preset.P0.HomePosition", "1"), (f"{p}.Preset.P0.ImageSource", "0"),
                (f"{p}.Preset.P0.Name", "")]
        for no, preset in sorted(mem.presets.items()):
            data = (f"tilt={preset.tilt:.6f}:focus={mem.focus:.6f}:pan={preset.pan:.6f}:"
                    f"iris={mem.iris:.6f}:zoom={preset.zoom:.6f}")
            out += [(f"{p}.Preset.P0.Position.P{no}.Data", data),
                    (f"{p}.Preset.P0.Position.P{no}.Name", preset.name)]
        out += [(f"{p}.PTZDriverStatuses.Driver1Status", "3")]
        out += [(f"{p}.Support.S1.{k}", "true" if v else "false") for k, v in SUPPORT.items()]
        out += [(f"{p}.UserAdv.U1.MoveSpeed", "100")]
        out += [(f"{p}.UserCtlQueue.U0.{k}", v) for k, v in (
            ("Priority", "10"), ("TimeoutTime", "60"), ("TimeoutType", "activity"),
            ("UseCookie", "yes"), ("UserGroup", "Administrator"))]
        various = {"AutoFocus": _bool(mem.autofocus), "AutoIris": _bool(mem.autoiris),
                   "CtlQueueing": "false", "CtlQueueLimit": "20", "CtlQueuePollTime": "20",
                   "HomePresetSet": _bool(1 in mem.presets),
                   "IrCutFilter": self.head.ir_cut_filter, "IrCutFilterEnabled": "true",
                   "PanEnabled": "true", "ReturnToOverview": "0", "SpeedCtlEnabled": "true",
                   "TiltEnabled": "true", "ZoomEnabled": "true"}
        return out + [(f"{p}.Various.V1.{k}", v) for k, v in various.items()]

    # --- the CGIs -------------------------------------------------------------------------

    def param_cgi(self, args: Mapping[str, str], now: float) -> Reply:
        """``action=list`` (all, or ``group=root.A,root.B``); the parameters are read-only."""
        action = args.get("action", "")
        if action != "list":
            return error(f'action: "{action}" is not supported by the simulated camera '
                         "(its parameters are read-only)")
        params = self.parameters(now)
        groups = [g.strip() for g in args.get("group", "").split(",") if g.strip()]
        lines: list[str] = []
        for group in groups or ["root"]:
            prefix = group if group.startswith("root") else f"root.{group}"
            found = [f"{k}={v}" for k, v in params if k == prefix or k.startswith(prefix + ".")]
            lines += found or [f"# Error: Error -1 getting param in group '{group}'"]
        return Reply(200, TEXT, ("\n".join(lines) + "\n").encode())

    def basic_device_info(self, body: bytes) -> Reply:
        request, failed = _json_request(body)
        if failed is not None:
            return failed
        method = request.get("method")
        properties = {**BRAND, "Version": FIRMWARE["Version"], "BuildDate":
                      FIRMWARE["BuildDate"], "SerialNumber": self.serial,
                      "HardwareID": "215", "Architecture": "sim", "Soc": "simulated",
                      "SocSerialNumber": ""}
        if method == "getSupportedVersions":
            return _json_reply(request, {"apiVersions": ["1.1"]})
        if method == "getAllProperties":
            return _json_reply(request, {"propertyList": properties})
        if method == "getProperties":
            wanted = request.get("params", {}).get("propertyList", [])
            if not isinstance(wanted, list):
                return _json_error(request, 4000)
            return _json_reply(request, {"propertyList": {
                k: properties[k] for k in wanted if isinstance(k, str) and k in properties}})
        return _json_error(request, 2004)

    def users(self, args: Mapping[str, str]) -> Reply:
        """``pwdgrp.cgi?action=get``: the configured user is in every group."""
        if args.get("action") != "get":
            return error("the simulated camera's users are set in its configuration")
        user = self.user
        return text([f'admin="{user}"', 'anonymous=""', f'operator="{user}"',
                     f'ptz="{user}"', f'users="{user}"', f'viewer="{user}"',
                     f'digusers="{user}"'])

    def user_groups(self) -> Reply:
        """``usergroup.cgi``: the requesting user's name, then its groups."""
        primary = "root" if self.user == "root" else "users"
        return Reply(200, TEXT, f"{self.user}\n{primary} admin operator ptz viewer\n".encode())


SUPPORT = {"AbsoluteBrightness": False, "AbsoluteFocus": True, "AbsoluteIris": True,
           "AbsolutePan": True, "AbsoluteTilt": True, "AbsoluteZoom": True,
           "ActionNotification": False, "AreaZoom": False, "AutoFocus": True,
           "AutoIrCutFilter": True, "AutoIris": True, "Auxiliary": False, "BackLight": False,
           "ContinuousBrightness": False, "ContinuousFocus": False, "ContinuousIris": False,
           "ContinuousPan": True, "ContinuousTilt": True, "ContinuousZoom": True,
           "DevicePreset": False, "DigitalZoom": False, "GenericHTTP": False,
           "IrCutFilter": True, "JoyStickEmulation": False, "LensOffset": False,
           "OSDMenu": False, "ProportionalSpeed": False, "RelativeBrightness": False,
           "RelativeFocus": True, "RelativeIris": True, "RelativePan": True,
           "RelativeTilt": True, "RelativeZoom": True, "ServerPreset": True, "SpeedCtl": True}


def _bool(value: bool) -> str:
    return "true" if value else "false"


def _io_ports() -> list[tuple[str, str]]:
    return [("root.IOPort.I0.Configurable", "no"), ("root.IOPort.I0.Direction", "input"),
            ("root.IOPort.I0.Input.Name", "Input 1"), ("root.IOPort.I0.Input.Trig", "closed"),
            ("root.IOPort.I1.Configurable", "no"), ("root.IOPort.I1.Direction", "output"),
            ("root.IOPort.I1.Output.Name", "Output 1"),
            ("root.IOPort.I1.Output.Active", "closed")]


def _stream_profiles(sizes: list[str]) -> list[tuple[str, str]]:
    return [("root.StreamProfile.MaxGroups", "26"),
            ("root.StreamProfile.S0.Description", "MJPEG, full resolution"),
            ("root.StreamProfile.S0.Name", "Quality"),
            ("root.StreamProfile.S0.Parameters", f"resolution={sizes[0]}&compression=10"),
            ("root.StreamProfile.S1.Description", "MJPEG, quarter resolution"),
            ("root.StreamProfile.S1.Name", "Bandwidth"),
            ("root.StreamProfile.S1.Parameters", f"resolution={sizes[-1 if len(sizes) < 2 else 1]}"
             "&compression=40")]


def api_discovery(body: bytes) -> Reply:
    request, failed = _json_request(body)
    if failed is not None:
        return failed
    if request.get("method") == "getApiList":
        return _json_reply(request, {"apiList": API_LIST})
    if request.get("method") == "getSupportedVersions":
        return _json_reply(request, {"apiVersions": ["1.0"]})
    return _json_error(request, 2004)


def _json_request(body: bytes) -> tuple[dict, Reply | None]:
    try:
        request = json.loads(body or b"null")
    except ValueError:
        request = None
    if not isinstance(request, dict):
        return {}, _json_error({}, 4000)
    return request, None


def _json_reply(request: dict, data: dict) -> Reply:
    reply = {"apiVersion": str(request.get("apiVersion", "1.0")), "method": request["method"],
             "data": data}
    if "context" in request:
        reply["context"] = request["context"]
    return Reply(200, JSON, json.dumps(reply).encode())


def _json_error(request: dict, code: int) -> Reply:
    reply = {"apiVersion": str(request.get("apiVersion", "1.0")),
             "method": str(request.get("method", "")),
             "error": {"code": code, "message": JSON_ERRORS[code]}}
    if "context" in request:
        reply["context"] = request["context"]
    return Reply(200, JSON, json.dumps(reply).encode())
