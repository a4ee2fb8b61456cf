"""A sans-IO engine for the Foxglove WebSocket protocol (client side).

No sockets, no event loop, no threads: the caller owns the WebSocket and

* feeds every text frame the server sends to :meth:`FoxgloveEngine.receive_text`
  and every binary frame to :meth:`FoxgloveEngine.receive_binary`; each returns
  a ``list`` of :class:`Event` objects (frozen dataclasses), possibly empty;
* calls the client-side methods (:meth:`~FoxgloveEngine.subscribe`,
  :meth:`~FoxgloveEngine.advertise`, :meth:`~FoxgloveEngine.message_data`, ...),
  which update the engine's state and *return* the message to send: a ``str``
  for the JSON operations (send it as a text frame) and ``bytes`` for the binary
  ones (send it as a binary frame).

Server input never makes the engine raise. Malformed JSON, an unknown ``op``,
wrong field types, a binary frame shorter than its header, data for a
subscription the client never made: each becomes a :class:`ProtocolViolation`
event and the engine carries on with the next frame. Input beyond the
engine's bounds (JSON nesting, channels and services kept, the size of one
schema text) is refused the same way, with a :attr:`ProtocolViolation.kind`
naming the bound. Bad *caller* arguments,
on the other hand, raise ``TypeError`` / ``ValueError`` at once.

The engine understands the three subprotocols in :data:`SUBPROTOCOLS`. The
parser is tolerant of all shapes whatever the negotiated subprotocol: channels
may carry a ``schemaId`` into the per-connection schema table
(``foxglove.sdk.v1.1``), inline ``schemaName`` / ``schema`` /
``schemaEncoding`` fields (``foxglove.websocket.v1`` and ``foxglove.sdk.v1``),
or both (the table entry wins).
"""

from __future__ import annotations

import base64
import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from struct import Struct
from types import MappingProxyType
from typing import Any, Final

from .._limits import json_too_deep
from .._slots import new_object, slot_setter

__all__ = [
    "DEFAULT_SCHEMA_ENCODINGS",
    "SUBPROTOCOLS",
    "Advertise",
    "AdvertiseServices",
    "Channel",
    "ConnectionGraphUpdate",
    "Event",
    "FetchAssetResponse",
    "FoxgloveEngine",
    "MessageData",
    "MessageSchema",
    "Parameter",
    "ParameterValues",
    "PlaybackState",
    "ProtocolViolation",
    "RemoveStatus",
    "ServerInfo",
    "ServiceCallFailure",
    "ServiceCallResponse",
    "ServiceDef",
    "Status",
    "Time",
    "Unadvertise",
    "UnadvertiseServices",
]

SUBPROTOCOLS: Final[tuple[str, ...]] = (
    "foxglove.sdk.v1.1",
    "foxglove.sdk.v1",
    "foxglove.websocket.v1",
)
"""The WebSocket subprotocols this engine speaks, newest first: offer them in
this order during the handshake and pass the negotiated one to
:class:`FoxgloveEngine`."""

DEFAULT_SCHEMA_ENCODINGS: Final[Mapping[str, str]] = MappingProxyType(
    {
        "cdr": "ros2msg",
        "protobuf": "protobuf",
        "json": "jsonschema",
        "ros1": "ros1msg",
        "flatbuffer": "flatbuffer",
    }
)
"""The schema encoding implied by a message encoding when a legacy channel
omits ``schemaEncoding``."""

_U32_MAX: Final = 0xFFFF_FFFF

# Binary opcodes, server -> client.
_OP_MESSAGE_DATA: Final = 0x01
_OP_TIME: Final = 0x02
_OP_SERVICE_CALL_RESPONSE: Final = 0x03
_OP_FETCH_ASSET_RESPONSE: Final = 0x04
_OP_PLAYBACK_STATE: Final = 0x05

# Binary opcodes, client -> server.
_OP_CLIENT_MESSAGE_DATA: Final = 0x01
_OP_SERVICE_CALL_REQUEST: Final = 0x02

# Headers, read after the 1-byte opcode (offset 1).
_MESSAGE_DATA_HEADER: Final = Struct("<IQ")  # subscription id, log time ns
_MESSAGE_DATA_PAYLOAD_AT: Final = 1 + _MESSAGE_DATA_HEADER.size  # 13
_TIME: Final = Struct("<Q")
_SERVICE_RESPONSE_HEADER: Final = Struct("<III")  # service id, call id, encoding length
_FETCH_ASSET_HEADER: Final = Struct("<IBI")  # request id, status, error length
# Written whole, opcode included.
_CLIENT_MESSAGE_HEADER: Final = Struct("<BI")
_SERVICE_REQUEST_HEADER: Final = Struct("<BIII")

_BINARY_NAMES: Final[Mapping[int, str]] = MappingProxyType(
    {
        _OP_MESSAGE_DATA: "message data",
        _OP_TIME: "time",
        _OP_SERVICE_CALL_RESPONSE: "service call response",
        _OP_FETCH_ASSET_RESPONSE: "fetch asset response",
        _OP_PLAYBACK_STATE: "playback state",
    }
)


# --------------------------------------------------------------------------
# Value types


@dataclass(frozen=True, slots=True)
class Channel:
    """A channel (topic) with its schema resolved.

    For a server channel, ``schema_name`` / ``schema_encoding`` / ``schema``
    come from the schema table (``foxglove.sdk.v1.1``) or the inline fields
    (legacy subprotocols); all three are ``""`` when the channel has no schema
    or references a schema the server never sent. ``schema`` is the text exactly
    as the server sent it: for binary schema encodings (``protobuf``,
    ``flatbuffer``) that is base64, which the caller decodes if it needs to.
    For a client channel (:meth:`FoxgloveEngine.advertise`) an omitted
    ``schema`` / ``schema_encoding`` is stored as ``""``.
    """

    id: int
    topic: str
    encoding: str
    schema_name: str
    schema_encoding: str
    schema: str


@dataclass(frozen=True, slots=True)
class MessageSchema:
    """One side (request or response) of a service: the message ``encoding``
    on the wire (``cdr``, ``json``, ...; ``""`` when the server did not say,
    which is the case for the old flat service shape: any of
    :attr:`ServerInfo.supported_encodings` may then be used) and the schema."""

    encoding: str
    schema_name: str
    schema_encoding: str
    schema: str


