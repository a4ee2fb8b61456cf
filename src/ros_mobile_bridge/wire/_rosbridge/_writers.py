"""Writing what the client sends: the encoders of the rosbridge v2 operations
that need no engine state (``advertise``, ``call_service``, ``auth``, ...; the
engine binds them as its static methods) with the checks of the caller's
arguments (they raise ``TypeError`` / ``ValueError`` at once), and
:func:`as_text` (part of :mod:`ros_mobile_bridge.wire.rosbridge`)."""

from __future__ import annotations

import json
import math
from typing import Any

from .._limits import truncate_for_log
from .._rosbridge_auth import auth_fields

__all__ = [
    "as_text",
    "check_str",
    "dumps",
    "encode_advertise",
    "encode_advertise_service",
    "encode_auth",
    "encode_call_service",
    "encode_cancel_action_goal",
    "encode_publish",
    "encode_send_action_goal",
    "encode_service_response",
    "encode_unadvertise",
    "encode_unadvertise_service",
]


def dumps(value: Any) -> str:
    return json.dumps(value, separators=(",", ":"), allow_nan=True)


def as_text(value: Any) -> str:
    """A server value as text for an id or a message: JSON when it is JSON,
    else a bounded description (CBOR can carry bytes, tags, integers too
    long for ``str``). Never raises."""
    try:
        return dumps(value)
    except Exception:
        return truncate_for_log(value, 1000)


def check_str(name: str, value: object) -> str:
    if not isinstance(value, str) or not value:
        raise TypeError(f"{name} must be a non-empty str")
    return value


# --------------------------------------------------------------------------
# Operations (the engine's static methods)


def encode_advertise(
    topic: str, type: str, *, id: str, latch: bool = False, queue_size: int | None = None
) -> str:
    obj: dict[str, Any] = {
        "op": "advertise",
        "id": check_str("id", id),
        "topic": check_str("topic", topic),
        "type": check_str("type", type),
    }
    if latch:
        obj["latch"] = True
    if queue_size is not None:
        obj["queue_size"] = int(queue_size)
    return dumps(obj)


def encode_unadvertise(topic: str, *, id: str) -> str:
    check_str("topic", topic)
    return dumps({"op": "unadvertise", "id": check_str("id", id), "topic": topic})


def encode_publish(topic: str, msg_json: str | bytes) -> str:
    """``publish`` with ``msg_json``, the message already encoded as JSON."""
    body = msg_json.decode() if isinstance(msg_json, bytes) else msg_json
    return f'{{"op":"publish","topic":{dumps(check_str("topic", topic))},"msg":{body}}}'


def encode_call_service(
    service: str,
    args: Any,
    *,
    id: str,
    timeout: float | None = None,
    type: str | None = None,
) -> str:
    """``call_service``. ``timeout`` (seconds) must be positive: on the
    server 0 or less means wait forever, so it is refused here."""
    obj: dict[str, Any] = {
        "op": "call_service",
        "id": check_str("id", id),
        "service": check_str("service", service),
    }
    if args is not None:
        obj["args"] = args
    if type is not None:
        obj["type"] = check_str("type", type)
    if timeout is not None:
        if not (timeout > 0 and math.isfinite(timeout)):
            raise ValueError(f"timeout must be positive and finite, got {timeout!r}")
        obj["timeout"] = timeout
    return dumps(obj)


def encode_advertise_service(service: str, type: str, *, id: str) -> str:
    """``advertise_service``: this client serves ``service`` of ``type``
    (``pkg/srv/Name``); the server then forwards calls as ``call_service``
    ops (:class:`ServiceRequest`)."""
    return dumps(
        {
            "op": "advertise_service",
            "id": check_str("id", id),
            "service": check_str("service", service),
            "type": check_str("type", type),
        }
    )


def encode_unadvertise_service(service: str, *, id: str) -> str:
    return dumps(
        {
            "op": "unadvertise_service",
            "id": check_str("id", id),
            "service": check_str("service", service),
        }
    )


def encode_service_response(
    service: str, values_json: str | bytes, *, id: str, result: bool
) -> str:
    """``service_response`` to the forwarded call ``id``. ``values_json``
    is the response already encoded as JSON (``result`` True), or the
    reason as a JSON string (``result`` False)."""
    if not isinstance(result, bool):
        raise TypeError("result must be a bool")
    body = values_json.decode() if isinstance(values_json, bytes) else values_json
    head = dumps(
        {
            "op": "service_response",
            "id": check_str("id", id),
            "service": check_str("service", service),
            "result": result,
        }
    )
    return f'{head[:-1]},"values":{body}}}'


def encode_send_action_goal(
    action: str, action_type: str, args: Any, *, id: str, feedback: bool = True
) -> str:
    return dumps(
        {
            "op": "send_action_goal",
            "id": check_str("id", id),
            "action": check_str("action", action),
            "action_type": check_str("action_type", action_type),
            "args": args,
            "feedback": feedback,
        }
    )


def encode_auth(
    *, mac: str, client: str, dest: str, rand: str, t: float, level: str, end: float
) -> str:
    """``auth``: the rosbridge v2 authentication message, to be sent
    before any other operation. Sent as given (the MAC is the caller's);
    ``t`` and ``end`` (seconds) go as integers when they are whole."""
    return dumps(
        auth_fields(mac=mac, client=client, dest=dest, rand=rand, t=t, level=level, end=end)
    )


def encode_cancel_action_goal(action: str, *, id: str) -> str:
    """Cancel the goal sent with ``send_action_goal`` id ``id``."""
    return dumps(
        {
            "op": "cancel_action_goal",
            "id": check_str("id", id),
            "action": check_str("action", action),
        }
    )
