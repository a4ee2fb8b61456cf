"""Reading what the server sends: the helpers that turn parsed JSON values and
binary frames into validated values and events (part of
:mod:`ros_mobile_bridge.wire.foxglove`).

Everything here is a function of its arguments: the engine's tables
(schemas, limits, the last ``serverInfo``) come in as parameters, and the
engine (:mod:`._engine`) owns and updates them. The JSON helpers raise
:class:`Malformed`, which the engine turns into a :class:`ProtocolViolation`."""

from __future__ import annotations

import base64
from collections.abc import Mapping
from typing import Any, Final

from ._events import (
    Channel,
    ConnectionGraphUpdate,
    Event,
    FetchAssetResponse,
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
)
from ._protocol import (
    BINARY_NAMES,
    DEFAULT_SCHEMA_ENCODINGS,
    FETCH_ASSET_HEADER,
    OP_FETCH_ASSET_RESPONSE,
    OP_PLAYBACK_STATE,
    OP_SERVICE_CALL_RESPONSE,
    PLAYBACK_STATE_HEADER,
    SERVICE_RESPONSE_HEADER,
)

__all__ = [
    "VIOLATIONS_SHOWN",
    "Malformed",
    "as_float",
    "as_id",
    "as_object",
    "as_str",
    "flat_side",
    "json_kind",
    "merge_violations",
    "nested_side",
    "opt_list",
    "opt_object_tuple",
    "opt_request_id",
    "opt_str",
    "opt_str_tuple",
    "parse_channel",
    "parse_parameter",
    "parse_service",
    "read_connection_graph_update",
    "read_fetch_asset_response",
    "read_parameter_values",
    "read_playback_state",
    "read_remove_status",
    "read_server_info",
    "read_service_call_failure",
    "read_service_call_response",
    "read_status",
    "req_id",
    "req_list",
    "req_str",
    "schema_dropped",
    "schema_fits",
    "truncated",
    "unknown_ids",
]


# --------------------------------------------------------------------------
# One frame, few violations: a frame of 100,000 bad items is not 100,000 events.


def unknown_ids(what: str, ids: list[int]) -> ProtocolViolation:
    """One violation for every id in ``ids`` (not empty) that names nothing
    the server advertised; the reason shows the first few."""
    shown = ", ".join(str(i) for i in ids[:3])
    more = f" and {len(ids) - 3} more" if len(ids) > 3 else ""
    plural = "s" if len(ids) > 1 else ""
    return ProtocolViolation(f"{what}{plural} {shown}{more}", count=len(ids))


VIOLATIONS_SHOWN: Final = 8
"""A frame's first this many violations are events of their own; the rest
are one event per kind (see :func:`merge_violations`)."""


def merge_violations(events: list[Event]) -> list[Event]:
    """``events`` with the violations after the first :data:`VIOLATIONS_SHOWN`
    merged into one event per kind, placed where that kind's first merged
    violation was: its reason names how many more and the first of them,
    its ``count`` the total. Other events keep their order."""
    if sum(1 for e in events if type(e) is ProtocolViolation) <= VIOLATIONS_SHOWN:
        return events
    out: list[Event] = []
    merged: dict[str, tuple[int, int]] = {}  # kind -> (its place in out, count)
    shown = 0
    for event in events:
        if type(event) is not ProtocolViolation:
            out.append(event)
        elif shown < VIOLATIONS_SHOWN:
            shown += 1
            out.append(event)
        elif event.kind in merged:
            at, count = merged[event.kind]
            merged[event.kind] = (at, count + event.count)
        else:
            merged[event.kind] = (len(out), event.count)
            out.append(event)
    for kind, (at, count) in merged.items():
        first = out[at]
        assert type(first) is ProtocolViolation
        if count > first.count:
            reason = f"{count} more in this frame, the first: {first.reason}"
            out[at] = ProtocolViolation(reason, kind, count)
    return out


# --------------------------------------------------------------------------
# Parsing helpers: raise Malformed, which the engine turns into a violation.


class Malformed(Exception):
    """Raised inside the parser for one malformed message or item."""


def json_kind(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, (int, float)):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "array"
    if isinstance(value, dict):
        return "object"
    return type(value).__name__


def as_id(value: object, what: str) -> int:
    if type(value) is not int or value < 0:
        raise Malformed(
            f"{what} must be a non-negative integer, got {json_kind(value)} {value!r:.40}"
        )
    return value


