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
