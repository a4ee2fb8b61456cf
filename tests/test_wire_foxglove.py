"""Tests for the sans-IO Foxglove WebSocket engine (``ros_mobile_bridge.wire.foxglove``).

The literal server messages below were captured from the official Foxglove SDK
server (foxglove-sdk-python 0.30.3, subprotocol ``foxglove.sdk.v1.1``).
"""

from __future__ import annotations

import array
import base64
import json
import struct
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from _util import examples
from ros_mobile_bridge.wire import foxglove as fg
from ros_mobile_bridge.wire.foxglove import (
    SUBPROTOCOLS,
    Advertise,
    AdvertiseServices,
    Channel,
    ConnectionGraphUpdate,
    Event,
    FetchAssetResponse,
    FoxgloveEngine,
    MessageData,
    MessageSchema,
    Parameter,
    ParameterValues,
    PlaybackState,
    ProtocolViolation,
    RemoveStatus,
    ServerInfo,
    ServiceCallFailure,
    ServiceCallResponse,
    ServiceDef,
    Status,
    Time,
    Unadvertise,
    UnadvertiseServices,
)

# --------------------------------------------------------------------------
# Real server output (sdk.v1.1)

SERVER_INFO = (
    '{"op":"serverInfo","name":"","capabilities":["clientPublish","services","parameters",'
    '"parametersSubscribe","connectionGraph","time"],"supportedEncodings":["json","cdr"],'
    '"metadata":{"fg-library":"foxglove-sdk-python/0.30.3"},"sessionId":"1795253552388"}'
)
ADVERTISE = (
    '{"op":"advertise","schemas":[{"id":1,"name":"Foo","encoding":"jsonschema",'
    '"data":"{\\"type\\":\\"object\\"}"},{"id":2,"name":"std_msgs/msg/String",'
    '"encoding":"ros2msg","data":"string data"}],"channels":[{"id":2,"topic":"/j",'
    '"encoding":"json","schemaId":1},{"id":1,"topic":"/chatter","encoding":"cdr",'
    '"schemaId":2},{"id":3,"topic":"/chatter2","encoding":"cdr","schemaId":2}]}'
)
ADVERTISE_SERVICES = (
    '{"op":"advertiseServices","services":[{"id":2,"name":"/trigger",'
    '"type":"std_srvs/srv/Trigger","requestSchema":"","responseSchema":""},{"id":1,'
    '"name":"/set_flag","type":"std_srvs/srv/SetBool","request":{"encoding":"cdr",'
    '"schemaName":"std_srvs/srv/SetBool_Request","schemaEncoding":"ros2msg",'
    '"schema":"bool data"},"response":{"encoding":"cdr","schemaName":'
    '"std_srvs/srv/SetBool_Response","schemaEncoding":"ros2msg",'
    '"schema":"bool success\\nstring message"}}]}'
)
PARAMETER_VALUES = (
    '{"op":"parameterValues","parameters":[{"name":"a","type":"float64","value":1.5},'
    '{"name":"b","value":"x"}],"id":"r1"}'
)
SERVICE_CALL_FAILURE = (
    '{"op":"serviceCallFailure","serviceId":1,"callId":44,"message":"Unsupported encoding"}'
)
UNADVERTISE = '{"op":"unadvertise","channelIds":[3]}'

FOO = Channel(2, "/j", "json", "Foo", "jsonschema", '{"type":"object"}')
CHATTER = Channel(1, "/chatter", "cdr", "std_msgs/msg/String", "ros2msg", "string data")
CHATTER2 = Channel(3, "/chatter2", "cdr", "std_msgs/msg/String", "ros2msg", "string data")


def engine(subprotocol: str = "foxglove.sdk.v1.1") -> FoxgloveEngine:
    return FoxgloveEngine(subprotocol)


def connected() -> FoxgloveEngine:
    """An engine that has seen the real serverInfo, advertise and advertiseServices."""
    e = engine()
    e.receive_text(SERVER_INFO)
    e.receive_text(ADVERTISE)
    e.receive_text(ADVERTISE_SERVICES)
    return e


def one(events: list[Event]) -> Event:
    assert len(events) == 1, events
    return events[0]


def violations(events: list[Event]) -> list[str]:
    return [e.reason for e in events if isinstance(e, ProtocolViolation)]


def only_violation(events: list[Event]) -> str:
    event = one(events)
    assert isinstance(event, ProtocolViolation), event
    return event.reason


def send(e: FoxgloveEngine, msg: dict[str, Any]) -> list[Event]:
    return e.receive_text(json.dumps(msg))


# --------------------------------------------------------------------------
# Construction


def test_subprotocols_newest_first() -> None:
    assert SUBPROTOCOLS == ("foxglove.sdk.v1.1", "foxglove.sdk.v1", "foxglove.websocket.v1")


@pytest.mark.parametrize("subprotocol", SUBPROTOCOLS)
def test_engine_accepts_known_subprotocols(subprotocol: str) -> None:
    e = FoxgloveEngine(subprotocol)
    assert e.subprotocol == subprotocol
    assert e.server_info is None
    assert dict(e.channels) == {}
    assert dict(e.services) == {}


def test_engine_rejects_unknown_subprotocol() -> None:
    with pytest.raises(ValueError, match="unknown Foxglove subprotocol"):
        FoxgloveEngine("foxglove.websocket.v2")
    with pytest.raises(TypeError, match="subprotocol must be a str"):
        FoxgloveEngine(1)  # type: ignore[arg-type]


def test_no_async_imports() -> None:
    import ast
    from pathlib import Path

    tree = ast.parse(Path(fg.__file__).read_text())
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
# Real server messages


def test_server_info_real() -> None:
    e = engine()
    info = one(e.receive_text(SERVER_INFO))
    assert info == ServerInfo(
        name="",
        capabilities=(
            "clientPublish",
            "services",
            "parameters",
            "parametersSubscribe",
            "connectionGraph",
            "time",
        ),
        supported_encodings=("json", "cdr"),
        metadata={"fg-library": "foxglove-sdk-python/0.30.3"},
        session_id="1795253552388",
    )
    assert e.server_info == info


def test_server_info_accepts_bytes_text() -> None:
    assert isinstance(one(engine().receive_text(SERVER_INFO.encode())), ServerInfo)


def test_server_info_minimal_and_lenient() -> None:
    info = one(send(engine(), {"op": "serverInfo", "name": "n", "capabilities": []}))
    assert info == ServerInfo("n", (), (), {}, None)
    events = send(
        engine(), {"op": "serverInfo", "capabilities": [], "metadata": {"a": 1, "b": "x"}}
    )
    assert violations(events) == ["serverInfo: metadata 'a' is not a string; dropped"]
    assert isinstance(events[-1], ServerInfo)
    assert events[-1].metadata == {"b": "x"}


def test_advertise_real_resolves_schema_table() -> None:
    e = engine()
    e.receive_text(SERVER_INFO)
    assert one(e.receive_text(ADVERTISE)) == Advertise((FOO, CHATTER, CHATTER2))
    assert dict(e.channels) == {2: FOO, 1: CHATTER, 3: CHATTER2}


def test_advertise_services_real_nested_and_flat() -> None:
    e = engine()
    e.receive_text(SERVER_INFO)
    event = one(e.receive_text(ADVERTISE_SERVICES))
    trigger = ServiceDef(
        2,
        "/trigger",
        "std_srvs/srv/Trigger",
        MessageSchema("", "std_srvs/srv/Trigger_Request", "ros2msg", ""),
        MessageSchema("", "std_srvs/srv/Trigger_Response", "ros2msg", ""),
    )
    set_flag = ServiceDef(
        1,
        "/set_flag",
        "std_srvs/srv/SetBool",
        MessageSchema("cdr", "std_srvs/srv/SetBool_Request", "ros2msg", "bool data"),
        MessageSchema(
            "cdr", "std_srvs/srv/SetBool_Response", "ros2msg", "bool success\nstring message"
        ),
    )
    assert event == AdvertiseServices((trigger, set_flag))
    assert dict(e.services) == {2: trigger, 1: set_flag}


