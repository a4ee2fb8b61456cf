"""Reading what the server sends, below the level of operations: the anchored
peeks at a JSON ``publish`` frame (the hot path), JSON and CBOR decoding (RFC
8746 typed arrays as numpy arrays), the decoders of a kept message's ``msg``,
and a minimal CBOR walker that finds a CBOR ``publish`` frame's ``op``,
``topic`` and cbor-raw bytes without decoding it (part of
:mod:`ros_mobile_bridge.wire.rosbridge`).

Everything here is a function of its arguments; the engine (:mod:`._engine`)
keeps the state. The walker raises :class:`Malformed`, which the engine turns
into a :class:`ProtocolViolation`."""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from typing import Any, Final

import cbor2
import numpy as np

from ._events import Publish

__all__ = [
    "MAX_CBOR_DEPTH",
    "PEEK_OP_FIRST",
    "PEEK_TOPIC_FIRST",
    "PUBLISH_PREFIX",
    "Malformed",
    "cbor_loads",
    "decode_cbor_msg",
    "decode_json_msg",
    "loads_utf8",
    "peek_cbor_publish",
]

# Anchored peeks at a JSON publish frame: {"op":"publish","topic":"..." or the
# two keys the other way round. Anything else takes the full parse.
_STRING: Final = rb'"((?:[^"\\]|\\.)*)"'
PEEK_OP_FIRST: Final = re.compile(rb'\{\s*"op"\s*:\s*"publish"\s*,\s*"topic"\s*:\s*' + _STRING)
PEEK_TOPIC_FIRST: Final = re.compile(
    rb'\{\s*"topic"\s*:\s*' + _STRING + rb'\s*,\s*"op"\s*:\s*"publish"\s*[,}]'
)

PUBLISH_PREFIX: Final = b'{"op":"publish","topic":"'
"""How a compact JSON publish frame starts (what rosbridge servers send):
checked before the peeks, which it spares on the hot path."""

MAX_CBOR_DEPTH: Final = 64

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
# Decoding kept messages


def loads_utf8(raw: bytes | bytearray) -> Any:
    """``json.loads`` of UTF-8 bytes, and only UTF-8.

    ``json.loads`` given bytes guesses UTF-16 or UTF-32 from a NUL in the first
    two bytes or from a byte order mark, so a text frame holding an operation
    spelled in UTF-16 (valid UTF-8, NULs and all) would be parsed as that
    operation. JSON on a WebSocket is UTF-8 (RFC 8259), and no UTF-8 JSON text
    starts with a NUL or with the bytes 0xFE or 0xFF: such bytes raise
    ``ValueError`` (not JSON) instead."""
    if b"\x00" in raw[:2] or raw[:1] in (b"\xfe", b"\xff"):
        raise ValueError(_NOT_UTF8)
    return json.loads(raw)


_json_decode: Final = json.JSONDecoder().decode
_json_raw_decode: Final = json.JSONDecoder().raw_decode
_NOT_UTF8: Final = "not UTF-8 JSON text (a NUL byte or a UTF-16/32 byte order mark at its start)"


def decode_json_msg(payload: memoryview) -> Any:
    """The ``msg`` of a JSON ``publish`` frame. Raises ``ValueError`` for a
    frame that is not JSON or has no ``msg`` (``RecursionError`` for one
    nested too deeply)."""
    obj = payload.obj
    raw = (
        obj if isinstance(obj, bytes | bytearray) and len(obj) == payload.nbytes else bytes(payload)
    )
    if b"\x00" in raw[:2] or raw[:1] in (b"\xfe", b"\xff"):  # (loads_utf8, inlined)
        raise ValueError(_NOT_UTF8)
    # decoded here: json.loads would first guess the encoding (a Python
    # function per frame); UTF-8 is the only one left
    text = raw.decode("utf-8", "surrogatepass")
    try:  # a frame with no whitespace around it (every hot-path frame) without two regex scans
        frame, end = _json_raw_decode(text)
    except ValueError:
        end = -1
    if end != len(text):
        frame = _json_decode(text)  # whitespace around it, or the error to raise
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
        return cbor2.loads(data, tag_hook=_typed_array, max_depth=MAX_CBOR_DEPTH)
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


class Malformed(Exception):
    pass


def _head(buf: bytes | bytearray, pos: int) -> tuple[int, int, int]:
    """(major type, argument, position after the head)."""
    try:
        initial = buf[pos]
    except IndexError:
        raise Malformed("truncated CBOR") from None
    major, info = initial >> 5, initial & 0x1F
    pos += 1
    if info < 24:
        return major, info, pos
    if info > 27:
        raise Malformed("indefinite or reserved CBOR length")
    size = 1 << (info - 24)
    end = pos + size
    if end > len(buf):
        raise Malformed("truncated CBOR")
    return major, int.from_bytes(buf[pos:end], "big"), end


def _skip(buf: bytes | bytearray, pos: int, depth: int = 0) -> int:
    """The position after the data item at ``pos``."""
    if depth > MAX_CBOR_DEPTH:
        raise Malformed("CBOR nested too deeply")
    major, arg, pos = _head(buf, pos)
    if major in (2, 3):
        pos += arg
        if pos > len(buf):
            raise Malformed("truncated CBOR")
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
        raise Malformed("truncated CBOR")
    try:
        return bytes(buf[after:end]).decode(), end
    except UnicodeDecodeError:
        raise Malformed("invalid UTF-8 in a CBOR text string") from None


def _map_entries(buf: bytes | bytearray, pos: int) -> tuple[int, int]:
    major, count, pos = _head(buf, pos)
    if major != 5:
        raise Malformed("not a CBOR map")
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
                raise Malformed(f"a cbor-raw message with '{key}' twice")
            seen.add(key)
        if key == "bytes":
            if major != 2:
                raise Malformed("a cbor-raw message whose 'bytes' is not a byte string")
            start, end = after, after + arg
            if end > len(buf):
                raise Malformed("truncated CBOR")
            pos = end
        elif key in ("secs", "nsecs"):
            if major != 0:
                raise Malformed(f"a cbor-raw stamp whose '{key}' is not an unsigned integer")
            if key == "secs":
                secs = arg
            else:
                nsecs = arg
            pos = after
        else:
            pos = _skip(buf, pos)
    if start < 0:
        raise Malformed("a cbor-raw message without 'bytes'")
    stamp = secs * 1_000_000_000 + nsecs if secs is not None else None
    return start, end, stamp


def peek_cbor_publish(buf: bytes | bytearray, raw_topics: set[str]) -> Publish | None:
    """A :class:`Publish` for a CBOR publish frame, or None when the frame is
    some other op (then parse it whole). A topic in ``raw_topics`` (subscribed
    with ``cbor-raw``) whose ``msg`` has the cbor-raw shape is read as CDR.
    Raises ``Malformed``."""
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
        raise Malformed("a publish without a topic or msg")
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
