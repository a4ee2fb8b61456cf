"""Fuzz harness for the sans-IO rosbridge v2 engine (``ros_mobile_bridge.wire.rosbridge``).

Drives one :class:`RosbridgeEngine` per example (with a fake clock) through a
random session: real-server frames, the same frames mutated (fields deleted or
replaced by random values, text truncated or bit-flipped, re-serialized with
other spacing, key orders and ``\\/`` escapes), random objects with a known
``op``, random text, CBOR binary frames (the real ones, mutated ones, random
CBOR with typed arrays and tags, random bytes), fragmented messages (in order,
shuffled, duplicated, with parts missing or ``total`` changed, as text or as
CBOR), interleaved with clock jumps so fragments expire.

The contract checked: the engine never raises on server input, returns a list
of ``Event`` objects with well-typed fields, never holds more than 16
fragmented messages, its ``Publish`` payloads are views of the frame (the
whole frame, or for ``cbor-raw`` a slice of it), ``decode_json_msg`` /
``decode_cbor_msg`` either decode a payload or raise the documented errors,
and a fragmented message that arrives whole yields the same event as the
unfragmented frame.

Run it directly::

    python fuzz/fuzz_rosbridge.py --examples 20000 [--seed 1]

or import it and call :func:`run` (``tests/test_fuzz_rosbridge_smoke.py`` does).
"""

from __future__ import annotations

import json
import struct
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import cbor2
from hypothesis import strategies as st

try:
    from ros_mobile_bridge.wire import rosbridge as rb
except ImportError:  # a checkout that is not installed: use its src/
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
    from ros_mobile_bridge.wire import rosbridge as rb

try:
    from _harness import cli_main, run_sessions
except ImportError:  # loaded by its path (the smoke tests): the harness is beside it
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _harness import cli_main, run_sessions

__all__ = ["SEED_BINARY", "SEED_TEXT", "STATS", "run", "run_session"]

SEED_TEXT: tuple[str, ...] = (
    # Captured from rosbridge_server_rs 0.1.6.
    '{"op":"publish","topic":"/chatter","msg":{"data":"hello 141"}}',
    '{"op":"service_response","service":"/set_flag","result":true,'
    '"values":{"success":true,"message":"flag set to True"},"id":"c1"}',
    '{"op":"service_response","service":"/slow_trigger",'
    '"values":"Timeout exceeded while waiting for service response","result":false,"id":"c7"}',
    '{"op":"status","level":"error","msg":"unknown operation: bogus_op","id":"b1"}',
    '{"op":"status","level":"error","msg":"unknown operation: bogus_op"}',
    '{"op":"action_feedback","action":"/fibonacci","values":{"sequence":[0,1,1]},"id":"g1"}',
    '{"op":"action_result","action":"/fibonacci","values":{"sequence":[0,1,1,2,3]},'
    '"status":4,"result":true,"id":"g1"}',
    '{"op":"action_result","action":"/fibonacci","values":"goal rejected","status":6,'
    '"result":false,"id":"g4"}',
    '{"op":"fragment","id":"rosbridge:504","data":"{\\"op\\":\\"publish\\",\\"top",'
    '"num":0,"total":4}',
    '{"op":"fragment","id":"rosbridge:504","data":"ic\\":\\"/chatter\\",\\"msg\\"",'
    '"num":1,"total":4}',
    '{"op":"fragment","id":"rosbridge:504","data":":{\\"data\\":\\"hello 1381","num":2,"total":4}',
    '{"op":"fragment","id":"rosbridge:504","data":"\\"}}","num":3,"total":4}',
    # Other servers' shapes (Python rosbridge with ujson, other key orders).
    '{"op": "publish", "topic": "\\/chatter", "msg": {"data": "hello"}}',
    '{"topic":"/chatter","op":"publish","msg":{"data":"hi"}}',
    '{"msg":{"data":"hi"},"op":"publish","topic":"/chatter"}',
    '{"op":"png","data":"iVBORw0KGgo="}',
    # A Foxglove server (foxglove.sdk.v1.1).
    '{"op":"serverInfo","name":"","capabilities":["clientPublish"],'
    '"supportedEncodings":["json","cdr"],"metadata":{},"sessionId":"1795253552388"}',
    '{"op":"advertise","channels":[{"id":1,"topic":"/chatter","encoding":"cdr",'
    '"schemaName":"std_msgs/msg/String","schema":"string data"}]}',
)

