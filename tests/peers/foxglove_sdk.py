"""The official Foxglove SDK WebSocket server (``foxglove-sdk``), in-process.

``SdkServer`` starts ``foxglove.start_server`` with its own context on
127.0.0.1 (an ephemeral port unless one is given), and records what clients
do through a thread-safe listener: advertisements, published messages,
subscriptions, parameter requests."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import foxglove
import numpy as np
from foxglove import Channel, MessageSchema, Parameter, Schema, Service, ServiceSchema
from foxglove.websocket import (
    Capability,
    PlaybackCommand,
    PlaybackControlRequest,
    PlaybackState,
    PlaybackStatus,
)
from rosbags.typesys import Stores, get_typestore

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)

ALL_CAPABILITIES = [
    Capability.ClientPublish,
    Capability.Services,
    Capability.Parameters,
    Capability.ConnectionGraph,
    Capability.Time,
]


def msgdef(typename: str) -> bytes:
    """The concatenated ros2msg definition of a bundled ROS 2 type."""
    text, _ = TYPESTORE.generate_msgdef(typename, ros_version=2)
    return text.encode()


def cdr(typename: str, **fields: Any) -> bytes:
    """Serialize a bundled ROS 2 message from keyword fields (nested
    messages as already-built rosbags objects)."""
    cls = TYPESTORE.types[typename]
    return bytes(TYPESTORE.serialize_cdr(cls(**fields), typename))


def string_msg(text: str) -> bytes:
    return cdr("std_msgs/msg/String", data=text)


def image_msg(
    width: int = 640,
    height: int = 480,
    *,
    pixels: Any = None,
    stamp: tuple[int, int] = (0, 0),
    frame_id: str = "",
) -> bytes:
    """A ``sensor_msgs/msg/Image`` (rgb8) as CDR: ``pixels`` (a uint8 array of
    ``width * height * 3``; zeros by default), ``stamp`` as (sec, nanosec)."""
    t = TYPESTORE.types
    return cdr(
        "sensor_msgs/msg/Image",
        header=t["std_msgs/msg/Header"](
            stamp=t["builtin_interfaces/msg/Time"](sec=stamp[0], nanosec=stamp[1]),
            frame_id=frame_id,
        ),
        height=height,
        width=width,
        encoding="rgb8",
        is_bigendian=0,
        step=width * 3,
        data=np.zeros(width * height * 3, dtype=np.uint8) if pixels is None else pixels,
    )


def decode(typename: str, payload: bytes) -> Any:
    return TYPESTORE.deserialize_cdr(payload, typename)


@dataclass
class Received:
    """One message a client published to the server."""

    topic: str
    encoding: str
    schema_name: str
    data: bytes
    time_ns: int


@dataclass
class Recorder:
    lock: threading.Lock = field(default_factory=threading.Lock)
    advertised: list[tuple[int, str, str, str]] = field(default_factory=list)
    unadvertised: list[int] = field(default_factory=list)
    messages: list[Received] = field(default_factory=list)
    subscribed: list[str] = field(default_factory=list)
    unsubscribed: list[str] = field(default_factory=list)
    param_subscribed: list[str] = field(default_factory=list)
    playback_requests: list[tuple[bool, float, int | None, str]] = field(default_factory=list)
    """(play, speed, seek time, request id) per playback control request."""
    graph_subscriptions: list[bool] = field(default_factory=list)
    """True per first subscription to the connection graph, False per last unsubscription."""
    channels: dict[tuple[int, int], tuple[str, str, str]] = field(default_factory=dict)


class _Listener:
    def __init__(self, server: SdkServer) -> None:
        self.s = server
        self.r = server.recorder

    def on_subscribe(self, client: Any, channel: Any) -> None:
        with self.r.lock:
            self.r.subscribed.append(channel.topic)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        with self.r.lock:
            self.r.unsubscribed.append(channel.topic)

    def on_client_advertise(self, client: Any, channel: Any) -> None:
        with self.r.lock:
            self.r.advertised.append(
                (channel.id, channel.topic, channel.encoding, channel.schema_name)
            )
            self.r.channels[(client.id, channel.id)] = (
                channel.topic,
                channel.encoding,
                channel.schema_name,
            )

    def on_client_unadvertise(self, client: Any, client_channel_id: int) -> None:
        with self.r.lock:
            self.r.unadvertised.append(client_channel_id)

    def on_message_data(self, client: Any, client_channel_id: int, data: bytes) -> None:
        now = time.time_ns()
        with self.r.lock:
            topic, encoding, schema = self.r.channels.get(
                (client.id, client_channel_id), ("?", "?", "?")
            )
            self.r.messages.append(Received(topic, encoding, schema, bytes(data), now))

    def on_get_parameters(
        self, client: Any, param_names: list[str], request_id: str | None = None
    ) -> list[Parameter]:
        with self.s.param_lock:
            items = dict(self.s.parameters)
        if param_names:
            items = {k: v for k, v in items.items() if k in param_names}
        return [Parameter(k, value=v) for k, v in items.items()]

    def on_set_parameters(
        self, client: Any, parameters: list[Parameter], request_id: str | None = None
    ) -> list[Parameter]:
        with self.s.param_lock:
            for p in parameters:
                self.s.parameters[p.name] = p.get_value()
        return parameters

    def on_parameters_subscribe(self, param_names: list[str]) -> None:
        with self.r.lock:
            self.r.param_subscribed.extend(param_names)

    def on_parameters_unsubscribe(self, param_names: list[str]) -> None:
        pass

    def on_playback_control_request(self, request: PlaybackControlRequest) -> PlaybackState:
        """A player of the recording: it plays or pauses at the speed asked,
        from the time asked (else from the start of its range)."""
        play = request.playback_command == PlaybackCommand.Play
        with self.r.lock:
            self.r.playback_requests.append(
                (play, request.playback_speed, request.seek_time, request.request_id)
            )
        seek = request.seek_time
        return PlaybackState(
            PlaybackStatus.Playing if play else PlaybackStatus.Paused,
            seek if seek is not None else self.s.playback_start,
            request.playback_speed,
            seek is not None,
            request.request_id,
        )

    def on_connection_graph_subscribe(self) -> None:
        with self.r.lock:
            self.r.graph_subscriptions.append(True)

    def on_connection_graph_unsubscribe(self) -> None:
        with self.r.lock:
            self.r.graph_subscriptions.append(False)


class SdkServer:
    """A running Foxglove SDK server. Use as a context manager or call
    :meth:`stop`. ``url`` is ``ws://127.0.0.1:PORT``."""

    def __init__(
        self,
        *,
        port: int = 0,
        services: list[Service] | None = None,
        capabilities: list[Any] | None = None,
        supported_encodings: list[str] | None = None,
        parameters: dict[str, Any] | None = None,
        tls: tuple[bytes, bytes] | None = None,
        listener: type[_Listener] | None = None,
        asset_handler: Callable[[str], bytes | None] | None = None,
        playback_time_range: tuple[int, int] | None = None,
    ) -> None:
        """``tls``: ``(certificate_pem, key_pem)`` to serve ``wss://``;
        ``listener``: a subclass of the recording listener to use instead;
        ``asset_handler``: serve assets (the server then lists ``assets``);
        ``playback_time_range``: a recording's (start, end) in ns (the
        server then lists ``playbackControl``)."""
        self.recorder = Recorder()
        self.playback_start = playback_time_range[0] if playback_time_range else 0
        self.param_lock = threading.Lock()
        self.parameters: dict[str, Any] = dict(parameters or {})
        self.context = foxglove.Context()
        self._channels: list[Channel] = []
        self.server = foxglove.start_server(
            name="rmb-test",
            host="127.0.0.1",
            port=port,
            context=self.context,
            capabilities=ALL_CAPABILITIES if capabilities is None else capabilities,
            server_listener=(listener or _Listener)(self),
            supported_encodings=["json", "cdr"]
            if supported_encodings is None
            else supported_encodings,
            services=services or [],
            asset_handler=asset_handler,
            playback_time_range=playback_time_range,
            tls_cert=tls[0] if tls else None,
            tls_key=tls[1] if tls else None,
        )
        self.port: int = self.server.port
        self.url = f"{'wss' if tls else 'ws'}://127.0.0.1:{self.port}"

    def channel(self, topic: str, typename: str, *, encoding: str = "cdr") -> Channel:
        """Advertise a channel of a bundled ROS 2 type (ros2msg schema)."""
        ch = Channel(
            topic,
            message_encoding=encoding,
            schema=Schema(name=typename, encoding="ros2msg", data=msgdef(typename)),
            context=self.context,
        )
        self._channels.append(ch)
        return ch

    def raw_channel(self, topic: str, *, encoding: str, schema: Schema | None) -> Channel:
        ch = Channel(topic, message_encoding=encoding, schema=schema, context=self.context)
        self._channels.append(ch)
        return ch

    def messages(self, topic: str | None = None) -> list[Received]:
        with self.recorder.lock:
            return [m for m in self.recorder.messages if topic is None or m.topic == topic]

    def subscribed(self) -> list[str]:
        with self.recorder.lock:
            return list(self.recorder.subscribed)

    def unsubscribed(self) -> list[str]:
        with self.recorder.lock:
            return list(self.recorder.unsubscribed)

    def playback_requests(self) -> list[tuple[bool, float, int | None, str]]:
        with self.recorder.lock:
            return list(self.recorder.playback_requests)

    def graph_subscriptions(self) -> list[bool]:
        with self.recorder.lock:
            return list(self.recorder.graph_subscriptions)

    def publish_parameters(self, values: dict[str, Any]) -> None:
        with self.param_lock:
            self.parameters.update(values)
        self.server.publish_parameter_values([Parameter(k, value=v) for k, v in values.items()])

    def stop(self) -> None:
        for ch in self._channels:
            ch.close()
        self._channels.clear()
        self.server.stop()

    def __enter__(self) -> SdkServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def ros2_service(
    name: str,
    srv_type: str,
    request_def: str | None,
    response_def: str | None,
    handler: Callable[[Any], bytes],
) -> Service:
    """A service with nested ros2msg request/response schemas (None: no schema)."""

    def schema(suffix: str, text: str | None) -> MessageSchema | None:
        if text is None:
            return None
        return MessageSchema(
            encoding="cdr",
            schema=Schema(name=f"{srv_type}_{suffix}", encoding="ros2msg", data=text.encode()),
        )

    return Service(
        name,
        schema=ServiceSchema(
            srv_type,
            request=schema("Request", request_def),
            response=schema("Response", response_def),
        ),
        handler=handler,
    )
