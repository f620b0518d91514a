"""``stb web``: the operator's live page on http://HOST:PORT (default 127.0.0.1:8080).

Sign-in first: users and roles in ``[web] users_file`` (``stb web user add NAME --role
operator|viewer``); a viewer sees, an operator also commands. Without a users file the page
listens on loopback only and everyone on this machine is the operator. TLS with
``tls_certificate`` and ``tls_key``.

A top view of the crater height map with the robot's track, the crane and its error circle,
each PTZ camera and where it looks; each camera's latest preview with the markers found and the
robot marker's expected pixel; every service's liveliness and health; the gravity-offload
figures. The page updates itself from the bus (Server-Sent Events), no reloading.

Subscribes: stb/tracker/robot, stb/gantry/{state,estimate,offload}, stb/ptz/*/{state,preview},
            stb/calib/*/pose (also queried at start), stb/health/**, stb/sim/truth/robot/*,
            stb/gantry/command/reply, liveliness stb/alive/**.
Publishes:  its own health and liveliness; stb/gantry/command when an operator presses one
            of the page's gantry buttons (arm, disarm, stop, reset); stb/calib/{camera}/collect
            (a calibration from the page: start, cancel, accept, discard); stb/ptz/{camera}/hand
            (an operator holds, moves or releases a camera). Runs stb record and stb report
            for the page's recordings ([web] recordings_dir).
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Sequence

from services.args import service_args


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["user"]:
        from services.web.user_cli import main as user_main

        return user_main(argv[1:])
    args = service_args("web", __doc__ or "", argv)
    from services.entry import run_service
    from services.web.service import run
    from services.web.settings import WebSettings

    return run_service("web", WebSettings, functools.partial(run, lab=args.lab), args)


if __name__ == "__main__":
    sys.exit(main())