def test_parameter_values_real() -> None:
    event = one(engine().receive_text(PARAMETER_VALUES))
    assert event == ParameterValues(
        (Parameter("a", 1.5, "float64"), Parameter("b", "x", None)), "r1"
    )


def test_service_call_failure_real() -> None:
    event = one(engine().receive_text(SERVICE_CALL_FAILURE))
    assert event == ServiceCallFailure(1, 44, "Unsupported encoding")


def test_unadvertise_real() -> None:
    e = connected()
    assert one(e.receive_text(UNADVERTISE)) == Unadvertise((CHATTER2,))
    assert set(e.channels) == {1, 2}


def test_message_data_real_layout() -> None:
    e = connected()
    # Allocate subscription ids 1..7 so that the captured frame's id 7 is ours.
    for topic_id in range(10, 17):
        send(
            e,
            {
                "op": "advertise",
                "channels": [
                    {"id": topic_id, "topic": f"/t{topic_id}", "encoding": "cdr", "schemaId": 2}
                ],
            },
        )
    sub_ids, _ = e.subscribe_many(range(10, 17))
    assert sub_ids == (1, 2, 3, 4, 5, 6, 7)
    frame = bytes.fromhex("01 07000000 7b00000000000000") + b"\x00\x01\x00\x00payload"
    event = one(e.receive_binary(frame))
    assert isinstance(event, MessageData)
    assert event.subscription_id == 7
    assert event.channel == e.channels[16]
    assert event.log_time_ns == 0x7B
    assert bytes(event.payload) == b"\x00\x01\x00\x00payload"


def test_service_call_response_real_layout() -> None:
    frame = b"\x03" + struct.pack("<III", 1, 44, 3) + b"cdr" + b"\x00\x01\x00\x00\x01\x00\x00\x00"
    event = one(engine().receive_binary(frame))
    assert isinstance(event, ServiceCallResponse)
    assert (event.service_id, event.call_id, event.encoding) == (1, 44, "cdr")
    assert bytes(event.payload) == b"\x00\x01\x00\x00\x01\x00\x00\x00"


# --------------------------------------------------------------------------
# Schema table (sdk.v1.1)


def test_schema_sent_once_is_reused_by_later_advertise() -> None:
    e = connected()
    events = send(
        e,
        {
            "op": "advertise",
            "channels": [{"id": 9, "topic": "/late", "encoding": "cdr", "schemaId": 2}],
        },
    )
    assert one(events) == Advertise(
        (Channel(9, "/late", "cdr", "std_msgs/msg/String", "ros2msg", "string data"),)
    )


def test_schema_survives_unadvertise_of_its_channels() -> None:
    e = connected()
    send(e, {"op": "unadvertise", "channelIds": [1, 3]})
    event = one(
        send(
            e,
            {
                "op": "advertise",
                "channels": [{"id": 4, "topic": "/c", "encoding": "cdr", "schemaId": 2}],
            },
        )
    )
    assert isinstance(event, Advertise)
    assert event.channels[0].schema == "string data"


def test_new_server_info_resets_schema_channel_and_service_tables() -> None:
    e = connected()
    events = e.receive_text(SERVER_INFO.replace("1795253552388", "2"))
    assert [type(ev) for ev in events] == [Unadvertise, UnadvertiseServices, ServerInfo]
    assert isinstance(events[0], Unadvertise)
    assert set(events[0].channels) == {FOO, CHATTER, CHATTER2}
    assert isinstance(events[1], UnadvertiseServices)
    assert {s.name for s in events[1].services} == {"/trigger", "/set_flag"}
    assert dict(e.channels) == {}
    assert dict(e.services) == {}
    assert e.server_info is not None
    assert e.server_info.session_id == "2"
    # The old schema ids mean nothing in the new session.
    events = send(
        e,
        {
            "op": "advertise",
            "channels": [{"id": 1, "topic": "/chatter", "encoding": "cdr", "schemaId": 2}],
        },
    )
    assert violations(events) == ["advertise: channel 1 ('/chatter') references unknown schemaId 2"]
    assert events[-1] == Advertise((Channel(1, "/chatter", "cdr", "", "", ""),))
    assert e.channels[1] == Channel(1, "/chatter", "cdr", "", "", "")


def test_first_server_info_emits_no_removals() -> None:
    assert [type(ev) for ev in engine().receive_text(SERVER_INFO)] == [ServerInfo]


def test_unknown_schema_id_still_advertises_channel() -> None:
    e = engine()
    e.receive_text(SERVER_INFO)
    events = send(
        e,
        {
            "op": "advertise",
            "channels": [{"id": 5, "topic": "/x", "encoding": "json", "schemaId": 42}],
        },
    )
    assert len(violations(events)) == 1
    assert "unknown schemaId 42" in violations(events)[0]
    assert e.channels[5] == Channel(5, "/x", "json", "", "", "")


def test_schema_id_and_inline_fields_prefer_table() -> None:
    e = connected()
    channel = {
        "id": 7,
        "topic": "/both",
        "encoding": "cdr",
        "schemaId": 2,
        "schemaName": "inline/Name",
        "schema": "inline text",
        "schemaEncoding": "ros2idl",
    }
    assert one(send(e, {"op": "advertise", "channels": [channel]})) == Advertise(
        (Channel(7, "/both", "cdr", "std_msgs/msg/String", "ros2msg", "string data"),)
    )
    # When the table lacks the id, the inline fields are used (and the dangling id reported).
    channel["schemaId"] = 99
    events = send(e, {"op": "advertise", "channels": [channel]})
    assert len(violations(events)) == 1
    assert events[-1] == Advertise(
        (Channel(7, "/both", "cdr", "inline/Name", "ros2idl", "inline text"),)
    )


def test_schema_ids_may_start_at_zero() -> None:
    e = engine()
    event = one(
        send(
            e,
            {
                "op": "advertise",
                "schemas": [{"id": 0, "name": "S", "encoding": "ros2msg", "data": "int32 a"}],
                "channels": [{"id": 0, "topic": "/zero", "encoding": "cdr", "schemaId": 0}],
            },
        )
    )
    assert event == Advertise((Channel(0, "/zero", "cdr", "S", "ros2msg", "int32 a"),))


def test_advertise_with_only_schemas_emits_nothing() -> None:
    e = engine()
    assert (
        send(
            e, {"op": "advertise", "schemas": [{"id": 3, "name": "S", "encoding": "e", "data": ""}]}
        )
        == []
    )


def test_protobuf_schema_data_kept_as_given_base64() -> None:
    e = engine()
    event = one(
        send(
            e,
            {
                "op": "advertise",
                "schemas": [{"id": 1, "name": "P", "encoding": "protobuf", "data": "AAH/"}],
                "channels": [{"id": 1, "topic": "/p", "encoding": "protobuf", "schemaId": 1}],
            },
        )
    )
    assert isinstance(event, Advertise)
    assert event.channels[0].schema == "AAH/"
    assert base64.b64decode(event.channels[0].schema) == b"\x00\x01\xff"


def test_bad_schema_entry_is_skipped_with_violation() -> None:
    e = engine()
    events = send(
        e,
        {
            "op": "advertise",
            "schemas": [{"id": "1", "name": "S", "encoding": "e", "data": "d"}, {"id": 2}],
            "channels": [{"id": 1, "topic": "/a", "encoding": "cdr", "schemaId": 1}],
        },
    )
    reasons = violations(events)
    assert len(reasons) == 3  # two bad schemas, one dangling reference
    assert reasons[0].startswith("advertise: schema skipped: field 'id'")
    assert reasons[1] == "advertise: schema skipped: missing field 'name'"
    assert isinstance(events[-1], Advertise)


# --------------------------------------------------------------------------
# Legacy inline-schema channels


@pytest.mark.parametrize(
    ("encoding", "schema_encoding"),
    [
        ("cdr", "ros2msg"),
        ("protobuf", "protobuf"),
        ("json", "jsonschema"),
        ("ros1", "ros1msg"),
        ("foo", ""),
    ],
)
@pytest.mark.parametrize("subprotocol", ["foxglove.websocket.v1", "foxglove.sdk.v1"])
def test_legacy_inline_schema_default_encoding(
    subprotocol: str, encoding: str, schema_encoding: str
) -> None:
    e = engine(subprotocol)
    event = one(
        send(
            e,
            {
                "op": "advertise",
                "channels": [
                    {
                        "id": 0,
                        "topic": "/t",
                        "encoding": encoding,
                        "schemaName": "pkg/T",
                        "schema": "text",
                    }
                ],
            },
        )
    )
    assert event == Advertise((Channel(0, "/t", encoding, "pkg/T", schema_encoding, "text"),))


