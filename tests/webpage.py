"""The operator's page as a script or a browser's fetch sees it: HTTP(S) requests with HTTP
Basic or a session cookie (the page tests and the compose test)."""

from __future__ import annotations

import base64
import http.client
import json
import ssl
from pathlib import Path
from urllib.parse import urlsplit


def basic(user: tuple[str, str]) -> dict[str, str]:
    """The Authorization header of HTTP Basic for (name, password)."""
    return {"Authorization": "Basic " + base64.b64encode(":".join(user).encode()).decode()}


class PageClient:
    """Requests to the page at ``url`` (http or https; ``cafile`` verifies its certificate)."""

    def __init__(self, url: str, cafile: Path | None = None) -> None:
        parts = urlsplit(url)
        self.host, self.port = parts.hostname or "127.0.0.1", parts.port or 80
        self.tls = None
        if parts.scheme == "https":
            self.tls = ssl.create_default_context(cafile=str(cafile) if cafile else None)

    def request(self, method: str, path: str, *, auth: tuple[str, str] | None = None,
                cookie: str | None = None, headers: dict | None = None, body: object = None,
                timeout_s: float = 10.0) -> tuple[int, dict[str, str], bytes]:
        """(status, headers with lower-case names, body); an event stream's body is not read."""
        conn = (http.client.HTTPSConnection(self.host, self.port, context=self.tls,
                                            timeout=timeout_s) if self.tls
                else http.client.HTTPConnection(self.host, self.port, timeout=timeout_s))
        sent = dict(headers or {})
        if auth:
            sent.update(basic(auth))
        if cookie:
            sent["Cookie"] = cookie
        data = None
        if body is not None:
            data = json.dumps(body).encode()
            sent.setdefault("Content-Type", "application/json")
        try:
            conn.request(method, path, body=data, headers=sent)
            reply = conn.getresponse()
            streaming = reply.getheader("content-type", "").startswith("text/event-stream")
            content = b"" if streaming else reply.read()
            return reply.status, {k.lower(): v for k, v in reply.getheaders()}, content
        finally:
            conn.close()

    def sign_in(self, user: tuple[str, str]) -> tuple[str, str, str]:
        """(cookie, CSRF token, the Set-Cookie header) of a new session."""
        status, headers, body = self.request("POST", "/signin", body={"user": user[0],
                                                                       "password": user[1]})
        assert status == 200, body
        cookie = headers["set-cookie"].split(";")[0]
        csrf = json.loads(self.request("GET", "/session.json", cookie=cookie)[2])["csrf"]
        return cookie, csrf, headers["set-cookie"]

    def command(self, name: str, cookie: str, csrf: str) -> tuple[int, dict]:
        status, _, body = self.request("POST", f"/gantry/{name}", cookie=cookie,
                                       headers={"X-CSRF-Token": csrf})
        return status, json.loads(body)
