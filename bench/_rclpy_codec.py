"""rclpy's own serialization, for scale beside ``bench_codec.py``'s class
table: ``rclpy.serialization.deserialize_message`` (rmw's C deserializer
into rclpy's generated message classes) and ``serialize_message``, calls per
second of CPU, on the class table's messages (TFMessage left out: the peer
environment has no tf2_msgs). Run with the ROS 2 peer environment's Python
(not run by hand; see bench/README.md):

    .venv/bin/python -c "import sys; sys.path.insert(0, 'tests'); \\
        from peers.ros_env import ensure_peer_env as e; import subprocess as s; \\
        p = e(); s.run([str(p.python), 'bench/_rclpy_codec.py'], env=p.env(0))"
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from nav_msgs.msg import Odometry  # type: ignore[import-not-found]
from rclpy.serialization import (  # type: ignore[import-not-found]
    deserialize_message,
    serialize_message,
)
from sensor_msgs.msg import (  # type: ignore[import-not-found]
    Image,
    Imu,
    JointState,
    PointCloud2,
    PointField,
)
from std_msgs.msg import String  # type: ignore[import-not-found]


def rate(func: Callable[[], object], seconds: float = 0.3) -> float:
    """Calls per second of CPU, the best batch of about a twentieth of ``seconds``."""
    func()
    batch = 1
    while True:
        start = time.thread_time()
        for _ in range(batch):
            func()
        if time.thread_time() - start > seconds / 20:
            break
        batch *= 2
    best = 0.0
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        start = time.thread_time()
        for _ in range(batch):
            func()
        best = max(best, batch / (time.thread_time() - start))
    return best


def cases() -> list[tuple[str, Any]]:
    odometry = Odometry()
    odometry.header.frame_id = "odom"
    odometry.child_frame_id = "base_link"
    joints = JointState()
    joints.name = [f"joint_{i}" for i in range(8)]
    joints.position = joints.velocity = joints.effort = [0.1] * 8
    image = Image(height=480, width=640, encoding="rgb8", step=1920)
    image.data = bytes(640 * 480 * 3)
    cloud = PointCloud2(height=1, width=100_000, point_step=16, row_step=1_600_000)
    cloud.fields = [
        PointField(name=name, offset=4 * i, datatype=7, count=1) for i, name in enumerate("xyzi")
    ]
    cloud.data = bytes(1_600_000)
    return [
        ("String", String(data="x" * 91)),
        ("Odometry", odometry),
        ("JointState 8", joints),
        ("Imu", Imu()),
        ("Image 640x480", image),
        ("PointCloud2 100k", cloud),
    ]


def main() -> None:
    print("rclpy.serialization (rmw's C (de)serializer, rclpy's message classes), calls/s of CPU")
    for label, message in cases():
        payload = serialize_message(message)
        kind = type(message)
        decode = rate(lambda p=payload, k=kind: deserialize_message(p, k))
        encode = rate(lambda m=message: serialize_message(m))
        print(
            f"{label:<17} {len(payload):>9,} | decode {decode / 1e3:9.1f} k/s "
            f"| encode {encode / 1e3:9.1f} k/s"
        )


if __name__ == "__main__":
    main()
