"""The doctor's device checks, each over the device's own protocol with its third-party client:
the motion capture (QTM RT, qtm-rt), each PTZ camera and the observation camera (VAPIX over
HTTP, httpx), the crane controller (Modbus/TCP, pymodbus, through the lab's register map)."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Mapping

import httpx
import qtm_rt
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

from common.crane_frame import CraneConnection
from common.crane_registers import FAULTED, SAFETY_OK
from common.lab_views import CameraConnection
from common.qtm_params import labels_from_xml
from services.doctor.table import Check, failed, passed

KNOWN_STATUS_BITS = 0b11111  # ENABLED, MOVING, AT_TARGET, FAULTED, SAFETY_OK
KNOWN_FAULT_BITS = 0b111  # watchdog, clamped, safety
PLAUSIBLE_SLACK_MM = 2000.0  # the crane's travel reaches this far past the workspace at most
PLAUSIBLE_SPEED_MM_S = 5000.0  # no lab crane moves faster


def mocap(host: str, port: int, needed: Mapping[str, str], timeout_s: float) -> Check:
    """QTM answers on its RT port and has a 3D label for each of ``needed`` (label → what
    the lab needs it for)."""
    name = "motion capture"
    try:
        labels = asyncio.run(_qtm_labels(host, port, timeout_s))
    except (OSError, TimeoutError, qtm_rt.QRTCommandException) as err:
        return failed(name, f"QTM at {host}:{port} does not answer ({err or 'timeout'})",
                      "start QTM's real-time server, or set [tracker] qtm_host / qtm_port")
    missing = [f"{label!r} ({why})" for label, why in needed.items() if label not in labels]
    if missing:
        return failed(name, f"QTM at {host}:{port}: no 3D label {', '.join(missing)}; it has "
                      f"{', '.join(labels) or 'none'}",
                      "label the markers in QTM's AIM model as the lab file names them "
                      "([tracker] robot_label, [gantry] crane_marker, [calib] marker_label)")
    return passed(name, f"QTM at {host}:{port}: {len(labels)} labels, "
                        f"{', '.join(needed)} among them")


async def _qtm_labels(host: str, port: int, timeout_s: float) -> list[str]:
    connection = await qtm_rt.connect(host, port=port, version="1.25", timeout=timeout_s)
    if connection is None:
        raise TimeoutError(f"no connection within {timeout_s:g} s")
    try:
        xml = await asyncio.wait_for(connection.get_parameters(parameters=["3d"]), timeout_s)
    finally:
        if connection.has_transport():
            connection.disconnect()
    return labels_from_xml(xml)


def vapix_parameters(camera: CameraConnection, groups: list[str], timeout_s: float
                     ) -> dict[str, str]:
    """``param.cgi?action=list`` of ``groups``: name → value (raises httpx.HTTPError)."""
    with httpx.Client(base_url=camera.url, auth=camera.http_auth(), timeout=timeout_s) as client:
        reply = client.get("/axis-cgi/param.cgi",
                           params={"action": "list", "group": ",".join(groups)})
        reply.raise_for_status()
    pairs = (line.split("=", 1) for line in reply.text.splitlines()
             if "=" in line and not line.startswith("#"))
    return {key.strip(): value.strip() for key, value in pairs}


def ptz_camera(name: str, camera: CameraConnection, timeout_s: float) -> Check:
    """The camera answers VAPIX: who it is, its PTZ limits and its picture sizes."""
    row = f"PTZ camera {name}"
    try:
        found = vapix_parameters(camera, ["root.Brand", "root.PTZ.Limit",
                                          "root.Properties.Image.Resolution"], timeout_s)
    except httpx.HTTPStatusError as err:
        fix = ("check [ptz.cameras." + name + "] user and password" if
               err.response.status_code in (401, 403) else "check the camera's firmware: "
               "VAPIX param.cgi must answer")
        return failed(row, f"{camera.url}: HTTP {err.response.status_code}", fix)
    except httpx.HTTPError as err:
        return failed(row, f"{camera.url} does not answer ({type(err).__name__})",
                      f"power the camera, or set [ptz.cameras.{name}] url")
    product = found.get("root.Brand.ProdFullName", "")
    limits = {k.rsplit(".", 1)[1]: v for k, v in found.items() if ".Limit.L1." in k}
    sizes = found.get("root.Properties.Image.Resolution", "")
    lacking = [what for what, value in (("identity (Brand)", product),
                                        ("PTZ limits (PTZ.Limit)", limits),
                                        ("picture sizes (Properties.Image.Resolution)", sizes))
               if not value]
    if lacking:
        return failed(row, f"{camera.url} ({product or 'unknown'}) does not say its "
                      f"{', '.join(lacking)}", "a PTZ camera with VAPIX's PTZ driver enabled "
                      "(System Options → PTZ in the camera's own page)")
    pan = f"pan {limits.get('MinPan', '?')}…{limits.get('MaxPan', '?')}°"
    return passed(row, f"{product}; {pan}; {sizes.split(',')[0]} and {sizes.count(',')} "
                       "smaller")


def observation_camera(camera: CameraConnection, timeout_s: float) -> Check:
    """The observation camera delivers a picture (VAPIX ``jpg/image.cgi``)."""
    row = "observation camera"
    try:
        with httpx.Client(base_url=camera.url, auth=camera.http_auth(),
                          timeout=timeout_s) as client:
            reply = client.get("/axis-cgi/jpg/image.cgi")
            reply.raise_for_status()
    except httpx.HTTPError as err:
        return failed(row, f"{camera.url}: no picture ({type(err).__name__})",
                      "power the camera, or set [observation] url, user and password")
    if not reply.content.startswith(b"\xff\xd8"):
        return failed(row, f"{camera.url}: the answer is not a JPEG picture",
                      "point [observation] url at the camera's own address")
    return passed(row, f"{camera.url}: a {len(reply.content) // 1024} kB picture")


def crane(host: str, port: int, registers: CraneConnection, workspace: tuple[float, ...],
          timeout_s: float) -> Check:
    """The controller answers Modbus and its registers, read through the lab's map, make a
    plausible crane: a position near the workspace (world), a speed a crane can have, only
    the status and fault bits the map defines."""
    row = "crane controller"
    client = ModbusTcpClient(host, port=port, timeout=timeout_s, retries=0)
    try:
        if not client.connect():
            return failed(row, f"{host}:{port} does not answer Modbus/TCP",
                          "power the controller, or set [gantry] crane_host / crane_port")
        reply = client.read_input_registers(registers.input_start, count=registers.input_count,
                                            device_id=registers.unit_id)
    except ModbusException as err:
        return failed(row, f"{host}:{port}: {err}", "check [gantry.crane] unit_id and the "
                      "input registers' addresses against the PLC's documentation")
    finally:
        client.close()
    if reply.isError():
        return failed(row, f"{host}:{port} refused the read of input registers "
                      f"{registers.input_start}–{registers.input_start + registers.input_count - 1}"
                      f" (unit {registers.unit_id}): {reply}",
                      "check [gantry.crane] unit_id and the input registers' addresses")
    return _plausible(row, f"{host}:{port}", list(reply.registers), registers, workspace)


def _plausible(row: str, where: str, block: list[int], registers: CraneConnection,
               workspace: tuple[float, ...]) -> Check:
    start = registers.input_start
    raw = [registers.read(n, block, start) for n in ("actual_x", "actual_y")]
    speed = math.hypot(*(registers.read(n, block, start) for n in ("velocity_x", "velocity_y")))
    status = block[registers.status - start]
    faults = block[registers.faults - start]
    x, y = registers.to_world(raw)
    x_min, x_max, y_min, y_max = workspace
    wrong = []
    if not (x_min - PLAUSIBLE_SLACK_MM <= x <= x_max + PLAUSIBLE_SLACK_MM
            and y_min - PLAUSIBLE_SLACK_MM <= y <= y_max + PLAUSIBLE_SLACK_MM):
        wrong.append(f"position ({x:.0f}, {y:.0f}) mm in the world, more than "
                     f"{PLAUSIBLE_SLACK_MM / 1000:g} m outside the workspace")
    if speed > PLAUSIBLE_SPEED_MM_S:
        wrong.append(f"speed {speed:.0f} mm/s")
    if status & ~KNOWN_STATUS_BITS or faults & ~KNOWN_FAULT_BITS:
        wrong.append(f"status 0x{status:04x}, faults 0x{faults:04x} (bits the map does not "
                     "define)")
    if wrong:
        return failed(row, f"{where} reads {'; '.join(wrong)}",
                      "the register map does not fit the PLC: check [gantry.crane.registers] "
                      "(addresses, value_bits, word_order, signed, units_per_mm) and its frame "
                      "(stb gantry commission)")
    state = "faulted" if status & FAULTED else "safety open" if not status & SAFETY_OK \
        else "ready"
    return passed(row, f"{where}: at ({x:.0f}, {y:.0f}) mm, {speed:.0f} mm/s, {state}")
