"""Client configuration."""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import re
import ssl
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final

from ._checks import check_interface_paths
from ._errors import ConnectError
from ._zenoh_options import ZenohSecurity, check_zenoh_config, describe_zenoh_config
from .flow._breaker import CircuitBreaker
from .flow._throttle import THROTTLE_MODES, Bucket, ThrottleMode
from .wire._rosbridge_auth import auth_fields

if TYPE_CHECKING:
    import httpx

__all__ = ["BreakerPolicy", "ClientOptions", "ReconnectPolicy", "RosbridgeAuth"]

_TOKEN: Final = re.compile(r"^[!#$%&'*+\-.^_`|~0-9A-Za-z]+$")
"""An HTTP header name (RFC 9110 ``token``); used with ``fullmatch`` (``$``
alone would let a trailing newline through)."""
_FIELD_VALUE: Final = re.compile(r"[\t\x20-\x7e]*")
"""What a header value may hold (RFC 9110 field-value, ASCII only): tab and
visible ASCII with spaces; no other control character (CR, LF, NUL, \\x01,
DEL...) and no non-ASCII text."""
_HANDSHAKE_HEADERS: Final = frozenset(
    {
        "host",
        "upgrade",
        "connection",
        "content-length",
        "transfer-encoding",
        "sec-websocket-key",
        "sec-websocket-version",
        "sec-websocket-accept",
        "sec-websocket-protocol",
        "sec-websocket-extensions",
    }
)
"""Headers the WebSocket handshake sets itself: a caller may not set them."""
_REDACTED: Final = "<redacted>"

CLOSE_SLACK_S: Final = 5.0
"""Added to :attr:`ClientOptions.teardown_timeout` by a close that waits from
outside the client's own task (``SyncClient.close``, ``ClientHandle.aclose``):
the teardown's own deadline, then closing the socket, then ending the task
(and, for the sync client, its event loop)."""


def _check_headers(value: object) -> tuple[tuple[str, str], ...]:
    """``value`` (a mapping or ``(name, value)`` pairs) as a tuple of pairs,
    or ``TypeError`` / ``ValueError`` naming the bad header (never its
    value: it may be a secret)."""
    if isinstance(value, str | bytes):
        raise TypeError("headers must be a mapping or (name, value) pairs, not a str")
    pairs: Iterable[Any]
    if isinstance(value, Mapping):
        pairs = value.items()
    elif isinstance(value, Iterable):
        pairs = value
    else:
        raise TypeError(f"headers must be a mapping or (name, value) pairs, not {value!r}")
    checked: list[tuple[str, str]] = []
    for pair in pairs:
        if not (isinstance(pair, tuple) and len(pair) == 2):
            raise TypeError("headers must be (name, value) pairs of str")
        name, text = pair
        if not isinstance(name, str) or not isinstance(text, str):
            raise TypeError(f"header names and values must be str (header {name!r})")
        if not _TOKEN.fullmatch(name):
            raise ValueError(f"invalid header name {name!r}")
        if name.lower() in _HANDSHAKE_HEADERS:
            raise ValueError(
                f"header {name!r} is set by the WebSocket handshake itself and cannot be "
                "overridden (subprotocols are chosen by the protocol)"
            )
        if not _FIELD_VALUE.fullmatch(text):
            raise ValueError(
                f"header {name!r}: the value may hold only tab and visible ASCII with spaces"
                " (0x20-0x7E): no CR, LF, NUL or other control character, no non-ASCII text"
                " (its value is not shown: it may be a secret)"
            )
        if text != text.strip(" \t"):
            raise ValueError(f"header {name!r}: the value must not start or end with whitespace")
        checked.append((name, text))
    return tuple(checked)


