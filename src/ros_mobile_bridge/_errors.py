"""The exception hierarchy. Everything the library raises to a caller is a
:class:`RosBridgeError`, except bad arguments, which raise ``ValueError`` /
``TypeError`` at once, and cancellation."""

from __future__ import annotations

__all__ = [
    "ActionGoalError",
    "ConnectError",
    "DecodeError",
    "NotConnected",
    "NotSupportedError",
    "ProtocolMismatchError",
    "RosBridgeError",
    "SchemaError",
    "ServiceError",
    "ServiceTimeout",
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
    """The operation needs a live connection and there is none (closed, or lost)."""


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


class ActionGoalError(RosBridgeError):
    """An action goal was rejected, aborted, or lost; ``reason`` says which."""

    def __init__(self, action: str, reason: str) -> None:
        self.action = action
        self.reason = reason
        super().__init__(f"action {action!r} goal failed: {reason}")


class DecodeError(RosBridgeError):
    """A payload could not be decoded or encoded with its schema."""


class SchemaError(DecodeError):
    """A schema definition could not be parsed, or a type name is unknown."""
