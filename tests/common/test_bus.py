"""The bus over real Zenoh sessions on loopback: delivery, bad input, staleness, latest-first."""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

import msgpack
import pytest

from common import codec, keys
from common import messages as m
from common.bus import MAX_KEYS, OTHER_KEYS, Bus
from common.node import Node
from common.settings import ServiceSettings
from common.wiredoc import example
from tests.common.test_codec import BAD
from tests.conftest import until_heard, wait_for

ROBOT_KEY = "stb/tracker/robot"


def _robot(x_mm: float = 1.0, measured_s: float | None = None) -> m.RobotPosition:
    return example(m.RobotPosition).model_copy(
        update={"x_mm": x_mm, "measured_s": measured_s or time.time()})


def test_typed_message_arrives_with_both_time_stamps(make_bus: Callable[..., Bus]) -> None:
    producer, consumer = make_bus(), make_bus()
    got: queue.Queue[m.RobotPosition] = queue.Queue()
    consumer.subscribe(keys.TRACKER_ROBOT, got.put)
    until_heard(producer, ROBOT_KEY)
    sent = _robot(x_mm=42.0, measured_s=time.time() - 0.05)
    before = time.time()
    producer.publish(keys.TRACKER_ROBOT, sent)
    msg = got.get(timeout=2)
    assert msg.x_mm == 42.0 and msg.measured_s == sent.measured_s
    assert before <= msg.sent_s <= time.time()
    assert consumer.key_stats()["stb/tracker/robot"].received == 1
    assert producer.key_stats()["stb/tracker/robot"].published == 1


def test_publish_refuses_the_wrong_model(make_bus: Callable[..., Bus]) -> None:
    with pytest.raises(TypeError, match="carries RobotPosition"):
        wrong: Any = example(m.CraneSetpoint)
        make_bus().publish(keys.TRACKER_ROBOT, wrong)


@pytest.mark.parametrize("case", BAD, ids=list(BAD))
def test_bad_payload_is_dropped_counted_and_the_next_good_one_arrives(
        make_bus: Callable[..., Bus], case: str) -> None:
    producer, consumer = make_bus(), make_bus()
    got: queue.Queue[m.RobotPosition] = queue.Queue()
    consumer.subscribe(keys.TRACKER_ROBOT, got.put)
    until_heard(producer, ROBOT_KEY)
    payload, reason = BAD[case]
    producer.session.put("stb/tracker/robot", payload)
    # dropped for its reason (not only received: a good sample that came before the worker
    # took the bad one would supersede it in the newest-only slot)
    wait_for(lambda: (stats := consumer.key_stats().get("stb/tracker/robot")) is not None
             and stats.dropped == {reason: 1},
             why=lambda: str(consumer.key_stats().get("stb/tracker/robot")))
    producer.publish(keys.TRACKER_ROBOT, _robot(x_mm=7.0))
    assert got.get(timeout=2).x_mm == 7.0
    assert got.empty()
    stats = consumer.key_stats()["stb/tracker/robot"]
    assert stats.dropped == {reason: 1} and stats.received == 2


def test_stale_and_future_samples_never_reach_the_handler(make_bus: Callable[..., Bus]) -> None:
    producer, consumer = make_bus(), make_bus(max_age_s=0.2, max_future_s=0.2)
    got: queue.Queue[m.RobotPosition] = queue.Queue()
    consumer.subscribe(keys.TRACKER_ROBOT, got.put)
    until_heard(producer, ROBOT_KEY)
    now = time.time()
    for x_mm, sent_s in ((1.0, now - 1.0), (2.0, now + 1.0)):
        producer.session.put("stb/tracker/robot", codec.encode(_robot(x_mm), sent_s=sent_s))
        def dropped(n: float = x_mm) -> bool:
            stats = consumer.key_stats().get("stb/tracker/robot")
            return stats is not None and sum(stats.dropped.values()) == n

        wait_for(dropped)
    producer.publish(keys.TRACKER_ROBOT, _robot(3.0))
    assert got.get(timeout=2).x_mm == 3.0
    assert consumer.key_stats()["stb/tracker/robot"].dropped == {"stale": 1, "from_future": 1}