_RAW_MSG = b"\x00\x01\x00\x00\n\x00\x00\x00hello 157\x00"

SEED_BINARY: tuple[bytes, ...] = (
    # Captured from rosbridge_server_rs 0.1.6 (compression "cbor").
    bytes.fromhex(
        "a3626f70677075626c69736865746f706963682f63686174746572636d7367a1646461746169"
        "68656c6c6f20313439"
    ),
    # compression "cbor-raw", and the other ops as CBOR.
    cbor2.dumps(
        {
            "op": "publish",
            "topic": "/chatter",
            "msg": {"bytes": _RAW_MSG, "secs": 1795260957, "nsecs": 634917618},
        }
    ),
    cbor2.dumps(
        {
            "op": "publish",
            "topic": "/points",
            "msg": {
                "data": cbor2.CBORTag(86, struct.pack("<2d", 1.5, 2.5)),
                "ids": cbor2.CBORTag(78, struct.pack("<3i", -1, 0, 1)),
                "scale": 0.5,
            },
        }
    ),
    cbor2.dumps(
        {"op": "action_feedback", "action": "/fibonacci", "values": {"sequence": [0, 1, 1]}}
        | {"id": "g1"}
    ),
    cbor2.dumps(
        {
            "op": "action_result",
            "action": "/fibonacci",
            "values": {"sequence": [0, 1, 1, 2, 3]},
            "status": 4,
            "result": True,
            "id": "g1",
        }
    ),
    cbor2.dumps(
        {"op": "service_response", "service": "/set_flag", "result": True, "values": {}}
        | {"id": "c1"}
    ),
    cbor2.dumps({"op": "status", "level": "warning", "msg": "slow", "id": "b2"}),
)

KNOWN_OPS: tuple[str, ...] = (
    "publish",
    "service_response",
    "status",
    "fragment",
    "action_feedback",
    "action_result",
    "png",
    "serverInfo",
    "advertise",
)

_FIELD_NAMES = (
    "op",
    "id",
    "topic",
    "msg",
    "service",
    "values",
    "result",
    "level",
    "action",
    "status",
    "data",
    "num",
    "total",
    "bytes",
    "secs",
    "nsecs",
    "channels",
    "sessionId",
    "type",
)

_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-3, 8),
    st.integers(-(2**64), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.sampled_from(("", "/chatter", "publish", "error", "fragment", "rosbridge:1")),
)
json_values = st.recursive(
    _scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.dictionaries(
            st.one_of(st.sampled_from(_FIELD_NAMES), st.text(max_size=6)), inner, max_size=5
        ),
    ),
    max_leaves=25,
)

_TYPED_ARRAY_TAGS = (64, 65, 66, 67, 68, 69, 70, 71, 72, 73, 74, 75, 77, 78, 79, 80, 81, 82)
_typed_arrays = st.builds(
    cbor2.CBORTag,
    st.sampled_from((*_TYPED_ARRAY_TAGS, 84, 85, 86)),
    st.binary(max_size=24),  # often not a multiple of the item size
)
_cbor_only = st.one_of(
    st.binary(max_size=16),
    _typed_arrays,
    st.builds(cbor2.CBORTag, st.integers(1000, 2**32), st.integers(0, 3)),
    st.just(cbor2.undefined),
    st.builds(cbor2.CBORSimpleValue, st.integers(0, 19)),
)
cbor_values = st.recursive(
    st.one_of(_scalars, _cbor_only),
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.dictionaries(
            st.one_of(st.sampled_from(_FIELD_NAMES), st.text(max_size=6)), inner, max_size=5
        ),
    ),
    max_leaves=20,
)


