"""The page answers only to its own names: a DNS-rebinding page, which sends its own name in
``Host``, is refused (421) before anything is read — on the open page it once read the CSRF
token and pressed Stop."""

from __future__ import annotations

import http.client
from collections.abc import Iterator
from pathlib import Path

import pytest

from services.web.app import build_app
from services.web.crater_image import CraterImage
from services.web.gate import Gate
from services.web.hosts import HostCheck
from services.web.server import WebServer


@pytest.mark.parametrize(("host", "allowed"), [
    ("127.0.0.1:8080", True), ("10.0.0.5", True), ("[::1]:8080", True), ("::1", True),
    ("localhost:8080", True), ("LocalHost", True), ("page.localhost", True),
    ("lab-pc:8080", True), ("lab-pc.", True), ("Lab-PC.example.org", True),
    ("evil.example:8080", False), ("lab-pc.evil.example", False), ("", False), (None, False),
    ("127.0.0.1.evil.example", False), ("[::1", False)])
def test_which_names_are_the_pages(host: str | None, allowed: bool) -> None:
    check = HostCheck(["lab-pc", "lab-pc.example.org"])
    assert check.allows(host) is allowed


@pytest.fixture
def open_page(tmp_path: Path) -> Iterator[int]:
    commands: list[str] = []

    def command(name: str, who: str) -> dict:
        commands.append(name)
        return {"accepted": True, "detail": name, "mode": "stopped"}

    app = build_app(Gate(None, 3600, tls=False), dict, lambda c: None, lambda c: None,
                    CraterImage(tmp_path / "none.npz"), push_period_s=0.05, max_streams=2,
                    command=command, hosts=HostCheck(["lab-pc"]))
    web = WebServer(app, "127.0.0.1", 0).start()
    try:
        yield web.port
    finally:
        web.close()
        assert commands == [], "no command from a foreign name was carried out"


def _ask(port: int, method: str, path: str, host: str) -> tuple[int, bytes]:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        conn.putrequest(method, path, skip_host=True)
        conn.putheader("Host", host)
        conn.putheader("Content-Length", "0")
        conn.endheaders()
        reply = conn.getresponse()
        return reply.status, reply.read()
    finally:
        conn.close()


def test_a_rebinding_page_gets_neither_the_token_nor_the_stop(open_page: int) -> None:
    assert _ask(open_page, "GET", "/session.json", "evil.example")[0] == 421
    assert _ask(open_page, "POST", "/gantry/stop", f"evil.example:{open_page}")[0] == 421
    status, body = _ask(open_page, "GET", "/session.json", f"127.0.0.1:{open_page}")
    assert status == 200 and b"csrf" in body
    assert _ask(open_page, "GET", "/session.json", "lab-pc")[0] == 200


def test_bodies_are_bounded_before_anything_reads_them(open_page: int) -> None:
    """A body declared larger than the page's requests ever are is refused at once (413,
    not read); a chunked one is cut off once past the bound; a small one is served."""
    conn = http.client.HTTPConnection("127.0.0.1", open_page, timeout=10)
    try:
        conn.putrequest("POST", "/signin")
        conn.putheader("Content-Type", "application/json")
        conn.putheader("Content-Length", str(500 * 1024 * 1024))
        conn.endheaders()  # nothing of the 500 MB sent: answered without waiting for it
        assert conn.getresponse().status == 413
    finally:
        conn.close()

    def chunks() -> Iterator[bytes]:
        for _ in range(64):
            yield b"x" * 16384  # 1 MiB in all

    conn = http.client.HTTPConnection("127.0.0.1", open_page, timeout=10)
    try:
        conn.request("POST", "/signin", body=chunks(), encode_chunked=True,
                     headers={"Content-Type": "application/json"})
        assert conn.getresponse().status == 413
    except (BrokenPipeError, ConnectionResetError):
        pass  # refused and closed while the rest was still being sent
    finally:
        conn.close()
    assert _ask(open_page, "GET", "/session.json", f"127.0.0.1:{open_page}")[0] == 200