def test_a_publisher_with_max_age_does_not_send_what_is_already_stale(
        make_bus: Callable[..., Bus]) -> None:
    """The age is judged at the ``sent_s`` stamp receivers judge it by: a sample measured
    longer ago than ``max_age_s`` is counted as stale by its publisher and never put."""
    producer, consumer = make_bus(), make_bus()
    got: queue.Queue[m.RobotPosition] = queue.Queue()
    consumer.subscribe(keys.TRACKER_ROBOT, got.put, latest=False)
    until_heard(producer, ROBOT_KEY)
    assert not producer.publish(keys.TRACKER_ROBOT, _robot(1.0, time.time() - 0.6),
                                max_age_s=0.5)
    assert producer.publish(keys.TRACKER_ROBOT, _robot(2.0, time.time() - 0.1), max_age_s=0.5)
    arrived = got.get(timeout=2)
    assert arrived.x_mm == 2.0 and arrived.sent_s - arrived.measured_s <= 0.5
    assert got.empty()
    stats = producer.key_stats()["stb/tracker/robot"]
    assert stats.dropped == {"stale": 1} and stats.published == 1


def test_slow_consumer_gets_the_latest_value_and_never_holds_back_the_producer(
        make_bus: Callable[..., Bus]) -> None:
    """The consumer's handler is held (as by slow work) until the producer has published all
    500 and they have reached the consumer: the producer finishes meanwhile, and the handler
    then gets the newest, not the 498 it missed."""
    producer, consumer = make_bus(), make_bus()
    seen: list[float] = []
    busy, release, last = threading.Event(), threading.Event(), threading.Event()
    newest = threading.Event()  # the consumer's session has the last sample (another handler)

    def slow(msg: m.RobotPosition) -> None:
        busy.set()
        release.wait(10)
        seen.append(msg.x_mm)
        if msg.x_mm == 499:
            last.set()

    def heard(msg: m.RobotPosition) -> None:
        if msg.x_mm == 499:
            newest.set()

    consumer.subscribe(keys.TRACKER_ROBOT, slow)
    consumer.subscribe(keys.TRACKER_ROBOT, heard, latest=False)
    until_heard(producer, ROBOT_KEY)
    producer.publish(keys.TRACKER_ROBOT, _robot(0.0))
    assert busy.wait(5), "the first sample reaches the handler"
    for i in range(1, 500):  # the handler still holds the first: the producer must not wait
        producer.publish(keys.TRACKER_ROBOT, _robot(float(i)))
    assert newest.wait(5), "every sample reached the consumer's session"
    release.set()
    assert last.wait(5), "the newest sample must arrive"
    assert len(seen) < 5, f"a slow consumer sees latest values, not a backlog ({seen})"
    assert seen == sorted(seen)


def test_latest_value_is_kept_per_key(make_bus: Callable[..., Bus]) -> None:
    producer, consumer = make_bus(), make_bus()
    got: list[str] = []
    gate = threading.Event()

    def handler(msg: m.PtzState) -> None:
        gate.wait(2)
        got.append(msg.camera)

    consumer.subscribe(keys.PTZ_STATE, handler)
    until_heard(producer, "stb/ptz/ptz1/state")
    state = example(m.PtzState)
    for camera in ("ptz1", "ptz2", "ptz1", "ptz2"):
        producer.publish(keys.PTZ_STATE, state.model_copy(
            update={"camera": camera, "measured_s": time.time()}), camera=camera)
    wait_for(lambda: all(consumer.key_stats().get(f"stb/ptz/{c}/state") is not None
                         and consumer.key_stats()[f"stb/ptz/{c}/state"].received == 2
                         for c in ("ptz1", "ptz2")), why=lambda: str(consumer.key_stats()))
    gate.set()
    wait_for(lambda: len(got) >= 2)
    # a last sample on a third key: it is queued behind whatever is still kept, so once it is
    # handled nothing that came before is left (the superseded samples are gone)
    producer.publish(keys.PTZ_STATE, state.model_copy(
        update={"camera": "ptz3", "measured_s": time.time()}), camera="ptz3")
    wait_for(lambda: "ptz3" in got)
    before = got[:got.index("ptz3")]
    assert sorted(before[-2:]) == ["ptz1", "ptz2"], "one camera must not hide the other"
    assert len(before) <= 3


