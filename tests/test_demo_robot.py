"""Tests for the embedded demo robot, talking raw Foxglove WebSocket protocol to it.

The robot is served by the official Foxglove SDK; these tests act as a minimal hand-written
client (``websockets`` sync API) so they do not depend on the library's own client.
"""

from __future__ import annotations

import json
import math
import socket
import struct
import threading
import time
import zlib
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

import pytest

pytest.importorskip("foxglove")

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from websockets.exceptions import InvalidStatus
from websockets.sync.client import ClientConnection, connect
from websockets.typing import Subprotocol

from _util import wait_until_sync
from ros_mobile_bridge.demo import (
    CMD_VEL_TIMEOUT_S,
    SERVICES,
    TOPICS,
    CmdVel,
    DemoRobot,
)
from ros_mobile_bridge.demo._png import CameraRenderer, encode_png_rgb

T = TypeVar("T")

SUBPROTOCOL = "foxglove.sdk.v1.1"
TIMEOUT = 5.0

TS = get_typestore(Stores.ROS2_JAZZY)
TS.register(
    {
        "std_srvs/srv/SetBool_Response": next(
            iter(get_types_from_msg("bool success\nstring message", "x/msg/Y").values())
        ),
        "std_srvs/srv/Trigger_Response": next(
            iter(get_types_from_msg("bool success\nstring message", "x/msg/Y").values())
        ),
    }
)


def open_ws(url: str, subprotocol: str = SUBPROTOCOL) -> ClientConnection:
    """Connect like a Foxglove client.

    ``max_queue=None``: the robot streams at 50 Hz and tests do not read everything; with the
    default bounded queue, websockets stops reading under backpressure and then cannot see the
    server's close frame, so leaving the ``with`` block would wait the full close_timeout (10 s).
    """
    return connect(
        url, subprotocols=[Subprotocol(subprotocol)], open_timeout=TIMEOUT, max_queue=None
    )


Message = dict[str, Any] | bytes


