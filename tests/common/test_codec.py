"""Codec: every model round-trips; every kind of bad payload is rejected with its reason."""

from __future__ import annotations

import contextlib
import math

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common import codec, keys
from common import messages as m
from common.wiredoc import EXAMPLES


def test_every_topic_model_has_an_example() -> None:
    assert {t.model for t in keys.ALL_TOPICS} <= set(EXAMPLES)


@pytest.mark.parametrize("example", EXAMPLES.values(), ids=lambda e: type(e).__name__)
def test_round_trip_is_lossless(example: m.Message) -> None:
    payload = codec.encode(example, sent_s=123.5)
    decoded = codec.decode(type(example), payload)
    assert decoded == example.model_copy(update={"sent_s": 123.5})


@pytest.mark.parametrize("example", EXAMPLES.values(), ids=lambda e: type(e).__name__)
def test_payload_is_a_plain_msgpack_map(example: m.Message) -> None:
    data = msgpack.unpackb(codec.encode(example))
    assert isinstance(data, dict)
    assert set(data) == set(type(example).model_fields)


def _robot(**change: object) -> dict:
    data = EXAMPLES[m.RobotPosition].model_dump()
    data.update(change)
    return data


BAD = {
    "not_msgpack": (b"\xc1\x00garbage", codec.NOT_MSGPACK),
    "truncated": (msgpack.packb(_robot())[:-3], codec.NOT_MSGPACK),
    "not_a_map": (msgpack.packb([1, 2, 3]), codec.NOT_A_MAP),
    "missing_field": (msgpack.packb({k: v for k, v in _robot().items() if k != "x_mm"}),
                      codec.MISSING_FIELD),
    "extra_field": (msgpack.packb(_robot(colour="red")), codec.EXTRA_FIELD),
    "string_for_float": (msgpack.packb(_robot(x_mm="12.5")), codec.WRONG_TYPE),
    "bool_for_float": (msgpack.packb(_robot(x_mm=True)), codec.WRONG_TYPE),
    "nan": (msgpack.packb(_robot(y_mm=float("nan"))), codec.NON_FINITE),
    "inf": (msgpack.packb(_robot(z_mm=float("inf"))), codec.NON_FINITE),
    "too_large": (msgpack.packb(_robot(label="x" * 70_000)), codec.TOO_LARGE),
}


@pytest.mark.parametrize("case", BAD, ids=list(BAD))
def test_bad_payload_is_rejected_with_its_reason(case: str) -> None:
    payload, reason = BAD[case]
    with pytest.raises(codec.DecodeError) as err:
        codec.decode(m.RobotPosition, payload, max_bytes=keys.TRACKER_ROBOT.max_payload_bytes)
    assert err.value.reason == reason


def test_non_finite_inside_a_nested_list_is_rejected() -> None:
    data = EXAMPLES[m.MarkerFrame].model_dump()
    data["markers"][0]["x_mm"] = float("-inf")
    with pytest.raises(codec.DecodeError) as err:
        codec.decode(m.MarkerFrame, msgpack.packb(data))
    assert err.value.reason == codec.NON_FINITE


def test_out_of_range_value_is_rejected() -> None:
    data = EXAMPLES[m.PtzState].model_dump()
    data["pan_deg"] = 540.0
    with pytest.raises(codec.DecodeError) as err:
        codec.decode(m.PtzState, msgpack.packb(data))
    assert err.value.reason == codec.OUT_OF_RANGE


_values = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-2**63, 2**64 - 1),
                    st.booleans(), st.none(), st.text(max_size=8), st.binary(max_size=8))


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(st.sampled_from([*m.CraneSetpoint.model_fields, "junk"]), _values))
def test_decode_accepts_only_finite_well_typed_setpoints(data: dict) -> None:
    try:
        msg = codec.decode(m.CraneSetpoint, msgpack.packb(data))
    except codec.DecodeError:
        return
    assert all(math.isfinite(v) for v in (msg.x_mm, msg.y_mm, msg.measured_s, msg.sent_s))
    assert isinstance(msg.hold, bool) and msg.seq >= 0


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=64))
def test_arbitrary_bytes_never_raise_anything_but_decode_error(payload: bytes) -> None:
    with contextlib.suppress(codec.DecodeError):
        codec.decode(m.CraneSetpoint, payload)
