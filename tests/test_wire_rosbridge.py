"""Tests for the sans-IO rosbridge v2 engine (``ros_mobile_bridge.wire.rosbridge``).

The literal server frames below were captured from rosbridge_server_rs 0.1.6;
the variants (spaces, ``\\/`` escapes, other key orders) are what the Python
rosbridge server (ujson) and others send.
"""

from __future__ import annotations

import itertools
import json
import math
import struct
from typing import Any

import cbor2
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from _util import examples
from ros_mobile_bridge.wire import rosbridge as rb
from ros_mobile_bridge.wire.rosbridge import (
    ActionFeedback,
    ActionResult,
    Event,
    ForeignProtocol,
    ProtocolViolation,
    Publish,
    RosbridgeEngine,
    ServiceResponse,
    Status,
    cbor_loads,
    decode_cbor_msg,
    decode_json_msg,
)

# --------------------------------------------------------------------------
# Real server output (rosbridge_server_rs 0.1.6)

PUBLISH = b'{"op":"publish","topic":"/chatter","msg":{"data":"hello 141"}}'
PUBLISH_CBOR = bytes.fromhex(
    "a3626f70677075626c69736865746f706963682f63686174746572636d7367a164646174616968656c6c6f20313439"
)
RAW_CDR = b"\x00\x01\x00\x00\n\x00\x00\x00hello 157\x00"
PUBLISH_CBOR_RAW = cbor2.dumps(
    {
        "op": "publish",
        "topic": "/chatter",
        "msg": {"bytes": RAW_CDR, "secs": 1795260957, "nsecs": 634917618},
    }
)
SERVICE_OK = (
    '{"op":"service_response","service":"/set_flag","result":true,'
    '"values":{"success":true,"message":"flag set to True"},"id":"c1"}'
)
SERVICE_FAILED = (
    '{"op":"service_response","service":"/slow_trigger",'
    '"values":"Timeout exceeded while waiting for service response","result":false,"id":"c7"}'
)
STATUS = '{"op":"status","level":"error","msg":"unknown operation: bogus_op","id":"b1"}'
STATUS_NO_ID = '{"op":"status","level":"error","msg":"unknown operation: bogus_op"}'
FEEDBACK = '{"op":"action_feedback","action":"/fibonacci","values":{"sequence":[0,1,1]},"id":"g1"}'
RESULT = (
    '{"op":"action_result","action":"/fibonacci","values":{"sequence":[0,1,1,2,3]},'
    '"status":4,"result":true,"id":"g1"}'
)
REJECTED = (
    '{"op":"action_result","action":"/fibonacci","values":"goal rejected","status":6,'
    '"result":false,"id":"g4"}'
)
FRAGMENTS = (
    '{"op":"fragment","id":"rosbridge:504","data":"{\\"op\\":\\"publish\\",\\"top",'
    '"num":0,"total":4}',
    '{"op":"fragment","id":"rosbridge:504","data":"ic\\":\\"/chatter\\",\\"msg\\"",'
    '"num":1,"total":4}',
    '{"op":"fragment","id":"rosbridge:504","data":":{\\"data\\":\\"hello 1381","num":2,"total":4}',
    '{"op":"fragment","id":"rosbridge:504","data":"\\"}}","num":3,"total":4}',
)

# A Foxglove server (foxglove-sdk-python 0.30.3).
FOXGLOVE_SERVER_INFO = (
    '{"op":"serverInfo","name":"","capabilities":["clientPublish","services","parameters",'
    '"parametersSubscribe","connectionGraph","time"],"supportedEncodings":["json","cdr"],'
    '"metadata":{"fg-library":"foxglove-sdk-python/0.30.3"},"sessionId":"1795253552388"}'
)
FOXGLOVE_ADVERTISE = (
    '{"op":"advertise","schemas":[{"id":2,"name":"std_msgs/msg/String",'
    '"encoding":"ros2msg","data":"string data"}],"channels":[{"id":1,"topic":"/chatter",'
    '"encoding":"cdr","schemaId":2}]}'
)


def one(events: list[Event]) -> Event:
    assert isinstance(events, list), events
    assert len(events) == 1, events
    return events[0]


def only_violation(events: list[Event]) -> str:
    event = one(events)
    assert isinstance(event, ProtocolViolation), event
    assert isinstance(event.reason, str)
    assert event.reason
    return event.reason


def raw_engine(topic: str) -> RosbridgeEngine:
    """An engine that subscribed ``topic`` with ``cbor-raw``."""
    engine = RosbridgeEngine()
    engine.subscribe(topic, id="s", compression="cbor-raw")
    return engine


def one_publish(events: list[Event]) -> Publish:
    event = one(events)
    assert isinstance(event, Publish), event
    return event


def msg_of(event: Publish) -> Any:
    """The decoded ``msg`` of any kind of Publish but ``cbor-raw``."""
    if event.kind == "json":
        assert event.message is None
        return decode_json_msg(event.payload)
    if event.kind == "cbor":
        assert event.message is None
        return decode_cbor_msg(event.payload)
    assert event.kind == "parsed", event.kind
    return event.message


def frag(key: Any, data: Any, num: Any, total: Any) -> str:
    return json.dumps({"op": "fragment", "id": key, "data": data, "num": num, "total": total})


