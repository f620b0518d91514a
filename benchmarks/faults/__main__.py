"""Fault campaign: the whole simulated lab under the faults a lab meets, and what held.

    .venv/bin/python -m benchmarks.faults [--per-key 10000] [--churn 4000] [--json FILE]
    .venv/bin/python -m benchmarks.faults --short        # a few seconds per fault (make test)

Starts ``stb up`` with every service (router, sim, tracker, calib with both cameras' poses
stored, ptz1, ptz2, gantry, web) in a network namespace of its own (as root; else, or with
``--loopback``, on free loopback ports), arms the gantry as an operator and waits until the
crane and both cameras follow the robot. Then, one after the other:

* fuzz: ``--per-key`` payloads on every key a service subscribes to (random bytes, broken
  msgpack, each key's message with fields missing, extra, mistyped or extreme);
* key churn: 8 garbage bytes on each of ``--churn`` distinct keys under subscribed wildcards;
* decode bombs: tracking frames whose JPEG header declares 24000×24000 pixels;
* spoofed frames: a bright spot far from the robot, 30 frames a second for a few seconds;
* a spoofed camera pose (ptz1 turned 40°, at version 2⁵³ and 2⁵³−1, measured now);
* SIGKILL of each service (the router last);
* SIGSTOP of the gantry for 0.3, 1 and 3 s and of the tracker for 2 s;
* a foreign Modbus client writing setpoints beside the gantry's.
* the page: 200 live views at once; 200 wrong sign-ins while an operator presses Stop; a
  link in a report folder to a file outside it.

Measured from outside, as a lab would: liveliness tokens and health messages on the bus, the
sim's true crane and robot (``stb/sim/truth/**``), the setpoints and estimates the gantry
publishes, the crane controller's status registers read over Modbus at 100 Hz (reads are not
activity for its watchdog), and each service's resident memory from /proc. The last lines
are the table of goals and figures; docs/reliability.md holds one run's.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict
from pathlib import Path

from benchmarks.faults.campaign import STEPS, run, table
from benchmarks.faults.lab import ROOT
from services.args import Parser

IN_NAMESPACE = "STB_FAULTS_IN_NAMESPACE"


def in_own_namespace(argv: list[str]) -> int | None:
    """Run the campaign again inside a new network namespace (only its loopback, up), so
    that nothing it does reaches the host's network; None where that cannot be done (not
    root, no unshare or ip): the campaign then runs on free loopback ports."""
    if os.geteuid() != 0 or not shutil.which("unshare") or not shutil.which("ip"):
        return None
    probe = subprocess.run(["unshare", "--net", "true"], capture_output=True)
    if probe.returncode != 0:
        return None
    command = ["unshare", "--net", "sh", "-c", 'ip link set lo up && exec "$0" "$@"',
               sys.executable, "-m", "benchmarks.faults", *argv]
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    return subprocess.call(command, env={**os.environ, IN_NAMESPACE: "1", "PYTHONPATH": path})


def main(argv: list[str] | None = None) -> int:
    parser = Parser(prog="python -m benchmarks.faults",
                    description=__doc__.split("\n\n")[0],
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--short", action="store_true", help="a few seconds per fault")
    parser.add_argument("--per-key", type=int, default=None, help="fuzz payloads per key "
                        "(default 10000; --short: 300)")
    parser.add_argument("--churn", type=int, default=None, help="distinct keys (default 4000; "
                        "--short: 1000)")
    parser.add_argument("--only", nargs="+", choices=STEPS, help="these faults only")
    parser.add_argument("--json", type=Path, help="write the rows with their figures here")
    parser.add_argument("--keep", type=Path, help="the lab's folder (logs); default: a "
                        "temporary one, removed")
    parser.add_argument("--loopback", action="store_true", help="on this host's loopback "
                        "(default: in a network namespace of its own when run as root)")
    args = parser.parse_args(argv)
    argv = sys.argv[1:] if argv is None else argv
    if not args.loopback and os.environ.get(IN_NAMESPACE) != "1":
        code = in_own_namespace(argv)
        if code is not None:
            return code
    where = "in a network namespace of its own" if os.environ.get(IN_NAMESPACE) == "1" \
        else "on the host's loopback"
    print(f"fault campaign {where}", flush=True)
    per_key = args.per_key or (300 if args.short else 10_000)
    churn = args.churn or (1000 if args.short else 4000)
    began = time.monotonic()
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)
        rows = run(args.short, per_key, churn, args.keep, args.only)
    else:
        with tempfile.TemporaryDirectory(prefix="stb-faults-") as folder:
            rows = run(args.short, per_key, churn, Path(folder), args.only)
    print(table(rows))
    held = sum(r.held for r in rows)
    print(f"\n{held} of {len(rows)} held; campaign {time.monotonic() - began:.0f} s")
    if args.json:
        args.json.write_text(json.dumps([asdict(r) for r in rows], indent=1, default=str))
    return 0 if held == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
