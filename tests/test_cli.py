"""The ``rmb`` command as a user runs it, in processes of its own: against
the demo robot (the official Foxglove SDK server, recording every velocity
command it receives) and against rosbridge_server_rs on a real ROS 2 graph.
Output shapes, exit codes (0 ok, 1 runtime, 2 usage, 130 Ctrl-C, 141 closed
pipe), YAML in and out, and what reached the robot."""

from __future__ import annotations

import json
import math
import re
import signal
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import pytest
import yaml

from _cli_run import ROOT, rmb, rmb_proc
from _util import wait_until_sync
from peers.rosbridge import RosBridge, RosGraph
from ros_mobile_bridge import __version__
from ros_mobile_bridge._cli._format import dump_yaml, json_line, plain
from ros_mobile_bridge.demo import DemoRobot

pytest_plugins = ["peers.ros_fixtures"]

BACKENDS = ["asyncio", "trio"]
TWIST = "geometry_msgs/msg/Twist"


def read_until(stream: IO[str] | None, found: Callable[[str], bool], lines: int = 200) -> str:
    """The first line of ``stream`` for which ``found`` holds (the test's
    timeout bounds the wait)."""
    assert stream is not None
    for _ in range(lines):
        line = stream.readline()
        assert line, "the stream ended first"
        if found(line):
            return line
    raise AssertionError("not found")


def interrupt(proc: subprocess.Popen[str]) -> tuple[str, str]:
    """Ctrl-C, then the rest of the output."""
    proc.send_signal(signal.SIGINT)
    try:
        return proc.communicate(timeout=20)
    finally:
        proc.kill()


def one_line(stderr: str) -> str:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rmb: "), stderr
    assert "Traceback" not in stderr
    return lines[0]


def strict_json(line: str) -> Any:
    def refuse(name: str) -> Any:
        raise ValueError(f"not JSON: {name}")

    return json.loads(line, parse_constant=refuse)


# -- global options ------------------------------------------------------------------------


def test_version() -> None:
    result = rmb("--version", process=True)  # (the module entry point, as a user starts it)
    assert result.returncode == 0
    assert result.stdout.strip() == f"rmb (ros-mobile-bridge) {__version__}"


def test_the_url_comes_from_rmb_url_a_leading_argument_or_u(robot: DemoRobot) -> None:
    field = ("--once", "--field", "header.frame_id")
    from_env = rmb("echo", "/odom", *field, url=robot.url)
    assert (from_env.returncode, from_env.stdout) == (0, "odom\n---\n"), from_env.stderr
    host_port = robot.url.removeprefix("ws://")
    leading = rmb("echo", host_port, "/odom", *field, url="127.0.0.1:1")
    assert (leading.returncode, leading.stdout) == (0, "odom\n---\n"), leading.stderr
    option = rmb("-u", robot.url, "echo", "/odom", *field, url="127.0.0.1:1")
    assert (option.returncode, option.stdout) == (0, "odom\n---\n"), option.stderr
    after_verb = rmb("echo", "/odom", "-u", robot.url, *field)
    assert (after_verb.returncode, after_verb.stdout) == (0, "odom\n---\n"), after_verb.stderr


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (("echo", "/odom"), "no robot address"),
        (("echo",), "missing TOPIC"),
        (("ecko", "/odom"), "did you mean echo"),
        (("param",), "verbs:\n  param list "),
        ((), "a COMMAND is needed"),
        (("pub", "/cmd_vel"), "missing TYPE"),
        # a ROS name is never read as the address; unquoted YAML gets a hint
        (("echo", "/odom", "extra"), "unexpected argument(s): extra"),
        (
            ("pub", "/cmd_vel", "geometry_msgs/msg/Twist", "linear:", "{x: 1}"),
            "quote YAML or JSON as one argument",
        ),
    ],
)
def test_usage_mistakes_exit_2_with_one_line(args: tuple[str, ...], says: str) -> None:
    result = rmb(*args)
    assert result.returncode == 2, result.stderr
    if not args:  # once as a process: the status is the process's
        assert rmb(*args, process=True).returncode == 2
    assert says in result.stderr and "Traceback" not in result.stderr


