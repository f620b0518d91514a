"""The lab's secured router (deploy/zenoh) for tests: secrets made by the real script."""

from __future__ import annotations

import subprocess
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import zenoh

from common.settings import TlsSettings, ZenohSettings
from tests.conftest import open_when_up, stb_process, wait_for
from tests.ports import free_port

ROOT = Path(__file__).resolve().parents[2]
ROUTER_CONFIG = ROOT / "deploy" / "zenoh" / "router.json5"
MAKE_SECRETS = ROOT / "deploy" / "zenoh" / "make-secrets"


def make_secrets(workdir: Path, *hosts: str) -> Path:
    """Run make-secrets so that ``workdir`` can be the router's working directory (the config
    names its files relative to it); returns the secrets folder."""
    secrets = workdir / "deploy" / "zenoh" / "secrets"
    args = [str(MAKE_SECRETS), "--out", str(secrets)]
    for host in hosts:
        args += ["--host", host]
    subprocess.run(args, check=True, capture_output=True, text=True, timeout=60)
    return secrets


@contextmanager
def secured_router(config: Path, workdir: Path, secrets: Path
                   ) -> Iterator[tuple[str, Callable[[str], zenoh.Session]]]:
    """``stb router --config CONFIG`` on a free loopback port, run from ``workdir`` (the
    config names its files relative to it): its endpoint, and ``session(user)`` opening a
    session as a lab identity (closed with the router)."""
    endpoint = f"tls/localhost:{free_port()}"
    router = stb_process("router", "--config", str(config), "--listen",
                         endpoint.replace("localhost", "127.0.0.1"), cwd=workdir)
    sessions: list[zenoh.Session] = []

    def session(user: str) -> zenoh.Session:
        sessions.append(open_when_up(identity(secrets, user, endpoint)))
        return sessions[-1]

    try:
        yield endpoint, session
    finally:
        for s in sessions:
            s.close()
        router.terminate()
        # longer than Zenoh's own close timeout (10 s: a session's close may wait that long
        # for its links before giving up, eclipse-zenoh/zenoh#2675), then the router is gone.
        # How fast a service stops on SIGTERM is tests/services/test_processes.py's subject,
        # not access control's: a router slower than that (once in a load tally, output lost)
        # is killed and reported as a warning with what it wrote
        try:
            router.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            router.kill()
            _, err = router.communicate(timeout=10)
            warnings.warn(f"stb router still ran 20 s after SIGTERM; killed. It wrote: "
                          f"{err[-3000:]}", stacklevel=1)


def identity(secrets: Path, user: str, endpoint: str, **changes: object) -> ZenohSettings:
    """Client settings of one lab identity (its password from its file, the lab's CA)."""
    values: dict = {"connect": [endpoint], "user": user,
                    "password_file": secrets / f"{user}.password",
                    "tls": TlsSettings(root_ca_certificate=secrets / "ca.pem"), **changes}
    return ZenohSettings(**values)


def identity_env(secrets: Path, user: str, endpoint: str) -> dict[str, str]:
    """The same as environment variables, as docker-compose.yml gives them to a service."""
    return {"STB_BUS__ZENOH__CONNECT": f'["{endpoint}"]', "STB_BUS__ZENOH__USER": user,
            "STB_BUS__ZENOH__PASSWORD_FILE": str(secrets / f"{user}.password"),
            "STB_BUS__ZENOH__TLS__ROOT_CA_CERTIFICATE": str(secrets / "ca.pem")}


def _collect(session: zenoh.Session, key_expr: str) -> tuple[list, object]:
    got: list[tuple[str, bytes]] = []
    sub = session.declare_subscriber(
        key_expr, lambda s: got.append((str(s.key_expr), s.payload.to_bytes())))
    return got, sub


def round_trip(session: zenoh.Session, timeout_s: float = 5.0) -> float:
    """A query to the router on ``session``'s own link, answered: the router has taken in (or
    refused) everything the session sent before it (one link, in order). Its seconds."""
    started = time.monotonic()
    list(session.liveliness().get("stb/alive/**", timeout=timeout_s))
    return time.monotonic() - started


def only_allowed_arrive(session: Callable[[str], zenoh.Session],
                        puts: list[tuple[str, str, bytes]], allowed: set[bytes]) -> None:
    """Each (account, key, payload) put three times; what arrives at a reader is exactly the
    ``allowed`` payloads (any account may read). ``session(account)``: a session as it."""
    sessions = {account: session(account) for account, _, _ in puts}
    got, _sub = _collect(session("tracker"), "stb/**")
    # the reader's subscription must reach the router first (a matching status cannot tell
    # it for the accounts the router denies: theirs never match): an allowed put, repeated
    # until the reader has it, says it has
    probe = next(((a, k, p) for a, k, p in puts if p in allowed), None)
    assert probe is not None, "an allowed put tells when the reader is subscribed, and when done"

    def heard_probe() -> int:
        return sum(p == probe[2] for _, p in got)

    wait_for(lambda: sessions[probe[0]].put(probe[1], probe[2]) or heard_probe(), timeout=10,
             period=0.05)
    for _ in range(3):
        for account, key, payload in puts:
            sessions[account].put(key, payload)
        time.sleep(0.05)  # paces the three rounds of puts
    wait_for(lambda: {p for _, p in got} >= allowed)
    # Nothing denied may arrive, so no arrival can say the router is done with it: a round
    # trip on each sender's own link says the router has routed or dropped its puts (one link,
    # in order); then one more allowed put, once the reader has it, came after anything the
    # router passed on to the reader before (one link to the reader, in order).
    for sender in sessions.values():
        round_trip(sender)
    before = heard_probe()
    wait_for(lambda: sessions[probe[0]].put(probe[1], probe[2]) or heard_probe() > before,
             timeout=10, period=0.05)
    payloads = {p for _, p in got}
    for _, _, denied in puts:
        assert denied in allowed or denied not in payloads, denied