def test_legacy_explicit_schema_encoding_wins() -> None:
    channel = {
        "id": 4,
        "topic": "/t",
        "encoding": "cdr",
        "schemaName": "pkg/msg/T",
        "schema": "module pkg {};",
        "schemaEncoding": "ros2idl",
    }
    event = one(send(engine("foxglove.websocket.v1"), {"op": "advertise", "channels": [channel]}))
    assert event == Advertise((Channel(4, "/t", "cdr", "pkg/msg/T", "ros2idl", "module pkg {};"),))


def test_channel_without_any_schema() -> None:
    event = one(
        send(
            engine(),
            {"op": "advertise", "channels": [{"id": 1, "topic": "/free", "encoding": "json"}]},
        )
    )
    assert event == Advertise((Channel(1, "/free", "json", "", "", ""),))


def test_bad_channel_skipped_others_kept() -> None:
    e = engine("foxglove.websocket.v1")
    events = send(
        e,
        {
            "op": "advertise",
            "channels": [
                {"id": -1, "topic": "/neg", "encoding": "cdr", "schemaName": "a"},
                {"id": 1, "topic": 5, "encoding": "cdr", "schemaName": "a"},
                {"id": 2, "topic": "/ok", "encoding": "cdr", "schemaName": "a", "schema": ""},
                "nope",
            ],
        },
    )
    assert len(violations(events)) == 3
    assert events[-1] == Advertise((Channel(2, "/ok", "cdr", "a", "ros2msg", ""),))
    assert set(e.channels) == {2}


def test_readvertise_live_channel_updates_it() -> None:
    e = connected()
    sub_id, _ = e.subscribe(1)
    send(
        e,
        {
            "op": "advertise",
            "channels": [{"id": 1, "topic": "/chatter", "encoding": "cdr", "schemaId": 1}],
        },
    )
    assert e.channels[1].schema_name == "Foo"
    assert e.subscription_channel(sub_id) == e.channels[1]


# --------------------------------------------------------------------------
# Ids 0 and null ids


def test_status_with_null_and_zero_like_ids() -> None:
    e = engine()
    assert one(send(e, {"op": "status", "level": 0, "message": "hi", "id": None})) == Status(
        0, "hi", None
    )
    assert one(send(e, {"op": "status", "level": 2, "message": "bad"})) == Status(2, "bad", None)
    assert one(send(e, {"op": "status", "level": 1, "message": "w", "id": "0"})) == Status(
        1, "w", "0"
    )
    # A numeric id is taken as its text.
    assert one(send(e, {"op": "status", "level": 1, "message": "w", "id": 0})) == Status(
        1, "w", "0"
    )


def test_parameter_values_null_id() -> None:
    event = one(send(engine(), {"op": "parameterValues", "parameters": [], "id": None}))
    assert event == ParameterValues((), None)
    event = one(send(engine(), {"op": "parameterValues", "parameters": []}))
    assert event == ParameterValues((), None)


def test_channel_and_service_id_zero() -> None:
    e = engine("foxglove.websocket.v1")
    send(
        e,
        {
            "op": "advertise",
            "channels": [{"id": 0, "topic": "/z", "encoding": "cdr", "schemaName": "a"}],
        },
    )
    send(e, {"op": "advertiseServices", "services": [{"id": 0, "name": "/s", "type": "p/S"}]})
    assert 0 in e.channels
    assert 0 in e.services
    sub_id, text = e.subscribe(0)
    assert json.loads(text) == {
        "op": "subscribe",
        "subscriptions": [{"id": sub_id, "channelId": 0}],
    }
    zero = e.channels[0]
    assert one(send(e, {"op": "unadvertise", "channelIds": [0]})) == Unadvertise((zero,))
    assert e.subscription_channel(sub_id) == zero
    assert isinstance(
        one(send(e, {"op": "unadvertiseServices", "serviceIds": [0]})), UnadvertiseServices
    )


# --------------------------------------------------------------------------
# Services: nested vs flat


def service_event(service: dict[str, Any], e: FoxgloveEngine | None = None) -> ServiceDef:
    base = {"id": 3, "name": "/svc", "type": "pkg/srv/Do"}
    event = one(send(e or engine(), {"op": "advertiseServices", "services": [{**base, **service}]}))
    assert isinstance(event, AdvertiseServices)
    return event.services[0]


NESTED_REQ = {
    "encoding": "cdr",
    "schemaName": "pkg/srv/Do_Request",
    "schemaEncoding": "ros2msg",
    "schema": "int32 a",
}
NESTED_RESP = {
    "encoding": "cdr",
    "schemaName": "pkg/srv/Do_Response",
    "schemaEncoding": "ros2msg",
    "schema": "int32 b",
}


def test_service_nested_both_sides() -> None:
    svc = service_event({"request": NESTED_REQ, "response": NESTED_RESP})
    assert svc.request == MessageSchema("cdr", "pkg/srv/Do_Request", "ros2msg", "int32 a")
    assert svc.response == MessageSchema("cdr", "pkg/srv/Do_Response", "ros2msg", "int32 b")


def test_service_nested_one_side_other_is_none_not_flat() -> None:
    svc = service_event({"request": NESTED_REQ, "responseSchema": "int32 flat"})
    assert svc.request == MessageSchema("cdr", "pkg/srv/Do_Request", "ros2msg", "int32 a")
    assert svc.response is None
    svc = service_event({"response": NESTED_RESP, "requestSchema": "int32 flat"})
    assert svc.request is None
    assert svc.response is not None


def test_service_with_both_shapes_uses_nested() -> None:
    svc = service_event(
        {
            "request": NESTED_REQ,
            "response": NESTED_RESP,
            "requestSchema": "x",
            "responseSchema": "y",
        }
    )
    assert svc.request is not None
    assert svc.request.schema == "int32 a"
    assert svc.response is not None
    assert svc.response.schema == "int32 b"


def test_service_flat_only() -> None:
    svc = service_event({"requestSchema": "int32 a", "responseSchema": ""})
    assert svc.request == MessageSchema("", "pkg/srv/Do_Request", "ros2msg", "int32 a")
    assert svc.response == MessageSchema("", "pkg/srv/Do_Response", "ros2msg", "")


def test_service_flat_missing_side_is_none() -> None:
    svc = service_event({"requestSchema": "int32 a"})
    assert svc.request is not None
    assert svc.response is None
    svc = service_event({})
    assert (svc.request, svc.response) == (None, None)


def test_service_null_nested_falls_back_to_flat() -> None:
    svc = service_event(
        {"request": None, "response": None, "requestSchema": "int32 a", "responseSchema": "int32 b"}
    )
    assert svc.request == MessageSchema("", "pkg/srv/Do_Request", "ros2msg", "int32 a")


def test_service_flat_on_ros1_server_uses_ros1msg() -> None:
    e = engine("foxglove.websocket.v1")
    send(
        e,
        {
            "op": "serverInfo",
            "name": "ros1",
            "capabilities": ["services"],
            "supportedEncodings": ["ros1"],
        },
    )
    svc = service_event({"requestSchema": "int32 a", "responseSchema": "int32 b"}, e)
    assert svc.request is not None
    assert svc.request.schema_encoding == "ros1msg"


def test_service_nested_defaults() -> None:
    svc = service_event({"request": {"encoding": "json", "schemaName": "R"}})
    assert svc.request == MessageSchema("json", "R", "jsonschema", "")


def test_bad_service_skipped() -> None:
    e = engine()
    events = send(
        e,
        {
            "op": "advertiseServices",
            "services": [
                {"id": 1, "name": "/a", "type": "t", "request": "not an object"},
                {"id": 2, "name": "/b", "type": "t", "requestSchema": 5},
                {"id": 3, "name": "/c", "type": "t"},
            ],
        },
    )
    assert len(violations(events)) == 2
    assert set(e.services) == {3}