class Peer:
    """A bare Foxglove WebSocket client over a sync websockets connection."""

    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws
        self.server_info: dict[str, Any] = {}
        self.channels: dict[str, dict[str, Any]] = {}  # topic -> channel (schema inlined)
        self.services: dict[str, dict[str, Any]] = {}  # name -> service
        self.parameter_values: list[dict[str, Any]] = []  # every parameterValues message
        self._schemas: dict[int, dict[str, Any]] = {}
        self._next_sub = 100
        self._next_call = 1

    def _absorb(self, msg: Message) -> None:
        if isinstance(msg, bytes):
            return
        op = msg.get("op")
        if op == "serverInfo":
            self.server_info = msg
        elif op == "advertise":
            # v1.1 sends schemas separately and references them by id; v1 inlines them.
            for schema in msg.get("schemas", []):
                self._schemas[schema["id"]] = schema
            for channel in msg["channels"]:
                if "schemaId" in channel:
                    schema = self._schemas[channel["schemaId"]]
                    channel = {
                        **channel,
                        "schemaName": schema["name"],
                        "schemaEncoding": schema["encoding"],
                        "schema": schema["data"],
                    }
                self.channels[channel["topic"]] = channel
        elif op == "parameterValues":
            self.parameter_values.append(msg)
        elif op == "advertiseServices":
            for service in msg["services"]:
                self.services[service["name"]] = service

    def recv(self, timeout: float) -> Message:
        raw = self.ws.recv(timeout=timeout)
        msg: Message = json.loads(raw) if isinstance(raw, str) else raw
        self._absorb(msg)
        return msg

    def wait_for(
        self, pick: Callable[[Message], T | None], timeout: float = TIMEOUT, what: str = "message"
    ) -> T:
        """Receive until ``pick`` returns non-None for a message; fail after ``timeout``."""
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"timed out waiting for {what}")
            try:
                msg = self.recv(remaining)
            except TimeoutError:
                raise AssertionError(f"timed out waiting for {what}") from None
            picked = pick(msg)
            if picked is not None:
                return picked

    def wait_state(self, cond: Callable[[], T | None], what: str = "state") -> T:
        """Receive (and absorb) messages until ``cond()`` is non-None; fail after TIMEOUT."""
        deadline = time.monotonic() + TIMEOUT
        while True:
            result = cond()
            if result is not None:
                return result
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"timed out waiting for {what}")
            try:
                self.recv(remaining)
            except TimeoutError:
                raise AssertionError(f"timed out waiting for {what}") from None

    def handshake(self) -> None:
        self.wait_for(lambda m: True if self.server_info else None, what="serverInfo")
        self.wait_for(
            lambda m: True if set(TOPICS) <= set(self.channels) else None, what="advertise"
        )
        self.wait_for(
            lambda m: True if set(SERVICES) <= set(self.services) else None,
            what="advertiseServices",
        )

    def send_json(self, msg: dict[str, Any]) -> None:
        self.ws.send(json.dumps(msg))

    def subscribe(self, topic: str) -> int:
        sub_id = self._next_sub
        self._next_sub += 1
        channel_id = self.channels[topic]["id"]
        self.send_json(
            {"op": "subscribe", "subscriptions": [{"id": sub_id, "channelId": channel_id}]}
        )
        return sub_id

    def next_data(self, sub_id: int, what: str = "message data") -> tuple[int, bytes]:
        """Next 0x01 MessageData frame for ``sub_id``: ``(log_time_ns, payload)``."""

        def pick(msg: Message) -> tuple[int, bytes] | None:
            if isinstance(msg, bytes) and msg[0] == 0x01:
                sid, log_time = struct.unpack_from("<IQ", msg, 1)
                if sid == sub_id:
                    return log_time, msg[13:]
            return None

        return self.wait_for(pick, what=what)

    def call_service(self, name: str, payload: bytes) -> dict[str, Any] | bytes:
        """Call ``name`` with a CDR ``payload``; the response payload, or the failure JSON."""
        service_id = self.services[name]["id"]
        call_id = self._next_call
        self._next_call += 1
        encoding = b"cdr"
        self.ws.send(
            b"\x02" + struct.pack("<III", service_id, call_id, len(encoding)) + encoding + payload
        )

        def pick(msg: Message) -> tuple[Message] | None:
            if isinstance(msg, bytes) and msg[0] == 0x03:
                sid, cid, enc_len = struct.unpack_from("<III", msg, 1)
                if (sid, cid) == (service_id, call_id):
                    assert msg[13 : 13 + enc_len] == b"cdr"
                    return (msg[13 + enc_len :],)
            if (
                isinstance(msg, dict)
                and msg.get("op") == "serviceCallFailure"
                and msg.get("callId") == call_id
            ):
                return (msg,)
            return None

        (response,) = self.wait_for(pick, what=f"response from {name}")
        return response

    def advertise(self, channel_id: int, topic: str, encoding: str, schema_name: str) -> None:
        self.send_json(
            {
                "op": "advertise",
                "channels": [
                    {
                        "id": channel_id,
                        "topic": topic,
                        "encoding": encoding,
                        "schemaName": schema_name,
                    }
                ],
            }
        )

    def publish(self, channel_id: int, payload: bytes) -> None:
        self.ws.send(b"\x01" + struct.pack("<I", channel_id) + payload)


def twist_cdr(linear_x: float, angular_z: float) -> bytes:
    twist = TS.types["geometry_msgs/msg/Twist"]
    vector = TS.types["geometry_msgs/msg/Vector3"]
    msg = twist(linear=vector(linear_x, 0.0, 0.0), angular=vector(0.0, 0.0, angular_z))
    return bytes(TS.serialize_cdr(msg, "geometry_msgs/msg/Twist", little_endian=True))


