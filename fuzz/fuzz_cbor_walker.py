"""Fuzz harness for the zero-copy CBOR walker of the rosbridge engine.

:meth:`RosbridgeEngine.receive_binary` first walks a CBOR frame without
decoding it (``peek_cbor_publish``, ``rb._peek_cbor_publish`` here, and its
helpers ``_head``, ``_skip``, ``_text``, ``_is_raw``, ``_raw_message`` in
``wire/_rosbridge/_readers.py``) to find
``op``, ``topic`` and, for a ``cbor-raw`` topic, the slice holding the CDR
message; any other frame is decoded whole (``cbor2``). This harness builds
CBOR byte by byte, so it reaches what ``cbor2.dumps`` never writes:
non-minimal heads, definite and indefinite lengths (chunked strings too),
tags (RFC 8746 typed arrays with odd lengths, bignums, embedded CBOR, huge
tag numbers), half/single/double floats and simple values, reserved
additional-info values, stray ``break`` bytes, declared lengths far beyond
the frame (up to 2**64 - 1), deep nesting (arrays, maps, tags; up to 100,000
levels), invalid UTF-8 in text strings, duplicate and non-text keys; as a
publish frame (often on the ``cbor-raw`` topic, with a cbor-raw ``msg``) or
another op, then cut short, bit-flipped or with bytes appended.

The contract checked, per frame:

* the walker returns a ``Publish`` or ``None`` or raises its own
  ``_Malformed`` (never another exception); a ``cbor-raw`` slice lies inside
  the frame;
* ``receive_binary`` (given ``bytes``, ``bytearray`` or ``memoryview``) returns
  a list of events, a ``ProtocolViolation`` for what it refuses, never an
  "internal error"; a ``Publish`` payload is a view of the frame;
* within :data:`DEADLINE_S`, and with a peak allocation (``tracemalloc``)
  within :func:`memory_bound` of the frame size;
* where ``cbor2`` decodes the frame to a publish map, the walker agrees on the
  topic (and for a cbor-raw ``msg`` on the bytes and the stamp); a frame the
  walker refuses that ``cbor2`` reads is counted ("walker refuses valid
  CBOR", the indefinite-length forms: see :data:`DIVERGENCES`).

Bignums go up to 4,000 bytes (about 9,600 decimal digits), past Python's
4,300-digit ``str()`` limit: such an integer in a ``status`` ``msg``/``level``
or an ``id`` used to make ``receive_binary`` raise ``ValueError`` (found by
issue 8's review; fixed, and kept in the generated shapes).

Run it directly::

    python fuzz/fuzz_cbor_walker.py --examples 20000 [--seed 1]

or import it and call :func:`run` (``tests/test_fuzz_parsers_smoke.py`` does).
"""

from __future__ import annotations

import struct
import sys
import time
import tracemalloc
from collections import Counter
from pathlib import Path
from typing import Any

import cbor2
from hypothesis import strategies as st

try:
    from ros_mobile_bridge.wire import rosbridge as rb
except ImportError:  # a checkout that is not installed: use its src/
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
    from ros_mobile_bridge.wire import rosbridge as rb

try:
    from _harness import cli_main, run_sessions
except ImportError:  # loaded by its path (the smoke tests): the harness is beside it
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _harness import cli_main, run_sessions

__all__ = ["DIVERGENCES", "STATS", "memory_bound", "run", "run_session"]

DEADLINE_S = 2.0
"""The most one frame may take (generous: a real one takes microseconds)."""

RAW_TOPIC = "/chatter"
"""Subscribed with ``cbor-raw`` in every example."""

MAX_BIGNUM_BYTES = 4000
"""The largest bignum payload generated: well past ``str()``'s 4,300-digit
limit."""


def memory_bound(frame_size: int) -> int:
    """The most handling a frame of ``frame_size`` bytes may allocate at its
    peak: a generous constant factor (a decoded value is larger than its
    CBOR), never anything sized by a declared length."""
    return 256 * 1024 + 64 * frame_size


STATS: Counter[str] = Counter()
"""What the run reached (printed by ``main``)."""

DIVERGENCES: list[bytes] = []
"""Up to 20 frames ``cbor2`` reads as a publish but the walker refuses."""


# --------------------------------------------------------------------------
# CBOR, byte by byte


