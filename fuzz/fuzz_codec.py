"""Fuzz harness for the CDR decoders and encoders (``CodecRegistry.decoder(name, "cdr")``).

Each example picks one schema (bundled standard types: ``String``, ``Twist``,
``Odometry``, ``Image``, ``PointCloud2``, ``JointState``, ``CameraInfo`` with
its fixed arrays, ``DiagnosticArray`` with sequences of messages holding
sequences of messages; and a custom ``ros2msg`` text with fixed arrays,
bounded strings and sequences, bounded and unbounded nested message
sequences, octets, chars and 64-bit integers), draws a random valid value for
it from its public definition (:meth:`CodecRegistry.definition`), encodes it,
and feeds the decoder:

* the valid payload (and checks the round trip: decode(encode(value)) equals
  value),
* the payload cut short, with bytes flipped or overwritten, with garbage
  appended, with the other endianness flag,
* the payload with a 4-byte length prefix (any aligned word of the body)
  replaced by a huge count (``0xFFFFFFF0``, ``0x7FFFFFFF``, ...) or one just
  past the payload,
* random bytes (after a valid header, or not).

For the bundled types, the generated decoder into the message classes
(``codec._cdr.build_class_decoder``) is fed the same payload and must agree
with the dict decoder: both decode it to the same message (the instance's
``to_dict()``), or both raise :class:`DecodeError`.

The contract checked: the decoder returns a value or raises
:class:`DecodeError` (never another exception), within a per-example deadline
(:data:`DEADLINE_S`), and the peak memory it allocates (``tracemalloc``)
stays within :func:`memory_bound` of the payload size (a length prefix must
never make it allocate what the payload cannot hold). The encoder, given a
valid value, returns bytes.

Run it directly::

    python fuzz/fuzz_codec.py --examples 20000 [--seed 1]

or import it and call :func:`run` (``tests/test_fuzz_parsers_smoke.py`` does).
"""

from __future__ import annotations

import contextlib
import math
import struct
import sys
import time
import tracemalloc
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import strategies as st

from ros_mobile_bridge.interfaces._base import RosMessage

try:
    from ros_mobile_bridge import DecodeError
    from ros_mobile_bridge.codec import CodecRegistry, FieldDef
except ImportError:  # a checkout that is not installed: use its src/
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
    from ros_mobile_bridge import DecodeError
    from ros_mobile_bridge.codec import CodecRegistry, FieldDef

try:
    from _harness import cli_main, run_sessions
except ImportError:  # loaded by its path (the smoke tests): the harness is beside it
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _harness import cli_main, run_sessions

__all__ = ["CUSTOM_SCHEMA", "SCHEMAS", "STATS", "memory_bound", "run", "run_session"]

CUSTOM_NAME = "fuzz_msgs/msg/Outer"
CUSTOM_SCHEMA = """\
# A custom type exercising what the bundled ones do not.
Inner[] items
Inner[<=3] few
Inner[2] pair
string<=8 label
string[<=2] names
string<=4[] short_names
string<=3[2] tags
uint8[4] fixed_bytes
byte[] octets
byte octet
char c
bool[] flags
bool[3] fixed_flags
int64 big
uint64 ubig
int16[<=5] shorts
float32 f32
float64[] values
builtin_interfaces/Time stamp
================================================================================
MSG: fuzz_msgs/Inner
int8 a
string<=4 name
float32[2] xy
Leaf[] leaves
================================================================================
MSG: fuzz_msgs/Leaf
uint32 id
string text
"""

SCHEMAS: tuple[str, ...] = (
    "std_msgs/msg/String",
    "geometry_msgs/msg/Twist",
    "nav_msgs/msg/Odometry",
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/PointCloud2",
    "sensor_msgs/msg/JointState",
    "sensor_msgs/msg/CameraInfo",
    "diagnostic_msgs/msg/DiagnosticArray",
    "std_msgs/msg/Empty",
    CUSTOM_NAME,
)

DEADLINE_S = 2.0
"""The most one decode may take (generous: a real one takes microseconds)."""

HUGE_COUNTS = (0xFFFFFFFF, 0xFFFFFFF0, 0x80000000, 0x7FFFFFFF, 0x10000000, 0x01000000)


def memory_bound(payload_size: int) -> int:
    """The most a decode of ``payload_size`` bytes may allocate at its peak.

    The decoded value may be larger than the payload (a 1-byte empty message
    becomes a dict, a 5-byte empty string a list slot and a ``str``), so the
    factor is generous; what it excludes is an allocation sized by a length
    prefix instead of by the bytes present (megabytes for a 40-byte frame)."""
    return 64 * 1024 + 400 * payload_size


