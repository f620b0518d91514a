"""A simulated lab's first start (``stb up``): the crater's height map made as a real lab makes
it — the sim's laser scan (``stb sim scan``) imported (``stb crater import``) to
``[gantry] height_map`` — so that the gantry and the page never read the sim's own crater
(its truth). Skipped when the lab runs no sim, when the map is there already, or when the lab
file points the gantry at the sim's own crater file on purpose."""

from __future__ import annotations

import logging
import subprocess
import sys
import tempfile
import time
from pathlib import Path

log = logging.getLogger(__name__)

STEP_TIMEOUT_S = 600.0  # each command; the scan and the import take 5-15 s on a lab PC


class FirstStartError(RuntimeError):
    """A first-start step failed; the message names the command and what it said."""


def height_map_to_import(services: list[str], height_map: Path, sim_crater: Path) -> bool:
    """Whether ``stb up`` must make the height map from the sim's scan before starting."""
    runs_sim = any(spec.split(":", 1)[0] == "sim" for spec in services)
    return runs_sim and not height_map.exists() and \
        height_map.resolve() != sim_crater.resolve()


def import_sim_scan(lab: Path | None, height_map: Path) -> None:
    """``stb sim scan`` into a temporary folder (the scan is ~170 MB), then ``stb crater
    import`` of it to ``height_map``; each step logged with its duration."""
    given = ["--lab", str(lab)] if lab is not None else []
    height_map.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="stb-scan-") as folder:
        scan = Path(folder) / "scan.ply"
        _step("the sim's laser scan", ["sim", "scan", "--out", str(scan), *given])
        _step(f"the scan imported to {height_map}",
              ["crater", "import", str(scan), "--out", str(height_map), *given])


def _step(what: str, args: list[str]) -> None:
    log.info("first start: %s (stb %s) ...", what, " ".join(args[:2]))
    started = time.monotonic()
    try:
        done = subprocess.run([sys.executable, "-m", "services.cli", *args],
                              capture_output=True, text=True, timeout=STEP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise FirstStartError(f"stb {' '.join(args[:2])} took more than "
                              f"{STEP_TIMEOUT_S:.0f} s") from None
    if done.returncode != 0:
        said = (done.stderr.strip() or done.stdout.strip()).splitlines()[-5:]
        raise FirstStartError(f"stb {' '.join(args)} exited {done.returncode}: "
                              + " / ".join(said))
    log.info("first start: %s done in %.1f s", what, time.monotonic() - started)
