"""Faults that come to the operator's page: many live views at once."""

from __future__ import annotations

import http.client
import json
import time

from benchmarks.faults.lab import wait_until
from tests.uplab import VIEWER
from tests.webpage import PageClient, basic

STREAMS = 200


class WebFaults:
    """The page's faults, as a part of ``Campaign`` (``self.web_url``: the page)."""

    def event_streams(self, count: int = STREAMS) -> None:
        """``count`` event streams opened and held at once (a browser tab each, or a script
        gone wrong): the page serves its ``max_streams``, refuses the rest at once, answers
        meanwhile, and frees them all when they close."""
        page = PageClient(self.web_url)
        pids, memory, start = self.pids(), self.settled_memory(), time.monotonic()
        held: list[http.client.HTTPConnection] = []
        statuses: dict[int, int] = {}
        try:
            for _ in range(count):
                conn = http.client.HTTPConnection(page.host, page.port, timeout=10)
                conn.request("GET", "/events", headers=basic(VIEWER))
                reply = conn.getresponse()
                statuses[reply.status] = statuses.get(reply.status, 0) + 1
                if reply.status == 200 and reply.readline().startswith(b"data: "):
                    held.append(conn)
                else:
                    reply.read()
                    conn.close()
            asked = time.monotonic()
            status, _, body = page.request("GET", "/state.json", auth=VIEWER)
            answered_s = time.monotonic() - asked
            answers = status == 200 and "crane" in json.loads(body)
            during = self.snapshot_memory()
        finally:
            for conn in held:
                conn.close()
        freed = wait_until(lambda: page.request("GET", "/events", auth=VIEWER)[0] == 200, 10)
        extra = {"served": statuses.get(200, 0), "refused (503)": statuses.get(503, 0),
                 "state.json meanwhile": f"{answered_s:.2f} s" if answers else "no answer",
                 "freed after closing": "yes" if freed else "no"}
        ok = answers and freed and statuses.get(200, 0) + statuses.get(503, 0) == count
        self._survived(f"{count} event streams at once", f"{count} live views opened and "
                       "held, then closed", start, pids, [(memory, during)], extra, ok)
