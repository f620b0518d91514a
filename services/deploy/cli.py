"""``stb deploy render --lab FILE [--out DIR] [--check]``: the lab's router configuration
(users, access control: deploy/zenoh/router.json5) and compose services (docker-compose.yml),
rendered from the lab file's PTZ cameras ([ptz.cameras.<name>]).

Adding a camera is then one lab-file section: add [ptz.cameras.ptz3], run this, make its
password (deploy/zenoh/make-secrets), restart the router and start the new service
(docs/deployment.md §3). --out DIR writes under DIR (default: the current folder, the
repository's root); --check writes nothing and exits 1 when the files there differ from what
the lab file renders.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from services.args import base_parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = base_parser("stb deploy render", __doc__ or "")
    parser.add_argument("action", choices=["render"])
    parser.add_argument("--out", type=Path, default=Path("."), metavar="DIR",
                        help="the project folder to write to (default: .)")
    parser.add_argument("--check", action="store_true",
                        help="compare only: exit 1 if the files differ from the lab file's")
    args = parser.parse_args(argv)
    from services.deploy.tool import render_files
    from services.entry import tool_main

    return tool_main("deploy", lambda: render_files(args))


if __name__ == "__main__":
    sys.exit(main())
