"""The String publisher of ``bench_rosbridge.py``: an rclpy node publishing
``std_msgs/msg/String`` in a tight loop at a target rate (an rclpy timer does
not reach 5 kHz). Run with the ROS peer environment's Python
(``PeerEnv.python``) in ``PeerEnv.node_env(domain_id)``; not run by hand.

    python bench/_ros_publisher.py TOPIC RATE CHARS

Each message's ``data`` is the decimal sequence number (0, 1, ...) padded
with zeros to 10 digits, a space, ``time.monotonic_ns()`` just before the
publish padded to 19 digits, a space, then filler up to CHARS characters, so
a receiver can count the messages it did not get and measure how long each
one took to reach it (the monotonic clock is the same in every process of
the machine). Publishing follows a fixed
schedule (message ``n`` is due at ``start + n / RATE``); when it falls behind,
the due messages go out back to back. Prints ``ready`` once the publisher
exists (publishing starts at once), then answers commands on stdin:

``count``
    ``count N T``: N messages published so far, at ``time.monotonic()`` T.
``quit``
    Exit (so does end of input).
"""

from __future__ import annotations

import sys
import threading
import time

import rclpy
from rclpy.qos import QoSProfile
from std_msgs.msg import String


def main() -> int:
    topic, rate, chars = sys.argv[1], float(sys.argv[2]), int(sys.argv[3])
    rclpy.init()
    node = rclpy.create_node("rmb_bench_publisher")
    publisher = node.create_publisher(String, topic, QoSProfile(depth=100))
    filler = "x" * max(0, chars - 31)
    published = 0
    stop = threading.Event()
    out_lock = threading.Lock()

    def answer(line: str) -> None:
        with out_lock:
            sys.stdout.write(line + "\n")
            sys.stdout.flush()

    def commands() -> None:
        for line in sys.stdin:
            word = line.strip()
            if word == "count":
                answer(f"count {published} {time.monotonic():.6f}")
            elif word == "quit":
                break
        stop.set()

    threading.Thread(target=commands, name="commands", daemon=True).start()
    answer("ready")
    period = 1.0 / rate
    start = time.monotonic()
    msg = String()
    try:
        while not stop.is_set():
            due = start + published * period
            now = time.monotonic()
            if now < due:
                wait = due - now
                if wait > 0.0002:
                    time.sleep(wait - 0.0001)
                continue
            msg.data = f"{published:010d} {time.monotonic_ns():019d} {filler}"
            publisher.publish(msg)
            published += 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
