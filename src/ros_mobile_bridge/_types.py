"""Public value types: frozen dataclasses and literals shared by every transport."""

from __future__ import annotations

import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Generic, Literal

from ._slots import new_object, unfrozen_twin

__all__ = [
    "DEFAULT_PORTS",
    "ActionOutcome",
    "Compression",
    "ConnectionStats",
    "Dispatch",
    "GoalState",
    "Message",
    "PlaybackRequest",
    "PlaybackState",
    "PlaybackStatus",
    "Priority",
    "Protocol",
    "SaveBandwidth",
    "ServerInfo",
    "ServerStatus",
    "ServiceInfo",
    "Status",
    "StatusLevel",
    "StatusRemoved",
    "SubscriptionState",
    "SubscriptionStats",
    "TopicEndpoints",
    "TopicInfo",
]

Protocol = Literal["foxglove-ws", "rosbridge", "zenoh"]
Status = Literal["connecting", "connected", "reconnecting", "closed", "error"]
Priority = Literal["data", "control"]
Dispatch = Literal["all", "latest"]
SubscriptionState = Literal["pending", "active"]
Compression = Literal["cbor", "cbor-raw"]
SaveBandwidth = bool | Literal["adaptive"]
GoalState = Literal["pending", "active", "succeeded", "canceled", "aborted", "failed"]
StatusLevel = Literal["info", "warning", "error"]
PlaybackStatus = Literal["playing", "paused", "buffering", "ended"]

if sys.version_info >= (3, 13):
    from typing import TypeVar
else:
    from typing_extensions import TypeVar

DataT = TypeVar("DataT", default=Any)
"""What ``Message.data`` holds: the message class a subscription names
(``subscribe(topic, Odometry)``), else ``Any``."""

ResultT = TypeVar("ResultT", default=Any)
"""An action goal's result: the action's ``Result`` class for a goal sent as
an instance of its ``Goal`` class, else ``Any``."""
FeedbackT = TypeVar("FeedbackT", default=Any)
"""An action goal's feedback: the action's ``Feedback`` class, else ``Any``."""
RequestT = TypeVar("RequestT", default=Any)
"""A served call's request: the service's ``Request`` class when ``serve()``
names the service's class, else ``Any``."""
ResponseT = TypeVar("ResponseT", default=Any)
"""A served call's response: the service's ``Response`` class, else ``Any``."""

DEFAULT_PORTS: Mapping[str, int] = {"foxglove-ws": 8765, "rosbridge": 9090, "zenoh": 7447}
"""The port each protocol's bridge listens on unless told otherwise."""


@dataclass(frozen=True, slots=True)
class Message(Generic[DataT]):
    """One message received on a subscription.

    ``data`` is the decoded message: an instance of the type's message class
    (``msg.data.pose.pose.position.x``; see :mod:`ros_mobile_bridge.interfaces`)
    whenever the library knows the type's ROS definition (bundled, the
    server's schema, the robot's description, a local workspace, or
    ``register_type``), with primitive arrays (``uint8[]`` image data,
    ``float64[]``) as numpy arrays that view the received frame where the
    codec allows; a ``dict`` for a channel that has only a JSON Schema, or
    JSON of a type with no ROS definition. ``msg.data.to_dict()`` gives the
    dict form. A subscription that names a class (``subscribe(topic,
    Odometry)``) is a ``Subscription[Odometry]``, and type checkers know
    ``msg.data`` is an ``Odometry``. When the payload could not be decoded
    (or, for a named class, was of another definition), ``data`` is the raw
    ``memoryview`` and ``decode_error`` says why.
    ``receive_time_ns`` is ``time.time_ns()`` when the frame arrived;
    ``log_time_ns`` is the timestamp the wire carries: the Foxglove server's
    log time, rmw_zenoh's source timestamp (the publisher's clock when it
    published), ``None`` over rosbridge. ``sequence`` is the publisher's
    sequence number where the wire carries one (Zenoh: rmw_zenoh's
    attachment; it counts per publisher, so a gap is a lost sample), else
    ``None``.
    """

    topic: str
    schema_name: str
    encoding: str
    data: DataT
    receive_time_ns: int
    log_time_ns: int | None
    byte_size: int
    decode_error: str | None = None
    sequence: int | None = None


_UnfrozenMessage = unfrozen_twin(Message)


def new_message(
    topic: str,
    schema_name: str,
    encoding: str,
    data: Any,
    receive_time_ns: int,
    log_time_ns: int | None,
    byte_size: int,
    decode_error: str | None,
    sequence: int | None,
) -> Message:
    """``Message(...)`` for the delivery hot path: the same frozen object,
    built as its unfrozen twin (plain slot stores instead of the dataclass
    ``__init__``'s ``object.__setattr__`` per field), then made a
    ``Message``: about a quarter of the cost, once per delivered message."""
    message: Any = new_object(_UnfrozenMessage)
    message.topic = topic
    message.schema_name = schema_name
    message.encoding = encoding
    message.data = data
    message.receive_time_ns = receive_time_ns
    message.log_time_ns = log_time_ns
    message.byte_size = byte_size
    message.decode_error = decode_error
    message.sequence = sequence
    message.__class__ = Message
    return message  # type: ignore[no-any-return]


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """A topic the server offers. ``schema_name`` is the ROS type as the server
    spells it (``pkg/msg/Type`` or ``pkg/Type``); ``encoding`` is the message
    encoding on the wire (``cdr``, ``json``, ...)."""

    name: str
    schema_name: str
    encoding: str = ""


