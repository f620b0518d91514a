"""The page's users: names, roles and argon2 password hashes in one JSON file (a secret).

A *viewer* sees everything the page shows and commands nothing; an *operator* also commands
the gantry. The file holds only hashes (argon2id, ``argon2-cffi``'s defaults), is written
whole through a temporary file and a rename (readers never see half a file), readable by its
owner only when it is new (a deployment's own mode is kept)::

    {"users": {"alice": {"role": "operator", "hash": "$argon2id$v=19$..."}}}
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from enum import StrEnum
from functools import cache
from pathlib import Path

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError, VerifyMismatchError

from common.files import write_atomically

NAME = re.compile(r"^[A-Za-z0-9_.@-]{1,64}$")
MIN_PASSWORD = 8
_HASHER = PasswordHasher()


@cache
def _dummy_hash() -> str:
    """Checked for a name that is no user's: the same work as a wrong password. Made at the
    first such check, not at import: an argon2 hash takes 0.22 s of a core, and a killed page
    took 2.2 s instead of about 1 s to come back in the fault campaign."""
    return _HASHER.hash("no such user: the same work as a wrong password")


class Role(StrEnum):
    VIEWER = "viewer"
    OPERATOR = "operator"


class UsersFileError(ValueError):
    """The users file cannot be read or is not a users file; the message names the file."""


@dataclass(frozen=True)
class User:
    name: str
    role: Role

    @property
    def may_command(self) -> bool:
        return self.role is Role.OPERATOR


class Users:
    """The users file, read once; ``verify`` answers sign-ins, ``add``/``remove`` rewrite it."""

    def __init__(self, path: Path, entries: dict[str, tuple[Role, str]]) -> None:
        self.path = path
        self._entries = entries

    @classmethod
    def load(cls, path: Path) -> Users:
        """The users in ``path``; a missing file is no users (``add`` creates it)."""
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return cls(path, {})
        except (OSError, UnicodeDecodeError) as err:
            raise UsersFileError(f"users file {path}: cannot read it ({err})") from err
        return cls(path, _parse(path, text))

    def __len__(self) -> int:
        return len(self._entries)

    def list(self) -> list[User]:
        return [User(name, role) for name, (role, _) in sorted(self._entries.items())]

    def verify(self, name: str, password: str) -> User | None:
        """The user if ``password`` is theirs, else None (an unknown name costs the same)."""
        role, stored = self._entries.get(name) or (None, _dummy_hash())
        try:
            _HASHER.verify(stored, password)
        except (VerifyMismatchError, VerificationError, InvalidHashError):
            return None
        return None if role is None else User(name, role)

    def add(self, name: str, role: Role, password: str) -> None:
        """Add ``name`` or replace their role and password, then write the file."""
        if not NAME.match(name):
            raise ValueError(f"user name {name!r}: 1-64 of A-Z a-z 0-9 _ . @ -")
        if len(password) < MIN_PASSWORD:
            raise ValueError(f"password: at least {MIN_PASSWORD} characters")
        self._entries[name] = (Role(role), _HASHER.hash(password))
        self._write()

    def remove(self, name: str) -> None:
        if name not in self._entries:
            raise KeyError(name)
        del self._entries[name]
        self._write()

    def _write(self) -> None:
        body = {"users": {name: {"role": str(role), "hash": stored}
                          for name, (role, stored) in sorted(self._entries.items())}}
        try:  # keep the mode a deployment gave the file (compose reads it as another user)
            mode = self.path.stat().st_mode & 0o777
        except FileNotFoundError:
            mode = 0o600
        write_atomically(self.path, json.dumps(body, indent=1).encode() + b"\n", mode=mode)


def _parse(path: Path, text: str) -> dict[str, tuple[Role, str]]:
    try:
        users = json.loads(text)["users"]
        return {str(name): (Role(entry["role"]), str(entry["hash"]))
                for name, entry in users.items()}
    except (ValueError, KeyError, TypeError, AttributeError) as err:
        raise UsersFileError(f"users file {path} is not a users file ({err!r}); make one "
                             "with: stb web user add NAME --role operator") from err

