"""Who may use the operator's page: users and roles, sign-in, sessions, HTTP Basic, the brake on
password guessing, TLS — the rules on injected clocks, then the real server over HTTP."""

from __future__ import annotations

import base64
import http.client
import json
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from services.web.access import Sessions, SignInBrake, basic_credentials
from services.web.app import build_app
from services.web.crater_image import CraterImage
from services.web.gate import Caller, Gate, command_refusal
from services.web.lanes import PASSWORDS_QUEUED
from services.web.server import WebServer
from services.web.settings import WebSettings
from services.web.users import Role, User, Users, UsersFileError
from tests.conftest import stb_process, wait_for
from tests.webpage import PageClient, basic

ALICE, VICTOR = ("alice", "alice-password-1"), ("victor", "victor-password-1")
PROTECTED = ["/app.js", "/state.json", "/events", "/map.json", "/map.png", "/preview/ptz1.jpg",
             "/video/observation.jpg",
             "/session.json"]


@pytest.fixture(scope="module")
def users_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("users") / "users.json"
    users = Users.load(path)
    users.add(ALICE[0], Role.OPERATOR, ALICE[1])
    users.add(VICTOR[0], Role.VIEWER, VICTOR[1])
    return path


# --- the rules, on injected clocks ---------------------------------------------------------


def test_the_users_file_holds_hashes_only_and_is_private(users_file: Path) -> None:
    text = users_file.read_text()
    assert ALICE[1] not in text and VICTOR[1] not in text and "$argon2id$" in text
    assert users_file.stat().st_mode & 0o777 == 0o600
    users = Users.load(users_file)
    assert users.verify(*ALICE) == User("alice", Role.OPERATOR)
    assert users.verify("alice", "wrong-password") is None
    assert users.verify("nobody", ALICE[1]) is None
    assert [(u.name, u.role) for u in users.list()] == [("alice", "operator"),
                                                         ("victor", "viewer")]


def test_adding_removing_and_bad_users(tmp_path: Path) -> None:
    path = tmp_path / "users.json"
    users = Users.load(path)
    with pytest.raises(ValueError, match="at least 8"):
        users.add("bob", Role.VIEWER, "short")
    with pytest.raises(ValueError, match="user name"):
        users.add("bob smith", Role.VIEWER, "long enough")
    users.add("bob", Role.VIEWER, "long enough")
    path.chmod(0o644)  # as make-secrets leaves it for compose: kept on rewrite
    users.add("bob", Role.OPERATOR, "another one")
    assert Users.load(path).verify("bob", "another one") == User("bob", Role.OPERATOR)
    assert path.stat().st_mode & 0o777 == 0o644
    users.remove("bob")
    assert not len(Users.load(path))
    with pytest.raises(KeyError):
        users.remove("bob")


@pytest.mark.parametrize("text", ["", "{", '{"users": []}', '{"users": {"a": {"role": "god", '
                                  '"hash": "x"}}}', '{"people": {}}'])
def test_a_bad_users_file_is_an_error_naming_it(tmp_path: Path, text: str) -> None:
    path = tmp_path / "users.json"
    path.write_text(text)
    with pytest.raises(UsersFileError, match=str(path)):
        Users.load(path)


def test_the_brake_lets_five_tries_then_doubles_the_wait() -> None:
    brake = SignInBrake(free=5, first_wait_s=1.0, longest_s=300.0, forget_s=3600.0)
    for _ in range(5):
        assert brake.wait_s("10.0.0.9", 100.0) == 0.0
        brake.failed("10.0.0.9", 100.0)
    assert brake.wait_s("10.0.0.9", 100.0) == 1.0
    assert brake.wait_s("10.0.0.8", 100.0) == 0.0, "another address is not braked"
    brake.failed("10.0.0.9", 101.0)
    assert brake.wait_s("10.0.0.9", 101.0) == 2.0
    for _ in range(20):
        brake.failed("10.0.0.9", 101.0)
    assert brake.wait_s("10.0.0.9", 101.0) == 300.0, "at most longest_s"
    brake.succeeded("10.0.0.9")
    assert brake.wait_s("10.0.0.9", 101.0) == 0.0
    for _ in range(6):
        brake.failed("10.0.0.7", 0.0)
    assert brake.failed("10.0.0.7", 5000.0) == 1, "an hour later the count starts again"


def test_the_brake_keeps_at_most_its_limit_of_addresses() -> None:
    brake = SignInBrake(limit=100)
    for i in range(1000):
        brake.failed(f"10.0.{i // 256}.{i % 256}", 1.0)
    assert len(brake._failures) == 100


