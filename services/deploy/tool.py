"""What ``stb deploy`` does once its flags are parsed (services/deploy/cli.py has the
command and its documentation)."""

from __future__ import annotations

import argparse
import sys

from common.errors import ConfigError
from common.files import write_atomically
from common.ptz_settings import PtzSettings
from common.settings import read_lab_file
from services.deploy.render import (
    COMPOSE_FILE,
    ROUTER_CONFIG,
    RenderError,
    cameras_of,
    compose_file,
    router_config,
)
from services.entry import ToolError, tool_settings

EXIT_DRIFT = 1


def render_files(args: argparse.Namespace) -> int:
    try:
        lab = read_lab_file(args.lab) if args.lab else {}
        cameras = cameras_of(list(lab.get("ptz", {}).get("cameras", {})))
    except (ConfigError, RenderError) as err:
        raise ToolError(str(err)) from err
    # the whole [ptz] section must be valid for one of its cameras (the lab file's, else the
    # built-in ones)
    args.instance = args.instance or (cameras[0].name if cameras else None)
    settings = tool_settings(PtzSettings, args)
    cameras = cameras or cameras_of(list(settings.cameras))
    rendered = {ROUTER_CONFIG: router_config(cameras), COMPOSE_FILE: compose_file(cameras)}
    names = ", ".join(c.name for c in cameras)
    if args.check:
        drifted = [name for name, text in rendered.items()
                   if not (args.out / name).is_file() or (args.out / name).read_text() != text]
        for name in drifted:
            print(f"{args.out / name} differs from what the lab file renders (cameras: "
                  f"{names}): stb deploy render --lab {args.lab or '$STB_LAB'}",
                  file=sys.stderr)
        return EXIT_DRIFT if drifted else 0
    for name, text in rendered.items():
        path = args.out / name
        write_atomically(path, text.encode())  # compose and the router read them
        print(f"wrote {path} (cameras: {names})")
    print("new identities need a password: deploy/zenoh/make-secrets; then restart the router "
          "and start the new services (docker compose up -d)")
    return 0