@dataclass(frozen=True, slots=True)
class ServiceInfo:
    """A service the server offers."""

    name: str
    type: str


@dataclass(frozen=True, slots=True)
class ServerInfo:
    """What the server said about itself during the handshake."""

    name: str
    protocol: str
    subprotocol: str | None = None
    capabilities: tuple[str, ...] = ()
    supported_encodings: tuple[str, ...] = ()
    metadata: Mapping[str, str] = field(default_factory=dict)
    session_id: str | None = None


@dataclass(frozen=True, slots=True)
class SubscriptionStats:
    """Counters of one subscription since it was opened.

    Every frame routed to the subscription is ``received``; each one then ends
    in exactly one of ``delivered``, ``dropped_throttle`` (replaced by a
    newer frame within the effective interval: the ``max_hz`` cap or the
    adaptive throttle's), ``dropped_conflated`` (superseded under
    ``dispatch="latest"``),
    ``dropped_overflow`` (the consumer fell behind; oldest dropped),
    ``dropped_breaker`` (the circuit breaker was tripped), or is still
    queued, or ``dropped_replay`` (``save_bandwidth`` on Foxglove: the server
    replayed, on resubscription, the message delivered last; over Zenoh, a
    transient-local publisher's message delivered already, live or from its
    history). ``decode_failures``
    counts delivered messages whose payload could not be decoded (delivered
    raw). ``effective_interval_ms`` is the larger of the ``max_hz`` cap and
    the adaptive throttle's interval; ``bucket`` names the throttle bucket
    (``""`` without one); ``arrival_bytes_per_s`` is the payload rate
    arriving over the last second, before any filter; ``bytes_received``
    the payload bytes of every frame routed to the subscription (the
    ``received`` ones), whatever became of them."""

    received: int
    delivered: int
    dropped_throttle: int
    dropped_conflated: int
    dropped_overflow: int
    decode_failures: int
    effective_interval_ms: float
    dropped_breaker: int = 0
    bucket: str = ""
    arrival_bytes_per_s: float = 0.0
    bytes_received: int = 0
    dropped_replay: int = 0


@dataclass(frozen=True, slots=True)
class ConnectionStats:
    """What one client has read from the network over its life (every
    connection it made, reconnects included); ``Client.stats()``.

    ``bytes_received``: bytes read from the socket (Foxglove, rosbridge:
    WebSocket framing included) or the payload bytes of the samples the
    zenoh session handed over (Zenoh: zenoh's own framing is not seen).
    ``messages_received``: WebSocket messages (Foxglove, rosbridge) or zenoh
    items (samples, replies, liveliness changes) received, whatever became
    of them."""

    bytes_received: int
    messages_received: int


@dataclass(frozen=True, slots=True)
class ActionOutcome(Generic[ResultT]):
    """How an action goal ended: ``status`` is ``"succeeded"`` or
    ``"canceled"``, ``result`` the action's result message (an instance of
    the action's ``Result`` class whenever the library knows the action's
    definition, else a dict)."""

    status: Literal["succeeded", "canceled"]
    result: ResultT


@dataclass(frozen=True, slots=True)
class TopicEndpoints:
    """Who publishes and who subscribes to one topic, as the robot's graph
    says now (``Client.topic_endpoints``): node names (rosbridge, Zenoh) or
    the ids the Foxglove server gives them (foxglove_bridge: node names),
    sorted. ``publishers`` / ``subscribers`` are empty for a topic the
    graph does not know."""

    topic: str
    publishers: tuple[str, ...]
    subscribers: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class ServerStatus:
    """A status message the Foxglove server sent (``Client.watch_server_status``):
    ``level`` and ``message`` as the server gave them; ``id`` names it when
    the server may withdraw it later (a :class:`StatusRemoved`)."""

    level: StatusLevel
    message: str
    id: str | None = None


@dataclass(frozen=True, slots=True)
class StatusRemoved:
    """The Foxglove server withdrew the status messages with these ``ids``."""

    ids: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class PlaybackState:
    """How a Foxglove server playing a recording plays it now
    (``Client.playback_state``): ``status``, the playback time
    ``current_time_ns`` (nanoseconds, the recording's clock), ``speed`` (a
    factor of real time), ``did_seek`` (this state follows a jump in time)
    and ``request_id``: the id of the :class:`PlaybackRequest` it answers,
    or None when the server changed playback on its own."""

    status: PlaybackStatus
    current_time_ns: int
    speed: float
    did_seek: bool
    request_id: str | None = None


@dataclass(frozen=True, slots=True)
class PlaybackRequest:
    """A request to a Foxglove server playing a recording
    (``Client.control_playback``): ``play`` (True) or pause (False), at
    ``speed`` (a factor of real time, > 0), jumping first to ``seek_ns``
    (nanoseconds, the recording's clock) unless None."""

    play: bool
    speed: float = 1.0
    seek_ns: int | None = None

    def __post_init__(self) -> None:
        """Bad values raise ``TypeError`` / ``ValueError`` here, before anything is sent."""
        if not isinstance(self.play, bool):
            raise TypeError(f"play must be a bool, got {type(self.play).__name__}")
        if isinstance(self.speed, bool) or not isinstance(self.speed, int | float):
            raise TypeError(f"speed must be a number, got {type(self.speed).__name__}")
        if not 0 < self.speed < float("inf"):
            raise ValueError(f"speed must be a positive factor of real time, got {self.speed!r}")
        if self.seek_ns is not None and (type(self.seek_ns) is not int or self.seek_ns < 0):
            raise ValueError(f"seek_ns must be None or an int >= 0 (ns), got {self.seek_ns!r}")