@dataclass(frozen=True, slots=True)
class ServiceDef:
    """A service the server advertises. ``request`` / ``response`` are ``None``
    when the server gave no schema for that side."""

    id: int
    name: str
    type: str
    request: MessageSchema | None
    response: MessageSchema | None


@dataclass(frozen=True, slots=True)
class Parameter:
    """A server parameter.

    ``value`` is ``None`` for an unset parameter, else a JSON value with these
    conversions: ``type="byte_array"`` -> ``bytes`` (base64 on the wire);
    ``type="float64"`` -> ``float`` even when the wire says ``2``;
    ``type="float64_array"`` -> ``list[float]``. Other values (``int``,
    ``bool``, ``str``, lists, nested ``dict``) are kept as parsed.
    """

    name: str
    value: object
    type: str | None = None


# --------------------------------------------------------------------------
# Events


@dataclass(frozen=True, slots=True)
class Event:
    """Base class of everything :meth:`FoxgloveEngine.receive_text` and
    :meth:`FoxgloveEngine.receive_binary` return."""


@dataclass(frozen=True, slots=True)
class ServerInfo(Event):
    """The server's ``serverInfo``. A second one starts a new session: the
    engine first forgets every channel, service and schema of the old one (and
    reports them with :class:`Unadvertise` / :class:`UnadvertiseServices`)."""

    name: str
    capabilities: tuple[str, ...]
    supported_encodings: tuple[str, ...]
    metadata: dict[str, str]
    session_id: str | None


@dataclass(frozen=True, slots=True)
class Status(Event):
    """A status message: ``level`` 0 info, 1 warning, 2 error."""

    level: int
    message: str
    id: str | None


@dataclass(frozen=True, slots=True)
class RemoveStatus(Event):
    """The server withdrew the statuses with these ids."""

    ids: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Advertise(Event):
    """Channels advertised (or re-advertised) by one ``advertise`` message."""

    channels: tuple[Channel, ...]


@dataclass(frozen=True, slots=True)
class Unadvertise(Event):
    """Channels that are gone, as they were when advertised."""

    channels: tuple[Channel, ...]


@dataclass(frozen=True, slots=True)
class AdvertiseServices(Event):
    """Services advertised (or re-advertised) by one ``advertiseServices`` message."""

    services: tuple[ServiceDef, ...]


@dataclass(frozen=True, slots=True)
class UnadvertiseServices(Event):
    """Services that are gone, as they were when advertised."""

    services: tuple[ServiceDef, ...]


@dataclass(frozen=True, slots=True)
class ParameterValues(Event):
    """Parameter values, in answer to ``getParameters`` / ``setParameters``
    (``id`` is the request id, or ``None``) or as a subscribed update."""

    parameters: tuple[Parameter, ...]
    id: str | None


@dataclass(frozen=True, slots=True)
class ConnectionGraphUpdate(Event):
    """A connection graph update, kept as parsed: the ``*_topics`` entries are
    ``{"name": ..., "publisherIds"/"subscriberIds": [...]}`` and the
    ``advertised_services`` entries ``{"name": ..., "providerIds": [...]}``."""

    published_topics: tuple[dict[str, Any], ...]
    subscribed_topics: tuple[dict[str, Any], ...]
    advertised_services: tuple[dict[str, Any], ...]
    removed_topics: tuple[str, ...]
    removed_services: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class ServiceCallFailure(Event):
    """The server could not serve call ``call_id`` of service ``service_id``."""

    service_id: int
    call_id: int
    message: str


@dataclass(frozen=True, slots=True)
class MessageData(Event):
    """A message on one of the client's subscriptions.

    ``channel`` is the channel the subscription was bound to when the frame
    arrived (still given after the server unadvertised it). ``payload`` is a
    zero-copy ``memoryview`` slice of the received frame: it keeps the frame
    alive, and it changes if the caller mutates a ``bytearray`` it passed in.
    """

    subscription_id: int
    channel: Channel
    log_time_ns: int
    payload: memoryview


_set_md_subscription_id = slot_setter(MessageData, "subscription_id")
_set_md_channel = slot_setter(MessageData, "channel")
_set_md_log_time_ns = slot_setter(MessageData, "log_time_ns")
_set_md_payload = slot_setter(MessageData, "payload")


def _message_data(
    subscription_id: int, channel: Channel, log_time_ns: int, payload: memoryview
) -> MessageData:
    """``MessageData(...)`` for the hot path, built through its slots (see
    ``_slots``): once per received message."""
    event: MessageData = new_object(MessageData)
    _set_md_subscription_id(event, subscription_id)
    _set_md_channel(event, channel)
    _set_md_log_time_ns(event, log_time_ns)
    _set_md_payload(event, payload)
    return event


@dataclass(frozen=True, slots=True)
class Time(Event):
    """The server's clock (``time`` capability), in nanoseconds."""

    timestamp_ns: int


@dataclass(frozen=True, slots=True)
class ServiceCallResponse(Event):
    """The response to service call ``call_id``; ``payload`` is a zero-copy
    ``memoryview`` slice of the received frame."""

    service_id: int
    call_id: int
    encoding: str
    payload: memoryview


@dataclass(frozen=True, slots=True)
class FetchAssetResponse(Event):
    """The answer to :meth:`FoxgloveEngine.fetch_asset`: when ``ok``, ``data``
    (a zero-copy ``memoryview``) holds the asset; otherwise ``error`` says why."""

    request_id: int
    ok: bool
    error: str
    data: memoryview


@dataclass(frozen=True, slots=True)
class PlaybackState(Event):
    """A playback-state frame (``foxglove.sdk``): the bytes after the opcode,
    undecoded."""

    raw: bytes


@dataclass(frozen=True, slots=True)
class ProtocolViolation(Event):
    """The server sent something the engine could not use; ``reason`` says what.
    The engine ignored (that part of) the frame and carries on.

    ``kind`` classifies it: ``"invalid_utf8"``, ``"json_depth"``,
    ``"schema_too_large"`` (the schema text was dropped, the channel or
    service kept), ``"channel_limit"``, ``"service_limit"`` (one event per
    message, however many were refused), else ``"malformed"``."""

    reason: str
    kind: str = "malformed"


# --------------------------------------------------------------------------
# Parsing helpers: raise _Malformed, which the engine turns into a violation.


class _Malformed(Exception):
    """Raised inside the parser for one malformed message or item."""


def _kind(value: object) -> str:
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