def test_unadvertise_services_unknown_id() -> None:
    e = connected()
    events = send(e, {"op": "unadvertiseServices", "serviceIds": [2, 77, "x"]})
    assert len(violations(events)) == 2
    assert isinstance(events[-1], UnadvertiseServices)
    assert [s.name for s in events[-1].services] == ["/trigger"]
    assert set(e.services) == {1}


# --------------------------------------------------------------------------
# Other server ops


def test_status_and_remove_status() -> None:
    e = engine()
    assert one(send(e, {"op": "status", "level": 1, "message": "careful", "id": "s1"})) == Status(
        1, "careful", "s1"
    )
    assert one(send(e, {"op": "removeStatus", "statusIds": ["s1", "s2"]})) == RemoveStatus(
        ("s1", "s2")
    )


def test_connection_graph_update() -> None:
    msg = {
        "op": "connectionGraphUpdate",
        "publishedTopics": [{"name": "/t", "publisherIds": ["n1"]}],
        "subscribedTopics": [{"name": "/t", "subscriberIds": ["n2"]}],
        "advertisedServices": [{"name": "/s", "providerIds": ["n1"]}],
        "removedTopics": ["/old"],
        "removedServices": ["/gone"],
    }
    assert one(send(engine(), msg)) == ConnectionGraphUpdate(
        ({"name": "/t", "publisherIds": ["n1"]},),
        ({"name": "/t", "subscriberIds": ["n2"]},),
        ({"name": "/s", "providerIds": ["n1"]},),
        ("/old",),
        ("/gone",),
    )
    assert one(send(engine(), {"op": "connectionGraphUpdate"})) == ConnectionGraphUpdate(
        (), (), (), (), ()
    )


def test_unadvertise_unknown_ids_are_violations_and_skipped() -> None:
    e = connected()
    events = send(e, {"op": "unadvertise", "channelIds": [99, 1, True]})
    assert violations(events) == [
        "unadvertise: channel id True is not an integer",
        "unadvertise: unknown channel id 99",
    ]
    assert events[-1] == Unadvertise((CHATTER,))
    assert only_violation(send(e, {"op": "unadvertise", "channelIds": [1]})) == (
        "unadvertise: unknown channel id 1"
    )


def test_unadvertise_of_100000_unknown_ids_is_one_violation_that_counts_them() -> None:
    e = connected()
    events = send(e, {"op": "unadvertise", "channelIds": [1, *range(10**6, 10**6 + 100_000)]})
    violation, unadvertise = events
    assert violation == ProtocolViolation(
        "unadvertise: unknown channel ids 1000000, 1000001, 1000002 and 99997 more",
        count=100_000,
    )
    assert unadvertise == Unadvertise((CHATTER,))
    events = send(e, {"op": "unadvertiseServices", "serviceIds": list(range(50, 60))})
    assert one(events) == ProtocolViolation(
        "unadvertiseServices: unknown service ids 50, 51, 52 and 7 more", count=10
    )


def test_a_frame_shows_its_first_violations_and_merges_the_rest_per_kind() -> None:
    shown = fg.VIOLATIONS_SHOWN
    bad = [{"id": i, "topic": "/x"} for i in range(shown + 100)]  # no encoding
    huge = "x" * 200
    oversize = [
        {
            "id": 10_000 + i,
            "topic": f"/big{i}",
            "encoding": "json",
            "schemaName": "S",
            "schema": huge,
            "schemaEncoding": "jsonschema",
        }
        for i in range(5)
    ]
    good = {"id": 7, "topic": "/ok", "encoding": "json", "schemaName": "S", "schema": "{}"}
    e = FoxgloveEngine("foxglove.sdk.v1.1", max_schema_size=100)
    events = send(e, {"op": "advertise", "channels": [*bad, *oversize, good]})
    reasons = [(v.kind, v.count) for v in events if isinstance(v, ProtocolViolation)]
    # the first `shown` stand alone, then one event per kind for the rest
    assert reasons == [("malformed", 1)] * shown + [("malformed", 100), ("schema_too_large", 5)]
    merged = [v for v in events if isinstance(v, ProtocolViolation)][shown]
    assert merged.reason.startswith("100 more in this frame, the first: advertise: channel skipped")
    assert sum(v.count for v in events if isinstance(v, ProtocolViolation)) == shown + 105
    advertised = events[-1]
    assert isinstance(advertised, Advertise)
    assert sorted(c.topic for c in advertised.channels) == [
        "/big0",
        "/big1",
        "/big2",
        "/big3",
        "/big4",
        "/ok",
    ]


def test_time_frame() -> None:
    assert one(engine().receive_binary(b"\x02" + struct.pack("<Q", 2**63 + 5))) == Time(2**63 + 5)


def test_fetch_asset_response_ok_and_error() -> None:
    ok = b"\x04" + struct.pack("<IBI", 9, 0, 0) + b"mesh-bytes"
    event = one(engine().receive_binary(ok))
    assert isinstance(event, FetchAssetResponse)
    assert (event.request_id, event.ok, event.error, bytes(event.data)) == (
        9,
        True,
        "",
        b"mesh-bytes",
    )
    err = b"\x04" + struct.pack("<IBI", 10, 1, 9) + b"not found"
    event = one(engine().receive_binary(err))
    assert isinstance(event, FetchAssetResponse)
    assert (event.request_id, event.ok, event.error, bytes(event.data)) == (
        10,
        False,
        "not found",
        b"",
    )


def test_fetch_asset_response_bad_status() -> None:
    reason = only_violation(engine().receive_binary(b"\x04" + struct.pack("<IBI", 1, 7, 0)))
    assert "unknown status 7" in reason


def test_playback_state_is_read() -> None:
    # as the Foxglove SDK server sends it: playing at 1.5x, 500 ns in, answering "r1"
    frame = b"\x05\x00" + struct.pack("<QfBI", 500, 1.5, 0, 2) + b"r1"
    assert one(engine().receive_binary(frame)) == PlaybackState(0, 500, 1.5, False, "r1")
    ended = b"\x05\x03" + struct.pack("<QfBI", 2**64 - 1, 0.5, 1, 0)
    assert one(engine().receive_binary(ended)) == PlaybackState(3, 2**64 - 1, 0.5, True, "")


def test_playback_state_truncated_or_garbled_is_a_violation() -> None:
    assert "truncated playback state" in only_violation(engine().receive_binary(b"\x05\x01"))
    long_id = b"\x05\x00" + struct.pack("<QfBI", 1, 1.0, 0, 9) + b"r1"
    assert "needs 28" in only_violation(engine().receive_binary(long_id))
    bad = b"\x05\x00" + struct.pack("<QfBI", 1, 1.0, 0, 2) + b"\xff\xfe"
    assert "not valid UTF-8" in only_violation(engine().receive_binary(bad))


def test_playback_control_request_frame() -> None:
    frame = engine().playback_control(True, 2.0, None, "a")
    assert frame == struct.pack("<BBfBQI", 3, 0, 2.0, 0, 0, 1) + b"a"
    seek = engine().playback_control(False, 0.5, 7_000_000_000, "req-2")
    assert seek == struct.pack("<BBfBQI", 3, 1, 0.5, 1, 7_000_000_000, 5) + b"req-2"


@pytest.mark.parametrize(
    ("args", "error"),
    [
        ((1, 1.0, None, "a"), TypeError),
        ((True, 0.0, None, "a"), ValueError),
        ((True, float("nan"), None, "a"), ValueError),
        ((True, "1", None, "a"), TypeError),
        ((True, 1.0, -1, "a"), ValueError),
        ((True, 1.0, 1.5, "a"), ValueError),
        ((True, 1.0, None, ""), ValueError),
    ],
)
def test_playback_control_request_refuses_bad_arguments(
    args: tuple[Any, ...], error: type[Exception]
) -> None:
    with pytest.raises(error):
        engine().playback_control(*args)


# --------------------------------------------------------------------------
# Parameters