def as_str(value: object, what: str) -> str:
    if type(value) is not str:
        raise Malformed(f"{what} must be a string, got {json_kind(value)}")
    return value


def as_object(value: object, what: str) -> dict[str, Any]:
    if type(value) is not dict:
        raise Malformed(f"{what} must be an object, got {json_kind(value)}")
    return value


def req_id(obj: dict[str, Any], key: str) -> int:
    if key not in obj:
        raise Malformed(f"missing field {key!r}")
    return as_id(obj[key], f"field {key!r}")


def req_str(obj: dict[str, Any], key: str) -> str:
    if key not in obj:
        raise Malformed(f"missing field {key!r}")
    return as_str(obj[key], f"field {key!r}")


def opt_str(obj: dict[str, Any], key: str) -> str | None:
    value = obj.get(key)
    if value is None:
        return None
    return as_str(value, f"field {key!r}")


def opt_request_id(obj: dict[str, Any], key: str) -> str | None:
    """A string id that may be absent or null; an integer is taken as its text."""
    value = obj.get(key)
    if value is None or type(value) is str:
        return value
    if type(value) is int:
        return str(value)
    raise Malformed(f"field {key!r} must be a string or null, got {json_kind(value)}")


def req_list(obj: dict[str, Any], key: str) -> list[Any]:
    if key not in obj:
        raise Malformed(f"missing field {key!r}")
    value = obj[key]
    if type(value) is not list:
        raise Malformed(f"field {key!r} must be an array, got {json_kind(value)}")
    return value


def opt_list(obj: dict[str, Any], key: str) -> list[Any]:
    value = obj.get(key)
    if value is None:
        return []
    if type(value) is not list:
        raise Malformed(f"field {key!r} must be an array, got {json_kind(value)}")
    return value


def opt_str_tuple(obj: dict[str, Any], key: str) -> tuple[str, ...]:
    return tuple(as_str(v, f"an entry of {key!r}") for v in opt_list(obj, key))


def opt_object_tuple(obj: dict[str, Any], key: str) -> tuple[dict[str, Any], ...]:
    return tuple(as_object(v, f"an entry of {key!r}") for v in opt_list(obj, key))


def as_float(value: object, what: str) -> float:
    if type(value) is float:
        return value
    if type(value) is int:
        try:
            return float(value)
        except OverflowError:
            raise Malformed(f"{what} is out of float64 range") from None
    raise Malformed(f"{what} must be a number, got {json_kind(value)}")


def parse_parameter(raw: object) -> Parameter:
    obj = as_object(raw, "a parameter")
    name = req_str(obj, "name")
    ptype = opt_str(obj, "type")
    value = obj.get("value")
    if value is None:
        return Parameter(name, None, ptype)
    if ptype == "byte_array":
        if type(value) is not str:
            raise Malformed(f"parameter {name!r}: byte_array value must be a base64 string")
        try:
            value = base64.b64decode(value, validate=True)
        except ValueError:
            raise Malformed(f"parameter {name!r}: byte_array value is not valid base64") from None
    elif ptype == "float64":
        value = as_float(value, f"parameter {name!r}: float64 value")
    elif ptype == "float64_array":
        if type(value) is not list:
            raise Malformed(f"parameter {name!r}: float64_array value must be an array")
        value = [as_float(v, f"parameter {name!r}: float64_array entry") for v in value]
    return Parameter(name, value, ptype)


def flat_side(
    raw: object, schema_name: str, schema_encoding: str, key: str
) -> MessageSchema | None:
    if raw is None:
        return None
    return MessageSchema("", schema_name, schema_encoding, as_str(raw, f"field {key!r}"))


def nested_side(raw: object, key: str) -> MessageSchema | None:
    if raw is None:
        return None
    obj = as_object(raw, f"field {key!r}")
    encoding = req_str(obj, "encoding")
    schema_name = req_str(obj, "schemaName")
    schema_encoding = opt_str(obj, "schemaEncoding") or DEFAULT_SCHEMA_ENCODINGS.get(encoding, "")
    schema = opt_str(obj, "schema") or ""
    return MessageSchema(encoding, schema_name, schema_encoding, schema)


# --------------------------------------------------------------------------
# Text messages: the entries of an advertisement, checked against the engine's
# schema table and limits, and the handlers of the ops that change no engine state.


def schema_fits(data: str, limit: int) -> bool:
    size = len(data)
    return size <= limit and (size * 4 <= limit or len(data.encode("utf-8", "replace")) <= limit)


