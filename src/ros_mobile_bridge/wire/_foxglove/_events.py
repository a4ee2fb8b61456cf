"""What the Foxglove engine hands out: the value types (:class:`Channel`,
:class:`ServiceDef`, :class:`Parameter`, ...) and the :class:`Event`
subclasses that :meth:`FoxgloveEngine.receive_text` and
:meth:`FoxgloveEngine.receive_binary` return, all frozen dataclasses (part of
:mod:`ros_mobile_bridge.wire.foxglove`). Nothing here parses or encodes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..._slots import new_object, slot_setter

__all__ = [
    "Advertise",
    "AdvertiseServices",
    "Channel",
    "ConnectionGraphUpdate",
    "Event",
    "FetchAssetResponse",
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
    "make_message_data",
]

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


def make_message_data(
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
    """A playback-state frame (``foxglove.sdk``, ``playbackControl``): the
    ``status`` (0 playing, 1 paused, 2 buffering, 3 ended; another value is
    kept as sent), the playback time ``current_time_ns``, the ``speed`` (a
    factor of real time), whether a seek caused it (``did_seek``) and the id
    of the playback control request it answers (``""`` for none)."""

    status: int
    current_time_ns: int
    speed: float
    did_seek: bool
    request_id: str


@dataclass(frozen=True, slots=True)
class ProtocolViolation(Event):
    """The server sent something the engine could not use; ``reason`` says what.
    The engine ignored (that part of) the frame and carries on.

    ``kind`` classifies it: ``"invalid_utf8"``, ``"json_depth"``,
    ``"schema_too_large"`` (the schema text was dropped, the channel or
    service kept), ``"channel_limit"``, ``"service_limit"`` (one event per
    message, however many were refused), else ``"malformed"``.

    ``count`` is how many unusable parts of the frame this one event stands
    for. A frame yields its first ``VIOLATIONS_SHOWN`` (8) violations as
    events of their own and the rest as one event per ``kind``, whose
    ``reason`` says how many and names the first; unknown ids in one
    ``unadvertise`` are always one event (a frame withdrawing 90,000 channels
    the client never kept is one event with ``count=90000``, not 90,000)."""

    reason: str
    kind: str = "malformed"
    count: int = 1
