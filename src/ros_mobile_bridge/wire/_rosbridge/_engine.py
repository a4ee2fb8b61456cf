"""The rosbridge engine itself: :class:`RosbridgeEngine`, the state of one
connection (part of :mod:`ros_mobile_bridge.wire.rosbridge`). It dispatches
each operation to its event, reassembles ``fragment`` messages and remembers
the ``cbor-raw`` topics; the readers (:mod:`._readers`) peek at and decode the
frames, the writers (:mod:`._writers`) encode what the client sends."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final

from .._limits import json_too_deep, truncate_for_log
from ._events import (
    ActionFeedback,
    ActionResult,
    Event,
    ForeignProtocol,
    ProtocolViolation,
    Publish,
    ServiceRequest,
    ServiceResponse,
    Status,
)
from ._readers import (
    PEEK_OP_FIRST,
    PEEK_TOPIC_FIRST,
    PUBLISH_PREFIX,
    Malformed,
    cbor_loads,
    loads_utf8,
    peek_cbor_publish,
)
from ._writers import (
    as_text,
    check_str,
    dumps,
    encode_advertise,
    encode_advertise_service,
    encode_auth,
    encode_call_service,
    encode_cancel_action_goal,
    encode_publish,
    encode_send_action_goal,
    encode_service_response,
    encode_unadvertise,
    encode_unadvertise_service,
)

__all__ = ["RosbridgeEngine"]

_PREFIX_LEN: Final = len(PUBLISH_PREFIX)
_MAX_FRAGMENTED: Final = 16
"""How many fragmented messages may be in reassembly at once."""


@dataclass(slots=True)
class _Partial:
    total: int
    last: float  # when the latest part arrived
    parts: dict[int, str] = field(default_factory=dict)
    size: int = 0


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
        topic = self.publish_topic(raw)
        if topic is not None:
            return [Publish(topic, "json", memoryview(raw))]
        match = PEEK_OP_FIRST.match(raw) or PEEK_TOPIC_FIRST.match(raw)
        if match is not None:
            topic_bytes = match.group(1).replace(b"\\/", b"/")
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

    def publish_topic(self, raw: bytes | bytearray) -> str | None:
        """The hot path of :meth:`receive_text`: the topic of a JSON
        ``publish`` frame whose ``op`` and ``topic`` come first (either order)
        and whose topic is plain UTF-8 without escapes, when no fragment
        awaits reassembly; else None, and :meth:`receive_text` handles the
        frame. For a topic returned here, :meth:`receive_text` would return
        exactly ``[Publish(topic, "json", memoryview(raw))]``, so a reader
        builds its frame without the event. Found by a prefix check (the
        compact spelling rosbridge servers send), else by the anchored
        peeks."""
        if self._partials or self._dropped:
            return None
        if raw.startswith(PUBLISH_PREFIX):
            end = raw.find(b'"', _PREFIX_LEN)
            topic_bytes = raw[_PREFIX_LEN:end]
            if end < 0 or b"\\" in topic_bytes:
                return None
        else:
            match = PEEK_OP_FIRST.match(raw) or PEEK_TOPIC_FIRST.match(raw)
            if match is None:
                return None
            topic_bytes = match.group(1)
            if b"\\" in topic_bytes:
                return None
        try:
            return topic_bytes.decode()
        except UnicodeDecodeError:
            return None

    def _parse_json(self, raw: bytes | bytearray, what: str, *, inner: bool = False) -> list[Event]:
        """Parse a whole JSON operation (``what`` names it for a violation;
        ``inner``: a reassembled message, which must not be a fragment)."""
        if json_too_deep(raw, self.max_json_depth):
            return [self._too_deep(what, len(raw))]
        try:
            obj = loads_utf8(raw)
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
            publish = peek_cbor_publish(data, self._raw_topics)
        except Malformed as exc:
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
        check_str("topic", topic)
        obj: dict[str, Any] = {"op": "subscribe", "id": check_str("id", id), "topic": topic}
        if type is not None:
            obj["type"] = check_str("type", type)
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
        return dumps(obj)

    def unsubscribe(self, topic: str, *, id: str) -> str:
        check_str("topic", topic)
        self._raw_topics.discard(topic)
        return dumps({"op": "unsubscribe", "id": check_str("id", id), "topic": topic})

    advertise = staticmethod(encode_advertise)
    unadvertise = staticmethod(encode_unadvertise)
    publish = staticmethod(encode_publish)
    call_service = staticmethod(encode_call_service)
    advertise_service = staticmethod(encode_advertise_service)
    unadvertise_service = staticmethod(encode_unadvertise_service)
    service_response = staticmethod(encode_service_response)
    send_action_goal = staticmethod(encode_send_action_goal)
    auth = staticmethod(encode_auth)
    cancel_action_goal = staticmethod(encode_cancel_action_goal)


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