def _mutate(obj: Any, data: st.DataObject, values: st.SearchStrategy[Any], depth: int = 0) -> Any:
    """Replace, delete or descend into parts of a parsed value."""
    choice = data.draw(st.integers(0, 5 if depth else 3))
    if choice == 0:
        return data.draw(values)
    if isinstance(obj, dict) and obj:
        key = data.draw(st.sampled_from(sorted(obj, key=str)))
        out = dict(obj)
        if choice == 1 and key != "op":
            del out[key]
        else:
            out[key] = _mutate(obj[key], data, values, depth + 1)
        return out
    if isinstance(obj, list) and obj:
        index = data.draw(st.integers(0, len(obj) - 1))
        out_list = list(obj)
        if choice == 1:
            del out_list[index]
        else:
            out_list[index] = _mutate(obj[index], data, values, depth + 1)
        return out_list
    return obj if choice > 3 else data.draw(values)


def _restyle(text: str, data: st.DataObject) -> str:
    """The same JSON, serialized as another server might: other spacing, key
    order, ASCII escapes, ``\\/``."""
    obj = json.loads(text)
    if isinstance(obj, dict) and data.draw(st.booleans()):
        keys = data.draw(st.permutations(list(obj)))
        obj = {k: obj[k] for k in keys}
    out = json.dumps(
        obj,
        separators=data.draw(st.sampled_from(((",", ":"), (", ", ": "), (" ,", " :")))),
        ensure_ascii=data.draw(st.booleans()),
    )
    return out.replace("/", "\\/") if data.draw(st.booleans()) else out


def _deep(data: st.DataObject) -> str:
    """Deeply nested JSON. A ``status`` stays clear of the recursion limit:
    one nested just under it parses (and is reported, not raised)."""
    op = data.draw(st.sampled_from(("publish", "status", "service_response")))
    depths = (60, 5000, 100_000) if op == "status" else (60, 900, 5000, 100_000)
    depth = data.draw(st.sampled_from(depths))
    head = f'{{"op":"{op}","topic":"/deep","service":"/s","msg":'
    return head + "[" * depth + "]" * depth + "}"


def _text_frame(data: st.DataObject) -> str | bytes:
    kind = data.draw(st.integers(0, 8), label="text kind")
    if kind == 0:
        return data.draw(st.sampled_from(SEED_TEXT))
    if kind in (1, 2):
        seed_obj = json.loads(data.draw(st.sampled_from(SEED_TEXT)))
        return json.dumps(_mutate(seed_obj, data, json_values))
    if kind == 3:
        return _restyle(data.draw(st.sampled_from(SEED_TEXT)), data)
    if kind == 4:
        return json.dumps(
            {
                "op": data.draw(st.sampled_from(KNOWN_OPS)),
                **data.draw(
                    st.dictionaries(st.sampled_from(_FIELD_NAMES), json_values, max_size=5)
                ),
            }
        )
    if kind == 5:
        raw = bytearray(data.draw(st.sampled_from(SEED_TEXT)).encode())
        for _ in range(data.draw(st.integers(0, 4))):
            pos = data.draw(st.integers(0, len(raw) - 1))
            raw[pos] = data.draw(st.integers(0, 255))
        cut = data.draw(st.integers(0, len(raw)))
        return bytes(raw[:cut])
    if kind == 6:
        return data.draw(st.text(max_size=200))
    if kind == 7:
        return _deep(data)
    return data.draw(st.binary(max_size=200))


def _indefinite(frame: bytes) -> bytes:
    """The frame with its top-level map made indefinite-length (if it is one)."""
    if frame and frame[0] >> 5 == 5 and frame[0] & 0x1F < 24:
        return b"\xbf" + frame[1:] + b"\xff"
    return frame


def _binary_frame(data: st.DataObject) -> bytes:
    kind = data.draw(st.integers(0, 7), label="binary kind")
    if kind == 0:
        return data.draw(st.sampled_from(SEED_BINARY))
    if kind in (1, 2):
        seed_obj = cbor2.loads(data.draw(st.sampled_from(SEED_BINARY)))
        mutated = _mutate(seed_obj, data, cbor_values)
        if isinstance(mutated, dict) and data.draw(st.booleans()):  # another key order
            keys = data.draw(st.permutations(list(mutated)))
            mutated = {k: mutated[k] for k in keys}
        return cbor2.dumps(mutated)
    if kind == 3:
        fields = data.draw(st.dictionaries(st.sampled_from(_FIELD_NAMES), cbor_values, max_size=5))
        obj = {"op": data.draw(st.sampled_from(KNOWN_OPS)), **fields}
        return cbor2.dumps(obj)
    if kind == 4:
        raw = bytearray(data.draw(st.sampled_from(SEED_BINARY)))
        for _ in range(data.draw(st.integers(0, 3))):
            pos = data.draw(st.integers(0, len(raw) - 1))
            raw[pos] = data.draw(st.integers(0, 255))
        return bytes(raw[: data.draw(st.integers(0, len(raw)))])
    if kind == 5:
        return _indefinite(data.draw(st.sampled_from(SEED_BINARY)))
    if kind == 6:
        return data.draw(st.binary(max_size=120))
    return cbor2.dumps(data.draw(cbor_values))  # CBOR, rarely a map


