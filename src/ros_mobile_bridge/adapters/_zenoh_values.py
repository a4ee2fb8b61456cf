"""Plain values of the Zenoh adapter (``adapters/_zenoh*.py``): its records of
subscriptions, queries and goals, and the helpers that read and write ROS
values (parameters, action type names, decoded fields, attachments)."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Final

from ..flow import Decoder
from ..wire import rmw_zenoh as rz
from ._parameter_events import by_node, parameter_from_ros, ros_field
from ._seam import GoalEvents

__all__ = [
    "MAX_GIDS_PER_TOPIC",
    "Goal",
    "Query",
    "Subscription",
    "by_node",
    "default_domain",
    "fresh",
    "parameter_from_ros",
    "parameter_to_ros",
    "ros_field",
    "split_type",
    "valid_attachment",
]

_ATTACHMENT_SIZE: Final = rz.ATTACHMENT_SIZE
MAX_GIDS_PER_TOPIC: Final = 1024
"""Publishers (gids) whose last delivered sequence number is kept per topic
of a transient-local publisher (see ``_zenoh_latched``)."""


def default_domain() -> int:
    """``$ROS_DOMAIN_ID`` when it is a valid domain id, else 0."""
    raw = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if raw.isdigit() and 0 <= int(raw) <= 232:
        return int(raw)
    return 0


@dataclass(slots=True)
class Subscription:
    topic: str
    tag: int
    handle: int | None  # None while paused (save_bandwidth)
    token: int | None = None
    feedback_of: str | None = None  # the action whose feedback topic this is
    parameter_events: bool = False  # the internal /parameter_events subscription
    # sample key -> (type name, decoder); bounded by _zenoh_samples._MAX_KEYS_PER_TOPIC
    keys: dict[str, tuple[str, Decoder | None]] = field(default_factory=dict)
    # a topic of a transient-local publisher: gid -> the highest sequence number
    # delivered (a _zenoh_latched.LatchedMemory record), else None
    seen: dict[bytes, int] | None = None


@dataclass(slots=True)
class Query:
    name: str
    replies: list[tuple[bool, bytes, bytes | None]] = field(default_factory=list)
    on_done: Callable[[list[tuple[bool, bytes, bytes | None]]], None] | None = None


@dataclass(slots=True)
class Goal:
    action: str
    action_type: str
    uuid: bytes
    events: GoalEvents
    feedback_decode: Decoder | None
    # its get_result query ended without a reply (the router or the server
    # went): the keep-alive asks again or fails it (see ZenohActions)
    orphaned: bool = False
    asked: int = 0  # get_result queries sent


def fresh(seen: dict[bytes, int], gid: bytes, sequence: int) -> bool:
    """Whether a sample from ``gid`` numbered ``sequence`` was not delivered
    yet (nothing at or above it from that gid in ``seen``, a subscription's
    record); if so it is recorded. :data:`MAX_GIDS_PER_TOPIC` gids at most,
    the one recorded first forgotten first."""
    last = seen.get(gid)
    if last is not None and sequence <= last:
        return False
    if last is None and len(seen) >= MAX_GIDS_PER_TOPIC:
        del seen[next(iter(seen))]
    seen[gid] = sequence
    return True


def valid_attachment(attachment: bytes | None) -> bool:
    """An attachment in a form a released rmw_zenoh sends (see
    ``wire.rmw_zenoh``): the fixed form checked by size and gid length byte,
    on the hot path; the keyed form by its names."""
    if attachment is not None and len(attachment) == _ATTACHMENT_SIZE:
        return attachment[16] == 0x10
    return rz.attachment_timestamp(attachment) is not None


def parameter_to_ros(value: Any) -> dict[str, Any]:
    """A Python value as an ``rcl_interfaces/msg/ParameterValue`` dict;
    ``ValueError`` for a value no parameter type holds."""
    if isinstance(value, bool):
        return {"type": 1, "bool_value": value}
    if isinstance(value, int):
        return {"type": 2, "integer_value": value}
    if isinstance(value, float):
        return {"type": 3, "double_value": value}
    if isinstance(value, str):
        return {"type": 4, "string_value": value}
    if isinstance(value, bytes | bytearray):
        return {"type": 5, "byte_array_value": list(value)}
    if isinstance(value, list | tuple):
        items = list(value)
        if all(isinstance(v, bool) for v in items):
            return {"type": 6, "bool_array_value": items}
        if all(isinstance(v, int) and not isinstance(v, bool) for v in items):
            return {"type": 7, "integer_array_value": items}
        if all(isinstance(v, int | float) and not isinstance(v, bool) for v in items):
            return {"type": 8, "double_array_value": [float(v) for v in items]}
        if all(isinstance(v, str) for v in items):
            return {"type": 9, "string_array_value": items}
    raise ValueError(f"no ROS parameter type holds {value!r}")


def split_type(type_name: str, namespace: str) -> tuple[str, str, str]:
    parts = type_name.split("/")
    if len(parts) == 2:
        return parts[0], namespace, parts[1]
    if len(parts) == 3 and parts[1] == namespace:
        return parts[0], parts[1], parts[2]
    raise ValueError(f"not a {namespace} type: {type_name!r}")