def twist_stamped_cdr(linear_x: float, angular_z: float) -> bytes:
    twist = TS.types["geometry_msgs/msg/Twist"]
    vector = TS.types["geometry_msgs/msg/Vector3"]
    header = TS.types["std_msgs/msg/Header"]
    stamp = TS.types["builtin_interfaces/msg/Time"]
    stamped = TS.types["geometry_msgs/msg/TwistStamped"]
    msg = stamped(
        header=header(stamp=stamp(sec=1, nanosec=2), frame_id="base_link"),
        twist=twist(linear=vector(linear_x, 0.0, 0.0), angular=vector(0.0, 0.0, angular_z)),
    )
    return bytes(TS.serialize_cdr(msg, "geometry_msgs/msg/TwistStamped", little_endian=True))


SET_BOOL_TRUE = b"\x00\x01\x00\x00\x01"
SET_BOOL_FALSE = b"\x00\x01\x00\x00\x00"
TRIGGER_REQUEST = b"\x00\x01\x00\x00\x00"


@pytest.fixture
def robot() -> Iterator[DemoRobot]:
    """Not conftest's ``robot``: a fresh one per test, at faster rates."""
    with DemoRobot(rate_hz=50.0, camera_hz=10.0) as demo:
        yield demo


@pytest.fixture
def peer(robot: DemoRobot) -> Iterator[Peer]:
    with open_ws(robot.url) as ws:
        client = Peer(ws)
        client.handshake()
        yield client


# --------------------------------------------------------------------------- handshake


def test_server_info_lists_capabilities(robot: DemoRobot, peer: Peer) -> None:
    info = peer.server_info
    assert info["name"] == "rmb-demo-robot"
    assert {"clientPublish", "services", "parameters", "time"} <= set(info["capabilities"])
    assert set(info["supportedEncodings"]) == {"json", "cdr"}
    assert robot.url == f"ws://127.0.0.1:{robot.port}"


def test_advertise_lists_topics_with_schemas(peer: Peer) -> None:
    assert set(peer.channels) == set(TOPICS)
    for topic, schema_name in TOPICS.items():
        channel = peer.channels[topic]
        assert channel["schemaName"] == schema_name
        if topic == "/status":
            assert channel["encoding"] == "json"
            assert channel["schemaEncoding"] == "jsonschema"
            assert json.loads(channel["schema"])["properties"]["mode"]["type"] == "string"
        else:
            assert channel["encoding"] == "cdr"
            assert channel["schemaEncoding"] == "ros2msg"
            # The concatenated .msg text must describe the type completely.
            types = get_types_from_msg(channel["schema"], schema_name)
            assert types[schema_name] == TS.fielddefs[schema_name]


def test_advertise_lists_services(peer: Peer) -> None:
    assert set(peer.services) == set(SERVICES)
    for name, service_type in SERVICES.items():
        service = peer.services[name]
        assert service["type"] == service_type
        assert service["request"]["encoding"] == "cdr"
        assert service["request"]["schemaName"] == f"{service_type}_Request"
        assert service["request"]["schemaEncoding"] == "ros2msg"
        assert service["response"]["schemaName"] == f"{service_type}_Response"
    assert peer.services["/set_led"]["request"]["schema"].strip() == "bool data"
    assert peer.services["/reset_odometry"]["request"]["schema"] == ""
    assert "bool success" in peer.services["/reset_odometry"]["response"]["schema"]


def test_legacy_subprotocol_is_refused_by_the_sdk(robot: DemoRobot) -> None:
    # Documents an SDK fact clients must know: only foxglove.sdk.v1 / foxglove.sdk.v1.1.
    with (
        pytest.raises(InvalidStatus),
        open_ws(robot.url, "foxglove.websocket.v1"),
    ):
        pass


# --------------------------------------------------------------------------- topics


def test_odom_frames_deserialize(peer: Peer) -> None:
    sub_id = peer.subscribe("/odom")
    log_time, payload = peer.next_data(sub_id, "/odom")
    odom: Any = TS.deserialize_cdr(payload, "nav_msgs/msg/Odometry")
    assert odom.header.frame_id == "odom"
    assert odom.child_frame_id == "base_link"
    stamp_ns = odom.header.stamp.sec * 1_000_000_000 + odom.header.stamp.nanosec
    assert stamp_ns == log_time
    assert abs(log_time - time.time_ns()) < 60 * 1_000_000_000
    assert odom.pose.pose.orientation.w == pytest.approx(1.0)
    assert odom.twist.twist.linear.x == 0.0