def test_handler_error_is_counted_and_the_subscription_goes_on(
        make_bus: Callable[..., Bus]) -> None:
    producer, consumer = make_bus(), make_bus()
    got: queue.Queue[float] = queue.Queue()

    def fragile(msg: m.RobotPosition) -> None:
        if msg.x_mm < 0:
            raise RuntimeError("bug in a handler")
        got.put(msg.x_mm)

    consumer.subscribe(keys.TRACKER_ROBOT, fragile)
    until_heard(producer, ROBOT_KEY)
    producer.publish(keys.TRACKER_ROBOT, _robot(-1.0))
    wait_for(lambda: consumer.key_stats().get("stb/tracker/robot")
             and consumer.key_stats()["stb/tracker/robot"].dropped.get("handler_error"))
    producer.publish(keys.TRACKER_ROBOT, _robot(5.0))
    assert got.get(timeout=2) == 5.0
    assert consumer.key_stats()["stb/tracker/robot"].dropped == {"handler_error": 1}


def test_ordered_subscription_delivers_every_sample(make_bus: Callable[..., Bus]) -> None:
    producer, consumer = make_bus(), make_bus()
    got: list[int] = []
    consumer.subscribe(keys.GANTRY_SETPOINT, lambda s: got.append(s.seq), latest=False)
    until_heard(producer, "stb/gantry/setpoint")
    for seq in range(50):
        producer.publish(keys.GANTRY_SETPOINT, example(m.CraneSetpoint).model_copy(
            update={"seq": seq, "measured_s": time.time()}))
    wait_for(lambda: len(got) == 50)
    assert got == list(range(50))


def test_late_joiner_gets_the_latest_pose_by_query(make_bus: Callable[..., Bus]) -> None:
    calib, ptz = make_bus(), make_bus()
    pose = example(m.CameraPose)
    calib.serve_latest(keys.CALIB_POSE, lambda: pose, camera="ptz1")
    answers = wait_for(lambda: ptz.query_latest(keys.CALIB_POSE, camera="ptz1"),
                       why=lambda: "the queryable never answered")
    assert [a.model_copy(update={"sent_s": 0.0}) for a in answers] == [pose]


def test_prefix_separates_two_labs(make_bus: Callable[..., Bus]) -> None:
    lab_a, lab_b = make_bus(prefix="laba"), make_bus(prefix="labb")
    got: queue.Queue[m.RobotPosition] = queue.Queue()
    lab_b.subscribe(keys.TRACKER_ROBOT, got.put)
    until_heard(lab_a, "labb/tracker/robot")  # lab b's subscriber is known to lab a's session
    lab_a.publish(keys.TRACKER_ROBOT, _robot())
    with pytest.raises(queue.Empty):
        got.get(timeout=0.5)


def test_generic_subscription_decodes_known_and_unknown_keys(
        make_bus: Callable[..., Bus]) -> None:
    producer, monitor = make_bus(), make_bus()
    got: queue.Queue = queue.Queue()
    monitor.subscribe_any("stb/**", got.put)
    until_heard(producer, "stb/custom/thing")
    producer.publish(keys.TRACKER_ROBOT, _robot(9.0))
    producer.session.put("stb/custom/thing", msgpack.packb({"a": 1}))
    items = dict(got.get(timeout=2) for _ in range(2))
    assert items["stb/tracker/robot"].x_mm == 9.0
    assert items["stb/custom/thing"] == {"a": 1}


def test_drop_counts_show_in_the_published_health(make_bus: Callable[..., Bus]) -> None:
    bus, attacker, watcher = make_bus(health_period_s=0.2), make_bus(), make_bus()
    node = Node("gantry", ServiceSettings(), bus)
    healths: queue.Queue[m.ServiceHealth] = queue.Queue()
    watcher.subscribe(keys.HEALTH, healths.put, latest=False, service="gantry")
    bus.subscribe(keys.GANTRY_FRAME, lambda frame: None)
    until_heard(attacker, "stb/gantry/camera/frame")
    until_heard(bus, "stb/health/gantry/main")
    for n, payload in enumerate((b"not msgpack at all", msgpack.packb({"camera": "x"})), 1):
        attacker.session.put("stb/gantry/camera/frame", payload)
        def dropped(n: int = n) -> bool:
            stats = bus.key_stats().get("stb/gantry/camera/frame")
            return stats is not None and sum(stats.dropped.values()) == n

        wait_for(dropped)
    node.publish_health()
    health = healths.get(timeout=2)
    assert health.service == "gantry" and health.status == "ok"
    assert health.keys["stb/gantry/camera/frame"].dropped == {"not_msgpack": 1,
                                                              "missing_field": 1}


