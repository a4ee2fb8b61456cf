"""``rmb graph --watch --json`` and ``rmb node list`` against each transport's
real peer: what appears and leaves is printed as one event per line, in
order; ``node list`` names the nodes where the transport knows them and is
one error line (exit 1) over Foxglove."""

from __future__ import annotations

import json
import queue
import signal
import subprocess
import threading
import time
from collections.abc import Callable
from typing import Any

import foxglove
import pytest
from foxglove.websocket import Capability

from _cli_run import cli_env
from _cli_run import rmb as run_rmb
from _cli_run import rmb_proc as start_rmb
from peers.foxglove_sdk import ALL_CAPABILITIES, SdkServer
from peers.rosbridge import RosBridge, RosGraph
from peers.zenoh_sdk_node import SdkNode
from ros_mobile_bridge._cli._graph import changes, graph_entries
from ros_mobile_bridge._types import ServiceInfo, TopicInfo

pytest_plugins = ["peers.ros_fixtures"]

BACKENDS = ["asyncio", "trio"]


def rmb(*args: str, **env: str) -> subprocess.CompletedProcess[str]:
    """``rmb ARGS`` with ``env`` set and no inherited ``$ROS_DOMAIN_ID``."""
    return run_rmb(*args, env=cli_env(drop=["ROS_DOMAIN_ID"], **env))


def rmb_proc(*args: str, **env: str) -> subprocess.Popen[str]:
    return start_rmb(*args, env=cli_env(drop=["ROS_DOMAIN_ID"], **env))