def test_odom_deserializes_with_the_advertised_schema_alone(peer: Peer) -> None:
    # A client without a bundled typestore parses the ros2msg text it was given.
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(peer.channels["/odom"]["schema"], "nav_msgs/msg/Odometry"))
    sub_id = peer.subscribe("/odom")
    _, payload = peer.next_data(sub_id, "/odom")
    odom: Any = store.deserialize_cdr(payload, "nav_msgs/msg/Odometry")
    assert odom.header.frame_id == "odom"


def test_pose_battery_status_and_camera(peer: Peer) -> None:
    pose_sub = peer.subscribe("/pose")
    _, payload = peer.next_data(pose_sub, "/pose")
    pose: Any = TS.deserialize_cdr(payload, "geometry_msgs/msg/PoseStamped")
    assert pose.header.frame_id == "odom"

    battery_sub = peer.subscribe("/battery")
    _, payload = peer.next_data(battery_sub, "/battery")
    battery: Any = TS.deserialize_cdr(payload, "sensor_msgs/msg/BatteryState")
    assert 0.0 < battery.percentage <= 1.0
    assert battery.present

    status_sub = peer.subscribe("/status")
    _, payload = peer.next_data(status_sub, "/status")
    status = json.loads(payload)
    assert status["mode"] == "idle"
    assert status["uptime_s"] >= 0
    assert status["speed"] == 0.0
    assert status["watchdog_timeout_s"] == CMD_VEL_TIMEOUT_S

    camera_sub = peer.subscribe("/camera/image/compressed")
    _, payload = peer.next_data(camera_sub, "/camera/image/compressed")
    image: Any = TS.deserialize_cdr(payload, "sensor_msgs/msg/CompressedImage")
    assert image.format == "png"
    png = bytes(image.data)
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    width, height = struct.unpack_from(">II", png, 16)
    assert (width, height) == (160, 120)


def test_time_is_broadcast(peer: Peer) -> None:
    def pick(msg: Message) -> int | None:
        if isinstance(msg, bytes) and msg[0] == 0x02:
            (stamp,) = struct.unpack_from("<Q", msg, 1)
            return int(stamp)
        return None

    stamp = peer.wait_for(pick, what="time")
    assert abs(stamp - time.time_ns()) < 60 * 1_000_000_000


# --------------------------------------------------------------------------- cmd_vel


def test_cdr_cmd_vel_is_logged_and_moves_the_robot(robot: DemoRobot, peer: Peer) -> None:
    peer.advertise(1, "/cmd_vel", "cdr", "geometry_msgs/msg/Twist")
    before = time.time_ns()
    peer.publish(1, twist_cdr(0.5, 0.25))
    log = wait_until_sync(robot.received_cmd_vel, what="cmd_vel logged")
    assert len(log) == 1
    cmd = log[0]
    assert isinstance(cmd, CmdVel)
    assert (cmd.linear_x, cmd.angular_z, cmd.encoding) == (0.5, 0.25, "cdr")
    assert cmd.receive_time_ns >= before
    assert robot.cmd_vel_log == log
    wait_until_sync(lambda: robot.pose[0] > 0.01, what="robot to move forward")
    assert robot.pose[2] > 0.0  # turning left


