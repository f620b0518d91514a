"""Fixtures of the process tests: a bus client that watches liveliness."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from common.bus import Bus, open_session
from tests.conftest import client_settings
from tests.services.test_processes import AliveWatcher


@pytest.fixture
def observer(router_endpoint: str) -> Iterator[tuple[Bus, AliveWatcher]]:
    settings = client_settings(router_endpoint)
    session = open_session(settings.zenoh)
    bus = Bus(session, settings)
    try:
        yield bus, AliveWatcher(session)
    finally:
        bus.close()
        session.close()