def test_sessions_expire_and_are_bounded() -> None:
    sessions = Sessions(lifetime_s=60.0, limit=3)
    user = User("alice", Role.OPERATOR)
    token, session = sessions.open(user, 0.0)
    assert sessions.get(token, 59.0) == session and len(session.csrf) >= 24
    assert sessions.get(token, 60.0) is None and sessions.get(token, 1.0) is None
    tokens = [sessions.open(user, 0.0)[0] for _ in range(4)]
    assert sessions.get(tokens[0], 1.0) is None and sessions.get(tokens[-1], 1.0) is not None
    sessions.close_user("alice")
    assert sessions.get(tokens[-1], 1.0) is None
    assert sessions.get("", 1.0) is None and sessions.get(None, 1.0) is None


def test_a_viewers_sign_ins_never_end_an_operators_session() -> None:
    """2,000 sign-ins by a viewer end only the viewer's own oldest sessions (1,001 once
    ended the operator's); with the table full of many users', the one holding the most
    gives way, not the operator with one."""
    sessions = Sessions(lifetime_s=3600.0, limit=100, per_user=20)
    operator, viewer = User("olga", Role.OPERATOR), User("victor", Role.VIEWER)
    kept, _ = sessions.open(operator, 0.0)
    viewer_tokens = [sessions.open(viewer, float(i))[0] for i in range(2000)]
    assert sessions.get(kept, 2000.0) is not None
    assert [t for t in viewer_tokens if sessions.get(t, 2000.0)] == viewer_tokens[-20:]
    for n in range(200):  # many users, each within their share: the table fills
        sessions.open(User(f"user{n}", Role.VIEWER), 2000.0)
    assert sessions.get(kept, 2001.0) is not None and len(sessions._by_token) == 100


@pytest.mark.parametrize(("header", "expected"), [
    ("Basic " + base64.b64encode(b"alice:pa:ss").decode(), ("alice", "pa:ss")),
    ("basic " + base64.b64encode(b"a:").decode(), ("a", "")),
    ("Basic " + base64.b64encode(b"nocolon").decode(), None),
    ("Basic !!!", None), ("Bearer abc", None), ("", None), (None, None),
    ("Basic " + base64.b64encode(b"\xff:x").decode(), None)])
def test_basic_credentials(header: str | None, expected: tuple[str, str] | None) -> None:
    assert basic_credentials(header) == expected


def _status(refusal: tuple[int, str] | None) -> int | None:
    return None if refusal is None else refusal[0]


def test_what_a_command_needs() -> None:
    operator, viewer = User("alice", Role.OPERATOR), User("victor", Role.VIEWER)
    session = Caller(operator, "10.0.0.5", "session", "token123")
    assert _status(command_refusal(None, None, None, "lab:8080")) == 401
    watching = Caller(viewer, "h", "session", "t")
    assert _status(command_refusal(watching, "t", None, "lab:8080")) == 403
    assert _status(command_refusal(session, None, None, "lab:8080")) == 403, "no CSRF token"
    assert _status(command_refusal(session, "other", None, "lab:8080")) == 403
    assert command_refusal(session, "token123", None, "lab:8080") is None
    basic = Caller(operator, "10.0.0.5", "basic")
    assert command_refusal(basic, None, None, "lab:8080") is None, "a script with curl -u"
    assert command_refusal(basic, None, "http://lab:8080", "lab:8080") is None
    assert _status(command_refusal(basic, None, "https://evil.example", "lab:8080")) == 403
    assert session.label == "alice (web 10.0.0.5)"


def test_the_gate_brakes_guessing_with_its_clock(users_file: Path) -> None:
    now = [1000.0]
    gate = Gate(Users.load(users_file), 3600, tls=False, clock=lambda: now[0])
    answers = [gate.sign_in("alice", f"guess {i}", "10.0.0.9").status for i in range(20)]
    assert answers[:5] == [401] * 5 and set(answers[5:]) == {429}
    assert gate.sign_in(*ALICE, "10.0.0.9").status == 429, "even the right password waits"
    assert gate.sign_in(*ALICE, "10.0.0.2").status == 200, "another address signs in"
    now[0] += 2.0
    outcome = gate.sign_in(*ALICE, "10.0.0.9")
    assert outcome.status == 200 and outcome.session is not None
    caller = gate.caller(outcome.token, None, "10.0.0.9")
    assert caller is not None and caller.user.name == "alice"
    now[0] += 3600.0
    assert gate.caller(outcome.token, None, "10.0.0.9") is None, "the session expired"


# --- the server over HTTP(S) ------------------------------------------------------------------