def test_odom_twist_reflects_command_then_watchdog_stops(robot: DemoRobot, peer: Peer) -> None:
    status_sub = peer.subscribe("/status")
    odom_sub = peer.subscribe("/odom")
    peer.advertise(1, "/cmd_vel", "cdr", "geometry_msgs/msg/Twist")
    sent = time.monotonic()
    peer.publish(1, twist_cdr(0.4, -0.2))

    def odom_twist(msg: Message) -> tuple[float, float] | None:
        if (
            isinstance(msg, bytes)
            and msg[0] == 0x01
            and struct.unpack_from("<I", msg, 1)[0] == odom_sub
        ):
            odom: Any = TS.deserialize_cdr(msg[13:], "nav_msgs/msg/Odometry")
            return odom.twist.twist.linear.x, odom.twist.twist.angular.z
        return None

    peer.wait_for(lambda m: (odom_twist(m) == (0.4, -0.2)) or None, what="odom twist = command")

    # No further commands: the robot's own watchdog must stop it.
    def watchdog(msg: Message) -> dict[str, Any] | None:
        if (
            isinstance(msg, bytes)
            and msg[0] == 0x01
            and struct.unpack_from("<I", msg, 1)[0] == status_sub
        ):
            status: dict[str, Any] = json.loads(msg[13:])
            return status if status["mode"] == "watchdog_stop" else None
        return None

    status = peer.wait_for(watchdog, what="watchdog_stop")
    assert time.monotonic() - sent >= CMD_VEL_TIMEOUT_S
    assert status["speed"] == 0.0
    peer.wait_for(lambda m: (odom_twist(m) == (0.0, 0.0)) or None, what="odom twist = 0")
    stopped = robot.pose
    # Well past the watchdog, the pose no longer changes.
    wait_until_sync(lambda: time.monotonic() - sent > 3 * CMD_VEL_TIMEOUT_S, what="time to pass")
    assert robot.pose == stopped


def test_json_and_stamped_cmd_vel(robot: DemoRobot, peer: Peer) -> None:
    peer.advertise(1, "/cmd_vel", "json", "geometry_msgs/msg/Twist")
    peer.advertise(2, "/cmd_vel_stamped", "cdr", "geometry_msgs/msg/TwistStamped")
    peer.advertise(3, "/cmd_vel_stamped", "json", "geometry_msgs/msg/TwistStamped")
    peer.advertise(4, "/chatter", "json", "std_msgs/msg/String")
    twist_json = {"linear": {"x": 0.3, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0.1}}
    peer.publish(1, json.dumps(twist_json).encode())
    wait_until_sync(lambda: len(robot.received_cmd_vel()) == 1, what="json cmd_vel")
    peer.publish(4, b'{"data": "ignored"}')
    peer.publish(2, twist_stamped_cdr(-0.2, 0.0))
    wait_until_sync(lambda: len(robot.received_cmd_vel()) == 2, what="stamped cdr cmd_vel")
    stamped_json = {
        "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
        "twist": twist_json,
    }
    peer.publish(3, json.dumps(stamped_json).encode())
    peer.publish(1, b"not json")  # dropped with a warning, not fatal
    peer.publish(1, json.dumps({"linear": {"x": 0.0}, "angular": {"z": 0.0}}).encode())
    wait_until_sync(lambda: len(robot.received_cmd_vel()) == 4, what="all cmd_vel")
    log = robot.received_cmd_vel()
    assert [(c.linear_x, c.angular_z, c.encoding) for c in log] == [
        (0.3, 0.1, "json"),
        (-0.2, 0.0, "cdr"),
        (0.3, 0.1, "json"),
        (0.0, 0.0, "json"),
    ]
    assert [c.receive_time_ns for c in log] == sorted(c.receive_time_ns for c in log)


def test_zero_twist_stops_immediately(robot: DemoRobot, peer: Peer) -> None:
    status_sub = peer.subscribe("/status")
    peer.advertise(1, "/cmd_vel", "cdr", "geometry_msgs/msg/Twist")
    peer.publish(1, twist_cdr(1.0, 0.0))
    wait_until_sync(lambda: robot.pose[0] > 0.01, what="robot to move")
    peer.publish(1, twist_cdr(0.0, 0.0))
    wait_until_sync(lambda: len(robot.received_cmd_vel()) == 2, what="zero twist logged")

    def mode(msg: Message) -> str | None:
        if (
            isinstance(msg, bytes)
            and msg[0] == 0x01
            and struct.unpack_from("<I", msg, 1)[0] == status_sub
        ):
            return str(json.loads(msg[13:])["mode"])
        return None

    # "idle", not "watchdog_stop": the client stopped the robot explicitly.
    peer.wait_for(lambda m: mode(m) == "idle" or None, what="idle status")
    assert robot.received_cmd_vel()[-1].linear_x == 0.0


