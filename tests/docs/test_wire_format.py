"""docs/wire-format.md is current, and its example subscriber works with zenoh + msgpack only."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import cast

from common import keys
from common import messages as m
from common.bus import Bus
from common.wiredoc import DOC_PATH, EXAMPLES, render
from tests.conftest import wait_for


def test_committed_page_is_generated_from_the_code() -> None:
    assert DOC_PATH.read_text() == render(), (
        "docs/wire-format.md is out of date: python -m common.wiredoc > docs/wire-format.md")


def test_page_names_every_key_and_every_field() -> None:
    text = DOC_PATH.read_text()
    for topic in keys.ALL_TOPICS:
        assert f"`stb/{topic.path}`" in text
        for field in topic.model.model_fields:
            assert f"`{field}`" in text


def test_example_subscriber_from_the_page_receives_messages(
        tmp_path: Path, router_endpoint: str, make_bus: Callable[..., Bus]) -> None:
    found = re.search(r"```python\n(.*?)```", DOC_PATH.read_text(), re.S)
    assert found, "the page has its example subscriber"
    code = found.group(1)
    imported = set(re.findall(r"^import (\w+)", code, re.M))
    assert imported == {"os", "sys", "time", "msgpack", "zenoh"}, "no project imports allowed"
    script = tmp_path / "subscriber.py"
    script.write_text(code)
    env = {**os.environ, "STB_ROUTER": router_endpoint, "STB_SECONDS": "30",
           "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-I", str(script), "stb/**"], cwd=tmp_path,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    producer = make_bus()
    alive_bus = make_bus()
    alive_bus.declare_alive("gantry", "main")
    stdout = proc.stdout
    assert stdout is not None
    try:
        os.set_blocking(stdout.fileno(), False)
        lines: list[str] = []

        def publish_and_read() -> bool:
            example = cast(m.CraneSetpoint, EXAMPLES[m.CraneSetpoint])
            producer.publish(keys.GANTRY_SETPOINT, example.model_copy(
                update={"measured_s": time.time()}))
            lines.extend(iter(stdout.readline, ""))
            return any("stb/gantry/setpoint" in line for line in lines) and any(
                line.startswith("alive stb/alive/gantry/main") for line in lines)

        wait_for(publish_and_read, timeout=15, period=0.2)
        setpoint = next(line for line in lines if line.startswith("stb/gantry/setpoint"))
        assert "'x_mm': 3480.0" in setpoint and "'hold': False" in setpoint
    finally:
        proc.terminate()
        proc.wait(5)
