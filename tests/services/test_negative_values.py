"""No argparse traps: every option that takes a number or a vector takes a negative one as
written (``--initial -100,200,...``, ``--target -1200,300,0``), on every command that has
one. Each command's own parser is run up to its parse (``Parser.parse_args``)."""

from __future__ import annotations

import importlib
from collections.abc import Sequence

import pytest

from services.args import Parser


class _Parsed(Exception):
    def __init__(self, namespace: object) -> None:
        self.namespace = namespace


@pytest.fixture
def parsed_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each command stops right after its flags are parsed, showing what they gave."""
    parse = Parser.parse_args

    def parse_then_stop(self: Parser, args: Sequence[str] | None = None,
                        namespace: object = None) -> object:
        raise _Parsed(parse(self, args, namespace))

    monkeypatch.setattr(Parser, "parse_args", parse_then_stop)


def _parse(module: str, argv: list[str]) -> object:
    with pytest.raises(_Parsed) as got:
        importlib.import_module(module).main(argv)
    return got.value.namespace


VECTOR = "-100,200,-3000,180.5,-0.5,1e3"
CASES = [
    ("services.calib.solve_cli", ["p.csv", "--initial", VECTOR], "initial", VECTOR),
    ("services.calib.solve_cli", ["p.csv", "--focal-px", "-743"], "focal_px", -743.0),
    ("services.calib.solve_cli", ["p.csv", "--max-offset-s", "-.5"], "max_offset_s", -0.5),
    ("services.calib.solve_cli", ["p.csv", "--inlier-px", "-10"], "inlier_px", -10.0),
    ("services.calib.solve_cli", ["p.csv", "--seed", "-1"], "seed", -1),
    ("services.ptz.aim_cli", ["--pose", "p.json", "--target", "-1200,300,0"], "target",
     "-1200,300,0"),
    ("services.experiment.cli", ["gantry", "--ahead", "-0.2", "0.3", "-1e-1"], "ahead",
     [-0.2, 0.3, -0.1]),
    ("services.experiment.cli", ["gantry", "--seed", "-3"], "seed", -3),
    ("services.experiment.cli", ["identify", "--evaluations", "-1"], "evaluations", -1),
    ("services.experiment.cli", ["identify", "--workers", "-2"], "workers", -2),
    ("services.gantry.commissioning.identify_cli", ["--box", "-400"], "box", -400.0),
    ("services.gantry.commissioning.identify_cli", ["--steps", "-12"], "steps", -12),
    ("services.calib.collect_cli", ["--camera", "ptz1", "--count", "-5"], "count", -5),
    ("services.calib.collect_cli", ["--camera", "ptz1", "--timeout", "-5.5"], "timeout", -5.5),
    ("services.sim.__main__", ["--seed", "-7"], "seed", -7),
    ("services.recording.record_cli", ["out.mcap", "--duration", "-1"], "duration", -1.0),
    ("services.recording.record_cli", ["out.mcap", "--video-fps", "-2"], "video_fps", -2.0),
    ("services.recording.replay_cli", ["in.mcap", "--speed", "-2"], "speed", -2.0),
    ("services.gantry.command_cli", ["arm", "--timeout", "-1"], "timeout", -1.0),
]


@pytest.mark.usefixtures("parsed_only")
@pytest.mark.parametrize(("module", "argv", "field", "expected"), CASES,
                         ids=[f"{c[0].split('.')[-2]}:{c[2]}" for c in CASES])
def test_a_negative_value_is_a_value(module: str, argv: list[str], field: str,
                                     expected: object) -> None:
    assert getattr(_parse(module, argv), field) == expected


@pytest.mark.usefixtures("parsed_only")
def test_options_are_still_options() -> None:
    args = _parse("services.calib.solve_cli", ["p.csv", "--initial", "1,2,3,4,5,6", "--json"])
    assert args.json is True and args.initial == "1,2,3,4,5,6"  # type: ignore[attr-defined]
    with pytest.raises(SystemExit):
        _parse("services.calib.solve_cli", ["p.csv", "--initial"])  # the value is missing
