"""The Foxglove engine itself: :class:`FoxgloveEngine`, the state machine of one
connection (part of :mod:`ros_mobile_bridge.wire.foxglove`). It keeps the
channels, services, schemas and subscriptions; the readers (:mod:`._readers`)
turn what the server sends into events, the writers (:mod:`._writers`) check
the caller's arguments and encode what the client sends."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from types import MappingProxyType
from typing import Any

from .._limits import json_too_deep
from ._events import (
    Advertise,
    AdvertiseServices,
    Channel,
    Event,
    Parameter,
    ProtocolViolation,
    ServerInfo,
    ServiceDef,
    Time,
    Unadvertise,
    UnadvertiseServices,
    make_message_data,
)
from ._protocol import (
    MESSAGE_DATA_HEADER,
    MESSAGE_DATA_PAYLOAD_AT,
    OP_FETCH_ASSET_RESPONSE,
    OP_MESSAGE_DATA,
    OP_PLAYBACK_STATE,
    OP_SERVICE_CALL_RESPONSE,
    OP_TIME,
    SUBPROTOCOLS,
    TIME,
    U32_MAX,
)
from ._readers import (
    Malformed,
    as_object,
    json_kind,
    merge_violations,
    opt_list,
    parse_channel,
    parse_service,
    read_connection_graph_update,
    read_fetch_asset_response,
    read_parameter_values,
    read_playback_state,
    read_remove_status,
    read_server_info,
    read_service_call_failure,
    read_service_call_response,
    read_status,
    req_id,
    req_list,
    req_str,
    schema_fits,
    truncated,
    unknown_ids,
)
from ._writers import (
    check_id,
    check_ids,
    check_str,
    dumps,
    encode_fetch_asset,
    encode_get_parameters,
    encode_message_data,
    encode_playback_control,
    encode_service_call_request,
    encode_set_parameters,
    encode_subscribe_connection_graph,
    encode_subscribe_parameter_updates,
    encode_unsubscribe_connection_graph,
    encode_unsubscribe_parameter_updates,
)

__all__ = ["FoxgloveEngine"]

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
            "status": read_status,
            "removeStatus": read_remove_status,
            "advertise": self._on_advertise,
            "unadvertise": self._on_unadvertise,
            "advertiseServices": self._on_advertise_services,
            "unadvertiseServices": self._on_unadvertise_services,
            "parameterValues": read_parameter_values,
            "connectionGraphUpdate": read_connection_graph_update,
            "serviceCallFailure": read_service_call_failure,
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

    def peek_message_data(
        self, data: bytes, start: int, stop: int
    ) -> tuple[Channel, int, memoryview] | None:
        """The hot path's look at the binary frame ``data[start:stop]``: for a
        well-formed message-data frame of a live subscription, its channel,
        log time and payload (a zero-copy ``memoryview`` of ``data``); None
        for anything else, which :meth:`receive_binary` then parses and
        reports. Reads nothing but the header, changes no state, never raises
        (given ``0 <= start <= stop <= len(data)``)."""
        if stop - start < MESSAGE_DATA_PAYLOAD_AT or data[start] != OP_MESSAGE_DATA:
            return None
        sub_id, log_time = MESSAGE_DATA_HEADER.unpack_from(data, start + 1)
        channel = self._subs.get(sub_id)
        if channel is None:
            return None
        return channel, log_time, memoryview(data)[start + MESSAGE_DATA_PAYLOAD_AT : stop]

    # -- server -> client: text ---------------------------------------------

    def receive_text(self, text: str | bytes | bytearray | memoryview) -> list[Event]:
        """Parse one text frame from the server.

        Returns the resulting events in order (:class:`ProtocolViolation` events
        for the parts that were unusable come before the event for the rest;
        past the first ``VIOLATIONS_SHOWN``, one per kind with its ``count``,
        however many parts of the frame were unusable). Never raises for any
        ``str`` or bytes-like input; ``bytes`` must be UTF-8.
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
            return [ProtocolViolation(f"text frame is a JSON {json_kind(msg)}, not an object")]
        op = msg.get("op")
        if type(op) is not str:
            return [ProtocolViolation("text frame has no string 'op' field")]
        handler = self._text_handlers.get(op)
        if handler is None:
            return [ProtocolViolation(f"unknown op {op!r:.60}")]
        out: list[Event] = []
        try:
            handler(msg, out)
        except Malformed as exc:
            out.append(ProtocolViolation(f"{op}: {exc}"))
        except Exception as exc:  # the contract: server input never raises
            out.append(ProtocolViolation(f"{op}: internal error: {exc!r}"))
        return merge_violations(out)

    def _too_deep(self, size: int) -> ProtocolViolation:
        return ProtocolViolation(
            f"a text frame of {size} characters nests deeper than {self.max_json_depth}; skipped",
            "json_depth",
        )

    def _on_server_info(self, msg: dict[str, Any], out: list[Event]) -> None:
        info = read_server_info(msg, out)
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
        self.server_info = info
        out.append(info)

    def _on_advertise(self, msg: dict[str, Any], out: list[Event]) -> None:
        schemas = opt_list(msg, "schemas")
        channels = opt_list(msg, "channels") if schemas else req_list(msg, "channels")
        refused = 0
        for raw in schemas:
            try:
                obj = as_object(raw, "a schema")
                sid = req_id(obj, "id")
                entry = (req_str(obj, "name"), req_str(obj, "encoding"), req_str(obj, "data"))
            except Malformed as exc:
                out.append(ProtocolViolation(f"advertise: schema skipped: {exc}"))
                continue
            if sid not in self._schemas and len(self._schemas) >= self.max_channels:
                refused += 1  # the table is bounded like the channels using it
                continue
            if schema_fits(entry[2], self.max_schema_size):
                self._oversize.pop(sid, None)
            else:  # kept without its text; the channel using it is reported
                self._oversize[sid] = len(entry[2])
                entry = (entry[0], entry[1], "")
            self._schemas[sid] = entry
        advertised: list[Channel] = []
        for raw in channels:
            try:
                channel = parse_channel(
                    raw,
                    out,
                    schemas=self._schemas,
                    oversize=self._oversize,
                    max_schema_size=self.max_schema_size,
                )
            except Malformed as exc:
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

    def _on_unadvertise(self, msg: dict[str, Any], out: list[Event]) -> None:
        removed: list[Channel] = []
        unknown: list[int] = []  # ids the server never advertised (or withdrew)
        for raw in req_list(msg, "channelIds"):
            if type(raw) is not int:
                out.append(
                    ProtocolViolation(f"unadvertise: channel id {raw!r:.40} is not an integer")
                )
                continue
            channel = self._channels.pop(raw, None)
            if channel is None:
                unknown.append(raw)
            else:
                self._sub_by_channel.pop(raw, None)
                removed.append(channel)
        if unknown:
            out.append(unknown_ids("unadvertise: unknown channel id", unknown))
        if removed:
            out.append(Unadvertise(tuple(removed)))

    def _on_advertise_services(self, msg: dict[str, Any], out: list[Event]) -> None:
        advertised: list[ServiceDef] = []
        refused = 0
        for raw in req_list(msg, "services"):
            try:
                service = parse_service(
                    raw, out, server_info=self.server_info, max_schema_size=self.max_schema_size
                )
            except Malformed as exc:
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

    def _on_unadvertise_services(self, msg: dict[str, Any], out: list[Event]) -> None:
        removed: list[ServiceDef] = []
        unknown: list[int] = []
        for raw in req_list(msg, "serviceIds"):
            if type(raw) is not int:
                out.append(
                    ProtocolViolation(
                        f"unadvertiseServices: service id {raw!r:.40} is not an integer"
                    )
                )
                continue
            service = self._services.pop(raw, None)
            if service is None:
                unknown.append(raw)
            else:
                removed.append(service)
        if unknown:
            out.append(unknown_ids("unadvertiseServices: unknown service id", unknown))
        if removed:
            out.append(UnadvertiseServices(tuple(removed)))

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
            if opcode == OP_MESSAGE_DATA:  # the hot path
                if size < MESSAGE_DATA_PAYLOAD_AT:
                    return [truncated(opcode, size, MESSAGE_DATA_PAYLOAD_AT)]
                sub_id, log_time = MESSAGE_DATA_HEADER.unpack_from(view, 1)
                channel = self._subs.get(sub_id)
                if channel is None:
                    if 0 < sub_id < self._next_sub_id:
                        return []  # unsubscribed; a late frame
                    return [ProtocolViolation(f"message data for unknown subscription id {sub_id}")]
                return [
                    make_message_data(sub_id, channel, log_time, view[MESSAGE_DATA_PAYLOAD_AT:])
                ]
            if opcode == OP_TIME:
                if size < 1 + TIME.size:
                    return [truncated(opcode, size, 1 + TIME.size)]
                return [Time(TIME.unpack_from(view, 1)[0])]
            if opcode == OP_SERVICE_CALL_RESPONSE:
                return [read_service_call_response(view, size)]
            if opcode == OP_FETCH_ASSET_RESPONSE:
                return [read_fetch_asset_response(view, size)]
            if opcode == OP_PLAYBACK_STATE:
                return [read_playback_state(view, size)]
        except Exception as exc:  # the contract: server input never raises
            return [ProtocolViolation(f"binary opcode 0x{opcode:02x}: internal error: {exc!r}")]
        return [ProtocolViolation(f"unknown binary opcode 0x{opcode:02x}")]

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
            check_id(channel_id, "channel_id")
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
        if first + len(channels) - 1 > U32_MAX:
            raise OverflowError("subscription ids exhausted for this connection")
        self._next_sub_id = first + len(channels)
        subscriptions = []
        for sub_id, channel in enumerate(channels, first):
            self._subs[sub_id] = channel
            self._sub_by_channel[channel.id] = sub_id
            subscriptions.append({"id": sub_id, "channelId": channel.id})
        text = dumps({"op": "subscribe", "subscriptions": subscriptions})
        return tuple(range(first, first + len(channels))), text

    def unsubscribe(self, subscription_ids: Iterable[int]) -> str:
        """Forget these subscriptions and return the ``unsubscribe`` JSON.
        Ids that are not live are still sent (the server decides) but change
        nothing here."""
        ids = check_ids(subscription_ids, "subscription_ids")
        for sub_id in ids:
            channel = self._subs.pop(sub_id, None)
            if channel is not None and self._sub_by_channel.get(channel.id) == sub_id:
                del self._sub_by_channel[channel.id]
        return dumps({"op": "unsubscribe", "subscriptionIds": ids})

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
        check_str(topic, "topic", nonempty=True)
        check_str(encoding, "encoding", nonempty=True)
        check_str(schema_name, "schema_name")
        if schema is not None:
            check_str(schema, "schema")
        if schema_encoding is not None:
            check_str(schema_encoding, "schema_encoding")
        channel_id = self._next_client_channel_id
        if channel_id > U32_MAX:
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
        return channel_id, dumps({"op": "advertise", "channels": [entry]})

    def unadvertise(self, channel_ids: Iterable[int]) -> str:
        """Withdraw client channels and return the ``unadvertise`` JSON."""
        ids = check_ids(channel_ids, "channel_ids", u32=True)
        for channel_id in ids:
            self._client_channels.pop(channel_id, None)
        return dumps({"op": "unadvertise", "channelIds": ids})

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
        return encode_message_data(client_channel_id, payload)

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
        return encode_service_call_request(service_id, call_id, encoding, payload)

    def get_parameters(self, names: Sequence[str], request_id: str | None = None) -> str:
        """``getParameters``; an empty ``names`` asks for all parameters."""
        return encode_get_parameters(names, request_id)

    def set_parameters(self, params: Sequence[Parameter], request_id: str | None = None) -> str:
        """``setParameters``. A ``float`` value is sent with ``"type":"float64"``
        (so ``2.0`` stays a float), a bytes-like value as base64 with
        ``"type":"byte_array"``, a list holding floats with
        ``"type":"float64_array"``; an explicit :attr:`Parameter.type` wins.
        A ``None`` value unsets the parameter. Values that are not JSON
        (NaN, infinity, arbitrary objects) raise ``ValueError`` / ``TypeError``."""
        return encode_set_parameters(params, request_id)

    def subscribe_parameter_updates(self, names: Sequence[str]) -> str:
        """``subscribeParameterUpdates`` (needs ``parametersSubscribe``)."""
        return encode_subscribe_parameter_updates(names)

    def unsubscribe_parameter_updates(self, names: Sequence[str]) -> str:
        """``unsubscribeParameterUpdates``."""
        return encode_unsubscribe_parameter_updates(names)

    def subscribe_connection_graph(self) -> str:
        """``subscribeConnectionGraph`` (needs ``connectionGraph``)."""
        return encode_subscribe_connection_graph()

    def unsubscribe_connection_graph(self) -> str:
        """``unsubscribeConnectionGraph``."""
        return encode_unsubscribe_connection_graph()

    def fetch_asset(self, uri: str, request_id: int) -> str:
        """``fetchAsset`` (needs ``assets``); the answer is a
        :class:`FetchAssetResponse` with the same ``request_id``."""
        return encode_fetch_asset(uri, request_id)

    def playback_control(
        self, play: bool, speed: float, seek_ns: int | None, request_id: str
    ) -> bytes:
        """A playback-control-request frame (opcode 0x03, ``foxglove.sdk``;
        needs ``playbackControl``): play (True) or pause at ``speed`` (a
        factor of real time, > 0), after a seek to ``seek_ns`` unless None.
        The server's :class:`PlaybackState` answering it carries ``request_id``
        (non-empty)."""
        return encode_playback_control(play, speed, seek_ns, request_id)
