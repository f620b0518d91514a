"""Every ``stb`` command answers ``--help`` from its flags alone: nothing heavy (Zenoh,
pydantic, numpy, OpenCV, matplotlib) is imported before the flags are parsed. (How fast that
is: ``python -m benchmarks.cli``.)"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.conftest import ROOT

COMMANDS = [[], ["router"], ["tracker"], ["ptz"], ["ptz", "aim"], ["calib"],
            ["calib", "solve"], ["calib", "collect"], ["gantry"], ["gantry", "arm"],
            ["gantry", "identify"], ["web"], ["camera"], ["observation"], ["sim"],
            ["sim", "estop"], ["up"],
            ["monitor"], ["record"], ["replay"], ["report"], ["config", "check"],
            ["experiment"], ["experiment", "gantry"], ["experiment", "identify"], ["deploy"],
            ["detect"]]
HEAVY = ("zenoh", "pydantic", "numpy", "cv2", "matplotlib", "scipy", "qtm_rt", "pymodbus",
         "httpx", "mcap", "numba")

PROBE = """
import json, sys
from services.cli import main
try:
    code = main(sys.argv[1:] + ["--help"])
except SystemExit as done:
    code = done.code
print(json.dumps({"code": code, "heavy": sorted(m for m in sys.modules
                                                if m.split(".")[0] in HEAVY)}))
"""


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: " ".join(c) or "stb")
def test_help_is_answered_before_anything_heavy_is_imported(command: list[str]) -> None:
    done = subprocess.run([sys.executable, "-c", f"HEAVY = {HEAVY!r}\n{PROBE}", *command],
                          capture_output=True, text=True, timeout=60, cwd=ROOT, check=False)
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["code"] in (0, None), done.stderr
    assert "usage: stb" in done.stdout
    described = done.stdout.split("\n\n", 1)[1] if "\n\n" in done.stdout else ""
    assert described.strip() and not described.lstrip().startswith(("options:", "positional")), \
        "a description after the usage"
    assert "``" not in done.stdout, "plain text, not RST"
    assert result["heavy"] == [], f"imported before the flags were parsed: {result['heavy']}"
