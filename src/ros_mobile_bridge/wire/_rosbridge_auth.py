"""The fields of the rosbridge v2 ``auth`` operation, checked in one place:
by :meth:`~ros_mobile_bridge.wire.rosbridge.RosbridgeEngine.auth` (the
sans-IO engine stands alone) and by
:class:`~ros_mobile_bridge.RosbridgeAuth` (when the options are built).
Imports nothing heavy: ``import ros_mobile_bridge`` loads it."""

from __future__ import annotations

import math
from typing import Any, Final

__all__ = ["AUTH_FIELDS", "auth_fields"]

AUTH_FIELDS: Final = ("mac", "client", "dest", "rand", "t", "level", "end")
"""The operation's fields, in the order they are sent."""


def auth_fields(
    *,
    mac: object,
    client: object,
    dest: object,
    rand: object,
    t: object,
    level: object,
    end: object,
    owner: str = "",
) -> dict[str, Any]:
    """The ``auth`` operation as an ordered dict (``op`` first), or
    ``TypeError`` / ``ValueError`` naming the bad field (``owner`` prefixes
    the name, e.g. ``"RosbridgeAuth."``). ``mac``, ``client``, ``dest``,
    ``rand`` and ``level`` are str; ``t`` and ``end`` finite numbers >= 0
    (seconds), kept as integers when they are whole. A value is named in an
    error only for the numbers: the MAC never is."""
    given = {
        "mac": mac, "client": client, "dest": dest, "rand": rand,
        "t": t, "level": level, "end": end,
    }  # fmt: skip
    obj: dict[str, Any] = {"op": "auth"}
    for name in AUTH_FIELDS:
        value = given[name]
        if name in ("t", "end"):
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise TypeError(f"{owner}{name} must be a number")
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{owner}{name} must be finite and >= 0, got {value!r}")
            obj[name] = int(value) if float(value).is_integer() else value
        else:
            if not isinstance(value, str):
                raise TypeError(f"{owner}{name} must be a str")
            obj[name] = value
    return obj
