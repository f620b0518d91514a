"""``python -m compose_test.prepare`` (``make compose-image``): the compose test's Docker engine
installed when missing, and the project's image made (its base too), ahead of the test.

CI starts it beside ``make test``, whose work is the processors' while this one mostly waits
for the package registries and the disk, so that the compose stage finds the image made (on a
fresh machine 2–3 minutes of engine, base and build). The test builds again all the same: a
made image costs it its cache's few seconds, and a failure here only leaves it the whole build
(and this log says why). Exit 0 when the image is made or no engine can run here, 1 otherwise."""

from __future__ import annotations

import subprocess
import sys
import time

from compose_test.engine import (
    ENGINE_HOME,
    OUT,
    Engine,
    EngineError,
    install_when_missing,
    why_no_engine,
)


def main() -> int:
    why = why_no_engine()
    if why is not None:
        print(f"compose image not made: {why}")
        return 0
    OUT.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    try:
        install_when_missing(OUT / "install.log")
        engine = Engine(ENGINE_HOME)
        engine.start()
        try:
            print(f"engine up after {time.monotonic() - started:.0f} s", flush=True)
            base = engine.base_image()
            print(f"base {base} after {time.monotonic() - started:.0f} s", flush=True)
            engine.build(base)
        finally:
            engine.stop()
    except (EngineError, OSError, subprocess.SubprocessError) as err:
        print(f"compose image not made: {err}", file=sys.stderr)
        return 1
    print(f"project image made after {time.monotonic() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