class Page(PageClient):
    """The page under test, and the commands that reached its gantry."""

    def __init__(self, url: str, cafile: Path | None, commands: list[tuple[str, str]]) -> None:
        super().__init__(url, cafile)
        self.commands = commands


def _serve(users: Users | None, tmp: Path, tls: tuple[Path, Path] | None = None,
           max_streams: int = 10, proxies: tuple[str, ...] = ()
           ) -> Iterator[tuple[Page, WebServer]]:
    commands: list[tuple[str, str]] = []

    def command(name: str, who: str) -> dict:
        commands.append((name, who))
        return {"accepted": True, "detail": name, "mode": "armed"}

    gate = Gate(users, 3600, tls=tls is not None)
    app = build_app(gate, lambda: {"robot": {"x_mm": 1.0}}, lambda c: b"\xff\xd8jpeg",
                    lambda c: b"\xff\xd8video", CraterImage(tmp / "none.npz"), push_period_s=0.05,
                    max_streams=max_streams, command=command)
    web = WebServer(app, "127.0.0.1", 0, tls, proxies).start()
    page = Page(f"{web.scheme}://127.0.0.1:{web.port}", tls[0] if tls else None, commands)
    try:
        yield page, web
    finally:
        web.close()


@pytest.fixture
def page(users_file: Path, tmp_path: Path) -> Iterator[Page]:
    for served, _ in _serve(Users.load(users_file), tmp_path):
        yield served


def test_without_credentials_only_the_sign_in_form_answers(page: Page) -> None:
    status, _, body = page.request("GET", "/")
    assert status == 200 and b'id="signin"' in body and b"map" not in body
    assert page.request("GET", "/signin.js")[0] == 200
    for path in PROTECTED:
        status, headers, _ = page.request("GET", path)
        assert status == 401, path
        assert headers["www-authenticate"].startswith("Basic")
    for command in ("arm", "disarm", "stop", "reset"):
        assert page.request("POST", f"/gantry/{command}")[0] == 401
    assert page.commands == []


def test_scripts_use_basic_with_the_same_users(page: Page) -> None:
    status, _, body = page.request("GET", "/state.json", auth=VICTOR)
    assert status == 200 and json.loads(body)["robot"]["x_mm"] == 1.0
    assert page.request("GET", "/state.json", auth=(VICTOR[0], "wrong"))[0] == 401
    status, _, body = page.request("GET", "/video/observation.jpg", auth=VICTOR)
    assert status == 200 and body == b"\xff\xd8video"
    status, _, body = page.request("POST", "/gantry/arm", auth=VICTOR)
    assert status == 403 and "viewer" in json.loads(body)["detail"]
    status, _, body = page.request("POST", "/gantry/arm", auth=ALICE)
    assert status == 200 and json.loads(body)["accepted"] is True
    assert page.commands == [("arm", "alice (web 127.0.0.1)")]
    status, _, _ = page.request("POST", "/gantry/stop", auth=ALICE,
                                headers={"Origin": "https://evil.example"})
    assert status == 403 and len(page.commands) == 1


def test_a_browser_session_needs_its_csrf_token_and_ends_at_sign_out(page: Page) -> None:
    status, headers, _ = page.request("POST", "/signin", body={"user": "alice",
                                                                "password": ALICE[1]})
    assert status == 200
    flags = {f.strip().split("=")[0].lower() for f in headers["set-cookie"].split(";")}
    assert {"httponly", "max-age", "path", "samesite"} <= flags and "secure" not in flags
    assert "samesite=strict" in headers["set-cookie"].lower()
    cookie = headers["set-cookie"].split(";")[0]
    me = json.loads(page.request("GET", "/session.json", cookie=cookie)[2])
    assert me["user"] == "alice" and me["role"] == "operator" and me["may_command"]
    assert b"canvas" in page.request("GET", "/", cookie=cookie)[2], "the page itself"
    assert page.request("POST", "/gantry/stop", cookie=cookie)[0] == 403, "no CSRF token"
    assert page.request("POST", "/gantry/stop", cookie=cookie,
                        headers={"X-CSRF-Token": "forged"})[0] == 403
    ok = page.request("POST", "/gantry/stop", cookie=cookie, headers={"X-CSRF-Token": me["csrf"]})
    assert ok[0] == 200 and page.commands == [("stop", "alice (web 127.0.0.1)")]
    assert page.request("POST", "/signout", cookie=cookie)[0] == 200
    assert page.request("GET", "/state.json", cookie=cookie)[0] == 401