def test_max_speed_parameter_clamps_linear_velocity(robot: DemoRobot, peer: Peer) -> None:
    odom_sub = peer.subscribe("/odom")
    peer.send_json(
        {"op": "setParameters", "parameters": [{"name": "max_speed", "value": 0.25}], "id": "s"}
    )
    wait_until_sync(lambda: robot.parameters["max_speed"] == 0.25, what="max_speed set")
    peer.advertise(1, "/cmd_vel", "cdr", "geometry_msgs/msg/Twist")
    peer.publish(1, twist_cdr(5.0, 0.0))

    def linear(msg: Message) -> float | None:
        if (
            isinstance(msg, bytes)
            and msg[0] == 0x01
            and struct.unpack_from("<I", msg, 1)[0] == odom_sub
        ):
            odom: Any = TS.deserialize_cdr(msg[13:], "nav_msgs/msg/Odometry")
            return float(odom.twist.twist.linear.x) if odom.twist.twist.linear.x else None
        return None

    assert peer.wait_for(linear, what="moving odom") == 0.25
    assert robot.received_cmd_vel()[-1].linear_x == 5.0  # the log keeps what was sent


# --------------------------------------------------------------------------- services


def test_set_led_service(robot: DemoRobot, peer: Peer) -> None:
    peer.send_json({"op": "subscribeParameterUpdates", "parameterNames": ["led"]})
    response = peer.call_service("/set_led", SET_BOOL_TRUE)
    assert isinstance(response, bytes)
    reply: Any = TS.deserialize_cdr(response, "std_srvs/srv/SetBool_Response")
    assert (reply.success, reply.message) == (True, "led on")
    assert robot.parameters["led"] is True
    assert robot.led is True

    def led_update() -> bool | None:
        for msg in peer.parameter_values:
            for param in msg["parameters"]:
                if param["name"] == "led":
                    return bool(param["value"])
        return None

    # Subscribers of the led parameter hear about the change made through the service.
    assert peer.wait_state(led_update, what="led parameter update") is True

    response = peer.call_service("/set_led", SET_BOOL_FALSE)
    assert isinstance(response, bytes)
    reply = TS.deserialize_cdr(response, "std_srvs/srv/SetBool_Response")
    assert (reply.success, reply.message) == (True, "led off")
    assert robot.parameters["led"] is False


def test_set_led_rejects_garbage(robot: DemoRobot, peer: Peer) -> None:
    failure = peer.call_service("/set_led", b"\x07")
    assert isinstance(failure, dict)
    assert failure["op"] == "serviceCallFailure"
    assert robot.parameters["led"] is False


def test_reset_odometry_service(robot: DemoRobot, peer: Peer) -> None:
    peer.advertise(1, "/cmd_vel", "cdr", "geometry_msgs/msg/Twist")
    peer.publish(1, twist_cdr(1.0, 0.5))
    wait_until_sync(lambda: robot.pose[0] > 0.02, what="robot to move")
    peer.publish(1, twist_cdr(0.0, 0.0))
    wait_until_sync(lambda: len(robot.received_cmd_vel()) == 2, what="zero twist logged")
    response = peer.call_service("/reset_odometry", TRIGGER_REQUEST)
    assert isinstance(response, bytes)
    reply: Any = TS.deserialize_cdr(response, "std_srvs/srv/Trigger_Response")
    assert (reply.success, reply.message) == (True, "odometry reset")
    assert robot.pose == (0.0, 0.0, 0.0)