def _as_id(value: object, what: str) -> int:
    if type(value) is not int or value < 0:
        raise _Malformed(f"{what} must be a non-negative integer, got {_kind(value)} {value!r:.40}")
    return value


def _as_str(value: object, what: str) -> str:
    if type(value) is not str:
        raise _Malformed(f"{what} must be a string, got {_kind(value)}")
    return value


def _as_object(value: object, what: str) -> dict[str, Any]:
    if type(value) is not dict:
        raise _Malformed(f"{what} must be an object, got {_kind(value)}")
    return value


def _req_id(obj: dict[str, Any], key: str) -> int:
    if key not in obj:
        raise _Malformed(f"missing field {key!r}")
    return _as_id(obj[key], f"field {key!r}")


def _req_str(obj: dict[str, Any], key: str) -> str:
    if key not in obj:
        raise _Malformed(f"missing field {key!r}")
    return _as_str(obj[key], f"field {key!r}")


def _opt_str(obj: dict[str, Any], key: str) -> str | None:
    value = obj.get(key)
    if value is None:
        return None
    return _as_str(value, f"field {key!r}")


def _opt_request_id(obj: dict[str, Any], key: str) -> str | None:
    """A string id that may be absent or null; an integer is taken as its text."""
    value = obj.get(key)
    if value is None or type(value) is str:
        return value
    if type(value) is int:
        return str(value)
    raise _Malformed(f"field {key!r} must be a string or null, got {_kind(value)}")


def _req_list(obj: dict[str, Any], key: str) -> list[Any]:
    if key not in obj:
        raise _Malformed(f"missing field {key!r}")
    value = obj[key]
    if type(value) is not list:
        raise _Malformed(f"field {key!r} must be an array, got {_kind(value)}")
    return value


def _opt_list(obj: dict[str, Any], key: str) -> list[Any]:
    value = obj.get(key)
    if value is None:
        return []
    if type(value) is not list:
        raise _Malformed(f"field {key!r} must be an array, got {_kind(value)}")
    return value


def _opt_str_tuple(obj: dict[str, Any], key: str) -> tuple[str, ...]:
    return tuple(_as_str(v, f"an entry of {key!r}") for v in _opt_list(obj, key))


def _opt_object_tuple(obj: dict[str, Any], key: str) -> tuple[dict[str, Any], ...]:
    return tuple(_as_object(v, f"an entry of {key!r}") for v in _opt_list(obj, key))


def _as_float(value: object, what: str) -> float:
    if type(value) is float:
        return value
    if type(value) is int:
        try:
            return float(value)
        except OverflowError:
            raise _Malformed(f"{what} is out of float64 range") from None
    raise _Malformed(f"{what} must be a number, got {_kind(value)}")


def _parse_parameter(raw: object) -> Parameter:
    obj = _as_object(raw, "a parameter")
    name = _req_str(obj, "name")
    ptype = _opt_str(obj, "type")
    value = obj.get("value")
    if value is None:
        return Parameter(name, None, ptype)
    if ptype == "byte_array":
        if type(value) is not str:
            raise _Malformed(f"parameter {name!r}: byte_array value must be a base64 string")
        try:
            value = base64.b64decode(value, validate=True)
        except ValueError:
            raise _Malformed(f"parameter {name!r}: byte_array value is not valid base64") from None
    elif ptype == "float64":
        value = _as_float(value, f"parameter {name!r}: float64 value")
    elif ptype == "float64_array":
        if type(value) is not list:
            raise _Malformed(f"parameter {name!r}: float64_array value must be an array")
        value = [_as_float(v, f"parameter {name!r}: float64_array entry") for v in value]
    return Parameter(name, value, ptype)


def _flat_side(
    raw: object, schema_name: str, schema_encoding: str, key: str
) -> MessageSchema | None:
    if raw is None:
        return None
    return MessageSchema("", schema_name, schema_encoding, _as_str(raw, f"field {key!r}"))


def _nested_side(raw: object, key: str) -> MessageSchema | None:
    if raw is None:
        return None
    obj = _as_object(raw, f"field {key!r}")
    encoding = _req_str(obj, "encoding")
    schema_name = _req_str(obj, "schemaName")
    schema_encoding = _opt_str(obj, "schemaEncoding") or DEFAULT_SCHEMA_ENCODINGS.get(encoding, "")
    schema = _opt_str(obj, "schema") or ""
    return MessageSchema(encoding, schema_name, schema_encoding, schema)


# --------------------------------------------------------------------------
# Argument checks for the client-side methods (raise at once).


def _check_id(value: object, what: str, *, u32: bool = False) -> int:
    if type(value) is not int:
        raise TypeError(f"{what} must be an int, got {type(value).__name__}")
    if value < 0:
        raise ValueError(f"{what} must be non-negative, got {value}")
    if u32 and value > _U32_MAX:
        raise ValueError(f"{what} must fit in 32 bits, got {value}")
    return value


def _check_str(value: object, what: str, *, nonempty: bool = False) -> str:
    if not isinstance(value, str):
        raise TypeError(f"{what} must be a str, got {type(value).__name__}")
    if nonempty and not value:
        raise ValueError(f"{what} must not be empty")
    return value


def _check_ids(values: Iterable[int], what: str, *, u32: bool = False) -> list[int]:
    if isinstance(values, (str, bytes, bytearray, memoryview)) or not isinstance(values, Iterable):
        raise TypeError(f"{what} must be an iterable of ints, got {type(values).__name__}")
    ids = [_check_id(v, f"each of {what}", u32=u32) for v in values]
    return list(dict.fromkeys(ids))  # de-duplicated, order kept


def _check_names(names: Sequence[str], what: str) -> list[str]:
    if isinstance(names, (str, bytes, bytearray)) or not isinstance(names, Iterable):
        raise TypeError(f"{what} must be a sequence of str, got {type(names).__name__}")
    return [_check_str(n, f"each of {what}") for n in names]


def _check_payload(payload: object) -> None:
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise TypeError(f"payload must be bytes-like, got {type(payload).__name__}")


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _float_arg(value: object, what: str) -> float:
    if not _is_number(value):
        raise TypeError(f"{what} must be a float, got {type(value).__name__}")
    try:
        return float(value)  # type: ignore[arg-type]
    except OverflowError:
        raise ValueError(f"{what} is out of float64 range") from None


