"""The collection's rules on a simulated clock (``services/calib/collection.py``): holds and
their renewals, zoom steps, the stall and time-out clocks, what a stall names, the mocap wait.
Each runs in milliseconds; the wired session is run against the whole lab in
``test_collect_e2e.py``."""

from __future__ import annotations

from collections.abc import Iterator
from itertools import pairwise

import numpy as np

from common import messages as m
from services.calib.collection import (
    MOCAP_WAIT_S,
    Action,
    Collected,
    Collection,
    Ended,
    HoldCamera,
    KeepImage,
    PublishProgress,
)
from services.calib.settings import CalibSettings

T0 = 1_000.0  # the collection's start, on the simulated clock
TICK_S = 0.05
WIDTH, HEIGHT = 704, 576


def _state(t: float, zoom: int = 1, pan: float = 0.0) -> m.PtzState:
    return m.PtzState(measured_s=t, camera="ptz1", status="calibrating", pan_deg=pan,
                      tilt_deg=-4.0, zoom=zoom, focal_px=743.1, aim_error_deg=0.0)


def _frame(t: float) -> m.MarkerFrame:
    """The wand at 500 mm/s along a line, and a static marker."""
    wand = np.array([-1000.0 + 500 * t % 3000, 200.0, 300.0])
    return m.MarkerFrame(measured_s=t, frame=int(t * 100), markers=[
        m.Marker(label="static_1", x_mm=0.0, y_mm=0.0, z_mm=0.0),
        m.Marker(label="wand", x_mm=wand[0], y_mm=wand[1], z_mm=wand[2])])


def _detections(t: float, u: float, v: float) -> m.MarkerDetections:
    return m.MarkerDetections(
        measured_s=t, camera="ptz1", status="ok", threshold=230, width_px=WIDTH,
        height_px=HEIGHT, markers=[m.DetectedMarker(u_px=u, v_px=v, radius_long_px=3,
                                                    radius_short_px=3, angle_deg=0,
                                                    roundness=1.0, area_px=28)])


def _spots() -> Iterator[tuple[float, float]]:
    """Spots over the whole picture, 44 px apart: every cell and corner gets its share."""
    while True:
        for j in range(12):
            for i in range(16):
                yield (i + 0.5) * WIDTH / 16, (j + 0.5) * HEIGHT / 12


class _Lab:
    """The bus as the collection hears it: mocap at 100 Hz, a snapshot's detections every
    0.2 s (each at a new spot), and the camera's state, which reaches a zoom asked for 0.5 s
    after the hold that asked for it."""

    def __init__(self, collection: Collection, *, held: bool = True) -> None:
        self.collection, self.held = collection, held
        self.now = T0
        self.zoom, self.zoom_at = 1, T0
        self.spots = _spots()
        self.actions: list[tuple[float, Action]] = []
        self.mocap_until = T0

    def run(self, seconds: float, *, mocap_lag_s: float = 0.0) -> list[tuple[float, Action]]:
        end = self.now + seconds
        while self.now < end:
            self.now = round(self.now + TICK_S, 6)
            while self.mocap_until + 0.01 <= self.now - mocap_lag_s:
                self.mocap_until = round(self.mocap_until + 0.01, 6)
                self.collection.on_frame(_frame(self.mocap_until))
            if self.held:
                self.collection.on_state(_state(self.now, self.zoom if self.now >= self.zoom_at
                                                else self.zoom - 1))
            if round((self.now - T0) / TICK_S) % 4 == 0:
                self.collection.on_detections(_detections(self.now, *next(self.spots)))
            for action in self.collection.step(self.now):
                self.actions.append((self.now, action))
                if isinstance(action, HoldCamera) and action.zoom not in (None, self.zoom):
                    self.zoom, self.zoom_at = action.zoom, self.now + 0.5
                if isinstance(action, Collected | Ended):
                    return self.actions
        return self.actions


def _settings(**changes: float) -> CalibSettings:
    return CalibSettings(min_spacing_mm=50.0, min_spacing_px=20.0, **changes)