# --------------------------------------------------------------------------
# Checking events

STATS: Counter[str] = Counter()
"""Event type names (and ``Publish/<kind>``) seen so far (printed by ``main``)."""

_EVENT_TYPES = (
    rb.Publish,
    rb.ServiceResponse,
    rb.ActionFeedback,
    rb.ActionResult,
    rb.Status,
    rb.ForeignProtocol,
    rb.ProtocolViolation,
)


def _opt_str(value: object) -> bool:
    return value is None or isinstance(value, str)


def _check_publish(event: rb.Publish, frame: object) -> None:
    assert isinstance(event.topic, str)
    assert isinstance(event.payload, memoryview)
    STATS[f"Publish/{event.kind}"] += 1
    if event.kind == "parsed":  # a full parse of JSON text
        assert event.log_time_ns is None
        return
    assert event.message is None
    if isinstance(frame, str):
        assert event.kind == "json"
        assert event.payload.tobytes() == frame.encode()
        return
    assert event.payload.obj is frame, "a view of the frame, not a copy"
    if event.kind == "cbor-raw":
        assert isinstance(frame, bytes | bytearray)
        assert event.payload.tobytes() in frame
        assert event.log_time_ns is None or event.log_time_ns >= 0
        return
    assert event.payload.nbytes == len(frame)  # type: ignore[arg-type]
    assert event.log_time_ns is None
    if event.kind == "json":
        try:
            rb.decode_json_msg(event.payload)
        except (ValueError, RecursionError):  # the backend's catch
            STATS["decode failed"] += 1
    else:
        assert event.kind == "cbor", event.kind
        try:
            rb.decode_cbor_msg(event.payload)
        except ValueError:
            STATS["decode failed"] += 1


def _check(events: object, frame: object) -> list[Any]:
    assert isinstance(events, list), type(events)
    for event in events:
        assert isinstance(event, _EVENT_TYPES), event
        STATS[type(event).__name__] += 1
        if isinstance(event, rb.ProtocolViolation):
            assert isinstance(event.reason, str)
            assert "internal error" not in event.reason, event.reason
        elif isinstance(event, rb.Publish):
            _check_publish(event, frame)
        elif isinstance(event, rb.ServiceResponse):
            assert isinstance(event.service, str)
            assert isinstance(event.result, bool)
            assert _opt_str(event.id)
        elif isinstance(event, rb.ActionFeedback):
            assert isinstance(event.action, str)
            assert _opt_str(event.id)
        elif isinstance(event, rb.ActionResult):
            assert isinstance(event.action, str)
            assert isinstance(event.result, bool)
            assert event.status is None or (
                isinstance(event.status, int) and not isinstance(event.status, bool)
            )
            assert _opt_str(event.id)
        elif isinstance(event, rb.Status):
            assert isinstance(event.level, str)
            assert isinstance(event.msg, str)
            assert _opt_str(event.id)
        else:
            assert event.detected == "foxglove-ws"
            assert isinstance(event.reason, str)
    return events


# --------------------------------------------------------------------------
# Fragments


