"""An MCP tool server for one robot (official ``mcp`` SDK 2.x, stdio transport).

An agent (Claude Desktop, an IDE, any MCP client) starts this program and gets
tools to look at the robot, call its services, read and set its parameters,
read type definitions, and publish - but only to the topics named with
``--allow-publish``; anything else is refused with an error the model can read.
When the agent's session ends (stdin closes, or SIGTERM/SIGINT), the client's
teardown sends a zero Twist to every velocity topic this server published to.
The robot still needs its own cmd_vel watchdog: nothing here can stop it once
the network between the two is gone. See docs/mcp.md.

    rmb demo --serve --port 8765 &
    # in an MCP client's configuration, the command to run:
    python examples/mcp_server.py ws://127.0.0.1:8765 --allow-publish /cmd_vel
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import anyio
from mcp.server.mcpserver import MCPServer
from mcp.server.mcpserver.exceptions import ToolError

import ros_mobile_bridge as rmb

MAX_WAIT_S = 30.0  # the longest any tool waits for the robot


@contextmanager
def robot_errors() -> Iterator[None]:
    """The library's errors (and bad arguments) as tool errors the model can read."""
    try:
        yield
    except (rmb.RosBridgeError, ValueError, TypeError) as exc:
        raise ToolError(f"{type(exc).__name__}: {exc}") from exc


def build_server(robot: rmb.Client, allowed: frozenset[str]) -> MCPServer:
    server = MCPServer("ros-mobile-bridge", instructions="Tools for one ROS 2 robot.")

    @server.tool()
    def list_topics() -> list[dict[str, str]]:
        """The topics the robot offers, with their message types."""
        return [{"name": t.name, "type": t.schema_name} for t in robot.topics]

    @server.tool()
    async def read_topic(topic: str, timeout: float = 5.0) -> dict[str, Any]:
        """The next message on ``topic``, waiting at most ``timeout`` seconds (max 30)."""
        with robot_errors(), anyio.move_on_after(min(max(timeout, 0.0), MAX_WAIT_S)):
            async with robot.subscribe(topic, dispatch="latest") as sub:
                async for msg in sub:
                    return {"topic": topic, "type": msg.schema_name, "data": rmb.jsonable(msg.data)}
        raise ToolError(f"no message on {topic} within {timeout} s (is the name right?)")

    @server.tool()
    def list_services() -> list[dict[str, str]]:
        """The services the robot offers, with their types."""
        return [{"name": s.name, "type": s.type} for s in robot.services]

    @server.tool()
    async def call_service(
        name: str, request: dict[str, Any], timeout: float = 5.0
    ) -> dict[str, Any]:
        """Call service ``name`` with ``request`` (a JSON object) and return its reply."""
        with robot_errors():
            reply = await robot.call_service(name, request, timeout=min(timeout, MAX_WAIT_S))
            answer: dict[str, Any] = rmb.jsonable(reply)
            return answer

    @server.tool()
    async def get_parameters(names: list[str] | None = None) -> dict[str, Any]:
        """Parameter values: the named ones, or all of them when ``names`` is omitted."""
        with robot_errors():
            values = await (robot.get_parameters(names) if names else robot.list_parameters())
            found: dict[str, Any] = rmb.jsonable(values)
            return found

    @server.tool()
    async def set_parameters(values: dict[str, Any]) -> dict[str, Any]:
        """Set parameters; returns the values the robot reports afterwards."""
        with robot_errors():
            now: dict[str, Any] = rmb.jsonable(await robot.set_parameters(values))
            return now

    @server.tool()
    def show_type(type_name: str) -> list[dict[str, Any]]:
        """The fields of a message type (e.g. geometry_msgs/msg/Twist), in order."""
        with robot_errors():
            return [
                {"name": f.name, "type": f.type, "array": f.array, "length": f.array_length}
                for f in robot.schema_definition(type_name)
            ]

    @server.tool()
    async def publish(topic: str, type_name: str, message: dict[str, Any]) -> str:
        """Publish one message (missing fields are zero) to a topic on the allow-list.

        A velocity command is obeyed only briefly (the robot's watchdog); send it again
        to keep moving, or call ``stop``."""
        if topic not in allowed:
            raise ToolError(f"publishing to {topic} is not allowed; allowed: {sorted(allowed)}")
        with robot_errors():
            await robot.publish(topic, type_name, message, priority="control")
        return f"published to {topic}"

    @server.tool()
    async def stop(topic: str = "/cmd_vel") -> str:
        """Send a zero velocity command to ``topic`` (which must be on the allow-list)."""
        if topic not in allowed:
            raise ToolError(f"publishing to {topic} is not allowed; allowed: {sorted(allowed)}")
        with robot_errors():
            await robot.publish_zero_twist(topic)
        return f"zero velocity sent to {topic}"

    @server.resource("robot://topics", mime_type="application/json")
    def topics_resource() -> list[dict[str, str]]:
        """The robot's topics (the same as the list_topics tool)."""
        return list_topics()

    return server


async def main(url: str, allowed: frozenset[str]) -> None:
    # messages go to stdout only through MCP; the library logs to stderr
    async with rmb.cancel_on_signals(), rmb.connect(url) as robot:
        await build_server(robot, allowed).run_stdio_async()
    # leaving connect() sent a zero Twist to each velocity topic published to


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url", help="the robot, e.g. ws://127.0.0.1:8765")
    parser.add_argument(
        "--allow-publish",
        action="append",
        default=[],
        metavar="TOPIC",
        help="a topic the agent may publish to (repeat for more)",
    )
    parser.add_argument("--backend", choices=("asyncio", "trio"), default="asyncio")
    a = parser.parse_args()
    anyio.run(main, a.url, frozenset(a.allow_publish), backend=a.backend)
