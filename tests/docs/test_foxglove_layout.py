"""docs/foxglove-layout.json is generated from the code, and every topic it shows is one that
``stb record`` and ``stb foxglove`` write."""

from __future__ import annotations

import json
from pathlib import Path

from common import keys
from services.recording.layout import CAMERAS, layout_json
from services.recording.typed import CRATER, GANTRY_IMAGE, SCENE, TF

LAYOUT = Path(__file__).resolve().parents[2] / "docs" / "foxglove-layout.json"


def test_the_layout_file_is_current() -> None:
    assert LAYOUT.read_text() == layout_json(), (
        "docs/foxglove-layout.json is out of date: python -m services.recording.layout > "
        "docs/foxglove-layout.json")


def _strings(node: object) -> list[str]:
    if isinstance(node, dict):
        return [s for k, v in node.items() for s in (_strings(v) + [k])]
    if isinstance(node, list):
        return [s for v in node for s in _strings(v)]
    return [node] if isinstance(node, str) else []


def test_every_topic_in_the_layout_exists() -> None:
    typed = {SCENE, CRATER, TF, GANTRY_IMAGE} | {f"/{c}/image" for c in CAMERAS} | {
        f"/{c}/annotations" for c in CAMERAS}
    shown = [s for s in _strings(json.loads(LAYOUT.read_text()))
             if s.startswith("/") or s.startswith("json/")]
    assert len(shown) >= 10, "the layout shows the scene, images and series"
    for path in shown:
        if not path.startswith("json/"):
            assert path in typed, path
            continue
        key, _, field = path.removeprefix("json/").partition(".")
        topic = keys.topic_for("stb", key)
        assert topic is not None and field in topic.model.model_fields, path
