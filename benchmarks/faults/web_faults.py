"""Faults that come to the operator's page: many live views at once; a flood of wrong
sign-ins while an operator presses Stop; a viewer's sign-ins by the thousand; wrong sign-ins
that name another client in X-Forwarded-For; a foreign name in Host; huge bodies before
sign-in; a report folder's link to a file outside; the page's move of a camera in calibration
mode."""

from __future__ import annotations

import http.client
import json
import socket
import threading
import time
from pathlib import Path

from benchmarks.faults.base import CampaignBase
from benchmarks.faults.lab import resident_mb, wait_until
from benchmarks.faults.rows import Row
from common import keys
from common import messages as m
from tests.uplab import OPERATOR, VIEWER
from tests.webpage import PageClient, basic

STREAMS = 200
SIGN_IN_ADDRESSES, SIGN_IN_TRIES = 40, 5
"""200 wrong sign-ins: 40 client addresses (127.0.0.2…) × 5, each within the brake's free
tries, so that every one of them costs a password check."""
GOAL_STOP_S = 0.5
BODY_MB, BODIES, GOAL_WEB_MB = 500, 3, 300
VIEWER_SIGN_INS = 2000
"""A viewer's sign-ins (``--short``: 40, twice a user's share of sessions) while an
operator stays signed in."""


