"""The robot side of ``bench/soak.py`` (started by it in subprocesses; not run by hand).

    python bench/_soak_robot.py foxglove PORT RUN
    python bench/_soak_robot.py ros RUN              (the ROS peer environment's Python)
    python bench/_soak_robot.py zenoh ROUTER DOMAIN SHARE RUN

Each is one robot: a camera (``/soak/camera``, ``sensor_msgs/msg/Image``
640x480 ``rgb8``, 30 Hz), odometry (``/soak/odom``, ``nav_msgs/msg/Odometry``,
50 Hz), each on a fixed schedule that never bursts to catch up, and a
subscriber to ``/cmd_vel`` (``geometry_msgs/msg/Twist``) that records every
control message it receives. Every published message carries ``RUN`` (this
robot process's number) in ``header.stamp.sec`` and its sequence number
(from 1) in ``header.stamp.nanosec``; every control Twist carries the client's
sequence number in ``linear.y`` (0, the client's parting zero Twist, is not
recorded).

``foxglove``: the Foxglove SDK server itself is the robot (a Foxglove
deployment's bridge runs in the robot's process, and dies with it), on
127.0.0.1:PORT, client publishing on; ``ros``: an rclpy node on the ROS 2
graph (``rosbridge_server_rs`` is the bridge, in its own process);
``zenoh``: zenoh-ros2-sdk nodes (zenoh peers, as rmw_zenoh's nodes are)
connected to the router at ROUTER, which reconnect to it by themselves when it
returns.

Everything is reported on stdout as it happens, one line each, written with
one ``os.write`` (a SIGKILL loses nothing already reported):

``ready``
    Publishers and the subscriber exist (the Foxglove server listens).
``cam SEQ T`` / ``odom SEQ T``
    Message SEQ was handed to the middleware at ``time.monotonic()`` T.
``cmd SEQ T``
    Control message SEQ arrived at T (the robot's first act on receipt).

It runs until its stdin closes, or it is killed.
"""

from __future__ import annotations

import os
import struct
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Final

CAMERA_TOPIC: Final = "/soak/camera"
ODOM_TOPIC: Final = "/soak/odom"
CMD_TOPIC: Final = "/cmd_vel"
IMAGE_TYPE: Final = "sensor_msgs/msg/Image"
ODOM_TYPE: Final = "nav_msgs/msg/Odometry"
TWIST_TYPE: Final = "geometry_msgs/msg/Twist"
CAMERA_HZ: Final = 30.0
ODOM_HZ: Final = 50.0
WIDTH: Final = 640
HEIGHT: Final = 480


def report(line: str) -> None:
    """One line on stdout, in one write (no buffer a SIGKILL could lose)."""
    os.write(1, (line + "\n").encode())


def paced(rate: float, publish: Callable[[int], None], stop: threading.Event) -> None:
    """Call ``publish(seq)`` for seq 1, 2, ... at ``rate`` per second on a fixed
    schedule; a late slot is skipped, never made up in a burst."""
    period = 1.0 / rate
    due = time.monotonic()
    seq = 0
    while not stop.is_set():
        now = time.monotonic()
        if due > now:
            stop.wait(due - now)
            continue
        if now - due > period:
            due = now
        seq += 1
        publish(seq)
        due += period


def run_streams(publishers: dict[str, Callable[[int], None]]) -> threading.Event:
    """One pacing thread per stream (``cam``, ``odom``); set the event to stop."""
    stop = threading.Event()
    rates = {"cam": CAMERA_HZ, "odom": ODOM_HZ}
    for name, publish in publishers.items():

        def send(seq: int, publish: Callable[[int], None] = publish, name: str = name) -> None:
            publish(seq)
            report(f"{name} {seq} {time.monotonic():.6f}")

        threading.Thread(
            target=paced, args=(rates[name], send, stop), name=name, daemon=True
        ).start()
    return stop