@dataclass(frozen=True, slots=True, repr=False)
class RosbridgeAuth:
    """The rosbridge v2 ``auth`` operation, sent as the first message of
    every rosbridge connection (reconnections included) when set in
    :attr:`ClientOptions.rosbridge_auth`.

    The fields are the protocol's: ``mac`` the message authentication code
    the robot's authenticator (``rosauth``) checks, computed by the caller
    from a shared secret and the other fields; ``client`` and ``dest`` the
    client's and the server's addresses; ``rand`` a random string; ``t``
    the request time and ``end`` the session's end (seconds since the
    epoch); ``level`` the user level. The library sends them as given and
    computes nothing. The protocol has no answer to ``auth``: what a server
    that checks it does with a wrong MAC (ignore the client, close the
    connection) is its own choice. ``mac`` never appears in ``repr``."""

    mac: str
    client: str
    dest: str
    rand: str
    t: float
    level: str
    end: float

    def __post_init__(self) -> None:
        auth_fields(
            mac=self.mac, client=self.client, dest=self.dest, rand=self.rand,
            t=self.t, level=self.level, end=self.end, owner="RosbridgeAuth.",
        )  # fmt: skip

    def __repr__(self) -> str:
        return (
            f"RosbridgeAuth(mac={_REDACTED!r}, client={self.client!r}, dest={self.dest!r}, "
            f"rand={self.rand!r}, t={self.t!r}, level={self.level!r}, end={self.end!r})"
        )


