"""The direct CDR decoder of flat types (codec/_flat.py) against the general
rosbags-based decoder it stands in for: for every bundled message type it
covers, the same dict (values and types) for any valid payload, and the same
outcome (the same dict or the same ``DecodeError``) for any damaged one."""

from __future__ import annotations

import math
import struct
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from _util import examples
from ros_mobile_bridge._errors import DecodeError, SchemaError
from ros_mobile_bridge.codec import CodecRegistry, bundled_interface_names
from ros_mobile_bridge.codec._model import INT_RANGES

REG = CodecRegistry()


def _flat_types() -> list[str]:
    names = []
    for name in bundled_interface_names():
        if "/msg/" not in name:
            continue
        try:
            decode = REG.dict_decoder(name)
        except SchemaError:
            continue  # wstring: no codec at all
        if "_general" in decode.__globals__:
            names.append(name)
    return sorted(names)


FLAT = _flat_types()
INTS = {**INT_RANGES, "byte": (0, 255)}  # ROS 2's octet is unsigned
TEXT = st.text(st.characters(blacklist_characters="\x00", blacklist_categories=("Cs",)))


def value_of(type_name: str) -> st.SearchStrategy[Any]:
    if type_name in INTS:
        return st.integers(*INTS[type_name])
    if type_name == "bool":
        return st.booleans()
    if type_name == "float32":
        return st.floats(width=32, allow_nan=False)
    if type_name == "float64":
        return st.floats(allow_nan=False)
    if type_name == "string":
        return TEXT
    fields = REG.definition(type_name)
    return st.fixed_dictionaries(
        {f.name: st.deferred(lambda t=f.type: value_of(t)) for f in fields}
    )


def general(decode: Any) -> Any:
    return decode.__globals__["_general"]


def no_fallback(payload: memoryview) -> Any:
    raise AssertionError("a valid payload went to the general decoder")


def outcome(decode: Any, payload: bytes) -> tuple[str, Any]:
    try:
        return "ok", typed(decode(memoryview(payload)))
    except DecodeError as exc:
        return "error", str(exc)


def typed(value: Any) -> Any:
    """``value`` with every leaf's type beside it (1 == 1.0 == True otherwise)."""
    if isinstance(value, dict):
        return {k: typed(v) for k, v in value.items()}
    if isinstance(value, float) and math.isnan(value):
        return (float, "nan")
    return (type(value), value)


def test_the_common_flat_types_are_covered_and_arrays_are_not() -> None:
    for name in (
        "std_msgs/msg/String",
        "std_msgs/msg/Header",
        "std_msgs/msg/Empty",
        "geometry_msgs/msg/Twist",
        "geometry_msgs/msg/PoseStamped",
    ):
        assert name in FLAT
    for name in (
        "sensor_msgs/msg/Image",
        "nav_msgs/msg/Odometry",
        "std_msgs/msg/Float64MultiArray",
    ):
        assert name not in FLAT
    assert len(FLAT) > 50


@settings(max_examples=examples(25), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_valid_payloads_decode_as_the_general_decoder_does(data: st.DataObject) -> None:
    for name in FLAT:  # every type in every example
        value = data.draw(value_of(name))
        payload = REG.encoder(name, "cdr")(value)
        decode = REG.dict_decoder(name)
        namespace = decode.__globals__  # the generated decoder's own
        slow = namespace["_general"]
        namespace["_general"] = no_fallback  # a valid payload is read directly
        try:
            got = outcome(decode, payload)
        finally:
            namespace["_general"] = slow
        assert got == outcome(slow, payload), name
        assert got[0] == "ok"


@settings(max_examples=examples(400), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_damaged_payloads_end_as_with_the_general_decoder(data: st.DataObject) -> None:
    name = data.draw(st.sampled_from(FLAT))
    payload = bytearray(REG.encoder(name, "cdr")(data.draw(value_of(name))))
    damage = data.draw(st.sampled_from(["cut", "byte", "append", "big-endian"]))
    if damage == "cut":
        del payload[data.draw(st.integers(0, len(payload))) :]
    elif damage == "byte":
        payload[data.draw(st.integers(0, len(payload) - 1))] = data.draw(st.integers(0, 255))
    elif damage == "append":
        payload += data.draw(st.binary(min_size=1, max_size=12))
    else:
        payload[1] = 0
    decode = REG.dict_decoder(name)
    assert outcome(decode, bytes(payload)) == outcome(general(decode), bytes(payload))


@pytest.mark.parametrize(
    "payload",
    [
        b"",
        b"\x00\x01\x00",
        b"\x00\x01\x00\x00\x05\x00\x00\x00abcde",  # no terminator
        b"\x00\x01\x00\x00\x03\x00\x00\x00\xff\xfe\x00",  # not UTF-8
        b"\x00\x01\x00\x00\x00\x00\x00\x00",  # a length without the terminator's byte
        b"\x00\x01\x00\x00\x02\x00\x00\x00a\x00" + b"\x00" * 8,  # bytes left over
    ],
)
def test_a_string_payload_it_cannot_read_raises_the_general_error(payload: bytes) -> None:
    decode = REG.dict_decoder("std_msgs/msg/String")
    with pytest.raises(DecodeError) as flat_error:
        decode(memoryview(payload))
    with pytest.raises(DecodeError) as general_error:
        general(decode)(memoryview(payload))
    assert str(flat_error.value) == str(general_error.value)


def test_a_string_is_read_straight_from_the_payload() -> None:
    raw = "héllo".encode() + b"\x00"
    payload = b"\x00\x01\x00\x00" + struct.pack("<I", len(raw)) + raw
    decode = REG.dict_decoder("std_msgs/msg/String")
    assert decode(memoryview(payload)) == {"data": "héllo"}
    assert decode(memoryview(payload + b"\x00\x00\x00")) == {"data": "héllo"}  # CDR padding


def test_a_fixed_size_type_is_read_in_one_go_with_up_to_3_bytes_of_padding() -> None:
    decode = REG.dict_decoder("geometry_msgs/msg/Twist")
    payload = b"\x00\x01\x00\x00" + struct.pack("<6d", 1, 2, 3, 4, 5, 6)
    namespace = decode.__globals__
    slow = namespace["_general"]
    namespace["_general"] = no_fallback
    try:
        for padding in (b"", b"\x00", b"\x00\x00\x00"):
            assert decode(memoryview(payload + padding)) == {
                "linear": {"x": 1.0, "y": 2.0, "z": 3.0},
                "angular": {"x": 4.0, "y": 5.0, "z": 6.0},
            }
    finally:
        namespace["_general"] = slow
    for damaged in (payload + b"\x00" * 4, payload[:-1], b"\x00\x00" + payload[2:]):
        assert outcome(decode, damaged) == outcome(slow, damaged)