def record_command(seq: float) -> None:
    if seq > 0:
        report(f"cmd {int(seq)} {time.monotonic():.6f}")


def stamp(buf: bytearray, run: int, seq: int) -> bytes:
    """A CDR message with ``header.stamp`` = (run, seq): the stamp is the
    first field after the 4-byte encapsulation header."""
    struct.pack_into("<iI", buf, 4, run, seq)
    return bytes(buf)


# -- Foxglove ------------------------------------------------------------------------------


def foxglove_main(port: int, run: int) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import foxglove
    from _peer import _STORE, ReliabilityListener, cdr, payloads, twist_seq
    from foxglove import Channel, Schema
    from foxglove.websocket import Capability

    class Listener(ReliabilityListener):
        def on_message_data(self, client: Any, client_channel_id: int, data: bytes) -> None:
            with self.cond:
                name, encoding = self.client_channels.get((client.id, client_channel_id), ("", ""))
            if name == CMD_TOPIC:
                record_command(twist_seq(data, encoding))

    context = foxglove.Context()
    server = foxglove.start_server(
        name="rmb-soak-robot",
        host="127.0.0.1",
        port=port,
        context=context,
        server_listener=Listener(),
        capabilities=[Capability.ClientPublish],
        supported_encodings=["cdr", "json"],
    )
    odom = cdr(
        ODOM_TYPE,
        header=_STORE.types["std_msgs/msg/Header"](
            stamp=_STORE.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="odom"
        ),
        child_frame_id="base_link",
        pose=_STORE.types["geometry_msgs/msg/PoseWithCovariance"](
            pose=_STORE.types["geometry_msgs/msg/Pose"](
                position=_STORE.types["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0),
                orientation=_STORE.types["geometry_msgs/msg/Quaternion"](
                    x=0.0, y=0.0, z=0.0, w=1.0
                ),
            ),
            covariance=__import__("numpy").zeros(36),
        ),
        twist=_STORE.types["geometry_msgs/msg/TwistWithCovariance"](
            twist=_STORE.types["geometry_msgs/msg/Twist"](
                linear=_STORE.types["geometry_msgs/msg/Vector3"](x=0.1, y=0.0, z=0.0),
                angular=_STORE.types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
            ),
            covariance=__import__("numpy").zeros(36),
        ),
    )
    buffers = {"cam": bytearray(payloads()["/bench/image"]), "odom": bytearray(odom)}
    channels: dict[str, Channel] = {}
    for name, topic, typename in (
        ("cam", CAMERA_TOPIC, IMAGE_TYPE),
        ("odom", ODOM_TOPIC, ODOM_TYPE),
    ):
        msgdef, _ = _STORE.generate_msgdef(typename, ros_version=2)
        channels[name] = Channel(
            topic,
            message_encoding="cdr",
            schema=Schema(name=typename, encoding="ros2msg", data=msgdef.encode()),
            context=context,
        )

    def publisher(name: str) -> Callable[[int], None]:
        log, buf = channels[name].log, buffers[name]
        return lambda seq: log(stamp(buf, run, seq))

    stop = run_streams({name: publisher(name) for name in channels})
    report("ready")
    sys.stdin.read()
    stop.set()
    server.stop()


# -- ROS 2 (rclpy), behind rosbridge ----------------------------------------------------------


def ros_main(run: int) -> None:
    import rclpy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import Image

    rclpy.init()
    node = rclpy.create_node("rmb_soak_robot")
    camera_pub = node.create_publisher(Image, CAMERA_TOPIC, QoSProfile(depth=5))
    odom_pub = node.create_publisher(Odometry, ODOM_TOPIC, QoSProfile(depth=50))
    node.create_subscription(
        Twist, CMD_TOPIC, lambda msg: record_command(msg.linear.y), QoSProfile(depth=100)
    )
    image = Image(height=HEIGHT, width=WIDTH, encoding="rgb8", step=WIDTH * 3)
    image.header.frame_id = "camera"
    image.data = bytes(os.urandom(WIDTH * HEIGHT * 3))
    odom = Odometry(child_frame_id="base_link")
    odom.header.frame_id = "odom"
    odom.pose.pose.orientation.w = 1.0
    lock = threading.Lock()  # rclpy publishers from two threads: one at a time

    def publisher(pub: Any, msg: Any) -> Callable[[int], None]:
        def publish(seq: int) -> None:
            msg.header.stamp.sec = run
            msg.header.stamp.nanosec = seq
            with lock:
                pub.publish(msg)

        return publish

    stop = run_streams({"cam": publisher(camera_pub, image), "odom": publisher(odom_pub, odom)})
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, name="spin", daemon=True).start()
    report("ready")
    sys.stdin.read()
    stop.set()
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()


