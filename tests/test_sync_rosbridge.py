"""``connect_sync`` against a real ROS 2 graph behind rosbridge_server_rs:
action goals (which the demo robot's Foxglove protocol has not) and a ROS
topic, from plain test functions, with asyncio and trio workers."""

from __future__ import annotations

import pytest

import ros_mobile_bridge as rmb
from _util import rosbridge_options as options
from peers.rosbridge import RosBridge

pytest_plugins = ["peers.ros_fixtures"]
pytestmark = pytest.mark.peer

FIB = "test_msgs/action/Fibonacci"


@pytest.fixture(params=["asyncio", "trio"])
def backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def test_an_action_goal_gives_feedback_and_its_result(rosbridge: RosBridge, backend: str) -> None:
    with rmb.connect_sync(
        rosbridge.url, protocol="rosbridge", backend=backend, options=options()
    ) as robot:
        with robot.send_action_goal("/fibonacci", FIB, {"order": 4}) as goal:
            goal.accepted(timeout=10)
            first = goal.next_feedback(timeout=10)
            outcome = goal.result(timeout=10)
            assert goal.done and goal.state == "succeeded"
            later = []
            with pytest.raises(rmb.NotConnected, match="ended"):
                for _ in range(6):  # the newest unseen feedback, if any, then the end
                    later.append(goal.next_feedback(timeout=1))
    assert outcome.status == "succeeded"
    assert outcome.result.sequence.tolist() == [0, 1, 1, 2, 3, 5]
    assert len(later) <= 1
    for feedback in (first, *later):
        sequence = feedback.sequence.tolist()
        assert sequence == [0, 1, 1, 2, 3, 5][: len(sequence)]


def test_a_goal_is_cancelled_on_request_and_when_its_block_is_left(
    rosbridge: RosBridge, backend: str
) -> None:
    with rmb.connect_sync(
        rosbridge.url, protocol="rosbridge", backend=backend, options=options()
    ) as robot:
        with robot.send_action_goal("/fibonacci", FIB, {"order": 50}) as goal:
            goal.next_feedback(timeout=10)
            goal.cancel(timeout=5)
            outcome = goal.result(timeout=10)
        assert outcome.status == "canceled"
        assert len(outcome.result.sequence) < 52
        with robot.send_action_goal("/fibonacci", FIB, {"order": 50}) as left:
            left.accepted(timeout=10)
        assert left.result(timeout=10).status == "canceled"  # the handle hears the end


def test_a_ros_topic_arrives_and_a_slow_service_times_out(
    rosbridge: RosBridge, backend: str
) -> None:
    with rmb.connect_sync(
        rosbridge.url, protocol="rosbridge", backend=backend, options=options()
    ) as robot:
        with robot.subscribe("/chatter", timeout=10) as sub:
            first, second = sub.get(), sub.get()
        assert first.topic == "/chatter" and first.data.data.startswith("hello ")
        n1 = int(first.data.data.removeprefix("hello "))
        assert int(second.data.data.removeprefix("hello ")) > n1
        with pytest.raises(rmb.ServiceTimeout):
            robot.call_service("/slow_trigger", {}, timeout=0.5)
        assert robot.call_service("/set_flag", {"data": True}, timeout=10).success is True