def _encode_parameter(param: Parameter) -> dict[str, object]:
    if not isinstance(param, Parameter):
        raise TypeError(f"parameters must be Parameter instances, got {type(param).__name__}")
    name = _check_str(param.name, "Parameter.name")
    ptype = param.type
    if ptype is not None:
        _check_str(ptype, "Parameter.type")
    value = param.value
    out: dict[str, object] = {"name": name}
    if value is None:  # unset the parameter
        return out
    if ptype is None:
        if isinstance(value, (bytes, bytearray, memoryview)):
            ptype = "byte_array"
        elif isinstance(value, float):
            ptype = "float64"
        elif (
            isinstance(value, (list, tuple))
            and any(isinstance(v, float) for v in value)
            and all(_is_number(v) for v in value)
        ):
            ptype = "float64_array"
    if ptype == "byte_array":
        if not isinstance(value, (bytes, bytearray, memoryview)):
            raise TypeError(f"parameter {name!r}: a byte_array value must be bytes-like")
        out["value"] = base64.b64encode(value).decode("ascii")
    elif ptype == "float64":
        out["value"] = _float_arg(value, f"parameter {name!r}")
    elif ptype == "float64_array":
        if not isinstance(value, (list, tuple)):
            raise TypeError(f"parameter {name!r}: a float64_array value must be a list")
        out["value"] = [_float_arg(v, f"an entry of parameter {name!r}") for v in value]
    else:
        out["value"] = value
    if ptype is not None:
        out["type"] = ptype
    return out


