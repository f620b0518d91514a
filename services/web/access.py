"""Who is asking (pure, every clock is an argument): signed-in sessions, HTTP Basic, and the
brake on guessing passwords.

* A session is a random token in an HttpOnly, SameSite=Strict cookie, kept here with its user,
  its CSRF token and its expiry; a command needs both the cookie and the CSRF token.
* HTTP Basic (``curl -u NAME:PASSWORD``) with the same users, for scripts.
* Failed sign-ins are counted per client address; after ``free`` failures each further try
  waits twice as long as the last (1 s, 2 s, … up to ``longest_s``), and a try within that
  wait is refused without looking at the password. (Not per user name: then anyone could keep
  an operator from signing in by failing in their name.)
"""

from __future__ import annotations

import base64
import binascii
import secrets
from collections import Counter, OrderedDict
from dataclasses import dataclass

from services.web.users import Role, User


@dataclass(frozen=True)
class Session:
    user: User
    csrf: str
    expires_s: float


PER_USER = 20
"""Sessions one user may hold at once (browsers, tabs, scripts); a further sign-in ends that
user's oldest — never another user's (1,001 sign-ins by a viewer once ended the operator's)."""


class Sessions:
    """Signed-in sessions by token: at most ``per_user`` of one user (their oldest go first)
    and ``limit`` in all (then the expired go, and the oldest of whoever holds the most, a
    viewer's before an operator's: an operator must be able to press Stop)."""

    def __init__(self, lifetime_s: float, limit: int = 1000, per_user: int = PER_USER) -> None:
        self.lifetime_s, self.limit, self.per_user = lifetime_s, limit, per_user
        self._by_token: OrderedDict[str, Session] = OrderedDict()

    def open(self, user: User, now_s: float) -> tuple[str, Session]:
        token = secrets.token_urlsafe(32)
        session = Session(user, secrets.token_urlsafe(24), now_s + self.lifetime_s)
        own = [t for t, s in self._by_token.items() if s.user.name == user.name]
        for old in own[:max(0, len(own) - self.per_user + 1)]:
            del self._by_token[old]
        if len(self._by_token) >= self.limit:
            for old in [t for t, s in self._by_token.items() if now_s >= s.expires_s]:
                del self._by_token[old]
        while len(self._by_token) >= self.limit:  # who gives way: the most sessions, a
            counts = Counter(s.user.name for s in self._by_token.values())  # viewer first
            victim = min(self._by_token.items(), key=lambda item: (
                -counts[item[1].user.name], item[1].user.role == Role.OPERATOR))[0]
            del self._by_token[victim]
        self._by_token[token] = session
        return token, session

    def get(self, token: str | None, now_s: float) -> Session | None:
        if not token:
            return None
        session = self._by_token.get(token)
        if session is not None and now_s >= session.expires_s:
            del self._by_token[token]
            return None
        return session

    def close(self, token: str | None) -> None:
        if token:
            self._by_token.pop(token, None)

    def close_user(self, name: str) -> None:
        """End every session of ``name`` (the user was removed or their role changed)."""
        for token in [t for t, s in self._by_token.items() if s.user.name == name]:
            del self._by_token[token]


def basic_credentials(header: str | None) -> tuple[str, str] | None:
    """(name, password) from an ``Authorization: Basic …`` header, or None."""
    scheme, _, encoded = (header or "").partition(" ")
    if scheme.lower() != "basic" or not encoded:
        return None
    try:
        name, sep, password = base64.b64decode(encoded.strip(), validate=True).decode(
            "utf-8").partition(":")
    except (binascii.Error, UnicodeDecodeError):
        return None
    return (name, password) if sep else None


@dataclass
class _Failures:
    count: int = 0
    last_s: float = 0.0


class SignInBrake:
    """Slows down password guessing from one client address."""

    def __init__(self, free: int = 5, first_wait_s: float = 1.0, longest_s: float = 300.0,
                 forget_s: float = 3600.0, limit: int = 10_000) -> None:
        self.free, self.first_wait_s, self.longest_s = free, first_wait_s, longest_s
        self.forget_s, self.limit = forget_s, limit
        self._failures: OrderedDict[str, _Failures] = OrderedDict()

    def wait_s(self, client: str, now_s: float) -> float:
        """How long ``client`` must wait before its next try; 0 when it may go ahead."""
        entry = self._failures.get(client)
        if entry is None or entry.count < self.free:
            return 0.0
        wait = min(self.longest_s, self.first_wait_s * 2.0 ** (entry.count - self.free))
        return max(0.0, entry.last_s + wait - now_s)

    def failed(self, client: str, now_s: float) -> int:
        """Count a failed sign-in; the number of failures in a row from ``client``."""
        entry = self._failures.pop(client, None) or _Failures()
        if now_s - entry.last_s > self.forget_s:
            entry = _Failures()
        entry.count += 1
        entry.last_s = now_s
        self._failures[client] = entry  # to the end: the least recently failed go first
        while len(self._failures) > self.limit:
            self._failures.popitem(last=False)
        return entry.count

    def succeeded(self, client: str) -> None:
        self._failures.pop(client, None)
