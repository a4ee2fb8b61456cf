"""A sans-IO engine for the Foxglove WebSocket protocol (client side).

No sockets, no event loop, no threads: the caller owns the WebSocket and

* feeds every text frame the server sends to :meth:`FoxgloveEngine.receive_text`
  and every binary frame to :meth:`FoxgloveEngine.receive_binary`; each returns
  a ``list`` of :class:`Event` objects (frozen dataclasses), possibly empty;
* calls the client-side methods (:meth:`~FoxgloveEngine.subscribe`,
  :meth:`~FoxgloveEngine.advertise`, :meth:`~FoxgloveEngine.message_data`, ...),
  which update the engine's state and *return* the message to send: a ``str``
  for the JSON operations (send it as a text frame) and ``bytes`` for the binary
  ones (send it as a binary frame).

Server input never makes the engine raise. Malformed JSON, an unknown ``op``,
wrong field types, a binary frame shorter than its header, data for a
subscription the client never made: each becomes a :class:`ProtocolViolation`
event and the engine carries on with the next frame. Input beyond the
engine's bounds (JSON nesting, channels and services kept, the size of one
schema text) is refused the same way, with a :attr:`ProtocolViolation.kind`
naming the bound. Bad *caller* arguments,
on the other hand, raise ``TypeError`` / ``ValueError`` at once.

The engine understands the three subprotocols in :data:`SUBPROTOCOLS`. The
parser is tolerant of all shapes whatever the negotiated subprotocol: channels
may carry a ``schemaId`` into the per-connection schema table
(``foxglove.sdk.v1.1``), inline ``schemaName`` / ``schema`` /
``schemaEncoding`` fields (``foxglove.websocket.v1`` and ``foxglove.sdk.v1``),
or both (the table entry wins).

This module is the public face; the parts live in the private package
``wire/_foxglove/``, split the way ``h11`` splits its code and imported one
way only (``_protocol`` and ``_events`` <- ``_readers`` / ``_writers`` <-
``_engine``):

* ``_protocol.py`` - :data:`SUBPROTOCOLS`, :data:`DEFAULT_SCHEMA_ENCODINGS`,
  the binary opcodes and frame headers;
* ``_events.py`` - the value types (:class:`Channel`, :class:`ServiceDef`,
  :class:`Parameter`, ...) and the :class:`Event` subclasses;
* ``_readers.py`` - parsing: JSON values and binary frames into validated
  values and events;
* ``_writers.py`` - the checks of the caller's arguments and the encoders of
  client messages;
* ``_engine.py`` - :class:`FoxgloveEngine`, the state machine that ties them.
"""

from __future__ import annotations

from ._foxglove._engine import FoxgloveEngine as FoxgloveEngine
from ._foxglove._events import Advertise as Advertise
from ._foxglove._events import AdvertiseServices as AdvertiseServices
from ._foxglove._events import Channel as Channel
from ._foxglove._events import ConnectionGraphUpdate as ConnectionGraphUpdate
from ._foxglove._events import Event as Event
from ._foxglove._events import FetchAssetResponse as FetchAssetResponse
from ._foxglove._events import MessageData as MessageData
from ._foxglove._events import MessageSchema as MessageSchema
from ._foxglove._events import Parameter as Parameter
from ._foxglove._events import ParameterValues as ParameterValues
from ._foxglove._events import PlaybackState as PlaybackState
from ._foxglove._events import ProtocolViolation as ProtocolViolation
from ._foxglove._events import RemoveStatus as RemoveStatus
from ._foxglove._events import ServerInfo as ServerInfo
from ._foxglove._events import ServiceCallFailure as ServiceCallFailure
from ._foxglove._events import ServiceCallResponse as ServiceCallResponse
from ._foxglove._events import ServiceDef as ServiceDef
from ._foxglove._events import Status as Status
from ._foxglove._events import Time as Time
from ._foxglove._events import Unadvertise as Unadvertise
from ._foxglove._events import UnadvertiseServices as UnadvertiseServices
from ._foxglove._protocol import DEFAULT_SCHEMA_ENCODINGS as DEFAULT_SCHEMA_ENCODINGS
from ._foxglove._protocol import SUBPROTOCOLS as SUBPROTOCOLS
from ._foxglove._readers import VIOLATIONS_SHOWN as VIOLATIONS_SHOWN

__all__ = [
    "DEFAULT_SCHEMA_ENCODINGS",
    "SUBPROTOCOLS",
    "VIOLATIONS_SHOWN",
    "Advertise",
    "AdvertiseServices",
    "Channel",
    "ConnectionGraphUpdate",
    "Event",
    "FetchAssetResponse",
    "FoxgloveEngine",
    "MessageData",
    "MessageSchema",
    "Parameter",
    "ParameterValues",
    "PlaybackState",
    "ProtocolViolation",
    "RemoveStatus",
    "ServerInfo",
    "ServiceCallFailure",
    "ServiceCallResponse",
    "ServiceDef",
    "Status",
    "Time",
    "Unadvertise",
    "UnadvertiseServices",
]
