"""A sans-IO engine for the rosbridge v2 protocol (client side).

No sockets, no event loop, no threads: the caller owns the WebSocket and

* feeds every text frame to :meth:`RosbridgeEngine.receive_text` (as the raw
  UTF-8 ``bytes``, or a ``str``) and every binary frame (CBOR) to
  :meth:`RosbridgeEngine.receive_binary`; each returns a ``list`` of
  :class:`Event` objects (frozen dataclasses), possibly empty;
* calls the builders (:meth:`~RosbridgeEngine.subscribe`,
  :meth:`~RosbridgeEngine.call_service`, ...), which return the JSON text to
  send as a text frame.

Server input never makes the engine raise: malformed JSON or CBOR, an unknown
``op``, wrong field types, a fragment that does not fit: each becomes a
:class:`ProtocolViolation` event. Foxglove frames (``serverInfo``, an
``advertise`` with ``channels``) become :class:`ForeignProtocol`: the caller
pointed a rosbridge client at a Foxglove server. Bad *caller* arguments raise
``TypeError`` / ``ValueError`` at once.

``publish`` is the hot path, and the engine does not parse it: it peeks at the
``op`` and ``topic`` of the frame (a ``\\/`` escape in the topic is undone; any
other shape falls back to a full parse) and hands the caller a
:class:`Publish` event holding a view of the undecoded frame, so a message the
caller drops is never parsed. :func:`decode_json_msg` and
:func:`decode_cbor_msg` turn a kept one into its ``msg``. With
``compression="cbor-raw"`` the event's payload is the serialized CDR message
itself, a zero-copy slice of the frame.

This module is the public face; the parts live in the private package
``wire/_rosbridge/``, split the way ``h11`` splits its code (and the way
``wire/_foxglove/`` is) and imported one way only (``_events`` <- ``_readers``
/ ``_writers`` <- ``_engine``):

* ``_events.py`` - the :class:`Event` classes and :data:`PublishKind`;
* ``_readers.py`` - the anchored ``publish`` peeks, JSON and CBOR decoding
  (typed arrays), :func:`decode_json_msg` / :func:`decode_cbor_msg` and the
  CBOR walker (cbor-raw);
* ``_writers.py`` - the encoders of the client's operations and the checks of
  their arguments, :func:`as_text`;
* ``_engine.py`` - :class:`RosbridgeEngine`: the dispatch of operations,
  ``fragment`` reassembly and the connection's state.
"""

from __future__ import annotations

# (``_MAX_CBOR_DEPTH``, ``_Malformed``, ``_peek_cbor_publish``: the CBOR walker
# under its former names, which fuzz/fuzz_cbor_walker.py drives.)
from ._rosbridge._engine import RosbridgeEngine as RosbridgeEngine
from ._rosbridge._events import ActionFeedback as ActionFeedback
from ._rosbridge._events import ActionResult as ActionResult
from ._rosbridge._events import Event as Event
from ._rosbridge._events import ForeignProtocol as ForeignProtocol
from ._rosbridge._events import ProtocolViolation as ProtocolViolation
from ._rosbridge._events import Publish as Publish
from ._rosbridge._events import PublishKind as PublishKind
from ._rosbridge._events import ServiceRequest as ServiceRequest
from ._rosbridge._events import ServiceResponse as ServiceResponse
from ._rosbridge._events import Status as Status
from ._rosbridge._readers import MAX_CBOR_DEPTH as _MAX_CBOR_DEPTH  # noqa: F401
from ._rosbridge._readers import Malformed as _Malformed  # noqa: F401
from ._rosbridge._readers import cbor_loads as cbor_loads
from ._rosbridge._readers import decode_cbor_msg as decode_cbor_msg
from ._rosbridge._readers import decode_json_msg as decode_json_msg
from ._rosbridge._readers import peek_cbor_publish as _peek_cbor_publish  # noqa: F401
from ._rosbridge._writers import as_text as as_text

__all__ = [
    "ActionFeedback",
    "ActionResult",
    "Event",
    "ForeignProtocol",
    "ProtocolViolation",
    "Publish",
    "PublishKind",
    "RosbridgeEngine",
    "ServiceRequest",
    "ServiceResponse",
    "Status",
    "as_text",
    "decode_cbor_msg",
    "decode_json_msg",
]
