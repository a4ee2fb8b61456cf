"""ROS type-name normalisation.

ROS 2 names an interface ``package/kind/Type`` (``kind`` is ``msg``, ``srv`` or
``action``). Bridges and users also write ``package/Type`` (ROS 1 and rosbridge
style), ``package::msg::Type`` (IDL style) and the DDS-mangled
``package::msg::dds_::Type_``. Everything in :mod:`ros_mobile_bridge.codec`
accepts any of these spellings.
"""

from __future__ import annotations

import re

__all__ = [
    "KINDS",
    "canonical_name",
    "guess_kind",
    "is_valid_type_name",
    "lookup_candidates",
    "normalize_type_name",
    "same_type_name",
    "service_type_names",
    "split_type_name",
]

KINDS = ("msg", "srv", "action")
"""The interface kinds ROS 2 knows, in lookup order."""

_SPLIT = re.compile(r"::|/")
_VALID = re.compile(r"[A-Za-z][A-Za-z0-9_]*/[A-Za-z][A-Za-z0-9_]*/[A-Za-z][A-Za-z0-9_]*")
_ACTION_INNER = ("_SendGoal_", "_GetResult_", "_FeedbackMessage")
_ACTION_SUFFIXES = ("_Goal", "_Result", "_Feedback", "_FeedbackMessage")
_SERVICE_SUFFIXES = ("_Request", "_Response", "_Event")


def _parts(name: str) -> list[str]:
    """Split ``name`` into its segments, dropping empty and ``dds_`` ones."""
    if not isinstance(name, str):
        raise TypeError(f"a type name must be a str, not {type(name).__name__}")
    text = name.strip()
    if not text:
        raise ValueError("empty type name")
    parts = [p for p in _SPLIT.split(text) if p]
    if "dds_" in parts:
        parts = [p for p in parts if p != "dds_"]
        if parts and parts[-1].endswith("_") and len(parts[-1]) > 1:
            parts[-1] = parts[-1][:-1]
    if not parts:
        raise ValueError(f"not a type name: {name!r}")
    return parts


def normalize_type_name(name: str, kind: str = "msg") -> str:
    """Return the canonical ``package/kind/Type`` spelling of ``name``.

    ``"pkg/Type"`` gains ``kind`` (``"pkg/msg/Type"`` by default); a name that
    already has three segments (``"pkg/msg/Type"``, ``"pkg/srv/Type_Request"``)
    is returned unchanged; ``"pkg::msg::Type"`` and the DDS-mangled
    ``"pkg::msg::dds_::Type_"`` become ``"pkg/msg/Type"``. Surrounding
    whitespace and leading/trailing slashes are ignored. A name with a single
    segment (no package) is returned stripped but otherwise unchanged.

    Raises ``ValueError`` for an empty name or an empty ``kind`` and
    ``TypeError`` when ``name`` is not a ``str``.
    """
    if not kind or "/" in kind:
        raise ValueError(f"invalid interface kind: {kind!r}")
    parts = _parts(name)
    if len(parts) == 2:
        parts.insert(1, kind)
    return "/".join(parts)


def split_type_name(name: str) -> tuple[str, str | None, str]:
    """Split ``name`` into ``(package, kind, type)``; ``kind`` is ``None`` when
    the name does not spell it (``"pkg/Type"``) and ``package`` is ``""`` when
    the name has no package. Raises ``ValueError`` for an empty name."""
    parts = _parts(name)
    if len(parts) == 1:
        return "", None, parts[0]
    if len(parts) == 2:
        return parts[0], None, parts[1]
    return parts[0], "/".join(parts[1:-1]), parts[-1]


def same_type_name(a: str, b: str) -> bool:
    """Whether ``a`` and ``b`` name the same interface.

    A missing kind segment matches any kind, so ``"std_msgs/String"`` equals
    ``"std_msgs/msg/String"`` and ``"std_srvs/SetBool"`` equals
    ``"std_srvs/srv/SetBool"``; two different explicit kinds never match. All
    spellings :func:`normalize_type_name` accepts are understood. Empty or
    non-string names are never equal to anything."""
    try:
        pa, ka, ta = split_type_name(a)
        pb, kb, tb = split_type_name(b)
    except (TypeError, ValueError):
        return False
    if pa != pb or ta != tb:
        return False
    return ka is None or kb is None or ka == kb


def guess_kind(type_part: str) -> str:
    """Guess the interface kind of a bare type name from its suffix:
    ``X_Request``/``X_Response``/``X_Event`` are ``srv``, ``X_Goal``/``X_Result``/
    ``X_Feedback`` and the action's inner services are ``action``, anything
    else ``msg``."""
    if any(s in type_part for s in _ACTION_INNER) or type_part.endswith(_ACTION_SUFFIXES):
        return "action"
    if type_part.endswith(_SERVICE_SUFFIXES):
        return "srv"
    return "msg"


def canonical_name(name: str) -> str:
    """Like :func:`normalize_type_name`, but a two-segment name gets the kind
    its suffix suggests (``"std_srvs/SetBool_Request"`` ->
    ``"std_srvs/srv/SetBool_Request"``). Used for keys the registry stores."""
    parts = _parts(name)
    if len(parts) == 2:
        parts.insert(1, guess_kind(parts[1]))
    return "/".join(parts)


def lookup_candidates(name: str) -> list[str]:
    """The canonical names ``name`` may refer to, most likely first.

    An explicit kind comes first; the other kinds follow so that a name stored
    under a guessed kind is still found."""
    pkg, kind, typ = split_type_name(name)
    if not pkg:
        return [typ]
    first = kind if kind is not None else guess_kind(typ)
    kinds = [first, *(k for k in KINDS if k != first)]
    return [f"{pkg}/{k}/{typ}" for k in kinds]


def is_valid_type_name(name: str) -> bool:
    """Whether ``name`` is a well-formed canonical ``package/kind/Type``."""
    return _VALID.fullmatch(name) is not None


def service_type_names(service_type: str) -> tuple[str, str]:
    """``"std_srvs/srv/SetBool"`` or ``"std_srvs/SetBool"`` ->
    ``("std_srvs/srv/SetBool_Request", "std_srvs/srv/SetBool_Response")``."""
    base = normalize_type_name(service_type, "srv")
    return f"{base}_Request", f"{base}_Response"