def _head(major: int, arg: int, data: st.DataObject) -> bytes:
    """A head for ``arg``, minimal or (sometimes) wider than needed."""
    widths = [w for w in (0, 1, 2, 4, 8) if arg < (24 if w == 0 else 1 << (8 * w))]
    width = widths[0] if data.draw(st.integers(0, 3)) else data.draw(st.sampled_from(widths))
    if width == 0:
        return bytes([major << 5 | arg])
    info = {1: 24, 2: 25, 4: 26, 8: 27}[width]
    return bytes([major << 5 | info]) + arg.to_bytes(width, "big")


def _string(major: int, raw: bytes, data: st.DataObject) -> bytes:
    if data.draw(st.integers(0, 11)) != 7:  # (hypothesis favours 0 and the maximum)
        return _head(major, len(raw), data) + raw
    # Indefinite: chunks of the same major type (sometimes a wrong one).
    out = bytearray([major << 5 | 31])
    pos = 0
    while pos < len(raw):
        n = data.draw(st.integers(1, max(len(raw) - pos, 1)))
        chunk_major = major if data.draw(st.integers(0, 9)) else 5 - major
        out += _head(chunk_major, n, data) + raw[pos : pos + n]
        pos += n
    return bytes(out) + b"\xff"


def _text(value: str, data: st.DataObject) -> bytes:
    return _string(3, value.encode("utf-8", "surrogatepass"), data)


def _container(major: int, items: list[bytes], data: st.DataObject) -> bytes:
    count = len(items) // 2 if major == 5 else len(items)
    if data.draw(st.integers(0, 9)) != 7:
        return _head(major, count, data) + b"".join(items)
    return bytes([major << 5 | 31]) + b"".join(items) + b"\xff"


_TYPED = (*range(64, 76), *range(77, 84), *range(84, 88))


def _item(data: st.DataObject, depth: int = 0) -> bytes:
    """One random CBOR data item (mostly well formed)."""
    kind = data.draw(st.integers(0, 14 if depth < 3 else 6), label="item")
    if kind in (3, 4, 5, 12, 14) and data.draw(st.booleans()):
        kind = 0  # keep most frames well formed, so the walker gets past them
    if kind == 0:
        major = data.draw(st.sampled_from((0, 1)))
        return _head(major, data.draw(st.integers(0, 2**64 - 1)), data)
    if kind == 1:
        return _string(2, data.draw(st.binary(max_size=24)), data)
    if kind == 2:
        text = data.draw(st.text(max_size=12))
        return _text(text, data)
    if kind == 3:  # invalid UTF-8 in a text string
        return _string(3, data.draw(st.binary(min_size=1, max_size=8)) + b"\xc3", data)
    if kind == 4:
        return data.draw(
            st.sampled_from(
                (
                    b"\xf4",
                    b"\xf5",
                    b"\xf6",
                    b"\xf7",
                    b"\xf8\x20",
                    b"\xf8\x10",  # simple value < 32 in the 1-byte form (not well formed)
                    b"\xf9\x7c\x00",
                    b"\xf9\x7e\x00",
                    b"\xfa\x7f\xc0\x00\x00",
                    b"\xfb" + struct.pack(">d", -0.0),
                    b"\xfb" + struct.pack(">d", 1e308),
                    b"\xfc",
                    b"\xfd",
                    b"\xfe",
                    b"\xff",  # a stray break
                    b"\x1c",  # reserved additional info
                    b"\x5c",
                    b"\x9d",
                    b"\xbe",
                    b"\xdf",
                )
            )
        )
    if kind == 5:  # huge declared length, little or nothing behind it
        major = data.draw(st.sampled_from((2, 3, 4, 5)))
        arg = data.draw(st.sampled_from((2**32 - 1, 2**63, 2**64 - 1, 0xFFFFFFF0, 1 << 20)))
        return _head(major, arg, data) + data.draw(st.binary(max_size=6))
    if kind == 6:
        return _text(data.draw(st.sampled_from(("op", "topic", "msg", "bytes", "publish"))), data)
    if kind == 7:
        items = [_item(data, depth + 1) for _ in range(data.draw(st.integers(0, 3)))]
        return _container(4, items, data)
    if kind == 8:
        items = []
        for _ in range(data.draw(st.integers(0, 3))):
            items += [_item(data, depth + 1), _item(data, depth + 1)]
        return _container(5, items, data)
    if kind == 9:  # RFC 8746 typed array, often not a multiple of its item size
        tag = data.draw(st.sampled_from(_TYPED))
        return _head(6, tag, data) + _string(2, data.draw(st.binary(max_size=33)), data)
    if kind == 10:  # bignum
        limit = MAX_BIGNUM_BYTES
        size = data.draw(st.sampled_from((0, 1, 9, 64, 1000, limit)))
        raw = data.draw(st.binary(min_size=size, max_size=size)) if size < 100 else b"\x01" * size
        return _head(6, data.draw(st.sampled_from((2, 3))), data) + _string(2, raw, data)
    if kind == 11:  # other tags
        tag = data.draw(st.sampled_from((0, 1, 24, 30, 55799, 2**32, 2**64 - 1)))
        return _head(6, tag, data) + _item(data, depth + 1)
    if kind == 12:  # deep nesting
        levels = data.draw(st.sampled_from((63, 64, 65, 200, 5000, 100_000)))
        opener = data.draw(st.sampled_from((b"\x81", b"\x9f", b"\xc6", b"\xa1\x61a", b"\xd8\x40")))
        closer = b"\xff" if opener == b"\x9f" else b""
        return opener * levels + b"\x00" + closer * levels
    if kind == 13:
        return cbor2.dumps(data.draw(st.sampled_from((1.5, "x" * 30, b"\x00" * 300, [1] * 30))))
    return data.draw(st.binary(max_size=12))