def test_a_viewer_session_sees_but_may_not_command(page: Page) -> None:
    cookie, csrf, _ = page.sign_in(VICTOR)
    assert page.request("GET", "/state.json", cookie=cookie)[0] == 200
    for command in ("arm", "disarm", "stop", "reset"):
        status, _, body = page.request("POST", f"/gantry/{command}", cookie=cookie,
                                       headers={"X-CSRF-Token": csrf})
        assert status == 403 and json.loads(body)["accepted"] is False
    assert page.commands == []


def test_twenty_wrong_passwords_end_refused_outright(page: Page) -> None:
    answers = []
    for i in range(20):
        status, headers, _ = page.request("POST", "/signin", body={"user": "alice",
                                                                    "password": f"guess{i}"})
        answers.append((status, headers.get("retry-after")))
    assert [s for s, _ in answers[:5]] == [401] * 5
    assert answers[19][0] == 429 and int(answers[19][1] or 0) >= 1
    assert page.request("POST", "/signin", body={"user": "alice", "password": ALICE[1]}
                        )[0] == 429, "the right password waits too"
    assert page.request("POST", "/signin", body="x", headers={"Content-Type": "text/plain"}
                        )[0] == 415, "another site's form cannot post a sign-in"


def _wrong_tries_each_forwarded_for_another(page: Page) -> list[int]:
    return [page.request("POST", "/signin", body={"user": "alice", "password": f"guess{i}"},
                         headers={"X-Forwarded-For": f"203.0.113.{i + 1}"})[0]
            for i in range(7)]


def test_x_forwarded_for_is_ignored_unless_from_a_configured_proxy(users_file: Path,
                                                                   tmp_path: Path) -> None:
    """A local process writing any address into X-Forwarded-For passed the sign-in brake
    (uvicorn trusts the header from loopback by default); now it is one address, braked,
    unless ``[web] trusted_proxies`` names the sender."""
    for page, _ in _serve(Users.load(users_file), tmp_path):
        assert _wrong_tries_each_forwarded_for_another(page)[5:] == [429, 429]
    for page, _ in _serve(Users.load(users_file), tmp_path, proxies=("127.0.0.1",)):
        assert _wrong_tries_each_forwarded_for_another(page) == [401] * 7, \
            "behind a configured proxy each client is braked on its own"


class HeldUsers(Users):
    """The users file whose password checks wait until ``release`` is set (as argon2 under a
    flood of sign-ins keeps them busy), once ``hold`` is set."""

    hold = threading.Event()
    release = threading.Event()
    started = threading.Semaphore(0)

    def verify(self, name: str, password: str) -> User | None:
        if self.hold.is_set():
            self.started.release()
            assert self.release.wait(60), "released by the test"
        return super().verify(name, password)


def test_a_stop_never_waits_behind_password_checks(users_file: Path, tmp_path: Path) -> None:
    users = HeldUsers.load(users_file)
    assert isinstance(users, HeldUsers)
    for page, _ in _serve(users, tmp_path):
        _stop_during_held_checks(page, users)


def _stop_during_held_checks(page: Page, users: HeldUsers) -> None:
    cookie, csrf, _ = page.sign_in(ALICE)
    users.hold.set()
    answers: list[tuple[int, dict[str, str]]] = []

    def wrong(i: int) -> None:
        status, headers, _ = page.request(
            "POST", "/signin", body={"user": "alice", "password": f"guess{i}"}, timeout_s=90)
        answers.append((status, headers))

    flood = [threading.Thread(target=wrong, args=(i,)) for i in range(60)]
    for thread in flood:
        thread.start()
    assert users.started.acquire(timeout=30), "a password check is under way"
    try:
        status, answer = page.command("stop", cookie, csrf)
        assert status == 200 and answer["accepted"], "the Stop, while checks are held"
        assert page.request("GET", "/state.json", cookie=cookie)[0] == 200
        # those past the lane's bound are refused at once, but the flood's threads may still
        # be sending theirs on a busy machine: wait for them, not for the held checks
        wait_for(lambda: sum(s == 503 for s, _ in answers) >= 60 - PASSWORDS_QUEUED,
                 timeout=30, why=lambda: f"past the lane's bound: refused, {len(answers)} answered")
        refused = [h for s, h in answers if s == 503]
        assert all(int(h["retry-after"]) >= 1 for h in refused)
        assert not users.release.is_set() and not any(s == 401 for s, _ in answers)
    finally:
        users.release.set()
        for thread in flood:
            thread.join(90)
    checked = [s for s, _ in answers if s != 503]
    assert checked and set(checked) <= {401, 429}, "the queued ones, checked or braked"
    assert len(checked) == PASSWORDS_QUEUED
    assert page.commands == [("stop", "alice (web 127.0.0.1)")]


