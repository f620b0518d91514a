"""Key expressions: built from one definition, matched back, validated."""

from __future__ import annotations

import pytest

from common import keys


def test_key_and_pattern_follow_the_template() -> None:
    assert keys.PTZ_STATE.key("stb", camera="ptz1") == "stb/ptz/ptz1/state"
    assert keys.PTZ_STATE.pattern("stb") == "stb/ptz/*/state"
    assert keys.TRACKER_ROBOT.key("lab2/stb") == "lab2/stb/tracker/robot"


def test_match_returns_parameters_of_a_concrete_key() -> None:
    assert keys.PTZ_STATE.match("stb", "stb/ptz/ptz2/state") == {"camera": "ptz2"}
    assert keys.PTZ_STATE.match("stb", "stb/ptz/ptz2/detections") is None
    assert keys.topic_for("stb", "stb/gantry/setpoint") is keys.GANTRY_SETPOINT
    assert keys.topic_for("stb", "other/gantry/setpoint") is None


def test_missing_or_bad_parameters_are_refused() -> None:
    with pytest.raises(ValueError, match="needs parameters"):
        keys.PTZ_STATE.key("stb")
    with pytest.raises(ValueError, match="bad camera"):
        keys.PTZ_STATE.key("stb", camera="a/b")
    with pytest.raises(ValueError, match="bad camera"):
        keys.PTZ_STATE.key("stb", camera="*")


@pytest.mark.parametrize("prefix", ["", "STB", "stb/", "/stb", "st*b", "a//b"])
def test_bad_prefixes_are_refused(prefix: str) -> None:
    with pytest.raises(ValueError, match="bad key prefix"):
        keys.check_prefix(prefix)


def test_every_key_of_the_design_is_defined_once() -> None:
    paths = [t.path for t in keys.ALL_TOPICS]
    assert len(paths) == len(set(paths))
    for path in ["tracker/markers", "tracker/robot", "ptz/{camera}/state",
                 "ptz/{camera}/detections", "calib/{camera}/pose", "gantry/camera/frame",
                 "gantry/detections", "gantry/estimate", "gantry/setpoint", "gantry/state"]:
        assert path in paths
    assert all(p.startswith("sim/truth/") for p in paths if p.startswith("sim/"))


def test_alive_keys_round_trip() -> None:
    key = keys.alive_key("stb", "ptz", "ptz1")
    assert key == "stb/alive/ptz/ptz1"
    assert keys.parse_alive("stb", key) == ("ptz", "ptz1")
    assert keys.parse_alive("stb", "stb/alive/ptz") is None
    assert keys.parse_alive("stb", "lab/alive/ptz/x") is None
