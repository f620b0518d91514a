"""Someone else's hand on a following camera pauses following (services/ptz/override.py)."""

from __future__ import annotations

from services.ptz.override import ManualOverride


def _following(override: ManualOverride, start: float = 0.0) -> float:
    """Ten seconds of following a robot that pans the camera 8°/s, commands at 10 Hz, looks
    at 5 Hz lagging the commands by 0.15 s; the time at the end."""
    t = start
    override.observe(t, 0.0, 0.0)
    while t < start + 10.0:
        t += 0.1
        override.commanded(t, 8.0 * (t - start), 1.0)
        if round(t * 10) % 2 == 0:
            assert not override.observe(t, 8.0 * (t - start - 0.15), 1.0)
    return t


def test_following_itself_never_looks_like_a_hand() -> None:
    override = ManualOverride()
    _following(override)
    assert not override.paused(10.0)


def test_a_big_swing_of_ours_is_on_our_path() -> None:
    override = ManualOverride()
    override.observe(0.0, -60.0, 0.0)
    override.commanded(0.1, 90.0, 30.0)  # the robot appeared across the crater
    for k in range(1, 16):  # pan 100°/s and tilt 90°/s each at their own pace
        t = 0.1 + 0.1 * k
        pan, tilt = min(-60.0 + 100.0 * (t - 0.22), 90.0), min(90.0 * (t - 0.22), 30.0)
        assert not override.observe(t, max(pan, -60.0), max(tilt, 0.0)), t


def test_a_move_by_hand_pauses_following_longer_while_it_goes_on() -> None:
    override = ManualOverride(tolerance_deg=5.0, pause_s=30.0)
    t = _following(override)
    assert override.observe(t + 0.2, 45.0, 20.0), "far off our path: someone's hand"
    assert override.paused(t + 29.0)
    assert override.observe(t + 20.0, 50.0, 20.0), "still moving it: the pause is longer"
    assert override.paused(t + 49.0) and not override.paused(t + 50.5)


def test_after_the_pause_the_way_back_is_ours() -> None:
    override = ManualOverride(pause_s=5.0)
    t = _following(override)
    override.observe(t + 0.2, 45.0, 20.0)
    t += 6.0
    assert not override.paused(t)
    assert not override.observe(t, 45.0, 20.0)
    override.commanded(t + 0.1, 80.0, 1.0)  # following again: back to the robot
    assert not override.observe(t + 0.3, 60.0, 10.0), "on its way from where it was left"


def test_zero_pause_never_pauses_and_no_command_no_judgement() -> None:
    assert not ManualOverride(pause_s=0.0).observe(1.0, 90.0, 0.0)
    fresh = ManualOverride()
    fresh.commanded(0.0, 10.0, 0.0)  # before the first look: nothing to judge from
    assert not fresh.observe(0.1, 90.0, 0.0)


def test_a_calibration_hold_still_under_way_after_the_mode_ended_is_ours() -> None:
    """Calibration mode sent the camera 150° away; the mode ended while it turned, following
    sent it back the other way, and the camera went on towards the hold for its latency
    before it turned: all of it ours (a flood of calibration requests once paused following
    for 30 s this way)."""
    override = ManualOverride()
    override.watch_only(0.0, 0.0)  # calibration mode: seen, not judged
    override.own_move(0.1, 150.0, -40.0)  # the hold
    override.watch_only(30.0, -9.0)
    assert not override.observe(0.7, 45.0, -13.0), "the mode ended; still turning to the hold"
    override.commanded(0.8, -20.0, 5.0)  # following: the robot is the other way
    assert not override.observe(1.0, 60.0, -16.0), "the hold, queued behind the latency"
    assert not override.observe(1.6, 20.0, -5.0), "and back towards the robot"
    for k in range(1, 40):  # following on, past the hold's life: a hand is seen again
        override.commanded(1.6 + 0.1 * k, -20.0, 5.0)
    assert not override.observe(5.5, -20.0, 5.0)
    assert override.observe(6.0, 90.0, 5.0), "someone else's hand, once our moves are done"


def test_a_move_home_is_not_judged_while_it_may_last() -> None:
    override = ManualOverride(own_move_s=5.0)
    override.observe(0.0, 0.0, 0.0)
    override.commanded(0.1, 10.0, 0.0)
    override.own_move(0.2, None, None)  # home: where, we do not know
    assert not override.observe(1.0, 120.0, -30.0) and not override.paused(1.0)
    assert not override.observe(5.3, 170.0, -45.0), "no command since: nothing to judge by"
    override.commanded(5.4, 160.0, -40.0)
    assert override.observe(5.6, 0.0, 0.0), "judged again after the home move's time"


def test_a_camera_back_from_a_reboot_is_judged_afresh_and_a_pause_goes_on() -> None:
    """It stopped answering and came back home (pan 0, tilt 0), 80° off our path: no one's
    hand; the next command starts the path from there. A pause under way is kept."""
    override = ManualOverride(pause_s=30.0)
    t = _following(override)
    override.lost_sight()
    assert not override.observe(t + 5.0, 0.0, 0.0), "home after a reboot"
    assert not override.paused(t + 5.0)
    override.commanded(t + 5.1, 80.0, 1.0)
    assert not override.observe(t + 5.3, 20.0, 0.5), "on its way back to the robot"
    assert override.observe(t + 6.0, -60.0, 40.0), "judged again once commanded"
    override.lost_sight()
    assert not override.observe(t + 7.0, 0.0, 0.0) and override.paused(t + 35.0)
