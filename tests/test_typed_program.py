"""A user's program written against the message classes passes ``mypy
--strict``; the same program with a ROS developer's typical slips (a
misspelt keyword, a misspelt field of a received message, a ``str`` for a
``float64``, the wrong answer class, a served request's misspelt field
and the wrong reply class) makes mypy report each one, on the line
where it is made.

One mypy run checks both files (about 10 s: it reads the package's typed
classes once)."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(180)

pytest.importorskip("mypy", reason="mypy is in the [dev] extra (the 3.11 phase of the suite)")

GOOD = """
from __future__ import annotations

import ros_mobile_bridge as rmb
from ros_mobile_bridge.interfaces.example_interfaces.action import Fibonacci
from ros_mobile_bridge.interfaces.example_interfaces.srv import AddTwoInts
from ros_mobile_bridge.interfaces.geometry_msgs.msg import Twist, Vector3
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry
from ros_mobile_bridge.interfaces.sensor_msgs.msg import Image


async def drive(robot: rmb.Client) -> float:
    async with robot.subscribe("/odom", Odometry, max_hz=10) as sub:
        async for msg in sub:
            x: float = msg.data.pose.pose.position.x
            stamp: int = msg.data.header.stamp.sec
            covariance = msg.data.pose.covariance  # numpy float64 array
            print(x, stamp, float(covariance[0]))
            break
    await robot.publish("/cmd_vel", Twist(linear=Vector3(x=0.2)), priority="control")
    await robot.publish("/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 0.2}})
    reply = await robot.call_service("/add", AddTwoInts.Request(a=1, b=2), timeout=5)
    total: int = reply.sum
    async with robot.send_action_goal("/fibonacci", Fibonacci.Goal(order=5)) as goal:
        async for feedback in goal.feedback:
            partial: list[int] = [int(v) for v in feedback.sequence]
            print(partial)
        outcome = await goal.result()
        last = int(outcome.result.sequence[-1])
    image = Image(height=2, width=2, encoding="mono8", step=2, data=bytes(4))
    return x + total + last + float(image.data.sum())


async def add(robot: rmb.Client) -> None:
    async with robot.serve("/add", AddTwoInts) as requests:
        async for req in requests:
            await req.reply(AddTwoInts.Response(sum=req.args.a + req.args.b))
            await req.reply({"sum": 3})  # a dict stays accepted


def blocking(robot: rmb.SyncClient) -> int:
    with robot.subscribe("/odom", Odometry, timeout=5) as sub:
        y: float = sub.get().data.pose.pose.position.y
    reply = robot.call_service("/add", AddTwoInts.Request(a=1, b=2))
    return int(y) + reply.sum
"""

# each slip, and the words mypy's report of it must contain
BAD = {
    "Twist(linera=Vector3(x=0.2))": r'Unexpected keyword argument "linera" for "Twist"',
    "msg.data.pose.pose.postion": r'"Pose" has no attribute "postion"',
    'Vector3(x="0.2")': r'Argument "x" to "Vector3" has incompatible type "str"; expected "float"',
    "reply.total": r'"Response" has no attribute "total"',
    "outcome.result.sequnce": r'"Result" has no attribute "sequnce"',
    "req.args.c": r'"Request" has no attribute "c"',
    "SetBool.Response(success=True)": r'Argument 1 to "reply" of "ServiceRequest" has incompatible type',
}

BAD_PROGRAM = """
from __future__ import annotations

import ros_mobile_bridge as rmb
from ros_mobile_bridge.interfaces.example_interfaces.action import Fibonacci
from ros_mobile_bridge.interfaces.example_interfaces.srv import AddTwoInts
from ros_mobile_bridge.interfaces.geometry_msgs.msg import Twist, Vector3
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool


async def drive(robot: rmb.Client) -> None:
    await robot.publish("/cmd_vel", Twist(linera=Vector3(x=0.2)))
    async with robot.subscribe("/odom", Odometry) as sub:
        async for msg in sub:
            print(msg.data.pose.pose.postion)
    await robot.publish("/cmd_vel", Twist(linear=Vector3(x="0.2")))
    reply = await robot.call_service("/add", AddTwoInts.Request(a=1, b=2))
    print(reply.total)
    async with robot.send_action_goal("/fibonacci", Fibonacci.Goal(order=5)) as goal:
        outcome = await goal.result()
        print(outcome.result.sequnce)
    async with robot.serve("/add", AddTwoInts) as requests:
        async for req in requests:
            print(req.args.c)
            await req.reply(SetBool.Response(success=True))
"""


def _line_of(program: str, text: str) -> int:
    for number, line in enumerate(program.splitlines(), 1):
        if text in line:
            return number
    raise AssertionError(f"{text!r} is not in the program")


def test_mypy_strict_passes_the_program_and_names_each_slip(tmp_path: Path) -> None:
    good = tmp_path / "good_program.py"
    bad = tmp_path / "bad_program.py"
    good.write_text(textwrap.dedent(GOOD))
    bad.write_text(textwrap.dedent(BAD_PROGRAM))
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "mypy",
            "--strict",
            "--no-incremental",
            "--cache-dir",
            str(tmp_path / "cache"),
            "--hide-error-context",
            "--no-error-summary",
            str(good),
            str(bad),
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        check=False,
    )
    report = result.stdout + result.stderr
    assert "good_program.py" not in report, report  # the correct program passes --strict
    errors = [line for line in report.splitlines() if ": error:" in line]
    program = bad.read_text()
    for slip, words in BAD.items():
        line = _line_of(program, slip)
        found = [e for e in errors if e.startswith(f"{bad.name}:{line}:") and re.search(words, e)]
        assert found, f"mypy did not report {slip!r} on line {line}:\n{report}"
    assert len(errors) == len(BAD), report  # nothing else is reported
    assert result.returncode == 1, report
