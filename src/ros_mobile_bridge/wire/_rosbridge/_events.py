"""What the rosbridge engine hands out: the :class:`Event` classes
(:class:`Publish`, :class:`ServiceResponse`, :class:`Status`, ...) that
:meth:`RosbridgeEngine.receive_text` and :meth:`RosbridgeEngine.receive_binary`
return, all frozen dataclasses, and :data:`PublishKind` (part of
:mod:`ros_mobile_bridge.wire.rosbridge`). Nothing here parses or encodes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

__all__ = [
    "ActionFeedback",
    "ActionResult",
    "Event",
    "ForeignProtocol",
    "ProtocolViolation",
    "Publish",
    "PublishKind",
    "ServiceRequest",
    "ServiceResponse",
    "Status",
]

PublishKind = Literal["json", "cbor", "cbor-raw", "parsed"]
"""How a :class:`Publish` payload is to be read: ``"json"`` / ``"cbor"``: the
whole frame (read its ``msg`` with :func:`decode_json_msg` /
:func:`decode_cbor_msg`); ``"cbor-raw"``: the CDR-serialized message;
``"parsed"``: already parsed (the frame needed a full parse), the value is in
:attr:`Publish.message`."""

# --------------------------------------------------------------------------
# Events


@dataclass(frozen=True, slots=True)
class Publish:
    """A message on a subscribed topic. ``payload`` is a view of the frame
    (see :data:`PublishKind`); ``message`` is only set for ``"parsed"``.
    ``log_time_ns`` is the bridge's stamp (``cbor-raw`` carries one)."""

    topic: str
    kind: PublishKind
    payload: memoryview
    message: Any = None
    log_time_ns: int | None = None


@dataclass(frozen=True, slots=True)
class ServiceResponse:
    """The answer to a ``call_service``. ``result`` False means the call
    failed, and ``values`` is then usually the server's error text."""

    id: str | None
    service: str
    result: bool
    values: Any


@dataclass(frozen=True, slots=True)
class ServiceRequest:
    """The server forwards a call to a service this client advertised
    (``advertise_service``): answer it with
    :meth:`RosbridgeEngine.service_response` and the same ``id``."""

    id: str
    service: str
    args: Any


@dataclass(frozen=True, slots=True)
class ActionFeedback:
    id: str | None
    action: str
    values: Any


@dataclass(frozen=True, slots=True)
class ActionResult:
    """A goal ended. ``status`` is the ``action_msgs/msg/GoalStatus`` code
    when the server sent one (4 succeeded, 5 canceled, 6 aborted)."""

    id: str | None
    action: str
    status: int | None
    result: bool
    values: Any


@dataclass(frozen=True, slots=True)
class Status:
    """A ``status`` message: the server's report about a request (``id``) or
    about the connection. ``level`` is ``"error"``, ``"warning"``, ``"info"``
    or ``"none"``."""

    level: str
    msg: str
    id: str | None


@dataclass(frozen=True, slots=True)
class ForeignProtocol:
    """The server sent a frame of another protocol (``detected``)."""

    detected: str
    reason: str


@dataclass(frozen=True, slots=True)
class ProtocolViolation:
    """A frame that could not be understood, or that the engine's bounds
    refuse; it was skipped. ``kind``: ``"invalid_utf8"``, ``"json_depth"``,
    ``"fragment_limit"`` (a fragmented message dropped by the reassembly
    bounds), else ``"malformed"``."""

    reason: str
    kind: str = "malformed"


Event = (
    Publish
    | ServiceResponse
    | ServiceRequest
    | ActionFeedback
    | ActionResult
    | Status
    | ForeignProtocol
    | ProtocolViolation
)
