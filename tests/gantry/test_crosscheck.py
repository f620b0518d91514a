"""Two position channels compared crosswise (pure): a tolerance, a window, no verdict without
a recent comparison."""

from __future__ import annotations

from services.gantry.crosscheck import CrossCheck


def _check() -> CrossCheck:
    return CrossCheck("the crane", tolerance_mm=100.0, window_s=0.5, fresh_s=0.5,
                      remedy="run stb gantry commission")


def test_a_disagreement_counts_once_it_has_lasted_the_window() -> None:
    check = _check()
    check.observe(10.0, 150.0)
    assert check.beyond() and check.failing(10.4) is None
    check.observe(10.45, 160.0)
    failing = check.failing(10.5)
    assert failing is not None and failing.off_mm == 160.0 and failing.since_s == 10.0
    text = failing.text(10.5)
    assert "disagrees with the motion capture by 160 mm" in text and "commission" in text


def test_one_agreeing_comparison_ends_it() -> None:
    check = _check()
    check.observe(10.0, 150.0)
    check.observe(10.3, 20.0)
    check.observe(10.4, 150.0)
    assert check.failing(10.6) is None, "the window starts again"
    check.observe(10.9, 150.0)
    assert check.failing(10.95) is not None


def test_no_recent_comparison_is_no_verdict_not_a_fault() -> None:
    check = _check()
    check.observe(10.0, 150.0)
    check.observe(10.5, 150.0)
    assert check.failing(10.6) is not None
    assert check.failing(11.1) is None, "the channel went quiet: unknown"
    assert "no recent comparison" in (check.verdict(11.1) or "")
    assert check.verdict(11.1, needed=False) is None


def test_arming_needs_an_agreeing_recent_comparison() -> None:
    check = _check()
    assert "no recent comparison" in (check.verdict(1.0) or "")
    check.observe(1.0, 30.0)
    assert check.verdict(1.2) is None
    check.observe(1.3, 130.0)
    assert "by 130 mm" in (check.verdict(1.3) or "")
    off = CrossCheck("x", tolerance_mm=0.0, window_s=0.5, fresh_s=0.5, remedy="")
    off.observe(1.0, 1e6)
    assert off.verdict(1.0) is None and off.failing(5.0) is None, "0: the check is off"
