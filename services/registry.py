"""The services the ``stb`` command knows, and which of them ``stb up`` runs by default.

A service is a package ``services.<name>`` whose ``__main__`` has ``main(argv)`` and whose
``settings`` module holds its settings class. It is listed here once it exists; ``stb up`` runs
``DEFAULT_UP`` unless the lab file's ``[up] services`` says otherwise.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the registry is read by ``stb --help``: nothing heavy at import
    from common.settings import ServiceSettings


@dataclass(frozen=True)
class ServiceInfo:
    description: str
    settings: str  # "module:Class"
    main: str = ""  # tools: the module whose main(argv) runs them


SERVICES: dict[str, ServiceInfo] = {
    "router": ServiceInfo("embedded Zenoh router (lab: eclipse/zenoh or this)",
                          "services.router.settings:RouterSettings"),
    "tracker": ServiceInfo("Qualisys QTM in; every frame's markers and the robot's position out",
                           "services.tracker.settings:TrackerSettings"),
    "ptz": ServiceInfo("one AXIS camera follows the robot (--instance ptz1|ptz2); "
                       "stb ptz aim: eq. 4", "common.ptz_settings:PtzSettings"),
    "calib": ServiceInfo("camera poses from passpoints (paper §2.2); stb calib solve | collect",
                         "services.calib.settings:CalibSettings"),
    "gantry": ServiceInfo("the crane follows the robot from its tracking camera (paper §3)",
                          "services.gantry.settings:GantrySettings"),
    "web": ServiceInfo("the operator's live page: crater, robot, crane, cameras, health "
                       "(http://127.0.0.1:8080)", "services.web.settings:WebSettings"),
    "camera": ServiceInfo("the tracking camera's frames on the bus, from a camera on this host",
                          "services.camera.settings:CameraSettings"),
    "observation": ServiceInfo("the crane's observation camera (bird's-eye video) on the bus, "
                               "from an IP camera's MJPEG stream",
                               "services.observation.settings:ObservationSettings"),
    "sim": ServiceInfo("the simulated lab: QTM RT mocap, VAPIX cameras, Modbus crane, frames",
                       "services.sim.settings:SimSettings"),
}

TOOLS: dict[str, ServiceInfo] = {
    "up": ServiceInfo("run the router and every service as supervised processes",
                      "services.supervisor:UpSettings", "services.up_cli"),
    "monitor": ServiceInfo("live table of alive services and every key's latest value; --raw",
                           "services.monitor.settings:MonitorSettings",
                           "services.monitor.__main__"),
    "record": ServiceInfo("record the bus to MCAP (+ Foxglove's typed channels): "
                          "stb record OUT.mcap [KEYEXPR...]",
                          "services.recording.record:RecordSettings",
                          "services.recording.record_cli"),
    "foxglove": ServiceInfo("the bus live in Foxglove (3D scene, previews, plots): "
                            "stb foxglove, then ws://127.0.0.1:8765",
                            "services.recording.live:FoxgloveSettings",
                            "services.recording.foxglove_cli"),
    "replay": ServiceInfo("put a recording back on the bus with its timing: "
                          "stb replay IN.mcap [--speed X]",
                          "services.recording.replay:ReplaySettings",
                          "services.recording.replay_cli"),
    "report": ServiceInfo("plots and a one-page HTML summary of a recording: "
                          "stb report IN.mcap --out DIR", "", "services.report.cli"),
    "config": ServiceInfo("check a lab config file: stb config check --lab FILE", ""),
    "experiment": ServiceInfo("the paper's gantry experiments on a simulated clock: "
                              "stb experiment gantry --scenario walker | identify", "",
                              "services.experiment.cli"),
    "deploy": ServiceInfo("the router's access control and the compose services from the lab "
                          "file: stb deploy render --lab FILE [--check]", "",
                          "services.deploy.cli"),
    "crater": ServiceInfo("the crater's height map from a laser scan: stb crater import SCAN "
                          "--out crater.npz", "", "services.crater.cli"),
    "doctor": ServiceInfo("everything a first run needs, checked against the lab file: "
                          "stb doctor [--json]", "services.doctor.settings:DoctorSettings",
                          "services.doctor.cli"),
    "detect": ServiceInfo("find markers in image files (paper §2.1): stb detect IMAGE --json",
                          "", "services.detect_cli"),
}

DEFAULT_UP: tuple[str, ...] = ("router", "sim", "tracker", "calib", "ptz:ptz1", "ptz:ptz2",
                               "gantry", "observation", "web")
"""What ``stb up`` starts when the lab file does not say: everything that exists so far."""


def settings_class(info: ServiceInfo) -> type[ServiceSettings]:
    module, _, name = info.settings.partition(":")
    return getattr(importlib.import_module(module), name)