def _dumps(obj: object) -> str:
    """Compact JSON; NaN / infinity and unserialisable values raise ValueError / TypeError."""
    return json.dumps(obj, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


# --------------------------------------------------------------------------
# The engine

_Handler = Callable[[dict[str, Any], list[Event]], None]


class FoxgloveEngine:
    """The client side of one Foxglove WebSocket connection, without the I/O.

    Construct it with the subprotocol the handshake negotiated (one of
    :data:`SUBPROTOCOLS`, else ``ValueError``). Use one engine per connection:
    after a reconnect, start a new one.

    State, all read-only views that follow the engine:

    * :attr:`server_info` - the last :class:`ServerInfo`, or ``None``;
    * :attr:`channels` - the server channels currently advertised, by id;
    * :attr:`services` - the server services currently advertised, by id;
    * :attr:`subscriptions` - the client's live subscriptions, by subscription
      id, each with the channel it is bound to;
    * :attr:`client_channels` - the client's own advertised channels, by id.

    Subscription ids and client channel ids are allocated by the engine, start
    at 1 and are never reused on one engine.
    """

    __slots__ = (
        "_channels",
        "_client_channels",
        "_next_client_channel_id",
        "_next_sub_id",
        "_oversize",
        "_schemas",
        "_services",
        "_sub_by_channel",
        "_subs",
        "_text_handlers",
        "max_channels",
        "max_json_depth",
        "max_schema_size",
        "max_services",
        "server_info",
        "subprotocol",
    )

    def __init__(
        self,
        subprotocol: str,
        *,
        max_channels: int = 10_000,
        max_services: int = 10_000,
        max_schema_size: int = 256 * 1024,
        max_json_depth: int = 100,
    ) -> None:
        if not isinstance(subprotocol, str):
            raise TypeError(f"subprotocol must be a str, got {type(subprotocol).__name__}")
        if subprotocol not in SUBPROTOCOLS:
            raise ValueError(
                f"unknown Foxglove subprotocol {subprotocol!r}; expected one of {SUBPROTOCOLS}"
            )
        self.subprotocol: str = subprotocol
        """The negotiated subprotocol."""
        for name, value in (
            ("max_channels", max_channels),
            ("max_services", max_services),
            ("max_schema_size", max_schema_size),
            ("max_json_depth", max_json_depth),
        ):
            if type(value) is not int or value < 1:
                raise ValueError(f"{name} must be a positive int, got {value!r}")
        self.max_channels = max_channels
        """Server channels kept at once; more are refused (``"channel_limit"``)."""
        self.max_services = max_services
        """Server services kept at once; more are refused (``"service_limit"``)."""
        self.max_schema_size = max_schema_size
        """Bytes of one schema text; a longer one is dropped (``"schema_too_large"``)."""
        self.max_json_depth = max_json_depth
        """Deepest JSON nesting read; a deeper text frame is skipped (``"json_depth"``)."""
        # schema id -> size of a schema text dropped for its size
        self._oversize: dict[int, int] = {}
        self.server_info: ServerInfo | None = None
        """The last ``serverInfo`` the server sent, or ``None`` before the first."""
        self._schemas: dict[int, tuple[str, str, str]] = {}  # id -> (name, encoding, data)
        self._channels: dict[int, Channel] = {}
        self._services: dict[int, ServiceDef] = {}
        self._subs: dict[int, Channel] = {}
        # channel id -> the live subscription the server still routes for it
        self._sub_by_channel: dict[int, int] = {}
        self._next_sub_id = 1
        self._client_channels: dict[int, Channel] = {}
        self._next_client_channel_id = 1
        self._text_handlers: dict[str, _Handler] = {
            "serverInfo": self._on_server_info,
            "status": self._on_status,
            "removeStatus": self._on_remove_status,
            "advertise": self._on_advertise,
            "unadvertise": self._on_unadvertise,
            "advertiseServices": self._on_advertise_services,
            "unadvertiseServices": self._on_unadvertise_services,
            "parameterValues": self._on_parameter_values,
            "connectionGraphUpdate": self._on_connection_graph_update,
            "serviceCallFailure": self._on_service_call_failure,
        }

    # -- state views --------------------------------------------------------

    @property
    def channels(self) -> Mapping[int, Channel]:
        """The server's currently advertised channels, by channel id (live view)."""
        return MappingProxyType(self._channels)

    @property
    def services(self) -> Mapping[int, ServiceDef]:
        """The server's currently advertised services, by service id (live view)."""
        return MappingProxyType(self._services)

    @property
    def subscriptions(self) -> Mapping[int, Channel]:
        """The client's subscriptions, by subscription id, with their bound channel (live view)."""
        return MappingProxyType(self._subs)

    @property
    def client_channels(self) -> Mapping[int, Channel]:
        """The client's own advertised channels, by client channel id (live view)."""
        return MappingProxyType(self._client_channels)

    def subscription_channel(self, sub_id: int) -> Channel | None:
        """The channel subscription ``sub_id`` is bound to, or ``None`` if it is
        not a live subscription."""
        return self._subs.get(sub_id)

    # -- server -> client: text ---------------------------------------------

    def receive_text(self, text: str | bytes | bytearray | memoryview) -> list[Event]:
        """Parse one text frame from the server.

        Returns the resulting events in order (:class:`ProtocolViolation` events
        for the parts that were unusable come before the event for the rest).
        Never raises for any ``str`` or bytes-like input; ``bytes`` must be UTF-8.
        """
        if isinstance(text, (bytes, bytearray, memoryview)):
            try:
                text = bytes(text).decode("utf-8")
            except UnicodeDecodeError as exc:
                return [ProtocolViolation(f"text frame is not valid UTF-8: {exc}", "invalid_utf8")]
        elif not isinstance(text, str):
            raise TypeError(f"text must be str or bytes, got {type(text).__name__}")
        if json_too_deep(text, self.max_json_depth):
            return [self._too_deep(len(text))]
        try:
            msg = json.loads(text)
        except RecursionError:
            return [self._too_deep(len(text))]
        except ValueError as exc:
            return [ProtocolViolation(f"text frame is not valid JSON: {exc}")]
        if type(msg) is not dict:
            return [ProtocolViolation(f"text frame is a JSON {_kind(msg)}, not an object")]
        op = msg.get("op")
        if type(op) is not str:
            return [ProtocolViolation("text frame has no string 'op' field")]
        handler = self._text_handlers.get(op)
        if handler is None:
            return [ProtocolViolation(f"unknown op {op!r:.60}")]
        out: list[Event] = []
        try:
            handler(msg, out)
        except _Malformed as exc:
            out.append(ProtocolViolation(f"{op}: {exc}"))
        except Exception as exc:  # the contract: server input never raises
            out.append(ProtocolViolation(f"{op}: internal error: {exc!r}"))
        return out

    def _too_deep(self, size: int) -> ProtocolViolation:
        return ProtocolViolation(
            f"a text frame of {size} characters nests deeper than {self.max_json_depth}; skipped",
            "json_depth",
        )

    def _schema_fits(self, data: str) -> bool:
        limit = self.max_schema_size
        size = len(data)
        return size <= limit and (
            size * 4 <= limit or len(data.encode("utf-8", "replace")) <= limit
        )

    def _on_server_info(self, msg: dict[str, Any], out: list[Event]) -> None:
        name = _opt_str(msg, "name") or ""
        capabilities = _opt_str_tuple(msg, "capabilities")
        encodings = _opt_str_tuple(msg, "supportedEncodings")
        raw_metadata = msg.get("metadata")
        metadata: dict[str, str] = {}
        if raw_metadata is not None:
            for key, value in _as_object(raw_metadata, "field 'metadata'").items():
                if type(value) is str:
                    metadata[key] = value
                else:
                    out.append(
                        ProtocolViolation(
                            f"serverInfo: metadata {key!r:.60} is not a string; dropped"
                        )
                    )
        session_id = _opt_request_id(msg, "sessionId")
        # A (new) session: nothing of the previous one survives.
        if self._channels:
            out.append(Unadvertise(tuple(self._channels.values())))
            self._channels.clear()
        if self._services:
            out.append(UnadvertiseServices(tuple(self._services.values())))
            self._services.clear()
        self._schemas.clear()
        self._oversize.clear()
        self._sub_by_channel.clear()
        info = ServerInfo(name, capabilities, encodings, metadata, session_id)
        self.server_info = info
        out.append(info)

    def _on_status(self, msg: dict[str, Any], out: list[Event]) -> None:
        level = msg.get("level")
        if type(level) is not int:
            raise _Malformed(f"field 'level' must be an integer, got {_kind(level)}")
        out.append(Status(level, _req_str(msg, "message"), _opt_request_id(msg, "id")))

    def _on_remove_status(self, msg: dict[str, Any], out: list[Event]) -> None:
        ids = tuple(
            _as_str(v, "an entry of 'statusIds'") if type(v) is not int else str(v)
            for v in _req_list(msg, "statusIds")
        )
        out.append(RemoveStatus(ids))

    def _on_advertise(self, msg: dict[str, Any], out: list[Event]) -> None:
        schemas = _opt_list(msg, "schemas")
        channels = _opt_list(msg, "channels") if schemas else _req_list(msg, "channels")
        refused = 0
        for raw in schemas:
            try:
                obj = _as_object(raw, "a schema")
                sid = _req_id(obj, "id")
                entry = (_req_str(obj, "name"), _req_str(obj, "encoding"), _req_str(obj, "data"))
            except _Malformed as exc:
                out.append(ProtocolViolation(f"advertise: schema skipped: {exc}"))
                continue
            if sid not in self._schemas and len(self._schemas) >= self.max_channels:
                refused += 1  # the table is bounded like the channels using it
                continue
            if self._schema_fits(entry[2]):
                self._oversize.pop(sid, None)
            else:  # kept without its text; the channel using it is reported
                self._oversize[sid] = len(entry[2])
                entry = (entry[0], entry[1], "")
            self._schemas[sid] = entry
        advertised: list[Channel] = []
        for raw in channels:
            try:
                channel = self._parse_channel(raw, out)
            except _Malformed as exc:
                out.append(ProtocolViolation(f"advertise: channel skipped: {exc}"))
                continue
            old = self._channels.get(channel.id)
            if old is None and len(self._channels) >= self.max_channels:
                refused += 1
                continue
            self._channels[channel.id] = channel
            if old is not None:
                # Re-advertised while live: subscriptions follow the new definition.
                for sub_id, bound in self._subs.items():
                    if bound is old:
                        self._subs[sub_id] = channel
            advertised.append(channel)
        if refused:
            out.append(
                ProtocolViolation(
                    f"advertise: {refused} channels or schemas refused: the connection keeps "
                    f"at most {self.max_channels}",
                    "channel_limit",
                )
            )
        if advertised:
            out.append(Advertise(tuple(advertised)))

    def _parse_channel(self, raw: object, out: list[Event]) -> Channel:
        obj = _as_object(raw, "a channel")
        cid = _req_id(obj, "id")
        topic = _req_str(obj, "topic")
        encoding = _req_str(obj, "encoding")
        raw_schema_id = obj.get("schemaId")
        if raw_schema_id is not None:
            schema_id = _as_id(raw_schema_id, "field 'schemaId'")
            entry = self._schemas.get(schema_id)
            if entry is not None:
                name, schema_encoding, data = entry
                schema_encoding = schema_encoding or DEFAULT_SCHEMA_ENCODINGS.get(encoding, "")
                size = self._oversize.get(schema_id)
                if size is not None:
                    out.append(self._schema_dropped(f"channel {cid} ({topic!r:.200})", name, size))
                return Channel(cid, topic, encoding, name, schema_encoding, data)
            out.append(
                ProtocolViolation(
                    f"advertise: channel {cid} ({topic!r:.60}) references unknown schemaId {schema_id}"
                )
            )
        schema_name = _opt_str(obj, "schemaName")
        schema = _opt_str(obj, "schema")
        schema_encoding_opt = _opt_str(obj, "schemaEncoding")
        if schema_name is None and schema is None and schema_encoding_opt is None:
            return Channel(cid, topic, encoding, "", "", "")
        if schema is not None and not self._schema_fits(schema):
            out.append(
                self._schema_dropped(f"channel {cid} ({topic!r:.200})", schema_name, len(schema))
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

    def _schema_dropped(self, what: str, schema_name: str | None, size: int) -> ProtocolViolation:
        return ProtocolViolation(
            f"advertise: {what}: the schema {schema_name or ''!r:.200} of {size} characters is over "
            f"{self.max_schema_size} bytes; dropped (messages decode with a bundled definition "
            "of the type, if any, else arrive raw)",
            "schema_too_large",
        )

    def _on_unadvertise(self, msg: dict[str, Any], out: list[Event]) -> None:
        removed: list[Channel] = []
        for raw in _req_list(msg, "channelIds"):
            if type(raw) is not int:
                out.append(
                    ProtocolViolation(f"unadvertise: channel id {raw!r:.40} is not an integer")
                )
                continue
            channel = self._channels.pop(raw, None)
            if channel is None:
                out.append(ProtocolViolation(f"unadvertise: unknown channel id {raw}"))
            else:
                self._sub_by_channel.pop(raw, None)
                removed.append(channel)
        if removed:
            out.append(Unadvertise(tuple(removed)))

    def _on_advertise_services(self, msg: dict[str, Any], out: list[Event]) -> None:
        advertised: list[ServiceDef] = []
        refused = 0
        for raw in _req_list(msg, "services"):
            try:
                service = self._parse_service(raw, out)
            except _Malformed as exc:
                out.append(ProtocolViolation(f"advertiseServices: service skipped: {exc}"))
                continue
            if service.id not in self._services and len(self._services) >= self.max_services:
                refused += 1
                continue
            self._services[service.id] = service
            advertised.append(service)
        if refused:
            out.append(
                ProtocolViolation(
                    f"advertiseServices: {refused} services refused: the connection keeps at "
                    f"most {self.max_services}",
                    "service_limit",
                )
            )
        if advertised:
            out.append(AdvertiseServices(tuple(advertised)))

    def _parse_service(self, raw: object, out: list[Event]) -> ServiceDef:
        obj = _as_object(raw, "a service")
        sid = _req_id(obj, "id")
        name = _req_str(obj, "name")
        stype = _req_str(obj, "type")
        nested_request = obj.get("request")
        nested_response = obj.get("response")
        if nested_request is not None or nested_response is not None:
            request = _nested_side(nested_request, "request")
            response = _nested_side(nested_response, "response")
        else:
            info = self.server_info
            ros1 = info is not None and "ros1" in info.supported_encodings
            schema_encoding = "ros1msg" if ros1 else "ros2msg"
            request = _flat_side(
                obj.get("requestSchema"), f"{stype}_Request", schema_encoding, "requestSchema"
            )
            response = _flat_side(
                obj.get("responseSchema"), f"{stype}_Response", schema_encoding, "responseSchema"
            )
        sides = []
        for side in (request, response):
            if side is not None and not self._schema_fits(side.schema):
                out.append(
                    self._schema_dropped(
                        f"service {sid} ({name!r:.200})", side.schema_name, len(side.schema)
                    )
                )
                side = MessageSchema(side.encoding, side.schema_name, side.schema_encoding, "")
            sides.append(side)
        return ServiceDef(sid, name, stype, sides[0], sides[1])

    def _on_unadvertise_services(self, msg: dict[str, Any], out: list[Event]) -> None:
        removed: list[ServiceDef] = []
        for raw in _req_list(msg, "serviceIds"):
            if type(raw) is not int:
                out.append(
                    ProtocolViolation(
                        f"unadvertiseServices: service id {raw!r:.40} is not an integer"
                    )
                )
                continue
            service = self._services.pop(raw, None)
            if service is None:
                out.append(ProtocolViolation(f"unadvertiseServices: unknown service id {raw}"))
            else:
                removed.append(service)
        if removed:
            out.append(UnadvertiseServices(tuple(removed)))

    def _on_parameter_values(self, msg: dict[str, Any], out: list[Event]) -> None:
        raw_params = _req_list(msg, "parameters")
        request_id = _opt_request_id(msg, "id")
        params: list[Parameter] = []
        for raw in raw_params:
            try:
                params.append(_parse_parameter(raw))
            except _Malformed as exc:
                out.append(ProtocolViolation(f"parameterValues: parameter skipped: {exc}"))
        out.append(ParameterValues(tuple(params), request_id))

    def _on_connection_graph_update(self, msg: dict[str, Any], out: list[Event]) -> None:
        out.append(
            ConnectionGraphUpdate(
                _opt_object_tuple(msg, "publishedTopics"),
                _opt_object_tuple(msg, "subscribedTopics"),
                _opt_object_tuple(msg, "advertisedServices"),
                _opt_str_tuple(msg, "removedTopics"),
                _opt_str_tuple(msg, "removedServices"),
            )
        )

    def _on_service_call_failure(self, msg: dict[str, Any], out: list[Event]) -> None:
        out.append(
            ServiceCallFailure(
                _req_id(msg, "serviceId"), _req_id(msg, "callId"), _req_str(msg, "message")
            )
        )

    # -- server -> client: binary -------------------------------------------

    def receive_binary(self, data: bytes | bytearray | memoryview) -> list[Event]:
        """Parse one binary frame from the server.

        Payloads in the returned events are zero-copy ``memoryview`` slices of
        ``data``. Never raises for any bytes-like input.

        Data for a subscription the client has already unsubscribed (it may
        still be in flight) is dropped silently; data for a subscription id the
        engine never allocated is a :class:`ProtocolViolation`.
        """
        view = data if isinstance(data, memoryview) else memoryview(data)
        if view.format != "B" or view.ndim != 1 or not view.c_contiguous:
            view = view.cast("B") if view.c_contiguous else memoryview(view.tobytes())
        size = len(view)
        if not size:
            return [ProtocolViolation("empty binary frame")]
        opcode = view[0]
        try:
            if opcode == _OP_MESSAGE_DATA:  # the hot path
                if size < _MESSAGE_DATA_PAYLOAD_AT:
                    return [self._truncated(opcode, size, _MESSAGE_DATA_PAYLOAD_AT)]
                sub_id, log_time = _MESSAGE_DATA_HEADER.unpack_from(view, 1)
                channel = self._subs.get(sub_id)
                if channel is None:
                    if 0 < sub_id < self._next_sub_id:
                        return []  # unsubscribed; a late frame
                    return [ProtocolViolation(f"message data for unknown subscription id {sub_id}")]
                return [_message_data(sub_id, channel, log_time, view[_MESSAGE_DATA_PAYLOAD_AT:])]
            if opcode == _OP_TIME:
                if size < 1 + _TIME.size:
                    return [self._truncated(opcode, size, 1 + _TIME.size)]
                return [Time(_TIME.unpack_from(view, 1)[0])]
            if opcode == _OP_SERVICE_CALL_RESPONSE:
                return [self._service_call_response(view, size)]
            if opcode == _OP_FETCH_ASSET_RESPONSE:
                return [self._fetch_asset_response(view, size)]
            if opcode == _OP_PLAYBACK_STATE:
                return [PlaybackState(view[1:].tobytes())]
        except Exception as exc:  # the contract: server input never raises
            return [ProtocolViolation(f"binary opcode 0x{opcode:02x}: internal error: {exc!r}")]
        return [ProtocolViolation(f"unknown binary opcode 0x{opcode:02x}")]

    @staticmethod
    def _truncated(opcode: int, size: int, needed: int) -> ProtocolViolation:
        return ProtocolViolation(
            f"truncated {_BINARY_NAMES[opcode]} frame (opcode 0x{opcode:02x}): "
            f"{size} bytes, the header needs {needed}"
        )

    def _service_call_response(self, view: memoryview, size: int) -> Event:
        start = 1 + _SERVICE_RESPONSE_HEADER.size
        if size < start:
            return self._truncated(_OP_SERVICE_CALL_RESPONSE, size, start)
        service_id, call_id, enc_len = _SERVICE_RESPONSE_HEADER.unpack_from(view, 1)
        end = start + enc_len
        if end > size:
            return self._truncated(_OP_SERVICE_CALL_RESPONSE, size, end)
        try:
            encoding = str(view[start:end], "utf-8")
        except UnicodeDecodeError:
            return ProtocolViolation(
                "service call response (opcode 0x03): encoding name is not valid UTF-8"
            )
        return ServiceCallResponse(service_id, call_id, encoding, view[end:])

    def _fetch_asset_response(self, view: memoryview, size: int) -> Event:
        start = 1 + _FETCH_ASSET_HEADER.size
        if size < start:
            return self._truncated(_OP_FETCH_ASSET_RESPONSE, size, start)
        request_id, status, err_len = _FETCH_ASSET_HEADER.unpack_from(view, 1)
        if status > 1:
            return ProtocolViolation(
                f"fetch asset response (opcode 0x04): unknown status {status} "
                f"for request {request_id}"
            )
        end = start + err_len
        if end > size:
            return self._truncated(_OP_FETCH_ASSET_RESPONSE, size, end)
        try:
            error = str(view[start:end], "utf-8")
        except UnicodeDecodeError:
            return ProtocolViolation(
                "fetch asset response (opcode 0x04): error message is not valid UTF-8"
            )
        return FetchAssetResponse(request_id, status == 0, error, view[end:])

    # -- client -> server ---------------------------------------------------

    def subscribe(self, channel_id: int) -> tuple[int, str]:
        """Subscribe to the advertised server channel ``channel_id``.

        Returns ``(subscription_id, json_text)``. The subscription stays bound to
        the channel as it is now (re-advertising the live id updates it) until
        :meth:`unsubscribe`, even if the server unadvertises the channel.
        ``ValueError`` if the channel is not currently advertised or already has
        a live subscription.
        """
        sub_ids, text = self.subscribe_many((channel_id,))
        return sub_ids[0], text

    def subscribe_many(self, channel_ids: Iterable[int]) -> tuple[tuple[int, ...], str]:
        """Subscribe to several advertised channels with one message. Returns the
        new subscription ids (in the order given) and the JSON text.

        All-or-nothing: ``TypeError`` / ``ValueError`` before any subscription is
        made if an id is not an int, not advertised, given twice, or already has
        a live subscription (the server ignores a second subscription to one
        channel)."""
        channels: list[Channel] = []
        seen: set[int] = set()
        for channel_id in channel_ids:
            _check_id(channel_id, "channel_id")
            channel = self._channels.get(channel_id)
            if channel is None:
                raise ValueError(f"channel {channel_id} is not advertised by the server")
            existing = self._sub_by_channel.get(channel_id)
            if existing is not None:
                raise ValueError(
                    f"channel {channel_id} already has subscription {existing}; "
                    "the server ignores a second one"
                )
            if channel_id in seen:
                raise ValueError(f"channel {channel_id} given twice")
            seen.add(channel_id)
            channels.append(channel)
        if not channels:
            raise ValueError("no channel ids given")
        first = self._next_sub_id
        if first + len(channels) - 1 > _U32_MAX:
            raise OverflowError("subscription ids exhausted for this connection")
        self._next_sub_id = first + len(channels)
        subscriptions = []
        for sub_id, channel in enumerate(channels, first):
            self._subs[sub_id] = channel
            self._sub_by_channel[channel.id] = sub_id
            subscriptions.append({"id": sub_id, "channelId": channel.id})
        text = _dumps({"op": "subscribe", "subscriptions": subscriptions})
        return tuple(range(first, first + len(channels))), text

    def unsubscribe(self, subscription_ids: Iterable[int]) -> str:
        """Forget these subscriptions and return the ``unsubscribe`` JSON.
        Ids that are not live are still sent (the server decides) but change
        nothing here."""
        ids = _check_ids(subscription_ids, "subscription_ids")
        for sub_id in ids:
            channel = self._subs.pop(sub_id, None)
            if channel is not None and self._sub_by_channel.get(channel.id) == sub_id:
                del self._sub_by_channel[channel.id]
        return _dumps({"op": "unsubscribe", "subscriptionIds": ids})

    def advertise(
        self,
        topic: str,
        encoding: str,
        schema_name: str,
        schema: str | None = None,
        schema_encoding: str | None = None,
    ) -> tuple[int, str]:
        """Advertise a client channel (needs the server's ``clientPublish``
        capability). Returns ``(client_channel_id, json_text)``.

        ``schema`` is text: for a binary schema encoding (``protobuf``) pass it
        base64-encoded. ``schema`` / ``schema_encoding`` are left out of the
        message when ``None``.
        """
        _check_str(topic, "topic", nonempty=True)
        _check_str(encoding, "encoding", nonempty=True)
        _check_str(schema_name, "schema_name")
        if schema is not None:
            _check_str(schema, "schema")
        if schema_encoding is not None:
            _check_str(schema_encoding, "schema_encoding")
        channel_id = self._next_client_channel_id
        if channel_id > _U32_MAX:
            raise OverflowError("client channel ids exhausted for this connection")
        self._next_client_channel_id += 1
        self._client_channels[channel_id] = Channel(
            channel_id, topic, encoding, schema_name, schema_encoding or "", schema or ""
        )
        entry: dict[str, object] = {
            "id": channel_id,
            "topic": topic,
            "encoding": encoding,
            "schemaName": schema_name,
        }
        if schema is not None:
            entry["schema"] = schema
        if schema_encoding is not None:
            entry["schemaEncoding"] = schema_encoding
        return channel_id, _dumps({"op": "advertise", "channels": [entry]})

    def unadvertise(self, channel_ids: Iterable[int]) -> str:
        """Withdraw client channels and return the ``unadvertise`` JSON."""
        ids = _check_ids(channel_ids, "channel_ids", u32=True)
        for channel_id in ids:
            self._client_channels.pop(channel_id, None)
        return _dumps({"op": "unadvertise", "channelIds": ids})

    def message_data(
        self, client_channel_id: int, payload: bytes | bytearray | memoryview
    ) -> bytes:
        """A client message-data frame (opcode 0x01): ``u32`` client channel id,
        then the payload. ``ValueError`` if the channel is not advertised."""
        if type(client_channel_id) is not int:
            raise TypeError(
                f"client_channel_id must be an int, got {type(client_channel_id).__name__}"
            )
        if client_channel_id not in self._client_channels:
            raise ValueError(f"client channel {client_channel_id} is not advertised")
        _check_payload(payload)
        return b"".join(
            (_CLIENT_MESSAGE_HEADER.pack(_OP_CLIENT_MESSAGE_DATA, client_channel_id), payload)
        )

    def service_call_request(
        self,
        service_id: int,
        call_id: int,
        encoding: str,
        payload: bytes | bytearray | memoryview,
    ) -> bytes:
        """A service-call-request frame (opcode 0x02): ``u32`` service id,
        ``u32`` call id, ``u32`` encoding length, the UTF-8 encoding name, then
        the payload. The caller picks ``call_id`` and matches the
        :class:`ServiceCallResponse` / :class:`ServiceCallFailure` by it."""
        _check_id(service_id, "service_id", u32=True)
        _check_id(call_id, "call_id", u32=True)
        enc = _check_str(encoding, "encoding", nonempty=True).encode("utf-8")
        _check_payload(payload)
        header = _SERVICE_REQUEST_HEADER.pack(
            _OP_SERVICE_CALL_REQUEST, service_id, call_id, len(enc)
        )
        return b"".join((header, enc, payload))

    def get_parameters(self, names: Sequence[str], request_id: str | None = None) -> str:
        """``getParameters``; an empty ``names`` asks for all parameters."""
        msg: dict[str, object] = {
            "op": "getParameters",
            "parameterNames": _check_names(names, "names"),
        }
        if request_id is not None:
            msg["id"] = _check_str(request_id, "request_id")
        return _dumps(msg)

    def set_parameters(self, params: Sequence[Parameter], request_id: str | None = None) -> str:
        """``setParameters``. A ``float`` value is sent with ``"type":"float64"``
        (so ``2.0`` stays a float), a bytes-like value as base64 with
        ``"type":"byte_array"``, a list holding floats with
        ``"type":"float64_array"``; an explicit :attr:`Parameter.type` wins.
        A ``None`` value unsets the parameter. Values that are not JSON
        (NaN, infinity, arbitrary objects) raise ``ValueError`` / ``TypeError``."""
        if isinstance(params, Parameter) or not isinstance(params, Iterable):
            raise TypeError("params must be a sequence of Parameter")
        msg: dict[str, object] = {
            "op": "setParameters",
            "parameters": [_encode_parameter(p) for p in params],
        }
        if request_id is not None:
            msg["id"] = _check_str(request_id, "request_id")
        return _dumps(msg)

    def subscribe_parameter_updates(self, names: Sequence[str]) -> str:
        """``subscribeParameterUpdates`` (needs ``parametersSubscribe``)."""
        return _dumps(
            {"op": "subscribeParameterUpdates", "parameterNames": _check_names(names, "names")}
        )

    def unsubscribe_parameter_updates(self, names: Sequence[str]) -> str:
        """``unsubscribeParameterUpdates``."""
        return _dumps(
            {"op": "unsubscribeParameterUpdates", "parameterNames": _check_names(names, "names")}
        )

    def subscribe_connection_graph(self) -> str:
        """``subscribeConnectionGraph`` (needs ``connectionGraph``)."""
        return _dumps({"op": "subscribeConnectionGraph"})

    def unsubscribe_connection_graph(self) -> str:
        """``unsubscribeConnectionGraph``."""
        return _dumps({"op": "unsubscribeConnectionGraph"})

    def fetch_asset(self, uri: str, request_id: int) -> str:
        """``fetchAsset`` (needs ``assets``); the answer is a
        :class:`FetchAssetResponse` with the same ``request_id``."""
        _check_str(uri, "uri", nonempty=True)
        _check_id(request_id, "request_id", u32=True)
        return _dumps({"op": "fetchAsset", "uri": uri, "requestId": request_id})
