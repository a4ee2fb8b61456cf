"""The seam between the connection (above) and a transport adapter (below).

An adapter is one live connection to one bridge: a sans-IO wire engine
(``wire/``) driven over a transport (``transport/``). It knows no throttling,
no outbox and no teardown policy, and holds no reference to the client: its
reader hands typed :data:`Event` values to an :class:`EventSink`, and the
layer above calls the :class:`Adapter` methods. A new transport is one wire
engine plus one adapter; what every adapter shares is in ``_shared.py``."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final, Literal, Protocol, TypeVar

from .._errors import NotSupportedError, RosBridgeError
from .._types import (
    PlaybackRequest,
    PlaybackState,
    ServerInfo,
    ServerStatus,
    ServiceInfo,
    StatusRemoved,
    TopicEndpoints,
    TopicInfo,
)
from ..codec import CodecRegistry
from ..flow import RawFrame, WireMessage

__all__ = [
    "ActionClient",
    "Adapter",
    "AssetFetcher",
    "Event",
    "EventSink",
    "GoalEvents",
    "GraphChanged",
    "NodeLister",
    "ParameterAccess",
    "ParameterValues",
    "PlaybackControl",
    "Rejected",
    "Replayed",
    "ServerClock",
    "ServiceHandler",
    "ServiceHost",
    "SubscribeHints",
    "TopicState",
    "TypeDescriber",
    "require",
]


@dataclass(frozen=True, slots=True)
class SubscribeHints:
    """What the client knows about a topic subscription that a bridge can use
    to send less (rosbridge ``throttle_rate``), or to pick a type."""

    max_hz: float | None = None
    schema: str | None = None
    compression: str | None = None
    """rosbridge: ``"cbor"`` or ``"cbor-raw"`` (None: JSON). Other adapters
    ignore it."""
    pause_hz: float | None = None
    """Foxglove: the bridge may stop sending the topic after each message
    and send it again at this rate (every local subscription asked for
    ``save_bandwidth``); None: send every message. Other adapters ignore it
    (rosbridge already gets ``max_hz`` as ``throttle_rate``)."""


class GoalEvents(Protocol):
    """Callbacks the adapter's reader makes for one action goal. All run in
    the reader task and must not block."""

    def on_feedback(self, values: Any) -> None:
        """A feedback message for the goal."""

    def on_result(self, status: int | None, values: Any, succeeded: bool) -> None:
        """The goal ended: ``status`` is the ``GoalStatus`` code if known."""

    def on_failed(self, reason: str) -> None:
        """The goal failed (refused by the server, or lost: ``reason``)."""

    def on_lost(self, error: RosBridgeError) -> None:
        """The connection went (``error`` says how): the goal is lost."""


class ServiceHandler(Protocol):
    """Where an adapter hands the calls to a service this client serves."""

    async def on_service_request(self, host: ServiceHost, request_id: str, args: Any) -> None:
        """A call arrived through ``host`` (the connection's serving part,
        which takes the answer; runs in the reader task: it may send an
        answer, and must not wait for anything else)."""

    def on_service_failed(self, error: RosBridgeError) -> None:
        """The bridge refused the service after :meth:`ServiceHost.advertise_service`
        returned (a late refusal, or one to an unconfirmed advertisement):
        ``error`` is a ``SchemaError`` or ``ServiceError``. Runs in the reader
        task; must not block."""


@dataclass(frozen=True, slots=True)
class GraphChanged:
    """The topic or service list changed: both, as they are now (sorted)."""

    topics: list[TopicInfo]
    services: list[ServiceInfo]


@dataclass(frozen=True, slots=True)
class TopicState:
    """The server now carries ``topic`` to this client (``active``), or no
    longer does."""

    topic: str
    active: bool


@dataclass(frozen=True, slots=True)
class ParameterValues:
    """Unsolicited parameter values (a parameter subscription's update)."""

    values: Mapping[str, Any]


@dataclass(frozen=True, slots=True)
class Rejected:
    """``count`` inbound frames (or parts of one) were skipped or refused for
    one reason. ``reason`` is a key of ``Client.rejections``
    (``"invalid_utf8"``, ``"malformed"``, ``"json_depth"``,
    ``"schema_too_large"``, ``"channel_limit"``, ``"service_limit"``,
    ``"fragment_limit"``, ...); ``detail`` says what, untruncated (the
    consumer truncates it to log). One event is one log line however large
    ``count`` is: a burst of drops is reported once, not once per frame."""

    reason: str
    detail: str
    count: int = 1


@dataclass(frozen=True, slots=True)
class Replayed:
    """A message on ``topic`` (``size`` payload bytes) arrived and was
    skipped: the server replayed, on a resubscription, the message the
    client had delivered last (``SubscribeHints.pause_hz``)."""

    topic: str
    size: int


@dataclass(frozen=True, slots=True)
class ServerClock:
    """The server's clock now reads ``time_ns`` (Foxglove's ``time``: a
    simulator's or a recording's clock)."""

    time_ns: int


Event = (
    RawFrame
    | GraphChanged
    | TopicState
    | ParameterValues
    | Rejected
    | Replayed
    | ServerClock
    | ServerStatus
    | StatusRemoved
    | PlaybackState
)
"""What an adapter hands up. A :class:`~ros_mobile_bridge.flow.RawFrame` is
one message for a subscribed topic, not decoded; the public
:class:`~ros_mobile_bridge.ServerStatus`, :class:`~ros_mobile_bridge.StatusRemoved`
and :class:`~ros_mobile_bridge.PlaybackState` are handed up as they are."""


class EventSink(Protocol):
    """Where an adapter hands its events: the only thing it knows of what
    stands above it. It holds no reference to the client."""

    async def deliver(self, events: list[Event]) -> None:
        """The reader's events, in order: one call per inbound message (per
        batch where the adapter reads in batches), made before it reads on,
        even with no events (the sink writes queued control frames first).
        The list is the sink's from then on."""

    def post(self, event: Event) -> None:
        """One event from outside the reader (a subscribe call, a discovery
        poll), applied at once. Must not block."""

    def deliver_now(self, frame: RawFrame) -> bool:
        """One frame handed over synchronously where the transport read it
        (outside the reader's task, while the reader waits with nothing
        pending), as :meth:`deliver` would hand it. False, having done
        nothing, when it must go through :meth:`deliver` instead (control
        frames wait to be written first)."""

    def quiet_until(self, now: float) -> float:
        """The monotonic time before which no subscription can take a new
        frame (each is inside its rate cap's window), given the time ``now``;
        0.0 when one can take a frame now, or there is none. Until then the
        adapter may leave its socket unread: what arrives meanwhile is read
        together when it ends, and each capped subscription delivers the
        newest of it, as its cap would have."""


class NodeLister(Protocol):
    """The ROS nodes of the graph and each topic's endpoints (rosbridge:
    ``/rosapi``; Zenoh: the liveliness tokens; Foxglove: the server's
    connection graph, where it offers one)."""

    async def nodes(self) -> list[str]:
        """The nodes now, full names, sorted (this client's own node left
        out). ``ServiceError`` when the bridge cannot say."""
        ...

    async def topic_endpoints(self, topic: str) -> TopicEndpoints:
        """Who publishes and subscribes to ``topic`` now (empty tuples for
        a topic the graph does not know)."""
        ...


class AssetFetcher(Protocol):
    """Fetching a file the server offers by URI (Foxglove's ``assets``:
    meshes and robot descriptions, ``package://`` URIs)."""

    async def fetch_asset(self, uri: str) -> bytes:
        """The asset's bytes. ``AssetError`` with the server's reason when
        it refused; ``NotSupportedError`` naming the capability when the
        server offers no assets."""
        ...


class PlaybackControl(Protocol):
    """Controlling a server that plays a recording (Foxglove's
    ``playbackControl``). Every state the server sends is also handed up as
    a :class:`~ros_mobile_bridge.PlaybackState` event."""

    async def control_playback(self, request: PlaybackRequest) -> PlaybackState:
        """Send ``request``; the state the server answers it with.
        ``NotSupportedError`` naming the capability when the server offers
        no playback control."""
        ...


class ParameterAccess(Protocol):
    """Reading, setting and watching parameters, named ``/node:param`` (or
    as the Foxglove server names them)."""

    async def get_parameters(self, names: Sequence[str]) -> dict[str, Any]:
        """The values of ``names`` the robot has (all of them for an empty
        ``names``); a name it does not have is absent."""
        ...

    async def set_parameters(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Set ``values``; the values held afterwards. ``ParameterError``
        naming each refused name, after the others were applied."""
        ...

    async def subscribe_parameters(self, names: Sequence[str]) -> None:
        """Report changes of ``names`` as :class:`ParameterValues` events
        (``NotSupportedError`` where the server can report none)."""

    async def unsubscribe_parameters(self, names: Sequence[str]) -> None:
        """Stop reporting changes of ``names``."""


class ActionClient(Protocol):
    """Sending goals to ROS 2 action servers."""

    async def send_action_goal(
        self, action: str, action_type: str, goal: Any, events: GoalEvents
    ) -> str:
        """Send a goal; returns its id once the action server accepted it
        (``ActionGoalError`` when it refused). ``events`` hears what becomes
        of it."""
        ...

    async def cancel_action_goal(self, action: str, goal_id: str) -> None:
        """Ask the server to cancel goal ``goal_id``."""


class ServiceHost(Protocol):
    """Offering a service on the robot's graph; its calls go to a
    :class:`ServiceHandler`."""

    async def advertise_service(
        self, name: str, service_type: str, handler: ServiceHandler, *, confirm: bool = True
    ) -> None:
        """Serve ``name`` (type ``pkg/srv/Name``): calls go to ``handler``.
        With ``confirm``, returns once the server accepted it (this needs the
        reader running) and raises ``SchemaError`` (unknown type) or
        ``ServiceError`` when it refused; without, returns once sent (a
        refusal is logged: restoring after a reconnect, before the new
        connection's reader runs). When it raises after the advertisement
        may have taken effect (sent, neither confirmed nor refused: a
        timeout, a cancellation), calls may still arrive: the caller answers
        them and then calls :meth:`unadvertise_service`."""

    async def unadvertise_service(self, name: str) -> None:
        """Stop serving ``name`` (a no-op when not served)."""

    async def respond_service(self, name: str, request_id: str, values: Any, result: bool) -> None:
        """Answer the call ``request_id`` to ``name``: ``values`` is the
        response (``result`` True) or the reason text (False). ``DecodeError``
        when the response does not fit the type. The frame's write is the
        last step and is not cut by cancellation: when this raises, nothing
        was sent; once the write happened, it returns normally."""


class TypeDescriber(Protocol):
    """Asking the robot for a message type's definition."""

    async def fetch_definition(self, schema: str) -> bool:
        """Whether a definition of message type ``schema`` is known now,
        after asking the robot for one (rosbridge:
        ``/rosapi/message_details``; Zenoh: the publishing node's type
        description service)."""
        ...


class Adapter(Protocol):
    """One connection to one bridge. Built connected by the adapter's
    ``open_*`` function; closed by :meth:`aclose`.

    The core below is what every transport does. What only some do is an
    optional part: :attr:`node_list`, :attr:`parameters`, :attr:`actions`,
    :attr:`serving`, :attr:`descriptions`, :attr:`assets`, :attr:`playback`,
    each None where this connection
    cannot (the protocol has no such operation, or this server does not
    offer it). The client checks a part once, with :func:`require`, which
    raises the one ``NotSupportedError`` for all."""

    protocol: str
    server_info: ServerInfo
    confirms_delivery: bool
    """Whether :meth:`confirm_delivery` proves that the server has what was
    sent (a round trip the server itself must answer), so the client may
    offer it to the caller; else it is the teardown's best effort."""
    codecs: CodecRegistry

    @property
    def node_list(self) -> NodeLister | None: ...

    @property
    def parameters(self) -> ParameterAccess | None: ...

    @property
    def actions(self) -> ActionClient | None: ...

    @property
    def serving(self) -> ServiceHost | None: ...

    @property
    def descriptions(self) -> TypeDescriber | None: ...

    @property
    def assets(self) -> AssetFetcher | None: ...

    @property
    def playback(self) -> PlaybackControl | None: ...

    @property
    def topics(self) -> list[TopicInfo]: ...

    @property
    def services(self) -> list[ServiceInfo]: ...

    def topic_active(self, topic: str) -> bool:
        """Whether the server currently carries ``topic`` to this client."""

    @property
    def bytes_received(self) -> int:
        """Bytes read from the network on this connection so far (see
        :class:`~ros_mobile_bridge.ConnectionStats`)."""
        ...

    @property
    def messages_received(self) -> int:
        """Messages (or zenoh items) received on this connection so far."""
        ...

    async def run(self, sink: EventSink) -> None:
        """The reader loop: hands every event to ``sink`` (events that
        happened before it started first). Returns when the connection
        closed cleanly after :meth:`aclose`; raises ``ConnectError`` when it
        was lost."""

    async def send(self, message: WireMessage) -> None:
        """Write one encoded message (the outbox's writer calls this)."""

    async def subscribe(self, topic: str, hints: SubscribeHints) -> None:
        """Want ``topic``: subscribe now if the server offers it, otherwise as
        soon as it does. Idempotent per topic."""

    async def unsubscribe(self, topic: str) -> None:
        """No local subscriber wants ``topic`` any more."""

    async def advertise(
        self,
        topic: str,
        schema: str,
        *,
        latch: bool = False,
        queue_size: int | None = None,
        best_effort: bool = False,
        confirm: bool = True,
    ) -> None:
        """Make ``topic`` publishable with type ``schema`` (waits for the
        bridge to be ready). A no-op when already advertised with it.
        ``latch``: the bridge keeps the last message (``queue_size`` of
        them) for late subscribers; ``queue_size``: the publisher's depth
        where the protocol has one (rosbridge's ``queue_size``, a Zenoh
        publisher's history), else ignored; ``best_effort``: a best-effort
        publisher (``NotSupportedError`` where the protocol cannot do
        either). ``confirm=False``:
        do not wait for an answer only the reader could read (a reconnect
        restores advertisements before the new connection's reader runs); a
        refusal is logged when it arrives."""

    async def unadvertise(self, topic: str) -> None: ...

    def publishing(self) -> Mapping[str, str]:
        """Topics this client advertised, with their schema names."""

    def advertised(self, topic: str) -> str | None:
        """The schema ``topic`` is advertised with and ready to publish, or
        None (then :meth:`advertise` first). Never waits."""

    def encode_publish(self, topic: str, data: Any) -> WireMessage:
        """Encode ``data`` for the advertised ``topic``. Raises
        ``DecodeError`` for data that does not fit the schema."""

    wire_timeout_slack: float
    """Seconds the client's deadline for a call runs past the ``timeout``
    forwarded to the server (0 when the protocol forwards none)."""

    async def call_service(self, name: str, request: Any, timeout: float) -> Any:
        """Call ``name`` and return the decoded response. ``timeout`` is
        forwarded where the protocol carries one; the client owns the
        deadline. Raises ``ServiceError`` on failure (``NotSupportedError``
        when the server takes no calls)."""

    async def confirm_delivery(self) -> None:
        """Return once everything sent so far has reached the server (a
        round trip behind it), so closing now loses nothing (see
        :attr:`confirms_delivery` for how sure that is). Raises
        ``NotConnected`` when the connection is lost first (the server's
        answer never came), and may wait as long as the server is silent:
        the caller owns the deadline."""

    def fail_pending(self, error: Exception) -> None:
        """Fail every pending request with ``error``."""

    async def keepalive(self) -> None:
        """Run the transport's keep-alive until the connection closes."""

    async def aclose(self) -> None:
        """Close the connection (never raises)."""


Part = Literal["node_list", "parameters", "actions", "serving", "assets", "playback"]
"""The optional parts of an :class:`Adapter` a call may require."""

_OFFERS: Final[dict[str, str]] = {
    "node_list": "no list of ROS nodes",
    "parameters": "no parameters",
    "actions": "no actions",
    "serving": "no way to serve a service",
    "assets": "no assets (Foxglove's 'assets' capability)",
    "playback": "no playback control (Foxglove's 'playbackControl' capability)",
}
_PROTOCOL_NAMES: Final = {"foxglove-ws": "Foxglove", "rosbridge": "rosbridge", "zenoh": "Zenoh"}

P = TypeVar("P")


def require(part: P | None, name: Part, protocol: str) -> P:
    """``part`` (the adapter's attribute ``name``), or ``NotSupportedError``
    when the connection has none: the one check and the one message for
    every optional part. ``protocol`` is ``Adapter.protocol``."""
    if part is None:
        shown = _PROTOCOL_NAMES.get(protocol, protocol)
        raise NotSupportedError(f"this {shown} connection offers {_OFFERS[name]}")
    return part
