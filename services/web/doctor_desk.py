"""The page's lab check: ``stb doctor --json`` run on this host with the page's bus and lab
file, one at a time, started by an operator; the latest table kept for everyone signed in.

    POST /doctor/run      an operator starts a check (409 while one runs)
    GET  /doctor.json     {"running", "by", "started_s", "finished_s", "exit", "rows", "error"}
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)
TIMEOUT_S = 180.0  # every device's timeout and the bus's listening window, with room


class DoctorBusy(RuntimeError):
    """A check runs already."""


class DoctorDesk:
    def __init__(self, environment: dict[str, str], lab: Path | None) -> None:
        self.environment, self.lab = environment, lab
        self._lock = threading.Lock()
        self._view: dict[str, Any] = {"running": False, "rows": []}

    def start(self, by: str) -> dict[str, Any]:
        with self._lock:
            if self._view["running"]:
                raise DoctorBusy(f"a check runs already (started by {self._view['by']})")
            self._view = {"running": True, "by": by, "started_s": time.time(), "rows": []}
        threading.Thread(target=self._run, name="doctor", daemon=True).start()
        log.info("lab check started by %s", by)
        return {"running": True}

    def view(self) -> dict[str, Any]:
        with self._lock:
            return dict(self._view)

    def _run(self) -> None:
        command = [sys.executable, "-m", "services.cli", "doctor", "--json"]
        if self.lab is not None:
            command += ["--lab", str(self.lab)]
        outcome: dict[str, Any] = {}
        try:
            done = subprocess.run(command, capture_output=True, text=True, timeout=TIMEOUT_S,
                                  env={**os.environ, **self.environment})
            if done.returncode in (0, 1):
                outcome = {"exit": done.returncode, "rows": json.loads(done.stdout)}
            else:
                outcome = {"exit": done.returncode,
                           "error": (done.stderr.strip().splitlines() or ["no answer"])[-1]}
        except subprocess.TimeoutExpired:
            outcome = {"error": f"stb doctor took more than {TIMEOUT_S:.0f} s"}
        except (OSError, ValueError) as err:
            outcome = {"error": f"stb doctor: {err}"}
        with self._lock:
            self._view = {**self._view, **outcome, "running": False,
                          "finished_s": time.time()}
        log.info("lab check: %s", outcome.get("error") or
                 ("all passed" if outcome.get("exit") == 0 else "failures"))
