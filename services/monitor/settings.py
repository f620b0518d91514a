"""Monitor settings: how it joins the bus and how often it redraws."""

from __future__ import annotations

from pydantic import Field

from common.settings import LogLevel, ServiceSettings


class MonitorSettings(ServiceSettings):
    section = "monitor"

    log_level: LogLevel = "WARNING"
    refresh_s: float = Field(1.0, gt=0)
