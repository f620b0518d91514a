"""``stb doctor [--lab FILE] [--json]``: everything a lab's first run needs, checked against
the lab file, one row each with its verdict and, when it fails, the fix — the motion capture
and the labels the lab uses (robot, crane, wand), each PTZ camera over VAPIX (identity, PTZ
limits, picture sizes) and its stored pose, the crane controller over Modbus through the lab's
register map, the tracking camera's frames on the bus, the observation camera's picture, the
hosts' clocks, disk space for recordings and the router's access control. Exit status: 0 when
every check passed (a skipped one does not apply to this lab), 1 when one failed (a lab-file
section that does not validate is a failed row), 2 a bad ``[doctor]`` section. Settings:
``[doctor]`` (listen_s, timeout_s, min_frame_hz, clock_tolerance_s, min_free_gb, targets,
router_config).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from services.args import base_parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = base_parser("stb doctor", __doc__ or "")
    parser.add_argument("--json", action="store_true", help="the rows as one JSON document")
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    from services.entry import tool_main

    return tool_main("doctor", lambda: _run(args.lab, args, args.json))


def _run(lab: Path | None, args: Any, as_json: bool) -> int:
    from services.doctor.run import examine
    from services.doctor.settings import DoctorSettings
    from services.doctor.table import exit_status, render
    from services.entry import tool_settings

    settings = tool_settings(DoctorSettings, args)
    say: Callable[[str], None] = (lambda _line: None) if as_json else \
        (lambda line: print(line, file=sys.stderr, flush=True))
    checks = examine(lab, settings, say)
    if as_json:
        print(json.dumps([c.as_dict() for c in checks], indent=1))
    else:
        print(render(checks))
    return exit_status(checks)


if __name__ == "__main__":
    sys.exit(main())