def _raw_msg(data: st.DataObject) -> bytes:
    """A cbor-raw ``msg``: ``bytes`` plus a stamp, sometimes with more or less."""
    entries: list[bytes] = []
    keys = data.draw(
        st.lists(st.sampled_from(("bytes", "secs", "nsecs", "extra")), min_size=0, max_size=4)
    )
    if data.draw(st.integers(0, 3)):
        keys = ["bytes", "secs", "nsecs"]
    for key in keys:
        entries.append(_text(key, data))
        if key == "bytes" and data.draw(st.integers(0, 3)):
            entries.append(_string(2, data.draw(st.binary(max_size=40)), data))
        elif key in ("secs", "nsecs") and data.draw(st.integers(0, 3)):
            entries.append(_head(0, data.draw(st.integers(0, 2**64 - 1)), data))
        else:
            entries.append(_item(data, 1))
    return _container(5, entries, data)


_OPS = ("publish", "publish", "publish", "status", "service_response", "action_result", "x")


def _frame(data: st.DataObject) -> bytes:
    kind = data.draw(st.integers(0, 9), label="frame")
    if kind == 0:
        return _item(data)
    if kind == 1:
        return data.draw(st.binary(max_size=64))
    fields: list[tuple[str | None, bytes]] = [
        ("op", _text(data.draw(st.sampled_from(_OPS)), data)),
        ("topic", _text(data.draw(st.sampled_from((RAW_TOPIC, "/other", ""))), data)),
        ("msg", _raw_msg(data) if data.draw(st.booleans()) else _item(data, 1)),
    ]
    for _ in range(data.draw(st.integers(0, 3))):
        key = data.draw(st.sampled_from(("id", "level", "op", "topic", "msg", "values", None)))
        fields.append((key, _item(data, 1)))
    fields = data.draw(st.permutations(fields))
    if data.draw(st.integers(0, 5)) == 0 and fields:
        fields.pop(data.draw(st.integers(0, len(fields) - 1)))
    entries: list[bytes] = []
    for key, value in fields:
        entries += [_text(key, data) if key is not None else _item(data, 1), value]
    frame = _container(5, entries, data)
    mutation = data.draw(st.integers(0, 6), label="mutation")
    if mutation == 1:
        return frame[: data.draw(st.integers(0, len(frame)))]
    if mutation == 2:
        raw = bytearray(frame)
        for _ in range(data.draw(st.integers(1, 3))):
            raw[data.draw(st.integers(0, len(raw) - 1))] ^= 1 << data.draw(st.integers(0, 7))
        return bytes(raw)
    if mutation == 3:
        return frame + data.draw(st.binary(min_size=1, max_size=8))
    return frame


# --------------------------------------------------------------------------
# Checks


def _walk(frame: bytes | bytearray) -> rb.Publish | str | None:
    """The walker alone: a Publish, None, or ``"malformed"``."""
    try:
        publish = rb._peek_cbor_publish(frame, {RAW_TOPIC})
    except rb._Malformed:
        return "malformed"
    assert publish is None or isinstance(publish, rb.Publish), publish
    return publish