class WebFaults(CampaignBase):
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

    def sign_in_flood(self) -> None:
        """200 wrong sign-ins at once, each within its address's free tries, while a
        signed-in operator presses Stop and a signed-in viewer asks for the state: both
        answered at once (a Stop once waited 16.6 s behind the password checks)."""
        page = PageClient(self.web_url)
        cookie, csrf, _ = page.sign_in(OPERATOR)
        viewer, _, _ = page.sign_in(VIEWER)
        answers: list[int] = []

        def wrong(address: str) -> None:
            for i in range(SIGN_IN_TRIES):
                conn = http.client.HTTPConnection(page.host, page.port, timeout=60,
                                                  source_address=(address, 0))
                try:
                    conn.request("POST", "/signin", json.dumps(
                        {"user": OPERATOR[0], "password": f"guess-{i}"}),
                        {"Content-Type": "application/json"})
                    answers.append(conn.getresponse().status)
                except OSError:
                    answers.append(0)
                finally:
                    conn.close()

        flood = [threading.Thread(target=wrong, args=(f"127.0.0.{2 + n}",))
                 for n in range(SIGN_IN_ADDRESSES)]
        start = time.monotonic()
        for thread in flood:
            thread.start()
        wait_until(lambda: len(answers) >= SIGN_IN_ADDRESSES, 30, 0.01)  # under way
        asked = time.monotonic()
        status, answer = page.command("stop", cookie, csrf)
        stop_s = time.monotonic() - asked
        asked = time.monotonic()
        state_status = page.request("GET", "/state.json", cookie=viewer)[0]
        state_s = time.monotonic() - asked
        for thread in flood:
            thread.join(120)
        flood_s = time.monotonic() - start
        stopped = status == 200 and bool(answer.get("accepted"))
        counts = {code: answers.count(code) for code in sorted(set(answers))}
        misses = ([] if stopped and stop_s <= GOAL_STOP_S else ["stop"]) + \
            ([] if state_status == 200 and state_s <= GOAL_STOP_S else ["state"])
        self.rows.append(Row(
            "wrong sign-ins", f"a signed-in operator's Stop answered ≤ {GOAL_STOP_S} s "
            f"during {SIGN_IN_ADDRESSES * SIGN_IN_TRIES} wrong sign-ins",
            f"{len(answers)} wrong sign-ins from {SIGN_IN_ADDRESSES} addresses in "
            f"{flood_s:.1f} s (answers {counts}); Stop answered in {stop_s:.2f} s "
            f"({'accepted' if stopped else answer.get('detail')}), /state.json in "
            f"{state_s:.2f} s ({state_status})", not misses,
            {"stop_s": stop_s, "state_s": state_s, "answers": counts}, misses))
        self.log(f"wrong sign-ins: {self.rows[-1].measured}")

    def report_link(self) -> None:
        """A link in a recording's report folder to a file outside it (a symlink once served
        /etc/shadow to any signed-in user): refused, while the report's own file is served."""
        report = Path(self.folder) / "recordings" / "20261204-000000.report"
        report.mkdir(parents=True, exist_ok=True)
        (report / "index.html").write_text("<html>the report</html>")
        secret = Path(self.folder) / "secret.txt"
        secret.write_text("root:$6$not-for-the-page")
        link = report / "leak.txt"
        link.unlink(missing_ok=True)
        link.symlink_to(secret)
        page = PageClient(self.web_url)
        viewer, _, _ = page.sign_in(VIEWER)
        own = page.request("GET", "/recordings/20261204-000000/index.html", cookie=viewer)
        leak = page.request("GET", "/recordings/20261204-000000/leak.txt", cookie=viewer)
        held = own[0] == 200 and leak[0] == 404 and b"root:" not in leak[2]
        self.rows.append(Row(
            "report folder's link out", "a link out of a report's folder is not served (404); "
            "the report's own files are", f"the report's index.html: {own[0]}; its link to a "
            f"file outside: {leak[0]}", held, {"own": own[0], "link": leak[0]},
            [] if held else ["served"]))
        self.log(f"report folder's link out: {self.rows[-1].measured}")

    def viewer_sign_ins(self) -> None:
        """A viewer signs in again and again (a script gone wrong, or on purpose): the
        operator's session, opened before, still answers (1,001 once ended it)."""
        page = PageClient(self.web_url)
        cookie, _, _ = page.sign_in(OPERATOR)
        count = 40 if self.short else VIEWER_SIGN_INS
        start, refused = time.monotonic(), 0
        for _ in range(count):
            status = page.request("POST", "/signin", body={"user": VIEWER[0],
                                                           "password": VIEWER[1]})[0]
            refused += status != 200
        status, _, body = page.request("GET", "/session.json", cookie=cookie)
        kept = status == 200 and json.loads(body).get("user") == OPERATOR[0]
        self.rows.append(Row(
            "viewer sign-ins", f"an operator's session survives a viewer's {count} sign-ins",
            f"{count} sign-ins by a viewer in {time.monotonic() - start:.1f} s ({refused} "
            f"refused); the operator's session afterwards: "
            f"{'kept' if kept else f'gone ({status})'}", kept and refused == 0,
            {"sign_ins": count, "kept": kept}, [] if kept else ["ended"]))
        self.log(f"viewer sign-ins: {self.rows[-1].measured}")

    def forwarded_for(self) -> None:
        """A local process (the page's own machine) tries passwords, each try naming another
        client in X-Forwarded-For: without ``[web] trusted_proxies`` the header is ignored,
        so the tries count for one address and the brake stops them (uvicorn's default once
        trusted it from loopback: any address passed the brake and went into the audit)."""
        page = PageClient(self.web_url)
        answers = [page.request("POST", "/signin", body={"user": OPERATOR[0],
                                                         "password": f"guess-xff-{i}"},
                                headers={"X-Forwarded-For": f"203.0.113.{i + 1}"})[0]
                   for i in range(8)]
        braked = 429 in answers
        wait_until(lambda: page.request("POST", "/signin", body={  # the brake waited out,
            "user": VIEWER[0], "password": VIEWER[1]})[0] == 200, 60, 0.5)  # for what follows
        self.rows.append(Row(
            "X-Forwarded-For from loopback", "ignored without a configured proxy: the "
            "brake stops the tries", f"8 wrong sign-ins from loopback, each naming another "
            f"client: answers {answers}", braked, {"answers": answers},
            [] if braked else ["trusted"]))
        self.log(f"X-Forwarded-For: {self.rows[-1].measured}")

    def foreign_host(self) -> None:
        """A DNS-rebinding page: the signed-in operator's browser sends another site's name
        in ``Host`` (its cookie is not sent to that name, so: without one, and with Basic as
        a script would): refused before anything is read, the page's own name answered."""
        page = PageClient(self.web_url)
        answers = {}
        for path, method in (("/session.json", "GET"), ("/state.json", "GET"),
                             ("/gantry/stop", "POST")):
            answers[path] = page.request(method, path, auth=OPERATOR, headers={
                "Host": "evil.example", "Origin": "http://evil.example"})[0]
        own = page.request("GET", "/state.json", auth=VIEWER)[0]
        held = all(code in (401, 403, 421) for code in answers.values()) and own == 200
        self.rows.append(Row(
            "foreign Host", "401/403/421 for another site's name in Host; the page's own "
            "answered", f"Host evil.example: {answers}; the page's own address: {own}", held,
            {"answers": answers, "own": own}, [] if held else ["answered"]))
        self.log(f"foreign Host: {self.rows[-1].measured}")

    def huge_bodies(self) -> None:
        """Three anonymous 500 MB bodies to ``/signin`` at once, each sent as fast as the
        page takes it: refused (413) on the declared length, the web process's own memory
        sampled meanwhile (2.14 GB once)."""
        page = PageClient(self.web_url)
        pid = self.meters.pid("web") or -1
        before, peak, answers = resident_mb(pid), 0.0, []
        sent_mb: list[float] = []

        def send() -> None:
            chunk, sent = b"{" + b" " * (1024 * 1024 - 1), 0
            try:
                with socket.create_connection((page.host, page.port), timeout=10) as conn:
                    conn.sendall(b"POST /signin HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                                 b"Content-Type: application/json\r\n"
                                 b"Content-Length: %d\r\n\r\n" % (BODY_MB * 1024 * 1024))
                    for _ in range(BODY_MB):
                        conn.sendall(chunk)
                        sent += 1
                    answers.append(int(conn.recv(64).split()[1]))
            except (OSError, IndexError, ValueError):
                answers.append(0)  # closed on us while we were still sending: refused
            sent_mb.append(sent)

        senders = [threading.Thread(target=send) for _ in range(BODIES)]
        for thread in senders:
            thread.start()
        while any(t.is_alive() for t in senders):
            peak = max(peak, resident_mb(pid))
            time.sleep(0.05)  # sampling the memory while the bodies come
        after = resident_mb(pid)
        answered = page.request("GET", "/state.json", auth=VIEWER)[0]
        held = peak <= GOAL_WEB_MB and answered == 200 and self.meters.pid("web") == pid
        self.rows.append(Row(
            "huge bodies", f"the web process's resident memory ≤ {GOAL_WEB_MB} MB under "
            f"{BODIES} × {BODY_MB} MB bodies to /signin", f"{BODIES} bodies of {BODY_MB} MB "
            f"declared: {max(sent_mb, default=0):.0f} MB at most sent before the page closed "
            f"(answers {answers}); web {before:.0f} → peak {peak:.0f} → {after:.0f} MB; "
            f"state.json after: {answered}", held,
            {"peak_mb": peak, "before_mb": before, "after_mb": after},
            [] if held else ["memory"]))
        self.log(f"huge bodies: {self.rows[-1].measured}")

    def calibration_move(self) -> None:
        """ptz1 in calibration mode (a collector's requests, held where it looks): the
        signed-in operator's page moves it 40° away: refused by the PTZ service, the camera
        stays at its hold (sim truth) — it once went, and spoiled the passpoints."""
        page, camera = PageClient(self.web_url), "ptz1"
        cookie, csrf, _ = page.sign_in(OPERATOR)
        states = self.meters.ptz_states
        start_wall, hold = time.time(), next(
            (s for s in reversed(states) if s.camera == camera), None)
        pan, tilt = (hold.pan_deg, hold.tilt_deg) if hold else (0.0, -30.0)

        def ask(active: bool) -> None:
            self.bus.publish(keys.PTZ_CALIBRATION, m.CalibrationMode(
                measured_s=time.time(), camera=camera, active=active, pan_deg=pan,
                tilt_deg=tilt, zoom=None, lease_s=2.0), camera=camera)

        def calibrating() -> bool:
            ask(True)  # the collector's lease, renewed as it would be
            return any(s.camera == camera and s.status == "calibrating"
                       and s.measured_s > start_wall for s in states[-20:])

        entered = wait_until(calibrating, 10, 0.3)
        moved_at = time.monotonic()
        status = page.request("POST", f"/ptz/{camera}/move", cookie=cookie,
                              headers={"X-CSRF-Token": csrf},
                              body={"pan_deg": (pan + 40.0 + 180.0) % 360.0 - 180.0,
                                    "tilt_deg": tilt})[0]
        wait_until(lambda: calibrating() and time.monotonic() > moved_at + 2.0, 5, 0.3)
        heads = [head for head, _ in self.meters.ptz_window(camera, moved_at)]
        away = max((abs((h.pan_deg - pan + 180.0) % 360.0 - 180.0) for h in heads),
                   default=float("nan"))
        ask(False)
        held = entered and status == 200 and away <= 1.0
        self.rows.append(Row(
            "page move in calibration mode", "the camera stays at its hold (≤ 1°)",
            f"ptz1 held at pan {pan:.1f}° for calibration "
            f"({'calibrating' if entered else 'NOT calibrating'}); the page's move 40° away "
            f"answered {status}; the camera's true pan at most {away:.2f}° from the hold over "
            f"the next 2 s", held, {"entered": entered, "away_deg": away, "status": status},
            [] if held else ["moved"]))
        self.log(f"calibration move: {self.rows[-1].measured}")
