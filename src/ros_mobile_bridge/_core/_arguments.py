"""The public methods' two-form arguments, checked and made one form:
``publish(topic, Twist(...))`` or ``publish(topic, schema, data)``,
``send_action_goal(action, Fibonacci.Goal(...))`` or ``(action, type,
goal)``, ``subscribe(topic, Odometry)`` or ``subscribe(topic, "pkg/msg/T")``.
Each raises ``TypeError`` / ``ValueError`` naming the mistake, at once."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

from .._checks import check_name, check_save_bandwidth, check_schema
from ..codec import same_type_name
from ..codec._classes import remember
from ..interfaces._base import RosGoal, RosMessage

_BUNDLED = "ros_mobile_bridge.interfaces."

__all__ = ["advertise_arguments", "goal_arguments", "publish_arguments", "subscribe_arguments"]


def advertise_arguments(
    topic: str, schema: str, latch: Any, queue_size: Any, best_effort: Any
) -> dict[str, Any]:
    """``advertise``'s arguments, checked (``TypeError`` / ``ValueError``
    naming the mistake); its publisher options as keyword arguments for the
    adapter: only those that differ from the defaults."""
    check_name("topic", topic)
    check_schema(schema)
    if not isinstance(latch, bool):
        raise TypeError("latch must be a bool")
    if not isinstance(best_effort, bool):
        raise TypeError("best_effort must be a bool")
    if queue_size is not None:
        if isinstance(queue_size, bool) or not isinstance(queue_size, int):
            raise TypeError(f"queue_size must be an int or None, not {type(queue_size).__name__}")
        if not 1 <= queue_size <= 10_000:
            raise ValueError(f"queue_size must be between 1 and 10000, got {queue_size}")
    given = {"latch": latch, "queue_size": queue_size, "best_effort": best_effort}
    return {name: value for name, value in given.items() if value not in (False, None)}


def goal_arguments(
    action_type: str | RosGoal[Any, Any], goal: Mapping[str, Any] | RosMessage | None
) -> tuple[str, dict[str, Any] | RosMessage]:
    """``send_action_goal``'s ``action_type`` and ``goal`` as (the action
    type, the goal): a goal instance given alone names its action
    (``pkg/action/Name_Goal`` -> ``pkg/action/Name``). ``TypeError`` /
    ``ValueError`` naming the mistake."""
    if isinstance(action_type, RosMessage):
        if goal is not None:
            raise TypeError("send_action_goal(action, goal) takes no third argument")
        goal, action_type = action_type, ""
    elif goal is None:
        raise TypeError("send_action_goal(action, action_type, goal) needs the goal")
    if isinstance(goal, RosMessage):
        own = type(goal).__ros_type__
        if not own.endswith("_Goal") or "/action/" not in own:
            raise TypeError(f"a {own} is not an action's goal (an action's Goal class is)")
        named = own.removesuffix("_Goal")
        if action_type and not same_type_name(action_type, named):
            raise ValueError(f"the goal is a {own}, not a goal of {action_type}")
        return action_type or named, goal
    if not isinstance(goal, Mapping):
        raise TypeError(
            f"goal must be a mapping (dict) or a goal instance, not {type(goal).__name__}"
        )
    return action_type, dict(goal)


def publish_arguments(
    schema: str | RosMessage, data: Mapping[str, Any] | RosMessage | None
) -> tuple[str, Mapping[str, Any] | RosMessage]:
    """``publish``'s ``schema`` and ``data`` as (the type name, the
    message): the type of an instance given alone is its class's; an
    instance given with a name must be of that type. ``TypeError`` /
    ``ValueError`` naming the mistake."""
    if isinstance(schema, RosMessage):
        if data is not None:
            raise TypeError("publish(topic, message) takes no data: the message is the data")
        return type(schema).__ros_type__, schema
    if data is None:
        raise TypeError("publish(topic, schema, data) needs the data (a dict or a message)")
    if isinstance(data, RosMessage):
        own = type(data).__ros_type__
        if isinstance(schema, str) and not same_type_name(schema, own):
            raise ValueError(f"the message is a {own}, not a {schema}")
    elif not isinstance(data, Mapping):
        raise TypeError(
            f"data must be a mapping (dict) or a message instance, not {type(data).__name__}"
        )
    return schema, data


def subscribe_arguments(
    given: type[RosMessage] | str | None,
    schema: str | None,
    compression: object,
    adaptive: object,
    decode: object,
    save_bandwidth: object,
    max_hz: float | None,
) -> tuple[type[RosMessage] | None, str | None, bool | Literal["adaptive"]]:
    """``subscribe``'s arguments checked: (the class wanted, the type name,
    the save-bandwidth mode). ``TypeError`` for a ``type`` that is neither
    a message class nor a name, ``ValueError`` when ``type`` and ``schema``
    name different types; the other arguments' mistakes as their checks
    raise them. A generated class of the user's is remembered, so its
    messages are received as instances of it."""
    want, name = _subscribe_type(given, schema)
    if want is not None and not want.__module__.startswith(_BUNDLED):
        remember(want)
    if name is not None:
        check_schema(name)
    if compression is not None and compression not in ("cbor", "cbor-raw"):
        raise ValueError(f"compression must be 'cbor', 'cbor-raw' or None, got {compression!r}")
    if not isinstance(adaptive, bool):
        raise TypeError("adaptive must be a bool")
    if not isinstance(decode, bool):
        raise TypeError("decode must be a bool")
    return want, name, check_save_bandwidth(save_bandwidth, max_hz, adaptive)


def _subscribe_type(
    given: type[RosMessage] | str | None, schema: str | None
) -> tuple[type[RosMessage] | None, str | None]:
    """(the class wanted, the type name) of ``subscribe``'s ``type`` and ``schema``."""
    if given is None:
        return None, schema
    if isinstance(given, str):
        want, name = None, given
    elif isinstance(given, type) and issubclass(given, RosMessage) and given is not RosMessage:
        want, name = given, given.__ros_type__
    else:
        raise TypeError(
            f"type must be a message class (geometry_msgs.msg.Twist) or a type name, not {given!r}"
        )
    if schema is not None and not same_type_name(schema, name):
        raise ValueError(f"type {name!r} and schema {schema!r} name different types")
    return want, name
