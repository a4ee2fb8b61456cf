"""The ROS 2 graph the rosbridge tests talk to, run with the peer environment's
Python (``PeerEnv.python``: rclpy and the message packages live there, not in
the project's venv).

By default it provides:

- publishers ``/chatter`` (std_msgs/msg/String "hello N", 10 Hz), ``/odom``
  (nav_msgs/msg/Odometry, frame_id "odom", 20 Hz) and ``/counter``
  (std_msgs/msg/Int32 counting up, 50 Hz);
- recording subscribers on ``/cmd_vel`` (geometry_msgs/msg/Twist),
  ``/cmd_vel_stamped`` (geometry_msgs/msg/TwistStamped) and ``/rmb_in``
  (std_msgs/msg/String);
- services ``/set_flag`` (std_srvs/srv/SetBool: true -> success, "flag set to
  True"; false -> failure, "refused") and ``/slow_trigger`` (std_srvs/srv/Trigger,
  answers after 3 s without blocking anything else);
- the action ``/fibonacci`` (test_msgs/action/Fibonacci): starting from [0, 1]
  it appends one number per step, ``order`` steps 0.1 s apart, with the
  partial sequence as feedback after each step; the result is the whole
  sequence. A negative order is rejected; a cancel request is accepted and the
  goal ends canceled with the partial sequence;
- a node ``rmb_params`` with parameters speed=0.5, label="demo",
  enabled=True, count=3.

It is driven by one JSON object per line on stdin and answers each with one
JSON line on stdout, ``{"ok": true, "result": ...}`` or ``{"ok": false,
"error": "..."}``, in order. Before any command it prints ``{"ready": true,
...}`` once every node is up. Commands (``cmd`` key):

- ``received`` {topic}: the messages recorded on a topic, as JSON-able dicts
  (``uint8[]`` as a list of ints);
- ``clear`` {topic}: forget them;
- ``matched`` {topic}: how many publishers the recording subscriber of a
  topic is matched with (DDS matching done: what they publish now arrives);
- ``record`` {topic, type}: a new recording subscriber (type "pkg/msg/Name");
- ``publish`` {topic, type, hz, data}: a periodic publisher of ``data``;
- ``image`` {topic, hz=30, width=640, height=480}: a sensor_msgs/msg/Image
  publisher, rgb8, deterministic pixels, header.stamp now and header.frame_id
  the decimal sequence number (0, 1, ...) so a receiver can count losses;
- ``stop`` {topic}: destroy a publisher started by ``publish``/``image``;
- ``node`` {name, topic}: a node of its own named ``name`` (no namespace)
  with a ``std_msgs/msg/String`` publisher on ``topic`` (nothing published),
  added to the executor; ``drop_node`` {name}: destroy it;
- ``count`` {topic}: how many messages were published on a topic so far;
- ``param`` {name}: the current value of an ``rmb_params`` parameter;
- ``call`` {service, type, args={}, timeout=5}: call a service from this ROS
  node (a real ROS client); answers ``{"response": {...}}``, or
  ``{"timeout": true}`` when no response came within ``timeout`` seconds;
- ``hold`` {service}: a ``std_srvs/srv/Trigger`` service that holds each
  call (one executor thread each) until ``release`` {service} (or 120 s),
  then answers it; ``held`` {service}: how many calls it received;
- ``ping``: answers "pong";
- ``quit``: answers, then exits. End of input also exits.
"""

from __future__ import annotations

import array
import importlib
import json
import sys
import threading
import time
import traceback
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription
from rclpy.timer import Timer

PARAMETERS: dict[str, Any] = {"speed": 0.5, "label": "demo", "enabled": True, "count": 3}
RECORDED: dict[str, str] = {
    "/cmd_vel": "geometry_msgs/msg/Twist",
    "/cmd_vel_stamped": "geometry_msgs/msg/TwistStamped",
    "/rmb_in": "std_msgs/msg/String",
}