def split(text: str, parts: int) -> list[str]:
    """``text`` in at most ``parts`` non-empty pieces (one empty piece for "")."""
    size = max(1, -(-len(text) // parts))
    return [text[i : i + size] for i in range(0, len(text), size)] or [""]


class Clock:
    def __init__(self, now: float = 100.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


# --------------------------------------------------------------------------
# Construction


def test_defaults() -> None:
    e = RosbridgeEngine()
    assert e.max_message_size == 64 * 1024 * 1024
    assert e.fragment_timeout == 10.0
    assert e.fragments_pending == 0


@pytest.mark.parametrize("size", [0, -1])
def test_max_message_size_must_be_positive(size: int) -> None:
    with pytest.raises(ValueError, match="max_message_size"):
        RosbridgeEngine(max_message_size=size)


@pytest.mark.parametrize("timeout", [0, -1.0, math.nan])
def test_fragment_timeout_must_be_positive(timeout: float) -> None:
    with pytest.raises(ValueError, match="fragment_timeout"):
        RosbridgeEngine(fragment_timeout=timeout)


def test_no_async_imports() -> None:
    import ast
    from pathlib import Path

    tree = ast.parse(Path(rb.__file__).read_text())
    imported = {
        alias.name.split(".")[0]
        for node in ast.walk(tree)
        if isinstance(node, ast.Import)
        for alias in node.names
    } | {
        (node.module or "").split(".")[0]
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom)
    }
    assert not imported & {"anyio", "asyncio", "trio", "socket", "websockets"}


# --------------------------------------------------------------------------
# JSON publish: the peek (hot path) and the full-parse fallback


def test_publish_real_frame_takes_the_fast_path_zero_copy() -> None:
    event = one_publish(RosbridgeEngine().receive_text(PUBLISH))
    assert event.topic == "/chatter"
    assert event.kind == "json"
    assert event.message is None
    assert event.log_time_ns is None
    assert event.payload.obj is PUBLISH  # a view of the frame, not a copy
    assert event.payload.nbytes == len(PUBLISH)
    assert decode_json_msg(event.payload) == {"data": "hello 141"}


def test_publish_from_str_and_bytearray() -> None:
    e = RosbridgeEngine()
    from_str = one_publish(e.receive_text(PUBLISH.decode()))
    assert (from_str.topic, from_str.kind) == ("/chatter", "json")
    assert decode_json_msg(from_str.payload) == {"data": "hello 141"}
    buf = bytearray(PUBLISH)
    from_bytearray = one_publish(e.receive_text(buf))
    assert from_bytearray.kind == "json"
    assert from_bytearray.payload.obj is buf
    assert decode_json_msg(from_bytearray.payload) == {"data": "hello 141"}


@pytest.mark.parametrize(
    "frame",
    [
        # Python rosbridge (ujson): spaces and an escaped slash.
        b'{"op": "publish", "topic": "\\/chatter", "msg": {"data": "hello"}}',
        b'{"op":"publish","topic":"\\/ns\\/chatter","msg":{"data":"hello"}}',
        b'{ "op" : "publish" , "topic" : "/chatter" , "msg" : {"data":"hello"} }',
        b'{"topic":"/chatter","op":"publish","msg":{"data":"hello"}}',
        b'{"topic": "\\/chatter", "op": "publish", "msg": {"data": "hello"}}',
        b'{\n  "op": "publish",\n  "topic": "/chatter",\n  "msg": {"data": "hello"}\n}',
    ],
)
def test_publish_peek_variants(frame: bytes) -> None:
    event = one_publish(RosbridgeEngine().receive_text(frame))
    assert event.kind == "json"
    assert event.topic == json.loads(frame)["topic"]
    assert event.payload.obj is frame
    assert decode_json_msg(event.payload) == {"data": "hello"}


@pytest.mark.parametrize(
    ("frame", "topic"),
    [
        (PUBLISH, "/chatter"),  # the real frame: the prefix check
        (b'{"op":"publish","topic":"/a/b_c","msg":{}}', "/a/b_c"),
        (b'{"op":"publish","topic":"/t\xc3\xa9","msg":{}}', "/t\u00e9"),
        (b'{"op": "publish", "topic": "/chatter", "msg": {}}', "/chatter"),  # the peeks
        (b'{"topic":"/chatter","op":"publish","msg":{}}', "/chatter"),
        # not here: receive_text takes these
        (b'{"op":"publish","topic":"\\/chatter","msg":{}}', None),
        (b'{"op": "publish", "topic": "\\/chatter", "msg": {}}', None),
        (b'{"op":"publish","topic":"/t\xff","msg":{}}', None),
        (b'{"op":"publish","topic":"/unterminated', None),
        (b'{"op":"publishx","topic":"/chatter","msg":{}}', None),
        (SERVICE_OK.encode(), None),
        (PUBLISH_CBOR, None),
    ],
)
def test_publish_topic_is_receive_texts_hot_path(frame: bytes, topic: str | None) -> None:
    """``publish_topic`` names the topic exactly when ``receive_text`` gives
    one JSON ``Publish`` of the whole frame on that topic."""
    engine = RosbridgeEngine()
    assert engine.publish_topic(frame) == topic
    if topic is not None:
        event = one_publish(engine.receive_text(frame))
        assert (event.topic, event.kind, event.payload.obj) == (topic, "json", frame)


def test_publish_topic_defers_to_receive_text_while_fragments_wait() -> None:
    engine = RosbridgeEngine()
    assert engine.receive_text(FRAGMENTS[0]) == []
    assert engine.fragments_pending == 1
    assert engine.publish_topic(PUBLISH) is None  # receive_text expires fragments first
    assert one_publish(engine.receive_text(PUBLISH)).topic == "/chatter"


@pytest.mark.parametrize(
    ("frame", "topic"),
    [
        (b'{"msg":{"data":"hello"},"op":"publish","topic":"/chatter"}', "/chatter"),
        (b'{"msg":{"data":"hello"},"topic":"/chatter","op":"publish"}', "/chatter"),
        (b'{"op":"publish","msg":{"data":"hello"},"topic":"/chatter"}', "/chatter"),
        (b'{"id":"x","op":"publish","topic":"/chatter","msg":{"data":"hello"}}', "/chatter"),
        (b' {"op":"publish","topic":"/chatter","msg":{"data":"hello"}}', "/chatter"),
        # Escapes other than \/ in the topic: the full parse decodes them.
        (b'{"op":"publish","topic":"\\u002fchatter","msg":{"data":"hello"}}', "/chatter"),
        (b'{"op":"publish","topic":"/caf\\u00e9","msg":{"data":"hello"}}', "/caf\u00e9"),
        (b'{"op":"publish","topic":"/a\\"b","msg":{"data":"hello"}}', '/a"b'),
        (b'{"op":"publish","topic":"/a\\\\b","msg":{"data":"hello"}}', "/a\\b"),
        # A backslash before a slash is not an escaped slash.
        (b'{"op":"publish","topic":"/a\\\\/b","msg":{"data":"hello"}}', "/a\\/b"),
        (b'{"op":"publish","topic":"/a\\\\\\/b","msg":{"data":"hello"}}', "/a\\/b"),
        (b'{"topic":"/x\\n","op":"publish","msg":{"data":"hello"}}', "/x\n"),
    ],
)
def test_publish_full_parse_fallback(frame: bytes, topic: str) -> None:
    event = one_publish(RosbridgeEngine().receive_text(frame))
    assert event.topic == topic
    assert event.topic == json.loads(frame)["topic"]
    assert msg_of(event) == {"data": "hello"}
    assert event.kind == "parsed"
    assert event.payload.tobytes() == frame


def test_publish_raw_utf8_topic_on_fast_path() -> None:
    frame = '{"op":"publish","topic":"/café/トピック","msg":{"data":"é"}}'
    event = one_publish(RosbridgeEngine().receive_text(frame))
    assert (event.topic, event.kind) == ("/café/トピック", "json")
    assert decode_json_msg(event.payload) == {"data": "é"}


def test_publish_topic_not_utf8_is_a_violation() -> None:
    frame = b'{"op":"publish","topic":"/\xff\xfe","msg":{}}'
    assert "UTF-8" in only_violation(RosbridgeEngine().receive_text(frame))


def test_publish_truncated_after_topic_decodes_to_value_error() -> None:
    """The fast path does not parse: the damage shows when the msg is decoded."""
    frame = b'{"op":"publish","topic":"/chatter","msg":{"data":"hel'
    event = one_publish(RosbridgeEngine().receive_text(frame))
    assert (event.topic, event.kind) == ("/chatter", "json")
    with pytest.raises(ValueError, match="Unterminated string"):
        decode_json_msg(event.payload)


def test_publish_fast_path_without_msg_decodes_to_value_error() -> None:
    event = one_publish(RosbridgeEngine().receive_text(b'{"op":"publish","topic":"/t"}'))
    with pytest.raises(ValueError, match="no 'msg'"):
        decode_json_msg(event.payload)


@pytest.mark.parametrize(
    "frame",
    [
        b'{"msg":{},"op":"publish"}',
        b'{"msg":{},"op":"publish","topic":5}',
        b'{"msg":{},"op":"publish","topic":null}',
        b'{"op":"publish","topic":["/t"],"msg":{}}',
        b'{"op":"publish","msg":{}}',
    ],
)
def test_publish_without_a_string_topic_is_a_violation(frame: bytes) -> None:
    reason = only_violation(RosbridgeEngine().receive_text(frame))
    assert reason.startswith("publish:")
    assert "'topic'" in reason


def test_publish_full_parse_without_msg_is_a_violation() -> None:
    reason = only_violation(RosbridgeEngine().receive_text('{"topic":"/t","x":1,"op":"publish"}'))
    assert reason == "publish: no 'msg'"


def test_publish_full_parse_msg_may_be_any_json() -> None:
    e = RosbridgeEngine()
    event = one_publish(e.receive_text('{"msg":null,"op":"publish","topic":"/t"}'))
    assert event.kind == "parsed"
    assert event.message is None  # present, and null
    event = one_publish(e.receive_text('{"msg":[1,2.5,"x"],"op":"publish","topic":"/t"}'))
    assert event.message == [1, 2.5, "x"]


# --------------------------------------------------------------------------
# decode_json_msg


@pytest.mark.parametrize(
    "payload",
    [b'{"msg":{"a":1}}', b' {"msg":{"a":1}}', b'{"msg":{"a":1}}\n', b'\t{"msg":{"a":1}} '],
)
def test_decode_json_msg_with_and_without_whitespace_around(payload: bytes) -> None:
    assert decode_json_msg(memoryview(payload)) == {"a": 1}


def test_decode_json_msg_of_a_slice_and_of_bytearray() -> None:
    buf = b'xx{"op":"publish","msg":{"a":[1,2]}}yy'
    assert decode_json_msg(memoryview(buf)[2:-2]) == {"a": [1, 2]}
    assert decode_json_msg(memoryview(bytearray(buf[2:-2]))) == {"a": [1, 2]}


@pytest.mark.parametrize(
    ("payload", "words"),
    [
        (b"", "Expecting value"),
        (b"nope", "Expecting value"),
        (b"\xff\xfe{}", "not UTF-8 JSON"),
        (b"\xff\xfe", "not UTF-8 JSON"),
        (b"{\x00}\x00", "not UTF-8 JSON"),
        (b"[1,2]", "no 'msg'"),
        (b'{"op":"publish"}', "no 'msg'"),
        (b'"msg"', "no 'msg'"),
        (b'{"msg":1} x', "Extra data"),
        (b'{"msg":1}{"msg":2}', "Extra data"),
        (b'{"msg":1', "Expecting ',' delimiter"),
        (b'{"msg":"\xff"}', "can't decode"),
    ],
)
def test_decode_json_msg_rejects(payload: bytes, words: str) -> None:
    with pytest.raises(ValueError, match=words):
        decode_json_msg(memoryview(payload))


# --------------------------------------------------------------------------
# CBOR publish


def test_publish_cbor_real_frame_zero_copy() -> None:
    event = one_publish(RosbridgeEngine().receive_binary(PUBLISH_CBOR))
    assert (event.topic, event.kind) == ("/chatter", "cbor")
    assert event.message is None
    assert event.log_time_ns is None
    assert event.payload.obj is PUBLISH_CBOR
    assert event.payload.nbytes == len(PUBLISH_CBOR)
    assert decode_cbor_msg(event.payload) == {"data": "hello 149"}


def test_publish_cbor_from_bytearray() -> None:
    buf = bytearray(PUBLISH_CBOR)
    event = one_publish(RosbridgeEngine().receive_binary(buf))
    assert event.payload.obj is buf
    assert decode_cbor_msg(event.payload) == {"data": "hello 149"}


@pytest.mark.parametrize("order", list(itertools.permutations(["op", "topic", "msg", "id"])))
def test_publish_cbor_any_key_order(order: tuple[str, ...]) -> None:
    fields = {"op": "publish", "topic": "/odom", "msg": {"x": 1.5, "list": [1, 2]}, "id": 7}
    frame = cbor2.dumps({k: fields[k] for k in order})
    event = one_publish(RosbridgeEngine().receive_binary(frame))
    assert (event.topic, event.kind) == ("/odom", "cbor")
    assert decode_cbor_msg(event.payload) == {"x": 1.5, "list": [1, 2]}


def test_publish_cbor_skips_unknown_keys_of_any_type() -> None:
    frame = cbor2.dumps(
        {
            1: "int key",
            b"b": [1, {"nested": b"x"}],
            "extra": cbor2.CBORTag(86, struct.pack("<d", 2.0)),
            "op": "publish",
            "topic": "/t",
            "msg": {"data": "ok"},
        }
    )
    event = one_publish(RosbridgeEngine().receive_binary(frame))
    assert event.topic == "/t"
    assert decode_cbor_msg(event.payload) == {"data": "ok"}


@pytest.mark.parametrize(
    "obj",
    [
        {"op": "publish", "msg": {"data": "x"}},
        {"op": "publish", "topic": "/t"},
        {"op": "publish", "topic": 5, "msg": {}},
        {"op": "publish", "topic": b"/t", "msg": {}},
        {"op": "publish", "topic": None, "msg": {}},
    ],
)
def test_publish_cbor_without_topic_or_msg_is_a_violation(obj: dict[str, Any]) -> None:
    reason = only_violation(RosbridgeEngine().receive_binary(cbor2.dumps(obj)))
    assert "malformed CBOR frame" in reason


def test_publish_cbor_topic_bad_utf8_is_a_violation() -> None:
    # {"op":"publish","topic":<text "\xff">,"msg":{}}
    frame = b"\xa3bopgpublishetopica\xffcmsg\xa0"
    assert "UTF-8" in only_violation(RosbridgeEngine().receive_binary(frame))


# --------------------------------------------------------------------------
# cbor-raw


def test_publish_cbor_raw_real_frame_zero_copy() -> None:
    event = one_publish(raw_engine("/chatter").receive_binary(PUBLISH_CBOR_RAW))
    assert (event.topic, event.kind) == ("/chatter", "cbor-raw")
    assert event.message is None
    assert event.payload.obj is PUBLISH_CBOR_RAW  # a slice of the frame, not a copy
    assert event.payload.tobytes() == RAW_CDR
    assert event.payload.nbytes == len(RAW_CDR)
    assert event.log_time_ns == 1795260957 * 1_000_000_000 + 634917618


def test_publish_cbor_raw_from_bytearray_and_other_orders() -> None:
    msg_items = [("nsecs", 5), ("bytes", b"\x01\x02\x03"), ("secs", 2)]
    for msg_order in itertools.permutations(msg_items):
        for top in itertools.permutations(["msg", "topic", "op"]):
            fields = {"op": "publish", "topic": "/r", "msg": dict(msg_order)}
            buf = bytearray(cbor2.dumps({k: fields[k] for k in top}))
            event = one_publish(raw_engine("/r").receive_binary(buf))
            assert event.kind == "cbor-raw"
            assert event.payload.obj is buf
            assert event.payload.tobytes() == b"\x01\x02\x03"
            assert event.log_time_ns == 2_000_000_005


@pytest.mark.parametrize(
    ("msg", "stamp"),
    [
        ({"bytes": b"abc"}, None),
        ({"bytes": b"abc", "secs": 3}, 3_000_000_000),
        ({"bytes": b"abc", "nsecs": 3}, None),  # no secs: no stamp
        ({"bytes": b"", "secs": 0, "nsecs": 0}, 0),
        ({"bytes": b"abc", "secs": 2**40, "nsecs": 999_999_999}, 2**40 * 10**9 + 999_999_999),
    ],
)
def test_publish_cbor_raw_stamps(msg: dict[str, Any], stamp: int | None) -> None:
    frame = cbor2.dumps({"op": "publish", "topic": "/r", "msg": msg})
    event = one_publish(raw_engine("/r").receive_binary(frame))
    assert event.kind == "cbor-raw"
    assert event.payload.tobytes() == msg["bytes"]
    assert event.log_time_ns == stamp


@pytest.mark.parametrize(
    "frame",
    [
        # found by fuzz/fuzz_cbor_walker.py: the walker read these differently
        # from a full CBOR parse (a negative nsecs was ignored; a second
        # 'bytes' that is an integer was ignored where cbor2 keeps the last)
        "a3626f70677075626c69736865746f706963682f63686174746572636d7367"
        "a365627974657340647365637300656e7365637320",
        "a3626f70677075626c69736865746f706963682f63686174746572636d7367"
        "a26562797465734065627974657300",
    ],
)
def test_cbor_raw_messages_a_full_parse_reads_differently_are_refused(frame: str) -> None:
    event = one(raw_engine("/chatter").receive_binary(bytes.fromhex(frame)))
    assert isinstance(event, ProtocolViolation), event
    assert event.kind == "malformed"


def test_publish_cbor_raw_large_payload() -> None:
    blob = bytes(range(256)) * 400  # a 4-byte length head
    frame = cbor2.dumps({"op": "publish", "topic": "/big", "msg": {"bytes": blob, "secs": 1}})
    event = one_publish(raw_engine("/big").receive_binary(frame))
    assert event.kind == "cbor-raw"
    assert event.payload.tobytes() == blob


def test_a_bytes_field_is_cbor_unless_the_topic_was_subscribed_raw() -> None:
    frame = cbor2.dumps({"op": "publish", "topic": "/r", "msg": {"bytes": b"abc", "secs": 1}})
    plain = one_publish(RosbridgeEngine().receive_binary(frame))
    assert plain.kind == "cbor"
    assert decode_cbor_msg(plain.payload) == {"bytes": b"abc", "secs": 1}
    engine = raw_engine("/r")
    assert one_publish(engine.receive_binary(frame)).kind == "cbor-raw"
    engine.unsubscribe("/r", id="s")
    assert one_publish(engine.receive_binary(frame)).kind == "cbor"
    engine.subscribe("/r", id="s", compression="cbor")
    assert one_publish(engine.receive_binary(frame)).kind == "cbor"


@pytest.mark.parametrize(
    "msg",
    [
        {"bytes": b"abc", "secs": 1, "other": 2},  # a message that has a bytes field
        {"data": b"abc"},
        {},
        {"bytes": b"a", "secs": 1, "nsecs": 2, "x": 3},
    ],
)
def test_publish_cbor_message_that_is_not_raw(msg: dict[str, Any]) -> None:
    frame = cbor2.dumps({"op": "publish", "topic": "/m", "msg": msg})
    event = one_publish(RosbridgeEngine().receive_binary(frame))
    assert event.kind == "cbor"
    assert decode_cbor_msg(event.payload) == msg


def test_publish_cbor_msg_not_a_map() -> None:
    frame = cbor2.dumps({"op": "publish", "topic": "/m", "msg": [1, 2]})
    event = one_publish(RosbridgeEngine().receive_binary(frame))
    assert event.kind == "cbor"
    assert decode_cbor_msg(event.payload) == [1, 2]


# --------------------------------------------------------------------------
# CBOR decoding: RFC 8746 typed arrays, half floats

TYPED = [
    (64, "u1", [0, 1, 255]),
    (68, "u1", [0, 128, 255]),
    (72, "i1", [-128, 0, 127]),
    (65, ">u2", [0, 1, 65535]),
    (66, ">u4", [0, 1, 2**32 - 1]),
    (67, ">u8", [0, 1, 2**64 - 1]),
    (69, "<u2", [0, 1, 65535]),
    (70, "<u4", [0, 1, 2**32 - 1]),
    (71, "<u8", [0, 1, 2**64 - 1]),
    (73, ">i2", [-(2**15), 0, 2**15 - 1]),
    (74, ">i4", [-(2**31), 0, 2**31 - 1]),
    (75, ">i8", [-(2**63), 0, 2**63 - 1]),
    (77, "<i2", [-(2**15), 0, 2**15 - 1]),
    (78, "<i4", [-(2**31), 0, 2**31 - 1]),
    (79, "<i8", [-(2**63), 0, 2**63 - 1]),
    (80, ">f2", [0.5, -2.0, 65504.0]),
    (81, ">f4", [0.5, -2.25, 1e30]),
    (82, ">f8", [1.5, 2.5, -1e300]),
    (84, "<f2", [0.5, -2.0, 65504.0]),
    (85, "<f4", [0.5, -2.25, 1e30]),
    (86, "<f8", [1.5, 2.5, -1e300]),
]


@pytest.mark.parametrize(("tag", "dtype", "values"), TYPED)
def test_typed_arrays(tag: int, dtype: str, values: list[Any]) -> None:
    raw = np.array(values, dtype=dtype).tobytes()
    array = cbor_loads(cbor2.dumps(cbor2.CBORTag(tag, raw)))
    assert isinstance(array, np.ndarray)
    assert array.dtype.isnative  # in this machine's byte order
    assert array.dtype == np.dtype(dtype).newbyteorder("=")
    assert array.tolist() == pytest.approx(values)
    assert array.tolist() == np.array(values, dtype=dtype).tolist()


def test_typed_array_float64_little_endian_example() -> None:
    array = cbor_loads(cbor2.dumps(cbor2.CBORTag(86, struct.pack("<2d", 1.5, 2.5))))
    assert array.dtype == np.float64
    assert array.tolist() == [1.5, 2.5]
    assert not array.flags.writeable  # a read-only view of the frame's bytes


def test_typed_array_big_endian_to_native_order() -> None:
    array = cbor_loads(cbor2.dumps(cbor2.CBORTag(82, struct.pack(">2d", 1.5, 2.5))))
    assert array.dtype == np.float64
    assert array.dtype.isnative
    assert array.tolist() == [1.5, 2.5]
    array = cbor_loads(cbor2.dumps(cbor2.CBORTag(65, struct.pack(">2H", 1, 0x0102))))
    assert array.dtype == np.uint16
    assert array.tolist() == [1, 0x0102]


def test_typed_arrays_inside_a_published_message() -> None:
    frame = cbor2.dumps(
        {
            "op": "publish",
            "topic": "/scan",
            "msg": {
                "ranges": cbor2.CBORTag(85, struct.pack("<3f", 0.5, 1.0, 2.0)),
                "header": {"stamp": {"sec": 1, "nanosec": 2}},
                "ids": cbor2.CBORTag(78, struct.pack("<2i", -5, 5)),
                "empty": cbor2.CBORTag(86, b""),
            },
        }
    )
    event = one_publish(RosbridgeEngine().receive_binary(frame))
    assert event.kind == "cbor"
    msg = decode_cbor_msg(event.payload)
    assert msg["ranges"].dtype == np.float32
    assert msg["ranges"].tolist() == [0.5, 1.0, 2.0]
    assert msg["ids"].tolist() == [-5, 5]
    assert msg["empty"].size == 0
    assert msg["header"] == {"stamp": {"sec": 1, "nanosec": 2}}


def test_typed_array_with_a_partial_item_is_an_error() -> None:
    with pytest.raises(ValueError, match="invalid CBOR"):
        cbor_loads(cbor2.dumps(cbor2.CBORTag(86, b"\x00" * 9)))
    frame = cbor2.dumps({"op": "publish", "topic": "/t", "msg": cbor2.CBORTag(78, b"abc")})
    event = one_publish(RosbridgeEngine().receive_binary(frame))  # the peek does not decode
    with pytest.raises(ValueError, match="invalid CBOR"):
        decode_cbor_msg(event.payload)


def test_other_tags_pass_through() -> None:
    value = cbor_loads(cbor2.dumps(cbor2.CBORTag(86, [1, 2])))  # not a byte string
    assert isinstance(value, cbor2.CBORTag)
    assert (value.tag, list(value.value)) == (86, [1, 2])  # cbor2 freezes it
    value = cbor_loads(cbor2.dumps(cbor2.CBORTag(4000, "x")))
    assert isinstance(value, cbor2.CBORTag)
    assert (value.tag, value.value) == (4000, "x")


@pytest.mark.parametrize(
    ("hex_", "value"),
    [("f93800", 0.5), ("f93c00", 1.0), ("f9c000", -2.0), ("f97bff", 65504.0), ("f90001", 2**-24)],
)
def test_half_floats(hex_: str, value: float) -> None:
    assert cbor_loads(bytes.fromhex(hex_)) == value


def test_half_float_inside_a_published_message() -> None:
    # {"op":"publish","topic":"/h","msg":{"v":<half 0.5>}}
    frame = b"\xa3bopgpublishetopicb/hcmsg\xa1av\xf9\x38\x00"
    event = one_publish(RosbridgeEngine().receive_binary(frame))
    assert decode_cbor_msg(event.payload) == {"v": 0.5}


@pytest.mark.parametrize(
    "data",
    [b"", b"\xa3bop", bytes.fromhex("ff"), b"\x1c", PUBLISH_CBOR[:-3], b"\x81" * 100 + b"\x00"],
)
def test_cbor_loads_malformed_raises_value_error(data: bytes) -> None:
    with pytest.raises(ValueError, match="invalid CBOR"):
        cbor_loads(data)


@pytest.mark.parametrize("data", [cbor2.dumps([1]), cbor2.dumps({"op": "publish"}), b"\x01"])
def test_decode_cbor_msg_without_msg(data: bytes) -> None:
    with pytest.raises(ValueError, match="no 'msg'"):
        decode_cbor_msg(memoryview(data))


# --------------------------------------------------------------------------
# Service responses, status, actions (JSON)


def test_service_response_real() -> None:
    event = one(RosbridgeEngine().receive_text(SERVICE_OK))
    assert event == ServiceResponse(
        "c1", "/set_flag", True, {"success": True, "message": "flag set to True"}
    )


def test_service_response_failure_real() -> None:
    event = one(RosbridgeEngine().receive_text(SERVICE_FAILED))
    assert event == ServiceResponse(
        "c7", "/slow_trigger", False, "Timeout exceeded while waiting for service response"
    )


def test_service_response_without_id_or_values() -> None:
    event = one(
        RosbridgeEngine().receive_text('{"op":"service_response","service":"/s","result":false}')
    )
    assert event == ServiceResponse(None, "/s", False, None)


def test_status_real_with_and_without_id() -> None:
    e = RosbridgeEngine()
    assert one(e.receive_text(STATUS)) == Status("error", "unknown operation: bogus_op", "b1")
    assert one(e.receive_text(STATUS_NO_ID)) == Status("error", "unknown operation: bogus_op", None)


def test_status_msg_that_is_not_a_string_becomes_json_text() -> None:
    event = one(RosbridgeEngine().receive_text('{"op":"status","level":"info","msg":{"a":[1]}}'))
    assert isinstance(event, Status)
    assert json.loads(event.msg) == {"a": [1]}


def test_action_feedback_real() -> None:
    event = one(RosbridgeEngine().receive_text(FEEDBACK))
    assert event == ActionFeedback("g1", "/fibonacci", {"sequence": [0, 1, 1]})


def test_action_result_real_succeeded_and_rejected() -> None:
    e = RosbridgeEngine()
    assert one(e.receive_text(RESULT)) == ActionResult(
        "g1", "/fibonacci", 4, True, {"sequence": [0, 1, 1, 2, 3]}
    )
    assert one(e.receive_text(REJECTED)) == ActionResult(
        "g4", "/fibonacci", 6, False, "goal rejected"
    )


def test_action_result_without_status() -> None:
    event = one(
        RosbridgeEngine().receive_text(
            '{"op":"action_result","action":"/a","values":{},"result":true,"id":"g"}'
        )
    )
    assert event == ActionResult("g", "/a", None, True, {})


@pytest.mark.parametrize(
    ("frame", "words"),
    [
        ('{"op":"service_response","service":"/s","result":"true","id":"c"}', "'result'"),
        ('{"op":"service_response","service":"/s","result":1,"id":"c"}', "'result'"),
        ('{"op":"service_response","service":7,"result":true,"id":"c"}', "'service'"),
        ('{"op":"action_result","action":"/a","status":"4","result":true}', "'status'"),
        ('{"op":"action_result","action":"/a","status":4.0,"result":true}', "'status'"),
        ('{"op":"action_result","action":"/a","status":true,"result":true}', "'status'"),
        ('{"op":"action_result","action":"/a","status":4,"result":"yes"}', "'result'"),
        ('{"op":"action_result","action":null,"status":4,"result":true}', "'action'"),
        ('{"op":"action_feedback","values":{},"id":"g"}', "'action'"),
        ('{"op":"action_feedback","action":["/a"],"values":{}}', "'action'"),
    ],
)
def test_wrong_field_types_are_violations(frame: str, words: str) -> None:
    reason = only_violation(RosbridgeEngine().receive_text(frame))
    assert reason.startswith(json.loads(frame)["op"] + ":")
    assert words in reason


# --------------------------------------------------------------------------
# Non-publish ops in CBOR binary frames


def test_cbor_action_and_service_frames_are_parsed_whole() -> None:
    e = RosbridgeEngine()
    for text in (FEEDBACK, RESULT, REJECTED, SERVICE_OK, SERVICE_FAILED, STATUS, STATUS_NO_ID):
        assert e.receive_binary(cbor2.dumps(json.loads(text))) == e.receive_text(text)


def test_cbor_action_result_values_with_typed_array() -> None:
    frame = cbor2.dumps(
        {
            "id": "g2",
            "values": {"sequence": cbor2.CBORTag(78, struct.pack("<3i", 0, 1, 1))},
            "status": 4,
            "result": True,
            "action": "/fibonacci",
            "op": "action_result",
        }
    )
    event = one(RosbridgeEngine().receive_binary(frame))
    assert isinstance(event, ActionResult)
    assert (event.id, event.action, event.status, event.result) == ("g2", "/fibonacci", 4, True)
    assert event.values["sequence"].tolist() == [0, 1, 1]


# --------------------------------------------------------------------------
# Foxglove frames


@pytest.mark.parametrize(
    "frame",
    [
        FOXGLOVE_SERVER_INFO,
        FOXGLOVE_ADVERTISE,
        '{"channels":[{"id":1,"topic":"/t"}]}',
        '{"sessionId":"1"}',
        '{"op":7,"channels":[]}',
    ],
)
def test_foxglove_frames_are_foreign(frame: str) -> None:
    e = RosbridgeEngine()
    for event in (
        one(e.receive_text(frame)),
        one(e.receive_binary(cbor2.dumps(json.loads(frame)))),
    ):
        assert isinstance(event, ForeignProtocol), event
        assert event.detected == "foxglove-ws"
        assert event.reason


def test_advertise_without_channels_is_not_foreign() -> None:
    reason = only_violation(RosbridgeEngine().receive_text('{"op":"advertise","topic":"/t"}'))
    assert "unknown op 'advertise'" in reason


def test_foxglove_binary_message_data_is_a_violation() -> None:
    frame = b"\x01" + struct.pack("<IQ", 1, 123) + b"\x00\x01\x00\x00"
    only_violation(RosbridgeEngine().receive_binary(frame))


# --------------------------------------------------------------------------
# Bad input: always one ProtocolViolation, never an exception


@pytest.mark.parametrize(
    ("frame", "words"),
    [
        (b"", "not JSON"),
        (b"hello", "not JSON"),
        (b'{"op":"status"', "not JSON"),
        (b"\xff\xfe{}", "not JSON"),
        (b"[1,2,3]", "got list"),
        (b'"publish"', "got str"),
        (b"null", "got NoneType"),
        (b"42", "got int"),
        (b"{}", "without an 'op'"),
        (b'{"topic":"/t","msg":{}}', "without an 'op'"),
        (b'{"op":null}', "without an 'op'"),
        (b'{"op":["publish"]}', "without an 'op'"),
        (b'{"op":"bogus_op"}', "unknown op 'bogus_op'"),
        (b'{"op":"subscribe","topic":"/t"}', "unknown op 'subscribe'"),
        (b'{"op":""}', "unknown op ''"),
        (b'{"op":"png","data":"iVBORw0KGgo="}', "png"),
        (b"[" * 100_000 + b"]" * 100_000, "nests deeper than 100"),
        (
            b'{"op":"status","msg":' + b"[" * 100_000 + b"]" * 100_000 + b"}",
            "nests deeper than 100",
        ),
    ],
)
def test_bad_text_frames(frame: bytes, words: str) -> None:
    e = RosbridgeEngine()
    assert words in only_violation(e.receive_text(frame))
    assert words in only_violation(e.receive_text(bytearray(frame)))
    try:
        text = frame.decode()
    except UnicodeDecodeError:
        return
    assert words in only_violation(e.receive_text(text))


def _indefinite_map(obj: dict[str, Any]) -> bytes:
    body = cbor2.dumps(obj)
    assert body[0] >> 5 == 5
    return b"\xbf" + body[1:] + b"\xff"


@pytest.mark.parametrize(
    ("frame", "words"),
    [
        (b"", "truncated"),
        (PUBLISH_CBOR[:1], "truncated"),
        (PUBLISH_CBOR[:20], "truncated"),
        (PUBLISH_CBOR[:-1], "truncated"),
        (PUBLISH_CBOR_RAW[:-5], "truncated"),
        (cbor2.dumps(json.loads(RESULT))[:-2], "truncated"),
        (b"\xbb" + b"\xff" * 8, "truncated"),  # a map of 2**64-1 entries
        (b"\xa1\x5b" + b"\xff" * 8, "truncated"),  # a 2**64-1 byte string as a key
        (_indefinite_map({"op": "publish", "topic": "/t", "msg": {}}), "indefinite"),
        (_indefinite_map(json.loads(STATUS)), "indefinite"),
        (b"\xa1\x1c\x00", "reserved"),
        (cbor2.dumps([1, 2]), "not a CBOR map"),
        (cbor2.dumps("publish"), "not a CBOR map"),
        (cbor2.dumps(None), "not a CBOR map"),
        (PUBLISH, "not a CBOR map"),  # JSON in a binary frame
        (b"\xa2bopfstatuscmsg" + b"\x81" * 100 + b"\x00", "too deeply"),
        (cbor2.dumps({"topic": "/t", "msg": {}}), "without an 'op'"),
        (cbor2.dumps({"op": "bogus"}), "unknown op 'bogus'"),
        (cbor2.dumps({"op": "publish", "msg": {}}), "without a topic"),
        (cbor2.dumps({"op": "service_response", "service": "/s", "result": 1}), "'result'"),
        (cbor2.dumps({"op": "action_result", "action": "/a", "status": "4"}), "'status'"),
    ],
)
def test_bad_binary_frames(frame: bytes, words: str) -> None:
    e = RosbridgeEngine()
    assert words in only_violation(e.receive_binary(frame))
    assert words in only_violation(e.receive_binary(bytearray(frame)))


def test_engine_keeps_working_after_bad_frames() -> None:
    e = RosbridgeEngine()
    only_violation(e.receive_text("garbage"))
    only_violation(e.receive_binary(b"\xff"))
    assert one_publish(e.receive_text(PUBLISH)).topic == "/chatter"
    assert one_publish(e.receive_binary(PUBLISH_CBOR)).topic == "/chatter"


# --------------------------------------------------------------------------
# Fragments


def test_fragments_real_in_order() -> None:
    e = RosbridgeEngine()
    for i, text in enumerate(FRAGMENTS[:-1]):
        assert e.receive_text(text) == []
        assert e.fragments_pending == 1, i
    event = one_publish(e.receive_text(FRAGMENTS[-1]))
    assert event.topic == "/chatter"
    assert event.kind == "parsed"
    assert event.message == {"data": "hello 1381"}
    assert json.loads(event.payload.tobytes()) == {
        "op": "publish",
        "topic": "/chatter",
        "msg": {"data": "hello 1381"},
    }
    assert e.fragments_pending == 0


@pytest.mark.parametrize("order", list(itertools.permutations(range(4))))
def test_fragments_any_order(order: tuple[int, ...]) -> None:
    e = RosbridgeEngine()
    events: list[Event] = []
    for index in order:
        assert events == []  # nothing before the last part
        events = e.receive_text(FRAGMENTS[index])
    assert one_publish(events).message == {"data": "hello 1381"}
    assert e.fragments_pending == 0


def test_fragments_as_cbor_binary_frames() -> None:
    e = RosbridgeEngine()
    for text in FRAGMENTS[:-1]:
        assert e.receive_binary(cbor2.dumps(json.loads(text))) == []
    event = one_publish(e.receive_binary(cbor2.dumps(json.loads(FRAGMENTS[-1]))))
    assert (event.topic, event.message) == ("/chatter", {"data": "hello 1381"})


def test_fragment_duplicate_part_is_ignored() -> None:
    e = RosbridgeEngine()
    assert e.receive_text(FRAGMENTS[0]) == []
    assert e.receive_text(FRAGMENTS[1]) == []
    reason = only_violation(e.receive_text(FRAGMENTS[1]))
    assert "part 1 sent twice" in reason
    # A duplicate with other data does not replace the first copy either.
    changed = json.loads(FRAGMENTS[0]) | {"data": "garbage"}
    assert "part 0 sent twice" in only_violation(e.receive_text(json.dumps(changed)))
    assert e.fragments_pending == 1
    assert e.receive_text(FRAGMENTS[2]) == []
    assert one_publish(e.receive_text(FRAGMENTS[3])).message == {"data": "hello 1381"}


def test_fragment_total_changed_drops_the_message() -> None:
    e = RosbridgeEngine()
    assert e.receive_text(FRAGMENTS[0]) == []
    assert e.receive_text(FRAGMENTS[1]) == []
    changed = json.loads(FRAGMENTS[2]) | {"total": 5}
    assert "'total' changed" in only_violation(e.receive_text(json.dumps(changed)))
    assert e.fragments_pending == 0
    events = e.receive_text(FRAGMENTS[3])  # the rest of the original: no message
    assert not any(isinstance(ev, Publish) for ev in events)


def test_fragment_single_part() -> None:
    text = '{"op":"status","level":"info","msg":"one part","id":"s"}'
    event = one(RosbridgeEngine().receive_text(frag("k", text, 0, 1)))
    assert event == Status("info", "one part", "s")


def test_fragments_reassemble_any_op() -> None:
    e = RosbridgeEngine()
    for text in (SERVICE_OK, RESULT, FEEDBACK, STATUS, FOXGLOVE_SERVER_INFO):
        parts = split(text, 3)
        events: list[Event] = []
        for num, part in enumerate(parts):
            events = e.receive_text(frag(f"id-{text[:20]}", part, num, len(parts)))
        assert events == e.receive_text(text)


def test_fragments_of_different_ids_interleave() -> None:
    e = RosbridgeEngine()
    a = split('{"op":"publish","topic":"/a","msg":{"data":1}}', 3)
    b = split('{"op":"publish","topic":"/b","msg":{"data":2}}', 2)
    assert e.receive_text(frag("a", a[0], 0, 3)) == []
    assert e.receive_text(frag("b", b[1], 1, 2)) == []
    assert e.receive_text(frag("a", a[2], 2, 3)) == []
    assert e.fragments_pending == 2
    assert one_publish(e.receive_text(frag("b", b[0], 0, 2))).topic == "/b"
    assert e.fragments_pending == 1
    event = one_publish(e.receive_text(frag("a", a[1], 1, 3)))
    assert (event.topic, event.message) == ("/a", {"data": 1})
    assert e.fragments_pending == 0


def test_fragment_id_reused_after_completion() -> None:
    e = RosbridgeEngine()
    for _ in range(3):
        for text in FRAGMENTS[:-1]:
            assert e.receive_text(text) == []
        assert one_publish(e.receive_text(FRAGMENTS[-1])).topic == "/chatter"


def test_fragment_over_max_message_size_is_dropped() -> None:
    clock = Clock()
    e = RosbridgeEngine(max_message_size=100, fragment_timeout=10, clock=clock)
    assert e.receive_text(frag("big", "x" * 40, 0, 4)) == []
    assert e.receive_text(frag("big", "x" * 40, 1, 4)) == []
    reason = only_violation(e.receive_text(frag("big", "x" * 40, 2, 4)))
    assert "over 100 characters" in reason
    assert "dropped" in reason
    assert e.fragments_pending == 0
    # The rest of it never makes a message.
    events = e.receive_text(frag("big", "x" * 40, 3, 4))
    assert not any(isinstance(ev, Publish) for ev in events)
    # Once whatever was held has expired, a message of the full size fits again.
    clock.now += 11
    whole = '{"op":"status","level":"info","msg":"' + "y" * 50 + '"}'
    assert len(whole) <= 100
    parts = split(whole, 2)
    assert e.receive_text(frag("ok", parts[0], 0, 2)) == []
    assert isinstance(one(e.receive_text(frag("ok", parts[1], 1, 2))), Status)


def test_fragment_single_part_over_max_message_size() -> None:
    e = RosbridgeEngine(max_message_size=10)
    reason = only_violation(e.receive_text(frag("k", '{"op":"status","msg":"x"}', 0, 1)))
    assert "over 10 characters" in reason
    assert e.fragments_pending == 0


def test_fragments_exactly_max_message_size_fit() -> None:
    whole = '{"op":"status","level":"info","msg":"' + "y" * 30 + '"}'
    e = RosbridgeEngine(max_message_size=len(whole))
    parts = split(whole, 3)
    for num, part in enumerate(parts[:-1]):
        assert e.receive_text(frag("k", part, num, 3)) == []
    assert isinstance(one(e.receive_text(frag("k", parts[-1], 2, 3))), Status)


def test_fragments_held_in_total_are_bounded() -> None:
    """``max_message_size`` also bounds what all messages in reassembly hold."""
    e = RosbridgeEngine(max_message_size=100)
    assert e.receive_text(frag("a", "x" * 60, 0, 2)) == []
    assert "over 100 characters" in only_violation(e.receive_text(frag("b", "y" * 60, 0, 2)))
    assert e.fragments_pending == 1
    # Two messages that fit together both complete ...
    whole = '{"op":"status","msg":"' + "z" * 10 + '"}'  # 34 characters
    e2 = RosbridgeEngine(max_message_size=100)
    assert e2.receive_text(frag("a", whole[:5], 0, 2)) == []
    assert e2.receive_text(frag("b", "y" * 60, 0, 2)) == []
    assert isinstance(one(e2.receive_text(frag("a", whole[5:], 1, 2))), Status)  # 94 held
    # ... and a completed message releases its share: 60 held, 39 more fit.
    assert e2.receive_text(frag("c", "w" * 39, 0, 2)) == []
    assert e2.fragments_pending == 2
    assert "over 100 characters" in only_violation(e2.receive_text(frag("d", "v" * 2, 0, 2)))


def test_fragments_time_out() -> None:
    clock = Clock()
    e = RosbridgeEngine(fragment_timeout=10, clock=clock)
    assert e.receive_text(FRAGMENTS[0]) == []
    assert e.receive_text(FRAGMENTS[1]) == []
    clock.now += 9.5
    assert one_publish(e.receive_text(PUBLISH)).topic == "/chatter"
    assert e.fragments_pending == 1  # not yet
    clock.now += 1.0  # 10.5 s since the parts stopped
    dropped, publish = e.receive_binary(PUBLISH_CBOR)
    assert isinstance(dropped, ProtocolViolation) and dropped.kind == "fragment_limit"
    assert isinstance(publish, Publish) and publish.topic == "/chatter"
    assert e.fragments_pending == 0
    for text in FRAGMENTS[2:]:  # the late rest of it never makes a message
        late = e.receive_text(text)
        assert not any(isinstance(ev, Publish) for ev in late)
        assert [ev.kind for ev in late if isinstance(ev, ProtocolViolation)] == ["fragment_limit"]


def test_fragment_timeout_only_drops_the_stale_message() -> None:
    clock = Clock()
    e = RosbridgeEngine(fragment_timeout=10, clock=clock)
    assert e.receive_text(frag("old", "{", 0, 2)) == []
    clock.now += 8
    whole = '{"op":"status","msg":"fresh"}'
    assert e.receive_text(frag("new", whole[:5], 0, 2)) == []
    clock.now += 4  # "old" is 12 s old, "new" 4 s
    expired, status = e.receive_text(frag("new", whole[5:], 1, 2))
    assert isinstance(expired, ProtocolViolation) and expired.kind == "fragment_limit"
    assert "'old'" in expired.reason and "1 of 2 parts" in expired.reason
    assert status == Status("", "fresh", None)
    assert e.fragments_pending == 0


def test_at_most_16_messages_in_reassembly_oldest_dropped() -> None:
    clock = Clock()
    e = RosbridgeEngine(clock=clock)
    wholes = [f'{{"op":"publish","topic":"/t{i}","msg":{{"i":{i}}}}}' for i in range(17)]
    for i, whole in enumerate(wholes):
        clock.now += 0.01
        events = e.receive_text(frag(f"m{i}", whole[:10], 0, 2))
        if i < 16:
            assert events == []
        else:  # the 17th evicts the oldest, and says so
            event = one(events)
            assert isinstance(event, ProtocolViolation) and event.kind == "fragment_limit"
            assert "'m0'" in event.reason
        assert e.fragments_pending == min(i + 1, 16)
    # m0 was dropped; m1..m16 complete.
    for i in range(1, 17):
        event = one_publish(e.receive_text(frag(f"m{i}", wholes[i][10:], 1, 2)))
        assert (event.topic, event.message) == (f"/t{i}", {"i": i})
    assert e.fragments_pending == 0
    assert not any(
        isinstance(ev, Publish) for ev in e.receive_text(frag("m0", wholes[0][10:], 1, 2))
    )


def test_fragment_inside_a_fragment_is_a_violation() -> None:
    inner = frag("inner", '{"op":"status","msg":"x"}', 0, 1)
    parts = split(inner, 2)
    e = RosbridgeEngine()
    assert e.receive_text(frag("outer", parts[0], 0, 2)) == []
    reason = only_violation(e.receive_text(frag("outer", parts[1], 1, 2)))
    assert "a fragment inside a fragment" in reason
    assert e.fragments_pending == 0


@pytest.mark.parametrize("whole", ["not json at all", '{"op":"publish"', "", "[1,"])
def test_reassembled_non_json_is_a_violation(whole: str) -> None:
    e = RosbridgeEngine()
    parts = split(whole, 2)
    events: list[Event] = []
    for num, part in enumerate(parts):
        events = e.receive_text(frag("k", part, num, len(parts)))
    assert "the reassembled message is not JSON" in only_violation(events)
    assert e.fragments_pending == 0


def test_reassembled_json_that_is_not_an_object() -> None:
    assert "got list" in only_violation(RosbridgeEngine().receive_text(frag("k", "[1]", 0, 1)))


@pytest.mark.parametrize(
    ("fields", "words"),
    [
        ({"id": 5}, "'id' and 'data' must be strings"),
        ({"id": None}, "'id' and 'data' must be strings"),
        ({"data": 5}, "'id' and 'data' must be strings"),
        ({"data": None}, "'id' and 'data' must be strings"),
        ({"num": "0"}, "bad 'num'/'total'"),
        ({"num": 1.0}, "bad 'num'/'total'"),
        ({"num": None}, "bad 'num'/'total'"),
        ({"total": "2"}, "bad 'num'/'total'"),
        ({"num": -1}, "bad 'num'/'total'"),
        ({"num": 2}, "bad 'num'/'total'"),
        ({"num": 3}, "bad 'num'/'total'"),
        ({"num": 0, "total": 0}, "bad 'num'/'total'"),
        ({"num": 0, "total": -1}, "bad 'num'/'total'"),
    ],
)
def test_bad_fragment_fields(fields: dict[str, Any], words: str) -> None:
    obj = {"op": "fragment", "id": "k", "data": "{", "num": 0, "total": 2} | fields
    e = RosbridgeEngine()
    reason = only_violation(e.receive_text(json.dumps(obj)))
    assert reason.startswith("fragment")
    assert words in reason
    assert e.fragments_pending == 0


def test_missing_fragment_fields() -> None:
    for missing in ("id", "data", "num", "total"):
        obj = {"op": "fragment", "id": "k", "data": "{", "num": 0, "total": 2}
        del obj[missing]
        only_violation(RosbridgeEngine().receive_text(json.dumps(obj)))


# --------------------------------------------------------------------------
# Outbound builders


def test_subscribe_minimal() -> None:
    text = RosbridgeEngine().subscribe("/chatter", id="s1")
    assert json.loads(text) == {"op": "subscribe", "id": "s1", "topic": "/chatter"}
    assert '"type"' not in text


def test_subscribe_all_options() -> None:
    text = RosbridgeEngine().subscribe(
        "/chatter",
        id="s2",
        type="std_msgs/msg/String",
        throttle_rate=100,
        queue_length=5,
        compression="cbor-raw",
        fragment_size=1000,
    )
    assert json.loads(text) == {
        "op": "subscribe",
        "id": "s2",
        "topic": "/chatter",
        "type": "std_msgs/msg/String",
        "throttle_rate": 100,
        "queue_length": 5,
        "compression": "cbor-raw",
        "fragment_size": 1000,
    }


def test_subscribe_zero_options_are_omitted() -> None:
    obj = json.loads(
        RosbridgeEngine().subscribe("/t", id="s", throttle_rate=0, queue_length=0, compression=None)
    )
    assert obj == {"op": "subscribe", "id": "s", "topic": "/t"}


@pytest.mark.parametrize(("compression", "sent"), [("cbor", "cbor"), ("cbor-raw", "cbor-raw")])
def test_subscribe_compression(compression: str, sent: str) -> None:
    obj = json.loads(RosbridgeEngine().subscribe("/t", id="s", compression=compression))
    assert obj["compression"] == sent


@pytest.mark.parametrize("compression", ["none", None])
def test_subscribe_no_compression_is_omitted(compression: str | None) -> None:
    obj = json.loads(RosbridgeEngine().subscribe("/t", id="s", compression=compression))
    assert "compression" not in obj


def test_subscribe_png_compression_is_allowed() -> None:
    obj = json.loads(RosbridgeEngine().subscribe("/t", id="s", compression="png"))
    assert obj["compression"] == "png"


@pytest.mark.parametrize("compression", ["", "CBOR", "gzip", "json"])
def test_subscribe_unknown_compression(compression: str) -> None:
    with pytest.raises(ValueError, match="compression"):
        RosbridgeEngine().subscribe("/t", id="s", compression=compression)


def test_subscribe_empty_type_is_refused() -> None:
    with pytest.raises(TypeError, match="type"):
        RosbridgeEngine().subscribe("/t", id="s", type="")


@pytest.mark.parametrize(
    "kwargs", [{"throttle_rate": -1}, {"queue_length": -1}, {"fragment_size": 0}]
)
def test_subscribe_negative_numbers(kwargs: dict[str, int]) -> None:
    with pytest.raises(ValueError, match=r"must not be negative|must be positive"):
        RosbridgeEngine().subscribe("/t", id="s", **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(("topic", "id_"), [("", "s"), ("/t", ""), (None, "s"), ("/t", 5)])
def test_subscribe_bad_topic_or_id(topic: Any, id_: Any) -> None:
    with pytest.raises(TypeError, match="non-empty str"):
        RosbridgeEngine().subscribe(topic, id=id_)


def test_subscribe_escapes_the_topic() -> None:
    topic = '/a"b\\c/é'
    assert json.loads(RosbridgeEngine().subscribe(topic, id="s"))["topic"] == topic


def test_unsubscribe_unadvertise() -> None:
    assert json.loads(RosbridgeEngine().unsubscribe("/t", id="s1")) == {
        "op": "unsubscribe",
        "id": "s1",
        "topic": "/t",
    }
    assert json.loads(RosbridgeEngine.unadvertise("/t", id="a1")) == {
        "op": "unadvertise",
        "id": "a1",
        "topic": "/t",
    }
    for builder in (RosbridgeEngine().unsubscribe, RosbridgeEngine.unadvertise):
        with pytest.raises(TypeError):
            builder("", id="x")
        with pytest.raises(TypeError):
            builder("/t", id="")


def test_advertise() -> None:
    assert json.loads(RosbridgeEngine.advertise("/t", "std_msgs/msg/String", id="a1")) == {
        "op": "advertise",
        "id": "a1",
        "topic": "/t",
        "type": "std_msgs/msg/String",
    }
    assert json.loads(
        RosbridgeEngine.advertise("/t", "std_msgs/msg/String", id="a2", latch=True, queue_size=3)
    ) == {
        "op": "advertise",
        "id": "a2",
        "topic": "/t",
        "type": "std_msgs/msg/String",
        "latch": True,
        "queue_size": 3,
    }
    assert "latch" not in json.loads(RosbridgeEngine.advertise("/t", "T", id="a", latch=False))
    with pytest.raises(TypeError, match="type"):
        RosbridgeEngine.advertise("/t", "", id="a")


@pytest.mark.parametrize(
    "msg", [{"data": "hello"}, {}, {"a": [1, 2.5, None, True], "b": {"c": '/x"y'}}]
)
def test_publish_builder(msg: dict[str, Any]) -> None:
    msg_json = json.dumps(msg)
    for arg in (msg_json, msg_json.encode()):
        text = RosbridgeEngine.publish("/out", arg)
        assert json.loads(text) == {"op": "publish", "topic": "/out", "msg": msg}
        # What we send is what the engine reads back on its fast path.
        event = one_publish(RosbridgeEngine().receive_text(text))
        assert (event.topic, event.kind) == ("/out", "json")
        assert decode_json_msg(event.payload) == msg


def test_publish_builder_escapes_the_topic_and_refuses_empty() -> None:
    text = RosbridgeEngine.publish('/a"b', "{}")
    assert json.loads(text)["topic"] == '/a"b'
    with pytest.raises(TypeError):
        RosbridgeEngine.publish("", "{}")


def test_call_service() -> None:
    assert json.loads(RosbridgeEngine.call_service("/s", {"data": True}, id="c1")) == {
        "op": "call_service",
        "id": "c1",
        "service": "/s",
        "args": {"data": True},
    }
    assert json.loads(
        RosbridgeEngine.call_service("/s", None, id="c2", timeout=2.5, type="std_srvs/srv/Trigger")
    ) == {
        "op": "call_service",
        "id": "c2",
        "service": "/s",
        "type": "std_srvs/srv/Trigger",
        "timeout": 2.5,
    }


def test_call_service_timeout_omitted_when_none() -> None:
    assert "timeout" not in json.loads(RosbridgeEngine.call_service("/s", {}, id="c"))


@pytest.mark.parametrize("timeout", [0, 0.0, -1, -0.5, math.nan, math.inf, -math.inf])
def test_call_service_timeout_must_be_positive_and_finite(timeout: float) -> None:
    with pytest.raises(ValueError, match="timeout"):
        RosbridgeEngine.call_service("/s", {}, id="c", timeout=timeout)


def test_call_service_bad_names() -> None:
    with pytest.raises(TypeError):
        RosbridgeEngine.call_service("", {}, id="c")
    with pytest.raises(TypeError):
        RosbridgeEngine.call_service("/s", {}, id="")
    with pytest.raises(TypeError):
        RosbridgeEngine.call_service("/s", {}, id="c", type="")


def test_send_action_goal() -> None:
    text = RosbridgeEngine.send_action_goal(
        "/fibonacci", "example_interfaces/action/Fibonacci", {"order": 5}, id="g1"
    )
    assert json.loads(text) == {
        "op": "send_action_goal",
        "id": "g1",
        "action": "/fibonacci",
        "action_type": "example_interfaces/action/Fibonacci",
        "args": {"order": 5},
        "feedback": True,
    }
    text = RosbridgeEngine.send_action_goal("/f", "pkg/action/F", {}, id="g2", feedback=False)
    assert json.loads(text)["feedback"] is False
    with pytest.raises(TypeError):
        RosbridgeEngine.send_action_goal("/f", "", {}, id="g")


def test_cancel_action_goal() -> None:
    assert json.loads(RosbridgeEngine.cancel_action_goal("/fibonacci", id="g1")) == {
        "op": "cancel_action_goal",
        "id": "g1",
        "action": "/fibonacci",
    }
    with pytest.raises(TypeError):
        RosbridgeEngine.cancel_action_goal("", id="g1")


# --------------------------------------------------------------------------
# Properties (hypothesis)

# Topics: printable text, often with slashes, quotes, backslashes and
# non-ASCII. Surrogates cannot be sent in a WebSocket text frame.
topics = st.text(
    alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), min_size=0, max_size=24
) | st.from_regex(r"\A(/[a-zA-Z_\u00e9\u30c8\\\"]{1,6}){1,4}\Z")
json_scalars = (
    st.none()
    | st.booleans()
    | st.integers(-(2**70), 2**70)
    | st.floats(allow_nan=False)
    | st.text(max_size=8)
)
json_values = st.recursive(
    json_scalars,
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3)
    ),
    max_leaves=10,
)
msgs = st.dictionaries(st.text(max_size=8), json_values, max_size=4)
separators = st.sampled_from([None, (",", ":"), (", ", ": "), (" , ", " : ")])


