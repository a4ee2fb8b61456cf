"""``rmb`` as a ros2 user types it, against the demo robot (the official
Foxglove SDK server) in processes of their own: relative names, the ros2
argument forms (``echo TOPIC TYPE``, ``service call NAME TYPE VALUES``,
``param get NODE NAME``), an address after the name, the verbs ros2 has
(``topic type|find``, ``service type|find``, ``param dump``, ``topics
-v|-c``, ``echo --csv|--flow-style``), ``--json`` with stable fields, and
one stderr line per event (Ctrl-C, a lost connection)."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
from typing import Any

import pytest
import yaml

from _cli_run import cli_env, rmb, rmb_proc
from peers.rosbridge import RosBridge
from ros_mobile_bridge.demo import DemoRobot

pytest_plugins = ["peers.ros_fixtures"]

BACKENDS = ["asyncio", "trio"]
TOPICS = {"/battery", "/camera/image/compressed", "/odom", "/pose", "/status"}


def ok(result: subprocess.CompletedProcess[str]) -> str:
    assert result.returncode == 0, result.stderr
    return result.stdout


def refused(result: subprocess.CompletedProcess[str], code: int = 2) -> str:
    assert result.returncode == code, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert lines and lines[-1].startswith("rmb"), result.stderr
    assert "Traceback" not in result.stderr
    return lines[-1]


def json_lines(text: str) -> list[Any]:
    return [json.loads(line) for line in text.splitlines()]


# -- names and argument forms ----------------------------------------------------------------


def test_relative_names_resolve_against_the_root(robot: DemoRobot) -> None:
    field = ("--once", "--field", "header.frame_id")
    assert ok(rmb("echo", "odom", *field, url=robot.url)) == "odom\n---\n"
    assert ok(rmb("topic", "echo", "odom", *field, url=robot.url)) == "odom\n---\n"
    assert ok(rmb("topic", "type", "odom", url=robot.url)) == "nav_msgs/msg/Odometry\n"
    called = ok(rmb("service", "call", "set_led", "{data: true}", url=robot.url))
    assert json.loads(called) == {"success": True, "message": "led on"}
    assert ok(rmb("info", "battery", url=robot.url)).startswith("Type: sensor_msgs/msg/Battery")


def test_echo_takes_ros2_s_type_argument_and_checks_it(robot: DemoRobot) -> None:
    field = ("--once", "--field", "header.frame_id")
    both = rmb("echo", "/odom", "nav_msgs/msg/Odometry", *field, url=robot.url)
    assert ok(both) == "odom\n---\n"
    short = rmb("echo", "/odom", "nav_msgs/Odometry", *field, url=robot.url)
    assert ok(short) == "odom\n---\n"
    wrong = rmb("echo", "/odom", "std_msgs/msg/String", "--once", url=robot.url)
    line = refused(wrong)
    assert "/odom is a nav_msgs/msg/Odometry, not a std_msgs/msg/String" in line
    assert wrong.stdout == ""


def test_service_call_takes_ros2_s_type_argument_and_checks_it(robot: DemoRobot) -> None:
    called = rmb(
        "service", "call", "/set_led", "std_srvs/srv/SetBool", "{data: false}", url=robot.url
    )
    assert json.loads(ok(called)) == {"success": True, "message": "led off"}
    assert robot.parameters["led"] is False
    no_values = rmb("call", "/reset_odometry", "std_srvs/srv/Trigger", url=robot.url)
    assert json.loads(ok(no_values))["success"] is True
    wrong = rmb("service", "call", "/set_led", "std_srvs/srv/Trigger", "{}", url=robot.url)
    assert "/set_led is a std_srvs/srv/SetBool, not a std_srvs/srv/Trigger" in refused(wrong)


def test_an_address_after_the_name_is_taken(robot: DemoRobot) -> None:
    host_port = robot.url.removeprefix("ws://")
    field = ("--once", "--field", "header.frame_id")
    assert ok(rmb("echo", "/odom", host_port, *field)) == "odom\n---\n"
    assert ok(rmb("echo", "/odom", robot.url, *field)) == "odom\n---\n"
    typed = rmb("echo", "/odom", "nav_msgs/msg/Odometry", host_port, *field)
    assert ok(typed) == "odom\n---\n"


def test_param_get_and_set_take_the_node_first(robot: DemoRobot) -> None:
    done = rmb("param", "set", "/demo_robot", "max_speed", "0.55", url=robot.url)
    assert ok(done) == "Set parameter successful: max_speed: 0.55\n"
    assert robot.parameters["max_speed"] == 0.55
    got = rmb("param", "get", "/demo_robot", "max_speed", url=robot.url)
    assert (got.returncode, got.stdout, got.stderr) == (0, "max_speed: 0.55\n", "")
    several = rmb("param", "get", "/demo_robot", "max_speed", "led", url=robot.url)
    assert ok(several).splitlines()[0] == "max_speed: 0.55"


def test_param_dump_prints_ros2_s_yaml(robot: DemoRobot) -> None:
    dumped = yaml.safe_load(ok(rmb("param", "dump", url=robot.url)))
    assert list(dumped) == ["/rmb_demo_robot"]
    params = dumped["/rmb_demo_robot"]["ros__parameters"]
    assert params["robot_name"] == "rmb-demo-robot" and set(params) >= {"led", "max_speed"}
    named = yaml.safe_load(ok(rmb("param", "dump", "/demo_robot", url=robot.url)))
    assert named["/demo_robot"]["ros__parameters"] == params
    as_json = json_lines(ok(rmb("param", "dump", "--json", url=robot.url)))
    assert as_json == [{"node": "/rmb_demo_robot", "parameters": params}]


# -- listings ----------------------------------------------------------------------------------


def test_topics_verbose_count_and_json(robot: DemoRobot) -> None:
    verbose = ok(rmb("topics", "-v", url=robot.url)).splitlines()
    assert verbose[0] == "Published topics:"
    assert "Subscribed topics:" in verbose
    # counted in the robot's connection graph: one publisher each, and no
    # subscriber of the robot's own topics
    assert " * /odom [nav_msgs/msg/Odometry] 1 publisher" in verbose
    assert verbose[verbose.index("Subscribed topics:") + 1] == ""
    assert ok(rmb("topic", "list", "-c", url=robot.url)) == f"{len(TOPICS)}\n"
    records = json_lines(ok(rmb("topics", "--json", url=robot.url)))
    assert {r["name"] for r in records} == TOPICS
    assert {"name": "/odom", "type": "nav_msgs/msg/Odometry", "encoding": "cdr"} in records
    counted = json_lines(ok(rmb("topics", "-c", "--json", url=robot.url)))
    assert counted == [{"count": len(TOPICS)}]
    with_counts = json_lines(ok(rmb("topics", "-v", "--json", url=robot.url)))
    assert {(r["publishers"], r["subscribers"]) for r in with_counts} == {(1, 0)}


def test_verbosity_before_the_verb_and_the_listing_after_it(robot: DemoRobot) -> None:
    # -v before the verb: log more and show the traceback; -v after topics: the listing
    both = rmb("-v", "topics", "-v", "-u", "127.0.0.1:1", "--timeout", "2")
    assert both.returncode == 1
    assert "Traceback" in both.stderr
    assert ok(rmb("topics", "-v", url=robot.url)).startswith("Published topics:\n")


def test_services_count_json_type_find(robot: DemoRobot) -> None:
    assert ok(rmb("services", "-c", url=robot.url)) == "2\n"
    assert json_lines(ok(rmb("service", "list", "--json", url=robot.url))) == [
        {"name": "/reset_odometry", "type": "std_srvs/srv/Trigger"},
        {"name": "/set_led", "type": "std_srvs/srv/SetBool"},
    ]
    assert ok(rmb("service", "type", "/set_led", url=robot.url)) == "std_srvs/srv/SetBool\n"
    assert ok(rmb("service", "find", "std_srvs/srv/Trigger", url=robot.url)) == "/reset_odometry\n"
    assert ok(rmb("service", "find", "std_srvs/Trigger", url=robot.url)) == "/reset_odometry\n"
    missing = rmb("service", "type", "/set_le", url=robot.url)
    assert "nearest: /set_led" in refused(missing, 1)


def test_topic_type_and_find(robot: DemoRobot) -> None:
    assert ok(rmb("topic", "find", "nav_msgs/msg/Odometry", url=robot.url)) == "/odom\n"
    found = json_lines(ok(rmb("topic", "find", "nav_msgs/Odometry", "--json", url=robot.url)))
    assert found == [{"name": "/odom", "type": "nav_msgs/msg/Odometry"}]
    assert ok(rmb("topic", "find", "std_msgs/msg/String", url=robot.url)) == ""
    typed = json_lines(ok(rmb("topic", "type", "/battery", "--json", url=robot.url)))
    assert typed == [{"name": "/battery", "type": "sensor_msgs/msg/BatteryState"}]
    assert "nearest: /odom" in refused(rmb("topic", "type", "/odm", url=robot.url), 1)


def test_json_of_params_and_of_a_call(robot: DemoRobot) -> None:
    listed = json_lines(ok(rmb("param", "list", "--json", url=robot.url)))
    assert {"node", "name", "value"} == set(listed[0])
    assert {r["name"] for r in listed} >= {"led", "max_speed", "robot_name"}
    got = json_lines(ok(rmb("param", "get", "robot_name", "--json", url=robot.url)))
    assert got == [{"node": None, "name": "robot_name", "value": "rmb-demo-robot"}]
    done = json_lines(ok(rmb("param", "set", "max_speed", "0.65", "--json", url=robot.url)))
    assert done == [{"node": None, "name": "max_speed", "value": 0.65, "set": True}]
    called = json_lines(ok(rmb("call", "/set_led", "{data: true}", "--json", url=robot.url)))
    assert called == [
        {
            "service": "/set_led",
            "type": "std_srvs/srv/SetBool",
            "response": {"success": True, "message": "led on"},
        }
    ]


# -- echo's formats ------------------------------------------------------------------------


def test_echo_csv_is_one_line_of_values_per_message(robot: DemoRobot) -> None:
    text = ok(rmb("echo", "/pose", "--csv", "-n", "2", url=robot.url))
    lines = text.splitlines()
    assert len(lines) == 2
    # header (sec, nanosec, frame_id), position (x, y, z), orientation (x, y, z, w)
    values = lines[0].split(",")
    assert len(values) == 10
    assert values[2] == "map" or not values[2].replace(".", "").isdigit()
    assert all(float(v) == float(v) for v in values[3:])


def test_echo_flow_style_is_one_yaml_line_per_message(robot: DemoRobot) -> None:
    text = ok(rmb("echo", "/odom", "--flow-style", "-n", "2", "--no-arr", url=robot.url))
    lines = text.splitlines()
    assert lines[1] == "---" and lines[3] == "---" and len(lines) == 4
    message = yaml.safe_load(lines[0])
    assert lines[0].startswith("{header: {stamp: {")
    assert message["header"]["frame_id"] == "odom"
    assert message["pose"]["covariance"] == "<array: 36 items>"


def test_echo_formats_exclude_each_other(robot: DemoRobot) -> None:
    result = rmb("echo", "/odom", "--csv", "--json", url=robot.url)
    assert result.returncode == 2 and "not allowed with" in result.stderr


# -- one line per event ----------------------------------------------------------------------


def test_action_send_over_foxglove_prints_no_goal_before_the_error(robot: DemoRobot) -> None:
    result = rmb(
        "action", "send", "/fib", "test_msgs/action/Fibonacci", "{order: 3}", url=robot.url
    )
    assert "NotSupportedError" in refused(result, 1)
    assert result.stdout == ""


def _interrupt(proc: subprocess.Popen[str]) -> tuple[str, str]:
    proc.send_signal(signal.SIGINT)
    try:
        return proc.communicate(timeout=20)
    finally:
        proc.kill()


@pytest.mark.parametrize("backend", BACKENDS)
def test_ctrl_c_while_echoing_prints_nothing_on_stderr(robot: DemoRobot, backend: str) -> None:
    proc = rmb_proc(
        "--backend", backend, "echo", "/odom", "--field", "header.frame_id", url=robot.url
    )
    assert proc.stdout is not None
    assert proc.stdout.readline() == "odom\n"
    _out, err = _interrupt(proc)
    assert proc.returncode == 130
    assert err == ""  # no WARNING for the Ctrl-C the user typed


@pytest.mark.parametrize("backend", BACKENDS)
def test_ctrl_c_while_connecting_to_a_silent_port(backend: str) -> None:
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        port = server.getsockname()[1]
        proc = rmb_proc("--backend", backend, "echo", "/odom", url=f"127.0.0.1:{port}")
        conn, _ = server.accept()  # connected: the handshake gets no answer
        with conn:
            _out, err = _interrupt(proc)
    assert proc.returncode == 130
    assert err == ""


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_lost_connection_then_ctrl_c_is_one_line(backend: str) -> None:
    bot = DemoRobot()
    bot.start()
    try:
        proc = rmb_proc(
            "--backend", backend, "echo", "/odom", "--field", "header.frame_id", url=bot.url
        )
        assert proc.stdout is not None
        assert proc.stdout.readline() == "odom\n"
    finally:
        bot.stop()
    assert proc.stderr is not None
    lost = proc.stderr.readline()
    _out, err = _interrupt(proc)
    assert proc.returncode == 130
    assert "connection lost" in lost
    assert err == "", err


# -- against rosbridge_server_rs on a ROS 2 graph (marked ros by its fixtures) ------------------


def test_rosbridge_topics_verbose_counts_publishers_and_subscribers(rosbridge: RosBridge) -> None:
    lines = ok(rmb("topics", "-v", url=rosbridge.url)).splitlines()
    published = lines[1 : lines.index("")]
    subscribed = lines[lines.index("Subscribed topics:") + 1 :]
    assert " * /chatter [std_msgs/msg/String] 1 publisher" in published
    assert any(line.startswith(" * /rmb_in [std_msgs/msg/String] ") for line in subscribed)
    records = {
        r["name"]: r for r in json_lines(ok(rmb("topics", "-v", "--json", url=rosbridge.url)))
    }
    assert records["/chatter"]["publishers"] == 1
    assert isinstance(records["/chatter"]["subscribers"], int)


def test_rosbridge_params_by_node(rosbridge: RosBridge) -> None:
    got = rmb("param", "get", "/rmb_params", "speed", "label", url=rosbridge.url)
    assert ok(got) == "speed: 0.5\nlabel: demo\n"
    relative = rmb("param", "get", "rmb_params", "speed", url=rosbridge.url)
    assert ok(relative) == "speed: 0.5\n"  # a node named relative is resolved against /
    dumped = yaml.safe_load(ok(rmb("param", "dump", "/rmb_params", url=rosbridge.url)))
    assert dumped["/rmb_params"]["ros__parameters"]["label"] == "demo"
    listed = ok(rmb("param", "list", "/rmb_params", url=rosbridge.url)).split()
    assert {"speed", "label"} <= set(listed)
    missing = rmb("param", "dump", "/rmb_parms", url=rosbridge.url)
    assert "nearest: /rmb_params" in refused(missing, 1)


def test_rosbridge_action_send_json_lines(rosbridge: RosBridge) -> None:
    goal = ("/fibonacci", "test_msgs/action/Fibonacci", "{order: 4}")
    records = json_lines(ok(rmb("action", "send", *goal, "--json", url=rosbridge.url)))
    assert records[0] == {
        "action": "/fibonacci",
        "type": "test_msgs/action/Fibonacci",
        "goal": {"order": 4},
    }
    feedback = [r["feedback"] for r in records[1:-1]]
    assert feedback and all(set(r) == {"feedback"} for r in records[1:-1])
    assert records[-1] == {"status": "succeeded", "result": {"sequence": [0, 1, 1, 2, 3, 5]}}


# -- over Zenoh, against a zenoh-ros2-sdk node (marked ros by its fixtures) ----------------------


def test_zenoh_params_by_node(sdk: Any, zenoh_router: Any, zenoh_domain: int) -> None:
    pytest.importorskip("zenoh_ros2_sdk")
    sdk("params")
    env = cli_env(ROS_DOMAIN_ID=str(zenoh_domain))

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return rmb("--protocol", "zenoh", "-u", zenoh_router.locator, *args, env=env)

    got = run("param", "get", "/sdk_params", "speed", "name")
    assert ok(got) == "speed: 0.5\nname: robot\n"
    dumped = yaml.safe_load(ok(run("param", "dump", "sdk_params")))
    assert dumped == {
        "/sdk_params": {"ros__parameters": {"enabled": True, "name": "robot", "speed": 0.5}}
    }
    done = run("param", "set", "/sdk_params", "speed", "1.5", "--json")
    assert json_lines(ok(done)) == [
        {"node": "/sdk_params", "name": "speed", "value": 1.5, "set": True}
    ]
