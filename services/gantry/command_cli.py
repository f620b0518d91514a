"""``stb gantry arm|disarm|stop|reset``: an operator's command to the gantry service.

    arm     let the gantry move the crane (needs a fault-free crane and the robot in view)
    disarm  the gantry lets go: the crane is disabled where it stands
    stop    at once, in any mode: setpoint frozen, crane disabled; latched until reset
    reset   clear the crane controller's latched faults (watchdog, e-stop); then arm again

Sends the command on the bus (as the lab file's bus identity: the operator's) and prints the
gantry's answer. Exit status: 0 accepted, 1 refused, 2 bad arguments, 3 no gantry or router.
"""

from __future__ import annotations

import argparse
import getpass
import os
import queue
import socket
import sys
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

from services.args import base_parser

if TYPE_CHECKING:  # imported once the flags are parsed: --help answers at once
    from common.bus import Bus

EXIT_REFUSED, EXIT_NO_SERVICE = 1, 3


def main(argv: Sequence[str]) -> int:
    parser = base_parser("stb gantry arm|disarm|stop|reset", __doc__ or "")
    parser.add_argument("command", help="arm, disarm, stop or reset")
    parser.add_argument("--reason", default="", help="why (shown with the gantry's mode)")
    parser.add_argument("--operator", default=f"{getpass.getuser()}@{socket.gethostname()}",
                        help="who asks (default: user@host)")
    parser.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the "
                        "gantry's answer")
    args = parser.parse_args(argv)
    from common.names import GANTRY_COMMANDS
    from services.entry import tool_main

    if args.command not in GANTRY_COMMANDS:
        parser.error(f"unknown command {args.command!r} (choose from "
                     f"{', '.join(GANTRY_COMMANDS)})")

    return tool_main(f"gantry {args.command}", lambda: _send(args))


def _send(args: argparse.Namespace) -> int:
    from common import messages as m
    from common.bus import Bus
    from services.entry import tool_session, tool_settings
    from services.gantry.settings import GantrySettings

    settings = tool_settings(GantrySettings, args)
    session = tool_session(settings)
    bus = Bus(session, settings.bus)
    try:
        return send(bus, args.command, m.who(args.operator), m.text(args.reason), args.timeout,
                    settings.bus.zenoh.identity("operator"))
    finally:
        bus.close()
        session.close()


def send(bus: Bus, command: str, operator: str, reason: str, timeout_s: float,
         sender: str) -> int:
    """Send ``command`` on ``sender``'s key (this host's bus identity) and print the answer."""
    from common import keys
    from common import messages as m

    replies: queue.Queue[m.GantryCommandReply] = queue.Queue()
    bus.subscribe(keys.GANTRY_COMMAND_REPLY, replies.put, latest=False)
    ident = f"cli-{os.getpid()}-{time.monotonic_ns() % 10**9}"
    time.sleep(0.2)  # let the subscription reach the router before the command goes out
    bus.publish(keys.GANTRY_COMMAND, m.GantryCommand.model_validate({
        "measured_s": time.time(), "command": command, "operator": operator,
        "reason": reason, "id": ident}), sender=sender)
    deadline = time.monotonic() + timeout_s
    while (left := deadline - time.monotonic()) > 0:
        try:
            reply = replies.get(timeout=left)
        except queue.Empty:
            break
        if reply.id == ident:
            verdict = "done" if reply.accepted else "refused"
            print(f"{command}: {verdict} — {reply.detail} (gantry {reply.mode})")
            return 0 if reply.accepted else EXIT_REFUSED
    print(f"stb gantry {command}: no answer within {timeout_s:g} s — is the gantry service "
          "running, and may this identity send commands (docs/deployment.md)?", file=sys.stderr)
    return EXIT_NO_SERVICE
