"""The two forms of ``publish``, ``send_action_goal`` and ``subscribe``:
an instance names its type; a mistake in either form is a ``TypeError`` or
``ValueError`` naming it, raised before anything is sent."""

from __future__ import annotations

from typing import Any

import pytest

from ros_mobile_bridge._core._arguments import (
    goal_arguments,
    publish_arguments,
    subscribe_arguments,
)
from ros_mobile_bridge.interfaces import RosMessage
from ros_mobile_bridge.interfaces.example_interfaces.action import Fibonacci
from ros_mobile_bridge.interfaces.geometry_msgs.msg import Twist, Vector3
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry
from ros_mobile_bridge.interfaces.std_msgs.msg import String

FIB = "example_interfaces/action/Fibonacci"


def sub_type(given: Any, schema: str | None) -> tuple[Any, str | None]:
    """``subscribe_arguments``'s class and type name, other arguments as defaults."""
    want, name, _mode = subscribe_arguments(given, schema, None, True, True, False, None)
    return want, name


def test_an_instance_names_its_type() -> None:
    twist = Twist(linear=Vector3(x=0.2))
    assert publish_arguments(twist, None) == ("geometry_msgs/msg/Twist", twist)
    assert publish_arguments("geometry_msgs/Twist", twist) == ("geometry_msgs/Twist", twist)
    assert publish_arguments("std_msgs/msg/String", {"data": "x"}) == (
        "std_msgs/msg/String",
        {"data": "x"},
    )
    goal = Fibonacci.Goal(order=5)
    assert goal_arguments(goal, None) == (FIB, goal)
    assert goal_arguments(FIB, goal) == (FIB, goal)
    assert goal_arguments(FIB, {"order": 5}) == (FIB, {"order": 5})
    assert sub_type(Odometry, None) == (Odometry, "nav_msgs/msg/Odometry")
    assert sub_type("nav_msgs/msg/Odometry", None) == (None, "nav_msgs/msg/Odometry")
    assert sub_type(None, "nav_msgs/Odometry") == (None, "nav_msgs/Odometry")
    assert sub_type(Odometry, "nav_msgs/Odometry") == (Odometry, "nav_msgs/msg/Odometry")


@pytest.mark.parametrize(
    ("call", "error", "words"),
    [
        (lambda: publish_arguments(String(), {"data": "x"}), TypeError, "takes no data"),
        (lambda: publish_arguments("std_msgs/msg/String", None), TypeError, "needs the data"),
        (lambda: publish_arguments("std_msgs/msg/String", ["x"]), TypeError, "not list"),
        (lambda: publish_arguments("geometry_msgs/msg/Twist", String()), ValueError, "String"),
        (lambda: goal_arguments(Fibonacci.Goal(), {"order": 1}), TypeError, "no third"),
        (lambda: goal_arguments(FIB, None), TypeError, "needs the goal"),
        (lambda: goal_arguments(FIB, Fibonacci.Result()), TypeError, "not an action's goal"),
        (lambda: goal_arguments("other/action/Count", Fibonacci.Goal()), ValueError, "Count"),
        (lambda: goal_arguments(FIB, 5), TypeError, "not int"),
        (lambda: sub_type(RosMessage, None), TypeError, "message class"),
        (lambda: sub_type(dict, None), TypeError, "message class"),  # type: ignore[arg-type]
        (lambda: sub_type(Odometry, "std_msgs/msg/String"), ValueError, "different"),
    ],
)
def test_each_mistake_is_named(call: Any, error: type[Exception], words: str) -> None:
    with pytest.raises(error, match=words):
        call()
