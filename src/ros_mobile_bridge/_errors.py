"""The exception hierarchy. Everything the library raises to a caller is a
:class:`RosBridgeError`, except bad arguments, which raise ``ValueError`` /
``TypeError`` at once, and cancellation. One kind of mistake or refusal is
one class, whichever call and transport meets it (docs/errors.md holds the
table)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = [
    "ActionGoalError",
    "ActionGoalLost",
    "AssetError",
    "ConnectError",
    "DecodeError",
    "MessageError",
    "NotConnected",
    "NotSupportedError",
    "ParameterError",
    "ProtocolMismatchError",
    "RosBridgeError",
    "SchemaError",
    "ServiceError",
    "ServiceTimeout",
    "connection_lost",
]


class RosBridgeError(Exception):
    """Base class of every error this library raises for a runtime failure."""


class ConnectError(RosBridgeError):
    """The connection could not be established (refused, TLS, HTTP rejection,
    timeout) or was lost. ``__cause__`` carries the underlying error."""


class ProtocolMismatchError(ConnectError):
    """The server speaks a different protocol than the one asked for.

    ``expected`` is the protocol the client asked for; ``detected`` is what the
    server appears to speak (``"foxglove-ws"``, ``"rosbridge"``) or ``None``
    when it said nothing recognisable."""

    def __init__(self, expected: str, detected: str | None, detail: str = "") -> None:
        self.expected = expected
        self.detected = detected
        self.detail = detail
        msg = f"expected a {expected} server, but the server "
        msg += f"looks like {detected}" if detected else "did not speak it"
        if detail:
            msg += f": {detail}"
        super().__init__(msg)


class NotConnected(RosBridgeError):
    """The operation needs a live connection and there is none (closed, or lost).

    A service call, action goal or parameter operation in flight when the
    connection is lost raises it at the loss, saying ``"the connection was
    lost: <why>"``, whether or not the client then reconnects (the request
    was lost with the connection; send it again once ``status`` is
    ``"connected"``)."""


def connection_lost(why: object) -> NotConnected:
    """The :class:`NotConnected` every request cut off by a lost connection
    raises: ``"the connection was lost: <why>"``."""
    return NotConnected(f"the connection was lost: {why}")


class NotSupportedError(RosBridgeError):
    """The server (or this transport) does not offer the requested capability."""


class ServiceError(RosBridgeError):
    """A service call failed on the server side. ``service`` names it and
    ``reason`` carries the server's own text."""

    def __init__(self, service: str, reason: str) -> None:
        self.service = service
        self.reason = reason
        super().__init__(f"service {service!r} failed: {reason}")


class ServiceTimeout(ServiceError, TimeoutError):
    """A service call got no answer before its deadline: the local one, or
    the server's own (rosbridge forwards the timeout; ``detail`` then holds
    the server's words)."""

    def __init__(self, service: str, timeout: float, detail: str = "") -> None:
        self.timeout = timeout
        text = f"no response within {timeout:g} s"
        super().__init__(service, f"{text} ({detail})" if detail else text)


class AssetError(RosBridgeError):
    """The server could not give the asset ``uri``; ``reason`` carries the
    server's own text."""

    def __init__(self, uri: str, reason: str) -> None:
        self.uri = uri
        self.reason = reason
        super().__init__(f"asset {uri!r} could not be fetched: {reason}")


class ActionGoalError(RosBridgeError):
    """An action goal was rejected, aborted, or lost; ``reason`` says which."""

    def __init__(self, action: str, reason: str) -> None:
        self.action = action
        self.reason = reason
        super().__init__(f"action {action!r} goal failed: {reason}")


class ActionGoalLost(ActionGoalError, NotConnected):
    """An action goal cut off by a lost connection: both an
    :class:`ActionGoalError` (``reason`` ``"disconnected"``) and a
    :class:`NotConnected`; its message says the connection was lost and
    why. The goal may still run on the robot: this client can no longer
    follow or cancel it."""

    def __init__(self, action: str, error: RosBridgeError) -> None:
        super().__init__(action, "disconnected")
        self.args = (f"action {action!r} goal failed: {error}",)


class DecodeError(RosBridgeError):
    """A payload could not be decoded or encoded with its schema."""


class SchemaError(DecodeError):
    """A schema definition could not be parsed, or a type name is unknown.

    ``failures`` maps each node that was asked for the type's description
    (over Zenoh, REP-2011 ``get_type_description``) and did not give it to
    why (no answer in time, a refusal with its reason, a description whose
    hash differs); empty when no node was asked."""

    def __init__(self, *args: object, failures: Mapping[str, str] | None = None) -> None:
        super().__init__(*args)
        self.failures: dict[str, str] = dict(failures or {})


class MessageError(DecodeError, ValueError):
    """A message, service request, action goal or service reply does not
    fit its type: an unknown field, a value of the wrong type, a number out
    of its field's range. Raised before anything is sent, by ``publish``,
    ``call_service``, ``send_action_goal`` and a served request's ``reply``,
    on every transport.

    ``type_name`` is the ROS type, ``field`` the dotted path of the field
    (``"linear.x"``; ``None`` when the whole value is wrong), ``reason``
    what is wrong, ``call`` the call that met it (``"publish /cmd_vel"``;
    empty where it was raised outside a call, by a class's constructor for
    instance: the text then reads ``invalid <type>: ...``). A :class:`DecodeError`
    and a ``ValueError``, so both older ``except`` clauses still catch it."""

    def __init__(
        self, type_name: str, reason: str, field: str | None = None, call: str = ""
    ) -> None:
        self.type_name = type_name
        self.reason = reason
        self.field = field
        self.call = call
        # in a call the value was to be sent; outside one (a class's
        # constructor, from_dict) it was only built
        text = f"{call}: cannot encode {type_name}: " if call else f"invalid {type_name}: "
        text += f"field {field!r}: {reason}" if field else reason
        super().__init__(text)

    def in_call(self, call: str) -> MessageError:
        """The same error, naming ``call`` (the front adds it)."""
        return MessageError(self.type_name, self.reason, self.field, call)


class ParameterError(RosBridgeError):
    """The robot refused to set some parameters, or does not have them.

    ``reasons`` maps each failed name to why: the robot's own text where the
    transport gives one (rcl's ``SetParametersResult.reason`` over Zenoh and
    rosbridge), ``"not found"`` (with the nearest names the robot has) for
    a name it does not have, and over Foxglove, whose protocol carries no
    reason, what the robot kept. ``values`` holds what the robot reports
    for the names asked about after the call (for ``set_parameters``: the
    names it accepted hold their new values: every accepted value is
    applied, the refusals change nothing)."""

    def __init__(self, reasons: Mapping[str, str], values: Mapping[str, Any] | None = None) -> None:
        self.reasons = dict(reasons)
        self.values = dict(values or {})
        text = "; ".join(f"{name!r}: {why}" for name, why in self.reasons.items())
        many = "parameters" if len(self.reasons) > 1 else "parameter"
        super().__init__(f"{many} {text}")