def _check_publish(event: rb.Publish, frame: bytes | bytearray) -> None:
    assert isinstance(event.topic, str)
    assert isinstance(event.payload, memoryview)
    assert event.payload.tobytes() in frame
    if event.kind == "cbor-raw":
        assert event.topic == RAW_TOPIC
        assert event.log_time_ns is None or event.log_time_ns >= 0
    elif event.kind == "cbor":
        assert event.payload.nbytes == len(frame)
    else:
        assert event.kind == "parsed", event.kind


def _check_events(events: object, frame: bytes | bytearray) -> list[Any]:
    assert isinstance(events, list), type(events)
    for event in events:
        STATS[type(event).__name__] += 1
        if isinstance(event, rb.ProtocolViolation):
            assert isinstance(event.reason, str)
            assert "internal error" not in event.reason, event.reason
        elif isinstance(event, rb.Publish):
            STATS[f"Publish/{event.kind}"] += 1
            _check_publish(event, frame)
        else:
            assert isinstance(
                event,
                rb.ServiceResponse
                | rb.ActionFeedback
                | rb.ActionResult
                | rb.Status
                | rb.ForeignProtocol,
            ), event
    return events


def _compare(frame: bytes, walked: rb.Publish | str | None) -> None:
    """The walker against a full decode (where ``cbor2`` can read the frame)."""
    try:
        obj = cbor2.loads(frame, max_depth=rb._MAX_CBOR_DEPTH)
    except Exception:  # what the walker makes of undecodable CBOR is free
        return
    if not (isinstance(obj, dict) and obj.get("op") == "publish"):
        return
    topic, msg = obj.get("topic"), obj.get("msg", KeyError)
    if not isinstance(topic, str) or msg is KeyError:
        return
    if walked == "malformed":
        STATS["walker refuses valid CBOR"] += 1
        if len(DIVERGENCES) < 20:
            DIVERGENCES.append(frame)
        return
    assert isinstance(walked, rb.Publish), (walked, frame.hex())
    assert walked.topic == topic, (walked.topic, topic, frame.hex())
    if walked.kind == "cbor-raw":
        assert isinstance(msg, dict), frame.hex()
        assert walked.payload.tobytes() == msg["bytes"], frame.hex()
        secs, nsecs = msg.get("secs"), msg.get("nsecs", 0)
        if isinstance(secs, int) and isinstance(nsecs, int):
            assert walked.log_time_ns == secs * 1_000_000_000 + nsecs, frame.hex()
        STATS["cbor-raw agrees with cbor2"] += 1
    else:
        STATS["topic agrees with cbor2"] += 1


def run_session(data: st.DataObject) -> None:
    """One example: one frame through the walker and through the engine."""
    frame = _frame(data)
    engine = rb.RosbridgeEngine()
    engine.subscribe(RAW_TOPIC, id="s", compression="cbor-raw")
    as_type = data.draw(st.sampled_from(("bytes", "bytearray", "memoryview")))
    given: bytes | bytearray | memoryview = (
        frame
        if as_type == "bytes"
        else bytearray(frame)
        if as_type == "bytearray"
        else memoryview(frame)
    )
    tracemalloc.start()
    start = time.perf_counter()
    try:
        walked = _walk(frame)
        walked_mutable = _walk(bytearray(frame))
        events = engine.receive_binary(given)
        elapsed = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert elapsed < DEADLINE_S, f"{len(frame)} bytes took {elapsed:.2f} s"
    assert peak <= memory_bound(len(frame)), f"{len(frame)} bytes peaked at {peak} bytes"
    STATS["max peak, bytes"] = max(STATS["max peak, bytes"], peak)
    STATS[f"walker: {type(walked).__name__ if not isinstance(walked, str) else walked}"] += 1
    assert type(walked) is type(walked_mutable), (walked, walked_mutable)
    if isinstance(walked, rb.Publish):
        assert isinstance(walked_mutable, rb.Publish)
        assert walked.kind == walked_mutable.kind
        assert walked.payload.tobytes() == walked_mutable.payload.tobytes()
        if walked.kind == "cbor-raw":
            start_at = frame.find(walked.payload.tobytes())
            assert 0 <= start_at <= len(frame) - walked.payload.nbytes
    _check_events(events, frame)
    _compare(frame, walked)


def run(max_examples: int = 1000, seed: int | None = None) -> None:
    """Run ``max_examples`` examples; raises on the first contract breach.
    A ``seed`` makes the run reproducible."""
    run_sessions(run_session, max_examples, seed)


def main(argv: list[str] | None = None) -> int:
    return cli_main(__doc__, run, STATS, argv)


if __name__ == "__main__":
    sys.exit(main())