def test_parameter_type_conversions() -> None:
    msg = {
        "op": "parameterValues",
        "parameters": [
            {"name": "f", "type": "float64", "value": 2},
            {"name": "b", "type": "byte_array", "value": "AAFoaQ=="},
            {"name": "arr", "type": "float64_array", "value": [1, 2.5]},
            {"name": "i", "value": 3},
            {"name": "flag", "value": True},
            {"name": "d", "value": {"k": 1.5, "n": {"z": [1, "a"]}}},
            {"name": "gone"},
            {"name": "custom", "type": "mystery", "value": [1]},
        ],
    }
    event = one(send(engine(), msg))
    assert isinstance(event, ParameterValues)
    params = {p.name: p for p in event.parameters}
    assert params["f"].value == 2.0
    assert type(params["f"].value) is float
    assert params["b"] == Parameter("b", b"\x00\x01hi", "byte_array")
    assert params["arr"].value == [1.0, 2.5]
    assert all(type(v) is float for v in params["arr"].value)  # type: ignore[attr-defined]
    assert params["i"] == Parameter("i", 3)
    assert params["flag"] == Parameter("flag", True)
    assert params["d"].value == {"k": 1.5, "n": {"z": [1, "a"]}}
    assert params["gone"] == Parameter("gone", None)
    assert params["custom"] == Parameter("custom", [1], "mystery")


@pytest.mark.parametrize(
    "bad",
    [
        {"name": "b", "type": "byte_array", "value": "not base64!"},
        {"name": "b", "type": "byte_array", "value": 5},
        {"name": "f", "type": "float64", "value": "1.0"},
        {"name": "f", "type": "float64", "value": True},
        {"name": "f", "type": "float64", "value": 10**400},
        {"name": "a", "type": "float64_array", "value": [1, "x"]},
        {"name": "a", "type": "float64_array", "value": 1.0},
        {"name": 5, "value": 1},
        {"value": 1},
        "p",
    ],
)
def test_bad_parameter_skipped(bad: object) -> None:
    msg = {"op": "parameterValues", "parameters": [bad, {"name": "ok", "value": 1}], "id": "q"}
    events = send(engine(), msg)
    assert len(violations(events)) == 1
    assert violations(events)[0].startswith("parameterValues: parameter skipped")
    assert events[-1] == ParameterValues((Parameter("ok", 1),), "q")


# --------------------------------------------------------------------------
# Subscriptions and message data


def test_subscribe_allocates_increasing_ids_from_one() -> None:
    e = connected()
    sub1, text1 = e.subscribe(1)
    sub2, text2 = e.subscribe(2)
    assert (sub1, sub2) == (1, 2)
    assert json.loads(text1) == {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 1}]}
    assert json.loads(text2) == {"op": "subscribe", "subscriptions": [{"id": 2, "channelId": 2}]}
    assert e.subscription_channel(1) == CHATTER
    assert dict(e.subscriptions) == {1: CHATTER, 2: FOO}


def test_subscribe_many() -> None:
    e = connected()
    ids, text = e.subscribe_many([3, 1])
    assert ids == (1, 2)
    assert json.loads(text)["subscriptions"] == [
        {"id": 1, "channelId": 3},
        {"id": 2, "channelId": 1},
    ]


def test_subscribe_validation() -> None:
    e = connected()
    with pytest.raises(ValueError, match="not advertised"):
        e.subscribe(42)
    with pytest.raises(ValueError, match="non-negative"):
        e.subscribe(-1)
    with pytest.raises(TypeError, match="must be an int"):
        e.subscribe("1")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="must be an int"):
        e.subscribe(True)
    with pytest.raises(ValueError, match="no channel ids"):
        e.subscribe_many([])
    with pytest.raises(ValueError, match="given twice"):
        e.subscribe_many([1, 1])
    e.subscribe(1)
    with pytest.raises(ValueError, match="already has subscription 1"):
        e.subscribe(1)
    # All-or-nothing: nothing was allocated by the failed calls.
    assert e.subscribe(2)[0] == 2


def test_message_data_for_live_subscription_zero_copy() -> None:
    e = connected()
    sub_id, _ = e.subscribe(1)
    frame = (
        b"\x01" + struct.pack("<IQ", sub_id, 123456789) + b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00"
    )
    event = one(e.receive_binary(frame))
    assert event == MessageData(sub_id, CHATTER, 123456789, memoryview(frame)[13:])
    assert isinstance(event, MessageData)
    assert event.payload.obj is frame  # a view of the frame, not a copy


def test_message_data_view_of_bytearray_and_memoryview() -> None:
    e = connected()
    sub_id, _ = e.subscribe(1)
    frame = bytearray(b"\x01" + struct.pack("<IQ", sub_id, 1) + b"abc")
    event = one(e.receive_binary(frame))
    assert isinstance(event, MessageData)
    frame[-1] = ord("z")
    assert bytes(event.payload) == b"abz"
    bigger = b"junk" + bytes(frame)
    event = one(e.receive_binary(memoryview(bigger)[4:]))
    assert isinstance(event, MessageData)
    assert bytes(event.payload) == b"abz"


def test_message_data_from_non_byte_memoryviews() -> None:
    e = connected()
    sub_id, _ = e.subscribe(1)
    raw = b"\x01" + struct.pack("<IQ", sub_id, 5) + b"x"  # 14 bytes
    as_u16 = memoryview(array.array("H", raw))
    event = one(e.receive_binary(as_u16))
    assert isinstance(event, MessageData)
    assert bytes(event.payload) == b"x"
    strided = memoryview(bytes(b for pair in zip(raw, raw, strict=True) for b in pair))[::2]
    event = one(e.receive_binary(strided))
    assert isinstance(event, MessageData)
    assert bytes(event.payload) == b"x"


def test_subscription_survives_unadvertise_until_unsubscribe() -> None:
    e = connected()
    sub_id, _ = e.subscribe(3)
    assert one(e.receive_text(UNADVERTISE)) == Unadvertise((CHATTER2,))
    assert 3 not in e.channels
    assert e.subscription_channel(sub_id) == CHATTER2
    frame = b"\x01" + struct.pack("<IQ", sub_id, 7) + b"late"
    event = one(e.receive_binary(frame))
    assert isinstance(event, MessageData)
    assert event.channel == CHATTER2
    assert json.loads(e.unsubscribe([sub_id])) == {"op": "unsubscribe", "subscriptionIds": [sub_id]}
    assert e.subscription_channel(sub_id) is None
    # A frame still in flight after unsubscribe is dropped quietly.
    assert e.receive_binary(frame) == []


def test_message_data_unknown_subscription_is_violation() -> None:
    e = connected()
    frame = b"\x01" + struct.pack("<IQ", 5, 0) + b"x"
    assert only_violation(e.receive_binary(frame)) == "message data for unknown subscription id 5"
    # Subscription id 0 is never allocated.
    frame = b"\x01" + struct.pack("<IQ", 0, 0)
    assert "unknown subscription id 0" in only_violation(e.receive_binary(frame))


def test_resubscribe_after_unadvertise_and_readvertise() -> None:
    e = connected()
    old, _ = e.subscribe(3)
    e.receive_text(UNADVERTISE)
    send(
        e,
        {
            "op": "advertise",
            "channels": [{"id": 3, "topic": "/chatter2", "encoding": "cdr", "schemaId": 1}],
        },
    )
    new, _ = e.subscribe(3)  # the server dropped the old subscription with the channel
    assert new != old
    assert e.subscription_channel(old) == CHATTER2
    assert e.subscription_channel(new) == e.channels[3]
    assert e.subscription_channel(new) != CHATTER2


def test_unsubscribe_validation_and_dedup() -> None:
    e = connected()
    sub_id, _ = e.subscribe(1)
    assert json.loads(e.unsubscribe([sub_id, sub_id, 99])) == {
        "op": "unsubscribe",
        "subscriptionIds": [sub_id, 99],
    }
    with pytest.raises(ValueError, match="non-negative"):
        e.unsubscribe([-1])
    with pytest.raises(TypeError, match="must be an int"):
        e.unsubscribe([1.0])  # type: ignore[list-item]
    with pytest.raises(TypeError, match="iterable of ints"):
        e.unsubscribe(1)  # type: ignore[arg-type]
    # After unsubscribing, the channel can be subscribed again.
    assert e.subscribe(1)[0] == sub_id + 1