@given(
    topics,
    msgs,
    st.permutations(["op", "topic", "msg"]),
    separators,
    st.booleans(),
    st.booleans(),
    st.sampled_from([bytes, bytearray, str]),
)
@settings(max_examples=examples(400))
def test_json_publish_property(
    topic: str,
    msg: dict[str, Any],
    order: list[str],
    seps: tuple[str, str] | None,
    ensure_ascii: bool,
    escape_slashes: bool,
    kind: type,
) -> None:
    fields = {"op": "publish", "topic": topic, "msg": msg}
    text = json.dumps({k: fields[k] for k in order}, separators=seps, ensure_ascii=ensure_ascii)
    if escape_slashes:  # '/' only occurs inside strings, and '\/' is a valid escape
        text = text.replace("/", "\\/")
    frame: Any = text if kind is str else kind(text.encode())
    event = one_publish(RosbridgeEngine().receive_text(frame))
    assert event.topic == topic
    assert event.kind in ("json", "parsed")
    assert msg_of(event) == msg
    if order[:2] == ["op", "topic"] and "\\" not in json.dumps(topic, ensure_ascii=ensure_ascii):
        assert event.kind == "json"  # the fast path was taken


@given(
    topics,
    msgs,
    st.permutations(["op", "topic", "msg", "id"]),
    st.booleans(),
    st.sampled_from([bytes, bytearray]),
)
@settings(max_examples=examples(300))
def test_cbor_publish_property(
    topic: str, msg: dict[str, Any], order: list[str], with_id: bool, kind: type
) -> None:
    # no cbor-raw subscription: even a msg shaped like cbor-raw is plain CBOR
    fields = {"op": "publish", "topic": topic, "msg": msg, "id": "p1"}
    frame = kind(cbor2.dumps({k: fields[k] for k in order if with_id or k != "id"}))
    event = one_publish(RosbridgeEngine().receive_binary(frame))
    assert event.topic == topic
    assert event.kind == "cbor"
    assert event.payload.obj is frame
    assert decode_cbor_msg(event.payload) == msg