def test_backend_trio_without_trio_is_one_line() -> None:
    code = (
        "import sys; sys.modules['trio'] = None\n"
        "from ros_mobile_bridge.cli import main\n"
        "sys.exit(main(['--backend', 'trio', 'topics', '127.0.0.1:1']))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert result.returncode == 2
    assert "needs trio: pip install 'ros-mobile-bridge[trio]'" in one_line(result.stderr)


def test_a_refused_connection_is_a_runtime_failure() -> None:
    result = rmb("info", "-u", "127.0.0.1:1", "--timeout", "2", process=True)  # (the exit status)
    assert result.returncode == 1
    assert "ConnectError" in one_line(result.stderr)


def test_verbose_shows_the_traceback() -> None:
    result = rmb("-v", "info", "-u", "127.0.0.1:1", "--timeout", "2")
    assert result.returncode == 1
    assert "Traceback" in result.stderr


# -- echo ----------------------------------------------------------------------------------


def test_echo_prints_ros2_yaml_documents(robot: DemoRobot) -> None:
    result = rmb("echo", "/battery", "-n", "2", url=robot.url)
    assert result.returncode == 0, result.stderr
    assert result.stdout.endswith("---\n")
    docs = [d for d in yaml.safe_load_all(result.stdout) if d is not None]
    assert len(docs) == 2
    assert docs[0]["serial_number"] == "RMB-DEMO-0001"
    assert docs[0]["cell_voltage"] and all(isinstance(v, float) for v in docs[0]["cell_voltage"])
    assert "\ncell_voltage:\n- " in result.stdout  # block style, as ros2 prints it


def test_echo_once_field_and_no_arr(robot: DemoRobot) -> None:
    once = rmb("echo", "/odom", "--once", url=robot.url)
    assert once.returncode == 0, once.stderr
    assert once.stdout.count("---\n") == 1
    x = rmb("echo", "/odom", "--once", "--field", "pose.pose.position", url=robot.url)
    assert set(yaml.safe_load(x.stdout.split("---")[0])) == {"x", "y", "z"}
    no_arr = rmb("echo", "/odom", "--once", "--no-arr", url=robot.url)
    doc = yaml.safe_load(no_arr.stdout.split("---")[0])
    assert doc["pose"]["covariance"] == "<array: 36 items>"
    bad = rmb("echo", "/odom", "--once", "--field", "pose.nosuch", url=robot.url)
    assert bad.returncode == 2
    assert "no field 'nosuch'" in one_line(bad.stderr)


def test_echo_json_lines_parse(robot: DemoRobot) -> None:
    result = rmb("echo", "/odom", "-n", "3", "--json", url=robot.url)
    assert result.returncode == 0, result.stderr
    records = [strict_json(line) for line in result.stdout.splitlines()]
    assert len(records) == 3
    assert {r["topic"] for r in records} == {"/odom"}
    assert len(records[0]["data"]["pose"]["covariance"]) == 36  # full arrays in JSON


@pytest.mark.parametrize("backend", BACKENDS)
def test_echo_of_a_missing_topic_names_the_nearest_then_ctrl_c_exits_130(
    robot: DemoRobot, backend: str
) -> None:
    proc = rmb_proc("--backend", backend, "echo", "/odm", url=robot.url)
    try:
        line = read_until(proc.stderr, lambda s: "has not appeared" in s)
    finally:
        _out, err = interrupt(proc)
    assert "nearest: /odom" in line
    assert proc.returncode == 130, err
    assert "Traceback" not in err


@pytest.mark.parametrize("backend", BACKENDS)
def test_echo_into_head_ends_quietly(robot: DemoRobot, backend: str) -> None:
    shell = (
        f"{sys.executable} -m ros_mobile_bridge --backend {backend} echo {robot.url} /odom"
        " | head -1; echo status=${PIPESTATUS[0]} >&2"
    )
    result = subprocess.run(
        ["bash", "-c", shell], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert result.stdout == "header:\n"
    assert "Traceback" not in result.stderr and "Exception ignored" not in result.stderr
    assert f"status={128 + signal.SIGPIPE}" in result.stderr, result.stderr


def test_non_finite_floats_print_as_yaml_and_as_json_null() -> None:
    message = {"ranges": [1.5, math.nan, math.inf, -math.inf], "poses": [{"x": 1.0}, {"x": 2.0}]}
    text = dump_yaml(plain(message))
    assert "- .nan\n- .inf\n- -.inf\n" in text
    assert "poses:\n- x: 1.0\n- x: 2.0\n" in text  # a list of dicts in YAML, not JSON
    back = yaml.safe_load(text)
    assert math.isnan(back["ranges"][1]) and back["ranges"][2] == math.inf
    line = json_line({"data": plain(message)})
    assert strict_json(line)["data"]["ranges"] == [1.5, None, None, None]


# -- hz, bw, info ---------------------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("verb", ["hz", "bw"])
def test_hz_and_bw_print_live_figures(robot: DemoRobot, backend: str, verb: str) -> None:
    proc = rmb_proc("--backend", backend, verb, "/odom", url=robot.url)
    try:
        if verb == "hz":
            line = read_until(proc.stdout, lambda s: s.startswith("average rate: "))
            stats = read_until(proc.stdout, lambda _s: True)
        else:
            line = read_until(proc.stdout, lambda s: "/s from " in s)
            stats = read_until(proc.stdout, lambda _s: True)
    finally:
        _out, err = interrupt(proc)
    if verb == "hz":
        assert float(line.split(":")[1]) > 1.0
        assert re.match(r"\tmin: [\d.]+s max: [\d.]+s std dev: [\d.]+s window: \d+", stats)
    else:
        assert re.match(r"[\d.]+ (B|KB|MB)/s from \d+ messages", line)
        assert stats.startswith("\tMessage size mean: ")
    assert proc.returncode == 130, err


def test_info_of_the_server_and_of_a_topic(robot: DemoRobot) -> None:
    server = rmb("info", url=robot.url)
    assert server.returncode == 0, server.stderr
    assert "protocol: foxglove-ws" in server.stdout
    assert "capabilities: " in server.stdout and "services" in server.stdout
    topic = rmb("info", "/odom", url=robot.url)
    assert topic.returncode == 0, topic.stderr
    assert topic.stdout.splitlines()[0] == "Type: nav_msgs/msg/Odometry"
    # counted in the robot's connection graph
    assert "Publisher count: 1" in topic.stdout and "Subscription count: 0" in topic.stdout
    missing = rmb("info", "/odm", url=robot.url)
    assert missing.returncode == 1
    assert "nearest: /odom" in one_line(missing.stderr)


def test_interface_show_from_the_robot(robot: DemoRobot) -> None:
    twist = rmb("interface", "show", TWIST, "--url", robot.url)
    assert twist.returncode == 0, twist.stderr
    assert twist.stdout.splitlines()[:2] == ["geometry_msgs/msg/Vector3 linear", "\tfloat64 x"]
    assert twist.stderr == ""  # the robot's Twist is the bundled one
    srv = rmb("interface", "show", "std_srvs/srv/SetBool", robot.url)
    assert srv.stdout.split("---") == ["bool data\n", "\nbool success\nstring message\n"]
    unknown = rmb("interface", "show", "nosuch_msgs/msg/Nothing", "--url", robot.url)
    assert unknown.returncode == 1
    assert "unknown type" in one_line(unknown.stderr)


# -- pub -------------------------------------------------------------------------------------


def test_pub_times_3_sends_three_then_the_zero(robot: DemoRobot) -> None:
    before = len(robot.received_cmd_vel())
    result = rmb(
        "pub", "/cmd_vel", TWIST, "{linear: {x: 0.2}}", "-t", "3", "-r", "20", url=robot.url
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [
        f"publishing #{n}: {{linear: {{x: 0.2}}}}" for n in (1, 2, 3)
    ]
    wait_until_sync(lambda: len(robot.received_cmd_vel()) - before >= 4, 10)
    assert [c.linear_x for c in robot.received_cmd_vel()[before:]] == [0.2, 0.2, 0.2, 0.0]


def test_pub_once_on_a_velocity_topic_says_why_the_robot_will_not_move(robot: DemoRobot) -> None:
    before = len(robot.received_cmd_vel())
    result = rmb("pub", "/cmd_vel", TWIST, "{linear: {x: 0.3}}", "--once", url=robot.url)
    assert result.returncode == 0, result.stderr
    assert "use -r 10" in one_line(result.stderr).lower()
    wait_until_sync(lambda: len(robot.received_cmd_vel()) - before >= 2, 10)
    assert [c.linear_x for c in robot.received_cmd_vel()[before:]] == [0.3, 0.0]


@pytest.mark.parametrize("backend", BACKENDS)
def test_pub_repeats_at_1hz_until_ctrl_c_then_stops_the_robot(
    robot: DemoRobot, backend: str
) -> None:
    before = len(robot.received_cmd_vel())
    proc = rmb_proc(
        "--backend", backend, "pub", "/cmd_vel", TWIST, "{angular: {z: 0.5}}", url=robot.url
    )
    try:
        wait_until_sync(lambda: len(robot.received_cmd_vel()) - before >= 2, 10)
    finally:
        out, err = interrupt(proc)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert out.startswith("publishing #1: {angular: {z: 0.5}}\npublishing #2: ")
    wait_until_sync(lambda: robot.received_cmd_vel()[-1].angular_z == 0.0, 10)
    got = [c.angular_z for c in robot.received_cmd_vel()[before:]]
    assert got[-1] == 0.0 and set(got[:-1]) == {0.5}, got


@pytest.mark.parametrize(
    ("data", "says"),
    [
        (
            "{linar: {x: 0.1}}",
            "rmb: MessageError: publish /cmd_vel: cannot encode geometry_msgs/msg/Twist: "
            "field 'linar': unknown field (its fields: linear, angular)",
        ),
        ("{linear: {x: fast}}", "expected a number"),
        ("{linear: {x: 0.1}", "not valid YAML"),
        ("[1, 2]", "must be a YAML mapping"),
    ],
)
def test_pub_bad_input_exits_2_in_one_line_and_sends_nothing(
    robot: DemoRobot, data: str, says: str
) -> None:
    before = len(robot.received_cmd_vel())
    result = rmb("pub", "/cmd_vel", TWIST, data, "--once", url=robot.url)
    assert result.returncode == 2
    assert says in one_line(result.stderr)
    assert robot.received_cmd_vel()[before:] == []


# -- call, param, action -------------------------------------------------------------------


def test_call_takes_yaml_and_a_bad_field_exits_2_like_pub(robot: DemoRobot) -> None:
    ok = rmb("call", "/set_led", "{data: true}", url=robot.url)
    assert ok.returncode == 0, ok.stderr
    assert json.loads(ok.stdout) == {"success": True, "message": "led on"}
    bad = rmb("call", "/set_led", "{dat: true}", url=robot.url)
    assert bad.returncode == 2
    assert one_line(bad.stderr).startswith("rmb: MessageError: call_service /set_led: ")
    assert "field 'dat': unknown field" in one_line(bad.stderr)
    missing = rmb("call", "/set_le", "{data: true}", url=robot.url)
    assert missing.returncode == 1
    assert "nearest: /set_led" in one_line(missing.stderr)


def test_param_get_set_list(robot: DemoRobot) -> None:
    listed = rmb("param", "list", url=robot.url)
    assert listed.returncode == 0, listed.stderr
    assert {"led", "max_speed", "robot_name"} <= set(listed.stdout.split())
    done = rmb("param", "set", "max_speed", "0.6", url=robot.url)
    assert done.returncode == 0, done.stderr
    assert robot.parameters["max_speed"] == 0.6
    got = rmb("param", "get", "max_speed", url=robot.url)
    assert (got.returncode, got.stdout) == (0, "max_speed: 0.6\n")


def test_param_that_is_not_set_or_not_found_exits_1(robot: DemoRobot) -> None:
    refused = rmb("param", "set", "max_speed", "fast", url=robot.url)
    assert refused.returncode == 1
    assert "failed" in one_line(refused.stderr)
    assert robot.parameters["max_speed"] != "fast"
    missing = rmb("param", "get", "max_sped", url=robot.url)
    assert missing.returncode == 1
    assert "nearest: max_speed" in one_line(missing.stderr)


def test_params_alias_keeps_working_and_fails_plainly(robot: DemoRobot) -> None:
    ok = rmb("params", "--set", "max_speed=0.7", url=robot.url)
    assert ok.returncode == 0 and json.loads(ok.stdout) == {"max_speed": 0.7}
    no_equals = rmb("params", "--set", "max_speed", url=robot.url)
    assert no_equals.returncode == 2
    assert "NAME=VALUE" in one_line(no_equals.stderr)
    assert rmb("params", "--set", "max_speed=fast", url=robot.url).returncode == 1
    assert rmb("params", "nosuch", url=robot.url).returncode == 1


def test_every_library_error_is_one_line_naming_its_class(robot: DemoRobot) -> None:
    # the caller's mistake: a value that does not fit its field, exit 2
    misfit = rmb("pub", "/cmd_vel", TWIST, "{linear: {x: fast}}", "--once", url=robot.url)
    assert misfit.returncode == 2
    line = one_line(misfit.stderr)
    assert line.startswith("rmb: MessageError: publish /cmd_vel: cannot encode "), line
    assert "field 'linear.x'" in line
    # the robot's refusal: exit 1, the same shape
    refused = rmb(
        "action", "send", "/fib", "test_msgs/action/Fibonacci", "{order: 3}", url=robot.url
    )
    assert refused.returncode == 1
    assert one_line(refused.stderr).startswith("rmb: NotSupportedError: ")


def test_action_send_over_foxglove_is_a_one_line_runtime_error(robot: DemoRobot) -> None:
    result = rmb(
        "action", "send", "/fib", "test_msgs/action/Fibonacci", "{order: 3}", url=robot.url
    )
    assert result.returncode == 1
    assert "NotSupportedError" in one_line(result.stderr)


# -- against rosbridge_server_rs on a ROS 2 graph ------------------------------------------------


def test_rosbridge_echo_info_hz(rosbridge: RosBridge, ros_graph: RosGraph) -> None:
    echo = rmb("echo", "/chatter", "--once", url=rosbridge.url)
    assert echo.returncode == 0, echo.stderr
    assert yaml.safe_load(echo.stdout.split("---")[0])["data"].startswith("hello ")
    server = rmb("info", url=rosbridge.url)
    assert server.returncode == 0, server.stderr
    assert "protocol: rosbridge" in server.stdout
    topic = rmb("info", "/chatter", url=rosbridge.url)
    assert topic.returncode == 0, topic.stderr
    lines = topic.stdout.splitlines()
    assert lines[0] == "Type: std_msgs/msg/String"
    assert int(next(x for x in lines if x.startswith("Publisher count: ")).split(": ")[1]) >= 1
    proc = rmb_proc("hz", "/counter", url=rosbridge.url)
    try:
        line = read_until(proc.stdout, lambda s: s.startswith("average rate: "))
    finally:
        interrupt(proc)
    assert float(line.split(":")[1]) > 5.0  # the graph publishes /counter at 50 Hz
    assert proc.returncode == 130


def test_rosbridge_action_send_prints_feedback_and_the_result(rosbridge: RosBridge) -> None:
    result = rmb(
        "action",
        "send",
        "/fibonacci",
        "test_msgs/action/Fibonacci",
        "{order: 4}",
        url=rosbridge.url,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.count("Feedback:") >= 1
    assert result.stdout.rstrip().endswith("Goal finished with status: SUCCEEDED")
    tail = result.stdout.split("Result:\n")[1].split("Goal finished")[0]
    assert yaml.safe_load(textwrap.dedent(tail)) == {"sequence": [0, 1, 1, 2, 3, 5]}


@pytest.mark.parametrize("backend", BACKENDS)
def test_rosbridge_action_send_ctrl_c_cancels_the_goal(rosbridge: RosBridge, backend: str) -> None:
    proc = rmb_proc(
        "--backend",
        backend,
        "action",
        "send",
        "/fibonacci",
        "test_msgs/action/Fibonacci",
        "{order: 50}",
        url=rosbridge.url,
    )
    try:
        read_until(proc.stdout, lambda s: s.startswith("Feedback:"))
    finally:
        out, err = interrupt(proc)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert "Goal finished with status: CANCELED" in out, out + err


def test_ros2_spellings_are_aliases(robot: DemoRobot) -> None:
    listed = rmb("topic", "list", "-t", url=robot.url)
    assert "/odom  [nav_msgs/msg/Odometry]" in listed.stdout.splitlines()
    called = rmb("service", "call", "/set_led", "{data: false}", url=robot.url)
    assert json.loads(called.stdout) == {"success": True, "message": "led off"}
    info = rmb("topic", "info", "/battery", url=robot.url)
    assert info.stdout.startswith("Type: sensor_msgs/msg/BatteryState\n")


def test_pub_of_a_non_twist_type_on_a_velocity_topic_warns_that_nothing_stops_it(
    robot: DemoRobot,
) -> None:
    result = rmb(
        "pub", "/cmd_vel", "std_msgs/msg/String", "{data: go}", "--once",
        "--no-velocity-check", url=robot.url,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "gets no stop command when rmb ends" in result.stderr
    assert "watchdog" in result.stderr


def test_record_of_a_misspelt_topic_names_the_nearest(robot: DemoRobot, tmp_path: Path) -> None:
    proc = rmb_proc("record", "/odmo", "-o", str(tmp_path / "x.mcap"), url=robot.url)
    try:
        line = read_until(proc.stderr, lambda s: "has not appeared" in s)
    finally:
        interrupt(proc)
    assert "nearest: /odom" in line
    assert proc.returncode == 130


def test_pub_keeps_publishing_across_a_reconnect_then_stops_on_ctrl_c(
    rosbridge_factory: Any, ros_graph: RosGraph
) -> None:
    # the bridge goes away and comes back on its port: pub waits for the
    # client's reconnect instead of exiting 1 with the robot still moving
    bridge = rosbridge_factory()
    port = bridge.port
    proc = rmb_proc(
        "pub", "/rmb_in", "std_msgs/msg/String", "{data: tick}", "-r", "10", url=bridge.url
    )
    try:
        wait_until_sync(
            lambda: {"data": "tick"} in ros_graph.received("/rmb_in"), 30, interval=0.02
        )
        bridge.stop()
        read_until(proc.stderr, lambda s: "connection lost" in s)  # the library's one line
        ros_graph.command({"cmd": "clear", "topic": "/rmb_in"})
        rosbridge_factory(port=port)
        read_until(proc.stderr, lambda s: "connected again" in s)
        wait_until_sync(
            lambda: {"data": "tick"} in ros_graph.received("/rmb_in"), 30, interval=0.02
        )
        assert proc.poll() is None  # still running
    finally:
        interrupt(proc)
    assert proc.returncode == 130
