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
"""

from __future__ import annotations

import json
import math
import re
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final, Literal

import cbor2
import numpy as np

from .._limits import json_too_deep, truncate_for_log
from ._rosbridge_auth import auth_fields

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

PublishKind = Literal["json", "cbor", "cbor-raw", "parsed"]
"""How a :class:`Publish` payload is to be read: ``"json"`` / ``"cbor"``: the
whole frame (read its ``msg`` with :func:`decode_json_msg` /
:func:`decode_cbor_msg`); ``"cbor-raw"``: the CDR-serialized message;
``"parsed"``: already parsed (the frame needed a full parse), the value is in
:attr:`Publish.message`."""

# Anchored peeks at a JSON publish frame: {"op":"publish","topic":"..." or the
# two keys the other way round. Anything else takes the full parse.
_STRING: Final = rb'"((?:[^"\\]|\\.)*)"'
_PEEK_OP_FIRST: Final = re.compile(rb'\{\s*"op"\s*:\s*"publish"\s*,\s*"topic"\s*:\s*' + _STRING)
_PEEK_TOPIC_FIRST: Final = re.compile(
    rb'\{\s*"topic"\s*:\s*' + _STRING + rb'\s*,\s*"op"\s*:\s*"publish"\s*[,}]'
)

_MAX_FRAGMENTED: Final = 16
"""How many fragmented messages may be in reassembly at once."""

_MAX_CBOR_DEPTH: Final = 64

# RFC 8746 typed arrays, as rosbridge's CBOR encoder uses them.
_TYPED_ARRAYS: Final[Mapping[int, str]] = {
    64: "u1",
    65: ">u2",
    66: ">u4",
    67: ">u8",
    68: "u1",
    69: "<u2",
    70: "<u4",
    71: "<u8",
    72: "i1",
    73: ">i2",
    74: ">i4",
    75: ">i8",
    77: "<i2",
    78: "<i4",
    79: "<i8",
    80: ">f2",
    81: ">f4",
    82: ">f8",
    84: "<f2",
    85: "<f4",
    86: "<f8",
}


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


# --------------------------------------------------------------------------
# Decoding kept messages


def _loads_utf8(raw: bytes | bytearray) -> Any:
    """``json.loads`` of UTF-8 bytes, and only UTF-8.

    ``json.loads`` given bytes guesses UTF-16 or UTF-32 from a NUL in the first
    two bytes or from a byte order mark, so a text frame holding an operation
    spelled in UTF-16 (valid UTF-8, NULs and all) would be parsed as that
    operation. JSON on a WebSocket is UTF-8 (RFC 8259), and no UTF-8 JSON text
    starts with a NUL or with the bytes 0xFE or 0xFF: such bytes raise
    ``ValueError`` (not JSON) instead."""
    if b"\x00" in raw[:2] or raw[:1] in (b"\xfe", b"\xff"):
        raise ValueError(
            "not UTF-8 JSON text (a NUL byte or a UTF-16/32 byte order mark at its start)"
        )
    return json.loads(raw)


def decode_json_msg(payload: memoryview) -> Any:
    """The ``msg`` of a JSON ``publish`` frame. Raises ``ValueError`` for a
    frame that is not JSON or has no ``msg`` (``RecursionError`` for one
    nested too deeply)."""
    obj = payload.obj
    data = obj if isinstance(obj, bytes | bytearray) and len(obj) == payload.nbytes else payload
    frame = _loads_utf8(bytes(data) if isinstance(data, memoryview) else data)
    if not isinstance(frame, dict) or "msg" not in frame:
        raise ValueError("the publish frame has no 'msg'")
    return frame["msg"]


def _typed_array(tag: cbor2.CBORTag, immutable: bool) -> Any:
    dtype = _TYPED_ARRAYS.get(tag.tag)
    value = tag.value
    if dtype is None or not isinstance(value, bytes):
        return tag
    array = np.frombuffer(value, dtype=dtype)
    if array.dtype.byteorder == ">":  # numbers in this machine's order
        array = array.astype(array.dtype.newbyteorder("="))
    return array


def cbor_loads(data: bytes | bytearray | memoryview) -> Any:
    """Decode CBOR, RFC 8746 typed arrays as numpy arrays (read-only views
    when little endian, converted copies when big endian). Raises
    ``ValueError`` for malformed input."""
    try:
        return cbor2.loads(data, tag_hook=_typed_array, max_depth=_MAX_CBOR_DEPTH)
    except cbor2.CBORError as exc:
        raise ValueError(f"invalid CBOR: {exc}") from None


def decode_cbor_msg(payload: memoryview) -> Any:
    """The ``msg`` of a CBOR ``publish`` frame (typed arrays as numpy
    arrays). Raises ``ValueError`` for malformed CBOR or a frame without
    ``msg``."""
    frame = cbor_loads(payload)
    if not isinstance(frame, dict) or "msg" not in frame:
        raise ValueError("the publish frame has no 'msg'")
    return frame["msg"]


# --------------------------------------------------------------------------
# A minimal CBOR walker: enough to find op, topic and a cbor-raw message's
# bytes without decoding the frame.


class _Malformed(Exception):
    pass


def _head(buf: bytes | bytearray, pos: int) -> tuple[int, int, int]:
    """(major type, argument, position after the head)."""
    try:
        initial = buf[pos]
    except IndexError:
        raise _Malformed("truncated CBOR") from None
    major, info = initial >> 5, initial & 0x1F
    pos += 1
    if info < 24:
        return major, info, pos
    if info > 27:
        raise _Malformed("indefinite or reserved CBOR length")
    size = 1 << (info - 24)
    end = pos + size
    if end > len(buf):
        raise _Malformed("truncated CBOR")
    return major, int.from_bytes(buf[pos:end], "big"), end


def _skip(buf: bytes | bytearray, pos: int, depth: int = 0) -> int:
    """The position after the data item at ``pos``."""
    if depth > _MAX_CBOR_DEPTH:
        raise _Malformed("CBOR nested too deeply")
    major, arg, pos = _head(buf, pos)
    if major in (2, 3):
        pos += arg
        if pos > len(buf):
            raise _Malformed("truncated CBOR")
    elif major == 4:
        for _ in range(arg):
            pos = _skip(buf, pos, depth + 1)
    elif major == 5:
        for _ in range(2 * arg):
            pos = _skip(buf, pos, depth + 1)
    elif major == 6:
        pos = _skip(buf, pos, depth + 1)
    return pos


def _text(buf: bytes | bytearray, pos: int) -> tuple[str | None, int]:
    """A text string at ``pos`` (None if the item is something else)."""
    major, arg, after = _head(buf, pos)
    if major != 3:
        return None, _skip(buf, pos)
    end = after + arg
    if end > len(buf):
        raise _Malformed("truncated CBOR")
    try:
        return bytes(buf[after:end]).decode(), end
    except UnicodeDecodeError:
        raise _Malformed("invalid UTF-8 in a CBOR text string") from None


def _map_entries(buf: bytes | bytearray, pos: int) -> tuple[int, int]:
    major, count, pos = _head(buf, pos)
    if major != 5:
        raise _Malformed("not a CBOR map")
    return count, pos


def _raw_message(buf: bytes | bytearray, pos: int) -> tuple[int, int, int | None]:
    """The (start, end) of a cbor-raw ``msg``'s ``bytes`` and its stamp.
    ``bytes`` must be a byte string and ``secs``/``nsecs`` unsigned integers,
    each given once: anything else is malformed (a full parse would read it
    differently, and a real bridge never sends it)."""
    count, pos = _map_entries(buf, pos)
    start = end = -1
    secs: int | None = None
    nsecs = 0
    seen: set[str] = set()
    for _ in range(count):
        key, pos = _text(buf, pos)
        major, arg, after = _head(buf, pos)
        if key in ("bytes", "secs", "nsecs"):
            if key in seen:
                raise _Malformed(f"a cbor-raw message with '{key}' twice")
            seen.add(key)
        if key == "bytes":
            if major != 2:
                raise _Malformed("a cbor-raw message whose 'bytes' is not a byte string")
            start, end = after, after + arg
            if end > len(buf):
                raise _Malformed("truncated CBOR")
            pos = end
        elif key in ("secs", "nsecs"):
            if major != 0:
                raise _Malformed(f"a cbor-raw stamp whose '{key}' is not an unsigned integer")
            if key == "secs":
                secs = arg
            else:
                nsecs = arg
            pos = after
        else:
            pos = _skip(buf, pos)
    if start < 0:
        raise _Malformed("a cbor-raw message without 'bytes'")
    stamp = secs * 1_000_000_000 + nsecs if secs is not None else None
    return start, end, stamp


def _peek_cbor_publish(buf: bytes | bytearray, raw_topics: set[str]) -> Publish | None:
    """A :class:`Publish` for a CBOR publish frame, or None when the frame is
    some other op (then parse it whole). A topic in ``raw_topics`` (subscribed
    with ``cbor-raw``) whose ``msg`` has the cbor-raw shape is read as CDR.
    Raises ``_Malformed``."""
    count, pos = _map_entries(buf, 0)
    op = topic = None
    msg_at = -1
    for _ in range(count):
        key, pos = _text(buf, pos)
        if key in ("op", "topic"):
            value, pos = _text(buf, pos)
            if key == "op":
                op = value
            else:
                topic = value
        else:
            if key == "msg":
                msg_at = pos
            pos = _skip(buf, pos)
    if op != "publish":
        return None
    if topic is None or msg_at < 0:
        raise _Malformed("a publish without a topic or msg")
    view = memoryview(buf)
    major, _, _ = _head(buf, msg_at)
    if topic in raw_topics and major == 5 and _is_raw(buf, msg_at):
        start, end, stamp = _raw_message(buf, msg_at)
        return Publish(topic, "cbor-raw", view[start:end], None, stamp)
    return Publish(topic, "cbor", view)


def _is_raw(buf: bytes | bytearray, pos: int) -> bool:
    """Whether the map at ``pos`` is a cbor-raw message (``bytes`` plus a
    ``secs``/``nsecs`` stamp and nothing else)."""
    count, pos = _map_entries(buf, pos)
    if not 1 <= count <= 3:
        return False
    keys = set()
    for _ in range(count):
        key, pos = _text(buf, pos)
        keys.add(key)
        pos = _skip(buf, pos)
    return "bytes" in keys and keys <= {"bytes", "secs", "nsecs"}


# --------------------------------------------------------------------------
# The engine


@dataclass(slots=True)
class _Partial:
    total: int
    last: float  # when the latest part arrived
    parts: dict[int, str] = field(default_factory=dict)
    size: int = 0


def _json(value: Any) -> str:
    return json.dumps(value, separators=(",", ":"), allow_nan=True)


def as_text(value: Any) -> str:
    """A server value as text for an id or a message: JSON when it is JSON,
    else a bounded description (CBOR can carry bytes, tags, integers too
    long for ``str``). Never raises."""
    try:
        return _json(value)
    except Exception:
        return truncate_for_log(value, 1000)


def _check_str(name: str, value: object) -> str:
    if not isinstance(value, str) or not value:
        raise TypeError(f"{name} must be a non-empty str")
    return value


class RosbridgeEngine:
    """The client side of one rosbridge v2 connection.

    ``max_message_size`` bounds a reassembled ``fragment`` message (and the
    total held in reassembly), in characters of its JSON text;
    ``fragment_timeout`` drops a fragmented message when no part of it came
    for that long, and ignores its late parts (each drop is a
    ``"fragment_limit"`` violation, reported with the next frame).
    ``max_json_depth`` bounds the nesting of a JSON operation that is parsed
    whole (a deeper one is a ``"json_depth"`` violation). ``clock`` (monotonic seconds)
    is injectable for tests. The engine remembers which topics were
    subscribed with ``cbor-raw`` (see :meth:`subscribe`), to tell their
    frames from a CBOR message with a ``bytes`` field."""

    def __init__(
        self,
        *,
        max_message_size: int = 64 * 1024 * 1024,
        fragment_timeout: float = 10.0,
        max_json_depth: int = 100,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if max_message_size <= 0:
            raise ValueError("max_message_size must be positive")
        if not fragment_timeout > 0:
            raise ValueError("fragment_timeout must be positive")
        if type(max_json_depth) is not int or max_json_depth < 1:
            raise ValueError("max_json_depth must be a positive int")
        self.max_json_depth = max_json_depth
        self.max_message_size = max_message_size
        self.fragment_timeout = fragment_timeout
        self._clock = clock
        self._partials: dict[str, _Partial] = {}
        self._dropped: dict[str, float] = {}  # id -> when, so late parts stay dropped
        self._raw_topics: set[str] = set()
        self._held = 0

    # -- inbound -------------------------------------------------------------
    def receive_text(self, data: bytes | bytearray | memoryview | str) -> list[Event]:
        """Handle one text frame: JSON, one operation."""
        if self._partials or self._dropped:
            expired = self._expire()
            if expired:
                return [*expired, *self.receive_text(data)]
        if isinstance(data, str):
            try:
                raw: bytes | bytearray = data.encode()
            except UnicodeEncodeError:
                return [ProtocolViolation("a text frame that is not valid Unicode", "invalid_utf8")]
        else:
            raw = data if isinstance(data, bytes | bytearray) else bytes(data)
        match = _PEEK_OP_FIRST.match(raw) or _PEEK_TOPIC_FIRST.match(raw)
        if match is not None:
            topic_bytes = match.group(1)
            if b"\\" in topic_bytes:
                topic_bytes = topic_bytes.replace(b"\\/", b"/")
            if b"\\" not in topic_bytes:
                try:
                    topic = topic_bytes.decode()
                except UnicodeDecodeError:
                    return [
                        ProtocolViolation(
                            "a publish frame with a topic that is not UTF-8", "invalid_utf8"
                        )
                    ]
                return [Publish(topic, "json", memoryview(raw))]
        return self._parse_json(raw, "a text frame")

    def _parse_json(self, raw: bytes | bytearray, what: str, *, inner: bool = False) -> list[Event]:
        """Parse a whole JSON operation (``what`` names it for a violation;
        ``inner``: a reassembled message, which must not be a fragment)."""
        if json_too_deep(raw, self.max_json_depth):
            return [self._too_deep(what, len(raw))]
        try:
            obj = _loads_utf8(raw)
        except RecursionError:
            return [self._too_deep(what, len(raw))]
        except UnicodeDecodeError as exc:
            return [ProtocolViolation(f"{what} is not valid UTF-8: {exc}", "invalid_utf8")]
        except ValueError as exc:
            return [ProtocolViolation(f"{what} is not JSON: {truncate_for_log(str(exc))}")]
        if inner and isinstance(obj, dict) and obj.get("op") == "fragment":
            return [ProtocolViolation(f"{what}: a fragment inside a fragment")]
        return self._handle(obj, raw)

    def _too_deep(self, what: str, size: int) -> ProtocolViolation:
        return ProtocolViolation(
            f"{what} of {size} bytes nests deeper than {self.max_json_depth}; skipped",
            "json_depth",
        )

    def receive_binary(self, data: bytes | bytearray | memoryview) -> list[Event]:
        """Handle one binary frame: CBOR, one operation."""
        if self._partials or self._dropped:
            expired = self._expire()
            if expired:
                return [*expired, *self.receive_binary(data)]
        if isinstance(data, memoryview):
            data = bytes(data)
        try:
            publish = _peek_cbor_publish(data, self._raw_topics)
        except _Malformed as exc:
            return [ProtocolViolation(f"malformed CBOR frame: {exc}")]
        if publish is not None:
            return [publish]
        try:
            obj = cbor_loads(data)
        except ValueError as exc:
            return [ProtocolViolation(str(exc))]
        except RecursionError:
            return [ProtocolViolation("CBOR nested too deeply", "json_depth")]
        try:
            return self._handle(obj, data)
        except Exception as exc:  # the contract: server input never raises
            return [ProtocolViolation(f"internal error: {truncate_for_log(repr(exc))}")]

    def _handle(self, obj: Any, raw: bytes | bytearray) -> list[Event]:
        if not isinstance(obj, dict):
            return [ProtocolViolation(f"expected a JSON object, got {type(obj).__name__}")]
        op = obj.get("op")
        if not isinstance(op, str):
            if "channels" in obj or "sessionId" in obj:
                return [ForeignProtocol("foxglove-ws", "a frame shaped like Foxglove's")]
            return [ProtocolViolation("a message without an 'op'")]
        try:
            if op == "publish":
                return [self._publish(obj, raw)]
            if op == "service_response":
                return [self._service_response(obj)]
            if op == "status":
                return [self._status(obj)]
            if op == "call_service":
                return [self._service_request(obj)]
            if op == "fragment":
                return self._fragment(obj)
            if op == "action_feedback":
                return [ActionFeedback(_opt_id(obj), _str(obj, "action"), obj.get("values"))]
            if op == "action_result":
                return [self._action_result(obj)]
            if op == "serverInfo" or (op == "advertise" and "channels" in obj):
                return [ForeignProtocol("foxglove-ws", f"the server sent a Foxglove {op!r}")]
            if op == "png":
                return [ProtocolViolation("png compression is not supported; message skipped")]
        except _FieldError as exc:
            return [ProtocolViolation(f"{op}: {exc}")]
        return [ProtocolViolation(f"unknown op {op!r}")]

    @staticmethod
    def _publish(obj: dict[str, Any], raw: bytes | bytearray) -> Publish:
        topic = _str(obj, "topic")
        if "msg" not in obj:
            raise _FieldError("no 'msg'")
        return Publish(topic, "parsed", memoryview(raw), obj["msg"])

    @staticmethod
    def _service_response(obj: dict[str, Any]) -> ServiceResponse:
        result = obj.get("result", True)
        if not isinstance(result, bool):
            raise _FieldError("'result' is not a bool")
        return ServiceResponse(_opt_id(obj), _str(obj, "service", ""), result, obj.get("values"))

    @staticmethod
    def _service_request(obj: dict[str, Any]) -> ServiceRequest:
        request_id = obj.get("id")
        if not isinstance(request_id, str) or not request_id:
            raise _FieldError("a forwarded call without a string 'id' cannot be answered")
        args = obj.get("args", {})
        if args is None:
            args = {}
        if not isinstance(args, dict):
            raise _FieldError("'args' is not an object")
        return ServiceRequest(request_id, _str(obj, "service"), args)

    @staticmethod
    def _status(obj: dict[str, Any]) -> Status:
        level = obj.get("level", "")
        level = level if isinstance(level, str) else as_text(level)
        msg = obj.get("msg", "")
        return Status(level, msg if isinstance(msg, str) else as_text(msg), _opt_id(obj))

    @staticmethod
    def _action_result(obj: dict[str, Any]) -> ActionResult:
        status = obj.get("status")
        if status is not None and (isinstance(status, bool) or not isinstance(status, int)):
            raise _FieldError("'status' is not an int")
        result = obj.get("result", True)
        if not isinstance(result, bool):
            raise _FieldError("'result' is not a bool")
        return ActionResult(
            _opt_id(obj), _str(obj, "action", ""), status, result, obj.get("values")
        )

    # -- fragments -------------------------------------------------------------
    def _expire(self) -> list[Event]:
        now = self._clock()
        timeout = self.fragment_timeout
        out: list[Event] = []
        for key in [k for k, p in self._partials.items() if now - p.last > timeout]:
            partial = self._partials[key]
            out.append(
                ProtocolViolation(
                    f"fragment {truncate_for_log(key, 100)!r}: {len(partial.parts)} of "
                    f"{partial.total} parts after {timeout:g} s; message dropped",
                    "fragment_limit",
                )
            )
            self._drop(key)
        for key in [k for k, t in self._dropped.items() if now - t > timeout]:
            del self._dropped[key]
        return out

    def _drop(self, key: str) -> None:
        partial = self._partials.pop(key, None)
        if partial is not None:
            self._held -= partial.size
            if len(self._dropped) >= 4 * _MAX_FRAGMENTED:
                del self._dropped[next(iter(self._dropped))]
            self._dropped[key] = self._clock()

    def _fragment(self, obj: dict[str, Any]) -> list[Event]:
        key = obj.get("id")
        data, num, total = obj.get("data"), obj.get("num"), obj.get("total")
        if not isinstance(key, str) or not isinstance(data, str):
            return [ProtocolViolation("fragment: 'id' and 'data' must be strings")]
        if (
            not (isinstance(num, int) and isinstance(total, int))
            or isinstance(num, bool)
            or isinstance(total, bool)
            or not 0 <= num < total
        ):
            return [ProtocolViolation(f"fragment {key!r}: bad 'num'/'total'")]
        if key in self._dropped:
            return [
                ProtocolViolation(
                    f"fragment {truncate_for_log(key, 100)!r}: part of a dropped message; ignored",
                    "fragment_limit",
                )
            ]
        partial = self._partials.get(key)
        now = self._clock()
        evicted: list[Event] = []
        if partial is None:
            if len(self._partials) >= _MAX_FRAGMENTED:
                oldest = min(self._partials, key=lambda k: self._partials[k].last)
                self._drop(oldest)
                evicted.append(
                    ProtocolViolation(
                        f"fragment {truncate_for_log(oldest, 100)!r}: more than "
                        f"{_MAX_FRAGMENTED} messages in reassembly; the oldest dropped",
                        "fragment_limit",
                    )
                )
            partial = self._partials[key] = _Partial(total, now)
        elif partial.total != total:
            self._drop(key)
            return [ProtocolViolation(f"fragment {key!r}: 'total' changed; message dropped")]
        if num in partial.parts:
            return [ProtocolViolation(f"fragment {key!r}: part {num} sent twice; ignored")]
        size = len(data)
        if partial.size + size > self.max_message_size or self._held + size > self.max_message_size:
            self._drop(key)
            return [
                *evicted,
                ProtocolViolation(
                    f"fragment {truncate_for_log(key, 100)!r}: over {self.max_message_size} "
                    "characters; message dropped",
                    "fragment_limit",
                ),
            ]
        partial.parts[num] = data
        partial.last = now
        partial.size += size
        self._held += size
        if len(partial.parts) < total:
            return evicted
        self._partials.pop(key)  # complete, not dropped
        self._held -= partial.size
        whole = "".join(partial.parts[i] for i in range(total)).encode("utf-8", "surrogatepass")
        return [
            *evicted,
            *self._parse_json(
                whole,
                f"fragment {truncate_for_log(key, 100)!r}: the reassembled message",
                inner=True,
            ),
        ]

    @property
    def fragments_pending(self) -> int:
        """How many fragmented messages are waiting for more parts."""
        return len(self._partials)

    # -- outbound ----------------------------------------------------------------
    def subscribe(
        self,
        topic: str,
        *,
        id: str,
        type: str | None = None,
        throttle_rate: int = 0,
        queue_length: int = 0,
        compression: str | None = None,
        fragment_size: int | None = None,
    ) -> str:
        """``subscribe``. ``type`` is omitted when unknown (never sent as
        ``""``); ``throttle_rate`` is in milliseconds."""
        _check_str("topic", topic)
        obj: dict[str, Any] = {"op": "subscribe", "id": _check_str("id", id), "topic": topic}
        if type is not None:
            obj["type"] = _check_str("type", type)
        if throttle_rate < 0 or queue_length < 0:
            raise ValueError("throttle_rate and queue_length must not be negative")
        if throttle_rate:
            obj["throttle_rate"] = int(throttle_rate)
        if queue_length:
            obj["queue_length"] = int(queue_length)
        if compression is not None and compression != "none":
            if compression not in ("cbor", "cbor-raw", "png"):
                raise ValueError(f"unknown compression {compression!r}")
            obj["compression"] = compression
        if fragment_size is not None:
            if fragment_size <= 0:
                raise ValueError("fragment_size must be positive")
            obj["fragment_size"] = int(fragment_size)
        if compression == "cbor-raw":
            self._raw_topics.add(topic)
        else:
            self._raw_topics.discard(topic)
        return _json(obj)

    def unsubscribe(self, topic: str, *, id: str) -> str:
        _check_str("topic", topic)
        self._raw_topics.discard(topic)
        return _json({"op": "unsubscribe", "id": _check_str("id", id), "topic": topic})

    @staticmethod
    def advertise(
        topic: str, type: str, *, id: str, latch: bool = False, queue_size: int | None = None
    ) -> str:
        obj: dict[str, Any] = {
            "op": "advertise",
            "id": _check_str("id", id),
            "topic": _check_str("topic", topic),
            "type": _check_str("type", type),
        }
        if latch:
            obj["latch"] = True
        if queue_size is not None:
            obj["queue_size"] = int(queue_size)
        return _json(obj)

    @staticmethod
    def unadvertise(topic: str, *, id: str) -> str:
        _check_str("topic", topic)
        return _json({"op": "unadvertise", "id": _check_str("id", id), "topic": topic})

    @staticmethod
    def publish(topic: str, msg_json: str | bytes) -> str:
        """``publish`` with ``msg_json``, the message already encoded as JSON."""
        body = msg_json.decode() if isinstance(msg_json, bytes) else msg_json
        return f'{{"op":"publish","topic":{_json(_check_str("topic", topic))},"msg":{body}}}'

    @staticmethod
    def call_service(
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
            "id": _check_str("id", id),
            "service": _check_str("service", service),
        }
        if args is not None:
            obj["args"] = args
        if type is not None:
            obj["type"] = _check_str("type", type)
        if timeout is not None:
            if not (timeout > 0 and math.isfinite(timeout)):
                raise ValueError(f"timeout must be positive and finite, got {timeout!r}")
            obj["timeout"] = timeout
        return _json(obj)

    @staticmethod
    def advertise_service(service: str, type: str, *, id: str) -> str:
        """``advertise_service``: this client serves ``service`` of ``type``
        (``pkg/srv/Name``); the server then forwards calls as ``call_service``
        ops (:class:`ServiceRequest`)."""
        return _json(
            {
                "op": "advertise_service",
                "id": _check_str("id", id),
                "service": _check_str("service", service),
                "type": _check_str("type", type),
            }
        )

    @staticmethod
    def unadvertise_service(service: str, *, id: str) -> str:
        return _json(
            {
                "op": "unadvertise_service",
                "id": _check_str("id", id),
                "service": _check_str("service", service),
            }
        )

    @staticmethod
    def service_response(service: str, values_json: str | bytes, *, id: str, result: bool) -> str:
        """``service_response`` to the forwarded call ``id``. ``values_json``
        is the response already encoded as JSON (``result`` True), or the
        reason as a JSON string (``result`` False)."""
        if not isinstance(result, bool):
            raise TypeError("result must be a bool")
        body = values_json.decode() if isinstance(values_json, bytes) else values_json
        head = _json(
            {
                "op": "service_response",
                "id": _check_str("id", id),
                "service": _check_str("service", service),
                "result": result,
            }
        )
        return f'{head[:-1]},"values":{body}}}'

    @staticmethod
    def send_action_goal(
        action: str, action_type: str, args: Any, *, id: str, feedback: bool = True
    ) -> str:
        return _json(
            {
                "op": "send_action_goal",
                "id": _check_str("id", id),
                "action": _check_str("action", action),
                "action_type": _check_str("action_type", action_type),
                "args": args,
                "feedback": feedback,
            }
        )

    @staticmethod
    def auth(
        *, mac: str, client: str, dest: str, rand: str, t: float, level: str, end: float
    ) -> str:
        """``auth``: the rosbridge v2 authentication message, to be sent
        before any other operation. Sent as given (the MAC is the caller's);
        ``t`` and ``end`` (seconds) go as integers when they are whole."""
        return _json(
            auth_fields(mac=mac, client=client, dest=dest, rand=rand, t=t, level=level, end=end)
        )

    @staticmethod
    def cancel_action_goal(action: str, *, id: str) -> str:
        """Cancel the goal sent with ``send_action_goal`` id ``id``."""
        return _json(
            {
                "op": "cancel_action_goal",
                "id": _check_str("id", id),
                "action": _check_str("action", action),
            }
        )


class _FieldError(Exception):
    pass


def _opt_id(obj: Mapping[str, Any]) -> str | None:
    value = obj.get("id")
    if value is None:
        return None
    return value if isinstance(value, str) else as_text(value)


def _str(obj: Mapping[str, Any], key: str, default: str | None = None) -> str:
    value = obj.get(key, default)
    if not isinstance(value, str):
        raise _FieldError(f"{key!r} is missing or not a string")
    return value