def schema_dropped(what: str, schema_name: str | None, size: int, limit: int) -> ProtocolViolation:
    return ProtocolViolation(
        f"advertise: {what}: the schema {schema_name or ''!r:.200} of {size} characters is over "
        f"{limit} bytes; dropped (messages decode with a bundled definition "
        "of the type, if any, else arrive raw)",
        "schema_too_large",
    )


def parse_channel(
    raw: object,
    out: list[Event],
    *,
    schemas: Mapping[int, tuple[str, str, str]],
    oversize: Mapping[int, int],
    max_schema_size: int,
) -> Channel:
    obj = as_object(raw, "a channel")
    cid = req_id(obj, "id")
    topic = req_str(obj, "topic")
    encoding = req_str(obj, "encoding")
    raw_schema_id = obj.get("schemaId")
    if raw_schema_id is not None:
        schema_id = as_id(raw_schema_id, "field 'schemaId'")
        entry = schemas.get(schema_id)
        if entry is not None:
            name, schema_encoding, data = entry
            schema_encoding = schema_encoding or DEFAULT_SCHEMA_ENCODINGS.get(encoding, "")
            size = oversize.get(schema_id)
            if size is not None:
                out.append(
                    schema_dropped(f"channel {cid} ({topic!r:.200})", name, size, max_schema_size)
                )
            return Channel(cid, topic, encoding, name, schema_encoding, data)
        out.append(
            ProtocolViolation(
                f"advertise: channel {cid} ({topic!r:.60}) references unknown schemaId {schema_id}"
            )
        )
    schema_name = opt_str(obj, "schemaName")
    schema = opt_str(obj, "schema")
    schema_encoding_opt = opt_str(obj, "schemaEncoding")
    if schema_name is None and schema is None and schema_encoding_opt is None:
        return Channel(cid, topic, encoding, "", "", "")
    if schema is not None and not schema_fits(schema, max_schema_size):
        out.append(
            schema_dropped(
                f"channel {cid} ({topic!r:.200})", schema_name, len(schema), max_schema_size
            )
        )
        schema = ""
    return Channel(
        cid,
        topic,
        encoding,
        schema_name or "",
        schema_encoding_opt or DEFAULT_SCHEMA_ENCODINGS.get(encoding, ""),
        schema or "",
    )


def parse_service(
    raw: object, out: list[Event], *, server_info: ServerInfo | None, max_schema_size: int
) -> ServiceDef:
    obj = as_object(raw, "a service")
    sid = req_id(obj, "id")
    name = req_str(obj, "name")
    stype = req_str(obj, "type")
    nested_request = obj.get("request")
    nested_response = obj.get("response")
    if nested_request is not None or nested_response is not None:
        request = nested_side(nested_request, "request")
        response = nested_side(nested_response, "response")
    else:
        ros1 = server_info is not None and "ros1" in server_info.supported_encodings
        schema_encoding = "ros1msg" if ros1 else "ros2msg"
        request = flat_side(
            obj.get("requestSchema"), f"{stype}_Request", schema_encoding, "requestSchema"
        )
        response = flat_side(
            obj.get("responseSchema"), f"{stype}_Response", schema_encoding, "responseSchema"
        )
    sides = []
    for side in (request, response):
        if side is not None and not schema_fits(side.schema, max_schema_size):
            out.append(
                schema_dropped(
                    f"service {sid} ({name!r:.200})",
                    side.schema_name,
                    len(side.schema),
                    max_schema_size,
                )
            )
            side = MessageSchema(side.encoding, side.schema_name, side.schema_encoding, "")
        sides.append(side)
    return ServiceDef(sid, name, stype, sides[0], sides[1])


def read_server_info(msg: dict[str, Any], out: list[Event]) -> ServerInfo:
    """The ``serverInfo`` as sent; a metadata entry that is not a string is dropped
    with a violation in ``out``. The engine then starts the new session."""
    name = opt_str(msg, "name") or ""
    capabilities = opt_str_tuple(msg, "capabilities")
    encodings = opt_str_tuple(msg, "supportedEncodings")
    raw_metadata = msg.get("metadata")
    metadata: dict[str, str] = {}
    if raw_metadata is not None:
        for key, value in as_object(raw_metadata, "field 'metadata'").items():
            if type(value) is str:
                metadata[key] = value
            else:
                out.append(
                    ProtocolViolation(f"serverInfo: metadata {key!r:.60} is not a string; dropped")
                )
    session_id = opt_request_id(msg, "sessionId")
    return ServerInfo(name, capabilities, encodings, metadata, session_id)


