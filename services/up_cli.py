"""``stb up``: the router and every service as separate processes, restarted when they die.

Like compose's ``restart: unless-stopped``: a process that exits is started again after a delay
that doubles from ``restart_initial_s`` up to ``restart_max_s`` and goes back to the start once a
process has run for ``stable_after_s``. Ctrl-C (or SIGTERM) stops the services, then the router.
Each child's output goes to ``<log_dir>/<service>-<instance>.log``. On a simulated lab's first
start the crater's height map is made from the sim's laser scan before anything starts
(``services/crater/first_start.py``).
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Sequence

from common.errors import ConfigError
from services.args import EXIT_CONFIG, base_parser, overrides_from

EXIT_FAILED = 1


def main(argv: Sequence[str] | None = None) -> int:
    parser = base_parser("stb up", __doc__ or "")
    parser.add_argument("--only", help="comma-separated services, e.g. router,sim")
    parser.add_argument("--no-view", action="store_true", help="log lines instead of a live table")
    args = parser.parse_args(argv)
    from common.lab_views import GantryHeightMap, SimCraterFile
    from common.node import configure_logging, stop_on_signals
    from common.settings import load_settings
    from services import supervisor
    from services.crater.first_start import (
        FirstStartError,
        height_map_to_import,
        import_sim_scan,
    )
    from services.web.settings import WebSettings

    try:
        overrides = overrides_from(args)
        if args.only:
            overrides["services"] = args.only.split(",")
        settings = load_settings(supervisor.UpSettings, args.lab, overrides)
        web = load_settings(WebSettings, args.lab) if supervisor.runs_web(settings) else None
        height_map = load_settings(GantryHeightMap, args.lab).height_map
        sim_crater = load_settings(SimCraterFile, args.lab).crater_file
    except ConfigError as err:
        print(f"stb up: {err}", file=sys.stderr)
        return EXIT_CONFIG
    configure_logging(settings.log_level)
    if height_map_to_import(settings.services, height_map, sim_crater):
        try:
            import_sim_scan(args.lab, height_map)
        except FirstStartError as err:
            print(f"stb up: the first start's height map: {err}", file=sys.stderr)
            return EXIT_FAILED
        except KeyboardInterrupt:
            return EXIT_FAILED
    stop = threading.Event()
    restore = stop_on_signals(stop)
    try:
        view = not args.no_view and sys.stdout.isatty()
        page = None if web is None else supervisor.page_url(web.host, web.port)
        return supervisor.run(settings, args.lab, stop, view=view, page=page)
    finally:
        restore()


if __name__ == "__main__":
    sys.exit(main())
