"""Fuzz harness for the sans-IO Foxglove engine (``ros_mobile_bridge.wire.foxglove``).

Drives one :class:`FoxgloveEngine` per example through a random session:
real-server messages, the same messages mutated (fields deleted or replaced
by random JSON, text truncated or bit-flipped), random JSON objects with a
known ``op``, random text, and binary frames (random bytes, every opcode with
a random body, well-formed headers with hostile lengths), interleaved with
client-side subscribe / unsubscribe calls so the message-data path is live.

The contract checked: the engine never raises on server input, returns a list
of ``Event`` objects, never reports an "internal error" (a caught bug), and its
message-data payloads are the exact tail of the frame.

Run it directly::

    python fuzz/fuzz_foxglove.py --examples 20000 [--seed 1]

or import it and call :func:`run` (``tests/test_fuzz_smoke.py`` does).
"""

from __future__ import annotations

import json
import struct
import sys
from collections import Counter
from pathlib import Path
from typing import Any

from hypothesis import strategies as st

try:
    from ros_mobile_bridge.wire import foxglove as fg
except ImportError:  # a checkout that is not installed: use its src/
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
    from ros_mobile_bridge.wire import foxglove as fg

try:
    from _harness import cli_main, run_sessions
except ImportError:  # loaded by its path (the smoke tests): the harness is beside it
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _harness import cli_main, run_sessions

__all__ = ["SEED_TEXT", "run", "run_session"]

SEED_TEXT: tuple[str, ...] = (
    # Captured from the official Foxglove SDK server (foxglove.sdk.v1.1).
    '{"op":"serverInfo","name":"","capabilities":["clientPublish","services","parameters",'
    '"parametersSubscribe","connectionGraph","time"],"supportedEncodings":["json","cdr"],'
    '"metadata":{"fg-library":"foxglove-sdk-python/0.30.3"},"sessionId":"1795253552388"}',
    '{"op":"advertise","schemas":[{"id":1,"name":"Foo","encoding":"jsonschema",'
    '"data":"{\\"type\\":\\"object\\"}"},{"id":2,"name":"std_msgs/msg/String",'
    '"encoding":"ros2msg","data":"string data"}],"channels":[{"id":2,"topic":"/j",'
    '"encoding":"json","schemaId":1},{"id":1,"topic":"/chatter","encoding":"cdr",'
    '"schemaId":2},{"id":3,"topic":"/chatter2","encoding":"cdr","schemaId":2}]}',
    '{"op":"advertiseServices","services":[{"id":2,"name":"/trigger",'
    '"type":"std_srvs/srv/Trigger","requestSchema":"","responseSchema":""},{"id":1,'
    '"name":"/set_flag","type":"std_srvs/srv/SetBool","request":{"encoding":"cdr",'
    '"schemaName":"std_srvs/srv/SetBool_Request","schemaEncoding":"ros2msg",'
    '"schema":"bool data"},"response":{"encoding":"cdr","schemaName":'
    '"std_srvs/srv/SetBool_Response","schemaEncoding":"ros2msg",'
    '"schema":"bool success\\nstring message"}}]}',
    '{"op":"parameterValues","parameters":[{"name":"a","type":"float64","value":1.5},'
    '{"name":"b","value":"x"}],"id":"r1"}',
    '{"op":"serviceCallFailure","serviceId":1,"callId":44,"message":"Unsupported encoding"}',
    '{"op":"unadvertise","channelIds":[3]}',
    # Legacy (foxglove.websocket.v1) shapes and the remaining ops.
    '{"op":"advertise","channels":[{"id":0,"topic":"/legacy","encoding":"cdr",'
    '"schemaName":"std_msgs/msg/String","schema":"string data"},{"id":5,"topic":"/pb",'
    '"encoding":"protobuf","schemaName":"pkg.Msg","schema":"AAH/",'
    '"schemaEncoding":"protobuf"}]}',
    '{"op":"status","level":1,"message":"careful","id":"s1"}',
    '{"op":"status","level":0,"message":"hello","id":null}',
    '{"op":"removeStatus","statusIds":["s1"]}',
    '{"op":"unadvertiseServices","serviceIds":[2]}',
    '{"op":"parameterValues","parameters":[{"name":"bytes","type":"byte_array",'
    '"value":"AAFoaQ=="},{"name":"arr","type":"float64_array","value":[1,2.5]},'
    '{"name":"d","value":{"k":1.5,"n":{"z":true}}},{"name":"gone"}],"id":null}',
    '{"op":"connectionGraphUpdate","publishedTopics":[{"name":"/t","publisherIds":["n1"]}],'
    '"subscribedTopics":[{"name":"/t","subscriberIds":["n2"]}],"advertisedServices":'
    '[{"name":"/s","providerIds":["n1"]}],"removedTopics":["/old"],"removedServices":[]}',
)

