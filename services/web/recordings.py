"""The page's recording desk: one ``stb record`` at a time, started and stopped by an operator,
its report (``stb report``) made when it ends, and the past recordings with their reports.

Each is a process of its own on this host (the same bus as the page, ``bus_environment``),
writing ``<recordings_dir>/<name>.mcap`` and then ``<name>.report/index.html``; the page
serves the reports' files.
"""

from __future__ import annotations

import contextlib
import logging
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)
NAME = re.compile(r"^[0-9]{8}-[0-9]{6}$")
REPORT_FILE = re.compile(r"^[A-Za-z0-9_.-]{1,100}$")
LISTED = 30  # past recordings listed on the page
STOP_WAIT_S = 20.0
FILE_LOOK_S = 0.1  # how often a starting recording's file is looked for
REPORT_TIMEOUT_S = 600.0


class DeskError(RuntimeError):
    """A recording cannot be started or stopped now; the message says why."""


@dataclass
class _Run:
    name: str
    by: str
    started_s: float
    process: subprocess.Popen
    log: Path
    recording_s: float | None = None
    """when its file appeared: ``stb record`` started up (its imports can take seconds on a
    busy host) and records; the page counts the recording's time from here"""


RECORDER = (sys.executable, "-m", "services.cli", "record")


class RecordingDesk:
    def __init__(self, folder: Path, environment: dict[str, str],
                 height_map: Path | None = None, recorder: Sequence[str] = RECORDER) -> None:
        """``recorder``: the command that records into the path given after it."""
        self.folder, self.environment, self.height_map = folder, environment, height_map
        self.recorder = list(recorder)
        self._lock = threading.Lock()
        self._run: _Run | None = None
        self._reporting: dict[str, str] = {}  # name → state while its report is made or failed

    def start(self, by: str, seconds: float | None = None) -> dict[str, Any]:
        with self._lock:
            if self._run is not None and self._run.process.poll() is None:
                raise DeskError(f"recording {self._run.name} runs already (started by "
                                f"{self._run.by})")
            self.folder.mkdir(parents=True, exist_ok=True)
            name = time.strftime("%Y%m%d-%H%M%S")
            out = self.folder / f"{name}.mcap"
            command = [*self.recorder, str(out)]
            if seconds:
                command += ["--duration", f"{seconds:g}"]
            log_path = self.folder / f"{name}.log"
            with open(log_path, "w") as log_file:
                process = subprocess.Popen(command, env=self._env(), stdout=log_file,
                                           stderr=subprocess.STDOUT)
            self._run = _Run(name, by, time.time(), process, log_path)
        log.info("recording %s started by %s", name, by)
        threading.Thread(target=self._report_when_done, args=(self._run,), daemon=True).start()
        return {"name": name, "recording": True}

    def stop(self, by: str) -> dict[str, Any]:
        with self._lock:
            run = self._run
        if run is None or run.process.poll() is not None:
            raise DeskError("no recording runs")
        run.process.send_signal(signal.SIGINT)
        try:
            run.process.wait(STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            run.process.kill()
            run.process.wait(5)
        log.info("recording %s stopped by %s", run.name, by)
        return {"name": run.name, "recording": False}

    def close(self) -> None:
        """The page stops: a recording under way ends with it (its file closed whole)."""
        with self._lock:
            run = self._run
        if run is not None and run.process.poll() is None:
            self.stop("the page stopping")

    def view(self) -> dict[str, Any]:
        """What the page shows: the recording under way (or none) and the past ones."""
        with self._lock:
            run = self._run
            reporting = dict(self._reporting)
        current = None
        if run is not None and run.process.poll() is None:
            since = run.recording_s
            current = {"name": run.name, "by": run.by, "starting": since is None,
                       "elapsed_s": 0.0 if since is None else time.time() - since,
                       "size_mb": _size_mb(self.folder / f"{run.name}.mcap")}
        past = []
        files = sorted(self.folder.glob("*.mcap"), reverse=True) if self.folder.is_dir() else []
        for path in files[:LISTED]:
            name = path.stem
            if current and name == current["name"]:
                continue
            report = self.folder / f"{name}.report" / "index.html"
            past.append({"name": name, "size_mb": _size_mb(path),
                         "report": f"recordings/{name}/index.html" if report.is_file() else None,
                         "state": reporting.get(name, "ready" if report.is_file() else "")})
        return {"current": current, "past": past}

    def report_file(self, name: str, file: str) -> Path | None:
        """A file of a recording's report, or None (no such recording or file, or a link
        that leads out of the report's folder: a symlink once served /etc/shadow)."""
        if not NAME.match(name) or not REPORT_FILE.match(file) or file.startswith("."):
            return None
        report = (self.folder / f"{name}.report").resolve()
        path = (report / file).resolve()
        if not path.is_relative_to(report) or not report.is_relative_to(self.folder.resolve()):
            log.warning("refused %s/%s: a link out of the recordings folder", name, file)
            return None
        return path if path.is_file() else None

    def _report_when_done(self, run: _Run) -> None:
        mcap = self.folder / f"{run.name}.mcap"
        while run.recording_s is None and run.process.poll() is None:
            if mcap.exists():
                run.recording_s = time.time()
            else:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    run.process.wait(FILE_LOOK_S)
        run.process.wait()
        if not mcap.is_file():
            return
        with self._lock:
            self._reporting[run.name] = "making its report"
        command = [sys.executable, "-m", "services.cli", "report", str(mcap), "--out",
                   str(self.folder / f"{run.name}.report")]
        if self.height_map is not None and self.height_map.is_file():
            command += ["--height-map", str(self.height_map)]
        try:
            done = subprocess.run(command, env=self._env(), capture_output=True, text=True,
                                  timeout=REPORT_TIMEOUT_S, check=False)
            state = "ready" if done.returncode == 0 else f"no report: {done.stderr[-300:]}"
        except subprocess.TimeoutExpired:
            state = f"no report: not made within {REPORT_TIMEOUT_S:g} s"
        with self._lock:
            if state == "ready":
                self._reporting.pop(run.name, None)
            else:
                self._reporting[run.name] = state
        (log.info if state == "ready" else log.warning)("recording %s: %s", run.name, state)

    def _env(self) -> dict[str, str]:
        import os

        return {**os.environ, **self.environment, "PYTHONUNBUFFERED": "1"}


def _size_mb(path: Path) -> float:
    try:
        return round(path.stat().st_size / 1e6, 1)
    except OSError:
        return 0.0