def _positive(name: str, value: object, *, allow_zero: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TypeError(f"{name} must be a number, not {type(value).__name__}")
    if math.isnan(value) or value < 0 or (value == 0 and not allow_zero):
        raise ValueError(f"{name} must be {'>= 0' if allow_zero else '> 0'}, got {value!r}")


def _count(name: str, value: object, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{name} must be an int, not {type(value).__name__}")
    if value < minimum:
        raise ValueError(f"{name} must be at least {minimum}, got {value!r}")


@dataclass(frozen=True, slots=True)
class ReconnectPolicy:
    """How a client re-establishes a connection it lost.

    Only a connection that was once established is retried: the first
    ``connect()`` fails at once. The n-th attempt waits
    ``min(max_delay, initial_delay * multiplier ** (n - 1))`` seconds,
    spread by ``jitter`` (a fraction: 0.2 means +/- 20 %).
    ``max_attempts=None`` retries until the client is closed."""

    initial_delay: float = 0.5
    max_delay: float = 10.0
    multiplier: float = 2.0
    jitter: float = 0.2
    max_attempts: int | None = None

    def __post_init__(self) -> None:
        _positive("initial_delay", self.initial_delay, allow_zero=True)
        _positive("max_delay", self.max_delay, allow_zero=True)
        _positive("multiplier", self.multiplier)
        _positive("jitter", self.jitter, allow_zero=True)
        if self.multiplier < 1:
            raise ValueError(f"multiplier must be >= 1, got {self.multiplier!r}")
        if self.jitter >= 1:
            raise ValueError(f"jitter must be below 1, got {self.jitter!r}")
        if self.max_delay < self.initial_delay:
            raise ValueError("max_delay must not be below initial_delay")
        if self.max_attempts is not None and (
            isinstance(self.max_attempts, bool)
            or not isinstance(self.max_attempts, int)
            or self.max_attempts < 1
        ):
            raise ValueError(
                f"max_attempts must be a positive int or None, got {self.max_attempts!r}"
            )

    def delay(self, attempt: int, random: Callable[[], float]) -> float:
        """Seconds to wait before attempt number ``attempt`` (1-based);
        ``random`` returns a float in [0, 1)."""
        base = min(self.max_delay, self.initial_delay * self.multiplier ** (attempt - 1))
        return max(0.0, base * (1.0 + self.jitter * (2.0 * random() - 1.0)))


@dataclass(frozen=True, slots=True)
class BreakerPolicy:
    """When a subscription's circuit breaker trips and how long it rests.

    It trips when, after ``warmup_s``, the event loop's lag has stayed at or
    above ``saturation_ms`` for ``dwell_s`` while the adaptive throttle sat
    at its deepest bucket. It then waits the next of ``cooldowns_s`` (the
    last repeats; the ladder restarts with each new connection), goes
    half-open, and closes after ``probe_s`` without saturation."""

    cooldowns_s: tuple[float, ...] = (30.0, 60.0, 120.0, 300.0)
    saturation_ms: float = 250.0
    dwell_s: float = 3.0
    warmup_s: float = 5.0
    probe_s: float = 5.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "cooldowns_s", tuple(self.cooldowns_s))
        self.build()  # validates every value

    def build(self) -> CircuitBreaker:
        """A breaker following this policy."""
        return CircuitBreaker(
            cooldowns_s=self.cooldowns_s,
            saturation_ms=self.saturation_ms,
            dwell_s=self.dwell_s,
            warmup_s=self.warmup_s,
            probe_s=self.probe_s,
        )


@dataclass(frozen=True, slots=True, repr=False)
class ClientOptions:
    """Everything about a connection that is not the target.

    Every field has a safe default; invalid values raise ``ValueError`` or
    ``TypeError`` when the options are built, never later. ``repr`` shows
    header names but never their values, nor a rosbridge ``auth`` MAC, a
    Zenoh password or Zenoh JSON5 configuration text."""

    connect_timeout: float = 10.0
    """Seconds for TCP connect, TLS, the WebSocket upgrade and the server's
    greeting (Foxglove ``serverInfo``) together."""
    discovery_grace: float = 0.2
    """After the greeting, how long ``connect()`` waits for the first topic
    and service advertisements, so ``client.topics`` is filled on entry. A
    server with nothing to advertise sends nothing: this bounds that wait."""
    max_frame_size: int = 64 * 1024 * 1024
    """Largest inbound message in bytes. A larger one closes the connection
    with a clear error (raw 1080p images need about 6 MiB)."""
    read_coalesce: float = 0.004
    """Foxglove and rosbridge: seconds a read may wait under a steady stream
    of small messages, so the frames that arrive meanwhile are read and
    handed to the consumers at one wake-up instead of one each. Starts when
    two reads come less than this apart, and stays on while each wait
    gathers more than one message and reads stay under 64 KiB; a message
    then reaches ``async for`` at most this much later (a service reply
    arriving within the stream too). Sporadic messages, streams slower than
    the window and saturated sockets are read as they arrive. 0 reads every
    frame as it arrives. At most 0.1."""
    keepalive_interval: float = 10.0
    """Seconds between WebSocket pings (0 disables keep-alive)."""
    keepalive_timeout: float = 10.0
    """Seconds to wait for a pong before the connection is declared lost."""
    service_timeout: float = 10.0
    """Default deadline of ``call_service`` and parameter requests, seconds."""
    teardown_timeout: float = 2.0
    """Deadline of the whole teardown (flush, zero Twist, close), seconds."""
    advertise_settle: float = 0.15
    """Pause after a new client advertisement before its first publish, so
    the bridge has its publisher ready. ``advertise()`` ahead of time takes
    it out of the hot path."""
    stop_topics: Sequence[str] = ()
    """Velocity topics that get a zero Twist on teardown even if this client
    never published to them."""
    zero_twist_on_exit: bool = True
    """Send the zero Twist on teardown (strongly recommended)."""
    subscription_buffer: int = 1024
    """Default per-subscription queue length (``dispatch="all"``). The queue
    is also bounded to 64 MiB of payload; past either bound the oldest frame
    is dropped (undecoded, counted)."""
    ssl_context: ssl.SSLContext | None = None
    """TLS settings for ``wss://`` (a private CA, a client certificate);
    the system defaults when None. A context that does not trust the
    server's certificate fails ``connect()`` with ``ConnectError``."""
    headers: Mapping[str, str] | Sequence[tuple[str, str]] = ()
    """Extra HTTP headers of the WebSocket handshake (Foxglove and
    rosbridge), e.g. ``{"Authorization": "Bearer ..."}`` for a reverse
    proxy. Stored as a tuple of ``(name, value)`` pairs. A name that is not
    an HTTP token, one the handshake sets itself (``Host``, ``Upgrade``,
    ``Connection``, ``Sec-WebSocket-*``), or a value with anything but tab
    and visible ASCII with spaces (CR, LF, NUL, any other control
    character, non-ASCII text) raises ``ValueError`` here, naming the
    header, never its value. Values are never logged (websockets' debug log
    is silenced for a connection with headers) nor shown in ``repr``."""
    rosbridge_auth: RosbridgeAuth | Callable[[], RosbridgeAuth] | None = None
    """rosbridge: the ``auth`` operation sent first on every connection, or
    a callable returning a fresh one per connection (a MAC is usually bound
    to a time and a random string). A callable that raises or returns
    something else fails that connection attempt with ``ConnectError`` (its
    error chained, not quoted): the first ``connect()`` raises it, a
    reconnection is retried under :attr:`reconnect`. ``repr`` shows a
    callable as ``<callable>``; websockets' debug log (which would print the
    start of the ``auth`` frame, MAC included) is silenced for a connection
    with ``auth``."""
    http_client: httpx.AsyncClient | None = None
    """Open the WebSocket (Foxglove and rosbridge) through this
    ``httpx.AsyncClient`` (``pip install ros-mobile-bridge[httpx]``): its
    proxies, auth, cookies, default headers, TLS settings and transport make
    the HTTP upgrade, then the library's own WebSocket engine runs on the
    upgraded connection. The caller keeps the client open for the whole
    session and closes it. Not with :attr:`ssl_context` (TLS is the
    client's: ``httpx.AsyncClient(verify=ctx)``). HTTP/1.1 only."""
    logger: logging.Logger = field(default_factory=lambda: logging.getLogger("ros_mobile_bridge"))
    """Where the library logs skipped frames, decode failures and teardown."""
    throttle_mode: ThrottleMode | Callable[[], ThrottleMode] = "auto"
    """The adaptive throttle's curve: ``"performance"``, ``"auto"`` or
    ``"efficient"``, or a callable read as messages arrive, so a settings
    change applies from the next message (under a cap, from the end of the
    current window)."""
    preset_overrides: Mapping[str, Sequence[Bucket | tuple[float, float, str]]] | None = None
    """Replacement curves per mode (``(threshold_ms, min_interval_ms,
    label)`` buckets). A curve that fails validation is logged and that
    mode keeps its default (:data:`DEFAULT_PRESETS`); an unknown mode name
    raises ``ValueError``."""
    breaker: BreakerPolicy | None = field(default_factory=BreakerPolicy)
    """The per-subscription circuit breaker; ``None`` never trips it
    automatically (``retry()`` / ``disable()`` still work)."""
    reconnect: ReconnectPolicy | None = field(default_factory=ReconnectPolicy)
    """How to re-establish a lost connection; ``None`` disables reconnecting
    (a lost connection then ends in status ``"error"``)."""
    on_latency: Callable[[float], None] | None = None
    """Called with the round-trip time in milliseconds of every correlated
    request/response (service calls, parameter requests) and of the idle
    probe (Foxglove: WebSocket ping; rosbridge: ``/rosapi/get_time``)."""
    unknown_topic_warning: float | None = 3.0
    """Seconds after which a subscription to a topic the robot does not
    offer (and that delivered nothing) logs one WARNING naming the nearest
    offered names; ``None`` never warns. The subscription keeps waiting:
    the topic may still come."""
    discovery_interval: float = 2.0
    """rosbridge: seconds between polls of ``/rosapi/topics`` and
    ``/rosapi/services`` (the server announces nothing by itself)."""
    latency_probe_interval: float = 5.0
    """rosbridge: seconds between ``/rosapi/get_time`` latency probes (0
    disables; the first failure turns the probe off)."""
    fragment_timeout: float = 10.0
    """rosbridge: seconds a fragmented message may take to arrive whole
    before its parts are dropped (a ``"fragment_limit"`` rejection)."""
    max_json_depth: int = 100
    """Deepest nesting of arrays and objects in one inbound JSON frame
    (Foxglove control messages, rosbridge operations). A deeper frame is
    skipped unparsed: a ``"json_depth"`` rejection."""
    max_channels: int = 10_000
    """Foxglove: server channels kept per connection, and names kept per
    table of its connection graph (rosbridge: topics kept from one discovery
    poll). Channels beyond it are refused, counted once per advertisement
    (or graph update) as a ``"channel_limit"`` rejection."""
    max_services: int = 10_000
    """Services kept per connection; beyond it a ``"service_limit"``
    rejection, once per advertisement (or discovery poll)."""
    max_schema_size: int = 256 * 1024
    """Foxglove: bytes of one channel schema text. A longer schema is
    dropped (the channel stays, its messages decode with a bundled
    definition of that type if there is one, else arrive raw): a
    ``"schema_too_large"`` rejection naming the channel."""
    max_schema_fields: int = 500
    """Fields of one schema, summed over every definition it holds. Building
    a decoder costs about 0.2 ms per field (rosbags generates and compiles
    code per type, much of it holding the GIL); past this the schema is
    refused like one over ``max_schema_size``."""
    max_pending_requests: int = 256
    """Service calls, parameter requests and action goals waiting for an
    answer on one connection. One more raises at once (``ServiceError`` for
    a call or parameter request, ``ActionGoalError`` for a goal)."""
    domain_id: int | None = None
    """Zenoh: the ROS domain (0-232) whose graph and data this client sees.
    None: ``$ROS_DOMAIN_ID`` when set to a valid id, else 0."""
    zenoh_shared_memory: bool = False
    """Zenoh: let the session use shared memory with peers on the same host
    (off by default, as rmw_zenoh configures its sessions)."""
    zenoh_security: ZenohSecurity | None = None
    """Zenoh: TLS trust, a client certificate (mutual TLS) and user/password
    authentication of the link (:class:`ZenohSecurity`); a ``tls/host:port``
    target needs no more when the router's certificate is signed by a
    public CA. Its password is never shown (docs/zenoh.md, "Secure links")."""
    zenoh_config: str | os.PathLike[str] | None = None
    """Zenoh: a Zenoh configuration to start from, as a file path (JSON5,
    JSON or YAML, the file rmw_zenoh reads from ``ZENOH_SESSION_CONFIG_URI``)
    or as JSON5 text (a ``str`` starting with ``{``). Read when the session
    opens; the library then sets ``mode`` (client), ``connect/endpoints``
    (the target), ``connect/timeout_ms``, scouting (off), shared memory
    (:attr:`zenoh_shared_memory`) and each field of
    :attr:`zenoh_security` that is set; every other key keeps the
    configuration's value. ``repr`` shows JSON5 text by its length only."""
    zenoh_backlog: int = 8192
    """Zenoh: samples that may wait between zenoh's threads and the reader
    task. Past it (or past :attr:`zenoh_backlog_bytes`) a sample is dropped
    before any subscription sees it: a ``"backlog_overflow"`` rejection."""
    zenoh_backlog_bytes: int = 64 * 1024 * 1024
    """Zenoh: payload bytes that may wait between zenoh's threads and the
    reader task (one sample larger than this still passes alone)."""
    type_description_timeout: float = 3.0
    """Zenoh: seconds a node may take to answer ``get_type_description``
    (REP-2011) when this client asks it for a type it does not know. Past
    it the type is unknown for this connection: a ``SchemaError`` naming
    the type and the node for a call, raw messages for a subscription."""
    type_description_hold: int = 256
    """Zenoh: samples of one topic held while its type's description is
    being fetched, decoded in order once it arrives. Past it a sample is
    dropped: a ``"description_hold_overflow"`` rejection."""
    interface_paths: Sequence[str | os.PathLike[str]] = ()
    """Local directories whose interface files (``.msg``, ``.srv``,
    ``.action``) the codec knows, for your own packages: an install prefix
    (``install/`` of a colcon workspace, ``/opt/ros/jazzy``: it has
    ``share/<pkg>/msg/...``), a ``share`` directory, or a package's source
    directory (``package.xml`` beside ``msg/``). A local definition wins
    over a bundled one, an earlier path over a later one; a server's schema
    wins over both. Read lazily and once per process,
    at most 20,000 files and 16 MiB of text (what is skipped is logged and
    counted). ``TypeError`` at construction for an entry that is not a
    path (docs/interfaces.md)."""
    ament_prefix_path: bool = True
    """Also search the prefixes ``$AMENT_PREFIX_PATH`` lists (a sourced ROS
    or workspace setup), after :attr:`interface_paths`."""

    def report_latency(self, ms: float) -> None:
        """Hand one round-trip time to :attr:`on_latency`; a failing callback
        is logged, never raised."""
        callback = self.on_latency
        if callback is not None:
            try:
                callback(ms)
            except Exception:
                self.logger.exception("on_latency callback failed")

    def __post_init__(self) -> None:
        _positive("connect_timeout", self.connect_timeout)
        _positive("discovery_grace", self.discovery_grace, allow_zero=True)
        _positive("keepalive_interval", self.keepalive_interval, allow_zero=True)
        _positive("read_coalesce", self.read_coalesce, allow_zero=True)
        if self.read_coalesce > 0.1:
            raise ValueError(f"read_coalesce must be at most 0.1 s, got {self.read_coalesce!r}")
        _positive("keepalive_timeout", self.keepalive_timeout)
        _positive("service_timeout", self.service_timeout)
        _positive("teardown_timeout", self.teardown_timeout)
        _positive("advertise_settle", self.advertise_settle, allow_zero=True)
        _positive("discovery_interval", self.discovery_interval)
        if self.unknown_topic_warning is not None:
            _positive("unknown_topic_warning", self.unknown_topic_warning)
        _positive("latency_probe_interval", self.latency_probe_interval, allow_zero=True)
        _positive("fragment_timeout", self.fragment_timeout)
        if isinstance(self.max_frame_size, bool) or not isinstance(self.max_frame_size, int):
            raise TypeError("max_frame_size must be an int")
        if self.max_frame_size < 1024:
            raise ValueError("max_frame_size must be at least 1024 bytes")
        _count("subscription_buffer", self.subscription_buffer, 1)
        _count("max_json_depth", self.max_json_depth, 2)
        _count("max_channels", self.max_channels, 1)
        _count("max_services", self.max_services, 1)
        _count("max_schema_size", self.max_schema_size, 64)
        _count("max_schema_fields", self.max_schema_fields, 1)
        _count("max_pending_requests", self.max_pending_requests, 1)
        if self.domain_id is not None:
            _count("domain_id", self.domain_id, 0)
            if self.domain_id > 232:
                raise ValueError(f"domain_id must be 0-232, got {self.domain_id!r}")
        if not isinstance(self.zenoh_shared_memory, bool):
            raise TypeError("zenoh_shared_memory must be a bool")
        if self.zenoh_security is not None and not isinstance(self.zenoh_security, ZenohSecurity):
            raise TypeError("zenoh_security must be a ZenohSecurity or None")
        check_zenoh_config(self.zenoh_config)
        _count("zenoh_backlog", self.zenoh_backlog, 1)
        _count("zenoh_backlog_bytes", self.zenoh_backlog_bytes, 1024)
        _positive("type_description_timeout", self.type_description_timeout)
        if math.isinf(self.type_description_timeout):
            raise ValueError("type_description_timeout must be finite")
        _count("type_description_hold", self.type_description_hold, 1)
        object.__setattr__(self, "interface_paths", check_interface_paths(self.interface_paths))
        if not isinstance(self.ament_prefix_path, bool):
            raise TypeError("ament_prefix_path must be a bool")
        if isinstance(self.stop_topics, str):
            raise TypeError("stop_topics must be a sequence of topic names, not a str")
        object.__setattr__(self, "stop_topics", tuple(self.stop_topics))
        for topic in self.stop_topics:
            if not isinstance(topic, str) or not topic.startswith("/"):
                raise ValueError(f"stop_topics entries must be absolute topic names, got {topic!r}")
        if not callable(self.throttle_mode) and self.throttle_mode not in THROTTLE_MODES:
            raise ValueError(
                f"throttle_mode must be one of {', '.join(THROTTLE_MODES)} or a callable, "
                f"got {self.throttle_mode!r}"
            )
        if self.breaker is not None and not isinstance(self.breaker, BreakerPolicy):
            raise TypeError("breaker must be a BreakerPolicy or None")
        if self.reconnect is not None and not isinstance(self.reconnect, ReconnectPolicy):
            raise TypeError("reconnect must be a ReconnectPolicy or None")
        if not isinstance(self.zero_twist_on_exit, bool):
            raise TypeError("zero_twist_on_exit must be a bool")
        if self.ssl_context is not None and not isinstance(self.ssl_context, ssl.SSLContext):
            raise TypeError("ssl_context must be an ssl.SSLContext or None")
        if not isinstance(self.logger, logging.Logger):
            raise TypeError("logger must be a logging.Logger")
        if self.on_latency is not None and not callable(self.on_latency):
            raise TypeError("on_latency must be callable")
        object.__setattr__(self, "headers", _check_headers(self.headers))
        auth = self.rosbridge_auth
        if auth is not None and not isinstance(auth, RosbridgeAuth) and not callable(auth):
            raise TypeError("rosbridge_auth must be a RosbridgeAuth, a callable or None")
        if self.http_client is not None:
            _check_http_client(self.http_client)
            if self.ssl_context is not None:
                raise ValueError(
                    "ssl_context does not apply with http_client: TLS is the client's own "
                    "(httpx.AsyncClient(verify=ssl_context))"
                )

    def __repr__(self) -> str:
        parts = []
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "headers":
                text = repr(tuple((name, _REDACTED) for name, _ in value))
            elif f.name == "rosbridge_auth" and callable(value):
                text = "<callable>"  # a partial(make_auth, secret=...) would show the secret
            elif f.name == "zenoh_config":
                text = describe_zenoh_config(value)  # JSON5 text may hold a password
            else:
                text = repr(value)
            parts.append(f"{f.name}={text}")
        return f"ClientOptions({', '.join(parts)})"

    def auth_message(self) -> RosbridgeAuth | None:
        """The rosbridge ``auth`` to send on a new connection (calling
        :attr:`rosbridge_auth` when it is a callable), or None. A callable
        that fails or returns something else raises ``ConnectError``: that
        connection attempt fails (a reconnection is retried under
        :attr:`reconnect`). The callable's own error is chained as
        ``__cause__``, never copied into the message (it may hold a secret)."""
        auth = self.rosbridge_auth
        if auth is None or isinstance(auth, RosbridgeAuth):
            return auth
        try:
            made = auth()
        except Exception as exc:
            raise ConnectError(
                f"rosbridge_auth callable failed with {type(exc).__name__}"
                " (its message is not shown: see __cause__)"
            ) from exc
        if not isinstance(made, RosbridgeAuth):
            raise ConnectError(
                f"rosbridge_auth callable returned {type(made).__name__}, not RosbridgeAuth"
            )
        return made


HTTPX_MISSING: Final = (
    "the httpx transport (ClientOptions.http_client) needs httpx: "
    "pip install 'ros-mobile-bridge[httpx]'"
)


def import_httpx() -> Any:
    """The ``httpx`` module, or ``ImportError`` saying how to install it."""
    try:
        import httpx
    except ImportError as exc:
        raise ImportError(HTTPX_MISSING) from exc
    return httpx


def _check_http_client(client: object) -> None:
    """``TypeError`` unless ``client`` is an open ``httpx.AsyncClient``
    (httpx is imported only here, when a client was given)."""
    httpx = import_httpx()
    if not isinstance(client, httpx.AsyncClient):
        raise TypeError(f"http_client must be an httpx.AsyncClient, not {type(client).__name__}")
    if client.is_closed:
        raise ValueError("http_client is closed")