KNOWN_OPS: tuple[str, ...] = (
    "serverInfo",
    "status",
    "removeStatus",
    "advertise",
    "unadvertise",
    "advertiseServices",
    "unadvertiseServices",
    "parameterValues",
    "connectionGraphUpdate",
    "serviceCallFailure",
)

_FIELD_NAMES = (
    "id",
    "name",
    "topic",
    "encoding",
    "schemaId",
    "schemaName",
    "schema",
    "schemaEncoding",
    "schemas",
    "channels",
    "channelIds",
    "services",
    "serviceIds",
    "request",
    "response",
    "requestSchema",
    "responseSchema",
    "parameters",
    "value",
    "type",
    "level",
    "message",
    "statusIds",
    "capabilities",
    "supportedEncodings",
    "metadata",
    "sessionId",
    "data",
    "callId",
    "serviceId",
    "publishedTopics",
    "removedTopics",
)

_ids = st.one_of(st.integers(0, 8), st.integers(-(2**64), 2**70))
_scalars = st.one_of(
    st.none(),
    st.booleans(),
    _ids,
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.sampled_from(("", "cdr", "json", "protobuf", "ros1", "byte_array", "float64", "AAFoaQ==")),
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
random_ops = st.builds(
    lambda op, fields: json.dumps({"op": op, **fields}),
    st.sampled_from(KNOWN_OPS),
    st.dictionaries(st.sampled_from(_FIELD_NAMES), json_values, max_size=5),
)


def _mutate(obj: Any, data: st.DataObject, depth: int = 0) -> Any:
    """Replace, delete or descend into parts of a parsed JSON value."""
    choice = data.draw(st.integers(0, 5 if depth else 3))
    if choice == 0:
        return data.draw(json_values)
    if isinstance(obj, dict) and obj:
        key = data.draw(st.sampled_from(sorted(obj)))
        out = dict(obj)
        if choice == 1 and key != "op":
            del out[key]
        else:
            out[key] = _mutate(obj[key], data, depth + 1)
        return out
    if isinstance(obj, list) and obj:
        index = data.draw(st.integers(0, len(obj) - 1))
        out_list = list(obj)
        if choice == 1:
            del out_list[index]
        else:
            out_list[index] = _mutate(obj[index], data, depth + 1)
        return out_list
    return obj if choice > 3 else data.draw(json_values)


def _text_frame(data: st.DataObject) -> str | bytes:
    kind = data.draw(st.integers(0, 6), label="text kind")
    if kind == 0:
        return data.draw(st.sampled_from(SEED_TEXT))
    if kind in (1, 2):
        seed_obj = json.loads(data.draw(st.sampled_from(SEED_TEXT)))
        return json.dumps(_mutate(seed_obj, data))
    if kind == 3:
        return data.draw(random_ops)
    if kind == 4:
        raw = bytearray(data.draw(st.sampled_from(SEED_TEXT)).encode())
        for _ in range(data.draw(st.integers(1, 4))):
            pos = data.draw(st.integers(0, len(raw) - 1))
            raw[pos] = data.draw(st.integers(0, 255))
        cut = data.draw(st.integers(0, len(raw)))
        return bytes(raw[:cut])
    if kind == 5:
        return data.draw(st.text(max_size=200))
    return data.draw(st.binary(max_size=200))


def _binary_frame(data: st.DataObject, live_subs: list[int]) -> bytes:
    kind = data.draw(st.integers(0, 7), label="binary kind")
    body = data.draw(st.binary(max_size=64))
    if kind == 0:
        return body
    if kind == 1:
        return bytes([data.draw(st.integers(0, 7))]) + body
    u32 = st.one_of(st.integers(0, 8), st.integers(0, 2**32 - 1))
    if kind in (2, 6, 7):  # message data, often for a live subscription
        sub_id = data.draw(st.one_of(st.sampled_from(live_subs), u32) if live_subs else u32)
        header = struct.pack("<BIQ", 1, sub_id, data.draw(st.integers(0, 2**64 - 1)))
    elif kind == 3:  # service call response with a hostile encoding length
        header = struct.pack("<BIII", 3, data.draw(u32), data.draw(u32), data.draw(u32))
    elif kind == 4:  # fetch asset response
        header = struct.pack(
            "<BIBI", 4, data.draw(u32), data.draw(st.integers(0, 3)), data.draw(u32)
        )
    else:
        header = struct.pack("<BQ", 2, data.draw(st.integers(0, 2**64 - 1)))
    cut = data.draw(st.integers(0, len(header) + len(body)))
    frame = header + body
    return frame if data.draw(st.booleans()) else frame[:cut]


STATS: Counter[str] = Counter()
"""Event type names seen so far (printed by ``main``)."""


def _check(events: object, frame: bytes | str | None = None) -> None:
    assert isinstance(events, list), type(events)
    for event in events:
        assert isinstance(event, fg.Event), event
        STATS[type(event).__name__] += 1
        if isinstance(event, fg.ProtocolViolation):
            assert isinstance(event.reason, str)
            assert "internal error" not in event.reason, event.reason
        elif isinstance(event, fg.MessageData):
            assert isinstance(event.channel, fg.Channel)
            assert isinstance(event.payload, memoryview)
            assert isinstance(frame, bytes)
            assert event.payload.tobytes() == frame[13:]


def run_session(data: st.DataObject) -> None:
    """One random session against a fresh engine (the body of the fuzz test)."""
    engine = fg.FoxgloveEngine(data.draw(st.sampled_from(fg.SUBPROTOCOLS)))
    if data.draw(st.integers(0, 3), label="prologue"):  # usually a sane start
        for text in (SEED_TEXT[0], SEED_TEXT[1], SEED_TEXT[6], SEED_TEXT[2]):
            _check(engine.receive_text(text))
        wanted = data.draw(st.lists(st.sampled_from(sorted(engine.channels)), unique=True))
        if wanted:
            engine.subscribe_many(wanted)
    for _ in range(data.draw(st.integers(1, 25), label="steps")):
        step = data.draw(st.integers(0, 9), label="step")
        if step <= 4:
            text = _text_frame(data)
            _check(engine.receive_text(text))
        elif step <= 7:
            frame = _binary_frame(data, list(engine.subscriptions))
            as_type = data.draw(st.sampled_from((bytes, bytearray, memoryview)))
            _check(engine.receive_binary(as_type(frame)), frame)
        elif step == 8:
            free = [cid for cid in engine.channels if cid not in _bound_channels(engine)]
            if free:
                sub_id, text = engine.subscribe(data.draw(st.sampled_from(free)))
                assert json.loads(text)["subscriptions"][0]["id"] == sub_id
        else:
            subs = list(engine.subscriptions)
            if subs:
                engine.unsubscribe([data.draw(st.sampled_from(subs))])
        for cid, channel in engine.channels.items():
            assert isinstance(channel, fg.Channel)
            assert channel.id == cid
        for sid, service in engine.services.items():
            assert isinstance(service, fg.ServiceDef)
            assert service.id == sid


def _bound_channels(engine: fg.FoxgloveEngine) -> set[int]:
    return {ch.id for ch in engine.subscriptions.values()}


def run(max_examples: int = 1000, seed: int | None = None) -> None:
    """Run ``max_examples`` random sessions; raises on the first contract breach.
    A ``seed`` makes the run reproducible."""
    run_sessions(run_session, max_examples, seed)


def main(argv: list[str] | None = None) -> int:
    return cli_main(__doc__, run, STATS, argv)


if __name__ == "__main__":
    sys.exit(main())
