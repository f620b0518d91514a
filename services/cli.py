"""The ``stb`` command: ``stb <service>``, ``stb up``, ``stb monitor``, ``stb config check``."""

from __future__ import annotations

import atexit
import contextlib
import importlib
import os
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

from common.errors import ConfigError
from services.args import EXIT_CONFIG, EXIT_INTERRUPTED, Parser
from services.registry import SERVICES, TOOLS, settings_class


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage())
        return 0 if argv else 2
    command, rest = argv[0], argv[1:]
    if command in SERVICES:
        return importlib.import_module(f"services.{command}.__main__").main(rest)
    if command in TOOLS and TOOLS[command].main:
        return importlib.import_module(TOOLS[command].main).main(rest)
    if command == "config":
        return _config(rest)
    print(f"stb: unknown command {command!r}\n\n{_usage()}", file=sys.stderr)
    return 2


def _usage() -> str:
    lines = ["usage: stb COMMAND [--lab FILE] [options]   (stb COMMAND --help for more)", "",
             "services:"]
    lines += [f"  {name:<10} {info.description}" for name, info in SERVICES.items()]
    lines += ["", "tools:"] + [f"  {name:<10} {info.description}" for name, info in TOOLS.items()]
    return "\n".join(lines)


def _config(argv: list[str]) -> int:
    """``stb config check --lab FILE``: validate every section a service would read."""
    parser = Parser(
        prog="stb config", description="stb config check --lab FILE: validate a lab file as "
        "every service would read it — each section and each field; an error names the "
        "field (for example gantry.x_max_mm) and the exit code is 2.")
    parser.add_argument("action", choices=["check"], help="check the lab file")
    parser.add_argument("--lab", type=Path, required=True, metavar="FILE",
                        help="the lab file (TOML), e.g. config/lab.toml")
    args = parser.parse_args(argv)
    from common.settings import load_settings, read_lab_file

    try:
        sections = read_lab_file(args.lab)
    except ConfigError as err:
        print(f"stb config: {err}", file=sys.stderr)
        return EXIT_CONFIG
    known = {name: info for name, info in {**SERVICES, **TOOLS}.items() if info.settings}
    errors = [f"unknown section [{name}] (known: bus, {', '.join(sorted(known))})"
              for name in sorted(set(sections) - set(known) - {"bus"})]
    for info in known.values():
        try:
            load_settings(settings_class(info), args.lab, environ={})
        except ConfigError as err:
            errors.append(str(err))
    for error in errors:
        print(error, file=sys.stderr)
    if not errors:
        print(f"{args.lab}: ok")
    return EXIT_CONFIG if errors else 0


def run() -> None:
    """The ``stb`` command as a process: ``main``, then the ending Python gives a process —
    its threads joined, its exit handlers run, its output flushed — but not the interpreter's
    finalization, after which ``os._exit``. Zenoh's runtime threads may still call into Python
    once a tool's session has closed; a thread that does so while the interpreter finalizes is
    ended by ``pthread_exit``, whose unwinding through Rust frames aborts the whole process
    (signal 6, "FATAL: exception not rethrown": at the end of ``stb calib collect`` in a CI
    run, after it had printed its result)."""
    try:
        code = main()
    except SystemExit as stop:  # argparse's --help and usage errors, sys.exit in a command
        if isinstance(stop.code, str):
            print(stop.code, file=sys.stderr)
        code = stop.code if isinstance(stop.code, int) else 0 if stop.code is None else 1
    except KeyboardInterrupt:  # Ctrl-C (or the page's stop) before a command took the signal
        print("stb: interrupted while starting", file=sys.stderr)
        code = EXIT_INTERRUPTED
    threading._shutdown()  # type: ignore[attr-defined]  # as at exit: joins the threads
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError):  # a reader that went away (``| head``)
            stream.flush()
    os._exit(code)


if __name__ == "__main__":
    run()
