"""The unit the router hands to subscriptions: one received, not yet decoded payload."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["Decoder", "RawFrame"]

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
