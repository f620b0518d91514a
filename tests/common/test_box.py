"""The one box type (common/volume.py)."""

from __future__ import annotations

import numpy as np

from common.volume import Box


def test_the_box_contains_its_edges_clamps_to_them_and_refuses_what_is_not_finite() -> None:
    box = Box((-1.0, 0.0), (1.0, 2.0))
    assert box.contains((1.0, 0.0)) and not box.contains((1.01, 0.0))
    assert not box.contains((np.nan, 1.0)) and not box.contains((0.0, np.inf))
    assert box.clamp((5.0, -3.0)) == (1.0, 0.0)
    assert box.shrunk(0.5) == Box((-0.5, 0.5), (0.5, 1.5))
