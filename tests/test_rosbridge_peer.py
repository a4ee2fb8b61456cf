"""The rosbridge test peer works: a real ROS 2 graph (``peers/ros_graph_node.py``)
behind the Rust rosbridge server, driven here with a raw WebSocket client, so a
failure in the rosbridge backend's tests can be told apart from a broken peer."""

from __future__ import annotations

import json
import uuid
from typing import Any

import pytest
from websockets.sync.client import ClientConnection

from _util import wait_until_sync
from peers.rosbridge import RosBridge, RosGraph

pytest_plugins = ["peers.ros_fixtures"]
pytestmark = pytest.mark.peer


def recv_json(ws: ClientConnection, timeout: float = 5.0) -> dict[str, Any]:
    frame = ws.recv(timeout=timeout)
    assert isinstance(frame, str), f"expected a text frame, got {frame!r:.80}"
    return dict(json.loads(frame))


def test_rosapi_lists_the_graph_topics_services_and_action(rosbridge: RosBridge) -> None:
    values = rosbridge.call_service("/rosapi/topics")["values"]
    topics = dict(zip(values["topics"], values["types"], strict=True))
    assert topics["/chatter"] == "std_msgs/msg/String"
    assert topics["/odom"] == "nav_msgs/msg/Odometry"
    services = rosbridge.call_service("/rosapi/services")["values"]["services"]
    assert {"/set_flag", "/slow_trigger"} <= set(services)
    actions = rosbridge.call_service("/rosapi/action_servers")["values"]["action_servers"]
    assert actions == ["/fibonacci"]


def test_subscribe_receives_chatter(rosbridge: RosBridge) -> None:
    with rosbridge.connect() as ws:
        ws.send(json.dumps({"op": "subscribe", "id": "s", "topic": "/chatter"}))
        first = recv_json(ws)
        second = recv_json(ws)
    assert first["op"] == "publish"
    assert first["topic"] == "/chatter"
    n1 = int(first["msg"]["data"].removeprefix("hello "))
    n2 = int(second["msg"]["data"].removeprefix("hello "))
    assert n2 == n1 + 1


def test_publish_reaches_the_graph(rosbridge: RosBridge, ros_graph: RosGraph) -> None:
    text = f"smoke {uuid.uuid4()}"
    with rosbridge.connect() as ws:
        ws.send(
            json.dumps(
                {"op": "advertise", "id": "a", "topic": "/rmb_in", "type": "std_msgs/msg/String"}
            )
        )
        ws.send(json.dumps({"op": "publish", "topic": "/rmb_in", "msg": {"data": text}}))
        # The bridge drops a publish sent just before the socket closes: a
        # round trip after it makes sure it was handled.
        assert rosbridge.call_service("/rosapi/get_time", ws=ws)["result"] is True
        wait_until_sync(
            lambda: {"data": text} in ros_graph.received("/rmb_in"),
            interval=0.05,
            what="the graph to receive the publish",
        )


def test_call_service_answers_and_reports_refusal_as_a_result(rosbridge: RosBridge) -> None:
    with rosbridge.connect() as ws:
        yes = rosbridge.call_service("/set_flag", {"data": True}, ws=ws)
        no = rosbridge.call_service("/set_flag", {"data": False}, ws=ws)
    assert yes["result"] is True
    assert yes["values"] == {"success": True, "message": "flag set to True"}
    assert no["result"] is True
    assert no["values"] == {"success": False, "message": "refused"}


def test_parameters_of_rmb_params_are_visible(rosbridge: RosBridge) -> None:
    names = rosbridge.call_service("/rosapi/get_param_names")["values"]["names"]
    assert {"/rmb_params:speed", "/rmb_params:label"} <= set(names)
    value = rosbridge.call_service("/rosapi/get_param", {"name": "/rmb_params:label"})["values"]
    assert json.loads(value["value"]) == "demo"


def test_action_goal_gets_feedback_and_result(rosbridge: RosBridge) -> None:
    with rosbridge.connect() as ws:
        ws.send(
            json.dumps(
                {
                    "op": "send_action_goal",
                    "id": "g",
                    "action": "/fibonacci",
                    "action_type": "test_msgs/action/Fibonacci",
                    "args": {"order": 3},
                    "feedback": True,
                }
            )
        )
        frames = [recv_json(ws) for _ in range(4)]
    assert [f["op"] for f in frames] == ["action_feedback"] * 3 + ["action_result"]
    assert frames[0]["values"] == {"sequence": [0, 1, 1]}
    assert frames[-1]["values"] == {"sequence": [0, 1, 1, 2, 3]}
    assert frames[-1]["status"] == 4
    assert frames[-1]["result"] is True


def test_graph_node_starts_and_stops_publishers(rosbridge: RosBridge, ros_graph: RosGraph) -> None:
    ros_graph.command(
        {
            "cmd": "publish",
            "topic": "/smoke_point",
            "type": "geometry_msgs/msg/Point",
            "hz": 20,
            "data": {"x": 1.5},
        }
    )
    try:
        with rosbridge.connect() as ws:
            msg = wait_until_sync(
                lambda: _subscribe_once(ws, "/smoke_point", "geometry_msgs/msg/Point"),
                10,
                interval=0.05,
                what="a message on /smoke_point",
            )
        assert msg == {"x": 1.5, "y": 0.0, "z": 0.0}
        assert ros_graph.command({"cmd": "count", "topic": "/smoke_point"}) > 0
    finally:
        ros_graph.command({"cmd": "stop", "topic": "/smoke_point"})


def _subscribe_once(ws: ClientConnection, topic: str, typename: str) -> dict[str, Any] | None:
    ws.send(json.dumps({"op": "subscribe", "id": topic, "topic": topic, "type": typename}))
    try:
        frame = recv_json(ws, timeout=1.0)
    finally:
        ws.send(json.dumps({"op": "unsubscribe", "id": topic, "topic": topic}))
    return dict(frame["msg"]) if frame.get("op") == "publish" else None


def test_a_second_bridge_with_other_flags_shares_the_graph(
    rosbridge_factory: Any, rosbridge: RosBridge
) -> None:
    second: RosBridge = rosbridge_factory("--fragment-timeout", "2", "--max-message-size", "100000")
    assert second.url != rosbridge.url
    assert second.call_service("/set_flag", {"data": True})["values"]["success"] is True
