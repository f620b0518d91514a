"""The simulated lab the campaign runs against (``stb up`` with every service), and what /proc
says about its processes."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import zenoh

from common.bus import open_session
from common.settings import ZenohSettings
from tests.uplab import SERVICES, write_up_lab

ROOT = Path(__file__).resolve().parents[2]
ALIVE = {"sim": "sim/main", "tracker": "tracker/main", "calib": "calib/main",
         "ptz:ptz1": "ptz/ptz1", "ptz:ptz2": "ptz/ptz2", "gantry": "gantry/main",
         "web": "web/main"}


@contextmanager
def running_lab(folder: Path, mocap: dict[str, float] | None = None, *,
                services: list[str] = SERVICES, poses: bool = True,
                env: dict[str, str] | None = None
                ) -> Iterator[tuple[subprocess.Popen, Path, str]]:
    """``stb up`` with ``services`` (every one by default); ``mocap``: settings of the sim's
    QTM to change; ``poses``: the cameras' poses stored (False: a fresh checkout's lab, none);
    ``env``: settings to set in ``stb up``'s environment (``STB_SECTION__FIELD``)."""
    lab, endpoint, _ = write_up_lab(folder, services, pose_version=1, users=True)
    if not poses:
        shutil.rmtree(folder / "calib")
    if mocap:
        settings = "".join(f"{name} = {value}\n" for name, value in mocap.items())
        lab.write_text(lab.read_text().replace("[sim.mocap]\n", "[sim.mocap]\n" + settings, 1))
    with open(folder / "up.log", "w") as log:
        up = subprocess.Popen([sys.executable, "-m", "services.cli", "up", "--lab", str(lab),
                               "--no-view"], cwd=ROOT, stdout=log, stderr=subprocess.STDOUT,
                              env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})})
    try:
        yield up, lab, endpoint
    finally:
        interrupt(up, 30)


def interrupt(proc: subprocess.Popen, timeout_s: float) -> None:
    """Ctrl-C, as a user would; killed if it has not ended within ``timeout_s``."""
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(p) for p in text.split()]


def cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def _status(pid: int, field: str) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(f"{field}:"):
                return float(line.split()[1])
    except OSError:
        pass
    return float("nan")


def resident_mb(pid: int) -> float:
    """A process's resident memory (VmRSS), shared memory included."""
    return _status(pid, "VmRSS") / 1024


def private_mb(pid: int) -> float:
    """A process's own resident memory (RssAnon): what it allocated. Not the shared memory it
    maps: Zenoh hands messages over 3 kB between processes on one host through each sender's
    16 MiB shared-memory pool, which every receiver maps once it gets such a message from that
    sender (it counts in each one's VmRSS, in 17 MiB steps, but exists once)."""
    return _status(pid, "RssAnon") / 1024


def shared_mb(pid: int) -> float:
    return _status(pid, "RssShmem") / 1024


def threads(pid: int) -> float:
    return _status(pid, "Threads")


def wait_until(predicate: Callable[[], object], timeout: float, period: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(period)
    return bool(predicate())


def ports_of(lab: Path) -> dict:
    import tomllib

    doc = tomllib.loads(lab.read_text())
    return {"crane": doc["sim"]["crane"]["port"], "web": doc["web"]["port"]}


def open_when_up(settings: ZenohSettings) -> zenoh.Session:
    deadline = time.monotonic() + 30
    while True:
        try:
            return open_session(settings)
        except Exception:  # noqa: BLE001 - the router is still starting
            if time.monotonic() > deadline:
                raise
            time.sleep(0.3)