@given(topics, st.binary(max_size=64), st.none() | st.integers(0, 2**40), st.integers(0, 10**9))
@settings(max_examples=examples(200))
def test_cbor_raw_publish_property(
    topic: str, payload: bytes, secs: int | None, nsecs: int
) -> None:
    assume(topic)  # an empty topic cannot be subscribed
    msg: dict[str, Any] = {"bytes": payload}
    if secs is not None:
        msg |= {"secs": secs, "nsecs": nsecs}
    frame = cbor2.dumps({"op": "publish", "topic": topic, "msg": msg})
    event = one_publish(raw_engine(topic).receive_binary(frame))
    assert (event.topic, event.kind) == (topic, "cbor-raw")
    assert event.payload.obj is frame
    assert event.payload.tobytes() == payload
    assert event.log_time_ns == (None if secs is None else secs * 10**9 + nsecs)


REAL_TEXT = (
    PUBLISH.decode(),
    SERVICE_OK,
    SERVICE_FAILED,
    STATUS,
    STATUS_NO_ID,
    FEEDBACK,
    RESULT,
    REJECTED,
    FOXGLOVE_SERVER_INFO,
)
wholes = (
    st.sampled_from(REAL_TEXT)
    | st.builds(
        lambda topic, msg: json.dumps({"op": "publish", "topic": topic, "msg": msg}),
        topics,
        msgs,
    )
    | st.text(max_size=300)
)


