"""The argument checks every public call shares: the same mistake gets the
same exception and the same words, wherever it is made."""

from __future__ import annotations

import difflib
import math
import os
from collections.abc import Iterable
from typing import Literal

__all__ = [
    "check_interface_paths",
    "check_name",
    "check_save_bandwidth",
    "check_schema",
    "check_timeout",
    "check_uri",
    "nearest",
    "nearest_hint",
]


def check_name(kind: str, name: object) -> str:
    """``name`` when it is an absolute ROS name (``/cmd_vel``); else
    ``TypeError`` / ``ValueError`` naming ``kind``."""
    if not isinstance(name, str):
        raise TypeError(f"{kind} must be a str, not {type(name).__name__}")
    if not name.startswith("/") or any(c.isspace() for c in name) or len(name) < 2:
        raise ValueError(f"{kind} must be an absolute ROS name like '/cmd_vel', got {name!r}")
    return name


def check_uri(uri: object) -> str:
    """``uri`` when it is a non-empty str with no whitespace (an asset's
    URI, ``package://pkg/meshes/base.stl``); else ``TypeError`` / ``ValueError``."""
    if not isinstance(uri, str):
        raise TypeError(f"uri must be a str, not {type(uri).__name__}")
    if not uri or any(c.isspace() for c in uri):
        raise ValueError(f"uri must be a URI like 'package://pkg/meshes/base.stl', got {uri!r}")
    return uri


def check_save_bandwidth(
    mode: object, max_hz: object, adaptive: bool
) -> bool | Literal["adaptive"]:
    """``save_bandwidth`` of a subscription: ``False``, ``True`` (needs a
    ``max_hz``) or ``"adaptive"`` (needs a ``max_hz`` or ``adaptive=True``);
    else ``TypeError`` / ``ValueError``: the mode pauses the stream between
    deliveries, so it needs a rate to resume at."""
    if mode is False:
        return False
    if mode is True:
        if max_hz is None:
            raise ValueError("save_bandwidth=True needs max_hz: the rate to resume the stream at")
        return True
    if mode == "adaptive" and isinstance(mode, str):
        if max_hz is None and not adaptive:
            raise ValueError(
                "save_bandwidth='adaptive' needs max_hz or adaptive=True: "
                "the rate to resume the stream at"
            )
        return "adaptive"
    if isinstance(mode, str):
        raise ValueError(f"save_bandwidth must be True, False or 'adaptive', got {mode!r}")
    raise TypeError(f"save_bandwidth must be a bool or 'adaptive', not {type(mode).__name__}")


def check_schema(schema: object) -> str:
    """``schema`` when it reads as a ROS type (``pkg/msg/Name`` or
    ``pkg/Name``); else ``TypeError`` / ``ValueError``."""
    if not isinstance(schema, str):
        raise TypeError(f"schema must be a str, not {type(schema).__name__}")
    if schema.count("/") not in (1, 2) or any(c.isspace() for c in schema):
        raise ValueError(
            f"schema must be a ROS type like 'geometry_msgs/msg/Twist', got {schema!r}"
        )
    return schema


def check_timeout(timeout: object) -> float | None:
    """``timeout`` as seconds (None stays None) when positive and finite;
    else ``TypeError`` / ``ValueError``."""
    if timeout is None:
        return None
    if isinstance(timeout, bool) or not isinstance(timeout, int | float):
        raise TypeError("timeout must be a number of seconds or None")
    if not timeout > 0 or math.isinf(timeout):
        raise ValueError(f"timeout must be a positive, finite number of seconds, got {timeout!r}")
    return float(timeout)


def check_interface_paths(paths: object) -> tuple[str, ...]:
    """``paths`` (a sequence of ``str`` or ``os.PathLike``) as a tuple of
    ``str``; ``TypeError`` for anything else (a lone ``str`` included: it
    would read as one path per character)."""
    if isinstance(paths, str | bytes) or not isinstance(paths, Iterable):
        raise TypeError(
            f"interface_paths must be a sequence of paths (str or os.PathLike), not {paths!r}"
        )
    out: list[str] = []
    for path in paths:
        if isinstance(path, bool) or not isinstance(path, str | os.PathLike):
            raise TypeError(f"interface_paths entries must be str or os.PathLike, not {path!r}")
        text = os.fspath(path)
        if not isinstance(text, str):
            raise TypeError(f"interface_paths entries must be text paths, not {path!r}")
        if not text:
            raise ValueError("interface_paths entries must not be empty")
        out.append(text)
    return tuple(out)


def nearest(name: str, known: Iterable[str], n: int = 3) -> list[str]:
    """The known names closest to ``name`` (difflib), best first."""
    return difflib.get_close_matches(name, sorted(set(known)), n=n, cutoff=0.5)


def nearest_hint(name: str, known: Iterable[str]) -> str:
    """``"; nearest: /odom, /odom_raw"`` for the names closest to ``name``,
    ``"; it offers: ..."`` (the first eight) when none is close, ``""`` when
    nothing is known: the words every "not found" shares."""
    names = sorted(set(known))
    close = nearest(name, names)
    if close:
        return f"; nearest: {', '.join(close)}"
    if names:
        more = f", ... ({len(names)} in all)" if len(names) > 8 else ""
        return f"; it offers: {', '.join(names[:8])}{more}"
    return ""
