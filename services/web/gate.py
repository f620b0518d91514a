"""The page's door: who a request comes from, signing in and out, and what they may do.

With a users file, every request needs a signed-in session (cookie) or HTTP Basic with one of
its users. Without one (allowed only on loopback, ``WebSettings``), everyone who reaches the
page is the local operator, and the page says so. Commands always need the operator role and,
from a browser, the session's CSRF token; HTTP Basic commands from another site's page (an
``Origin`` not our own) are refused, since a browser may send cached Basic credentials on its
own.
"""

from __future__ import annotations

import hashlib
import logging
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import urlsplit

from common.messages import who
from services.web.access import Session, Sessions, SignInBrake, basic_credentials
from services.web.users import Role, User, Users

log = logging.getLogger(__name__)
COOKIE = "stb_session"
LOCAL = User("local", Role.OPERATOR)
BASIC_REMEMBERED_S = 60.0  # a script's Basic credentials, checked once a minute, not per request


@dataclass(frozen=True)
class Caller:
    """Who asks: the user, from where, how (``session``, ``basic`` or ``open``), and the CSRF
    token that goes with a session."""

    user: User
    address: str
    how: str
    csrf: str = ""

    @property
    def label(self) -> str:
        """How a command names them on the bus and in the logs: ``alice (web 10.0.0.5)``."""
        return who(f"{self.user.name} (web {self.address})")


@dataclass(frozen=True)
class SignIn:
    """A sign-in's outcome: a session token, or the HTTP status and why not."""

    token: str | None
    session: Session | None
    status: int
    detail: str
    retry_after_s: float = 0.0


class Gate:
    """Sessions, Basic auth and the sign-in brake over one users file (or none: open)."""

    def __init__(self, users: Users | None, session_s: float, *, tls: bool,
                 clock: Callable[[], float] = time.time, brake: SignInBrake | None = None
                 ) -> None:
        self.users, self.tls, self.clock = users, tls, clock
        self.sessions = Sessions(session_s)
        self.brake = brake or SignInBrake()
        self.open_csrf = secrets.token_urlsafe(24)
        self._lock = threading.Lock()
        self._salt = secrets.token_bytes(16)
        self._basic: dict[bytes, tuple[User, float]] = {}

    @property
    def is_open(self) -> bool:
        return self.users is None

    def caller(self, cookie: str | None, authorization: str | None, address: str
               ) -> Caller | None:
        """Who sent a request, or None (not signed in; wrong or braked Basic credentials).
        May check a password (argon2: run it in the password lane, ``lanes.py``)."""
        known, needs_check = self.caller_at_once(cookie, authorization, address)
        if not needs_check:
            return known
        credentials = basic_credentials(authorization)
        assert credentials is not None
        user = self._basic_user(authorization or "", credentials, address)
        return None if user is None else Caller(user, address, "basic")

    def caller_at_once(self, cookie: str | None, authorization: str | None, address: str
                       ) -> tuple[Caller | None, bool]:
        """Who sent a request as far as it is known without checking a password: (the caller
        or None, whether Basic credentials still need a check — then ask ``caller``)."""
        if self.users is None:
            return Caller(LOCAL, address, "open", self.open_csrf), False
        with self._lock:
            session = self.sessions.get(cookie, self.clock())
        if session is not None:
            return Caller(session.user, address, "session", session.csrf), False
        if basic_credentials(authorization) is None:
            return None, False
        digest = self._digest(authorization or "")
        with self._lock:
            remembered = self._basic.get(digest)
            if remembered is not None and self.clock() < remembered[1]:
                return Caller(remembered[0], address, "basic"), False
        return None, True

    def sign_in(self, name: str, password: str, address: str) -> SignIn:
        if self.users is None:
            return SignIn(None, None, 404, "this page has no users: no sign-in needed")
        with self._lock:
            wait = self.brake.wait_s(address, self.clock())
        if wait > 0:
            log.warning("sign-in as %r from %s refused: %.0f s to wait after failed tries",
                        name, address, wait)
            return SignIn(None, None, 429, f"too many failed sign-ins from {address}: try "
                          f"again in {wait:.0f} s", wait)
        user = self._check_password(name, password, address)
        if user is None:
            return SignIn(None, None, 401, "wrong user name or password")
        with self._lock:
            token, session = self.sessions.open(user, self.clock())
        log.info("%s (%s) signed in from %s", user.name, user.role, address)
        return SignIn(token, session, 200, "signed in")

    def sign_out(self, cookie: str | None) -> None:
        with self._lock:
            self.sessions.close(cookie)

    def forget(self, name: str) -> None:
        """End ``name``'s sessions and remembered Basic credentials."""
        with self._lock:
            self.sessions.close_user(name)
            self._basic = {k: v for k, v in self._basic.items() if v[0].name != name}

    def _basic_user(self, header: str, credentials: tuple[str, str], address: str
                    ) -> User | None:
        digest, now = self._digest(header), self.clock()
        user = self._check_password(*credentials, address)
        if user is not None:
            with self._lock:
                self._basic = {k: v for k, v in self._basic.items() if now < v[1]}
                self._basic[digest] = (user, now + BASIC_REMEMBERED_S)
        return user

    def _digest(self, header: str) -> bytes:
        return hashlib.sha256(self._salt + header.encode()).digest()

    def _check_password(self, name: str, password: str, address: str) -> User | None:
        assert self.users is not None
        with self._lock:
            if self.brake.wait_s(address, self.clock()) > 0:
                return None
        user = self.users.verify(name[:64], password[:1024])
        with self._lock:
            if user is not None:
                self.brake.succeeded(address)
                return user
            failures = self.brake.failed(address, self.clock())
        log.warning("failed sign-in as %r from %s (%d in a row)", name[:64], address, failures)
        return None


def command_refusal(caller: Caller | None, csrf_header: str | None, origin: str | None,
                    host: str | None) -> tuple[int, str] | None:
    """Why a command may not go ahead (HTTP status, reason), or None when it may."""
    if caller is None:
        return 401, "sign in first"
    if not caller.user.may_command:
        return 403, f"{caller.user.name} is a {caller.user.role}: viewers do not command"
    if caller.how == "basic":
        if origin and urlsplit(origin).netloc != host:
            return 403, f"a command from another site's page ({origin}) is refused"
        return None
    if not csrf_header or not secrets.compare_digest(csrf_header, caller.csrf):
        return 403, "missing or wrong CSRF token (X-CSRF-Token): reload the page"
    return None