@given(wholes, st.integers(1, 8), st.randoms(use_true_random=False))
@settings(max_examples=examples(300))
def test_fragment_reassembly_property(whole: str, parts: int, rnd: Any) -> None:
    """Any text, cut into parts sent in any order, is handled as the text itself
    (JSON), or dropped as not JSON."""
    chunks = split(whole, parts)
    order = list(range(len(chunks)))
    rnd.shuffle(order)
    e = RosbridgeEngine()
    events: list[Event] = []
    for index in order:
        assert events == []
        events = e.receive_text(frag("k", chunks[index], index, len(chunks)))
    assert e.fragments_pending == 0
    try:
        obj = json.loads(whole)
    except ValueError:
        assert "the reassembled message is not JSON" in only_violation(events)
        return
    direct = RosbridgeEngine().receive_text(whole)
    if isinstance(obj, dict) and obj.get("op") == "fragment":
        assert "a fragment inside a fragment" in only_violation(events)
        return
    assert [type(ev) for ev in events] == [type(ev) for ev in direct]
    for got, want in zip(events, direct, strict=True):
        if isinstance(got, Publish):
            assert isinstance(want, Publish)
            assert got.kind == "parsed"
            assert got.topic == want.topic
            assert got.message == msg_of(want)
        elif not isinstance(got, ProtocolViolation):
            assert got == want


