"""The unit the router hands to subscriptions: one received, not yet decoded payload."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .._slots import new_object
from .._types import Message, _UnfrozenMessage

__all__ = ["Decoder", "RawFrame", "frame_message"]

Decoder = Callable[[memoryview], Any]


class RawFrame:
    """A received payload plus everything needed to decode it later.

    ``decode`` is bound to the schema of the channel that carried the frame,
    captured when it arrived, so a frame still queued after its channel was
    unadvertised or re-advertised with another schema decodes correctly.
    ``payload`` is a zero-copy view of the received WebSocket message.
    ``sequence`` is the publisher's sequence number where the wire carries
    one (rmw_zenoh's attachment), else None."""

    __slots__ = (
        "decode",
        "encoding",
        "log_time_ns",
        "payload",
        "receive_time_ns",
        "schema_name",
        "sequence",
        "topic",
    )

    def __init__(
        self,
        topic: str,
        schema_name: str,
        encoding: str,
        payload: memoryview,
        log_time_ns: int | None,
        receive_time_ns: int,
        decode: Decoder | None,
        sequence: int | None = None,
    ) -> None:
        self.topic = topic
        self.schema_name = schema_name
        self.encoding = encoding
        self.payload = payload
        self.log_time_ns = log_time_ns
        self.receive_time_ns = receive_time_ns
        self.decode = decode
        self.sequence = sequence


def frame_message(frame: RawFrame, data: Any, byte_size: int, decode_error: str | None) -> Message:
    """``frame`` delivered as a :class:`Message` holding ``data`` (decoded,
    or the payload itself), with the frame's topic, schema, encoding, times
    and sequence. ``byte_size`` is the payload's (the caller has it at
    hand). The one place a subscription builds its messages, on the
    delivery hot path: as ``_types.new_message`` does, an unfrozen twin with
    plain slot stores, then made a frozen ``Message``."""
    message: Any = new_object(_UnfrozenMessage)
    message.topic = frame.topic
    message.schema_name = frame.schema_name
    message.encoding = frame.encoding
    message.data = data
    message.receive_time_ns = frame.receive_time_ns
    message.log_time_ns = frame.log_time_ns
    message.byte_size = byte_size
    message.decode_error = decode_error
    message.sequence = frame.sequence
    message.__class__ = Message
    return message  # type: ignore[no-any-return]
