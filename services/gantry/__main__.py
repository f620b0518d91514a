"""``stb gantry``: the crane follows the robot (paper §3), once an operator arms it.

``stb gantry arm|disarm|stop|reset [--reason TEXT]``: an operator's command (see its --help).
``stb gantry identify [--box MM]``: measure the crane that is there (commissioning).
``stb gantry commission [--box MM] [--toml OUT]``: the crane's frame, the tracking camera's
lens and mount, and the dynamics, measured on a crane's first day.
The modes: disarmed at start (the crane is never enabled), armed (tracking; holding without a
fresh estimate), stopped (by stop, a latched fault, the e-stop or the crane disabled at its
controller: setpoint frozen, crane disabled; only reset, then arm, moves it again).
The paper's experiments on a simulated clock: ``stb experiment gantry --help``."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.args import service_args


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["identify"]:
        from services.gantry.commissioning.identify_cli import main as identify_main

        return identify_main(argv[1:])
    if argv[:1] == ["commission"]:
        from services.gantry.commissioning.commission_cli import main as commission_main

        return commission_main(argv[1:])
    if argv[:1] and not argv[0].startswith("-"):  # an operator's command: arm, disarm, …
        from services.gantry.command_cli import main as command_main

        return command_main(argv)
    args = service_args("gantry", __doc__ or "", argv)
    from services.entry import run_service
    from services.gantry.service import run
    from services.gantry.settings import GantrySettings

    return run_service("gantry", GantrySettings, run, args)


if __name__ == "__main__":
    sys.exit(main())
