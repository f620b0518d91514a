"""Session helpers: peer and client modes, user/password, TLS settings passed through."""

from __future__ import annotations

import json
import queue
import time
from pathlib import Path

import pytest
from pydantic import SecretStr

from common import keys
from common import messages as m
from common.bus import Bus, BusUnreachable, open_session, zenoh_config
from common.settings import BusSettings, TlsSettings, ZenohSettings
from common.wiredoc import example
from tests.conftest import free_port, until_heard


def test_two_peers_talk_without_a_router() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    a = open_session(ZenohSettings(mode="peer", listen=[endpoint], connect=[]))
    b = open_session(ZenohSettings(mode="peer", connect=[endpoint]))
    bus_a, bus_b = Bus(a, BusSettings()), Bus(b, BusSettings())
    try:
        got: queue.Queue[m.CraneState] = queue.Queue()
        bus_b.subscribe(keys.GANTRY_STATE, got.put)
        until_heard(bus_a, "stb/gantry/state")
        bus_a.publish(keys.GANTRY_STATE, example(m.CraneState).model_copy(
            update={"measured_s": time.time()}))
        assert got.get(timeout=3).status == "tracking"
    finally:
        for bus, session in ((bus_a, a), (bus_b, b)):
            bus.close()
            session.close()


def test_user_and_password_are_enforced_by_the_router(tmp_path: Path) -> None:
    users = tmp_path / "users.txt"
    users.write_text("gantry:right-secret\n")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_session(ZenohSettings(mode="router", listen=[endpoint], connect=[],
                                        users_file=users))
    try:
        def client(user: str | None, password: str | None) -> ZenohSettings:
            return ZenohSettings(connect=[endpoint], user=user, connect_timeout_ms=0,
                                 password=SecretStr(password) if password else None)

        open_session(client("gantry", "right-secret")).close()
        for user, password in (("gantry", "wrong"), ("nobody", "right-secret"), (None, None)):
            with pytest.raises(BusUnreachable, match="cannot open a Zenoh client session"):
                open_session(client(user, password))
    finally:
        router.close()


def test_tls_settings_reach_the_zenoh_config() -> None:
    tls = TlsSettings(root_ca_certificate=Path("/pki/ca.pem"), certificate=Path("/pki/g.pem"),
                      private_key=Path("/pki/g.key"), enable_mtls=True)
    client = zenoh_config(ZenohSettings(connect=["tls/router.lab:7447"], tls=tls))
    got = json.loads(client.get_json("transport/link/tls"))
    assert got["root_ca_certificate"] == "/pki/ca.pem"
    assert got["connect_certificate"] == "/pki/g.pem" and got["connect_private_key"] == "/pki/g.key"
    assert got["enable_mtls"] is True
    router = zenoh_config(ZenohSettings(mode="router", listen=["tls/0.0.0.0:7447"], connect=[],
                                        tls=tls))
    got = json.loads(router.get_json("transport/link/tls"))
    assert got["listen_certificate"] == "/pki/g.pem" and got["listen_private_key"] == "/pki/g.key"


def test_scouting_is_off_and_reconnection_is_fast_by_default() -> None:
    cfg = zenoh_config(ZenohSettings())
    assert json.loads(cfg.get_json("scouting/multicast/enabled")) is False
    assert json.loads(cfg.get_json("connect/retry"))["period_max_ms"] == 500
    assert json.loads(cfg.get_json("mode")) == "client"


def test_the_shared_memory_pool_is_sized_from_the_settings() -> None:
    """Every receiver maps each sender's pool: 4 MiB by default, not Zenoh's 16 MiB."""
    path = "transport/shared_memory/transport_optimization/pool_size"
    assert json.loads(zenoh_config(ZenohSettings()).get_json(path)) == 4 * 1024 * 1024
    assert json.loads(zenoh_config(ZenohSettings(shm_pool_mib=1.5)).get_json(path)) == 1572864
