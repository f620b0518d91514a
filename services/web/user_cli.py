"""``stb web user add|list|remove``: who may sign in to the operator's page.

    stb web user add NAME --role operator|viewer [--password-stdin]
    stb web user list
    stb web user remove NAME

The users file is ``[web] users_file`` of the lab file (``--lab``), or ``--users FILE``. It
holds argon2 hashes only; keep it readable by the web service alone (compose mounts it as a
secret). A viewer sees everything and commands nothing; an operator also commands the
gantry. A running page reads the file at start: restart it (``docker compose restart web``)
for a change to apply. Exit status: 0 done, 1 refused (no such user, a weak password), 2 bad
arguments or file.
"""

from __future__ import annotations

import argparse
import getpass
import sys
from collections.abc import Sequence
from pathlib import Path

from services.args import EXIT_CONFIG, base_parser

EXIT_REFUSED = 1


def main(argv: Sequence[str]) -> int:
    parser = base_parser("stb web user", __doc__ or "")
    parser.add_argument("action", choices=["add", "list", "remove"])
    parser.add_argument("name", nargs="?", help="the user's name (add, remove)")
    parser.add_argument("--role", choices=["viewer", "operator"], help="add: what they may do")
    parser.add_argument("--users", type=Path, metavar="FILE",
                        help="the users file (default: [web] users_file of the lab file)")
    parser.add_argument("--password-stdin", action="store_true",
                        help="add: read the password from the first line of standard input")
    args = parser.parse_args(argv)
    if args.action != "list" and not args.name:
        parser.error(f"{args.action} needs the user's NAME")
    if args.action == "add" and not args.role:
        parser.error("add needs --role viewer or --role operator")
    from services.entry import ToolError, tool_main

    def run() -> int:
        path = args.users or _users_file_of_lab(args)
        if path is None:
            raise ToolError("no users file: give --users FILE or set [web] users_file in the "
                            "lab file (--lab)")
        return _act(args, path)

    return tool_main("web user", run)


def _users_file_of_lab(args: argparse.Namespace) -> Path | None:
    from services.entry import tool_settings
    from services.web.settings import WebSettings

    return tool_settings(WebSettings, args).users_file


def _act(args: argparse.Namespace, path: Path) -> int:
    from services.entry import ToolError
    from services.web.users import Role, Users, UsersFileError

    try:
        users = Users.load(path)
        if args.action == "list":
            for user in users.list():
                print(f"{user.name}\t{user.role}")
            if not len(users):
                print(f"no users in {path}", file=sys.stderr)
            return 0
        if args.action == "remove":
            users.remove(args.name)
            print(f"removed {args.name} from {path}")
            return 0
        users.add(args.name, Role(args.role), _password(args.password_stdin))
    except UsersFileError as err:
        raise ToolError(str(err), EXIT_CONFIG) from err
    except KeyError:
        raise ToolError(f"no user {args.name!r} in {path}", EXIT_REFUSED) from None
    except ValueError as err:
        raise ToolError(str(err), EXIT_REFUSED) from err
    except OSError as err:
        raise ToolError(f"cannot write {path}: {err.strerror}", EXIT_CONFIG) from err
    print(f"{args.name} ({args.role}) may sign in: {path}")
    return 0


def _password(from_stdin: bool) -> str:
    if from_stdin:
        return sys.stdin.readline().rstrip("\r\n")
    first = getpass.getpass("password: ")
    if getpass.getpass("again: ") != first:
        raise ValueError("the two passwords differ")
    return first
