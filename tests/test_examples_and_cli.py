"""The examples and the ``rmb`` command run against the demo robot, as a user
would run them (separate processes)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from ros_mobile_bridge.demo import DemoRobot

ROOT = Path(__file__).resolve().parent.parent


def run(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
        check=False,
    )


@pytest.mark.parametrize(
    "script", ["quickstart_asyncio.py", "quickstart_trio.py", "teleop_watchdog.py"]
)
def test_example_runs_against_the_demo_robot(robot: DemoRobot, script: str) -> None:
    before = len(robot.received_cmd_vel())
    result = run(
        str(ROOT / "examples" / script), robot.url, *(["0.5"] if "teleop" in script else [])
    )
    assert result.returncode == 0, result.stderr
    if script != "quickstart_trio.py":
        commands = robot.received_cmd_vel()[before:]
        assert commands, "the example published no velocity command"
        assert (commands[-1].linear_x, commands[-1].angular_z) == (0.0, 0.0)


def test_rmb_demo_main_job_exits_zero_with_the_zero_twist_last() -> None:
    result = run("-m", "ros_mobile_bridge", "demo", "--seconds", "1")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "OK: the zero Twist arrived last" in result.stdout


def test_rmb_demo_on_trio() -> None:
    result = run("-m", "ros_mobile_bridge", "--backend", "trio", "demo", "--seconds", "0.5")
    assert result.returncode == 0, result.stdout + result.stderr


def test_rmb_topics_echo_call_params(robot: DemoRobot) -> None:
    topics = run("-m", "ros_mobile_bridge", "topics", robot.url, "-t")
    assert topics.returncode == 0, topics.stderr
    assert "/odom  [nav_msgs/msg/Odometry]" in topics.stdout.splitlines()
    echo = run("-m", "ros_mobile_bridge", "echo", robot.url, "/status", "-n", "2", "--json")
    assert echo.returncode == 0, echo.stderr
    lines = [json.loads(line) for line in echo.stdout.splitlines()]
    assert len(lines) == 2 and lines[0]["topic"] == "/status" and "mode" in lines[0]["data"]
    call = run("-m", "ros_mobile_bridge", "call", robot.url, "/set_led", '{"data": true}')
    assert call.returncode == 0, call.stderr
    assert json.loads(call.stdout) == {"success": True, "message": "led on"}
    params = run("-m", "ros_mobile_bridge", "params", robot.url, "--set", "max_speed=0.75")
    assert json.loads(params.stdout) == {"max_speed": 0.75}


def test_rmb_pub_reaches_the_robot(robot: DemoRobot) -> None:
    before = len(robot.received_cmd_vel())
    pub = run(
        "-m",
        "ros_mobile_bridge",
        "pub",
        robot.url,
        "/cmd_vel",
        "geometry_msgs/msg/Twist",
        '{"linear": {"x": 0.1}}',
        "-n",
        "2",
        "-r",
        "20",
    )
    assert pub.returncode == 0, pub.stderr
    got = robot.received_cmd_vel()[before:]
    assert [c.linear_x for c in got] == [0.1, 0.1, 0.0]  # two commands, then the teardown's zero


def test_rmb_reports_errors_plainly() -> None:
    refused = run("-m", "ros_mobile_bridge", "topics", "127.0.0.1:1", "--timeout", "2")
    assert refused.returncode == 1
    assert "ConnectError" in refused.stderr
    bad = run("-m", "ros_mobile_bridge", "topics", "host:notaport")
    assert bad.returncode == 2
    assert "invalid port" in bad.stderr


@pytest.mark.parametrize(
    ("schema", "data", "named"),
    [
        ("geometry_msgs/msg/Twst", '{"linear": {"x": 0.3}}', "geometry_msgs/msg/Twst"),
        ("std_msgs/msg/String", '{"data": "go"}', "std_msgs/msg/String"),
    ],
)
@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_rmb_pub_refuses_a_wrong_type_on_cmd_vel_in_one_line(
    robot: DemoRobot, schema: str, data: str, named: str, backend: str
) -> None:
    before = len(robot.received_cmd_vel())
    pub = run(
        "-m", "ros_mobile_bridge", "--backend", backend, "pub", robot.url, "/cmd_vel", schema, data
    )
    assert pub.returncode == 1
    lines = pub.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rmb: SchemaError: "), pub.stderr
    assert named in lines[0]
    assert robot.received_cmd_vel()[before:] == []  # nothing reached the robot


def test_rmb_pub_no_velocity_check_sends_what_it_is_told(robot: DemoRobot) -> None:
    pub = run(
        "-m",
        "ros_mobile_bridge",
        "pub",
        robot.url,
        "/cmd_vel",
        "std_msgs/msg/String",
        '{"data": "go"}',
        "--no-velocity-check",
        "--once",
    )
    assert pub.returncode == 0, pub.stderr
    assert pub.stdout.count("publishing #") == 1