def test_a_collection_at_two_zooms_holds_each_and_ends_collected() -> None:
    collection = Collection(_settings(), "ptz1", 6, 600.0, [1, 2], T0)
    lab = _Lab(collection)
    actions = lab.run(120)
    assert isinstance(actions[-1][1], Collected)
    holds = [(t, a.zoom) for t, a in actions if isinstance(a, HoldCamera)]
    assert holds[0] == (T0 + TICK_S, 1)
    switched = next(t for t, zoom in holds if zoom == 2)
    # renewed every lease_s / 3 while at a step; the next step held on the first tick after
    assert all(0.99 <= b - a <= 1.06 for (a, za), (b, zb) in pairwise(holds) if za == zb)
    wide, tele = collection.collectors
    assert wide.done and wide.uncovered() == [] and tele.done and len(tele.times) == 6
    # no passpoint at zoom 2 from before the camera reported standing there
    assert min(tele.times) >= switched + 0.5
    kept = [a for _, a in actions if isinstance(a, KeepImage)]
    assert [k.index for k in kept] == list(range(len(wide.times) + len(tele.times)))
    assert all(k.pixel == (k.detections.markers[0].u_px, k.detections.markers[0].v_px)
               for k in kept)
    progress = [t for t, a in actions if isinstance(a, PublishProgress)]
    assert all(0.5 <= b - a < 0.5 + 1.5 * TICK_S for a, b in pairwise(progress))
    assert collection.progress(lab.now, "collecting", "", None).zooms_done == 2
    assert collection.step(lab.now + 1) == [], "nothing more once collected"


def test_the_steps_but_the_widest_take_step_count_passpoints() -> None:
    """The widest step (listed in the middle here) takes ``count`` and covers the picture;
    every other step ``step_count``; a ``step_count`` above ``count`` is held to ``count``."""
    collection = Collection(_settings(), "ptz1", 12, 600.0, [5, 2, 4], T0, step_count=6)
    assert isinstance(_Lab(collection).run(300)[-1][1], Collected)
    five, wide, four = collection.collectors
    assert [len(five.times), len(four.times)] == [6, 6]
    assert len(wide.times) >= 12 and wide.uncovered() == []
    assert collection.progress(T0, "collecting", "", None).target == 24
    held = Collection(_settings(), "ptz1", 8, 600.0, [1, 2], T0, step_count=20)
    assert [c.target for c in held.collectors] == [8, 8]


def test_detections_wait_for_the_mocap_to_pass_them_at_most_a_second() -> None:
    """With the mocap stream 0.3 s behind, detections are held until it has passed their time
    (interpolated, never extrapolated), and still taken."""
    collection = Collection(_settings(), "ptz1", 6, 600.0, None, T0)
    actions = _Lab(collection).run(60, mocap_lag_s=0.3)
    assert isinstance(actions[-1][1], Collected)
    kept = [(t, a) for t, a in actions if isinstance(a, KeepImage)]
    assert all(t - a.detections.measured_s >= 0.3 - 1e-6 for t, a in kept)
    assert collection.collector.skipped["marker not in mocap"] == 0


def test_a_mocap_that_stays_behind_gives_up_on_a_detection_after_the_wait() -> None:
    collection = Collection(_settings(), "ptz1", 6, 600.0, None, T0)
    collection.on_state(_state(T0 + 0.1))
    collection.on_frame(_frame(T0 + 0.1))
    collection.on_detections(_detections(T0 + 0.2, 300.0, 200.0))
    collection.step(T0 + 0.2 + MOCAP_WAIT_S - 0.01)
    assert collection.collector.snapshots == 0, "still waiting for the mocap"
    collection.step(T0 + 0.2 + MOCAP_WAIT_S)
    assert collection.collector.skipped["marker not in mocap"] == 1


