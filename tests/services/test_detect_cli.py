"""``stb detect``: files in, the API's fields out as JSON, annotated images on request."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from services.detect_cli import main
from tests.common.test_markers import disc_frame


def test_json_per_image_with_annotations_and_a_clear_error(
        tmp_path: Path, rng: np.random.Generator, capsys) -> None:  # noqa: ANN001
    good = tmp_path / "one.png"
    cv2.imwrite(str(good), disc_frame(rng, [(100.3, 200.7, 6)]))
    colour = tmp_path / "two.jpg"
    cv2.imwrite(str(colour), cv2.cvtColor(disc_frame(rng, [(50, 60, 5), (400, 300, 5)]),
                                          cv2.COLOR_GRAY2BGR))
    broken = tmp_path / "broken.png"
    broken.write_text("not an image")
    code = main([str(good), str(colour), str(broken), "--json", "--annotate",
                 str(tmp_path / "ann")])
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert code == 1, "a broken file makes the exit code non-zero"
    one, two, bad = lines
    assert one["status"] == "ok" and one["threshold"] == 230
    (marker,) = one["markers"]
    assert set(marker) == {"u", "v", "radius_long", "radius_short", "angle_deg", "roundness",
                           "area"}
    assert abs(marker["u"] - 100.3) < 0.3 and abs(marker["v"] - 200.7) < 0.3
    assert two["status"] == "too_many" and len(two["markers"]) == 2
    assert bad["error"] == "not a readable image file"
    annotated = cv2.imread(one["annotated"])
    assert annotated is not None and annotated.shape == (576, 704, 3)


def test_parameters_reach_the_detector(tmp_path: Path, rng: np.random.Generator,
                                       capsys) -> None:  # noqa: ANN001
    path = tmp_path / "two.png"
    cv2.imwrite(str(path), disc_frame(rng, [(50, 60, 5), (400, 300, 5)]))
    assert main([str(path), "--json", "--max-markers", "2", "--t-lim", "220",
                 "--threshold", "240"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "ok" and len(out["markers"]) == 2 and out["threshold"] == 240
