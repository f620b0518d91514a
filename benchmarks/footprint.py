"""What the demo lab's processes hold in memory: each service's resident memory under
``stb up``, as a lab engineer starts it (``make demo`` without the live view).

    .venv/bin/python -m benchmarks.footprint [--lab config/demo.toml] [--settle 70]

Starts ``stb up --lab LAB --no-view``, waits until ``stb up`` has started every service
and they have run for ``--settle`` seconds (70: the lab is sampled from about 75 s after its
start, the 5 s in which no service was added included; the demo calibrates its cameras and
follows the robot meanwhile; it says how many services ``stb up`` had to restart and when
each camera's pose was stored), then samples each
process five times a second for ``--seconds`` and prints, per process, the peak of:

* VmRSS — what ``top`` shows: the process's resident memory, shared libraries and Zenoh's
  shared-memory pools included (every process that received a large message from another
  maps that sender's 16 MiB pool);
* RssAnon — what the process itself allocated (``benchmarks/faults/lab.py private_mb``);
* Pss — its proportional share (``/proc/PID/smaps_rollup``): its own pages, and each page it
  shares with other processes (a shared library, a Zenoh pool) divided by how many map it.

The lab's totals: the sum of the VmRSS (the router and ``stb up`` itself included, the sim's
device processes too), which counts a page that eleven processes share eleven times; and
the sum of the Pss, which counts it once: what the machine holds for the lab. Goals (issue
39): a PTZ service ≤ 150 MB, the gantry ≤ 200 MB (VmRSS), the demo lab ≤ 1.2 GB. Figures
with this command are in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.faults.lab import _status, children, cmdline

ROOT = Path(__file__).resolve().parent.parent
GOALS_MB = {"ptz": 150.0, "gantry": 200.0}
LAB_GOAL_MB = 1200.0


def processes(up_pid: int) -> dict[str, int]:
    """Every process of the lab by name: ``stb up``, its services (``ptz:ptz1``), and their
    children (the sim's device processes, ``sim/1``)."""
    found = {"stb up": up_pid}
    for pid in children(up_pid):
        words = cmdline(pid).split()
        module = next((w for w in words if w.startswith("services.")), "?")
        name = module.removeprefix("services.")
        if "--instance" in words and words[words.index("--instance") + 1] != "main":
            name += ":" + words[words.index("--instance") + 1]
        found[name] = pid
        for n, child in enumerate(children(pid), start=1):
            found[f"{name}/{n}"] = child
    return found


def pss_mb(pid: int) -> float:
    """A process's proportional set size (MB), NaN when it is gone."""
    try:
        for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
            if line.startswith("Pss:"):
                return float(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def sample(pids: dict[str, int], seconds: float) -> dict[str, dict[str, float]]:
    peak = {name: {"rss_mb": 0.0, "anon_mb": 0.0, "pss_mb": 0.0} for name in pids}
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        for name, pid in pids.items():
            now = {"rss_mb": _status(pid, "VmRSS") / 1024,
                   "anon_mb": _status(pid, "RssAnon") / 1024, "pss_mb": pss_mb(pid)}
            for field, value in now.items():
                if value == value:  # not NaN: the process is there
                    peak[name][field] = max(peak[name][field], value)
        time.sleep(0.2)
    return peak


def measure(lab: Path, settle_s: float, seconds: float) -> dict[str, dict[str, float]]:
    started = time.time()
    with tempfile.TemporaryDirectory() as folder, \
            open(Path(folder) / "up.log", "w") as log:
        up = subprocess.Popen([sys.executable, "-m", "services.cli", "up", "--lab", str(lab),
                               "--no-view"], cwd=ROOT, stdout=log, stderr=subprocess.STDOUT,
                              env={**os.environ, "PYTHONUNBUFFERED": "1"})
        try:
            count, since = 0, time.monotonic()  # the services are there when none is added
            while time.monotonic() - since < 5.0:
                if len(children(up.pid)) != count:
                    count, since = len(children(up.pid)), time.monotonic()
                time.sleep(0.2)
            print(f"{count} services running; settling {settle_s:.0f} s", file=sys.stderr)
            time.sleep(settle_s)
            peak = sample(processes(up.pid), seconds)
            restarts = (Path(folder) / "up.log").read_text().count(" exited with ")
            print(f"restarts while it ran: {restarts}", file=sys.stderr)
            solved = solved_since(started)
            print(f"cameras calibrated while it ran: {len(solved)}" + (
                " (" + ", ".join(f"{camera} {s:.0f} s" for camera, s in sorted(solved.items()))
                + " after stb up started)" if solved else " (their stored poses in run/calib/ "
                "were loaded; delete that folder to measure a lab that solves)"),
                file=sys.stderr)
            return peak
        finally:
            up.send_signal(signal.SIGINT)
            try:
                up.wait(30)
            except subprocess.TimeoutExpired:
                up.kill()
                up.wait()


def solved_since(started: float) -> dict[str, float]:
    """The cameras whose pose the calib service stored (solved) since ``started``, and when
    (seconds after it)."""
    stored = {path.parent.name: path.stat().st_mtime - started
              for path in (ROOT / "run" / "calib").glob("*/pose.json")}
    return {camera: s for camera, s in stored.items() if s >= 0}


def table(peak: dict[str, dict[str, float]]) -> str:
    rows = ["| process | VmRSS MB | RssAnon MB | Pss MB | goal |", "|---|---:|---:|---:|---|"]
    for name, p in sorted(peak.items()):
        goal = GOALS_MB.get(name.split(":")[0])
        rows.append(f"| {name} | {p['rss_mb']:.0f} | {p['anon_mb']:.0f} | {p['pss_mb']:.0f} | "
                    f"{'' if goal is None else f'≤ {goal:.0f} (VmRSS)'} |")
    total = {field: sum(p[field] for p in peak.values())
             for field in ("rss_mb", "anon_mb", "pss_mb")}
    rows.append(f"| **lab** | {total['rss_mb']:.0f} | {total['anon_mb']:.0f} | "
                f"**{total['pss_mb']:.0f}** | ≤ {LAB_GOAL_MB:.0f} |")
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--lab", type=Path, default=ROOT / "config" / "demo.toml")
    parser.add_argument("--settle", type=float, default=70.0)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    peak = measure(args.lab.resolve(), args.settle, args.seconds)
    print(json.dumps(peak, indent=1) if args.json else table(peak))


if __name__ == "__main__":
    main()