class Events:
    """The JSON events a running ``rmb graph --watch --json`` printed (read
    by a thread, so a missing event fails the test in 30 s, not a hang)."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.proc = proc
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.seen: list[dict[str, Any]] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line)
        self.lines.put(None)

    def next(self, want: Callable[[dict[str, Any]], bool]) -> list[dict[str, Any]]:
        """Events up to and including the first one ``want`` accepts."""
        got: list[dict[str, Any]] = []
        deadline = time.monotonic() + 30
        while True:
            try:
                line = self.lines.get(timeout=max(deadline - time.monotonic(), 0.0))
            except queue.Empty:
                raise AssertionError(f"not printed in 30 s; so far: {self.seen}") from None
            assert line is not None, f"rmb ended; so far: {self.seen}"
            event = json.loads(line)
            assert set(event) == {"event", "kind", "name", "type"}, event
            got.append(event)
            self.seen.append(event)
            if want(event):
                return got

    def until_all(self, *wanted: tuple[str, str, str]) -> list[dict[str, Any]]:
        """Events up to the last of ``wanted`` ``(event, kind, name)``, in
        any order (a node and its topic come from two sources)."""
        got: list[dict[str, Any]] = []
        left = set(wanted)
        while left:
            got += self.next(lambda e: (e["event"], e["kind"], e["name"]) in left)
            left.discard((got[-1]["event"], got[-1]["kind"], got[-1]["name"]))
        return got

    def stop(self) -> int:
        self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.communicate(timeout=20)
        finally:
            self.proc.kill()
        return self.proc.returncode


def watch(*args: str) -> Events:
    return Events(rmb_proc("graph", "--watch", "--json", "--interval", "0.2", *args))


def is_(event: str, kind: str, name: str) -> Callable[[dict[str, Any]], bool]:
    return lambda e: (e["event"], e["kind"], e["name"]) == (event, kind, name)


# -- the diff (no robot) ----------------------------------------------------------------------


def test_changes_are_removals_then_additions_sorted_and_actions_are_read_off_services() -> None:
    before = graph_entries("topic", [TopicInfo("/a", "x/msg/A"), TopicInfo("/b", "x/msg/B")])
    after = graph_entries("topic", [TopicInfo("/b", "x/msg/C"), TopicInfo("/c", "x/msg/C")])
    assert changes(before, after) == [
        (False, ("topic", "/a", "x/msg/A")),
        (False, ("topic", "/b", "x/msg/B")),
        (True, ("topic", "/b", "x/msg/C")),
        (True, ("topic", "/c", "x/msg/C")),
    ]
    # a type learnt late is no event; a type that changes is two
    late = graph_entries("service", [ServiceInfo("/s", ""), ServiceInfo("/t", "x/srv/T")])
    known = graph_entries("service", [ServiceInfo("/s", "x/srv/S"), ServiceInfo("/t", "x/srv/U")])
    assert changes(late, known) == [
        (False, ("service", "/t", "x/srv/T")),
        (True, ("service", "/t", "x/srv/U")),
    ]
    services = [
        ServiceInfo("/fib/_action/send_goal", "t/action/Fibonacci_SendGoal"),
        ServiceInfo("/fib/_action/get_result", "t/action/Fibonacci_GetResult"),
        ServiceInfo("/set", "std_srvs/srv/SetBool"),
    ]
    assert graph_entries("service", services) == {
        ("action", "/fib", "t/action/Fibonacci"),
        ("service", "/set", "std_srvs/srv/SetBool"),
    }


# -- Foxglove ----------------------------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
def test_foxglove_graph_watch_follows_advertise_and_unadvertise(
    server: SdkServer, backend: str
) -> None:
    server.channel("/odom", "nav_msgs/msg/Odometry")
    events = watch("--backend", backend, "-u", server.url)
    try:
        first = events.next(is_("added", "topic", "/odom"))
        assert first[-1]["type"] == "nav_msgs/msg/Odometry"
        battery = server.channel("/battery", "sensor_msgs/msg/BatteryState")
        added = events.next(is_("added", "topic", "/battery"))
        battery.close()
        removed = events.next(is_("removed", "topic", "/battery"))
    finally:
        code = events.stop()
    assert [(e["event"], e["name"]) for e in added] == [("added", "/battery")]
    assert [(e["event"], e["name"]) for e in removed] == [("removed", "/battery")]
    assert code == 130


def test_foxglove_node_list_reads_the_connection_graph(server: SdkServer) -> None:
    graph = foxglove.ConnectionGraph()
    graph.set_published_topic("/odom", ["/base_driver"])
    graph.set_subscribed_topic("/odom", ["/nav2"])
    server.server.publish_connection_graph(graph)
    result = rmb("node", "list", "-u", server.url)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["/base_driver", "/nav2"]


def test_foxglove_node_list_without_a_connection_graph_is_one_error_line() -> None:
    caps = [c for c in ALL_CAPABILITIES if c != Capability.ConnectionGraph]
    with SdkServer(capabilities=caps) as server:
        result = rmb("node", "list", "-u", server.url)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "'connectionGraph' capability" in lines[0], result.stderr


# -- Zenoh -------------------------------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
def test_zenoh_graph_watch_sees_a_talker_come_and_go(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int, backend: str
) -> None:
    common = ("--backend", backend, "--protocol", "zenoh", "-u", zenoh_router.locator)
    domain = {"ROS_DOMAIN_ID": str(zenoh_domain)}
    events = Events(rmb_proc("graph", "--watch", "--json", "--interval", "0.2", *common, **domain))
    try:
        talker = sdk("talker", "--rate", "10", "--node", "graph_talker")
        came = events.until_all(("added", "topic", "/chatter"), ("added", "node", "/graph_talker"))
        listed = rmb("node", "list", "--json", *common, **domain)
        talker.stop()
        went = events.until_all(
            ("removed", "node", "/graph_talker"), ("removed", "topic", "/chatter")
        )
    finally:
        code = events.stop()
    assert ("added", "topic", "/chatter", "std_msgs/msg/String") in [
        (e["event"], e["kind"], e["name"], e["type"]) for e in came
    ]
    # ``rmb node list`` is a node of its own while it runs; the watch may see
    # it come and go between the talker's events (it did under CI's load)
    assert all(e["event"] == "added" for e in came if not e["name"].startswith("/rmb_"))
    assert all(e["event"] == "removed" for e in went if not e["name"].startswith("/rmb_"))
    assert listed.returncode == 0, listed.stderr
    # the talker, and the node of the rmb graph command itself
    names = [json.loads(x)["name"] for x in listed.stdout.splitlines()]
    assert "/graph_talker" in names and len(names) == 2, names
    assert code == 130


# -- rosbridge ---------------------------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
def test_rosbridge_graph_watch_sees_a_node_come_and_go(
    rosbridge: RosBridge, ros_graph: RosGraph, backend: str
) -> None:
    name = f"graph_watch_{backend}"
    topic = f"/graph_watch_{backend}"
    events = watch("--backend", backend, "-u", rosbridge.url)
    try:
        events.next(is_("added", "node", "/rmb_graph"))
        ros_graph.command({"cmd": "node", "name": name, "topic": topic})
        came = events.until_all(("added", "node", f"/{name}"), ("added", "topic", topic))
        listed = rmb("node", "list", "-u", rosbridge.url)
        ros_graph.command({"cmd": "drop_node", "name": name})
        went = events.until_all(("removed", "node", f"/{name}"), ("removed", "topic", topic))
    finally:
        code = events.stop()

    # the node and its topic came, then went, and neither the other way round
    def of(events: list[dict[str, Any]]) -> list[tuple[str, str]]:
        return [(e["event"], e["name"]) for e in events if e["name"] in (topic, f"/{name}")]

    assert sorted(of(came)) == [("added", topic), ("added", f"/{name}")], came
    assert sorted(of(went)) == [("removed", topic), ("removed", f"/{name}")], went
    assert listed.returncode == 0, listed.stderr
    assert {f"/{name}", "/rmb_graph", "/rmb_params"} <= set(listed.stdout.split())
    assert code == 130