def test_a_collection_never_held_fails_after_hold_wait_s_naming_the_ptz_service() -> None:
    collection = Collection(_settings(stall_s=0.3, hold_wait_s=0.5), "ptz1", 100, 60.0, None, T0)
    assert not any(isinstance(a, Ended) for a in collection.step(T0 + 0.5))
    (ended,) = collection.step(T0 + 0.51)
    assert isinstance(ended, Ended) and ended.state == "failed"
    assert ended.message.startswith("no passpoint for 0.5 s (0 of 100; since the last: no "
                                    "snapshot at all)")
    assert "has not taken the camera into calibration mode" in ended.message


def test_the_stall_clock_starts_again_when_the_camera_is_held() -> None:
    """A collection started before the PTZ service is up (calib starts faster) gets its whole
    ``stall_s`` of snapshots once the camera is held (a CI run failed after 4 s with "no
    snapshot at all": the PTZ service was still starting)."""
    collection = Collection(_settings(stall_s=0.3, hold_wait_s=0.5), "ptz1", 100, 60.0, None, T0)
    collection.step(T0)
    collection.on_state(_state(T0 + 0.2))
    assert not any(isinstance(a, Ended) for t in (0.2, 0.45, 0.5) for a in
                   collection.step(T0 + t))
    (ended,) = collection.step(T0 + 0.51)
    assert isinstance(ended, Ended) and "sends no detections" in ended.message


def test_a_stalled_collection_names_what_to_check_for_every_reason_seen() -> None:
    """A clean-clone CI's slow start gave more snapshots before the motion capture streamed
    ("marker not in mocap") than with the camera looking at the sky ("no marker"): both hints
    are given, the most frequent first, not only the top one."""
    collection = Collection(_settings(stall_s=4), "ptz1", 100, 60.0, None, T0)
    collection.on_state(_state(T0))
    collection.step(T0)
    collection.collector.skipped.update({"marker not in mocap": 4, "no marker": 2})
    (ended,) = collection.step(T0 + 4.01)
    assert isinstance(ended, Ended)
    assert ended.message.startswith("no passpoint for 4 s (0 of 100; since the last: 4 marker "
                                    "not in mocap, 2 no marker): the motion capture does not "
                                    "see the wand")
    assert ended.message.index("motion capture") < ended.message.index("not in the camera's")


def test_a_collection_times_out_naming_the_zoom_step_and_what_was_skipped() -> None:
    collection = Collection(_settings(stall_s=100), "ptz1", 100, 5.0, [1, 4], T0)
    lab = _Lab(collection, held=False)
    collection.on_state(_state(T0))
    (_, ended) = lab.run(10)[-1]
    assert isinstance(ended, Ended) and ended.state == "failed"
    # a snapshot every 0.2 s for 5 s, each a passpoint
    assert ended.message == ("timed out after 5 s with 25 of 100 passpoints at zoom 1 (step 1 "
                             "of 2) (none skipped)")


def test_a_cancelled_collection_ends_at_the_next_step() -> None:
    collection = Collection(_settings(), "ptz1", 100, 60.0, None, T0)
    collection.step(T0)
    collection.cancel()
    assert collection.step(T0 + 0.05) == [Ended("cancelled", "cancelled")]


def test_the_pose_is_solved_at_the_pan_and_tilt_the_camera_was_held_at() -> None:
    """Once the collection is over and the camera released, it may still say "calibrating"
    while it turns back home: that state is not the passpoints' pan and tilt (a collection
    held at pan 6° once stored pan 0°)."""
    collection = Collection(_settings(), "ptz1", 10, 60.0, None, T0)
    collection.on_state(_state(T0 + 1, pan=6.0))
    collection.stop_holding()
    collection.on_state(_state(T0 + 2, pan=0.0))  # turning home, still "calibrating"
    assert collection.camera_state is not None and collection.camera_state.pan_deg == 6.0


def test_progress_asks_for_the_corners_still_missing_while_collecting() -> None:
    collection = Collection(_settings(), "ptz1", 6, 60.0, [1, 3], T0)
    progress = collection.progress(T0, "collecting", "", None)
    assert progress.message.startswith("carry the wand to the picture's top left")
    assert (progress.zoom, progress.zooms, progress.target) == (1, 2, 12)
    assert collection.progress(T0, "solving", "", None).message == ""