def message_class(typename: str) -> Any:
    """The Python class of "pkg/msg/Name" (also "pkg/Name")."""
    parts = typename.split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"bad message type {typename!r}")
    return getattr(importlib.import_module(f"{parts[0]}.{parts[1]}"), parts[2])


def to_jsonable(value: Any) -> Any:
    """A message (or field value) as plain JSON data."""
    if hasattr(value, "get_fields_and_field_types"):
        return {
            name: to_jsonable(getattr(value, name)) for name in value.get_fields_and_field_types()
        }
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, array.array):
        return value.tolist()
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    return value


def _element_class(field_type: str) -> Any | None:
    """For "sequence<pkg/Name>" or "pkg/Name[3]", the element message class."""
    inner = field_type
    if inner.startswith("sequence<"):
        inner = inner[len("sequence<") :].split(",")[0].rstrip(">")
    inner = inner.split("[")[0]
    return message_class(inner) if "/" in inner else None


def fill(msg: Any, data: dict[str, Any]) -> Any:
    """Set the fields of ``msg`` from JSON data, nested messages included."""
    types = msg.get_fields_and_field_types()
    for key, value in data.items():
        if key not in types:
            raise ValueError(f"{type(msg).__name__} has no field {key!r}")
        current = getattr(msg, key)
        if isinstance(value, dict) and hasattr(current, "get_fields_and_field_types"):
            fill(current, value)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            cls = _element_class(types[key])
            if cls is None:
                raise ValueError(f"field {key!r} does not hold messages")
            setattr(msg, key, [fill(cls(), v) for v in value])
        else:
            setattr(msg, key, value)
    return msg


