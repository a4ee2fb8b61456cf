"""What the adapters that watch ``/parameter_events`` share (Zenoh and
rosbridge): the topic and its type, reading ROS parameter values, and
turning one ``rcl_interfaces/msg/ParameterEvent`` into the watched
``/node:param`` values it changes.

Contract of :func:`watched_values`:

* the event's new and changed parameters whose ``/node:param`` name is
  watched map to their plain values (a value PARAMETER_NOT_SET, or of an
  unknown type, to ``None``); a watched deleted parameter maps to ``None``;
* an event naming no watched parameter gives an empty dict;
* an event that is not a ``ParameterEvent`` (no ``/``-rooted node name,
  parameter lists that are not lists, values that do not convert) gives
  ``None``: the caller counts it as malformed and skips it."""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import Any, Final

__all__ = [
    "PARAMETER_EVENTS",
    "PARAMETER_EVENT_TYPE",
    "by_node",
    "parameter_from_ros",
    "ros_field",
    "watched_values",
]

PARAMETER_EVENTS: Final = "/parameter_events"
PARAMETER_EVENT_TYPE: Final = "rcl_interfaces/msg/ParameterEvent"


def ros_field(value: Any, name: str) -> Any:
    """Field ``name`` of a decoded message (a mapping or an object);
    ``None`` when it has none."""
    if isinstance(value, Mapping):
        return value.get(name)
    return getattr(value, name, None)


def by_node(names: Sequence[str]) -> dict[str, list[str]]:
    """``["/a:x", "/a:y", "/b:z"]`` -> ``{"/a": ["x", "y"], "/b": ["z"]}``;
    ``ValueError`` for a name that is not ``/node:param``."""
    out: dict[str, list[str]] = {}
    for name in names:
        node, sep, param = name.partition(":")
        if not sep or not node.startswith("/") or not param:
            raise ValueError(f"a parameter name is /node:param, got {name!r}")
        out.setdefault(node, []).append(param)
    return out


# rcl_interfaces/msg/ParameterType codes and the ParameterValue field of each
_PARAM_FIELDS: Final = {
    1: "bool_value",
    2: "integer_value",
    3: "double_value",
    4: "string_value",
    5: "byte_array_value",
    6: "bool_array_value",
    7: "integer_array_value",
    8: "double_array_value",
    9: "string_array_value",
}


def parameter_from_ros(value: Any) -> tuple[bool, Any]:
    """A decoded ``rcl_interfaces/msg/ParameterValue`` as ``(set, plain)``:
    ``(False, None)`` for PARAMETER_NOT_SET. ``TypeError`` or ``ValueError``
    for an array field that holds no array."""
    code = ros_field(value, "type")
    name = _PARAM_FIELDS.get(code) if isinstance(code, int) else None
    if name is None:
        return False, None
    plain = ros_field(value, name)
    if code == 5 and not isinstance(plain, bytes | bytearray):
        plain = bytes(plain or ())
    elif code >= 6 and plain is not None and not isinstance(plain, list):
        plain = list(plain)
    return True, plain


def _entries(event: Any, group: str) -> list[Any]:
    """The list ``group`` of an event (absent counts as empty);
    ``TypeError`` when it is not a list."""
    items = ros_field(event, group)
    if items is None:
        return []
    if isinstance(items, str | bytes | Mapping) or not isinstance(items, Collection):
        raise TypeError(f"{group} is not a list")
    return list(items)


def watched_values(event: Any, watched: Collection[str]) -> dict[str, Any] | None:
    """The watched values one ``ParameterEvent`` changes (see the module's
    contract); ``None`` for an event that is not one."""
    node = ros_field(event, "node")
    if not isinstance(node, str) or not node.startswith("/"):
        return None
    values: dict[str, Any] = {}
    try:
        for group in ("new_parameters", "changed_parameters"):
            for param in _entries(event, group):
                name = f"{node}:{ros_field(param, 'name')}"
                if name in watched:
                    known, plain = parameter_from_ros(ros_field(param, "value"))
                    values[name] = plain if known else None
        for param in _entries(event, "deleted_parameters"):
            name = f"{node}:{ros_field(param, 'name')}"
            if name in watched:
                values[name] = None
    except (TypeError, ValueError):
        return None
    return values