def test_reset_odometry_accepts_a_header_only_request(peer: Peer) -> None:
    # Some encoders write an empty request as the 4-byte CDR header alone.
    response = peer.call_service("/reset_odometry", b"\x00\x01\x00\x00")
    assert isinstance(response, bytes)
    reply: Any = TS.deserialize_cdr(response, "std_srvs/srv/Trigger_Response")
    assert reply.success


# --------------------------------------------------------------------------- parameters


def _param_values(request_id: str) -> Callable[[Message], dict[str, Any] | None]:
    def pick(msg: Message) -> dict[str, Any] | None:
        if (
            isinstance(msg, dict)
            and msg.get("op") == "parameterValues"
            and msg.get("id") == request_id
        ):
            return {p["name"]: p for p in msg["parameters"]}
        return None

    return pick


def test_get_parameters(peer: Peer) -> None:
    peer.send_json({"op": "getParameters", "parameterNames": [], "id": "all"})
    params = peer.wait_for(_param_values("all"), what="all parameters")
    assert set(params) == {"max_speed", "robot_name", "led"}
    assert params["max_speed"]["value"] == 1.0
    assert params["max_speed"]["type"] == "float64"
    assert params["robot_name"]["value"] == "rmb-demo-robot"
    assert params["led"]["value"] is False

    peer.send_json({"op": "getParameters", "parameterNames": ["led", "nope"], "id": "some"})
    params = peer.wait_for(_param_values("some"), what="some parameters")
    assert set(params) == {"led"}


def test_set_parameters(robot: DemoRobot, peer: Peer) -> None:
    with open_ws(robot.url) as ws2:
        watcher = Peer(ws2)
        watcher.handshake()
        watcher.send_json({"op": "subscribeParameterUpdates", "parameterNames": ["max_speed"]})
        # Subscriptions are processed in order: a get afterwards proves the subscribe landed.
        watcher.send_json({"op": "getParameters", "parameterNames": ["max_speed"], "id": "sync"})
        watcher.wait_for(_param_values("sync"), what="sync")

        peer.send_json(
            {
                "op": "setParameters",
                "parameters": [
                    {"name": "max_speed", "value": 0.5, "type": "float64"},
                    {"name": "led", "value": "yes"},  # wrong type: kept as it was
                    {"name": "robot_name", "value": "rover"},
                    {"name": "extra", "value": 3},
                ],
                "id": "set",
            }
        )
        params = peer.wait_for(_param_values("set"), what="set reply")
        assert params["max_speed"]["value"] == 0.5
        assert params["led"]["value"] is False
        assert params["robot_name"]["value"] == "rover"
        assert robot.parameters == {
            "max_speed": 0.5,
            "robot_name": "rover",
            "led": False,
            "extra": 3,
        }

        def update(msg: Message) -> float | None:
            if isinstance(msg, dict) and msg.get("op") == "parameterValues" and "id" not in msg:
                for param in msg["parameters"]:
                    if param["name"] == "max_speed":
                        return float(param["value"])
            return None

        assert watcher.wait_for(update, what="published max_speed") == 0.5


# --------------------------------------------------------------------------- lifecycle


def test_stop_is_idempotent_and_leaves_no_thread() -> None:
    before = set(threading.enumerate())
    demo = DemoRobot()
    demo.stop()  # never started: no-op
    port = demo.start()
    assert port == demo.port > 0
    assert demo.running
    assert set(threading.enumerate()) - before  # the simulation thread
    with pytest.raises(RuntimeError):
        demo.start()
    demo.stop()
    demo.stop()
    assert not demo.running
    assert set(threading.enumerate()) == before
    assert demo.port == port  # still readable after stop
    # The listening socket is gone once stop() returns. (Probed by binding, not connecting: a
    # connect to a just-freed ephemeral port can self-connect and look like a live server.)
    with socket.socket() as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        probe.bind(("127.0.0.1", port))


def test_restart_on_the_same_port() -> None:
    first = DemoRobot()
    port = first.start()
    first.stop()
    # A fixed port (as a --serve user would pass) is immediately reusable after stop().
    demo = DemoRobot(port=port)
    with demo:
        assert demo.port == port
        with open_ws(demo.url) as ws:
            Peer(ws).handshake()
    # The same object can be started again; its state survives.
    demo.start()
    try:
        assert demo.port == port
        with open_ws(demo.url) as ws:
            Peer(ws).handshake()
    finally:
        demo.stop()