STATS: Counter[str] = Counter()
"""What the run reached (printed by ``main``)."""

_registry = CodecRegistry()
_class_decoders: dict[str, Any] = {}


def _class_decoder(name: str) -> Any:
    """The class decoder of ``name``, or None for a type without a class."""
    if name not in _class_decoders:
        from ros_mobile_bridge.codec._cdr import build_class_decoder
        from ros_mobile_bridge.interfaces._base import message_class

        decoder = None
        if name != CUSTOM_NAME:
            key, msgdef = _registry._find_ros(name)
            decoder = build_class_decoder(key, _registry._closure(key, msgdef), message_class)
            # build its big-endian variant now, not within a measured decode
            with contextlib.suppress(DecodeError):
                decoder(memoryview(bytes(4096)))
        _class_decoders[name] = decoder
    return _class_decoders[name]


_registry.add_schema(CUSTOM_NAME, "ros2msg", CUSTOM_SCHEMA)

_INT_RANGES = {
    "byte": (0, 255),
    "char": (0, 255),
    "int8": (-(2**7), 2**7 - 1),
    "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
}
_MAX_SEQ = 4  # elements drawn for an unbounded sequence


def _text(bound: int | None) -> st.SearchStrategy[str]:
    # No NUL: a CDR string is NUL-terminated, so one inside cannot round-trip.
    alphabet = st.characters(exclude_categories=("Cs",), exclude_characters="\x00")
    return st.text(alphabet, max_size=min(bound, 12) if bound else 12)


def _primitive(base: str, bound: int | None) -> st.SearchStrategy[Any]:
    if base in _INT_RANGES:
        lo, hi = _INT_RANGES[base]
        return st.integers(lo, hi)
    if base == "float64":
        return st.floats(allow_nan=False)
    if base == "float32":
        return st.floats(allow_nan=False, width=32)
    if base == "bool":
        return st.booleans()
    if base == "string":
        return _text(bound)
    raise AssertionError(f"no strategy for {base!r}")


def _element(field: FieldDef) -> st.SearchStrategy[Any]:
    typ = field.type
    if typ.startswith("string<="):
        return _text(int(typ[len("string<=") :]))
    if "/" in typ:
        return _message(typ)
    return _primitive(typ, None if field.array else field.upper_bound)


def _message(name: str) -> st.SearchStrategy[dict[str, Any]]:
    """Random valid data for type ``name``, from its public definition."""
    fields: dict[str, st.SearchStrategy[Any]] = {}
    for field in _registry.definition(name):
        element = _element(field)
        if not field.array:
            fields[field.name] = element
        elif field.array_length is not None:
            n = field.array_length
            fields[field.name] = st.lists(element, min_size=n, max_size=n)
        else:
            fields[field.name] = st.lists(element, max_size=min(field.upper_bound or _MAX_SEQ, 4))
    return st.fixed_dictionaries(fields)


_STRATEGIES = {name: st.deferred(lambda name=name: _message(name)) for name in SCHEMAS}  # type: ignore[misc]


def _plain(value: Any) -> Any:
    """A decoded value with messages as dicts and numpy arrays as lists (to
    compare with the input)."""
    if isinstance(value, RosMessage):
        return _plain(value.to_dict())
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _same(got: Any, want: Any) -> bool:
    if isinstance(want, float) and isinstance(got, float):
        return got == want or (math.isnan(got) and math.isnan(want))
    if isinstance(want, dict):
        return (
            isinstance(got, dict)
            and got.keys() == want.keys()
            and all(_same(got[k], want[k]) for k in want)
        )
    if isinstance(want, list):
        return (
            isinstance(got, list)
            and len(got) == len(want)
            and all(_same(g, w) for g, w in zip(got, want, strict=True))
        )
    return bool(got == want) and type(got) is type(want)


# --------------------------------------------------------------------------
# Payload mutations


def _flip(payload: bytes, data: st.DataObject) -> bytes:
    raw = bytearray(payload)
    for _ in range(data.draw(st.integers(1, 4))):
        pos = data.draw(st.integers(0, len(raw) - 1))
        if data.draw(st.booleans()):
            raw[pos] ^= 1 << data.draw(st.integers(0, 7))
        else:
            raw[pos] = data.draw(st.sampled_from((0x00, 0x7F, 0x80, 0xFF)))
    return bytes(raw)


