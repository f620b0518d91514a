"""The tracker → PTZ peer link (docs/deployment.md): two services as Zenoh peers, our settings
only. Robot samples go straight from one to the other — still arriving with the router gone —
and, with the router there too, each arrives once."""

from __future__ import annotations

import queue
import time

from common import keys
from common import messages as m
from common.bus import Bus, open_session
from common.settings import BusSettings, ZenohSettings
from common.wiredoc import example
from tests.conftest import wait_for
from tests.ports import free_port


def _peer(router: str) -> Bus:
    settings = BusSettings(zenoh=ZenohSettings(mode="peer", connect=[router],
                                               listen=["tcp/127.0.0.1:0"]))
    return Bus(open_session(settings.zenoh), settings)


def test_robot_samples_go_straight_from_tracker_to_ptz_and_arrive_once() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_session(ZenohSettings(mode="router", listen=[endpoint], connect=[]))
    tracker, ptz = _peer(endpoint), _peer(endpoint)
    try:
        got: queue.Queue[m.RobotPosition] = queue.Queue()
        ptz.subscribe(keys.TRACKER_ROBOT, got.put, latest=False)  # every one, in order
        # the router tells each peer where the other listens (gossip); they connect directly
        assert wait_for(lambda: list(tracker.session.info.peers_zid()), timeout=10)

        def send(x_mm: float) -> None:
            tracker.publish(keys.TRACKER_ROBOT, example(m.RobotPosition).model_copy(
                update={"x_mm": x_mm, "measured_s": time.time()}))

        def probed() -> bool:
            send(0.0)
            return not got.empty()

        wait_for(probed, timeout=5)  # the subscription is known
        send(-1.0)  # in order behind the probes: once it is taken, so are they
        wait_for(lambda: got.get(timeout=5).x_mm == -1.0, timeout=10, period=0.0)
        for i in range(20):
            send(float(i + 1))
        wait_for(lambda: got.qsize() >= 20, timeout=5)
        time.sleep(0.3)  # the subject: no second copy comes (not through the router too)
        assert [got.get_nowait().x_mm for _ in range(got.qsize())] == [i + 1 for i in range(20)]

        router.close()  # the router gone: the peer link carries them on
        for i in range(5):
            send(100.0 + i)
        assert [got.get(timeout=2).x_mm for _ in range(5)] == [100.0 + i for i in range(5)]
    finally:
        tracker.close()
        ptz.close()
        tracker.session.close()
        ptz.session.close()
        router.close()
