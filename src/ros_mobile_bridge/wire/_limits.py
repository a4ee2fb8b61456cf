"""Small helpers for the inbound limits: what the library logs from the wire
is truncated, and JSON nesting is measured before it is parsed.

Pure functions, no I/O: the sans-IO wire engines use them too.

The rejection reasons an adapter reports in a ``Rejected`` event
(``adapters/_seam.py``), which :attr:`Client.rejections` counts:

* ``"invalid_utf8"``: a text frame (or a text field) that is not UTF-8;
* ``"malformed"``: any other frame the engine could not use;
* ``"json_depth"``: JSON nested deeper than ``ClientOptions.max_json_depth``;
* ``"schema_too_large"``: a channel schema over ``max_schema_size`` bytes or
  ``max_schema_fields`` fields (the channel stays, its schema is dropped);
* ``"channel_limit"`` / ``"service_limit"``: an advertisement beyond
  ``max_channels`` / ``max_services`` (reported once per advertisement);
* ``"fragment_limit"``: a rosbridge fragmented message dropped by the
  reassembly bounds (size, count of messages in reassembly, timeout);
* ``"sequence_too_long"``: a CDR sequence length beyond what the payload
  holds (a decode failure, counted by the subscription);
* ``"overflow"``: events an adapter found before its reader ran (a
  bootstrap's graph and rejections) beyond the 256 it keeps.
"""

from __future__ import annotations

import re
from typing import Final

import numpy as np

__all__ = ["REJECTION_REASONS", "json_too_deep", "truncate_for_log"]

REJECTION_REASONS: Final = (
    "invalid_utf8",
    "malformed",
    "json_depth",
    "schema_too_large",
    "channel_limit",
    "service_limit",
    "fragment_limit",
    "sequence_too_long",
)

LOG_LIMIT: Final = 500
"""Characters of wire text one log line shows."""

# a string, or an unterminated one up to the end (so each attempt succeeds:
# no quadratic rescans of a hostile frame)
_STRING: Final = re.compile(rb'"[^"\\]*(?:\\.?[^"\\]*)*(?:"|\Z)', re.DOTALL)
_OPEN: Final = (ord("["), ord("{"))
_CLOSE: Final = (ord("]"), ord("}"))


def truncate_for_log(text: object, limit: int = LOG_LIMIT) -> str:
    """``text`` (or its ``str``) cut to ``limit`` characters, with its full
    length said when it was cut. Never raises (a value whose ``str`` fails,
    such as a huge int, is described instead)."""
    if not isinstance(text, str):
        if isinstance(text, int) and text.bit_length() > 4 * limit:
            return f"<an integer of {text.bit_length()} bits>"
        try:
            text = str(text)
        except Exception:
            return f"<a {type(text).__name__} that cannot be shown>"
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text)} characters)"


def json_too_deep(raw: bytes | bytearray | memoryview | str, limit: int) -> bool:
    """Whether the JSON text ``raw`` nests arrays and objects more than
    ``limit`` deep. Cheap: two C-speed counts decide for almost every frame;
    only a frame with more than ``limit`` brackets is measured (strings
    removed by a regular expression, the depth by a cumulative sum). Brackets
    inside strings never count; for text that is not JSON the answer is
    only an estimate (the parser rejects it anyway)."""
    data = raw.encode("utf-8", "surrogatepass") if isinstance(raw, str) else raw
    if isinstance(data, memoryview):
        data = bytes(data)
    if data.count(b"[") + data.count(b"{") <= limit:
        return False
    if b'"' in data:
        data = _STRING.sub(b"", data)
    codes = np.frombuffer(data, dtype=np.uint8)
    step = (codes == _OPEN[0]).astype(np.int32)
    step += codes == _OPEN[1]
    step -= codes == _CLOSE[0]
    step -= codes == _CLOSE[1]
    return bool(step.size) and int(np.cumsum(step).max()) > limit
