"""A decoded message as JSON-safe data, for programs that hand messages on
(a web relay, an agent tool server, a log)."""

from __future__ import annotations

import base64
import math
from collections.abc import Mapping
from typing import Any

from ..interfaces._base import RosMessage

__all__ = ["jsonable"]


def jsonable(value: Any) -> Any:
    """A copy of ``value`` (a decoded message, ``Message.data``, or any part
    of one) that ``json.dumps`` accepts and that strict JSON parsers read:
    mappings become dicts with ``str`` keys, lists and tuples lists, numpy
    arrays and scalars lists and Python numbers, ``bytes``/``bytearray``/
    ``memoryview`` (a ``uint8[]`` field) a base64 string, and NaN and the
    infinities ``None`` (JSON has no spelling for them), a message instance
    its dict (``to_dict()``). Everything else is returned as is. Never
    modifies ``value``."""
    if isinstance(value, RosMessage):
        value = value.to_dict()
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, bytes | bytearray | memoryview):
        return base64.b64encode(value).decode("ascii")
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    tolist = getattr(value, "tolist", None)  # numpy arrays and scalars
    if callable(tolist) and not isinstance(value, str | int | bool):
        return jsonable(tolist())
    return value
