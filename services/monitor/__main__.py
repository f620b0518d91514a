"""``stb monitor [--raw KEYEXPR] [--duration S]``: a remote monitoring subscriber.

Without ``--raw`` it redraws a table of alive services and of every key's latest value, rate
and age once per second. With ``--raw`` it prints every valid sample under KEYEXPR as one JSON
line. It joins the bus as a client (``--connect tcp/ROUTER:7447``) and never publishes.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from services.args import base_parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = base_parser("stb monitor", __doc__ or "")
    parser.add_argument("--raw", metavar="KEYEXPR", help="print samples under KEYEXPR as JSON")
    parser.add_argument("--duration", type=float, help="stop after this many seconds")
    args = parser.parse_args(argv)
    from services.entry import tool_main
    from services.monitor.subscriber import monitor

    return tool_main("monitor", lambda: monitor(args))


if __name__ == "__main__":
    sys.exit(main())