# -- Zenoh (zenoh-ros2-sdk nodes) ----------------------------------------------------------


def zenoh_main(router: str, domain: int, share: str, run: int) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    import numpy as np
    from zenoh_ros2_sdk import message_registry

    message_registry.get_registry(share)  # the first call fixes the directory
    from peers.zenoh_sdk_node import _offline

    _offline()
    import zenoh_ros2_sdk as sdk

    host, port = router.removeprefix("tcp/").rsplit(":", 1)
    where: dict[str, Any] = {"domain_id": domain, "router_ip": host, "router_port": int(port)}
    camera = sdk.ROS2Publisher(CAMERA_TOPIC, IMAGE_TYPE, node_name="soak_camera", **where)
    odom = sdk.ROS2Publisher(ODOM_TOPIC, ODOM_TYPE, node_name="soak_odom", **where)
    sub = sdk.ROS2Subscriber(
        CMD_TOPIC,
        TWIST_TYPE,
        lambda msg: record_command(msg.linear.y),
        node_name="soak_base",
        **where,
    )
    types = sdk.ZenohSession.get_instance(host, int(port)).store.types

    def t(name: str, **fields: Any) -> Any:
        return types[name](**fields)

    def header(seq: int, frame: str) -> Any:
        return t(
            "std_msgs/msg/Header",
            stamp=t("builtin_interfaces/msg/Time", sec=run, nanosec=seq),
            frame_id=frame,
        )

    pixels = np.frombuffer(os.urandom(WIDTH * HEIGHT * 3), dtype=np.uint8)
    vec = t("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0)
    pose = t(
        "geometry_msgs/msg/PoseWithCovariance",
        pose=t(
            "geometry_msgs/msg/Pose",
            position=t("geometry_msgs/msg/Point", x=1.0, y=2.0, z=0.0),
            orientation=t("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=1.0),
        ),
        covariance=np.zeros(36),
    )
    twist = t(
        "geometry_msgs/msg/TwistWithCovariance",
        twist=t("geometry_msgs/msg/Twist", linear=vec, angular=vec),
        covariance=np.zeros(36),
    )

    def camera_publish(seq: int) -> None:
        camera.publish(
            header=header(seq, "camera"),
            height=HEIGHT,
            width=WIDTH,
            encoding="rgb8",
            is_bigendian=0,
            step=WIDTH * 3,
            data=pixels,
        )

    def odom_publish(seq: int) -> None:
        odom.publish(header=header(seq, "odom"), child_frame_id="base_link", pose=pose, twist=twist)

    stop = run_streams({"cam": camera_publish, "odom": odom_publish})
    report("ready")
    sys.stdin.read()
    stop.set()
    for closer in (sub, camera, odom):
        closer.close()


if __name__ == "__main__":
    role = sys.argv[1]
    if role == "foxglove":
        foxglove_main(int(sys.argv[2]), int(sys.argv[3]))
    elif role == "ros":
        ros_main(int(sys.argv[2]))
    else:
        zenoh_main(sys.argv[2], int(sys.argv[3]), sys.argv[4], int(sys.argv[5]))