def read_status(msg: dict[str, Any], out: list[Event]) -> None:
    level = msg.get("level")
    if type(level) is not int:
        raise Malformed(f"field 'level' must be an integer, got {json_kind(level)}")
    out.append(Status(level, req_str(msg, "message"), opt_request_id(msg, "id")))


def read_remove_status(msg: dict[str, Any], out: list[Event]) -> None:
    ids = tuple(
        as_str(v, "an entry of 'statusIds'") if type(v) is not int else str(v)
        for v in req_list(msg, "statusIds")
    )
    out.append(RemoveStatus(ids))


def read_parameter_values(msg: dict[str, Any], out: list[Event]) -> None:
    raw_params = req_list(msg, "parameters")
    request_id = opt_request_id(msg, "id")
    params: list[Parameter] = []
    for raw in raw_params:
        try:
            params.append(parse_parameter(raw))
        except Malformed as exc:
            out.append(ProtocolViolation(f"parameterValues: parameter skipped: {exc}"))
    out.append(ParameterValues(tuple(params), request_id))


def read_connection_graph_update(msg: dict[str, Any], out: list[Event]) -> None:
    out.append(
        ConnectionGraphUpdate(
            opt_object_tuple(msg, "publishedTopics"),
            opt_object_tuple(msg, "subscribedTopics"),
            opt_object_tuple(msg, "advertisedServices"),
            opt_str_tuple(msg, "removedTopics"),
            opt_str_tuple(msg, "removedServices"),
        )
    )


def read_service_call_failure(msg: dict[str, Any], out: list[Event]) -> None:
    out.append(
        ServiceCallFailure(req_id(msg, "serviceId"), req_id(msg, "callId"), req_str(msg, "message"))
    )


# --------------------------------------------------------------------------
# Binary frames, after the opcode


def truncated(opcode: int, size: int, needed: int) -> ProtocolViolation:
    return ProtocolViolation(
        f"truncated {BINARY_NAMES[opcode]} frame (opcode 0x{opcode:02x}): "
        f"{size} bytes, the header needs {needed}"
    )


def read_service_call_response(view: memoryview, size: int) -> Event:
    start = 1 + SERVICE_RESPONSE_HEADER.size
    if size < start:
        return truncated(OP_SERVICE_CALL_RESPONSE, size, start)
    service_id, call_id, enc_len = SERVICE_RESPONSE_HEADER.unpack_from(view, 1)
    end = start + enc_len
    if end > size:
        return truncated(OP_SERVICE_CALL_RESPONSE, size, end)
    try:
        encoding = str(view[start:end], "utf-8")
    except UnicodeDecodeError:
        return ProtocolViolation(
            "service call response (opcode 0x03): encoding name is not valid UTF-8"
        )
    return ServiceCallResponse(service_id, call_id, encoding, view[end:])


def read_fetch_asset_response(view: memoryview, size: int) -> Event:
    start = 1 + FETCH_ASSET_HEADER.size
    if size < start:
        return truncated(OP_FETCH_ASSET_RESPONSE, size, start)
    request_id, status, err_len = FETCH_ASSET_HEADER.unpack_from(view, 1)
    if status > 1:
        return ProtocolViolation(
            f"fetch asset response (opcode 0x04): unknown status {status} for request {request_id}"
        )
    end = start + err_len
    if end > size:
        return truncated(OP_FETCH_ASSET_RESPONSE, size, end)
    try:
        error = str(view[start:end], "utf-8")
    except UnicodeDecodeError:
        return ProtocolViolation(
            "fetch asset response (opcode 0x04): error message is not valid UTF-8"
        )
    return FetchAssetResponse(request_id, status == 0, error, view[end:])


def read_playback_state(view: memoryview, size: int) -> Event:
    start = 1 + PLAYBACK_STATE_HEADER.size
    if size < start:
        return truncated(OP_PLAYBACK_STATE, size, start)
    status, time_ns, speed, did_seek, id_len = PLAYBACK_STATE_HEADER.unpack_from(view, 1)
    end = start + id_len
    if end > size:
        return truncated(OP_PLAYBACK_STATE, size, end)
    try:
        request_id = str(view[start:end], "utf-8")
    except UnicodeDecodeError:
        return ProtocolViolation("playback state (opcode 0x05): request id is not valid UTF-8")
    return PlaybackState(status, time_ns, speed, did_seek != 0, request_id)