def _never_raises(events: object) -> None:
    assert isinstance(events, list)
    for event in events:
        assert isinstance(event, Event)
        if isinstance(event, ProtocolViolation):
            assert isinstance(event.reason, str)


@given(st.text())
@settings(max_examples=examples(300))
def test_any_text_never_raises(text: str) -> None:
    _never_raises(RosbridgeEngine().receive_text(text))


@given(st.binary())
@settings(max_examples=examples(300))
def test_any_text_bytes_never_raises(data: bytes) -> None:
    _never_raises(RosbridgeEngine().receive_text(data))


@given(st.binary(max_size=80), st.sampled_from([bytes, bytearray]))
@settings(max_examples=examples(500))
def test_any_binary_never_raises(data: bytes, kind: type) -> None:
    _never_raises(RosbridgeEngine().receive_binary(kind(data)))


@given(st.binary(max_size=40))
@settings(max_examples=examples(300))
def test_any_bytes_after_a_publish_prefix_never_raise(tail: bytes) -> None:
    """The CBOR walker and the JSON peek on frames that start well."""
    e = RosbridgeEngine()
    _never_raises(e.receive_binary(b"\xa3bopgpublishetopicb/tcmsg" + tail))
    _never_raises(e.receive_binary(PUBLISH_CBOR[: len(PUBLISH_CBOR) // 2] + tail))
    _never_raises(e.receive_text(b'{"op":"publish","topic":"/t","msg":' + tail))


@given(
    st.sampled_from(
        ["publish", "service_response", "status", "fragment", "action_feedback", "action_result"]
    ),
    st.dictionaries(
        st.sampled_from(
            [
                *("id", "topic", "msg", "service", "values", "result", "level", "action"),
                *("status", "data", "num", "total"),
            ]
        ),
        json_values,
        max_size=5,
    ),
)
@settings(max_examples=examples(500))
def test_known_op_with_random_fields_never_raises(op: str, fields: dict[str, Any]) -> None:
    e = RosbridgeEngine()
    _never_raises(e.receive_text(json.dumps({**fields, "op": op})))
    _never_raises(e.receive_text(json.dumps({"op": op, **fields, "op2": 1})))
    _never_raises(e.receive_binary(cbor2.dumps({**fields, "op": op})))


# --------------------------------------------------------------------------
# Limits and hostile values: classified violations, never an exception


@pytest.mark.parametrize("field", ["msg", "level", "id"])
def test_cbor_integer_too_long_for_str_never_raises(field: str) -> None:
    obj: dict[str, Any] = {"op": "status", "level": "error", "msg": "m", field: 1 << 20000}
    event = one(RosbridgeEngine().receive_binary(cbor2.dumps(obj)))
    assert isinstance(event, Status)
    text = {"msg": event.msg, "level": event.level, "id": event.id}[field]
    assert text is not None and "20001 bits" in text and len(text) < 100


def test_cbor_bignum_in_other_fields_never_raises() -> None:
    e = RosbridgeEngine()
    for obj in (
        {"op": "service_response", "id": 1 << 20000, "service": "/s", "result": True},
        {"op": "action_result", "id": "g", "action": "/a", "status": 1 << 20000},
        {"op": "fragment", "id": "k", "data": "x", "num": 1 << 20000, "total": 1 << 20001},
        {"op": 1 << 20000},
    ):
        events = e.receive_binary(cbor2.dumps(obj))
        assert isinstance(events, list) and len(events) <= 1


def test_json_number_too_long_for_int_is_a_violation() -> None:
    event = one(RosbridgeEngine().receive_text(b'{"op":"status","msg":' + b"1" * 5000 + b"}"))
    assert isinstance(event, ProtocolViolation) and event.kind == "malformed"


def test_json_depth_limit_is_a_classified_violation() -> None:
    e = RosbridgeEngine(max_json_depth=5)
    ok = b'{"op":"status","msg":"m","x":[[[[]]]]}'  # depth 5
    assert isinstance(one(e.receive_text(ok)), Status)
    deep = b'{"op":"status","msg":"m","x":[[[[[]]]]]}'
    event = one(e.receive_text(deep))
    assert isinstance(event, ProtocolViolation) and event.kind == "json_depth"
    # strings full of brackets are not nesting
    text = json.dumps({"op": "status", "msg": "[" * 100}).encode()
    assert isinstance(one(e.receive_text(text)), Status)
    # a reassembled message is held to it too
    parts = split(deep.decode(), 2)
    assert e.receive_text(frag("k", parts[0], 0, 2)) == []
    event = one(e.receive_text(frag("k", parts[1], 1, 2)))
    assert isinstance(event, ProtocolViolation) and event.kind == "json_depth"


def test_invalid_utf8_text_frame_is_its_own_kind() -> None:
    event = one(RosbridgeEngine().receive_text(b'{"op":"status","msg":"\xff"}'))
    assert isinstance(event, ProtocolViolation) and event.kind == "invalid_utf8"


@pytest.mark.parametrize("encoding", ["utf-16-le", "utf-16-be", "utf-16", "utf-32"])
def test_text_frame_in_utf16_or_utf32_is_not_json(encoding: str) -> None:
    """json.loads would guess the encoding from NULs or a BOM and parse the
    operation; a text frame is UTF-8 JSON or nothing (found by the fragment
    reassembly property: a reassembled ':\\x000000000' read as UTF-16)."""
    op = '{"op":"status","level":"error","msg":"x"}'.encode(encoding)
    for e in (RosbridgeEngine(),):
        event = one(e.receive_text(op))
        assert isinstance(event, ProtocolViolation), event
        assert "not JSON" in event.reason
    parts = [op[: len(op) // 2], op[len(op) // 2 :]]
    # the same bytes reassembled from fragments (as latin-1 text so they survive JSON)
    e = RosbridgeEngine()
    assert e.receive_text(frag("k", parts[0].decode("latin-1"), 0, 2)) == []
    event = one(e.receive_text(frag("k", parts[1].decode("latin-1"), 1, 2)))
    assert isinstance(event, ProtocolViolation)


def test_text_frame_reassembled_with_a_nul_second_is_not_json() -> None:
    e = RosbridgeEngine()
    event = one(e.receive_text(frag("k", ":\x000000000", 0, 1)))
    assert isinstance(event, ProtocolViolation)
    assert "the reassembled message is not JSON" in event.reason


def test_fragment_over_the_size_bound_is_a_fragment_limit() -> None:
    e = RosbridgeEngine(max_message_size=10)
    event = one(e.receive_text(frag("k", "x" * 11, 0, 2)))
    assert isinstance(event, ProtocolViolation) and event.kind == "fragment_limit"