def test_state_views_are_read_only() -> None:
    e = connected()
    with pytest.raises(TypeError):
        e.channels[9] = FOO  # type: ignore[index]
    with pytest.raises(TypeError):
        e.services[9] = None  # type: ignore[index]


# --------------------------------------------------------------------------
# Truncated binary frames and garbage


@pytest.mark.parametrize(
    ("frame", "name"),
    [
        (b"\x01", "message data"),
        (b"\x01" + b"\x00" * 11, "message data"),
        (b"\x02\x00\x00\x00\x00\x00\x00\x00", "time"),
        (b"\x03" + b"\x00" * 11, "service call response"),
        (b"\x03" + struct.pack("<III", 1, 2, 10) + b"cdr", "service call response"),
        (b"\x03" + struct.pack("<III", 1, 2, 0xFFFFFFFF), "service call response"),
        (b"\x04" + b"\x00" * 8, "fetch asset response"),
        (b"\x04" + struct.pack("<IBI", 1, 1, 50) + b"short", "fetch asset response"),
    ],
)
def test_truncated_binary_frames(frame: bytes, name: str) -> None:
    reason = only_violation(connected().receive_binary(frame))
    assert reason.startswith(f"truncated {name} frame (opcode 0x{frame[0]:02x})")


def test_empty_and_unknown_binary_frames() -> None:
    assert only_violation(engine().receive_binary(b"")) == "empty binary frame"
    assert only_violation(engine().receive_binary(b"\x09abc")) == "unknown binary opcode 0x09"
    assert only_violation(engine().receive_binary(b"\x00")) == "unknown binary opcode 0x00"


def test_bad_utf8_in_binary_strings() -> None:
    frame = b"\x03" + struct.pack("<III", 1, 2, 2) + b"\xff\xfe"
    assert "not valid UTF-8" in only_violation(engine().receive_binary(frame))
    frame = b"\x04" + struct.pack("<IBI", 1, 1, 1) + b"\xff"
    assert "not valid UTF-8" in only_violation(engine().receive_binary(frame))


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("", "not valid JSON"),
        ("{", "not valid JSON"),
        ("[1, 2]", "JSON array, not an object"),
        ("42", "JSON number, not an object"),
        ('"op"', "JSON string, not an object"),
        ("null", "JSON null, not an object"),
        ("{}", "no string 'op' field"),
        ('{"op": 5}', "no string 'op' field"),
        ('{"op": "bogus"}', "unknown op 'bogus'"),
        ('{"op": "subscribe"}', "unknown op 'subscribe'"),
        ("[" * 100_000 + "]" * 100_000, "nests deeper than 100"),
        ("1" * 5000, "not valid JSON"),
    ],
)
def test_garbage_text(text: str, expected: str) -> None:
    assert expected in only_violation(engine().receive_text(text))


def test_invalid_utf8_text_bytes() -> None:
    assert "not valid UTF-8" in only_violation(engine().receive_text(b'{"op":"\xff"}'))


@pytest.mark.parametrize(
    "msg",
    [
        {"op": "serverInfo", "capabilities": "all"},
        {"op": "serverInfo", "capabilities": [1]},
        {"op": "serverInfo", "metadata": []},
        {"op": "serverInfo", "name": 1},
        {"op": "serverInfo", "sessionId": [1]},
        {"op": "status", "message": "m"},
        {"op": "status", "level": "1", "message": "m"},
        {"op": "status", "level": True, "message": "m"},
        {"op": "status", "level": 1, "message": None},
        {"op": "status", "level": 1, "message": "m", "id": {}},
        {"op": "removeStatus"},
        {"op": "removeStatus", "statusIds": [None]},
        {"op": "advertise"},
        {"op": "advertise", "channels": {}},
        {"op": "advertise", "schemas": 1, "channels": []},
        {"op": "unadvertise", "channelIds": 3},
        {"op": "advertiseServices", "services": None},
        {"op": "unadvertiseServices"},
        {"op": "parameterValues"},
        {"op": "parameterValues", "parameters": [], "id": 1.5},
        {"op": "connectionGraphUpdate", "publishedTopics": ["x"]},
        {"op": "connectionGraphUpdate", "removedTopics": [1]},
        {"op": "serviceCallFailure", "serviceId": "1", "callId": 1, "message": "m"},
        {"op": "serviceCallFailure", "serviceId": 1, "callId": -1, "message": "m"},
        {"op": "serviceCallFailure", "serviceId": 1, "callId": 1},
    ],
)
def test_wrong_field_types_are_violations(msg: dict[str, Any]) -> None:
    reason = only_violation(send(engine(), msg))
    assert reason.startswith(f"{msg['op']}: ")
    assert "internal error" not in reason


def test_engine_keeps_working_after_garbage() -> None:
    e = engine()
    e.receive_text("garbage")
    e.receive_binary(b"\x01")
    assert isinstance(one(e.receive_text(SERVER_INFO)), ServerInfo)
    assert isinstance(one(e.receive_text(ADVERTISE)), Advertise)


def test_receive_text_rejects_non_text_argument() -> None:
    with pytest.raises(TypeError, match="text must be str or bytes"):
        engine().receive_text(42)  # type: ignore[arg-type]


# --------------------------------------------------------------------------
# Client -> server JSON ops


def test_client_advertise_and_unadvertise() -> None:
    e = engine()
    cid, text = e.advertise("/cmd_vel", "cdr", "geometry_msgs/msg/Twist")
    assert cid == 1
    assert json.loads(text) == {
        "op": "advertise",
        "channels": [
            {
                "id": 1,
                "topic": "/cmd_vel",
                "encoding": "cdr",
                "schemaName": "geometry_msgs/msg/Twist",
            }
        ],
    }
    cid2, text = e.advertise(
        "/j", "json", "J", schema='{"type":"object"}', schema_encoding="jsonschema"
    )
    assert cid2 == 2
    assert json.loads(text)["channels"][0] == {
        "id": 2,
        "topic": "/j",
        "encoding": "json",
        "schemaName": "J",
        "schema": '{"type":"object"}',
        "schemaEncoding": "jsonschema",
    }
    assert e.client_channels[2] == Channel(2, "/j", "json", "J", "jsonschema", '{"type":"object"}')
    assert json.loads(e.unadvertise([1])) == {"op": "unadvertise", "channelIds": [1]}
    assert set(e.client_channels) == {2}
    assert e.advertise("/again", "cdr", "x")[0] == 3  # ids are never reused


def test_client_advertise_validation() -> None:
    e = engine()
    with pytest.raises(TypeError, match="topic must be a str"):
        e.advertise(b"/t", "cdr", "x")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="topic must not be empty"):
        e.advertise("", "cdr", "x")
    with pytest.raises(TypeError, match="schema_name must be a str"):
        e.advertise("/t", "cdr", None)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="schema must be a str"):
        e.advertise("/t", "cdr", "x", schema=b"bytes")  # type: ignore[arg-type]
    assert e.advertise("/t", "cdr", "x")[0] == 1


def test_get_parameters() -> None:
    e = engine()
    assert json.loads(e.get_parameters(["a", "b"], "r1")) == {
        "op": "getParameters",
        "parameterNames": ["a", "b"],
        "id": "r1",
    }
    assert json.loads(e.get_parameters([])) == {"op": "getParameters", "parameterNames": []}
    with pytest.raises(TypeError, match="sequence of str"):
        e.get_parameters("abc")
    with pytest.raises(TypeError, match="must be a str"):
        e.get_parameters([1])  # type: ignore[list-item]


