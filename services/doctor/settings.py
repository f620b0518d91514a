"""``[doctor]``: how long ``stb doctor`` listens and waits, and what it calls enough."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field

from common.settings import ServiceSettings


class DoctorSettings(ServiceSettings):
    section = "doctor"

    listen_s: float = Field(3.0, gt=0, le=60, description="how long it listens on the bus "
                            "(frames, the services' health messages)")
    timeout_s: float = Field(3.0, gt=0, le=60, description="each device's answer")
    min_frame_hz: float = Field(5.0, gt=0, le=200, description="the tracking camera's frames "
                                "a second at least")
    clock_tolerance_s: float = Field(0.1, gt=0, le=10, description="a host's clock this far "
                                     "off this host's fails (the gantry pairs pictures and "
                                     "crane positions by their times)")
    min_free_gb: float = Field(2.0, ge=0, description="free space for recordings at least "
                               "(an hour of the demo lab's at its 30 MB a minute: 1.8 GB)")
    targets: list[str] = Field(default_factory=list, description="more motion-capture labels "
                               "the lab needs now, e.g. stb gantry commission's targets "
                               '["target_1", "target_2"]')
    router_config: Path | None = Field(None, description="the router's Zenoh configuration, "
                                       "for its access control; default: [router] config_file")