def test_bad_payloads_are_logged_at_a_bounded_rate(make_bus: Callable[..., Bus],
                                                   caplog: pytest.LogCaptureFixture) -> None:
    bus = make_bus()
    with caplog.at_level("WARNING", logger="common.bus"):
        for _ in range(200):
            assert bus.accept(keys.TRACKER_ROBOT, "stb/tracker/robot", b"\xc1") is None
    assert bus.key_stats()["stb/tracker/robot"].dropped == {"not_msgpack": 200}
    assert len(caplog.records) == 1
    assert "stb/tracker/robot" in caplog.records[0].getMessage()


def test_backlog_after_a_network_stall_never_reaches_the_handler(
        router_endpoint: str, make_bus: Callable[..., Bus]) -> None:
    from common.bus import open_session
    from tests.conftest import client_settings
    from tests.faultproxy import FaultProxy

    proxy = FaultProxy(int(router_endpoint.rsplit(":", 1)[1]))
    settings = client_settings(proxy.endpoint)
    session = open_session(settings.zenoh)
    producer = Bus(session, settings)
    consumer = make_bus(max_age_s=0.3)
    ages: list[float] = []
    consumer.subscribe(keys.TRACKER_ROBOT, lambda msg: ages.append(time.time() - msg.sent_s))
    try:
        until_heard(producer, ROBOT_KEY)
        stop = threading.Event()

        def produce() -> None:
            while not stop.wait(0.02):
                producer.publish(keys.TRACKER_ROBOT, _robot())

        producing = threading.Thread(target=produce, daemon=True)
        producing.start()
        wait_for(lambda: len(ages) > 10)
        proxy.stall()
        time.sleep(1.5)  # the subject: a network stall of 1.5 s
        before = len(ages)
        proxy.release()
        wait_for(lambda: len(ages) > before + 10, timeout=5)
        stop.set()
        producing.join(2)  # not publishing while the publisher is undeclared below
        dropped = consumer.key_stats()["stb/tracker/robot"].dropped
        print("after stall:", dropped, f"max age {max(ages):.3f} s")
        # the backlog arrives in a burst: the mailbox supersedes most of it, and whatever is
        # taken out of the mailbox too late is dropped as stale; either way it is counted
        backlog = dropped.get("stale", 0) + dropped.get("superseded", 0)
        assert backlog > 0, "the backlog must have arrived and been dropped"
        assert max(ages) < 0.3, f"a sample {max(ages):.2f} s old reached the handler"
    finally:
        producer.close()
        session.close()
        proxy.close()


def test_a_flood_of_distinct_keys_keeps_health_bounded_and_the_busiest_keys_their_own(
        make_bus: Callable[..., Bus], caplog: pytest.LogCaptureFixture) -> None:
    """One garbage sample on each of 4,000 keys grew a health message to 131 KB (past the
    64 KiB limit, so it was dropped everywhere) and wrote 4,000 log lines."""
    bus = make_bus()
    for _ in range(50):
        bus.count_received("stb/tracker/robot")  # the service's real traffic
    with caplog.at_level(logging.WARNING, logger="common.bus"):
        for k in range(4000):
            bus.count_drop(f"stb/fuzz/{k}", "not_msgpack", "garbage")
    stats = bus.key_stats()
    assert len(stats) <= MAX_KEYS + 1
    assert stats["stb/tracker/robot"].received == 50
    assert sum(s.dropped.get("not_msgpack", 0) for s in stats.values()) == 4000, "none lost"
    assert stats[OTHER_KEYS].dropped["not_msgpack"] >= 4000 - MAX_KEYS
    health = m.ServiceHealth(measured_s=time.time(), service="web", instance="main",
                             host="h", pid=1, started_s=0.0, status="ok", keys=stats)
    assert len(codec.encode(health)) < keys.HEALTH.max_payload_bytes
    assert len(caplog.records) <= MAX_KEYS + 1
