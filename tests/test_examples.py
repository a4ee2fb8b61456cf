"""The examples of issue 11 (teleop, monitor, fleet, relay, MCP server), each run
as a user would run it (a separate process) against the demo robot."""

from __future__ import annotations

import itertools
import json
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import anyio
import httpx
import pytest
from httpx_ws import aconnect_ws

from _util import wait_until_sync
from ros_mobile_bridge.demo import DemoRobot

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"


def run(script: str, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(EXAMPLES / script), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
        check=False,
    )


def test_teleop_asyncio_drives_the_route_and_stops_with_a_zero_twist(robot: DemoRobot) -> None:
    before = len(robot.received_cmd_vel())
    x0 = robot.pose[0]
    result = run("teleop_asyncio.py", robot.url)
    assert result.returncode == 0, result.stderr
    commands = [(c.linear_x, c.angular_z) for c in robot.received_cmd_vel()[before:]]
    # the route, step by step at 10 Hz, then the teardown's zero Twist, once and last (a
    # command may replace one the writer has not sent yet, hence "at most" per step)
    steps = [(command, len(list(run))) for command, run in itertools.groupby(commands)]
    assert [command for command, _ in steps] == [(0.3, 0.0), (0.1, 0.8), (0.3, 0.0), (0.0, 0.0)]
    assert [n for _, n in steps][3] == 1
    assert all(0 < n <= limit for (_, n), limit in zip(steps, (6, 5, 4), strict=False))
    assert robot.pose[0] > x0  # it moved
    assert "odometry messages" in result.stdout
    assert result.stdout.rstrip().endswith("stopped: zero Twist sent on teardown")


