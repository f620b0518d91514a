"""Gravity offload against the paper's figures (§4): a 10 cm error on a 2 m cable changes the
vertical force by less than 1 % and adds about 5 % of sideways pull."""

from __future__ import annotations

import pytest

from services.gantry.offload import offload


def test_the_papers_ten_centimetres_on_a_two_metre_cable() -> None:
    found = offload(100.0, 2000.0)
    assert found.vertical_loss_pct < 1.0
    assert found.vertical_loss_pct == pytest.approx(0.125, abs=0.001)  # 1 − cos(asin 0.05)
    assert found.horizontal_share_pct == pytest.approx(5.0, abs=0.01)
    assert not found.warning  # the warning is for more than 5 %


def test_more_error_more_pull_and_the_warning_beyond_the_limit() -> None:
    small, large = offload(50.0, 2000.0), offload(-300.0, 2000.0)
    assert small.horizontal_share_pct < large.horizontal_share_pct
    assert large.horizontal_error_mm == 300.0 and large.warning
    assert offload(5000.0, 2000.0).horizontal_share_pct == pytest.approx(100.0)  # lying flat


def test_a_cable_without_length_is_refused() -> None:
    with pytest.raises(ValueError, match="cable length"):
        offload(10.0, 0.0)