def _huge_length(payload: bytes, data: st.DataObject) -> bytes:
    """An aligned body word (where length prefixes live) set to a huge count."""
    words = (len(payload) - 4) // 4
    if words <= 0:
        return payload + struct.pack("<I", data.draw(st.sampled_from(HUGE_COUNTS)))
    at = 4 + 4 * data.draw(st.integers(0, words - 1))
    count = data.draw(
        st.one_of(
            st.sampled_from(HUGE_COUNTS),
            st.integers(len(payload) - at - 3, len(payload) + 64),  # just past the end
            st.integers(0, 2**32 - 1),
        )
    )
    return payload[:at] + struct.pack("<I", max(count, 0)) + payload[at + 4 :]


def _payload(data: st.DataObject, valid: bytes) -> tuple[str, bytes]:
    kind = data.draw(st.integers(0, 7), label="payload kind")
    if kind == 0:
        return "valid", valid
    if kind == 1:
        return "truncated", valid[: data.draw(st.integers(0, max(len(valid) - 1, 0)))]
    if kind == 2:
        return "flipped", _flip(valid, data)
    if kind in (3, 4):
        return "huge length", _huge_length(valid, data)
    if kind == 5:
        endian = b"\x00\x00" if valid[1] == 1 else b"\x00\x01"
        extra = data.draw(st.binary(max_size=16))
        return "other endian / appended", endian + valid[2:] + extra
    if kind == 6:
        head = data.draw(st.sampled_from((b"\x00\x01\x00\x00", b"\x00\x00\x00\x00", b"")))
        return "random", head + data.draw(st.binary(max_size=64))
    # A valid prefix, then a huge count, then a few bytes.
    cut = data.draw(st.integers(4, max(len(valid), 4)))
    cut -= cut % 4
    tail = data.draw(st.binary(max_size=8))
    return "huge length", valid[:cut] + struct.pack("<I", 0xFFFFFFF0) + tail


def check_decode(decode: Any, payload: bytes) -> tuple[str, Any]:
    """Decode ``payload`` under the contract; ``("ok", value)`` or ``("error", exc)``."""
    tracemalloc.start()
    start = time.perf_counter()
    try:
        try:
            value: Any = decode(memoryview(payload))
            outcome = "ok"
        except DecodeError as exc:
            value = exc
            outcome = "error"
        elapsed = time.perf_counter() - start
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert elapsed < DEADLINE_S, f"decode of {len(payload)} bytes took {elapsed:.2f} s"
    assert peak <= memory_bound(len(payload)), (
        f"decode of {len(payload)} bytes peaked at {peak} bytes ({payload.hex()})"
    )
    STATS["max decode peak, bytes"] = max(STATS["max decode peak, bytes"], peak)
    STATS["max payload, bytes"] = max(STATS["max payload, bytes"], len(payload))
    return outcome, value


def run_session(data: st.DataObject) -> None:
    """One example: a schema, a valid value, one payload derived from it."""
    name = data.draw(st.sampled_from(SCHEMAS), label="schema")
    value = data.draw(_STRATEGIES[name], label="value")
    encode = _registry.encoder(name, "cdr")
    decode = _registry.dict_decoder(name)
    valid = encode(value)
    assert isinstance(valid, bytes)
    kind, payload = _payload(data, valid)
    outcome, decoded = check_decode(decode, payload)
    STATS[f"{kind}: {outcome}"] += 1
    class_decode = _class_decoder(name)
    if class_decode is not None:
        class_outcome, instance = check_decode(class_decode, payload)
        assert class_outcome == outcome, (name, payload.hex(), decoded, instance)
        if outcome == "ok":
            assert _same(_plain(instance.to_dict()), _plain(decoded)), (name, payload.hex())
        STATS[f"class decoder agrees: {outcome}"] += 1
    if payload == valid:
        assert outcome == "ok", decoded
        assert _same(_plain(decoded), value), (name, value, decoded)
        STATS["round trips"] += 1


def run(max_examples: int = 1000, seed: int | None = None) -> None:
    """Run ``max_examples`` examples; raises on the first contract breach.
    A ``seed`` makes the run reproducible."""
    run_sessions(run_session, max_examples, seed)


def main(argv: list[str] | None = None) -> int:
    return cli_main(__doc__, run, STATS, argv)


if __name__ == "__main__":
    sys.exit(main())