def test_start_on_a_busy_port_raises_and_leaves_nothing_running(robot: DemoRobot) -> None:
    before = set(threading.enumerate())
    clash = DemoRobot(port=robot.port)
    with pytest.raises(RuntimeError, match="bind"):
        clash.start()
    assert not clash.running
    assert set(threading.enumerate()) == before
    clash.stop()  # still fine


def test_foxglove_app_url(robot: DemoRobot) -> None:
    url = robot.foxglove_app_url
    assert url is not None
    assert "ds=foxglove-websocket" in url
    assert str(robot.port) in url


def test_port_before_start_raises() -> None:
    with pytest.raises(RuntimeError):
        _ = DemoRobot().port


@pytest.mark.parametrize(
    "kwargs",
    [{"rate_hz": 0.0}, {"camera_hz": -1.0}, {"rate_hz": math.nan}, {"port": 70000}, {"max_log": 0}],
)
def test_invalid_arguments(kwargs: dict[str, Any]) -> None:
    with pytest.raises(ValueError):  # noqa: PT011 - message varies per argument
        DemoRobot(**kwargs)


def test_cmd_vel_log_is_bounded() -> None:
    small = DemoRobot(max_log=2)
    with small, open_ws(small.url) as ws:
        peer = Peer(ws)
        peer.handshake()
        peer.advertise(1, "/cmd_vel", "cdr", "geometry_msgs/msg/Twist")
        for i in range(3):
            peer.publish(1, twist_cdr(0.1 * i, 0.0))
        wait_until_sync(
            lambda: [c.linear_x for c in small.received_cmd_vel()] == [0.1, 0.2],
            what="oldest entry dropped",
        )


# --------------------------------------------------------------------------- png


def _decode_png_rgb(png: bytes) -> tuple[int, int, bytes]:
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    pos = 8
    width = height = 0
    idat = b""
    while pos < len(png):
        (length,) = struct.unpack_from(">I", png, pos)
        kind = png[pos + 4 : pos + 8]
        body = png[pos + 8 : pos + 8 + length]
        (crc,) = struct.unpack_from(">I", png, pos + 8 + length)
        assert crc == zlib.crc32(kind + body) & 0xFFFFFFFF
        if kind == b"IHDR":
            width, height, depth, colour, _, _, _ = struct.unpack(">IIBBBBB", body)
            assert (depth, colour) == (8, 2)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    raw = zlib.decompress(idat)
    stride = width * 3
    rows = [raw[r * (stride + 1) : (r + 1) * (stride + 1)] for r in range(height)]
    assert all(row[0] == 0 for row in rows)
    return width, height, b"".join(row[1:] for row in rows)


def test_png_encoder_round_trips() -> None:
    rgb = bytes(range(256)) * 3  # 16x16 RGB
    width, height, decoded = _decode_png_rgb(encode_png_rgb(16, 16, rgb))
    assert (width, height, decoded) == (16, 16, rgb)
    with pytest.raises(ValueError, match="expected"):
        encode_png_rgb(16, 16, b"short")


def test_camera_dot_follows_the_robot() -> None:
    renderer = CameraRenderer()
    _, _, at_origin = _decode_png_rgb(renderer.render(0.0, 0.0, 0.0))
    _, _, moved = _decode_png_rgb(renderer.render(1.5, -1.0, 1.0, led=True))
    assert at_origin != moved

    def pixel(rgb: bytes, px: int, py: int) -> bytes:
        i = (py * 160 + px) * 3
        return rgb[i : i + 3]

    assert pixel(at_origin, 80, 60) == bytes((255, 150, 40))  # orange dot at the centre
    assert pixel(moved, 80 + 30, 60 + 20) == bytes((60, 220, 90))  # green: led on