class Graph:
    """Every node of the test graph, and the state the commands read."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.node = Node("rmb_graph")
        self.params = Node("rmb_params")
        for name, value in PARAMETERS.items():
            self.params.declare_parameter(name, value)
        self.reentrant = ReentrantCallbackGroup()
        self.received: dict[str, list[Any]] = {}
        self.subscriptions: dict[str, Subscription] = {}
        self.publishers: dict[str, tuple[Publisher, Timer]] = {}
        self.published: dict[str, int] = {}
        self.extra_nodes: dict[str, Node] = {}
        self.executor: MultiThreadedExecutor | None = None
        self.holds: dict[str, tuple[threading.Event, list[int]]] = {}

        self._periodic("/chatter", "std_msgs/msg/String", 10.0, self._chatter)
        self._periodic("/odom", "nav_msgs/msg/Odometry", 20.0, self._odom)
        self._periodic("/counter", "std_msgs/msg/Int32", 50.0, self._counter)
        for topic, typename in RECORDED.items():
            self.record(topic, typename)

        from std_srvs.srv import SetBool, Trigger
        from test_msgs.action import Fibonacci

        self.node.create_service(SetBool, "/set_flag", self._set_flag)
        self.node.create_service(
            Trigger, "/slow_trigger", self._slow_trigger, callback_group=self.reentrant
        )
        self.fibonacci = ActionServer(
            self.node,
            Fibonacci,
            "/fibonacci",
            execute_callback=self._fibonacci,
            goal_callback=lambda goal: (
                GoalResponse.REJECT if goal.order < 0 else GoalResponse.ACCEPT
            ),
            cancel_callback=lambda _handle: CancelResponse.ACCEPT,
            callback_group=self.reentrant,
        )

    # publishers

    def _periodic(self, topic: str, typename: str, hz: float, make: Callable[[int], Any]) -> None:
        if topic in self.publishers:
            raise ValueError(f"{topic} already has a publisher here")
        if hz <= 0:
            raise ValueError("hz must be positive")
        publisher = self.node.create_publisher(message_class(typename), topic, QoSProfile(depth=10))

        def tick() -> None:
            with self.lock:
                n = self.published.get(topic, 0)
                self.published[topic] = n + 1
            publisher.publish(make(n))

        timer = self.node.create_timer(1.0 / hz, tick)
        with self.lock:
            self.publishers[topic] = (publisher, timer)
            self.published.setdefault(topic, 0)

    def _chatter(self, n: int) -> Any:
        from std_msgs.msg import String

        return String(data=f"hello {n}")

    def _odom(self, n: int) -> Any:
        from nav_msgs.msg import Odometry

        msg = Odometry()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.header.frame_id = "odom"
        msg.child_frame_id = "base_link"
        msg.pose.pose.position.x = n * 0.01
        msg.pose.pose.orientation.w = 1.0
        msg.twist.twist.linear.x = 0.2
        return msg

    def _counter(self, n: int) -> Any:
        from std_msgs.msg import Int32

        return Int32(data=n)

    def publish(self, topic: str, typename: str, hz: float, data: dict[str, Any]) -> None:
        cls = message_class(typename)
        template = fill(cls(), data)  # fail now on bad data, not in the timer
        self._periodic(topic, typename, hz, lambda _n: template)

    def image(self, topic: str, hz: float, width: int, height: int) -> None:
        from sensor_msgs.msg import Image

        row = bytes((x * 7) % 256 for x in range(width * 3))
        pixels = array.array("B", b"".join(row[y % 256 :] + row[: y % 256] for y in range(height)))

        def make(n: int) -> Any:
            msg = Image()
            msg.header.stamp = self.node.get_clock().now().to_msg()
            msg.header.frame_id = str(n)
            msg.height = height
            msg.width = width
            msg.encoding = "rgb8"
            msg.is_bigendian = 0
            msg.step = width * 3
            msg.data = pixels
            return msg

        self._periodic(topic, "sensor_msgs/msg/Image", hz, make)

    def stop(self, topic: str) -> None:
        with self.lock:
            entry = self.publishers.pop(topic, None)
        if entry is None:
            raise ValueError(f"no publisher on {topic}")
        publisher, timer = entry
        timer.cancel()
        self.node.destroy_timer(timer)
        self.node.destroy_publisher(publisher)

    # subscribers

    def record(self, topic: str, typename: str) -> None:
        with self.lock:
            if topic in self.subscriptions:
                raise ValueError(f"{topic} is already recorded")
            self.received.setdefault(topic, [])

        def on_message(msg: Any) -> None:
            data = to_jsonable(msg)
            with self.lock:
                self.received[topic].append(data)

        sub = self.node.create_subscription(
            message_class(typename), topic, on_message, QoSProfile(depth=100)
        )
        with self.lock:
            self.subscriptions[topic] = sub

    # services and the action

    def _set_flag(self, request: Any, response: Any) -> Any:
        if request.data:
            response.success = True
            response.message = f"flag set to {request.data}"
        else:
            response.success = False
            response.message = "refused"
        return response

    def _slow_trigger(self, _request: Any, response: Any) -> Any:
        time.sleep(3.0)
        response.success = True
        response.message = "slow trigger done"
        return response

    def _fibonacci(self, goal_handle: Any) -> Any:
        from test_msgs.action import Fibonacci

        sequence = [0, 1]
        for _ in range(goal_handle.request.order):
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                return Fibonacci.Result(sequence=sequence)
            sequence.append(sequence[-1] + sequence[-2])
            goal_handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
            time.sleep(0.1)
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            goal_handle.succeed()
        return Fibonacci.Result(sequence=sequence)

    def hold(self, service: str) -> None:
        from std_srvs.srv import Trigger

        release = threading.Event()
        calls: list[int] = []
        self.holds[service] = (release, calls)

        def held(_request: Any, response: Any) -> Any:
            with self.lock:
                calls.append(1)
            release.wait(120.0)
            response.success = False
            response.message = "released"
            return response

        self.node.create_service(Trigger, service, held, callback_group=self.reentrant)

    def call(self, service: str, typename: str, args: dict[str, Any], timeout: float) -> Any:
        pkg, _, name = typename.split("/")
        cls = getattr(importlib.import_module(f"{pkg}.srv"), name)
        client = self.node.create_client(cls, service, callback_group=self.reentrant)
        try:
            if not client.wait_for_service(timeout_sec=timeout):
                return {"timeout": True, "available": False}
            future = client.call_async(fill(cls.Request(), args))
            done = threading.Event()
            future.add_done_callback(lambda _f: done.set())
            if not done.wait(timeout):
                future.cancel()
                return {"timeout": True, "available": True}
            return {"response": to_jsonable(future.result())}
        finally:
            self.node.destroy_client(client)

    # commands

    def command(self, request: dict[str, Any]) -> Any:
        cmd = request.get("cmd")
        topic = str(request.get("topic", ""))
        if cmd == "ping":
            return "pong"
        if cmd == "received":
            with self.lock:
                return list(self.received.get(topic, []))
        if cmd == "clear":
            with self.lock:
                self.received[topic] = []
            return None
        if cmd == "matched":
            with self.lock:
                sub = self.subscriptions[topic]
            return sub.get_publisher_count()
        if cmd == "record":
            self.record(topic, str(request["type"]))
            return None
        if cmd == "publish":
            self.publish(
                topic, str(request["type"]), float(request.get("hz", 10.0)), request.get("data", {})
            )
            return None
        if cmd == "image":
            self.image(
                topic,
                float(request.get("hz", 30.0)),
                int(request.get("width", 640)),
                int(request.get("height", 480)),
            )
            return None
        if cmd == "stop":
            self.stop(topic)
            return None
        if cmd == "node":
            from std_msgs.msg import String

            node = Node(str(request["name"]))
            node.create_publisher(String, topic, 10)
            assert self.executor is not None
            self.executor.add_node(node)
            self.extra_nodes[node.get_name()] = node
            return None
        if cmd == "drop_node":
            node = self.extra_nodes.pop(str(request["name"]))
            assert self.executor is not None
            self.executor.remove_node(node)
            node.destroy_node()
            return None
        if cmd == "count":
            with self.lock:
                return self.published.get(topic, 0)
        if cmd == "call":
            return self.call(
                str(request["service"]),
                str(request["type"]),
                request.get("args", {}),
                float(request.get("timeout", 5.0)),
            )
        if cmd == "hold":
            self.hold(str(request["service"]))
            return None
        if cmd == "held":
            with self.lock:
                return len(self.holds[str(request["service"])][1])
        if cmd == "release":
            self.holds[str(request["service"])][0].set()
            return None
        if cmd == "param":
            return self.params.get_parameter(str(request["name"])).value
        raise ValueError(f"unknown command {cmd!r}")


def _answer(payload: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(payload) + "\n")
    sys.stdout.flush()


def main() -> int:
    rclpy.init()
    graph = Graph()
    executor = MultiThreadedExecutor(num_threads=4)
    graph.executor = executor
    executor.add_node(graph.node)
    executor.add_node(graph.params)
    spinner = threading.Thread(target=executor.spin, name="ros-spin", daemon=True)
    spinner.start()
    _answer({"ready": True, "nodes": ["/rmb_graph", "/rmb_params"]})
    try:
        for line in sys.stdin:
            if not line.strip():
                continue
            try:
                request = json.loads(line)
                if request.get("cmd") == "quit":
                    _answer({"ok": True, "result": None})
                    break
                _answer({"ok": True, "result": graph.command(request)})
            except Exception as exc:
                traceback.print_exc(file=sys.stderr)
                _answer({"ok": False, "error": f"{type(exc).__name__}: {exc}"})
    finally:
        for release, _calls in graph.holds.values():
            release.set()
        executor.shutdown(timeout_sec=2.0)
        graph.node.destroy_node()
        graph.params.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