def _fragments(text: str, key: str, data: st.DataObject) -> list[dict[str, Any]]:
    parts_n = data.draw(st.integers(1, 6))
    size = max(1, -(-len(text) // parts_n))
    chunks = [text[i : i + size] for i in range(0, len(text), size)] or [""]
    return [
        {"op": "fragment", "id": key, "data": chunk, "num": i, "total": len(chunks)}
        for i, chunk in enumerate(chunks)
    ]


def _send_fragment(
    engine: rb.RosbridgeEngine, frag: dict[str, Any], data: st.DataObject
) -> list[Any]:
    if data.draw(st.integers(0, 4)) == 0:
        frame = cbor2.dumps(frag)
        return _check(engine.receive_binary(frame), frame)
    text = json.dumps(frag)
    return _check(engine.receive_text(text), text)


def _fragment_step(
    engine: rb.RosbridgeEngine, data: st.DataObject, counter: list[int], roomy: bool
) -> None:
    whole = data.draw(st.one_of(st.sampled_from(SEED_TEXT[:8]), st.text(max_size=40)))
    counter[0] += 1
    key = data.draw(st.sampled_from((f"f{counter[0]}", "rosbridge:504", "a")))
    frags = _fragments(whole, key, data)
    mode = data.draw(st.integers(0, 5), label="fragment mode")
    if mode == 0 and key.startswith("f") and roomy:
        # Clean delivery of a fresh id: the same event as the whole frame.
        events: list[Any] = []
        for frag in frags:
            events = _send_fragment(engine, frag, data)
        # another message's parts that expired meanwhile (the clock moved in
        # an earlier step) are reported on this receipt: not this message's
        events = [
            e
            for e in events
            if not (
                isinstance(e, rb.ProtocolViolation)
                and e.kind == "fragment_limit"
                and repr(key) not in e.reason
            )
        ]
        expected = rb.RosbridgeEngine().receive_text(whole)
        assert [type(e) for e in events] == [type(e) for e in expected], (events, expected)
        for got, want in zip(events, expected, strict=True):
            if isinstance(got, rb.Publish):
                assert got.topic == want.topic
            elif not isinstance(got, rb.ProtocolViolation):
                assert repr(got) == repr(want)  # repr: NaN != NaN
        STATS["fragments reassembled"] += 1
        return
    if mode == 1:
        frags = data.draw(st.permutations(frags))
    elif mode == 2 and frags:
        frags = [*frags, data.draw(st.sampled_from(frags))]
    elif mode == 3 and len(frags) > 1:
        frags = frags[1:]
    elif mode == 4:
        frags = [
            {**f, "total": data.draw(st.integers(-1, 8))} if data.draw(st.booleans()) else f
            for f in frags
        ]
    elif mode == 5:
        frags = [_mutate(f, data, json_values) for f in frags]
    for frag in frags:
        _send_fragment(engine, frag, data)


# --------------------------------------------------------------------------
# Sessions


class _Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def run_session(data: st.DataObject) -> None:
    """One random session against a fresh engine (the body of the fuzz test)."""
    clock = _Clock()
    max_size = data.draw(st.sampled_from((64 * 1024 * 1024, 64 * 1024 * 1024, 200, 40)))
    engine = rb.RosbridgeEngine(max_message_size=max_size, fragment_timeout=10.0, clock=clock)
    if data.draw(st.booleans(), label="chatter subscribed with cbor-raw"):
        engine.subscribe("/chatter", id="s", compression="cbor-raw")
    roomy = max_size > 1024
    counter = [0]
    for _ in range(data.draw(st.integers(1, 25), label="steps")):
        step = data.draw(st.integers(0, 11), label="step")
        if step <= 4:
            text = _text_frame(data)
            _check(engine.receive_text(text), text)
        elif step <= 7:
            frame = _binary_frame(data)
            if data.draw(st.booleans()):
                frame = bytearray(frame)  # type: ignore[assignment]
            _check(engine.receive_binary(frame), frame)
        elif step <= 9:
            _fragment_step(engine, data, counter, roomy)
        else:
            clock.now += data.draw(st.sampled_from((0.5, 5.0, 9.99, 10.5, 60.0)))
        assert 0 <= engine.fragments_pending <= 16


def run(max_examples: int = 1000, seed: int | None = None) -> None:
    """Run ``max_examples`` random sessions; raises on the first contract breach.
    A ``seed`` makes the run reproducible."""
    run_sessions(run_session, max_examples, seed)


def main(argv: list[str] | None = None) -> int:
    return cli_main(__doc__, run, STATS, argv)


if __name__ == "__main__":
    sys.exit(main())
