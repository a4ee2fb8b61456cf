"""The Foxglove WebSocket protocol's constants: the subprotocols the engine
speaks, the schema encodings legacy channels imply, the binary opcodes and
the binary frame headers. Shared by the readers, the writers and the engine
(part of :mod:`ros_mobile_bridge.wire.foxglove`)."""

from __future__ import annotations

from collections.abc import Mapping
from struct import Struct
from types import MappingProxyType
from typing import Final

__all__ = [
    "BINARY_NAMES",
    "CLIENT_MESSAGE_HEADER",
    "DEFAULT_SCHEMA_ENCODINGS",
    "FETCH_ASSET_HEADER",
    "MESSAGE_DATA_HEADER",
    "MESSAGE_DATA_PAYLOAD_AT",
    "OP_CLIENT_MESSAGE_DATA",
    "OP_FETCH_ASSET_RESPONSE",
    "OP_MESSAGE_DATA",
    "OP_PLAYBACK_CONTROL_REQUEST",
    "OP_PLAYBACK_STATE",
    "OP_SERVICE_CALL_REQUEST",
    "OP_SERVICE_CALL_RESPONSE",
    "OP_TIME",
    "PLAYBACK_REQUEST_HEADER",
    "PLAYBACK_STATE_HEADER",
    "SERVICE_REQUEST_HEADER",
    "SERVICE_RESPONSE_HEADER",
    "SUBPROTOCOLS",
    "TIME",
    "U32_MAX",
]

SUBPROTOCOLS: Final[tuple[str, ...]] = (
    "foxglove.sdk.v1.1",
    "foxglove.sdk.v1",
    "foxglove.websocket.v1",
)
"""The WebSocket subprotocols this engine speaks, newest first: offer them in
this order during the handshake and pass the negotiated one to
:class:`FoxgloveEngine`."""

DEFAULT_SCHEMA_ENCODINGS: Final[Mapping[str, str]] = MappingProxyType(
    {
        "cdr": "ros2msg",
        "protobuf": "protobuf",
        "json": "jsonschema",
        "ros1": "ros1msg",
        "flatbuffer": "flatbuffer",
    }
)
"""The schema encoding implied by a message encoding when a legacy channel
omits ``schemaEncoding``."""

U32_MAX: Final = 0xFFFF_FFFF

# Binary opcodes, server -> client.
OP_MESSAGE_DATA: Final = 0x01
OP_TIME: Final = 0x02
OP_SERVICE_CALL_RESPONSE: Final = 0x03
OP_FETCH_ASSET_RESPONSE: Final = 0x04
OP_PLAYBACK_STATE: Final = 0x05

# Binary opcodes, client -> server.
OP_CLIENT_MESSAGE_DATA: Final = 0x01
OP_SERVICE_CALL_REQUEST: Final = 0x02
OP_PLAYBACK_CONTROL_REQUEST: Final = 0x03  # foxglove.sdk, the playbackControl capability

# Headers, read after the 1-byte opcode (offset 1).
MESSAGE_DATA_HEADER: Final = Struct("<IQ")  # subscription id, log time ns
MESSAGE_DATA_PAYLOAD_AT: Final = 1 + MESSAGE_DATA_HEADER.size  # 13
TIME: Final = Struct("<Q")
SERVICE_RESPONSE_HEADER: Final = Struct("<III")  # service id, call id, encoding length
FETCH_ASSET_HEADER: Final = Struct("<IBI")  # request id, status, error length
PLAYBACK_STATE_HEADER: Final = Struct("<BQfBI")  # status, time ns, speed, did seek, id length
# Written whole, opcode included.
CLIENT_MESSAGE_HEADER: Final = Struct("<BI")
SERVICE_REQUEST_HEADER: Final = Struct("<BIII")
# opcode, command (0 play, 1 pause), speed, has seek, seek time ns, request id length
PLAYBACK_REQUEST_HEADER: Final = Struct("<BBfBQI")

BINARY_NAMES: Final[Mapping[int, str]] = MappingProxyType(
    {
        OP_MESSAGE_DATA: "message data",
        OP_TIME: "time",
        OP_SERVICE_CALL_RESPONSE: "service call response",
        OP_FETCH_ASSET_RESPONSE: "fetch asset response",
        OP_PLAYBACK_STATE: "playback state",
    }
)