def test_teleop_asyncio_keyboard_mode_reads_keys_from_stdin(robot: DemoRobot) -> None:
    before = len(robot.received_cmd_vel())
    result = subprocess.run(
        [sys.executable, str(EXAMPLES / "teleop_asyncio.py"), robot.url, "--interactive"],
        input="w\nq\n",
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    commands = [(c.linear_x, c.angular_z) for c in robot.received_cmd_vel()[before:]]
    assert (0.3, 0.0) in commands  # the "w" key
    assert commands[-1] == (0.0, 0.0)


def test_monitor_trio_counts_every_topic(robot: DemoRobot) -> None:
    result = run(
        "monitor_trio.py", robot.url, "/odom", "/battery", "/status", "/nosuch",
        "--count", "2", "--seconds", "5", "--json",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert list(report) == ["/odom", "/battery", "/status", "/nosuch"]
    # /nosuch never appears, so the run ends on --seconds; the others have their count
    for topic in ("/odom", "/battery", "/status"):
        assert report[topic]["count"] >= 2, report
        assert report[topic]["rate_hz"] > 0
    assert report["/odom"]["count"] > report["/battery"]["count"]  # 20 Hz against 1 Hz
    assert report["/nosuch"] == {"count": 0, "rate_hz": 0.0, "latest": {}}
    assert set(report["/odom"]["latest"]) == {"x", "y"}
    assert report["/status"]["latest"]["mode"] in ("idle", "driving", "watchdog_stop")


def test_monitor_trio_stops_once_every_topic_has_its_count(robot: DemoRobot) -> None:
    result = run("monitor_trio.py", robot.url, "/odom", "/status", "--count", "3", "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["/status"]["count"] == 3  # 2 Hz: the last topic to reach 3 ends the run
    assert report["/odom"]["count"] >= 3


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_fleet_drives_every_robot_and_reports_the_one_that_failed(backend: str) -> None:
    with ExitStack() as stack:
        bots = [stack.enter_context(DemoRobot(name=f"bot{i}")) for i in range(3)]
        dead = "ws://127.0.0.1:1"
        urls = [bots[0].url, dead, bots[1].url, bots[2].url]
        result = run("fleet.py", *urls, "--seconds", "1.0", "--backend", backend)
        assert result.returncode == 1, result.stderr  # one robot failed
        lines = dict(line.split(": ", 1) for line in result.stdout.splitlines())
        assert list(lines) == urls
        assert lines[dead].startswith("FAILED ConnectError")
        for bot in bots:
            assert lines[bot.url].startswith("ok mode="), result.stdout
            commands = [c.linear_x for c in bot.received_cmd_vel()]
            assert commands.count(0.2) >= 3
            assert commands[-1] == 0.0  # each robot's own teardown stopped it
            assert set(commands) == {0.2, 0.0}


def test_fleet_exits_zero_when_every_robot_answers(robot: DemoRobot) -> None:
    with DemoRobot() as other:
        result = run("fleet.py", robot.url, other.url, "--seconds", "0.3")
        assert result.returncode == 0, result.stdout + result.stderr
        assert other.received_cmd_vel()[-1].linear_x == 0.0


# -- relay_starlette.py: a Starlette app under uvicorn, browsers played by httpx-ws --------


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def relay(robot: DemoRobot) -> Iterator[str]:
    """The relay example serving the robot's /odom (20 Hz) on a free port; yields its ws URL."""
    port = free_port()
    script = str(EXAMPLES / "relay_starlette.py")
    cmd = [sys.executable, script, robot.url, "/odom", "--port", str(port)]
    with subprocess.Popen(cmd, cwd=ROOT, stderr=subprocess.PIPE, text=True) as proc:

        def page() -> httpx.Response | None:
            assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
            try:
                return httpx.get(f"http://127.0.0.1:{port}/", timeout=1)
            except httpx.TransportError:
                return None

        try:
            served = wait_until_sync(page, 30, what="the relay to start", interval=0.2)
            assert "new WebSocket" in served.text  # the page a browser loads
            yield f"ws://127.0.0.1:{port}/ws"
        finally:
            proc.terminate()  # uvicorn's graceful shutdown runs the lifespan's teardown
            _, stderr = proc.communicate(timeout=15)
            # uvicorn re-raises the signal once it has shut down cleanly
            assert proc.returncode in (0, -signal.SIGTERM), stderr
            assert "Traceback" not in stderr, stderr


async def read(ws: Any) -> dict[str, Any]:
    message: dict[str, Any] = json.loads(await ws.receive_text(timeout=10))
    await ws.send_text("next")
    return message


async def test_relay_delivers_the_topic_as_json_in_order(relay: str) -> None:
    async with httpx.AsyncClient() as http, aconnect_ws(relay, http) as ws:
        messages = [await read(ws) for _ in range(10)]
    seqs = [m["seq"] for m in messages]
    assert seqs == sorted(set(seqs))  # strictly increasing, never the same message twice
    assert {m["topic"] for m in messages} == {"/odom"}
    assert len(messages[0]["data"]["pose"]["covariance"]) == 36  # numpy array -> JSON list
    assert messages[0]["data"]["header"]["frame_id"] == "odom"


async def test_a_slow_browser_gets_the_newest_message_not_a_backlog(relay: str) -> None:
    async with (
        httpx.AsyncClient() as http,
        aconnect_ws(relay, http) as fast,
        aconnect_ws(relay, http) as slow,
    ):
        slow_seqs = [json.loads(await slow.receive_text(timeout=10))["seq"]]
        fast_seq = (await read(fast))["seq"]
        for _ in range(3):
            # the slow browser dawdles over its message while the fast one keeps reading
            with anyio.move_on_after(0.5):
                while True:
                    fast_seq = (await read(fast))["seq"]
            await slow.send_text("next")  # ready: what comes is the newest, not the next
            slow_seqs.append(json.loads(await slow.receive_text(timeout=10))["seq"])
            assert slow_seqs[-1] >= fast_seq
        gaps = [b - a for a, b in itertools.pairwise(slow_seqs)]
        assert all(gap > 1 for gap in gaps), slow_seqs  # it skipped; nothing was queued


async def test_a_browser_leaving_does_not_disturb_the_others(relay: str) -> None:
    async with httpx.AsyncClient() as http, aconnect_ws(relay, http) as stays:
        async with aconnect_ws(relay, http) as leaves:
            await read(leaves)
            await read(stays)
        # one left mid-stream (and one more leaves without a word, after one message)
        async with aconnect_ws(relay, http) as rude:
            await rude.receive_text(timeout=10)
        seqs = [(await read(stays))["seq"] for _ in range(5)]
        assert seqs == sorted(set(seqs))
        async with aconnect_ws(relay, http) as newcomer:
            assert (await read(newcomer))["seq"] >= seqs[-1]


# -- mcp_server.py, driven by the MCP SDK's own client over stdio ------------------------

MCP_TOOLS = {
    "list_topics", "read_topic", "list_services", "call_service", "get_parameters",
    "set_parameters", "show_type", "publish", "stop",
}  # fmt: skip


def tool_text(result: Any) -> str:
    return "".join(getattr(block, "text", "") for block in result.content)


async def test_mcp_server_tools_against_the_demo_robot(
    robot: DemoRobot, anyio_backend: str, tmp_path: Path
) -> None:
    from mcp import ClientSession
    from mcp.client.stdio import StdioServerParameters, stdio_client

    server = StdioServerParameters(
        command=sys.executable,
        args=[str(EXAMPLES / "mcp_server.py"), robot.url, "--allow-publish", "/cmd_vel",
              "--backend", anyio_backend],
        # the SDK passes the server only a safe subset of the environment
        env={"PYTHONPATH": os.environ["PYTHONPATH"]} if "PYTHONPATH" in os.environ else None,
        cwd=ROOT,
    )  # fmt: skip
    before = len(robot.received_cmd_vel())
    with (tmp_path / "server.log").open("w+") as errlog:
        async with stdio_client(server, errlog=errlog) as streams, ClientSession(*streams) as mcp:
            await mcp.initialize()
            assert {tool.name for tool in (await mcp.list_tools()).tools} == MCP_TOOLS

            async def call(tool: str, /, **arguments: Any) -> Any:
                result = await mcp.call_tool(tool, arguments)
                assert not result.is_error, tool_text(result)
                return result.structured_content

            topics = (await call("list_topics"))["result"]
            assert {"name": "/odom", "type": "nav_msgs/msg/Odometry"} in topics
            battery = await call("read_topic", topic="/battery")
            assert battery["type"] == "sensor_msgs/msg/BatteryState"
            assert 0 < battery["data"]["percentage"] <= 1
            services = (await call("list_services"))["result"]
            assert {"name": "/set_led", "type": "std_srvs/srv/SetBool"} in services
            reply = await call("call_service", name="/set_led", request={"data": True})
            assert reply == {"success": True, "message": "led on"} and robot.led
            assert await call("get_parameters", names=["led"]) == {"led": True}
            assert await call("set_parameters", values={"robot_name": "mcp-bot"}) == {
                "robot_name": "mcp-bot"
            }
            assert robot.parameters["robot_name"] == "mcp-bot"
            assert "max_speed" in await call("get_parameters")
            fields = (await call("show_type", type_name="geometry_msgs/msg/Twist"))["result"]
            assert [(f["name"], f["type"]) for f in fields] == [
                ("linear", "geometry_msgs/msg/Vector3"),
                ("angular", "geometry_msgs/msg/Vector3"),
            ]
            twist = {"linear": {"x": 0.25}}
            await call("publish", topic="/cmd_vel", type_name="geometry_msgs/msg/Twist",
                       message=twist)  # fmt: skip
            resource = await mcp.read_resource("robot://topics")
            assert "/odom" in getattr(resource.contents[0], "text", "")

            # refused: a topic not on the allow-list, an unknown topic's bounded wait
            refused = await mcp.call_tool(
                "publish",
                {"topic": "/cmd_vel_stamped", "type_name": "geometry_msgs/msg/TwistStamped",
                 "message": {"twist": {"linear": {"x": 0.5}}}},
            )  # fmt: skip
            assert refused.is_error
            assert "publishing to /cmd_vel_stamped is not allowed" in tool_text(refused)
            missing = await mcp.call_tool("read_topic", {"topic": "/nosuch", "timeout": 0.3})
            assert missing.is_error and "no message on /nosuch" in tool_text(missing)
            bad = await mcp.call_tool("call_service", {"name": "/nosuch", "request": {}})
            assert bad.is_error
        # the session is over: the server's teardown stopped the robot
        errlog.seek(0)
        log = errlog.read()
    commands = robot.received_cmd_vel()[before:]
    assert [c.linear_x for c in commands] == [0.25, 0.0], log
    assert "Traceback" not in log, log