def test_set_parameters_typing() -> None:
    text = engine().set_parameters(
        [
            Parameter("f", 2.0),
            Parameter("i", 2),
            Parameter("flag", True),
            Parameter("b", b"\x00\x01hi"),
            Parameter("arr", [1, 2.5]),
            Parameter("ints", [1, 2]),
            Parameter("s", "x"),
            Parameter("d", {"k": [1, 2]}),
            Parameter("unset", None),
            Parameter("forced", 3, "float64"),
            Parameter("forced_arr", (1, 2), "float64_array"),
        ],
        "set1",
    )
    assert "2.0" in text
    msg = json.loads(text)
    assert msg["op"] == "setParameters"
    assert msg["id"] == "set1"
    params = {p["name"]: p for p in msg["parameters"]}
    assert params["f"] == {"name": "f", "value": 2.0, "type": "float64"}
    assert params["i"] == {"name": "i", "value": 2}
    assert params["flag"] == {"name": "flag", "value": True}
    assert params["b"] == {"name": "b", "value": "AAFoaQ==", "type": "byte_array"}
    assert params["arr"] == {"name": "arr", "value": [1.0, 2.5], "type": "float64_array"}
    assert params["ints"] == {"name": "ints", "value": [1, 2]}
    assert params["s"] == {"name": "s", "value": "x"}
    assert params["d"] == {"name": "d", "value": {"k": [1, 2]}}
    assert params["unset"] == {"name": "unset"}
    assert params["forced"] == {"name": "forced", "value": 3.0, "type": "float64"}
    assert params["forced_arr"] == {
        "name": "forced_arr",
        "value": [1.0, 2.0],
        "type": "float64_array",
    }


def test_set_parameters_round_trips_through_the_parser() -> None:
    sent = [
        Parameter("f", 2.0),
        Parameter("b", b"\xff\x00"),
        Parameter("a", [0.5, 1.0]),
        Parameter("i", 7),
    ]
    msg = json.loads(engine().set_parameters(sent))
    event = one(send(engine(), {"op": "parameterValues", "parameters": msg["parameters"]}))
    assert event == ParameterValues(
        (
            Parameter("f", 2.0, "float64"),
            Parameter("b", b"\xff\x00", "byte_array"),
            Parameter("a", [0.5, 1.0], "float64_array"),
            Parameter("i", 7, None),
        ),
        None,
    )


@pytest.mark.parametrize(
    ("param", "error"),
    [
        (Parameter("nan", float("nan")), ValueError),
        (Parameter("inf", [1.0, float("inf")]), ValueError),
        (Parameter("obj", object()), TypeError),
        (Parameter("nested_bytes", {"b": b"x"}), TypeError),
        (Parameter("bad_bytes", "str", "byte_array"), TypeError),
        (Parameter("bad_float", "1.0", "float64"), TypeError),
        (Parameter("bad_arr", 1.0, "float64_array"), TypeError),
        (Parameter(1, 1), TypeError),  # type: ignore[arg-type]
    ],
)
def test_set_parameters_rejects_bad_values(param: Parameter, error: type[Exception]) -> None:
    with pytest.raises(error):
        engine().set_parameters([param])


def test_set_parameters_rejects_non_parameters() -> None:
    with pytest.raises(TypeError, match="Parameter"):
        engine().set_parameters(Parameter("a", 1))  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="Parameter instances"):
        engine().set_parameters([{"name": "a", "value": 1}])  # type: ignore[list-item]


def test_parameter_update_subscriptions_and_connection_graph() -> None:
    e = engine()
    assert json.loads(e.subscribe_parameter_updates(["a"])) == {
        "op": "subscribeParameterUpdates",
        "parameterNames": ["a"],
    }
    assert json.loads(e.unsubscribe_parameter_updates(("a", "b"))) == {
        "op": "unsubscribeParameterUpdates",
        "parameterNames": ["a", "b"],
    }
    assert json.loads(e.subscribe_connection_graph()) == {"op": "subscribeConnectionGraph"}
    assert json.loads(e.unsubscribe_connection_graph()) == {"op": "unsubscribeConnectionGraph"}


def test_fetch_asset() -> None:
    e = engine()
    assert json.loads(e.fetch_asset("package://robot/mesh.stl", 0)) == {
        "op": "fetchAsset",
        "uri": "package://robot/mesh.stl",
        "requestId": 0,
    }
    with pytest.raises(ValueError, match="32 bits"):
        e.fetch_asset("u", 2**32)
    with pytest.raises(ValueError, match="uri must not be empty"):
        e.fetch_asset("", 1)


def test_client_json_is_compact_and_keeps_unicode() -> None:
    text = engine().get_parameters(["größe"])
    assert text == '{"op":"getParameters","parameterNames":["größe"]}'


# --------------------------------------------------------------------------
# Client -> server binary ops


def test_message_data_layout_byte_exact() -> None:
    e = engine()
    cid, _ = e.advertise("/t", "cdr", "x")
    assert e.message_data(cid, b"\xaa\xbb") == b"\x01\x01\x00\x00\x00\xaa\xbb"
    assert e.message_data(cid, bytearray(b"z")) == b"\x01\x01\x00\x00\x00z"
    assert e.message_data(cid, memoryview(b"xyz")[1:]) == b"\x01\x01\x00\x00\x00yz"


def test_message_data_validation() -> None:
    e = engine()
    with pytest.raises(ValueError, match="not advertised"):
        e.message_data(1, b"")
    cid, _ = e.advertise("/t", "cdr", "x")
    with pytest.raises(TypeError, match="must be an int"):
        e.message_data(True, b"")
    with pytest.raises(TypeError, match="bytes-like"):
        e.message_data(cid, "text")  # type: ignore[arg-type]
    e.unadvertise([cid])
    with pytest.raises(ValueError, match="not advertised"):
        e.message_data(cid, b"")


def test_service_call_request_layout_byte_exact() -> None:
    frame = engine().service_call_request(1, 44, "cdr", b"\x00\x01\x00\x00\x01\x00\x00\x00")
    assert (
        frame
        == bytes.fromhex("02 01000000 2c000000 03000000")
        + b"cdr"
        + b"\x00\x01\x00\x00\x01\x00\x00\x00"
    )


def test_service_call_request_validation() -> None:
    e = engine()
    with pytest.raises(ValueError, match="non-negative"):
        e.service_call_request(-1, 0, "cdr", b"")
    with pytest.raises(ValueError, match="32 bits"):
        e.service_call_request(0, 2**32, "cdr", b"")
    with pytest.raises(TypeError, match="must be an int"):
        e.service_call_request(0, 1.0, "cdr", b"")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="encoding must not be empty"):
        e.service_call_request(0, 0, "", b"")
    with pytest.raises(TypeError, match="bytes-like"):
        e.service_call_request(0, 0, "cdr", None)  # type: ignore[arg-type]


# --------------------------------------------------------------------------
# Properties (hypothesis)

u32 = st.integers(0, 2**32 - 1)
payloads = st.binary(max_size=256)


@given(st.text())
@settings(max_examples=examples(300))
def test_any_text_never_raises(text: str) -> None:
    events = connected().receive_text(text)
    assert all(isinstance(ev, Event) for ev in events)


@given(st.binary())
@settings(max_examples=examples(300))
def test_any_text_bytes_never_raises(data: bytes) -> None:
    events = connected().receive_text(data)
    assert all(isinstance(ev, Event) for ev in events)


@given(st.binary(max_size=64), st.sampled_from([bytes, bytearray, memoryview]))
@settings(max_examples=examples(500))
def test_any_binary_never_raises(data: bytes, kind: type) -> None:
    e = connected()
    e.subscribe_many([1, 2, 3])
    events = e.receive_binary(kind(data))
    assert isinstance(events, list)
    for ev in events:
        assert isinstance(ev, Event)
        if isinstance(ev, ProtocolViolation):
            assert "internal error" not in ev.reason


@given(st.integers(0, 7), st.binary(max_size=40))
@settings(max_examples=examples(500))
def test_any_opcode_with_any_body_never_raises(opcode: int, body: bytes) -> None:
    events = connected().receive_binary(bytes([opcode]) + body)
    assert all(isinstance(ev, Event) for ev in events)
    assert not any("internal error" in r for r in violations(events))


json_scalars = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8)
json_values = st.recursive(
    json_scalars,
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3)
    ),
    max_leaves=10,
)
known_ops = st.sampled_from(
    [
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
    ]
)
field_names = st.sampled_from(
    [
        "id",
        "name",
        "channels",
        "schemas",
        "services",
        "parameters",
        "channelIds",
        "serviceIds",
        "level",
        "message",
    ]
)