def test_event_streams_are_bounded(users_file: Path, tmp_path: Path) -> None:
    for page, _ in _serve(Users.load(users_file), tmp_path, max_streams=2):
        streams = []
        for _ in range(2):
            conn = http.client.HTTPConnection("127.0.0.1", page.port, timeout=10)
            conn.request("GET", "/events", headers=basic(VICTOR))
            reply = conn.getresponse()
            assert reply.status == 200 and reply.readline().startswith(b"data: ")
            streams.append(conn)
        assert page.request("GET", "/events", auth=VICTOR)[0] == 503
        streams.pop().close()
        def freed(p: Page = page) -> bool:
            return p.request("GET", "/events", auth=VICTOR)[0] == 200

        wait_for(freed, timeout=10, period=0.05, why=lambda: "a closed stream frees its place")
        for conn in streams:
            conn.close()


def _certificate(tmp: Path) -> tuple[Path, Path]:
    cert, key = tmp / "web.pem", tmp / "web.key"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                    "ec_paramgen_curve:P-256", "-nodes", "-keyout", str(key), "-out", str(cert),
                    "-days", "2", "-subj", "/CN=127.0.0.1", "-addext",
                    "subjectAltName=IP:127.0.0.1"], check=True, capture_output=True, timeout=30)
    return cert, key


def test_over_tls_the_session_cookie_is_secure(users_file: Path, tmp_path: Path) -> None:
    for page, web in _serve(Users.load(users_file), tmp_path, tls=_certificate(tmp_path)):
        assert web.scheme == "https"
        status, headers, _ = page.request("POST", "/signin", body={"user": "alice",
                                                                    "password": ALICE[1]})
        assert status == 200 and "secure" in headers["set-cookie"].lower()
        assert page.request("GET", "/state.json", auth=ALICE)[0] == 200
        with pytest.raises((http.client.HTTPException, ConnectionError)):
            plain = http.client.HTTPConnection("127.0.0.1", page.port, timeout=5)
            plain.request("GET", "/state.json")
            plain.getresponse()


def test_a_bad_certificate_is_an_error_at_start(tmp_path: Path) -> None:
    (tmp_path / "bad.pem").write_text("not a certificate")
    gate = Gate(None, 60, tls=True)
    app = build_app(gate, dict, lambda c: None, lambda c: None, CraterImage(None),
                    push_period_s=1,
                    max_streams=1)
    with pytest.raises(OSError):
        WebServer(app, "127.0.0.1", 0, (tmp_path / "bad.pem", tmp_path / "bad.pem"))


def test_the_page_refuses_the_network_without_users() -> None:
    with pytest.raises(ValueError, match="users_file"):
        WebSettings(host="0.0.0.0")
    with pytest.raises(ValueError, match="tls_key"):
        WebSettings(tls_certificate=Path("a.pem"))
    assert WebSettings(host="0.0.0.0", users_file=Path("u.json")).host == "0.0.0.0"
    assert WebSettings(host="::1").users_file is None


def test_stb_web_on_the_network_without_users_stops_naming_the_field() -> None:
    done = stb_process("web", "--set", "host=0.0.0.0", "--set", "port=0")
    _, err = done.communicate(timeout=60)
    assert done.returncode == 2 and "users_file" in err, err


def test_stb_web_user_adds_lists_and_removes(tmp_path: Path) -> None:
    path = tmp_path / "users.json"

    def stb(*args: str, stdin: str = "") -> subprocess.CompletedProcess:
        process = stb_process("web", "user", *args, "--users", str(path),
                              stdin=subprocess.PIPE)
        out, err = process.communicate(stdin, timeout=60)
        return subprocess.CompletedProcess(args, process.returncode, out, err)

    added = stb("add", "carol", "--role", "operator", "--password-stdin",
                stdin="carol-password\n")
    assert added.returncode == 0, added.stderr
    assert Users.load(path).verify("carol", "carol-password") == User("carol", Role.OPERATOR)
    assert stb("list").stdout.split() == ["carol", "operator"]
    weak = stb("add", "dave", "--role", "viewer", "--password-stdin", stdin="short\n")
    assert weak.returncode == 1 and "at least 8" in weak.stderr
    assert stb("add", "dave", "--password-stdin", stdin="x\n").returncode == 2, "needs --role"
    assert stb("remove", "carol").returncode == 0 and not len(Users.load(path))
    gone = stb("remove", "carol")
    assert gone.returncode == 1 and "no user 'carol'" in gone.stderr