@given(known_ops, st.dictionaries(field_names | st.text(max_size=6), json_values, max_size=4))
@settings(max_examples=examples(500))
def test_known_op_with_random_fields_never_raises(op: str, fields: dict[str, Any]) -> None:
    events = connected().receive_text(json.dumps({**fields, "op": op}))
    assert all(isinstance(ev, Event) for ev in events)
    assert not any("internal error" in r for r in violations(events))


@given(u32, payloads)
def test_message_data_layout_property(channel_count: int, payload: bytes) -> None:
    e = engine()
    cid = 0
    for _ in range(channel_count % 5 + 1):
        cid, _ = e.advertise("/t", "cdr", "x")
    frame = e.message_data(cid, payload)
    assert frame[0] == 0x01
    assert struct.unpack_from("<I", frame, 1) == (cid,)
    assert frame[5:] == payload
    assert len(frame) == 5 + len(payload)


@given(u32, u32, st.text(min_size=1, max_size=20), payloads)
def test_service_call_request_layout_property(
    service_id: int, call_id: int, encoding: str, payload: bytes
) -> None:
    try:
        enc = encoding.encode("utf-8")
    except UnicodeEncodeError:  # lone surrogates are not valid text on the wire
        return
    frame = engine().service_call_request(service_id, call_id, encoding, payload)
    assert frame[0] == 0x02
    assert struct.unpack_from("<III", frame, 1) == (service_id, call_id, len(enc))
    assert frame[13 : 13 + len(enc)] == enc
    assert frame[13 + len(enc) :] == payload
    # The response has the same layout after the opcode: the parser reads it back.
    event = one(engine().receive_binary(b"\x03" + frame[1:]))
    assert isinstance(event, ServiceCallResponse)
    assert (event.service_id, event.call_id, event.encoding) == (service_id, call_id, encoding)
    assert bytes(event.payload) == payload


@given(u32, st.integers(0, 2**64 - 1), payloads)
def test_message_data_parse_property(sub_offset: int, log_time: int, payload: bytes) -> None:
    e = connected()
    sub_id, _ = e.subscribe(1)
    frame = b"\x01" + struct.pack("<IQ", sub_id, log_time) + payload
    event = one(e.receive_binary(frame))
    assert isinstance(event, MessageData)
    assert (event.subscription_id, event.log_time_ns, bytes(event.payload)) == (
        sub_id,
        log_time,
        payload,
    )
    never_allocated = sub_id + 1 + sub_offset % (2**32 - sub_id - 1)
    bad = b"\x01" + struct.pack("<IQ", never_allocated, log_time) + payload
    assert "unknown subscription" in only_violation(e.receive_binary(bad))
    for cut in range(13):
        assert "truncated message data" in only_violation(e.receive_binary(frame[:cut] or b"\x01"))


# --------------------------------------------------------------------------
# Limits: refused input is a classified violation, never an exception


def kinds(events: list[Event]) -> list[str]:
    return [e.kind for e in events if isinstance(e, ProtocolViolation)]


def test_invalid_utf8_is_its_own_kind() -> None:
    events = engine().receive_text(b'{"op":"status","level":0,"message":"\xff"}')
    assert kinds(events) == ["invalid_utf8"]


def test_json_nested_beyond_the_limit_is_refused_unparsed() -> None:
    def status(depth: int) -> str:
        # the frame object itself is one level
        return (
            '{"op":"status","level":0,"message":"m","x":'
            + "[" * (depth - 1)
            + "]" * (depth - 1)
            + "}"
        )

    e = FoxgloveEngine("foxglove.sdk.v1.1", max_json_depth=10)
    assert isinstance(one(e.receive_text(status(10))), fg.Status)
    assert kinds(e.receive_text(status(11))) == ["json_depth"]
    # brackets inside strings do not count
    text = json.dumps({"op": "status", "level": 0, "message": "[" * 50 + "{" * 50})
    assert isinstance(one(e.receive_text(text)), fg.Status)
    # far past the interpreter's recursion limit: refused, not a RecursionError
    assert kinds(engine().receive_text("[" * 100_000)) == ["json_depth"]


def advertise_channels(ids: range, **extra: Any) -> dict[str, Any]:
    return {
        "op": "advertise",
        "channels": [
            {"id": i, "topic": f"/t{i}", "encoding": "cdr", "schemaName": "std_msgs/msg/String"}
            | extra
            for i in ids
        ],
    }


def test_channels_beyond_max_channels_are_refused_once_per_advertise() -> None:
    e = FoxgloveEngine("foxglove.sdk.v1.1", max_channels=3)
    events = send(e, advertise_channels(range(5)))
    advertised = [ev for ev in events if isinstance(ev, fg.Advertise)]
    assert [c.id for c in advertised[0].channels] == [0, 1, 2]
    assert kinds(events) == ["channel_limit"]  # one report for two refused channels
    assert "2 channels" in violations(events)[0]
    assert sorted(e.channels) == [0, 1, 2]
    # re-advertising a kept channel is fine; a new one is still refused
    events = send(e, advertise_channels(range(2, 4)))
    assert [c.id for c in one([ev for ev in events if isinstance(ev, fg.Advertise)]).channels] == [
        2
    ]  # type: ignore[attr-defined]
    assert kinds(events) == ["channel_limit"]
    # room again after an unadvertise
    send(e, {"op": "unadvertise", "channelIds": [0]})
    assert kinds(send(e, advertise_channels(range(3, 4)))) == []
    assert sorted(e.channels) == [1, 2, 3]


def test_services_beyond_max_services_are_refused_once_per_advertise() -> None:
    e = FoxgloveEngine("foxglove.sdk.v1.1", max_services=2)
    services = [{"id": i, "name": f"/s{i}", "type": "std_srvs/srv/Empty"} for i in range(4)]
    events = send(e, {"op": "advertiseServices", "services": services})
    assert kinds(events) == ["service_limit"]
    assert sorted(e.services) == [0, 1]


def test_schema_over_max_schema_size_is_dropped_and_the_channel_kept() -> None:
    e = FoxgloveEngine("foxglove.sdk.v1.1", max_schema_size=100)
    events = send(
        e,
        advertise_channels(range(1), schema="string data\n" + "#" * 200, schemaEncoding="ros2msg"),
    )
    assert kinds(events) == ["schema_too_large"]
    assert "/t0" in violations(events)[0]  # names the channel
    assert e.channels[0].schema == "" and e.channels[0].schema_name == "std_msgs/msg/String"
    # the same through the schema table (foxglove.sdk.v1.1): reported per channel using it
    events = send(
        e,
        {
            "op": "advertise",
            "schemas": [{"id": 7, "name": "x/msg/Big", "encoding": "ros2msg", "data": "#" * 101}],
            "channels": [
                {"id": 1, "topic": "/a", "encoding": "cdr", "schemaId": 7},
                {"id": 2, "topic": "/b", "encoding": "cdr", "schemaId": 7},
            ],
        },
    )
    assert kinds(events) == ["schema_too_large", "schema_too_large"]
    assert e.channels[1].schema == "" and e.channels[1].schema_name == "x/msg/Big"
    # a schema that fits is kept
    events = send(
        e, advertise_channels(range(3, 4), schema="string data", schemaEncoding="ros2msg")
    )
    assert kinds(events) == [] and e.channels[3].schema == "string data"


def test_service_schema_over_max_schema_size_is_dropped() -> None:
    e = FoxgloveEngine("foxglove.sdk.v1.1", max_schema_size=100)
    side = {"encoding": "cdr", "schemaName": "x/srv/S_Request", "schema": "#" * 101}
    service = {"id": 1, "name": "/s", "type": "x/srv/S", "request": side, "response": side}
    events = send(e, {"op": "advertiseServices", "services": [service]})
    assert kinds(events) == ["schema_too_large", "schema_too_large"]
    svc = e.services[1]
    assert svc.request is not None and svc.request.schema == ""


def test_limits_are_validated() -> None:
    with pytest.raises(ValueError, match="max_channels"):
        FoxgloveEngine("foxglove.sdk.v1.1", max_channels=0)
